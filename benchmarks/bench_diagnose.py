"""Diagnosis speed: one full diagnosis (compare + rank the whole catalog with cross-validation).

    python benchmarks/bench_diagnose.py            # ~30 s

Targets (issue 4): a 10 s, 100 Hz forearm trial against the full catalog in
<= 2 s; a 10 s gait2d trial <= 20 s.  Each case is timed end to end on a
synthetic trial with a hidden effect (best of 3 runs, one core), with the
time split into the comparison (kinematics, inverse dynamics, noise floor) and
the ranking (fits and 5-fold cross-validation of every candidate).  Also shown:
the muscle-level forearm case (activation dynamics fitted through seven
muscles), the motion-level forearm case (multiple-shooting simulations) and one
``--add`` step.
"""
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import pinmsk  # noqa: E402
from pinmsk.diagnose import compare, diagnose, make_trial, run  # noqa: E402


def best_of(fn, repeat=3):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def case(label, model, trial, budget, **kw):
    t_all, d = best_of(lambda: diagnose(model, trial, **kw))
    t_cmp, _ = best_of(lambda: compare(model, trial, **{k: v for k, v in kw.items() if k == "mode"}))
    ratio = f"{t_all / budget:5.2f} of budget" if budget else "  (no budget)"
    print(f"{label:<44} {trial.n_frames:>6} {len(d.ranking):>5} {t_cmp:8.3f} {t_all - t_cmp:8.3f} "
          f"{t_all:8.3f} {budget if budget else '-':>7}  {ratio}   best: {d.ranking[0].label}")
    return t_all


def main():
    print(f"pinmsk diagnosis benchmark -- {platform.processor() or platform.machine()}, "
          f"python {platform.python_version()}, numpy {np.__version__}")
    print(f"{'case':<44} {'frames':>6} {'cands':>5} {'compare':>8} {'rank':>8} {'total s':>8} "
          f"{'budget':>7}")
    forearm = pinmsk.load_model("forearm")
    gait = pinmsk.load_model("gait2d")
    results = {}
    tr = make_trial(forearm, ["payload:hand:mass=0.5", "joint_damping:elbow_flexion:c=0.2"],
                    duration=10.0, rate=100.0, seed=1)
    results["forearm torque"] = case("forearm, torque level, 10 s @ 100 Hz", forearm, tr, 2.0)
    tr_m = make_trial(forearm, ["activation_dynamics:muscles:tau_rise=0.02,tau_fall=0.08"],
                      duration=10.0, rate=100.0, seed=1)
    results["forearm muscle"] = case("forearm, muscle level (EMG), 10 s @ 100 Hz", forearm, tr_m, 2.0)
    results["forearm motion"] = case("forearm, motion level (simulation), 10 s", forearm, tr, None,
                                     mode="motion")
    tr_g = make_trial(gait, ["segment_mass:hat:delta=0.1"], duration=10.0, rate=100.0, seed=1)
    results["gait2d"] = case("gait2d, torso rows with GRF, 10 s @ 100 Hz", gait, tr_g, 20.0)
    t_add, r = best_of(lambda: run(forearm, tr, add=["payload:hand", "joint_damping"]))
    print(f"{'forearm run with two --add steps (3 diagnoses)':<44} {tr.n_frames:>6} {'':>5} {'':>8} {'':>8} "
          f"{t_add:8.3f} {'-':>7}  final verdict {r.verdict}")
    ok = results["forearm torque"] <= 2.0 and results["forearm muscle"] <= 2.0 and results["gait2d"] <= 20.0
    print("targets met" if ok else "TARGETS MISSED")


if __name__ == "__main__":
    main()
