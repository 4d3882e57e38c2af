"""OpenSim ``.trc`` marker files: reading and writing.

Measured markers are a :class:`pinmsk.Trial` with channels ``<marker>_x``,
``<marker>_y``, ``<marker>_z`` in **metres** (lab frame as recorded; OpenSim's
y up).  ``meta["markers"]`` lists the marker names in file order.  The
``Units`` field of the header (``mm``, ``cm`` or ``m``) is honoured; data
whose size contradicts it (a 1.7 m person recorded as 0.0017 m or 1700 m) is
refused with a message that names the header field.  Short gaps are filled by
:func:`pinmsk.signals.gaps.fill_gaps`.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import TrialError
from ..signals.gaps import DEFAULT_MAX_GAP, fill_gaps
from ..trial import AXES, Trial, marker_array, marker_names
from .output_files import atomic_write

__all__ = ["read_trc", "write_trc", "UNIT_SCALE"]


#: Length units a TRC header may declare, as metres per unit.
UNIT_SCALE = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "dm": 0.1, "meters": 1.0, "millimeters": 1e-3,
              "centimeters": 1e-2}


#: A human marker cloud spans between these sizes (m) in a frame; outside them the
#: declared unit is wrong by a factor of 1000 or more.
_SPAN_RANGE = (0.02, 20.0)


def _split(line: str, sep: str | None) -> list[str]:
    line = line.rstrip("\r\n")
    if sep is None:
        return line.split()
    return [c.strip() for c in line.split(sep)]


def _check_units(xyz: np.ndarray, unit: str, scale: float, path) -> None:
    """Refuse data whose spread contradicts the declared unit (``xyz`` in m, (N, M, 3))."""
    if xyz.shape[1] >= 2:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            span = np.nanmax(xyz, axis=1) - np.nanmin(xyz, axis=1)      # (N, 3)
            size = np.nanmedian(np.nanmax(span, axis=1))
        what = "the markers span"
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            size = np.nanmedian(np.nanmax(np.abs(xyz[:, 0, :]), axis=1))
        what = "the marker lies"
        if not np.isfinite(size) or size == 0:
            return
    if not np.isfinite(size):
        return
    lo, hi = _SPAN_RANGE
    if lo <= size <= hi:
        return
    guess = [u for u, s in (("mm", 1e-3), ("cm", 1e-2), ("m", 1.0)) if lo <= size / scale * s <= hi]
    raise TrialError(
        f"{path}: the header declares Units={unit!r}, but then {what} {size:.4g} m in a typical frame "
        f"(a body is {lo}-{hi} m); the units contradict the header"
        + (f" -- the numbers look like {guess[0]!r}" if guess else "")
        + "; fix the Units field of the header (or pass units=... to read_trc)"
    )


def read_trc(path, *, max_gap: int = DEFAULT_MAX_GAP, units: str | None = None,
             check_units: bool = True, warn: bool = True) -> Trial:
    """Read an OpenSim ``.trc`` marker file into a Trial of ``<marker>_{x,y,z}`` in metres.

    Parameters
    ----------
    path : str or Path
    max_gap : int
        Longest interior gap (frames) filled by linear interpolation; see :func:`fill_gaps`.
    units : str, optional
        Override the header's ``Units`` (``"mm"``, ``"cm"``, ``"m"``); by default the header is used.
    check_units : bool
        Refuse data whose spread contradicts the units (default True).

    ``meta``: ``source``, ``format="trc"``, ``markers``, ``units`` (as declared),
    ``rate`` (``DataRate``), ``header`` (the key/value fields), ``gaps``,
    ``declared_frames``, and ``file_time`` (the Time column as written) when rounded times were rebuilt
