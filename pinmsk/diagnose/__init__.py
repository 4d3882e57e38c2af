"""Diagnosis: compare a model with measurements, find the missing physical effect, add it, refit.

The loop, in a notebook::

    import pinmsk
    from pinmsk import diagnose as dx

    model = pinmsk.load_model("forearm")
    trial = pinmsk.read_trial("forearm_payload.csv")
    d = dx.diagnose(model, trial)          # where it fails, ranked effects
    print(d.summary_text())
    d.ranking[0].effect                    # the fitted effect, with uncertainties
    model2 = d.with_effect()               # model + the best significant effect
    d2 = dx.diagnose(model2, trial)        # the error falls; verdict at_noise_floor

and as the CLI does it: ``dx.run(model, trial, add=["payload:hand"])``, whose result
:func:`pinmsk.presentation.report.save_diagnosis` writes as JSON, report and figures.  Modules: :mod:`.compare` (residuals, modes,
noise floor), :mod:`.contact` (the contact mode: a driven foot's GRF, the contact
models as candidates, BIC), :mod:`.fit` (:class:`EffectFit`, the one way to fit an
effect, :class:`~.fit.JointProblem` for several at once, and cross-validation),
:mod:`.scoring` (joint refits, the held-out test, identifiability, pairs, what an
unexplained residual follows), :mod:`.diagnosis` (ranking, verdict, the loop),
:mod:`.synth` (hidden-effect trials).
"""
from . import synth
from .compare import DEFAULT_CUTOFF, Comparison, NoiseFloor, compare, external_forces_from_trial
from .diagnosis import ALPHA, AT_FLOOR, THRESHOLD, Diagnosis, DiagnosisRun, EffectScore, diagnose, parse_effect, run
from .fit import EffectFit
from .synth import make_trial

__all__ = [
    "ALPHA", "AT_FLOOR", "Comparison", "DEFAULT_CUTOFF", "Diagnosis", "DiagnosisRun", "EffectFit", "EffectScore",
    "NoiseFloor", "THRESHOLD", "compare", "diagnose", "external_forces_from_trial",
    "make_trial", "parse_effect", "run", "synth",
]
