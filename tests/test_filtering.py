"""Tests of pinmsk.signals.filtering: zero-lag Butterworth and quintic-spline derivatives.

References are analytic: derivatives of sin(2*pi*f*t) and of a degree-5
polynomial, and the forward-backward Butterworth gain 1 / (1 + (f/fc)**(2n)).
"""

import numpy as np
import pytest
from scipy.signal import butter, sosfilt, sosfiltfilt

from pinmsk.errors import TrialError
from pinmsk.signals.filtering import differentiate, filter_padlen, lowpass

W = 2 * np.pi  # 1 Hz


def _phase_lag(t, y, omega):
    """Lag (s) and amplitude of the best fit A*sin(omega*(t - lag)) to y."""
    basis = np.column_stack([np.sin(omega * t), np.cos(omega * t)])
    s, c = np.linalg.lstsq(basis, y, rcond=None)[0]
    return np.arctan2(-c, s) / omega, np.hypot(s, c)


def test_lowpass_has_zero_lag_and_the_squared_butterworth_gain():
    rate, cutoff, order = 100.0, 6.0, 4
    t = np.arange(0.0, 10.0, 1.0 / rate)
    y = lowpass(np.sin(W * t), rate=rate, cutoff=cutoff, order=order)
    inner = slice(200, -200)  # away from the padded ends
    lag, amp = _phase_lag(t[inner], y[inner], W)
    assert abs(lag) < 1e-3
    # forward-backward gain |H|^2 = 1 / (1 + (f/fc)^(2n)) = 0.99999940 at 1 Hz
    assert amp == pytest.approx(1.0 / (1.0 + (1.0 / cutoff) ** (2 * order)), abs=1e-6)
    # the same filter run once (causal) lags by ~69 ms: the lag test can see lag
    one_pass = sosfilt(butter(order, cutoff / (rate / 2), output="sos"), np.sin(W * t))
    lag_causal, _ = _phase_lag(t[inner], one_pass[inner], W)
    assert lag_causal > 0.05


def test_lowpass_gain_at_cutoff_is_one_half():
    rate, cutoff = 200.0, 10.0
    t = np.arange(0.0, 20.0, 1.0 / rate)
    y = lowpass(np.sin(2 * np.pi * cutoff * t), rate=rate, cutoff=cutoff)
    inner = slice(400, -400)
    _, amp = _phase_lag(t[inner], y[inner], 2 * np.pi * cutoff)
    assert amp == pytest.approx(0.5, abs=1e-3)


def test_lowpass_is_vectorised_over_columns_and_uses_documented_padding():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((300, 3))
    y = lowpass(x, rate=100.0, cutoff=8.0)
    assert y.shape == x.shape
    np.testing.assert_allclose(y[:, 1], lowpass(x[:, 1], rate=100.0, cutoff=8.0), rtol=0, atol=1e-14)
    sos = butter(4, 8.0 / 50.0, output="sos")
    assert filter_padlen(4) == 15                                  # scipy's minimum for order 4
    assert filter_padlen(4, rate=100.0, cutoff=8.0) == 25          # two periods of the cut-off
    assert filter_padlen(4, rate=1000.0, cutoff=6.0, n=200) == 199  # capped by the signal
    # documented padding = odd extension over two periods of the cut-off
    np.testing.assert_allclose(y, sosfiltfilt(sos, x, axis=0, padtype="odd", padlen=25), rtol=0, atol=1e-14)


def test_lowpass_end_transients_are_small_at_high_rates():
    """A slow ramp-and-curve at 1 kHz filtered at 6 Hz keeps its ends (scipy's 15-sample pad does not)."""
    rate = 1000.0
    t = np.arange(0.0, 1.35, 1.0 / rate)
    x = 1.2 * t + 0.3 * np.sin(2 * np.pi * 0.9 * t + 0.4)
    y = lowpass(x, rate=rate, cutoff=6.0)
    sos = butter(4, 6.0 / 500.0, output="sos")
    short = sosfiltfilt(sos, x, padtype="odd", padlen=15)
    assert np.max(np.abs(y - x)) < 0.2 * np.max(np.abs(short - x))
    assert np.max(np.abs(y - x)) < 5e-3


def test_lowpass_rejects_cutoff_at_or_above_nyquist():
    with pytest.raises(TrialError, match=r"cutoff 60 Hz .*Nyquist frequency 50 Hz \(rate 100 Hz\)"):
        lowpass(np.zeros(200), rate=100.0, cutoff=60.0)
    with pytest.raises(TrialError, match="cutoff 0 Hz"):
        lowpass(np.zeros(200), rate=100.0, cutoff=0.0)


def test_lowpass_rejects_too_few_samples_naming_n_cutoff_and_rate():
    with pytest.raises(TrialError, match=r"10 samples .*order-4 .*cutoff 6 Hz, rate 100 Hz.*N > 15"):
        lowpass(np.zeros(10), rate=100.0, cutoff=6.0)


