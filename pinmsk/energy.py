"""Muscle metabolic energy rate models (thesis App. B): Bhargava 2004 and Umberger 2003.

Both give the total rate ``E' = H' + W'`` (thesis Eq. B.1) in W for each
muscle and frame, with the contractile work rate ``W' = -F_ce v_ce`` (Eq. B.2;
``F_ce >= 0`` the contractile force in N, ``v_ce`` in m/s, negative when
shortening) and muscle mass ``m = rho l_opt F_max / sigma`` (Eq. B.3,
``rho = 1059.7 kg/m^3``, ``sigma = 0.25 MPa``).

Inputs are time-first ``(N, m)`` arrays (or anything broadcastable) and
per-muscle ``(m,)`` parameters, SI units:

- ``u`` excitation, ``a`` activation (0..1);
- ``l_ce`` fiber length (m), ``v_ce`` fiber velocity (m/s);
- ``f_ce`` contractile (active fiber) force (N), ``f_isom`` the normalized
  active force-length factor ``f_L(l_ce)`` (0..1);
- ``l_opt`` (m), ``f_max`` (N), ``fast_fraction`` (0..1).

Functions return a dict of the parts (W) so they can be plotted and tested one
by one; ``"total"`` is ``E'``.  The signals may be CasADi values (the parameters stay
numpy): the same code gives the optimal-control engine's cost and its exact
derivatives (:mod:`pinmsk.backend`; use ``smooth > 0`` there).
"""
from __future__ import annotations

import numpy as np

from .backend import backend_of
from .errors import ModelError

__all__ = ["RHO_MUSCLE", "SIGMA_MUSCLE", "muscle_mass", "stimulation_time",
           "bhargava2004", "umberger2003", "metabolic_rate", "smooth_step", "smooth_relu",
           "smooth_clip", "smooth_power", "SMOOTH_WIDTH"]

RHO_MUSCLE = 1059.7      # kg/m^3, muscle density (Eq. B.3)
SIGMA_MUSCLE = 0.25e6    # Pa, specific tension (Eq. B.3)


SMOOTH_WIDTH = 0.01     # default width of the C1 switches used inside optimizations


# -- C1 (in fact C-infinity) versions of the switches --------------------------------------
# The heat-rate models are piecewise: ``u > a`` (B.17), ``v <= 0`` (B.11, B.15-B.16),
# ``l_ce <= l_opt`` (B.15-B.16), the pieces of psi_H (B.9), the 100 W/kg cap and 1 W/kg
# floor (B.13-B.21) and the clipping of u and a to [0, 1].  A gradient-based optimizer
# (SLSQP) stalls on their kinks, so ``smooth=w > 0`` replaces every switch by a C1 blend of
# width ``w``: a step ``x > 0`` by the logistic ``smooth_step(x, w)``; ``max(x, 0)`` by a
# quadratic corner ``smooth_relu`` (exact for |x| >= w/2, error <= w/8);
# ``clip(x, 0, 1)`` by ``smooth_clip`` (exact inside [0, 1], quadratic corners outside);
# and ``beta^p`` (p = 0.6, 0.2: infinite slope at 0) by ``smooth_power``, exact for
# ``beta >= w`` and the C1 quadratic through 0 below.  Arguments of the switches are
# normalized so that one ``w`` fits them all: u, a, l_ce / l_opt and v_ce / l_opt (1/s)
# switch with width w; the cap (100 W/kg) and the floor (1 W/kg) with width w x 100 W/kg.  ``smooth=0`` is the exact model; as ``w -> 0`` the smooth models
# converge to it, with errors O(w) (O(w^p) within beta < w) (tests/test_energy.py).

def smooth_step(x, w):
    """Logistic step ``1 / (1 + exp(-x / w))`` (the Heaviside ``x > 0`` when ``w = 0``)."""
    xp = backend_of(x)
    x = xp.asarray(x)
    if w <= 0:
        return xp.where(x > 0, 1.0, 0.0) if xp.symbolic else (x > 0).astype(float)
    return 0.5 * (1.0 + xp.tanh(0.5 * x / w))


