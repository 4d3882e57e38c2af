"""Trial-level inverse dynamics and simulation, with components."""
import numpy as np
import pytest

import pinmsk
from pinmsk import dynamics, skeleton
from pinmsk.trial import Trial
from test_model import _Drag


def gaussian_elbow(n=2001, duration=2.0, peak=np.deg2rad(120), sigma=0.25):
    t = np.linspace(0, duration, n)
    q = peak * np.exp(-((t - duration / 2) ** 2) / (2 * sigma ** 2))
    return t, q


def test_id_of_trial_matches_skeleton_and_subtracts_components():
    model = pinmsk.load_model("forearm")
    t, q = gaussian_elbow()
    trial = Trial(t, {"elbow_flexion": q})
    out = pinmsk.inverse_dynamics(model, trial)
    motion = model.motion(trial)
    ref = skeleton.rnea(model, motion.q, motion.v, motion.a)[:, 0]
    assert np.allclose(out["elbow_flexion_moment"], ref)
    damped = model + _Drag("elbow_flexion", c=0.3)
    out2 = pinmsk.inverse_dynamics(damped, trial)
    # damping opposes the motion, so the actuators must supply 0.3 v more
    assert np.allclose(out2["elbow_flexion_moment"] - out["elbow_flexion_moment"], 0.3 * motion.v[:, 0])
    parts = dynamics.component_forces(damped, motion)
    assert np.allclose(parts["test_drag:elbow_flexion"][:, 0], -0.3 * motion.v[:, 0])


def test_simulate_reproduces_motion_from_its_inverse_dynamics():
    """ID then FD round trip: driving the model with its own ID moments reproduces the motion."""
    model = pinmsk.load_model("forearm") + _Drag("elbow_flexion", c=0.3)
    t, q = gaussian_elbow()
    trial = Trial(t, {"elbow_flexion": q})
    tau = pinmsk.inverse_dynamics(model, trial, cutoff=0)     # noise-free: no filter
    motion = model.motion(trial, cutoff=0)
    sim = pinmsk.simulate(model, t=t, q0=motion.q[0], v0=motion.v[0], moments=tau, method="rk4")
    assert np.max(np.abs(sim["elbow_flexion"] - q)) < 2e-4
    assert np.max(np.abs(sim["elbow_flexion_speed"] - motion.v[:, 0])) < 5e-3


def test_simulate_without_moments_is_a_pendulum_with_damping_losing_energy():
    model = pinmsk.load_model("forearm") + _Drag("elbow_flexion", c=0.05)
    t = np.linspace(0, 3, 3001)
    sim = pinmsk.simulate(model, t=t, q0=[1.5], v0=[0.0])
    q = sim["elbow_flexion"]
    v = sim["elbow_flexion_speed"]
    e = skeleton.mechanical_energy(model, q[:, None], v[:, None])
    assert np.all(np.diff(e) <= 1e-9)          # damping only removes energy
    assert e[-1] < e[0] - 0.1
