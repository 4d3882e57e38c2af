"""Throughput of OpenSim's InverseDynamicsTool / StaticOptimization against pinmsk, in one run.

    python benchmarks/bench_opensim.py [--repeat 3] [--data DIR]

OpenSim (``pip install opensim``) is an optional peer here, never a pinmsk dependency: without it,
or without ``../shared/data/opensim-models`` (see its SOURCE.md), this script says so and exits 0.

What is timed (best of ``--repeat`` runs, one core: BLAS/OpenMP threads are limited to 1):

* **OpenSim, on its own models and data**, run from Python on a copy of the model folder in a
  temporary directory (setup paths rewritten to it, OpenSim's logging and console output
  suppressed).  "Tool" time = construct the tool from its setup XML + ``run()``: the model is
  loaded, the files read, the coordinates low-pass filtered (6 Hz) and differentiated, every
  frame solved and the results written.

  - Arm26 (2 dof, 6 Thelen2003 muscles): ``arm26_Setup_InverseDynamics.xml`` and
    ``arm26_Setup_StaticOptimization.xml`` (AnalyzeTool + StaticOptimization, activation
    exponent 2, muscle physiology on) on ``arm26_InverseKinematics.mot`` (121 frames).
  - Gait10dof18musc (subject01.osim, 10 dof, 18 muscles): ``ID/walk_Setup_ID.xml`` with the
    two-plate GRF, and an AnalyzeTool + StaticOptimization setup written here (the tutorial ships
    no SO setup) with ``Working_with_Static_Optimization/gait10dof18musc_Strong_actuators.xml``
    (residual + reserve actuators) appended, on ``IK/subject01_walk_IK.mot`` (151 frames).

* **pinmsk, on the most comparable built-in models**, same frame counts and the same 6 Hz cutoff:

  - ``forearm`` (1 dof, 7 Thelen2003 muscles) driven by Arm26's ``r_elbow_flex``;
  - ``gait2d`` (11 dof planar, 16 muscles) driven by the subject01 walk mapped with
    ``pinmsk.pipeline.opensim_to_gait2d`` (hip centre = subject01's pelvis offset) and the same
    GRF (planar, measured COP);
  - ID = ``pinmsk.inverse_dynamics``; SO = ``StaticOptimization(mode="activation", exponent=2)``
    (gait2d: ``reserves=True``, as OpenSim's run has reserve actuators) on those moments.
    "compute" = filter + differentiate + solve (SO: ID + SO, because OpenSim's SO does its own
    inverse dynamics); "end to end" adds model loading, file reading and writing an .sto, like
    the OpenSim tool times.

The models differ (joints, segment parameters, muscle paths, 3-D vs planar), so the ratios are a
throughput comparison (frames per second on comparable problems), **not** a like-for-like
validation.  The physics cross-check lives in ``tests/test_opensim_peer.py`` (a pendulum built in
both).  Sanity of the OpenSim runs: Arm26's ID output is compared with the repository's
``reference_outputs`` (must agree to ~1e-6), its SO forces are checked to balance OpenSim's own ID
moments through OpenSim's moment arms, and the SO reference outputs are compared and reported.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import platform  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import pinmsk  # noqa: E402
from pinmsk.io.shared_data import shared_data_dir  # noqa: E402

#: Cutoff (Hz) of every setup used here (the Arm26 and Gait10dof18musc setups all say 6 Hz).
CUTOFF = 6.0

#: Hip joint centre in subject01's pelvis frame (x, y; m): ``hip_r``'s ``pelvis_offset``
#: translation in ``Gait10dof18musc/subject01.osim`` (-0.0724378, -0.0677247, 0.0855524).
SUBJECT01_HIP_OFFSET = (-0.0724378, -0.0677247)

#: Arm26 ID reference: the setup filters at 6 Hz and writes to FilteredResults.
ARM26_ID_REFERENCE = "InverseDynamics_Filtered"
ARM26_SO_REFERENCE = "StaticOptimization_Physiological"


# ---------------------------------------------------------------------------
# Locating things
# ---------------------------------------------------------------------------

def import_opensim():
    """``(opensim module, None)`` or ``(None, reason)``."""
    try:
        import opensim
    except ImportError as exc:
        return None, f"opensim is not importable ({exc}); install it with `pip install opensim`"
    return opensim, None


# ---------------------------------------------------------------------------
# OpenSim harness
# ---------------------------------------------------------------------------

@contextlib.contextmanager
def quiet(osim):
    """Silence OpenSim: its logger off (no opensim.log) and C++ stdout/stderr sent to /dev/null.

    ``AnalyzeTool`` prints the model summary with ``std::cout``, which no logger setting stops,
    so file descriptors 1 and 2 are redirected while OpenSim runs.
    """
    osim.Logger.setLevelString("Off")
    with contextlib.suppress(Exception):
        osim.Logger.removeFileSink()
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


def stage(src: Path, dst: Path) -> Path:
    """Copy a model folder (without ``reference_outputs`` or a stray ``opensim.log`` another run left
    there) to ``dst``; OpenSim runs there."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("reference_outputs", "opensim.log"))
    return dst


