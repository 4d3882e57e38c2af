"""Diagnose a forearm trial with a hidden effect: compare, rank, add, compare again.

    python examples/01_diagnose_forearm.py [OUT_DIR]

The trial (data/forearm_payload_damping.csv) was recorded -- synthesised, see
data/README.md -- from a forearm holding 0.5 kg with 0.2 N m s/rad of joint
damping; the model knows neither.  Two rounds of "rank, add the best" find both.
Headless: writes figures and an HTML report to OUT_DIR (default: a new temporary folder).
"""
import sys

import pinmsk
from pinmsk import diagnose as dx
from pinmsk.io.shared_data import shipped_trial
from pinmsk.presentation.report import save_diagnosis
from _common import output_folder

out = output_folder(sys.argv[1] if len(sys.argv) > 1 else None, "01_diagnose_forearm")
model = pinmsk.load_model("forearm")
trial = pinmsk.read_trial(shipped_trial("forearm_payload_damping.csv"))

d = dx.diagnose(model, trial)                    # where the model fails, and the ranked effects
print(d.summary_text())
print()
for step in range(3):
    if d.verdict == "at_noise_floor":
        break
    best = d.best                                 # the fitted effect that explains most, held out
    print(f"adding {best.label}: {best.describe_params()}")
    model = model + best.effect                   # a new model; the old one is unchanged
    d = dx.diagnose(model, trial)
    print(f"  total rmse now {d.rmse['total']:.4g} (noise floor {d.noise_floor['total']:.4g}): {d.verdict}")

# the same loop as the CLI runs it, with figures and a report
result = dx.run(pinmsk.load_model("forearm"), trial, add=[e.label for e in model.effects])
save_diagnosis(result, report_path=out / "diagnosis_report.html", plot_dir=out / "figures")
print()
print(f"final verdict: {result.verdict}; model effects: {', '.join(c.label for c in result.model.components)}")
