"""Contact benchmarks: force evaluation (3 spheres x 1,000 frames) and the real-data identification.

    python benchmarks/bench_contact.py [--skip-fit]

Targets: <= 1 ms for the 1,000-frame evaluation, <= 60 s for the
hyper-volumetric identification on the real stance phase on 2 cores.  The
identification is timed with the defaults of ``pinmsk contact fit`` and, in the
same run, with what they replaced: the finite-difference Jacobian
(``jacobian="2-point"``) against the exact one, one start against the multi-start
with the simpler models' optima, serial against two processes.  All figures are
measured in this run (wall time; the machine may be shared).
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from pinmsk.components import Motion
from pinmsk.contact import ContactFit, foot_contacts, ground_reaction, load_foot2d
from pinmsk.contact.foot import Foot2dGeometry, foot2d_site_kinematics
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.skeleton import ExternalForce, external_generalized_force

_SHARED = shared_data_dir()
DATA = (_SHARED / "real" / "csu-treadmill-leg2d" / "rawdata.txt") if _SHARED else Path("/nonexistent")


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
        from pinmsk.contact import read_csu_foot2d
        trial, opts = read_csu_foot2d(DATA, body_mass=67.2), {}
        what = "the real CSU cycle"
    else:
        from pinmsk.contact import synthetic_foot_trial
        trial, opts, what = synthetic_foot_trial(), {"cutoff": None}, "the synthetic cycle (real data absent)"
    # the SVD inside scipy's 'trf' (LAPACK gesdd) on a Jacobian of this size, threaded vs one thread
    import scipy.linalg as sl
    from threadpoolctl import threadpool_limits
    a = np.random.default_rng(1).normal(size=(360, 18))
    t_thr = best_of(lambda: sl.svd(a, full_matrices=False), repeat=3, number=20)
    with threadpool_limits(limits=1):
        t_one = best_of(lambda: sl.svd(a, full_matrices=False), repeat=3, number=20)
    print(f"gesdd SVD 360 x 18 (one 'trf' iteration): BLAS threaded {t_thr * 1e3:.2f} ms, "
          f"threadpool_limits(1) {t_one * 1e3:.2f} ms (the fit runs with the latter)")

    from scipy.optimize._numdiff import approx_derivative
    res = ContactFit(n_starts=1, max_nfev=1, **opts).fit(None, trial).residual_
    x = res.to_x(res.p0)
    with threadpool_limits(limits=1):
        t_fun = best_of(lambda: res(x), number=10)
        t_exact = best_of(lambda: res.jacobian(x), number=10)
        t_fd = best_of(lambda: approx_derivative(res, x, method="2-point", rel_step=1e-6), repeat=3, number=3)
    print(f"Eq. 4.2 residual of the hyper-volumetric fit on {what} ({res.prob.t.size} frames, {x.size} free): "
          f"{t_fun * 1e3:.2f} ms; Jacobian exact (Dual numbers) {t_exact * 1e3:.2f} ms, finite differences "
          f"{t_fd * 1e3:.2f} ms (x{t_fd / t_exact:.1f})")

    def run(label, **kw):
        fit = ContactFit(**opts, **kw).fit(None, trial)
        print(f"  {label:<52} {fit.seconds_:6.2f} s  {fit.nfev_:5d} evaluations  J = {fit.objective_:.5f}")
        return fit

    print(f"hyper-volumetric identification on {what} ({os.cpu_count()} cores; target <= 60 s):")
    run("one start, finite-difference Jacobian", n_starts=1, jacobian="2-point")
    run("one start, exact Jacobian", n_starts=1)
    run("4 starts, no nested starts, exact", nested=False)
    run("defaults (4 starts incl. vol/point optima), finite diff.", jacobian="2-point")
    best = run("defaults (4 starts incl. vol/point optima), exact")
    run("defaults, 2 processes", n_jobs=2)
    run("defaults, toe='fit' (29 free)", toe="fit")
    print("  starts of the default fit: " + "; ".join(
        f"{lab} -> {j:.5f}" for lab, j in zip(best.start_labels_, best.starts_)))
    print("  nested fits: " + ", ".join(f"{k} J = {f.objective_:.5f}" for k, f in best.nested_.items()))


if __name__ == "__main__":
    from _record import run
    run(main)
