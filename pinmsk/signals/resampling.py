"""Aligning channels recorded at different rates (markers 100 Hz, force plates and EMG 2000 Hz).

* :func:`to_time` -- one Trial onto given times (linear by default; optional
  anti-alias low-pass when the new rate is lower; channels with NaN, such as
  the COP of an unloaded plate, are interpolated linearly without filtering).
* :func:`align` -- several Trials onto one common time base over the time they
  all cover, merged into one Trial (duplicate channel names are refused).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..errors import TrialError
from .filtering import lowpass
from .sampling import measured_rate, median_step
from ..trial import Trial

__all__ = ["to_time", "align", "common_time"]


def common_time(trials: Sequence[Trial], *, rate: float) -> np.ndarray:
    """Times at ``rate`` Hz over the interval all ``trials`` cover."""
    t0 = max(float(t.time[0]) for t in trials)
    t1 = min(float(t.time[-1]) for t in trials)
    if t1 <= t0:
        spans = ", ".join(f"{t.time[0]:.4g}-{t.time[-1]:.4g} s" for t in trials)
        raise TrialError(f"the trials do not overlap in time ({spans}); check their start times")
    n = int(math.floor((t1 - t0) * rate * (1 + 1e-12) + 1e-9)) + 1
    return t0 + np.arange(n) / rate


def to_time(trial: Trial, time, *, antialias: bool = True, order: int = 4) -> Trial:
    """``trial`` interpolated (linearly) onto ``time``; low-passed first if that lowers the rate.

    The anti-alias filter is a zero-lag Butterworth at 0.4 x the new rate, applied to the
    finite channels only.  Times outside the trial are an error (no extrapolation).
    """
    time = np.asarray(time, dtype=float)
    src = trial
    if antialias and time.size > 1 and trial.n_frames > 1:
        new_rate = 1.0 / median_step(time)
        old_rate = measured_rate(trial)
        if new_rate < 0.99 * old_rate:
            finite = [n for n in trial.names if np.all(np.isfinite(trial[n]))]
            if finite:
                vals = trial.to_dict(); vals.pop("time")
                filt = lowpass(trial.get(finite), rate=old_rate, cutoff=0.4 * new_rate, order=order)
                for j, n in enumerate(finite):
                    vals[n] = filt[:, j]
                src = Trial(trial.time, vals, units=dict(trial.units), meta=dict(trial.meta))
    return src.resample(time, method="linear")


def align(*trials: Trial, rate: float | None = None, time=None, antialias: bool = True) -> Trial:
    """Merge Trials sampled at different rates onto one time base.

    ``time`` (explicit times) or ``rate`` (Hz, over the common interval); default the rate
    of the first trial.  Channel names must be unique across the trials.
    """
    if not trials:
        raise TrialError("align needs at least one trial")
    names: dict = {}
    for i, t in enumerate(trials):
        for n in t.names:
            if n in names:
                raise TrialError(f"channel {n!r} is in trial {names[n]} and trial {i}; duplicate column "
                                 "names are ambiguous: rename or drop one before aligning")
            names[n] = i
    if time is None:
        rate = measured_rate(trials[0]) if rate is None else float(rate)
        time = common_time(trials, rate=rate)
    out = to_time(trials[0], time, antialias=antialias)
    for t in trials[1:]:
        out = out.merge(to_time(t, time, antialias=antialias))
    return out
