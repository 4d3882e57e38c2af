"""Activation dynamics (thesis App. A.1-A.2): hand values, exact inverse, integration."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pinmsk.errors import TrialError
from pinmsk.muscles import (TAU_FALL, TAU_RISE, activation_from_excitation, activation_rate,
                            excitation_from_activation, he_activation_rate)

T2 = 1.0 / TAU_FALL
T1 = 1.0 / TAU_RISE - T2


def test_time_constants_are_the_thesis_values():
    assert TAU_RISE == 0.011 and TAU_FALL == 0.068


def test_hand_values_winters_stark():
    # full excitation from rest: adot = (1 - 0)(t1 + t2) = 1/tau_rise
    assert activation_rate(1.0, 0.0) == pytest.approx(1.0 / 0.011, rel=1e-14)
    # switched off from full activation: adot = -t2 = -1/tau_fall
    assert activation_rate(0.0, 1.0) == pytest.approx(-1.0 / 0.068, rel=1e-14)
    # half-way up: (0.8 - 0.3)(t1 0.8 + t2)
    assert activation_rate(0.8, 0.3) == pytest.approx(0.5 * (T1 * 0.8 + T2), rel=1e-14)
    assert activation_rate(0.5, 0.5) == 0.0


def test_he_et_al_single_expression():
    # Eq. A.1 uses the rise term on the way down too: (0 - 1)(t1*0 + t2) = -1/tau_fall,
    # but (0.2 - 0.6)(t1*0.2 + t2) differs from Winters & Stark's (0.2 - 0.6) t2.
    assert he_activation_rate(1.0, 0.0) == pytest.approx(1.0 / 0.015, rel=1e-14)
    assert he_activation_rate(0.0, 1.0) == pytest.approx(-1.0 / 0.050, rel=1e-14)
    t2, t1 = 1 / 0.05, 1 / 0.015 - 1 / 0.05
    assert he_activation_rate(0.2, 0.6) == pytest.approx(-0.4 * (t1 * 0.2 + t2), rel=1e-14)
    assert he_activation_rate(0.2, 0.6, tau_rise=TAU_RISE, tau_fall=TAU_FALL) != \
        pytest.approx(activation_rate(0.2, 0.6))


def test_branch_is_sign_of_rate():
    u, a = np.meshgrid(np.linspace(0, 1, 101), np.linspace(0, 1, 101))
    adot = activation_rate(u, a)
    np.testing.assert_array_equal(adot >= 0, u >= a)


def test_inverse_round_trip_exact():
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 1, (500, 7))
    a = rng.uniform(0, 1, (500, 7))
    adot = activation_rate(u, a)
    np.testing.assert_allclose(excitation_from_activation(a, adot), u, rtol=0, atol=1e-12)
    # and the other way: any (a, adot) maps to an excitation reproducing adot
    adot2 = rng.uniform(-14, 90, (500, 7))
    u2 = excitation_from_activation(a, adot2)
    np.testing.assert_allclose(activation_rate(u2, a), adot2, rtol=1e-12, atol=1e-10)


def test_inverse_matches_printed_formula_A5():
    a = np.linspace(0.05, 1, 20)[:, None]
    adot = np.linspace(0.5, 60, 15)[None, :]
    printed = (a * T1 - T2 + np.sqrt((a * T1 + T2) ** 2 + 4 * adot * T1)) / (2 * T1)
    np.testing.assert_allclose(excitation_from_activation(a, adot), printed, rtol=1e-12)
    adot_neg = -np.linspace(0.5, 10, 15)[None, :]
    np.testing.assert_allclose(excitation_from_activation(a, adot_neg), (adot_neg + T2 * a) / T2,
                               rtol=1e-13)


def test_broadcasting_scalars_and_arrays():
    assert np.shape(activation_rate(0.5, np.zeros((4, 3)))) == (4, 3)
    assert np.shape(excitation_from_activation(np.zeros(3), 1.0)) == (3,)
    assert np.ndim(excitation_from_activation(0.2, 0.0)) == 0
    assert float(excitation_from_activation(0.2, 0.0)) == 0.2


def test_integration_exact_for_constant_excitation():
    t = np.linspace(0, 0.3, 301)
    a = activation_from_excitation(t, np.ones((301, 2)), a0=0.0)
    np.testing.assert_allclose(a[:, 0], -np.expm1(-t / TAU_RISE), rtol=0, atol=1e-15)
    a = activation_from_excitation(t, np.zeros(301), a0=1.0)
    assert a.shape == (301,)
    np.testing.assert_allclose(a, np.exp(-t / TAU_FALL), rtol=1e-13)


def test_integration_second_order_against_solve_ivp():
    ph = np.array([0.0, 1.3, 2.9])

    def u_of(tt):
        return 0.4 + 0.35 * np.sin(2 * np.pi * 2 * np.asarray(tt)[..., None] + ph)

    errors = []
    for dt in (2e-3, 1e-3):
        t = np.arange(0, 1.0 + dt / 2, dt)
        a = activation_from_excitation(t, u_of(t))
        ref = solve_ivp(lambda tt, y: activation_rate(u_of(tt), y), (0, 1), u_of(0.0),
                        method="DOP853", rtol=1e-11, atol=1e-13, t_eval=t).y.T
        errors.append(np.abs(a - ref).max())
    # trapezoid-mean excitation per step: error O(dt^2) (measured 8.7e-5 and 2.2e-5)
    assert errors[1] < 5e-5
    assert 3.0 < errors[0] / errors[1] < 5.0


def test_integration_bounded_with_coarse_sampling():
    # 50 ms steps: explicit RK4 is unstable at tau_rise = 11 ms; the exact step is not.
    t = np.arange(0, 2, 0.05)
    u = (np.sin(7 * t) > 0).astype(float)[:, None]
    a = activation_from_excitation(t, u, a0=0.0)
    assert a.min() >= 0.0 and a.max() <= 1.0


def test_integration_bad_input():
    t = np.linspace(0, 1, 11)
    u = np.full((11, 2), 0.3)
    u[4, 1] = np.nan
    with pytest.raises(TrialError, match=r"u is nan for muscle 1 at frame 4"):
        activation_from_excitation(t, u)
    t_bad = t.copy()
    t_bad[5] = t_bad[4]
    with pytest.raises(TrialError, match="time must increase"):
        activation_from_excitation(t_bad, np.zeros((11, 2)))
    with pytest.raises(TrialError, match="same N"):
        activation_from_excitation(t, np.zeros((10, 2)))


def test_vectorised_recurrence_equals_the_step_by_step_one():
    """activation_from_excitation solves the held steps by scans (narrow problems) or step by step (wide),
    with per-muscle time constants: both equal a plain loop of held_step over the frames, also when the
    branch iteration is cut short and finishes step by step."""
    import pinmsk.muscles.activation as act
    from pinmsk.muscles.activation import held_step

    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.005, 0.015, 400))
    smooth = 0.5 + 0.4 * np.sin(np.outer(t, [1.3, 2.9, 7.0]) + [0.0, 1.0, 2.0])
    u = np.clip(smooth * (1 + 0.2 * rng.standard_normal(smooth.shape)), 0, 1)
    tr, tf = np.array([0.01, 0.03, 0.005]), np.array([0.05, 0.2, 0.04])

    def loop(u, tr, tf):
        a = np.empty(np.broadcast_shapes(u.shape, (1,) + np.shape(tr)))
        a[0] = u[0]
        for k in range(1, t.size):
            a[k] = held_step(a[k - 1], 0.5 * (u[k] + u[k - 1]), t[k] - t[k - 1], tau_rise=tr, tau_fall=tf)
        return a

    ref = loop(u, tr, tf)
    np.testing.assert_allclose(activation_from_excitation(t, u, tau_rise=tr, tau_fall=tf), ref, atol=1e-14)
    wide = np.repeat(u[:, None, :], 120, axis=1)                       # (N, 120, 3): the step-by-step path
    np.testing.assert_allclose(activation_from_excitation(t, wide, tau_rise=tr, tau_fall=tf),
                               np.repeat(ref[:, None, :], 120, axis=1), atol=1e-14)
    um = 0.5 * (u[1:] + u[:-1])
    t1, t2 = act._rates(tr, tf)
    h = np.diff(t)[:, None]
    cut = act._held_steps(u[0], um, np.exp(-(t1 * um + t2) * h), np.broadcast_to(np.exp(-t2 * h), um.shape),
                          max_rounds=1)
    np.testing.assert_allclose(cut, ref[1:], atol=1e-14)
