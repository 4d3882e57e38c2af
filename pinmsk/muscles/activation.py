"""Activation dynamics: excitation u -> activation a, forward and inverse (thesis App. A.1-A.2).

All functions are elementwise over broadcastable arrays (scalars, ``(m,)``,
``(N, m)``).  Time constants are in seconds.

- :func:`he_activation_rate` -- He et al., thesis Eq. A.1.
- :func:`activation_rate` -- Winters & Stark, thesis Eq. A.2-A.4
  (``tau_rise = 0.011 s``, ``tau_fall = 0.068 s``).
- :func:`excitation_from_activation` -- its exact inverse, thesis Eq. A.5.
- :func:`held_step` -- the exact solution of A.2 over a step with the excitation held;
  :func:`held_step_excitation` its inverse, :func:`reachable_activation` the activations
  a step can reach (``u = 0`` and ``u = 1``).
- :func:`activation_from_excitation` -- integrates A.2 over a sampled excitation
  (held steps at the mean of each interval's two samples).

This is the one implementation of the law: the activation-dynamics effect
(:class:`pinmsk.effects.ActivationDynamics`), MSO, EID, FSO and the muscle
models call these functions.  The time constants broadcast like the signals
(one per muscle, or per parameter set), so a fitter or a model with
per-muscle constants runs them in one pass.  Which constants a model uses is
the model's activation component (:func:`pinmsk.effects.activation.excitation_path`);
:data:`TAU_RISE` and :data:`TAU_FALL` are Winters & Stark's values, the
default of the Thelen 2003 muscle model and of the effect.
"""
from __future__ import annotations

import numpy as np

from ..backend import backend_of
from ..errors import TrialError
from ._common import as_array, check_finite

__all__ = ["TAU_RISE", "TAU_FALL", "he_activation_rate", "activation_rate",
           "excitation_from_activation", "activation_from_excitation", "held_step", "held_step_excitation",
           "reachable_activation"]

TAU_RISE = 0.011  # s, activation time constant (thesis A.2.1, from [2, 12])
TAU_FALL = 0.068  # s, deactivation time constant


def _rates(tau_rise, tau_fall):
    """``(t1, t2)`` of thesis Eq. A.3-A.4 (scalars or broadcastable arrays); t1 > 0 needs tau_rise < tau_fall."""
    tr = np.asarray(tau_rise, dtype=float)
    tf = np.asarray(tau_fall, dtype=float)
    if not (np.all(tr > 0) and np.all(tf > 0)):
        raise TrialError(f"activation time constants must be > 0 (tau_rise={tau_rise}, "
                         f"tau_fall={tau_fall})")
    t2 = 1.0 / tf
    t1 = 1.0 / tr - t2
    if t1.ndim == 0 and t2.ndim == 0:
        return float(t1), float(t2)
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


def activation_rate(u, a, *, tau_rise: float = TAU_RISE, tau_fall: float = TAU_FALL,
                    smooth: float = 0.0):
    """Winters & Stark activation rate, thesis Eq. A.2-A.4 (numpy or CasADi inputs).

    ``adot = (u - a)(t1 u + t2)`` when ``u >= a`` (activation) and
    ``(u - a) t2`` when ``u < a`` (deactivation), with ``t2 = 1/tau_fall`` and
    ``t1 = 1/tau_rise - t2``.  For ``u >= 0`` the factor ``t1 u + t2`` is
    positive, so ``u >= a`` if and only if ``adot >= 0`` (the thesis' remark),
    which is what makes :func:`excitation_from_activation` an exact inverse.

    ``smooth = w > 0`` replaces the rise/fall switch ``u >= a`` by
    ``(1 + tanh((u - a)/w))/2``, as De Groote et al. (2016, Eq. 1-2) do, so that the
    rate is smooth for a gradient-based optimizer; ``w = 0`` (default) is Eq. A.2 as is.
    The rate itself is continuous either way (the switched term vanishes at ``u = a``);
    the blend removes the jump of its slope there.
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    xp = backend_of(u, a)
    u = xp.asarray(u)
    a = xp.asarray(a)
    d = u - a
    if smooth:
        return d * (t2 + t1 * u * (0.5 + 0.5 * xp.tanh(d / smooth)))
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


def held_step(a_prev, u, h, *, tau_rise=TAU_RISE, tau_fall=TAU_FALL):
    """Activation after ``h`` s from ``a_prev`` with the excitation ``u`` held (Eq. A.2 solved exactly).

    ``a = u - (u - a_prev) exp(-k h)`` with ``k = t1 u + t2`` when ``u >= a_prev``
    and ``k = t2`` otherwise: ``a`` approaches ``u`` monotonically, so the branch
    cannot change within the step.  Everything broadcasts.
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    a_prev = np.asarray(a_prev, dtype=float)
    u = np.asarray(u, dtype=float)
    d = u - a_prev
    k = t2 + t1 * u * (d >= 0)
    return u - d * np.exp(-k * np.asarray(h, dtype=float))


