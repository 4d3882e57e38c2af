"""Static optimization on an imported OpenSim model: pinmsk against OpenSim's StaticOptimization, in one run.

    python benchmarks/bench_osim_so.py [--repeat 3] [--data DIR]

gait10dof18musc (``Working_with_Static_Optimization/subject01.osim`` with its
``gait10dof18musc_Strong_actuators.xml``: pelvis residuals FX, FY, MZ and coordinate reserves), the
subject01 IK walk (151 frames) and ``subject01_walk_grf.xml``, activation exponent 2:

* **OpenSim**: an AnalyzeTool with a StaticOptimization analysis (muscle physiology on, 6 Hz
  coordinate filter), its ``run()`` timed (model set-up, reading, filtering, solving and writing cannot
  be split).
* **pinmsk**: ``StaticOptimization(mode="activation", convention="opensim", actuators=...)`` on the
  imported model (exact knees, polynomial muscle paths; the import and the file reads are outside the
  timing: compute = filter, loads, inverse dynamics, the coordinate map, the QPs, the result Trial), with
  its own 6 Hz Butterworth filter on the coordinates and, as OpenSim, none on the loads.

It prints both times, the ratio, and the largest activation difference over OpenSim's frames (the
filters differ a little, so this is larger than the like-for-like test's: tests/test_osim_so.py).
Without ``../shared/data/opensim-models`` (or ``--data``) it says so and exits 0; without the optional
peer ``opensim`` it times pinmsk only.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_opensim as harness  # noqa: E402

from pinmsk.io.external_loads import read_external_loads  # noqa: E402
from pinmsk.io.shared_data import shared_data_dir  # noqa: E402
from pinmsk.io.tables import read_trial  # noqa: E402
from pinmsk.model import import_osim  # noqa: E402
from pinmsk.opensim.actuators import read_actuators  # noqa: E402
from pinmsk.solvers import StaticOptimization  # noqa: E402


def _best(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def opensim_so(osim, model_file: Path, actuators: Path, coordinates: Path, loads: Path, out: Path, span):
    """OpenSim's StaticOptimization over ``span``, silenced; (seconds of ``run()``, activation .sto path)."""
    with harness.quiet(osim):
        return harness.static_optimization_run(osim, model_file, coordinates, out, span=span, actuators=actuators,
                                               loads=loads)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--data", type=Path, default=None, help="the shared data folder (default ../shared/data)")
    args = ap.parse_args(argv)
    data = args.data or shared_data_dir()
    gait = None if data is None else Path(data) / "opensim-models" / "Gait10dof18musc"
    work = None if gait is None else gait / "Working_with_Static_Optimization"
    if work is None or not (work / "subject01.osim").is_file():
        print("bench_osim_so: ../shared/data/opensim-models/Gait10dof18musc is absent; nothing to time")
        return 0
    model, _ = import_osim(work / "subject01.osim")
    ik_path = gait / "IK" / "subject01_walk_IK.mot"
    ik = read_trial(ik_path)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # the ExternalLoads file names its data file relative to its own folder: give it an absolute one
        loads_xml = tmp / "grf.xml"
        loads_xml.write_text((gait / "ExperimentalData" / "subject01_walk_grf.xml").read_text().replace(
            "<datafile>subject01_walk_grf.mot</datafile>",
            f"<datafile>{gait / 'ExperimentalData' / 'subject01_walk_grf.mot'}</datafile>"))
        loads = read_external_loads(loads_xml)
        grf = read_trial(Path(loads.datafile), strict=False)       # files read once, outside the timing
        acts_file = work / "gait10dof18musc_Strong_actuators.xml"
        acts = read_actuators(acts_file, model)[0]

        def ours():
            return StaticOptimization(mode="activation", convention="opensim", actuators=list(acts)).fit(
                model, ik, cutoff=6.0, grf=grf, grf_cutoff=0, external_loads=loads).result_

        ours()         # warm-up: the first analysis of a process pays SciPy's signal import (~2 s), not timed
        t_ours, res = _best(ours, args.repeat)
        print(f"machine: {harness.machine()}")
        print(f"gait10dof18musc subject01 walk: {ik.n_frames} frames, {len(model.muscle_names)} muscles, "
              f"{len(acts)} actuators; best of {args.repeat}")
        print(f"SO compute, pinmsk (filter, loads, ID, map, QPs):  {1e3 * t_ours:8.1f} ms")
        osim, why = harness.import_opensim()
        if osim is None:
            print(f"OpenSim: {why}; its static optimization is not timed")
            return 0
        span = (float(ik.time[0]), float(ik.time[-1]))
        runs = [opensim_so(osim, work / "subject01.osim", acts_file, ik_path, loads_xml, tmp / f"os_{r}", span)
                for r in range(args.repeat)]
        t_os = min(r[0] for r in runs)
        ref = read_trial(runs[0][1])
    t = np.asarray(res.time)
    k = np.array([int(np.argmin(np.abs(t - x))) for x in np.asarray(ref.time)])
    inner = slice(3, -3)          # the two filters' edge handling differs on the first and last frames
    diff = max(float(np.max(np.abs(np.asarray(res[f"{m}_activation"])[k][inner] - np.asarray(ref[m])[inner])))
               for m in model.muscle_names)
    print(f"SO, OpenSim StaticOptimization (run):             {1e3 * t_os:8.1f} ms  -> pinmsk compute "
          f"{t_os / t_ours:.0f}x faster")
    print(f"max |activation difference| on OpenSim's {ref.n_frames} frames (ends skipped; pinmsk's own "
          f"filter): {diff:.4f}")
    return 0


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
