"""The diagnosis loop: backward elimination after each joint refit (``--remove``), and a validation design
that adapts to short trials (``--folds``, one stride of a walk).

The synthetic trials (:func:`pinmsk.diagnose.make_trial`) hide known effects; each test checks the
recovery against that truth.  The one-stride walk is OpenSim's IK of the Gait2354 pipeline.
"""
from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import diagnose, make_trial, run
from pinmsk.diagnose.diagnosis import FOLDS, MIN_BLOCK, MIN_TRAIN, choose_folds
from pinmsk.errors import ModelError, TrialError
from pinmsk.presentation.cli import build_parser, main

SEGMENT = "segment_mass:forearm_hand"
PAYLOAD = "payload:hand"


@pytest.fixture(scope="module")
def payload_trial(forearm):
    """The forearm holding a true 0.5 kg payload at the hand."""
    return make_trial(forearm, ["payload:hand:mass=0.5"], seed=1)


@pytest.fixture(scope="module")
def wrong_first(forearm, payload_trial):
    """segment_mass added first (the wrong effect), then the true payload, then segment_mass removed."""
    return run(forearm, payload_trial, add=["segment_mass", PAYLOAD], remove=[SEGMENT])


def _entry(d, label):
    return next(e for e in d.elimination if e["label"] == label)


# -- backward elimination ---------------------------------------------------------------------------

def test_segment_mass_made_redundant_by_the_hand_payload_is_named_and_removed(wrong_first):
    r = wrong_first
    assert len(r.steps) == 4 and [x["removed"] for x in r.removed] == [SEGMENT]
    alone = r.steps[1]                                    # segment_mass alone takes the payload: kept
    assert _entry(alone, SEGMENT)["significant"] and alone.suggest_remove is None
    both = r.steps[2]                                     # the payload joined: segment_mass is redundant
    seg, pay = _entry(both, SEGMENT), _entry(both, PAYLOAD)
    assert seg["significant"] is False and seg["suggest_remove"]
    assert seg["z"] < seg["critical_z"] and abs(seg["improvement"]) < 0.05     # noise variances per frame
    assert seg["alias_of"] == PAYLOAD and seg["alias_correlation"] > 0.99
    assert pay["significant"] and pay["z"] > 5 and not pay["suggest_remove"]
    assert both.suggest_remove == SEGMENT and both.stopping["suggest_remove"] == SEGMENT
    assert f"remove it with --remove {SEGMENT}" in both.verdict_line()
    # the joint refit had left the payload light (segment_mass took part of it) ...
    mass_before = both.model.component(PAYLOAD).values["mass"]
    assert mass_before < 0.48
    # ... the removal refits it without segment_mass: back to the truth, and the loop ends normally
    final = r.final
    assert [c.label for c in final.model.components] == [PAYLOAD]
    assert final.model.component(PAYLOAD).values["mass"] == pytest.approx(0.5, abs=0.01)
    moved = r.removed[0]["effects"][0]["params"]["mass"]
    assert moved["before"] == pytest.approx(mass_before) and moved["after"] == pytest.approx(0.5, abs=0.01)
    assert final.verdict == "at_noise_floor" and final.suggest_remove is None
    assert _entry(final, PAYLOAD)["significant"] and "--remove" not in final.verdict_line()
    text = r.summary_text()
    assert f"step 3: removed {SEGMENT}" in text and f"-> remove it: --remove {SEGMENT}" in text


def test_elimination_and_removal_in_the_json(wrong_first, tmp_path):
    d = json.loads(wrong_first.write_json(tmp_path / "d.json").read_text())
    for key in ("inputs", "rmse", "noise_floor", "ranking", "verdict", "added", "refit", "pairs", "stopping"):
        assert key in d
    assert [a["effect"] for a in d["added"]] == ["payload"]          # the removed one is not in the final model
    assert d["removed"][0]["removed"] == SEGMENT
    (e,) = d["elimination"]
    assert set(e) >= {"label", "significant", "improvement", "z", "critical_z", "bic_change", "alias_of",
                      "alias_correlation", "determined", "suggest_remove", "without"}
    assert e["label"] == PAYLOAD and e["significant"] and e["without"] == "switched off (mass = 0)"
    assert d["stopping"]["suggest_remove"] is None


def test_two_true_effects_are_both_kept(forearm):
    trial = make_trial(forearm, ["payload:hand:mass=0.5", "joint_damping:elbow_flexion:c=0.2"], seed=2)
    r = run(forearm, trial, add=[PAYLOAD, "joint_damping"])
    final = r.final
    assert [e["significant"] for e in final.elimination] == [True, True]
    assert final.suggest_remove is None and final.verdict == "at_noise_floor"
    assert all(e["alias_of"] is None for e in final.elimination)


