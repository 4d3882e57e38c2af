"""Path and boundary constraints of the optimal-control engine.

A constraint gives *rows*: ``(label, expression, lower, upper)`` with one label
per row (what it is, so that an infeasible problem can say which constraint is
violated, where and by how much).  Path constraints are evaluated at every
collocation point (``path(pt)``), boundary constraints once on the horizon
(``boundary(glob)``: ``x0``, ``xN`` the first and last states, ``T`` the
duration, and the state layout).

- :class:`TrackingTolerance` -- ``|q_c - q_d(t)| <= eps`` (thesis Eq. 3.7);
- :class:`ExcitationBounds` -- ``lo <= u <= hi`` (Eq. 3.8; default [0, 1] from the muscles);
- :class:`CoordinateBounds` -- ``lo <= q_c <= hi`` on the path (e.g. the knee
  hyper-extension bound of Eq. 5.10);
- :class:`InitialState` -- the start of the motion fixed (the thesis's forward
  simulations start from the target's state at rest activation ``a(0) = u(0)``);
- :class:`FinalState` -- coordinates and speeds fixed at the end;
- :class:`Periodic` -- ``x(T) = x(0)`` for the chosen states (Eq. 5.9);
- :class:`Symmetric` -- ``x(T) = mirror(x(0))``: left and right swapped, the
  forward translation advanced (a half gait cycle, Eq. 5.8);
- :class:`AverageSpeed` -- ``(q_c(T) - q_c(0)) / T = speed``;
- :class:`Bounds` -- box bounds on the decision variables themselves (coordinates, speeds,
  accelerations at every node), as Moco's ``setStateInfo`` / PredSim's bounds: they keep
  IPOPT's steps inside the physiological range, and a finite speed or acceleration bound
  also sets that variable's scale (half its range), as Moco scales by the bounds.
"""
from __future__ import annotations

import numpy as np

from ...errors import ModelError
from ._values import ValueEq

__all__ = ["Constraint", "TrackingTolerance", "ExcitationBounds", "CoordinateBounds", "InitialState", "FinalState",
           "Periodic", "Symmetric", "AverageSpeed", "Bounds"]


class Constraint(ValueEq):
    """Base class: ``path(pt)`` and ``boundary(glob)`` return lists of ``(label, expr, lo, hi)``."""

    def check(self, problem) -> None:
        """Resolve names against ``problem``'s model; refuse what cannot apply, by name."""

    def path(self, pt) -> list:
        return []

    def boundary(self, glob) -> list:
        return []


class TrackingTolerance(Constraint):
    """``|q_c(t) - q_d(t)| <= tolerance`` at every collocation point (thesis Eq. 3.7)."""

    def __init__(self, target, tolerance: float, *, coordinate: str | None = None):
        if not float(tolerance) > 0:
            raise ModelError(f"tracking tolerance must be > 0 rad, got {tolerance} "
                             "(the problem would be infeasible)")
        self.target, self.tolerance, self.coordinate = target, float(tolerance), coordinate

    def check(self, problem) -> None:
        self._name = self.coordinate or problem.model.coordinates[0]
        self._j = problem.model.coordinate_index(self._name)

    def path(self, pt) -> list:
        e = pt["q"][self._j] - self.target(pt["t"])
        return [(f"tracking error of {self._name} (rad)", e, -self.tolerance, self.tolerance)]


class ExcitationBounds(Constraint):
    """``lower <= u_i(t) <= upper`` for every muscle (thesis Eq. 3.8)."""

    def __init__(self, lower: float = 0.0, upper: float = 1.0):
        lo, hi = float(lower), float(upper)
        if not lo < hi:
            raise ModelError(f"excitation bounds ({lower}, {upper}) are empty: lower must be below upper "
                             "(the problem would be infeasible)")
        self.lower, self.upper = lo, hi


class CoordinateBounds(Constraint):
    """``lower <= q_c(t) <= upper`` on the path (rad or m), e.g. no knee hyper-extension (Eq. 5.10)."""

    def __init__(self, coordinate: str, lower: float = -np.inf, upper: float = np.inf):
        if not float(lower) < float(upper):
            raise ModelError(f"bounds of {coordinate}: lower {lower} must be below upper {upper}")
        self.coordinate, self.lower, self.upper = coordinate, float(lower), float(upper)

    def check(self, problem) -> None:
        self._j = problem.model.coordinate_index(self.coordinate)

    def path(self, pt) -> list:
        return [(f"bound on {self.coordinate}", pt["q"][self._j], self.lower, self.upper)]


