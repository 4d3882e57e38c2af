"""Vectorised root finding for the muscle layer.

:func:`safeguarded_newton` solves many independent scalar equations at once
(one per muscle-frame) with Newton steps kept inside a bracket and bisection as
the fallback (the ``rtsafe`` strategy), so every element converges even where
the residual is non-monotone (descending limb of the force-length curve) or
the derivative is only approximate.

:func:`compliant_equilibrium` uses it for the fiber length of a compliant
tendon muscle, ``F_tendon = (F_ce + F_pe) cos(alpha)``, shared by the
Thelen 2003 and Nagano-Gerritsen models.
"""
from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np

from ..errors import ConvergenceError
from ._common import locate, where_first
from .pennation import check_along_positive

__all__ = ["safeguarded_newton", "compliant_equilibrium"]


def _fail(message: str, mask: np.ndarray, names, inputs: Mapping[str, np.ndarray] | None):
    frame, muscle = where_first(mask)
    where = locate(frame, muscle, names)
    values = ""
    if inputs:
        k = np.unravel_index(int(np.flatnonzero(mask.ravel())[0]), mask.shape) if mask.ndim else ()
        vals = []
        for key, arr in inputs.items():
            arr = np.broadcast_to(np.asarray(arr, dtype=float), mask.shape)
            vals.append(f"{key} = {float(arr[k]):.6g}")
        values = " (" + ", ".join(vals) + ")"
    raise ConvergenceError(f"{message} for {where}{values}; {int(mask.sum())} muscle-frame(s) "
                           "affected")


def safeguarded_newton(fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                       x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, lo_sign: float,
                       tol: np.ndarray | float, max_iter: int = 100, what: str = "root",
                       names: Sequence[str] | None = None,
                       inputs: Mapping[str, np.ndarray] | None = None,
                       accept_jumps: bool = False) -> np.ndarray:
    """Solve ``fun(x) = 0`` elementwise, keeping ``x`` in the bracket ``(lo, hi)``.

    ``fun(x)`` returns ``(R, dR/dx)`` (the derivative may be approximate).
    ``R`` has the sign ``lo_sign`` at ``lo`` and the opposite sign at ``hi``.
    An element has converged when its Newton step is at most ``tol`` (absolute,
    broadcastable); it then takes that last step and is frozen.  A bracket that
    collapses onto an interior point is a root if ``R`` is continuous there; if
    ``R`` jumps across zero instead, the element fails unless ``accept_jumps``
    (then the jump point is returned).  A bracket that collapses onto ``lo`` or
    ``hi`` means there was no sign change: no root.
    Raises :class:`ConvergenceError` naming the first failing muscle and frame.
    """
    x = np.array(x0, dtype=float)
    shape = x.shape
    lo = np.array(np.broadcast_to(lo, shape), dtype=float)
    hi = np.array(np.broadcast_to(hi, shape), dtype=float)
    tol = np.broadcast_to(np.asarray(tol, dtype=float), shape)
    lo0, hi0 = lo.copy(), hi.copy()
    done = np.zeros(shape, dtype=bool)
    step_old = hi - lo
    for _ in range(max_iter):
        r, dr = fun(x)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(r == 0.0, 0.0, r / dr)
        small = np.abs(step) <= tol
        small &= ~done
        if small.any():
            x = np.where(small, x - step, x)      # the final Newton step is nearly free accuracy
            done |= small
        if done.all():
            return x
        # Shrink the bracket with the sign of R at the current iterate.
        on_lo_side = (r * lo_sign) > 0
        lo = np.where(on_lo_side, x, lo)
        hi = np.where(on_lo_side, hi, x)
        collapsed = ((hi - lo) <= tol) & ~done
        if collapsed.any():
            # A bracket that shrank onto an interior point holds a root (the
            # residual changes sign across it); one stuck at an end of the
            # admissible interval means there was no sign change to begin with.
            stuck = collapsed & ((lo <= lo0) | (hi >= hi0))
            if stuck.any():
                _fail(f"{what}: no solution in the admissible interval", stuck, names, inputs)
            # ...unless the residual jumps there: a continuous R is within
            # |dR| tol of zero at a bracket end that is tol away from the root.
            jump = collapsed & ~(np.abs(r) <= 1e3 * np.abs(dr) * tol)
            if not accept_jumps and jump.any():
                _fail(f"{what}: the residual is discontinuous at the solution", jump, names,
                      inputs)
            x = np.where(collapsed, 0.5 * (lo + hi), x)
            done |= collapsed
            if done.all():
                return x
        x_newton = x - step
        # Newton is accepted inside the bracket and while it at least halves the
        # step every two iterations; otherwise bisect (guaranteed progress).
        ok = (x_newton > lo) & (x_newton < hi) & (np.abs(2.0 * step) <= np.abs(step_old))
        mid = 0.5 * (lo + hi)
        x_new = np.where(ok, x_newton, mid)
        step_old = np.where(ok, step, 0.5 * (hi - lo))
        x = np.where(done, x, x_new)
    _fail(f"{what}: no convergence in {max_iter} iterations", ~done, names, inputs)


