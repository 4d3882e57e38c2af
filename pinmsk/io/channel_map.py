"""Column maps: rename a trial's columns (with a sign or offset) to a model's channel names.

A map is a TOML file (``--map map.toml``, :func:`load_channel_map`)::

    # old column name -> new channel name
    [rename]
    hip_flexion_r = "hip_r"
    knee_angle_r = "knee_r"
    pelvis_ty = "torso_y"

    [scale]              # optional: new = scale * old + offset (default scale 1)
    hip_r = -1           # keyed by the new name (hip_r) or the old one (hip_flexion_r)

    [offset]             # optional, in the new channel's SI unit (rad, m; default 0)
    pelvis_ty = 0.1

* Angles are converted from degrees first (when the file says ``inDegrees=yes``),
  so ``offset`` is in radians for an angle.
* An entry also maps the ``<old>_speed`` and ``<old>_moment`` columns, when the
  trial has them and the map does not name them itself, with the same scale and
  no offset (a sign flip of a coordinate flips its speed and moment).
* An old name also matches an OpenSim 4 state path ``/jointset/<joint>/<old>/value``.
* Columns the map does not name are kept as they are.
* ``[scale]`` and ``[offset]`` keys name a ``[rename]`` entry by its old column
  name or by its new channel name (not both for one entry).
* Errors name the file and the entry: an unknown section or a ``[scale]`` /
  ``[offset]`` key that is not a ``[rename]`` entry (with a "did you mean"), an
  entry naming a column the trial lacks, two entries with one new name, a new
  name the trial already has; and, given a model, the coordinates the model
  needs that the mapped trial still lacks.

Built-in maps (``--map NAME``, :data:`BUILTIN_MAPS`) take OpenSim sagittal gait
coordinates to ``gait2d`` (OpenSim rotates about +z, z to the right; gait2d: hip + =
extension, knee + = flexion, ankle + = plantarflexion, 0 = upright):

* ``torso_angle = -pelvis_tilt`` (OpenSim + = posterior tilt; gait2d + = forward lean);
* ``hip_[rl] = -hip_flexion_[rl]``;
* ``knee_[rl] = +knee_angle_[rl]`` for Rajagopal (+ = flexion), ``-knee_angle_[rl]`` for
  gait2392, Gait10dof18musc and Moco's 2D model (negative in flexion);
* ``ankle_[rl] = -ankle_angle_[rl]`` (OpenSim + = dorsiflexion);
* ``mtp_[rl] = 0`` (those models have no mtp coordinate, or lock it);
* ``torso_x, torso_y``: the gait2d HAT centre of mass placed so that gait2d's hip joint
  lies on the OpenSim hip centre ``pelvis_t[xy] + R(pelvis_tilt) hip``.

``hip`` is the hip joint centre in the OpenSim pelvis frame: the unscaled Rajagopal et
al. (2016) model's :data:`RAJAGOPAL_HIP_OFFSET`, or Gait10dof18musc's
:data:`GAIT10DOF_HIP_OFFSET`.  The HAT is taken as rigid with the pelvis (lumbar
extension is ignored) and out-of-plane coordinates are left unmapped.  The maps:

* ``rajagopal-gait2d``: knee ``+``, Rajagopal hip;
* ``gait10dof-gait2d``: knee ``-``, Gait10dof18musc hip (also right within 4 mm for
  Moco's ``2D_gait.osim``);
* ``opensim-gait2d``: Rajagopal hip, knee sign from the data: flexion must be positive
  over a stride, so a knee angle mostly negative (median of both knees < 0) is read as
  ``-knee_angle``; the choice is reported in ``meta["channel_map"]["notes"]``.

Ground-reaction columns (``ground_force_vx``, ``1_ground_force_vx``,
``r_ground_force_vx``, ``ground_force_r_vx``, ...) are kept as they are: pinmsk reads
all these forms, and OpenSim's ground frame is gait2d's (x forward, y up).
:func:`pinmsk.pipeline.opensim_to_gait2d` is :func:`apply_channel_map` with these maps.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from ..errors import TrialError
from ..trial import Trial, close_matches, parse_ground_reaction
from .tables import read_trial, state_path_coordinate
from .toml_files import read_toml

__all__ = ["MapEntry", "ChannelMap", "load_channel_map", "apply_channel_map", "read_mapped", "suggest_map",
           "with_state_path_coordinates", "map_hint",
           "BUILTIN_MAPS", "MAP_SCHEMA", "opensim_gait2d_map", "RAJAGOPAL_HIP_OFFSET", "GAIT10DOF_HIP_OFFSET"]

#: Hip joint centre in the pelvis frame of the Rajagopal et al. (2016) model (unscaled, m;
#: x forward, y up): ``hip_r`` location_in_parent (-0.056276, -0.07849, 0.07726).
RAJAGOPAL_HIP_OFFSET = (-0.056276, -0.07849)

#: Hip joint centre in the pelvis frame of OpenSim's Gait10dof18musc (= gait2392, unscaled, m):
#: ``hip_r`` pelvis_offset translation (-0.0707, -0.0661, 0.0835).
GAIT10DOF_HIP_OFFSET = (-0.0707, -0.0661)

#: Sections of a map file and what they hold.
MAP_SCHEMA = {
    "rename": "old column name = \"new channel name\" (required)",
    "scale": "old column name or new channel name = factor: new = scale * old + offset (default 1)",
    "offset": "old column name or new channel name = value in the new channel's SI unit, rad or m (default 0)",
}

#: Derived columns an entry carries along (same scale, no offset).
_DERIVED = ("_speed", "_moment")


@dataclass(frozen=True)
class MapEntry:
    """``target = scale * source + offset``; ``auto_sign``: the sign comes from the data."""

    source: str
    target: str
    scale: float = 1.0
    offset: float = 0.0
    auto_sign: bool = False


@dataclass(frozen=True)
class ChannelMap:
    """A column map (see the module docstring).

    ``where`` names it in messages (the file, or ``built-in map 'NAME'``).  ``required``:
    every entry must find its column (map files); built-in maps skip absent ones and let
    the model check name what is missing.  ``hip_offset``: place gait2d's ``torso_x``,
    ``torso_y`` from OpenSim's ``pelvis_tx``, ``pelvis_ty``, ``pelvis_tilt`` with this hip
    centre.  ``zeros``: targets set to 0 when no entry gives them.  ``origins``: new name ->
    the source columns it comes from, for messages.
    """

    name: str
    entries: tuple[MapEntry, ...]
    where: str
    required: bool = True
    hip_offset: tuple[float, float] | None = None
    zeros: tuple[str, ...] = ()
    origins: Mapping[str, str] = field(default_factory=dict)

    def angular_sources(self, model) -> set[str]:
        """Source names whose target is one of ``model``'s rotational coordinates."""
        rot = set(model.rotational_coordinates)
        return {e.source for e in self.entries if e.target in rot}


