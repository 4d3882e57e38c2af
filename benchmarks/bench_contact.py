"""Contact benchmarks: force evaluation (3 spheres x 1,000 frames) and the real-data identification.

    python benchmarks/bench_contact.py [--starts 4] [--jobs 2] [--skip-fit]

Targets (issue 6): <= 1 ms for the 1,000-frame evaluation, <= 60 s for the
hyper-volumetric identification on the real stance phase on 2 cores.  All
figures are measured in this run.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from pinmsk.components import Motion
from pinmsk.contact import ContactFit, foot_contacts, ground_reaction, load_foot2d, stance_cycle
from pinmsk.contact.foot import Foot2dGeometry, foot2d_site_kinematics
from pinmsk.skeleton import ExternalForce, external_generalized_force

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "csu-treadmill-leg2d" / "rawdata.txt"


def best_of(fn, repeat=7, number=20):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t) / number)
    return min(times)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--skip-fit", action="store_true")
    args = ap.parse_args(argv)

    model = load_foot2d()
    rng = np.random.default_rng(0)
    n = 1000
    q = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(0.03, 0.1, n), rng.uniform(-0.5, 0.5, n),
                         rng.uniform(-0.6, 0.3, n)])
    v = rng.normal(size=(n, 4))
    motion = Motion(np.arange(n) * 0.01, q, v, np.zeros_like(q))
    print(f"contact force evaluation, 3 spheres x {n} frames (foot2d)")
    for kind in ("point", "volumetric", "hypervolumetric"):
        cs = foot_contacts(model, kind)
        caches = [c.prepare(model, motion) for c in cs]

        def ev():
            return ground_reaction([c.evaluate_kinematics(k) for c, k in zip(cs, caches)])
        t = best_of(ev)
        print(f"  {kind:<16} forces + GRF/COP: {t * 1e3:7.3f} ms   (target <= 1 ms: {'OK' if t <= 1e-3 else 'MISSED'})")
    cs = foot_contacts(model, "hypervolumetric")
    geom = Foot2dGeometry.from_model(model)
    t_kin = best_of(lambda: foot2d_site_kinematics(geom, q, v))
    print(f"  analytic foot2d site kinematics (3 sites):      {t_kin * 1e3:7.3f} ms")
    t_prep = best_of(lambda: [c.prepare(model, motion) for c in cs], repeat=3, number=1)
    print(f"  Pinocchio kinematics + Jacobians (prepare, once): {t_prep * 1e3:7.2f} ms")
    caches = [c.prepare(model, motion) for c in cs]
    t_q = best_of(lambda: [c.generalized_force(model, motion, cache=k) for c, k in zip(cs, caches)])
    outs = [c.evaluate_kinematics(k) for c, k in zip(cs, caches)]
    ext = [ExternalForce(c.target, o.force, o.point) for c, o in zip(cs, outs)]
    t_rnea = best_of(lambda: external_generalized_force(model, q, ext), repeat=3, number=1)
    print(f"  generalized force J^T w (cached Jacobians):      {t_q * 1e3:7.3f} ms; "
          f"via RNEA with fext: {t_rnea * 1e3:.1f} ms (x{t_rnea / t_q:.0f})")

    if args.skip_fit:
        return
    if DATA.exists():
        from pinmsk.csu import read_csu
        trial = read_csu(DATA, body_mass=67.2)
        window = stance_cycle(trial)
        cutoff = 12.0
        what = f"real CSU cycle {window[0]:.2f}-{window[1]:.2f} s"
    else:
        from pinmsk.contact import synthetic_foot_trial
        trial, window, cutoff, what = synthetic_foot_trial(), None, None, "synthetic cycle (real data absent)"
    # the SVD inside scipy's 'trf' (LAPACK gesdd) on a Jacobian of this size, threaded vs one thread
    import scipy.linalg as sl
    from threadpoolctl import threadpool_limits
    a = np.random.default_rng(1).normal(size=(360, 29))
    t_thr = best_of(lambda: sl.svd(a, full_matrices=False), repeat=3, number=20)
    with threadpool_limits(limits=1):
        t_one = best_of(lambda: sl.svd(a, full_matrices=False), repeat=3, number=20)
    print(f"gesdd SVD 360 x 29 (one 'trf' iteration): BLAS threaded {t_thr * 1e3:.2f} ms, "
          f"threadpool_limits(1) {t_one * 1e3:.2f} ms (the fit runs with the latter)")
    for toe in ("kinematic", "fit"):
        fit = ContactFit(contact="hypervolumetric", window=window, cutoff=cutoff, n_starts=args.starts,
                         n_jobs=args.jobs, toe=toe).fit(None, trial)
        print(f"hyper-volumetric identification (toe={toe}, {fit.n_free_} free) on the {what}: {fit.seconds_:.1f} s "
              f"with {args.starts} starts on {args.jobs} processes ({os.cpu_count()} cores), {fit.nfev_} "
              f"evaluations, J = {fit.objective_:.4f} (target <= 60 s: {'OK' if fit.seconds_ <= 60 else 'MISSED'})")
        fit1 = ContactFit(contact="hypervolumetric", window=window, cutoff=cutoff, n_starts=1, toe=toe).fit(None, trial)
        print(f"  one start, serial: {fit1.seconds_:.1f} s, {fit1.nfev_} evaluations, J = {fit1.objective_:.4f}")


if __name__ == "__main__":
    main()
