"""Trial: measured or simulated data over time as named channels.

A :class:`Trial` holds a time base ``time`` (N,) in seconds, strictly
increasing, and C named channels stored together as one read-only (N, C)
float array (time first, SI units: rad, m, N, N·m, s).  Operations return new
Trials; the arrays of a Trial are never modified.

Channel names follow the pinmsk conventions (see DESIGN.md):

* ``<coord>`` (generalized coordinate, rad or m), ``<coord>_speed``,
  ``<coord>_moment``;
* ``<muscle>_activation``, ``<muscle>_excitation``, ``<muscle>_emg``,
  ``<muscle>_force``;
* ground reaction ``ground_force_v[xyz]`` (force, N), ``ground_force_p[xyz]``
  (centre of pressure, m), ``ground_torque_[xyz]`` (N·m), with an optional
  side prefix ``r_ground_force_vy``; OpenSim's ``1_ground_force_vy`` and
  ``ground_force_r_vy`` spellings are recognised by :func:`parse_ground_reaction`.

Reading and writing files lives in :mod:`pinmsk.io`; filtering and
differentiation in :mod:`pinmsk.signals.filtering`.
"""

from __future__ import annotations

import difflib
import fnmatch
import math
import re
import types
from collections.abc import Iterable, Mapping, Sequence
from typing import NamedTuple

import numpy as np

from pinmsk.errors import TrialError
from pinmsk.signals.filtering import differentiate, lowpass
from pinmsk.signals.sampling import check_increasing, median_step, uniform_rate

__all__ = [
    "Trial",
    "TIME",
    "SPEED_SUFFIX",
    "MOMENT_SUFFIX",
    "ACTIVATION_SUFFIX",
    "EXCITATION_SUFFIX",
    "EMG_SUFFIX",
    "FORCE_SUFFIX",
    "GROUND_REACTION_CHANNELS",
    "DEGREES_THRESHOLD",
    "GroundReactionName",
    "coordinate_channels",
    "speed_channels",
    "moment_channels",
    "activation_channels",
    "excitation_channels",
    "emg_channels",
    "force_channels",
    "ground_reaction_channels",
    "parse_ground_reaction",
    "is_angular_name",
    "close_matches",
    "time_label_unit",
    "TIME_UNITS",
]

# ---------------------------------------------------------------------------
# Channel names
# ---------------------------------------------------------------------------

TIME = "time"
SPEED_SUFFIX = "_speed"
MOMENT_SUFFIX = "_moment"
ACTIVATION_SUFFIX = "_activation"
EXCITATION_SUFFIX = "_excitation"
EMG_SUFFIX = "_emg"
FORCE_SUFFIX = "_force"

#: Time units :func:`read_trial` takes (``time_unit``), as factors to seconds.
#: Time units a time column may be in (``read_trial(time_unit=...)``, ``--time-unit``), as factors to s.
TIME_UNITS = {"s": 1.0, "ms": 1e-3}

#: A time column's label: ``time`` or ``t`` (any case), with an optional unit in brackets or after
#: an underscore: ``Time (s)``, ``time [ms]``, ``t_ms``, ``Time (seconds)``.
_TIME_LABEL = re.compile(r"^(?:time|t)\s*(?:[(\[]\s*(?P<unit>[^)\]]*?)\s*[)\]]|_(?P<bare>[a-z]+))?$",
                         re.IGNORECASE)
#: Spellings of the time units in a column label.
_UNIT_WORDS = {"s": "s", "sec": "s", "secs": "s", "second": "s", "seconds": "s",
               "ms": "ms", "msec": "ms", "msecs": "ms", "millisecond": "ms", "milliseconds": "ms"}


def time_label_unit(label: str) -> str | None:
    """The unit a time column's label declares: ``""`` for ``time`` / ``t`` alone (undeclared),
    ``"s"`` or ``"ms"`` for ``Time (s)``, ``Time [ms]``, ``t_ms``...; ``None`` if the label is not a
    time column.  A unit pinmsk does not convert (``Time (min)``) raises TrialError naming it."""
    m = _TIME_LABEL.match(label.strip())
    if m is None:
        return None
    word = m["unit"] if m["unit"] is not None else m["bare"]
    if word is None:
        return ""
    unit = _UNIT_WORDS.get(word.strip().lower())
    if unit is None:
        raise TrialError(f"time column {label!r}: unit {word!r} is not one of s, ms "
                         f"({', '.join(sorted(_UNIT_WORDS))})")
    return unit


#: The nine ground-reaction channels of one force plate, without side prefix.
GROUND_REACTION_CHANNELS = (
    "ground_force_vx", "ground_force_vy", "ground_force_vz",
    "ground_force_px", "ground_force_py", "ground_force_pz",
    "ground_torque_x", "ground_torque_y", "ground_torque_z",
)  # fmt: skip

#: An angular channel declared in radians whose largest magnitude exceeds this
#: (1.5 turns, 540 degrees) is taken to be in degrees by :meth:`Trial.validate`.
DEGREES_THRESHOLD = 3.0 * math.pi


def _as_names(names, what: str = "names") -> tuple[str, ...]:
    """A tuple of channel names from one name or an iterable of names."""
    if isinstance(names, str):
        return (names,)
    out = tuple(names)
    bad = [n for n in out if not isinstance(n, str)]
    if bad:
        raise TrialError(f"{what} must be strings, got {bad[:3]!r}")
    return out