def _corner(x, w):
    """One-sided C1 ``max(x, 0)``: 0 for x <= 0, ``x^2/(2w)`` on [0, w], ``x - w/2`` above."""
    xp = backend_of(x)
    xc = xp.clip(x, 0.0, w)
    return xc * xc / (2.0 * w) + xp.maximum(x - w, 0.0)


def smooth_relu(x, w):
    """C1 ``max(x, 0)``: exact for ``|x| >= w/2``, ``(x + w/2)^2 / (2w)`` between (error
    <= w/8 at 0); ``np.maximum(x, 0)`` when ``w = 0``."""
    xp = backend_of(x)
    x = xp.asarray(x)
    if w <= 0:
        return xp.maximum(x, 0.0)
    return _corner(x + 0.5 * w, w)


def smooth_clip(x, lo, hi, w):
    """C1 ``clip(x, lo, hi)``: exact inside [lo, hi]; outside, a quadratic corner of width
    ``w`` levels off at ``lo - w/2`` and ``hi + w/2`` (``np.clip`` when ``w = 0``)."""
    xp = backend_of(x)
    x = xp.asarray(x)
    if w <= 0:
        return xp.clip(x, lo, hi)
    return x + _corner(lo - x, w) - _corner(x - hi, w)


def smooth_power(b, p, w):
    """C1 ``max(b, 0)^p`` for 0 < p < 1: exact for ``b >= w``; below, the quadratic
    ``w^p ((2 - p) b/w + (p - 1) (b/w)^2)`` that matches value and slope at ``w`` and is 0
    at 0 (negative for b < 0; callers floor the total).  ``w = 0``: exact."""
    xp = backend_of(b)
    b = xp.asarray(b)
    if w <= 0:
        return xp.maximum(b, 0.0) ** p
    r = b / w
    low = w ** p * ((2.0 - p) * r + (p - 1.0) * r * r)
    return xp.where(b >= w, xp.maximum(b, w) ** p, low)


def _blend(cond_arg, when_true, when_false, w):
    """``where(cond_arg > 0, when_true, when_false)``, a logistic blend when ``w > 0``."""
    xp = backend_of(cond_arg, when_true, when_false)
    if w <= 0:
        return xp.where(xp.asarray(cond_arg) > 0, when_true, when_false)
    s = smooth_step(cond_arg, w)
    if xp.symbolic:     # the saturation guard below is a numpy round-off matter
        return s * when_true + (1.0 - s) * when_false
    with np.errstate(invalid="ignore"):   # a saturated step must not turn inf * 0 into nan
        mixed = s * when_true + (1.0 - s) * when_false
    return np.where(s == 1.0, when_true, np.where(s == 0.0, when_false, mixed))


def muscle_mass(l_opt, f_max):
    """Muscle mass ``rho l_opt F_max / sigma`` (kg), thesis Eq. B.3."""
    return RHO_MUSCLE * np.asarray(l_opt, dtype=float) * np.asarray(f_max, dtype=float) / SIGMA_MUSCLE


def stimulation_time(t, u, threshold: float = 0.1, *, smooth: float = 0.0):
    """Running total time (s) during which ``u > threshold`` (``t_stim`` of Eq. B.7), (N, m).

    Trapezoid of the indicator: each interval counts the mean of its two end
    indicators times its length.  ``smooth = w > 0``: logistic indicator of width w.
    """
    t = np.asarray(t, dtype=float)
    on = smooth_step(np.asarray(u, dtype=float) - threshold, smooth)
    if on.ndim == 1:
        on = on[:, None]
    out = np.zeros_like(on)
    out[1:] = np.cumsum(0.5 * (on[1:] + on[:-1]) * np.diff(t)[:, None], axis=0)
    return out


