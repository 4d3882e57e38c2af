"""Zero-lag low-pass filtering and spline differentiation of sampled signals.

Arrays are time-first: a signal is ``(N,)`` or ``(N, k)`` with one column per
channel, and every function works on all columns at once.

* :func:`lowpass` is a Butterworth filter run forwards and backwards
  (``scipy.signal.sosfiltfilt`` on second-order sections), so it has no phase
  lag.  Because the signal passes the filter twice, the gain is
  ``|H(f)|**2 = 1 / (1 + (f / cutoff)**(2 * order))``: 0.5 (-6 dB) at
  ``cutoff``, not -3 dB, and the effective order is ``2 * order``.  ``cutoff`` is
  the design frequency of the single pass; no "Winter correction" is applied.
* :func:`bandpass` is the Butterworth band-pass run forwards and backwards (``sosfiltfilt``),
  the one pinmsk uses (EMG, noise bands, simulated EMG); its gain is the square of the design's.
* :func:`differentiate` optionally low-passes, then passes a quintic
  interpolating B-spline (``scipy.interpolate.make_interp_spline(k=5)``, with
  scipy's default not-a-knot end conditions) through the samples and returns
  its first and second derivatives at the sample times.  The spline
  reproduces polynomials up to degree 5 exactly, so the derivatives are exact
  for them; for smooth signals the error of the j-th derivative falls as
  ``h**(6 - j)``.

Problems with the input raise :class:`pinmsk.errors.TrialError` naming the
cutoff, rate, number of samples or the offending column and row.
"""

from __future__ import annotations

import functools

import numpy as np

from ..errors import TrialError
from .sampling import check_increasing, uniform_rate

__all__ = ["lowpass", "bandpass", "bandpass_design", "differentiate", "filter_padlen", "DEFAULT_CUTOFF", "CONTACT_CUTOFF", "FILTER_ORDER"]

#: Default low-pass cut-off (Hz) of kinematics and ground reaction forces in every analysis
#: (:func:`pinmsk.kinematics.prepare`); ``cutoff=0`` / ``--cutoff 0`` turns filtering off.
DEFAULT_CUTOFF = 6.0
#: Cut-off (Hz) of the foot kinematics that drive a contact fit (:class:`pinmsk.contact.ContactFit`):
#: contact damping acts on the penetration rate at heel strike, a transient that 6 Hz would erase.
CONTACT_CUTOFF = 12.0
#: Order of the designed Butterworth filter (run forwards and backwards).
FILTER_ORDER = 4

def filter_padlen(order: int, *, rate: float | None = None, cutoff: float | None = None,
                  n: int | None = None) -> int:
    """Samples of odd extension added at each end by :func:`lowpass`.

    Without ``rate`` and ``cutoff``: scipy's default for ``sosfiltfilt`` on a
    Butterworth filter of this ``order`` (``3 * (2 * n_sections + 1)``), the
    fewest samples a signal must exceed.  With them: at least two periods of
    the cut-off, ``ceil(2 * rate / cutoff)`` samples (capped at ``n - 1``),
    because scipy's default is 15 samples whatever the rate: at 1 kHz and
    6 Hz that is 15 ms against a filter response of about 300 ms, and the end
    transients then reach far into the trial (0.05 rad on a walk's hip angle).
    """
    n_sections = (int(order) + 1) // 2
    base = 3 * (2 * n_sections + 1)
    if rate is None or cutoff is None:
        return base
    pad = max(base, int(np.ceil(2.0 * float(rate) / float(cutoff))))
    return pad if n is None else min(pad, int(n) - 1)


def _check_finite(x: np.ndarray, what: str) -> None:
    bad = ~np.isfinite(x)
    if bad.any():
        flat = bad.reshape(bad.shape[0], -1)
        col = int(np.flatnonzero(flat.any(axis=0))[0])
        row = int(np.flatnonzero(flat[:, col])[0])
        where = f"column {col}, " if x.ndim > 1 else ""
        raise TrialError(
            f"{what}: {where}row {row} is {float(x.reshape(x.shape[0], -1)[row, col])!r} "
            f"({int(flat.sum())} non-finite value(s) in total); fill or cut the "
            "gap before filtering or differentiating"
        )


