"""The sidecar ``pinmsk import`` writes carries the import's components: actuators (``[[actuators]]``), OpenSim
contacts (``[[contacts]]``, their spheres' frames as URDF links) and effects (``[[effects]]``), and names the source
.osim (``[model] osim``) whose geometric muscle paths the viewer draws.

Round trips: ``load_model(sidecar)`` against ``load_model(x.osim)`` -- equal components (parameters with bounds and
vary flags, options), the same contact forces over a motion (1e-12 relative) and the same static optimization with
the actuators (1e-9).  The inline leg of tests/test_osim_import.py (a muscle, three actuators, a HuntCrossleyForce
and a SmoothSphereHalfSpaceForce) needs nothing; Moco's ``2D_gait.osim`` (four SmoothSphereHalfSpaceForce, one
CoordinateActuator) and RajagopalWalk (13 CoordinateActuators; its 80 muscles are not imported by default) skip
cleanly without ``../shared/data``.  Where a model has no imported muscles, SO gets the same one-muscle set on both
models (SO needs a muscle; the actuators are what is compared).  Nothing here runs OpenSim: the imported contacts and
actuators are checked against OpenSim in test_osim_contact.py and test_actuators.py.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import pinmsk
import test_osim_import as t
from test_osim_exact import _walk          # a smooth trial in OpenSim's coordinates
from pinmsk.actuators import CoordinateActuator, PointActuator, TorqueActuator
from pinmsk.actuators import from_spec as actuator_from_spec
from pinmsk.actuators import to_spec as actuator_to_spec
from pinmsk.components import Motion
from pinmsk.contact import HuntCrossleyForce, SmoothSphereHalfSpaceForce, foot_contacts
from pinmsk.contact.spec import from_spec as contact_from_spec
from pinmsk.contact.spec import to_spec as contact_to_spec
from pinmsk.errors import ModelError
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.muscles.models import Thelen2003
from pinmsk.muscles.muscle_set import MuscleSet
from pinmsk.muscles.paths import MomentArmPath
from pinmsk.opensim.actuators import actuator_hook
from pinmsk.opensim.contacts import contact_hook
from pinmsk.opensim.importer import write_import
from pinmsk.solvers.static import StaticOptimization
from pinmsk.trial import Trial

MOCO = "opensim-models/Moco2DWalking"
RAJAGOPAL = "opensim-models/RajagopalWalk/subject_walk_scaled.osim"


def _quiet(fn, *args, **kw):
    """``fn(*args, **kw)`` without the import report's one-line summary and SO's no-GRF residual warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return fn(*args, **kw)


@pytest.fixture(scope="module")
def leg_path(tmp_path_factory):
    p = tmp_path_factory.mktemp("sidecar") / "leg.osim"
    p.write_text(t.leg())
    return p


