"""Noise floors on short and real trials, and residuals that are systematic, not noise.

* the robust band powers keep their shape when the event guard around a spike is longer than the
  record (a 2 s trial whose movement lies below 1 Hz);
* after the true electromechanical delay joins the model, activation dynamics -- a low-pass of the
  EMG that also filters its noise -- is not significant: the noise it filters is counted for the chain
  of the joint fit, with the delay as refitted;
* the angles' noise model takes a movement's spectral tail (heel strikes) for movement: a coloured
  (low-passed) part only where its flat passband is seen; the floor is checked against the residual;
* a residual whose mean over the trial is significant (Newey-West) is systematic, never at the floor;
* noise levels the user states replace the fitted ones;
* on OpenSim's subject01 walk the floor holds and the verdict is not at_noise_floor (skips without
  the shared data).
"""
from __future__ import annotations

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import compare, diagnose, make_trial, run
from pinmsk.diagnose.noise import consistency, parse_noise
from pinmsk.diagnose.scoring import hac_mean
from pinmsk.signals.filtering import lowpass
from pinmsk.signals.noise import band_edges, band_powers, fit_noise


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


# -- the floor never takes movement for noise --------------------------------------------------------

def test_angle_noise_of_a_walk_is_the_noise_not_the_heel_strikes():
    """A gait2d walk with heel-strike bounces: noise-free, the angles' noise model is (almost) nothing --
    the bounces' spectrum above the band start is movement, not low-passed noise; with the realistic
    0.2 deg of white angle noise the model is white at 0.2 deg (within 10 %)."""
    g = pinmsk.load_model("gait2d")
    exact = make_trial(g, [], duration=6.0, rate=100.0, noise=None, motion="walk")
    cm = compare(g, exact).noise.models["coordinates"]
    assert np.all(cm.coloured == 0)
    assert np.max(np.rad2deg(cm.rms())) < 0.01
    noisy = make_trial(g, [], duration=6.0, rate=100.0, seed=2, motion="walk")
    cm = compare(g, noisy).noise.models["coordinates"]
    rot = [j for j, c in enumerate(cm.channels) if c not in ("torso_x", "torso_y")]
    assert np.all(cm.coloured == 0)
    np.testing.assert_allclose(np.rad2deg(cm.rms()[rot]), 0.2, rtol=0.1)


def test_low_passed_noise_needs_its_flat_passband():
    """Noise low-passed at 8 Hz (flat from the 2.2 Hz band start to the corner) is coloured with
    ``flat_passband``; a spectrum that falls from the band start on (a movement's tail, power 1/f^4
    above 2 Hz, over white noise of 0.05 that it meets near 9 Hz) is white there, at the level of its
    flat top, where the unchecked fit takes the tail for noise low-passed at 5.6 Hz (5.5x the level)."""
    rng = np.random.default_rng(3)
    rate, n = 100.0, 1001
    t = np.arange(n) / rate
    s = 3 * np.sin(2 * np.pi * 0.8 * t)
    col = lowpass(rng.standard_normal(n), rate=rate, cutoff=8.0)
    col *= 0.05 / col.std()
    m = fit_noise(s + col, rate, 2.2, flat_passband=True)
    assert m.coloured[0] > 0 and m.corner[0] == pytest.approx(8.0, rel=0.2)
    assert m.rms()[0] == pytest.approx(0.05, rel=0.2)
    rng = np.random.default_rng(4)
    f = np.fft.rfftfreq(n, 1 / rate)
    tail = np.where(f > 0, 1.0 / np.maximum(f, 2.0) ** 4, 0.0)
    spec = np.sqrt(tail) * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    move = np.fft.irfft(spec, n)
    move *= 0.5 / move.std()
    white = 0.05 * rng.standard_normal(n)
    free = fit_noise(s + move + white, rate, 2.2)                     # without the check: coloured, 0.28
    checked = fit_noise(s + move + white, rate, 2.2, flat_passband=True)
    assert free.coloured[0] > 0 and free.rms()[0] > 4 * 0.05
    assert checked.coloured[0] == 0
    assert checked.rms()[0] == pytest.approx(0.05, rel=0.15)


def test_floor_is_capped_where_the_residual_is_far_below_it():
    """The consistency check: a floor above 1.5x the residual's RMS on a channel is capped at that RMS
    (said in the text), the others stand."""
    rng = np.random.default_rng(0)
    e = np.column_stack([rng.standard_normal(500), 2.0 * rng.standard_normal(500)])
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    check = consistency(e, np.array([3.0 * rms[0], 1.2 * rms[1]]), ["a_moment", "b_moment"])
    assert check["capped"] == ["a_moment"]
    np.testing.assert_allclose(check["factors"], [1.0 / 3.0, 1.0])
    assert "a_moment" in check["text"] and "capped at the residual's RMS" in check["text"]
    assert check["checked"]["b_moment"]["ratio"] == pytest.approx(1 / 1.2)


