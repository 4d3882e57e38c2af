"""Moco's own 2-D walking problems (``example2DWalking``), timed, side by side with pinmsk.

    python benchmarks/bench_gait_moco.py [--moco-only | --pinmsk-only] [--problems tracking,predictive]
        [--timeout-tracking 900] [--timeout-predictive 600] [--out DIR] [--data DIR]

OpenSim (``pip install opensim``, 4.6 bundles Moco, CasADi and IPOPT) is an optional peer, never a
pinmsk dependency: without it, or without ``../shared/data/opensim-models/Moco2DWalking`` (see its
SOURCE.md), this script says so and exits 0.

**One process per tool.**  OpenSim and the pip ``casadi`` both ship ``libcasadi.so.3.7`` with
different ABIs, so they can never share a Python process (``/work/notes/ocp.md``).  Each Moco
problem runs in a child process (this file with ``--_worker``), in its own process group, with a
wall-clock timeout; the parent never imports opensim or casadi: the pinmsk side (:func:`run_pinmsk`,
the CasADi engine) runs in a child too (``--_pinmsk``), after the Moco children have exited.

**The pinmsk side** (:func:`build_pinmsk`) solves the same two problems on the same model, imported by
pinmsk, with Moco's exact objective: the goals :class:`pinmsk.solvers.ocp.ControlEffort`,
``StateTracking`` and ``ContactTracking`` are Moco's ``MocoControlGoal``, ``MocoStateTrackingGoal``
(as MocoTrack sets it up) and ``MocoContactTrackingGoal`` (integrands, weights and normalisations read
in opensim-core), so both objectives are in the same units and directly comparable.  Moco's own
tracking solution scored by pinmsk's goals (:func:`moco_tracking_under_pinmsk`) reproduces Moco's
reported terms (control effort exactly, contact within 0.1 %, state tracking within 1 %: pinmsk's
Butterworth and spline of the reference against OpenSim's IIR filter with its own end padding and
GCV spline differ by up to 1e-3 rad / 0.04 rad/s at the last reference frame).

**The problems** are those of ``example2DWalking.py`` (Falisse et al. 2019, PLOS One 14:e0217730,
as shipped with Moco; read there, formulated again here):

* *tracking* -- ``MocoTrack`` of ``referenceCoordinates.sto`` (low-pass 6 Hz, position derivatives
  tracked, reference applied to the guess), half a gait cycle of 0.470089 s, control effort weight 10,
  state tracking weight 1, ``MocoContactTrackingGoal`` of ``referenceGRF.xml`` (weight 1, heel + front
  sphere per foot, plane projection, normal z), left/right symmetry as a ``MocoPeriodicityGoal``
  (every ``_r`` state ends at the start of its ``_l`` twin and vice versa, pelvis_tx excluded,
  lumbar actuator control), the example's coordinate bounds; MocoTrack's default solver settings.
* *predictive* -- ``MocoStudy``: the same symmetry, ``MocoAverageSpeedGoal`` 1.2 m/s, ``MocoControlGoal``
  weight 10, exponent 3, divided by displacement; final time in [0.4, 0.6] s; CasADi solver, 50 mesh
  intervals, IPOPT tolerances 1e-4, 1000 iterations max; guess = ``--predictive-guess``, else the
  tracking solution when this run produced one (as the example does), else Moco's default guess
  (recorded in the output).

Everything OpenSim reads or writes lives in a copy of the model folder under ``--out`` (default: a
fresh temporary directory); the shared data are only read.  OpenSim's Logger is off; IPOPT's
console output goes to ``<problem>.log`` beside the solution.

Per problem, the output JSON ``moco_2d_walking.json`` (and the printed table) records: status,
success, objective, IPOPT iterations, solver seconds, wall seconds, the half-cycle and full-stride
solution ``.sto`` files (``createPeriodicTrajectory``) and the full-stride GRF
(``createExternalLoadsTableForGait``), and the RMS (deg) of the solution's joint angles against
``referenceCoordinates.sto`` (the tracked data; for the prediction, how far it walks from it).
A child killed by the timeout is reported as ``"not converged within X s"`` (no solution).
Each Moco stride is also mapped onto gait2d (:func:`moco_stride_on_gait2d`) and validated with
:func:`pinmsk.gait_validation.validate_gait` (joint angles against Winter and the measured walk,
the GRF double hump, activations against EMG): ``<problem>_validation.json`` / ``.html``.

Measured here in one run (``python benchmarks/bench_gait_moco.py``; 2 cores shared with other jobs,
pip opensim 4.6, OMP/BLAS threads 1; objectives in Moco's units, both tools; an earlier run on
another machine had Moco's tracking at 387 s and its prediction unconverged after 58 min):

| problem | tool | status | objective | iterations | wall (s) | Moco/pinmsk | joint RMS max (deg) | GRF RMS max (% BW) |
|---|---|---|---|---|---|---|---|---|
| tracking | Moco | Solve_Succeeded | 1.543 | 156 | 675.5 | | 7.14 | 2.71 |
| tracking | pinmsk | Solve_Succeeded | 1.001 | 1322 | 103.8 | 6.5 | 2.47 | 1.28 |
| predictive | Moco | not converged within 600 s | (0.168, inf_pr 1.37) | 34 | 600 | | - | - |
| predictive | pinmsk | Solve_Succeeded | 0.1197 | 606 | 113.4 | > 5.3 | 9.36 | 10.95 |

* tracking terms: Moco control effort 0.800 / state tracking 0.368 / contact 0.375; pinmsk 0.743 / 0.142 /
  0.115 (24 Hermite-Simpson intervals as MocoTrack's 0.02 s mesh, IPOPT tol 1e-4 and the limited-memory
  Hessian; Moco: MocoTrack's tolerances 1e-2).  Moco's solution scored by pinmsk's goals: 0.800 / 0.371 /
  0.374 (1.5455 against Moco's 1.5426), so the lower pinmsk optimum is a better solution of the same
  objective on pinmsk's import of the model (fitted muscle paths, implicit dynamics), not another
  objective.  The lumbar control's periodicity was not imposed in that run (pinmsk's control went 0.0018
  -> 0.0033); with it (``Symmetric(controls=)``, ``--pinmsk-only`` right after, load average 1.6-1.9):
  tracking 1.019 (1267 it, 117.6 s), prediction 0.1201 (564 it, 117.4 s), joints within 2.41 / 9.31 deg
  and GRF within 1.26 / 10.81 % BW of the reference.
* prediction: pinmsk from its own tracking solution of the same run (as Moco's example), 50 intervals,
  final time 0.515 s, 1.2 m/s; joint RMS / GRF RMS against the (tracked) reference data, which a
  prediction need not reproduce.  Moco (guess: its tracking solution) was killed at iteration 34.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

FOLDER = "opensim-models/Moco2DWalking"
FILES = ("2D_gait.osim", "referenceCoordinates.sto", "referenceGRF.sto", "referenceGRF.xml")
PROBLEMS = ("tracking", "predictive")
HALF_CYCLE = 0.470089          # s, the tracking problem's duration (example2DWalking.py)
SPEED = 1.2                    # m/s, the prediction's prescribed average speed
#: coordinate bounds of both problems (rad; pelvis_tx, pelvis_ty in m)
BOUNDS = {
    "groundPelvis/pelvis_tilt": (-20.0, -10.0), "groundPelvis/pelvis_tx": (0.0, 1.0),
    "groundPelvis/pelvis_ty": (0.75, 1.25),
    "hip_l/hip_flexion_l": (-10.0, 60.0), "hip_r/hip_flexion_r": (-10.0, 60.0),
    "knee_l/knee_angle_l": (-50.0, 0.0), "knee_r/knee_angle_r": (-50.0, 0.0),
    "ankle_l/ankle_angle_l": (-15.0, 25.0), "ankle_r/ankle_angle_r": (-15.0, 25.0),
    "lumbar/lumbar": (0.0, 20.0),
}
ANGLES = ("pelvis_tilt", "hip_flexion_r", "hip_flexion_l", "knee_angle_r", "knee_angle_l",
          "ankle_angle_r", "ankle_angle_l", "lumbar")
CONTACTS = {"r": ("contactHeel_r", "contactFront_r"), "l": ("contactHeel_l", "contactFront_l")}


# ---------------------------------------------------------------------------
# the child: one Moco problem (imports opensim; never casadi)

def _swap_side(name: str) -> str:
    return name.replace("_r", "\0").replace("_l", "_r").replace("\0", "_l")


def _symmetry(osim, model):
    """Left/right symmetry of a half cycle (the example's MocoPeriodicityGoal)."""
    goal = osim.MocoPeriodicityGoal("symmetryGoal")
    names = [model.getStateVariableNames().getitem(i) for i in range(model.getNumStateVariables())]
    for n in names:
        sided = "_r" in n or "_l" in n
        if n.startswith("/jointset"):
            if sided:
                goal.addStatePair(osim.MocoPeriodicityGoalPair(n, _swap_side(n)))
            elif "pelvis_tx/value" not in n:
                goal.addStatePair(osim.MocoPeriodicityGoalPair(n))
        elif n.endswith("/activation") and sided:
            goal.addStatePair(osim.MocoPeriodicityGoalPair(n, _swap_side(n)))
    goal.addControlPair(osim.MocoPeriodicityGoalPair("/lumbarAct"))
    return goal


def _bounds(problem):
    for path, (lo, hi) in BOUNDS.items():
        scale = 1.0 if path.endswith(("pelvis_tx", "pelvis_ty")) else math.pi / 180.0
        problem.setStateInfo(f"/jointset/{path}/value", [lo * scale, hi * scale])


def _tracking(osim):
    track = osim.MocoTrack()
    track.setName("gaitTracking")
    ref = osim.TableProcessor("referenceCoordinates.sto")
    ref.append(osim.TabOpLowPassFilter(6))
    mp = osim.ModelProcessor("2D_gait.osim")
    track.setModel(mp)
    track.setStatesReference(ref)
    track.set_states_global_tracking_weight(1.0)
    track.set_allow_unused_references(True)
    track.set_track_reference_position_derivatives(True)
    track.set_apply_tracked_states_to_guess(True)
    track.set_initial_time(0.0)
    track.set_final_time(HALF_CYCLE)
    study = track.initialize()
    problem = study.updProblem()
    model = mp.process()
    model.initSystem()
    problem.addGoal(_symmetry(osim, model))
    osim.MocoControlGoal.safeDownCast(problem.updGoal("control_effort")).setWeight(10.0)
    grf = osim.MocoContactTrackingGoal("contact", 1.0)
    grf.setExternalLoadsFile("referenceGRF.xml")
    for side, label in (("r", "Right_GRF"), ("l", "Left_GRF")):
        names = osim.StdVectorString()
        for c in CONTACTS[side]:
            names.append(c)
        grf.addContactGroup(names, label)
    grf.setProjection("plane")
    grf.setProjectionVector(osim.Vec3(0, 0, 1))
    problem.addGoal(grf)
    _bounds(problem)
    return study, model, "MocoTrack default (reference applied to the guess)"


def _predictive(osim, guess: Path | None):
    study = osim.MocoStudy()
    study.setName("gaitPrediction")
    problem = study.updProblem()
    mp = osim.ModelProcessor("2D_gait.osim")
    problem.setModelProcessor(mp)
    model = mp.process()
    model.initSystem()
    problem.addGoal(_symmetry(osim, model))
    speed = osim.MocoAverageSpeedGoal("speed")
    speed.set_desired_average_speed(SPEED)
    problem.addGoal(speed)
    effort = osim.MocoControlGoal("effort", 10.0)
    effort.setExponent(3)
    effort.setDivideByDisplacement(True)
    problem.addGoal(effort)
    problem.setTimeBounds(0, [0.4, 0.6])
    _bounds(problem)
    solver = study.initCasADiSolver()
    solver.set_num_mesh_intervals(50)
    solver.set_verbosity(2)
    solver.set_optim_solver("ipopt")
    solver.set_optim_convergence_tolerance(1e-4)
    solver.set_optim_constraint_tolerance(1e-4)
    solver.set_optim_max_iterations(1000)
    if guess is not None:
        solver.setGuessFile(str(guess))
        how = f"the tracking solution ({guess.name})"
    else:
        how = "Moco's default guess (no tracking solution in this run)"
    return study, model, how


def worker(problem: str, workdir: Path, result: Path, guess: Path | None) -> int:
    os.chdir(workdir)                       # OpenSim resolves the model's relative files from here
    import opensim as osim
    osim.Logger.setLevelString("Off")
    t0 = time.perf_counter()
    study, model, how = _tracking(osim) if problem == "tracking" else _predictive(osim, guess)
    t_setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    sol = study.solve()
    wall = time.perf_counter() - t1
    out = {"problem": problem, "guess": how, "setup_seconds": t_setup, "solve_wall_seconds": wall,
           "success": bool(sol.success()), "status": sol.getStatus(),
           "objective": float(sol.getObjective()), "iterations": int(sol.getNumIterations()),
           "solver_seconds": float(sol.getSolverDuration()),
           "final_time": float(sol.getFinalTime()), "mesh_points": int(sol.getNumTimes())}
    if sol.isSealed():
        sol.unseal()                        # a failed solve is sealed; its iterate is still written
    half = workdir / f"{problem}_solution_halfcycle.sto"
    sol.write(str(half))
    full = osim.createPeriodicTrajectory(sol)
    full_path = workdir / f"{problem}_solution_fullStride.sto"
    full.write(str(full_path))
    r, l = osim.StdVectorString(), osim.StdVectorString()
    for c in CONTACTS["r"]:
        r.append(c)
    for c in CONTACTS["l"]:
        l.append(c)
    grf_path = workdir / f"{problem}_solutionGRF_fullStride.sto"
    osim.STOFileAdapter.write(osim.createExternalLoadsTableForGait(model, full, r, l), str(grf_path))
    out.update(solution=str(half), full_stride=str(full_path), grf_full_stride=str(grf_path))
    result.write_text(json.dumps(out, indent=2))
    return 0


# ---------------------------------------------------------------------------
# the parent: copies, children, timeouts, comparison (never imports opensim)

def _last_iterate(log: Path) -> dict:
    """The last IPOPT iteration row of ``log``: ``{"iterations", "objective", "inf_pr", "inf_du"}`` (or {})."""
    last = None
    for line in log.read_text(errors="replace").splitlines():
        f = line.split()
        if len(f) >= 4 and f[0].rstrip("r").isdigit():
            try:
                last = (int(f[0].rstrip("r")), float(f[1]), float(f[2]), float(f[3]))
            except ValueError:
                continue
    if last is None:
        return {}
    return dict(zip(("iterations", "objective", "inf_pr", "inf_du"), last), note="last IPOPT iterate at the timeout")


def _run_child(problem: str, workdir: Path, timeout: float, guess: Path | None) -> dict:
    result = workdir / f"{problem}_result.json"
    result.unlink(missing_ok=True)
    log = workdir / f"{problem}.log"
    cmd = [sys.executable, str(Path(__file__).resolve()), "--_worker", problem, "--out", str(workdir),
           "--_result", str(result)] + (["--_guess", str(guess)] if guess else [])
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        p = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=workdir, start_new_session=True)
        try:
            rc = p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)   # the child's own process group (IPOPT, MUMPS threads)
            p.wait()
            return {"problem": problem, "status": f"not converged within {timeout:.0f} s", "success": False,
                    "wall_seconds": time.perf_counter() - t0, "log": str(log), **_last_iterate(log)}
    wall = time.perf_counter() - t0
    if rc != 0 or not result.exists():
        tail = log.read_text(errors="replace").strip().splitlines()[-1:] or [""]
        return {"problem": problem, "status": f"child failed (exit {rc}): {tail[0]}", "success": False,
                "wall_seconds": wall, "log": str(log)}
    out = json.loads(result.read_text())
    out.update(wall_seconds=wall, log=str(log))
    return out