def reachable_activation(a_prev, h, *, tau_rise=TAU_RISE, tau_fall=TAU_FALL):
    """``(lo, hi)``: the activations reachable after ``h`` from ``a_prev`` with ``0 <= u <= 1`` held.

    The activation rate grows with ``u``, so the reachable set is the interval
    between :func:`held_step` at ``u = 0`` (``a_prev exp(-h / tau_fall)``) and at
    ``u = 1`` (``1 - (1 - a_prev) exp(-h / tau_rise)``); both are linear in ``a_prev``.
    """
    a_prev = np.asarray(a_prev, dtype=float)
    lo = held_step(a_prev, 0.0, h, tau_rise=tau_rise, tau_fall=tau_fall)
    hi = held_step(a_prev, 1.0, h, tau_rise=tau_rise, tau_fall=tau_fall)
    return lo, hi


def held_step_excitation(a_prev, a_next, h, *, tau_rise=TAU_RISE, tau_fall=TAU_FALL):
    """The excitation that, held over ``h``, takes ``a_prev`` to ``a_next``: the inverse of :func:`held_step`.

    Falling (``a_next < a_prev``): ``a_next = u + (a_prev - u) e^(-t2 h)``, closed form.
    Rising: ``a_next = u + (a_prev - u) e^(-(t1 u + t2) h)``, increasing in ``u``; bisection
    (60 halvings).  Results are clipped to [0, 1] (values outside come only from round-off at the bounds).
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    a_prev, a_next, h, t1, t2 = np.broadcast_arrays(np.asarray(a_prev, float), np.asarray(a_next, float),
                                                    np.asarray(h, float), np.asarray(t1, float),
                                                    np.asarray(t2, float))
    u = np.empty(a_prev.shape)
    fall = a_next < a_prev
    e = np.exp(-t2 * h)
    with np.errstate(divide="ignore", invalid="ignore"):
        u_fall = (a_next - a_prev * e) / (1.0 - e)
    u[fall] = u_fall[fall]
    rise = ~fall
    if rise.any():
        ap, an, hh, r1, r2 = a_prev[rise], a_next[rise], h[rise], t1[rise], t2[rise]
        lo = ap.copy()              # u = a_prev gives no change
        hi = np.ones_like(ap)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            big = held_step(ap, mid, hh, tau_rise=1.0 / (r1 + r2), tau_fall=1.0 / r2) > an
            hi = np.where(big, mid, hi)
            lo = np.where(big, lo, mid)
        u[rise] = 0.5 * (lo + hi)
    return np.clip(u, 0.0, 1.0)


#: Signals per frame above which :func:`_held_steps` goes step by step rather than by scans.
_SCAN_WIDTH = 256


def _affine_scan(e, b, x0):
    """``x_1..x_n`` of ``x_{k+1} = e_k x_k + b_k`` (``e``, ``b`` (n, ...)) from ``x_0``, by doubling.

    The composition of the affine steps is an associative scan (Hillis & Steele):
    ``log2 n`` vectorised passes instead of ``n`` Python steps.  Only products of
    the ``e_k`` in (0, 1] appear, so it cannot overflow.
    """
    E = np.array(e, dtype=float)
    B = np.array(b, dtype=float)
    s = 1
    while s < E.shape[0]:
        B[s:] = E[s:] * B[:-s] + B[s:]
        E[s:] = E[s:] * E[:-s]
        s *= 2
    return E * x0 + B


def _held_steps(a0, um, e_rise, e_fall, max_rounds: int = 40):
    """Activations after each held step (the recurrence of :func:`held_step`), all frames at once.

    Each step is affine in the activation once its branch (rising: ``um >= a``)
    is known, so the branches are guessed (rising where the excitation rises),
    the affine recurrence solved by :func:`_affine_scan`, the branches read off
    the result, and so on until they agree with it -- then the answer is the
    step-by-step one (same branch at every step).  What is still inconsistent
    after ``max_rounds`` rounds is finished step by step from the first
    disagreement.  Wide problems (many parameter sets, where a numpy call per
    step costs little beside the data it moves) go step by step from the start.
    """
    if int(np.prod(um.shape[1:])) > _SCAN_WIDTH:
        return _steps(a0, um, e_rise, e_fall, 0, np.empty(um.shape))
    rise = np.empty(um.shape, dtype=bool)
    rise[0] = um[0] >= a0
    rise[1:] = um[1:] >= um[:-1]
    for _ in range(max_rounds):
        e = np.where(rise, e_rise, e_fall)
        a = _affine_scan(e, (1.0 - e) * um, a0)
        prev = np.concatenate([np.broadcast_to(a0, a.shape[1:])[None], a[:-1]])
        now = um >= prev
        if np.array_equal(now, rise):
            return a
        wrong, rise = now != rise, now
    # steps before the first wrong branch are exact (they saw only right branches): finish from there
    k0 = int(np.flatnonzero(np.any(wrong, axis=tuple(range(1, um.ndim))))[0])
    return _steps(prev[k0], um, e_rise, e_fall, k0, a)


def _steps(start, um, e_rise, e_fall, k0, out):
    """``out[k0:]`` by :func:`held_step`'s recurrence from the activation ``start`` before step ``k0``."""
    shape = um.shape[1:]
    cur = np.array(np.broadcast_to(start, shape), dtype=float)
    d = np.empty(shape)
    f = np.empty(shape)
    for k in range(k0, um.shape[0]):
        np.subtract(um[k], cur, out=d)
        np.copyto(f, e_fall[k])
        np.copyto(f, e_rise[k], where=d >= 0)
        np.multiply(d, f, out=d)
        np.subtract(um[k], d, out=cur)
        out[k] = cur
    return out


