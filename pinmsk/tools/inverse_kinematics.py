"""OpenSim's InverseKinematicsTool: a marker file -> the model's coordinates (.mot) and marker errors (.sto).

The problem is OpenSim's (OpenSim/Tools/InverseKinematicsTool.cpp, Simulation/InverseKinematicsSolver.cpp
on Simbody's Assembler).  For each frame k of the marker file within the time range (first and last
frames: those nearest the range's ends) the coordinates minimise

    sum_m w_m |x_m(q) - y_m[k]|^2  +  W_k sum_c w_c (q_c - t_c[k])^2,      W_k = sum_m w_m

over the markers of the applied IKMarkerTasks measured in that frame (a NaN marker drops out) and
the applied IKCoordinateTasks; the second sum carries ``W_k`` because Simbody's marker goal is
divided by the total marker weight (AssemblyCondition_Markers.cpp) while a coordinate goal is not.
Locked coordinates stay at their defaults (their tasks are dropped, as OpenSim drops them), clamped
ones within their ranges; coordinate coupler constraints are enforced exactly.  The solver is
:class:`pinmsk.ik.InverseKinematics` (batched Levenberg-Marquardt), started from the model's
default pose.

Outputs as OpenSim writes them: the motion (``Coordinates``, ``inDegrees=yes``, ``time`` then the
model's coordinates in OpenSim's order, rotations in degrees, translations in m) and the marker
errors per frame (``time, total_squared_error, marker_error_RMS, marker_error_max``, m^2 and m,
unweighted, the RMS over the markers in use).

:func:`inverse_kinematics` runs the problem on a model and a marker Trial; :func:`write_outputs`
writes its files; :func:`run` runs an ``InverseKinematicsTool`` setup file.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ModelError, PinmskError, TrialError
from ..ik import InverseKinematics
from ..io.ik_tasks import ik_tasks_from_node
from ..io.opensim_setup import SetupError, SetupFile
from ..io.output_files import output_folder, output_transaction
from ..io.tables import read_trial, write_trial
from ..io.trc import read_trc
from ..kinematics import coordinate_map
from ..markers import MarkerSet, ModelMarker, model_marker_set
from ..trial import Trial, marker_names

__all__ = ["IKOutcome", "inverse_kinematics", "write_outputs", "run", "frame_range", "rotational_coordinates"]

#: Column names of OpenSim's marker error file (InverseKinematicsTool::run).
ERROR_COLUMNS = ("total_squared_error", "marker_error_RMS", "marker_error_max")


@dataclass
class IKOutcome:
    """``motion`` (Trial of the coordinates, rad and m, OpenSim's order), ``errors`` (Trial of
    :data:`ERROR_COLUMNS`), ``fitter`` (the fitted :class:`~pinmsk.ik.InverseKinematics`),
    ``rotational`` (the coordinates written in degrees)."""

    motion: Trial
    errors: Trial
    fitter: InverseKinematics
    rotational: tuple


def rotational_coordinates(model) -> tuple:
    """The coordinates an OpenSim motion file holds in degrees: an import's Rotational ones, else the
    model's revolute joints."""
    types = model.meta.get("osim_motion_types")
    if types:
        return tuple(c for c, t in types.items() if str(t).lower() == "rotational")
    return tuple(model.rotational_coordinates)


def frame_range(time: np.ndarray, time_range, where: str = "") -> slice:
    """The frames OpenSim's IK solves: from the one nearest the range's start to the one nearest its end,
    the range first cut to the data's."""
    t = np.asarray(time, dtype=float)
    if time_range is None:
        return slice(0, t.size)
    t0, t1 = max(float(time_range[0]), t[0]), min(float(time_range[1]), t[-1])
    if t1 < t0:
        raise TrialError(f"{where}time range {time_range[0]:g} to {time_range[1]:g} s: ends before it starts "
                         f"within the marker data ({t[0]:g} to {t[-1]:g} s)")
    i0 = int(np.argmin(np.abs(t - t0)))
    i1 = int(np.argmin(np.abs(t - t1)))
    return slice(i0, i1 + 1)


def _close(name, names) -> str:
    hint = difflib.get_close_matches(str(name), list(names), n=3)
    return f"; did you mean {', '.join(map(repr, hint))}?" if hint else ""