@pytest.fixture(scope="module")
def leg(leg_path, tmp_path_factory):
    """``(direct, back, files)``: the leg loaded from its .osim and from the sidecar written from it."""
    direct = _quiet(pinmsk.load_model, leg_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")        # every component is written: no "not written" warning
        files = write_import(direct, tmp_path_factory.mktemp("leg_out"))
    return direct, pinmsk.load_model(files["sidecar"]), files


def _shared(rel):
    d = shared_data_dir()
    if d is None or not (d / rel).is_file():
        pytest.skip(f"../shared/data/{rel} is absent")
    return d / rel


def _close(a, b, rel):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    return float(np.max(np.abs(a - b), initial=0.0)) <= rel * max(1.0, float(np.max(np.abs(a), initial=0.0)))


def _same_components(direct, back):
    """Equal components in the same order, with the same parameter table (values, bounds, vary)."""
    assert [c.label for c in back.components] == [c.label for c in direct.components]
    assert back.effects == direct.effects and back.contacts == direct.contacts
    assert back.parameters == direct.parameters
    for a, b in zip(direct.components, back.components):
        assert type(a) is type(b) and a._options() == b._options(), a.label


def _same_contact_forces(direct, back, motion):
    """The contacts' forces, points, indentations and generalized forces over ``motion`` agree to 1e-12
    (relative to each quantity's peak); returns the peak normal force (N)."""
    peak = 0.0
    for a, b in zip(direct.contacts, back.contacts):
        fa, fb = a.evaluate(direct, motion), b.evaluate(back, motion)
        for what in ("normal", "force", "point", "penetration", "slip"):
            assert _close(getattr(fa, what), getattr(fb, what), 1e-12), (a.label, what)
        assert _close(a.generalized_force(direct, motion), b.generalized_force(back, motion), 1e-12), a.label
        peak = max(peak, float(np.max(fa.normal)))
    return peak


def _same_so(direct, back, trial):
    """Static optimization with the models' actuators (and reserves) gives the same result to 1e-9; returns
    the largest actuator control."""
    sa = _quiet(StaticOptimization(reserves=True).fit, direct, trial, cutoff=0)
    sb = _quiet(StaticOptimization(reserves=True).fit, back, trial, cutoff=0)
    assert [a.name for a in sa.actuators_] == [a.name for a in sb.actuators_]
    assert sa.actuators_ == sb.actuators_
    ra, rb = sa.result_, sb.result_
    assert ra.names == rb.names
    for n in ra.names:
        assert _close(ra[n], rb[n], 1e-9), n
    return float(np.max(np.abs(sa.controls_)))


def _one_muscle(model, coordinate):
    """The same one-muscle set for two models without muscles (a Thelen muscle of 4 cm moment arm)."""
    coords = model.coordinates
    coeffs = np.zeros((1, len(coords), 1))
    coeffs[0, coords.index(coordinate), 0] = 0.04
    path = MomentArmPath(muscles=("m",), coordinates=coords, l0=[0.3], coeffs=coeffs)
    mtu = Thelen2003(names=("m",), f_max=[2000.0], l_opt=[0.1], l_slack=[0.2], pennation=[0.0])
    return MuscleSet(names=("m",), model_type="thelen2003", mtu=mtu, path=path, tendon="rigid")


def _touching(model, motion, depth=0.01):
    """``motion`` with the pelvis lowered at each frame so that the first contact sphere is ``depth`` into the
    floor (y = 0), so the contact forces are not nil."""
    import pinocchio as pin
    c = model.contacts[0]
    pm, pd = model.pin, model.pin.createData()
    fid = model.frame_id(c.target)
    q = np.array(motion.q)
    iy = model.coordinate_index("pelvis_ty")
    for k in range(len(q)):
        pin.framesForwardKinematics(pm, pd, q[k])
        q[k, iy] += c.values["radius"] - depth - pd.oMf[fid].translation[1]
    return Motion(motion.t, q, motion.v, motion.a)


# -- the leg: every component kind, both contact laws ---------------------------------------------------------

def test_the_legs_sidecar_has_its_actuators_contacts_and_frames(leg):
    direct, back, files = leg
    _same_components(direct, back)
    assert {type(c) for c in back.effects} == {CoordinateActuator, PointActuator, TorqueActuator}
    assert {type(c) for c in back.contacts} == {HuntCrossleyForce, SmoothSphereHalfSpaceForce}
    text = files["sidecar"].read_text()
    assert text.count("[[actuators]]") == 3 and text.count("[[contacts]]") == 2 and "NOT WRITTEN" not in text
    assert 'type = "SmoothSphereHalfSpaceForce"' in text and "min_control = -inf" in text
    # the sphere's frame is a link of the URDF, placed where OpenSim places the sphere
    urdf = files["urdf"].read_text()
    assert '<link name="heel"/>' in urdf and '<joint name="heel_frame_joint" type="fixed">' in urdf
    assert back.frame_id("heel") is not None and back.meta["source_osim"] == str(direct.meta["osim"])


def test_the_legs_contact_forces_and_so_are_the_osims(leg):
    direct, back, _ = leg
    trial = _walk(direct, n=40)
    ma, mb = direct.motion(trial, cutoff=0), back.motion(trial, cutoff=0)
    assert np.array_equal(ma.q, mb.q) and np.array_equal(ma.v, mb.v)
    peak = _same_contact_forces(direct, back, _touching(direct, ma))
    assert peak > 50.0                                           # the spheres press into the floor
    assert _same_so(direct, back, trial) > 1e-3                  # the actuators take part


def test_effects_are_written_and_those_the_format_cannot_hold_are_named(leg, tmp_path):
    direct, _, _ = leg
    from pinmsk.effects.damping import JointDamping
    from pinmsk.effects.spring import JointSpring
    damping = JointDamping("knee_angle", c=0.7)
    spring = JointSpring("hip_flexion").fix("k")                  # a fixed parameter: [[effects]] has no 'fixed'
    model = direct + damping + spring
    with pytest.warns(UserWarning, match=r"1 component\(s\) are not written to the sidecar: "
                                         r"joint_spring:hip_flexion \(its \[\[effects\]\] entry does not hold"):
        files = write_import(model, tmp_path)
    assert "# NOT WRITTEN (they would not read back equal" in files["sidecar"].read_text()
    back = pinmsk.load_model(files["sidecar"])
    assert back.component("joint_damping:knee_angle") == damping
    assert back.component("joint_damping:knee_angle").params == damping.params
    assert "joint_spring:hip_flexion" not in [c.label for c in back.components]


def test_changed_bounds_and_vary_flags_survive_the_sidecar(leg, tmp_path):
    direct, _, _ = leg
    model = direct.with_parameters(
        {"smooth_sphere_half_space:heel.stiffness": 2e6},
        vary={"smooth_sphere_half_space:heel.radius": True, "hunt_crossley_force:heel.dissipation": False,
              "coordinate_actuator:lumbar_reserve.optimal_force": True},
        bounds={"smooth_sphere_half_space:heel.stiffness": (1e5, 5e6),
                "point_actuator:FX.optimal_force": (1.0, 50.0)})
    back = pinmsk.load_model(write_import(model, tmp_path)["sidecar"])
    _same_components(model, back)
    assert back.parameters["smooth_sphere_half_space:heel.stiffness"].max == 5e6


# -- the readers: each type's entry, and bad entries refused by name ---------------------------------------

def test_every_contact_and_actuator_type_reads_back_its_own_entry():
    hs = dict(location=(0.01, -0.02, 0.003), plane_normal=(0.1, 1.0, 0.0), plane_point=(0.0, 0.02, 0.0))
    contacts = [SmoothSphereHalfSpaceForce("s", radius=0.03, stiffness=3e6, dissipation=2.0, hertz_smoothing=250.0,
                                           **hs),
                HuntCrossleyForce("h", radius=0.02, stiffness=1e6, static_friction=0.9, transition_velocity=0.1,
                                  bounds={"stiffness": (1e3, 1e8)}, **hs).free("radius"),
                *foot_contacts(pinmsk.load_model("gait2d"), "hypervolumetric", side="r"),
                *foot_contacts(pinmsk.load_model("foot2d"), "point")]
    for c in contacts:
        spec = contact_to_spec(c)
        back = contact_from_spec(spec)
        assert back == c and back.params == c.params and back._options() == c._options(), c.label
    actuators = [CoordinateActuator("r", "knee", optimal_force=50.0, min_control=-2.0, max_control=math.inf),
                 PointActuator("p", "pelvis", point=(0.1, 0.0, 0.0), direction=(0.0, 2.0, 0.0), point_is_global=True,
                               optimal_force=3.0),
                 TorqueActuator("t", "pelvis", body_b="femur_r", axis=(1.0, 0.0, 0.0), torque_is_global=False)]
    for a in actuators:
        back = actuator_from_spec(actuator_to_spec(a))
        assert back == a and back.params == a.params, a.label
    assert actuator_from_spec({"type": "coordinate_actuator", "name": "x", "coordinate": "knee"}).max_control == math.inf


@pytest.mark.parametrize("spec, message", [
    ({"type": "SmoothSphereHalfSpaceForce", "frame": "heel", "stifness": 1.0},
     r"unknown key 'stifness' in a 'SmoothSphereHalfSpaceForce' contact \(frame heel\) \(did you mean 'stiffness'\?\)"),
    ({"type": "HuntCrossleyForce", "frame": "heel", "center": "sole"}, r"unknown key 'center'"),
    ({"type": "SmoothSphereHalfSpace", "frame": "heel"}, r"did you mean 'SmoothSphereHalfSpaceForce'\?"),
    ({"type": "HuntCrossleyForce", "frame": "heel", "plane_normal": [0, 0, 0]}, r"frame heel.*has no direction"),
    ({"type": "HuntCrossleyForce", "frame": "heel", "fixed": ["stiffnes"]},
     r"'fixed' names unknown parameter 'stiffnes' \(did you mean 'stiffness'\?\)"),
    ({"type": "HuntCrossleyForce", "frame": "heel", "fixed": ["radius"], "free": ["radius"]}, r"both fixed and free"),
    ({"type": "HuntCrossleyForce", "frame": "heel", "stiffness": 1.0, "params": {"stiffness": 2.0}}, "given twice"),
])
def test_bad_contact_entries_are_refused_by_name(spec, message):
    with pytest.raises(ModelError, match=r"leg\.toml \[\[contacts\]\] #1.*" + message):
        contact_from_spec(spec, where="leg.toml [[contacts]] #1")


@pytest.mark.parametrize("spec, message", [
    ({"type": "CoordinateActuator", "name": "r", "coordinate": "knee", "max_contrl": 1.0},
     r"'r': unknown key 'max_contrl' in a CoordinateActuator \(did you mean 'max_control'\?\)"),
    ({"type": "PointActuator", "name": "p", "body": "pelvis", "axis": [1, 0, 0]}, r"unknown key 'axis'"),
    ({"type": "CoordinateActutor", "name": "r", "coordinate": "knee"}, r"did you mean 'CoordinateActuator'\?"),
    ({"type": "TorqueActuator", "name": "t"}, r"give 'body_a', the body it acts on"),
    ({"type": "CoordinateActuator", "coordinate": "knee"}, r"give the actuator's 'name'"),
    ({"type": "CoordinateActuator", "name": "r", "coordinate": "knee", "min_control": 2.0, "max_control": 1.0},
     r"min_control 2 > max_control 1"),
    ({"type": "PointActuator", "name": "p", "body": "pelvis", "force_is_global": "yes"},
     r"force_is_global must be true or false"),
    ({"type": "CoordinateActuator", "name": "r", "coordinate": "knee", "optimal_force": -1.0},
     r"optimal_force' = -1 .* outside its bounds"),
])
def test_bad_actuator_entries_are_refused_by_name(spec, message):
    with pytest.raises(ModelError, match=r"leg\.toml \[\[actuators\]\] #1.*" + message):
        actuator_from_spec(spec, where="leg.toml [[actuators]] #1")


def test_a_sidecar_actuator_on_a_missing_coordinate_is_named(leg, tmp_path):
    _, _, files = leg
    text = files["sidecar"].read_text().replace('coordinate = "lumbar_extension"', 'coordinate = "lumbar_extnsion"')
    bad = files["sidecar"].parent / "bad.toml"
    bad.write_text(text)
    with pytest.raises(ModelError, match=r"no coordinate 'lumbar_extnsion'; did you mean 'lumbar_extension'"):
        pinmsk.load_model(bad)
    bad.unlink()


# -- the viewer draws the geometric paths of the .osim the sidecar names ----------------------------------------

def test_the_viewer_draws_the_source_osims_paths_or_says_why_not(leg, tmp_path):
    from pinmsk.presentation.viewer import muscle_polylines
    direct, back, files = leg
    q = direct.motion(_walk(direct, n=8), cutoff=0).q
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        drawn, expected = muscle_polylines(back), muscle_polylines(direct)
    assert drawn.names == expected.names == ("vas",)
    assert np.array_equal(drawn(q)["vas"], expected(q)["vas"])
    # the sidecar moved away from its .osim: the viewer says which file it misses, and draws no paths
    moved = tmp_path / "moved"
    moved.mkdir()
    for f in files.values():
        (moved / f.name).write_text(f.read_text())
    alone = pinmsk.load_model(moved / files["sidecar"].name)
    with pytest.warns(UserWarning, match=r"model 'leg' \(.*leg\.toml, \[model\] osim\): the OpenSim model it was "
                                         r"imported from, .*leg\.osim, is not found, so no muscle paths are drawn"):
        assert muscle_polylines(alone) is None
    # the .osim changed since: drawn, with a warning saying so
    changed = Path(alone.meta["source_osim"])                     # where [model] osim points from moved/
    changed.parent.mkdir(parents=True, exist_ok=True)
    changed.write_text(Path(direct.meta["osim"]).read_text() + "\n")
    with pytest.warns(UserWarning, match=r"leg\.osim changed since the sidecar was written"):
        assert muscle_polylines(alone).names == ("vas",)


# -- the shared models ------------------------------------------------------------------------------------------

def _moco_trial(d, frames=None):
    """Moco's reference walking coordinates (the first ``frames``)."""
    tr = pinmsk.read_trial(d / "referenceCoordinates.sto")
    k = slice(0, frames)
    return Trial(tr.time[k], {n.split("/")[-2]: np.asarray(tr[n])[k] for n in tr.names if n.endswith("/value")})


def test_moco_2d_gait_contacts_and_actuator_round_trip(tmp_path):
    path = _shared(f"{MOCO}/2D_gait.osim")
    d = path.parent
    direct, _ = pinmsk.model.import_osim(path, hooks=(actuator_hook, contact_hook))   # fast: no muscle fits
    files = write_import(path, tmp_path, hooks=(actuator_hook, contact_hook))
    back = pinmsk.load_model(files["sidecar"])
    _same_components(direct, back)
    assert len(back.contacts) == 4 and [a.name for a in back.effects] == ["lumbarAct"]
    peak = _same_contact_forces(direct, back, direct.motion(_moco_trial(d), cutoff=0))
    assert peak > 200.0                                           # stance
    m = _one_muscle(direct, "knee_angle_r")
    assert _same_so(direct.with_muscles(m), back.with_muscles(m), _moco_trial(d, 30)) > 1e-3


@pytest.mark.slow
def test_moco_2d_gait_full_import_round_trip(tmp_path):
    """With its 18 fitted muscles (~20 s on 2 shared cores); test_moco_2d_gait_contacts_and_actuator_round_trip
    covers the same code fast."""
    path = _shared(f"{MOCO}/2D_gait.osim")
    direct = _quiet(pinmsk.load_model, path)
    back = pinmsk.load_model(write_import(direct, tmp_path)["sidecar"])
    _same_components(direct, back)
    _same_contact_forces(direct, back, direct.motion(_moco_trial(path.parent), cutoff=0))
    assert _same_so(direct, back, _moco_trial(path.parent, 20)) > 1e-3


@pytest.mark.slow          # the legs' and Moco 2-D gait's sidecar actuators round trip by default
def test_rajagopals_thirteen_actuators_round_trip(tmp_path):
    path = _shared(RAJAGOPAL)
    direct = _quiet(pinmsk.load_model, path)
    assert len(direct.muscle_names) == 80                          # fitted along the patella couplers
    back = pinmsk.load_model(write_import(direct, tmp_path)["sidecar"])
    assert back.muscle_names == direct.muscle_names
    _same_components(direct, back)
    assert len(back.effects) == 13 and not back.contacts
    m = _one_muscle(direct, "knee_angle_r")
    assert _same_so(direct.with_muscles(m), back.with_muscles(m), _walk(direct, n=15)) > 1e-3
