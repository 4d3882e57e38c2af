"""Digital IIR filters without importing ``scipy.signal``: the Butterworth design and the recursions.

``scipy.signal`` costs about a second to import (it imports most of SciPy), more than inverse dynamics
of a whole walking trial; a command that filters a short trial should not pay for it.  This module gives
the few pieces :mod:`pinmsk.signals.filtering` uses, computing what SciPy's functions of the same names
compute:

* :func:`butter_sos` -- the digital low-pass Butterworth design as second-order sections
  (``scipy.signal.butter(order, wn, output="sos")``): the analog prototype's poles
  ``-exp(i pi m / 2N)``, ``m = -N+1, -N+3, ..., N-1`` (Oppenheim & Schafer, *Discrete-Time Signal
  Processing*, 3rd ed., sec. 7.3), the cut-off pre-warped and the bilinear transform applied
  (``z = (4 + s w) / (4 - s w)``, ``w = 4 tan(pi wn / 2)``, all zeros at ``z = -1``), and the poles paired
  into sections as SciPy's ``zpk2sos`` pairs them ("nearest": the pole closest to the unit circle in
  the last section, each with its nearest zeros), the gain in the first;
* :func:`sosfilt_zi` / :func:`lfilter_zi` -- the steady state of a unit step (solving
  ``(I - A) z = B`` of each section's transposed direct form II);
* :func:`sosfilt`, :func:`lfilter` (with an initial state) and :func:`lfiltic` -- the recursions of the
  transposed direct form II.  Up to :data:`SHORT` samples they run as a loop over the samples
  (vectorised over the channels); longer signals go to ``scipy.signal``'s compiled loops, whose import
  is then small beside the work, and so does every signal once ``scipy.signal`` is imported or the loops
  have cost :data:`BUDGET` seconds in the process.  Both evaluate the same recursion in the same order of
  operations (the same numbers to the bit).
"""
from __future__ import annotations

import numpy as np

__all__ = ["SHORT", "butter_sos", "sosfilt_zi", "lfilter_zi", "sosfilt", "lfilter", "lfiltic"]

#: Signals up to this many samples are filtered here; longer ones by ``scipy.signal``.
SHORT = 5000
#: Seconds of filtering here after which ``scipy.signal`` is imported and used for every signal: a
#: process that filters many short trials pays the import once rather than the slower loop each time.
BUDGET = 0.5
_SPENT = [0.0]


def use_numpy(n: int, module: str = "scipy.signal", spent: list = _SPENT, budget: float | None = None) -> bool:
    """Whether a signal of ``n`` samples is computed here: it is short, ``module`` is not imported yet and
    the loops here have not yet cost ``budget`` seconds (``spent[0]``) in this process."""
    import sys
    return n <= SHORT and module not in sys.modules and spent[0] < (BUDGET if budget is None else budget)


class _Clock:
    """Adds the seconds of its ``with`` block to ``spent[0]``."""

    def __init__(self, spent):
        self.spent = spent

    def __enter__(self):
        import time
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        import time
        self.spent[0] += time.perf_counter() - self.t0


def butter_sos(order: int, wn: float) -> np.ndarray:
    """``(sections, 6)`` second-order sections ``[b0, b1, b2, 1, a1, a2]`` of the digital low-pass
    Butterworth filter of ``order`` with cut-off ``wn`` (a fraction of the Nyquist frequency, 0 < wn < 1)."""
    order = int(order)
    wn = float(wn)
    if order < 1 or not 0.0 < wn < 1.0:
        raise ValueError(f"butter_sos needs order >= 1 and 0 < wn < 1, got {order}, {wn}")
    m = np.arange(-order + 1, order, 2)
    p = -np.exp(1j * np.pi * m / (2 * order))                 # analog prototype (unit cut-off)
    warped = 4.0 * np.tan(np.pi * wn / 2.0)                   # 2 fs tan(pi wn / fs) with fs = 2
    p = warped * p
    k = warped ** order
    fs2 = 4.0
    pz = (fs2 + p) / (fs2 - p)
    zz = -np.ones(order, dtype=complex)
    k = k * np.real(1.0 / np.prod(fs2 - p))
    return _zpk2sos_nearest(zz, pz, k)


