"""Noise models of measured signals: a coloured spectrum fitted above the signal's band, and realisations.

A measured channel is ``x = s + n``: a signal ``s`` whose power lies below
``band_start`` (the movement's band) and noise ``n``.  Third differences see
only the top of the noise spectrum, so noise that was low-passed before it was
recorded -- an EMG envelope (rectified, low-passed at a few Hz), angles the lab
filtered, a plate's anti-alias filter -- is invisible to them.  This module
models the noise's one-sided power spectral density (units^2 / Hz) as

    S(f) = w^2 + c^2 G(f; f_c, p),      G = (1 + (tan(pi f / f_s) / tan(pi f_c / f_s))^(2 p))^(-2)

white noise ``w`` plus noise that went through a zero-lag (forwards-backwards)
digital Butterworth low-pass of order ``p`` at ``f_c`` (``f_s`` the sampling
rate; for ``f << f_s`` the analogue ``(1 + (f / f_c)^(2 p))^(-2)``) -- the shape
:func:`pinmsk.signals.filtering.lowpass` and :func:`pinmsk.signals.emg.envelope`
give (G is the power gain of that filter).  Below ``band_start`` the noise is
not observable apart from the signal; the model extrapolates it (flat
passband), which is what a filtered white process does.

Fitting (:func:`fit_noise`), per column:

1. the signal is removed by a zero-lag high-pass at ``band_start``
   (implicitly: each band filter below starts there);
2. the band ``[band_start, 0.45 rate]`` is cut into half-octave bands; the
   power in each is measured robustly (:func:`band_powers`): the mean square
   of the band-passed signal (zero-lag order-2 Butterworth band-pass) away
   from events -- samples beyond 5 robust standard deviations and the band
   filter's ringing around them -- so spikes and steps (friction reversals,
   heel strikes) do not count as noise, at the efficiency of the plain mean
   square where there are none;
3. the expected band power of the model, ``w^2 A_j + c^2 B_j(f_c, p)``, with
   ``A_j, B_j`` the integrals of ``1`` and ``G`` against each band filter's
   power gain, is linear in ``(w^2, c^2)``: non-negative least squares in
   error relative to the model (a band power's spread is proportional to its
   mean; relative to the data would bias the level low), reweighted twice,
   for each ``(f_c, p)`` on a grid (``f_c`` from the second band
   edge, ``sqrt(2) band_start``, to ``0.45 rate``: a corner in the lowest band
   would put its power below the bands, where nothing tells it from the
   signal; ``p`` = 2 or 4), and the coloured part is kept only when
   it lowers the BIC of the log band powers (weights: the number of
   independent samples in each band, ``2 B T``, over 2, the variance of the
   log of a variance estimate per sample); a known corner (``corner=``,
   e.g. an envelope's low-pass) fixes ``f_c``.

Multiplicative noise (``multiplicative=True``, EMG: the envelope's noise
scales with the contraction) is ``n = g(t) eps(t)`` with ``g`` the signal's
level (its low-pass at ``band_start``, floored at 1 % of its peak) and ``eps``
stationary; the spectrum is that of ``eps``.

:meth:`NoiseModel.sample` draws realisations in the time domain (white noise
through the same zero-lag Butterworth), so they have exactly the modelled
spectrum, end effects included.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from ..errors import TrialError
from .filtering import FILTER_ORDER, bandpass, bandpass_design, lowpass

__all__ = ["NoiseModel", "fit_noise", "band_edges", "band_powers", "signal_band", "TOP_BAND", "LOG_VAR"]

#: Highest band edge as a fraction of the sampling rate (below Nyquist, where the band filters stay stable).
TOP_BAND = 0.45
#: Variance of the log of a band power per independent Gaussian sample (2 / n for n samples).
LOG_VAR = 2.0
_ORDERS = (2, 4)
#: Order of each band's Butterworth band-pass design (four poles; run forwards and backwards).
BAND_ORDER = 2
_N_CORNERS = 24


def signal_band(x, rate: float, *, fraction: float = 0.99, floor: float = 0.5) -> float:
    """Frequency (Hz) below which ``fraction`` of the power of ``x`` (time-first, each column
    detrended and scaled to unit variance) lies: the top of a movement's band."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    n = x.shape[0]
    tt = np.arange(n)
    keep = np.std(x, axis=0) > 0
    if n < 8 or not keep.any():
        return float(floor)
    x = x[:, keep]
    A = np.column_stack([np.ones(n), tt])
    x = x - A @ np.linalg.lstsq(A, x, rcond=None)[0]
    x = x / np.maximum(np.std(x, axis=0), 1e-300)
    P = np.abs(np.fft.rfft(x * np.hanning(n)[:, None], axis=0)) ** 2
    P = P.sum(axis=1)
    f = np.fft.rfftfreq(n, 1.0 / rate)
    c = np.cumsum(P) / max(P.sum(), 1e-300)
    return float(max(f[min(np.searchsorted(c, fraction), f.size - 1)], floor))


