"""One law, one place: the muscle classes and the band-passes call the shared law functions, and the
numbers are those of the formulas they replaced (written out here, from the thesis and scipy)."""
import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from pinmsk.muscles import Thelen2003, Thelen2003OpenSim
from pinmsk.muscles.thelen2003 import (GAMMA, K_PE, PASSIVE_STRAIN0, thelen_active_force_length,
                                       thelen_active_force_length_derivative, thelen_force_velocity,
                                       thelen_passive_force_length, thelen_passive_force_length_derivative)
from pinmsk.errors import TrialError
from pinmsk.signals.filtering import bandpass, bandpass_design, filter_padlen

RNG = np.random.default_rng(7)


def _close(a, b, rel=1e-12):
    a, b = np.asarray(a, float), np.asarray(b, float)
    np.testing.assert_allclose(a, b, rtol=rel, atol=rel * max(1.0, float(np.abs(b).max())))


def test_thelen2003_force_limits_and_rigid_force_are_eq_a7_a8():
    m = Thelen2003(f_max=np.array([500.0, 900.0]), l_opt=np.array([0.1, 0.08]),
                   l_slack=np.array([0.2, 0.25]), pennation=np.array([0.0, 0.2]))
    l_mt = np.column_stack([np.linspace(0.26, 0.36, 41), np.linspace(0.3, 0.36, 41)])
    v_mt = 0.3 * np.sin(np.linspace(0, 6, 41))[:, None] * np.ones(2)
    l_ce, v_ce, cos = m.fiber_rigid(l_mt, v_mt)
    d = l_ce / m.l_opt - 1.0
    f_l = np.exp(-(d * d) / GAMMA)                                                     # Eq. A.8
    f_pe = (np.exp(K_PE * np.maximum(d, 0.0) / PASSIVE_STRAIN0) - 1.0) / (np.exp(K_PE) - 1.0)  # Eq. A.7
    fa, fp = m.force_limits(l_mt, v_mt)
    _close(fa, m.f_max * f_l * thelen_force_velocity(v_ce / m.v_max) * cos)
    _close(fp, m.f_max * f_pe * cos)
    assert (d > 0.05).any() and (d < -0.05).any()          # both sides of the optimum are exercised
    _close(m.rigid_force(np.ones_like(l_mt), l_mt, np.zeros_like(v_mt)),
           m.f_max * (f_l + f_pe) * cos)


def test_thelen2003_opensim_curves_are_the_law_functions_with_its_shapes():
    m = Thelen2003OpenSim(f_max=np.ones(3), l_opt=np.full(3, 0.1), l_slack=np.full(3, 0.2),
                          active_shape=np.array([0.45, 0.5, 0.3]), passive_shape=np.array([5.0, 4.0, 6.0]),
                          passive_strain=np.array([0.6, 0.5, 0.7]))
    l = np.concatenate([np.linspace(0.4, 1.8, 57), [1.0]])[:, None] * np.ones(3)
    fl, dfl, fpe, dfpe = m._length_curves(l)
    g, k, e0 = m.active_shape, m.passive_shape, m.passive_strain
    d = l - 1.0
    _close(fl, np.exp(-(d * d) / g))
    _close(dfl, -2.0 * d / g * np.exp(-(d * d) / g))
    _close(fpe, np.where(d > 0, (np.exp(k * d / e0) - 1.0) / (np.exp(k) - 1.0), 0.0))
    _close(dfpe, np.where(d > 0, k / e0 * np.exp(k * d / e0) / (np.exp(k) - 1.0), 0.0))
    assert np.all(dfpe[-1] == 0.0)                         # OpenSim's slope at l_norm = 1 exactly
    _close(fpe, thelen_passive_force_length(l, k_pe=k, strain0=e0))
    _close(dfl, thelen_active_force_length_derivative(l, gamma=g))
    h = 1e-6                                                # the derivatives are those of the values
    _close(thelen_passive_force_length_derivative(1.3, k_pe=k, strain0=e0),
           (thelen_passive_force_length(1.3 + h, k_pe=k, strain0=e0)
            - thelen_passive_force_length(1.3 - h, k_pe=k, strain0=e0)) / (2 * h), rel=1e-7)
    _close(thelen_active_force_length(0.7, gamma=g), np.exp(-0.09 / g))


def test_bandpass_is_scipys_butterworth_filtfilt_exactly():
    x = RNG.standard_normal((3000, 2))
    # the EMG envelope's: order 4, the pad of its low-pass
    old = sosfiltfilt(butter(4, [20 / 500, 450 / 500], btype="band", output="sos"), x, axis=0,
                      padtype="odd", padlen=filter_padlen(4))
    np.testing.assert_array_equal(bandpass(x, rate=1000.0, band=(20, 450), padlen=filter_padlen(4)), old)
    # the noise bands': order 2, scipy's default pad
    old = sosfiltfilt(butter(2, [3 / 50, 7 / 50], btype="band", output="sos"), x, axis=0)
    np.testing.assert_array_equal(bandpass(x, rate=100.0, band=(3.0, 7.0), order=2), old)
    # the simulated EMG carrier's: along axis 1
    y = RNG.standard_normal((2, 1500, 3))
    old = sosfiltfilt(butter(4, [20 / 500, 450 / 500], btype="band", output="sos"), y, axis=1)
    np.testing.assert_array_equal(bandpass(y, rate=1000.0, band=(20, 450), axis=1), old)
    assert not bandpass_design((20, 450), 1000.0).flags.writeable
    with pytest.raises(TrialError, match="Nyquist"):
        bandpass(x, rate=100.0, band=(20, 50))