def bhargava2004(*, u, a, l_ce, v_ce, f_ce, f_isom, l_opt, f_max, fast_fraction, t_stim,
                 tau_phi: float = 0.045, smooth: float = 0.0):
    """Bhargava et al. (2004) energy rate, thesis Eq. B.4-B.12 (W per muscle).

    ``A' = phi m (f_fast 133 u_fast + f_slow 40 u_slow)`` with
    ``u_fast = 1 - cos(pi u/2)``, ``u_slow = sin(pi u/2)``,
    ``phi = 0.06 + exp(-t_stim u / tau_phi)`` (B.5-B.7);
    ``M' = psi_H(l_ce/l_opt) m (f_fast 111 u_fast + f_slow 74 u_slow)`` (B.8-B.9);
    ``S' = -alpha v_ce`` with ``alpha = 0.16 F_iso + 0.18 F_ce`` when shortening
    and ``0.157 F_ce`` when lengthening, ``F_iso = a f_isom F_max`` the
    isometric force at the current activation and length (B.10-B.11);
    ``B' = 0.0225 m`` (B.12, W/kg times kg); ``W' = -F_ce v_ce`` (B.2).

    ``smooth = w > 0`` gives the C1 version used inside optimizations (switches
    blended over width w, see the module notes; ``t_stim`` should then come from
    ``stimulation_time(..., smooth=w)``); ``w = 0`` is the exact model.
    """
    w = float(smooth)
    xp = backend_of(u, a, l_ce, v_ce, f_ce, f_isom, t_stim)
    u = xp.asarray(u)
    m = muscle_mass(l_opt, f_max)
    ff = np.asarray(fast_fraction, dtype=float)
    fs = 1.0 - ff
    u_fast = 1.0 - xp.cos(0.5 * np.pi * u)
    u_slow = xp.sin(0.5 * np.pi * u)
    phi = 0.06 + xp.exp(-xp.asarray(t_stim) * u / tau_phi)
    act = phi * m * (ff * 133.0 * u_fast + fs * 40.0 * u_slow)
    ln = xp.asarray(l_ce) / np.asarray(l_opt, dtype=float)
    if w <= 0:
        psi = xp.where(ln <= 0.5, 0.5 * ln, xp.where(ln <= 1.0, ln,
                                                       xp.where(ln <= 1.5, -2.0 * ln + 3.0, 0.0)))
    else:   # the same pieces, switched on one after the other by logistic steps
        p0, p1, p2 = 0.5 * ln, ln, -2.0 * ln + 3.0
        psi = (p0 + smooth_step(ln - 0.5, w) * (p1 - p0) + smooth_step(ln - 1.0, w) * (p2 - p1)
               + smooth_step(ln - 1.5, w) * (0.0 - p2))
    maint = psi * m * (ff * 111.0 * u_fast + fs * 74.0 * u_slow)
    v = xp.asarray(v_ce)
    f_ce = xp.asarray(f_ce)
    f_iso = xp.asarray(a) * xp.asarray(f_isom) * np.asarray(f_max, dtype=float)
    alpha = _blend(v / np.asarray(l_opt, dtype=float), 0.157 * f_ce, 0.16 * f_iso + 0.18 * f_ce, w)
    short = -alpha * v
    basal = 0.0225 * m * (0.0 * short + 1.0) if xp.symbolic else 0.0225 * m * np.ones_like(short)
    work = -f_ce * v
    heat = act + maint + short + basal
    return {"activation": act, "maintenance": maint, "shortening": short, "basal": basal,
            "heat": heat, "work": work, "total": heat + work}


