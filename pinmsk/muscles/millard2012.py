"""Millard et al. (2013) muscle curves as OpenSim's Millard2012EquilibriumMuscle builds them.

OpenSim's curves are *smooth segmented functions*: chains of quintic Bezier
segments ``(x(u), y(u))``, ``u`` in [0, 1], each a "corner" between two points
with given slopes (opensim-core ``SegmentedQuinticBezierToolkit``), continued
linearly outside their domain.  :class:`QuinticBezierCurve` evaluates such a
chain exactly and vectorised: ``x(u) = x`` is solved for ``u`` per element by
safeguarded Newton iteration to machine precision (the curve's ``x(u)`` is
monotone on every segment), then ``y``, ``dy/dx`` and ``d^2y/dx^2`` follow
from the Bezier polynomials.  OpenSim solves the same equation by Newton
iteration to ``|x(u) - x| <= 100 eps``, so both give the same values to
round-off.

The curve classes mirror OpenSim's (property names and defaults as in
opensim-core 4.x), each with ``value`` / ``derivative`` and the
``build_curve()`` chain of ``SmoothSegmentedFunctionFactory``:

- :class:`ActiveForceLengthCurve` (5 segments),
- :class:`FiberForceLengthCurve` (2; passive),
- :class:`ForceVelocityCurve` and :class:`ForceVelocityInverseCurve` (4),
- :class:`TendonForceLengthCurve` (2; of the normalised tendon length).

:class:`Millard2012EquilibriumMuscle` holds one OpenSim muscle's properties
and applies OpenSim's own adjustment of the curves (``extendFinalizeFromProperties``:
the damped or rigid-tendon model uses an active-force-length minimum of 0 and
force-velocity end slopes of 0; the undamped elastic-tendon model raises them)
in :meth:`Millard2012EquilibriumMuscle.effective`.  The vectorised
muscle-tendon model is :class:`pinmsk.muscles.Millard2012`.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Sequence

import numpy as np

from ..errors import ModelError
from ._common import OpenSimMuscleProperties

__all__ = [
    "QuinticBezierCurve", "corner_control_points", "scale_curviness",
    "ActiveForceLengthCurve", "FiberForceLengthCurve", "ForceVelocityCurve",
    "ForceVelocityInverseCurve", "TendonForceLengthCurve", "Millard2012EquilibriumMuscle",
    "MIN_NONZERO_DAMPING",
]

_ROOT_EPS = math.sqrt(np.finfo(float).eps)
#: OpenSim switches to the undamped model below this fiber damping coefficient
MIN_NONZERO_DAMPING = 0.001

# Power-basis coefficients of the degree-5 Bernstein polynomials: the Bezier
# value is sum_j u^j (control_points @ _BERNSTEIN)[j].
_TABLE = 17      # samples per segment of the u(x) table that seeds Newton
_BERNSTEIN = np.array([[math.comb(5, k) * math.comb(5 - k, j - k) * (-1) ** (j - k) if j >= k else 0
                        for j in range(6)] for k in range(6)], dtype=float)


def scale_curviness(curviness):
    """OpenSim's map of a curviness in [0, 1] to the corner's control-point fraction ``0.1 + 0.8 c``."""
    return 0.1 + 0.8 * curviness


def corner_control_points(x0, y0, dydx0, x1, y1, dydx1, c, *, what: str = "curve"):
    """The 6 x- and y- control points of the quintic Bezier corner from ``(x0, y0)``
    with slope ``dydx0`` to ``(x1, y1)`` with slope ``dydx1``.

    The two end tangents meet at the corner point C; the inner control points
    lie a fraction ``c`` (the scaled curviness) of the way from each end to C,
    doubled so that the segment's curvature is zero at its ends.  Raises
    :class:`ModelError` when the tangents do not form a C-shaped corner.
    """
    if abs(dydx0 - dydx1) > _ROOT_EPS:
        xc = (y1 - y0 - x1 * dydx1 + x0 * dydx0) / (dydx0 - dydx1)
    else:
        xc = 0.5 * (x1 + x0)
    yc = (xc - x1) * dydx1 + y1
    a = (xc - x0) ** 2 + (yc - y0) ** 2
    b = (xc - x1) ** 2 + (yc - y1) ** 2
    d = (x1 - x0) ** 2 + (y1 - y0) ** 2
    if not (d > a and d > b):
        raise ModelError(f"{what}: the end slopes {dydx0:g} at ({x0:g}, {y0:g}) and {dydx1:g} at "
                         f"({x1:g}, {y1:g}) do not form a C-shaped corner; check the curve settings")
    x0m, y0m = x0 + c * (xc - x0), y0 + c * (yc - y0)
    x1m, y1m = x1 + c * (xc - x1), y1 + c * (yc - y1)
    return (np.array([x0, x0m, x0m, x1m, x1m, x1]), np.array([y0, y0m, y0m, y1m, y1m, y1]))


def _poly(c, u, second: bool = False):
    """Value and u-derivative (and second derivative) of ``sum_j c[j] u^j`` (Horner).

    ``c`` has the 6 power-basis coefficients on its *first* axis (contiguous rows).
    """
    p = c[5]
    dp = np.zeros_like(u)
    ddp = np.zeros_like(u) if second else None
    for j in range(4, -1, -1):
        if second:
            ddp = ddp * u + 2.0 * dp
        dp = dp * u + p
        p = p * u + c[j]
    return (p, dp, ddp) if second else (p, dp)


class QuinticBezierCurve:
    """A chain of quintic Bezier segments with linear extrapolation: OpenSim's SmoothSegmentedFunction.

    ``ctrl_x``, ``ctrl_y``: control points ``(S, 6)`` for one curve, or
    ``(m, S, 6)`` for m curves with the same number of segments evaluated
    together (then inputs have the muscles on their last axis, ``(..., m)``).
    ``x0, x1`` bound the domain; outside it the curve continues with the value
    ``y0``/``y1`` and the slope ``dydx0``/``dydx1`` (second derivative 0).
    Immutable; evaluation is vectorised over frames and muscles.
    """

    def __init__(self, ctrl_x, ctrl_y, x0, x1, y0, y1, dydx0, dydx1):
        cx = np.asarray(ctrl_x, dtype=float)
        cy = np.asarray(ctrl_y, dtype=float)
        if cx.ndim == 2:
            cx, cy = cx[None], cy[None]
        if cx.shape != cy.shape or cx.ndim != 3 or cx.shape[-1] != 6:
            raise ModelError(f"Bezier control points must be (S, 6) or (m, S, 6) for x and y, got "
                             f"{np.shape(ctrl_x)} and {np.shape(ctrl_y)}")
        self.m, self.n_segments = cx.shape[0], cx.shape[1]
        self.ctrl_x, self.ctrl_y = cx, cy
        ends = [np.broadcast_to(np.asarray(v, dtype=float), (self.m,)).copy()
                for v in (x0, x1, y0, y1, dydx0, dydx1)]
        self.x0, self.x1, self.y0, self.y1, self.dydx0, self.dydx1 = ends
        # power-basis coefficients (6, m * S): one contiguous row per power, gathered per element
        self._px = np.ascontiguousarray((cx @ _BERNSTEIN).reshape(-1, 6).T)
        self._py = np.ascontiguousarray((cy @ _BERNSTEIN).reshape(-1, 6).T)
        # u(x) and u(y) tables for the Newton initial guess: samples of each segment, keyed by
        # the global parameter "segment index + u" (continuous across segment joints)
        uu = np.linspace(0.0, 1.0, _TABLE)
        powers = uu[:, None] ** np.arange(6)
        glob = (np.arange(self.n_segments)[:, None] + uu).ravel()
        self._tables = {}
        for key, coeffs in (("x", cx @ _BERNSTEIN), ("y", cy @ _BERNSTEIN)):
            self._tables[key] = (np.einsum("msj,kj->msk", coeffs, powers).reshape(self.m, -1), glob)
        for arr in (self.ctrl_x, self.ctrl_y, self._px, self._py, *ends, glob,
                    self._tables["x"][0], self._tables["y"][0]):
            arr.flags.writeable = False

    @classmethod
    def stack(cls, curves: Sequence["QuinticBezierCurve"]) -> "QuinticBezierCurve":
        """One curve object evaluating ``len(curves)`` single curves side by side (muscles last)."""
        if len(curves) == 1:
            return curves[0]
        cat = lambda attr: np.concatenate([getattr(c, attr) for c in curves])
        return cls(cat("ctrl_x"), cat("ctrl_y"), cat("x0"), cat("x1"), cat("y0"), cat("y1"),
                   cat("dydx0"), cat("dydx1"))

    # -- evaluation ---------------------------------------------------------------
    def _guess(self, t, key):
        """``(row, u0)``: the segment row (into the flattened coefficients) and a table-interpolated
        initial ``u`` of each element of ``t`` (an x or, for :meth:`inverse`, a y)."""
        table, glob = self._tables[key]
        if self.m == 1:
            g = np.interp(t, table[0], glob)
            rows = 0
        else:
            g = np.empty(t.shape)
            for j in range(self.m):          # one 1-D interpolation per muscle (m is small)
                g[..., j] = np.interp(t[..., j], table[j], glob)
            rows = np.arange(self.m) * self.n_segments
        k = np.minimum(np.floor(g), self.n_segments - 1)
        return rows + k.astype(np.intp), g - k

    def _solve_u(self, coeffs, target, u):
        """``u`` in [0, 1] with ``poly(coeffs, u) = target`` (increasing polynomial), per element:
        Newton from the guess ``u``, bisection where a step leaves the bracket."""
        lo = np.zeros_like(u)
        hi = np.ones_like(u)
        tol = 8.0 * np.finfo(float).eps * np.maximum(np.abs(target), 1.0)
        active = np.ones(u.shape, dtype=bool)
        for _ in range(80):
            p, dp = _poly(coeffs, u)
            f = p - target
            lo = np.where(f < 0, u, lo)
            hi = np.where(f > 0, u, hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                un = u - f / dp
            ok = (dp > 0) & (un >= lo) & (un <= hi)
            un = np.where(ok, un, 0.5 * (lo + hi))
            done = (np.abs(f) <= tol) | (hi - lo <= 4.0 * np.finfo(float).eps)
            u = np.where(active & ~done, un, u)
            active &= ~done
            if not active.any():
                break
        return u

    def evaluate(self, x, orders: Sequence[int] = (0, 1)):
        """``[y, dy/dx, d2y/dx2][k] for k in orders`` at ``x`` (orders 0, 1, 2)."""
        if any(o not in (0, 1, 2) for o in orders):
            raise ValueError(f"derivative orders must be 0, 1 or 2, got {tuple(orders)}")
        x = np.asarray(x, dtype=float)
        if self.m > 1 and (x.ndim == 0 or x.shape[-1] != self.m):
            raise ModelError(f"{self.m} stacked curves need inputs with {self.m} muscles on the last "
                             f"axis, got shape {x.shape}")
        shape = x.shape
        if self.m == 1:
            ends = [float(v[0]) for v in (self.x0, self.x1, self.y0, self.y1, self.dydx0, self.dydx1)]
        else:
            ends = [self.x0, self.x1, self.y0, self.y1, self.dydx0, self.dydx1]
        x0, x1, y0, y1, s0, s1 = ends
        xin = np.clip(x, x0, x1)
        k, u = self._guess(xin, "x")
        cx = self._px[:, k]
        u = self._solve_u(cx, xin, u)
        second = 2 in orders
        _, dx, ddx = _poly(cx, u, True) if second else (*_poly(cx, u), None)
        y, dy, ddy = _poly(self._py[:, k], u, True) if second else (*_poly(self._py[:, k], u), None)
        below, above = x < x0, x > x1
        out = []
        for o in orders:
            if o == 0:
                r = np.where(below, y0 + s0 * (x - x0), np.where(above, y1 + s1 * (x - x1), y))
            elif o == 1:
                r = np.where(below, s0, np.where(above, s1, dy / dx))
            else:
                r = np.where(below | above, 0.0, (ddy * dx - dy * ddx) / (dx * dx * dx))
            out.append(np.reshape(r, shape))
        return out

    def value(self, x):
        """The curve's value at ``x``."""
        return self.evaluate(x, (0,))[0]

    def derivative(self, x, order: int = 1):
        """``d^order y / dx^order`` at ``x`` (order 0, 1 or 2)."""
        return self.evaluate(x, (order,))[0]

    def inverse(self, y):
        """``x`` with ``value(x) = y`` for a curve increasing in x (tendon, passive, force-velocity).

        Outside the range it inverts the linear continuation, or returns the domain
        end where the end slope is 0.
        """
        y = np.asarray(y, dtype=float)
        if self.m == 1:
            ends = [float(v[0]) for v in (self.x0, self.x1, self.y0, self.y1, self.dydx0, self.dydx1)]
        else:
            ends = [self.x0, self.x1, self.y0, self.y1, self.dydx0, self.dydx1]
        x0, x1, y0, y1, s0, s1 = ends
        yin = np.clip(y, y0, y1)
        k, u = self._guess(yin, "y")
        u = self._solve_u(self._py[:, k], yin, u)
        x = _poly(self._px[:, k], u)[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            xb = np.where(s0 > 0, x0 + (y - y0) / s0, x0)
            xa = np.where(s1 > 0, x1 + (y - y1) / s1, x1)
        return np.where(y < y0, xb, np.where(y > y1, xa, x))


# --------------------------------------------------------------------------- curve settings
def _check(ok: bool, curve: str, message: str) -> None:
    if not ok:
        raise ModelError(f"{curve}: {message}")


def _finite(curve: str, **values) -> None:
    for k, v in values.items():
        _check(isinstance(v, (int, float)) and math.isfinite(v), curve, f"{k} = {v!r} is not a finite number")


class _Curve:
    """OpenSim's curve-object interface of the frozen curve settings below (the curve is built once)."""

    def build_curve(self) -> QuinticBezierCurve:
        raise NotImplementedError

    def value(self, x):
        """The curve at ``x`` (OpenSim ``calcValue``), vectorised."""
        return _cached(self).value(x)

    def derivative(self, x, order: int = 1):
        """``d^order y / dx^order`` at ``x`` (OpenSim ``calcDerivative``; order 0, 1 or 2)."""
        return _cached(self).derivative(x, order)

    def inverse(self, y):
        """``x`` where the (increasing) curve equals ``y``: see :meth:`QuinticBezierCurve.inverse`."""
        return _cached(self).inverse(y)


@dataclass(frozen=True)
class ActiveForceLengthCurve(_Curve):
    """OpenSim ``ActiveForceLengthCurve``: the active force-length multiplier of the normalised fiber length.

    Five corners: 0 at ``min_norm_active_fiber_length``, the steep ascending limb
    to ``transition_norm_fiber_length``, the shallow ascending limb of slope
    ``shallow_ascending_slope`` to the plateau 1 at 1.0, the descending limb to
    ``max_norm_active_fiber_length``; ``minimum_value`` outside.  Curviness 1
    (fixed in OpenSim).
    """

    min_norm_active_fiber_length: float = 0.47 - 0.0259
    transition_norm_fiber_length: float = 0.73
    max_norm_active_fiber_length: float = 1.8123
    shallow_ascending_slope: float = 0.8616
    minimum_value: float = 0.1

    def __post_init__(self):
        name = type(self).__name__
        x0, x1 = self.min_norm_active_fiber_length, self.transition_norm_fiber_length
        x3 = self.max_norm_active_fiber_length
        _finite(name, **asdict(self))
        _check(x0 >= 0 and x1 > x0 + _ROOT_EPS and 1.0 > x1 + _ROOT_EPS and x3 > 1.0 + _ROOT_EPS, name,
               f"needs 0 <= min_norm_active_fiber_length ({x0:g}) < transition_norm_fiber_length "
               f"({x1:g}) < 1 < max_norm_active_fiber_length ({x3:g})")
        _check(self.minimum_value >= 0, name, f"minimum_value = {self.minimum_value:g} must be >= 0")
        bound = (1.0 - self.minimum_value) / (1.0 - x1)
        _check(0 <= self.shallow_ascending_slope < bound, name,
               f"shallow_ascending_slope = {self.shallow_ascending_slope:g} must be in [0, {bound:g})")

    def build_curve(self) -> QuinticBezierCurve:
        """``SmoothSegmentedFunctionFactory::createFiberActiveForceLengthCurve`` (x2 = 1, curviness 1)."""
        x0, x1, x2 = self.min_norm_active_fiber_length, self.transition_norm_fiber_length, 1.0
        x3, ylow, dydx = self.max_norm_active_fiber_length, self.minimum_value, self.shallow_ascending_slope
        c = scale_curviness(1.0)
        what = type(self).__name__
        dx = 0.05 * x2
        xs = x2 - dx
        y0, y1 = 0.0, 1.0 - dydx * (xs - x1)
        dydx01 = 1.25 * (y1 - y0) / (x1 - x0)
        x01, y01 = x0 + 0.5 * (x1 - x0), y0 + 0.5 * (y1 - y0)
        x1s, y1s = x1 + 0.5 * (xs - x1), y1 + 0.5 * (1.0 - y1)
        y2, y3 = 1.0, 0.0
        x23, y23 = (x2 + dx) + 0.5 * (x3 - (x2 + dx)), y2 + 0.5 * (y3 - y2)
        dydx23 = (y3 - y2) / ((x3 - dx) - (x2 + dx))
        corners = [(x0, ylow, 0.0, x01, y01, dydx01), (x01, y01, dydx01, x1s, y1s, dydx),
                   (x1s, y1s, dydx, x2, y2, 0.0), (x2, y2, 0.0, x23, y23, dydx23),
                   (x23, y23, dydx23, x3, ylow, 0.0)]
        return _chain(corners, c, what, x0, x3, ylow, ylow, 0.0, 0.0)


@dataclass(frozen=True)
class FiberForceLengthCurve(_Curve):
    """OpenSim ``FiberForceLengthCurve``: the passive fiber force multiplier of the normalised fiber length.

    0 (slope 0) at ``1 + strain_at_zero_force``, 1 (slope
    ``stiffness_at_one_norm_force``) at ``1 + strain_at_one_norm_force``.  The
    optional ``stiffness_at_low_force``, ``stiffness_at_one_norm_force`` and
    ``curviness`` are given all together or not at all; when absent OpenSim's
    fitted defaults are used: 0.2, ``2/(e1 - e0)`` and 0.75.
    """

    strain_at_zero_force: float = 0.0
    strain_at_one_norm_force: float = 0.7
    stiffness_at_low_force: float | None = None
    stiffness_at_one_norm_force: float | None = None
    curviness: float | None = None

    def __post_init__(self):
        name = type(self).__name__
        opt = (self.stiffness_at_low_force, self.stiffness_at_one_norm_force, self.curviness)
        _check(all(v is None for v in opt) or all(v is not None for v in opt), name,
               "stiffness_at_low_force, stiffness_at_one_norm_force and curviness must be given "
               "all together or not at all")
        _finite(name, **{k: v for k, v in asdict(self).items() if v is not None})
        e0, e1, k_low, k_iso, c = self.in_use()
        _check(e1 > e0, name, f"strain_at_one_norm_force ({e1:g}) must exceed strain_at_zero_force ({e0:g})")
        _check(k_iso > 1.0 / (e1 - e0), name,
               f"stiffness_at_one_norm_force = {k_iso:g} must be > 1/(e1 - e0) = {1.0 / (e1 - e0):g}")
        _check(0 < k_low < 1.0 / (e1 - e0), name,
               f"stiffness_at_low_force = {k_low:g} must be in (0, {1.0 / (e1 - e0):g})")
        _check(0 <= c <= 1, name, f"curviness = {c:g} must be in [0, 1]")

    def in_use(self):
        """``(e0, e1, stiffness_at_low_force, stiffness_at_one_norm_force, curviness)`` in use."""
        e0, e1 = self.strain_at_zero_force, self.strain_at_one_norm_force
        if self.curviness is None:
            return e0, e1, 0.2, 2.0 / (e1 - e0), 0.75
        return e0, e1, self.stiffness_at_low_force, self.stiffness_at_one_norm_force, self.curviness

    def build_curve(self) -> QuinticBezierCurve:
        """``SmoothSegmentedFunctionFactory::createFiberForceLengthCurve``."""
        e0, e1, k_low, k_iso, curv = self.in_use()
        c = scale_curviness(curv)
        x_zero, x_iso = 1.0 + e0, 1.0 + e1
        delta = min(0.1 / k_iso, 0.1 * (x_iso - x_zero))
        x_low = x_zero + delta
        x_foot = x_zero + 0.5 * (x_low - x_zero)
        y_low = k_low * (x_low - x_foot)
        corners = [(x_zero, 0.0, 0.0, x_low, y_low, k_low), (x_low, y_low, k_low, x_iso, 1.0, k_iso)]
        return _chain(corners, c, type(self).__name__, x_zero, x_iso, 0.0, 1.0, 0.0, k_iso)


@dataclass(frozen=True)
class ForceVelocityCurve(_Curve):
    """OpenSim ``ForceVelocityCurve``: the force-velocity multiplier of the normalised fiber velocity.

    ``v`` in units of the maximum contraction velocity, negative when shortening:
    0 at -1, 1 at 0 (slope ``isometric_slope``), ``max_eccentric_velocity_force_multiplier``
    at +1; the slopes at and near +-1 and the two curvinesses shape the ends.
    """

    concentric_slope_at_vmax: float = 0.0
    concentric_slope_near_vmax: float = 0.25
    isometric_slope: float = 5.0
    eccentric_slope_at_vmax: float = 0.0
    eccentric_slope_near_vmax: float = 0.15
    max_eccentric_velocity_force_multiplier: float = 1.4
    concentric_curviness: float = 0.6
    eccentric_curviness: float = 0.9

    def __post_init__(self):
        name = type(self).__name__
        _finite(name, **asdict(self))
        fmax = self.max_eccentric_velocity_force_multiplier
        _check(fmax > 1.0, name, f"max_eccentric_velocity_force_multiplier = {fmax:g} must be > 1")
        self._check_slopes(name, fmax)
        for k in ("concentric_curviness", "eccentric_curviness"):
            _check(0 <= getattr(self, k) <= 1, name, f"{k} = {getattr(self, k):g} must be in [0, 1]")

    def _check_slopes(self, name, fmax):
        c, nc = self.concentric_slope_at_vmax, self.concentric_slope_near_vmax
        e, ne = self.eccentric_slope_at_vmax, self.eccentric_slope_near_vmax
        _check(0 <= c < 1, name, f"concentric_slope_at_vmax = {c:g} must be in [0, 1)")
        _check(c < nc <= 1, name, f"concentric_slope_near_vmax = {nc:g} must be in "
                                  f"(concentric_slope_at_vmax, 1]")
        _check(self.isometric_slope > 1, name, f"isometric_slope = {self.isometric_slope:g} must be > 1")
        _check(0 <= e < fmax - 1, name, f"eccentric_slope_at_vmax = {e:g} must be in [0, {fmax - 1:g})")
        _check(e <= ne < fmax - 1, name, f"eccentric_slope_near_vmax = {ne:g} must be in "
                                         f"[eccentric_slope_at_vmax, {fmax - 1:g})")

    def _corners(self):
        fmax = self.max_eccentric_velocity_force_multiplier
        c_con = scale_curviness(self.concentric_curviness)
        c_ecc = scale_curviness(self.eccentric_curviness)
        dc, dnc, diso = self.concentric_slope_at_vmax, self.concentric_slope_near_vmax, self.isometric_slope
        de, dne = self.eccentric_slope_at_vmax, self.eccentric_slope_near_vmax
        x_nc = -0.9
        y_nc = 0.5 * dnc * (x_nc + 1.0) + 0.5 * dc * (x_nc + 1.0)
        x_ne = 0.9
        y_ne = fmax + 0.5 * dne * (x_ne - 1.0) + 0.5 * de * (x_ne - 1.0)
        what = type(self).__name__
        pts = [corner_control_points(-1.0, 0.0, dc, x_nc, y_nc, dnc, c_con, what=what),
               corner_control_points(x_nc, y_nc, dnc, 0.0, 1.0, diso, c_con, what=what),
               corner_control_points(0.0, 1.0, diso, x_ne, y_ne, dne, c_ecc, what=what),
               corner_control_points(x_ne, y_ne, dne, 1.0, fmax, de, c_ecc, what=what)]
        return np.array([p[0] for p in pts]), np.array([p[1] for p in pts])

    def build_curve(self) -> QuinticBezierCurve:
        """``SmoothSegmentedFunctionFactory::createFiberForceVelocityCurve``."""
        cx, cy = self._corners()
        return QuinticBezierCurve(cx, cy, -1.0, 1.0, 0.0, self.max_eccentric_velocity_force_multiplier,
                                  self.concentric_slope_at_vmax, self.eccentric_slope_at_vmax)


@dataclass(frozen=True)
class ForceVelocityInverseCurve(ForceVelocityCurve):
    """OpenSim ``ForceVelocityInverseCurve``: normalised fiber velocity of the force-velocity multiplier.

    The same Bezier segments as the :class:`ForceVelocityCurve` of the same
    settings with x and y swapped; the end slopes must be > 0 (the inverse's are
    their reciprocals).  Its defaults are OpenSim's (end slopes 0.1).
    """

    concentric_slope_at_vmax: float = 0.1
    eccentric_slope_at_vmax: float = 0.1

    def _check_slopes(self, name, fmax):
        super()._check_slopes(name, fmax)
        for k in ("concentric_slope_at_vmax", "eccentric_slope_at_vmax"):
            _check(getattr(self, k) > 0, name, f"{k} = {getattr(self, k):g} must be > 0 (the inverse "
                                               "curve's end slope is its reciprocal)")
        _check(self.concentric_slope_near_vmax < 1, name, "concentric_slope_near_vmax must be < 1")

    def build_curve(self) -> QuinticBezierCurve:
        """``SmoothSegmentedFunctionFactory::createFiberForceVelocityInverseCurve``."""
        cx, cy = self._corners()
        return QuinticBezierCurve(cy, cx, 0.0, self.max_eccentric_velocity_force_multiplier, -1.0, 1.0,
                                  1.0 / self.concentric_slope_at_vmax, 1.0 / self.eccentric_slope_at_vmax)


@dataclass(frozen=True)
class TendonForceLengthCurve(_Curve):
    """OpenSim ``TendonForceLengthCurve``: the tendon force multiplier of the normalised tendon length.

    0 (slope 0) at slack length 1.0, 1 at ``1 + strain_at_one_norm_force``,
    linear with slope ``stiffness_at_one_norm_force`` above the toe force
    ``norm_force_at_toe_end``.  The three optional settings are given together
    or not at all; when absent OpenSim's fitted defaults are used:
    ``1.375/e0``, 2/3 and 0.5.
    """

    strain_at_one_norm_force: float = 0.049
    stiffness_at_one_norm_force: float | None = None
    norm_force_at_toe_end: float | None = None
    curviness: float | None = None

    def __post_init__(self):
        name = type(self).__name__
        opt = (self.stiffness_at_one_norm_force, self.norm_force_at_toe_end, self.curviness)
        _check(all(v is None for v in opt) or all(v is not None for v in opt), name,
               "stiffness_at_one_norm_force, norm_force_at_toe_end and curviness must be given all "
               "together or not at all")
        _finite(name, **{k: v for k, v in asdict(self).items() if v is not None})
        e0, k_iso, f_toe, c = self.in_use()
        _check(e0 > 0, name, f"strain_at_one_norm_force = {e0:g} must be > 0")
        _check(0 < f_toe < 1, name, f"norm_force_at_toe_end = {f_toe:g} must be in (0, 1)")
        _check(k_iso > 1.0 / e0, name,
               f"stiffness_at_one_norm_force = {k_iso:g} must be > 1/strain_at_one_norm_force = {1 / e0:g}")
        _check(0 <= c <= 1, name, f"curviness = {c:g} must be in [0, 1]")

    def in_use(self):
        """``(strain_at_one_norm_force, stiffness, toe force, curviness)`` in use."""
        e0 = self.strain_at_one_norm_force
        if self.curviness is None:
            return e0, 1.375 / e0, 2.0 / 3.0, 0.5
        return e0, self.stiffness_at_one_norm_force, self.norm_force_at_toe_end, self.curviness

    def build_curve(self) -> QuinticBezierCurve:
        """``SmoothSegmentedFunctionFactory::createTendonForceLengthCurve``."""
        e_iso, k_iso, f_toe, curv = self.in_use()
        c = scale_curviness(curv)
        x_iso = 1.0 + e_iso
        x_toe = (f_toe - 1.0) / k_iso + x_iso
        x_foot = 1.0 + (x_toe - 1.0) / 10.0
        y_toe_mid = 0.5 * f_toe
        x_toe_mid = (y_toe_mid - 1.0) / k_iso + x_iso
        dydx_toe_mid = y_toe_mid / (x_toe_mid - x_foot)
        x_ctrl = x_foot + 0.5 * (x_toe_mid - x_foot)
        y_ctrl = dydx_toe_mid * (x_ctrl - x_foot)
        corners = [(1.0, 0.0, 0.0, x_ctrl, y_ctrl, dydx_toe_mid),
                   (x_ctrl, y_ctrl, dydx_toe_mid, x_toe, f_toe, k_iso)]
        return _chain(corners, c, type(self).__name__, 1.0, x_toe, 0.0, f_toe, 0.0, k_iso)


def _chain(corners, c, what, x0, x1, y0, y1, dydx0, dydx1) -> QuinticBezierCurve:
    pts = [corner_control_points(*k, c, what=what) for k in corners]
    return QuinticBezierCurve(np.array([p[0] for p in pts]), np.array([p[1] for p in pts]),
                              x0, x1, y0, y1, dydx0, dydx1)


_CURVES: dict = {}


def _cached(settings) -> QuinticBezierCurve:
    """The built curve of frozen curve settings (built once per distinct setting)."""
    key = (type(settings), tuple(asdict(settings).values()))
    curve = _CURVES.get(key)
    if curve is None:
        if len(_CURVES) > 4096:       # many distinct settings (parameter sweeps): start again
            _CURVES.clear()
        curve = _CURVES[key] = settings.build_curve()
    return curve


# --------------------------------------------------------------------------- OpenSim muscle
@dataclass(frozen=True)
class Millard2012EquilibriumMuscle(OpenSimMuscleProperties):
    """The properties of one OpenSim ``Millard2012EquilibriumMuscle``, with OpenSim's names and defaults.

    The curve properties are the four curve objects.  :meth:`effective` returns
    the settings OpenSim actually uses after ``extendFinalizeFromProperties``
    (and what it changed); :meth:`model_parameters` gives the keyword arguments
    of :class:`pinmsk.muscles.Millard2012` for those effective curves.
    """

    fiber_damping: float = 0.1
    default_activation: float = 0.05
    activation_time_constant: float = 0.010
    deactivation_time_constant: float = 0.040
    minimum_activation: float = 0.01
    maximum_pennation_angle: float = math.acos(0.1)
    active_force_length_curve: ActiveForceLengthCurve = field(default_factory=ActiveForceLengthCurve)
    force_velocity_curve: ForceVelocityCurve = field(default_factory=ForceVelocityCurve)
    fiber_force_length_curve: FiberForceLengthCurve = field(default_factory=FiberForceLengthCurve)
    tendon_force_length_curve: TendonForceLengthCurve = field(default_factory=TendonForceLengthCurve)

    def __post_init__(self):
        self._check_properties("activation_time_constant", "deactivation_time_constant")
        need = self._require
        need(0.0 <= self.maximum_pennation_angle <= math.pi / 2, "maximum_pennation_angle", "in [0, pi/2]")
        need(self.fiber_damping >= 0, "fiber_damping", ">= 0")
        need(0 <= self.minimum_activation < 1, "minimum_activation", "in [0, 1)")

    @property
    def damped(self) -> bool:
        """Whether OpenSim uses the damped model (fiber damping >= 0.001)."""
        return self.fiber_damping >= MIN_NONZERO_DAMPING

    def effective(self) -> tuple["Millard2012EquilibriumMuscle", list[str]]:
        """``(muscle, changes)``: the curve settings OpenSim uses, and a sentence per change.

        Damped model or rigid tendon: active-force-length ``minimum_value`` 0 and
        force-velocity slopes at +-vmax 0.  Undamped elastic tendon: ``minimum_value``
        at least 0.1, slopes at vmax at least half the slopes near vmax, and
        ``minimum_activation`` at least 0.01 (OpenSim refuses less).  Damping below
        0.001 is set to 0.
        """
        changes: list[str] = []
        afl, fv, m = self.active_force_length_curve, self.force_velocity_curve, self
        if 0 < self.fiber_damping < MIN_NONZERO_DAMPING:
            changes.append(f"fiber_damping {self.fiber_damping:g} < {MIN_NONZERO_DAMPING:g}: set to 0")
            m = replace(m, fiber_damping=0.0)
        if not self.ignore_tendon_compliance and not m.damped:
            mode = "undamped elastic-tendon model"
            if afl.minimum_value < 0.1:
                changes.append(f"{mode}: ActiveForceLengthCurve minimum_value {afl.minimum_value:g} -> 0.1")
                afl = replace(afl, minimum_value=0.1)
            con = max(fv.concentric_slope_at_vmax, 0.5 * fv.concentric_slope_near_vmax)
            ecc = max(fv.eccentric_slope_at_vmax, 0.5 * fv.eccentric_slope_near_vmax)
            if self.minimum_activation < 0.01:
                raise ModelError(f"{type(self).__name__}: minimum_activation = {self.minimum_activation:g} "
                                 "is below 0.01, which OpenSim refuses for the undamped elastic-tendon model")
        else:
            mode = "damped model" if m.damped else "rigid-tendon model"
            if afl.minimum_value > 0:
                changes.append(f"{mode}: ActiveForceLengthCurve minimum_value {afl.minimum_value:g} -> 0")
                afl = replace(afl, minimum_value=0.0)
            con = 0.0 if fv.concentric_slope_at_vmax > 0 else fv.concentric_slope_at_vmax
            ecc = 0.0 if fv.eccentric_slope_at_vmax > 0 else fv.eccentric_slope_at_vmax
        for which, old, new in (("concentric", fv.concentric_slope_at_vmax, con),
                                ("eccentric", fv.eccentric_slope_at_vmax, ecc)):
            if new != old:
                changes.append(f"{mode}: ForceVelocityCurve {which}_slope_at_vmax {old:g} -> {new:g}")
        fv = replace(fv, concentric_slope_at_vmax=con, eccentric_slope_at_vmax=ecc)
        return replace(m, active_force_length_curve=afl, force_velocity_curve=fv), changes

    def minimum_fiber_length(self) -> float:
        """OpenSim's fiber-length floor (m): the larger of the active curve's minimum and the
        length at the maximum pennation angle (1 % of l_opt for a zero maximum angle)."""
        h = self.optimal_fiber_length * math.sin(self.pennation_angle_at_optimal)
        if self.maximum_pennation_angle > 1e-14:
            pennated = h / math.sin(self.maximum_pennation_angle)
        else:
            pennated = 0.01 * self.optimal_fiber_length
        return max(self.active_force_length_curve.min_norm_active_fiber_length * self.optimal_fiber_length,
                   pennated, 1e-14)

    def properties(self) -> dict:
        """All properties by their OpenSim names (the curves as nested dicts)."""
        return asdict(self)

    def model_parameters(self) -> dict:
        """Keyword arguments of :class:`pinmsk.muscles.Millard2012` for this muscle as OpenSim uses it
        (:meth:`effective` curves; SI units)."""
        m, _ = self.effective()
        afl, fpe, fv, tfl = (m.active_force_length_curve, m.fiber_force_length_curve,
                             m.force_velocity_curve, m.tendon_force_length_curve)
        e0, e1, k_low, k_iso, c_pe = fpe.in_use()
        t_e, t_k, t_toe, t_c = tfl.in_use()
        return dict(
            f_max=float(m.max_isometric_force), l_opt=float(m.optimal_fiber_length),
            l_slack=float(m.tendon_slack_length), pennation=float(m.pennation_angle_at_optimal),
            v_max=float(m.max_contraction_velocity * m.optimal_fiber_length),
            damping=float(m.fiber_damping), max_pennation=float(m.maximum_pennation_angle),
            min_norm_active_fiber_length=afl.min_norm_active_fiber_length,
            transition_norm_fiber_length=afl.transition_norm_fiber_length,
            max_norm_active_fiber_length=afl.max_norm_active_fiber_length,
            shallow_ascending_slope=afl.shallow_ascending_slope,
            active_minimum_value=afl.minimum_value,
            passive_strain_at_zero_force=e0, passive_strain=e1, passive_stiffness_at_low_force=k_low,
            passive_stiffness=k_iso, passive_curviness=c_pe,
            concentric_slope_at_vmax=fv.concentric_slope_at_vmax,
            concentric_slope_near_vmax=fv.concentric_slope_near_vmax,
            isometric_slope=fv.isometric_slope, eccentric_slope_at_vmax=fv.eccentric_slope_at_vmax,
            eccentric_slope_near_vmax=fv.eccentric_slope_near_vmax,
            max_eccentric_velocity_force_multiplier=fv.max_eccentric_velocity_force_multiplier,
            concentric_curviness=fv.concentric_curviness, eccentric_curviness=fv.eccentric_curviness,
            tendon_strain=t_e, tendon_stiffness=t_k, tendon_toe_force=t_toe, tendon_curviness=t_c,
            tau_rise=float(m.activation_time_constant), tau_fall=float(m.deactivation_time_constant))
