"""Dynamic optimization speed against the thesis (Sec. 3.3.6): one command, ratios from this run.

Thesis CPU times to the accepted optimum (GA + SQP + pattern search, MATLAB):
finger tapping 15 min, forearm with Fourier series 30 min, forearm with
polynomials 50 min; one model call 0.4 s (finger) and 0.9 s (forearm).

Run:  python benchmarks/bench_dynamic.py [--jobs 2] [--skip-polynomial] [--designs]

``--designs`` adds the robustness sweep of the inverse-forward designs (Sec. 5.1): IFM
and IFT on the forearm for J1-J5 with both parametrizations, and IFM finger tapping at
2-7 Hz, each from the automatic guesses (about 2.5 min).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))

import pinmsk  # noqa: E402
from pinmsk.solvers.dynamic import simulate_ff  # noqa: E402


def sim_time(model, T, steps, reps=5, tendon="rigid"):
    t = np.linspace(0, T, steps + 1)
    tm = 0.5 * (t[1:] + t[:-1])
    u = np.full((t.size, model.n_muscles), 0.1)
    um = np.full((tm.size, model.n_muscles), 0.1)
    simulate_ff(model, t, u, um, [0.3], [0.0], tendon=tendon)
    t0 = time.perf_counter()
    for _ in range(reps):
        simulate_ff(model, t, u, um, [0.3], [0.0], tendon=tendon)
    return (time.perf_counter() - t0) / reps


def main(argv=None):
    import finger_tapping as ft
    import forearm_dynamic_optimization as fa
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--skip-polynomial", action="store_true")
    ap.add_argument("--designs", action="store_true", help="IFM/IFT robustness sweep")
    args = ap.parse_args(argv)
    try:
        load = os.getloadavg()[0]
    except OSError:  # pragma: no cover
        load = float("nan")
    print(f"cores {os.cpu_count()}, load average {load:.2f}, multi-start workers {args.jobs}")
    finger = pinmsk.load_model("finger")
    forearm = pinmsk.load_model("forearm", moment_arms="angle")   # as the example (thesis Fig. 3.5)
    print(f"one FF simulation as the optimizer runs it: finger 6 Hz period (200 RK4 steps) "
          f"{1e3 * sim_time(finger, 1 / 6, 200):.1f} ms (thesis 400 ms); forearm 1.9 s (100 steps) "
          f"{1e3 * sim_time(forearm, 1.9, 100):.1f} ms (thesis 900 ms); with a compliant tendon "
          f"(IMEX) {1e3 * sim_time(finger, 1 / 6, 200, tendon='compliant'):.0f} / "
          f"{1e3 * sim_time(forearm, 1.9, 100, tendon='compliant'):.0f} ms")
    rows = []
    res, sec = ft.solve(finger, 6.0, jobs=args.jobs)
    rows.append(("finger tapping 6 Hz, 6th-order polynomials (14 par.)", sec, 15 * 60, 10, res))
    res, sec = fa.solve(forearm, "J4", "fourier", jobs=args.jobs)
    rows.append(("forearm J4, 11-term Fourier series (77 par.)", sec, 30 * 60, 60, res))
    if not args.skip_polynomial:
        res, sec = fa.solve(forearm, "J4", "polynomial", jobs=args.jobs)
        rows.append(("forearm J4, 10th-order polynomials (77 par.)", sec, 50 * 60, 60, res))
    print(f"{'problem':55s} {'seconds':>8s} {'thesis s':>9s} {'ratio':>7s} {'target':>7s}  result")
    for name, sec, thesis, target, res in rows:
        flag = "converged" if res.converged else "NOT CONVERGED"
        print(f"{name:55s} {sec:8.1f} {thesis:9d} {thesis / sec:6.0f}x {'<=' + str(target) + ' s':>7s}  "
              f"{flag}, J = {res.objective:.4g}, {res.nit} it.")
    if args.designs:
        design_sweep(forearm, finger, fa, jobs=args.jobs)
    return rows


def design_sweep(forearm, finger, fa, *, jobs):
    """IFM/IFT from the automatic guesses: converged or not, objective, seconds."""
    from pinmsk.solvers.dynamic import DynamicOptimization, Target
    from pinmsk.solvers.parametrization import Polynomial
    n_ok = n = 0
    print(f"{'design':6s} {'controls':10s} {'obj.':4s} {'J':>10s} {'seconds':>8s}  result")
    for design in ("ifm", "ift"):
        for kind in ("fourier", "polynomial"):
            for J in fa.OBJECTIVES:
                res, sec = fa.solve(forearm, J, kind, jobs=jobs, design=design)
                n, n_ok = n + 1, n_ok + res.converged
                print(f"{design:6s} {kind:10s} {J:4s} {res.objective:10.4g} {sec:8.1f}  "
                      f"{'converged' if res.converged else 'NOT CONVERGED: ' + res.status}")
    for hz in (2.0, 4.0, 5.0, 6.0, 7.0):
        T = 1.0 / hz
        prob = DynamicOptimization(
            finger, parametrization=Polynomial(6, duration=T), design="ifm",
            target=Target("sine", amplitude=0.21, frequency=hz), step=T / 200,
            objective={"kind": "effort", "exponent": 2, "normalize": False},
            tracking_weight=0.9, n_starts=3, n_jobs=jobs, tol=1e-6)
        t0 = time.perf_counter()
        res = prob.fit().result_
        n, n_ok = n + 1, n_ok + res.converged
        print(f"finger IFM {hz:3.0f} Hz: J {res.objective:.4g} (J2 {res.terms['tracking']:.3g}) "
              f"{time.perf_counter() - t0:6.1f} s  "
              f"{'converged' if res.converged else 'NOT CONVERGED: ' + res.status}")
    print(f"inverse-forward designs: {n_ok} of {n} problems converged from the automatic guesses")


if __name__ == "__main__":
    main()
