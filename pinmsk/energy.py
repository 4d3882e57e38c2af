"""Muscle metabolic energy rate models (thesis App. B): Bhargava 2004 and Umberger 2003.

Both give the total rate ``E' = H' + W'`` (thesis Eq. B.1) in W for each
muscle and frame, with the contractile work rate ``W' = -F_ce v_ce`` (Eq. B.2;
``F_ce >= 0`` the contractile force in N, ``v_ce`` in m/s, negative when
shortening) and muscle mass ``m = rho l_opt F_max / sigma`` (Eq. B.3,
``rho = 1059.7 kg/m^3``, ``sigma = 0.25 MPa``).

Inputs are time-first ``(N, m)`` arrays (or anything broadcastable) and
per-muscle ``(m,)`` parameters, SI units:

- ``u`` excitation, ``a`` activation (0..1);
- ``l_ce`` fibre length (m), ``v_ce`` fibre velocity (m/s);
- ``f_ce`` contractile (active fibre) force (N), ``f_isom`` the normalized
  active force-length factor ``f_L(l_ce)`` (0..1);
- ``l_opt`` (m), ``f_max`` (N), ``fast_fraction`` (0..1).

Functions return a dict of the parts (W) so they can be plotted and tested one
by one; ``"total"`` is ``E'``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["RHO_MUSCLE", "SIGMA_MUSCLE", "muscle_mass", "stimulation_time",
           "bhargava2004", "umberger2003", "metabolic_rate"]

RHO_MUSCLE = 1059.7      # kg/m^3, muscle density (Eq. B.3)
SIGMA_MUSCLE = 0.25e6    # Pa, specific tension (Eq. B.3)


def muscle_mass(l_opt, f_max):
    """Muscle mass ``rho l_opt F_max / sigma`` (kg), thesis Eq. B.3."""
    return RHO_MUSCLE * np.asarray(l_opt, dtype=float) * np.asarray(f_max, dtype=float) / SIGMA_MUSCLE


def stimulation_time(t, u, threshold: float = 0.1):
    """Running total time (s) during which ``u > threshold`` (``t_stim`` of Eq. B.7), (N, m).

    Trapezoid of the indicator: each interval counts the mean of its two end
    indicators times its length.
    """
    t = np.asarray(t, dtype=float)
    on = (np.asarray(u, dtype=float) > threshold).astype(float)
    if on.ndim == 1:
        on = on[:, None]
    out = np.zeros_like(on)
    out[1:] = np.cumsum(0.5 * (on[1:] + on[:-1]) * np.diff(t)[:, None], axis=0)
    return out


def bhargava2004(*, u, a, l_ce, v_ce, f_ce, f_isom, l_opt, f_max, fast_fraction, t_stim,
                 tau_phi: float = 0.045):
    """Bhargava et al. (2004) energy rate, thesis Eq. B.4-B.12 (W per muscle).

    ``A' = phi m (f_fast 133 u_fast + f_slow 40 u_slow)`` with
    ``u_fast = 1 - cos(pi u/2)``, ``u_slow = sin(pi u/2)``,
    ``phi = 0.06 + exp(-t_stim u / tau_phi)`` (B.5-B.7);
    ``M' = psi_H(l_ce/l_opt) m (f_fast 111 u_fast + f_slow 74 u_slow)`` (B.8-B.9);
    ``S' = -alpha v_ce`` with ``alpha = 0.16 F_iso + 0.18 F_ce`` when shortening
    and ``0.157 F_ce`` when lengthening, ``F_iso = a f_isom F_max`` the
    isometric force at the current activation and length (B.10-B.11);
    ``B' = 0.0225 m`` (B.12, W/kg times kg); ``W' = -F_ce v_ce`` (B.2).
    """
    u = np.asarray(u, dtype=float)
    m = muscle_mass(l_opt, f_max)
    ff = np.asarray(fast_fraction, dtype=float)
    fs = 1.0 - ff
    u_fast = 1.0 - np.cos(0.5 * np.pi * u)
    u_slow = np.sin(0.5 * np.pi * u)
    phi = 0.06 + np.exp(-np.asarray(t_stim, dtype=float) * u / tau_phi)
    act = phi * m * (ff * 133.0 * u_fast + fs * 40.0 * u_slow)
    ln = np.asarray(l_ce, dtype=float) / np.asarray(l_opt, dtype=float)
    psi = np.where(ln <= 0.5, 0.5 * ln, np.where(ln <= 1.0, ln,
                                                   np.where(ln <= 1.5, -2.0 * ln + 3.0, 0.0)))
    maint = psi * m * (ff * 111.0 * u_fast + fs * 74.0 * u_slow)
    v = np.asarray(v_ce, dtype=float)
    f_ce = np.asarray(f_ce, dtype=float)
    f_iso = np.asarray(a, dtype=float) * np.asarray(f_isom, dtype=float) * np.asarray(f_max, dtype=float)
    alpha = np.where(v <= 0, 0.16 * f_iso + 0.18 * f_ce, 0.157 * f_ce)
    short = -alpha * v
    basal = 0.0225 * m * np.ones_like(short)
    work = -f_ce * v
    heat = act + maint + short + basal
    return {"activation": act, "maintenance": maint, "shortening": short, "basal": basal,
            "heat": heat, "work": work, "total": heat + work}


def umberger2003(*, u, a, l_ce, v_ce, f_ce, f_isom, l_opt, f_max, fast_fraction,
                 xi: float = 1.0, v_max_slow: float = 4.0, v_max_fast: float = 10.0):
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
    """
    u = np.asarray(u, dtype=float)
    a = np.asarray(a, dtype=float)
    m = muscle_mass(l_opt, f_max)
    ff = np.asarray(fast_fraction, dtype=float)
    fs = 1.0 - ff
    beta = np.where(u > a, u, 0.5 * (u + a))
    beta = np.maximum(beta, 0.0)
    h_am = 128.0 * ff + 25.0
    a_st = 100.0 / v_max_slow
    a_ft = 153.0 / v_max_fast
    a_l = 4.0 * a_st
    l_opt = np.asarray(l_opt, dtype=float)
    vt = np.asarray(v_ce, dtype=float) / l_opt
    long = np.asarray(l_ce, dtype=float) > l_opt
    fl = np.asarray(f_isom, dtype=float)
    am_scale = np.where(long, 0.4 + 0.6 * fl, 1.0)
    sl_scale = np.where(long, fl, 1.0)
    maint = h_am * beta ** 0.6 * xi * am_scale
    slow_term = np.minimum(-a_st * fs * vt, 100.0)          # capped at 100 W/kg (thesis)
    shorten = (slow_term - a_ft * ff * vt) * beta ** 0.2 * xi
    lengthen = a_l * vt * beta * xi
    sl = np.where(vt <= 0, shorten, lengthen) * sl_scale
    h = np.maximum(maint + sl, 1.0)
    heat = m * h
    f_ce = np.asarray(f_ce, dtype=float)
    work = -f_ce * np.asarray(v_ce, dtype=float)
    return {"activation_maintenance": m * maint, "shortening_lengthening": m * sl,
            "specific_heat": h, "heat": heat, "work": work, "total": heat + work}


def metabolic_rate(model_name: str, **kw):
    """Dispatch by name: ``"umberger2003"`` or ``"bhargava2004"`` (``t_stim`` needed for the latter)."""
    from .errors import ModelError
    if model_name == "umberger2003":
        kw.pop("t_stim", None)
        return umberger2003(**kw)
    if model_name == "bhargava2004":
        return bhargava2004(**kw)
    raise ModelError(f"unknown metabolic model '{model_name}'; valid: umberger2003, bhargava2004")