def activation_from_excitation(t, u, a0=None, *, tau_rise=TAU_RISE, tau_fall=TAU_FALL):
    """Activation ``a`` (N, ...) from a sampled excitation ``u`` (N, ...) at times ``t`` (N,), Eq. A.2.

    Method: over each sample interval the excitation is replaced by its mean
    (the trapezoid of the two samples) and Eq. A.2 is solved *exactly* for that
    constant excitation (:func:`held_step`).
    This is second-order accurate in the sample interval for smooth ``u``,
    unconditionally stable and keeps ``a`` between the excitation bounds, so
    coarse EMG sampling cannot make it blow up as explicit RK4 would
    (RK4 needs ``h < 2.8 tau_rise ~ 30 ms``).

    The recurrence is sequential in time, but affine in the activation once
    each step's branch is known: it is solved for all frames at once by an
    associative scan, iterated until the branches agree with the result
    (:func:`_held_steps`), with all other axes (muscles, parameter sets)
    vectorised.  ``tau_rise``, ``tau_fall`` broadcast against
    ``u``'s trailing axes (e.g. ``(m,)`` per muscle, ``(P, 1)`` per parameter set).

    ``a0`` defaults to ``u[0]`` (steady state, ``adot = 0`` at the first sample).
    """
    t1, t2 = _rates(tau_rise, tau_fall)
    t = as_array(t, "t")
    u = as_array(u, "u")
    squeeze = u.ndim == 1
    if squeeze:
        u = u[:, None]
    if u.ndim < 2 or t.ndim != 1 or t.shape[0] != u.shape[0]:
        raise TrialError(f"activation_from_excitation needs t (N,) and u (N, m) with the same N; "
                         f"got t {t.shape} and u {u.shape}")
    check_finite(t=t, u=u)
    h = np.diff(t)
    if (h <= 0).any():
        k = int(np.flatnonzero(h <= 0)[0])
        raise TrialError(f"time must increase strictly; t[{k + 1}] = {t[k + 1]} <= t[{k}] = {t[k]}")
    u = np.ascontiguousarray(u)                       # frames first in memory: the recurrence reads frame by frame
    n = u.shape[0]
    shape = np.broadcast_shapes(u.shape[1:], np.shape(t1), np.shape(t2))
    a = np.empty((n,) + shape)
    if a0 is not None:
        check_finite(a0=a0)
    a[0] = np.broadcast_to(u[0], shape) if a0 is None else np.broadcast_to(as_array(a0, "a0"), shape)
    if n == 1:
        return a[:, 0] if squeeze else a
    um = 0.5 * (u[1:] + u[:-1])                                            # (N-1, ...) step excitations
    if um.shape[1:] != shape:
        um = np.ascontiguousarray(np.broadcast_to(um, (n - 1,) + shape))
    hb = h.reshape((-1,) + (1,) * len(shape))
    e_rise = np.exp(-(t1 * um + t2) * hb)                                  # held_step's decay factors
    e_fall = np.broadcast_to(np.exp(-t2 * hb), um.shape)
    a[1:] = _held_steps(a[0], um, e_rise, e_fall)
    return a[:, 0] if squeeze else a