# ---------------------------------------------------------------------------
# built-in maps
# ---------------------------------------------------------------------------

def opensim_gait2d_map(*, knee_sign="auto", hip_offset=RAJAGOPAL_HIP_OFFSET,
                       name: str = "opensim-gait2d") -> ChannelMap:
    """The OpenSim -> gait2d map (module docstring); ``knee_sign`` is ``"auto"``, ``1`` or ``-1``."""
    if knee_sign not in ("auto", 1, -1):
        raise TrialError(f"knee_sign must be 'auto', 1 or -1, not {knee_sign!r}")
    auto = knee_sign == "auto"
    entries = [MapEntry("pelvis_tilt", "torso_angle", -1.0)]
    for s in "rl":
        entries += [MapEntry(f"hip_flexion_{s}", f"hip_{s}", -1.0),
                    MapEntry(f"knee_angle_{s}", f"knee_{s}", 1.0 if auto else float(knee_sign), auto_sign=auto),
                    MapEntry(f"ankle_angle_{s}", f"ankle_{s}", -1.0)]
    origins = {e.target: e.source for e in entries}
    origins.update({"torso_x": "pelvis_tx, pelvis_ty, pelvis_tilt", "torso_y": "pelvis_tx, pelvis_ty, pelvis_tilt"})
    return ChannelMap(name, tuple(entries), f"built-in map {name!r}", required=False,
                      hip_offset=tuple(hip_offset), zeros=("mtp_r", "mtp_l"), origins=origins)


