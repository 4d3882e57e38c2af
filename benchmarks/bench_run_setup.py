"""``pinmsk run`` of an OpenSim setup against OpenSim's own tool on the same setup, each as a whole process.

    python benchmarks/bench_run_setup.py [--repeat 5] [--data DIR]

The setup is Gait10dof18musc's ``ID/walk_Setup_ID.xml`` as shipped (subject01.osim with its exact knee,
the IK walk of 151 frames, ``subject01_walk_grf.xml`` with two plates, 6 Hz low-pass), run

* by pinmsk: ``python -m pinmsk run walk_Setup_ID.xml --results-dir DIR``;
* by OpenSim: ``python -c "import opensim; ...InverseDynamicsTool(setup)...run()"`` (logging off),
  results in another folder.

Each figure is the wall time of the whole process (interpreter start, imports, the model read, the
files read, the filter, every frame, the file written), best and median of ``--repeat`` runs, the two
tools alternating so the machine's load falls on both alike; the ratio is OpenSim's time over
pinmsk's.  The two result files are compared too (RMS of the difference as % of each column's peak).
OpenSim (``pip install opensim``) is an optional peer: without it, or without
``../shared/data/opensim-models``, this script says so and exits 0.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

OPENSIM = """
import sys, opensim
opensim.Logger.removeFileSink()
opensim.Logger.setLevelString("Off")
tool = opensim.InverseDynamicsTool(sys.argv[1])
tool.setResultsDir(sys.argv[2])
assert tool.run()
"""


def _timed(argv, cwd) -> float:
    t0 = time.perf_counter()
    run = subprocess.run(argv, capture_output=True, text=True, cwd=cwd)
    dt = time.perf_counter() - t0
    if run.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, argv[:4]))} ... failed ({run.returncode}):\n{run.stderr[-2000:]}")
    return dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--data", default=None, help="the shared data folder (default: ../shared/data)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from pinmsk.io.shared_data import shared_data_dir

    data = Path(args.data) if args.data else shared_data_dir()
    setup = None if data is None else data / "opensim-models" / "Gait10dof18musc" / "ID" / "walk_Setup_ID.xml"
    if setup is None or not setup.is_file():
        print("bench_run_setup: ../shared/data/opensim-models/Gait10dof18musc is absent; nothing to time")
        return 0
    if subprocess.run([sys.executable, "-c", "import opensim"], capture_output=True).returncode != 0:
        print("bench_run_setup: opensim is not importable (pip install opensim); nothing to compare with")
        return 0

    import numpy as np

    from pinmsk.io.tables import read_trial

    with tempfile.TemporaryDirectory() as tmp:
        ours_dir, theirs_dir = Path(tmp) / "pinmsk", Path(tmp) / "opensim"
        ours_cmd = [sys.executable, "-m", "pinmsk", "run", str(setup), "--results-dir", str(ours_dir)]
        theirs_cmd = [sys.executable, "-c", OPENSIM, str(setup), str(theirs_dir)]
        # OpenSim's tool opens <model_file> from the working directory (its other paths from the setup's
        # folder): it runs where ../subject01.osim is the model, a folder of the temporary one
        cwd = Path(tmp) / "work" / "ID"
        cwd.mkdir(parents=True)
        (cwd.parent / "subject01.osim").symlink_to(setup.parent.parent / "subject01.osim")
        _timed(ours_cmd, ROOT), _timed(theirs_cmd, cwd)        # warm the file cache once
        ours, theirs = [], []
        for _ in range(args.repeat):
            ours.append(_timed(ours_cmd, ROOT))
            theirs.append(_timed(theirs_cmd, cwd))
        a = read_trial(ours_dir / "subject01_walk_ID.sto")
        b = read_trial(theirs_dir / "subject01_walk_ID.sto")
    if a.names != b.names or a.n_frames != b.n_frames:
        raise SystemExit(f"the results differ in layout: {a.n_frames} x {a.names} against {b.n_frames} x {b.names}")
    err = {n: 100 * float(np.sqrt(np.mean((np.asarray(a[n]) - np.asarray(b[n])) ** 2)) / np.max(np.abs(b[n])))
           for n in b.names}
    worst = max(err, key=err.get)
    print(f"Gait10dof18musc ID/walk_Setup_ID.xml, {a.n_frames} frames, {args.repeat} runs each, whole processes")
    print(f"  pinmsk run                     best {min(ours):.3f} s  median {statistics.median(ours):.3f} s")
    print(f"  OpenSim InverseDynamicsTool    best {min(theirs):.3f} s  median {statistics.median(theirs):.3f} s")
    print(f"  ratio (OpenSim / pinmsk)       best {min(theirs) / min(ours):.2f}x  "
          f"median {statistics.median(theirs) / statistics.median(ours):.2f}x")
    print(f"  results: largest RMS difference {err[worst]:.3f} % of the peak ({worst}); "
          f"{', '.join(f'{n} {e:.3f}' for n, e in err.items())}")
    return 0


if __name__ == "__main__":
    from _record import run
    raise SystemExit(run(main))
