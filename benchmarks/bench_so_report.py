"""``pinmsk so ... --report --plot`` against the same run without them, as whole processes.

    python benchmarks/bench_so_report.py [--repeat 1] [--data DIR] [--frames N]

RajagopalWalk (``opensim-models/RajagopalWalk/subject_walk_scaled.osim``, 80 muscles) on the walk of
``real/opensim-moco-walk-emg`` (``coordinates.sto``, its ``grf_walk.xml``, ``electromyography.sto``
beside it), reserves on: the bare run writes the activations only; the reported run adds ``--report``
and ``--plot``.  Each command is a fresh interpreter, timed by its wall clock (best of ``--repeat``)
after one untimed run that fills the import cache.  It prints both times and their ratio against the
target of 1.3 (a report must not multiply the run time).  Without the shared data it says so and
exits 0.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TARGET = 1.3


def _run(args, env) -> float:
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "pinmsk", *map(str, args)], env=env, cwd=REPO,
                         capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"pinmsk {' '.join(map(str, args))} failed ({res.returncode}): {res.stderr[-2000:]}")
    return dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--data", type=Path, default=None, help="the shared data folder (default ../shared/data)")
    args = ap.parse_args(argv)
    from pinmsk.io.shared_data import shared_data_dir
    data = args.data or shared_data_dir()
    raj = None if data is None else Path(data) / "opensim-models" / "RajagopalWalk"
    walk = None if data is None else Path(data) / "real" / "opensim-moco-walk-emg"
    if raj is None or not (raj / "subject_walk_scaled.osim").is_file() or not (walk / "coordinates.sto").is_file():
        print("bench_so_report: RajagopalWalk or real/opensim-moco-walk-emg is absent; nothing to time")
        return 0
    with tempfile.TemporaryDirectory(prefix="pinmsk-bench-so-report-") as tmp:
        tmp = Path(tmp)
        env = dict(os.environ, PINMSK_CACHE_DIR=str(tmp / "cache"),
                   PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        xml = (raj / "grf_walk.xml").read_text().replace(
            "<datafile>grf_walk.mot</datafile>", f"<datafile>{walk / 'grf_walk.mot'}</datafile>")
        (tmp / "grf_walk.xml").write_text(xml)
        bare = [raj / "subject_walk_scaled.osim", walk / "coordinates.sto", "--external-loads",
                tmp / "grf_walk.xml", "--reserves", "--lenient", "--missing-coordinates", "default",
                "-o", tmp / "so.sto"]
        full = bare + ["--report", tmp / "so.html", "--plot", tmp / "figures"]
        _run(["so", *bare], env)                          # fills the import cache
        t_bare = min(_run(["so", *bare], env) for _ in range(args.repeat))
        t_full = min(_run(["so", *full], env) for _ in range(args.repeat))
        size = (tmp / "so.html").stat().st_size
        print(f"pinmsk so on RajagopalWalk (best of {args.repeat}; {os.cpu_count()} cores, "
              f"load {os.getloadavg()[0]:.1f})")
        print(f"  bare run               {t_bare:7.2f} s")
        print(f"  --report --plot        {t_full:7.2f} s   ratio {t_full / t_bare:.2f} (target <= {TARGET})")
        print(f"  report size            {size / 1e6:7.2f} MB")
    return 0


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
