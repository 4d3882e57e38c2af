"""Which physical limit sets the maximum finger-tapping frequency (thesis Sec. 3.2.2).

The literature-based finger (built-in model ``finger_literature``: segments approximately after
Buchner et al. 1988, FDS+FDP and EDC architecture of Gonzalez et al. 1997 after Lieber et al.
1992; see ``urdf/README.md``) tracks ``theta_d = 0.21 sin(2 pi f t)`` (Eq. 3.1) over one period
with the thesis's problem: each excitation a 6th-order polynomial (Eq. 3.2),
``J = 0.1 J1 + 0.9 J2`` (Eq. 3.3), ``0 <= u <= 1``, the initial state taken from the target.
It is solved by the optimal-control engine (:mod:`pinmsk.solvers.ocp`: CasADi + IPOPT,
Hermite-Simpson collocation, 50 intervals per period, implicit skeleton dynamics).

As ``examples/finger_tapping.py`` defines it, the maximum trackable frequency is where the optimal
``J2`` crosses 0.25 (half of the 0.5 a finger standing still scores), interpolated linearly between
solved frequencies after an upward scan and a bisection.

The sweep varies one physical factor at a time around the literature model and reports each
maximum frequency: activation time constants (tau_rise and tau_fall together, x0.5, x1, x2),
maximum shortening velocity v_max (x0.5, x1, x2), rigid vs compliant tendon (Thelen 2003 tendon,
De Groote 2016 implicit form), segment inertia (mass and inertia of the finger, x0.5, x1, x2;
the gravity moment scales with them), and, as a check of the mechanism, F_max of both muscles
(x0.5, x1, x2).

Both studies are run: the thesis's problem (one period from the target's initial angle and speed,
activations free at t = 0) and a steady tapping cycle (angle, speed, activations periodic,
excitations at the nodes: Polynomial(6) with ocp.Periodic stops at Maximum_Iterations_Exceeded /
Infeasible_Problem_Detected on the engine).  Measured (full run, ~170 s on the loaded machine):
single period 30.2 Hz, set by strength / inertia (inertia x0.5, x2: 42.9, 20.9 Hz; F_max the
mirror image; activation and v_max move it < 1 Hz; compliant tendon 39.6 Hz); steady cycle
10.9 Hz, set by activation dynamics (x0.5, x2: 16.3, 7.2 Hz) and the fibre's force-velocity
damping (v_max x0.5, x2: 8.4, 13.8 Hz; compliant tendon 19.5 Hz; inertia and F_max < 0.4 Hz).

Run:  python examples/finger_frequency_limit.py --out out/finger_limit   [--quick]
Writes finger_frequency_limit.json (every solved frequency, J, J1, J2, convergence, seconds, the
limits) and finger_frequency_limit.png (the sweep figure).  Never imports opensim (casadi and
opensim cannot share a process).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

import pinmsk
from pinmsk.muscles.muscle_set import MuscleSet
from pinmsk.solvers import ocp
from pinmsk.solvers.ocp.tasks import scale_masses   # masses and inertias x factor, COMs kept
from pinmsk.solvers.parametrization import Polynomial
from _common import output_folder

J2_LIMIT = 0.25          # examples/finger_tapping.py's criterion
MU = 0.1                 # thesis Eq. 3.3
AMPLITUDE = 0.21         # rad, thesis Eq. 3.1
INTERVALS = 50           # Hermite-Simpson intervals per period
LITERATURE = [6.46, 6.92]   # Hz: Kuboyama et al. 2004 [82]; [83] 6.92 +- 0.56 (thesis Sec. 3.2.2)
THESIS_MAX = 6.0
SCAN = [4.0, 6.0, 8.0, 11.0, 16.0, 22.0, 32.0, 45.0, 64.0, 90.0, 128.0]
QUICK_SCAN = [8.0, 16.0, 32.0, 64.0]
# Converged solves take 30-60 IPOPT iterations here.  The few that do not converge stall at a
# tracked solution with an activation collocation defect at its lower bound (a = 0), and more
# iterations or more starts do not help (measured: 1000 -> 3000 iterations, 3 starts: the same
# point after 170 s), so they are cut short and left out of the bracket (see max_frequency).
MAX_ITER = 300


def solve(model, f, *, tendon="rigid", periodic=False, max_iter=MAX_ITER):
    """The finger-tapping problem at ``f`` Hz; returns (Result, seconds).

    ``periodic=False``: the thesis's problem - one period from the target's initial state
    (angle, speed; the activations start free), excitations 6th-order polynomials.
    ``periodic=True``: a steady tapping cycle - angle, speed, activations (and tendon forces) at ``T``
    equal those at 0 (ocp.Periodic), no initial state imposed, excitations free at the nodes (ocp.NodeControls:
    the polynomial with periodicity does not converge on the engine, see the module notes).
    """
    T = 1.0 / f
    tg = ocp.Target("sine", amplitude=AMPLITUDE, frequency=f)
    if tendon == "compliant":
        model
    if periodic:
        constraints = [ocp.ExcitationBounds(0, 1), ocp.Periodic()]
        controls = ocp.NodeControls()
    else:
        constraints = [ocp.InitialState(q={"mcp_flexion": float(tg(0.0, 0))}, v={"mcp_flexion": float(tg(0.0, 1))}),
                       ocp.ExcitationBounds(0, 1)]
        controls = ocp.GlobalControls(Polynomial(6, duration=T))
    t0 = time.perf_counter()
    fit = ocp.Collocation(
        model, cost=MU * ocp.Effort(2, normalize=False) + (1.0 - MU) * ocp.TrackCoordinates(tg),
        constraints=constraints, duration=T, intervals=INTERVALS, scheme="hermite-simpson",
        controls=controls, formulation="ff", tendon=tendon, n_starts=1,
        solver={"max_iter": max_iter, "print_level": 0}, verbose=False).fit()
    return fit.result_, time.perf_counter() - t0


def _row(res, sec):
    return {"J": float(res.objective), "J1": float(res.terms["effort"]), "J2": float(res.terms["tracking"]),
            "converged": bool(res.converged), "status": str(res.status), "seconds": float(sec)}


def max_frequency(model, *, tendon="rigid", periodic=False, scan=SCAN, bisections=3):
    """Scan upward until J2 > J2_LIMIT, bisect, interpolate; returns (f_max or None, {f: row}).

    Only converged solves bracket the limit: an unconverged frequency is recorded (``converged``
    false in its row) and passed over - the scan goes on to the next frequency, a bisection tries
    the midpoint moved by +-10 % of the bracket instead.  None: the whole scan tracks (or nothing
    below the first untracked frequency converged).
    """
    solved = {}

    def j2(f):
        f = round(float(f), 3)
        if f not in solved:
            solved[f] = _row(*solve(model, f, tendon=tendon, periodic=periodic))
        r = solved[f]
        return r["J2"] if r["converged"] else None

    lo = hi = None
    for f in scan:
        j = j2(f)
        if j is None:
            continue
        if j > J2_LIMIT:
            hi = f
            break
        lo = f
    if hi is None or lo is None:
        return None, solved
    for _ in range(bisections):
        for mid in (0.5 * (lo + hi), 0.6 * lo + 0.4 * hi, 0.4 * lo + 0.6 * hi):
            mid = round(mid, 3)
            j = j2(mid)
            if j is not None:
                break
        else:
            break
        lo, hi = (mid, hi) if j <= J2_LIMIT else (lo, mid)
    j_lo, j_hi = j2(lo), j2(hi)
    return float(lo + (J2_LIMIT - j_lo) / (j_hi - j_lo) * (hi - lo)), solved


# ---------------------------------------------------------------------------- the variants


def with_mtu(model, **changes):
    """``model`` with its muscle model's parameters changed (``tau_rise``, ``v_max``, ...)."""
    ms = model.muscles
    new = MuscleSet(names=ms.names, model_type=ms.model_type, mtu=ms.mtu.replace(**changes), path=ms.path,
                    tendon=ms.tendon, volume=ms.volume, fast_fraction=ms.fast_fraction)
    return model.with_muscles(new)


