"""Marker trajectories: the OpenSim ``.trc`` reader, gap handling and model marker sets.

Measured markers are a :class:`pinmsk.Trial` with channels ``<marker>_x``,
``<marker>_y``, ``<marker>_z`` in **metres** (lab frame as recorded; OpenSim's
y up).  ``meta["markers"]`` lists the marker names in file order.

* :func:`read_trc` -- TRC files (tab, comma or whitespace separated).  The
  ``Units`` field of the header (``mm``, ``cm`` or ``m``) is honoured; data
  whose size contradicts it (a 1.7 m person recorded as 0.0017 m or 1700 m)
  is refused with a message that names the header field.
* :func:`fill_gaps` -- interior gaps of up to ``max_gap`` frames are filled by
  linear interpolation between the samples either side (exact on a straight
  line at constant speed); longer gaps and gaps at the start or end are left as
  NaN and **flagged** (``meta["gaps"]``, a warning).  Nothing is ever
  forward-filled.  :mod:`pinmsk.ik` gives a marker that is NaN in a frame zero
  weight in that frame.
* :func:`load_marker_set` -- the model's markers (body + position in the body
  frame) from a TOML ``[[markers]]`` table, e.g. ``urdf/markers_gait2d.toml``.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from .errors import ModelError, TrialError
from .io.toml_files import read_toml
from .trial import Trial

__all__ = ["read_trc", "fill_gaps", "find_gaps", "Gap", "marker_names", "marker_array",
           "ModelMarker", "MarkerSet", "load_marker_set", "UNIT_SCALE", "DEFAULT_MAX_GAP"]

#: Length units a TRC header may declare, as metres per unit.
UNIT_SCALE = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "dm": 0.1, "meters": 1.0, "millimeters": 1e-3,
              "centimeters": 1e-2}

#: Default longest gap (frames) that :func:`read_trc` fills by interpolation.
DEFAULT_MAX_GAP = 10

#: A human marker cloud spans between these sizes (m) in a frame; outside them the
#: declared unit is wrong by a factor of 1000 or more.
_SPAN_RANGE = (0.02, 20.0)

AXES = ("x", "y", "z")


# ---------------------------------------------------------------------------
# gaps
# ---------------------------------------------------------------------------

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


def marker_names(trial: Trial) -> tuple[str, ...]:
    """Marker names of a marker Trial (``meta["markers"]``, or from ``<m>_x`` channels)."""
    names = trial.meta.get("markers")
    if names:
        return tuple(names)
    return tuple(n[:-2] for n in trial.names if n.endswith("_x") and f"{n[:-2]}_y" in trial)


def marker_array(trial: Trial, names: Sequence[str] | None = None, *, axes: str = "xyz") -> np.ndarray:
    """Marker positions ``(N, M, len(axes))`` (m) of ``names`` (default: all markers).

    Absent axes (2-D data has no ``_z``) are an error unless left out of ``axes``.
    """
    names = marker_names(trial) if names is None else tuple(names)
    cols = [f"{m}_{a}" for m in names for a in axes]
    missing = [c for c in cols if c not in trial]
    if missing:
        raise TrialError(f"marker trial has no channels {', '.join(missing[:5])}"
                         f"{' ...' if len(missing) > 5 else ''} (markers: {', '.join(marker_names(trial))})")
    return trial.get(cols).reshape(trial.n_frames, len(names), len(axes))


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


# ---------------------------------------------------------------------------
# TRC
# ---------------------------------------------------------------------------

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
    ``declared_frames``.  Missing cells (empty or NaN) are gaps.  The header's
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
            t = t[0] + np.arange(t.size) / rate
    meta = {"source": str(path), "format": "trc", "markers": tuple(markers), "units": unit,
            "rate": rate, "header": header, "declared_frames": declared, "read_notes": tuple(notes)}
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
    from .io.output_files import atomic_write
    text = "\n".join(lines) + "\n"
    return atomic_write(path, lambda fh: fh.write(text))


# ---------------------------------------------------------------------------
# model marker sets
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class ModelMarker:
    """A marker fixed in a body: ``position`` (m) in the frame of ``body``; ``weight`` in IK."""

    name: str
    body: str
    position: tuple[float, float, float]
    weight: float = 1.0
    description: str = ""


@dataclass(frozen=True)
class MarkerSet:
    """Named model markers, optionally grouped into sets (``sets["csu"] = ("RSHO", ...)``)."""

    markers: tuple[ModelMarker, ...]
    sets: dict
    model: str | None = None
    source: str | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.markers)

    def __getitem__(self, name: str) -> ModelMarker:
        for m in self.markers:
            if m.name == name:
                return m
        raise ModelError(f"marker set {self.source or ''} has no marker {name!r} (has: {', '.join(self.names)})")

    def __len__(self) -> int:
        return len(self.markers)

    def subset(self, names: Iterable[str]) -> "MarkerSet":
        """The markers of a named set (``"csu"``) or of a list of marker names, in that order."""
        if isinstance(names, str):
            if names not in self.sets:
                raise ModelError(f"marker set {self.source or ''} has no set {names!r} "
                                 f"(sets: {', '.join(self.sets) or 'none'})")
            names = self.sets[names]
        return MarkerSet(tuple(self[n] for n in names), {}, self.model, self.source)

    def renamed(self, mapping: dict) -> "MarkerSet":
        """Rename markers (``{"RSHO": "R.Shoulder"}``) so they match the measured names."""
        ms = tuple(ModelMarker(mapping.get(m.name, m.name), m.body, m.position, m.weight, m.description)
                   for m in self.markers)
        return MarkerSet(ms, {}, self.model, self.source)


def load_marker_set(path) -> MarkerSet:
    """Read model markers from a TOML file with a ``[[markers]]`` table.

    Each entry has ``name``, ``body`` (a frame of the model), ``position`` =
    ``[x, y, z]`` (m, in that body's frame) and optionally ``weight`` (default
    1) and ``description``.  An optional ``[sets]`` table maps set names to lists
    of marker names (e.g. ``csu = ["RSHO", ...]``).  A bare name such as
    ``"gait2d"`` loads the built-in ``urdf/markers_gait2d.toml``.
    """
    p = Path(path)
    if not p.suffix and not p.exists():
        from .builtin_models import builtin_dir

        p = builtin_dir() / f"markers_{path}.toml"
    doc = read_toml(p, what="marker set file")
    entries = doc.get("markers")
    if not entries:
        raise ModelError(f"{p}: no [[markers]] table")
    out, seen = [], set()
    for k, e in enumerate(entries):
        where = f"{p}: [[markers]] entry {k + 1}"
        for key in ("name", "body", "position"):
            if key not in e:
                raise ModelError(f"{where} has no {key!r}")
        if e["name"] in seen:
            raise ModelError(f"{where}: duplicate marker name {e['name']!r}")
        seen.add(e["name"])
        pos = e["position"]
        if len(pos) != 3:
            raise ModelError(f"{where} ({e['name']}): position must be [x, y, z] in metres, got {pos!r}")
        w = float(e.get("weight", 1.0))
        if not w >= 0:
            raise ModelError(f"{where} ({e['name']}): weight must be >= 0, got {w}")
        out.append(ModelMarker(str(e["name"]), str(e["body"]), tuple(float(x) for x in pos), w,
                               str(e.get("description", ""))))
    sets = {k: tuple(v) for k, v in doc.get("sets", {}).items()}
    for s, names in sets.items():
        bad = [n for n in names if n not in seen]
        if bad:
            raise ModelError(f"{p}: set {s!r} names unknown markers {bad}")
    return MarkerSet(tuple(out), sets, doc.get("model", {}).get("name") if isinstance(doc.get("model"), dict)
                     else doc.get("model"), str(p))