def _cplxreal(z):
    """SciPy's ``_cplxreal``: (complex ones with positive imaginary part, sorted by real part; reals sorted)."""
    z = np.atleast_1d(z)
    if z.size == 0:
        return z, z
    tol = 100 * np.finfo((1.0 * z).dtype).eps
    z = z[np.lexsort((abs(z.imag), z.real))]
    real_idx = abs(z.imag) <= tol * abs(z)
    zr = z[real_idx].real
    if len(zr) == len(z):
        return np.array([]), zr
    z = z[~real_idx]
    zp = z[z.imag > 0]
    zn = z[z.imag < 0]
    if len(zp) != len(zn):
        raise ValueError("array contains complex value with no matching conjugate")
    same_real = np.diff(zp.real) <= tol * abs(zp[:-1])
    diffs = np.diff(np.concatenate(([0], same_real, [0])))
    run_starts = np.nonzero(diffs > 0)[0]
    run_stops = np.nonzero(diffs < 0)[0]
    for i in range(len(run_starts)):
        start = run_starts[i]
        stop = run_stops[i] + 1
        for chunk in (zp[start:stop], zn[start:stop]):
            chunk[...] = chunk[np.lexsort([abs(chunk.imag)])]
    if any(abs(zp - zn.conj()) > tol * abs(zn)):
        raise ValueError("array contains complex value with no matching conjugate")
    zc = (zp + zn.conj()) / 2
    return zc, zr


def _nearest(fro, to, which):
    order = np.argsort(np.abs(fro - to))
    if which == "any":
        return order[0]
    mask = np.isreal(fro[order])
    if which == "complex":
        mask = ~mask
    return order[np.flatnonzero(mask)[0]]


def _section(z, p):
    """``[b, a]`` of one section with zeros ``z`` and poles ``p`` (1 or 2 each), gain 1."""
    b = np.real(np.poly(z)) if len(z) else np.ones(1)
    a = np.real(np.poly(p))
    out = np.zeros(6)
    out[3 - len(b):3] = b
    out[6 - len(a):6] = a
    return out


def _zpk2sos_nearest(z, p, k) -> np.ndarray:
    """SciPy's ``zpk2sos(z, p, k, pairing="nearest")`` for a digital filter with as many zeros as poles."""
    n_sections = (max(len(p), len(z)) + 1) // 2
    if len(p) % 2 == 1:
        p = np.concatenate((p, [0.0]))
        z = np.concatenate((z, [0.0]))
    z = np.concatenate(_cplxreal(z))
    p = np.concatenate(_cplxreal(p))
    sos = np.zeros((n_sections, 6))
    for si in range(n_sections - 1, -1, -1):
        i1 = np.argmin(np.abs(1 - np.abs(p)))
        p1 = p[i1]
        p = np.delete(p, i1)
        if np.isreal(p1) and np.isreal(p).sum() == 0:
            j = _nearest(z, p1, "real")
            z1 = z[j]
            z = np.delete(z, j)
            sos[si] = _section([z1, 0], [p1, 0])
        elif (len(p) + 1 == len(z) and not np.isreal(p1) and np.isreal(p).sum() == 1
              and np.isreal(z).sum() == 1):
            j = _nearest(z, p1, "complex")
            z1 = z[j]
            z = np.delete(z, j)
            sos[si] = _section([z1, z1.conj()], [p1, p1.conj()])
        else:
            if np.isreal(p1):
                real = np.flatnonzero(np.isreal(p))
                i2 = real[np.argmin(np.abs(np.abs(p[real]) - 1))]
                p2 = p[i2]
                p = np.delete(p, i2)
            else:
                p2 = p1.conj()
            j = _nearest(z, p1, "any")
            z1 = z[j]
            z = np.delete(z, j)
            if not np.isreal(z1):
                sos[si] = _section([z1, z1.conj()], [p1, p2])
            elif len(z) > 0:
                j = _nearest(z, p1, "real")
                z2 = z[j]
                z = np.delete(z, j)
                sos[si] = _section([z1, z2], [p1, p2])
            else:
                sos[si] = _section([z1], [p1, p2])
    sos[0][:3] *= k
    return sos


def lfilter_zi(b, a) -> np.ndarray:
    """The initial state of :func:`lfilter` at the steady state of a unit step (``scipy.signal.lfilter_zi``)."""
    b = np.atleast_1d(np.asarray(b, dtype=float))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    b, a = b / a[0], a / a[0]
    n = max(len(a), len(b))
    a = np.concatenate((a, np.zeros(n - len(a))))
    b = np.concatenate((b, np.zeros(n - len(b))))
    companion = np.zeros((n - 1, n - 1))
    companion[0] = -a[1:]
    companion[np.arange(1, n - 1), np.arange(n - 2)] = 1.0
    i_minus_a = np.eye(n - 1) - companion.T
    return np.linalg.solve(i_minus_a, b[1:] - a[1:] * b[0])


def sosfilt_zi(sos) -> np.ndarray:
    """``(sections, 2)``: the initial states of :func:`sosfilt` at the steady state of a unit step."""
    sos = np.asarray(sos, dtype=float)
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for s in range(sos.shape[0]):
        b, a = sos[s, :3], sos[s, 3:]
        zi[s] = scale * lfilter_zi(b, a)
        scale *= b.sum() / a.sum()
    return zi


