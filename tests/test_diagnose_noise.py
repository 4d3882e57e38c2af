"""Noise floors that hold: coloured noise models, propagation through the model, consistent filtering.

The noise models of :mod:`pinmsk.signals.noise` against known spectra; the diagnosis floor
(:mod:`pinmsk.diagnose.noise`) against the noise the synthetic trials really carry; the floor
recomputed when an effect changes the model; GRF and kinematics filtered alike on a gait2d walk.
"""
from __future__ import annotations

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import compare, diagnose, make_trial, run
from pinmsk.diagnose.comparison import white_noise_sigma
from pinmsk.signals.filtering import lowpass
from pinmsk.signals.noise import band_edges, fit_noise, signal_band

RATE = 100.0


@pytest.fixture(scope="module")
def gait2d():          # forearm: tests/conftest.py's
    return pinmsk.load_model("gait2d")


def _signal(n=1001):
    t = np.arange(n) / RATE
    return t, 3 * np.sin(2 * np.pi * 0.8 * t) + np.sin(2 * np.pi * 1.3 * t)


# -- the noise models ---------------------------------------------------------------------------

def test_white_and_coloured_noise_models():
    """White noise comes back white; noise low-passed at 6 Hz comes back coloured with its corner and its
    full variance, of which third differences see a few per cent; signals with steps fit white only."""
    rng = np.random.default_rng(0)
    t, s = _signal()
    band = 2 * signal_band(s, RATE)
    assert 2.0 < band < 3.5 and band_edges(band, RATE)[-1] <= 0.45 * RATE
    white = 0.05 * rng.standard_normal(t.size)
    m = fit_noise(s + white, RATE, band)
    assert m.coloured[0] == 0 and m.rms()[0] == pytest.approx(white.std(), rel=0.1)
    col = lowpass(rng.standard_normal(t.size), rate=RATE, cutoff=6.0)
    col *= 0.05 / col.std()
    m = fit_noise(s + col, RATE, band)
    assert m.coloured[0] > 0 and m.corner[0] == pytest.approx(6.0, rel=0.15) and m.order[0] == 4
    assert m.rms()[0] == pytest.approx(0.05, rel=0.2)
    assert white_noise_sigma(s + col) < 0.1 * 0.05                 # what the old estimate saw
    draws = m.sample(np.random.default_rng(1), t.size, 4)
    assert np.std(draws) == pytest.approx(m.rms()[0], rel=0.1)
    # friction-like steps are signal: the white-only fit is not fooled into a coloured floor
    steps = s + white + 2.0 * np.sign(np.sin(2 * np.pi * 0.5 * t))
    assert fit_noise(steps, RATE, band, coloured=False).rms()[0] == pytest.approx(0.05, rel=0.25)
    # a known corner (an envelope's low-pass) fixes the shape
    m = fit_noise(s + col, RATE, band, corner=6.0)
    assert m.corner_given and m.corner[0] == 6.0 and m.rms()[0] == pytest.approx(0.05, rel=0.2)
    with pytest.raises(pinmsk.TrialError, match="noise corner 80 Hz"):
        fit_noise(s + col, RATE, band, corner=80.0)
    with pytest.raises(pinmsk.TrialError, match="too close to the top"):
        band_edges(30.0, RATE)


# -- EMG envelopes: their own noise model -----------------------------------------------------------

def _true_residual_noise(m, noisy, clean):
    """RMS of the residual the noise alone makes: the noisy trial's residual minus the noise-free one's."""
    return float(np.sqrt(np.mean((compare(m, noisy).residual - compare(m, clean).residual) ** 2)))


