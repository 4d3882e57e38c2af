"""Muscle-tendon paths: lengths, moment arms and their time derivatives.

A path gives each muscle ``i`` a length ``l0_i`` at ``q = 0`` and, for every
coordinate ``j`` it crosses, a moment-arm polynomial in that coordinate alone,
``r_ij(q_j) = sum_k c_ijk q_j**k``.  With the sign convention
``r = -dl/dq`` (positive: the muscle shortens when ``q_j`` grows):

    l_i(q)       = l0_i - sum_j integral_0^{q_j} r_ij(s) ds
    dl_i/dt      = -sum_j r_ij(q_j) v_j
    d2l_i/dt2    = -sum_j [ r_ij(q_j) a_j + r_ij'(q_j) v_j**2 ]

The thesis's constant moment arms (Table 3.5, forearm) and its Eq. 5.12 (gait,
``l = l0 - r_H phi_H + r_K phi_K - r_A (phi_A - pi/2)``) are the degree-0 case.
Sidecars store paths per muscle as ``paths.<variant> = { l0 = ...,
moment_arms = { <coordinate> = [c0, c1, ...] } }`` (see ``urdf/README.md``).

Arrays are time-first: ``q`` is ``(N, nv)`` or one frame ``(nv,)``; results
are ``(N, m)`` / ``(N, m, nv)``, or ``(m,)`` / ``(m, nv)`` for one frame.

One pose on any backend (:mod:`pinmsk.backend`): ``lengths_at(q) -> (m,)`` and
``moment_arms_at(q) -> (m, nv)`` take a numpy ``(nv,)`` (then they are
``lengths`` / ``moment_arms`` of that frame, the same numbers) or a CasADi
``(nv, 1)`` ``SX``/``MX`` (then CasADi ``(m, 1)`` and ``(m, nv)`` expressions of
the same polynomials, for the optimal-control engine's exact derivatives).
Sign convention, both path classes: the moment arm is ``r = -dl/dq``, *not*
``dl/dq``, so a muscle force ``F >= 0`` (pulling, shortening) gives the
generalized force ``tau = r^T F`` (``tau_j = sum_i r_ij F_i``: the power
``F (-dl/dt) = F r v``), and ``dl/dt = -r v``.
Polynomials are evaluated by Horner's rule over all frames, muscles and
coordinates at once (the only Python loop is over the polynomial degree).
"""

from __future__ import annotations

import difflib
import functools
from dataclasses import dataclass

import numpy as np

from pinmsk.backend import is_symbolic
from pinmsk.errors import ModelError, PinmskError

__all__ = ["MomentArmPath", "PolynomialPath", "PolynomialPathOnUse", "DisplayPoints", "display_points_from_sidecar", "path_variants"]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.flags.writeable = False
    return a