def reference_rms_deg(solution: Path, reference: Path) -> dict:
    """RMS (deg) of the half-cycle solution's angles against the reference half cycle, both over their
    own duration (0-100 %; the prediction's duration is free, the tracking's equals the reference's)."""
    import warnings

    import numpy as np

    import pinmsk
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")             # Moco's .sto headers carry extra keys
        sol = pinmsk.read_trial(solution, strict=False)
        ref = pinmsk.read_trial(reference, strict=False)
    out = {}
    for a in ANGLES:
        s = next((n for n in sol.names if n.endswith(f"/{a}/value")), None)
        r = next((n for n in ref.names if n.endswith(f"/{a}/value") or n == a), None)
        if s is None or r is None:
            continue
        ps = (sol.time - sol.time[0]) / (sol.time[-1] - sol.time[0])
        pr = (ref.time - ref.time[0]) / (ref.time[-1] - ref.time[0])
        d = np.asarray(sol[s]) - np.interp(ps, pr, np.asarray(ref[r]))
        out[a] = float(np.degrees(np.sqrt(np.mean(d ** 2))))
    return out


#: 2D_gait.osim muscle -> the gait2d muscle group it stands for (for the activation-EMG comparison)
MOCO_MUSCLES = {"glut_max": "glutei", "iliopsoas": "iliopsoas", "hamstrings": "hamstrings",
                "rect_fem": "rectus_femoris", "vasti": "vasti", "gastroc": "gastrocnemius", "soleus": "soleus",
                "tib_ant": "tibialis_anterior"}


