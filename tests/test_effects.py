"""Physics of each effect family, checked against an independent computation."""
from __future__ import annotations

import doctest

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk import effects
from pinmsk.components import Motion
from pinmsk.dynamics import inverse_dynamics_array, skeleton_with_inertias
from pinmsk.effects import (ActivationDynamics, CoulombFriction, ElectromechanicalDelay,
                            JointDamping, JointSpring, PassiveElastic, Payload,
                            RienerEdrich1999PassiveMoment, SegmentMass)
from pinmsk.diagnose.catalog import catalog
from pinmsk.effects.registry import from_spec
from pinmsk.errors import ModelError
from pinmsk.muscles.activation import activation_from_excitation


@pytest.fixture(scope="module")
def forearm():
    return pinmsk.load_model("forearm")


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def _motion(model, n=50, seed=1):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)
    q = rng.uniform(0.2, 1.2, (n, model.nv))
    return Motion(t, q, rng.normal(0, 2, (n, model.nv)), rng.normal(0, 10, (n, model.nv)))


# -- joint effects: closed forms ---------------------------------------------------------------

def test_joint_effects_closed_forms(forearm):
    mo = _motion(forearm)
    q, v = mo.q[:, 0], mo.v[:, 0]
    np.testing.assert_allclose(JointDamping("elbow_flexion", c=0.7).generalized_force(forearm, mo)[:, 0],
                               -0.7 * v)
    np.testing.assert_allclose(CoulombFriction("elbow_flexion", F_c=1.5).generalized_force(forearm, mo)[:, 0],
                               -1.5 * np.tanh(v / 0.01))
    np.testing.assert_allclose(JointSpring("elbow_flexion", k=3.0, q0=0.4).generalized_force(forearm, mo)[:, 0],
                               -3.0 * (q - 0.4))
    pe = PassiveElastic("elbow_flexion", amplitude=2.0, theta_0=1.4, k_lo=8.0, k_hi=12.0)
    z = np.exp(8.0 * (1.4 - 0.0)) + np.exp(12.0 * (2.6 - 1.4))          # the branches at the range ends
    np.testing.assert_allclose(pe.generalized_force(forearm, mo)[:, 0],
                               2.0 * (np.exp(-8.0 * (q - 1.4)) - np.exp(12.0 * (q - 1.4))) / z, rtol=1e-12)
    # at the ends of the range (0, 2.6 rad) the moments add up to the amplitude, within the other branch's share
    ends = Motion(np.zeros(2), np.array([[0.0], [2.6]]), np.zeros((2, 1)), np.zeros((2, 1)))
    Q = pe.generalized_force(forearm, ends)[:, 0]
    assert Q[0] > 0 > Q[1] and Q[0] - Q[1] == pytest.approx(2.0, rel=1e-3)
    # the published form (1 N m at theta_lo from the lower branch, at theta_hi from the upper one) maps exactly
    pub = PassiveElastic.from_limits("elbow_flexion", forearm, theta_lo=0.3, k_lo=8.0, theta_hi=2.2, k_hi=12.0)
    np.testing.assert_allclose(pub.generalized_force(forearm, mo)[:, 0],
                               np.exp(-8.0 * (q - 0.3)) - np.exp(12.0 * (q - 2.2)), rtol=1e-12)
    assert pub.values["theta_0"] == pytest.approx((8.0 * 0.3 + 12.0 * 2.2) / 20.0)
    # zero moment at the rest angle, restoring everywhere
    at = Motion(np.zeros(1), np.array([[1.4]]), np.zeros((1, 1)), np.zeros((1, 1)))
    assert pe.generalized_force(forearm, at)[0, 0] == 0.0
    dq, _ = pe.state_derivatives(forearm, mo)
    assert np.all(dq[:, 0, 0] < 0)
    # no member of the family is a constant: the stiffening rates are at least 1/rad, and the diagnosis
    # bounds the rest angle (and the spring's) to the joint's range
    assert PassiveElastic.parameters[2].min == PassiveElastic.parameters[3].min == 1.0
    for eff, name in ((PassiveElastic("elbow_flexion"), "theta_0"), (JointSpring("elbow_flexion"), "q0")):
        p = eff.for_model(forearm).params[name]
        assert (p.min, p.max) == (0.0, 2.6)


def test_friction_smoothing_is_fixed_and_small():
    assert CoulombFriction.velocity_scale == 0.01
    assert [p.name for p in CoulombFriction.parameters] == ["F_c"]       # v_s is not fitted


# -- payload and segment mass: against Pinocchio with the inertia folded in -----------------------