# -- a systematic residual is never at the noise floor ------------------------------------------------

def test_newey_west_standard_error_of_a_mean():
    """AR(1) noise (rho = 0.9): the standard error of the mean covers the spread of the means of 400
    records (within 15 %), where the i.i.d. formula is 4.4x too small."""
    rng = np.random.default_rng(7)
    rho, n, R = 0.9, 1000, 400
    e = rng.standard_normal((n + 200, R))
    x = np.empty_like(e)
    x[0] = e[0]
    for k in range(1, e.shape[0]):
        x[k] = rho * x[k - 1] + e[k]
    x = x[200:]
    mean, se, lags = hac_mean(x)
    assert np.median(se) == pytest.approx(np.std(mean), rel=0.15)
    assert np.std(mean) > 4 * np.median(x.std(axis=0)) / np.sqrt(n)
    assert np.all(lags > 1)


def test_offset_below_the_floor_is_systematic_not_noise(forearm):
    """A sensor offset of 0.03 N m (0.3x the floor) left out of the candidates (joint damping cannot make a
    mean): the residual is consistent with the noise by size (1.06x), but its mean over the trial is
    0.031 N m at z = 5.8 (Newey-West): missing_effect, outside the catalog, never at_noise_floor.  The
    clean trial's mean is not systematic and it is at the floor."""
    trial = make_trial(forearm, ["sensor_offset:elbow_flexion:offset=0.03"], duration=8.0, rate=100.0, seed=1)
    d = diagnose(forearm, trial, candidates=["joint_damping"])
    st = d.stopping["systematic"]
    ch = st["channels"]["elbow_flexion_moment"]
    assert d.stopping["consistent_with_noise"] and d.ratio < 1.25
    assert ch["systematic_mean"] and ch["mean"] == pytest.approx(0.03, abs=0.01) and ch["mean_z"] > st["critical_z"]
    assert d.verdict == "missing_effect" and st["systematic"] == ["elbow_flexion_moment"]
    assert d.outside_catalog is not None and "its mean over the trial" in \
        d.outside_catalog["channels"]["elbow_flexion_moment"]["summary"]
    assert "systematic, not noise" in d.verdict_line()
    clean = make_trial(forearm, [], duration=8.0, rate=100.0, seed=1)
    d0 = diagnose(forearm, clean, candidates=["joint_damping", "payload:hand"])
    assert d0.verdict == "at_noise_floor" and d0.stopping["systematic"]["systematic"] == []


def test_offset_below_the_floor_is_found_by_its_mean(forearm):
    """The same offset with the whole catalog: its squared-error test cannot see it (held-out z 2.86 <
    3.2), the mean test can (the Wald chi-square of the mean falls from 33.5 to 0.0: z 5.79), and of the
    candidates that take the mean away the offset takes most; its value is the hidden one."""
    trial = make_trial(forearm, ["sensor_offset:elbow_flexion:offset=0.03"], duration=8.0, rate=100.0, seed=1)
    d = diagnose(forearm, trial)
    best = d.best
    assert best.label == "sensor_offset:elbow_flexion" and best.test["passes_by"] == "mean"
    assert best.test["z"] < best.test["critical_z"] < best.test["mean"]["z"]
    assert best.test["mean"]["chi2_before"] == pytest.approx(33.5, abs=1.0)
    assert best.test["mean"]["chi2_after"] < 0.5
    assert best.effect.values["offset"] == pytest.approx(0.03, abs=0.005)
    # the others that take the mean away take less of it, and are named beside the suggestion
    by_mean = [s for s in d.significant if s.test["passes_by"] == "mean" and s is not best]
    assert by_mean and all(s.test["mean"]["z"] < best.test["mean"]["z"] for s in by_mean)
    assert "takes the systematic mean of elbow_flexion_moment away" in d.verdict_line()


# -- noise the user states -----------------------------------------------------------------------------

