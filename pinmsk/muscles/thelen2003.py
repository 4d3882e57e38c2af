"""Thelen 2003 Hill-type muscle: force-length, force-velocity, equilibrium, contraction dynamics.

Thesis App. A.3 (Eq. A.6-A.9).  Pure, elementwise functions over broadcastable
arrays; the :class:`pinmsk.muscles.Thelen2003` object binds per-muscle
parameters to them.  The curves (force-length, passive, force-velocity without
``smooth``, :func:`thelen_fiber_force`) also take CasADi values (:mod:`pinmsk.backend`),
so the optimal-control engine differentiates this same code.  Conventions:

- lengths normalized by ``l_opt`` (``l_norm = l_ce / l_opt``);
- fiber velocity normalized by ``v_max`` (``v_norm = v_ce / v_max``,
  ``v_max = 10 l_opt /s`` by default), negative when shortening;
- forces normalized by ``F_max``.

Force-velocity (Eq. A.9).  Writing ``s = 0.25 + 0.75 a`` (the activation
scaling of the maximum shortening velocity) and ``w = v_norm / s``, Eq. A.9 is
equivalent to ``f_ce = a f_isom fv(w)`` with

    fv(w) = (1 + w) / (1 - w/A_f)                     -1 <= w <= 0 (concentric)
    fv(w) = (1 + c f_hat w) / (1 + c w),  c = (2 + 2/A_f)/(f_hat - 1)     w > 0

so ``fv(0) = 1``, ``fv(-1) = 0`` and ``fv -> f_hat`` for fast lengthening.
Eq. A.9 as printed cannot be solved for velocity beyond ``f_ce = 0`` or near
the eccentric asymptote ``f_hat a f_isom`` (the velocity is unbounded there),
which a forward simulation does reach.  As in Thelen (2003) and OpenSim's
Thelen2003Muscle we continue the curve linearly (C1) below ``w = -1`` and
above ``fv = 0.95 f_hat``; the velocity-from-force and force-from-velocity
functions here are exact inverses of each other including these extensions.
Between them, they are Eq. A.9 exactly.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..backend import backend_of
from ..errors import ConvergenceError
from ._common import check_active, locate, where_first
from ._solve import compliant_equilibrium, safeguarded_newton
from .pennation import check_along_positive, pennation_height
from .tendon import TENDON_STRAIN0, thelen_tendon_force, thelen_tendon_stiffness, thelen_tendon_strain

__all__ = [
    "K_PE", "PASSIVE_STRAIN0", "GAMMA", "A_F", "F_HAT", "FV_EXTRAPOLATION",
    "thelen_passive_force_length", "thelen_passive_force_length_derivative",
    "thelen_active_force_length", "thelen_active_force_length_derivative",
    "thelen_force_velocity", "thelen_force_velocity_derivative", "thelen_force_velocity_inverse",
    "thelen_fiber_velocity", "thelen_fiber_force", "thelen_fiber_force_partials",
    "thelen_activation_from_force", "thelen_equilibrium", "thelen_contraction_rate",
]

K_PE = 5.0               # passive shape factor (Eq. A.7)
PASSIVE_STRAIN0 = 0.6    # passive muscle strain at F_max, young adults (Eq. A.7)
GAMMA = 0.45             # active force-length shape factor (Eq. A.8)
A_F = 0.25               # force-velocity shape factor (Eq. A.9)
F_HAT = 1.4              # asymptotic eccentric force, young adults (Eq. A.9)
FV_EXTRAPOLATION = 0.95  # fraction of f_hat above which fv continues linearly (Thelen 2003)



def _fv_constants(a_f, f_hat, extrapolation):
    """``(c, p_thr, w_thr, k_con, k_ecc)`` of the force-velocity curve with shape factor ``a_f``,
    eccentric asymptote ``f_hat`` and linear-tail threshold ``extrapolation`` (module docstring)."""
    c = (2.0 + 2.0 / a_f) / (f_hat - 1.0)               # eccentric hyperbola rate
    p_thr = extrapolation * f_hat                       # fv where the linear tail starts
    w_thr = (p_thr - 1.0) / (c * (f_hat - p_thr))       # w where it starts
    k_con = a_f / (1.0 + a_f)                           # slope of the tail below w = -1
    k_ecc = c * (f_hat - 1.0) / (1.0 + c * w_thr) ** 2  # slope of the tail above w_thr
    return c, p_thr, w_thr, k_con, k_ecc


# Derived force-velocity constants of the thesis values (see the module docstring).
_C, _P_THR, _W_THR, _K_CON, _K_ECC = _fv_constants(A_F, F_HAT, FV_EXTRAPOLATION)
_PE_SCALE = 1.0 / math.expm1(K_PE)


# --------------------------------------------------------------------------- curves
def thelen_passive_force_length(l_norm, *, k_pe=K_PE, strain0=PASSIVE_STRAIN0):
    """Parallel elastic force, thesis Eq. A.7: ``(exp(k_pe (l - 1)/strain0) - 1)/(exp(k_pe) - 1)``.

    Zero below optimal length: the parallel element is slack there (the
    printed formula would give a small negative force; OpenSim clips too).
    Any backend; ``k_pe`` and ``strain0`` may be per-muscle arrays.
    """
    xp = backend_of(l_norm)
    d = xp.maximum(xp.asarray(l_norm) - 1.0, 0.0)
    return xp.expm1((k_pe / strain0) * d) / np.expm1(k_pe)


def thelen_passive_force_length_derivative(l_norm, *, k_pe=K_PE, strain0=PASSIVE_STRAIN0):
    """d f_pe / d l_norm of Eq. A.7 (right derivative at l_norm = 1, zero below); any backend."""
    xp = backend_of(l_norm)
    l = xp.asarray(l_norm)
    rate = k_pe / strain0
    return xp.where(l >= 1.0, rate * xp.exp(rate * xp.maximum(l - 1.0, 0.0)) / np.expm1(k_pe), 0.0)


def thelen_active_force_length(l_norm, *, gamma=GAMMA):
    """Thelen 2003 active force-length ``f_isom = exp(-(l - 1)^2 / gamma)``, thesis Eq. A.8; any backend,
    ``gamma`` may be a per-muscle array."""
    xp = backend_of(l_norm)
    d = xp.asarray(l_norm) - 1.0
    return xp.exp(d * d * (-1.0 / gamma))


def thelen_active_force_length_derivative(l_norm, *, gamma=GAMMA):
    """d f_isom / d l_norm of Eq. A.8: ``-2 (l - 1)/gamma f_isom``; any backend."""
    xp = backend_of(l_norm)
    d = xp.asarray(l_norm) - 1.0
    return (-2.0 / gamma) * d * xp.exp(d * d * (-1.0 / gamma))


FV_SMOOTH_MAX = 0.03     # widest blend: the eccentric hyperbola has its pole at w = -1/_C = -0.04


def _fv_blend(w, fv, dfv, smooth):
    """Replace ``fv, dfv`` within ``|w| < smooth`` by a C2 blend of the two hyperbolas.

    The Thelen curve's slope jumps at ``w = 0`` (5 concentric, 10 eccentric).  The
    inverse muscle model's activation rate (Eq. 5.4) contains ``df/dv``, so with the
    kink the recovered excitation jumps whenever a fiber reverses.  The blend
    ``(1 - S) fv_con + S fv_ecc`` with the quintic smoothstep ``S`` of
    ``(w + smooth) / (2 smooth)`` matches each piece to the second derivative at the
    band edges; it is increasing for ``smooth <= FV_SMOOTH_MAX``.
    """
    if not 0.0 < smooth <= FV_SMOOTH_MAX:
        raise ValueError(f"force-velocity smoothing width must be in (0, {FV_SMOOTH_MAX}], "
                         f"got {smooth}")
    wb = np.clip(w, -smooth, smooth)
    s = (wb + smooth) / (2.0 * smooth)
    S = s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
    dS = 30.0 * s * s * (1.0 - s) ** 2 / (2.0 * smooth)
    den = 1.0 - wb / A_F
    con, dcon = (1.0 + wb) / den, (1.0 + 1.0 / A_F) / (den * den)
    ec = 1.0 + _C * wb
    ecc, decc = 1.0 + _C * (F_HAT - 1.0) * wb / ec, _C * (F_HAT - 1.0) / (ec * ec)
    inside = np.abs(w) < smooth
    return (np.where(inside, con + S * (ecc - con), fv),
            np.where(inside, dcon + S * (decc - dcon) + dS * (ecc - con), dfv))


def thelen_force_velocity(v_norm, *, smooth: float = 0.0, a_f=A_F, f_hat=F_HAT,
                          extrapolation=FV_EXTRAPOLATION):
    """Normalized force-velocity multiplier ``f_V(v/v_max)`` at full activation (Eq. A.9 inverted).

    ``f_V(0) = 1``, ``f_V(-1) = 0`` (maximum shortening velocity), increasing,
    ``-> 1.4`` for lengthening until the linear tail at ``0.95 * 1.4``.  At
    activation ``a`` the active fiber force is ``a f_isom f_V(v_norm / (0.25 + 0.75 a))``;
    "activation-mode" static optimization uses ``f_V(v_norm)`` (the a = 1 curve).
    ``smooth > 0`` blends the slope jump at 0 over ``|w| < smooth`` (see :func:`_fv_blend`;
    thesis shape only).  ``a_f``, ``f_hat``, ``extrapolation``: other shape factors
    (scalars or per-muscle arrays; OpenSim's Thelen2003Muscle ``Af``, ``Flen`` and
    ``fv_linear_extrap_threshold``); the defaults are the thesis values.
    """
    thesis = a_f is A_F and f_hat is F_HAT and extrapolation is FV_EXTRAPOLATION
    if smooth:
        if not thesis:
            raise ValueError("force-velocity smoothing supports the thesis shape factors only")
        w = np.asarray(v_norm, dtype=float)
        return _fv_blend(w, thelen_force_velocity(w), thelen_force_velocity_derivative(w),
                         smooth)[0]
    if thesis:
        a_f, f_hat, c, w_thr, k_con, k_ecc = A_F, F_HAT, _C, _W_THR, _K_CON, _K_ECC
    else:
        a_f, f_hat = np.asarray(a_f, dtype=float), np.asarray(f_hat, dtype=float)
        c, _, w_thr, k_con, k_ecc = _fv_constants(a_f, f_hat, np.asarray(extrapolation, dtype=float))
    xp = backend_of(v_norm)
    w = xp.asarray(v_norm)
    w1 = xp.clip(w, -1.0, 0.0)
    w2 = xp.clip(w, 0.0, w_thr)
    # Branch-free: each clipped piece is zero (or 1) outside its interval, so
    # the four pieces add up without np.where chains.
    return ((1.0 + w1) / (1.0 - w1 / a_f)
            + (c * (f_hat - 1.0)) * w2 / (1.0 + c * w2)
            + k_con * xp.minimum(w + 1.0, 0.0)
            + k_ecc * xp.maximum(w - w_thr, 0.0))


def thelen_force_velocity_derivative(v_norm, *, smooth: float = 0.0):
    """d f_V / d v_norm (left derivative at 0, where the Thelen curve has a kink: 5 vs 10;
    continuous with ``smooth > 0``, see :func:`_fv_blend`)."""
    w = np.asarray(v_norm, dtype=float)
    if smooth:
        return _fv_blend(w, thelen_force_velocity(w), thelen_force_velocity_derivative(w),
                         smooth)[1]
    w1 = np.clip(w, -1.0, 0.0)
    w2 = np.clip(w, 0.0, _W_THR)
    con = (1.0 + 1.0 / A_F) / (1.0 - w1 / A_F) ** 2
    ecc = _C * (F_HAT - 1.0) / (1.0 + _C * w2) ** 2
    return np.where(w < -1.0, _K_CON,
                    np.where(w <= 0.0, con, np.where(w < _W_THR, ecc, _K_ECC)))


def thelen_force_velocity_inverse(f_v):
    """Inverse of :func:`thelen_force_velocity`: ``v_norm`` (at a = 1) from the multiplier."""
    p = np.asarray(f_v, dtype=float)
    p1 = np.clip(p, 0.0, 1.0)
    p2 = np.clip(p, 1.0, _P_THR)
    return ((p1 - 1.0) / (1.0 + p1 / A_F)
            + (p2 - 1.0) / (_C * (F_HAT - p2))
            + np.minimum(p, 0.0) / _K_CON
            + np.maximum(p - _P_THR, 0.0) / _K_ECC)


def _speed_scale(a):
    return 0.25 + 0.75 * backend_of(a).asarray(a)


def thelen_fiber_velocity(f_ce, a, f_isom, *, v_max=1.0):
    """Fiber velocity from active fiber force, thesis Eq. A.9 (with the linear tails).

    ``v = (0.25 + 0.75 a) v_max (f - a f_isom) / b`` with
    ``b = a f_isom + f/A_f`` (concentric) or
    ``b = (2 + 2/A_f)(a f_isom f_hat - f)/(f_hat - 1)`` (eccentric).
    ``f_ce`` is the active (contractile) force normalized by F_max; the result
    is in the units of ``v_max`` (default: normalized).  Needs ``a f_isom > 0``.
    """
    f_ce = np.asarray(f_ce, dtype=float)
    a = np.asarray(a, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = thelen_force_velocity_inverse(f_ce / (a * f_isom))
    return _speed_scale(a) * v_max * w


def thelen_fiber_force(v_ce, a, f_isom, *, v_max=1.0):
    """Active fiber force (normalized) from fiber velocity: the exact inverse of Eq. A.9.

    ``f = a f_isom f_V(v / ((0.25 + 0.75 a) v_max))``.
    """
    xp = backend_of(v_ce, a, f_isom)
    a = xp.asarray(a)
    w = xp.asarray(v_ce) / (_speed_scale(a) * v_max)
    return a * f_isom * thelen_force_velocity(w)


def thelen_fiber_force_partials(v_norm, a, f_isom, *, smooth: float = 0.0):
    """``(f, df/dv_norm, df/da, df/df_isom)`` of ``f = a f_isom f_V(v_norm / s(a))``.

    ``s = 0.25 + 0.75 a``; used by the inverse model's activation rate (thesis Eq. 5.4).
    ``smooth``: width of the C2 blend at ``w = 0`` (:func:`_fv_blend`; 0 = Eq. A.9 as is).
    """
    a = np.asarray(a, dtype=float)
    s = _speed_scale(a)
    w = np.asarray(v_norm, dtype=float) / s
    fv = thelen_force_velocity(w)
    dfv = thelen_force_velocity_derivative(w)
    if smooth:
        fv, dfv = _fv_blend(w, fv, dfv, smooth)
    f = a * f_isom * fv
    df_dv = a * f_isom * dfv / s
    # dw/da = -0.75 w / s
    df_da = f_isom * (fv - 0.75 * a * w * dfv / s)
    return f, df_dv, df_da, a * fv


def thelen_activation_from_force(f_ce, f_isom, v_norm, *, tol: float = 1e-13,
                                 max_iter: int = 100, names: Sequence[str] | None = None,
                                 smooth: float = 0.0):
    """Activation ``a`` with ``a f_isom f_V(v_norm/(0.25 + 0.75 a)) = f_ce`` (thesis Eq. 5.2 for a).

    Closed form at v = 0 (``a = f_ce/f_isom``); otherwise the activation scaling of
    v_max makes it nonlinear and it is solved by vectorised safeguarded Newton
    (``a`` in ``[0, a_hi]``, residual increasing in ``a`` for ``f_ce > 0``).
    Where ``f_ce <= 0`` (the passive force alone meets or exceeds the demand)
    ``a = 0``.  ``a > 1`` is returned as is: the muscle is too weak.  ``smooth``: the
    force-velocity blend of :func:`thelen_fiber_force_partials` (0 = Eq. A.9 as is).
    """
    f_ce = np.asarray(f_ce, dtype=float)
    f_isom = np.asarray(f_isom, dtype=float)
    v_norm = np.asarray(v_norm, dtype=float)
    shape = np.broadcast_shapes(f_ce.shape, f_isom.shape, v_norm.shape)
    positive = np.broadcast_to(f_ce > 0, shape)
    fv1 = thelen_force_velocity(v_norm)
    with np.errstate(divide="ignore", invalid="ignore"):
        a0 = f_ce / (f_isom * fv1)
    a0 = np.where(np.isfinite(a0) & (a0 > 0), a0, 1.0)
    # Elements without a positive demand solve a dummy problem with root a = 1.
    target = np.where(positive, f_ce, thelen_fiber_force(v_norm, 1.0, f_isom))
    a0 = np.broadcast_to(np.where(positive, a0, 1.0), shape)

    def residual(a):
        f, _, df_da, _ = thelen_fiber_force_partials(v_norm, a, f_isom, smooth=smooth)
        return f - target, df_da

    # Upper bracket: grow until the muscle can produce the force.
    hi = np.broadcast_to(np.maximum(2.0 * a0, 1.0), shape).copy()
    for _ in range(60):
        short = residual(hi)[0] < 0
        if not short.any():
            break
        hi = np.where(short, 2.0 * hi, hi)
    else:
        frame, muscle = where_first(short)
        raise ConvergenceError(
            f"no activation produces the fiber force at {locate(frame, muscle, names)}: "
            "the force-length factor f_isom is ~0 there (fiber far from l_opt)")
    a = safeguarded_newton(residual, np.minimum(a0, hi), 0.0, hi, lo_sign=-1.0, tol=tol,
                           max_iter=max_iter, what="activation from fiber force", names=names)
    return np.where(positive, a, 0.0)


# --------------------------------------------------------------------------- muscle-tendon unit
def _fiber_closure(a, *, gamma=GAMMA, k_pe=K_PE, strain0_m=PASSIVE_STRAIN0):
    """``(l_norm, v_norm) -> (a f_isom f_V + f_pe, d/dl_norm)`` for the equilibrium solver."""
    a = np.asarray(a, dtype=float)
    rate = k_pe / strain0_m
    pe_scale = 1.0 / math.expm1(k_pe)

    def fiber(l_norm, v_norm):
        d = l_norm - 1.0
        fl = np.exp(d * d * (-1.0 / gamma))
        dpos = np.maximum(d, 0.0)
        e = np.exp(rate * dpos)
        fpe = (e - 1.0) * pe_scale
        dfpe = (rate * pe_scale) * e * (d >= 0.0)
        act = a * fl
        if v_norm is not None:
            act = act * thelen_force_velocity(v_norm / _speed_scale(a))
        f = act + fpe
        df = act * d * (-2.0 / gamma) + dfpe
        return f, df

    return fiber


def _tendon_closure(strain0):
    def tendon(eps):
        return (thelen_tendon_force(eps, strain0=strain0),
                thelen_tendon_stiffness(eps, strain0=strain0))
    return tendon


def thelen_equilibrium(l_mt, a, *, l_opt, l_slack, pennation, v_max=None, v_mt=None,
                       tendon_strain0: float = TENDON_STRAIN0, tol: float = 1e-10,
                       max_iter: int = 100, names: Sequence[str] | None = None):
    """Compliant-tendon fiber equilibrium ``F_t = (F_ce + F_pe) cos(alpha)`` (thesis App. A.3).

    Solves for ``l_ce`` at muscle-tendon length ``l_mt`` and activation ``a``,
    isometric (``v_ce = 0``) unless ``v_mt`` is given (then see
    :func:`pinmsk.muscles._solve.compliant_equilibrium` for the velocity share).
    Vectorised safeguarded Newton/bisection to ``|d l| <= tol l_opt``.
    Returns ``(l_ce, v_ce, f_t)`` with ``f_t`` the tendon force normalized by F_max.
    Raises :class:`ConvergenceError` naming the muscle and frame on failure.
    """
    l_opt = np.asarray(l_opt, dtype=float)
    v_max = 10.0 * l_opt if v_max is None else np.asarray(v_max, dtype=float)
    a = np.asarray(a, dtype=float)
    l, v, f_t, _ = compliant_equilibrium(
        l_mt, l_opt=l_opt, l_slack=l_slack, height=pennation_height(l_opt, pennation),
        tendon=_tendon_closure(tendon_strain0),
        tendon_strain=lambda f: thelen_tendon_strain(f, strain0=tendon_strain0),
        fiber=_fiber_closure(a), v_mt=v_mt, v_scale=v_max, tol=tol, max_iter=max_iter,
        names=names, inputs={"l_mt": l_mt, "a": a})
    return l, v, f_t


def thelen_contraction_rate(l_ce, l_mt, a, *, l_opt, l_slack, pennation, v_max=None,
                            tendon_strain0: float = TENDON_STRAIN0,
                            names: Sequence[str] | None = None):
    """Contraction dynamics ``l_ce' = f_CD(l_ce, l_mt, a)`` for the compliant tendon (thesis Eq. 3.9).

    The tendon force at ``l_t = l_mt - l_ce cos(alpha)`` (Eq. A.6) divided by
    ``cos(alpha)``, minus the parallel force (Eq. A.7), is the active fiber force;
    Eq. A.9 turns it into the fiber velocity (m/s).  Needs ``a > 0`` (the
    velocity is undetermined for an inactive fiber; use a minimum activation
    such as 0.01) and ``l_ce > l_opt sin(alpha_opt)``.
    """
    l_ce = np.asarray(l_ce, dtype=float)
    a = np.asarray(a, dtype=float)
    l_opt = np.asarray(l_opt, dtype=float)
    v_max = 10.0 * l_opt if v_max is None else np.asarray(v_max, dtype=float)
    check_active(a, l_ce, names)
    h = pennation_height(l_opt, pennation)
    x2 = l_ce * l_ce - h * h
    x = np.sqrt(np.maximum(x2, 0.0))
    check_along_positive(x, l_mt, names, what="contraction dynamics")
    cos = x / l_ce
    l_norm = l_ce / l_opt
    f_t = thelen_tendon_force((np.asarray(l_mt, dtype=float) - x) / l_slack - 1.0,
                              strain0=tendon_strain0)
    f_ce = f_t / cos - thelen_passive_force_length(l_norm)
    return thelen_fiber_velocity(f_ce, a, thelen_active_force_length(l_norm), v_max=v_max)
