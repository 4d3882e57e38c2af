"""Gaps in marker trajectories: finding them and filling the short ones.

Interior gaps of up to ``max_gap`` frames are filled by linear interpolation
between the samples either side (exact on a straight line at constant speed);
longer gaps and gaps at the start or end are left as NaN and **flagged**
(``meta["gaps"]``, a warning).  Nothing is ever forward-filled.
:mod:`pinmsk.ik` gives a marker that is NaN in a frame zero weight in that frame.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import TrialError
from ..trial import AXES, Trial, marker_names

__all__ = ["Gap", "find_gaps", "fill_gaps", "DEFAULT_MAX_GAP"]


#: Default longest gap (frames) that :func:`read_trc` fills by interpolation.
DEFAULT_MAX_GAP = 10


@dataclass(frozen=True)
class Gap:
    """A run of missing samples of one marker: frames ``start .. stop-1`` (0-based)."""

    marker: str
    start: int
    stop: int
    t_start: float
    t_stop: float
    filled: bool

    @property
    def length(self) -> int:
        return self.stop - self.start

    def __str__(self) -> str:
        what = "filled" if self.filled else "NOT filled"
        return (f"{self.marker}: {self.length} frame(s) {self.start}-{self.stop - 1} "
                f"({self.t_start:.4g}-{self.t_stop:.4g} s), {what}")


def _runs(bad: np.ndarray) -> list[tuple[int, int]]:
    idx = np.flatnonzero(bad)
    if idx.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    stops = np.concatenate([idx[breaks] + 1, [idx[-1] + 1]])
    return list(zip(starts.tolist(), stops.tolist()))


def find_gaps(trial: Trial, *, max_gap: int = DEFAULT_MAX_GAP) -> list[Gap]:
    """Every run of NaN of every marker, marked ``filled`` if :func:`fill_gaps` would fill it."""
    out = []
    t = trial.time
    n = trial.n_frames
    for m in marker_names(trial):
        cols = [f"{m}_{a}" for a in AXES if f"{m}_{a}" in trial]
        bad = ~np.isfinite(trial.get(cols)).all(axis=1)
        for s, e in _runs(bad):
            interior = s > 0 and e < n
            out.append(Gap(m, s, e, float(t[s]), float(t[e - 1]), bool(interior and e - s <= max_gap)))
    return out


def fill_gaps(trial: Trial, *, max_gap: int = DEFAULT_MAX_GAP, warn: bool = True) -> Trial:
    """Fill interior marker gaps of at most ``max_gap`` frames by linear interpolation.

    A marker is missing in a frame when any of its coordinates is not finite.
    Longer gaps and gaps touching the first or last frame stay NaN; all gaps are
    listed in ``meta["gaps"]`` (:class:`Gap`), and unfilled ones are warned about
    (``warn=False`` to silence).  Values are never carried forward.
    """
    if int(max_gap) != max_gap or max_gap < 0:
        raise TrialError(f"max_gap must be a whole number of frames >= 0, got {max_gap!r}")
    gaps = find_gaps(trial, max_gap=max_gap)
    if not gaps:
        return trial.with_meta(gaps=(), max_gap=int(max_gap))
    t = trial.time
    chans = trial.to_dict(); chans.pop("time")
    for g in gaps:
        cols = [f"{g.marker}_{a}" for a in AXES if f"{g.marker}_{a}" in chans]
        for c in cols:
            x = chans[c]
            x[g.start:g.stop] = np.nan  # a partly missing marker is missing
            if g.filled:
                x[g.start:g.stop] = np.interp(t[g.start:g.stop], [t[g.start - 1], t[g.stop]],
                                              [x[g.start - 1], x[g.stop]])
    flagged = [g for g in gaps if not g.filled]
    if flagged and warn:
        listing = "; ".join(str(g) for g in flagged[:5]) + (" ..." if len(flagged) > 5 else "")
        warnings.warn(
            f"{trial.meta.get('source', 'marker trial')}: {len(flagged)} marker gap(s) longer than "
            f"max_gap={max_gap} frames or at the ends were left as NaN ({listing}); inverse kinematics "
            "gives those markers zero weight in those frames (raise max_gap to interpolate them)",
            stacklevel=2)
    out = Trial(t, chans, units=dict(trial.units), meta={**trial.meta, "gaps": tuple(gaps),
                                                           "max_gap": int(max_gap)})
    return out
