"""Reading and writing Trials: CSV and OpenSim ``.sto`` / ``.mot`` files (and reading ``.c3d``).

Formats (chosen by suffix, case-insensitive):

* ``.csv``: one header row of column names, the first of which is the time
  (``time``, ``t``, ``Time (s)``, ``Time [ms]``: a unit in the label is
  converted to seconds); then one row per frame.  Values are SI (angles in
  radians) unless the reader is told otherwise (``in_degrees=True``,
  ``--degrees``): a CSV cannot declare degrees itself.
* ``.sto`` / ``.mot`` (OpenSim storage): header lines up to a line
  ``endheader``.  The first line is the table name unless it is a
  ``key=value`` line; ``key=value`` lines give fields such as ``version``,
  ``nRows``, ``nColumns`` (time included), ``inDegrees`` and ``DataType``
  (old ``datarows N`` / ``datacolumns N`` lines are read too); other lines are
  comments.  Then a column-label line starting with ``time`` and the data.
  Columns are tab separated, or comma separated, or separated by whitespace,
  chosen from the label line; trailing separators are ignored.
* ``.c3d`` (read only, with the optional ``ezc3d``: ``pip install pinmsk[c3d]``):
  the markers, the analog channels or the force platforms, one time base
  per Trial (``read_trial(path, part=...)``).

Lenient reading: a header row or column count that disagrees with the data,
or a row repeating the time stamp of the row before, is an error unless
``strict=False`` (``--lenient`` on the command line); then each repair is a
:class:`pinmsk.errors.RepairWarning` saying exactly what was done.

Degrees: when a file says ``inDegrees=yes`` the angular channels are
converted to radians at read (``meta["converted_to_radians"]`` lists them).
Which channels are angular: ``angular`` if given, else those that
:func:`pinmsk.trial.is_angular_name` accepts (not ``time``; not ending in
``_tx/_ty/_tz``, ``_x/_y/_z``, ``_p[xyz]``, ``_v[xyz]``; not containing
force, moment, torque, activation, excitation, emg, length, power, energy).
:func:`write_trial` stores radians with ``inDegrees=no`` unless asked for
``in_degrees=True``, which writes the angular channels in degrees.

Writes are atomic (:func:`pinmsk.io.output_files.atomic_write`).  Numbers
are written as ``%.9g`` (``precision=9`` significant digits, about what
measured or computed channels carry); ``precision=17`` writes every float64
exactly, so a write then read gives the same values.  The time column gets
more digits where 9 would not keep its steps distinct to 1 %.

Time is in seconds, or in the unit its label declares; a time column without a
unit that looks like milliseconds (a median step of 0.2 to 100) is refused
unless ``time_unit`` (``--time-unit``) says what it is.

Errors are :class:`pinmsk.errors.TrialError` naming the file, line and column.
"""

from __future__ import annotations

import csv
import functools
import io as _io
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pinmsk.errors import RepairWarning, TrialError
from pinmsk.trial import TIME, TIME_UNITS, Trial, is_angular_name, time_label_unit

from ..signals.sampling import median_step
from .c3d import read_c3d
from .output_files import atomic_write

__all__ = ["read_trial", "write_trial", "read_sto_header", "StoHeader", "FORMATS", "C3D_PARTS",
           "state_path_coordinate", "check_precision", "DEFAULT_PRECISION"]

#: File suffix -> format name.
FORMATS = {".csv": "csv", ".sto": "sto", ".mot": "mot"}

#: Significant digits written by default (``write_trial(precision=...)``, CLI ``--precision``).
DEFAULT_PRECISION = 9
#: A median time step above this (s), i.e. a rate below 5 Hz, is not a motion recording in
#: seconds; with a step of at most 100 it is one in milliseconds (10 Hz - 5 kHz).
_MS_STEP = (0.2, 100.0)
_KEY_VALUE = re.compile(r"^([A-Za-z_][\w.\-]*)\s*=\s*(.*)$")
_OLD_KEY = re.compile(r"^(datarows|datacolumns)\s+(\S+)$", re.IGNORECASE)


def _format_of(path: Path, *, reading: bool = False) -> str:
    kind = FORMATS.get(path.suffix.lower())
    if kind is None:
        kinds = ", ".join(FORMATS) + (" (or .c3d)" if reading else "")
        raise TrialError(f"file {str(path)!r}: unsupported file type {path.suffix!r}; use one of {kinds}")
    return kind