def _coordinate_targets(tasks, model, coordinates, defaults, coordinate_trial, time, where):
    """``{coordinate: (weight, target)}`` of the applied coordinate tasks (targets in rad or m)."""
    cmap = coordinate_map(model)
    locked = set(cmap.welded) if cmap is not None else set(model.meta.get("locked_coordinates") or ())
    out = {}
    for t in tasks:
        if t.kind != "coordinate" or not t.apply:
            continue
        if t.name not in coordinates and t.name not in locked:
            raise ModelError(f"{t.where}: coordinate task '{t.name}': model '{model.name}' has no such "
                             f"coordinate{_close(t.name, coordinates)}")
        if t.name in locked:                # OpenSim locks it at its value and drops the task
            continue
        if t.value_type == "manual_value":
            target = t.value
        elif t.value_type == "default_value":
            target = defaults.get(t.name, 0.0)
        else:
            if coordinate_trial is None:
                raise PinmskError(f"{t.where}: coordinate task '{t.name}' takes its value from_file, and "
                                  f"{where}no coordinate file is given")
            if t.name not in coordinate_trial:
                raise TrialError(f"{t.where}: coordinate task '{t.name}': the coordinate file "
                                 f"{coordinate_trial.meta.get('source', '')} has no column '{t.name}'"
                                 f"{_close(t.name, coordinate_trial.names)}")
            target = _spline(coordinate_trial.time, coordinate_trial[t.name], time)
        out[t.name] = (t.weight, target)
    return out


def _spline(t, y, at):
    """The coordinate file's values at the marker frames: OpenSim fits a quintic GCV spline
    (GCVSplineSet(5, ...)); here the interpolating quintic spline (the same where the file is sampled
    at the marker times)."""
    from scipy.interpolate import make_interp_spline

    t = np.asarray(t, dtype=float)
    k = min(5, t.size - 1)
    if k < 1:
        return np.full(np.shape(at), float(y[0]))
    if k % 2 == 0:
        k -= 1
    return make_interp_spline(t, np.asarray(y, dtype=float), k=k)(np.clip(at, t[0], t[-1]))


def inverse_kinematics(model, markers: Trial, *, tasks=None, time_range=None, coordinate_trial: Trial | None = None,
                       accuracy: float = 1e-5, progress=None, where: str = "") -> IKOutcome:
    """OpenSim's IK of ``markers`` (a Trial of ``<marker>_{x,y,z}``, m) on ``model``.

    ``tasks``: :class:`~pinmsk.io.ik_tasks.IKTask` s; without an applied marker task (None, or none
    applied) every model marker in the trial is tracked with weight 1, as OpenSim does; an applied
    marker task must name a model marker and a marker of the trial.  ``time_range`` (s),
    ``coordinate_trial`` (targets of ``from_file`` coordinate tasks, rad/m), ``accuracy`` (the step
    tolerance is a tenth of it, rad or m).  ``where`` prefixes messages (the setup file).
    """
    mset = model_marker_set(model)
    in_trial = set(marker_names(markers))
    marker_tasks = [t for t in (tasks or ()) if t.kind == "marker" and t.apply]
    if not marker_tasks:
        # no applied marker task: OpenSim's MarkersReference then tracks every marker of the file the
        # model has, at its default weight 1
        used = [m for m in mset.markers if m.name in in_trial]
        if not used:
            raise TrialError(f"{markers.meta.get('source', 'the marker trial')}: none of model '{model.name}''s "
                             f"markers ({', '.join(mset.names[:8])}{' ...' if len(mset) > 8 else ''}) is in it "
                             f"(markers: {', '.join(sorted(in_trial)[:8])})")
    else:
        by_name = {m.name: m for m in mset.markers}
        used = []
        for t in marker_tasks:
            if t.name not in by_name:
                raise ModelError(f"{t.where}: marker task '{t.name}': model '{model.name}' has no such marker"
                                 f"{_close(t.name, by_name)}")
            if t.name not in in_trial:
                raise TrialError(f"{t.where}: marker task '{t.name}': the marker file "
                                 f"{markers.meta.get('source', '')} has no such marker{_close(t.name, in_trial)}")
            m = by_name[t.name]
            used.append(ModelMarker(m.name, m.body, m.position, t.weight))
    # OpenSim's frames and times are the marker file's Time column as written (pinmsk's reader rebuilds
    # rounded times from the rate; the file's are kept in meta["file_time"])
    file_time = markers.meta.get("file_time")
    file_time = np.asarray(markers.time if file_time is None else file_time, dtype=float)
    frames = frame_range(file_time, time_range, where)
    trial = _cut(markers, frames)
    cmap = coordinate_map(model)
    if cmap is not None:
        coordinates = tuple(c for c in cmap.osim_coordinates if c not in cmap.welded)
        defaults = {c: float(v) for c, v in cmap.defaults.items()}
        order = tuple(cmap.osim_coordinates)
    else:
        coordinates = tuple(model.coordinate_order)
        defaults = {}
        order = coordinates
    rotational = rotational_coordinates(model)
    targets = _coordinate_targets(tasks or (), model, coordinates, defaults, coordinate_trial, file_time[frames],
                                  where)
    bounds = {}
    pm = model.pin
    for c in model.meta.get("clamped_coordinates") or ():
        if c in coordinates and pm.existJointName(c):
            iq = pm.idx_qs[pm.getJointId(c)]
            bounds[c] = (float(pm.lowerPositionLimit[iq]), float(pm.upperPositionLimit[iq]))
    ik = InverseKinematics(markers=MarkerSet(tuple(used), {}, model.name, mset.source), axes="xyz",
                           q0={c: v for c, v in defaults.items() if c in coordinates} or None,
                           coordinate_tasks=targets or None, bounds=bounds or None,
                           tol=accuracy)
    ik.fit(model, trial, progress=progress)
    res = ik.result_
    times = file_time[frames]
    # every coordinate of the model, as OpenSim's Kinematics reporter writes them: a locked one at its value
    held = {} if cmap is None else cmap.welded
    motion = Trial(times, {c: res[c] if c in res else np.full(times.size, float(held.get(c, 0.0))) for c in order},
                   meta={"name": "Coordinates"})
    err = ik.marker_error_
    sq = np.where(np.isfinite(err), err ** 2, 0.0)
    total = sq.sum(axis=1)
    errors = Trial(times, {"total_squared_error": total,
                                "marker_error_RMS": np.sqrt(total / err.shape[1]),
                                "marker_error_max": np.sqrt(sq.max(axis=1))},
                   meta={"name": "Model Marker Errors from IK"})
    return IKOutcome(motion, errors, ik, rotational)


