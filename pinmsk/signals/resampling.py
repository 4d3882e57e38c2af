"""Aligning channels recorded at different rates (markers 100 Hz, force plates and EMG 2000 Hz).

* one Trial onto other times is :meth:`pinmsk.Trial.resample` (with ``antialias=True``
  it low-passes first when the new rate is lower);
* :func:`align` -- several Trials onto one common time base over the time they
  all cover, merged into one Trial (duplicate channel names are refused).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..errors import TrialError
from ..trial import Trial
from .sampling import measured_rate

__all__ = ["align", "common_time"]


def common_time(trials: Sequence[Trial], *, rate: float) -> np.ndarray:
    """Times at ``rate`` Hz over the interval all ``trials`` cover."""
    t0 = max(float(t.time[0]) for t in trials)
    t1 = min(float(t.time[-1]) for t in trials)
    if t1 <= t0:
        spans = ", ".join(f"{t.time[0]:.4g}-{t.time[-1]:.4g} s" for t in trials)
        raise TrialError(f"the trials do not overlap in time ({spans}); check their start times")
    n = int(math.floor((t1 - t0) * rate * (1 + 1e-12) + 1e-9)) + 1
    return t0 + np.arange(n) / rate


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
    out = trials[0].resample(time, method="linear", antialias=antialias)
    for t in trials[1:]:
        out = out.merge(t.resample(time, method="linear", antialias=antialias))
    return out