def variants(model, quick=False):
    """{factor: [(label, scale, model, tendon)]}, one factor varied at a time around ``model``."""
    mtu = model.muscles.mtu
    out = {
        "activation time constants": [
            (f"x{s:g}", s, with_mtu(model, tau_rise=mtu.tau_rise * s, tau_fall=mtu.tau_fall * s), "rigid")
            for s in (0.5, 2.0)],
        "v_max": [(f"x{s:g}", s, with_mtu(model, v_max=np.asarray(mtu.v_max) * s), "rigid") for s in (0.5, 2.0)],
        "tendon": [("compliant", 1.0, model, "compliant")],
        "segment inertia": [(f"x{s:g}", s, scale_masses(model, s), "rigid") for s in (0.5, 2.0)],
        # beyond the thesis's factors: the check of the mechanism found at the limit (the weak
        # extensor's moment against the inertial moment I (2 pi f)^2 A): F_max of both muscles
        "F_max": [(f"x{s:g}", s, with_mtu(model, f_max=np.asarray(mtu.f_max) * s), "rigid") for s in (0.5, 2.0)],
    }
    if quick:
        out = {"v_max": out["v_max"][:1]}
    return out


# ---------------------------------------------------------------------------- figure


def figure(studies, path):
    """One row per study (thesis single period; steady cycle), one panel per factor."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    factors = list(next(iter(studies.values()))["sweep"])
    fig, axes = plt.subplots(len(studies), len(factors), figsize=(2.7 * len(factors) + 1, 3.3 * len(studies)),
                             sharey="row", squeeze=False)
    for row, (title, st) in zip(axes, studies.items()):
        for ax, name in zip(row, factors):
            ref = {"label": "rigid" if name == "tendon" else "x1", "scale": 1.0, "max_frequency": st["max_frequency"]}
            entries = sorted(st["sweep"][name] + [ref], key=lambda e: (e["label"] != "rigid", e["scale"]))
            labels = [e["label"] for e in entries]
            values = [np.nan if e["max_frequency"] is None else e["max_frequency"] for e in entries]
            ax.bar(labels, np.nan_to_num(values), color=["C0" if e is ref else "C1" for e in entries])
            for k, v in enumerate(values):
                ax.text(k, 0 if not np.isfinite(v) else v, "n/a" if not np.isfinite(v) else f"{v:.1f}",
                        ha="center", va="bottom", fontsize=7)
            ax.axhline(THESIS_MAX, color="k", ls="--", lw=0.8)
            ax.axhspan(min(LITERATURE), max(LITERATURE), color="gray", alpha=0.3, lw=0)
            ax.set_title(f"{name}", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3, axis="y")
        row[0].set_ylabel(f"{title}\nmax frequency (Hz)", fontsize=8)
    fig.suptitle("finger_literature: max tapping frequency (J2 = 0.25), one factor at a time; dashed: thesis "
                 "~6 Hz, band: measured 6.46-6.92 Hz", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------- mechanism at the limit


def mechanism(model, f, *, tendon="rigid", periodic=False):
    """What the muscles do at ``f`` Hz: peak activation, peak force / F_max and the peak
    muscle-tendon shortening speed (|r qdot|, the fibre speed along the tendon with a rigid tendon)
    as a fraction of v_max cos(pennation)."""
    res, sec = solve(model, f, tendon=tendon, periodic=periodic)
    ms = model.muscles
    qd = np.asarray(res["mcp_flexion_speed"], dtype=float)
    r = ms.moment_arms(np.zeros((1, model.nv)))[0, :, 0]       # (N, muscles, nv) -> constant arms at q = 0
    out = {"frequency": f, **_row(res, sec), "muscles": {}}
    for i, n in enumerate(ms.names):
        a = np.asarray(res[f"{n}_activation"], dtype=float)
        F = np.asarray(res[f"{n}_force"], dtype=float)
        v_mt = np.abs(r[i] * qd)
        vmax = float(np.asarray(ms.mtu.v_max)[i] * np.cos(ms.mtu.pennation[i]))
        out["muscles"][n] = {"peak_activation": float(a.max()), "peak_force_over_fmax": float(F.max() / ms.mtu.f_max[i]),
                             "peak_shortening_speed_m_s": float(v_mt.max()),
                             "peak_speed_over_vmax": float(v_mt.max() / vmax)}
    return out


def study(model, *, periodic, scan, bisections, quick):
    """The literature finger's limit and the one-factor sweep around it, for one problem form."""
    base, base_solved = max_frequency(model, periodic=periodic, scan=scan, bisections=bisections)
    kind = "steady cycle" if periodic else "single period (thesis)"
    print(f"{kind}: finger_literature max frequency {base} Hz")
    sweep = {}
    for name, cases in variants(model, quick=quick).items():
        sweep[name] = []
        for label, scale, m, tendon in cases:
            fmax, solved = max_frequency(m, tendon=tendon, periodic=periodic, scan=scan, bisections=bisections)
            sweep[name].append({"label": label, "scale": scale, "tendon": tendon, "max_frequency": fmax,
                                "solved": {str(k): v for k, v in sorted(solved.items())}})
            print(f"  {name:27s} {label:10s} max frequency {fmax} Hz")
    effect = {}
    for name, cases in sweep.items():
        values = [v for v in [base] + [e["max_frequency"] for e in cases] if v is not None]
        effect[name] = max(values) - min(values)
    unconverged = sorted(f"{name} {e['label']} {f} Hz" for name, cases in sweep.items() for e in cases
                         for f, row in e["solved"].items() if not row["converged"])
    unconverged += [f"base {f} Hz" for f, row in base_solved.items() if not row["converged"]]
    return {"max_frequency": base, "solved": {str(k): v for k, v in sorted(base_solved.items())},
            "sweep": sweep, "range_of_max_frequency_by_factor_Hz": effect,
            "factor_moving_the_limit_most": max(effect, key=lambda k: effect[k]) if effect else None,
            "unconverged_solves_left_out": unconverged,
            "at_6Hz": _row(*solve(model, THESIS_MAX, periodic=periodic)),
            "mechanism_at_max_frequency": mechanism(model, base, periodic=periodic) if base else None}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="output folder (default: a new temporary folder)")
    ap.add_argument("--quick", action="store_true", help="coarse scan, no bisection, one variant (for tests)")
    args = ap.parse_args(argv)
    out = output_folder(args.out, "finger_frequency_limit")
    t_all = time.perf_counter()
    model = pinmsk.load_model("finger_literature")
    scan = QUICK_SCAN if args.quick else SCAN
    bis = 0 if args.quick else 3
    studies = {"single period (thesis)": study(model, periodic=False, scan=scan, bisections=bis, quick=args.quick)}
    if not args.quick:
        studies["steady cycle"] = study(model, periodic=True, scan=scan, bisections=bis, quick=False)
    figure(studies, out / "finger_frequency_limit.png")
    thesis = studies["single period (thesis)"]
    summary = {
        "model": "finger_literature",
        "problem": {"target": f"{AMPLITUDE} sin(2 pi f t)", "cost": "0.1 J1 + 0.9 J2", "scheme": "hermite-simpson",
                    "intervals_per_period": INTERVALS,
                    "single period (thesis)": "Polynomial(6) excitations, initial angle and speed from the target",
                    "steady cycle": "node excitations, periodic angle, speed, activations (and tendon forces)",
                    "criterion": f"optimal J2 = {J2_LIMIT}, linear interpolation after scan + bisection"},
        "max_frequency": thesis["max_frequency"], "solved": thesis["solved"], "at_6Hz": thesis["at_6Hz"],
        "studies": studies,
        "thesis_max_frequency": THESIS_MAX, "literature_max_frequency": LITERATURE,
        "quick": bool(args.quick), "seconds_total": time.perf_counter() - t_all,
    }
    (out / "finger_frequency_limit.json").write_text(json.dumps(summary, indent=2, default=float))
    for title, st in studies.items():
        print(f"{title}: limit {st['max_frequency']} Hz; factor moving it most: {st['factor_moving_the_limit_most']} "
              f"{ {k: round(v, 2) for k, v in st['range_of_max_frequency_by_factor_Hz'].items()} }")
    print(f"{summary['seconds_total']:.1f} s")
    return summary


if __name__ == "__main__":
    main()