def moco_stride_on_gait2d(full: Path, grf: Path):
    """Moco's full-stride solution as a gait2d stride Trial: coordinates by
    :func:`pinmsk.pipeline.opensim_to_gait2d` (Gait10dof18musc hip centre, knee + = extension in the
    OpenSim model), GRF ``r_ground_force_v{x,y}``, activations renamed to gait2d's groups."""
    import warnings

    import numpy as np

    import pinmsk
    from pinmsk.io.channel_map import GAIT10DOF_HIP_OFFSET
    from pinmsk.pipeline import opensim_to_gait2d
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = pinmsk.read_trial(full, strict=False)
        g = pinmsk.read_trial(grf, strict=False)
    model = pinmsk.load_model("gait2d")
    values = [n for n in sol.names if n.startswith("/jointset/") and n.endswith("/value")]
    kin = opensim_to_gait2d(sol.select(values), model, hip_offset=GAIT10DOF_HIP_OFFSET, knee_sign=-1)
    ch = {c: np.asarray(kin[c]) for c in kin.names}
    for s in "rl":
        for a in "xy":
            ch[f"{s}_ground_force_v{a}"] = np.interp(sol.time, g.time, np.asarray(g[f"ground_force_{s}_v{a}"]))
        for m, group in MOCO_MUSCLES.items():
            n = next((c for c in sol.names if c.endswith(f"/{m}_{s}/activation")), None)   # with or without /forceset
            if n is not None:
                ch[f"{group}_{s}_activation"] = np.asarray(sol[n])
    return pinmsk.Trial(sol.time, ch, meta={"source": str(full)})