def _horner(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """sum_k coeffs[i, j, k] x[n, j]**k for all n, i, j -> (N, m, nv)."""
    out = np.empty((x.shape[0],) + coeffs.shape[:2])
    out[...] = coeffs[None, :, :, -1]
    for k in range(coeffs.shape[2] - 2, -1, -1):
        out *= x[:, None, :]
        out += coeffs[None, :, :, k]
    return out


def _horner_at(coeffs: np.ndarray, X):
    """sum_k coeffs[i, j, k] X[i, j]**k for one pose, X a CasADi (m, nv) -> (m, nv) (the Horner
    recursion of :func:`_horner`, elementwise)."""
    import casadi as ca

    out = ca.DM(coeffs[:, :, -1]) + 0.0 * X
    for k in range(coeffs.shape[2] - 2, -1, -1):
        out = out * X + ca.DM(coeffs[:, :, k])
    return out


def _symbolic_pose(q, nv: int):
    """A CasADi pose as a column (nv, 1) (accepts (nv, 1) or (1, nv))."""
    import casadi as ca

    if q.numel() != nv or min(q.shape) != 1:
        raise PinmskError(f"q must have shape ({nv}, 1) for one pose, got {q.shape}")
    return ca.reshape(q, nv, 1)


def _numeric_pose(q, nv: int, coordinates) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (nv,):
        raise PinmskError(f"q must have shape ({nv},) for one pose over coordinates ({', '.join(coordinates)}), "
                          f"got {q.shape}")
    return q


def _rebuild(cls, muscles, coordinates, l0, coeffs):  # pickle support
    return cls(muscles=muscles, coordinates=coordinates, l0=l0, coeffs=coeffs)


class MomentArmPath:
    """Polynomial moment-arm paths of ``m`` muscles over a model's ``nv`` coordinates.

    Parameters (keyword-only)
    -------------------------
    muscles : tuple of str, length m
    coordinates : tuple of str, length nv -- the model's velocity coordinates, in order
    l0 : (m,) muscle-tendon lengths at q = 0 (m)
    coeffs : (m, nv, K) moment-arm polynomial coefficients, ``coeffs[i, j, k]``
        multiplies ``q_j**k`` in ``r_ij`` (m/rad^k; m/m^k for a prismatic coordinate)

    Instances are immutable; build them from a sidecar with :meth:`from_sidecar`.
    """

    __slots__ = ("_muscles", "_coordinates", "_l0", "_coeffs", "_int_coeffs", "_der_coeffs")

    def __init__(self, *, muscles, coordinates, l0, coeffs):
        muscles = tuple(str(m) for m in muscles)
        coordinates = tuple(str(c) for c in coordinates)
        for what, names in (("muscle", muscles), ("coordinate", coordinates)):
            dupes = sorted({n for n in names if names.count(n) > 1})
            if dupes:
                raise ModelError(f"MomentArmPath: {what} names must be unique; repeated: {', '.join(dupes)}")
        m, nv = len(muscles), len(coordinates)
        l0 = np.asarray(l0, dtype=float)
        coeffs = np.asarray(coeffs, dtype=float)
        if l0.shape != (m,):
            raise ModelError(f"MomentArmPath: l0 must have shape ({m},) for {m} muscles, got {l0.shape}")
        if coeffs.ndim != 3 or coeffs.shape[:2] != (m, nv) or coeffs.shape[2] < 1:
            raise ModelError(
                f"MomentArmPath: coeffs must have shape ({m}, {nv}, K>=1) (muscles, coordinates, degree + 1), "
                f"got {coeffs.shape}"
            )
        if not (np.all(np.isfinite(l0)) and np.all(np.isfinite(coeffs))):
            raise ModelError("MomentArmPath: l0 and coeffs must be finite")
        K = coeffs.shape[2]
        k = np.arange(1, K + 1, dtype=float)
        # antiderivative of r (zero constant term) and derivative of r
        int_coeffs = np.concatenate([np.zeros((m, nv, 1)), coeffs / k], axis=2)
        der_coeffs = coeffs[:, :, 1:] * k[: K - 1] if K > 1 else np.zeros((m, nv, 1))
        set_ = object.__setattr__
        set_(self, "_muscles", muscles)
        set_(self, "_coordinates", coordinates)
        set_(self, "_l0", _readonly(l0))
        set_(self, "_coeffs", _readonly(coeffs))
        set_(self, "_int_coeffs", _readonly(int_coeffs))
        set_(self, "_der_coeffs", _readonly(der_coeffs))

    def __setattr__(self, name, value):
        raise AttributeError(f"MomentArmPath is immutable; build a new one instead of setting {name!r}")

    def __delattr__(self, name):
        raise AttributeError("MomentArmPath is immutable")

    def __reduce__(self):
        return (_rebuild, (type(self), self._muscles, self._coordinates, np.array(self._l0), np.array(self._coeffs)))

    def __eq__(self, other) -> bool:
        """Same muscles, coordinates, lengths at q = 0 and moment-arm coefficients."""
        if type(other) is not type(self):
            return NotImplemented
        return (self._muscles == other._muscles and self._coordinates == other._coordinates
                and np.array_equal(self._l0, other._l0) and np.array_equal(self._coeffs, other._coeffs))

    def __hash__(self) -> int:
        return hash((self._muscles, self._coordinates, self._l0.tobytes(), self._coeffs.tobytes()))

    def __repr__(self) -> str:
        return (
            f"MomentArmPath({len(self._muscles)} muscles x {len(self._coordinates)} coordinates, "
            f"degree {self.degree})"
        )

    # --- read-only views ------------------------------------------------------
    @property
    def muscles(self) -> tuple[str, ...]:
        return self._muscles

    @property
    def coordinates(self) -> tuple[str, ...]:
        return self._coordinates

    @property
    def l0(self) -> np.ndarray:
        return self._l0

    @property
    def coeffs(self) -> np.ndarray:
        return self._coeffs

    @property
    def n_muscles(self) -> int:
        return len(self._muscles)

    @property
    def nv(self) -> int:
        return len(self._coordinates)

    @property
    def degree(self) -> int:
        """Polynomial degree of the moment arms (0 = constant)."""
        return self._coeffs.shape[2] - 1

    # --- construction from a sidecar -------------------------------------------
    @classmethod
    def from_sidecar(cls, muscle_entries, coordinates, variant: str, *, source=None) -> "MomentArmPath":
        """Paths of variant ``variant`` from a sidecar's ``[[muscles]]`` entries.

        ``muscle_entries`` is the parsed list of muscle tables, ``coordinates``
        the model's velocity coordinates in order, ``source`` (optional) the
        file named in error messages.  Coordinates a muscle does not list get a
        zero moment arm.
        """
        where = f" in {source}" if source else ""
        coordinates = tuple(str(c) for c in coordinates)
        index = {c: j for j, c in enumerate(coordinates)}
        entries = list(muscle_entries)
        if not entries:
            raise ModelError(f"no [[muscles]]{where}: a MomentArmPath needs at least one muscle")
        names, l0s, arms = [], [], []
        for n, entry in enumerate(entries, start=1):
            name = entry.get("name") if isinstance(entry, dict) else None
            if not isinstance(name, str) or not name:
                raise ModelError(f"muscle #{n}{where} has no name = \"...\"")
            paths = entry.get("paths") or {}
            if not isinstance(paths, dict) or variant not in paths:
                have = sorted(paths) if isinstance(paths, dict) else []
                close = difflib.get_close_matches(str(variant), have, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else "."
                raise ModelError(
                    f"muscle {name!r}{where} has no path variant {variant!r}{hint} "
                    f"Its variants: {', '.join(have) if have else 'none'}. Add "
                    f"paths.{variant} = {{ l0 = ..., moment_arms = {{ <coordinate> = [c0, ...] }} }} "
                    "or choose an existing variant"
                )
            path = paths[variant]
            if not isinstance(path, dict) or "l0" not in path:
                raise ModelError(f"muscle {name!r}{where}: paths.{variant} needs l0 = <length at q = 0 in m>")
            try:
                l0 = float(path["l0"])
            except (TypeError, ValueError):
                raise ModelError(f"muscle {name!r}{where}: paths.{variant}.l0 must be a number, got {path['l0']!r}") from None
            moment_arms = path.get("moment_arms", {})
            if not isinstance(moment_arms, dict):
                raise ModelError(
                    f"muscle {name!r}{where}: paths.{variant}.moment_arms must be a table "
                    "{ <coordinate> = [c0, c1, ...] }"
                )
            row = {}
            for coord, cs in moment_arms.items():
                if coord not in index:
                    close = difflib.get_close_matches(coord, coordinates, n=1)
                    hint = f"; did you mean {close[0]!r}?" if close else "."
                    raise ModelError(
                        f"muscle {name!r}{where}: path {variant!r} has a moment arm for coordinate {coord!r}, "
                        f"which the model does not have{hint} The model's coordinates are: {', '.join(coordinates)}"
                    )
                try:
                    c = np.atleast_1d(np.asarray(cs, dtype=float))
                except (TypeError, ValueError):
                    c = np.zeros(0)
                if c.ndim != 1 or c.size == 0 or not np.all(np.isfinite(c)):
                    raise ModelError(
                        f"muscle {name!r}{where}: paths.{variant}.moment_arms.{coord} must be a non-empty list of "
                        f"finite numbers [c0, c1, ...], got {cs!r}"
                    )
                row[index[coord]] = c
            names.append(name)
            l0s.append(l0)
            arms.append(row)
        K = max([len(c) for row in arms for c in row.values()] + [1])
        coeffs = np.zeros((len(names), len(coordinates), K))
        for i, row in enumerate(arms):
            for j, c in row.items():
                coeffs[i, j, : len(c)] = c
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ModelError(f"muscle names must be unique{where}; repeated: {', '.join(dupes)}")
        return cls(muscles=tuple(names), coordinates=coordinates, l0=np.array(l0s), coeffs=coeffs)

    # --- evaluation ---------------------------------------------------------------
    def _frames(self, **arrays):
        """Check shapes; return 2-D arrays and whether the inputs were single frames."""
        out, ndims = [], set()
        n = None
        for label, a in arrays.items():
            a = np.asarray(a, dtype=float)
            if a.ndim not in (1, 2) or a.shape[-1] != self.nv:
                raise PinmskError(
                    f"{label} must have shape ({self.nv},) or (N, {self.nv}) for coordinates "
                    f"({', '.join(self._coordinates)}), got {a.shape}"
                )
            ndims.add(a.ndim)
            a2 = a.reshape(-1, self.nv)
            if n is not None and a2.shape[0] != n:
                raise PinmskError(f"{', '.join(arrays)} must have the same number of frames; got {n} and {a2.shape[0]}")
            n = a2.shape[0]
            out.append(a2)
        if len(ndims) > 1:
            raise PinmskError(f"{', '.join(arrays)} must all be single frames (nv,) or all (N, nv)")
        return out, ndims == {1}

    def lengths(self, q) -> np.ndarray:
        """Muscle-tendon lengths l(q): (N, m), or (m,) for one frame."""
        (q,), single = self._frames(q=q)
        out = self._l0 - _horner(self._int_coeffs, q).sum(axis=2)
        return out[0] if single else out

    def moment_arms(self, q) -> np.ndarray:
        """Moment arms r = -dl/dq: (N, m, nv), or (m, nv) for one frame."""
        (q,), single = self._frames(q=q)
        out = _horner(self._coeffs, q)
        return out[0] if single else out

    def moment_arm_derivative(self, q, order: int = 1) -> np.ndarray:
        """``d^order r_ij / dq_j^order`` (each arm depends on its own coordinate only):
        (N, m, nv), or (m, nv) for one frame."""
        (q,), single = self._frames(q=q)
        c = np.asarray(self._coeffs)
        for _ in range(int(order)):
            K = c.shape[2]
            c = c[:, :, 1:] * np.arange(1, K) if K > 1 else np.zeros(c.shape[:2] + (1,))
        out = _horner(c, q)
        return out[0] if single else out

    def lengths_at(self, q):
        """l(q) at one pose, any backend: numpy (nv,) -> (m,) (= :meth:`lengths`), CasADi (nv, 1) -> (m, 1)."""
        if not is_symbolic(q):
            return self.lengths(_numeric_pose(q, self.nv, self._coordinates))
        import casadi as ca

        X = ca.repmat(_symbolic_pose(q, self.nv).T, self.n_muscles, 1)
        return ca.DM(self._l0) - ca.sum2(_horner_at(self._int_coeffs, X))

    def moment_arms_at(self, q):
        """r = -dl/dq at one pose, any backend: numpy (nv,) -> (m, nv) (= :meth:`moment_arms`), CasADi
        (nv, 1) -> (m, nv)."""
        if not is_symbolic(q):
            return self.moment_arms(_numeric_pose(q, self.nv, self._coordinates))
        import casadi as ca

        X = ca.repmat(_symbolic_pose(q, self.nv).T, self.n_muscles, 1)
        return _horner_at(self._coeffs, X)

    def velocities(self, q, v) -> np.ndarray:
        """Lengthening velocities dl/dt = -sum_j r_j v_j: (N, m), or (m,)."""
        (q, v), single = self._frames(q=q, v=v)
        out = -np.einsum("nmj,nj->nm", _horner(self._coeffs, q), v)
        return out[0] if single else out

    def accelerations(self, q, v, a) -> np.ndarray:
        """d2l/dt2 = -sum_j (r_j a_j + r_j'(q_j) v_j^2): (N, m), or (m,)."""
        (q, v, a), single = self._frames(q=q, v=v, a=a)
        out = -np.einsum("nmj,nj->nm", _horner(self._coeffs, q), a) - np.einsum(
            "nmj,nj->nm", _horner(self._der_coeffs, q), v * v
        )
        return out[0] if single else out


def path_variants(muscle_entries) -> tuple[str, ...]:
    """Path variants every muscle of ``muscle_entries`` defines, sorted."""
    sets = [set((e.get("paths") or {}).keys()) for e in muscle_entries]
    return tuple(sorted(set.intersection(*sets))) if sets else ()


@dataclass(frozen=True, eq=False)
class DisplayPoints:
    """Display-only polyline of one muscle: points fixed in bodies.

    ``bodies[p]`` is the body (URDF link) of point ``p``; ``positions[p]`` its
    coordinates in that body's frame (m).  These points only draw the muscle;
    lengths and moment arms come from :class:`MomentArmPath`.
    """

    muscle: str
    bodies: tuple
    positions: np.ndarray

    def __init__(self, *, muscle: str, bodies, positions):
        bodies = tuple(str(b) for b in bodies)
        positions = np.asarray(positions, dtype=float)
        if positions.shape != (len(bodies), 3) or len(bodies) < 2:
            raise ModelError(
                f"muscle {muscle!r}: display points need at least 2 points, each [body, x, y, z]; "
                f"got {len(bodies)} bodies and positions of shape {positions.shape}"
            )
        object.__setattr__(self, "muscle", str(muscle))
        object.__setattr__(self, "bodies", bodies)
        object.__setattr__(self, "positions", _readonly(positions))


def display_points_from_sidecar(muscle_entries, *, bodies=None, source=None) -> tuple[DisplayPoints, ...]:
    """The ``points`` of every muscle that has them, in sidecar order.

    ``bodies`` (optional): the model's body/link names, to check each point's body.
    """
    where = f" in {source}" if source else ""
    known = None if bodies is None else tuple(bodies)
    out = []
    for entry in muscle_entries:
        pts = entry.get("points")
        if pts is None:
            continue
        name = entry.get("name", "?")
        rows = []
        for p in pts:
            if not (isinstance(p, (list, tuple)) and len(p) == 4 and isinstance(p[0], str)):
                raise ModelError(f"muscle {name!r}{where}: each display point must be [\"body\", x, y, z], got {p!r}")
            if known is not None and p[0] not in known:
                close = difflib.get_close_matches(p[0], known, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else "."
                raise ModelError(f"muscle {name!r}{where}: display point on unknown body {p[0]!r}{hint}")
            rows.append(p)
        out.append(DisplayPoints(muscle=name, bodies=[r[0] for r in rows], positions=[r[1:] for r in rows]))
    return tuple(out)


#: Frames a polynomial path evaluates at a time: its monomials' work arrays (frames x terms x variables)
#: stay this size, in memory and in the CPU cache, however long the motion.
BLOCK_FRAMES = 2048


def _in_blocks(n_arrays: int):
    """Run a PolynomialPath method over blocks of :data:`BLOCK_FRAMES` frames of its first ``n_arrays``
    arguments (each (N, nv)) and join the results along the frames (the same numbers: frames are
    independent)."""
    def wrap(method):
        @functools.wraps(method)
        def run(self, *args, **kwargs):
            first = np.asarray(args[0]) if args else None
            if first is None or first.ndim != 2 or first.shape[0] <= BLOCK_FRAMES or len(args) < n_arrays:
                return method(self, *args, **kwargs)
            arrays, rest = [np.asarray(a) for a in args[:n_arrays]], args[n_arrays:]
            parts = [method(self, *(a[s:s + BLOCK_FRAMES] for a in arrays), *rest, **kwargs)
                     for s in range(0, first.shape[0], BLOCK_FRAMES)]
            if isinstance(parts[0], tuple):
                return tuple(np.concatenate(p) for p in zip(*parts))
            return np.concatenate(parts)
        return run
    return wrap


def _products_of_others(p):
    """For each v, the product over the last axis of ``p`` (N, T, V) without entry v: (N, T) each, from
    prefix and suffix products (no division, so exact zeros stay zeros)."""
    V = p.shape[2]
    if V == 1:
        return [np.ones(p.shape[:2])]
    before = [np.ones(p.shape[:2])]
    for v in range(1, V):
        before.append(before[-1] * p[:, :, v - 1])
    out = [None] * V
    after = None
    for v in range(V - 1, -1, -1):
        out[v] = before[v] if after is None else before[v] * after
        after = p[:, :, v] if after is None else after * p[:, :, v]
    return out


def _poly_rebuild(cls, muscles, coordinates, terms):  # pickle support
    return cls(muscles=muscles, coordinates=coordinates, terms=terms)


class PolynomialPath:
    """Multivariate polynomial paths of ``m`` muscles over a model's ``nv`` coordinates.

    Muscle ``i`` depends on the coordinates it crosses, ``q_v`` for ``v`` in its
    ``coordinates``, through scaled variables ``x_v = (q_v - center_v) / scale_v``:

        l_i(q) = sum_t c_t prod_v x_v**e_tv,      r_ij = -dl_i/dq_j

    (lengths in m, moment arms in m, the same polynomial for both, as OpenSim's
    PolynomialPathFitter and PredSim fit them).  The methods are those of
    :class:`MomentArmPath`; a :class:`~pinmsk.muscles.muscle_set.MuscleSet`
    takes either.

    Parameters (keyword-only)
    -------------------------
    muscles : tuple of str, length m
    coordinates : tuple of str, length nv -- the model's velocity coordinates, in order
    terms : sequence (one per muscle) of mappings with ``coordinates`` (names of the
        coordinates crossed, k of them), ``center`` and ``scale`` (k,), ``exponents``
        (T, k) non-negative integers and ``coefficients`` (T,) in m
    """

    __slots__ = ("_muscles", "_coordinates", "_terms", "_cidx", "_center", "_scale", "_tmus", "_exps",
                 "_coef", "_starts", "_degree")

    def __init__(self, *, muscles, coordinates, terms):
        muscles = tuple(str(m) for m in muscles)
        coordinates = tuple(str(c) for c in coordinates)
        for what, names in (("muscle", muscles), ("coordinate", coordinates)):
            dupes = sorted({n for n in names if names.count(n) > 1})
            if dupes:
                raise ModelError(f"PolynomialPath: {what} names must be unique; repeated: {', '.join(dupes)}")
        terms = list(terms)
        if len(terms) != len(muscles):
            raise ModelError(f"PolynomialPath: {len(terms)} term tables for {len(muscles)} muscles")
        index = {c: j for j, c in enumerate(coordinates)}
        V = max([len(t["coordinates"]) for t in terms] + [1])
        m = len(muscles)
        cidx = np.full((m, V), -1, dtype=int)
        center = np.zeros((m, V))
        scale = np.ones((m, V))
        tmus, exps, coef, clean = [], [], [], []
        for i, (name, t) in enumerate(zip(muscles, terms)):
            names = tuple(str(c) for c in t["coordinates"])
            k = len(names)
            for c in names:
                if c not in index:
                    close = difflib.get_close_matches(c, coordinates, n=1)
                    hint = f"; did you mean {close[0]!r}?" if close else ""
                    raise ModelError(f"PolynomialPath: muscle {name!r} crosses coordinate {c!r}, which the model "
                                     f"does not have{hint}")
            e = np.asarray(t["exponents"], dtype=int).reshape(-1, k) if k else np.zeros((len(t["coefficients"]), 0), int)
            c_ = np.asarray(t["coefficients"], dtype=float).reshape(-1)
            ce = np.asarray(t.get("center", np.zeros(k)), dtype=float).reshape(k)
            sc = np.asarray(t.get("scale", np.ones(k)), dtype=float).reshape(k)
            if e.shape[0] != c_.size or c_.size == 0 or np.any(e < 0):
                raise ModelError(f"PolynomialPath: muscle {name!r} needs as many exponent rows (non-negative) as "
                                 f"coefficients (at least one); got {e.shape} and {c_.size}")
            if not (np.all(np.isfinite(c_)) and np.all(np.isfinite(ce)) and np.all(np.isfinite(sc)) and np.all(sc > 0)):
                raise ModelError(f"PolynomialPath: muscle {name!r} has non-finite coefficients or a scale <= 0")
            cidx[i, :k] = [index[c] for c in names]
            center[i, :k], scale[i, :k] = ce, sc
            pad = np.zeros((e.shape[0], V), dtype=int)
            pad[:, :k] = e
            tmus.append(np.full(e.shape[0], i))
            exps.append(pad)
            coef.append(c_)
            clean.append({"coordinates": names, "center": tuple(ce), "scale": tuple(sc),
                          "exponents": tuple(map(tuple, e.tolist())), "coefficients": tuple(c_.tolist())})
        tmus = np.concatenate(tmus) if tmus else np.zeros(0, int)
        counts = np.bincount(tmus, minlength=m)
        set_ = object.__setattr__
        set_(self, "_muscles", muscles)
        set_(self, "_coordinates", coordinates)
        set_(self, "_terms", tuple(clean))
        set_(self, "_cidx", cidx)
        set_(self, "_center", center)
        set_(self, "_scale", scale)
        set_(self, "_tmus", tmus)
        set_(self, "_exps", np.concatenate(exps) if exps else np.zeros((0, V), int))
        set_(self, "_coef", np.concatenate(coef) if coef else np.zeros(0))
        set_(self, "_starts", np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int))
        set_(self, "_degree", int(self._exps.sum(axis=1).max()) if self._exps.size else 0)

    def __setattr__(self, name, value):
        raise AttributeError(f"PolynomialPath is immutable; build a new one instead of setting {name!r}")

    def __delattr__(self, name):
        raise AttributeError("PolynomialPath is immutable")

    def __reduce__(self):
        return (_poly_rebuild, (type(self), self._muscles, self._coordinates, [dict(t) for t in self._terms]))

    def __repr__(self) -> str:
        return (f"PolynomialPath({len(self._muscles)} muscles x {len(self._coordinates)} coordinates, "
                f"degree {self.degree}, {self._coef.size} terms)")

    # the same read-only views and frame checks as MomentArmPath (same slot names)
    muscles = MomentArmPath.muscles
    coordinates = MomentArmPath.coordinates
    n_muscles = MomentArmPath.n_muscles
    nv = MomentArmPath.nv
    _frames = MomentArmPath._frames

    @property
    def terms(self) -> tuple:
        """Per muscle: its coordinates, center, scale, exponents and coefficients."""
        return self._terms

    @property
    def degree(self) -> int:
        """Highest total degree of the length polynomials (0 = constant lengths)."""
        return self._degree

    # --- evaluation ---------------------------------------------------------------
    def _x(self, q):
        x = (q[:, np.maximum(self._cidx, 0)] - self._center) / self._scale
        return np.where(self._cidx >= 0, x, 0.0)                         # (N, m, V)

    def _monomial_parts(self, q, orders):
        """Per term and variable v, d^o(x_v^e)/dx_v^o for each o in orders -> {o: (N, T, V)}."""
        x = self._x(q)
        K = self._degree
        N = x.shape[0]
        V = self._exps.shape[1]
        pw = np.empty(x.shape + (K + 1,))                                  # x^0 .. x^K by products
        pw[..., 0] = 1.0
        if K:
            np.cumprod(np.broadcast_to(x[..., None], x.shape + (K,)), axis=-1, out=pw[..., 1:])
        pw = pw.reshape(N, -1)                                              # (N, m * V * (K+1))
        out = {}
        v = np.arange(V)[None, :]
        for o in orders:
            k = np.arange(K + 1)
            fall = np.ones(K + 1)
            for s in range(o):
                fall = fall * (k - s)
            e = self._exps - o
            ok = e >= 0
            # one flat gather (np.take) of x_v^(e - o) per term and variable: the same numbers as indexing
            # pw[:, muscle, v, e - o], several times faster
            flat = (self._tmus[:, None] * V + v) * (K + 1) + np.maximum(e, 0)     # (T, V)
            factor = np.where(ok, fall[np.maximum(self._exps, 0)], 0.0)           # (T, V)
            out[o] = np.take(pw, flat, axis=1) * factor                            # (N, T, V)
        return out

    def _reduce(self, a):
        """Sum over each muscle's terms: (N, T, ...) -> (N, m, ...)."""
        return np.add.reduceat(a, self._starts, axis=1) if a.shape[1] else np.zeros((a.shape[0], self.n_muscles) + a.shape[2:])

    def _grad_x(self, parts):
        """dl/dx_v (N, m, V) from parts {0, 1}."""
        p0, p1 = parts[0], parts[1]
        V = p0.shape[2]
        g = []
        for v, others in enumerate(_products_of_others(p0)):
            g.append(self._reduce(self._coef * p1[:, :, v] * others))
        return np.stack(g, axis=2)

    def _scatter(self, gx):
        """(N, m, V) derivatives in x -> (N, m, nv) in q (divided by the scales)."""
        N, m = gx.shape[:2]
        out = np.zeros((N, m, self.nv))
        g = gx / self._scale
        for v in range(gx.shape[2]):
            rows = np.flatnonzero(self._cidx[:, v] >= 0)
            out[:, rows, self._cidx[rows, v]] += g[:, rows, v]
        return out

    @_in_blocks(1)
    def lengths(self, q) -> np.ndarray:
        """Muscle-tendon lengths l(q): (N, m), or (m,) for one frame."""
        (q,), single = self._frames(q=q)
        p0 = self._monomial_parts(q, (0,))[0]
        out = self._reduce(self._coef * np.prod(p0, axis=2))
        return out[0] if single else out

    @_in_blocks(1)
    def moment_arms(self, q) -> np.ndarray:
        """Moment arms r = -dl/dq: (N, m, nv), or (m, nv) for one frame."""
        (q,), single = self._frames(q=q)
        out = -self._scatter(self._grad_x(self._monomial_parts(q, (0, 1))))
        return out[0] if single else out

    @_in_blocks(1)
    def lengths_and_moment_arms(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``(lengths(q), moment_arms(q))`` from one evaluation of the monomials (the same numbers)."""
        (q,), single = self._frames(q=q)
        parts = self._monomial_parts(q, (0, 1))
        lengths = self._reduce(self._coef * np.prod(parts[0], axis=2))
        arms = -self._scatter(self._grad_x(parts))
        return (lengths[0], arms[0]) if single else (lengths, arms)

    @_in_blocks(1)
    def moment_arm_derivative(self, q, order: int = 1) -> np.ndarray:
        """``d^order r_ij / dq_j^order`` along each arm's own coordinate (the diagonal; cross terms
        are in :meth:`accelerations`): (N, m, nv), or (m, nv) for one frame."""
        (q,), single = self._frames(q=q)
        o = int(order) + 1
        parts = self._monomial_parts(q, (0, o))
        p0, po = parts[0], parts[o]
        g = []
        for v, others in enumerate(_products_of_others(p0)):
            g.append(self._reduce(self._coef * po[:, :, v] * others))
        gx = np.stack(g, axis=2) / self._scale ** (o - 1)
        out = -self._scatter(gx)
        return out[0] if single else out

    def lengths_at(self, q):
        """l(q) at one pose, any backend: numpy (nv,) -> (m,) (= :meth:`lengths`), CasADi (nv, 1) -> (m, 1)."""
        if not is_symbolic(q):
            return self.lengths(_numeric_pose(q, self.nv, self._coordinates))
        return self._symbolic_at(q)[0]

    def moment_arms_at(self, q):
        """r = -dl/dq at one pose, any backend: numpy (nv,) -> (m, nv) (= :meth:`moment_arms`), CasADi
        (nv, 1) -> (m, nv)."""
        if not is_symbolic(q):
            return self.moment_arms(_numeric_pose(q, self.nv, self._coordinates))
        return self._symbolic_at(q)[1]

    def _symbolic_at(self, q):
        """``(l (m, 1), r (m, nv))`` as CasADi expressions: the polynomials of :meth:`lengths` and
        their exact gradient as in :meth:`moment_arms` (``dl/dx_v = sum_t c_t e_tv x_v^(e_tv - 1)
        prod_{u != v} x_u^e_tu``, divided by ``scale_v``), muscle by muscle, term by term."""
        import casadi as ca

        qc = _symbolic_pose(q, self.nv)
        sym = ca.MX if isinstance(qc, ca.MX) else ca.SX
        m = self.n_muscles
        ends = list(self._starts[1:]) + [self._coef.size]
        lengths, arms = [], sym.zeros(m, self.nv)
        for i in range(m):
            cols = [int(j) for j in self._cidx[i] if j >= 0]
            xs = [(qc[j] - self._center[i, v]) / self._scale[i, v] for v, j in enumerate(cols)]

            def pw(v, e):
                return 1.0 if e == 0 else xs[v] ** int(e)

            length, grad = 0.0, [0.0] * len(cols)
            for t in range(int(self._starts[i]), int(ends[i])):
                e, c = self._exps[t], float(self._coef[t])
                factors = [pw(v, e[v]) for v in range(len(cols))]
                prod = c
                for f in factors:
                    prod = prod * f
                length = length + prod
                for v in range(len(cols)):
                    if e[v] == 0:
                        continue
                    g = c * float(e[v]) * pw(v, e[v] - 1)
                    for u, f in enumerate(factors):
                        if u != v:
                            g = g * f
                    grad[v] = grad[v] + g
            lengths.append(length)
            for v, j in enumerate(cols):
                arms[i, j] = arms[i, j] - grad[v] / self._scale[i, v]
        return ca.vertcat(*[sym(x) if not is_symbolic(x) else x for x in lengths]), arms

    def velocities(self, q, v) -> np.ndarray:
        """Lengthening velocities dl/dt = -sum_j r_j v_j: (N, m), or (m,)."""
        (q, v), single = self._frames(q=q, v=v)
        out = -np.einsum("nmj,nj->nm", self.moment_arms(q), v)
        return out[0] if single else out

    @_in_blocks(3)
    def accelerations(self, q, v, a) -> np.ndarray:
        """d2l/dt2 = sum_j dl/dq_j a_j + sum_jk d2l/dq_j dq_k v_j v_k: (N, m), or (m,)."""
        (q, v, a), single = self._frames(q=q, v=v, a=a)
        parts = self._monomial_parts(q, (0, 1, 2))
        p0, p1, p2 = parts[0], parts[1], parts[2]
        grad = self._scatter(self._grad_x({0: p0, 1: p1}))
        # the velocities of each muscle's own variables, in x units
        vx = np.where(self._cidx >= 0, v[:, np.maximum(self._cidx, 0)], 0.0) / self._scale      # (N, m, V)
        vt = vx[:, self._tmus]                                                               # (N, T, V)
        V = p0.shape[2]
        quad = np.zeros(p0.shape[:2])
        others = _products_of_others(p0)
        for i in range(V):
            for j in range(V):
                if i == j:
                    f = p2[:, :, i] * others[i]
                else:
                    rest = np.prod(np.delete(p0, [i, j], axis=2), axis=2) if V > 2 else 1.0
                    f = p1[:, :, i] * p1[:, :, j] * rest
                quad = quad + f * vt[:, :, i] * vt[:, :, j]
        out = np.einsum("nmj,nj->nm", grad, a) + self._reduce(self._coef * quad)
        return out[0] if single else out


def _lazy_rebuild(fit, muscles, coordinates, fitted):  # pickle support
    path = PolynomialPathOnUse(fit, muscles=muscles, coordinates=coordinates)
    if fitted is not None:
        path._adopt(fitted)
    return path


class PolynomialPathOnUse(PolynomialPath):
    """A :class:`PolynomialPath` whose terms are made when they are first needed.

    ``fit()`` (a picklable callable) returns the PolynomialPath; it runs on the first use of anything
    but :attr:`muscles`, :attr:`coordinates`, :attr:`n_muscles` and :attr:`nv`, which are known before.
    Afterwards this object is that path (the same numbers).  An OpenSim import makes its muscle paths so
    (:mod:`pinmsk.opensim.muscle_import`): an analysis that never evaluates a path, inverse dynamics,
    never pays for fitting the polynomials.  :attr:`fitted` says whether the fit has run.
    """

    __slots__ = ("_fit", "_done")

    def __init__(self, fit, *, muscles, coordinates):
        set_ = object.__setattr__
        set_(self, "_fit", fit)
        set_(self, "_done", False)
        set_(self, "_muscles", tuple(str(m) for m in muscles))
        set_(self, "_coordinates", tuple(str(c) for c in coordinates))

    @property
    def fitted(self) -> bool:
        return self._done

    def _adopt(self, path: PolynomialPath) -> None:
        if path.muscles != self._muscles or path.coordinates != self._coordinates:
            raise ModelError(f"PolynomialPathOnUse: the fit made a path of muscles {list(path.muscles)} over "
                             f"{list(path.coordinates)}, not of {list(self._muscles)} over {list(self._coordinates)}")
        for name in PolynomialPath.__slots__:
            object.__setattr__(self, name, getattr(path, name))
        object.__setattr__(self, "_done", True)

    def __getattr__(self, name):
        # called only for an attribute not set yet: the fitted path's
        if name.startswith("__") or name in ("_fit", "_done") or name not in PolynomialPath.__slots__:
            raise AttributeError(name)
        if self._done:
            raise AttributeError(name)
        try:
            path = self._fit()
        except AttributeError as exc:      # not to be taken for a missing attribute by getattr()
            raise RuntimeError(f"fitting the muscle paths failed: {exc}") from exc
        self._adopt(path)
        return object.__getattribute__(self, name)

    def __reduce__(self):
        fitted = PolynomialPath(muscles=self._muscles, coordinates=self._coordinates,
                                terms=[dict(t) for t in self._terms]) if self._done else None
        return (_lazy_rebuild, (self._fit, self._muscles, self._coordinates, fitted))

    def __repr__(self) -> str:
        if self._done:
            return super().__repr__()
        return (f"PolynomialPath({len(self._muscles)} muscles x {len(self._coordinates)} coordinates, fitted on "
                "first use)")