#: Built-in maps by name (``--map NAME``).
BUILTIN_MAPS = {
    "opensim-gait2d": lambda: opensim_gait2d_map(),
    "rajagopal-gait2d": lambda: opensim_gait2d_map(knee_sign=1, name="rajagopal-gait2d"),
    "gait10dof-gait2d": lambda: opensim_gait2d_map(knee_sign=-1, hip_offset=GAIT10DOF_HIP_OFFSET,
                                                   name="gait10dof-gait2d"),
}


def suggest_map(trial: Trial, model) -> str | None:
    """A built-in map to suggest when ``trial`` lacks ``model``'s coordinates but holds a map's sources."""
    missing = [c for c in model.coordinates if c not in trial]
    if not missing:
        return None
    for name, make in BUILTIN_MAPS.items():
        cmap = make()
        found = any(_find(trial.names, e.source) is not None for e in cmap.entries)
        if found and set(missing) <= set(cmap.origins) | set(cmap.zeros):
            return name
    return None


# ---------------------------------------------------------------------------
# map files
# ---------------------------------------------------------------------------

def _unknown(key: str, valid, what: str, where: str) -> TrialError:
    hint = close_matches(key, valid, n=1)
    did = f" (did you mean {hint[0]!r}?)" if hint else ""
    return TrialError(f"{where}: unknown {what} {key!r}{did}; valid: {', '.join(valid) or '(none)'}")


def _number(value, where: str, what: str) -> float:
    ok = not isinstance(value, bool) and isinstance(value, (int, float))
    number = float(value) if ok and abs(value) < 1e308 else float("nan")     # a TOML integer may exceed a float
    if not np.isfinite(number):
        shown = repr(value) if len(repr(value)) < 40 else repr(value)[:37] + "..."
        raise TrialError(f"{where}: {what} = {shown} must be a finite number")
    return number


def load_channel_map(spec) -> ChannelMap:
    """A :class:`ChannelMap` from a built-in name (:data:`BUILTIN_MAPS`) or a TOML file path."""
    if isinstance(spec, ChannelMap):
        return spec
    if str(spec) in BUILTIN_MAPS:
        return BUILTIN_MAPS[str(spec)]()
    path = Path(spec)
    if path.suffix.lower() != ".toml":
        hint = close_matches(str(spec), BUILTIN_MAPS, n=1)
        did = f" (did you mean {hint[0]!r}?)" if hint else ""
        raise TrialError(f"column map {str(spec)!r} is neither a built-in map{did} nor a .toml file; "
                         f"built-in maps: {', '.join(BUILTIN_MAPS)}")

    raw = read_toml(path, what="column map", error=TrialError)
    where = str(path)
    for key, value in raw.items():
        if key not in MAP_SCHEMA:
            err = _unknown(key, list(MAP_SCHEMA), "section", where)
            if not isinstance(value, dict):
                err = TrialError(f"{err}; put column renames under a [rename] table")
            raise err
        if not isinstance(value, dict):
            raise TrialError(f"{where}: {key} must be a table [{key}]")
    rename = raw.get("rename")
    if not rename:
        raise TrialError(f"{where}: no [rename] table; a column map renames columns: "
                         "[rename] then lines old_name = \"new_name\"")
    targets: dict[str, str] = {}
    for old, new in rename.items():
        if not isinstance(new, str) or not new.strip():
            raise TrialError(f"{where}: [rename] {old} = {new!r}: the new name must be a non-empty string")
        if "time" in (old, new):
            raise TrialError(f"{where}: [rename] {old} = {new!r}: 'time' is the time base and cannot be renamed")
        if new in targets:
            raise TrialError(f"{where}: [rename] {targets[new]!r} and {old!r} both map to {new!r}")
        targets[new] = old
    by_new = {new.strip(): old for old, new in rename.items()}
    keyed: dict[str, dict[str, tuple[str, object]]] = {}     # section -> old name -> (key as written, value)
    for section in ("scale", "offset"):
        keyed[section] = {}
        for key, value in raw.get(section, {}).items():
            old = key if key in rename else by_new.get(key)
            if old is None:
                raise _unknown(key, list(rename) + [n for n in by_new if n not in rename],
                               f"[{section}] key (neither an old nor a new name of a [rename] entry)", where)
            if old in keyed[section]:
                raise TrialError(f"{where}: [{section}] {keyed[section][old][0]} and {key} name the same "
                                 f"[rename] entry {old} = {rename[old]!r}; keep one")
            keyed[section][old] = (key, value)
    entries = []
    for old, new in rename.items():
        key, value = keyed["scale"].get(old, (old, 1.0))
        scale = _number(value, where, f"[scale] {key}")
        if scale == 0.0:
            raise TrialError(f"{where}: [scale] {key} = 0 would erase the column")
        key, value = keyed["offset"].get(old, (old, 0.0))
        offset = _number(value, where, f"[offset] {key}")
        entries.append(MapEntry(old, new.strip(), scale, offset))
    return ChannelMap(path.stem, tuple(entries), where, required=True)


