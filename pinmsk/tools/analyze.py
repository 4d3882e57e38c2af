"""OpenSim's AnalyzeTool from its setup file: its StaticOptimization and MuscleAnalysis analyses.

The tool's properties (opensim-core ``OpenSim/Tools/AnalyzeTool.cpp``, ``AbstractTool.cpp``):

=================================================  =======================================================
property                                           honoured as
=================================================  =======================================================
``model_file``                                     the ``.osim``, imported (:func:`pinmsk.model.load_model`)
``force_set_files``                                OpenSim force set files of reserve and residual
                                                   actuators, added to the model's
                                                   (:func:`pinmsk.opensim.actuators.read_actuators`)
``replace_force_set``                              ``false`` (true would drop the muscles: refused)
``results_directory``, ``input_directory``         as for every tool (:mod:`pinmsk.tools._common`)
``output_precision``                               OpenSim's decimal places: enough significant digits
                                                   for them at each file's largest value
``initial_time``, ``final_time``                   the frames analysed (OpenSim's ``findIndex`` rule)
``coordinates_file``                               ``.mot`` / ``.sto``, degrees as its header says
``lowpass_cutoff_frequency_for_coordinates``       OpenSim's pad + IIR filter; negative = none
``external_loads_file``                            an ExternalLoads ``.xml``, loads unfiltered
``solve_for_equilibrium_for_auxiliary_states``,    do not change these analyses (no integration; the
integrator settings, an empty ``ControllerSet``    muscle states are not used, see below)
=================================================  =======================================================

``states_file`` and ``speeds_file`` are refused (pinmsk differentiates the coordinates).  Each
analysis reads ``on``, ``start_time``, ``end_time``, ``step_interval`` (every n-th frame) and
``in_degrees`` (these outputs hold no angles), and:

* **StaticOptimization** (``OpenSim/Analyses/StaticOptimization.cpp``) --
  :class:`pinmsk.solvers.static.StaticOptimization` with OpenSim's muscle model
  (``convention="opensim"``): ``use_muscle_physiology`` true = activation mode (the
  inextensible-tendon force-length-velocity capacity, no passive force), false = force mode;
  ``activation_exponent``; ``use_model_force_set`` true (false, coordinate actuators in place of
  the muscles, is refused); ``optimizer_convergence_criterion`` and ``optimizer_max_iterations``
  are checked and bound OpenSim's optimizer: pinmsk solves each frame's problem to its optimum
  (its own tolerance, tighter than OpenSim's default 1e-4), and a frame that does not converge is
  an error.  Files ``<tool>_<analysis>_activation.sto`` (muscle activations and actuator controls)
  and ``<tool>_<analysis>_force.sto`` (muscle and actuator forces), named bare as OpenSim names them.
* **MuscleAnalysis** (``OpenSim/Analyses/MuscleAnalysis.cpp``) -- ``muscle_list`` and
  ``moment_arm_coordinate_list`` (``all`` or names), ``compute_moments`` (OpenSim's default false).
  Files ``<tool>_<analysis>_Length.sto``, with ``compute_moments`` ``..._MomentArm_<coord>.sto``
  (geometric paths, OpenSim's path algorithm: :func:`pinmsk.solvers.muscle_analysis.muscle_analysis`),
  and, when every muscle analysed has an inextensible tendon (pinmsk's rigid-tendon fiber
  kinematics are then OpenSim's), ``FiberLength``, ``NormalizedFiberLength``, ``TendonLength`` and
  ``PennationAngle``.  OpenSim's other files (``Moment_<coord>``, the fiber quantities of compliant
  tendons, fiber velocities, forces and powers) depend on muscle states and forces a kinematic
  analysis does not have: they are not written, and a warning names them.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import PinmskError
from . import _common, layout

__all__ = ["run", "ANALYSES"]

#: The analyses of an AnalysisSet this runner runs.
ANALYSES = ("StaticOptimization", "MuscleAnalysis")

#: MuscleAnalysis files that need muscle states (activation, fiber dynamics) or forces.
_STATE_FILES = ("FiberVelocity", "NormFiberVelocity", "PennationAngularVelocity", "TendonForce", "FiberForce",
                "ActiveFiberForce", "PassiveFiberForce", "ActiveFiberForceAlongTendon",
                "PassiveFiberForceAlongTendon", "FiberActivePower", "FiberPassivePower", "TendonPower",
                "MuscleActuatorPower")
_FIBER_FILES = ("FiberLength", "NormalizedFiberLength", "TendonLength", "PennationAngle")


@dataclass
class _Analysis:
    node: object
    kind: str
    name: str
    start: float
    end: float
    step: int
    options: dict


def _read_analysis(member) -> _Analysis | None:
    kind = member.tag
    if kind not in ANALYSES:
        raise member.error(None, f"<{kind}> is not an analysis pinmsk runs (it runs "
                                 f"{', '.join('<' + a + '>' for a in ANALYSES)}); remove it from the AnalysisSet")
    on = member.flag("on", True)
    start = member.number("start_time", -math.inf)
    end = member.number("end_time", math.inf)
    step = member.integer("step_interval", 1)
    if step < 1:
        raise member.error("step_interval", f"{step} is not a positive number of frames")
    member.flag("in_degrees", True)          # no angles in these outputs
    opts = {}
    if kind == "StaticOptimization":
        if not member.flag("use_model_force_set", True):
            raise member.error("use_model_force_set", "false replaces the muscles by coordinate actuators; "
                                                      "pinmsk's static optimization balances with the muscles: "
                                                      "set it true")
        opts["exponent"] = member.number("activation_exponent", 2.0)
        if not opts["exponent"] >= 1:
            raise member.error("activation_exponent", f"{opts['exponent']:g} is not >= 1")
        opts["physiology"] = member.flag("use_muscle_physiology", True)
        crit = member.number("optimizer_convergence_criterion", 1e-4)
        if not crit > 0:
            raise member.error("optimizer_convergence_criterion", f"{crit:g} is not > 0")
        iters = member.integer("optimizer_max_iterations", 100)
        if iters < 1:
            raise member.error("optimizer_max_iterations", f"{iters} is not >= 1")
    else:
        opts["muscles"] = member.words("muscle_list", ["all"])
        opts["coordinates"] = member.words("moment_arm_coordinate_list", ["all"])
        opts["moments"] = member.flag("compute_moments", False)
    member.finish()
    return _Analysis(member, kind, member.name or kind, start, end, step, opts) if on else None


def run(setup, *, results_dir=None) -> list[Path]:
    """Run an AnalyzeTool setup (see the module docstring); the files written, in order."""

    node = setup.node
    folder = _common.input_folder(node)
    model_path = _common.model_file(node, folder=folder)
    if node.flag("replace_force_set", False):
        raise node.error("replace_force_set", "true replaces the model's force set, muscles included; pinmsk "
                                              "adds the force set files to the model's muscles: set it false")
    force_files = []
    for w in node.words("force_set_files"):
        p = Path(w) if Path(w).is_absolute() else folder / w
        if not p.exists():
            raise node.error("force_set_files", f"file '{w}' not found (resolved to {p})")
        force_files.append(p)
    out_dir = _common.results_folder(node, results_dir)
    decimals = node.integer("output_precision", 8)
    if decimals < 0:
        raise node.error("output_precision", f"{decimals} is not a number of decimal places")
    start = node.number("initial_time", -math.inf)
    end = node.number("final_time", math.inf)
    if end < start:
        raise node.error("final_time", f"{end:g} s is before <initial_time> {start:g} s")
    node.flag("solve_for_equilibrium_for_auxiliary_states", False)
    node.ignore("maximum_number_of_integrator_steps", "maximum_integrator_step_size",
                "minimum_integrator_step_size", "integrator_error_tolerance")
    loads_path = node.file("external_loads_file", folder=folder)
    coords_path, _ = _common.coordinates_file(node, "coordinates_file", folder=folder)
    cutoff = _common.lowpass_cutoff(node, "lowpass_cutoff_frequency_for_coordinates")
    members = node.objects("AnalysisSet")
    analyses = [a for a in (_read_analysis(m) for m in members) if a is not None]
    node.finish()
    if not analyses:
        raise node.error("AnalysisSet", "no analysis is on; pinmsk runs StaticOptimization and MuscleAnalysis")

    model = _common.load_setup_model(node, model_path)
    actuators = []
    if force_files:
        from ..opensim.actuators import read_actuators
        for p in force_files:
            try:
                actuators += list(read_actuators(p, model)[0])
            except PinmskError as exc:
                raise node.error("force_set_files", str(exc)) from None
    coords = _common.read_coordinates(node, "coordinates_file", coords_path, model)
    _common.check_range(node, "initial_time", coords.time, start, end)
    trial = _common.opensim_filtered(coords, cutoff, str(coords_path))
    cut, keep, rows, kw = _common.loads_and_frames(node, loads_path, trial, start, end, "initial_time")
    base = setup.name or node.name or "analyze"
    tables = []
    for a in analyses:
        t = np.asarray(cut.time)
        r = rows - keep[0]
        r = np.intersect1d(r, _common.reported_rows(t, a.start, a.end))
        r = _every(r + keep[0], a.step) - keep[0]
        if not r.size:
            raise a.node.error(None, f"no frame between its start_time {a.start:g} s and end_time {a.end:g} s "
                                     "within the tool's time range")
        if a.kind == "StaticOptimization":
            tables += _static_optimization(a, model, cut, r, actuators, kw, base)
        else:
            tables += _muscle_analysis(a, model, cut, r, base)
    folder_out = _common.make_results_folder(out_dir)
    return [_common.write_storage(tab, folder_out / name, precision=_digits(tab, decimals))
            for name, tab in tables]


def _every(rows: np.ndarray, step: int) -> np.ndarray:
    """The frames an analysis records with ``step_interval`` ``step``, as OpenSim's AnalyzeTool steps it
    through the states: the first (its ``begin``), the last (its ``end``) and between them those whose
    index in the (padded) states is a multiple of ``step`` (``Analysis::proceed``)."""
    if step == 1 or rows.size <= 2:
        return rows
    k = np.arange(rows.size)
    keep = (k == 0) | (k == rows.size - 1) | (rows % step == 0)
    return rows[keep]


def _digits(table, decimals: int) -> int:
    """Significant digits that keep OpenSim's ``decimals`` places at the table's largest magnitude."""
    v = np.abs(np.asarray(table.values, dtype=float))
    big = float(np.max(v)) if v.size and np.isfinite(v).all() else 1.0
    lead = int(math.floor(math.log10(big))) + 1 if big >= 1 else 1
    return int(min(17, max(1, decimals + lead)))


def _static_optimization(a: _Analysis, model, trial, rows, actuators, kw, base):
    from ..solvers.static import StaticOptimization

    from ..components import Motion
    from ..dynamics import inverse_dynamics_array
    from ..kinematics import coordinate_map, prepare, source_coordinates

    so = StaticOptimization(mode="activation" if a.options["physiology"] else "force",
                            exponent=a.options["exponent"], convention="opensim",
                            actuators=actuators or None)
    try:
        # the motion and its inverse dynamics over every frame (the padded ones give the splines their
        # ends), the optimization on the frames analysed only
        inputs = prepare(model, trial, cutoff=0, missing_coordinates="default", **kw)
        mo = inputs.motion
        tau = inverse_dynamics_array(model, mo, external=inputs.external, actuated=False)
        if coordinate_map(model) is not None:         # OpenSim's coordinates' forces, as SO balances them
            tau = source_coordinates(model, mo, tau)[2]
        sub = Motion(mo.t[rows], mo.q[rows], mo.v[rows], mo.a[rows],
                     {k: np.asarray(v)[rows] for k, v in mo.signals.items()})
        so.fit(model, sub, moments=tau[rows])
    except PinmskError as exc:
        raise a.node.error(None, str(exc)) from None
    external = _external_force_columns(model, kw, sub) if kw else None
    act, force = layout.so_tables(model, so.result_, [x.name for x in so.actuators_], external=external)
    return [(f"{base}_{a.name}_activation.sto", act), (f"{base}_{a.name}_force.sto", force)]


def _external_force_columns(model, kw, motion):
    """The external loads as OpenSim's ForceReporter records them beside the actuators' forces:
    ``<body>_<name>_F[xyz]`` (ground frame), ``_p[xyz]`` (the point in the body's frame) and ``_T[xyz]``, the
    data file's columns interpolated at the frames (opensim-core ``ExternalForce::getRecordValues``)."""
    import pinocchio as pin

    loads, grf = kw["external_loads"], kw["grf"]
    t = np.asarray(motion.t)
    tg = np.asarray(grf.time, dtype=float)

    def at(cols):
        return np.column_stack([np.interp(t, tg, np.asarray(grf[c], dtype=float)) for c in cols])

    pm = model.pin
    pd = pm.createData()
    names, blocks = [], []
    for spec in loads.loads:
        head = f"{spec.body}_{spec.name}_"
        names += [head + f"F{x}" for x in "xyz"]
        blocks.append(at(spec.columns("force")))
        if spec.columns("point") is not None:
            p = at(spec.columns("point"))
            fid = model.frame_id(spec.body)
            local = np.empty_like(p)
            for k in range(t.size):
                pin.framesForwardKinematics(pm, pd, np.asarray(motion.q[k]))
                M = pd.oMf[fid]
                local[k] = M.rotation.T @ (p[k] - M.translation)
            names += [head + f"p{x}" for x in "xyz"]
            blocks.append(local)
        if spec.columns("torque") is not None:
            names += [head + f"T{x}" for x in "xyz"]
            blocks.append(at(spec.columns("torque")))
    return names, np.hstack(blocks) if blocks else np.zeros((t.size, 0))


def _pick(a: _Analysis, prop: str, words, offered, what: str):
    if len(words) == 1 and words[0].lower() == "all":
        return list(offered)
    unknown = [w for w in words if w not in offered]
    if unknown:
        raise a.node.error(prop, f"{', '.join(unknown)} {'is' if len(unknown) == 1 else 'are'} not "
                                 f"{what} of the model ({', '.join(offered)})")
    return list(words)


def _muscle_analysis(a: _Analysis, model, trial, rows, base):
    from ..kinematics import trial_coordinates
    from ..solvers.muscle_analysis import muscle_analysis

    if model.muscles is None or model.n_muscles == 0:
        raise a.node.error(None, f"model '{model.name}' has no muscles to analyse")
    all_muscles = list(model.muscles.names)
    muscles = _pick(a, "muscle_list", a.options["muscles"], all_muscles, "muscles")
    cmap = model.meta.get("coordinate_map")
    offered = list(getattr(cmap, "osim_coordinates", None) or trial_coordinates(model))
    coords = _pick(a, "moment_arm_coordinate_list", a.options["coordinates"], offered, "coordinates")
    try:
        out = muscle_analysis(model, trial, cutoff=0, missing_coordinates="default")
    except PinmskError as exc:
        raise a.node.error(None, str(exc)) from None
    t = np.asarray(out.time)[rows]
    n = len(rows)

    def col(name):
        return np.asarray(out[name])[rows] if name in out else np.zeros(n)

    files = [("Length", np.column_stack([col(f"{m}_length") for m in muscles]))]
    if a.options["moments"]:
        for c in coords:
            files.append((f"MomentArm_{c}", np.column_stack([col(f"{m}_moment_arm_{c}") for m in muscles])))
    idx = [all_muscles.index(m) for m in muscles]
    mtu = model.muscles.mtu
    # OpenSim's ignore_tendon_compliance, carried by the import as the muscle set's tendon
    rigid = np.full(len(all_muscles), getattr(model.muscles, "tendon", "compliant") == "rigid")
    skipped = list(_STATE_FILES) + ([f"Moment_{c}" for c in coords] if a.options["moments"] else [])
    if rigid[idx].all():
        l_ce = np.column_stack([col(f"{m}_fiber_length") for m in muscles])
        l_min = getattr(mtu, "l_min", None)
        if l_min is not None:          # OpenSim clamps an inextensible tendon's fiber at its minimum length
            l_ce = np.maximum(l_ce, np.asarray(l_min, dtype=float)[idx])
        l_opt = np.asarray(mtu.l_opt, dtype=float)[idx]
        alpha0 = np.asarray(mtu.pennation, dtype=float)[idx]
        h = l_opt * np.sin(alpha0)                       # constant fiber-width pennation
        alpha = np.arcsin(np.clip(h / l_ce, 0.0, 1.0))
        l_mt = np.column_stack([col(f"{m}_length") for m in muscles])
        files += [("FiberLength", l_ce), ("NormalizedFiberLength", l_ce / l_opt),
                  ("TendonLength", l_mt - l_ce * np.cos(alpha)), ("PennationAngle", alpha)]
    else:
        compliant = [m for m, r in zip(muscles, rigid[idx]) if not r]
        skipped = list(_FIBER_FILES) + skipped
        warnings.warn(f"{a.node.where}: {', '.join(skipped)} not written: with compliant tendons "
                      f"({', '.join(compliant[:3])}{' ...' if len(compliant) > 3 else ''}) they depend on the "
                      "muscles' states, which a kinematic analysis does not have", stacklevel=3)
    if rigid[idx].all():
        warnings.warn(f"{a.node.where}: {', '.join(skipped)} not written: they depend on the muscles' "
                      "activation and forces, which a kinematic analysis does not have", stacklevel=3)
    return [(f"{base}_{a.name}_{q}.sto", _common.storage_trial(q, t, muscles, X)) for q, X in files]
