"""Noise floors on short and real trials, and residuals that are systematic, not noise.

* the robust band powers keep their shape when the event guard around a spike is longer than the
  record (a 2 s trial whose movement lies below 1 Hz);
* after the true electromechanical delay joins the model, activation dynamics -- a low-pass of the
  EMG that also filters its noise -- is not significant: the noise it filters is counted for the chain
  of the joint fit, with the delay as refitted;
"""
from __future__ import annotations

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import diagnose, make_trial, run
from pinmsk.signals.noise import band_edges, band_powers


# -- short trials ----------------------------------------------------------------------------------

def test_band_powers_event_guard_longer_than_the_record():
    """White noise, 151 samples at 100 Hz, lowest band at 1.98 Hz: in that narrow band the noise itself
    has peaks beyond 5 robust standard deviations (seed 8, column 0), and the guard either side of an
    event (1.5 rate / f_low = 76 samples) spans more than the record.  The powers keep their (J, k)
    shape (the guard used to come back 153 samples long) and match a sample-by-sample computation of
    the rule: the mean square away from the guarded events, or ``(MAD / 0.6745)^2`` where fewer than a
    quarter of the samples remain."""
    from scipy.signal import butter, sosfiltfilt

    x = np.column_stack([np.random.default_rng(8).standard_normal(151),
                         np.random.default_rng(9).standard_normal(151)])
    x[140, 1] += 12.0
    rate = 100.0
    edges = band_edges(1.98, rate)
    P = band_powers(x, rate, edges)
    assert P.shape == (len(edges) - 1, 2)
    long_guard_events = 0
    for j, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        sos = butter(2, [a / (0.5 * rate), b / (0.5 * rate)], btype="band", output="sos")
        half = int(np.ceil(1.5 * rate / a))
        for k in range(2):
            y = sosfiltfilt(sos, x[:, k])
            scale = np.median(np.abs(y)) / 0.6745
            hit = np.flatnonzero(np.abs(y) > 5.0 * scale)
            long_guard_events += int(hit.size > 0 and 2 * half + 1 > y.size)
            keep = np.array([not np.any(np.abs(hit - i) <= half) for i in range(y.size)])
            want = np.mean(y[keep] ** 2) if keep.sum() >= 0.25 * y.size else scale ** 2
            assert P[j, k] == pytest.approx(want, rel=1e-12), (j, k)
    assert long_guard_events >= 1                          # the case that broke is exercised


@pytest.mark.parametrize("rate", [75.0, 76.0, 100.0])
def test_two_second_trial_with_slow_movement_diagnoses(forearm, rate):
    """A valid 2 s forearm trial (seed 3: its movement lies below 1 Hz, so the noise bands start near
    2 Hz) with hidden Coulomb friction, whose steps are events in the residual: the diagnosis runs
    (it crashed in band_powers with shapes (153, 1) and (151, 1) at 100 Hz) and its floor is finite."""
    trial = make_trial(forearm, ["coulomb_friction:elbow_flexion"], duration=2.0, rate=rate, seed=3)
    d = diagnose(forearm, trial, folds=3, candidates=["coulomb_friction", "joint_damping"])
    assert d.comparison.noise.info["band_start_hz"] < 2.5
    assert np.all(np.isfinite(d.comparison.noise.sigma)) and np.all(d.comparison.noise.sigma > 0)
    assert d.verdict in ("missing_effect", "at_noise_floor")


# -- muscle level: a delay, then activation dynamics -----------------------------------------------

def test_activation_dynamics_not_significant_after_the_true_delay(forearm):
    """Hidden delay 30 ms (seed 3): the delay is found; with it in the model, activation dynamics refitted
    jointly with it takes the delay to zero and filters 30 % of the residual's power, nearly all of it
    envelope noise.  Counting the filtered noise with the delay as the joint fit leaves it (not the delay
    of the model, which filters nothing) the candidate is not significant and the verdict is
    at_noise_floor (before: z = 4.5, suggested)."""
    hidden = pinmsk.effects.get("electromechanical_delay")("muscles", delay=0.03)
    trial = make_trial(forearm, [hidden], duration=8.0, rate=100.0, seed=3)
    r = run(forearm, trial, add=["electromechanical_delay"],
            candidates=["electromechanical_delay", "activation_dynamics"])
    first = r.steps[0]
    assert first.best is not None and first.best.family == "electromechanical_delay"
    delay = r.model.component("electromechanical_delay:muscles").values["delay"]
    assert delay == pytest.approx(0.03, abs=0.015)
    final = r.final
    ad = final.score("activation_dynamics")
    assert ad is not None and not ad.significant, final.summary_text()
    assert ad.test["z"] < final.settings["z_critical"]
    assert final.verdict == "at_noise_floor", final.summary_text()