def validate_moco(problem: str, r: dict, out: Path) -> dict | None:
    """Moco's stride against Winter, the measured walk and published values (pinmsk.gait_validation):
    the summary numbers, with the full JSON and an HTML report written under ``out``."""
    from pinmsk.gait_validation import validate_gait
    if not r.get("full_stride"):
        return None
    v = validate_gait(moco_stride_on_gait2d(Path(r["full_stride"]), Path(r["grf_full_stride"])),
                      label=f"Moco {problem}")
    v.to_json(out / f"{problem}_validation.json")
    try:
        v.write_report(out / f"{problem}_validation.html", figures_dir=out / f"{problem}_figures")
    except ImportError:                      # matplotlib absent: the numbers are still written
        pass
    n = v.numbers
    summary = {"joint_rms_deg": {ref: {j: round(x["rms_deg"], 2) for j, x in d.items() if j.endswith("_r")}
                                 for ref, d in n["joint_angles"].items()},
               "joint_correlation": {ref: {j: round(x["correlation"], 3) for j, x in d.items() if j.endswith("_r")}
                                     for ref, d in n["joint_angles"].items()},
               "grf_double_hump_r": n["grf"].get("simulation", {}).get("r"),
               "grf_rms_bw_pct": n["grf"].get("rms_bw_pct"),
               "emg_correlation_r": {m: x.get("correlation_r") for m, x in n.get("emg", {}).items()},
               "cadence_steps_per_min": n["spatiotemporal"]["cadence_steps_per_min"]["value"],
               "stride_length_m": n["spatiotemporal"]["stride_length_m"]["value"],
               "speed_m_per_s": n["speed_m_per_s"]}
    return summary


