"""Robustness of the predictive gait: the default problem from several generic guesses.

    python examples/gait_robustness.py --out out/robustness [--guesses walking,standing,qr1,qr2] [--jobs 2]

Each guess is one of :func:`pinmsk.solvers.ocp.gait.predictive_gait`'s generic starts: ``walking``
(sinusoids from the speed and duration only, the default), ``standing`` (feet on the ground, the pelvis
moving forward at the speed) and ``qr<seed>`` (quasi-random: standing plus random joint-angle waves and
activations, PredSim's habit).  None is a tracking solution.  Every run is the default problem
(metabolic energy per distance plus effort, 1.3 m/s, coarse-to-fine 15 -> 25 intervals, the toe
springs in the fine stage), solved in its own process (``--jobs`` at a time).

Prints one row per guess (converged, iterations, seconds, objective, cost of transport, RMS and
correlation of the right hip / knee / ankle against Winter's Table A.1 when the shared data is present,
swing knee flexion, second vertical GRF peak) and the spread of the converged optima (the range of
the objective and of each number), and writes ``robustness.json``.
"""
from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from _common import output_folder

JOINTS = ("hip_r", "knee_r", "ankle_r")


def guess_options(name: str) -> dict:
    """predictive_gait's guess arguments for ``walking``, ``standing`` or ``qr<seed>``."""
    if name in ("walking", "standing"):
        return {"guess": name}
    if name.startswith("qr") and name[2:].isdigit():
        return {"guess": "quasi-random", "seed": int(name[2:])}
    raise SystemExit(f"gait_robustness: unknown guess {name!r} (walking, standing or qr<seed>)")


def solve(name: str, options: dict | None = None) -> dict:
    """One default predictive gait from guess ``name`` (``options``: more predictive_gait arguments):
    its numbers (JSON-ready)."""
    from pinmsk.errors import PinmskError
    from pinmsk.gait_validation import validate_gait
    from pinmsk.solvers.ocp.gait import predictive_gait, stride_result
    fit = predictive_gait(verbose=False, **guess_options(name), **(options or {})).fit()
    r = fit.result_
    stride, s = stride_result(fit)
    row = {"guess": name, "converged": bool(r.converged), "status": r.status, "iterations": int(r.nit),
           "seconds": float(r.seconds), "objective": float(r.objective),
           "cost_of_transport": s["cost_of_transport"],
           "swing_knee_deg": float(np.degrees(np.max(stride["knee_r"])))}
    try:
        n = validate_gait(stride).numbers      # its speed, CoT and body weight from the stride's info
    except PinmskError as exc:         # a stride without a stance (e.g. a failed run) has no double hump
        row["validation"] = f"not validated: {exc}"
        return row
    w = n["joint_angles"].get("winter", {})
    for j in JOINTS:
        if j in w:
            row[f"{j}_rms_deg"] = float(w[j]["rms_deg"])
            row[f"{j}_corr"] = float(w[j]["correlation"])
    hump = n["grf"].get("simulation", {}).get("r", {})
    row["second_peak_bw_pct"] = hump.get("second_peak_bw_pct")
    row["stance_pct"] = hump.get("stance_pct")
    return row


COLUMNS = ("converged", "iterations", "seconds", "objective", "cost_of_transport", "hip_r_rms_deg", "hip_r_corr",
           "knee_r_rms_deg", "knee_r_corr", "ankle_r_rms_deg", "ankle_r_corr", "swing_knee_deg",
           "second_peak_bw_pct", "stance_pct")


def table(rows: list[dict]) -> str:
    """The markdown table of the runs and, over the converged ones, each number's range."""
    def fmt(x):
        if isinstance(x, bool):
            return "yes" if x else "no"
        if isinstance(x, (int, float)):
            return f"{x:.4g}"
        return "-" if x is None else str(x)
    lines = ["| guess | " + " | ".join(COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for r in rows:
        lines.append(f"| {r['guess']} | " + " | ".join(fmt(r.get(c)) for c in COLUMNS) + " |")
    ok = [r for r in rows if r["converged"]]
    if ok:
        spread = []
        for c in COLUMNS[3:]:
            v = [r[c] for r in ok if isinstance(r.get(c), (int, float))]
            spread.append(f"{min(v):.4g} to {max(v):.4g}" if v else "-")
        lines.append(f"| spread ({len(ok)} of {len(rows)} converged) | | | | " + " | ".join(spread) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="output folder (default: a new temporary folder)")
    ap.add_argument("--guesses", default="walking,standing,qr1,qr2")
    ap.add_argument("--jobs", type=int, default=1, help="solves at a time (each in its own process)")
    a = ap.parse_args(argv)
    names = [g.strip() for g in a.guesses.split(",") if g.strip()]
    for g in names:
        guess_options(g)                       # refuse a bad name before any solve
    a.out = output_folder(a.out, "gait_robustness")
    if a.jobs > 1:
        with ProcessPoolExecutor(max_workers=a.jobs) as ex:
            rows = list(ex.map(solve, names))
    else:
        rows = [solve(g) for g in names]
    text = table(rows)
    print(text)
    (a.out / "robustness.json").write_text(json.dumps(rows, indent=2))
    print(f"wrote {a.out / 'robustness.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
