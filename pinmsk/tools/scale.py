"""OpenSim's ScaleTool: scale a generic ``.osim`` to a subject and place its markers on a static trial.

Three steps, as ``ScaleTool::run`` takes them (``OpenSim/Tools/ScaleTool.cpp``):

1. *GenericModelMaker*: read the model and merge the marker set file into it (a marker of the same name
   is replaced).
2. *ModelScaler*: the scale factors of the measurements and manual scales, in ``scaling_order``, then
   the scaled model (:mod:`pinmsk.opensim.scaling`); written with the scale set.
3. *MarkerPlacer* (:func:`place_markers`): the markers not in the static trial are removed; the static
   pose is solved by :class:`pinmsk.ik.InverseKinematics` on the marker positions averaged over the time
   range (the rows inside it, as ``TimeSeriesTable::averageRow``) with the IK task set's marker weights
   (a marker without an applied task weighs 1, as OpenSim's ``MarkersReference`` weighs it) and its
   coordinate tasks (``default_value``, ``manual_value``, ``from_file``), weighted as Simbody's
   assembler weighs them against the markers (a coordinate task's weight times the sum of the marker
   weights); locked coordinates stay at their default values.  Then every model marker that is not
   ``fixed`` is moved, in its own frame, onto its measured position averaged as
   ``MarkerData::averageFrames`` averages it (from the last frame at or before the start to the first
   at or after the end, gaps skipped).  The pose is written as OpenSim's states file
   (``/jointset/<joint>/<coordinate>/value`` and ``/speed``, radians and metres).

:func:`run` runs a ScaleTool setup file; :func:`scale_subject` is the command line's version (a model,
a static trial, the subject's mass, and a measurement set or the default measurements of
:func:`default_measurements`).
"""
from __future__ import annotations

import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import PinmskError
from ..io.opensim_setup import SetupError, read_setup
from ..io.output_files import output_transaction
from ..io.tables import read_trial, write_trial
from ..io.trc import read_trc
from ..opensim import scaling as sc
from ..trial import Trial, marker_array, marker_names

__all__ = ["run", "scale_subject", "place_markers", "default_measurements", "read_measurement_file",
           "MarkerPlacement"]


# --------------------------------------------------------------------------------------------
# markers of a static trial
# --------------------------------------------------------------------------------------------
def _static(path) -> Trial:
    return read_trc(path, max_gap=0, warn=False)


def _markers(trial: Trial) -> dict[str, np.ndarray]:
    names = marker_names(trial)
    X = marker_array(trial, names)
    return {n: X[:, i] for i, n in enumerate(names)}


def _clip(trial: Trial, time_range) -> tuple[float, float]:
    t0, t1 = float(time_range[0]), float(time_range[1])
    return max(t0, float(trial.time[0])), min(t1, float(trial.time[-1]))


# --------------------------------------------------------------------------------------------
# marker placement
# --------------------------------------------------------------------------------------------
@dataclass
class MarkerPlacement:
    """The result of :func:`place_markers`: the model tree with its markers moved, the static pose
    ``{coordinate: value}`` at ``time``, the names of the markers moved and removed, the IK fit, and the
    per-marker distance between model and measured markers at the pose before moving them (m)."""

    tree: object
    pose: dict
    time: float
    moved: list
    removed: list
    ik: object
    marker_errors: dict

    def summary(self) -> str:
        """The static pose's marker errors before the markers were moved (OpenSim's placement log)."""
        e = np.array([v for v in self.marker_errors.values() if np.isfinite(v)])
        worst = max(self.marker_errors, key=lambda k: self.marker_errors[k]) if e.size else "-"
        return (f"static pose at t = {self.time:g} s: marker error RMS {np.sqrt(np.mean(e ** 2)) if e.size else 0:.6f} m, "
                f"max {e.max() if e.size else 0:.6f} m ({worst}); {len(self.moved)} markers moved, "
                f"{len(self.removed)} removed (not in the trial)")

    def pose_trial(self, root=None) -> Trial:
        """The pose as OpenSim's states table (one row): ``/jointset/<joint>/<coordinate>/value`` and
        ``/speed`` (zero)."""
        paths = sc.coordinate_paths(self.tree if root is None else root)
        ch = {}
        for c, v in self.pose.items():
            ch[f"{paths[c]}/value"] = np.array([v])
            ch[f"{paths[c]}/speed"] = np.array([0.0])
        return Trial(np.array([self.time]), ch, meta={"name": "static pose"})