def _suffixed(names, suffix: str) -> tuple[str, ...]:
    return tuple(n + suffix for n in _as_names(names))


def coordinate_channels(coords) -> tuple[str, ...]:
    """Channel names of generalized coordinates: the coordinate names."""
    return _as_names(coords, "coordinates")


def speed_channels(coords) -> tuple[str, ...]:
    """``<coord>_speed`` for each coordinate."""
    return _suffixed(coords, SPEED_SUFFIX)


def moment_channel(coord: str) -> str:
    """``<coord>_moment``: the generalized force of one coordinate (N·m or N)."""
    return coord + MOMENT_SUFFIX


def moment_channels(coords) -> tuple[str, ...]:
    """``<coord>_moment`` for each coordinate (generalized force, N·m or N)."""
    return _suffixed(coords, MOMENT_SUFFIX)


def activation_channels(muscles) -> tuple[str, ...]:
    """``<muscle>_activation`` for each muscle."""
    return _suffixed(muscles, ACTIVATION_SUFFIX)


def excitation_channels(muscles) -> tuple[str, ...]:
    """``<muscle>_excitation`` for each muscle."""
    return _suffixed(muscles, EXCITATION_SUFFIX)


def emg_channels(muscles) -> tuple[str, ...]:
    """``<muscle>_emg`` for each muscle."""
    return _suffixed(muscles, EMG_SUFFIX)


def force_channels(muscles) -> tuple[str, ...]:
    """``<muscle>_force`` for each muscle (N)."""
    return _suffixed(muscles, FORCE_SUFFIX)


def ground_reaction_channels(side: str | None = None) -> tuple[str, ...]:
    """The nine ground-reaction channel names, prefixed ``<side>_`` if given.

    ``ground_reaction_channels("r")[1] == "r_ground_force_vy"``.
    """
    if side is None or side == "":
        return GROUND_REACTION_CHANNELS
    return tuple(f"{side}_{n}" for n in GROUND_REACTION_CHANNELS)


class GroundReactionName(NamedTuple):
    """A parsed ground-reaction channel name.

    ``quantity`` is ``"force"`` (``v``), ``"point"`` (``p``, centre of
    pressure) or ``"torque"``; ``axis`` is ``"x"``, ``"y"`` or ``"z"``;
    ``side`` is the prefix or infix (``"r"``, ``"1"``) or ``None``.
    """

    side: str | None
    quantity: str
    axis: str


_GRF_RE = re.compile(
    r"^(?:(?P<pre>[A-Za-z0-9]+)_)?ground_(?:"
    r"force_(?:(?P<mid>[A-Za-z0-9]+)_)?(?P<vp>[vp])(?P<fax>[xyz])"
    r"|torque_(?:(?P<tmid>[A-Za-z0-9]+)_)?(?P<tax>[xyz]))$"
)


def parse_ground_reaction(name: str) -> GroundReactionName | None:
    """Parse a ground-reaction channel name, or return ``None``.

    Accepts ``ground_force_vy``, ``r_ground_force_vy``, OpenSim's
    ``1_ground_force_vy`` and ``ground_force_r_vy``, and the torque forms
    ``ground_torque_x``, ``l_ground_torque_x``, ``ground_torque_l_x``.
    """
    m = _GRF_RE.match(name)
    if m is None:
        return None
    inner = m["mid"] or m["tmid"]
    if m["pre"] is not None and inner is not None:
        return None
    side = m["pre"] or inner
    if m["vp"] is not None:
        quantity = "force" if m["vp"] == "v" else "point"
        return GroundReactionName(side, quantity, m["fax"])
    return GroundReactionName(side, "torque", m["tax"])


_NOT_ANGULAR_WORDS = (
    "force", "moment", "torque", "activation", "excitation", "emg",
    "length", "power", "energy",
)  # fmt: skip
_NOT_ANGULAR_END = re.compile(r"(?:^|_)(?:t[xyz]|[pv][xyz]|[xyz]|trans(?:lation)?[xyz]?)$")
_DERIVATIVE_END = re.compile(r"_(?:speed|u|acceleration|accel)$")


def is_angular_name(name: str) -> bool:
    """Whether a channel name looks like a rotational coordinate (or its rate).

    This is the heuristic used when a file declares ``inDegrees=yes`` and the
    caller does not say which channels are angles.  A name is angular unless

    * it is ``time`` or contains a ``.`` (OpenSim 3 state variables such as
      ``soleus.activation``);
    * it is an OpenSim 4 state path (contains ``/``) whose last part is not
      ``value``, ``speed``, ``accel`` or ``acceleration`` (then the coordinate
      is the part before it);
    * after removing a ``_speed``, ``_u``, ``_acceleration`` or ``_accel``
      suffix, it contains force, moment, torque, activation, excitation, emg,
      length, power or energy (case-insensitive);
    * it ends in a translation or position suffix: ``_tx/_ty/_tz``,
      ``_px/_py/_pz``, ``_vx/_vy/_vz``, ``_x/_y/_z`` or ``trans``/``translation``
      with an optional axis letter (``box_transX``).
    """
    if not isinstance(name, str):
        return False
    lowered = name.lower()
    if lowered == TIME or "." in lowered:
        return False
    if "/" in lowered:
        parts = [p for p in lowered.split("/") if p]
        if len(parts) < 2 or parts[-1] not in ("value", "speed", "accel", "acceleration"):
            return False
        lowered = parts[-2]
    base = _DERIVATIVE_END.sub("", lowered)
    if not base or any(w in base for w in _NOT_ANGULAR_WORDS):
        return False
    return _NOT_ANGULAR_END.search(base) is None