def test_payload_equals_rnea_of_the_heavier_skeleton(forearm):
    mo = _motion(forearm)
    p = Payload("hand", mass=1.3)
    heavy = skeleton_with_inertias(forearm.with_effect(p))
    rnea_heavy = np.array([pin.rnea(heavy, heavy.createData(), q, v, a) for q, v, a in zip(mo.q, mo.v, mo.a)])
    rnea_base = inverse_dynamics_array(forearm, mo)
    np.testing.assert_allclose(-p.generalized_force(forearm, mo), rnea_heavy - rnea_base, rtol=1e-9, atol=1e-9)
    # and the ID of the model with the payload is that heavier skeleton's
    np.testing.assert_allclose(inverse_dynamics_array(forearm + p, mo), rnea_heavy, rtol=1e-9, atol=1e-9)


def test_payload_static_hand_computed_case(forearm):
    # forearm horizontal (q = pi/2), at rest: a 2 kg mass 0.3611664 m from the elbow
    mo = Motion(np.zeros(1), np.array([[np.pi / 2]]), np.zeros((1, 1)), np.zeros((1, 1)))
    Q = Payload("hand", mass=2.0).generalized_force(forearm, mo)[0, 0]
    # gravity pulls the hand down: an extending (negative) moment of m g r
    assert Q == pytest.approx(-2.0 * 9.81 * 0.3611664, rel=1e-9)


def test_segment_mass_equals_rnea_of_the_scaled_skeleton(forearm, gait2d):
    for model, body in ((forearm, "forearm_hand"), (gait2d, "hat"), (gait2d, "thigh_l")):
        mo = _motion(model, n=12)
        s = SegmentMass(body, delta=0.15)
        scaled = skeleton_with_inertias(model.with_effect(s))
        j = model.pin.frames[model.frame_id(body)].parentJoint
        assert scaled.inertias[j].mass == pytest.approx(1.15 * model.pin.inertias[j].mass)
        np.testing.assert_allclose(scaled.inertias[j].lever, model.pin.inertias[j].lever, atol=1e-12)
        d = scaled.createData()
        r_scaled = np.array([pin.rnea(scaled, d, q, v, a) for q, v, a in zip(mo.q, mo.v, mo.a)])
        r_base = inverse_dynamics_array(model.without("riener_edrich_1999:r").without("riener_edrich_1999:l")
                                        if model.components else model, mo)
        np.testing.assert_allclose(-s.generalized_force(model, mo), r_scaled - r_base, rtol=1e-8, atol=1e-8)


def test_segment_mass_refuses_massless_bodies(gait2d):
    with pytest.raises(ModelError, match="does not move or has no mass.*hat"):
        gait2d.with_effect(SegmentMass("torso_x_slider", delta=0.1))


# -- Riener & Edrich 1999 ----------------------------------------------------------------------------

def test_riener_edrich_equation_values():
    th, tk, ta = RienerEdrich1999PassiveMoment.moments_deg(0.0, 0.0, 0.0)
    assert ta == pytest.approx(np.exp(2.1016) - np.exp(-7.9763) - 1.792, rel=1e-12)
    assert tk == pytest.approx(np.exp(1.8) - np.exp(-3.971) - 4.82 + np.exp(2.22), rel=1e-12)
    assert th == pytest.approx(np.exp(1.4655) - np.exp(1.3403) + 8.072, rel=1e-12)
    th, tk, ta = RienerEdrich1999PassiveMoment.moments_deg(10.0, 30.0, -5.0)
    assert ta == pytest.approx(np.exp(2.1016 + 0.0843 * 5 - 0.0176 * 30) - np.exp(-7.9763 - 0.1949 * 5 + 0.0008 * 30)
                               - 1.792, rel=1e-12)