from the rate.  Missing cells (empty or NaN) are gaps.  The header's
    ``NumFrames`` may exceed the rows present (excerpts); this is noted in
    ``meta["read_notes"]``, not an error.
    """
    path = Path(path)
    if not path.exists():
        raise TrialError(f"TRC file not found: {path}")
    lines = path.read_text(errors="replace").splitlines()
    if len(lines) < 5:
        raise TrialError(f"{path}: a TRC file has at least 5 header lines; this one has {len(lines)} lines")
    sep = "\t" if "\t" in lines[3] else ("," if "," in lines[3] else None)
    keys = [k for k in _split(lines[1], sep) if k]
    vals = [v for v in _split(lines[2], sep) if v]
    if len(vals) < len(keys):
        raise TrialError(f"{path}: line 2 has {len(keys)} header keys but line 3 only {len(vals)} values")
    header = dict(zip(keys, vals))
    unit = units if units is not None else header.get("Units")
    if unit is None:
        raise TrialError(f"{path}: the header has no 'Units' field (line 2); pass units='mm' or 'm'")
    scale = UNIT_SCALE.get(unit.strip().lower())
    if scale is None:
        raise TrialError(f"{path}: unknown Units {unit!r} (known: {', '.join(UNIT_SCALE)})")
    try:
        rate = float(header.get("DataRate", header.get("CameraRate")))
    except (TypeError, ValueError):
        raise TrialError(f"{path}: the header has no numeric DataRate (line 3)") from None
    name_cells = _split(lines[3], sep)
    if len(name_cells) < 2 or name_cells[0].lower().rstrip("#") not in ("frame",) or name_cells[1].lower() != "time":
        raise TrialError(f"{path}: line 4 must start with 'Frame#' and 'Time', got {name_cells[:2]}")
    if sep is None:
        markers = name_cells[2:]
    else:
        markers = [c for c in name_cells[2:] if c]
    markers = [m.strip() for m in markers]
    nm = len(markers)
    rows, times = [], []
    notes = []
    for k, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = _split(line, sep)
        if sep is not None:
            while cells and cells[-1] == "" and len(cells) > 2 + 3 * nm:
                cells.pop()
        if len(cells) < 2 or (cells[0] == "" and cells[1] == ""):
            continue  # blank or separator-only line
        vals_ = cells[2:2 + 3 * nm]
        if sep is None and len(vals_) < 3 * nm:
            raise TrialError(f"{path}: line {k} has {len(vals_)} coordinates for {nm} markers "
                             "(whitespace-separated files cannot mark missing values; use NaN)")
        if len(vals_) < 3 * nm:  # trailing markers missing in this row
            vals_ = vals_ + [""] * (3 * nm - len(vals_))
        try:
            times.append(float(cells[1]))
            rows.append([float(v) if v not in ("", "nan", "NaN") else np.nan for v in vals_])
        except ValueError as exc:
            raise TrialError(f"{path}: line {k}: {exc}") from None
    if not rows:
        raise TrialError(f"{path}: no data rows after the 5 header lines")
    data = np.array(rows, dtype=float) * scale
    declared = header.get("NumFrames")
    if declared is not None and declared.isdigit() and int(declared) != len(rows):
        notes.append(f"header NumFrames={declared} but {len(rows)} data rows are present")
    xyz = data.reshape(len(rows), nm, 3)
    empty = np.all(np.isnan(xyz), axis=(0, 2))
    if empty.any():  # e.g. virtual markers named in the header but without data columns
        notes.append(f"markers named on line 4 but with no data, dropped: "
                     f"{', '.join(m for m, e in zip(markers, empty) if e)}")
        markers = [m for m, e in zip(markers, empty) if not e]
        xyz = xyz[:, ~empty]
        nm = len(markers)
    seen: set = set()
    dup = sorted({m for m in markers if m in seen or seen.add(m)})
    if dup:
        raise TrialError(f"{path}: duplicate marker name(s) {', '.join(map(repr, dup))} on line 4 (with data); "
                         "duplicate column names are ambiguous -- rename them so each marker is unique")
    if check_units:
        _check_units(xyz, unit, scale, path)
    chans = {}
    for i, m in enumerate(markers):
        for j, a in enumerate(AXES):
            chans[f"{m}_{a}"] = xyz[:, i, j]
    t = np.asarray(times)
    file_time = None
    dt = np.diff(t)
    if dt.size and np.any(dt <= 0):
        r = int(np.flatnonzero(dt <= 0)[0])
        raise TrialError(f"{path}: Time is not increasing at data row {r + 2} "
                         f"({t[r]:.6g} then {t[r + 1]:.6g} s)")
    if dt.size:
        mean_step = (t[-1] - t[0]) / dt.size
        if abs(mean_step * rate - 1) > 0.01:
            raise TrialError(f"{path}: the header says DataRate={rate:g} Hz, but the Time column steps by "
                             f"{mean_step:.6g} s on average ({1 / mean_step:.6g} Hz); fix the header or the times")
        if np.max(np.abs(dt - mean_step)) > 0.01 * mean_step:
            # times printed with too few decimals (0.007, 0.006, ... at 150 Hz): rebuild from the rate
            notes.append(f"Time column rounded (steps {dt.min():.6g}-{dt.max():.6g} s); times rebuilt as "
                         f"t0 + k / DataRate ({rate:g} Hz)")
            file_time = t
            t = t[0] + np.arange(t.size) / rate
    meta = {"source": str(path), "format": "trc", "markers": tuple(markers), "units": unit,
            "rate": rate, "header": header, "declared_frames": declared, "read_notes": tuple(notes)}
    if file_time is not None:
        meta["file_time"] = file_time
    trial = Trial(t, chans, units={c: "m" for c in chans}, meta=meta)
    return fill_gaps(trial, max_gap=max_gap, warn=warn)


def write_trc(trial: Trial, path, *, units: str = "mm", markers: Sequence[str] | None = None) -> Path:
    """Write a marker Trial (metres) as a tab-separated TRC file in ``units``; NaN -> empty cell."""
    path = Path(path)
    markers = marker_names(trial) if markers is None else tuple(markers)
    scale = UNIT_SCALE[units]
    xyz = marker_array(trial, markers) / scale
    n = trial.n_frames
    rate = trial.rate if n > 1 else 1.0
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{rate:g}\t{rate:g}\t{n}\t{len(markers)}\t{units}\t{rate:g}\t1\t{n}",
             "Frame#\tTime\t" + "\t\t\t".join(markers) + "\t\t",
             "\t\t" + "\t".join(f"{a}{i + 1}" for i in range(len(markers)) for a in "XYZ"),
             ""]
    for k in range(n):
        cells = ["" if not np.isfinite(v) else f"{v:.9g}" for v in xyz[k].ravel()]
        lines.append(f"{k + 1}\t{trial.time[k]:.9g}\t" + "\t".join(cells))
    text = "\n".join(lines) + "\n"
    return atomic_write(path, lambda fh: fh.write(text))
