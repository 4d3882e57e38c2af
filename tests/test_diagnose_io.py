"""Diagnosis bad input, figures, the HTML report, the shipped trials, the demo and the example."""
from __future__ import annotations

import json

import numpy as np
import pytest

import pinmsk
from pinmsk import effects
from pinmsk.components import Parameter
from pinmsk.demo import demo
from pinmsk.diagnose import EffectFit, compare, diagnose, make_trial, run
from pinmsk.io.shared_data import shipped_trial, shipped_trials
from pinmsk.presentation.report import save_diagnosis, write_failure_report, write_report
from pinmsk.errors import ConvergenceError, ModelError, TrialError

from conftest import REPO


@pytest.fixture(scope="module")
def forearm():
    return pinmsk.load_model("forearm")


@pytest.fixture(scope="module")
def damped(forearm):
    return make_trial(forearm, ["joint_damping:elbow_flexion:c=0.3"], seed=5)


# -- bad input ------------------------------------------------------------------------------

def test_no_comparable_channel(forearm):
    t = np.linspace(0, 10, 1001)
    tr = pinmsk.Trial(t, {"elbow_flexion": np.sin(t), "something_else": t})
    with pytest.raises(TrialError, match="no channel model 'forearm' can be compared on.*elbow_flexion_moment"):
        diagnose(forearm, tr)
    tr = pinmsk.Trial(t, {"elbow_flex": np.sin(t), "elbow_flexion_moment": t})
    with pytest.raises(TrialError, match="no channel for coordinate.*elbow_flexion.*did you mean 'elbow_flex'"):
        diagnose(forearm, tr)
    with pytest.raises(TrialError, match="excitation or EMG channels.*BRD_excitation"):
        diagnose(forearm, pinmsk.Trial(t, {"elbow_flexion": np.sin(t), "elbow_flexion_moment": t}),
                 mode="muscle")
    part = {"elbow_flexion": np.sin(t), "BRD_excitation": 0 * t + 0.1}
    with pytest.raises(TrialError, match="not BICLH_excitation"):
        diagnose(forearm, pinmsk.Trial(t, part))
    with pytest.raises(ModelError, match="unknown comparison mode 'torq'"):
        diagnose(forearm, pinmsk.Trial(t, {"elbow_flexion": np.sin(t), "elbow_flexion_moment": t}),
                 mode="torq")


def test_motion_mode_refuses_a_floating_base():
    g = pinmsk.load_model("gait2d")
    tr = make_trial(g, [], duration=2.0, seed=1, noise=None)
    with pytest.raises(TrialError, match="floating base.*torso_x.*mode='torque'"):
        diagnose(g, tr, mode="motion")


def test_too_few_samples(forearm):
    short = make_trial(forearm, [], duration=1.5, rate=50.0, seed=1)
    with pytest.raises(TrialError, match=r"too few for 5 cross-validation blocks.*folds=\d"):
        diagnose(forearm, short, folds=5)
    tiny = make_trial(forearm, [], duration=0.4, rate=50.0, seed=1)
    with pytest.raises(TrialError, match="samples"):
        diagnose(forearm, tiny)
    ok = make_trial(forearm, [], duration=6.0, rate=100.0, seed=1)
    with pytest.raises(TrialError, match="need at least 10 per window"):
        diagnose(forearm, ok, window=0.05)


def test_unknown_effect_or_target_lists_what_exists(forearm, damped):
    with pytest.raises(ModelError, match="unknown effect 'joint_dampng'.*did you mean 'joint_damping'.*"
                                         "known effects: .*coulomb_friction"):
        run(forearm, damped, add=["joint_dampng"])
    with pytest.raises(ModelError, match="no coordinate 'knee'.*Targets for joint_damping.*elbow_flexion"):
        run(forearm, damped, add=["joint_damping:knee"])
    with pytest.raises(ModelError, match="no frame 'hnd'.*did you mean 'hand'"):
        run(forearm, damped, add=["payload:hnd"])
    with pytest.raises(ModelError, match="'riener_edrich_1999' does not apply.*pick one of: .*joint_damping:elbow_flexion"):
        run(forearm, damped, add=["riener_edrich_1999"])
    with pytest.raises(ModelError, match="only be fitted in a muscle-level comparison"):
        run(forearm, damped, add=["activation_dynamics:muscles"])


class _Broken(effects.JointEffect):
    """A user effect that returns NaN: its fit cannot converge."""
    family = "test_broken_effect"
    parameters = (Parameter("a", 1.0, 0.0, 10.0, "N m", "amplitude"),
                  Parameter("b", 1.0, 0.1, 10.0, "1", "shape"))

    def _force(self, q, v, p):
        return np.full_like(q, np.nan)


def test_fit_that_does_not_converge(forearm, damped):
    c = compare(forearm, damped)
    with pytest.raises(ConvergenceError, match="passive_elastic:elbow_flexion did not converge after"):
        EffectFit(effects.PassiveElastic("elbow_flexion"), max_nfev=1).fit(c)
    with pytest.raises(ConvergenceError, match="test_broken_effect:elbow_flexion.*non-finite"):
        EffectFit(_Broken("elbow_flexion")).fit(c)
    # in a ranking the candidate is skipped with the reason, not a traceback
    d = diagnose(forearm, damped, candidates=[_Broken("elbow_flexion"), "joint_damping"])
    assert [s.label for s in d.ranking] == ["joint_damping:elbow_flexion"]
    assert d.skipped and "non-finite" in d.skipped[0][1]
    assert "skipped test_broken_effect" in d.summary_text()