def close_matches(name: str, candidates: Iterable[str], n: int = 3) -> list[str]:
    """Up to ``n`` candidates that look like ``name`` (difflib, then substrings)."""
    candidates = list(candidates)
    found = difflib.get_close_matches(name, candidates, n=n, cutoff=0.6)
    low = name.lower()
    for c in candidates:
        if len(found) >= n:
            break
        cl = c.lower()
        if c not in found and low and (low in cl or (len(cl) >= 3 and cl in low)):
            found.append(c)
    return found


def _missing_message(missing: list[str], available: tuple[str, ...], what: str) -> str:
    parts = []
    for name in missing:
        hint = close_matches(name, available)
        if hint:
            alts = " or ".join(repr(h) for h in hint)
            parts.append(f"{name!r} (did you mean {alts}?)")
        else:
            parts.append(repr(name))
    shown = ", ".join(available[:12]) + (", ..." if len(available) > 12 else "")
    return (
        f"missing {what}: {', '.join(parts)}; the trial has {len(available)} "
        f"channels: {shown or '(none)'}"
    )


# ---------------------------------------------------------------------------
# Trial
# ---------------------------------------------------------------------------


AXES = ("x", "y", "z")


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


def _pandas(what: str):
    """pandas, imported when a method needs it; MissingDependencyError naming the method otherwise."""
    try:
        import pandas
    except ImportError:
        from pinmsk.errors import MissingDependencyError
        raise MissingDependencyError(f"{what} needs pandas, which pinmsk does not install: pip install pandas "
                                     "(or pip install pinmsk[pandas])") from None
    return pandas


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