def test_stated_noise_replaces_the_fitted_levels(forearm):
    """``noise=`` sets white levels: the synthetic trial's own 0.2 deg and 2 % of the peak moment give a
    floor within 10 % of the residual of the true model (the model of the trial); the levels are in the
    JSON; names that are no channel or group are refused by name."""
    trial = make_trial(forearm, [], duration=8.0, rate=100.0, seed=5)
    peak = float(np.max(np.abs(trial["elbow_flexion_moment"])))
    stated = {"angles": np.deg2rad(0.2), "elbow_flexion_moment": 0.02 * peak}
    c = compare(forearm, trial, noise=stated)
    assert c.noise.info["stated"] == pytest.approx({"elbow_flexion": np.deg2rad(0.2),
                                                    "elbow_flexion_moment": 0.02 * peak})
    assert c.noise.sigma[0] == pytest.approx(c.rmse()["total"], rel=0.1)
    assert "stated by the user" in c.noise.method
    assert c.with_model(forearm).noise.info["stated"] == c.noise.info["stated"]
    assert parse_noise(["angles=0.2deg", "torso_x=0.5mm", "moments=0.3"]) == pytest.approx(
        {"angles": np.deg2rad(0.2), "torso_x": 5e-4, "moments": 0.3})
    with pytest.raises(pinmsk.TrialError, match="'knee' is no measured channel"):
        compare(forearm, trial, noise={"knee": 0.01})
    with pytest.raises(pinmsk.TrialError, match="'ground_reaction' names ground reaction noise"):
        compare(forearm, trial, noise={"ground_reaction": 1.0})
    with pytest.raises(pinmsk.TrialError, match="is not a number"):
        parse_noise(["angles=a lot"])


# -- the lab walk: Gait10dof18musc subject01 ------------------------------------------------------------

def _subject01(shared_data):
    d = shared_data / "opensim-models" / "Gait10dof18musc"
    if not (d / "subject01.osim").exists():
        pytest.skip("Gait10dof18musc is absent from the shared data")
    model = pinmsk.load_model(str(d / "subject01.osim"), nonlinear="fit")
    trial = pinmsk.read_trial(d / "IK" / "subject01_walk_IK.mot")
    return model, trial, d / "ExperimentalData" / "subject01_walk_grf.xml"


def test_subject01_walk_floor_holds_and_is_not_at_the_floor(shared_data):
    """OpenSim's subject01 walk (IK at 60 Hz, plates from the ExternalLoads file): the angle noise is
    white at the flat top of the angles' spectrum (<= 0.2 deg, the heel strikes above 6.75 Hz are
    movement), the floor lies below 1.5x the residual on every channel (it was 27.7 N against a 12.1 N
    residual on pelvis_tx), the plates were zeroed by the lab while unloaded (said), and the verdict is
    not at_noise_floor."""
    model, trial, xml = _subject01(shared_data)
    d = diagnose(model, trial, external_loads=xml, candidates=["segment_mass:torso", "segment_mass:pelvis"])
    c = d.comparison
    cm = c.noise.models["coordinates"]
    rot = [j for j, n in enumerate(cm.channels) if n not in ("pelvis_tx", "pelvis_ty")]
    assert np.max(np.rad2deg(cm.rms()[rot])) <= 0.2
    for ch in c.channels:
        assert d.noise_floor[ch] <= 1.5 * d.rmse[ch], (ch, d.noise_floor[ch], d.rmse[ch])
    assert d.noise_floor["pelvis_tx_moment"] < 0.5 * 27.7
    gm = c.noise.models["ground reaction"]
    assert any("zeroed by the lab" in n for n in gm.notes)
    assert "subject01_walk_grf.mot" in c.noise.method
    assert d.verdict != "at_noise_floor", d.summary_text()
    js = d.to_dict()
    assert "consistency" in js["noise_model"] and "systematic" in js["stopping"]
    # the pelvis tilt residual's mean over the walk, against its Newey-West error
    tilt = js["stopping"]["systematic"]["channels"]["pelvis_tilt_moment"]
    assert abs(tilt["mean"]) == pytest.approx(10.0, abs=2.0) and abs(tilt["mean_z"]) > 2.0


def test_records_without_noise_have_no_floor_to_call_noise(forearm):
    """A trial whose records hold no noise (``noise=None``: the model's own moments, smoothed data's
    stand-in) with a hidden sensor offset left out of the candidates: the propagated floor lies orders of
    magnitude below the residual on every channel, so it is said to be not estimable, each channel is
    weighed by its own residual, and the verdict is never at_noise_floor; a stated noise level restores a
    floor to judge against."""
    trial = make_trial(forearm, ["sensor_offset:elbow_flexion:offset=0.3"], duration=4.0, rate=100.0, noise=None)
    d = diagnose(forearm, trial, candidates=["joint_damping"])
    info = d.comparison.noise.info
    assert info["estimable"] is False and d.stopping["floor_estimable"] is False
    assert "NOT ESTIMABLE" in d.comparison.noise.method
    rms = d.comparison.rmse()
    assert d.noise_floor["elbow_flexion_moment"] == pytest.approx(rms["elbow_flexion_moment"], rel=1e-9)
    assert max(info["estimate"].values()) < 1e-3 * rms["elbow_flexion_moment"]
    assert d.verdict == "missing_effect" and "not estimable" in d.verdict_line()
    stated = diagnose(forearm, trial, candidates=["joint_damping"], noise={"moments": 0.05})
    assert stated.comparison.noise.info["estimable"] is True and stated.stopping["floor_estimable"]
