"""Muscle level under realistic EMG envelope noise: a delay, activation dynamics, or both, told apart.

Each hidden chain is ranked against the three candidates fitted alone and together
(``electromechanical_delay``, ``activation_dynamics``, ``delayed_activation_dynamics``); the one with the
best held-out score wins, fewer parameters on a tie.  The parameters come back within their standard
errors (coloured envelope noise makes ``tau_rise`` the loosest), and the model with the winner is at the
noise floor, recomputed through its chain.
"""
from __future__ import annotations

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import diagnose, make_trial

CANDIDATES = ["electromechanical_delay", "activation_dynamics", "delayed_activation_dynamics"]

CASES = [
    ("electromechanical_delay", {"delay": 0.05}),
    ("activation_dynamics", {"tau_rise": 0.03, "tau_fall": 0.06}),
    ("delayed_activation_dynamics", {"delay": 0.03, "tau_rise": 0.02, "tau_fall": 0.08}),
]


@pytest.mark.parametrize("family,truth", CASES, ids=["delay", "activation", "both"])
def test_delay_activation_or_both(forearm, family, truth):          # forearm: tests/conftest.py's
    hidden = pinmsk.effects.get(family)("muscles", **truth)
    trial = make_trial(forearm, [hidden], duration=8.0, rate=100.0, seed=4)
    d = diagnose(forearm, trial, candidates=CANDIDATES)
    assert d.verdict == "missing_effect"
    best = d.ranking[0]
    assert best.family == family and best.significant, d.summary_text()
    for k, v in truth.items():
        se = best.stderr[k]
        assert se is not None and np.isfinite(se), (k, se)
        assert abs(best.params[k] - v) < max(3.0 * se, 0.1 * v), (k, best.params[k], se, v)
    others = {s.family: s for s in d.ranking[1:]}
    assert set(others) == set(CANDIDATES) - {family}
    after = diagnose(d.with_effect(), trial, candidates=["joint_damping"])
    assert after.verdict == "at_noise_floor", after.summary_text()
    # the floor went through the new chain: activation dynamics filter the EMG noise, a delay does not
    ratio = after.comparison.noise.white[0] / d.comparison.noise.white[0]
    if family == "electromechanical_delay":
        assert ratio == pytest.approx(1.0, abs=0.05)
    else:
        assert ratio < 0.97


def test_emg_for_some_muscles_refuses_the_muscle_level_not_the_torque_level():
    """EMG for 2 of the forearm's 7 muscles: the muscle level (and the automatic choice, which would
    otherwise drop the EMG unseen) is refused by name, pointing at the torque level; the torque level
    compares no excitation and gives the same equation error as without the EMG channels."""
    from pinmsk.diagnose import compare
    from pinmsk.errors import TrialError
    model = pinmsk.load_model("forearm")
    trial = make_trial(model, ["joint_damping:elbow_flexion:c=0.2"], duration=2.0, rate=100.0, seed=1)
    emg = {f"{m}_emg": 0.1 + 0.05 * np.sin(np.asarray(trial.time) + k)
           for k, m in enumerate(model.muscle_names[:2])}
    part = trial.with_channels(emg)
    for mode in ("auto", "muscle"):
        with pytest.raises(TrialError, match=r"emg channels for some muscles \(2 of 7\) but not BICSH_emg, .*"
                                             r"mode='torque' \(--mode torque\)"):
            compare(model, part, mode=mode)
    got, ref = compare(model, part, mode="torque"), compare(model, trial, mode="torque")
    assert got.mode == "torque"
    np.testing.assert_array_equal(got.eq.e, ref.eq.e)