# ---------------------------------------------------------------------------
# applying a map
# ---------------------------------------------------------------------------

def _find(names: tuple[str, ...], source: str) -> str | None:
    """The column holding ``source``: itself, or an OpenSim state path ``/.../<source>/value``."""
    if source in names:
        return source
    for n in names:
        if state_path_coordinate(n) == (source, "value"):
            return n
    return None


def _hat_position(tx, ty, tilt, model, hip_offset):
    """gait2d ``torso_x, torso_y`` with its hip joint on the OpenSim hip centre (see module docstring)."""
    ox, oy = hip_offset
    hx = tx + np.cos(tilt) * ox - np.sin(tilt) * oy
    hy = ty + np.sin(tilt) * ox + np.cos(tilt) * oy
    ta = -tilt
    # distance from the hip joint up to the HAT COM in gait2d (the hip's placement in the HAT frame)
    pm = model.pin
    above = -float(pm.jointPlacements[pm.getJointId("hip_r")].translation[1])
    return hx + above * np.sin(ta), hy + above * np.cos(ta)


def _plan(trial: Trial, cmap: ChannelMap) -> dict[str, tuple[str, MapEntry]]:
    """Column -> (new name, entry) for the map's entries and the ``_speed``/``_moment`` they carry.

    An entry is satisfied by its column or by one of those it carries (a moments trial
    has ``knee_angle_r_moment`` but no ``knee_angle_r``).
    """
    src = trial.meta.get("source") or "the trial"
    explicit = {e.source for e in cmap.entries}
    plan: dict[str, tuple[str, MapEntry]] = {}
    for e in cmap.entries:
        col = _find(trial.names, e.source)
        if col is not None:
            plan[col] = (e.target, e)
        base = col[: -len("value")] if col is not None and col.endswith("/value") else None
        carried = 0
        for suffix in _DERIVED:
            d = base + suffix[1:] if base is not None else e.source + suffix
            if d in trial and e.source + suffix not in explicit:
                plan[d] = (e.target + suffix, MapEntry(d, e.target + suffix, e.scale, 0.0, e.auto_sign))
                carried += 1
        if col is None and not carried and cmap.required:
            hint = close_matches(e.source, trial.names, n=1)
            did = f" (did you mean {hint[0]!r}?)" if hint else ""
            raise TrialError(f"{cmap.where}: [rename] {e.source} = {e.target!r}: {src} has no column "
                             f"{e.source!r}{did}")
    return plan


def _data_sign(trial: Trial, plan, cmap: ChannelMap) -> tuple[float, str | None]:
    """The sign of the ``auto_sign`` entries: + if their coordinates are mostly positive; and the note."""
    auto = [c for c, (_, e) in plan.items() if e.auto_sign and e in cmap.entries]
    if not any(e.auto_sign for _, e in plan.values()):
        return 1.0, None
    src = trial.meta.get("source") or "the trial"
    if not auto:
        raise TrialError(f"{cmap.where}: cannot choose the knee sign from {src}: it has no knee angle "
                         "column; use --map rajagopal-gait2d or gait10dof-gait2d")
    med = float(np.median(np.concatenate([trial[c] for c in auto])))
    shown = ", ".join((state_path_coordinate(c) or (c,))[0] for c in auto)
    if med < 0:
        return -1.0, (f"{cmap.where}: {shown} median {med:.3g} rad, so flexion is negative (gait2392 / "
                      "Gait10dof18musc convention): knee = -knee_angle")
    return 1.0, f"{cmap.where}: {shown} median {med:.3g} rad, so flexion is positive (Rajagopal convention): " \
                "knee = +knee_angle"