#: Moco's intervals: MocoTrack's default mesh_interval 0.02 s (ceil(0.470089 / 0.02) = 24) for the
#: tracking, the example's set_num_mesh_intervals(50) for the prediction; Hermite-Simpson (Moco's default)
MOCO_INTERVALS = {"tracking": 24, "predictive": 50}


def _contact_spheres(osim_path: Path) -> dict:
    """``{force name: sphere name}`` of the model's SmoothSphereHalfSpaceForces (contactHeel_r -> heel_r):
    Moco's contact groups name the forces, pinmsk's contacts carry their sphere's name."""
    import xml.etree.ElementTree as ET
    out = {}
    for el in ET.parse(osim_path).getroot().iter("SmoothSphereHalfSpaceForce"):
        out[el.get("name")] = el.findtext("socket_sphere").rsplit("/", 1)[-1]
    return out


def build_pinmsk(problem: str, model_dir: Path, *, intervals: int | None = None, guess=None, model=None):
    """The pinmsk Collocation of Moco's ``problem`` on 2D_gait.osim, with Moco's exact objective.

    Both: Moco's coordinate bounds (``setStateInfo`` -> :class:`ocp.Bounds`), the left/right symmetry of
    the MocoPeriodicityGoal (every ``_r`` coordinate, speed and activation ends at its ``_l`` twin's
    start and vice versa, the other coordinates and speeds periodic except pelvis_tx's value;
    :class:`ocp.Symmetric` + :class:`ocp.Periodic` of pelvis_tx's speed) and, as its
    ``addControlPair("/lumbarAct")``, the lumbar actuator's control periodic (``Symmetric(controls=)``),
    Hermite-Simpson.

    * tracking: ``10 ControlEffort(2)`` (MocoTrack's control_effort, weight 10, all 19 controls)
      ``+ StateTracking`` (all 10 coordinates' values and position derivatives, low-passed at 6 Hz,
      weight 1) ``+ ContactTracking`` (Right_GRF = contactHeel_r + contactFront_r, Left_GRF, plane
      projection, normal z, weight 1); the duration 0.470089 s; guess: the (filtered) reference
      coordinates, as MocoTrack's apply_tracked_states_to_guess.
    * predictive: ``10 ControlEffort(3, per="distance")``, average speed 1.2 m/s, free final time in
      [0.4, 0.6] s; guess ``guess`` (the bench passes pinmsk's own tracking solution, as Moco's example
      does), else the reference coordinates.
    """
    import warnings

    import numpy as np

    import pinmsk
    from pinmsk.solvers import ocp
    model_dir = Path(model_dir)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = model if model is not None else pinmsk.load_model(model_dir / "2D_gait.osim")
        ref = pinmsk.read_trial(model_dir / "referenceCoordinates.sto", strict=False)
    q = {p.split("/")[-2]: np.asarray(ref[p]) for p in ref.names if p.endswith("/value")}
    t = np.asarray(ref.time) - ref.time[0]
    bounds = ocp.Bounds(q={path.split("/")[-1]: (lo, hi) if path.endswith(("_tx", "_ty"))
                           else (math.radians(lo), math.radians(hi)) for path, (lo, hi) in BOUNDS.items()})
    pairs = {"hip_flexion_r": "hip_flexion_l", "knee_angle_r": "knee_angle_l", "ankle_angle_r": "ankle_angle_l"}
    from pinmsk.actuators import CoordinateActuator
    acts = tuple(c.name for c in m.components if isinstance(c, CoordinateActuator))   # /lumbarAct
    cons = [ocp.Symmetric(pairs, exclude=("pelvis_tx",), controls=acts),
            ocp.Periodic(states=("v",), exclude=tuple(c for c in m.coordinates if c != "pelvis_tx")), bounds]
    tracking = ocp.StateTracking(t, q, lowpass=6.0, position_derivatives=True)
    if problem == "tracking":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            grf = pinmsk.read_trial(model_dir / "referenceGRF.sto", strict=False)
        spheres = _contact_spheres(model_dir / "2D_gait.osim")
        tg = np.asarray(grf.time) - grf.time[0]
        groups = {label: (tuple(spheres[c] for c in CONTACTS[s]),
                          np.column_stack([np.asarray(grf[f"ground_force_{s}_v{a}"]) for a in "xyz"]))
                  for s, label in (("r", "Right_GRF"), ("l", "Left_GRF"))}
        cost = (10.0 * ocp.ControlEffort(2) + tracking
                + ocp.ContactTracking(groups, tg, projection="plane", vector=(0, 0, 1), name="contact"))
        duration, start = HALF_CYCLE, pinmsk.Trial(t, tracking.reference(t))
    else:
        cost = 10.0 * ocp.ControlEffort(3, per="distance", coordinate="pelvis_tx", name="effort")
        cons.append(ocp.AverageSpeed(SPEED, coordinate="pelvis_tx"))
        duration, start = (0.4, 0.6), guess if guess is not None else pinmsk.Trial(t, tracking.reference(t))
    return ocp.Collocation(m, cost=cost, constraints=cons, duration=duration,
                           intervals=intervals or MOCO_INTERVALS[problem], scheme="hermite-simpson", guess=start,
                           solver={"hessian": "limited-memory", "max_iter": 3000, "tol": 1e-4,
                                   "constraint_tol": 1e-4}, verbose=False)


