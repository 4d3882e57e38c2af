"""The muscles of a model as one component.

A :class:`MuscleSet` joins a muscle-tendon model (``Thelen2003``,
``NaganoGerritsen``, or for imported OpenSim models ``Millard2012``,
``DeGroote2016``, ``Thelen2003OpenSim``; vectorised over muscles) with the muscles' paths
(lengths and moment arms as functions of the coordinates).  Muscle forces
``F`` (N, m) map to generalized forces by ``tau = R(q)^T F`` with ``R`` the
(N, m, nv) moment arms (thesis Eq. 3.14 in one dof).

The per-muscle parameters (``f_max``, ``l_opt``, ...) are stored once, in the
muscle-tendon model ``mtu``, which validates them
(:data:`pinmsk.muscles.models.MUSCLE_PARAMETERS`); the set reads them from there.
In a model's parameter table they are ``muscle:<name>.<parameter>``, fixed
(``vary=False``) unless freed.
"""
from __future__ import annotations

import copy
import difflib
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from ..components import Component, Motion, Parameter, Parameters, _replace
from ..errors import ModelError
from .models import MUSCLE_PARAMETERS

#: Prefix of muscle parameters in ``pinmsk.Model.parameters`` (``muscle:BIClong.f_max``).
MUSCLE_PREFIX = "muscle"
#: Specific tension (Pa) giving the default muscle volume ``F_max l_opt / sigma`` (thesis Eq. B.3).
SPECIFIC_TENSION = 0.25e6


_PROXIES = ("display_points", "_vary", "_bounds")