def apply_channel_map(trial: Trial, cmap, *, model=None, require_coordinates: bool = True) -> Trial:
    """``trial`` with its columns renamed by ``cmap`` (a :class:`ChannelMap`, name or path).

    With ``model`` and ``require_coordinates``, the mapped trial must hold every
    coordinate of the model; a :class:`~pinmsk.errors.TrialError` lists those it
    lacks.  ``meta["channel_map"]`` records the map, the renames and the notes
    (choices the map made from the data, coordinates it set to 0).
    """
    cmap = load_channel_map(cmap)
    src = trial.meta.get("source") or "the trial"
    names = trial.names
    plan = _plan(trial, cmap)
    sign, note = _data_sign(trial, plan, cmap)
    notes = [note] if note else []
    # column -> (new name, values)
    mapped = {c: (t, e.scale * (sign if e.auto_sign else 1.0) * np.asarray(trial[c]) + e.offset)
              for c, (t, e) in plan.items()}
    if cmap.hip_offset is not None and model is not None and "hip_r" in model.coordinates:
        cols = [_find(names, c) for c in ("pelvis_tx", "pelvis_ty", "pelvis_tilt")]
        if None not in cols:
            hx, hy = _hat_position(*(np.asarray(trial[c]) for c in cols), model, cmap.hip_offset)
            mapped[cols[0]], mapped[cols[1]] = ("torso_x", hx), ("torso_y", hy)
    clash = [(c, t) for c, (t, _) in mapped.items() if t in trial and t not in mapped]
    if clash:
        c, t = clash[0]
        raise TrialError(f"{cmap.where}: {c} -> {t!r}: {src} already has a column {t!r}; drop or rename it first")
    out: dict[str, np.ndarray] = {}
    units = {}
    for n in names:
        new, values = mapped.get(n, (n, np.asarray(trial[n])))
        out[new] = values
        if n in trial.units:
            units[new] = trial.units[n]
    filled = [z for z in cmap.zeros if z not in out and (model is None or z in model.coordinates)]
    for z in filled:
        out[z] = np.zeros(trial.n_frames)
    if filled:
        unused = [c for c in (f"mtp_angle_{z[-1]}" for z in filled) if _find(names, c) is not None]
        notes.append(f"{cmap.where}: {', '.join(filled)} set to 0 (the OpenSim models of this map have no mtp "
                     "coordinate or lock it" + (f"; {', '.join(unused)} not used)" if unused else ")"))
    if model is not None and require_coordinates:
        missing = [c for c in model.coordinate_order if c not in out]
        if missing:
            shown = ", ".join(f"{c} (from {cmap.origins[c]})" if c in cmap.origins else c for c in missing)
            raise TrialError(f"{src} mapped with {cmap.where} lacks {len(missing)} coordinate(s) of model "
                             f"{model.name!r}: {shown}; "
                             + map_hint(Trial(trial.time, out), missing).replace("to rename", "to rename more of"))
    meta = {**trial.meta, "channel_map": {"name": cmap.name, "where": cmap.where, "notes": tuple(notes),
                                          "renamed": {c: t for c, (t, _) in mapped.items()}}}
    return Trial(trial.time, out, units=units, meta=meta)


#: an OpenSim state path's last part -> the suffix of pinmsk's channel for that quantity
_STATE_SUFFIX = {"value": "", "speed": "_speed", "accel": "_acceleration", "acceleration": "_acceleration"}


def with_state_path_coordinates(trial: Trial, coordinates) -> Trial:
    """``trial`` with each of ``coordinates`` that has no channel of its own but an OpenSim 4 state
    path column (``/jointset/<joint>/<coord>/value``, ``.../speed``, ``.../accel``: Moco's and
    OpenSim's states files) given that column under pinmsk's name (``<coord>``, ``<coord>_speed``,
    ``<coord>_acceleration``); the path columns stay as they are.  Degrees were already converted by
    ``read_trial`` (it matches state paths too)."""
    wanted = set(coordinates)
    add = {}
    for col in trial.names:
        hit = state_path_coordinate(col)
        if hit is None or hit[0] not in wanted:
            continue
        name = hit[0] + _STATE_SUFFIX[hit[1]]
        if name not in trial.names and name not in add:
            add[name] = trial[col]
    return trial.with_channels(add) if add else trial