def test_riener_edrich_mapping_and_restoring_at_neutral(gait2d):
    re = RienerEdrich1999PassiveMoment("r")
    assert re.coordinates() == ("hip_r", "knee_r", "ankle_r")
    q = np.zeros((1, gait2d.nv))
    mo = Motion(np.zeros(1), q, q, q)
    Q = re.generalized_force(gait2d, mo)[0]
    th, tk, ta = re.moments_deg(0.0, 0.0, 0.0)
    i = {c: gait2d.coordinate_index(c) for c in re.coordinates()}
    assert Q[i["hip_r"]] == pytest.approx(-th) and Q[i["knee_r"]] == pytest.approx(tk)
    assert Q[i["ankle_r"]] == pytest.approx(ta)
    dq, dv = re.state_derivatives(gait2d, mo)
    for c in re.coordinates():
        assert dq[0, i[c], i[c]] < 0, f"{c}: passive moment must be restoring at the neutral posture"
    assert np.all(dv == 0)
    # restoring over a gait-like range too
    rng = np.random.default_rng(0)
    qq = np.zeros((200, gait2d.nv))
    qq[:, i["hip_r"]] = rng.uniform(-0.5, 0.4, 200)
    qq[:, i["knee_r"]] = rng.uniform(0.0, 1.2, 200)
    qq[:, i["ankle_r"]] = rng.uniform(-0.3, 0.3, 200)
    dq, _ = re.state_derivatives(gait2d, Motion(np.arange(200.0), qq, 0 * qq, 0 * qq))
    for c in re.coordinates():
        assert np.all(dq[:, i[c], i[c]] < 0)
    # the equilibria of a relaxed leg: hip ~27 deg flexion, knee ~15 deg flexion, ankle ~18 deg plantarflexion
    grid = np.deg2rad(np.linspace(-60, 60, 2401))
    for c, lo, hi in (("hip_r", -30, -24), ("knee_r", 12, 18), ("ankle_r", 15, 21)):
        qq = np.zeros((grid.size, gait2d.nv))
        qq[:, i[c]] = grid
        f = re.generalized_force(gait2d, Motion(np.arange(grid.size * 1.0), qq, 0 * qq, 0 * qq))[:, i[c]]
        eq = np.rad2deg(grid[np.argmin(np.abs(f))])
        assert lo < eq < hi, (c, eq)


def test_riener_edrich_from_the_sidecar(gait2d):
    labels = [c.label for c in gait2d.components]
    assert "riener_edrich_1999:r" in labels and "riener_edrich_1999:l" in labels
    e = from_spec({"type": "riener_edrich_1999", "side": "l"})
    assert e.target == "l" and e.values == {"scale": 1.0}
    assert RienerEdrich1999PassiveMoment("knee_r").target == "r"
    with pytest.raises(ModelError, match="side 'r' or 'l'"):
        RienerEdrich1999PassiveMoment(None)
    with pytest.raises(ModelError, match="disagree"):
        RienerEdrich1999PassiveMoment("r", side="l")
    with pytest.raises(ModelError, match="no coordinate 'hip_r'"):
        pinmsk.load_model("forearm").with_effect(RienerEdrich1999PassiveMoment("r"))


# -- muscle-level effects --------------------------------------------------------------------------

def test_activation_dynamics_matches_the_muscle_layer():
    t = np.linspace(0, 2, 401)
    u = np.column_stack([0.5 + 0.45 * np.sign(np.sin(2 * np.pi * 1.3 * t)), 0.3 + 0.2 * np.sin(5 * t)])
    ad = ActivationDynamics("muscles", tau_rise=0.015, tau_fall=0.06)
    a = ad.transform(t, u)
    ref = activation_from_excitation(t, u, tau_rise=0.015, tau_fall=0.06)
    np.testing.assert_allclose(a, ref, rtol=1e-12, atol=1e-12)
    # batch over parameter sets equals one at a time
    batch = ad.transform_batch(t, u, {"tau_rise": np.array([0.015, 0.03]), "tau_fall": np.array([0.06, 0.1])})
    np.testing.assert_allclose(batch[1], activation_from_excitation(t, u, tau_rise=0.03, tau_fall=0.1),
                               rtol=1e-12)
    # rises faster than it falls
    step = np.where(t < 1, 1.0, 0.0)[:, None]
    a = ad.transform(t, step * 0 + np.where(t < 0.2, 0.0, np.where(t < 1, 1.0, 0.0))[:, None])
    k_rise = np.argmax(a[:, 0] > 0.632)
    k_fall = np.argmax((t > 1) & (a[:, 0] < 0.368))
    assert (t[k_rise] - 0.2) < 0.03 and 0.04 < (t[k_fall] - 1.0) < 0.09


def test_delay_shifts_a_band_limited_signal_exactly():
    t = np.arange(0, 4, 0.01)
    u = (0.5 + 0.3 * np.sin(2 * np.pi * 0.7 * t))[:, None]
    d = ElectromechanicalDelay("muscles", delay=0.0437).transform(t, u)
    inner = (t > 0.3) & (t < 3.7)
    np.testing.assert_allclose(d[inner, 0], 0.5 + 0.3 * np.sin(2 * np.pi * 0.7 * (t[inner] - 0.0437)), atol=2e-4)
    # white noise keeps its variance at a half-sample delay (no interpolation smoothing)
    rng = np.random.default_rng(0)
    w = rng.standard_normal((2000, 1))
    tt = np.arange(2000) * 0.01
    half = ElectromechanicalDelay("muscles", delay=0.005).transform(tt, w)
    assert np.std(half[100:-100]) == pytest.approx(np.std(w[100:-100]), rel=0.05)