def pinmsk_against_reference(r, model_dir: Path, mass: float) -> dict:
    """A pinmsk half cycle against referenceCoordinates.sto (RMS deg) and referenceGRF.sto (RMS % of
    body weight, fore-aft and vertical per side), both over 0-100 % of their own duration."""
    import warnings

    import numpy as np

    import pinmsk
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = pinmsk.read_trial(model_dir / "referenceCoordinates.sto", strict=False)
        grf = pinmsk.read_trial(model_dir / "referenceGRF.sto", strict=False)
    spheres = _contact_spheres(model_dir / "2D_gait.osim")
    t = np.asarray(r.time)
    ps = (t - t[0]) / (t[-1] - t[0])
    pr = (np.asarray(ref.time) - ref.time[0]) / (ref.time[-1] - ref.time[0])
    rms = {}
    for a in ANGLES:
        col = next(n for n in ref.names if n.endswith(f"/{a}/value"))
        rms[a] = float(np.degrees(np.sqrt(np.mean((np.asarray(r[a]) - np.interp(ps, pr, np.asarray(ref[col]))) ** 2))))
    bw = mass * 9.80665
    pg = (np.asarray(grf.time) - grf.time[0]) / (grf.time[-1] - grf.time[0])
    g_rms = {}
    for s in "rl":
        for k, a in enumerate("xy"):
            f = sum(np.asarray(r[f"smooth_sphere_half_space:{spheres[c]}_force_{a}"]) for c in CONTACTS[s])
            d = f - np.interp(ps, pg, np.asarray(grf[f"ground_force_{s}_v{a}"]))
            g_rms[f"{s}_v{a}"] = float(100.0 * np.sqrt(np.mean(d ** 2)) / bw)
    return {"reference_rms_deg": rms, "grf_rms_bw_pct": g_rms}


def moco_grf_rms(grf_full_stride: Path, model_dir: Path, final_time: float) -> dict:
    """RMS (% body weight) of Moco's half-cycle GRF (the first ``final_time`` s of its full-stride GRF
    table) against referenceGRF.sto, fore-aft and vertical per side, over 0-100 % of each."""
    import warnings

    import numpy as np

    import pinmsk
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = pinmsk.read_trial(grf_full_stride, strict=False)
        ref = pinmsk.read_trial(Path(model_dir) / "referenceGRF.sto", strict=False)
    t = np.asarray(g.time) - g.time[0]
    keep = t <= final_time + 1e-9
    ps = t[keep] / t[keep][-1]
    pr = (np.asarray(ref.time) - ref.time[0]) / (ref.time[-1] - ref.time[0])
    bw = 62.0 * 9.80665                        # 2D_gait.osim's mass (62 kg) times its gravity
    return {f"{s}_v{a}": float(100.0 * np.sqrt(np.mean((np.asarray(g[f"ground_force_{s}_v{a}"])[keep]
                                                        - np.interp(ps, pr, np.asarray(ref[f"ground_force_{s}_v{a}"])))
                                                       ** 2)) / bw)
            for s in "rl" for a in "xy"}


def run_pinmsk_score(solution: Path, grf: Path, model_dir: Path) -> dict | None:
    """:func:`moco_tracking_under_pinmsk` in a child process (the parent never imports casadi/opensim
    state of the other tool; this one needs only numpy, scipy and pinmsk)."""
    code = ("import json, sys; sys.path.insert(0, {root!r}); import importlib.util as u; "
            "s = u.spec_from_file_location('b', {me!r}); b = u.module_from_spec(s); s.loader.exec_module(b); "
            "from pathlib import Path; print(json.dumps(b.moco_tracking_under_pinmsk(Path({a!r}), Path({g!r}), "
            "Path({d!r}))))").format(root=str(Path(__file__).resolve().parents[1]), me=str(Path(__file__).resolve()),
                                     a=str(solution), g=str(grf), d=str(model_dir))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    lines = [x for x in proc.stdout.splitlines() if x.startswith("{")]
    return json.loads(lines[-1]) if proc.returncode == 0 and lines else None


