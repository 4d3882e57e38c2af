"""Shared helpers of the muscle layer: input checks, error locations, parameter arrays.

Muscle quantities are time-first arrays ``(N, m)`` (frames x muscles); per-muscle
parameters are ``(m,)`` and broadcast against them.  A scalar or an ``(m,)``
array is a single frame.  Error messages name the muscle (index, and name when
known) and the frame, because a NaN in one of 1.6 million muscle-frames is
otherwise impossible to find.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import ModelError, TrialError

__all__ = ["as_array", "check_active", "check_finite", "locate", "muscle_parameter", "where_first"]


def as_array(x, what: str) -> np.ndarray:
    """``x`` as a float ndarray (no copy when it already is one)."""
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TrialError(f"{what} must be numeric, got {type(x).__name__}: {exc}") from None


def where_first(mask: np.ndarray) -> tuple[int | None, int | None]:
    """(frame, muscle) of the first True element of a boolean array.

    Arrays are time-first, so the last axis is the muscle and the first the
    frame; 1-D arrays are one frame over muscles; scalars have neither.
    """
    mask = np.asarray(mask)
    if mask.ndim == 0:
        return None, None
    flat = int(np.flatnonzero(mask.ravel())[0])
    idx = np.unravel_index(flat, mask.shape)
    if mask.ndim == 1:
        return None, int(idx[0])
    return int(idx[0]), int(idx[-1])


def locate(frame: int | None, muscle: int | None, names: Sequence[str] | None = None) -> str:
    """Human-readable location: ``muscle 3 ('soleus') at frame 120``."""
    parts = []
    if muscle is not None:
        label = f"muscle {muscle}"
        if names is not None and 0 <= muscle < len(names):
            label += f" ({names[muscle]!r})"
        parts.append(label)
    if frame is not None:
        parts.append(f"frame {frame}")
    return " at ".join(parts) if parts else "the scalar input"


def check_finite(names: Sequence[str] | None = None, **arrays) -> None:
    """Raise :class:`TrialError` naming the first non-finite input, its muscle and frame."""
    for what, arr in arrays.items():
        if arr is None:
            continue
        a = np.asarray(arr)
        # isfinite().all() is one fast pass; only locate the culprit on failure.
        if not np.isfinite(a).all():
            bad = ~np.isfinite(a)
            frame, muscle = where_first(bad)
            value = a[np.unravel_index(int(np.flatnonzero(bad.ravel())[0]), a.shape)] if a.ndim else a
            raise TrialError(
                f"{what} is {float(value)} for {locate(frame, muscle, names)} "
                f"({int(bad.sum())} non-finite value(s) in total); remove or interpolate the "
                "gaps in the kinematics/forces before calling the muscle model")


def check_active(a: np.ndarray, l_ce: np.ndarray, names: Sequence[str] | None = None) -> None:
    """Raise :class:`TrialError` at the first activation ``a <= 0`` (contraction dynamics needs ``a > 0``).

    ``a`` broadcasts against the fiber lengths ``l_ce``; the message names the muscle and frame.
    """
    if not (a > 0).all():
        frame, muscle = where_first(~(np.broadcast_to(a, np.broadcast_shapes(a.shape, l_ce.shape)) > 0))
        raise TrialError(f"contraction dynamics needs activation > 0, got a <= 0 at "
                         f"{locate(frame, muscle, names)}; clip activation to a minimum "
                         "such as 0.01")


def muscle_parameter(value, what: str, m: int, *, names: Sequence[str] | None = None,
                     positive: bool = True, low: float | None = None,
                     high: float | None = None, high_open: bool = False) -> np.ndarray:
    """A read-only float copy of a per-muscle parameter broadcast to ``(m,)``.

    Raises :class:`ModelError` naming the first invalid muscle.
    """
    try:
        arr = np.array(np.broadcast_to(np.asarray(value, dtype=float), (m,)), dtype=float)
    except ValueError:
        raise ModelError(f"{what} has shape {np.shape(value)}; expected a scalar or ({m},) "
                         "(one value per muscle)") from None
    bad = ~np.isfinite(arr)
    if positive:
        bad |= ~(arr > 0)
    if low is not None:
        bad |= arr < low
    if high is not None:
        bad |= (arr >= high) if high_open else (arr > high)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        rule = "must be finite"
        if positive:
            rule += " and > 0"
        if low is not None:
            rule += f" and >= {low}"
        if high is not None:
            rule += f" and {'<' if high_open else '<='} {high:g}"
        raise ModelError(f"{what} = {float(arr[i])!r} for {locate(None, i, names)}; it {rule}")
    arr.flags.writeable = False
    return arr


def n_muscles(*values) -> int:
    """The number of muscles implied by per-muscle parameters (the longest 1-D one)."""
    m = 1
    for v in values:
        if v is None:
            continue
        shape = np.shape(v)
        if len(shape) > 1:
            raise ModelError(f"per-muscle parameters must be scalars or 1-D, got shape {shape}")
        if shape:
            if m != 1 and shape[0] not in (1, m):
                raise ModelError(f"per-muscle parameters disagree on the number of muscles "
                                 f"({m} vs {shape[0]})")
            m = max(m, shape[0])
    return m