def _cut(trial: Trial, frames: slice) -> Trial:
    if frames == slice(0, trial.n_frames):
        return trial
    return Trial.from_array(trial.time[frames], trial.names, trial.values[frames], meta=dict(trial.meta))


def write_outputs(outcome: IKOutcome, motion_path, errors_path=None, *, precision=None) -> list[Path]:
    """Write the motion (degrees for rotations, as OpenSim's IK) and, if ``errors_path``, the marker errors."""
    out = [write_trial(outcome.motion, motion_path, in_degrees=True, angular=outcome.rotational,
                       precision=precision)]
    if errors_path is not None:
        out.append(write_trial(outcome.errors, errors_path, precision=precision))
    return out


def read_coordinates(path, model) -> Trial:
    """A coordinate file (.mot/.sto) in rad and m (degrees converted where its header says so)."""
    return read_trial(path, angular=rotational_coordinates(model))


# -- the setup runner ------------------------------------------------------------------------------

def run(setup: SetupFile, *, results_dir=None) -> list[Path]:
    """Run an ``InverseKinematicsTool`` setup; returns the files written.

    Reads model_file, marker_file, coordinate_file, time_range, IKTaskSet (inline or
    ``file=``), output_motion_file, results_directory, report_errors, report_marker_locations
    (true is refused), constraint_weight, accuracy; any other property with a value is refused by
    name.  Paths resolve against the setup's folder.  As OpenSim does, the motion goes to
    ``output_motion_file`` and the marker errors to ``<results_directory>/<tool name>_ik_marker_errors.sto``;
    ``results_dir`` puts both in that folder instead.
    """
    from ..model import load_model

    if setup.tool != "InverseKinematicsTool":
        raise SetupError(f"{setup.path}: a <{setup.tool}> setup, not an <InverseKinematicsTool>")
    node = setup.node
    where = f"{setup.path}: "
    model_file = node.file("model_file")
    if model_file is None:
        raise node.error("model_file", "names no model (pinmsk runs a setup's own model file)")
    marker_file = node.file("marker_file")
    if marker_file is None:
        raise node.error("marker_file", "names no marker file (.trc)")
    coordinate_file = node.file("coordinate_file")
    time_range = node.numbers("time_range", 2)
    tasks = ik_tasks_from_node(node)
    output = node.text("output_motion_file")
    if output == "Unassigned":          # OpenSim writes no motion then
        output = None
    results = node.text("results_directory")
    report_errors = node.flag("report_errors", True)
    if node.flag("report_marker_locations", False):
        raise node.error("report_marker_locations", "model marker locations are not written by pinmsk; set it false")
    weight_text = node.text("constraint_weight")
    constraint_weight = math.inf
    if weight_text is not None and weight_text.lower() not in ("inf", "infinity", "unassigned"):
        constraint_weight = node.number("constraint_weight")
    accuracy = node.number("accuracy", 1e-5)
    if not accuracy > 0:
        raise node.error("accuracy", f"must be > 0, got {accuracy:g}")
    node.finish()

    model = load_model(model_file)
    cmap = coordinate_map(model)
    if math.isfinite(constraint_weight) and cmap is not None and cmap.couplers:
        raise node.error("constraint_weight", f"{constraint_weight:g} makes the model's {len(cmap.couplers)} "
                                              "coordinate coupler constraint(s) soft; pinmsk enforces them "
                                              "exactly: set it to Inf")
    markers = read_trc(marker_file, max_gap=0, warn=False)
    coords = read_coordinates(coordinate_file, model) if coordinate_file is not None else None
    from ..presentation.progress import Progress
    frames = frame_range(np.asarray(markers.meta.get("file_time", markers.time)), time_range, where)
    with Progress(frames.stop - frames.start, "IK", unit="frames") as bar:    # drawn on a terminal, after 2 s
        outcome = inverse_kinematics(model, markers, tasks=tasks, time_range=time_range, coordinate_trial=coords,
                                     accuracy=accuracy, progress=bar, where=where)
    if results_dir is not None:
        folder = Path(results_dir)
        motion_path = folder / Path(output).name if output else None
    else:
        folder = setup.folder / (results or ".")
        motion_path = (setup.folder / output) if output else None
    errors_path = folder / f"{setup.name}_ik_marker_errors.sto" if report_errors else None
    written = []
    with output_transaction():
        if errors_path is not None or results_dir is not None:
            output_folder(folder)
        if motion_path is not None:
            written += write_outputs(outcome, motion_path)
        if errors_path is not None:
            written.append(write_trial(outcome.errors, errors_path))
    return written