def test_an_exact_alias_is_dropped_and_the_true_effect_kept(forearm):
    """A sensor gain and a segment mass on a one-body model change the moment alike (rank deficient): the
    gain, added second on a segment-mass trial, explains nothing beside the mass and is the one to drop."""
    trial = make_trial(forearm, ["segment_mass:forearm_hand:delta=0.3"], seed=3)
    r = run(forearm, trial, add=["segment_mass", "sensor_gain:elbow_flexion"], remove=["sensor_gain"])
    both = r.steps[2]
    gain = _entry(both, "sensor_gain:elbow_flexion")
    assert gain["suggest_remove"] and gain["alias_of"] == SEGMENT and gain["alias_correlation"] > 0.999
    assert both.suggest_remove == "sensor_gain:elbow_flexion"
    assert [c.label for c in r.model.components] == [SEGMENT]
    assert r.model.component(SEGMENT).values["delta"] == pytest.approx(0.3, abs=0.02)
    assert r.verdict == "at_noise_floor" and r.final.suggest_remove is None


def test_remove_refuses_an_effect_the_model_lacks(forearm, payload_trial):
    with pytest.raises(ModelError, match="remove names 'joint_damping'.*its effects: none"):
        run(forearm, payload_trial, remove=["joint_damping"])


def test_effect_spec_values_are_held(forearm):
    """``family:target:name=value`` holds that parameter: the fit moves only the others."""
    trial = make_trial(forearm, ["joint_spring:elbow_flexion:k=2,q0=0.5"], seed=3)
    r = run(forearm, trial, add=["joint_spring:elbow_flexion:q0=0.5"])
    spring = r.model.component("joint_spring:elbow_flexion")
    assert spring.values["q0"] == 0.5 and not spring.params["q0"].vary
    assert spring.values["k"] == pytest.approx(2.0, rel=0.02)