def band_edges(band_start: float, rate: float) -> np.ndarray:
    """Half-octave band edges from ``band_start`` up to ``TOP_BAND * rate`` (at least two bands)."""
    top = TOP_BAND * rate
    if not 0 < band_start < top / 2:
        raise TrialError(f"the noise band starts at {band_start:.3g} Hz, too close to the top "
                         f"{top:.3g} Hz ({rate:g} Hz sampling): sample faster or filter less")
    k = int(np.floor(2 * np.log2(top / band_start)))
    return band_start * 2.0 ** (np.arange(k + 1) / 2.0)


@functools.lru_cache(maxsize=32)
def _band_filters(edges: tuple, rate: float):
    return [bandpass_design((a, b), rate, order=BAND_ORDER) for a, b in zip(edges[:-1], edges[1:])]


@functools.lru_cache(maxsize=32)
def _band_gains(edges: tuple, rate: float):
    """``(f, df, gains (J, F))``: each band filter's zero-lag power gain on a frequency grid."""
    from scipy.signal import sosfreqz

    f = np.linspace(0.0, 0.5 * rate, 4097)[1:]
    gains = np.array([np.abs(sosfreqz(s, worN=f, fs=rate)[1]) ** 4 for s in _band_filters(edges, rate)])
    return f, f[1] - f[0], gains