#: Words of a column name that say it is no coordinate (a load, a muscle signal, a rate).
_NOT_COORDINATE = {"speed", "moment", "force", "torque", "activation", "excitation", "emg", "acceleration", "grf",
                   "cop", "velocity", "power"}


def _words(name: str) -> list[str]:
    import re
    return [w for w in re.split(r"[^a-z0-9]+", name.lower()) if w]


def _guess_column(coordinate: str, columns) -> str | None:
    """The column most like ``coordinate``: sharing its first word (``Elbow angle`` for
    ``elbow_flexion``), else by :func:`close_matches`; columns naming a load or a rate are never guessed."""
    import difflib
    free = [n for n in columns if not (set(_words(n)) & _NOT_COORDINATE)
            and parse_ground_reaction(n) is None]
    words = _words(coordinate)
    if not words:
        return None
    norm = "_".join(words)
    sharing = [n for n in free if words[0] in _words(n)]
    if sharing:
        return max(sharing, key=lambda n: difflib.SequenceMatcher(None, norm, "_".join(_words(n))).ratio())
    found = close_matches(coordinate, free, n=1)
    return found[0] if found else None


def map_hint(trial: Trial, missing) -> str:
    """How to give ``trial`` the ``missing`` coordinates with a map file: one line naming ``--map`` and
    a map to start from, as a one-line TOML table (a guessed column for each coordinate, from the
    trial's names, or ``YOUR_COLUMN``)."""
    taken: set[str] = set()
    pairs = []
    for c in missing:
        guess = _guess_column(c, [n for n in trial.names if n not in taken])
        if guess is not None:
            taken.add(guess)
        key = guess or f"YOUR_{c}_COLUMN"
        pairs.append(f'{key} = "{c}"' if key.replace("_", "").isalnum() else f'"{key}" = "{c}"')
    shown = ", ".join(pairs[:6]) + (", ..." if len(pairs) > 6 else "")
    return ("to rename the file's columns, pass --map MAP.toml (command line) or cmap='MAP.toml' (Python) with "
            f"MAP.toml holding: rename = {{{shown}}} (add [scale] / [offset] for a sign or a zero; "
            "docs/tutorials/own_csv.md)")


def read_mapped(path, *, model=None, cmap=None, strict: bool = True, require_coordinates: bool = True,
                time_unit: str | None = None, in_degrees: bool | None = None) -> Trial:
    """:func:`pinmsk.io.read_trial`, then :func:`apply_channel_map` (what the CLI's ``--map`` does).

    ``time_unit`` and ``in_degrees`` are :func:`~pinmsk.io.read_trial`'s (``--time-unit``, ``--degrees``).

    With ``model``, the angles read from degrees are the model's rotational coordinates and
    the map's sources that become them.  Without ``cmap``, a trial that lacks the model's
    coordinates but looks like a built-in map's input is an error naming that map.
    """
    cmap = None if cmap is None else load_channel_map(cmap)
    angular = None
    if model is not None:
        angular = set(model.rotational_coordinates) | (cmap.angular_sources(model) if cmap else set())
    trial = read_trial(path, angular=angular, strict=strict, time_unit=time_unit, in_degrees=in_degrees)
    if cmap is not None:
        return apply_channel_map(trial, cmap, model=model, require_coordinates=require_coordinates)
    if model is not None:
        # an exact OpenSim import's own coordinates too (a patella angle that drives only dependent joints)
        full = getattr(model, "meta", {}).get("coordinate_map")
        trial = with_state_path_coordinates(
            trial, tuple(model.coordinate_order) + tuple(getattr(full, "osim_coordinates", ())))
    name = suggest_map(trial, model) if model is not None and require_coordinates else None
    if name:
        missing = [c for c in model.coordinate_order if c not in trial]
        raise TrialError(f"{path}: no column for coordinate(s) {', '.join(missing)} of model {model.name!r}, "
                         f"but the columns look like OpenSim's: pass --map {name} (command line) or "
                         f"cmap={name!r} (or a map file)")
    return trial
