"""EMG envelopes (known AM signal), normalisation across trials, rate checks; channel alignment."""
import numpy as np
import pytest

from pinmsk import Trial, TrialError
from pinmsk.signals.emg import envelope, envelopes, normalize, on_off, onset_times
from pinmsk.signals.resampling import align
from pinmsk.signals.sampling import check_rate, measured_rate


def _am(rate=2000.0, T=4.0, A=2.0, depth=0.5, fc=100.0, fm=1.0):
    t = np.arange(int(T * rate)) / rate
    mod = 1 + depth * np.sin(2 * np.pi * fm * t)
    return t, A * mod * np.sin(2 * np.pi * fc * t), A * mod


def test_envelope_of_a_known_am_signal():
    t, x, a = _am()
    env = envelope(x, rate=2000.0, band=(20, 450), cutoff=6.0)
    expected = 2 / np.pi * a           # mean of |A sin| = 2A/pi, modulation passes the 6 Hz low-pass
    mid = slice(1000, 7000)            # away from the ends
    err = np.max(np.abs(env[mid] - expected[mid])) / np.max(expected)
    assert err < 0.02
    assert np.corrcoef(env[mid], expected[mid])[0, 1] > 0.999


def test_envelope_removes_dc_offset_and_low_frequency_artefact():
    t, x, a = _am()
    drift = 0.8 + 0.5 * np.sin(2 * np.pi * 2 * t)      # electrode offset + 2 Hz movement artefact
    env = envelope(x + drift, rate=2000.0)
    mid = slice(1000, 7000)
    assert np.max(np.abs(env[mid] - 2 / np.pi * a[mid])) / np.max(a) < 0.03


def test_emg_stated_rate_contradicting_time_column():
    t, x, _ = _am(rate=1000.0, T=2.0)
    tr = Trial(t, {"soleus": x})
    with pytest.raises(TrialError, match=r"stated to be sampled at 2000 Hz.*1000 Hz"):
        envelopes(tr, stated_rate=2000.0)
    out = envelopes(tr, stated_rate=1000.0, band=(20, 400))
    assert out.names == ("soleus",)


def test_band_above_nyquist_is_an_error():
    t, x, _ = _am(rate=500.0, T=2.0)
    with pytest.raises(TrialError, match="Nyquist frequency 250 Hz"):
        envelope(x, rate=500.0, band=(20, 450))


def test_normalisation_is_across_trials_not_per_trial():
    t, x, _ = _am(T=2.0)
    weak = envelopes(Trial(t, {"m": 1.0 * x}))
    strong = envelopes(Trial(t, {"m": 3.0 * x}))
    (w, s), scale = normalize([weak, strong])
    assert np.max(s["m"]) == pytest.approx(1.0)
    assert np.max(w["m"]) == pytest.approx(1 / 3, rel=1e-9)      # relative amplitude kept
    (w2,), _ = normalize([weak], reference={"m": 2 * scale["m"]})
    assert np.max(w2["m"]) == pytest.approx(1 / 6, rel=1e-9)


def test_on_off_timing():
    t = np.arange(100) / 100.0
    env = np.where((t >= 0.2) & (t < 0.5), 1.0, 0.05)
    env[70] = 0.9                                  # one-sample spike dropped by min_samples
    on = on_off(env, threshold=0.25, min_samples=3)
    assert onset_times(t, on) == [(0.2, 0.49)]


def test_align_channels_at_different_rates():
    t100 = np.arange(0, 1.0 + 1e-9, 0.01)
    t2000 = np.arange(0, 2001) / 2000.0
    markers = Trial(t100, {"heel_x": 0.5 + 1.2 * t100})
    grf = Trial(t2000, {"ground_force_vy": 700.0 - 100.0 * t2000})
    both = align(markers, grf, rate=100.0, antialias=False)
    assert both.n_frames == 101 and both.names == ("heel_x", "ground_force_vy")
    np.testing.assert_allclose(both["ground_force_vy"], 700 - 100 * t100, atol=1e-9)
    # a line stays a line through the anti-alias low-pass, away from the ends
    both2 = align(markers, grf, rate=100.0)
    np.testing.assert_allclose(both2["ground_force_vy"][20:-20], 700 - 100 * t100[20:-20], atol=1e-3)
    assert measured_rate(grf) == pytest.approx(2000.0)


def test_align_refuses_duplicate_channels_and_disjoint_times():
    a = Trial(np.arange(10) / 10.0, {"x": np.zeros(10)})
    b = Trial(np.arange(10) / 10.0, {"x": np.ones(10)})
    with pytest.raises(TrialError, match="duplicate column names"):
        align(a, b)
    c = Trial(5 + np.arange(10) / 10.0, {"y": np.ones(10)})
    with pytest.raises(TrialError, match="do not overlap"):
        align(a, c)


def test_check_rate_and_nonuniform_sampling():
    t = np.arange(50) / 100.0
    tr = Trial(t, {"x": t})
    assert check_rate(tr, 100.0) == pytest.approx(100.0)
    with pytest.raises(TrialError, match="stated to be sampled at 150 Hz"):
        check_rate(tr, 150.0, what="marker data")
    t2 = t.copy(); t2[25:] += 0.05
    with pytest.raises(TrialError, match="uniform sampling"):
        measured_rate(Trial(t2, {"x": t}))
    with pytest.raises(TrialError, match="outside the trial"):
        tr.resample([0.0, 1.0], method="linear", antialias=True)
