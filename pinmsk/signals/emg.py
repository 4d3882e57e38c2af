"""Surface EMG: envelopes, normalisation across trials, on/off timing.

The linear envelope (e.g. Winter 2009, Sec. 10): zero-lag Butterworth
**band-pass** (default 20-450 Hz: removes movement artefact and high-frequency
noise), full-wave **rectification**, zero-lag Butterworth **low-pass** (default
6 Hz).  For a carrier ``A sin(2 pi f t)`` the envelope is the rectified mean
``2 A / pi`` (times any slow modulation that passes the low-pass).

**Normalisation across trials, not per trial**: :func:`normalize` divides each
muscle by one reference (its peak envelope over *all* the trials given, or a
maximum-voluntary-contraction value), so the relative amplitude of a muscle
between trials is kept; scaling each trial to its own maximum would erase it.

Rates are checked: the band-pass needs ``rate > 2 x high`` edge, and a
``stated_rate`` that disagrees with the time column raises
:class:`~pinmsk.errors.TrialError` (:func:`pinmsk.signals.sampling.check_rate`).
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..errors import TrialError
from ..trial import Trial
from .filtering import bandpass, filter_padlen, lowpass
from .sampling import check_rate, measured_rate

__all__ = ["envelope", "envelopes", "normalize", "on_off", "onset_times", "DEFAULT_BAND",
           "DEFAULT_LOWPASS"]

DEFAULT_BAND = (20.0, 450.0)
DEFAULT_LOWPASS = 6.0


def envelope(x, *, rate: float, band: tuple[float, float] | None = DEFAULT_BAND,
             cutoff: float = DEFAULT_LOWPASS, order: int = 4) -> np.ndarray:
    """Linear envelope of raw EMG ``x`` ((N,) or (N, k), time first) sampled at ``rate`` Hz.

    ``band=None`` skips the band-pass (already band-passed data).  Returns the
    low-passed rectified signal, clipped at 0 (the low-pass may undershoot).
    """
    x = np.asarray(x, dtype=float)
    rate = float(rate)
    if band is not None:
        lo, hi = map(float, band)
        if not (0 < lo < hi):
            raise TrialError(f"EMG band must be (low, high) with 0 < low < high Hz; got {band}")
        if hi >= 0.5 * rate:
            raise TrialError(
                f"the EMG band-pass upper edge {hi:g} Hz is at or above the Nyquist frequency {0.5 * rate:g} Hz "
                f"of the stated rate {rate:g} Hz: either the rate is wrong (EMG is usually sampled at >= 1000 Hz) "
                "or choose band=(low, high) with high < rate / 2")
        n = x.shape[0]
        if n <= filter_padlen(order):
            raise TrialError(f"{n} EMG samples are too few to band-pass")
        if not np.all(np.isfinite(x)):
            raise TrialError("EMG contains NaN/inf; cut or fill the gap before the envelope")
        # the pad of the low-pass below, not scipy's default for the band-pass design
        x = bandpass(x, rate=rate, band=(lo, hi), order=order, padlen=filter_padlen(order))
    env = lowpass(np.abs(x), rate=rate, cutoff=cutoff, order=order)
    return np.maximum(env, 0.0)


def envelopes(trial: Trial, *, channels: Sequence[str] | None = None, stated_rate: float | None = None,
              band: tuple[float, float] | None = DEFAULT_BAND, cutoff: float = DEFAULT_LOWPASS,
              order: int = 4, rename: Mapping[str, str] | None = None) -> Trial:
    """Envelope Trial of EMG channels (default all), named ``rename[c]`` or ``<c>``.

    ``stated_rate`` (Hz, e.g. from the acquisition header) is checked against the time column.
    """
    rate = check_rate(trial, stated_rate, what="EMG") if stated_rate is not None else measured_rate(trial)
    channels = list(trial.names) if channels is None else list(channels)
    env = envelope(trial.get(channels), rate=rate, band=band, cutoff=cutoff, order=order)
    rename = dict(rename or {})
    names = [rename.get(c, c) for c in channels]
    return Trial(trial.time, {n: env[:, j] for j, n in enumerate(names)},
                 meta={**dict(trial.meta), "emg_band": band, "emg_lowpass": cutoff, "emg_rate": rate})


def normalize(trials: Sequence[Trial], *, channels: Sequence[str] | None = None,
              reference: Mapping[str, float] | None = None) -> tuple[list[Trial], dict]:
    """Scale each channel by one value common to all ``trials``: its peak over all of them.

    ``reference`` (e.g. MVC envelope peaks) replaces the peak.  Returns the scaled
    Trials and the ``{channel: scale}`` used.  A single trial is allowed (then it is its
    own reference, which is what per-trial normalisation would do -- say so when reporting).
    """
    trials = list(trials)
    if not trials:
        raise TrialError("normalize needs at least one trial")
    channels = list(trials[0].names) if channels is None else list(channels)
    scale = {}
    for c in channels:
        if reference is not None and c in reference:
            s = float(reference[c])
        else:
            s = max(float(np.nanmax(t[c])) for t in trials)
        if not s > 0:
            raise TrialError(f"EMG channel {c!r} has no positive value in any trial; cannot normalise it")
        scale[c] = s
    out = []
    for t in trials:
        d = t.to_dict(); d.pop("time")
        for c in channels:
            d[c] = d[c] / scale[c]
        out.append(Trial(t.time, d, units=dict(t.units), meta={**dict(t.meta), "emg_scale": scale}))
    return out, scale


def on_off(x, *, threshold: float = 0.25, min_samples: int = 1) -> np.ndarray:
    """Boolean 'on' mask: ``x >= threshold * max(x)``, with 'on' runs shorter than ``min_samples`` dropped."""
    x = np.asarray(x, dtype=float)
    on = x >= threshold * np.nanmax(x)
    if min_samples > 1:
        idx = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(int), [0]])))
        for s, e in zip(idx[::2], idx[1::2]):
            if e - s < min_samples:
                on[s:e] = False
    return on


def onset_times(time, on: np.ndarray) -> list[tuple[float, float]]:
    """``[(t_on, t_off), ...]`` of the runs of ``on``."""
    time = np.asarray(time)
    idx = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(on, dtype=int), [0]])))
    return [(float(time[s]), float(time[e - 1])) for s, e in zip(idx[::2], idx[1::2])]
