"""MSO and EID: activation dynamics between frames (thesis Sec. 2.2.3-2.2.4, App. A.2)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pinmsk.muscles.activation import activation_rate
from pinmsk.solvers import EID, ModifiedStaticOptimization, StaticOptimization
from pinmsk.solvers.mso import activation_bounds, step_excitation


def _integrate(u, a0, dt):
    sol = solve_ivp(lambda t, a: activation_rate(u, a), (0, dt), np.atleast_1d(a0), rtol=1e-12, atol=1e-14)
    return sol.y[:, -1]


def test_activation_bounds_are_u0_and_u1():
    a0 = np.array([0.0, 0.3, 0.9])
    lo, hi = activation_bounds(a0, 0.01)
    np.testing.assert_allclose(lo, _integrate(np.zeros(3), a0, 0.01), rtol=1e-9)
    np.testing.assert_allclose(hi, _integrate(np.ones(3), a0, 0.01), rtol=1e-9)


def test_step_excitation_inverts_the_dynamics():
    rng = np.random.default_rng(0)
    a0 = rng.uniform(0, 1, 20)
    u = rng.uniform(0, 1, 20)
    a1 = np.array([_integrate(u[i:i + 1], a0[i], 0.01)[0] for i in range(20)])
    np.testing.assert_allclose(step_excitation(a0, a1, 0.01), u, atol=1e-9)


def test_mso_respects_the_rate_limits(forearm, motion):
    ms = ModifiedStaticOptimization().fit(forearm, motion)
    a = ms.activations_
    lo, hi = activation_bounds(a[:-1], np.diff(motion.t)[:, None])
    assert np.all(a[1:] >= lo - 1e-9) and np.all(a[1:] <= hi + 1e-9)
    assert np.max(ms.violation_) < 1e-8
    assert np.all((ms.excitations_ >= 0) & (ms.excitations_ <= 1))
    so = StaticOptimization(mode="activation").fit(forearm, motion)
    assert np.max(np.abs(a - so.activations_)) > 1e-3          # the limits do bind somewhere
    assert "rate limits" in ms.report()


def test_fast_dynamics_reduce_mso_and_eid_to_so(forearm, motion):
    so = StaticOptimization(mode="activation").fit(forearm, motion)
    ms = ModifiedStaticOptimization(tau_rise=1e-5, tau_fall=1e-5).fit(forearm, motion)
    ei = EID(tau_rise=1e-5, tau_fall=1e-5).fit(forearm, motion)
    np.testing.assert_allclose(ms.activations_, so.activations_, atol=1e-7)
    np.testing.assert_allclose(ei.activations_, so.activations_, atol=1e-5)


def test_eid_is_optimal_over_the_trial(forearm, motion):
    ei = EID().fit(forearm, motion)
    ms = ModifiedStaticOptimization().fit(forearm, motion)
    a = ei.activations_
    lo, hi = activation_bounds(a[:-1], np.diff(motion.t)[:, None])
    assert np.all(a[1:] >= lo - 1e-7) and np.all(a[1:] <= hi + 1e-7)
    assert np.max(ei.violation_) < 1e-6
    # MSO's answer is feasible for EID, so EID's time integral cannot be larger
    t = motion.t
    mso_integral = np.sum(np.diff(t) * 0.5 * (ms.cost_[1:] + ms.cost_[:-1]))
    assert ei.objective_ <= mso_integral * (1 + 1e-6)
    # the recovered excitations reproduce the activations
    for k in range(1, 40, 7):
        np.testing.assert_allclose(_integrate(ei.excitations_[k], a[k - 1], t[k] - t[k - 1]), a[k], atol=1e-7)
    assert "sparse" in ei.report()


@pytest.mark.parametrize("P", [1, 3])
def test_eid_other_exponents(forearm, motion, P):
    ei = EID(exponent=P).fit(forearm, motion)
    assert np.max(ei.violation_) < 1e-6
