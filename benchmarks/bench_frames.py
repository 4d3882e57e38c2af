"""Cost per frame and peak memory of ID and SO on an imported OpenSim model, from 1e3 to 1e6 frames.

    python benchmarks/bench_frames.py           # 1e3, 1e4, 1e5 and 1e6 frames (minutes; about 1 GB)
    python benchmarks/bench_frames.py --quick   # 1e3, 1e4, 1e5 frames

The model is Gait10dof18musc's ``subject01.osim`` (exact knee, 18 muscles with polynomial paths),
imported once into a temporary import cache before the clock starts (its muscle paths fitted).  The
motion is its ``IK/subject01_walk_IK.mot`` walk repeated to N frames at 60 Hz (the seams' jumps are
filtered like the rest).  Each case runs in its own process, on one BLAS thread:

* **ID**: :func:`pinmsk.dynamics.inverse_dynamics` of the trial (6 Hz low-pass, spline derivatives,
  RNEA, moments in OpenSim's coordinates), no external loads;
* **SO**: :class:`pinmsk.solvers.static.StaticOptimization` over the six hip/knee/ankle flexions
  (force mode, P = 2) on the motion of the same trial, solved in chunks of
  :data:`pinmsk.solvers.static.CHUNK_FRAMES` frames.

Printed: microseconds per frame of the call (wall; both code paths' imports done before, by a 300- and a
6,000-frame run) and the process's peak resident memory (VmHWM) above what it held before the call, per case, and the ratio of the per-frame costs to the smallest
size's (flat = 1).  Targets: per-frame costs flat from 1e3 to 1e6; at most 1 GB at 1e6 frames.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, sys, time, warnings
warnings.simplefilter("ignore")
import numpy as np
from pinmsk.io.tables import read_trial
from pinmsk.model import import_osim
from pinmsk.trial import Trial

def peak_kb():
    with open("/proc/self/status") as fh:
        return next(int(l.split()[1]) for l in fh if l.startswith("VmHWM:"))

what, n, gait = sys.argv[1], int(sys.argv[2]), sys.argv[3]
model, _ = import_osim(gait + "/subject01.osim")
model.muscles.path.degree                    # read from the import cache (fitted before)
walk = read_trial(gait + "/IK/subject01_walk_IK.mot", angular=set(model.rotational_coordinates))

def repeated(n):
    idx = np.arange(n) % walk.n_frames
    return Trial(np.arange(n) / 60.0, {c: np.asarray(walk[c])[idx] for c in walk.names if c != "time"})

def run(trial):
    if what == "id":
        from pinmsk.dynamics import inverse_dynamics
        return float(np.nansum(inverse_dynamics(model, trial, cutoff=6.0, ground_reaction="ignore").values))
    from pinmsk.kinematics import motion
    from pinmsk.solvers.static import StaticOptimization
    mo = motion(model, trial, cutoff=6.0)
    so = StaticOptimization(dofs=["hip_flexion_r", "knee_angle_r", "ankle_angle_r", "hip_flexion_l",
                                  "knee_angle_l", "ankle_angle_l"], reserves=True).fit(model, mo)
    return float(np.nansum(so.forces_))

for warm in (300, 6000):          # the imports of the short- and long-trial code paths, off the clock
    run(repeated(warm))
trial = repeated(n)
del walk
before = peak_kb()
t0 = time.perf_counter()
check = run(trial)
dt = time.perf_counter() - t0
print(json.dumps({"us": dt / n * 1e6, "peak_mb": (peak_kb() - before) / 1e3, "total_mb": peak_kb() / 1e3,
                  "check": check}))
"""


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    sys.path.insert(0, str(REPO))
    from pinmsk.io.shared_data import shared_data_dir
    data = shared_data_dir()
    gait = None if data is None else Path(data) / "opensim-models" / "Gait10dof18musc"
    if gait is None or not (gait / "subject01.osim").is_file():
        print("bench_frames: ../shared/data/opensim-models is absent; nothing to time")
        return 0
    sizes = [1_000, 10_000, 100_000] + ([] if "--quick" in argv else [1_000_000])
    with tempfile.TemporaryDirectory(prefix="pinmsk-bench-frames-") as tmp:
        env = dict(os.environ, PINMSK_CACHE_DIR=tmp, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", PYTHONPATH=os.pathsep.join([str(REPO)] + [os.environ.get("PYTHONPATH", "")]))
        env.pop("PINMSK_NO_CACHE", None)
        prime = ("import warnings; warnings.simplefilter('ignore'); from pinmsk.model import import_osim; "
                 f"import_osim({str(gait / 'subject01.osim')!r})[0].muscles.path.degree")
        subprocess.run([sys.executable, "-c", prime], env=env, check=True)
        print("Cost per frame and peak memory, Gait10dof18musc subject01 (18 muscles, polynomial paths), one "
              "BLAS thread, each case its own process")
        print(f"  {'':4} {'frames':>10} {'us/frame':>10} {'vs smallest':>12} {'peak above start':>17} {'process':>10}")
        for what in ("id", "so"):
            first = None
            for n in sizes:
                done = subprocess.run([sys.executable, "-c", _CHILD, what, str(n), str(gait)], env=env,
                                      capture_output=True, text=True)
                if done.returncode != 0:
                    print(f"  {what:4} {n:>10,} failed: {done.stderr.strip().splitlines()[-1:]}")
                    continue
                r = json.loads(done.stdout.strip().splitlines()[-1])
                first = r["us"] if first is None else first
                print(f"  {what.upper():4} {n:>10,} {r['us']:10.1f} {r['us'] / first:11.2f}x {r['peak_mb']:13.0f} MB "
                      f"{r['total_mb']:7.0f} MB")
    return 0


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