def test_lowpass_rejects_nan_naming_column_and_row():
    x = np.zeros((100, 2))
    x[37, 1] = np.nan
    with pytest.raises(TrialError, match="column 1, row 37 is nan"):
        lowpass(x, rate=100.0, cutoff=6.0)


def test_differentiate_sine_without_filter_is_accurate():
    t = np.arange(0.0, 2.0 + 1e-12, 0.01)  # 100 Hz, 201 samples
    x = np.sin(W * t)
    xs, v, a = differentiate(t, x)
    np.testing.assert_array_equal(xs, x)
    # errors relative to the derivative amplitudes W and W**2, ends included
    assert np.max(np.abs(v - W * np.cos(W * t))) / W < 1e-7
    assert np.max(np.abs(a + W**2 * np.sin(W * t))) / W**2 < 1e-6


def test_differentiate_is_vectorised_over_columns():
    t = np.arange(0.0, 1.0, 0.01)
    x = np.column_stack([np.sin(W * t), np.cos(3 * t), t**2])
    _, v, a = differentiate(t, x)
    for j in range(3):
        _, vj, aj = differentiate(t, x[:, j])
        np.testing.assert_allclose(v[:, j], vj, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a[:, j], aj, rtol=0, atol=1e-10)
    np.testing.assert_allclose(a[:, 2], 2.0, rtol=1e-8)


def test_differentiate_degree_five_polynomial_is_exact_on_uneven_times():
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 1.0, 40))
    p = np.polynomial.Polynomial([0.3, -2.0, 3.0, 0.5, -1.0, 2.0])
    xs, v, a = differentiate(t, p(t))
    np.testing.assert_allclose(v, p.deriv(1)(t), rtol=0, atol=1e-8)
    np.testing.assert_allclose(a, p.deriv(2)(t), rtol=0, atol=1e-8)


def test_differentiate_matches_scipys_quintic_spline_and_keeps_grids_apart():
    # the cached operators of a time grid give scipy's make_interp_spline(k=5) derivatives; a second grid
    # of the same length (same cache key size) gets its own
    from scipy.interpolate import make_interp_spline
    rng = np.random.default_rng(5)
    x = np.cumsum(rng.normal(size=(120, 3)), axis=0)
    for t in (np.sort(rng.uniform(0.0, 1.2, 120)), np.arange(120) * 0.01, np.arange(120) * 0.01 + 0.5):
        sp = make_interp_spline(t, x, k=5, axis=0)
        for _ in range(2):                       # the first call builds the grid's operators, the second reuses them
            xs, v, a = differentiate(t, x)
            np.testing.assert_array_equal(xs, x)
            np.testing.assert_allclose(v, sp.derivative(1)(t), rtol=0, atol=1e-9 * np.abs(v).max())
            np.testing.assert_allclose(a, sp.derivative(2)(t), rtol=0, atol=1e-9 * np.abs(a).max())


def test_cutoff_reduces_noise_in_acceleration():
    rate = 100.0
    t = np.arange(0.0, 4.0, 1.0 / rate)
    rng = np.random.default_rng(1)
    x = np.sin(W * t) + 1e-3 * rng.standard_normal(t.size)  # 1 mrad noise
    a_true = -(W**2) * np.sin(W * t)
    inner = slice(50, -50)

    def rms(e):
        return float(np.sqrt(np.mean(e[inner] ** 2)))

    _, _, a_raw = differentiate(t, x)
    _, _, a_filt = differentiate(t, x, cutoff=6.0)
    # noise amplified by ~1/h^2 without filtering: tens of rad/s^2
    assert rms(a_raw - a_true) > 10.0
    # with a 6 Hz cutoff: under 1.3 % of the 39.5 rad/s^2 amplitude
    assert rms(a_filt - a_true) < 0.5
    assert rms(a_raw - a_true) / rms(a_filt - a_true) > 50


def test_differentiate_errors_name_the_problem():
    t = np.arange(5) * 0.01
    with pytest.raises(TrialError, match="at least 6 samples, got 5"):
        differentiate(t, np.zeros(5))
    t = np.array([0.0, 0.01, 0.02, 0.02, 0.04, 0.05, 0.06])
    with pytest.raises(TrialError, match=r"not strictly increasing at row 3"):
        differentiate(t, np.zeros(7))
    t = np.cumsum(np.r_[0.0, np.full(49, 0.01), np.full(50, 0.02)])
    with pytest.raises(TrialError, match="uniform sampling.*resample"):
        differentiate(t, np.zeros(100), cutoff=5.0)
    with pytest.raises(TrialError, match=r"x must have shape \(N,\) or \(N, k\) with N = len\(time\) = 100"):
        differentiate(t, np.zeros(99))
