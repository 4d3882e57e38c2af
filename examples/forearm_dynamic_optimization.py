"""Forearm dynamic optimization with Fourier-series and polynomial excitations (thesis Sec. 3.3).

The 1-dof elbow with seven Thelen muscles (Table 3.2), moment arms as functions of
the elbow angle as in the thesis (Fig. 3.5; ``--moment-arms constant`` for Table 3.5's
constant arms), tracks a flexion-extension
cycle of 1.9 s within 0.1 rad (tracking constraint Eq. 3.7) with ``0 <= u <= 1``
(Eq. 3.8).  Each excitation is an 11-term Fourier series (Eq. 3.4, K = 5,
77 parameters), then a 10th-order polynomial (Eq. 3.2, 77 parameters), then -- the
local baseline -- a clamped cubic B-spline with 11 coefficients (77 parameters).
Objectives (Table 3.3): J1 (S = 1, P = 2), J2 (S = 1, P = 3), J3 (S = V, P = 2),
J4 (S = V, P = 3) of Eq. 3.5 and J5, metabolic energy Eq. 3.6 with the
Umberger 2003 heat rates (App. B.2), started from the J4 and J1 optima.  Then
J4 with Fourier series in each simulation design of Sec. 5.1: fully forward
with a rigid or a compliant tendon, inverse-forward from muscle forces (IFM)
and from the elbow torque (IFT).  For J5 the optimizer sees the heat-rate model with C1-smoothed switches (width 0.01,
``pinmsk.energy``); the reported objective is the exact piecewise model.

The measured average motion of the thesis (Fig. 3.6) is not available; the target
is the smooth cycle ``0.3 + 0.8 (1 - cos(2 pi t / 1.9))`` rad (0.3 -> 1.9 -> 0.3 rad).

Run:  python examples/forearm_dynamic_optimization.py --out out/forearm  [--quick]
      [--moment-arms angle|constant]
Writes forearm_do.json (per objective and parametrization; "designs": J4 per design)
and PNG figures.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import pinmsk
from pinmsk.solvers.dynamic import DynamicOptimization, Target
from pinmsk.solvers.parametrization import Fourier, Polynomial, Spline

PERIOD = 1.9
TOL = 0.1
PARAMETRIZATIONS = ("fourier", "polynomial", "spline")   # global (Sec. 3.1) and the local baseline
OBJECTIVES = {
    "J1": {"kind": "effort", "exponent": 2, "weights": "none"},
    "J2": {"kind": "effort", "exponent": 3, "weights": "none"},
    "J3": {"kind": "effort", "exponent": 2, "weights": "volume"},
    "J4": {"kind": "effort", "exponent": 3, "weights": "volume"},
    "J5": {"kind": "metabolic", "model": "umberger2003"},
}


def target():
    return Target("cycle", amplitude=1.6, period=PERIOD, offset=0.3)


def solve(model, objective, kind, *, jobs=2, steps=100, n_starts=2, maxiter=400, x0=None,
          design="ff", tendon="rigid", budget_factor=1.0):
    """One problem of Table 3.3.  100 RK4 steps of 19 ms: the result's integration check
    (against twice as many steps) is ~3e-5 rad, against the 0.1 rad tolerance; bounds and
    tracking are imposed at every grid point."""
    par = {"fourier": lambda: Fourier(5, period=PERIOD),
           "polynomial": lambda: Polynomial(10, duration=PERIOD),
           "spline": lambda: Spline(11, duration=PERIOD)}[kind]()   # 11 coefficients per muscle each
    prob = DynamicOptimization(model, parametrization=par, target=target(), step=PERIOD / steps,
                               objective=OBJECTIVES[objective], tracking_tolerance=TOL,
                               n_starts=n_starts, n_jobs=jobs, maxiter=maxiter, tol=1e-7,
                               bound_points=steps + 1, tracking_points=steps + 1, design=design,
                               tendon=tendon, budget_factor=budget_factor)
    t0 = time.perf_counter()
    res = prob.fit(x0).result_
    return res, time.perf_counter() - t0


def plot_excitations(panels, path):
    """One panel of excitations per ``(name, result)``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(len(panels), 1, figsize=(8, 2.2 * len(panels)), sharex=True,
                           squeeze=False)
    for a, (name, r) in zip(ax[:, 0], panels):
        for i, n in enumerate(r.muscles):
            a.plot(r.time, r.u[:, i], label=n)
        a.set_ylabel(f"u ({name.split(',')[-1].strip()})")
        a.set_title(f"{name}: J = {r.objective:.4g}" + ("" if r.converged else " [NOT CONVERGED]"),
                    fontsize=9)
        a.grid(alpha=0.3)
    ax[0, 0].legend(ncol=4, fontsize=7)
    ax[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_tracking(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4))
    first = next(iter(results.values()))
    ax.fill_between(first.time, first.target[:, 0] - TOL, first.target[:, 0] + TOL, color="0.85",
                    label="target +- 0.1 rad")
    for (k, kind), r in results.items():
        ax.plot(r.time, r.q[:, 0], lw=1, ls="-" if kind == "fourier" else "--", label=f"{k} {kind}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("elbow flexion (rad)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


DESIGNS = {   # Sec. 5.1: what the Fourier series parametrize, and the tendon
    "ff_rigid": dict(design="ff", tendon="rigid"),
    "ff_compliant": dict(design="ff", tendon="compliant"),
    "ifm": dict(design="ifm"),
    "ift": dict(design="ift"),
}


def compare_designs(model, names, *, jobs, steps, path):
    """J4 with Fourier series in each simulation design of Sec. 5.1: excitations (FF, rigid or
    compliant tendon), muscle-tendon forces (IFM) or the elbow torque (IFT).  IFM and IFT
    recover the excitations with the inverse muscle model (Fig. 5.6, compliant tendon)."""
    table, results = {}, {}
    for name in names:
        # the compliant tendon starts from the rigid optimum (a cheap guess, Sec. 3.5.3): from
        # the generic guesses it needs ~5x more iterations, each ~7x dearer (implicit fibers)
        x0 = results["ff_rigid"].x if name == "ff_compliant" and "ff_rigid" in results else None
        res, sec = solve(model, "J4", "fourier", jobs=jobs, steps=steps, x0=x0, **DESIGNS[name])
        results[name] = res
        table[name] = {"objective": res.objective, "converged": res.converged,
                       "status": res.status, "max_tracking_error": res.max_tracking_error,
                       "max_bound_violation": res.max_bound_violation, "seconds": sec,
                       "peak_activation": dict(zip(res.muscles, np.max(res.a, axis=0).tolist()))}
        print(f"J4 fourier {name:12s} J {res.objective:.5g}  err {res.max_tracking_error:.4f} rad  "
              f"{'ok' if res.converged else 'NOT CONVERGED'}  {sec:.1f} s")
    plot_excitations([(f"J4, {n}", r) for n, r in results.items()], path)
    return table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/forearm")
    ap.add_argument("--quick", action="store_true", help="J4 with Fourier series only, FF and IFT (tests)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--moment-arms", default="angle", choices=("angle", "constant"),
                    help="moment arms as functions of the elbow angle (as the thesis, Fig. 3.5; "
                         "default) or constant (Table 3.5)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    model = pinmsk.load_model("forearm", moment_arms=args.moment_arms)
    runs = [("J4", "fourier")] if args.quick else \
        [(k, p) for p in PARAMETRIZATIONS for k in OBJECTIVES]
    results, summary = {}, {}
    for k, kind in runs:
        x0 = None
        if k == "J5":   # metabolic cost: warm starts from the effort optima (cheap guesses, Sec. 3.5.3)
            x0 = np.array([results[(j, kind)].x for j in ("J4", "J1") if (j, kind) in results])
            x0 = x0 if len(x0) else None
        res, sec = solve(model, k, kind, jobs=args.jobs, steps=60 if args.quick else 100, x0=x0)
        results[(k, kind)] = res
        summary.setdefault(k, {})[kind] = {
            "objective": res.objective, "converged": res.converged, "status": res.status,
            "max_tracking_error": res.max_tracking_error,
            "max_bound_violation": res.max_bound_violation, "seconds": sec,
            "integration_error": res.terms["integration_error"],
            # J5: SLSQP minimizes the C1-smoothed heat-rate model (width `smooth`, pinmsk.energy);
            # "objective" is the exact piecewise model at the solution, this the smoothed one
            "objective_optimized": res.terms["J_optimized"],
            "peak_excitation": dict(zip(res.muscles, np.max(res.u, axis=0).tolist())),
            "n_parameters": int(res.coeffs.size)}
        print(f"{k} {kind:10s} J {res.objective:.5g}  err {res.max_tracking_error:.4f} rad  "
              f"bound viol {res.max_bound_violation:.2g}  "
              f"{'ok' if res.converged else 'NOT CONVERGED'}  {sec:.1f} s")
    plot_tracking(results, out / "forearm_tracking.png")
    for kind in PARAMETRIZATIONS:
        if any(p == kind for _, p in runs):
            plot_excitations([(f"{kind}, {k}", results[(k, kind)]) for k in OBJECTIVES
                              if (k, kind) in results], out / f"forearm_excitations_{kind}.png")
    names = ["ift"] if args.quick else list(DESIGNS)
    summary["designs"] = compare_designs(model, names, jobs=args.jobs, steps=60 if args.quick else 100,
                                         path=out / "forearm_designs.png")
    summary["target"] = "0.3 + 0.8 (1 - cos(2 pi t / 1.9)) rad (synthetic; thesis data unavailable)"
    summary["moment_arms"] = args.moment_arms
    summary["thesis"] = {"J4_final_objective": {"fourier": 0.10, "polynomial": 0.12},
                         "minutes": {"fourier": 30, "polynomial": 50}}
    (out / "forearm_do.json").write_text(json.dumps(summary, indent=2, default=float))
    return summary


if __name__ == "__main__":
    main()
