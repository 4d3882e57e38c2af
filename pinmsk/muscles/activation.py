"""Activation dynamics: excitation u -> activation a, forward and inverse (thesis App. A.1-A.2).

All functions are elementwise over broadcastable arrays (scalars, ``(m,)``,
``(N, m)``).  Time constants are in seconds.

- :func:`he_activation_rate` -- He et al., thesis Eq. A.1.
- :func:`activation_rate` -- Winters & Stark, thesis Eq. A.2-A.4
  (``tau_rise = 0.011 s``, ``tau_fall = 0.068 s``).
- :func:`excitation_from_activation` -- its exact inverse, thesis Eq. A.5.
- :func:`activation_from_excitation` -- integrates A.2 over a sampled excitation.
"""
from __future__ import annotations

import numpy as np

from ..errors import TrialError
from ._common import as_array, check_finite

__all__ = ["TAU_RISE", "TAU_FALL", "he_activation_rate", "activation_rate",
           "excitation_from_activation", "activation_from_excitation"]

TAU_RISE = 0.011  # s, activation time constant (thesis A.2.1, from [2, 12])
TAU_FALL = 0.068  # s, deactivation time constant


def _rates(tau_rise: float, tau_fall: float) -> tuple[float, float]:
    """``(t1, t2)`` of thesis Eq. A.3-A.4; t1 > 0 needs tau_rise < tau_fall."""
    if not (tau_rise > 0 and tau_fall > 0):
        raise TrialError(f"activation time constants must be > 0 (tau_rise={tau_rise}, "
                         f"tau_fall={tau_fall})")
    t2 = 1.0 / tau_fall
    t1 = 1.0 / tau_rise - t2
    return t1, t2


def he_activation_rate(u, a, *, tau_rise: float = 0.015, tau_fall: float = 0.050):
    """He et al. activation rate ``adot = (u - a)(t1 u + t2)``, thesis Eq. A.1.

    One expression for rise and fall; the thesis quotes tau_rise ~ 15 ms and
    tau_fall ~ 50 ms for this model, which are the defaults.
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    u = np.asarray(u, dtype=float)
    a = np.asarray(a, dtype=float)
    return (u - a) * (t1 * u + t2)


def activation_rate(u, a, *, tau_rise: float = TAU_RISE, tau_fall: float = TAU_FALL):
    """Winters & Stark activation rate, thesis Eq. A.2-A.4.

    ``adot = (u - a)(t1 u + t2)`` when ``u >= a`` (activation) and
    ``(u - a) t2`` when ``u < a`` (deactivation), with ``t2 = 1/tau_fall`` and
    ``t1 = 1/tau_rise - t2``.  For ``u >= 0`` the factor ``t1 u + t2`` is
    positive, so ``u >= a`` if and only if ``adot >= 0`` (the thesis' remark),
    which is what makes :func:`excitation_from_activation` an exact inverse.
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    u = np.asarray(u, dtype=float)
    a = np.asarray(a, dtype=float)
    d = u - a
    # deactivation uses t2 only: the rise term t1*u is switched off when u < a.
    return d * (t2 + t1 * u * (d >= 0))


def excitation_from_activation(a, adot, *, tau_rise: float = TAU_RISE,
                               tau_fall: float = TAU_FALL):
    """Inverse Winters & Stark activation dynamics: excitation ``u`` from ``(a, adot)``, Eq. A.5.

    ``adot >= 0``: the positive root of ``t1 u^2 + (t2 - a t1) u - a t2 - adot = 0``,
    ``u = (a t1 - t2 + sqrt((a t1 + t2)^2 + 4 adot t1)) / (2 t1)``;
    ``adot < 0``: ``u = (adot + t2 a) / t2``.

    The positive root is evaluated as ``u = a + 2 adot / (B + sqrt(B^2 + 4 t1 adot))``
    with ``B = a t1 + t2`` -- algebraically identical to Eq. A.5 but free of the
    cancellation in ``a t1 - t2 + sqrt(...)`` when ``adot`` is small.
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    a = np.asarray(a, dtype=float)
    adot = np.asarray(adot, dtype=float)
    rising = adot >= 0
    b = a * t1 + t2
    pos = np.where(rising, adot, 0.0)          # keep the sqrt argument >= b^2 on both branches
    u_rise = a + 2.0 * pos / (b + np.sqrt(b * b + 4.0 * t1 * pos))
    u_fall = a + adot / t2
    return np.where(rising, u_rise, u_fall)


def activation_from_excitation(t, u, a0=None, *, tau_rise: float = TAU_RISE,
                               tau_fall: float = TAU_FALL):
    """Activation ``a`` (N, m) from a sampled excitation ``u`` (N, m) at times ``t`` (N,), Eq. A.2.

    Method: over each sample interval the excitation is replaced by its mean
    (the trapezoid of the two samples) and Eq. A.2 is solved *exactly* for that
    constant excitation: ``a(t+h) = u_m - (u_m - a) exp(-k h)`` with
    ``k = t1 u_m + t2`` when ``u_m >= a`` and ``k = t2`` otherwise (the branch
    cannot change within a step because ``a`` approaches ``u_m`` monotonically).
    This is second-order accurate in the sample interval for smooth ``u``,
    unconditionally stable and keeps ``a`` between the excitation bounds, so
    coarse EMG sampling cannot make it blow up as explicit RK4 would
    (RK4 needs ``h < 2.8 tau_rise ~ 30 ms``).

    The recurrence is sequential in time; the loop runs over frames with all
    muscles vectorised and the exponentials precomputed for all frames.

    ``a0`` defaults to ``u[0]`` (steady state, ``adot = 0`` at the first sample).
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    t = as_array(t, "t")
    u = as_array(u, "u")
    squeeze = u.ndim == 1
    if squeeze:
        u = u[:, None]
    if u.ndim != 2 or t.ndim != 1 or t.shape[0] != u.shape[0]:
        raise TrialError(f"activation_from_excitation needs t (N,) and u (N, m) with the same N; "
                         f"got t {t.shape} and u {u.shape}")
    check_finite(t=t, u=u)
    h = np.diff(t)
    if (h <= 0).any():
        k = int(np.flatnonzero(h <= 0)[0])
        raise TrialError(f"time must increase strictly; t[{k + 1}] = {t[k + 1]} <= t[{k}] = {t[k]}")
    n, m = u.shape
    a = np.empty_like(u)
    if a0 is not None:
        check_finite(a0=a0)
    a[0] = u[0] if a0 is None else np.broadcast_to(as_array(a0, "a0"), (m,))
    if n == 1:
        return a[:, 0] if squeeze else a
    um = 0.5 * (u[1:] + u[:-1])                       # (N-1, m) step excitations
    e_rise = np.exp(-(t1 * um + t2) * h[:, None])     # decay factors of both branches
    e_fall = np.exp(-t2 * h)[:, None] * np.ones((1, m))
    prev = a[0].copy()
    for k in range(n - 1):
        d = um[k] - prev
        prev = um[k] - d * np.where(d >= 0, e_rise[k], e_fall[k])
        a[k + 1] = prev
    return a[:, 0] if squeeze else a