def test_signal_effect_targets(forearm):
    assert ActivationDynamics().target == "muscles"
    ActivationDynamics("BRD").check_target(forearm)
    mask = ActivationDynamics("BRD").muscle_mask(forearm)
    assert mask.sum() == 1 and mask[forearm.muscles.index("BRD")]
    with pytest.raises(ModelError, match="no muscle 'BRX'.*BRD"):
        ActivationDynamics("BRX").check_target(forearm)


# -- catalog -----------------------------------------------------------------------------------------

def test_catalog_per_model(forearm, gait2d):
    t = np.linspace(0, 1, 101)
    tr = pinmsk.Trial(t, {"elbow_flexion": 0.5 + 0 * t, "elbow_flexion_moment": 0 * t})
    labels = {c.label for c in catalog(forearm, tr)}
    assert labels == {"joint_damping:elbow_flexion", "coulomb_friction:elbow_flexion",
                      "joint_spring:elbow_flexion", "passive_elastic:elbow_flexion", "payload:hand",
                      "segment_mass:forearm_hand", "sensor_offset:elbow_flexion", "sensor_gain:elbow_flexion",
                      "end_stop_upper:elbow_flexion", "end_stop_lower:elbow_flexion"}
    # ... each with its rest angle within the joint's range (0-2.6 rad)
    spring = next(c for c in catalog(forearm, tr) if c.family == "joint_spring")
    assert (spring.params["q0"].min, spring.params["q0"].max) == (0.0, 2.6)
    # with excitations only: muscle-level comparison, muscle effects join
    ex = pinmsk.Trial(t, {"elbow_flexion": 0.5 + 0 * t,
                          **{f"{m}_excitation": 0.1 + 0 * t for m in forearm.muscle_names}})
    labels = {c.label for c in catalog(forearm, ex)}
    assert {"activation_dynamics:muscles", "electromechanical_delay:muscles"} <= labels
    # a frame the user names
    labels = {c.label for c in catalog(forearm, tr, frames=["forearm_hand"], families=["payload"])}
    assert labels == {"payload:forearm_hand"}
    with pytest.raises(ModelError, match="unknown effect 'dampign'.*joint_damping"):
        catalog(forearm, tr, families=["dampign"])
    # gait2d with ground reactions only: the torso rows see masses, not joint effects
    g = {c: 0 * t for c in gait2d.coordinates}
    for s in ("r", "l"):
        g.update({f"{s}_ground_force_v{a}": (300.0 if a == "y" else 0.0) + 0 * t for a in "xyz"})
        g.update({f"{s}_ground_force_p{a}": 0 * t for a in "xyz"})
    labels = {c.label for c in catalog(gait2d, pinmsk.Trial(t, g))}
    assert "segment_mass:hat" in labels and not any(x.startswith("joint_damping") for x in labels)
    # a whole-body mass scale besides the segments; no sensor on the torso rows (no recorded moment)
    assert "scale" in labels and not any(x.startswith("sensor_") for x in labels)
    assert not any(x.startswith("riener_edrich") for x in labels)      # already in the model
    # the trunk's centre of mass (as RRA adjusts it) and each plate's corrections, one per loaded foot
    assert "com_offset:hat" in labels
    assert {f"plate_{k}:foot_{s}" for k in ("offset", "cop_offset", "tilt", "gain", "lag") for s in "rl"} <= labels


def test_user_registered_effect_docstring_example(forearm):
    """The registration example of pinmsk.effects' docstring runs, and the effect joins the catalog."""
    try:
        res = doctest.testmod(effects, verbose=False, raise_on_error=False)
        assert res.attempted >= 2 and res.failed == 0
        assert "quadratic_drag" in effects.families()
        t = np.linspace(0, 1, 101)
        tr = pinmsk.Trial(t, {"elbow_flexion": 0.5 + 0 * t, "elbow_flexion_moment": 0 * t})
        drag = [c for c in catalog(forearm, tr) if c.family == "quadratic_drag"]
        assert [c.target for c in drag] == ["elbow_flexion"]
        with pytest.raises(ModelError, match="already registered"):
            effects.register(type("Other", (effects.JointEffect,), {"family": "quadratic_drag"}))
    finally:
        effects.unregister("quadratic_drag")
    assert "quadratic_drag" not in effects.families()
    with pytest.raises(ModelError, match="built-in"):
        effects.unregister("joint_damping")
