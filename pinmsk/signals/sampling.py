"""The sampling rate a time column shows, checked against one tolerance.

Every analysis that needs a rate (filtering, differentiation, resampling, EMG
envelopes) takes it from :func:`uniform_rate`: the median time step, accepted
when no step differs from it by more than :data:`UNIFORM_TOLERANCE`.  That
covers time stamps rounded to a few decimals (600 Hz written as 0.0017,
0.0033, 0.005 deviates by 4 %) and refuses dropped frames (a doubled step
deviates by 100 %).  :func:`check_rate` compares the measured rate with one a
file header or a user states.
"""
from __future__ import annotations

import numpy as np

from ..errors import TrialError

__all__ = ["UNIFORM_TOLERANCE", "RATE_AGREEMENT", "median_step", "check_increasing", "uniform_rate",
           "measured_rate", "check_rate"]

#: Largest relative deviation of one time step from the median step that still counts as
#: uniform sampling.
UNIFORM_TOLERANCE = 0.1

#: Largest relative difference between a stated and the measured rate (:func:`check_rate`).
RATE_AGREEMENT = 0.01


def median_step(time) -> float:
    """Median time step (s) of a time column; ``nan`` for fewer than 2 samples."""
    t = np.asarray(time, dtype=float)
    return float(np.median(np.diff(t))) if t.size > 1 else float("nan")


def check_increasing(time, *, where: str = "") -> np.ndarray:
    """The time steps of ``time``; TrialError naming the row where time does not increase."""
    t = np.asarray(time, dtype=float)
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        row = int(bad[0]) + 1
        raise TrialError(
            f"{where}time is not strictly increasing at row {row}: time[{row}]={float(t[row])!r} "
            f"<= time[{row - 1}]={float(t[row - 1])!r} ({bad.size} such row(s)); sort the samples "
            "or remove repeated frames")
    return dt


def uniform_rate(time, *, where: str = "", purpose: str = "filtering") -> float:
    """Sampling rate (Hz) of ``time``; TrialError unless it increases with uniform steps.

    ``where`` prefixes the message (e.g. ``"walk.csv: "``); ``purpose`` says what
    needed the rate.
    """
    t = np.asarray(time, dtype=float)
    if t.size < 2:
        raise TrialError(f"{where}{purpose} needs at least 2 samples")
    dt = check_increasing(t, where=where)
    step = float(np.median(dt))
    dev = np.abs(dt - step)
    k = int(np.argmax(dev))
    if dev[k] > UNIFORM_TOLERANCE * step:
        raise TrialError(
            f"{where}{purpose} needs uniform sampling, but the time step at row {k + 1} is {dt[k]:.6g} s "
            f"against a median of {step:.6g} s (steps range {dt.min():.6g} to {dt.max():.6g} s); resample "
            f"first, e.g. trial.resample({1 / step:.6g})")
    return 1.0 / step


def _where(trial) -> str:
    src = trial.meta.get("source")
    return f"{src}: " if src else ""


def measured_rate(trial) -> float:
    """The uniform sampling rate (Hz) of a Trial's time column (:func:`uniform_rate`)."""
    return uniform_rate(trial.time, where=_where(trial), purpose="a sampling rate")


def check_rate(trial, stated: float, *, what: str = "signal", tolerance: float = RATE_AGREEMENT) -> float:
    """The measured rate; TrialError if it differs from ``stated`` Hz by more than ``tolerance``."""
    r = measured_rate(trial)
    if abs(r / float(stated) - 1.0) > tolerance:
        raise TrialError(
            f"{trial.meta.get('source', what)}: the {what} is stated to be sampled at {stated:g} Hz, but its "
            f"time column steps at {r:.6g} Hz ({1 / r:.6g} s per sample); check the acquisition rate in "
            "the header or the time column (a wrong rate shifts every event and filter cut-off)")
    return r