class InitialState(Constraint):
    """The initial coordinates ``q`` and speeds ``v`` fixed (dicts by coordinate, or arrays), and
    ``activation="steady"`` (``a(0) = u(0)``, the rest state of activation dynamics) or ``"free"``."""

    def __init__(self, *, q=None, v=None, activation: str = "steady"):
        if activation not in ("steady", "free"):
            raise ModelError(f"InitialState activation must be 'steady' or 'free', not {activation!r}")
        self.q, self.v, self.activation = q, v, activation

    def _values(self, problem, given, what):
        nv = problem.model.nv
        if given is None:
            return {}
        if isinstance(given, dict):
            return {problem.model.coordinate_index(k): float(x) for k, x in given.items()}
        arr = np.asarray(given, dtype=float)
        if arr.shape != (nv,):
            raise ModelError(f"InitialState {what}: {nv} values needed, got shape {arr.shape}")
        return dict(enumerate(arr))

    def check(self, problem) -> None:
        self._q = self._values(problem, self.q, "q")
        self._v = self._values(problem, self.v, "v")

    def boundary(self, glob) -> list:
        names, lay = glob["coordinates"], glob["layout"]
        rows = [(f"initial {names[j]}", glob["x0"][lay["q"][j]], x, x) for j, x in self._q.items()]
        rows += [(f"initial {names[j]} speed", glob["x0"][lay["v"][j]], x, x) for j, x in self._v.items()]
        if self.activation == "steady" and glob["m"]:
            for i, n in enumerate(glob["muscles"]):
                rows.append((f"initial activation of {n} = excitation", glob["x0"][lay["a"][i]] - glob["e0"][i],
                             0.0, 0.0))
        return rows


class FinalState(InitialState):
    """The final coordinates ``q`` and speeds ``v`` fixed (dicts by coordinate, or arrays)."""

    def __init__(self, *, q=None, v=None):
        super().__init__(q=q, v=v, activation="free")

    def boundary(self, glob) -> list:
        names, lay = glob["coordinates"], glob["layout"]
        rows = [(f"final {names[j]}", glob["xN"][lay["q"][j]], x, x) for j, x in self._q.items()]
        rows += [(f"final {names[j]} speed", glob["xN"][lay["v"][j]], x, x) for j, x in self._v.items()]
        return rows


def _state_rows(glob, states, exclude):
    """Indices into the state vector of the named state groups, less excluded coordinates."""
    lay, names = glob["layout"], glob["coordinates"]
    out = []
    for group in states:
        if group not in lay:
            raise ModelError(f"unknown state group '{group}'; valid: {', '.join(lay)}")
        for k, row in enumerate(lay[group]):
            label = names[k] if group in ("q", "v") else glob["muscles"][k]
            if group in ("q", "v") and names[k] in exclude:
                continue
            out.append((group, label, row))
    return out


class Periodic(Constraint):
    """``x(T) = x(0)`` for the state groups ``states`` (``"q"``, ``"v"``, ``"a"``, ``"f_t"``),
    except the coordinates in ``exclude`` (e.g. the forward translation) (thesis Eq. 5.9)."""

    def __init__(self, states=("q", "v", "a", "f_t"), *, exclude=()):
        self.states, self.exclude = tuple(states), tuple(exclude)

    def check(self, problem) -> None:
        for c in self.exclude:
            problem.model.coordinate_index(c)

    def boundary(self, glob) -> list:
        x0, xN = glob["x0"], glob["xN"]
        states = [s for s in self.states if s in glob["layout"]]
        return [(f"periodicity of {g} {label}", xN[r] - x0[r], 0.0, 0.0)
                for g, label, r in _state_rows(glob, states, self.exclude)]


class Symmetric(Constraint):
    """A half cycle: ``x(T)`` is ``x(0)`` with left and right swapped (thesis Eq. 5.8).

    ``pairs``: {right: left} coordinate names (muscles are paired by their ``_r``/``_l``
    suffixes); ``negate``: coordinates whose sign flips in the mirror (out-of-plane ones);
    ``exclude``: coordinates left free (the forward translation, which advances); ``controls``:
    actuators (CoordinateActuators, by name) whose control at ``T`` is that of its ``_r``/``_l``
    mirror at 0, or its own when it has no side (Moco's ``addControlPair``, e.g. a lumbar actuator).
    """

    def __init__(self, pairs: dict, *, negate=(), exclude=(), controls=()):
        self.pairs, self.negate, self.exclude = dict(pairs), tuple(negate), tuple(exclude)
        self.controls = tuple(controls)

    def check(self, problem) -> None:
        m = problem.model
        idx = {}
        for r, l in self.pairs.items():
            idx[m.coordinate_index(r)] = m.coordinate_index(l)
            idx[m.coordinate_index(l)] = m.coordinate_index(r)
        self._mirror_q = idx
        names = list(m.muscle_names) if m.muscles is not None else []
        mus = {}
        for i, n in enumerate(names):
            for a, b in (("_r", "_l"), ("_l", "_r")):
                if n.endswith(a):
                    other = n[: -len(a)] + b
                    if other not in names:
                        raise ModelError(f"Symmetric: muscle '{n}' has no mirror '{other}'")
                    mus[i] = names.index(other)
        self._mirror_m = mus
        for c in self.negate + self.exclude:
            m.coordinate_index(c)
        acts = [a.name for a in problem._pm.actuators] if self.controls else []
        ctl = {}
        for n in self.controls:
            if n not in acts:
                raise ModelError(f"Symmetric: controls: '{n}' is not an actuator of model '{m.name}' "
                                 f"(actuators: {', '.join(acts) or 'none'})")
            other = _mirror_name(n)
            ctl[acts.index(n)] = acts.index(other) if other in acts else acts.index(n)
        self._mirror_act = ctl

    def boundary(self, glob) -> list:
        x0, xN, lay, names = glob["x0"], glob["xN"], glob["layout"], glob["coordinates"]
        rows = []
        for g in ("q", "v"):
            for j, name in enumerate(names):
                if name in self.exclude:
                    continue
                k = self._mirror_q.get(j, j)
                s = -1.0 if name in self.negate else 1.0
                rows.append((f"symmetry of {g} {name}", xN[lay[g][j]] - s * x0[lay[g][k]], 0.0, 0.0))
        for g in ("a", "f_t"):
            if g not in lay:
                continue
            for i, name in enumerate(glob["muscles"]):
                k = self._mirror_m.get(i, i)
                rows.append((f"symmetry of {g} {name}", xN[lay[g][i]] - x0[lay[g][k]], 0.0, 0.0))
        for i, k in self._mirror_act.items():
            rows.append((f"symmetry of the control of {glob['actuators'][i]}", glob["actN"][i] - glob["act0"][k],
                         0.0, 0.0))
        return rows