def moco_tracking_under_pinmsk(solution: Path, grf: Path, model_dir: Path) -> dict:
    """Moco's tracking solution (its half-cycle .sto and OpenSim's GRF of it) scored by pinmsk's goals
    (:class:`ocp.ControlEffort`, :class:`ocp.StateTracking`, :class:`ocp.ContactTracking`: their
    weights, references, projection and normalisation) with Moco's Hermite-Simpson quadrature (Simpson
    over the mesh points and midpoints the .sto holds), in numpy: a cross-check that the goals are
    Moco's (the terms should be Moco's objective_* header values)."""
    import warnings

    import numpy as np

    import pinmsk
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = pinmsk.read_trial(solution, strict=False)
        g = pinmsk.read_trial(grf, strict=False)
    fit = build_pinmsk("tracking", model_dir, model=_LazyModel())
    terms = {t.name: t for t in fit.cost.terms()}
    t = np.asarray(sol.time) - sol.time[0]
    w = np.zeros(t.size)                        # Simpson: nodes at even rows, midpoints at odd rows
    h = t[2::2] - t[:-2:2]
    w[:-2:2] += h / 6
    w[2::2] += h / 6
    w[1::2] += 4 * h / 6
    controls = [n for n in sol.names if n.count("/") == 1]           # /lumbarAct, /hamstrings_r ...
    u = np.column_stack([np.asarray(sol[n]) for n in controls])
    out = {"control_effort": float(w @ np.sum(u ** 2, axis=1)), "controls": len(controls)}
    st = terms["state_tracking"]
    ref = st.reference(t)
    err = 0.0
    for key, y in ref.items():
        c, what = (key[:-6], "speed") if key.endswith("_speed") else (key, "value")
        col = next(n for n in sol.names if n.endswith(f"/{c}/{what}"))
        err = err + (np.asarray(sol[col]) - y) ** 2
    out["state_tracking"] = float(w @ err)
    ct = terms["contact"]
    tg = np.asarray(g.time) - g.time[0]
    e2 = 0.0
    for s, label in (("r", "Right_GRF"), ("l", "Left_GRF")):
        fr = ct._splines[label](t)
        fm = np.column_stack([np.interp(t, tg, np.asarray(g[f"ground_force_{s}_v{a}"])) for a in "xyz"])
        e2 = e2 + np.sum((fm - fr)[:, :2] ** 2, axis=1)                 # plane projection, normal z
    out["contact"] = float(w @ e2) / (62.0 * 9.80665)
    out["objective"] = 10.0 * out["control_effort"] + out["state_tracking"] + out["contact"]
    return out


class _LazyModel:
    """A stand-in model for building the goals only (they need the model when the problem is set up)."""
    coordinates = ()


def pinmsk_worker(problems, model_dir: Path, result: Path) -> int:
    """The pinmsk side in its own process (casadi; never opensim): each problem's objective in Moco's
    units (the same goals, weights and normalisations), its terms, times and the comparison with the
    reference data.  The prediction starts from this run's pinmsk tracking solution when there is one."""
    import numpy as np

    import pinmsk
    out, guess = {}, None
    t0 = time.perf_counter()
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = pinmsk.load_model(model_dir / "2D_gait.osim")
    t_load = time.perf_counter() - t0
    for p in problems:
        t1 = time.perf_counter()
        fit = build_pinmsk(p, model_dir, model=model, guess=guess if p == "predictive" else None)
        r = fit.fit().result_
        wall = time.perf_counter() - t1
        o = {"status": r.status, "success": bool(r.converged), "objective": float(r.objective),
             "terms": r.terms, "iterations": int(r.nit), "solve_seconds": float(r.seconds), "wall_seconds": wall,
             "load_seconds": t_load, "intervals": fit.intervals, "scheme": fit.scheme,
             "final_time": float(r.time[-1] - r.time[0]),
             "guess": "pinmsk's tracking solution of this run" if (p == "predictive" and guess is not None)
             else "the reference coordinates (low-passed at 6 Hz) and their derivatives"}
        o.update(pinmsk_against_reference(r, model_dir, float(sum(I.mass for I in model.pin.inertias))))
        for n in (n for n in r.names if n.endswith("_control")):   # Moco's symmetry also pairs /lumbarAct
            o[f"{n}_start_end"] = [float(r[n][0]), float(r[n][-1])]
        if p == "predictive":
            o["speed_m_per_s"] = float((r["pelvis_tx"][-1] - r["pelvis_tx"][0]) / o["final_time"])
        out[p] = o
        if p == "tracking" and r.converged:
            guess = r
        print(f"pinmsk {p}: {r.status}, objective {r.objective:.5g}, {r.nit} iterations, {wall:.1f} s",
              flush=True)
    result.write_text(json.dumps(out, indent=2, default=float))
    return 0


def run_pinmsk(problems, data_dir: Path | None = None, timeout: float = 1800.0) -> dict:
    """The pinmsk side of ``problems`` (see :func:`build_pinmsk`) in a child process (the parent may have
    imported opensim; casadi cannot load beside it): ``{problem: result dict}`` ({} if it failed)."""
    root = Path(__file__).resolve().parents[1]
    from pinmsk.io.shared_data import shared_data_dir
    model_dir = Path(data_dir or shared_data_dir()) / FOLDER
    result = Path(tempfile.mkdtemp(prefix="bench_gait_moco_pinmsk_")) / "pinmsk_result.json"
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(root))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--_pinmsk", ",".join(problems),
           "--data", str(model_dir.parents[1]), "--_result", str(result)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
    print(proc.stdout, end="")
    if proc.returncode or not result.exists():
        print(f"pinmsk side failed: {proc.stderr.strip().splitlines()[-1:]}")
        return {}
    return json.loads(result.read_text())


