"""Forearm dynamic optimization with Fourier-series and polynomial excitations (thesis Sec. 3.3).

The 1-dof elbow with seven Thelen muscles (Table 3.2), moment arms as functions of
the elbow angle as in the thesis (Fig. 3.5; ``--moment-arms constant`` for Table 3.5's
constant arms), tracks a flexion-extension
cycle of 1.9 s within 0.1 rad (tracking constraint Eq. 3.7) with ``0 <= u <= 1``
(Eq. 3.8), solved by the optimal-control engine (:mod:`pinmsk.solvers.ocp`: Hermite-Simpson
direct collocation, 50 intervals, IPOPT with exact derivatives).  Each excitation is an 11-term Fourier series (Eq. 3.4, K = 5,
77 parameters), then a 10th-order polynomial (Eq. 3.2, 77 parameters), then -- the
local baseline -- a clamped cubic B-spline with 11 coefficients (77 parameters).
Objectives (Table 3.3): J1 (S = 1, P = 2), J2 (S = 1, P = 3), J3 (S = V, P = 2),
J4 (S = V, P = 3) of Eq. 3.5 and J5, metabolic energy Eq. 3.6 with the
Umberger 2003 heat rates (App. B.2), started from the J4 optimum.  J5 is reported as the
mean metabolic power in W (``MetabolicEnergy(per="time")`` with no normalizer; the
replaced engine divided it by the sum of the muscles' maximum rates at its first guess).  Then
J4 with Fourier series in each simulation design of Sec. 5.1: fully forward
with a rigid or a compliant tendon, inverse-forward from muscle forces (IFM)
and from the elbow torque (IFT).  For J5 the heat-rate model's switches are C1-smoothed
(width 0.01, ``pinmsk.energy``); the objective reported is that smoothed model.

The measured average motion of the thesis (Fig. 3.6) is not available; the target
is the smooth cycle ``0.3 + 0.8 (1 - cos(2 pi t / 1.9))`` rad (0.3 -> 1.9 -> 0.3 rad).

Run:  python examples/forearm_dynamic_optimization.py --out out/forearm  [--quick] [--intervals 50]
      [--moment-arms angle|constant]
Writes forearm_do.json (per objective and parametrization; "designs": J4 per design)
and PNG figures.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

import pinmsk
from pinmsk.solvers import ocp
from pinmsk.solvers.ocp import Target
from pinmsk.solvers.parametrization import Fourier, Polynomial, Spline

from finger_tapping import signals
from _common import output_folder

PERIOD = 1.9
TOL = 0.1
PARAMETRIZATIONS = ("fourier", "polynomial", "spline")   # global (Sec. 3.1) and the local baseline
OBJECTIVES = {
    "J1": lambda: ocp.Effort(2, weights="none"),
    "J2": lambda: ocp.Effort(3, weights="none"),
    "J3": lambda: ocp.Effort(2, weights="volume"),
    "J4": lambda: ocp.Effort(3, weights="volume"),
    "J5": lambda: ocp.MetabolicEnergy("umberger2003"),   # mean metabolic power (W)
}


def target():
    return Target("cycle", amplitude=1.6, period=PERIOD, offset=0.3)


def solve(model, objective, kind, *, intervals=50, guess=None, formulation="ff", tendon="rigid",
          max_iter=1000):
    """One problem of Table 3.3: ``objective`` a key of OBJECTIVES, ``kind`` a parametrization;
    tracking and excitation bounds hold at every node and midpoint; the elbow starts at rest
    on the target.  ``guess``: a previous result (a warm start)."""
    par = {"fourier": lambda: Fourier(5, period=PERIOD),
           "polynomial": lambda: Polynomial(10, duration=PERIOD),
           "spline": lambda: Spline(11, duration=PERIOD)}[kind]()   # 11 coefficients per muscle each
    tg = target()
    c = model.coordinates[0]
    fit = ocp.Collocation(
        model, cost=OBJECTIVES[objective](),
        constraints=[ocp.TrackingTolerance(tg, TOL), ocp.InitialState(q={c: float(tg(0.0))}, v={c: 0.0})],
        duration=PERIOD, intervals=intervals, scheme="hermite-simpson", controls=ocp.GlobalControls(par),
        formulation=formulation, tendon=tendon, guess=guess,
        solver={"max_iter": max_iter})
    t0 = time.perf_counter()
    res = fit.fit().result_
    return res, time.perf_counter() - t0


def plot_excitations(panels, path):
    """One panel of excitations per ``(name, result)``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(len(panels), 1, figsize=(8, 2.2 * len(panels)), sharex=True,
                           squeeze=False)
    for a, (name, r) in zip(ax[:, 0], panels):
        t, _, _, u, _, _ = signals(r)
        for i, n in enumerate(r.muscles):
            a.plot(t, u[:, i], label=n)
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
    t, _, qd, _, _, _ = signals(next(iter(results.values())))
    ax.fill_between(t, qd - TOL, qd + TOL, color="0.85", label="target +- 0.1 rad")
    for (k, kind), r in results.items():
        ax.plot(r.time, signals(r)[1], lw=1, ls="-" if kind == "fourier" else "--", label=f"{k} {kind}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("elbow flexion (rad)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


DESIGNS = {   # Sec. 5.1: what the Fourier series parametrize, and the tendon
    "ff_rigid": dict(formulation="ff", tendon="rigid"),
    "ff_compliant": dict(formulation="ff", tendon="compliant"),
    "ifm": dict(formulation="ifm"),
    "ift": dict(formulation="ift"),
}


def compare_designs(model, names, *, intervals, path):
    """J4 with Fourier series in each simulation design of Sec. 5.1: excitations (FF, rigid or
    compliant tendon), muscle-tendon forces (IFM) or the elbow torque (IFT).  IFM and IFT
    recover the excitations with the inverse muscle model (Fig. 5.6, compliant tendon)."""
    table, results = {}, {}
    for name in names:
        # the compliant tendon starts from the rigid optimum (a cheap guess, Sec. 3.5.3)
        guess = results.get("ff_rigid") if name == "ff_compliant" else None
        res, sec = solve(model, "J4", "fourier", intervals=intervals, guess=guess, **DESIGNS[name])
        results[name] = res
        table[name] = {"objective": res.objective, "converged": res.converged,
                       "status": res.status, "max_tracking_error": res.max_tracking_error,
                       "max_bound_violation": res.max_bound_violation, "seconds": sec,
                       "peak_activation": dict(zip(res.muscles, np.max(signals(res)[4], axis=0).tolist()))}
        print(f"J4 fourier {name:12s} J {res.objective:.5g}  err {res.max_tracking_error:.4f} rad  "
              f"{'ok' if res.converged else 'NOT CONVERGED'}  {sec:.1f} s")
    plot_excitations([(f"J4, {n}", r) for n, r in results.items()], path)
    return table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="output folder (default: a new temporary folder)")
    ap.add_argument("--quick", action="store_true", help="J4 with Fourier series only, FF and IFT (tests)")
    ap.add_argument("--intervals", type=int, default=50, help="collocation intervals")
    ap.add_argument("--moment-arms", default="angle", choices=("angle", "constant"),
                    help="moment arms as functions of the elbow angle (as the thesis, Fig. 3.5; "
                         "default) or constant (Table 3.5)")
    args = ap.parse_args(argv)
    out = output_folder(args.out, "forearm_dynamic_optimization")
    model = pinmsk.load_model("forearm", moment_arms=args.moment_arms)
    runs = [("J4", "fourier")] if args.quick else \
        [(k, p) for p in PARAMETRIZATIONS for k in OBJECTIVES]
    results, summary = {}, {}
    for k, kind in runs:
        # metabolic cost: a warm start from the J4 optimum (a cheap guess, Sec. 3.5.3)
        guess = results.get(("J4", kind)) if k == "J5" else None
        res, sec = solve(model, k, kind, intervals=args.intervals, guess=guess)
        results[(k, kind)] = res
        summary.setdefault(k, {})[kind] = {
            "objective": res.objective, "converged": res.converged, "status": res.status,
            "max_tracking_error": res.max_tracking_error,
            "max_bound_violation": res.max_bound_violation, "seconds": sec,
            "iterations": res.nit, "terms": res.terms,
            "peak_excitation": dict(zip(res.muscles, np.max(signals(res)[3], axis=0).tolist())),
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
    summary["designs"] = compare_designs(model, names, intervals=args.intervals,
                                         path=out / "forearm_designs.png")
    summary["J5_unit"] = "W (mean metabolic power, Umberger 2003, smoothed switches)"
    summary["target"] = "0.3 + 0.8 (1 - cos(2 pi t / 1.9)) rad (synthetic; thesis data unavailable)"
    summary["moment_arms"] = args.moment_arms
    summary["thesis"] = {"J4_final_objective": {"fourier": 0.10, "polynomial": 0.12},
                         "minutes": {"fourier": 30, "polynomial": 50}}
    (out / "forearm_do.json").write_text(json.dumps(summary, indent=2, default=float))
    return summary


if __name__ == "__main__":
    main()
