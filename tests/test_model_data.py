"""The frozen Model, its Data (workspace), and the one parameter table.

* assignment to a Model, a component, a Motion or the table raises;
* two Data objects share nothing: components prepared in two threads on two
  motions give bit-for-bit the serial numbers, and one Data shares kinematics
  between the components prepared on one motion;
* ``model.parameters`` lists every effect, contact and muscle parameter with its
  declared unit and bounds; fixing and freeing round-trips; a fixed parameter
  keeps its value in an effect fit while the free one is recovered.
"""
from __future__ import annotations

import math
import pickle
import subprocess
import sys
import threading

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk.components import Motion, Parameters
from pinmsk.contact import HyperVolumetric, load_foot2d
from pinmsk.diagnose import EffectFit, compare, make_trial
from pinmsk.effects import JointDamping, JointSpring, Payload, SegmentMass
from pinmsk.effects._base import frame_point_kinematics, torque_regressor
from pinmsk.errors import ModelError
from pinmsk.muscles import Thelen2003
from pinmsk.muscles.models import MUSCLE_PARAMETERS
from pinmsk.muscles.muscle_set import MuscleSet


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def _motion(model, n, seed):
    """A smooth random motion of ``model`` over ``n`` frames."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n)
    w = rng.uniform(1.0, 3.0, model.nv)
    ph = rng.uniform(0, 2 * np.pi, model.nv)
    amp = rng.uniform(0.1, 0.4, model.nv)
    arg = 2 * np.pi * w[None] * t[:, None] + ph[None]
    q = amp * np.sin(arg)
    v = amp * 2 * np.pi * w * np.cos(arg)
    a = -amp * (2 * np.pi * w) ** 2 * np.sin(arg)
    q[:, model.coordinate_index("torso_y")] += 0.95 if "torso_y" in model.coordinates else 0.0
    return Motion(t, q, v, a)


# -- frozen ------------------------------------------------------------------------------------

def test_model_cannot_be_assigned_to(forearm):
    m = forearm + JointDamping("elbow_flexion", c=0.2)
    for attr, value in (("name", "other"), ("meta", {}), ("effects", ()), ("muscles", None), ("extra", 1)):
        with pytest.raises(AttributeError, match="immutable"):
            setattr(m, attr, value)
    with pytest.raises(TypeError):
        m.meta["description"] = "changed"                       # a read-only mapping
    with pytest.raises(TypeError):
        m.meta["package_dirs"][0] = "/elsewhere"                # nested lists are tuples
    with pytest.raises(ValueError, match="read-only"):
        m.gravity[1] = 0.0
    with pytest.raises(AttributeError, match="immutable"):
        m.effects[0].target = "wrist"
    with pytest.raises(AttributeError, match="immutable"):
        m.muscles.tendon = "compliant"
    with pytest.raises(ValueError, match="read-only"):
        m.muscles.f_max[0] = 1.0
    assert m.name == "forearm" and m.effects[0].target == "elbow_flexion"


def test_model_copies_its_skeleton_and_with_gravity_leaves_it_alone(forearm):
    pm = pin.Model(forearm.pin)
    m = pinmsk.Model(name="copy", pin_model=pm)
    pm.gravity = pin.Motion(np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0]))
    np.testing.assert_array_equal(m.gravity, [0.0, -9.81, 0.0])     # the caller's change does not reach it
    moon = forearm.with_gravity([0.0, -1.62, 0.0])
    np.testing.assert_array_equal(moon.gravity, [0.0, -1.62, 0.0])
    np.testing.assert_array_equal(forearm.gravity, [0.0, -9.81, 0.0])
    np.testing.assert_array_equal(forearm.pin.gravity.linear, [0.0, -9.81, 0.0])
    assert moon.pin is not forearm.pin and moon.muscles is forearm.muscles
    # the moon's gravity moment of the horizontal forearm is 1.62 / 9.81 of the Earth's
    q = np.array([[np.pi / 2]])
    earth = pinmsk.skeleton.gravity_torque(forearm, q)[0, 0]
    assert pinmsk.skeleton.gravity_torque(moon, q)[0, 0] == pytest.approx(earth * 1.62 / 9.81, rel=1e-12)
    with pytest.raises(ModelError, match="gravity must be 3 finite numbers"):
        forearm.with_gravity([0.0, "down", 0.0])


def test_motion_is_read_only_and_independent_of_its_inputs(forearm):
    q = np.zeros((5, 1))
    sig = np.ones(5)
    mo = Motion(np.arange(5.0), q, q, q, {"s": sig})
    q[0, 0] = 1.0
    sig[0] = 7.0
    assert mo.q[0, 0] == 0.0 and mo.signal("s")[0] == 1.0
    with pytest.raises(ValueError, match="read-only"):
        mo.q[0, 0] = 2.0
    with pytest.raises(TypeError):
        mo.signals["s"] = sig
    again = pickle.loads(pickle.dumps(mo))
    np.testing.assert_array_equal(again.signal("s"), mo.signal("s"))


def test_frozen_things_pickle_and_compare(forearm):
    m = forearm.with_gravity([0.0, -9.0, 0.0]).fix("muscle:BRD.f_max").free("muscle:BRA.l_opt")
    m2 = pickle.loads(pickle.dumps(m))
    assert m2.parameters == m.parameters
    np.testing.assert_array_equal(m2.gravity, [0.0, -9.0, 0.0])
    assert m2.meta["package_dirs"] == m.meta["package_dirs"]
    assert m2.muscles == m.muscles and m2.muscles.display_points == m.muscles.display_points


# -- Data ----------------------------------------------------------------------------------------

def _components(model):
    return [SegmentMass("shank_r", delta=0.3), SegmentMass("thigh_l", delta=-0.2), Payload("foot_r", mass=2.0),
            HyperVolumetric("heel_r", center="sole")]


def _forces(model, motion, data):
    return np.stack([c.generalized_force(model, motion, cache=c.prepare(model, motion, data=data))
                     for c in _components(model)])


def test_two_data_in_two_threads_match_serial(gait2d):
    motions = [_motion(gait2d, 120, seed=s) for s in (1, 2)]
    serial = [_forces(gait2d, mo, gait2d.create_data()) for mo in motions]
    assert not np.allclose(serial[0], serial[1])                 # different motions, different forces
    assert np.abs(serial[0]).max() > 1.0                          # and real ones
    out = [[None] * 4, [None] * 4]
    start = threading.Barrier(2)

    def work(k):
        data = gait2d.create_data()
        start.wait()
        for rep in range(4):
            out[k][rep] = _forces(gait2d, motions[k], data)
            data.clear() if rep % 2 else None                     # recompute half of the time

    threads = [threading.Thread(target=work, args=(k,)) for k in (0, 1)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for k in (0, 1):
        for rep in range(4):
            np.testing.assert_array_equal(out[k][rep], serial[k])


def test_data_shares_kinematics_on_one_motion_only(gait2d, forearm):
    mo = _motion(gait2d, 30, seed=3)
    data, other = gait2d.create_data(), gait2d.create_data()
    Y = torque_regressor(gait2d, mo, data)
    assert torque_regressor(gait2d, mo, data) is Y                         # computed once per Data
    assert torque_regressor(gait2d + SegmentMass("hat"), mo, data) is Y    # same skeleton, same Data
    assert torque_regressor(gait2d, mo, other) is not Y
    np.testing.assert_array_equal(torque_regressor(gait2d, mo, other), Y)
    np.testing.assert_array_equal(torque_regressor(gait2d, mo), Y)          # no Data: afresh, same numbers
    # a second motion with the same numbers is another motion (identity, not values)
    twin = Motion(mo.t, mo.q, mo.v, mo.a)
    assert torque_regressor(gait2d, twin, data) is not Y
    # the regressor reproduces the skeleton's inverse dynamics: rnea = Y pi
    pi = np.concatenate([gait2d.pin.inertias[j].toDynamicParameters() for j in range(1, gait2d.pin.njoints)])
    tau = pinmsk.skeleton.rnea(gait2d, mo.q, mo.v, mo.a)
    np.testing.assert_allclose(Y @ pi, tau, atol=1e-9)
    J, acc = frame_point_kinematics(gait2d, mo, "foot_r", data)
    assert frame_point_kinematics(gait2d, mo, "foot_r", data)[0] is J
    with pytest.raises(ModelError, match="created by model 'forearm'"):
        torque_regressor(gait2d, mo, forearm.create_data())
    assert "cached quantities" in repr(data)
    # it keeps the last max_motions motions
    small = gait2d.create_data()
    first = torque_regressor(gait2d, mo, small)
    for seed in range(small.max_motions):
        torque_regressor(gait2d, _motion(gait2d, 3, seed=10 + seed), small)
    assert torque_regressor(gait2d, mo, small) is not first


def test_model_imports_the_contact_physics_only():
    """model -> contact physics, contact identification -> model: one way (no import cycle)."""
    code = ("import sys, pinmsk.model as m; "
            "assert 'pinmsk.contact.spec' in sys.modules and 'pinmsk.contact.identify' not in sys.modules; "
            "from pinmsk.contact import ContactFit, load_foot2d; print(load_foot2d().name)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "foot2d"


# -- the parameter table -------------------------------------------------------------------------

def test_parameters_list_every_component_and_muscle_with_units_and_bounds(forearm):
    m = forearm + JointDamping("elbow_flexion", c=0.2) + Payload("hand", mass=1.5)
    table = m.parameters
    assert isinstance(table, Parameters)
    p = table["joint_damping:elbow_flexion.c"]
    assert (p.value, p.min, p.max, p.unit, p.vary) == (0.2, 0.0, JointDamping.parameters[0].max,
                                                       JointDamping.parameters[0].unit, True)
    assert table["payload:hand.mass"].unit == "kg" and table["payload:hand.mass"].value == 1.5
    mech = forearm.muscles.mtu.mechanical_parameters
    assert mech == ("f_max", "l_opt", "l_slack", "pennation", "v_max")
    assert len(table) == 2 + forearm.n_muscles * len(mech)
    for i, name in enumerate(forearm.muscle_names):
        for what in mech:
            row = table[f"muscle:{name}.{what}"]
            assert row.value == getattr(forearm.muscles.mtu, what)[i]
            rule = MUSCLE_PARAMETERS[what]
            assert (row.unit, row.min, row.max, row.vary) == (rule.unit, rule.low, rule.high, False)
    assert table["muscle:BRD.f_max"].value == 101.58 and table["muscle:BRD.pennation"].max == math.pi / 2
    with pytest.raises(ModelError, match="no parameter 'muscle:BRD.fmax'; did you mean 'muscle:BRD.f_max'"):
        m.with_parameters({"muscle:BRD.fmax": 1.0})
    with pytest.raises(KeyError):
        table["nothing"]
    assert table.get("nothing") is None
    with pytest.raises(AttributeError, match="read-only"):
        table.x = 1
    assert "joint_damping:elbow_flexion.c" in table.pretty() and "N m s/rad" in table.pretty()


def test_muscle_parameters_are_validated_in_one_place(forearm):
    """The muscle model checks them, whichever way they come: its constructor, a set, a table."""
    rule = r"f_max = -5.0 for muscle 1 \('BICLH'\); it must be finite and > 0"
    ms = forearm.muscles
    f_max = np.array(ms.f_max)
    f_max[1] = -5.0
    with pytest.raises(ModelError, match=rule):
        Thelen2003(f_max=f_max, l_opt=ms.l_opt, l_slack=ms.l_slack, names=ms.names)
    with pytest.raises(ModelError, match=rule):
        ms.mtu.replace(f_max=f_max)
    with pytest.raises(ModelError, match=rule):
        forearm.with_parameters({"muscle:BICLH.f_max": -5.0})
    with pytest.raises(ModelError, match=r"volume = -1.0 for muscle 0 \('BRD'\)"):
        MuscleSet(names=ms.names, model_type=ms.model_type, mtu=ms.mtu, path=ms.path, volume=-1.0)
    # stored once: the set reads the muscle model's arrays
    assert ms.f_max is ms.mtu.f_max and ms.l_opt is ms.mtu.l_opt and ms.volume is ms.mtu.volume
    bare = MuscleSet(names=ms.names, model_type=ms.model_type, mtu=ms.mtu.replace(volume=None), path=ms.path)
    np.testing.assert_allclose(bare.volume, ms.f_max * ms.l_opt / 0.25e6)  # thesis Eq. B.3 default


def test_contact_parameters_in_the_table():
    foot = load_foot2d()
    np.testing.assert_array_equal(foot.gravity, [0.0, -9.81, 0.0])           # from urdf/foot2d.toml
    assert foot.meta["sidecar"].endswith("foot2d.toml")
    spheres = pinmsk.contact.foot_contacts(foot, "volumetric")
    m = foot.with_effect(*spheres)
    names = [n for n in m.parameters if n.startswith("volumetric:heel.")]
    assert names == [f"volumetric:heel.{p.name}" for p in spheres[0].parameters]
    R = m.parameters["volumetric:heel.R"]
    assert (R.min, R.max, R.unit, R.value) == (0.001, 0.055, "m", 0.051)     # Table 4.3's bound and optimum
    assert not m.parameters["volumetric:heel.dx"].vary                       # offsets fixed unless relaxed
    relaxed = pinmsk.contact.foot_contacts(foot, "volumetric", relax=True)
    assert relaxed[0].params["dx"].vary and relaxed[0].params["dy"].vary and not spheres[0].params["dx"].vary


def test_fix_and_free_round_trip(forearm):
    spring = JointSpring("elbow_flexion", k=2.0, q0=1.0)
    assert spring.fix("q0").params["q0"].vary is False and spring.params["q0"].vary is True
    assert spring.fix("q0").free("q0").params == spring.params
    m = forearm + spring
    name = "joint_spring:elbow_flexion.q0"
    fixed = m.fix(name)
    assert fixed.parameters[name].vary is False and m.parameters[name].vary is True
    assert fixed.free(name).parameters == m.parameters
    # a table carried back: values, bounds and vary of every row
    table = m.parameters.fix(name).with_values({"muscle:BRD.f_max": 203.16}).free("muscle:BRD.f_max")
    back = m.with_parameters(table)
    assert back.parameters == table
    assert m.with_parameters(back.parameters.fix("muscle:BRD.f_max").with_values(
        {"muscle:BRD.f_max": 101.58}).free(name)).parameters == m.parameters
    # muscle values reach the muscle model: the active force capacity of BRD doubles, the others stay
    q, v = np.array([[0.8], [1.4]]), np.zeros((2, 1))
    before = m.muscles.force_limits(q, v)[0]
    after = back.muscles.force_limits(q, v)[0]
    np.testing.assert_allclose(after[:, 0], 2.0 * before[:, 0], rtol=1e-12)
    np.testing.assert_array_equal(after[:, 1:], before[:, 1:])
    assert back.muscles.f_max[0] == 203.16 and m.muscles.f_max[0] == 101.58
    # bounds: narrower bounds are kept, values outside them refused
    narrow = m.with_parameters(bounds={"joint_spring:elbow_flexion.k": (1.0, 3.0)})
    assert (narrow.parameters["joint_spring:elbow_flexion.k"].min, narrow.parameters["joint_spring:elbow_flexion.k"].max) == (1.0, 3.0)
    with pytest.raises(ModelError, match="outside its bounds"):
        narrow.with_parameters({"joint_spring:elbow_flexion.k": 4.0})
    with pytest.raises(ModelError, match="l_opt = -0.1 for muscle 0 \\('BRD'\\)"):
        m.with_parameters({"muscle:BRD.l_opt": -0.1})
    with pytest.raises(ModelError, match="no parameter 'qzero' \\(in vary=\\)"):
        spring.with_params(vary={"qzero": False})


def test_a_fixed_parameter_is_not_varied_by_an_effect_fit(forearm):
    truth = JointSpring("elbow_flexion", k=2.0, q0=1.0)
    trial = make_trial(forearm, [truth], duration=6.0, rate=100.0, seed=5)
    cmp = compare(forearm, trial)
    free = EffectFit(JointSpring("elbow_flexion", k=0.5, q0=0.0)).fit(cmp)
    assert free.n_params_ == 2 and free.params_["q0"] == pytest.approx(1.0, rel=0.05)
    # q0 fixed at the truth: only k is fitted (and recovered); q0 is exactly what was given
    start = (forearm + JointSpring("elbow_flexion", k=0.5, q0=1.0)).fix("joint_spring:elbow_flexion.q0")
    one = EffectFit(start.component("joint_spring:elbow_flexion")).fit(cmp)
    assert one.n_params_ == 1 and one.params_["q0"] == 1.0 and "q0" not in one.stderr_
    assert one.params_["k"] == pytest.approx(2.0, rel=0.05)
    # fixed at a wrong rest angle it stays wrong, and the fit is worse than the free one
    wrong = EffectFit(JointSpring("elbow_flexion", k=0.5, q0=0.6).fix("q0")).fit(cmp)
    assert wrong.params_["q0"] == 0.6 and wrong.sse_ > 2 * free.sse_