# -- figures and report --------------------------------------------------------------------

# slow: test_demo_writes_everything writes the same figures and report by default
@pytest.mark.slow
def test_figures_and_report(tmp_path, forearm):
    from pinmsk.presentation import plots
    trial = make_trial(forearm, ["payload:hand:mass=0.5", "joint_damping:elbow_flexion:c=0.2"], seed=12)
    result = run(forearm, trial, add=["payload:hand"])
    save_diagnosis(result, plot_dir=tmp_path / "fig", report_path=tmp_path / "r.html", json_path=tmp_path / "r.json")
    names = {p.name for p in (tmp_path / "fig").glob("*.png")}
    assert names == {"comparison_before.png", "comparison_after.png", "residual_heatmap.png", "ranking.png",
                     "effect_contribution.png", "error_steps.png"}
    for p in (tmp_path / "fig").glob("*.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000
    html = (tmp_path / "r.html").read_text()
    assert html.count("data:image/png;base64,") >= 6
    assert "http://" not in html and "https://" not in html and "<script" not in html
    for needle in ("payload:hand", "joint_damping:elbow_flexion", "noise floor", "Worst windows", "forearm",
                   "missing_effect", "mass", "std. error"):
        assert needle in html, needle
    assert json.loads((tmp_path / "r.json").read_text())["added"][0]["effect"] == "payload"
    # channel plots used by `pinmsk id --plot`
    out = plots.save_channels(trial, ["elbow_flexion", "elbow_flexion_moment"], tmp_path / "ch", stem="id")
    assert [p.name for p in out] == ["id.png"]
    # one diagnosis report on its own, and the page of a diagnosis that could not run
    p = write_report(result.steps[0], tmp_path / "one.html")
    assert "payload:hand" in p.read_text()
    t = np.linspace(0, 1, 51)
    short = pinmsk.Trial(t, {"elbow_flexion": 0.5 + t, "elbow_flexion_moment": np.sin(t)})
    with pytest.raises(pinmsk.PinmskError) as err:
        run(forearm, short)
    p = write_failure_report(tmp_path / "short.html", forearm, short, err.value)
    text = p.read_text()
    assert "could not run" in text and "data:image/png;base64," in text


# -- shipped data, demo and example -------------------------------------------------------------

def test_shipped_trials_are_documented_and_diagnosable(forearm):
    names = shipped_trials()
    assert {"forearm_payload.csv", "forearm_payload_damping.csv", "gait2d_hat_mass.csv"} <= set(names)
    readme = (REPO / "data" / "README.md").read_text()
    for n in names:
        assert n in readme
        assert shipped_trial(n).stat().st_size < 200_000
    d = diagnose(forearm, pinmsk.read_trial(shipped_trial("forearm_payload.csv")))
    assert d.best.label == "payload:hand" and d.best.params["mass"] == pytest.approx(1.0, rel=0.05)
    with pytest.raises(TrialError, match="no shipped trial 'nope.csv'.*forearm_payload.csv"):
        shipped_trial("nope.csv")


def test_shipped_gait_trial():
    g = pinmsk.load_model("gait2d")
    r = run(g, pinmsk.read_trial(shipped_trial("gait2d_hat_mass.csv")), add=["segment_mass:hat"])
    assert r.steps[0].best.label == "segment_mass:hat"
    assert r.added[0].params["delta"] == pytest.approx(0.1, rel=0.15)
    assert r.verdict == "at_noise_floor"


def test_demo_writes_everything(tmp_path):
    lines = []
    result = demo(tmp_path, echo=lines.append)
    text = "\n".join(lines)
    assert "payload:hand" in text and "total rmse before" in text and "at_noise_floor" in text
    for name in ("before.png", "after.png", "report.html", "diagnosis.json"):
        assert (tmp_path / name).stat().st_size > 1000, name
    assert result.steps[0].ratio > 5 and result.final.ratio < 1.5


def test_synth_bad_requests(forearm):
    with pytest.raises(ModelError, match="multi-joint muscles.*rectus_femoris_r"):
        make_trial("gait2d", [], measure=("grf", "excitations"))
    with pytest.raises(ModelError, match="fixed to the world"):
        make_trial(forearm, [], measure=("grf",))
    with pytest.raises(ModelError, match="include 'excitations'"):
        make_trial(forearm, ["activation_dynamics"], measure=("moments",))
    with pytest.raises(ModelError, match="unknown noise keys.*angle"):
        make_trial(forearm, [], noise={"angel": 0.1})


def test_effect_fit_estimator(forearm, damped):
    est = EffectFit(effects.JointDamping("elbow_flexion"))
    assert not hasattr(est, "effect_")                       # the constructor only stores arguments
    assert est.fit(compare(forearm, damped)) is est
    assert est.params_["c"] == pytest.approx(0.3, rel=0.05) and est.stderr_["c"] < 0.01
    assert est.converged_ and est.n_params_ == 1 and est.bic_change_ < -100 and est.aic_change_ < -100
    assert est.effect_.params["c"].stderr == est.stderr_["c"]
    assert est.report().startswith("joint_damping:elbow_flexion: c = 0.") and "BIC change" in est.report()