class MuscleSet(Component):
    """All muscles of a model: parameters, paths, force capacity and joint moments."""

    family = "muscles"
    kind = "muscle"
    target_kind = "model"

    def __init__(self, *, names, model_type: str, mtu, path, tendon: str = "rigid",
                 volume=None, fast_fraction=None, display_points=None):
        names = tuple(str(n) for n in names)
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ModelError(f"duplicate muscle names {dup}")
        if tendon not in ("rigid", "compliant"):
            raise ModelError(f"muscle tendon must be 'rigid' or 'compliant', not {tendon!r}")
        changes = {}
        if mtu.names != names:
            if mtu.names is not None:
                raise ModelError(f"the muscle model names {list(mtu.names)}, the set {list(names)}")
            changes["names"] = names
        if volume is not None:
            changes["volume"] = volume
        if fast_fraction is not None:
            changes["fast_fraction"] = fast_fraction
        if changes:
            mtu = mtu.replace(**changes)        # validates the values (MUSCLE_PARAMETERS)
        if mtu.n != len(names):
            raise ModelError(f"{len(names)} muscle names for a muscle model of {mtu.n} muscles")
        self.target = None
        self.names = names
        self.model_type = model_type
        self.mtu = mtu
        self.path = path
        self.tendon = tendon
        self.display_points = MappingProxyType({k: tuple(tuple(p) for p in v)
                                                for k, v in (display_points or {}).items()})
        self._vary = MappingProxyType({})          # {"<muscle>.<parameter>": bool}; default fixed
        self._bounds = MappingProxyType({})        # {"<muscle>.<parameter>": (lo, hi)} narrower than the rule

    # -- parameters (stored once, in mtu) ------------------------------------
    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def f_max(self) -> np.ndarray:
        return self.mtu.f_max

    @property
    def l_opt(self) -> np.ndarray:
        return self.mtu.l_opt

    @property
    def l_slack(self) -> np.ndarray:
        return self.mtu.l_slack

    @property
    def pennation(self) -> np.ndarray:
        return self.mtu.pennation

    @property
    def volume(self) -> np.ndarray:
        """Muscle volumes (m^3): the model's, else ``F_max l_opt / sigma`` (thesis Eq. B.3)."""
        if self.mtu.volume is not None:
            return self.mtu.volume
        v = self.f_max * self.l_opt / SPECIFIC_TENSION
        v.flags.writeable = False
        return v

    @property
    def fast_fraction(self) -> np.ndarray:
        """Fraction of fast-twitch fibers per muscle (0.5 where the model gives none)."""
        if self.mtu.fast_fraction is not None:
            return self.mtu.fast_fraction
        ff = np.full(self.n, 0.5)
        ff.flags.writeable = False
        return ff

    @property
    def pcsa(self) -> np.ndarray:
        """Physiological cross-sectional area, volume / optimal fiber length (m^2)."""
        return self.volume / self.l_opt

    @property
    def _params(self) -> dict[str, Parameter]:
        out = {}
        whats = self.mtu.mechanical_parameters
        columns = [getattr(self.mtu, what) for what in whats]
        for i, name in enumerate(self.names):
            for what, col in zip(whats, columns):
                rule = MUSCLE_PARAMETERS[what]
                key = f"{name}.{what}"
                lo, hi = self._bounds.get(key, (rule.low, rule.high))
                out[key] = Parameter(key, float(col[i]), lo, hi, rule.unit, rule.doc,
                                     vary=self._vary.get(key, False))
        return out

    def parameter_table(self, prefix: str | None = None) -> Parameters:
        """The muscle parameters as ``muscle:<name>.<parameter>`` (``prefix`` replaces ``muscle``)."""
        pre = MUSCLE_PREFIX if prefix is None else prefix
        return Parameters(_replace(p, name=f"{pre}:{k}") for k, p in self._params.items())

    def with_params(self, values: Mapping[str, float] | None = None, *, stderr=None,
                    vary: Mapping[str, bool] | None = None,
                    bounds: Mapping[str, tuple[float, float]] | None = None, **kw: float) -> "MuscleSet":
        """A copy with per-muscle parameters ``"<muscle>.<parameter>"`` changed (values go to a
        new muscle model, which validates them); ``vary`` and ``bounds`` as for any component."""
        values = {**(values or {}), **kw}
        declared = self._params
        for what, changes in (("values", values), ("vary", vary), ("bounds", bounds)):
            for key in changes or ():
                if key not in declared:
                    close = difflib.get_close_matches(key, list(declared), n=3)
                    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
                    where = "" if what == "values" else f" (in {what}=)"
                    raise ModelError(f"muscles: no parameter '{key}'{where}{hint} "
                                     "(names are '<muscle>.<parameter>')")
        if stderr:
            raise ModelError("muscles: standard errors of muscle parameters are not stored")
        new_bounds = dict(self._bounds)
        for key, (lo, hi) in (bounds or {}).items():
            lo, hi = float(lo), float(hi)
            if not lo <= hi:
                raise ModelError(f"muscles: bounds for '{key}' are [{lo:g}, {hi:g}]; lower > upper")
            new_bounds[key] = (lo, hi)
        columns: dict[str, np.ndarray] = {}
        for key, val in values.items():
            muscle, what = key.rsplit(".", 1)
            col = columns.setdefault(what, np.array(getattr(self.mtu, what), dtype=float))
            col[self.names.index(muscle)] = float(val)
        for key in {*values, *(bounds or {})} & set(new_bounds):
            # narrowed bounds; the muscle model checks each value against its declaration
            p = declared[key]
            lo, hi = new_bounds[key]
            _replace(p, value=float(values.get(key, p.value)), min=lo, max=hi).check("muscles")
        new = copy.copy(self)
        d = new.__dict__
        if columns:
            d["mtu"] = self.mtu.replace(**columns)
        d["_bounds"] = MappingProxyType(new_bounds)
        d["_vary"] = MappingProxyType({**self._vary, **{k: bool(v) for k, v in (vary or {}).items()}})
        return new

    def __getstate__(self):
        # mappingproxies do not pickle
        state = dict(self.__dict__)
        for k in _PROXIES:
            state[k] = dict(state[k])
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        for k in _PROXIES:
            self.__dict__[k] = MappingProxyType(state[k])

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            close = difflib.get_close_matches(name, self.names, n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise ModelError(f"no muscle '{name}'{hint} (muscles: {', '.join(self.names)})") from None

    # -- paths --------------------------------------------------------------
    def lengths(self, q) -> np.ndarray:
        return self.path.lengths(q)

    def velocities(self, q, v) -> np.ndarray:
        return self.path.velocities(q, v)

    def moment_arms(self, q) -> np.ndarray:
        return self.path.moment_arms(q)

    def path_kinematics(self, q, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(lengths (N, m), lengthening velocities (N, m), moment arms (N, m, nv))`` of the frames: the
        path's ``lengths_and_moment_arms`` evaluated once where it has one (a polynomial path's monomials
        are the cost), ``dl/dt = -R v`` (the paths' convention)."""
        both = getattr(self.path, "lengths_and_moment_arms", None)
        if both is None:
            return self.lengths(q), self.velocities(q, v), self.moment_arms(q)
        lengths, R = both(q)
        return lengths, -np.einsum("nmj,nj->nm", R, np.asarray(v, dtype=float)), R

    def force_limits_from(self, lengths, velocities) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`force_limits` from the paths' lengths and velocities (:meth:`path_kinematics`)."""
        return self.mtu.force_limits(lengths, velocities)

    def lengths_at(self, q):
        """The path's lengths at one pose, numpy (nv,) -> (m,) or CasADi (nv, 1) -> (m, 1)
        (``path.lengths_at``; paths without a closed form refuse by name)."""
        return self._path_at("lengths_at")(q)

    def moment_arms_at(self, q):
        """The path's moment arms ``r = -dl/dq`` at one pose, (m, nv), numpy or CasADi (``path.moment_arms_at``)."""
        return self._path_at("moment_arms_at")(q)

    def _path_at(self, name):
        fn = getattr(self.path, name, None)
        if fn is None:
            raise ModelError(f"muscle paths {type(self.path).__name__} have no closed form the optimal-control "
                             "engine can use; fit a PolynomialPath to them (pinmsk.opensim.paths.fit_polynomial_paths)")
        return fn

    # -- forces -------------------------------------------------------------
    def force_limits(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """Rigid-tendon force capacity ``(F_active, F_passive)``, each (N, m).

        Muscle force is ``F = a * F_active + F_passive`` with ``0 <= a <= 1``:
        ``F_active = F_max f_L f_V cos(alpha)`` at the current fiber length and
        velocity, ``F_passive`` the parallel element along the tendon (zero for
        models without one).
        """
        return self.mtu.force_limits(self.lengths(q), self.velocities(q, v))

    def joint_moments(self, q, forces) -> np.ndarray:
        """``tau = R(q)^T F`` over frames: (N, nv) from forces (N, m)."""
        R = self.moment_arms(q)
        F = np.asarray(forces, dtype=float)
        if F.ndim == 1:
            F = F[None, :]
        return np.einsum("nm,nmj->nj", F, R)

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        """Joint moments of the forces in the motion's ``<muscle>_force`` signals."""
        F = np.column_stack([motion.signal(f"{n}_force") for n in self.names])
        return self.joint_moments(motion.q, F)

    def __eq__(self, other) -> bool:
        """Same muscles, muscle model (all its parameters), paths, tendon and parameter flags."""
        return (type(other) is type(self) and self.names == other.names and self.mtu == other.mtu
                and self.path == other.path and self.tendon == other.tendon and self._params == other._params)

    def __hash__(self) -> int:
        return hash((type(self).__name__, self.names, self.tendon))

    def __repr__(self) -> str:
        return f"MuscleSet({self.model_type}, {self.n} muscles: {', '.join(self.names)})"