def lfiltic(b, a, y, x=None) -> np.ndarray:
    """The initial state of :func:`lfilter` from past outputs ``y`` and inputs ``x`` (most recent first),
    as ``scipy.signal.lfiltic``."""
    b = np.atleast_1d(np.asarray(b, dtype=float))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    n, m = len(a) - 1, len(b) - 1
    k = max(m, n)
    y = np.asarray(y, dtype=float)
    x = np.zeros(m) if x is None else np.asarray(x, dtype=float)
    x = np.concatenate((x, np.zeros(max(m - x.size, 0))))[:max(m, 0)] if m else x[:0]
    y = np.concatenate((y, np.zeros(max(n - y.size, 0))))[:n]
    zi = np.zeros(k)
    for i in range(m):
        zi[i] = np.sum(b[i + 1:] * x[:m - i])
    for i in range(n):
        zi[i] -= np.sum(a[i + 1:] * y[:n - i])
    return zi / a[0]


def _as_columns(x):
    x = np.asarray(x, dtype=float)
    return x.reshape(x.shape[0], -1), x.shape


def _axis_zero(axis) -> None:
    if axis != 0:
        raise ValueError(f"pinmsk.signals.iir filters along axis 0 (time first), not axis {axis}")


def sosfilt(sos, x, *, zi, axis: int = 0):
    """``(y, final state)`` of the cascade ``sos`` over ``x`` along axis 0 from the state ``zi``
    ``(sections, 2, ...)`` (``scipy.signal.sosfilt(sos, x, axis=0, zi=zi)``)."""
    _axis_zero(axis)
    sos = np.asarray(sos, dtype=float)
    x = np.asarray(x, dtype=float)
    zi = np.asarray(zi, dtype=float)
    if not use_numpy(x.shape[0]):
        from scipy.signal import sosfilt as scipy_sosfilt
        return scipy_sosfilt(sos.copy(), x, axis=0, zi=zi)
    with _Clock(_SPENT):
        return _sosfilt(sos, x, zi)


def _sosfilt(sos, x, zi):
    flat, shape = _as_columns(x)
    z = np.broadcast_to(zi, (sos.shape[0], 2) + shape[1:]).reshape(sos.shape[0], 2, -1).copy()
    y = flat.copy()
    for s in range(sos.shape[0]):
        b0, b1, b2, a0, a1, a2 = sos[s] / sos[s, 3]
        z0, z1 = z[s, 0].copy(), z[s, 1].copy()
        for n in range(y.shape[0]):
            xn = y[n]                   # read before y[n] is replaced below
            yn = b0 * xn + z0
            z0 = b1 * xn - a1 * yn + z1
            z1 = b2 * xn - a2 * yn
            y[n] = yn
        z[s, 0], z[s, 1] = z0, z1
    return y.reshape(shape), z.reshape((sos.shape[0], 2) + shape[1:])


def lfilter(b, a, x, *, zi, axis: int = 0):
    """``(y, final state)`` of the filter ``b / a`` over ``x`` along axis 0 from the state ``zi``
    ``(max(len(a), len(b)) - 1, ...)`` (``scipy.signal.lfilter(b, a, x, axis=0, zi=zi)``)."""
    _axis_zero(axis)
    b = np.atleast_1d(np.asarray(b, dtype=float))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    x = np.asarray(x, dtype=float)
    zi = np.asarray(zi, dtype=float)
    if not use_numpy(x.shape[0]):
        from scipy.signal import lfilter as scipy_lfilter
        return scipy_lfilter(b, a, x, axis=0, zi=zi)
    with _Clock(_SPENT):
        return _lfilter(b, a, x, zi)


def _lfilter(b, a, x, zi):
    b, a = b / a[0], a / a[0]
    k = max(len(a), len(b))
    a = np.concatenate((a, np.zeros(k - len(a))))
    b = np.concatenate((b, np.zeros(k - len(b))))
    flat, shape = _as_columns(x)
    z = [row.copy() for row in np.broadcast_to(zi, (k - 1,) + shape[1:]).reshape(k - 1, -1)]
    y = flat.copy()
    for n in range(y.shape[0]):
        xn = y[n]                       # read before y[n] is replaced below
        yn = z[0] + b[0] * xn if k > 1 else b[0] * xn
        for i in range(k - 2):
            z[i] = z[i + 1] + b[i + 1] * xn - a[i + 1] * yn
        if k > 1:
            z[k - 2] = b[k - 1] * xn - a[k - 1] * yn
        y[n] = yn
    return y.reshape(shape), (np.stack(z) if k > 1 else np.zeros((0,) + flat.shape[1:])).reshape((k - 1,) + shape[1:])