def read_sto(path) -> tuple[list[str], np.ndarray]:
    """Column names and data of an OpenSim .sto/.mot (a reader independent of pinmsk's)."""
    lines = Path(path).read_text().splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    names = lines[end + 1].split()
    data = np.loadtxt(lines[end + 2:], ndmin=2)
    return names, data


def compare_sto(ours, reference) -> tuple[float, float]:
    """(max |ours - reference|, max |reference|) over all columns matched by name (time included).

    The same column names (in any order: OpenSim versions order ID outputs differently) and row
    count are required.
    """
    n1, a = read_sto(ours)
    n2, b = read_sto(reference)
    if sorted(n1) != sorted(n2) or a.shape != b.shape:
        raise ValueError(f"{ours} has columns {n1} and shape {a.shape}; {reference} has {n2}, {b.shape}")
    a = a[:, [n1.index(n) for n in n2]]
    return float(np.max(np.abs(a - b))), float(np.max(np.abs(b[:, 1:])))


def opensim_id(osim, setup: Path, *, cutoff: float | None = None, results: Path,
               time_range=None, preload_model: bool = False) -> tuple[float, Path]:
    """Run an InverseDynamicsTool setup with every path made absolute; (seconds, output .sto).

    The setup's model, coordinates and external-loads paths are resolved against the setup's
    folder (as OpenSim does), the results go to ``results``.  The time covers constructing the
    tool and ``run()`` (model loading, reading, filtering, solving, writing); with ``preload_model``
    the model is read from its file before the clock starts and handed to the tool (``setModel``), as
    pinmsk's side is timed on a model already imported.
    """
    setup = Path(setup).resolve()
    base = setup.parent
    with quiet(osim):
        model = None
        if preload_model:
            probe = osim.InverseDynamicsTool(str(setup))
            model = osim.Model(str((base / probe.getModelFileName().strip()).resolve()))
        t0 = time.perf_counter()
        tool = osim.InverseDynamicsTool(str(setup))
        tool.setModelFileName(str((base / tool.getModelFileName().strip()).resolve()))
        if model is not None:
            tool.setModel(model)        # the tool keeps a pointer: ``model`` stays alive to the end
        tool.setCoordinatesFileName(str((base / tool.getCoordinatesFileName().strip()).resolve()))
        ext = tool.getExternalLoadsFileName().strip()
        if ext and ext != "Unassigned":
            tool.setExternalLoadsFileName(str((base / ext).resolve()))
        if cutoff is not None:
            tool.setLowpassCutoffFrequency(float(cutoff))
        if time_range is not None:
            tool.setStartTime(float(time_range[0]))
            tool.setEndTime(float(time_range[1]))
        tool.setResultsDir(str(results))
        ok = tool.run()
        dt = time.perf_counter() - t0
    if not ok:
        raise RuntimeError(f"OpenSim InverseDynamicsTool failed on {setup}")
    return dt, Path(results) / tool.getOutputGenForceFileName().strip()