def lowpass(x, *, rate: float, cutoff: float, order: int = 4) -> np.ndarray:
    """Zero-lag Butterworth low-pass of ``x`` along axis 0.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, k)
        Uniformly sampled signal(s), time first.
    rate : float
        Sampling rate in Hz.
    cutoff : float
        Cut-off frequency in Hz of the designed (single-pass) filter;
        ``0 < cutoff < rate / 2``.
    order : int
        Order of the designed filter; forward-backward filtering doubles it.

    Returns
    -------
    numpy.ndarray
        Filtered signal with the shape of ``x``.

    Notes
    -----
    ``sosfiltfilt`` with ``padtype="odd"`` and
    ``padlen=filter_padlen(order, rate=rate, cutoff=cutoff, n=N)`` (two periods
    of the cut-off): each end is extended by a point reflection about the end
    sample, which keeps the end value and slope and limits start-up transients.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 0:
        raise TrialError("lowpass needs a signal of shape (N,) or (N, k), got a scalar")
    rate = float(rate)
    cutoff = float(cutoff)
    if not (np.isfinite(rate) and rate > 0):
        raise TrialError(f"sampling rate must be a positive number of Hz, got {rate!r}")
    nyquist = 0.5 * rate
    if not (np.isfinite(cutoff) and 0 < cutoff < nyquist):
        raise TrialError(
            f"cutoff {cutoff:g} Hz must be above 0 and below the Nyquist frequency "
            f"{nyquist:g} Hz (rate {rate:g} Hz); choose a lower cutoff"
        )
    if int(order) != order or order < 1:
        raise TrialError(f"filter order must be a positive integer, got {order!r}")
    order = int(order)
    n = x.shape[0]
    if n <= filter_padlen(order):
        padlen = filter_padlen(order)
        raise TrialError(
            f"{n} samples are too few for an order-{order} Butterworth low-pass "
            f"(cutoff {cutoff:g} Hz, rate {rate:g} Hz): zero-lag filtering pads "
            f"{padlen} samples at each end and needs N > {padlen}; use a longer "
            "trial or a lower order"
        )
    padlen = filter_padlen(order, rate=rate, cutoff=cutoff, n=n)
    _check_finite(x, "lowpass input")
    from .iir import sosfilt  # scipy.signal's (imported only for long signals: it costs ~1 s)

    # scipy's sosfiltfilt (padtype="odd", axis 0) step by step, with the design's initial state kept
    # with the design (scipy solves for it on every call): the same operations, the same numbers
    sos, zi = _butterworth_state(int(order), float(cutoff / nyquist))
    zi = zi.reshape(zi.shape + (1,) * (x.ndim - 1))          # (sections, 2[, 1]): broadcast over columns
    ext = np.concatenate((2 * x[0:1] - x[padlen:0:-1], x, 2 * x[-1:] - x[-2:-(padlen + 2):-1]), axis=0)
    y, _ = sosfilt(sos, ext, zi=zi * ext[0:1])
    y, _ = sosfilt(sos, y[::-1], zi=zi * y[-1:])
    return y[::-1][padlen:-padlen]


@functools.lru_cache(maxsize=64)
def _butterworth_state(order: int, wn: float) -> tuple[np.ndarray, np.ndarray]:
    """The design and its steady-state initial conditions per unit step (``scipy.signal.sosfilt_zi``),
    cached together (read-only)."""
    from .iir import sosfilt_zi

    sos = _butterworth(order, wn)
    zi = sosfilt_zi(sos.copy())
    zi.flags.writeable = False
    return sos, zi


@functools.lru_cache(maxsize=64)
def _butterworth(order: int, wn: float) -> np.ndarray:
    """Second-order sections of the low-pass Butterworth design (cached: analyses filter many
    short trials at the same few cut-offs, and the design costs more than filtering them)."""
    from .iir import butter_sos

    sos = butter_sos(order, wn)         # scipy.signal.butter(order, wn, output="sos")
    sos.flags.writeable = False            # shared by every caller: never changed
    return sos


def bandpass_design(band, rate: float, order: int = 4) -> np.ndarray:
    """Second-order sections of the Butterworth band-pass ``band = (low, high)`` Hz at ``rate`` Hz:
    ``scipy.signal.butter(order, [low, high] / (rate / 2), btype="band", output="sos")`` (``2 order``
    poles), cached and read-only.  ``0 < low < high < rate / 2``."""
    lo, hi = (float(b) for b in band)
    rate = float(rate)
    if not (np.isfinite(rate) and rate > 0):
        raise TrialError(f"sampling rate must be a positive number of Hz, got {rate!r}")
    if not (0 < lo < hi < 0.5 * rate):
        raise TrialError(f"band-pass ({lo:g}, {hi:g}) Hz must have 0 < low < high < the Nyquist frequency "
                         f"{0.5 * rate:g} Hz (rate {rate:g} Hz)")
    if int(order) != order or order < 1:
        raise TrialError(f"filter order must be a positive integer, got {order!r}")
    return _bandpass_sos(int(order), lo, hi, rate)


@functools.lru_cache(maxsize=64)
def _bandpass_sos(order: int, lo: float, hi: float, rate: float) -> np.ndarray:
    from scipy.signal import butter  # here, not at import (slow)

    sos = butter(order, [lo / (0.5 * rate), hi / (0.5 * rate)], btype="band", output="sos")
    sos.flags.writeable = False            # shared by every caller: never changed
    return sos


def bandpass(x, *, rate: float, band, order: int = 4, padlen: int | None = None, axis: int = 0) -> np.ndarray:
    """Zero-lag Butterworth band-pass of ``x`` along ``axis``: :func:`bandpass_design` run forwards and
    backwards (``scipy.signal.sosfiltfilt``, ``padtype="odd"``), so the gain is ``|H(f)|**2``.

    ``padlen`` is the samples of odd extension at each end: None is scipy's default for this design
    (``3 (2 n_sections + 1)`` less the sections' zero coefficients); the EMG envelope passes
    :func:`filter_padlen` of its order, the pad of the low-pass that follows it.
    """
    from scipy.signal import sosfiltfilt

    sos = bandpass_design(band, rate, order).copy()      # scipy's filter wants a writeable design
    return sosfiltfilt(sos, np.asarray(x, dtype=float), axis=axis,
                       padtype="odd", padlen=padlen)


#: the coordinate filters of :func:`differentiate`: pinmsk's own, and OpenSim's ID tool's
FILTER_METHODS = ("butterworth", "opensim")


def reflect_pad(x, pad: int) -> np.ndarray:
    """``x`` (N,) or (N, k) with ``pad`` samples added at each end, reflected about the end samples and
    negated (``2 x_0 - x_k``: OpenSim's ``Signal::Pad``, which keeps the value and the slope at each end);
    a pad of N or more is built up in steps, as OpenSim does."""
    x = np.asarray(x, dtype=float)
    pad = int(pad)
    if pad <= 0:
        return x
    if x.shape[0] < 2:
        raise TrialError(f"padding needs at least 2 samples, got {x.shape[0]}")
    target = x.shape[0] + 2 * pad
    while x.shape[0] < target:
        p = min((target - x.shape[0]) // 2, x.shape[0] - 1)
        x = np.concatenate([2.0 * x[0] - x[p:0:-1], x, 2.0 * x[-1] - x[-2:-2 - p:-1]], axis=0)
    return x


def iir_coefficients(rate: float, cutoff: float) -> tuple[np.ndarray, np.ndarray, float]:
    """``(numerator, denominator, cutoff used)`` of OpenSim's third-order IIR low-pass
    (``Signal::LowpassIIR``): a Butterworth by the bilinear transform with a pre-warped cut-off,
    ``w_a = tan(pi f_c / f_s)``, ``H(z) = w_a^3 (1 + z^-1)^3 / D(z)``; a cut-off at or above half the
    rate is lowered to 0.49 times the rate, as OpenSim lowers it."""
    rate, cutoff = float(rate), float(cutoff)
    if not (rate > 0 and cutoff > 0):
        raise TrialError(f"the IIR low-pass needs a positive rate and cut-off, got {rate:g} Hz and {cutoff:g} Hz")
    if cutoff >= 0.5 * rate:
        cutoff = 0.49 * rate
    wa = np.tan(np.pi * cutoff / rate)
    wa2, wa3 = wa * wa, wa ** 3
    den = (wa + 1.0) * (wa2 + wa + 1.0)
    b = np.array([1.0, 3.0, 3.0, 1.0]) * wa3 / den
    a = np.array([1.0, (3 * wa3 + 2 * wa2 - 2 * wa - 3) / den, (3 * wa3 - 2 * wa2 - 2 * wa + 3) / den,
                  (wa - 1) * (wa2 - wa + 1) / den])
    return b, a, cutoff


def lowpass_iir(x, *, rate: float, cutoff: float) -> np.ndarray:
    """OpenSim's ``Storage::lowpassIIR``: the filter of :func:`iir_coefficients` run forwards, then
    backwards, each pass started with its first three outputs equal to its inputs (OpenSim's start, not
    a steady state); every column at once."""
    from .iir import lfilter, lfiltic  # scipy.signal's (imported only for long signals: it costs ~1 s)

    x = np.asarray(x, dtype=float)
    if x.shape[0] < 4:
        raise TrialError(f"the IIR low-pass needs at least 4 samples, got {x.shape[0]}")
    b, a, _ = iir_coefficients(rate, cutoff)
    flat = x.reshape(x.shape[0], -1)

    def one_pass(sig):
        out = sig.copy()
        zi = np.column_stack([lfiltic(b, a, y=sig[2::-1, k], x=sig[2::-1, k]) for k in range(sig.shape[1])])
        out[3:], _ = lfilter(b, a, sig[3:], axis=0, zi=zi)
        return out

    return one_pass(one_pass(flat)[::-1])[::-1].reshape(x.shape)


def lowpass_opensim(x, *, rate: float, cutoff: float) -> tuple[np.ndarray, int]:
    """OpenSim's coordinate low-pass as its InverseDynamicsTool applies it: the trial padded at each end
    by half its length (``Storage::pad(size / 2)``, :func:`reflect_pad`), then :func:`lowpass_iir`.

    Returns ``(padded and filtered samples (N + 2 pad, ...), pad)``: the ID tool fits its quintic
    spline through the padded samples (:func:`differentiate` with ``method="opensim"``)."""
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    rate, cutoff = float(rate), float(cutoff)
    if not (0 < cutoff < 0.5 * rate):
        raise TrialError(f"cutoff {cutoff:g} Hz must be above 0 and below the Nyquist frequency "
                         f"{0.5 * rate:g} Hz (rate {rate:g} Hz); choose a lower cutoff")
    if n < 8:
        raise TrialError(f"OpenSim's coordinate filter needs at least 8 samples, got {n}")
    _check_finite(x, "lowpass input")
    pad = n // 2
    return lowpass_iir(reflect_pad(x, pad), rate=rate, cutoff=cutoff), pad


def differentiate(time, x, *, cutoff: float | None = None, order: int = 4, method: str = "butterworth"):
    """Smoothed samples and first and second time derivatives of ``x``.

    Parameters
    ----------
    time : array_like, shape (N,)
        Strictly increasing sample times in s (N >= 6).
    x : array_like, shape (N,) or (N, k)
        Samples, time first.
    cutoff : float, optional
        If given, ``x`` is first passed through :func:`lowpass` with this
        cut-off (Hz) and ``order``, at the rate ``1 / median(diff(time))``;
        the time steps must then be uniform within :data:`pinmsk.signals.sampling.UNIFORM_TOLERANCE`.
    order : int
        Butterworth order used when ``cutoff`` is given.
    method : "butterworth" or "opensim"
        The low-pass when ``cutoff`` is given: :func:`lowpass` (``order``), or OpenSim's
        InverseDynamicsTool's (:func:`lowpass_opensim`, whose spline is fitted through the padded
        samples, as the tool's ``GCVSplineSet`` of degree 5 with no smoothing is, and evaluated at
        ``time``).

    Returns
    -------
    x_s, dx, ddx : numpy.ndarray
        The (filtered) samples and the first and second derivatives of the
        quintic interpolating spline through them, at ``time``; each with the
        shape of ``x``.
    """
    if method not in FILTER_METHODS:
        raise TrialError(f"the coordinate filter must be one of {', '.join(FILTER_METHODS)}; got {method!r}")
    t = np.asarray(time, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.ndim != 1:
        raise TrialError(f"time must have shape (N,), got {t.shape}")
    if x.ndim not in (1, 2) or x.shape[0] != t.shape[0]:
        raise TrialError(
            f"x must have shape (N,) or (N, k) with N = len(time) = {t.shape[0]}, got {x.shape}"
        )
    n = t.shape[0]
    if n < 6:
        raise TrialError(
            f"differentiation by quintic spline needs at least 6 samples, got {n}"
        )
    _check_finite(t, "time")
    check_increasing(t)
    _check_finite(x, "signal to differentiate")
    if cutoff is not None and method == "opensim":
        rate = uniform_rate(t)
        y, pad = lowpass_opensim(x, rate=rate, cutoff=cutoff)
        step = (t[-1] - t[0]) / (n - 1)
        tp = np.concatenate((t[0] - step * np.arange(pad, 0, -1), t, t[-1] + step * np.arange(1, pad + 1)))
        ops = _quintic_operators(tp)
        c = ops.solve(y.reshape(tp.size, -1))
        keep = slice(pad, pad + n)
        return (y[keep].reshape(x.shape), (ops.d1 @ c)[keep].reshape(x.shape),
                (ops.d2 @ c)[keep].reshape(x.shape))
    if cutoff is not None:
        rate = uniform_rate(t)
        x = lowpass(x, rate=rate, cutoff=cutoff, order=order)
    ops = _quintic_operators(t)
    flat = x.reshape(n, -1)
    c = ops.solve(flat)         # the interpolating spline's coefficients
    return x, (ops.d1 @ c).reshape(x.shape), (ops.d2 @ c).reshape(x.shape)


class _QuinticOperators:
    """The linear maps of :func:`differentiate` on one time grid: the LU factors of the quintic
    not-a-knot spline's collocation matrix (the one banded system ``make_interp_spline(k=5)`` solves) and
    the sparse matrices taking the spline's coefficients to its first and second derivatives at the sample
    times (the derivative splines' coefficient maps of scipy's ``splder``, Schumaker ch. 5, times their
    collocation matrices).  A trial's channels, and later trials on the same grid, share them: one
    factorization, then a triangular solve and two sparse products per call."""

    __slots__ = ("t", "lu", "d1", "d2", "collocation")

    def __init__(self, t: np.ndarray):
        from .bspline import SPENT, use_dense
        if use_dense(t.size):
            import time
            t0 = time.perf_counter()
            self._dense(t)
            SPENT[0] += time.perf_counter() - t0
            return
        from scipy.interpolate import BSpline, make_interp_spline
        from scipy.sparse import diags_array
        from scipy.sparse.linalg import splu

        k = 5
        knots = make_interp_spline(t, np.zeros(t.size), k=k, check_finite=False).t     # scipy's not-a-knot knots
        self.t = t.copy()
        # the collocation matrix (banded: k sub- and super-diagonals), factored once by SuperLU (its
        # multi-column solve is several times faster than LAPACK's banded dgbtrs on a trial's channels)
        self.lu = splu(BSpline.design_matrix(t, knots, k).tocsc())
        ops = []
        D = None
        tk, kk = knots, k
        for _ in range(2):
            # c'_i = k (c_{i+1} - c_i) / (t_{i+k+1} - t_{i+1}): a bidiagonal map of the coefficients
            m = tk.size - kk - 1
            w = kk / (tk[kk + 1:kk + m] - tk[1:m])
            step = diags_array([-w, w], offsets=[0, 1], shape=(m - 1, m), format="csr")
            D = step if D is None else step @ D
            tk, kk = tk[1:-1], kk - 1
            ops.append((BSpline.design_matrix(t, tk, kk) @ D).tocsr())
        self.d1, self.d2 = ops

    def _dense(self, t: np.ndarray) -> None:
        """The same maps as dense arrays (:mod:`pinmsk.signals.bspline`), for a short grid: no SciPy import,
        the collocation matrix kept and solved by LAPACK's LU on each call."""
        from .bspline import derivative_step, design_matrix, not_a_knot

        k = 5
        knots = not_a_knot(t, k)
        self.t = t.copy()
        self.lu = None
        ops = [design_matrix(t, knots, k)]
        tk, kk, maps = knots, k, []
        for _ in range(2):
            B = design_matrix(t, tk[1:-1], kk - 1)
            for tj, kj in reversed(maps + [(tk, kk)]):     # B_(k-1) @ S_(k) [@ S_(k+1)]
                B = derivative_step(B, tj, kj)
            maps.append((tk, kk))
            ops.append(B)
            tk, kk = tk[1:-1], kk - 1
        self.collocation, self.d1, self.d2 = ops

    def solve(self, x: np.ndarray) -> np.ndarray:
        """The coefficients ``(N, k)`` of the interpolating splines through the columns of ``x`` ``(N, k)``."""
        if self.lu is None:
            import time

            from .bspline import SPENT
            t0 = time.perf_counter()
            out = np.linalg.solve(self.collocation, x)
            SPENT[0] += time.perf_counter() - t0
            return out
        return self.lu.solve(np.ascontiguousarray(x))


#: (N, hash of the time grid) -> its :class:`_QuinticOperators` (the grid itself checked on a hit)
_OPERATORS: dict[tuple, _QuinticOperators] = {}

#: Grids of more samples are not kept between calls: their operators (some 300 bytes a sample) would
#: outlive the analysis of a long trial, and building them again costs as much as one use.
CACHE_SAMPLES = 50_000


def _quintic_operators(t: np.ndarray) -> _QuinticOperators:
    key = (t.size, hash(t.tobytes()))
    hit = _OPERATORS.get(key)
    if hit is not None and np.array_equal(hit.t, t):
        return hit
    ops = _QuinticOperators(t)
    if t.size > CACHE_SAMPLES:
        return ops
    if len(_OPERATORS) >= 16:
        _OPERATORS.pop(next(iter(_OPERATORS)))
    _OPERATORS[key] = ops
    return ops
