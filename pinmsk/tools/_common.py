"""What OpenSim's tools share: the results folder, the model, the coordinates file and its filter,
the time range, the forces a setup excludes, and OpenSim's storage files.

Each is read as OpenSim's tools read it (opensim-core ``OpenSim/Tools/InverseDynamicsTool.cpp``,
``DynamicsTool.cpp``, ``AnalyzeTool.cpp``; ``OpenSim/Common/Storage.cpp``):

* paths resolve against the setup file's folder (or ``<input_directory>`` when it is given);
* the coordinates are filtered, when ``<lowpass_cutoff_frequency_for_coordinates>`` is not
  negative, as ``Storage.pad(n // 2)``, a resample to the smallest time step when the steps
  are not uniform, and ``Storage.lowpassIIR`` (:func:`pinmsk.signals.filtering.lowpass_iir`), so the
  padded frames stay with the trial and its derivatives come from the padded signal;
* the frames reported run from the last frame at or before the range's start to the last
  frame at or before its end (``Storage::findIndex``), within the data.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import PinmskError
from ..io.opensim_setup import SetupError
from ..io.output_files import output_folder
from ..io.tables import read_sto_header, read_trial, write_trial
from ..signals.filtering import lowpass_iir, reflect_pad
from ..trial import Trial

#: Smallest time-step excess over the shortest step that makes OpenSim resample a storage (``SimTK::Eps``).
_RESAMPLE_EPS = 2.220446049250313e-16


def input_folder(node) -> Path:
    """Where the setup's input files resolve: ``<input_directory>`` (relative to the setup) or the setup's folder."""
    d = node.text("input_directory")
    if d is None:
        return node.setup.folder
    p = Path(d)
    p = p if p.is_absolute() else node.setup.folder / p
    if not p.is_dir():
        raise node.error("input_directory", f"folder '{d}' not found (resolved to {p})")
    return p


def results_folder(node, results_dir) -> Path:
    """The folder results go to: ``results_dir`` when given, else ``<results_directory>`` (relative to the
    setup; OpenSim's default is the setup's folder).  Created (and recorded in the open output
    transaction) when written."""
    d = node.text("results_directory")
    if results_dir is not None:
        return Path(results_dir)
    if d is None:
        return node.setup.folder
    p = Path(d)
    return p if p.is_absolute() else node.setup.folder / p


def make_results_folder(path: Path) -> Path:
    return output_folder(path)


def model_file(node, prop: str = "model_file", *, folder=None) -> Path:
    """The ``.osim`` the setup names (resolved; a missing file is refused with its resolved path)."""
    path = node.file(prop, folder=folder)
    if path is None:
        raise node.error(prop, "no model named; give the .osim file to run")
    return path


def load_setup_model(node, path: Path, prop: str = "model_file", *, muscles: bool = True):
    """The model at ``path`` (an ``.osim``, imported as :func:`pinmsk.model.load_model` does; its
    approximations warned of).  Its muscle paths are fitted on first use, so an analysis that applies no
    muscle (inverse dynamics with the muscles excluded, ``muscles=False``) pays for none."""
    from ..model import load_model

    try:
        return load_model(path)
    except PinmskError as exc:
        raise node.error(prop, str(exc)) from None


def rotational(model) -> tuple[str, ...]:
    """OpenSim's rotational coordinates of an imported model (all the model's coordinates otherwise)."""
    types = model.meta.get("osim_motion_types") or {}
    return tuple(c for c, t in types.items() if t == "Rotational") if types else tuple(model.coordinates)


def coordinates_file(node, prop: str, *, folder=None, degrees_prop: str | None = None) -> tuple[Path, bool | None]:
    """The coordinates file ``prop`` (resolved) and what ``degrees_prop`` (a setup flag) says of its angles."""
    path = node.file(prop, folder=folder)
    if path is None:
        raise node.error(prop, "no coordinates file named")
    declared = None
    if degrees_prop is not None and node.text(degrees_prop) is not None:
        declared = node.flag(degrees_prop)
    return path, declared


def read_coordinates(node, prop: str, path: Path, model, *, declared: bool | None = None,
                     degrees_prop: str | None = None) -> Trial:
    """The coordinates file (``.mot`` / ``.sto``), its angles in radians as its ``inDegrees`` says (or, for a
    header that does not say, as ``declared``, the setup's ``degrees_prop``); a disagreement is refused."""
    try:
        header_says = read_sto_header(path).in_degrees if path.suffix.lower() in (".sto", ".mot") else None
    except PinmskError as exc:
        raise node.error(prop, str(exc)) from None
    if declared is not None and header_says is not None and declared != header_says:
        raise node.error(degrees_prop, f"says {'degrees' if declared else 'radians'} but {path} declares "
                                       f"inDegrees={'yes' if header_says else 'no'}; make them agree")
    try:
        trial = read_trial(path, angular=rotational(model))
    except PinmskError as exc:
        raise node.error(prop, str(exc)) from None
    if header_says is None and declared:
        rot = set(rotational(model))
        trial = Trial(trial.time, {n: np.radians(trial[n]) if n in rot else trial[n] for n in trial.names},
                      meta=trial.meta)
    return trial


def lowpass_cutoff(node, prop: str) -> float | None:
    """The setup's low-pass cut-off (Hz), or None for OpenSim's "no filter" (a negative value; the default)."""
    c = node.number(prop, -1.0)
    if c is None or c < 0:
        return None
    if c == 0:
        raise node.error(prop, "0 Hz would remove the signal; give a cut-off in Hz or -1 for no filter")
    return float(c)


def opensim_filtered(trial: Trial, cutoff: float | None, where: str) -> Trial:
    """The coordinates as OpenSim's tool holds them before its splines: unchanged without a cut-off;
    with one, reflect-padded by half their length, resampled at the smallest step when the steps are not
    uniform (a quintic spline, as OpenSim's degree-5 GCV spline of zero error variance interpolates), and
    low-passed by OpenSim's IIR filter (see the module docstring)."""
    if cutoff is None:
        return trial
    t = np.asarray(trial.time, dtype=float)
    if t.size < 4:
        raise PinmskError(f"{where}: {t.size} frames; OpenSim's filter needs 4 or more")
    X = np.asarray(trial.values, dtype=float)
    pad = t.size // 2
    t = reflect_pad(t, pad)
    X = reflect_pad(X, pad)
    steps = np.diff(t)
    dt = float(steps.min())
    if dt <= 0:
        raise PinmskError(f"{where}: the time column does not increase; the coordinates cannot be filtered")
    if (t[-1] - t[0]) / (t.size - 1) - dt > _RESAMPLE_EPS:
        grid = []
        x = t[0]
        while x <= t[-1]:              # OpenSim's accumulated steps from the first time
            grid.append(x)
            x += dt
        grid = np.array(grid)
        X = _quintic_resample(t, X, grid)
        t = grid
    X = lowpass_iir(X, rate=1.0 / dt, cutoff=cutoff)
    return Trial.from_array(t, trial.names, X, meta=dict(trial.meta))


def held_ends(data: Trial, time) -> Trial:
    """``data`` with its end rows repeated at the frames of ``time`` that lie less than one of its steps
    outside it (a resampled time axis a rounding away from the data's first sample, where OpenSim's
    splines of the loads hold their ends)."""
    t = np.asarray(data.time, dtype=float)
    tt = np.asarray(time, dtype=float)
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    before = tt[(tt < t[0]) & (tt > t[0] - step)]
    after = tt[(tt > t[-1]) & (tt < t[-1] + step)]
    if not before.size and not after.size:
        return data
    X = np.asarray(data.values, dtype=float)
    t_new = np.concatenate([before[:1], t, after[-1:]])
    X_new = np.concatenate([X[:1]] * bool(before.size) + [X] + [X[-1:]] * bool(after.size), axis=0)
    return Trial.from_array(t_new, data.names, X_new, meta=dict(data.meta))


def time_range(node, prop: str = "time_range") -> tuple[float, float]:
    """``<time_range>`` (OpenSim's default: all of the data)."""
    r = node.numbers(prop, 2, default=None)
    if r is None:
        return -math.inf, math.inf
    if r[1] < r[0]:
        raise node.error(prop, f"ends ({r[1]:g} s) before it starts ({r[0]:g} s)")
    return float(r[0]), float(r[1])


def check_range(node, prop: str, time, start: float, end: float) -> None:
    """Refuse a time range that misses the data altogether (naming the property and the data's span)."""
    t = np.asarray(time, dtype=float)
    if start > t[-1] or end < t[0]:
        raise node.error(prop, f"{start:g}-{end:g} s lies outside the coordinates' {t[0]:.6g}-{t[-1]:.6g} s")


def reported_rows(time: np.ndarray, start: float, end: float) -> np.ndarray:
    """The rows OpenSim's tools report for ``[start, end]`` on ``time``: from the last row at or before
    the start to the last row at or before the end (``Storage::findIndex``), the range clipped to the data."""
    t = np.asarray(time, dtype=float)
    s = max(start, t[0])
    e = min(end, t[-1])
    i0 = max(int(np.searchsorted(t, s, side="right")) - 1, 0)
    i1 = max(int(np.searchsorted(t, e, side="right")) - 1, 0)
    return np.arange(i0, i1 + 1)


@dataclass(frozen=True)
class ForceChoice:
    """What ``<forces_to_exclude>`` leaves: the model with the excluded components removed, and whether
    the muscles are excluded (pinmsk's inverse dynamics applies no muscle force)."""

    model: object
    components: bool
    excluded: tuple[str, ...]


def exclude_forces(node, prop: str, words, model, model_path) -> ForceChoice:
    """Apply ``<forces_to_exclude>`` as OpenSim's ``DynamicsTool::disableModelForces`` does: the keywords
    ``All``, ``actuators`` (muscles among them) and ``Muscles`` (any case), else a force's name.

    pinmsk's inverse dynamics applies no muscle force and no actuator without its control (OpenSim's
    actuators apply none at zero control): a muscle left in is refused by name, as is a force the
    import did not carry (it would act in OpenSim) and a name that is no force of the model."""
    from ..io.osim import read_osim

    doc = read_osim(model_path)
    muscles = [m.name for m in doc.muscles]
    actuators = [a.name for a in doc.actuators]
    others = [c.name for c in doc.contact_forces] + [o.name for o in doc.other if o.category == "force"]
    known = set(muscles) | set(actuators) | set(others)
    excluded: set = set()
    everything = False
    for w in words:
        key = w.upper()
        if key == "ALL":
            everything = True
            excluded = set(known)
        elif key == "ACTUATORS":
            excluded |= set(muscles) | set(actuators)
        elif key == "MUSCLES":
            excluded |= set(muscles)
        elif w in known:
            excluded.add(w)
        else:
            raise node.error(prop, f"'{w}' is not a force of model '{doc.name}' nor All, actuators or Muscles "
                                   f"(its forces: {', '.join(sorted(known)) or 'none'}); groups are not read")
    kept_muscles = [m for m in muscles if m not in excluded]
    if kept_muscles:
        shown = ", ".join(kept_muscles[:4]) + (" ..." if len(kept_muscles) > 4 else "")
        raise node.error(prop, f"leaves {len(kept_muscles)} muscle(s) applying force ({shown}); pinmsk's inverse "
                               "dynamics applies no muscle force: add Muscles")
    report = model.meta.get("import_report")
    not_imported = {e.element for e in getattr(report, "not_imported", ())}
    lost = [e.name for e in list(doc.contact_forces) + [o for o in doc.other if o.category == "force"]
            if e.name not in excluded and e.where in not_imported]
    if lost:
        raise node.error(prop, f"leaves force(s) {', '.join(lost)} applying, which pinmsk did not import; "
                               "exclude them by name (or All)")
    out = model
    if not everything:
        for name in sorted(excluded - set(muscles)):
            for c in list(out.components):
                if c.target == name or c.label.endswith(":" + name) or getattr(c, "name", None) == name:
                    out = out.without(c.label)
    return ForceChoice(out, not everything, tuple(sorted(excluded)))


def storage_trial(title: str, time, names, values) -> Trial:
    """A Trial written as OpenSim writes a storage: ``title`` on the first line, then ``version``, ``nRows``,
    ``nColumns``, ``inDegrees=no``, ``endheader`` (no other header fields)."""
    return Trial.from_array(np.asarray(time, dtype=float), tuple(names), np.asarray(values, dtype=float),
                            meta={"name": title})


def write_storage(trial: Trial, path: Path, *, precision: int | None = None) -> Path:
    """Write an OpenSim storage (see :func:`storage_trial`); atomic."""
    return write_trial(trial, path, precision=precision)


def output_name(node, prop: str, default: str) -> str:
    """A result file's name (``<output_gen_force_file>``), as OpenSim's ``Storage::printResult`` makes it:
    ``.sto`` added when it has no extension.  A folder in it is refused (the folder is
    ``<results_directory>``)."""
    name = node.text(prop, default)
    p = Path(name)
    if p.name != name:
        raise node.error(prop, f"'{name}' names a folder; give a file name (results go to <results_directory>)")
    return name if p.suffix else name + ".sto"


__all__ = ["SetupError"]


def loads_and_frames(node, loads_path, trial: Trial, start: float, end: float, prop: str):
    """The external loads of the setup and the frames they cover: ``(cut, keep, rows, kw)``: the
    (filtered) ``trial`` cut to the frames the loads' data cover (``keep``, indices into ``trial``),
    the reported ``rows`` (indices into ``trial``, :func:`reported_rows`) and the loads as keyword
    arguments of the analyses (``external_loads``, ``grf``).  Reported frames beyond the loads' data are
    refused by name (``prop``: the setup's time property)."""
    from ..io.external_loads import read_external_loads

    kw = {}
    keep = np.arange(trial.n_frames)
    span = ""
    if loads_path is not None:
        loads = read_external_loads(loads_path)
        if loads.datafile is None:
            raise node.error("external_loads_file", f"{loads_path} names no <datafile>")
        grf = held_ends(read_trial(loads.datafile), trial.time)
        tg = np.asarray(grf.time, dtype=float)
        keep = np.flatnonzero((trial.time >= tg[0] - 1e-9) & (trial.time <= tg[-1] + 1e-9))
        kw = dict(external_loads=loads, grf=grf)
        span = f" ({tg[0]:.6g}-{tg[-1]:.6g} s)"
    rows = reported_rows(trial.time, start, end)
    if not keep.size or rows[0] < keep[0] or rows[-1] > keep[-1]:
        raise node.error(prop, f"the frames {trial.time[rows[0]]:.6g}-{trial.time[rows[-1]]:.6g} s reach "
                               f"beyond the external loads' data{span}")
    cut = trial if keep.size == trial.n_frames else Trial.from_array(
        np.asarray(trial.time)[keep], trial.names, np.asarray(trial.values)[keep], meta=dict(trial.meta))
    return cut, keep, rows, kw


def _quintic_resample(t: np.ndarray, X: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The quintic not-a-knot interpolating spline through ``X`` (N, k) at ``t``, evaluated at ``grid``:
    dense maps for a short trial (:mod:`pinmsk.signals.bspline`, no SciPy import), SciPy's otherwise."""
    from ..signals.bspline import design_matrix, not_a_knot, use_dense

    if use_dense(t.size):
        knots = not_a_knot(t, 5)
        coef = np.linalg.solve(design_matrix(t, knots, 5), X)
        return design_matrix(grid, knots, 5) @ coef
    from scipy.interpolate import make_interp_spline
    return make_interp_spline(t, X, k=5)(grid)