@pytest.mark.slow          # the removal itself runs by default in test_an_exact_alias_is_dropped_and_the_true_effect_kept
def test_cli_suggests_and_does_the_removal(tmp_path, capsys):
    src = tmp_path / "pay.csv"
    assert main(["synth", "forearm", "--effect", "payload:hand:mass=0.5", "--seed", "1", "-o", str(src)]) == 0
    out = tmp_path / "d.json"
    assert main(["diagnose", "forearm", str(src), "--add", "segment_mass", "--add", PAYLOAD,
                 "--remove", SEGMENT, "--json", str(out)]) == 0
    text = capsys.readouterr().out                     # every step: the suggestion after the adds, then the removal
    assert f"remove it with --remove {SEGMENT}" in text and f"step 3: removed {SEGMENT}" in text
    d = json.loads(out.read_text())
    assert d["removed"][0]["removed"] == SEGMENT and d["verdict"] == "at_noise_floor"
    assert d["added"][0]["params"]["mass"] == pytest.approx(0.5, abs=0.01)
    capsys.readouterr()
    assert main(["diagnose", "forearm", str(src), "--remove", "joint_damping"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "remove names 'joint_damping'" in err[0]


# -- short trials ---------------------------------------------------------------------------------------

def test_folds_are_chosen_for_the_trial_length():
    assert choose_folds(5 * MIN_BLOCK, None, 17) == (FOLDS, "")
    k, note = choose_folds(3 * MIN_BLOCK + 5, None, 10)
    assert k == 3 and "3 folds, not 5" in note
    k, note = choose_folds(43, None, 10)                 # one stride at 60 Hz: 2 blocks of 21-22
    assert k == 2 and "43 analysable samples" in note
    k, note = choose_folds(34, None, 5)                  # blocks of 17: shorter than MIN_BLOCK, still valid
    assert k == 2 and "too few for blocks of 20" in note
    assert choose_folds(100, 4, 10) == (4, "")           # given: as given
    with pytest.raises(TrialError, match=r"too few for 5 cross-validation blocks.*--folds 2 \(folds=2"):
        choose_folds(43, 5, 10)
    # the training set must keep MIN_TRAIN rows beside the guard: 31 rows, blocks of 16, guard 10 leave 5
    with pytest.raises(TrialError, match=f"leaves 5 to fit on, fewer than {MIN_TRAIN}; record a longer trial"):
        choose_folds(31, None, 10)


def test_short_trial_hidden_effects_are_found(forearm):
    """1.2 s at 60 Hz (one stride's length): 43 analysable samples, two blocks; a hidden damping and a hidden
    payload are each found, and after the add the loop stops at the noise floor."""
    for spec, label, name, true in [("joint_damping:elbow_flexion:c=0.2", "joint_damping:elbow_flexion", "c", 0.2),
                                    ("payload:hand:mass=0.2", PAYLOAD, "mass", 0.2)]:
        trial = make_trial(forearm, [spec], duration=1.2, rate=60.0, seed=2)
        r = run(forearm, trial, add=[label])
        first = r.steps[0]
        assert first.comparison.eq.rows.size == 43 and first.settings["guard"] == 10
        assert first.stopping["folds"] == 2 and first.stopping["folds_chosen"] == "auto"
        assert "2 folds, not 5: 43 analysable samples" in first.stopping["blocks"]
        assert first.best.label == label and first.best.test["z"] > 5
        assert first.best.params[name] == pytest.approx(true, rel=0.05)
        assert r.verdict == "at_noise_floor"
    with pytest.raises(TrialError, match="--folds 2"):
        diagnose(forearm, trial, folds=5)


def test_short_trial_worst_windows_hold_ten_samples(forearm):
    trial = make_trial(forearm, ["payload:hand:mass=0.2"], duration=1.2, rate=60.0, seed=2)
    d = diagnose(forearm, trial)
    spans = {round(w["end"] - w["start"], 6) for w in d.worst_windows}
    assert spans and min(spans) >= 10 / 60 - 1e-9


def test_folds_flag(tmp_path, capsys):
    src = tmp_path / "short.csv"
    assert main(["synth", "forearm", "--effect", "payload:hand:mass=0.2", "--duration", "1.2", "--rate", "60",
                 "--seed", "2", "-o", str(src)]) == 0
    out = tmp_path / "d.json"
    assert main(["diagnose", "forearm", str(src), "--json", str(out)]) == 0
    assert json.loads(out.read_text())["stopping"]["folds"] == 2
    assert main(["diagnose", "forearm", str(src), "--folds", "3", "--json", str(out)]) == 2
    assert "pass --folds 2" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["diagnose", "forearm", str(src), "--folds", "1"])
    assert exc.value.code == 2


def test_every_command_line_remedy_in_the_diagnosis_messages_exists():
    """Each ``--flag`` a message of pinmsk/diagnose suggests is an option of ``pinmsk diagnose`` (of
    ``pinmsk synth`` for the synthetic trials' module)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    options = {name: set(sub.choices[name]._option_string_actions) for name in ("diagnose", "synth")}
    found = set()
    for path in sorted((Path(pinmsk.__file__).parent / "diagnose").glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                found |= {(path.name, f) for f in re.findall(r"(?<![\w-])--[a-z][a-z-]+", node.value)}
    assert {f for _, f in found} >= {"--add", "--remove", "--folds", "--window", "--mode"}
    missing = sorted((p, f) for p, f in found if f not in options["synth" if p == "synth.py" else "diagnose"])
    assert not missing, missing


# -- one stride of a real walk ------------------------------------------------------------------------------

@pytest.mark.filterwarnings("ignore:.*approximated by fixed-axis joints")
def test_gait2354_one_stride_walk_diagnoses(shared_data):
    d = Path(shared_data) / "opensim-models" / "Gait2354Pipeline"
    if not (d / "OutputReference" / "subject01_walk1_ik.mot").exists():
        pytest.skip("the Gait2354 pipeline is not in the shared data")
    model = pinmsk.load_model(str(d / "OutputReference" / "subject01_simbody.osim"), nonlinear="fit")
    trial = pinmsk.read_trial(d / "OutputReference" / "subject01_walk1_ik.mot")
    assert trial.n_frames == 73                          # 0.4-1.6 s at 60 Hz
    diag = diagnose(model, trial, external_loads=d / "forces_grf.xml")
    assert diag.comparison.eq.rows.size == 43            # 0.25 s (1.5 / 6 Hz) left out at each end
    assert diag.stopping["folds"] == 2 and diag.stopping["folds_chosen"] == "auto"
    assert diag.ranking and all(np.isfinite(s.test["z"]) for s in diag.ranking)
    assert diag.verdict in ("at_noise_floor", "missing_effect")


def test_a_fold_that_did_not_converge_is_reported(forearm, payload_trial, monkeypatch):
    """The held-out test rests on one fit per fold: a fold's unconverged fit shows in the note and JSON."""
    from pinmsk.diagnose.fit import EffectFit, JointProblem
    real = {cls: cls.cross_validate for cls in (EffectFit, JointProblem)}

    def stopped(cls):
        def cv(self, *a, **k):
            e, _ = real[cls](self, *a, **k)
            return e, False
        return cv

    d = diagnose(forearm, payload_trial, candidates=["payload:hand"])
    assert d.ranking[0].test["folds_converged"] is True and "fold" not in d.ranking[0].note
    for cls in real:
        monkeypatch.setattr(cls, "cross_validate", stopped(cls))
    d = diagnose(forearm, payload_trial, candidates=["payload:hand"])
    s = d.ranking[0]
    assert s.test["folds_converged"] is False and "cross-validation fold" in s.note
    assert d.to_dict()["ranking"][0]["held_out_test"]["folds_converged"] is False