def _read_lines(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8-sig", errors="replace")
    return text.splitlines()


def _clean(line: str) -> str:
    """A header line without surrounding whitespace and trailing separators."""
    return line.strip().rstrip(",\t ").strip()


# ---------------------------------------------------------------------------
# Header
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class StoHeader:
    """The header of an OpenSim ``.sto`` / ``.mot`` file.

    ``fields`` maps each ``key=value`` key as written to its value (strings);
    ``lines`` maps the same keys to their 1-based line numbers; ``n_lines`` is
    the number of lines up to and including ``endheader``.
    """

    path: str
    name: str
    fields: Mapping[str, str]
    comments: tuple[str, ...]
    n_lines: int
    lines: Mapping[str, int] = field(default_factory=dict)

    def _lookup(self, *keys: str) -> tuple[str, str] | None:
        lowered = {k.lower(): k for k in self.fields}
        for key in keys:
            if key in lowered:
                return lowered[key], self.fields[lowered[key]]
        return None

    def _int(self, *keys: str) -> int | None:
        found = self._lookup(*keys)
        if found is None:
            return None
        key, value = found
        try:
            return int(value)
        except ValueError:
            raise TrialError(
                f"file {self.path!r}, line {self.lines.get(key, '?')}: {key}={value!r} "
                "is not an integer"
            ) from None

    @property
    def n_rows(self) -> int | None:
        """``nRows`` (or old ``datarows``), or ``None`` if absent."""
        return self._int("nrows", "datarows")

    @property
    def n_columns(self) -> int | None:
        """``nColumns`` (or old ``datacolumns``), time included, or ``None``."""
        return self._int("ncolumns", "datacolumns")

    @property
    def in_degrees(self) -> bool | None:
        """``inDegrees`` as a bool, or ``None`` if the header does not say."""
        found = self._lookup("indegrees")
        if found is None:
            return None
        key, value = found
        v = value.strip().lower()
        if v in ("yes", "true", "1"):
            return True
        if v in ("no", "false", "0"):
            return False
        raise TrialError(
            f"file {self.path!r}, line {self.lines.get(key, '?')}: inDegrees={value!r} must be yes or no"
        )


def _parse_header(lines: list[str], path: Path) -> StoHeader:
    end = next((i for i, line in enumerate(lines) if _clean(line).lower() == "endheader"), None)
    if end is None:
        if not any(line.strip() for line in lines):
            raise TrialError(f"file {str(path)!r} is empty")
        raise TrialError(
            f"file {str(path)!r}: no 'endheader' line; an OpenSim .sto/.mot file starts with "
            "header lines (name, version=1, nRows=..., nColumns=..., inDegrees=...) ending "
            "with a line 'endheader'"
        )
    name = ""
    fields: dict[str, str] = {}
    where: dict[str, int] = {}
    comments: list[str] = []
    for i in range(end):
        text = _clean(lines[i])
        m = _KEY_VALUE.match(text) or _OLD_KEY.match(text)
        if m:
            fields[m[1]] = m[2].strip()
            where[m[1]] = i + 1
        elif i == 0:
            name = text
        elif text:
            comments.append(text)
    return StoHeader(str(path), name, fields, tuple(comments), end + 1, where)


def read_sto_header(path) -> StoHeader:
    """The header of an OpenSim ``.sto`` / ``.mot`` file (lines up to ``endheader``)."""
    path = Path(path)
    return _parse_header(_read_lines(path), path)


# ---------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------


def _strip_trailing_empty(cells: list[str]) -> list[str]:
    while cells and not cells[-1].strip():
        cells.pop()
    return cells


def _table(
    path: Path,
    labels: list[str],
    label_line: int,
    rows: list[list[str]],
    linenos: list[int],
    notes: list[str],
    strict: bool,
):
    """Check labels and rows; return (time, names, values (N, C)).

    A row with the time stamp of the row before (files printed with rounding
    repeat the last frame so) is an error; with ``strict=False`` such rows are
    dropped, keeping the first of each time stamp, with a note in ``notes``.
    """
    src = str(path)
    labels = [lab.strip() for lab in labels]
    if not labels:
        raise TrialError(f"file {src!r}, line {label_line}: no column labels")
    try:
        unit = time_label_unit(labels[0])
    except TrialError as exc:
        raise TrialError(f"file {src!r}, line {label_line}: {exc}") from None
    if unit is None:
        raise TrialError(
            f"file {src!r}, line {label_line}: missing time column; the first column is "
            f"{labels[0]!r} but must be the time: 'time', 't', 'Time (s)' or 'Time [ms]' "
            "(a unit in brackets is converted)"
        )
    empty = [j + 1 for j, lab in enumerate(labels) if not lab]
    if empty:
        raise TrialError(f"file {src!r}, line {label_line}: column {empty[0]} has an empty label")
    positions: dict[str, list[int]] = {}
    for j, lab in enumerate(labels):
        positions.setdefault(lab, []).append(j + 1)
    dup = {lab: cols for lab, cols in positions.items() if len(cols) > 1}
    if dup:
        detail = "; ".join(f"{lab!r} (columns {', '.join(map(str, cols))})" for lab, cols in dup.items())
        raise TrialError(
            f"file {src!r}, line {label_line}: duplicate column names {detail}; rename them"
        )
    if not rows:
        raise TrialError(f"file {src!r}: header only; column labels on line {label_line} but no data rows")
    n_cols = len(labels)
    lengths = np.fromiter((len(r) for r in rows), dtype=int, count=len(rows))
    ragged = np.flatnonzero(lengths != n_cols)
    if ragged.size:
        k = int(ragged[0])
        others = ", ".join(str(linenos[i]) for i in ragged[1:6]) + (", ..." if ragged.size > 6 else "")
        more = f" ({ragged.size - 1} more ragged rows, lines {others})" if ragged.size > 1 else ""
        raise TrialError(
            f"file {src!r}, line {linenos[k]}: ragged row with {lengths[k]} values but "
            f"{n_cols} column labels on line {label_line}{more}"
        )
    try:
        values = np.array(rows, dtype=float)
    except ValueError:
        for r, row in enumerate(rows):  # error path only: find the first bad cell
            for j, cell in enumerate(row):
                try:
                    float(cell)
                except ValueError:
                    raise TrialError(
                        f"file {src!r}, line {linenos[r]}, column {j + 1} ({labels[j]!r}): "
                        f"cannot read {cell.strip()!r} as a number"
                    ) from None
        raise TrialError(f"file {src!r}: cannot read the data rows as numbers") from None
    time = values[:, 0]
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        k = int(bad[0])
        raise TrialError(f"file {src!r}, line {linenos[k]}: time is {float(time[k])!r}; it must be finite")
    dup = np.flatnonzero(values[1:, 0] == values[:-1, 0]) + 1   # rows repeating the time before
    if not strict and dup.size:
        notes.append(_dropped_duplicates(src, labels, values, dup, linenos, len(rows)))
        keep = np.ones(len(rows), dtype=bool)
        keep[dup] = False
        values = values[keep]
        linenos = [n for n, k in zip(linenos, keep) if k]
        time = values[:, 0]
    back = np.flatnonzero(np.diff(time) <= 0)
    if back.size:
        k = int(back[0]) + 1
        fix = (
            f"; it repeats the time stamp of the line before{_LENIENT_FIX} (rows repeating a time "
            "stamp are dropped, keeping the first of each)"
            if time[k] == time[k - 1]
            else ""
        )
        raise TrialError(
            f"file {src!r}, line {linenos[k]} (data row {k}): time {float(time[k])!r} is not greater "
            f"than {float(time[k - 1])!r} on line {linenos[k - 1]}; time must be strictly increasing "
            f"({back.size} such row(s)){fix}"
        )
    return time, labels[1:], values[:, 1:], unit


def _split_sto(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return _strip_trailing_empty(line.rstrip().split(delimiter))


#: How to ask for a lenient read, appended to the errors it would repair.
_LENIENT_FIX = "; to read the file anyway, pass --lenient (command line) or strict=False (Python)"

#: A lenient read refuses files where more than this fraction of the rows (and more than 5)
#: repeat a time stamp: that is a time column printed with too few digits, which dropping rows
#: would not repair.
_MAX_DUPLICATE_FRACTION = 0.1


def _dropped_duplicates(src, labels, values, dup, linenos, n_rows) -> str:
    """The note for dropping rows ``dup`` (each repeating the time stamp before), or raise."""
    if dup.size > max(_MAX_DUPLICATE_FRACTION * n_rows, 5):
        raise TrialError(
            f"file {src!r}: {dup.size} of {n_rows} rows repeat the time stamp of the row before "
            f"(first on line {linenos[int(dup[0])]}); the time column looks printed with too few "
            "digits, which dropping rows cannot repair; write the time with more digits"
        )
    lines = ", ".join(str(linenos[k]) for k in dup[:5]) + (", ..." if dup.size > 5 else "")
    now, before = values[dup, 1:], values[dup - 1, 1:]
    diff = np.abs(now - before)
    same = (diff <= 1e-8 * np.maximum(np.abs(now), np.abs(before))) | (np.isnan(now) & np.isnan(before))
    differ = ~np.all(same, axis=1)
    if not differ.any():
        how = "each repeated the row before"
    else:
        r, c = np.unravel_index(int(np.argmax(np.where(same, -1.0, np.nan_to_num(diff, nan=np.inf)))), diff.shape)
        how = (f"{int(differ.sum())} had other values than the row before, by up to "
               f"{float(diff[r, c]):.6g} in {labels[c + 1]!r} on line {linenos[int(dup[r])]}")
    s = "" if dup.size == 1 else "s"
    return f"{src}: dropped {dup.size} duplicated time stamp{s} at line{s} {lines} (kept the first of each; {how})"


def _mismatch(message: str, repair: str, notes: list[str], strict: bool) -> None:
    """Raise ``message`` (strict) or note ``repair`` (what the lenient read did instead)."""
    if strict:
        raise TrialError(message + _LENIENT_FIX)
    notes.append(repair)


def _read_sto(path: Path, lines: list[str], notes: list[str], strict: bool):
    header = _parse_header(lines, path)
    src = str(path)
    dtype = header._lookup("datatype")
    if dtype is not None and dtype[1].strip().lower() != "double":
        raise TrialError(
            f"file {src!r}, line {header.lines.get(dtype[0], '?')}: DataType={dtype[1]!r} is not "
            "supported; only scalar (double) columns can be read"
        )
    label_idx = next((i for i in range(header.n_lines, len(lines)) if _clean(lines[i])), None)
    if label_idx is None:
        raise TrialError(
            f"file {src!r}: header only; nothing after 'endheader' on line {header.n_lines} "
            "(expected a column-label line starting with 'time' and data rows)"
        )
    label_text = lines[label_idx]
    delimiter = "\t" if "\t" in label_text else ("," if "," in label_text else None)
    labels = _split_sto(label_text, delimiter)
    data = [(i + 1, lines[i]) for i in range(label_idx + 1, len(lines)) if _clean(lines[i])]
    rows = [_split_sto(text, delimiter) for _, text in data]
    linenos = [n for n, _ in data]
    n_columns = header.n_columns
    if n_columns is not None and n_columns != len(labels):
        key = header._lookup("ncolumns", "datacolumns")[0]
        shown = ", ".join(labels[:6]) + (", ..." if len(labels) > 6 else "")
        _mismatch(
            f"file {src!r}: header says {key}={n_columns} (line {header.lines.get(key)}) but the "
            f"column-label line {label_idx + 1} has {len(labels)} columns ({shown}); fix the header "
            "or the labels",
            f"{src}: header says {key}={n_columns} (line {header.lines.get(key)}), data has "
            f"{len(labels)} columns; used the data's {len(labels)}",
            notes,
            strict,
        )
    time, names, values, unit = _table(path, labels, label_idx + 1, rows, linenos, notes, strict)
    n_rows = header.n_rows
    if n_rows is not None and n_rows != len(rows):
        key = header._lookup("nrows", "datarows")[0]
        _mismatch(
            f"file {src!r}: header says {key}={n_rows} (line {header.lines.get(key)}) but there are "
            f"{len(rows)} data rows (lines {linenos[0]}-{linenos[-1]}); the file may be truncated, "
            "or fix the header",
            f"{src}: header says {key}={n_rows} (line {header.lines.get(key)}), data has "
            f"{len(rows)} rows (lines {linenos[0]}-{linenos[-1]}); used the data's {len(rows)}",
            notes,
            strict,
        )
    return header, time, names, values, unit


def _read_csv(path: Path, lines: list[str], notes: list[str], strict: bool):
    reader = csv.reader(lines)
    rows: list[list[str]] = []
    linenos: list[int] = []
    for row in reader:
        row = _strip_trailing_empty(row)
        if row:
            rows.append(row)
            linenos.append(reader.line_num)
    if not rows:
        raise TrialError(f"file {str(path)!r} is empty")
    return _table(path, rows[0], linenos[0], rows[1:], linenos[1:], notes, strict)


def _check_time_unit(path: Path, time: np.ndarray, time_unit, label_unit: str = "") -> np.ndarray:
    """Time in seconds: scaled by ``time_unit`` or the unit of the column's label (they must agree
    when both are given); with neither, refused if it looks like ms."""
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise TrialError(f"time_unit must be one of {', '.join(TIME_UNITS)}, got {time_unit!r}")
    if label_unit and time_unit is not None and label_unit != time_unit:
        raise TrialError(f"file {str(path)!r}: the time column's label declares {label_unit} but the time "
                         f"unit asked for is {time_unit} (--time-unit / time_unit); drop one of them")
    time_unit = time_unit or label_unit or None
    if time_unit is not None:
        return time * TIME_UNITS[time_unit]
    if time.size < 3:
        return time
    step = median_step(time)
    if _MS_STEP[0] < step <= _MS_STEP[1]:
        raise TrialError(
            f"file {str(path)!r}: the time column looks like milliseconds: its median step is {step:.6g}, "
            f"which in seconds would be a {1 / step:.3g} Hz recording ({1000 / step:.4g} Hz if it is ms); "
            "time must be in seconds: label the column 'Time (ms)', pass --time-unit ms (command line) or "
            "read_trial(path, time_unit='ms') (Python); --time-unit s keeps a slow recording in seconds"
        )
    return time


def state_path_coordinate(name: str) -> tuple[str, str] | None:
    """``(coordinate, quantity)`` of an OpenSim 4 state path such as ``/jointset/knee_r/knee_angle_r/value``.

    ``quantity`` is the last part (``value``, ``speed``, ``accel`` or
    ``acceleration``); other names give ``None``.
    """
    if not isinstance(name, str) or "/" not in name:
        return None
    parts = [p for p in name.split("/") if p]
    if len(parts) < 2 or parts[-1] not in ("value", "speed", "accel", "acceleration"):
        return None
    return parts[-2], parts[-1]


#: What ``read_trial(path.c3d, part=...)`` returns.
C3D_PARTS = ("markers", "analogs", "platforms")


def _read_c3d_part(path: Path, part: str) -> Trial:
    """One time base of a C3D file as a Trial (see :func:`read_trial`)."""
    if part not in C3D_PARTS:
        raise TrialError(f"file {str(path)!r}: part={part!r}; a C3D part is one of {', '.join(C3D_PARTS)}")
    data = read_c3d(path, platforms=part == "platforms")
    have = {
        "markers": 0 if data.markers is None else len(data.markers.meta["markers"]),
        "analogs": 0 if data.analogs is None else data.analogs.n_channels,
        "platforms": len(data.platforms),
    }
    if not have[part]:
        others = [f"{n} {k}" for k, n in have.items() if n and k != part]
        hint = f"; it has {' and '.join(others)}: pass part={next(k for k, n in have.items() if n)!r}" if others else ""
        raise TrialError(f"file {str(path)!r} has no {part}{hint}")
    if part == "markers":
        trial = data.markers
    elif part == "analogs":
        trial = data.analogs
    else:
        plates = data.platforms
        channels = {}
        for k, plate in enumerate(plates):
            prefix = f"{k + 1}_" if len(plates) > 1 else ""
            channels.update({prefix + n: plate[n] for n in plate.names})
        trial = Trial(plates[0].time, channels, meta={"platforms": len(plates)})
    return trial.with_meta(source=str(path), format="c3d", part=part, read_notes=())


def read_trial(path, *, angular=None, strict: bool = True, part: str | None = None,
               time_unit: str | None = None, in_degrees: bool | None = None) -> Trial:
    """Read a Trial from a ``.csv``, ``.sto``, ``.mot`` or ``.c3d`` file.

    Parameters
    ----------
    path : str or Path
    angular : iterable of str, optional
        Channels that are angles, converted from degrees when the file says
        ``inDegrees=yes``; a name also matches an OpenSim 4 state path of that
        coordinate (``/jointset/<joint>/<name>/value``); names that are not
        columns of the file are ignored (so a model's rotational coordinates
        can be passed for any file).  Default: the channels
        :func:`is_angular_name` accepts.
    strict : bool
        If True (default), a header ``nRows``/``nColumns`` that disagrees with
        the data, or a row repeating the time stamp of the row before, is an
        error whose message says how to read the file leniently.  If False,
        the file is read anyway and each repair is a
        :class:`~pinmsk.errors.RepairWarning` saying what was done (also kept
        in ``meta["read_notes"]``): the data's own row and column counts are
        used, and rows repeating a time stamp are dropped, keeping the first
        of each (refused when more than 10 % of the rows, and more than 5,
        repeat one: a time column printed with too few digits).  Other
        problems still raise.
    part : str, optional
        ``.c3d`` only (needs ``pip install pinmsk[c3d]``): which of the
        file's time bases to return, as read by :func:`pinmsk.io.c3d.read_c3d`:
        ``"markers"`` (default; ``<label>_{x,y,z}`` in m at the point rate),
        ``"analogs"`` (every analog channel by label at the analog rate) or
        ``"platforms"`` (``ground_force_v[xyz]``, ``ground_force_p[xyz]``,
        ``ground_torque_[xyz]`` at the analog rate, prefixed ``1_``, ``2_``
        ... by platform number when there are several).  No axis change is
        made (see :func:`pinmsk.io.c3d.remap_axes`).
    time_unit : {None, "s", "ms"}
        Unit of the time column.  ``None`` (default): the unit its label
        declares (``Time (s)``, ``Time [ms]``, ``t_ms``: converted to seconds),
        else seconds, and then a file whose median time step is between 0.2
        and 100 (below 5 Hz in seconds, but 10 Hz to 5 kHz in milliseconds) is
        refused as "looks like milliseconds".  ``"ms"`` converts from
        milliseconds; ``"s"`` takes seconds without that check.  A label
        declaring another unit than ``time_unit`` is an error.
    in_degrees : bool or None
        Whether the angular channels are in degrees.  ``None`` (default): as
        the file declares (``inDegrees`` of a ``.sto``/``.mot``; a CSV is in
        radians).  ``True`` / ``False`` override the file (a CSV exported in
        degrees: ``in_degrees=True``, ``--degrees`` on the command line).

    Returns
    -------
    Trial
        ``meta`` holds ``source`` (the path), ``format`` (csv/sto/mot/c3d),
        ``name`` (first header line), ``in_degrees`` (as declared; ``None``
        if not declared, ``False`` for CSV), ``header`` (the key=value
        fields), ``converted_to_radians`` (channel names) and ``read_notes``
        (the repairs ``strict=False`` made).
    """
    path = Path(path)
    if path.suffix.lower() == ".c3d":
        if time_unit is not None or in_degrees is not None:
            raise TrialError(f"file {str(path)!r}: a C3D file states its own units; time_unit and in_degrees "
                             "(--time-unit, --degrees) apply to .csv/.sto/.mot files")
        return _read_c3d_part(path, "markers" if part is None else part)
    if part is not None:
        raise TrialError(f"file {str(path)!r}: part={part!r} applies to .c3d files only")
    kind = _format_of(path, reading=True)
    lines = _read_lines(path)
    notes: list[str] = []
    if in_degrees is not None and not isinstance(in_degrees, bool):
        raise TrialError(f"in_degrees must be True, False or None, got {in_degrees!r}")
    if kind == "csv":
        time, names, values, label_unit = _read_csv(path, lines, notes, strict)
        name, declared, fields = path.stem, False, {}
    else:
        header, time, names, values, label_unit = _read_sto(path, lines, notes, strict)
        name, declared, fields = header.name, header.in_degrees, dict(header.fields)
    in_degrees = declared if in_degrees is None else in_degrees
    time = _check_time_unit(path, time, time_unit, label_unit)
    if angular is None:
        angular_names = tuple(n for n in names if is_angular_name(n))
    else:
        wanted = {angular} if isinstance(angular, str) else set(angular)
        angular_names = tuple(
            n for n in names if n in wanted or (state_path_coordinate(n) or ("",))[0] in wanted
        )
    converted: tuple[str, ...] = ()
    if in_degrees:
        idx = [names.index(a) for a in angular_names]
        values[:, idx] = np.deg2rad(values[:, idx])
        converted = angular_names
    meta = {
        "source": str(path),
        "format": kind,
        "name": name,
        "in_degrees": in_degrees,
        "header": fields,
        "converted_to_radians": converted,
        "read_notes": tuple(notes),
    }
    for note in notes:
        warnings.warn(RepairWarning(note), stacklevel=2)
    return Trial.from_array(time, names, values, meta=meta)


# ---------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------


#: Trial metadata keys that describe a file read in, not an analysis: never written back.
_READ_META = {"source", "format", "name", "in_degrees", "header", "converted_to_radians", "read_notes"}


def _meta_lines(meta) -> str:
    """``key=value`` header lines of a Trial's analysis metadata (what filter, loads, model...).

    OpenSim readers keep unknown ``key=value`` header fields, so the record of
    what was applied travels with the file; only scalar values on one line are
    written.
    """
    out = []
    for key, value in meta.items():
        if key in _READ_META or key in ("version", "nRows", "nColumns", "inDegrees"):
            continue
        if not isinstance(value, (str, int, float, bool)) or not _KEY_VALUE.match(f"{key}=x"):
            continue
        text = str(value)
        if "\n" in text or "\r" in text:
            continue
        out.append(f"{key}={text}\n")
    return "".join(out)


#: Values formatted per block: the formatter's scratch arrays then stay in the CPU cache.
_BLOCK_VALUES = 8192

#: Largest precision of the vectorised formatter: its digits come from
#: ``|x| * 10^k`` in float64, exact to well below one unit of the last digit
#: only while that integer stays far below 2^53.
_FAST_DIGITS = 12


def check_precision(precision) -> int:
    """``precision`` as an int from 1 to 17, or TrialError naming it."""
    if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)) \
            or not 1 <= precision <= 17:
        raise TrialError(f"precision must be a whole number of significant digits from 1 to 17 "
                         f"(17 writes float64 exactly); got {precision!r}")
    return int(precision)


