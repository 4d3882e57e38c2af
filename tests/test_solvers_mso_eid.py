"""MSO and EID: activation dynamics between frames (thesis Sec. 2.2.3-2.2.4, App. A.2)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pinmsk.effects import ActivationDynamics, DelayedActivationDynamics, ElectromechanicalDelay
from pinmsk.errors import ModelError, SolverError
from pinmsk.muscles.activation import activation_rate, held_step
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
    """The model's activation component sets the constants: the fastest allowed make MSO and EID SO."""
    so = StaticOptimization(mode="activation").fit(forearm, motion)
    fast = forearm.with_effect(ActivationDynamics("muscles", tau_rise=0.001, tau_fall=0.002))
    ms = ModifiedStaticOptimization().fit(fast, motion)
    ei = EID().fit(fast, motion)
    # tau_fall = 2 ms (its lower bound) still keeps exp(-dt / tau_fall) ~ 0.7 % of the last activation
    # where SO's falls faster: SO everywhere to 1e-4, and to 1e-7 on 98 % of the muscle-frames
    for fit, tol in ((ms, 1e-7), (ei, 1e-5)):
        np.testing.assert_allclose(fit.activations_, so.activations_, atol=1e-4)
        assert np.mean(np.abs(fit.activations_ - so.activations_) < tol) > 0.98
    assert "activation_dynamics:muscles" in ms.report() and "tau_rise 1 ms" in ms.report()


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


# -- the model's activation component and delay -----------------------------------------------

def _forward(u, a0, t, tau_rise, tau_fall):
    """Activations from held-step excitations u (N, m): the component's law, frame after frame."""
    a = np.empty_like(u)
    a[0] = a0
    for k in range(1, len(t)):
        a[k] = held_step(a[k - 1], u[k], t[k] - t[k - 1], tau_rise=tau_rise, tau_fall=tau_fall)
    return a


@pytest.mark.parametrize("solver", [ModifiedStaticOptimization, EID], ids=["mso", "eid"])
def test_activation_component_changes_mso_and_eid(forearm, motion, solver):
    """Slow activation (60/200 ms) from the model: other activations than the default 11/68 ms, and the
    recovered excitations, pushed through the component's dynamics, give back the activations."""
    slow = forearm.with_effect(ActivationDynamics("muscles", tau_rise=0.06, tau_fall=0.2))
    base = solver().fit(forearm, motion)
    fit = solver().fit(slow, motion)
    assert np.max(np.abs(fit.activations_ - base.activations_)) > 1e-2
    assert np.max(fit.violation_) < 1e-6
    t, a = motion.t, fit.activations_
    lo, hi = activation_bounds(a[:-1], np.diff(t)[:, None], tau_rise=0.06, tau_fall=0.2)
    assert np.all(a[1:] >= lo - 1e-7) and np.all(a[1:] <= hi + 1e-7)
    back = _forward(fit.excitations_, a[0], t, 0.06, 0.2)
    np.testing.assert_allclose(back, a, atol=1e-7)
    # with the default constants the same excitations would not reproduce them
    assert np.max(np.abs(_forward(fit.excitations_, a[0], t, 0.011, 0.068) - a)) > 1e-2
    assert "tau_rise 60 ms, tau_fall 200 ms (activation_dynamics:muscles)" in fit.report()


def test_delay_in_the_model_leads_the_excitations(forearm, motion):
    """Delay and activation dynamics together: the recorded excitation is the muscle's, d earlier."""
    d = 0.05
    both = forearm.with_effect(DelayedActivationDynamics("muscles", delay=d, tau_rise=0.03, tau_fall=0.1))
    ms = ModifiedStaticOptimization().fit(both, motion)
    plain = ModifiedStaticOptimization().fit(forearm.with_effect(ActivationDynamics("muscles", tau_rise=0.03,
                                                                                     tau_fall=0.1)), motion)
    np.testing.assert_allclose(ms.activations_, plain.activations_, atol=1e-12)     # a delay moves no force
    t = motion.t
    late = t > t[-1] - d + 1e-12
    assert np.all(np.isnan(ms.excitations_[late])) and not np.any(np.isnan(ms.excitations_[~late]))
    # the recording, delayed by the model's delay, is the muscle's excitation
    shift = ElectromechanicalDelay("muscles", delay=d)
    u_muscle = shift.transform(t, np.nan_to_num(ms.excitations_))
    inner = (t > t[0] + d + 0.02) & (t < t[-1] - d - 0.05)
    np.testing.assert_allclose(u_muscle[inner], plain.excitations_[inner], atol=2e-3)
    assert "electromechanical delay 50 ms" in ms.report()


def test_time_constant_arguments_are_refused_by_name(forearm, motion):
    with pytest.raises(SolverError, match=r"ModifiedStaticOptimization\(tau_rise=\.\.\.\).*model.with_effect"
                                          r"\(ActivationDynamics"):
        ModifiedStaticOptimization(tau_rise=0.02).fit(forearm, motion)
    with pytest.raises(SolverError, match=r"tau_fall=.*activation component"):
        EID(tau_fall=0.1).fit(forearm, motion)
    twice = forearm.with_effect(ActivationDynamics("muscles"), ActivationDynamics("BRD"))
    with pytest.raises(ModelError, match="two activation dynamics on BRD.*activation_dynamics:muscles"):
        ModifiedStaticOptimization().fit(twice, motion)


def test_an_unknown_muscle_level_component_is_refused_by_name(forearm, motion):
    """A muscle-level component that is neither a delay nor activation dynamics: MSO cannot represent it."""
    from pinmsk.effects import SignalEffect

    class Gain(SignalEffect):
        family = "excitation_gain"
        parameters = ()

        def transform_batch(self, t, u, params, mask=None):
            return 2.0 * np.broadcast_to(u, (1,) + np.shape(u)[-2:])

    with pytest.raises(ModelError, match="excitation_gain:muscles is a muscle-level component the analyses "
                                         "cannot represent"):
        ModifiedStaticOptimization().fit(forearm.with_effect(Gain("muscles")), motion)