def _mirror_name(name: str) -> str:
    """``name`` with its side (``_r``/``_l`` suffix or infix, ``r_``/``l_`` prefix) swapped, else itself."""
    for a, b in (("_r", "_l"), ("_l", "_r")):
        if name.endswith(a):
            return name[: -len(a)] + b
        if f"{a}_" in name:
            return name.replace(f"{a}_", f"{b}_", 1)
        if name.startswith(f"{a[1]}_"):
            return f"{b[1]}_" + name[2:]
    return name


class AverageSpeed(Constraint):
    """``(q_c(T) - q_c(0)) / T = speed`` (m/s): a prescribed average walking speed."""

    def __init__(self, speed: float, *, coordinate: str | None = None):
        self.speed, self.coordinate = float(speed), coordinate

    def check(self, problem) -> None:
        self._name = self.coordinate or problem.forward_coordinate()
        self._j = problem.model.coordinate_index(self._name)

    def boundary(self, glob) -> list:
        lay = glob["layout"]
        d = glob["xN"][lay["q"][self._j]] - glob["x0"][lay["q"][self._j]]
        return [(f"average speed along {self._name} (m/s)", d / glob["T"], self.speed, self.speed)]


class Bounds(Constraint):
    """Box bounds ``{coordinate: (lower, upper)}`` on the coordinates ``q`` (rad or m), speeds ``v``
    and accelerations ``qdd`` at every collocation point (bounds on the variables, not path rows).

    ``q`` bounds narrow the model's joint limits (never widen them); a finite ``v`` or ``qdd``
    bound also sets the variable's scale to half its range (Moco's scaling by the bounds).
    ``default_v`` / ``default_qdd``: ``(lower, upper)`` for every coordinate not named;
    ``df_t``: ``(lower, upper)`` of the normalized tendon-force rates (1/s) of compliant tendons
    (De Groote et al. 2016 bound them; also their scale).
    """

    def __init__(self, *, q=None, v=None, qdd=None, default_v=None, default_qdd=None, df_t=None):
        self.q, self.v, self.qdd = dict(q or {}), dict(v or {}), dict(qdd or {})
        self.df_t = None if df_t is None else tuple(map(float, df_t))
        if self.df_t is not None and not self.df_t[0] < self.df_t[1]:
            raise ModelError(f"Bounds df_t: lower {self.df_t[0]} must be below upper {self.df_t[1]}")
        self.default_v = None if default_v is None else tuple(map(float, default_v))
        self.default_qdd = None if default_qdd is None else tuple(map(float, default_qdd))
        for what, d in (("q", self.q), ("v", self.v), ("qdd", self.qdd)):
            for c, b in d.items():
                lo, hi = map(float, b)
                if not lo < hi:
                    raise ModelError(f"Bounds {what} of {c}: lower {lo} must be below upper {hi}")
        for what, b in (("default_v", self.default_v), ("default_qdd", self.default_qdd)):
            if b is not None and not b[0] < b[1]:
                raise ModelError(f"Bounds {what}: lower {b[0]} must be below upper {b[1]}")

    def check(self, problem) -> None:
        for d in (self.q, self.v, self.qdd):
            for c in d:
                problem.model.coordinate_index(c)

    def arrays(self, model, what: str):
        """``(lower, upper)`` arrays (nv,) of ``what`` (``"q"``, ``"v"``, ``"qdd"``), +-inf where unbounded."""
        nv = model.nv
        d = {"q": self.q, "v": self.v, "qdd": self.qdd}[what]
        dflt = {"q": None, "v": self.default_v, "qdd": self.default_qdd}[what]
        lo, hi = np.full(nv, -np.inf), np.full(nv, np.inf)
        if dflt is not None:
            lo[:], hi[:] = dflt
        for c, (a, b) in d.items():
            j = model.coordinate_index(c)
            lo[j], hi[j] = float(a), float(b)
        return lo, hi