def opensim_so(osim, setup: Path, *, results: Path) -> tuple[float, Path, Path]:
    """Run an AnalyzeTool setup holding a StaticOptimization; (seconds, activation .sto, force .sto).

    Model, coordinates and external-loads paths are resolved against the setup's folder.  Timed:
    constructing the tool from the XML (which loads the model and its force-set files) + ``run()``.
    """
    setup = Path(setup).resolve()
    base = setup.parent
    cwd = os.getcwd()
    os.chdir(base)  # the AnalyzeTool constructor resolves model/force-set files against the cwd
    try:
        with quiet(osim):
            t0 = time.perf_counter()
            tool = osim.AnalyzeTool(str(setup))
            tool.setResultsDir(str(results))
            ok = tool.run()
            dt = time.perf_counter() - t0
    finally:
        os.chdir(cwd)
    if not ok:
        raise RuntimeError(f"OpenSim AnalyzeTool (static optimization) failed on {setup}")
    name = tool.getName()
    return (dt, Path(results) / f"{name}_StaticOptimization_activation.sto",
            Path(results) / f"{name}_StaticOptimization_force.sto")


def static_optimization_run(osim, model_path, coordinates, out: Path, *, span, actuators=None, loads=None,
                            physiological: bool = True, cutoff: float = 6.0) -> tuple[float, Path]:
    """OpenSim's StaticOptimization (an AnalyzeTool built in Python, activation exponent 2, the model's
    force set plus the ``actuators`` force set file) on ``span`` of ``coordinates`` low-passed at
    ``cutoff``, results in ``out``; returns (seconds of ``tool.run()``, the activation .sto)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    model = osim.Model(str(model_path))
    if actuators is not None:
        fs = osim.ForceSet(str(actuators))
        for i in range(fs.getSize()):
            model.updForceSet().cloneAndAppend(fs.get(i))
    model.initSystem()
    tool = osim.AnalyzeTool()
    tool.setModel(model)
    tool.setLoadModelAndInput(True)
    tool.setName("so")
    tool.setCoordinatesFileName(str(coordinates))
    tool.setLowpassCutoffFrequency(cutoff)
    tool.setInitialTime(span[0])
    tool.setFinalTime(span[1])
    tool.setResultsDir(str(out))
    if loads is not None:
        tool.setExternalLoadsFileName(str(loads))
    so = osim.StaticOptimization()
    so.setStartTime(span[0])
    so.setEndTime(span[1])
    so.setUseModelForceSet(True)
    so.setActivationExponent(2.0)
    so.setUseMusclePhysiology(physiological)
    model.addAnalysis(so)
    t0 = time.perf_counter()
    ok = tool.run()
    dt = time.perf_counter() - t0
    if not ok:
        raise RuntimeError(f"OpenSim's AnalyzeTool (static optimization) failed on {model_path}")
    return dt, out / "so_StaticOptimization_activation.sto"


def gait_so_setup(osim, folder: Path, path: Path, *, t0: float, t1: float) -> Path:
    """Write an AnalyzeTool + StaticOptimization setup for the subject01 walk (absolute paths)."""
    tool = osim.AnalyzeTool()
    tool.setName("subject01_walk")
    tool.setModelFilename(str(folder / "subject01.osim"))
    files = osim.ArrayStr()
    files.append(str(folder / "Working_with_Static_Optimization" / "gait10dof18musc_Strong_actuators.xml"))
    tool.setForceSetFiles(files)
    tool.setReplaceForceSet(False)
    tool.setCoordinatesFileName(str(folder / "IK" / "subject01_walk_IK.mot"))
    tool.setExternalLoadsFileName(str(folder / "ExperimentalData" / "subject01_walk_grf.xml"))
    tool.setLowpassCutoffFrequency(CUTOFF)
    tool.setInitialTime(t0)
    tool.setFinalTime(t1)
    so = osim.StaticOptimization()
    so.setName("StaticOptimization")
    so.setStartTime(t0)
    so.setEndTime(t1)
    so.setUseModelForceSet(True)
    so.setActivationExponent(2.0)
    so.setUseMusclePhysiology(True)
    tool.getAnalysisSet().cloneAndAppend(so)
    tool.printToXML(str(path))
    return path


def so_moment_balance(osim, model_file: Path, coords_file: Path, id_file: Path, force_file: Path) -> float:
    """max_k,j |sum_i r_ij(q_k) F_ik - tau_jk| / max |tau_j| of an OpenSim SO run on a muscle-only model.

    Moment arms from OpenSim (``Muscle.computeMomentArm``) at the IK coordinates, forces from the
    SO force file, moments from OpenSim's ID (same cutoff), rows matched by time.
    """
    qn, q_deg = read_sto(coords_file)
    fn, F = read_sto(force_file)
    tn, tau = read_sto(id_file)
    with quiet(osim):
        model = osim.Model(str(model_file))
        state = model.initSystem()
    cs = model.getCoordinateSet()
    muscles = model.getMuscles()
    worst = 0.0
    for j in range(cs.getSize()):
        c = cs.get(j)
        col = tn.index(f"{c.getName()}_moment")
        scale = float(np.max(np.abs(tau[:, col])))
        resid = []
        for k in range(F.shape[0]):
            row = int(np.argmin(np.abs(q_deg[:, 0] - F[k, 0])))
            for jj in range(cs.getSize()):
                cs.get(jj).setValue(state, np.deg2rad(q_deg[row, qn.index(cs.get(jj).getName())]), False)
            model.assemble(state)
            model.realizePosition(state)
            m = sum(muscles.get(i).computeMomentArm(state, c) * F[k, fn.index(muscles.get(i).getName())]
                    for i in range(muscles.getSize()))
            krow = int(np.argmin(np.abs(tau[:, 0] - F[k, 0])))
            resid.append(m - tau[krow, col])
        worst = max(worst, float(np.max(np.abs(resid))) / scale)
    return worst


def run_opensim(osim, models: Path, tmp: Path, repeat: int) -> dict:
    """Time OpenSim on Arm26 and Gait10dof18musc; sanity-check Arm26 against its references."""
    out: dict = {}
    arm = stage(models / "Arm26", tmp / "Arm26")
    ref = models / "Arm26" / "reference_outputs"
    times = []
    for r in range(repeat):
        dt, sto = opensim_id(osim, arm / "arm26_Setup_InverseDynamics.xml", results=tmp / f"arm_id_{r}")
        times.append(dt)
    out["arm_id"] = (min(times), read_sto(sto)[1].shape[0])
    out["arm_id_check"] = compare_sto(sto, ref / ARM26_ID_REFERENCE / "arm26_InverseDynamics.sto")
    _, sto_u = opensim_id(osim, arm / "arm26_Setup_InverseDynamics.xml", cutoff=-1.0, results=tmp / "arm_id_u")
    out["arm_id_check_unfiltered"] = compare_sto(sto_u, ref / "InverseDynamics_Unfiltered"
                                                 / "arm26_InverseDynamics.sto")
    times = []
    for r in range(repeat):
        dt, act, frc = opensim_so(osim, arm / "arm26_Setup_StaticOptimization.xml", results=tmp / f"arm_so_{r}")
        times.append(dt)
    out["arm_so"] = (min(times), read_sto(act)[1].shape[0])
    ref_act = ref / ARM26_SO_REFERENCE / "arm26_StaticOptimization_activation.sto"
    out["arm_so_vs_reference"] = compare_sto(act, ref_act)
    a_ours, a_ref = read_sto(act)[1][:, 1:], read_sto(ref_act)[1][:, 1:]
    out["arm_so_floor"] = (float(np.min(a_ours)), int(np.sum(a_ref < 0.0099)), a_ref.size)
    out["arm_so_balance"] = so_moment_balance(osim, arm / "arm26.osim", arm / "arm26_InverseKinematics.mot", sto, frc)

    gait = stage(models / "Gait10dof18musc", tmp / "Gait10dof18musc")
    times = []
    for r in range(repeat):
        dt, sto = opensim_id(osim, gait / "ID" / "walk_Setup_ID.xml", results=tmp / f"gait_id_{r}")
        times.append(dt)
    out["gait_id"] = (min(times), read_sto(sto)[1].shape[0])
    gref = models / "Gait10dof18musc" / "reference_outputs" / "ID" / "subject01_walk_ID.sto"
    if gref.is_file():
        out["gait_id_check"] = compare_sto(sto, gref)
    _, ik = read_sto(gait / "IK" / "subject01_walk_IK.mot")
    setup = gait_so_setup(osim, gait, tmp / "gait_so_setup.xml", t0=float(ik[0, 0]), t1=float(ik[-1, 0]))
    times = []
    for r in range(repeat):
        dt, act, _ = opensim_so(osim, setup, results=tmp / f"gait_so_{r}")
        times.append(dt)
    out["gait_so"] = (min(times), read_sto(act)[1].shape[0])
    return out


# ---------------------------------------------------------------------------
# pinmsk side
# ---------------------------------------------------------------------------

def _read(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pinmsk.read_trial(path, strict=False, **kw)


def forearm_kinematics(model, ik: pinmsk.Trial) -> pinmsk.Trial:
    """forearm's ``elbow_flexion`` from Arm26's ``r_elbow_flex`` (both 0 = extended, + = flexion)."""
    return pinmsk.Trial(ik.time, {"elbow_flexion": np.asarray(ik["r_elbow_flex"], dtype=float)})


def uniform_grf(grf: pinmsk.Trial) -> pinmsk.Trial:
    """The GRF on its nominal uniform time base (subject01's file rounds 1/600 s steps to 4 decimals)."""
    rate = round((grf.n_frames - 1) / float(grf.time[-1] - grf.time[0]))
    t = grf.time[0] + np.arange(grf.n_frames) / rate
    if np.max(np.abs(t - grf.time)) > 1e-4:
        raise ValueError("the GRF time stamps are not a rounded uniform grid")
    return pinmsk.Trial(t, {n: np.asarray(grf[n]) for n in grf.names}, meta=dict(grf.meta))


def gait2d_inputs(model, ik: pinmsk.Trial, grf: pinmsk.Trial):
    """(kinematics, external forces) of the subject01 walk on gait2d."""
    from pinmsk.grf import external_forces
    from pinmsk.pipeline import opensim_to_gait2d

    # gait10dof18musc, like gait2392, counts knee flexion negative (range [-120, 10] deg);
    # opensim_to_gait2d's knee_sign="auto" detects that and flips it
    kin = opensim_to_gait2d(ik, model, hip_offset=SUBJECT01_HIP_OFFSET, knee_sign="auto")
    g = uniform_grf(grf).resample(kin.time, method="linear", antialias=True)
    # subject01_walk_grf.xml: ground_force_* -> calcn_r, 1_ground_force_* -> calcn_l
    ext = external_forces(model, g, planar=True, frames={None: "foot_r", "1": "foot_l"})
    return kin, ext


def pinmsk_id(model, kin, ext):
    return pinmsk.inverse_dynamics(model, kin, cutoff=CUTOFF, external=ext)


def pinmsk_so(model, kin, ext, *, reserves: bool):
    from pinmsk.solvers.static import StaticOptimization

    idt = pinmsk_id(model, kin, ext)
    return StaticOptimization(mode="activation", exponent=2, reserves=reserves).fit(
        model, kin, moments=idt, cutoff=CUTOFF)


def _best(fn, repeat):
    best, result = np.inf, None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def run_pinmsk(models: Path, tmp: Path, repeat: int) -> dict:
    """Compute-only and end-to-end timings of pinmsk's ID and SO on forearm and gait2d."""
    out: dict = {}
    arm_ik = models / "Arm26" / "arm26_InverseKinematics.mot"
    g = models / "Gait10dof18musc"
    gait_ik, gait_grf = g / "IK" / "subject01_walk_IK.mot", g / "ExperimentalData" / "subject01_walk_grf.mot"
    tmp.mkdir(parents=True, exist_ok=True)

    fa = pinmsk.load_model("forearm")
    kin = forearm_kinematics(fa, _read(arm_ik))
    pinmsk_so(fa, kin, (), reserves=False)  # warm-up (imports, caches)
    out["arm_id"] = (_best(lambda: pinmsk_id(fa, kin, ()), repeat)[0], kin.n_frames)
    t, so = _best(lambda: pinmsk_so(fa, kin, (), reserves=False), repeat)
    out["arm_so"] = (t, kin.n_frames)
    out["arm_so_violation"] = float(np.max(so.violation_))

    def arm_e2e(with_so):
        m = pinmsk.load_model("forearm")
        k = forearm_kinematics(m, _read(arm_ik))
        res = pinmsk_so(m, k, (), reserves=False).result_ if with_so else pinmsk_id(m, k, ())
        pinmsk.write_trial(res, tmp / "forearm.sto")
    out["arm_id_e2e"] = _best(lambda: arm_e2e(False), repeat)[0]
    out["arm_so_e2e"] = _best(lambda: arm_e2e(True), repeat)[0]

    gm = pinmsk.load_model("gait2d")
    kin, ext = gait2d_inputs(gm, _read(gait_ik), _read(gait_grf))
    pinmsk_so(gm, kin, ext, reserves=True)
    out["gait_id"] = (_best(lambda: pinmsk_id(gm, kin, ext), repeat)[0], kin.n_frames)
    t, so = _best(lambda: pinmsk_so(gm, kin, ext, reserves=True), repeat)
    out["gait_so"] = (t, kin.n_frames)
    out["gait_so_reserve_frames"] = int(np.sum(so.status_ == 2))

    def gait_e2e(with_so):
        m = pinmsk.load_model("gait2d")
        k, e = gait2d_inputs(m, _read(gait_ik), _read(gait_grf))
        res = pinmsk_so(m, k, e, reserves=True).result_ if with_so else pinmsk_id(m, k, e)
        pinmsk.write_trial(res, tmp / "gait2d.sto")
    out["gait_id_e2e"] = _best(lambda: gait_e2e(False), repeat)[0]
    out["gait_so_e2e"] = _best(lambda: gait_e2e(True), repeat)[0]
    return out


# ---------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------

def machine(osim=None) -> str:
    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    import pinocchio

    parts = [f"{cpu}, {os.cpu_count()} logical CPUs (1 thread used)", f"{platform.system()} {platform.release()}",
             f"Python {platform.python_version()}", f"numpy {np.__version__}", f"pinocchio {pinocchio.__version__}",
             f"pinmsk {getattr(pinmsk, '__version__', '?')}"]
    if osim is not None:
        parts.append(f"opensim {osim.__version__}")
    return "; ".join(parts)


def table(o: dict, p: dict) -> list[str]:
    rows = [
        ("ID", "Arm26 (2 dof, 6 mus.)", o["arm_id"], "forearm (1 dof, 7 mus.)", p["arm_id"], p["arm_id_e2e"]),
        ("SO", "Arm26 (2 dof, 6 mus.)", o["arm_so"], "forearm (1 dof, 7 mus.)", p["arm_so"], p["arm_so_e2e"]),
        ("ID", "Gait10dof18musc + GRF", o["gait_id"], "gait2d (11 dof, 16 mus.)", p["gait_id"], p["gait_id_e2e"]),
        ("SO", "Gait10dof18musc + GRF", o["gait_so"], "gait2d (11 dof, 16 mus.)", p["gait_so"], p["gait_so_e2e"]),
    ]
    lines = [f"{'':3} {'OpenSim model':23} {'frames':>6} {'tool fr/s':>10}   {'pinmsk model':24} {'frames':>6} "
             f"{'compute fr/s':>12} {'e2e fr/s':>9}   {'ratio compute':>13} {'ratio e2e':>9}"]
    for what, om, (ot, on), pm, (pt, pn), pe in rows:
        ofs, pfs, pes = on / ot, pn / pt, pn / pe
        lines.append(f"{what:3} {om:23} {on:6d} {ofs:10.0f}   {pm:24} {pn:6d} {pfs:12.0f} {pes:9.0f}   "
                     f"{pfs / ofs:12.1f}x {pes / ofs:8.1f}x")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--data", default=None)
    a = ap.parse_args(argv)
    osim, why = import_opensim()
    if osim is None:
        print(f"bench_opensim: {why} -- nothing to compare")
        return 0
    d = Path(a.data) if a.data else shared_data_dir()
    models = None if d is None else d / "opensim-models"
    if models is None or not (models / "Arm26").is_dir() or not (models / "Gait10dof18musc").is_dir():
        print("bench_opensim: ../shared/data/opensim-models (Arm26, Gait10dof18musc) is absent -- nothing to compare")
        return 0
    with tempfile.TemporaryDirectory(prefix="bench_opensim_") as tmp:
        tmp = Path(tmp)
        o = run_opensim(osim, models, tmp / "opensim", a.repeat)
        p = run_pinmsk(models, tmp / "pinmsk", a.repeat)
    print(f"OpenSim {osim.__version__} vs pinmsk: frames per second, best of {a.repeat}, one core")
    print(f"machine: {machine(osim)}")
    print("THE MODELS DIFFER (OpenSim's own 3-D models vs pinmsk's built-in forearm / planar gait2d): this is a")
    print("throughput comparison on comparable problems, not a like-for-like validation.")
    print("OpenSim 'tool' = setup XML -> run(): load model, read, filter 6 Hz, solve, write .sto.  pinmsk 'compute' =")
    print("filter 6 Hz + differentiate + solve (SO = ID + SO); 'e2e' adds load_model, read_trial, write_trial.")
    print("ratio = pinmsk frames/s / OpenSim frames/s (> 1: pinmsk faster).")
    for line in table(o, p):
        print("  " + line)
    err, scale = o["arm_id_check"]
    err_u, scale_u = o["arm_id_check_unfiltered"]
    print("sanity of the OpenSim runs:")
    print(f"  Arm26 ID (setup, 6 Hz) vs reference_outputs/{ARM26_ID_REFERENCE}: max |diff| {err:.1e} "
          f"(max |tau| {scale:.3g} N m) -> {'OK' if err <= 1e-6 * max(1.0, scale) else 'MISMATCH'}; "
          f"unfiltered vs InverseDynamics_Unfiltered: {err_u:.1e}")
    if "gait_id_check" in o:
        ge, gs = o["gait_id_check"]
        print(f"  Gait10dof18musc ID vs reference_outputs/ID: max |diff| {ge:.1e} (max |tau| {gs:.4g})")
    print(f"  Arm26 SO forces balance OpenSim's ID moments (OpenSim moment arms): max residual "
          f"{o['arm_so_balance']:.1e} of max |tau|")
    se, ss = o["arm_so_vs_reference"]
    amin, nlow, ntot = o["arm_so_floor"]
    print(f"  Arm26 SO activations vs reference_outputs/{ARM26_SO_REFERENCE}: max |diff| {se:.3f} "
          f"(max activation {ss:.3f}) -- NOT reproduced: the reference (an older OpenSim) has {nlow} of {ntot}")
    print(f"    activations below 0.01; OpenSim 4.6's Thelen2003Muscle bounds a >= minimum_activation = 0.01 "
          f"(it refuses lower values), our run's smallest is {amin:.4f}, so SO's solution shifts.")
    print(f"pinmsk: forearm SO max moment violation {p['arm_so_violation']:.1e} N m; gait2d SO used reserves "
          f"in {p['gait_so_reserve_frames']} of {p['gait_so'][1]} frames")
    return 0


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