def _time_precision(time: np.ndarray, precision: int) -> int:
    """Digits for the time column: at least ``precision``, enough that each step stays within 1 %."""
    t = np.asarray(time, dtype=float)
    if t.size < 2 or precision >= 17:
        return precision
    step = np.diff(t)
    mag = np.maximum(np.abs(t[1:]), np.abs(t[:-1]))
    with np.errstate(divide="ignore"):
        e = np.floor(np.log10(np.where(mag > 0, mag, 1.0)))
    for p in range(precision, 17):
        if np.all(step > 100.0 * 10.0 ** (e - p + 1)):
            return p
    return 17


#: The characters of every ``%.{p}g`` text (p <= 12), in five 8-byte words per value:
#: ``-0.000`` (the sign, and the ``0.000`` of 0.000ddd), twelve digits each followed
#: by a ``.`` slot, then ``e``, the exponent's sign, three exponent digits and the separator.
_TEMPLATE = b"-0.000\0\0" + b"0." * 12 + b"e+000\0\0\0"
_DIGIT_AT = 8
_EXP_AT = 32
#: Kinds of text: 0-15 fixed notation with decimal exponent ``kind - 4``; 16 / 17
#: scientific with a 2- / 3-digit exponent; 18 zero; 19 Python's text (spliced in).
_KINDS = 20
_PYTHON = 19