# -- the command line (``pinmsk ik``) --------------------------------------------------------------

def errors_path_for(output) -> Path:
    """OpenSim's name of the marker error file beside a motion file: ``<stem>_ik_marker_errors.sto``."""
    output = Path(output)
    return output.with_name(f"{output.stem}_ik_marker_errors.sto")


def command(args, progress_factory) -> list[Path]:
    """``pinmsk ik MODEL TRC -o q.mot [--tasks TASKS.xml] [--time START END] [--marker-errors FILE]``.

    ``progress_factory(total, label, unit)`` makes the progress line (the CLI's)."""
    from ..io.output_files import check_output_file
    from ..io.ik_tasks import read_ik_tasks
    from ..model import load_model

    errors_path = Path(args.marker_errors) if args.marker_errors else errors_path_for(args.output)
    check_output_file(errors_path)
    tasks = read_ik_tasks(args.tasks) if args.tasks else None
    model = load_model(args.model, nonlinear=getattr(args, "nonlinear", None))
    markers = read_trc(args.trc, max_gap=0, warn=False)
    coords = read_coordinates(args.coordinates, model) if getattr(args, "coordinates", None) else None
    n = frame_range(np.asarray(markers.meta.get("file_time", markers.time)), args.time)
    with progress_factory(n.stop - n.start, "IK", "frames") as bar:
        outcome = inverse_kinematics(model, markers, tasks=tasks, time_range=args.time, coordinate_trial=coords,
                                     progress=bar)
    written = write_outputs(outcome, args.output, errors_path, precision=getattr(args, "precision", None))
    e = outcome.errors
    print(f"IK of {e.n_frames} frames, {len(outcome.fitter.marker_rms_)} markers: marker error RMS "
          f"{1000 * float(np.mean(e['marker_error_RMS'])):.2f} mm mean, "
          f"max {1000 * float(np.max(e['marker_error_max'])):.2f} mm; "
          f"{int(outcome.fitter.converged_.sum())}/{e.n_frames} frames converged")
    for p in written:
        print(f"wrote {p}")
    return written