def umberger2003(*, u, a, l_ce, v_ce, f_ce, f_isom, l_opt, f_max, fast_fraction,
                 xi: float = 1.0, v_max_slow: float = 4.0, v_max_fast: float = 10.0,
                 smooth: float = 0.0):
    """Umberger et al. (2003) energy rate, thesis Eq. B.13-B.21 (W per muscle).

    Mass-specific heat rate ``h'`` (W/kg): with ``beta`` = ``u`` if ``u > a``
    else ``(u + a)/2`` (B.17), ``h_AM = 128 f_fast + 25`` (B.18),
    ``alpha_S(ST) = 100 / v_max(ST)``, ``alpha_S(FT) = 153 / v_max(FT)``,
    ``alpha_L = 4 alpha_S(ST)`` (B.19-B.21), ``v~ = v_ce / l_opt`` (1/s):

    - ``l_ce <= l_opt`` (B.15): ``h_AM beta^0.6 xi`` plus, shortening,
      ``-v~ beta^0.2 xi (alpha_S(ST) f_slow + alpha_S(FT) f_fast)`` or,
      lengthening, ``alpha_L v~ beta xi``;
    - ``l_ce > l_opt`` (B.16): the maintenance part times ``0.4 + 0.6 f_isom`` and
      the velocity parts times ``f_isom``.

    As the thesis states, ``-alpha_S(ST) f_slow v~`` is capped at 100 W/kg and
    the total ``h'`` is floored at 1.0 W/kg.  ``H' = m h'`` (B.13),
    ``E' = H' + W'`` with ``W' = -F_ce v_ce``.  ``xi = 1.0`` (anaerobic-type
    movement) as for the thesis's forearm; 1.5 for gait.

    ``smooth = w > 0`` gives the C1 version used inside optimizations: the
    ``u > a``, ``v~ <= 0`` and ``l_ce > l_opt`` switches are logistic blends, the
    cap and the floor quadratic corners, and ``beta^0.6``, ``beta^0.2`` are
    ``smooth_power`` (finite slopes at 0; see the module notes); ``w = 0`` is
    the exact model.
    """
    w = float(smooth)
    xp = backend_of(u, a, l_ce, v_ce, f_ce, f_isom)
    u = xp.asarray(u)
    a = xp.asarray(a)
    m = muscle_mass(l_opt, f_max)
    ff = np.asarray(fast_fraction, dtype=float)
    fs = 1.0 - ff
    if w <= 0:
        beta = xp.where(u > a, u, 0.5 * (u + a))
        beta = xp.maximum(beta, 0.0)
    else:   # u if u > a else (u + a)/2  ==  (u + a)/2 + max(u - a, 0)/2
        beta = 0.5 * (u + a) + 0.5 * smooth_relu(u - a, w)
    h_am = 128.0 * ff + 25.0
    a_st = 100.0 / v_max_slow
    a_ft = 153.0 / v_max_fast
    a_l = 4.0 * a_st
    l_opt = np.asarray(l_opt, dtype=float)
    vt = xp.asarray(v_ce) / l_opt
    dl = xp.asarray(l_ce) / l_opt - 1.0          # > 0: long fiber
    fl = xp.asarray(f_isom)
    am_scale = _blend(dl, 0.4 + 0.6 * fl, 1.0, w)
    sl_scale = _blend(dl, fl, 1.0, w)
    maint = h_am * smooth_power(beta, 0.6, w) * xi * am_scale
    x_slow = -a_st * fs * vt                                    # capped at 100 W/kg (thesis)
    slow_term = x_slow - smooth_relu(x_slow - 100.0, 100.0 * w)   # widths: w x 100 W/kg
    shorten = (slow_term - a_ft * ff * vt) * smooth_power(beta, 0.2, w) * xi
    lengthen = a_l * vt * beta * xi
    sl = _blend(vt, lengthen, shorten, w) * sl_scale
    h = 1.0 + smooth_relu(maint + sl - 1.0, 100.0 * w)         # floored at 1 W/kg (thesis)
    heat = m * h
    f_ce = xp.asarray(f_ce)
    work = -f_ce * xp.asarray(v_ce)
    return {"activation_maintenance": m * maint, "shortening_lengthening": m * sl,
            "specific_heat": h, "heat": heat, "work": work, "total": heat + work}


def metabolic_rate(model_name: str, **kw):
    """Dispatch by name: ``"umberger2003"`` or ``"bhargava2004"`` (``t_stim`` needed for the latter)."""
    if model_name == "umberger2003":
        kw.pop("t_stim", None)
        return umberger2003(**kw)
    if model_name == "bhargava2004":
        return bhargava2004(**kw)
    raise ModelError(f"unknown metabolic model '{model_name}'; valid: umberger2003, bhargava2004")