@pytest.mark.parametrize("lowpass_hz", [6.0, 3.0])
def test_clean_emg_driven_trial_is_at_the_floor(forearm, lowpass_hz):
    """EMG envelopes (rectified, low-passed at 6 or 3 Hz) carry multiplicative, coloured noise that third
    differences do not see: the floor propagates the envelope's own noise model through the muscles and
    matches the noise actually in the residual, so a clean trial comes out at the floor."""
    kw = dict(duration=10.0, rate=RATE, seed=21, measure=("excitations",), noise={"emg_lowpass": lowpass_hz})
    noisy = make_trial(forearm, [], **kw)
    assert noisy.meta["emg_lowpass"] == lowpass_hz
    clean = make_trial(forearm, [], **{**kw, "noise": None})
    d = diagnose(forearm, noisy, candidates=["electromechanical_delay", "joint_damping"])
    assert d.verdict == "at_noise_floor" and not d.significant, d.summary_text()
    assert 0.75 < d.ratio < 1.3
    truth = _true_residual_noise(forearm, noisy, clean)
    assert d.noise_floor["total"] == pytest.approx(truth, rel=0.25)
    em = d.comparison.noise.models["excitation"]
    assert em.kind == "multiplicative" and em.corner_given and np.all(em.corner == lowpass_hz)
    assert "EMG/excitation noise (relative noise low-passed at" in d.comparison.noise.method
    if lowpass_hz == 6.0:
        # without the trial's note of the low-pass the corner is fitted, and the floor still holds
        bare = pinmsk.Trial(noisy.time, {n: noisy[n] for n in noisy.names})
        c = compare(forearm, bare)
        assert not c.noise.models["excitation"].corner_given
        assert np.all(np.abs(c.noise.models["excitation"].corner - 6.0) < 1.5)
        assert 0.7 < c.ratio() < 1.35


# -- the floor is recomputed for every model ----------------------------------------------------

def test_floor_follows_the_model_after_an_add(forearm):
    """A 1 kg payload in the hand makes the same angle noise cost more moment: after the add the
    kinematic part of the floor is the new model's (as a fresh comparison of it), not the old one."""
    trial = make_trial(forearm, ["payload:hand:mass=1.0"], duration=8.0, rate=RATE, seed=11)
    r = run(forearm, trial, add=["payload:hand"])
    before, after = (s.comparison.noise for s in r.steps)
    assert after.propagated[0] > 1.3 * before.propagated[0]
    fresh = compare(r.model, trial).noise
    np.testing.assert_allclose(after.sigma, fresh.sigma, rtol=1e-12)
    assert r.verdict == "at_noise_floor"
    js = r.to_dict()["noise_model"]
    assert js["kinematic"]["elbow_flexion_moment"] == pytest.approx(after.propagated[0])
    assert set(js["sources"]) == {"coordinates", "moments"}


# -- consistent filtering on a walk -------------------------------------------------------------------

def test_walk_filters_ground_reaction_like_the_kinematics(gait2d):
    """A noise-free gait2d walk with heel-strike bounces: with kinematics and GRF through the same 6-Hz
    low-pass the torso residual stays at (below) the unfiltered level; low-passing only the kinematics
    leaves the impacts in the GRF and the residual 10x larger.  With realistic noise the clean walk is
    at the floor."""
    exact = make_trial(gait2d, [], duration=4.0, rate=RATE, noise=None, motion="walk")
    assert np.min(exact["l_ground_force_vy"]) == 0.0 and np.max(exact["l_ground_force_vy"]) > 700
    consistent = compare(gait2d, exact).rmse()["total"]
    unfiltered = compare(gait2d, exact, cutoff=0).rmse()["total"]
    inconsistent = compare(gait2d, exact, grf_cutoff=0).rmse()["total"]
    assert consistent <= unfiltered
    assert inconsistent > 10 * consistent
    inputs = compare(gait2d, exact).inputs
    assert inputs.filtering.applied_to == ("coordinates", "ground reaction")
    noisy = make_trial(gait2d, [], duration=6.0, rate=RATE, seed=2, motion="walk")
    d = diagnose(gait2d, noisy, candidates=["segment_mass:hat", "segment_mass:thigh_r"])
    assert d.verdict == "at_noise_floor" and not d.significant, d.summary_text()
    assert 0.8 < d.ratio < 1.2
    assert "ground-reaction noise" in d.comparison.noise.method