def _as_words(b: np.ndarray) -> np.ndarray:
    """(..., 8 k) uint8 -> (..., k) uint64 over the same bytes."""
    return np.ascontiguousarray(b).view(np.uint64)


@functools.lru_cache(maxsize=None)
def _tables() -> dict:
    """Lookup tables of the vectorised ``%g`` formatter (:func:`_format_block`).

    Every text ``%.{p}g`` gives for a finite non-zero value (p <= 12) is a
    subsequence of ``_TEMPLATE``.  A value keeps the bytes of its ``code =
    (negative * _KINDS + kind) * 13 + digits kept`` and the others become NUL,
    which is then deleted.  Tables (by code): ``prefix`` (word 0, masked),
    ``keep_digits`` (words 1-3), ``keep_exp`` (word 4), ``lengths``; by value:
    ``d4`` (10000,) the words ``"d.d.d.d."``, ``nd0/nd1/nd2`` the digits a
    12-digit mantissa keeps when its last non-zero group of four is group 0/1/2,
    ``ew`` (800,) the exponent words of -400 ... 399, ``kind13`` (13 * 800,)
    ``13 * kind`` by ``800 p + exponent + 400``, ``pow10`` 10^0 ... 10^308 and
    ``pow10_all`` 10^-330 ... 10^330.
    """
    tpl = np.frombuffer(_TEMPLATE, dtype=np.uint8)
    digit = [_DIGIT_AT + 2 * j for j in range(12)]
    e = _EXP_AT
    keep = np.zeros((2 * _KINDS * 13, tpl.size), dtype=bool)
    for neg in (0, 1):
        for kind in range(_KINDS):
            for nd in range(1, 13):
                k = keep[(neg * _KINDS + kind) * 13 + nd]
                k[e + 5] = True                                  # the separator
                if kind == _PYTHON:
                    continue
                k[0] = bool(neg)
                if kind < 16:
                    ex = kind - 4
                    if ex >= 0:
                        k[digit[:max(ex + 1, nd)]] = True
                        if nd > ex + 1:
                            k[digit[ex] + 1] = True
                    else:
                        k[list(range(1, 2 - ex))] = True          # "0." and -ex - 1 zeros
                        k[digit[:nd]] = True
                elif kind < 18:
                    k[digit[:nd]] = True
                    if nd > 1:
                        k[digit[0] + 1] = True
                    k[[e, e + 1, e + 3, e + 4] + ([e + 2] if kind == 17 else [])] = True
                else:
                    k[1] = True                                  # zero
    words = _as_words(np.where(keep, tpl, 0).astype(np.uint8))
    masks = _as_words(np.where(keep, 0xFF, 0).astype(np.uint8))
    tz4 = np.array([4 if i == 0 else len(f"{i:04d}") - len(f"{i:04d}".rstrip("0")) for i in range(10000)])
    kind13 = np.zeros((13, 800), dtype=np.int64)
    for p in range(1, 13):
        for ex in range(-400, 400):
            kind = ex + 4 if -4 <= ex < p else (16 if abs(ex) < 100 else 17)
            kind13[p, ex + 400] = 13 * kind
    digits = "".join(".".join(f"{i:04d}") + "." for i in range(10000)).encode()
    exps = b"".join(b"e" + (b"-" if x < 0 else b"+") + b"%03d" % min(abs(x), 999) + b"\0\0\0"
                    for x in range(-400, 400))
    return {
        "prefix": words[:, 0].copy(), "keep_digits": [masks[:, g].copy() for g in (1, 2, 3)],
        "keep_exp": masks[:, 4].copy(), "lengths": keep.sum(axis=1),
        "d4": _as_words(np.frombuffer(digits, dtype=np.uint8).reshape(10000, 8))[:, 0].copy(),
        "nd0": 4 - tz4, "nd1": 8 - tz4, "nd2": 12 - tz4,
        "ew": _as_words(np.frombuffer(exps, dtype=np.uint8).reshape(800, 8))[:, 0].copy(),
        "kind13": kind13.ravel(), "pow10": np.array([float(f"1e{j}") for j in range(309)]),
        "pow10_all": np.array([float(f"1e{j}") for j in range(-330, 331)]),   # 10^(i - 330)
    }


