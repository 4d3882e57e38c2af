"""IK -> ID -> SO on the 1.35 s Rajagopal walking trial mapped onto gait2d (1,350 frames at 1 kHz).

    python benchmarks/bench_pipeline.py [--repeat 3] [--data DIR]

One core: BLAS/OpenMP threads are limited to 1 before numpy is imported.  The chain timed:

1. IK: gait2d's CSU markers (both sides, 12 markers, x-y) generated from the mapped coordinates
   (``pinmsk.pipeline.opensim_to_gait2d``) -- the measured Rajagopal markers are 3-D on another
   model's bodies, so IK from them onto gait2d is not a like-for-like fit -- then
   ``InverseKinematics`` on all 1,350 frames (Levenberg-Marquardt, warm-started);
2. ID: inverse dynamics with the two-plate GRF (``grf_walk.mot`` resampled to 1 kHz, COP moved to
   gait2d's ankles) on the IK result;
3. SO: ``StaticOptimization(mode="activation", exponent=2, reserves=True)`` on the ID moments.

File reading is timed separately.  Target: IK + ID + SO <= 2 s.  If ``opensim`` is importable its
InverseDynamicsTool and StaticOptimization (AnalyzeTool) are timed on Gait10dof18musc's
subject01 walk (from ``../shared/data/opensim-models``) and the ratio printed: the models and
trials differ (3-D 10-dof/18-muscle vs 2-D 11-dof/16-muscle; different frame counts), so the ratio
is per frame as well as per trial, and it is indicative only.  ``pip install opensim`` provides it; the harness (a
temporary copy of the model folder, OpenSim's output suppressed, the SO setup) is
``benchmarks/bench_opensim.py``, which also compares equal frame counts (Arm26 / forearm,
subject01 / gait2d) and separates compute from model loading and file I/O.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import pinmsk  # noqa: E402
from pinmsk.io.shared_data import shared_data_dir  # noqa: E402
from pinmsk.grf import external_forces  # noqa: E402
from pinmsk.ik import InverseKinematics, markers_trial  # noqa: E402
from pinmsk.markers import load_marker_set, read_trc  # noqa: E402
from pinmsk.pipeline import opensim_to_gait2d, transferred_cops  # noqa: E402
from pinmsk.solvers.static import StaticOptimization  # noqa: E402

TARGET_S = 2.0


def prepare(folder: Path):
    t0 = time.perf_counter()
    model = pinmsk.load_model("gait2d")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        coords = pinmsk.read_trial(folder / "coordinates.sto", strict=False)
        grf = pinmsk.read_trial(folder / "grf_walk.mot", strict=False)
    trc = read_trc(folder / "markers_walk.trc", warn=False)
    t_read = time.perf_counter() - t0
    kin_ref = opensim_to_gait2d(coords, model)
    grf = grf.resample(kin_ref.time, method="linear", antialias=True)
    mset = load_marker_set("gait2d")
    mset = mset.subset(list(mset.sets["csu"]) + list(mset.sets["csu_left"]))
    q_ref = kin_ref.get(model.coordinates)
    mk = markers_trial(model, mset, kin_ref.time, q_ref, axes="xy")
    return model, kin_ref, grf, trc, mset, mk, t_read


def chain(model, grf, trc, mset, mk):
    t0 = time.perf_counter()
    ik = InverseKinematics(markers=mset, axes="xy", q0={"torso_y": 1.0}).fit(model, mk)
    kin = ik.result_
    t1 = time.perf_counter()
    cops = transferred_cops(model, kin, grf, trc, {"r": "R.Ankle", "l": "L.Ankle"})
    ext = external_forces(model, grf, planar=True, cop=cops)
    idt = pinmsk.inverse_dynamics(model, kin, external=ext)
    t2 = time.perf_counter()
    so = StaticOptimization(mode="activation", exponent=2, reserves=True).fit(model, kin, moments=idt)
    t3 = time.perf_counter()
    return {"ik": t1 - t0, "id": t2 - t1, "so": t3 - t2, "total": t3 - t0}, ik, idt, so


def _opensim_harness():
    """benchmarks/bench_opensim.py as a module (the OpenSim harness shared by both benchmarks)."""
    import importlib.util

    path = Path(__file__).resolve().with_name("bench_opensim.py")
    spec = importlib.util.spec_from_file_location("bench_opensim", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def opensim_timing(models_dir: Path, repeat: int = 1):
    """(id_s, so_s, id_frames, so_frames, version) of OpenSim's tools on Gait10dof18musc, or a reason string.

    ID: ``ID/walk_Setup_ID.xml`` (two-plate GRF, 6 Hz); SO: AnalyzeTool + StaticOptimization
    (activation exponent 2, muscle physiology, the tutorial's strong reserve actuators), both run
    on a copy of the model folder in a temporary directory with OpenSim's output suppressed
    (see ``bench_opensim.py``).  Times are best of ``repeat`` and cover constructing the tool from
    its setup XML and ``run()``; frame counts are the rows OpenSim wrote.
    """
    bo = _opensim_harness()
    osim, why = bo.import_opensim()
    if osim is None:
        return f"{why} -- no OpenSim timing"
    g = models_dir / "Gait10dof18musc"
    if not g.is_dir():
        return f"{g} is absent -- no OpenSim timing"
    try:
        with tempfile.TemporaryDirectory(prefix="bench_pipeline_osim_") as tmp:
            tmp = Path(tmp)
            gait = bo.stage(g, tmp / "Gait10dof18musc")
            t_id, sto = min((bo.opensim_id(osim, gait / "ID" / "walk_Setup_ID.xml", results=tmp / f"id{r}")
                             for r in range(max(1, repeat))), key=lambda x: x[0])
            n_id = bo.read_sto(sto)[1].shape[0]
            _, ik = bo.read_sto(gait / "IK" / "subject01_walk_IK.mot")
            setup = bo.gait_so_setup(osim, gait, tmp / "so_setup.xml", t0=float(ik[0, 0]), t1=float(ik[-1, 0]))
            t_so, act, _ = min((bo.opensim_so(osim, setup, results=tmp / f"so{r}") for r in range(max(1, repeat))),
                               key=lambda x: x[0])
            n_so = bo.read_sto(act)[1].shape[0]
        return t_id, t_so, n_id, n_so, osim.__version__
    except Exception as exc:  # noqa: BLE001 - a benchmark reports
        return f"OpenSim timing failed: {type(exc).__name__}: {exc}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--data", default=None)
    a = p.parse_args(argv)
    d = Path(a.data) if a.data else shared_data_dir()
    folder = None if d is None else d / "real" / "opensim-moco-walk-emg"
    if folder is None or not folder.is_dir():
        print("bench_pipeline: ../shared/data/real/opensim-moco-walk-emg is absent; nothing to time")
        return 0
    model, kin_ref, grf, trc, mset, mk, t_read = prepare(folder)
    runs = [chain(model, grf, trc, mset, mk) for _ in range(max(1, a.repeat))]
    best = {k: min(r[0][k] for r in runs) for k in runs[0][0]}
    _, ik, idt, so = runs[-1]
    n = mk.n_frames
    idx = [model.coordinate_index(c) for c in ik.free_coordinates_]
    qerr = float(np.max(np.abs(ik.q_[:, idx] - kin_ref.get(model.coordinates)[:, idx])))
    print(f"pinmsk IK -> ID -> SO, gait2d, {n} frames ({kin_ref.time[-1] - kin_ref.time[0]:.3f} s at "
          f"{1 / np.median(np.diff(kin_ref.time)):.0f} Hz), one core, best of {len(runs)}:")
    print(f"  read files         {t_read * 1e3:8.1f} ms (not in the chain)")
    print(f"  IK (12 markers)    {best['ik'] * 1e3:8.1f} ms  ({best['ik'] / n * 1e6:.1f} us/frame, mean "
          f"{ik.iterations_.mean():.2f} iterations, max |q - q_ref| {qerr:.1e})")
    print(f"  ID (2 plates)      {best['id'] * 1e3:8.1f} ms  ({best['id'] / n * 1e6:.1f} us/frame)")
    print(f"  SO (16 muscles)    {best['so'] * 1e3:8.1f} ms  ({best['so'] / n * 1e6:.1f} us/frame)")
    print(f"  chain total        {best['total'] * 1e3:8.1f} ms  target <= {TARGET_S * 1e3:.0f} ms: "
          f"{'PASS' if best['total'] <= TARGET_S else 'FAIL'}")
    ot = opensim_timing(d / "opensim-models", repeat=max(1, a.repeat))
    if isinstance(ot, str):
        print(f"  {ot}")
    else:
        t_id, t_so, n_id, n_so, version = ot
        ours_id, ours_so = best["id"], best["so"]
        print(f"  OpenSim {version} tools (Gait10dof18musc subject01 walk, "
              f"a different 3-D model and trial; tool = setup XML -> run(), best of {max(1, a.repeat)}):")
        print(f"    InverseDynamicsTool {t_id * 1e3:8.1f} ms for {n_id} frames -> ratio per frame "
              f"{(t_id / n_id) / (ours_id / n):.1f}x (pinmsk faster if > 1; the tool time includes model "
              "loading and file I/O, pinmsk's does not -- bench_opensim.py separates the two)")
        print(f"    StaticOptimization  {t_so * 1e3:8.1f} ms for {n_so} frames -> ratio per frame "
              f"{(t_so / n_so) / (ours_so / n):.1f}x (OpenSim's SO includes its own ID)")
    return 0 if best["total"] <= TARGET_S else 1


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