def compliant_equilibrium(l_mt, *, l_opt, l_slack, height,
                          tendon: Callable, tendon_strain: Callable, fiber: Callable,
                          v_mt=None, v_scale=1.0, tol: float = 1e-10, max_iter: int = 100,
                          names: Sequence[str] | None = None,
                          inputs: Mapping[str, np.ndarray] | None = None):
    """Fiber length where tendon and fiber forces balance along the line of action.

    Solves ``R(x) = f_t(eps(x)) - f_fib(l_ce(x), v_ce) cos(alpha(x)) = 0`` for the
    fiber projection ``x`` in ``(0, l_mt - l_slack]`` (normalized forces):
    at ``x -> 0`` the fiber is fully pennated and R >= 0, at ``x = l_mt - l_slack``
    the tendon is slack and R <= 0.  Tolerance: ``|dx| <= tol * l_opt``.

    ``tendon(eps) -> (f_t, df_t/deps)``, ``tendon_strain(f_t) -> eps``,
    ``fiber(l_norm, v_norm) -> (f_fib, df_fib/dl_norm)`` with ``v_norm = None``
    meaning isometric (v_ce = 0).

    With ``v_mt`` given, the fiber velocity is the quasi-static series-stiffness
    share of ``v_mt`` (``x' = k_t v_mt / (k_t + k_m)`` with the isometric fiber
    stiffness ``k_m >= 0`` along the line of action, negative values on the
    descending limb counted as 0; OpenSim's initialisation heuristic): a
    consistent initial state, not an exact one.  The share inherits the jumps
    of the tendon stiffness (at slack, and at the Thelen toe where the thesis
    constants leave a 0.07 % slope step); a root that falls on such a jump is
    returned at the jump, with a residual no larger than the jump (~1e-5 F_max).

    Returns ``(l_ce, v_ce, f_t, cos_alpha)``.
    """
    l_mt = np.asarray(l_mt, dtype=float)
    dynamic = v_mt is not None
    shape = np.broadcast_shapes(l_mt.shape, np.shape(l_opt), np.shape(l_slack), np.shape(height),
                                *(np.shape(v) for v in (inputs or {}).values()),
                                np.shape(v_mt) if dynamic else ())
    hi = np.broadcast_to(l_mt - l_slack, shape)
    check_along_positive(hi, l_mt, names, what="compliant-tendon equilibrium")
    h2 = np.asarray(height, dtype=float) ** 2
    inv_lopt = 1.0 / np.asarray(l_opt, dtype=float)
    inv_ls = 1.0 / np.asarray(l_slack, dtype=float)
    lmt_ls = l_mt * inv_ls - 1.0                       # eps = lmt_ls - x / l_slack

    def kinematics(x):
        l = np.sqrt(x * x + h2)
        inv_l = 1.0 / l
        cos = x * inv_l
        f_t, k_t = tendon(lmt_ls - x * inv_ls)
        return l, inv_l, cos, f_t, k_t

    def velocity(l, inv_l, cos, k_t):
        f0, df0 = fiber(l * inv_lopt, None)
        k_m = df0 * (cos * cos) * inv_lopt + f0 * h2 * inv_l * inv_l * inv_l
        # A negative fiber stiffness (descending limb) would let k_t + k_m pass
        # through zero and the share through a pole; count it as zero, so the
        # share stays in [0, 1] and continuous in x (1: the fiber takes it all).
        k_m = np.maximum(k_m, 0.0)
        k_tx = k_t * inv_ls
        den = k_tx + k_m
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(den > 0, k_tx / den, 1.0)
        return cos * share * v_mt

    def residual(x):
        l, inv_l, cos, f_t, k_t = kinematics(x)
        v_norm = velocity(l, inv_l, cos, k_t) / v_scale if dynamic else None
        f, df = fiber(l * inv_lopt, v_norm)
        r = f_t - f * cos
        # dR/dx: tendon stiffness plus the fiber's along-line stiffness
        # d(f cos)/dx = f' cos^2 / l_opt + f h^2 / l^3 (velocity held fixed).
        dr = -k_t * inv_ls - (df * (cos * cos) * inv_lopt + f * h2 * inv_l * inv_l * inv_l)
        return r, dr

    # Initial guess: the fiber force at the rigid-tendon length stretches the
    # tendon by the inverse tendon curve; one cheap step that lands close to the
    # root for stiff tendons.
    l_r = np.sqrt(hi * hi + h2)
    cos_r = hi / l_r
    f_r, _ = fiber(l_r * inv_lopt, None)
    x0 = l_mt - l_slack * (1.0 + tendon_strain(f_r * cos_r))
    x0 = np.where(x0 > 0.0, x0, 0.5 * hi)
    x0 = np.broadcast_to(x0, shape)
    x = safeguarded_newton(residual, x0, 0.0, hi, lo_sign=1.0,
                           tol=tol * np.broadcast_to(l_opt, shape), max_iter=max_iter,
                           what="compliant-tendon fiber equilibrium" + (
                               " (with v_mt: the unit may shorten faster than the fiber can at "
                               "this activation; use the isometric equilibrium, v_mt=None)"
                               if dynamic else ""),
                           names=names, inputs=inputs, accept_jumps=dynamic)
    l, inv_l, cos, f_t, k_t = kinematics(x)
    v = velocity(l, inv_l, cos, k_t) if dynamic else np.zeros(shape)
    return l, v, f_t, cos