def _shape(f, corner, order, design_rate):
    """Power gain of a zero-lag Butterworth low-pass designed at ``design_rate`` Hz (what
    :func:`~pinmsk.signals.filtering.lowpass` does: bilinear, so the analogue ``f / f_c`` becomes
    ``tan(pi f / rate) / tan(pi f_c / rate)``); ``design_rate = inf``: the analogue filter (a signal
    filtered at a much higher rate, e.g. an EMG envelope made at 1 kHz, then sampled)."""
    f = np.asarray(f, dtype=float)
    design_rate = np.asarray(design_rate, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        dr = np.where(np.isfinite(design_rate), design_rate, 1.0)
        x_dig = np.tan(np.pi * np.minimum(f, 0.4999 * dr) / dr) / np.tan(np.pi * corner / dr)
    x = np.where(np.isfinite(design_rate), x_dig, f / corner)
    return 1.0 / (1.0 + x ** (2 * order)) ** 2


def band_powers(x, rate: float, edges: Sequence[float], *, modulation=None, trim: int = 0) -> np.ndarray:
    """Robust power ``(J, k)`` of ``x`` (N, k) in each band (see the module notes).

    The mean square of the band-passed signal (divided by ``modulation`` (N, k)
    first if given) over the samples away from events: a sample beyond 5
    robust standard deviations (``MAD / 0.6745``) marks an event (a step, a
    spike), and the band filter's ringing around it, ``1.5 rate / f_low``
    samples either side, is left out.  Where less than a quarter of the samples
    remain, ``(MAD / 0.6745)^2``.  ``trim`` samples at each end are left out.
    """
    x = np.asarray(x, dtype=float)
    squeeze = x.ndim == 1
    if squeeze:
        x = x[:, None]
    out = np.empty((len(edges) - 1, x.shape[1]))
    sl = slice(trim, x.shape[0] - trim if trim else None)
    edges = tuple(float(e) for e in edges)
    for j, band in enumerate(zip(edges[:-1], edges[1:])):
        y = bandpass(x, rate=float(rate), band=band, order=BAND_ORDER)
        if modulation is not None:
            y = y / modulation
        y = y[sl]
        scale = np.median(np.abs(y), axis=0) / 0.6745
        event = np.abs(y) > 5.0 * np.maximum(scale, 1e-300)
        if event.any():
            event = _dilate(event, int(np.ceil(1.5 * rate / edges[j])))
        keep = ~event
        n_keep = keep.sum(axis=0)
        ms = np.sum(np.where(keep, y * y, 0.0), axis=0) / np.maximum(n_keep, 1)
        out[j] = np.where(n_keep >= 0.25 * y.shape[0], ms, scale ** 2)
    return out[:, 0] if squeeze else out


def _dilate(mask: np.ndarray, half: int) -> np.ndarray:
    """``mask`` (N, k) widened by ``half`` samples either side along axis 0, clipped at the ends: the
    same shape whatever ``half`` (a window longer than the record covers all of it)."""
    n = mask.shape[0]
    c = np.concatenate([np.zeros((1, mask.shape[1])), np.cumsum(mask, axis=0)], axis=0)
    i = np.arange(n)
    hi = np.minimum(i + half + 1, n)
    lo = np.maximum(i - half, 0)
    return (c[hi] - c[lo]) > 0


@dataclass(frozen=True)
class NoiseModel:
    """Fitted noise of some channels: ``S(f) = w^2 + c^2 G(f; f_c, p)`` per column (see the module notes).

    ``white`` and ``coloured`` are ``(k,)`` in units/sqrt(Hz) (``eps``'s units,
    relative, for multiplicative noise), ``corner`` (Hz), ``order`` and
    ``design_rate`` (Hz the low-pass was designed at; inf: analogue) ``(k,)``;
    ``modulation`` is ``g(t)`` (N, k) for multiplicative noise, else None.
    """

    channels: tuple[str, ...]
    rate: float
    band_start: float
    white: np.ndarray
    coloured: np.ndarray
    corner: np.ndarray
    order: np.ndarray
    modulation: np.ndarray | None = None
    design_rate: np.ndarray | None = None
    kind: str = "additive"
    corner_given: bool = False
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def n_columns(self) -> int:
        return len(self.channels)

    def psd(self, f) -> np.ndarray:
        """One-sided PSD ``(F, k)`` at frequencies ``f``."""
        f = np.asarray(f, dtype=float)[:, None]
        design = self.design_rate if self.design_rate is not None else np.full(self.n_columns, self.rate)
        return self.white ** 2 + self.coloured ** 2 * _shape(f, self.corner, self.order, design)

    def variance(self) -> np.ndarray:
        """Variance ``(k,)`` of the stationary part (``eps`` for multiplicative noise): the PSD's integral."""
        f = np.linspace(0.0, 0.5 * self.rate, 8193)
        return np.trapezoid(self.psd(f), f, axis=0)

    def rms(self) -> np.ndarray:
        """RMS ``(k,)`` of the noise itself (modulation included)."""
        s = np.sqrt(self.variance())
        if self.modulation is None:
            return s
        return s * np.sqrt(np.mean(self.modulation ** 2, axis=0))

    def scaled(self, factor) -> "NoiseModel":
        """The same spectrum shape with its amplitude multiplied by ``factor`` ((k,) or scalar)."""
        f = np.broadcast_to(np.asarray(factor, dtype=float), self.white.shape)
        return replace(self, white=self.white * f, coloured=self.coloured * f)

    def sample(self, rng, n: int, realisations: int = 1) -> np.ndarray:
        """``(R, n, k)`` Gaussian realisations with the model's spectrum (FFT synthesis: each frequency
        of the record gets an independent complex amplitude of variance ``S(f) rate n / 2``), times the
        modulation for multiplicative noise."""
        f = np.fft.rfftfreq(n, 1.0 / self.rate)
        amp = np.sqrt(self.psd(f) * self.rate * n / 4.0)                         # (F, k), per real part
        z = rng.standard_normal((2, realisations) + amp.shape)
        spec = amp * (z[0] + 1j * z[1])
        spec[:, 0] = spec[:, 0].real * np.sqrt(2.0)
        if n % 2 == 0:
            spec[:, -1] = spec[:, -1].real * np.sqrt(2.0)
        out = np.fft.irfft(spec, n=n, axis=1)
        if self.modulation is not None:
            out = out * self.modulation[None, : n]
        return out

    def to_dict(self) -> dict:
        """JSON-ready description: kind, band start, and per channel the fitted spectrum."""
        rms = self.rms()
        return {
            "kind": self.kind, "band_start_hz": float(self.band_start),
            "channels": {c: {"rms": float(rms[j]), "white_psd": float(self.white[j] ** 2),
                             "coloured_psd": float(self.coloured[j] ** 2),
                             "corner_hz": float(self.corner[j]) if self.coloured[j] > 0 else None,
                             "order": int(self.order[j]) if self.coloured[j] > 0 else None,
                             "designed_at_hz": (None if self.coloured[j] <= 0 or self.design_rate is None
                                                or not np.isfinite(self.design_rate[j])
                                                else float(self.design_rate[j]))}
                         for j, c in enumerate(self.channels)},
            **({"notes": list(self.notes)} if self.notes else {}),
        }

    def describe(self) -> str:
        """One phrase: how many channels are white / coloured, and the corners."""
        col = [j for j in range(self.n_columns) if self.coloured[j] > 0]
        what = "relative " if self.kind == "multiplicative" else ""
        if not col:
            return f"white {what}noise"
        corners = sorted({f"{float(self.corner[j]):.3g}" for j in col})
        src = "given" if self.corner_given else "fitted"
        return (f"{what}noise low-passed at {'/'.join(corners)} Hz ({src}) in {len(col)} of "
                f"{self.n_columns} channels" + (", plus white" if np.any(self.white[col] > 0) else ""))


@functools.lru_cache(maxsize=16)
def _shape_integrals(edges: tuple, rate: float, corners: tuple, shapes: tuple):
    """``{shape: (n_corners, J)}``: each band's integral of the shape ``(order, design rate)``."""
    f, df, gains = _band_gains(edges, rate)
    return {key: np.array([(gains * _shape(f, fc, key[0], key[1])).sum(axis=1) * df for fc in corners])
            for key in shapes}


def _nnls2(a, b, y):
    """Non-negative ``(x1, x2)`` minimising ``|x1 a + x2 b - y|^2`` for a batch: ``a, b, y`` (G, J)."""
    aa, bb, ab = np.sum(a * a, 1), np.sum(b * b, 1), np.sum(a * b, 1)
    ay, by = np.sum(a * y, 1), np.sum(b * y, 1)
    det = aa * bb - ab * ab
    with np.errstate(divide="ignore", invalid="ignore"):
        x1 = np.where(det > 0, (bb * ay - ab * by) / det, -1.0)
        x2 = np.where(det > 0, (aa * by - ab * ay) / det, -1.0)
        only1 = np.maximum(ay / np.maximum(aa, 1e-300), 0.0)
        only2 = np.maximum(by / np.maximum(bb, 1e-300), 0.0)
    both = (x1 >= 0) & (x2 >= 0)
    c1 = np.sum((y - only1[:, None] * a) ** 2, 1)
    c2 = np.sum((y - only2[:, None] * b) ** 2, 1)
    x1 = np.where(both, x1, np.where(c1 <= c2, only1, 0.0))
    x2 = np.where(both, x2, np.where(c1 <= c2, 0.0, only2))
    return x1, x2


def _flat_passband(P, A, weights, edges, corners) -> np.ndarray:
    """``(n_corners, k)``: whether each corner's passband is seen flat in each column of band powers ``P``
    (J, k) -- at least two bands wholly below the corner, and the first band's density ``P / A`` above
    the last one's by no more than twice the standard deviation of their log ratio (``1 / weights`` per
    band): a movement's tail falls by a factor 4 or more per half octave (power ~ f^-4), low-passed
    noise not at all before its corner; the margin keeps low-passed noise coloured in all but a few
    per cent of records."""
    dens = np.log(np.maximum(P, 1e-300) / A[:, None])
    out = np.zeros((len(corners), P.shape[1]), dtype=bool)
    upper = np.asarray(edges[1:], dtype=float)
    for i, fc in enumerate(corners):
        m = int(np.sum(upper <= fc * (1 + 1e-9)))
        if m < 2:
            continue
        spread = 2.0 * np.sqrt(1.0 / weights[0] + 1.0 / weights[m - 1])
        out[i] = (dens[0] - dens[m - 1]) <= spread
    return out


def _fit_column(P, A, B, weights, corners, shapes, allowed=None):
    """Best ``(w2, c2, corner, (order, design))`` for band powers ``P`` (J,): white only or white + coloured
    by BIC; ``B`` maps each shape key ``(order, design rate)`` to its band integrals per corner;
    ``allowed`` (n_corners,) the corners a coloured part may take (default all).

    Non-negative least squares in error relative to the model (a band power's spread is proportional
    to its mean), starting from the data and reweighted twice, for the whole grid at once."""
    J = P.size
    ok = P > 0
    white_only = (0.0, 0.0, float(corners[-1]), (4, np.inf))
    if not ok.any():
        return white_only
    w = weights[ok]
    Pk = P[ok]
    Ak = A[ok]
    # white only: the weighted median of the bands' own estimates, so that signal leaking into the
    # lowest bands (the spectrum of friction steps, a movement's tail) cannot lift it
    est = Pk / Ak
    order_ = np.argsort(est)
    cum = np.cumsum(w[order_])
    median_white = (float(est[order_][np.searchsorted(cum, 0.5 * cum[-1])]),) + white_only[1:]
    if not shapes:
        return median_white
    keys = [(key, k) for key in shapes for k in range(len(corners))]
    Bk = np.array([B[key][k][ok] for key, k in keys])                          # (G, J)
    G = Bk.shape[0]
    Ak2 = np.broadcast_to(Ak, (G + 1, Ak.size))
    Bk2 = np.vstack([np.zeros((1, Ak.size)), Bk])                             # row 0: white only
    ref = np.broadcast_to(Pk, Ak2.shape)
    sw = np.sqrt(w)
    for _ in range(3):
        scale = sw / ref
        x1, x2 = _nnls2(Ak2 * scale, Bk2 * scale, Pk * scale)
        model = x1[:, None] * Ak2 + x2[:, None] * Bk2
        ref = np.where(np.all(model > 0, axis=1, keepdims=True), model, ref)
    chi2 = np.sum(w * np.log(np.maximum(model, 1e-300) / Pk) ** 2, axis=1)
    score = chi2 + np.where(np.arange(G + 1) == 0, 1.0, 3.0) * np.log(J)
    score[1:] = np.where(x2[1:] > 0, score[1:], np.inf)
    if allowed is not None:
        ok_corner = np.array([bool(allowed[k]) for _, k in keys])
        score[1:] = np.where(ok_corner, score[1:], np.inf)
    i = int(np.argmin(score))
    if i == 0:
        return median_white if allowed is not None else (float(x1[0]),) + white_only[1:]
    key, k = keys[i - 1]
    return float(x1[i]), float(x2[i]), float(corners[k]), key


def fit_noise(x, rate: float, band_start: float, *, channels: Sequence[str] | None = None,
              multiplicative: bool = False, corner: float | None = None, design_rate: float | None = None,
              coloured: bool = True, band_scale=None, trim: int | None = None,
              flat_passband: bool = False) -> NoiseModel:
    """Fit a :class:`NoiseModel` to ``x`` (N, k), sampled at ``rate`` Hz, above ``band_start`` Hz.

    ``corner`` fixes the coloured part's low-pass (Hz, e.g. an EMG envelope's);
    ``design_rate`` the rate (Hz) the low-pass was applied at (None: the
    trial's rate or analogue, whichever fits better; e.g. an envelope made at
    1 kHz and sampled at 100 Hz has the analogue shape); ``coloured=False`` fits white noise only (for signals with steps or transients,
    whose spectrum a single record cannot tell from coloured noise);
    ``band_scale`` ``(J,)`` or ``(J, k)`` multiplies the measured band powers
    first (a correction from elsewhere, e.g. a residual that shows less noise
    in a band than the input suggests); ``flat_passband=True`` keeps a fitted coloured part only where
    its passband is seen: at least two bands lie wholly below its corner and their power densities do
    not fall from the first to the last by more than twice their statistical spread (a spectrum that
    falls from the band start on is the tail of the signal, not low-passed noise: white only).  See the
    module notes for the method.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    n, k = x.shape
    names = tuple(channels) if channels is not None else tuple(f"x{j}" for j in range(k))
    edges = band_edges(band_start, rate)
    trim = int(np.ceil(rate / band_start)) if trim is None else int(trim)
    if n <= 2 * trim + 10:
        raise TrialError(f"{n} samples are too few to fit a noise model above {band_start:.3g} Hz")
    modulation = None
    notes = []
    if multiplicative:
        level = lowpass(x, rate=rate, cutoff=band_start, order=FILTER_ORDER)
        peak = np.max(np.abs(level), axis=0, keepdims=True)
        modulation = np.maximum(np.abs(level), 0.01 * np.maximum(peak, 1e-300))
    P = band_powers(x, rate, edges, modulation=modulation, trim=trim)
    if band_scale is not None:
        P = P * np.broadcast_to(np.asarray(band_scale, dtype=float).reshape(P.shape[0], -1), P.shape)
    f, df, gains = _band_gains(tuple(float(e) for e in edges), float(rate))
    A = gains.sum(axis=1) * df
    if corner is not None:
        corners = np.array([float(corner)])
        if not 0 < corner < 0.5 * rate:
            raise TrialError(f"noise corner {corner:g} Hz must lie between 0 and the Nyquist frequency "
                             f"{0.5 * rate:g} Hz")
    else:
        # a corner in the lowest band would put all its power below the bands, where nothing
        # tells it from the signal: the passband must show in at least one band
        corners = np.geomspace(edges[1], TOP_BAND * rate, _N_CORNERS)
    designs = (float(rate), np.inf) if design_rate is None else (float(design_rate),)
    shapes = [(p, dr) for p in _ORDERS for dr in designs] if coloured else []
    B = _shape_integrals(tuple(float(e) for e in edges), float(rate), tuple(float(c) for c in corners),
                         tuple(shapes))
    T = (n - 2 * trim) / rate
    weights = 2.0 * np.diff(edges) * T / LOG_VAR
    w = np.zeros(k)
    c = np.zeros(k)
    fc = np.full(k, corners[-1])
    order = np.full(k, 4)
    design = np.full(k, np.inf)
    allowed = (_flat_passband(P, A, weights, edges, corners) if flat_passband and shapes
               else np.ones((len(corners), k), dtype=bool))
    for j in range(k):
        w2, c2, fcj, (pj, dj) = _fit_column(P[:, j], A, B, weights, corners, shapes,
                                            allowed[:, j] if flat_passband else None)
        w[j], c[j], fc[j], order[j], design[j] = np.sqrt(w2), np.sqrt(c2), fcj, pj, dj
    return NoiseModel(names, float(rate), float(band_start), w, c, fc, order, modulation, design,
                      "multiplicative" if multiplicative else "additive", corner is not None, tuple(notes))
