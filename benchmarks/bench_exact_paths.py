"""Exact muscle paths against their polynomial surrogates on Rajagopal's walking model: cost and error.

    python benchmarks/bench_exact_paths.py [--frames N]

The model is ``opensim-models/RajagopalWalk/subject_walk_scaled.osim`` (80 muscles, 46 cylinder
wraps), imported once before the clock starts.  The motion is a synthetic gait-like sweep of N frames
(default 101): every coordinate a sinusoid over the middle half of its OpenSim range.  On one BLAS
thread it prints

* the wall time of the muscles' lengths and moment arms at all frames from the exact paths
  (:func:`pinmsk.opensim.path_check.exact_path_kinematics`: one batch of body placements, every wrap
  solved for all frames at once, moment arms by central differences) and from the surrogates
  (``model.muscles.lengths`` and ``moment_arms``), and their ratio;
* the surrogates' largest errors at those frames (:func:`pinmsk.opensim.path_check.check_surrogates`).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=101)
    args = ap.parse_args(argv)
    from pinmsk.io.osim import read_osim
    from pinmsk.io.shared_data import shared_data_dir
    from pinmsk.model import import_osim
    from pinmsk.opensim.path_check import check_surrogates, exact_path_kinematics
    root = shared_data_dir()
    path = None if root is None else root / "opensim-models" / "RajagopalWalk" / "subject_walk_scaled.osim"
    if path is None or not path.is_file():
        print("RajagopalWalk not found in the shared data (set PINMSK_SHARED_DATA)", file=sys.stderr)
        return 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        model, _ = import_osim(path)
        t_import = time.perf_counter() - t0
    ranges = {c.name: c.range for c in read_osim(path).coordinates}
    t = np.linspace(0.0, 1.0, args.frames)
    q = np.zeros((t.size, model.nv))
    for k, c in enumerate(model.coordinates):
        lo, hi = ranges.get(c, (-0.1, 0.1))
        lo, hi = max(lo, -1.5), min(hi, 1.5)
        q[:, k] = 0.5 * (lo + hi) + 0.25 * (hi - lo) * np.sin(2 * np.pi * t + 0.7 * k)
    exact_path_kinematics(model, q[:2])             # first-call set-up outside the clock
    model.muscles.lengths(q[:2]), model.muscles.moment_arms(q[:2])
    t0 = time.perf_counter()
    exact_path_kinematics(model, q)
    t_exact = time.perf_counter() - t0
    t0 = time.perf_counter()
    model.muscles.lengths(q), model.muscles.moment_arms(q)
    t_poly = time.perf_counter() - t0
    check = check_surrogates(model, q)
    print(f"model: {path.name}, {model.n_muscles} muscles, {t.size} frames (import {t_import:.2f} s)")
    print(f"exact paths:  {t_exact * 1e3:9.1f} ms  ({t_exact / t.size * 1e3:.2f} ms per frame)")
    print(f"surrogates:   {t_poly * 1e3:9.1f} ms  ({t_poly / t.size * 1e3:.3f} ms per frame)")
    print(f"ratio exact / surrogate: {t_exact / t_poly:.1f}")
    print(check.line())
    return 0


if __name__ == "__main__":
    from _record import run
    raise SystemExit(run(main))