def _fmt(x, spec=".4g"):
    return "-" if x is None else format(x, spec) if isinstance(x, (int, float)) else str(x)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--moco-only", action="store_true", help="run the Moco side only")
    ap.add_argument("--pinmsk-only", action="store_true", help="run the pinmsk side only (no opensim needed)")
    ap.add_argument("--problems", default="tracking,predictive",
                    help="comma-separated subset of tracking,predictive")
    ap.add_argument("--timeout-tracking", type=float, default=900.0, help="s (default 900)")
    ap.add_argument("--timeout-predictive", type=float, default=600.0, help="s (default 600)")
    ap.add_argument("--predictive-guess", type=Path, default=None,
                    help="guess .sto of the prediction (default: this run's tracking solution, else Moco's)")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: a new temporary one)")
    ap.add_argument("--data", type=Path, default=None, help="shared data folder (default ../shared/data)")
    ap.add_argument("--_worker", choices=PROBLEMS, help=argparse.SUPPRESS)
    ap.add_argument("--_result", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--_guess", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--_pinmsk", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a._worker:
        return worker(a._worker, a.out, a._result, a._guess)
    if a._pinmsk:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        return pinmsk_worker(a._pinmsk.split(","), a.data / FOLDER, a._result)
    if a.moco_only and a.pinmsk_only:
        ap.error("--moco-only and --pinmsk-only exclude each other")

    problems = [p.strip() for p in a.problems.split(",") if p.strip()]
    bad = [p for p in problems if p not in PROBLEMS]
    if bad:
        ap.error(f"--problems: unknown {bad} (choose from {', '.join(PROBLEMS)})")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from pinmsk.io.shared_data import shared_data_dir
    data = a.data or shared_data_dir()
    src = None if data is None else Path(data) / FOLDER
    if src is None or not all((src / f).exists() for f in FILES):
        print(f"bench_gait_moco: {FOLDER} is absent (see its SOURCE.md); nothing to do")
        return 0
    probe = subprocess.run([sys.executable, "-c", "import opensim"], capture_output=True)
    if probe.returncode != 0 and not a.pinmsk_only:
        print("bench_gait_moco: opensim is not installed (pip install opensim); nothing to do")
        return 0
    out = a.out or Path(tempfile.mkdtemp(prefix="bench_gait_moco_"))
    out.mkdir(parents=True, exist_ok=True)
    for f in FILES:                          # OpenSim only ever sees this copy
        shutil.copy2(src / f, out / f)
    timeouts = {"tracking": a.timeout_tracking, "predictive": a.timeout_predictive}
    results = {}
    guess = a.predictive_guess.resolve() if a.predictive_guess else None
    if guess is not None and not guess.exists():
        ap.error(f"--predictive-guess: {guess} does not exist")
    for p in problems:
        results[p] = {}
        if a.pinmsk_only:
            continue
        print(f"Moco {p}: running (timeout {timeouts[p]:.0f} s) in {out} ...", flush=True)
        r = _run_child(p, out, timeouts[p], guess if p == "predictive" else None)
        if r.get("solution"):
            r["reference_rms_deg"] = reference_rms_deg(Path(r["solution"]), out / "referenceCoordinates.sto")
            r["grf_rms_bw_pct"] = moco_grf_rms(Path(r["grf_full_stride"]), out, r["final_time"])
            if p == "tracking":
                r["under_pinmsk_goals"] = run_pinmsk_score(Path(r["solution"]), Path(r["grf_full_stride"]), out)
            if p == "tracking" and a.predictive_guess is None:
                guess = Path(r["solution"])
            r["validation"] = validate_moco(p, r, out)
        results[p]["moco"] = r
        print(f"  status {r['status']}, success {r['success']}, objective {_fmt(r.get('objective'))}, "
              f"iterations {_fmt(r.get('iterations'))}, wall {r['wall_seconds']:.1f} s", flush=True)
    if not a.moco_only:
        print(f"pinmsk {', '.join(problems)}: running ...", flush=True)
        ours = run_pinmsk(problems, a.data)
        for p in problems:
            results[p]["pinmsk"] = ours.get(p)
            m, q = results[p].get("moco") or {}, results[p]["pinmsk"]
            if q and m.get("wall_seconds") and q.get("wall_seconds"):
                results[p]["ratio_moco_over_pinmsk"] = m["wall_seconds"] / q["wall_seconds"]
    (out / "moco_2d_walking.json").write_text(json.dumps(results, indent=2))
    print("\n| problem | tool | status | objective (Moco's units) | iterations | wall (s) | Moco/pinmsk time "
          "| max joint RMS vs reference (deg) | max GRF RMS (% BW) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for p, r in results.items():
        for tool in ("moco", "pinmsk"):
            x = r.get(tool)
            if not x:
                continue
            rms = x.get("reference_rms_deg") or {}
            g = x.get("grf_rms_bw_pct") or {}
            ratio = r.get("ratio_moco_over_pinmsk") if tool == "pinmsk" else None
            print(f"| {p} | {tool} | {x['status']} | {_fmt(x.get('objective'))} | {_fmt(x.get('iterations'))} | "
                  f"{x['wall_seconds']:.1f} | {_fmt(ratio, '.2f')} | {_fmt(max(rms.values()) if rms else None, '.2f')} "
                  f"| {_fmt(max(g.values()) if g else None, '.2f')} |")
    print(f"\nresults: {out / 'moco_2d_walking.json'}")
    return 0


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