def _columns(precision, separators) -> dict:
    """Per-column constants of :func:`_format_block`: ``precision`` (C,) <= 12, ``separators`` (C,) bytes."""
    t = _tables()
    prec = np.asarray(precision, dtype=np.int64)
    sep = np.zeros((prec.size, 8), dtype=np.uint8)
    sep[:, 5] = np.asarray(separators, dtype=np.uint8)
    return {"prec": prec, "top": t["pow10"][prec], "low": t["pow10"][prec - 1],
            # distance from an integer beyond which y may be a rounding tie: 1e-6 at p = 9,
            # far above the float64 error of y (a few 1e-16 y)
            "tie": 0.5 - 10.0 ** (prec - 15.0), "align": 10 ** (12 - prec),
            "kind_at": 800 * prec + 400, "sep": _as_words(sep)[:, 0]}


def _format_block(block: np.ndarray, cols: dict) -> bytes:
    """The text of a (B, C) block: cell ``[i, j]`` as ``"%.{p_j}g" % x`` and column j's separator.

    Vectorised over the block (``cols`` from :func:`_columns`): each value's
    digits come from ``rint(|x| 10^(p - 1 - exponent))`` in float64 and are laid
    out by :func:`_tables`.  Values within 1e-6 of their last digit's unit from
    a rounding tie (where float64 cannot tell which way ``%`` rounds; about
    2e-6 of random values), non-finite ones and those beyond 1e+-290 are
    formatted by Python instead, so the text is exactly what ``%`` gives.
    """
    t = _tables()
    pow10 = t["pow10"]
    prec = cols["prec"]
    B, C = block.shape
    x = np.asarray(block, dtype=float)
    ax = np.abs(x)
    fast = (ax > 1e-290) & (ax < 1e290)     # False for 0, inf, nan and the extremes
    all_fast = bool(fast.all())
    safe = ax if all_fast else np.where(fast, ax, 1.0)
    # decimal exponent floor(log10 |x|) from the binary one (exact but near powers of ten,
    # where the check below moves it by one)
    e2 = np.frexp(safe)[1].astype(np.int64)
    e2 -= 1
    e2 *= 78913                     # (e * 78913) >> 18 = floor(e log10 2) for |e| < 1650
    e2 >>= 18
    ex = e2 + (safe >= t["pow10_all"][e2 + 331])

    def scaled(e, rows=slice(None)):
        k = (prec - 1) - e          # within -290 ... 301
        y = safe[rows] * pow10[np.maximum(k, 0)]
        big = k < 0                 # |x| >= 10^p: divide by the exact power instead
        if big.any():
            y[big] = safe[rows][big] / pow10[-k[big]]
        r = np.rint(y)
        return r, np.abs(y - r) > cols["tie"]

    r, slow = scaled(ex)            # a tie here may also decide the exponent
    shift = (r >= cols["top"]).astype(np.int64) - (r < cols["low"])
    rows = np.flatnonzero(shift.any(axis=1))
    if rows.size:                   # log10 one off near powers of ten, or 9.99..95 rounding up
        ex[rows] += shift[rows]
        r[rows], slow2 = scaled(ex[rows], rows)
        slow[rows] |= slow2
    m = r.astype(np.int64)
    m *= cols["align"]              # 12 digits, left-aligned
    g0 = m // 100000000
    g2 = m % 10000
    g1 = (m // 10000) % 10000
    nd = np.where(g2 != 0, t["nd2"][g2], np.where(g1 != 0, t["nd1"][g1], t["nd0"][g0]))
    code = t["kind13"][ex + cols["kind_at"]]
    code += nd
    if not all_fast:
        code[~fast] = np.where(ax[~fast] == 0.0, 18 * 13 + 1, _PYTHON * 13 + 1)
        slow |= ~fast & (ax != 0.0)
    code[slow] = _PYTHON * 13 + 1
    code += np.signbit(x) * (_KINDS * 13)
    code = code.ravel()
    out = np.empty((B * C, 5), dtype=np.uint64)
    out[:, 0] = t["prefix"][code]
    for g, grp in enumerate((g0, g1, g2)):
        out[:, 1 + g] = t["d4"][grp.ravel()] & t["keep_digits"][g][code]
    e4 = t["ew"][ex + 400]
    e4 |= cols["sep"]
    out[:, 4] = e4.ravel() & t["keep_exp"][code]
    text = out.tobytes().translate(None, b"\0")
    cells = np.flatnonzero(slow.ravel())
    if cells.size == 0:
        return text
    # splice Python's text in before each such cell's separator (its only byte so far)
    ends = np.cumsum(t["lengths"][code])[cells] - 1
    pieces = [("%.*g" % (int(prec[i % C]), x.flat[i])).encode() for i in cells]
    at = np.repeat(ends, [len(s) for s in pieces])
    return np.insert(np.frombuffer(text, dtype=np.uint8), at,
                     np.frombuffer(b"".join(pieces), dtype=np.uint8)).tobytes()


def _format_rows(table: np.ndarray, precision: np.ndarray, delimiter: str) -> str:
    """The text of ``table`` (N, C) by Python's ``%`` (precisions above :data:`_FAST_DIGITS`)."""
    row = delimiter.join(f"%.{int(p)}g" for p in precision) + "\n"
    return "".join((row * len(chunk)) % tuple(chunk.ravel().tolist())
                   for chunk in (table[i:i + 1024] for i in range(0, table.shape[0], 1024)))


def _write_rows(fh, table: np.ndarray, delimiter: str, precision: int = DEFAULT_PRECISION) -> None:
    """Write the (N, 1 + C) numeric table, one line per frame, at ``precision`` significant digits."""
    prec = np.full(table.shape[1], precision, dtype=np.int64)
    if table.shape[1]:
        prec[0] = _time_precision(table[:, 0], precision)
    seps = np.full(table.shape[1], ord(delimiter), dtype=np.uint8)
    seps[-1:] = ord("\n")
    fast = prec.max(initial=0) <= _FAST_DIGITS
    cols = _columns(prec, seps) if fast else None
    raw = getattr(fh, "buffer", None)     # the ASCII text goes straight to the byte stream
    if raw is not None:
        fh.flush()
    rows = max(1, _BLOCK_VALUES // max(table.shape[1], 1))
    for start in range(0, table.shape[0], rows):
        block = table[start:start + rows]
        if not fast:
            fh.write(_format_rows(block, prec, delimiter))
        elif raw is not None:
            raw.write(_format_block(block, cols))
        else:
            fh.write(_format_block(block, cols).decode("ascii"))


def write_trial(trial: Trial, path, *, in_degrees: bool = False, angular=None,
                precision: int | None = None) -> Path:
    """Write ``trial`` to ``path`` (``.csv``, ``.sto`` or ``.mot``), atomically.

    Parameters
    ----------
    trial : Trial
    path : str or Path
    in_degrees : bool
        ``.sto``/``.mot`` only: write the angular channels in degrees and
        declare ``inDegrees=yes``.  Default: radians, ``inDegrees=no``.
    angular : iterable of str, optional
        Channels that are angles (used with ``in_degrees=True``; names not in
        the trial are ignored); default: those
        :func:`pinmsk.trial.is_angular_name` accepts.
    precision : int or None
        Significant digits of each value, 1 to 17 (None: :data:`DEFAULT_PRECISION`,
        9, as ``%.9g``; 17 writes every float64 exactly).  The time column gets more where
        needed to keep its steps distinct to 1 %.

    Returns
    -------
    Path
        The path written.
    """
    if not isinstance(trial, Trial):
        raise TypeError(f"write_trial needs a Trial, got {type(trial).__name__}")
    path = Path(path)
    kind = _format_of(path)
    precision = check_precision(DEFAULT_PRECISION if precision is None else precision)
    names = trial.names
    bad = [n for n in names if any(c in n for c in "\t\r\n")]
    if bad:
        raise TrialError(f"cannot write {str(path)!r}: channel names contain tabs or line breaks: {bad!r}")
    table = np.empty((trial.n_frames, trial.n_channels + 1))
    table[:, 0] = trial.time
    table[:, 1:] = trial.values
    if in_degrees:
        if kind == "csv":
            raise TrialError(
                f"cannot write {str(path)!r} in degrees: a CSV file cannot declare degrees; "
                "write a .sto/.mot or keep radians"
            )
        if angular is None:
            idx = [1 + i for i, n in enumerate(names) if is_angular_name(n)]
        else:
            wanted = {angular} if isinstance(angular, str) else set(angular)
            idx = [1 + i for i, n in enumerate(names) if n in wanted]
        table[:, idx] = np.rad2deg(table[:, idx])

    if kind == "csv":
        buf = _io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow((TIME,) + names)
        head = buf.getvalue()
        delimiter = ","
    else:
        title = trial.meta.get("name")
        if not isinstance(title, str) or not title.strip() or "\n" in title or "=" in title:
            title = path.stem
        head = (
            f"{title}\nversion=1\nnRows={trial.n_frames}\nnColumns={trial.n_channels + 1}\n"
            f"inDegrees={'yes' if in_degrees else 'no'}\n" + _meta_lines(trial.meta) + "endheader\n"
            + "\t".join((TIME,) + names)
            + "\n"
        )
        delimiter = "\t"

    def write(fh):
        fh.write(head)
        _write_rows(fh, table, delimiter, precision)

    atomic_write(path, write)
    return path
