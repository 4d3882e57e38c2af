"""Forward static optimization (thesis Sec. 3.4) on the forearm's Gaussian motion."""
import numpy as np
import pinocchio as pin
import pytest

from pinmsk.errors import InfeasibleError, SolverError
from pinmsk.solvers import FSO, StaticOptimization
from pinmsk.solvers.analytical import gaussian_elbow_motion


@pytest.mark.parametrize("P", [2, 3])
def test_fso_tracks_and_matches_so(forearm, motion, P):
    f = FSO(exponent=P).fit(forearm, motion)
    assert f.t_.size == 100
    assert np.rad2deg(np.max(np.abs(f.tracking_error_))) < 0.2
    # a force held over [t_k, t_k+1] acts on average at the middle: compare with SO there
    mid = gaussian_elbow_motion(times=f.t_hold_)
    F_so = StaticOptimization(exponent=P).fit(forearm, mid).forces_
    assert np.max(np.abs(f.forces_ - F_so)) < 0.01 * np.max(F_so)
    assert np.all(f.forces_ >= -1e-9) and np.all(f.forces_ <= forearm.muscles.f_max + 1e-6)
    assert "tracking error" in f.report()


def test_constraint_mode_produces_desired_acceleration(forearm, motion):
    f = FSO().fit(forearm, motion)
    pm = forearm.pin
    d = pm.createData()
    R = forearm.muscles.moment_arms(f.q_)
    for k in range(0, 100, 9):
        tau = pin.rnea(pm, d, f.q_[k], f.v_[k], f.acc_desired_[k])
        assert abs(R[k, :, 0] @ f.forces_[k] - tau[0]) < 1e-7


@pytest.mark.parametrize("kw", [dict(tracking="q"), dict(tracking="qv"), dict(enforce="cost"),
                                dict(enforce="cost", exponent=3), dict(integrator="RK45"),
                                dict(mode="activation")])
def test_fso_variants_track(forearm, motion, kw):
    f = FSO(**kw).fit(forearm, motion)
    assert np.rad2deg(np.max(np.abs(f.tracking_error_))) < 0.5
    assert f.result_.n_frames == 100
    assert "elbow_flexion_error" in f.result_


def test_fso_infeasible_and_reserves(forearm, motion):
    from pinmsk.components import Motion
    fast = Motion(motion.t * 0.1, motion.q, motion.v * 10, motion.a * 100)   # 10x faster: too strong
    with pytest.raises(InfeasibleError, match="t = "):
        FSO().fit(forearm, fast)
    f = FSO(reserves=True).fit(forearm, fast)
    assert np.max(np.abs(f.reserves_)) > 1.0
    assert np.rad2deg(np.max(np.abs(f.tracking_error_))) < 1.0


def test_fso_bad_options(forearm, motion):
    for kw, word in [(dict(tracking="x"), "tracking"), (dict(enforce="soft"), "enforce"),
                     (dict(control_points=1), "control_points"), (dict(gains=(1, 2)), "gains")]:
        with pytest.raises(SolverError, match=word):
            FSO(**kw).fit(forearm, motion)
    with pytest.raises(SolverError, match="not run"):
        FSO().report()


def test_fso_honours_the_models_activation_dynamics(forearm, motion):
    """Activation mode with slow activation dynamics (60/200 ms) in the model: the control points' activations
    stay within what the held excitations reach, differ from FSO without it, and the excitations given
    back reproduce them; force mode refuses the component by name."""
    from pinmsk.effects import ActivationDynamics
    from pinmsk.errors import ModelError
    from pinmsk.muscles.activation import held_step, reachable_activation

    slow = forearm.with_effect(ActivationDynamics("muscles", tau_rise=0.06, tau_fall=0.2))
    plain = FSO(mode="activation").fit(forearm, motion)
    f = FSO(mode="activation", enforce="cost").fit(slow, motion)
    a, t = f.activations_, f.t_
    lo, hi = reachable_activation(a[:-1], np.diff(t)[:, None], tau_rise=0.06, tau_fall=0.2)
    assert np.all(a[1:] >= lo - 1e-8) and np.all(a[1:] <= hi + 1e-8)
    assert np.max(np.abs(a - FSO(mode="activation", enforce="cost").fit(forearm, motion).activations_)) > 1e-2
    u = f.excitations_
    back = [a[0]]
    for k in range(1, t.size):
        back.append(held_step(back[-1], u[k], t[k] - t[k - 1], tau_rise=0.06, tau_fall=0.2))
    np.testing.assert_allclose(np.array(back), a, atol=1e-7)
    assert "BRD_excitation" in f.result_ and "BRD_excitation" not in plain.result_
    assert "tau_rise 60 ms" in f.report()
    with pytest.raises(ModelError, match="force mode.*activation_dynamics:muscles.*mode='activation'"):
        FSO().fit(slow, motion)