class Trial:
    """Time plus named channels, each (N,), stored as one (N, C) array.

    Parameters
    ----------
    time : array_like, shape (N,)
        Sample times in s; finite and strictly increasing, N >= 1.
    channels : Mapping[str, array_like], optional
        Channel name to samples of shape (N,).  Order is kept.
    units : Mapping[str, str], optional
        Unit of some channels (e.g. ``{"knee_moment": "N*m"}``); informative.
    meta : Mapping, optional
        Free information such as ``source`` (the file read), ``format`` and
        ``in_degrees`` (what the file declared).

    Notes
    -----
    ``time``, ``values`` and the arrays returned by ``trial[name]`` are
    read-only views; copy them to modify.  One name gives one shape
    everywhere: ``trial[name]`` and ``trial.get(name)`` are (N,) (the latter
    a copy); a list of names, ``trial.get([a, b])``, is (N, k).  ``meta`` and ``units`` are
    read-only mappings; use :meth:`with_meta` / :meth:`with_units`.
    """

    __slots__ = ("_time", "_values", "_names", "_index", "_units", "_meta")

    def __init__(self, time, channels: Mapping | None = None, *, units=None, meta=None):
        if channels is None:
            channels = {}
        if not isinstance(channels, Mapping):
            raise TrialError(
                f"channels must be a mapping of name -> (N,) array, got {type(channels).__name__}; "
                "use Trial.from_array(time, names, values) for an (N, C) array"
            )
        t = np.asarray(time, dtype=float)
        names = _as_names(channels, "channel names")
        cols = []
        for name in names:
            try:
                col = np.asarray(channels[name], dtype=float)
            except (TypeError, ValueError) as exc:
                raise TrialError(f"channel {name!r}: values are not numeric ({exc})") from None
            if col.shape != t.shape:
                raise TrialError(
                    f"channel {name!r} has shape {col.shape}, expected {t.shape} to match time"
                )
            cols.append(col)
        values = np.stack(cols, axis=1) if cols else np.empty(t.shape + (0,))
        self._setup(t, names, values, units, meta)

    @classmethod
    def from_array(cls, time, names, values, *, units=None, meta=None) -> Trial:
        """A Trial from ``time`` (N,), ``names`` (C,) and ``values`` (N, C)."""
        names = _as_names(names, "channel names")
        try:
            v = np.asarray(values, dtype=float)
        except (TypeError, ValueError) as exc:
            raise TrialError(f"values are not numeric ({exc})") from None
        t = np.asarray(time, dtype=float)
        if v.ndim == 1 and len(names) == 1:
            v = v[:, None]
        if v.ndim != 2 or v.shape[1] != len(names) or (t.ndim == 1 and v.shape[0] != t.shape[0]):
            raise TrialError(
                f"values have shape {v.shape}, expected (N, C) = ({t.shape[0] if t.ndim else '?'}, "
                f"{len(names)}) for {len(names)} names and {t.shape[0] if t.ndim else '?'} time samples"
            )
        obj = cls.__new__(cls)
        obj._setup(t, names, v, units, meta)
        return obj

    @classmethod
    def _adopt(cls, time, names, values: np.ndarray, *, units=None, meta=None) -> Trial:
        """A Trial that keeps ``values`` (a float (N, C) array the caller hands over and no longer
        writes) instead of a copy; it is made read-only."""
        obj = cls.__new__(cls)
        obj._setup(np.asarray(time, dtype=float), _as_names(names, "channel names"), values, units, meta,
                   copy=False)
        return obj

    def _setup(self, t, names, values, units, meta, copy: bool = True) -> None:
        meta = dict(meta or {})
        where = f"file {meta['source']!r}: " if meta.get("source") else ""
        if t.ndim != 1 or t.shape[0] == 0:
            raise TrialError(f"{where}time must be a non-empty (N,) array, got shape {t.shape}")
        if not np.all(np.isfinite(t)):
            row = int(np.flatnonzero(~np.isfinite(t))[0])
            raise TrialError(f"{where}time is not finite at row {row} (value {float(t[row])!r})")
        check_increasing(t, where=where)
        empty = [i for i, n in enumerate(names) if not n]
        if empty:
            raise TrialError(f"{where}channel name at position {empty[0]} is empty")
        if TIME in names:
            raise TrialError(
                f"{where}a channel is named 'time', which is reserved for the time base; "
                "pass it as time instead"
            )
        if len(set(names)) != len(names):
            seen, dup = set(), []
            for n in names:
                if n in seen and n not in dup:
                    dup.append(n)
                seen.add(n)
            raise TrialError(f"{where}duplicate channel names: {', '.join(map(repr, dup))}")
        units = dict(units or {})
        unknown = [u for u in units if u not in names and u != TIME]
        if unknown:
            raise TrialError(f"{where}units given for unknown channels: {unknown}")
        self._time = _readonly(np.array(t, dtype=float))
        self._values = _readonly((np.array(values, dtype=float) if copy else np.asarray(values, dtype=float))
                                 .reshape(t.shape[0], len(names)))
        self._names = tuple(names)
        self._index = {n: i for i, n in enumerate(self._names)}
        self._units = types.MappingProxyType(units)
        self._meta = types.MappingProxyType(meta)

    def __reduce__(self):
        return (
            _rebuild,
            (self._time, self._names, self._values, dict(self._units), dict(self._meta)),
        )

    # -- basic properties --------------------------------------------------

    @property
    def time(self) -> np.ndarray:
        """Sample times (N,) in s, read-only."""
        return self._time

    @property
    def values(self) -> np.ndarray:
        """All channels as a read-only (N, C) array, columns in :attr:`names` order."""
        return self._values

    @property
    def names(self) -> tuple[str, ...]:
        """Channel names in column order (``time`` excluded)."""
        return self._names

    @property
    def units(self) -> Mapping[str, str]:
        """Read-only mapping of channel name to unit string (only those given)."""
        return self._units

    @property
    def meta(self) -> Mapping:
        """Read-only mapping of free information (``source``, ``in_degrees``, ...)."""
        return self._meta

    @property
    def n_frames(self) -> int:
        """Number of samples N."""
        return self._time.shape[0]

    @property
    def n_channels(self) -> int:
        """Number of channels C."""
        return len(self._names)

    @property
    def duration(self) -> float:
        """``time[-1] - time[0]`` in s."""
        return float(self._time[-1] - self._time[0])

    @property
    def rate(self) -> float:
        """Median sampling rate in Hz (``nan`` for a single frame)."""
        if self.n_frames < 2:
            return float("nan")
        return 1.0 / median_step(self._time)

    def _where(self) -> str:
        src = self._meta.get("source")
        return f"file {src!r}: " if src else ""

    # -- access --------------------------------------------------------------

    def __contains__(self, name) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> np.ndarray:
        """Samples (N,) of one channel (read-only view)."""
        if not isinstance(name, str):
            raise TypeError(
                f"Trial indices are channel names, got {type(name).__name__}; "
                "use trial.get(names) for several channels"
            )
        return self._values[:, self._indices((name,))[0]]

    def _indices(self, names: tuple[str, ...], what: str = "channels") -> list[int]:
        missing = [n for n in names if n not in self._index]
        if missing:
            msg = self._where() + _missing_message(missing, self._names, what)
            if TIME in missing:
                msg += "; 'time' is the time base, use trial.time"
            raise TrialError(msg)
        return [self._index[n] for n in names]

    def get(self, names, *, rows=None) -> np.ndarray:
        """Channels as a writable copy: one name (a string) gives its samples (N,), as ``trial[name]``;
        a list or tuple of k names gives an (N, k) array in the order given (also for one name in a
        list: ``trial.get(["knee_r"])`` is (N, 1)), as NumPy and pandas index ``x["a"]`` / ``x[["a"]]``.

        ``rows`` (frame indices or a boolean mask) takes only those frames.
        """
        single = isinstance(names, str)
        idx = self._indices(_as_names(names))
        if rows is None:
            out = self._values[:, idx]
        else:
            rows = np.asarray(rows)
            rows = np.flatnonzero(rows) if rows.dtype == bool else rows
            out = self._values[np.ix_(rows, idx)]
        return out[:, 0] if single else out

    def channels_matching(self, pattern) -> tuple[str, ...]:
        """Names matching a glob pattern (``"*_moment"``) or a compiled regex (search)."""
        if isinstance(pattern, re.Pattern):
            return tuple(n for n in self._names if pattern.search(n))
        return tuple(n for n in self._names if fnmatch.fnmatchcase(n, pattern))

    def to_pandas(self):
        """A ``pandas.DataFrame``: one column per channel (copies), indexed by the time in s (index name
        ``time``); ``df.attrs`` holds ``units`` and ``meta``.  Needs pandas (``pip install pandas``);
        pinmsk itself does not.  :meth:`from_pandas` reads it back."""
        pd = _pandas("Trial.to_pandas")
        df = pd.DataFrame(self._values.copy(), columns=list(self._names),
                          index=pd.Index(self._time.copy(), name=TIME))
        df.attrs["units"] = dict(self._units)
        df.attrs["meta"] = dict(self._meta)
        return df

    @classmethod
    def from_pandas(cls, df, *, time: str | None = None, units=None, meta=None) -> Trial:
        """A Trial from a ``pandas.DataFrame`` of numeric columns.

        The time base is the column ``time`` (or that column's name given as ``time``; a label
        with a unit such as ``Time (ms)`` is converted to s, as :func:`pinmsk.io.read_trial` does),
        else the index (as :meth:`to_pandas` writes it).  Every other column is a channel.
        ``units`` / ``meta`` default to ``df.attrs`` (what :meth:`to_pandas` stored).  Needs pandas.
        """
        pd = _pandas("Trial.from_pandas")
        if not isinstance(df, pd.DataFrame):
            raise TrialError(f"from_pandas needs a pandas.DataFrame, got {type(df).__name__}")
        names = [str(c) for c in df.columns]
        if len(set(names)) != len(names):
            raise TrialError(f"from_pandas: duplicate column names {sorted({n for n in names if names.count(n) > 1})}")
        if time is None:
            found = [c for c in df.columns if time_label_unit(str(c)) is not None]
            if len(found) > 1:
                raise TrialError(f"from_pandas: several time columns {found}; pass time=NAME")
            time = found[0] if found else None
        elif time not in df.columns:
            raise TrialError(f"from_pandas: no column {time!r} for the time (columns: {', '.join(names[:12])})")
        if time is None:
            t = np.asarray(df.index, dtype=float) if pd.api.types.is_numeric_dtype(df.index) else None
            if t is None:
                raise TrialError("from_pandas: no 'time' column and the index is not numeric; pass time=NAME")
            data = df
        else:
            unit = time_label_unit(str(time)) or "s"
            t = np.asarray(df[time], dtype=float) * TIME_UNITS[unit]
            data = df.drop(columns=[time])
        bad = [str(c) for c in data.columns if not pd.api.types.is_numeric_dtype(data[c])]
        if bad:
            raise TrialError(f"from_pandas: column(s) {', '.join(map(repr, bad[:5]))} are not numeric")
        attrs = getattr(df, "attrs", {}) or {}
        units = dict(attrs.get("units", {})) if units is None else units
        meta = dict(attrs.get("meta", {})) if meta is None else meta
        units = {k: v for k, v in units.items() if k in set(map(str, data.columns))}
        return cls.from_array(t, [str(c) for c in data.columns], data.to_numpy(dtype=float), units=units, meta=meta)

    def to_dict(self) -> dict[str, np.ndarray]:
        """``{"time": time, name: samples, ...}`` with writable copies."""
        out = {TIME: self._time.copy()}
        out.update({n: self._values[:, i].copy() for i, n in enumerate(self._names)})
        return out

    def __repr__(self) -> str:
        shown = ", ".join(self._names[:8]) + (", ..." if self.n_channels > 8 else "")
        rate = f" at {self.rate:.6g} Hz" if self.n_frames > 1 else ""
        src = f", source={self._meta['source']!r}" if self._meta.get("source") else ""
        return (
            f"Trial({self.n_frames} frames, {self._time[0]:.6g} to {self._time[-1]:.6g} s{rate}, "
            f"{self.n_channels} channels: {shown or '-'}{src})"
        )

    # -- new trials ----------------------------------------------------------

    def _new(self, time, names, values, *, units=None, meta=None) -> Trial:
        keep_units = {n: u for n, u in (self._units if units is None else units).items() if n in names}
        return Trial.from_array(
            time, names, values, units=keep_units, meta=dict(self._meta if meta is None else meta)
        )

    def with_channels(self, channels: Mapping | None = None, /, **more) -> Trial:
        """A new Trial with channels added or replaced (replaced keep their column).

        ``trial.with_channels({"a_speed": v})`` or ``trial.with_channels(a_speed=v)``.
        """
        new = dict(channels or {})
        both = sorted(set(new) & set(more))
        if both:
            raise TrialError(f"channels given twice (mapping and keyword): {both}")
        new.update(more)
        if TIME in new:
            raise TrialError("'time' cannot be set as a channel; build a new Trial instead")
        cols = {}
        for name, v in new.items():
            if not isinstance(name, str) or not name:
                raise TrialError(f"channel names must be non-empty strings, got {name!r}")
            try:
                col = np.asarray(v, dtype=float)
            except (TypeError, ValueError) as exc:
                raise TrialError(f"channel {name!r}: values are not numeric ({exc})") from None
            if col.shape != self._time.shape:
                raise TrialError(
                    f"channel {name!r} has shape {col.shape}, expected {self._time.shape} to match time"
                )
            cols[name] = col
        names = list(self._names) + [n for n in cols if n not in self._index]
        values = np.empty((self.n_frames, len(names)))
        values[:, : self.n_channels] = self._values
        for name, col in cols.items():
            values[:, names.index(name)] = col
        return self._new(self._time, names, values)

    def with_meta(self, **entries) -> Trial:
        """A new Trial (same arrays) with ``meta`` entries added or replaced."""
        return self._new(self._time, self._names, self._values, meta={**self._meta, **entries})

    def with_units(self, units: Mapping[str, str]) -> Trial:
        """A new Trial (same arrays) with channel units added or replaced."""
        self._indices(tuple(units))
        return self._new(self._time, self._names, self._values, units={**self._units, **units})

    def select(self, names) -> Trial:
        """A new Trial with only ``names``, in that order."""
        names = _as_names(names)
        return self._new(self._time, names, self._values[:, self._indices(names)])

    def drop(self, names) -> Trial:
        """A new Trial without ``names`` (each must exist)."""
        gone = set(self._indices(_as_names(names)))
        keep = [i for i in range(self.n_channels) if i not in gone]
        return self._new(self._time, [self._names[i] for i in keep], self._values[:, keep])

    def slice_time(self, t0: float | None = None, t1: float | None = None) -> Trial:
        """A new Trial with the samples ``t0 <= time <= t1`` (ends included).

        ``None`` leaves that side open.  Bounds are matched with a tolerance of
        1e-6 of the median time step, so bounds printed with rounding still
        include the sample they name.
        """
        t = self._time
        tol = 1e-6 * (np.median(np.diff(t)) if t.shape[0] > 1 else 1.0)
        lo = -np.inf if t0 is None else float(t0) - tol
        hi = np.inf if t1 is None else float(t1) + tol
        if t0 is not None and t1 is not None and float(t1) < float(t0):
            raise TrialError(f"slice_time: t1={t1!r} is before t0={t0!r}")
        mask = (t >= lo) & (t <= hi)
        if not mask.any():
            raise TrialError(
                f"{self._where()}no samples between {t0!r} and {t1!r} s; "
                f"the trial spans {t[0]:.6g} to {t[-1]:.6g} s"
            )
        return self._new(t[mask], self._names, self._values[mask])

    def resample(self, time_or_rate, *, method: str = "cubic", antialias: bool = False,
                 order: int = 4) -> Trial:
        """A new Trial interpolated onto new sample times (the one resampling of pinmsk).

        Parameters
        ----------
        time_or_rate : float or array_like
            A rate in Hz (samples at ``time[0] + k / rate`` up to ``time[-1]``)
            or the new times (strictly increasing, inside ``[time[0], time[-1]]``;
            no extrapolation).
        method : {"cubic", "linear"}
            ``"cubic"``: not-a-knot cubic spline
            (``scipy.interpolate.CubicSpline``), all channels must be finite.
            ``"linear"``: piecewise linear (``numpy.interp``); a NaN only
            affects the intervals next to it.
        antialias : bool
            When the new rate is lower than the trial's, low-pass the finite
            channels first (zero-lag Butterworth of ``order`` at 0.4 x the new
            rate), so that aligning 2 kHz force plates onto 100 Hz markers does
            not alias.  Channels with NaN (e.g. the COP of an unloaded plate)
            are interpolated unfiltered.
        """
        t = self._time
        if np.ndim(time_or_rate) == 0:
            rate = float(time_or_rate)
            if not (np.isfinite(rate) and rate > 0):
                raise TrialError(f"resample rate must be a positive number of Hz, got {time_or_rate!r}")
            n = int(math.floor((t[-1] - t[0]) * rate * (1 + 1e-12) + 1e-9)) + 1
            new_t = np.minimum(t[0] + np.arange(n) / rate, t[-1])
        else:
            new_t = np.asarray(time_or_rate, dtype=float)
            if new_t.ndim != 1 or new_t.shape[0] == 0:
                raise TrialError(f"new times must be a non-empty (M,) array, got shape {new_t.shape}")
            check_increasing(new_t, where="resample: new ")
            tol = 1e-9 * max(1.0, abs(t[0]), abs(t[-1]))
            out = np.flatnonzero((new_t < t[0] - tol) | (new_t > t[-1] + tol))
            if out.size:
                k = int(out[0])
                raise TrialError(
                    f"{self._where()}resample: new time[{k}]={float(new_t[k])!r} is outside the trial "
                    f"[{float(t[0])!r}, {float(t[-1])!r}] s ({out.size} such samples); slice the new times, "
                    "extrapolation is not done"
                )
            new_t = np.clip(new_t, t[0], t[-1])
        src = self._values
        if antialias and new_t.size > 1 and self.n_frames > 1:
            new_rate, old_rate = 1.0 / median_step(new_t), uniform_rate(t, where=self._where(),
                                                                        purpose="anti-alias filtering")
            finite = np.flatnonzero(np.all(np.isfinite(src), axis=0))
            if new_rate < 0.99 * old_rate and finite.size:
                src = src.copy()
                src[:, finite] = lowpass(src[:, finite], rate=old_rate, cutoff=0.4 * new_rate, order=order)
        if method == "linear":
            values = np.empty((new_t.shape[0], self.n_channels))
            for j in range(self.n_channels):  # one call per channel, vectorised over frames
                values[:, j] = np.interp(new_t, t, src[:, j])
        elif method == "cubic":
            if self.n_frames < 2:
                raise TrialError("resample needs at least 2 frames")
            self._check_finite(self._names, hint="or use method='linear'")
            from scipy.interpolate import CubicSpline

            if self.n_channels:
                values = CubicSpline(t, src, axis=0)(new_t)
            else:
                values = np.empty((new_t.shape[0], 0))
        else:
            raise TrialError(f"resample method must be 'cubic' or 'linear', got {method!r}")
        return self._new(new_t, self._names, values, meta={**self._meta, "resampled": method})

    def merge(self, other: Trial) -> Trial:
        """A new Trial with the channels of both; the time bases must agree.

        Times agree when both have N samples differing by at most 1e-6 of the
        median time step.  Channel names must not overlap.  Entries of
        ``self.meta`` win over those of ``other.meta``.
        """
        if not isinstance(other, Trial):
            raise TypeError(f"can only merge a Trial, got {type(other).__name__}")
        t, u = self._time, other._time
        tol = 1e-6 * (np.median(np.diff(t)) if t.shape[0] > 1 else 1.0)
        if t.shape != u.shape or np.max(np.abs(t - u)) > tol:
            detail = (
                f"{t.shape[0]} vs {u.shape[0]} frames"
                if t.shape != u.shape
                else f"largest difference {np.max(np.abs(t - u)):.3g} s "
                f"at row {int(np.argmax(np.abs(t - u)))}"
            )
            raise TrialError(
                f"cannot merge trials with different time bases ({detail}; "
                f"{t[0]:.6g}-{t[-1]:.6g} s vs {u[0]:.6g}-{u[-1]:.6g} s); "
                "resample one onto the other first: other.resample(trial.time)"
            )
        dup = [n for n in other._names if n in self._index]
        if dup:
            raise TrialError(
                f"cannot merge: both trials have channels {', '.join(map(repr, dup))}; "
                "drop or rename them first"
            )
        return Trial.from_array(
            t,
            self._names + other._names,
            np.concatenate([self._values, other._values], axis=1),
            units={**other._units, **self._units},
            meta={**other._meta, **self._meta},
        )

    # -- checks ----------------------------------------------------------------

    def require(self, coordinates) -> tuple[str, ...]:
        """Check that every coordinate has a channel; return the names.

        Raises TrialError naming the missing ones with close matches
        ("did you mean 'r_elbow_flex'?").
        """
        names = coordinate_channels(coordinates)
        self._indices(names, what="coordinate channel(s)")
        return names

    def check_finite(self, names=None, *, limit: float | None = None, nan_ok: bool = False,
                     what: str = "") -> Trial:
        """Check that channels (all, or ``names``) are finite and, with ``limit``, within ±limit.

        Raises TrialError naming, for each bad channel (up to 5), the number of
        bad values, the first rows and the time of the first; ``what`` (e.g.
        "before the diagnosis") is added to the message.  A ``limit`` catches
        fill values such as 1e300 that are finite but not measurements;
        ``nan_ok`` accepts NaN (a centre of pressure while a plate is unloaded)
        but not infinity.  Returns the trial unchanged.
        """
        self._check_finite(self._names if names is None else _as_names(names), hint=what, limit=limit,
                           nan_ok=nan_ok)
        return self

    def _block(self, idx: list[int]) -> np.ndarray:
        """The (N, k) samples of channel indices ``idx``: a read-only view when they are consecutive (a
        trial built from exactly the columns asked, in order), else a copy."""
        if idx and idx[-1] - idx[0] == len(idx) - 1 and idx == list(range(idx[0], idx[-1] + 1)):
            view = self._values[:, idx[0]:idx[-1] + 1]
            view.flags.writeable = False
            return view
        return self._values[:, idx]

    def _check_finite(self, names, hint: str = "", limit: float | None = None, nan_ok: bool = False,
                      block: np.ndarray | None = None) -> None:
        idx = self._indices(tuple(names))
        if block is None:
            block = self._block(idx)
        bad = np.isinf(block) if nan_ok else ~np.isfinite(block)
        if limit is not None:
            with np.errstate(invalid="ignore"):
                bad |= np.abs(block) > limit
        cols = np.flatnonzero(bad.any(axis=0))
        if cols.size == 0:
            return
        lines = []
        for c in cols[:5]:
            rows = np.flatnonzero(bad[:, c])
            first = ", ".join(str(r) for r in rows[:5]) + (", ..." if rows.size > 5 else "")
            name = self._names[idx[c]]
            value = float(self._values[rows[0], idx[c]])
            if np.isfinite(value):
                kind = f"{value:.3g} first, beyond ±{limit:.3g}"
                what = "implausible"
            else:
                kind = f"{'NaN' if np.isnan(value) else 'inf'} first"
                what = "non-finite"
            lines.append(
                f"channel {name!r} has {rows.size} {what} value(s) ({kind}) at rows "
                f"{first} (time {self._time[rows[0]]:.6g} s)"
            )
        more = f"; and {cols.size - 5} more channels" if cols.size > 5 else ""
        raise TrialError(
            self._where() + "; ".join(lines) + more
            + "; fill or cut the gaps (slice_time, resample(method='linear'))"
            + (f" {hint}" if hint else "")
        )

    def _check_radians(self, names, block: np.ndarray | None = None) -> None:
        idx = self._indices(tuple(names))
        if not idx:
            return
        if block is None:
            block = self._block(idx)
        peak = np.max(np.abs(block), axis=0, initial=0.0)
        if not np.isfinite(peak).all():     # gaps (NaN, inf) are not angles: the peak of the finite samples
            peak = np.max(np.abs(block), axis=0, initial=0.0, where=np.isfinite(block))
        over = np.flatnonzero(peak > DEGREES_THRESHOLD)
        if over.size == 0:
            return
        k = int(over[0])
        name = self._names[idx[k]]
        declared = self._meta.get("in_degrees")
        converted = self._meta.get("converted_to_radians", ())
        what = f"column {name!r} looks like degrees (max {peak[k]:.1f})"
        if not self._meta.get("source"):
            fix = "but trial channels must be in radians; convert with numpy.deg2rad"
        elif declared is True and name not in converted:
            fix = (
                "but it was not converted from degrees because it was not recognised as "
                f"an angle; pass angular=[..., {name!r}] to read_trial"
            )
        elif self._meta.get("format") == "csv" and not declared:
            fix = ("but a CSV is read in radians; if it is in degrees, pass --degrees (command line) or "
                   "read_trial(path, in_degrees=True) (Python)")
        elif declared is None:
            fix = (
                "but the file does not declare inDegrees (radians assumed); if it is in degrees, pass "
                "--degrees (command line) or in_degrees=True (Python), or set inDegrees=yes in the header"
            )
        else:
            fix = ("but the file declares radians; if it is in degrees, pass --degrees (command line) or "
                   "in_degrees=True (Python), or set inDegrees=yes in the header")
        others = f" (also {', '.join(repr(self._names[idx[i]]) for i in over[1:4])})" if over.size > 1 else ""
        raise TrialError(f"{self._where()}{what} {fix}{others}")

    def validate(self, *, coordinates=None, angular=None) -> Trial:
        """Check the trial for use; return it unchanged or raise TrialError.

        Checks, in order: time finite and strictly increasing (first offending
        row and values); the ``coordinates`` are present (with suggestions);
        every channel is finite (channel, count and first rows); and angular
        channels look like radians: a largest magnitude above
        :data:`DEGREES_THRESHOLD` (3π, 540°) means degrees.  The angular
        channels are ``angular`` if given (names absent from the trial are
        ignored; presence is what ``coordinates`` checks), else those
        ``coordinates`` that :func:`is_angular_name` takes for rotations; with
        neither, no unit check is made.
        """
        check_increasing(self._time, where=self._where())
        coords = self.require(coordinates) if coordinates is not None else ()
        self._check_finite(self._names)
        if angular is not None:
            self._check_radians([n for n in _as_names(angular) if n in self._index])
        else:
            self._check_radians([c for c in coords if is_angular_name(c)])
        return self

    # -- filtering -------------------------------------------------------------

    def kinematics(self, coordinates, *, cutoff: float | None = None, order: int = 4, method: str = "butterworth"):
        """Coordinates, speeds and accelerations ``(q, v, a)``, each (N, n).

        ``q`` are the ``coordinates`` channels (low-passed at ``cutoff`` Hz if
        given); ``v`` and ``a`` are derivatives of the quintic spline through
        them (:func:`pinmsk.signals.filtering.differentiate`, whose ``method`` picks the low-pass:
        pinmsk's Butterworth or OpenSim's ID tool's).  The coordinates must be
        present and finite, and rotational ones (by :func:`is_angular_name`)
        must look like radians.
        """
        names = self.require(coordinates)
        block = self._block(self._indices(tuple(names)))      # gathered once for the checks and the spline
        self._check_finite(names, block=block)
        angular = [i for i, c in enumerate(names) if is_angular_name(c)]
        self._check_radians([names[i] for i in angular],
                            block=block if len(angular) == len(names) else block[:, angular])
        q, v, a = differentiate(self._time, block, cutoff=cutoff, order=order, method=method)
        return (q.copy() if q is block else q), v, a

    def smoothed(self, cutoff: float, *, order: int = 4, names=None) -> Trial:
        """A new Trial with channels (all, or ``names``) low-passed at ``cutoff`` Hz.

        Zero-lag Butterworth (:func:`pinmsk.signals.filtering.lowpass`) at the median
        rate; the time steps must be uniform within
        :data:`pinmsk.signals.sampling.UNIFORM_TOLERANCE` (10 %).
        """
        names = self._names if names is None else _as_names(names)
        idx = self._indices(names)
        self._check_finite(names)
        t = self._time
        rate = uniform_rate(t, where=self._where(), purpose="smoothing")
        values = self._values.copy()
        values[:, idx] = lowpass(values[:, idx], rate=rate, cutoff=cutoff, order=order)
        return self._new(t, self._names, values, meta={**self._meta, "lowpass_cutoff": float(cutoff)})


def _rebuild(time, names, values, units, meta) -> Trial:
    """Unpickle a Trial."""
    return Trial.from_array(time, names, values, units=units, meta=meta)
