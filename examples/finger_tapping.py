"""Finger tapping by dynamic optimization (thesis Sec. 3.2.2, Table 3.1, Fig. 3.1-3.4).

A 1-dof index finger with one flexor and one extensor tracks
``theta_d = 0.21 sin(2 pi f t)`` (Eq. 3.1) over one period; each excitation is a
6th-order polynomial (Eq. 3.2, 14 parameters); the cost is
``J = mu J1 + (1 - mu) J2`` with ``mu = 0.1`` (Eq. 3.3); ``0 <= u <= 1`` holds
at every collocation point (Eq. 3.8).  Fully forward design: excitation -> activation
(Eq. A.2) -> Thelen muscle -> Pinocchio skeleton, solved by the optimal-control engine
(:mod:`pinmsk.solvers.ocp`: Hermite-Simpson direct collocation, 50 intervals, IPOPT with
exact derivatives) from its automatic guess.

The maximum trackable frequency is where the optimal ``J2`` crosses 0.25
(half of the 0.5 that a finger standing still would score), interpolated
between solved frequencies after a scan and a bisection.

Run:  python examples/finger_tapping.py --out out/finger   [--quick]
Writes finger_tapping.json (frequencies, J, J1, J2, max_frequency, seconds, ...)
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
from pinmsk.solvers.ocp.tasks import scale_masses
from pinmsk.solvers.parametrization import Polynomial
from _common import output_folder

THESIS = {"frequencies": [2, 4, 5, 6, 7], "J": [0.041, 0.196, 0.211, 0.898, 1.553],
          "J1": [0.101, 0.145, 0.176, 0.109, 0.097], "J2": [0.035, 0.201, 0.215, 0.986, 1.714],
          "max_frequency": 6.0, "literature_max_frequency": [6.46, 6.92]}
J2_LIMIT = 0.25
MU = 0.1


def solve(model, f, *, intervals=50, n_starts=1):
    """One frequency: ``J = mu J1 + (1 - mu) J2`` (Eq. 3.3), the finger starting on the target."""
    T = 1.0 / f
    tg = Target("sine", amplitude=0.21, frequency=f)
    c = model.coordinates[0]
    fit = ocp.Collocation(
        model, cost=MU * ocp.Effort(2, normalize=False) + (1.0 - MU) * ocp.TrackCoordinates(tg),
        constraints=[ocp.InitialState(q={c: float(tg(0.0))}, v={c: float(tg(0.0, 1))})],
        duration=T, intervals=intervals, scheme="hermite-simpson",
        controls=ocp.GlobalControls(Polynomial(6, duration=T)), n_starts=n_starts)
    t0 = time.perf_counter()
    res = fit.fit().result_
    return res, time.perf_counter() - t0


def signals(res):
    """``(time, q, q_desired, u, a, F)`` of an engine result: (N,) and (N, n_muscles) arrays."""
    c = res.coordinates[0]
    get = lambda suffix: np.column_stack([res[f"{n}_{suffix}"] for n in res.muscles])  # noqa: E731
    return (res.time, res[c], res[f"{c}_desired"], get("excitation"), get("activation"), get("force"))


def slow_muscle_variant(model, v_max=0.1):
    """The finger with fibers short enough that v_max = 10 l_opt = ``v_max`` (m/s), tendons
    lengthened to keep l_mt(0) = l_slack + l_opt (a sensitivity case, not the model)."""
    from pinmsk.muscles.muscle_set import MuscleSet
    ms = model.muscles
    l_opt = np.full(ms.n, v_max / 10.0)
    l_slack = ms.l_slack + ms.l_opt - l_opt
    mtu = ms.mtu.replace(l_opt=l_opt, l_slack=l_slack)
    new = MuscleSet(names=ms.names, model_type=ms.model_type, mtu=mtu, path=ms.path,
                    tendon=ms.tendon, volume=ms.volume, fast_fraction=ms.fast_fraction)
    return model.with_muscles(new)


def max_frequency(model, solved, *, scan, bisections):
    """Scan upward until J2 > J2_LIMIT, bisect, interpolate.  ``solved``: {f: J2}."""
    for f in scan:
        if any(j > J2_LIMIT for j in solved.values()):
            break
        if f in solved:
            continue
        res, _ = solve(model, f)
        solved[f] = res.terms["tracking"] if res.converged else np.inf
    fs = sorted(solved)
    bad = [f for f in fs if solved[f] > J2_LIMIT]
    if not bad:
        return None, solved          # trackable over the whole scan
    hi = bad[0]
    good = [f for f in fs if f < hi]
    if not good:
        return None, solved
    lo = good[-1]
    for _ in range(bisections):
        mid = round(0.5 * (lo + hi), 3)
        res, _ = solve(model, mid)
        solved[mid] = res.terms["tracking"] if res.converged else np.inf
        lo, hi = (mid, hi) if solved[mid] <= J2_LIMIT else (lo, mid)
    j_lo, j_hi = solved[lo], solved[hi]
    if np.isfinite(j_hi):
        fmax = lo + (J2_LIMIT - j_lo) / (j_hi - j_lo) * (hi - lo)
    else:
        fmax = lo
    return float(fmax), solved


def figure(res, path, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(2, 2, figsize=(9, 6), sharex=True)
    t, q, qd, u, a, F = signals(res)
    ax[0, 0].plot(t, qd, "k--", label=r"$\theta_d$")
    ax[0, 0].plot(t, q, label=r"$\theta_s$")
    ax[0, 0].set_ylabel("angle (rad)")
    ax[0, 0].legend()
    for i, n in enumerate(res.muscles):
        ax[0, 1].plot(t, F[:, i], label=n)
        ax[1, 0].plot(t, u[:, i], label=n)
        ax[1, 1].plot(t, a[:, i], label=n)
    ax[0, 1].set_ylabel("force (N)")
    ax[1, 0].set_ylabel("excitation")
    ax[1, 1].set_ylabel("activation")
    for a in ax.ravel():
        a.grid(alpha=0.3)
    ax[0, 1].legend()
    ax[1, 0].set_xlabel("time (s)")
    ax[1, 1].set_xlabel("time (s)")
    fig.suptitle(title + ("" if res.converged else "  [NOT CONVERGED]"))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def table_figure(freqs, J, J1, J2, fmax, path, extra=None, solved=None):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4))
    if solved:
        fs = sorted(solved)
        ax.plot(fs, [max(solved[f], 1e-7) for f in fs], ".-", color="C0", alpha=0.5,
                label="J2 (pinmsk, scan)")
    ax.plot(freqs, J2, "o", color="C0", label="J2 (pinmsk)")
    ax.plot(freqs, J1, "s-", color="C1", label="J1 (pinmsk)")
    ax.plot(THESIS["frequencies"], THESIS["J2"], "o--", color="gray", label="J2 (thesis Table 3.1)")
    ax.plot(THESIS["frequencies"], THESIS["J1"], "s--", color="silver", label="J1 (thesis Table 3.1)")
    if extra is not None:
        ax.plot(extra["frequencies"], extra["J2"], "^-", color="C2",
                label="J2, v_max = 0.1 m/s variant")
    ax.axhline(J2_LIMIT, color="k", lw=0.8, ls=":")
    if fmax:
        ax.axvline(fmax, color="C0", lw=0.8, ls=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    from matplotlib.ticker import NullFormatter, ScalarFormatter
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xticks([2, 4, 6, 10, 20, 40, 80])
    ax.set_xlabel("tapping frequency (Hz)")
    ax.set_ylabel("cost")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="output folder (default: a new temporary folder)")
    ap.add_argument("--quick", action="store_true", help="two frequencies, no search (for tests)")
    args = ap.parse_args(argv)
    out = output_folder(args.out, "finger_tapping")
    model = pinmsk.load_model("finger")
    freqs = [2.0, 6.0] if args.quick else [2.0, 4.0, 5.0, 6.0, 7.0]
    rows, seconds, results = [], [], {}
    for f in freqs:
        res, sec = solve(model, f)
        results[f] = res
        seconds.append(sec)
        rows.append((res.objective, res.terms["effort"], res.terms["tracking"]))
        print(f"{f:5.1f} Hz  J {rows[-1][0]:.4g}  J1 {rows[-1][1]:.4g}  J2 {rows[-1][2]:.4g}  "
              f"{'ok' if res.converged else 'NOT CONVERGED'}  {sec:.1f} s")
    for f in (2.0, 6.0, 7.0):
        if f in results:
            figure(results[f], out / f"finger_{int(f)}Hz.png", f"finger tapping, f = {f:g} Hz")
    solved = {f: (r.terms["tracking"] if r.converged else np.inf) for f, r in results.items()}
    scan = [] if args.quick else [10.0, 14.0, 20.0, 28.0, 40.0, 56.0, 80.0]
    fmax, solved = max_frequency(model, solved, scan=scan,
                                 bisections=0 if args.quick else 3)
    # 50 % finger mass at 2 Hz (Fig. 3.4)
    half, sec_half = solve(scale_masses(model, 0.5), 2.0)
    figure(half, out / "finger_2Hz_half_mass.png", "finger tapping, f = 2 Hz, 50 % finger mass")
    full = results[2.0]
    ratio = float(signals(half)[3].max() / signals(full)[3].max())
    # sensitivity: thesis-like muscle speed (v_max = 0.1 m/s)
    variant = None
    if not args.quick:
        slow = slow_muscle_variant(model)
        vr = {f: solve(slow, f)[0] for f in THESIS["frequencies"]}
        sv = {f: (r.terms["tracking"] if r.converged else np.inf) for f, r in vr.items()}
        fmax_slow, sv = max_frequency(slow, sv, scan=[3.0, 8.0, 10.0, 14.0],
                                      bisections=3)
        variant = {"description": "finger with l_opt = 1 cm (v_max = 10 l_opt = 0.1 m/s), "
                                  "tendons lengthened to keep the same l_mt at q = 0",
                   "frequencies": THESIS["frequencies"],
                   "J": [vr[f].objective for f in THESIS["frequencies"]],
                   "J1": [vr[f].terms["effort"] for f in THESIS["frequencies"]],
                   "J2": [vr[f].terms["tracking"] for f in THESIS["frequencies"]],
                   "converged": [vr[f].converged for f in THESIS["frequencies"]],
                   "max_frequency": fmax_slow,
                   "solved_J2": {str(k): v for k, v in sorted(sv.items())}}
        figure(vr[7.0], out / "finger_7Hz_slow_muscles.png",
               "finger tapping, f = 7 Hz, v_max = 0.1 m/s variant")
    table_figure(freqs, [r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows], fmax,
                 out / "finger_table.png", variant, solved)
    summary = {
        "frequencies": freqs, "J": [r[0] for r in rows], "J1": [r[1] for r in rows],
        "J2": [r[2] for r in rows], "max_frequency": fmax, "seconds": seconds,
        "converged": [results[f].converged for f in freqs],
        "max_bound_violation": [results[f].max_bound_violation for f in freqs],
        "iterations": [results[f].nit for f in freqs],
        "max_frequency_criterion": f"optimal J2 = {J2_LIMIT} (standing still scores 0.5), "
                                   "linear interpolation between solved frequencies",
        "solved_J2": {str(k): v for k, v in sorted(solved.items())},
        "half_mass_2Hz": {"J": half.objective, "J1": half.terms["effort"],
                          "J2": half.terms["tracking"], "converged": half.converged,
                          "peak_excitation_ratio_half_to_full": ratio, "seconds": sec_half},
        "thesis": THESIS, "slow_muscle_variant": variant,
    }
    (out / "finger_tapping.json").write_text(json.dumps(summary, indent=2, default=float))
    print(f"max trackable frequency: {fmax if fmax else 'beyond the scan'} Hz "
          f"(thesis ~6 Hz; literature 6.46, 6.92 +- 0.56 Hz)")
    if variant:
        print(f"v_max = 0.1 m/s variant: J2 {np.round(variant['J2'], 3).tolist()}, "
              f"max frequency {variant['max_frequency']}")
    print(f"50 % mass at 2 Hz: J {half.objective:.4g}, peak excitation ratio {ratio:.3f}")
    return summary


if __name__ == "__main__":
    main()