def place_markers(root, static: Trial, *, time_range, marker_weights: Mapping[str, float] | None = None,
                  coordinate_tasks: Mapping[str, tuple] | None = None, coordinates: Trial | None = None,
                  max_marker_movement: float = -1.0, move: bool = True) -> MarkerPlacement:
    """OpenSim's MarkerPlacer on a model tree (:func:`pinmsk.opensim.scaling.read_osim_tree`).

    ``marker_weights``: ``{marker: weight}`` of the applied IK marker tasks (others weigh 1);
    ``coordinate_tasks``: ``{coordinate: (value, weight)}`` with ``value`` a number, ``None`` (the
    coordinate's default value) or ``"from_file"`` (``coordinates``' value at the start of the time
    range, linearly interpolated: OpenSim fits a GCV spline, which passes within its smoothing of the
    samples).  ``max_marker_movement`` (> 0, in the marker file's units, as OpenSim compares it before
    converting them): a marker that moves more than that along an axis over the averaged frames is
    reported with a warning, as OpenSim reports it.  See the module docstring.
    """
    from ..ik import InverseKinematics, MarkerSet
    from ..markers import ModelMarker
    from ..model import import_osim

    t0, t1 = _clip(static, time_range)
    if t1 < t0:
        raise PinmskError(f"marker placement: time range {time_range[0]:g} to {time_range[1]:g} s is outside "
                          f"the static trial ({static.time[0]:g} to {static.time[-1]:g} s)")
    markers = _markers(static)
    tree, removed = sc.delete_unused_markers(root, markers)
    in_range = (static.time >= t0) & (static.time <= t1)
    if not in_range.any():
        raise PinmskError(f"marker placement: no frame of the static trial lies in {t0:g} to {t1:g} s")
    ik_target = {n: X[in_range].mean(axis=0) for n, X in markers.items()}
    i0, i1 = sc.frame_range(static.time, t0, t1)
    if max_marker_movement is not None and max_marker_movement > 0:
        from ..io.trc import UNIT_SCALE
        unit = str(static.meta.get("units") or "m")
        per_unit = UNIT_SCALE.get(unit.lower(), 1.0)
        for n, X in markers.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                span = float(np.nanmax(np.nanmax(X[i0:i1 + 1], axis=0) - np.nanmin(X[i0:i1 + 1], axis=0)))
            span /= per_unit
            if span > max_marker_movement:
                warnings.warn(f"marker placement: marker {n} moves {span:.6g} {unit} over {static.time[i0]:g} to "
                              f"{static.time[i1]:g} s (max_marker_movement {max_marker_movement:g} {unit})",
                              sc.ScaleWarning, stacklevel=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        move_target = {n: np.nanmean(X[i0:i1 + 1], axis=0) for n, X in markers.items()}

    with tempfile.TemporaryDirectory() as tmp:
        path = sc.write_osim_tree(tree, Path(tmp) / "model.osim")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model, _ = import_osim(path, hooks=(), locked="weld")     # OpenSim holds locked coordinates
    weights = dict(marker_weights or {})
    mm = [ModelMarker(d["name"], d["body"], tuple(d["position"]), float(weights.get(d["name"], 1.0)))
          for d in model.meta.get("markers") or ()]
    mm = [m for m in mm if m.weight > 0]
    if not mm:
        raise PinmskError("marker placement: no model marker with a weight is in the static trial")
    mset = MarkerSet(tuple(mm), {}, model.name, "model")
    ch = {}
    for n in mset.names:
        for a, k in zip("xyz", range(3)):
            ch[f"{n}_{a}"] = np.array([ik_target[n][k]])
    target_trial = Trial(np.array([t0]), ch, meta={"markers": list(mset.names)})
    defaults = sc.coordinate_defaults(tree)
    # Simbody's assembler minimises sum(w_m r_m^2) / (2 sum w_m) + sum w_c (q_c - v_c)^2 / 2
    # (AssemblyCondition_Markers, _QValue): InverseKinematics's coordinate tasks carry that sum w_m
    tasks = {}
    for c, (v, w) in (coordinate_tasks or {}).items():
        if c not in defaults:
            raise PinmskError(f"marker placement: coordinate task '{c}' names no coordinate of the model")
        if isinstance(v, str) and v == "from_file":
            if coordinates is None or c not in coordinates:
                raise PinmskError(f"marker placement: coordinate task '{c}' takes its value from the coordinate "
                                  "file, which " + ("is not given" if coordinates is None else "has no such column"))
            v = float(np.interp(t0, coordinates.time, coordinates[c]))
        tasks[c] = (float(w), defaults[c] if v is None else float(v))
    ik = InverseKinematics(markers=mset, axes="xyz", q0=dict(defaults), coordinate_tasks=tasks,
                           max_iter=200, tol=1e-12).fit(model, target_trial)
    pose = {c: float(ik.result_[c][0]) for c in defaults if c in ik.result_}
    for c, v in defaults.items():
        pose.setdefault(c, v)
    errors = {m: float(e) for m, e in zip(mset.names, ik.marker_error_[0])}
    moved = []
    if move:
        tree, moved = sc.move_markers(tree, pose, move_target)
    return MarkerPlacement(tree, pose, t0, moved, removed, ik, errors)


# --------------------------------------------------------------------------------------------
# measurements without a setup
# --------------------------------------------------------------------------------------------
def default_measurements(root, measured: Sequence[str]) -> tuple[list, list]:
    """The default scaling of the command line: each body carrying two or more markers that are in the
    trial is scaled uniformly by its own measurement (all pairs of its markers); every other body by the
    mean of those bodies' factors.  Returns ``(measurements, bodies left for the mean)``."""
    measured = set(measured)
    on = {}
    for m in sc.model_markers(root):
        if m["name"] in measured:
            on.setdefault(m["frame"].rstrip("/").rsplit("/", 1)[-1], []).append(m["name"])
    bodies = [b for b in _body_names(root)]
    out = []
    for b in bodies:
        names = on.get(b, [])
        if len(names) >= 2:
            pairs = [(names[i], names[j]) for i in range(len(names)) for j in range(i + 1, len(names))]
            out.append(sc.Measurement(b, tuple(pairs), (sc.BodyScale(b),)))
    if not out:
        raise PinmskError("default scaling: no body carries two markers that are in the static trial; "
                          "give a measurement set (--setup-measurements)")
    rest = [b for b in bodies if b not in {m.name for m in out}]
    return out, rest


def _body_names(root) -> list[str]:
    return [b.get("name") for b in root.iter("Body")]


def read_measurement_file(path) -> list:
    """The measurements of a ``<MeasurementSet>`` file, or of the ModelScaler of a ScaleTool setup."""
    setup = read_setup(path)
    node = setup.node
    if setup.tool == "ScaleTool":
        ms = node.child("ModelScaler")
        if ms is None:
            raise SetupError(f"{setup.path}: the ScaleTool has no <ModelScaler> with a <MeasurementSet>")
        nodes = ms.objects("MeasurementSet", "Measurement")
    elif setup.tool == "MeasurementSet":
        nodes = node.objects("objects", "Measurement")
    else:
        raise SetupError(f"{setup.path}: holds a <{setup.tool}>, not a <MeasurementSet> or a ScaleTool setup")
    if not nodes:
        raise SetupError(f"{setup.path}: the measurement set is empty")
    return [sc.measurement_from_node(n) for n in nodes]


def scale_subject(model, static, *, mass: float, output, measurements=None, marker_set=None,
                  time_range=None, preserve_mass_distribution: bool = True,
                  place: bool = False, report=None) -> list[Path]:
    """Scale ``model`` (.osim) to the static trial ``static`` (.trc) and a subject of ``mass`` kg; write
    ``output`` (.osim) and ``<output stem>_scale_set.xml`` beside it (with ``place``, the markers are also
    placed and ``<output stem>_static_pose.mot`` is written).  ``measurements``: a measurement set file
    (default: :func:`default_measurements`); ``marker_set``: a marker set file merged into the model;
    ``time_range``: ``(start, end)`` s (default: the whole trial); ``report``: a callable given the
    factors' and the placement's summaries (e.g. ``print``).  Returns the paths written."""
    output = Path(output)
    root = sc.read_osim_tree(model)
    if marker_set is not None:
        root = sc.with_markers(root, sc.read_marker_set(marker_set))
    trial = _static(static)
    markers = _markers(trial)
    tr = (float(trial.time[0]), float(trial.time[-1])) if time_range is None else tuple(map(float, time_range))
    kw = dict(markers=markers, time=trial.time, time_range=tr, source=str(static))
    if measurements is not None:
        ms = read_measurement_file(measurements)
        factors = sc.scale_factors(root, measurements=ms, order=("measurements",), **kw)
    else:
        ms, rest = default_measurements(root, list(markers))
        first = sc.scale_factors(root, measurements=ms, order=("measurements",), **kw)
        mean = float(np.mean([m.factor for m in first.measurements]))
        manual = [sc.ManualScale(b, (mean, mean, mean)) for b in rest]
        factors = sc.scale_factors(root, measurements=ms, manual=manual,
                                   order=("measurements", "manualScale"), **kw)
    scaled = sc.scale_model(root, factors, mass=mass, preserve_mass_distribution=preserve_mass_distribution)
    placement = place_markers(scaled, trial, time_range=tr) if place else None
    if report is not None:
        report(factors.summary())
        if placement is not None:
            report(placement.summary())
    stem = output.with_suffix("")
    written = []
    with output_transaction():
        written.append(sc.write_osim_tree(placement.tree if placement else scaled, output))
        written.append(sc.write_scale_set(factors, Path(f"{stem}_scale_set.xml")))
        if placement is not None:
            written.append(write_trial(placement.pose_trial(), Path(f"{stem}_static_pose.mot"), precision=17))
    return written


# --------------------------------------------------------------------------------------------
# the setup runner
# --------------------------------------------------------------------------------------------
def run(setup, *, results_dir=None) -> list[Path]:
    """Run an OpenSim ScaleTool setup (a :class:`pinmsk.io.opensim_setup.SetupFile` whose ``tool`` is
    ``"ScaleTool"``); outputs are written where the setup names them (relative to its folder), or in
    ``results_dir``.  Every property that would change the result and that pinmsk does not read is
    refused by name.  Returns the paths written."""
    if setup.tool != "ScaleTool":
        raise SetupError(f"{setup.path}: a {setup.tool} setup, not a ScaleTool setup")
    node = setup.node
    mass = node.number("mass", -1.0)
    node.ignore("height", "age", "notes")
    out_dir = None if results_dir is None else Path(results_dir)

    def out(n, prop):
        p = n.file(prop, must_exist=False)
        if p is None:
            return None
        return p if out_dir is None else out_dir / p.name

    gmm = node.child("GenericModelMaker")
    if gmm is None or not gmm.has("model_file"):
        raise node.error("GenericModelMaker", "names no <model_file>: there is no model to scale")
    model_file = gmm.file("model_file")
    marker_set_file = gmm.file("marker_set_file")
    gmm.finish()

    scaler = node.child("ModelScaler")
    placer = node.child("MarkerPlacer")
    plan = {}
    if scaler is not None:
        plan["scale"] = scaler.flag("apply", True)
        order = scaler.words("scaling_order")
        for step in order:
            if step not in sc.SCALING_STEPS:
                raise scaler.error("scaling_order", f"unknown step '{step}' (the steps are "
                                                    f"{', '.join(sc.SCALING_STEPS)})")
        measurements = [sc.measurement_from_node(n) for n in scaler.objects("MeasurementSet", "Measurement")]
        manual = [sc.manual_scale_from_node(n) for n in scaler.objects("ScaleSet", "Scale")]
        scale_markers = scaler.file("marker_file")
        scale_range = scaler.numbers("time_range", 2, default=[-1.0, -1.0])
        preserve = scaler.flag("preserve_mass_distribution", False)
        scaled_out = out(scaler, "output_model_file")
        scale_set_out = out(scaler, "output_scale_file")
        scaler.finish()
    if placer is not None:
        plan["place"] = placer.flag("apply", True)
        weights, coord_tasks = {}, {}
        for t in placer.objects("IKTaskSet"):
            apply = t.flag("apply", True)
            w = t.number("weight", 1.0)
            if t.tag == "IKMarkerTask":
                if apply:
                    weights[t.name] = w
            elif t.tag == "IKCoordinateTask":
                kind = t.text("value_type", "default_value")
                value = t.number("value", 0.0)
                if kind not in ("default_value", "manual_value", "from_file"):
                    raise t.error("value_type", f"'{kind}' is not default_value, manual_value or from_file")
                if apply:
                    coord_tasks[t.name] = ({"default_value": None, "from_file": "from_file"}.get(kind, value), w)
            else:
                raise t.error(None, f"<{t.tag}> is not an IKMarkerTask or IKCoordinateTask")
            t.finish()
        place_markers_file = placer.file("marker_file")
        coordinate_file = placer.file("coordinate_file")
        place_range = placer.numbers("time_range", 2)
        motion_out = out(placer, "output_motion_file")
        placed_out = out(placer, "output_model_file")
        markers_out = out(placer, "output_marker_file")
        max_movement = placer.number("max_marker_movement", -1.0)
        placer.finish()
    node.finish()

    root = sc.read_osim_tree(model_file)
    if marker_set_file is not None:
        root = sc.with_markers(root, sc.read_marker_set(marker_set_file))
    root.find("Model").set("name", setup.name or root.find("Model").get("name", ""))
    factors = None
    if plan.get("scale"):
        if scale_markers is None and any(m.apply for m in measurements) and "measurements" in order:
            raise scaler.error("marker_file", "measurements are applied but no marker file is named")
        trial = _static(scale_markers) if scale_markers is not None else None
        factors = sc.scale_factors(root, measurements=measurements, manual=manual, order=order,
                                   markers=None if trial is None else _markers(trial),
                                   time=None if trial is None else trial.time,
                                   time_range=tuple(scale_range), source=str(scale_markers),
                                   unknown_bodies="warn")
        root = sc.scale_model(root, factors, mass=mass, preserve_mass_distribution=preserve)
    placement = None
    if plan.get("place"):
        if place_markers_file is None or place_range is None:
            raise placer.error("marker_file" if place_markers_file is None else "time_range",
                               "marker placement needs a marker file and a time range")
        coords = None
        if coordinate_file is not None:
            coords = read_trial(coordinate_file, angular=sc.rotational_coordinates(root), time_unit="s")
            coords = Trial(coords.time, {sc.state_coordinate(k): coords[k] for k in coords.names},
                           meta=dict(coords.meta))
        elif any(v == "from_file" for v, _ in coord_tasks.values()):
            raise placer.error("coordinate_file", "coordinate tasks take values from_file but no coordinate "
                                                  "file is named")
        placement = place_markers(root, _static(place_markers_file), time_range=place_range,
                                  marker_weights=weights, coordinate_tasks=coord_tasks, coordinates=coords,
                                  max_marker_movement=max_movement)
    written = []
    with output_transaction():
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
        if factors is not None:
            if scaled_out is not None:
                written.append(sc.write_osim_tree(root, scaled_out))
            if scale_set_out is not None:
                written.append(sc.write_scale_set(factors, scale_set_out))
        if placement is not None:
            if placed_out is not None:
                written.append(sc.write_osim_tree(placement.tree, placed_out))
            if markers_out is not None:
                written.append(sc.write_marker_set(placement.tree, markers_out))
            if motion_out is not None:
                written.append(write_trial(placement.pose_trial(), motion_out, precision=17))
    return written
