"""OpenSim's contact forces imported (pinmsk/opensim/contacts.py), against OpenSim's own numbers.

* Moco's ``2D_gait.osim`` (4 SmoothSphereHalfSpaceForce on a floor turned by -90 degrees about z): at
  every frame of ``referenceCoordinates.sto`` (speeds: a cubic spline's derivative, the same in both
  tools) each force's ``getRecordValues`` (force and torque on the sphere's body and on the ground),
  and the generalized forces they make (OpenSim's InverseDynamicsSolver with the contacts on and
  off), against pinmsk's; the summed GRF against ``referenceGRF.sto`` is printed only (those GRF are
  the predictive simulation's, with its own speeds).
* A ball (6-dof CustomJoint) with a HuntCrossleyForce sphere on a tilted offset frame and a
  SmoothSphereHalfSpaceForce sphere, against a tilted half space off the origin, over penetrations
  of -3..12 mm and speeds that include fast rebounds: both laws against OpenSim's.
* The import report (what became what, what is not imported, by name) and bad input.

Skips cleanly without ``opensim`` or the shared data (the report and bad-input tests need neither).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import pinmsk
from pinmsk.components import Motion
from pinmsk.contact import (HuntCrossleyForce, SmoothSphereHalfSpaceForce, contact_ground_reactions,
                            ground_reaction_trial)
from pinmsk.dynamics import component_forces, inverse_dynamics_array
from pinmsk.errors import ModelError
from pinmsk.model import import_osim
from pinmsk.opensim.contacts import contact_hook

from pinmsk.io.shared_data import shared_data_dir

from conftest import import_opensim

MOCO = "opensim-models/Moco2DWalking"
#: the Moco model's forces and the frames (its ContactSpheres) pinmsk puts them on
FORCES = {"contactHeel_r": "heel_r", "contactHeel_l": "heel_l", "contactFront_r": "front_r",
          "contactFront_l": "front_l"}


# -- helpers --------------------------------------------------------------------------------

def _opensim():
    osim, why = import_opensim()
    if osim is None:
        pytest.skip(why)
    return osim


def _moco_dir():
    d = shared_data_dir()
    d = None if d is None else d / MOCO
    if d is None or not (d / "2D_gait.osim").is_file() or not (d / "referenceCoordinates.sto").is_file():
        pytest.skip(f"../shared/data/{MOCO} is absent")
    return d


def _records(force, state) -> np.ndarray:
    """A contact force's getRecordValues: (force, torque) on the sphere's body, then on the half space's."""
    rv = force.getRecordValues(state)
    return np.array([rv.get(i) for i in range(rv.size())])


def _set_state(osim_model, state, names, q, v):
    cs = osim_model.getCoordinateSet()
    for j, name in enumerate(names):
        c = cs.get(name)
        c.setValue(state, float(q[j]), False)
        c.setSpeedValue(state, float(v[j]))


def _u_order(osim_model, state) -> list[str]:
    """OpenSim's coordinates in the order of the state's speeds (the mobilities')."""
    cs = osim_model.getCoordinateSet()
    where = {}
    for i in range(cs.getSize()):
        state.updU().setToZero()
        cs.get(i).setSpeedValue(state, 1.0)
        u = state.getU()
        where[cs.get(i).getName()] = next(j for j in range(u.size()) if u.get(j) == 1.0)
    return sorted(where, key=where.get)


def _outputs(model, mo):
    """``{label: (ContactForces, (N, 3) origin of the sphere's body)}`` over the motion."""
    import pinocchio as pin

    pm, pd = model.pin, model.pin.createData()
    out = {}
    for comp in model.contacts:
        body = pm.frames[model.frame_id(comp.target)].parentFrame
        origin = np.empty((mo.n_frames, 3))
        for k in range(mo.n_frames):
            pin.framesForwardKinematics(pm, pd, mo.q[k])
            origin[k] = pd.oMf[body].translation
        out[comp.label] = (comp.evaluate(model, mo), origin)
    return out


def _check_records(comp, outputs, k, rec):
    """(error of the force and torque on the sphere's body and on the ground, error of the normal /
    friction split, |F|) at frame k against OpenSim's record values ``rec``."""
    out, origin = outputs[comp.label]
    F, point = out.force[k], out.point[k]
    mine = np.concatenate([F, np.cross(point - origin[k], F), -F, np.cross(point, -F)])
    n = np.asarray(comp.plane_normal)
    normal = rec[:3] @ n                                  # OpenSim's force split into normal and friction
    split = max(abs(normal - out.normal[k]), np.abs(rec[:3] - normal * n - out.friction[k]).max())
    return np.abs(mine - rec).max(), split, np.linalg.norm(rec[:3])


# -- Moco's 2-D walking model ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def moco():
    """``(model, motion, names, Q, V)``: 2D_gait imported (skeleton + contacts), the reference motion
    with spline speeds, OpenSim's coordinate names and values."""
    d = _moco_dir()
    model, _ = import_osim(d / "2D_gait.osim", hooks=(contact_hook,))      # the muscles are not needed here
    tr = pinmsk.read_trial(d / "referenceCoordinates.sto")
    names = [n.split("/")[-2] for n in tr.names]
    Q = np.column_stack([tr[n] for n in tr.names])
    spline = CubicSpline(tr.time, Q, axis=0)
    V, A = spline(tr.time, 1), spline(tr.time, 2)
    cols = [names.index(c) for c in model.coordinates]
    return model, Motion(tr.time, Q[:, cols], V[:, cols], A[:, cols]), names, Q, V


@pytest.fixture(scope="module")
def moco_opensim(moco):
    osim = _opensim()
    model = osim.Model(str(_moco_dir() / "2D_gait.osim"))
    state = model.initSystem()
    return osim, model, state


def test_moco_contacts_are_imported_as_smooth_spheres(moco):
    model, *_ = moco
    assert [c.target for c in model.contacts] == list(FORCES.values())
    heel = model.component("smooth_sphere_half_space:heel_r")
    assert isinstance(heel, SmoothSphereHalfSpaceForce)
    assert heel.values == {"radius": 0.035, "stiffness": 3067776.0, "dissipation": 2.0, "static_friction": 0.8,
                           "dynamic_friction": 0.8, "viscous_friction": 0.5, "transition_velocity": 0.2,
                           "constant_contact_force": 1e-5, "hertz_smoothing": 300.0, "hunt_crossley_smoothing": 50.0}
    np.testing.assert_allclose(heel.plane_normal, (0.0, 1.0, 0.0), atol=1e-15)      # -x of the turned floor
    # the sphere's frame sits on calcn_r at the ContactSphere's location
    pm = model.pin
    f = pm.frames[model.frame_id("heel_r")]
    assert pm.frames[f.parentFrame].name == "calcn_r"
    np.testing.assert_allclose(f.placement.translation - pm.frames[f.parentFrame].placement.translation,
                               [0.031307527581931796, 0.010435842527310599, 0.0], atol=1e-15)
    report = model.meta["import_report"]
    (entry,) = [e for e in report.find('name="contactHeel_r"') if e.status == "exact"]
    assert "smooth_sphere_half_space:heel_r" in entry.became and "calcn_r" in entry.became
    assert any("derivative_smoothing" in e.became for e in report.find('name="contactHeel_r"'))
    assert not [e for e in report.not_imported if "Contact" in e.element or "contact" in e.element]


def test_moco_contact_forces_match_opensim(moco, moco_opensim):
    """Force and torque on each sphere's body and on the ground, normal and friction, at all 50 frames."""
    model, mo, names, Q, V = moco
    osim, om, state = moco_opensim
    forces = {name: osim.Force.safeDownCast(om.getComponent("/" + name)) for name in FORCES}
    outputs = _outputs(model, mo)
    worst, worst_split, loaded = 0.0, 0.0, 0
    for k in range(mo.n_frames):
        _set_state(om, state, names, Q[k], V[k])
        om.realizeDynamics(state)
        for name, frame in FORCES.items():
            err, split, scale = _check_records(model.component(f"smooth_sphere_half_space:{frame}"), outputs, k,
                                               _records(forces[name], state))
            worst = max(worst, err / max(scale, 1.0))
            worst_split = max(worst_split, split / max(scale, 1.0))
            loaded += scale > 100.0
    print(f"\n2D_gait SmoothSphereHalfSpaceForce vs OpenSim, 50 frames x 4 spheres: max error {worst:.2e} "
          f"(force, torque; relative to max(|F|, 1 N)), normal/friction split {worst_split:.2e}")
    assert loaded > 40                    # the motion loads the spheres (a half gait cycle)
    assert worst < 1e-9 and worst_split < 1e-9


def test_moco_contact_generalized_forces_match_opensim(moco, moco_opensim):
    """J^T of the contact wrenches: OpenSim's inverse dynamics with the contacts on minus off (muscles
    and actuators off) is minus pinmsk's contact generalized force."""
    model, mo, names, Q, V = moco
    osim, om, state = moco_opensim
    om = om.clone()
    state = om.initSystem()
    for i in range(om.getForceSet().getSize()):
        om.getForceSet().get(i).setAppliesForce(state, False)
    contacts = [osim.Force.safeDownCast(om.getComponent("/" + name)) for name in FORCES]
    solver = osim.InverseDynamicsSolver(om)
    order = [model.coordinates.index(c) for c in _u_order(om, state)]
    udot = osim.Vector(state.getNU(), 0.0)
    mine = sum(component_forces(model, mo).values())
    worst = 0.0
    for k in range(0, mo.n_frames, 3):
        _set_state(om, state, names, Q[k], V[k])
        tau = []
        for on in (True, False):
            for f in contacts:
                f.setAppliesForce(state, on)
            om.realizeVelocity(state)
            t = solver.solve(state, udot)
            tau.append(np.array([t.get(i) for i in range(t.size())]))
        theirs = tau[1] - tau[0]
        worst = max(worst, np.abs(theirs - mine[k, order]).max() / max(np.abs(theirs).max(), 1.0))
    print(f"\n2D_gait contact generalized forces vs OpenSim: max relative error {worst:.2e}")
    assert worst < 1e-9


def test_moco_contacts_hold_the_walker_up_and_give_its_grf(moco):
    """With the imported contacts the reference walk (a predictive solution with these contacts)
    nearly balances at the pelvis: inverse dynamics' pelvis_ty residual drops from about body weight
    to a few percent of it.  The contacts' GRF channels are those of the spheres summed per side."""
    model, mo, *_ = moco
    weight = model.mass * 9.80665
    ty = model.coordinate_index("pelvis_ty")
    rms = {on: float(np.sqrt(np.mean(inverse_dynamics_array(model, mo, components=on)[:, ty] ** 2)))
           for on in (True, False)}
    assert rms[False] > 0.9 * weight and rms[True] < 0.1 * weight, rms
    grf = ground_reaction_trial(model, mo)
    sides = contact_ground_reactions(model, mo)
    assert set(sides) == {"r", "l"}
    for side, front in (("r", "front_r"), ("l", "front_l")):
        total = sum(model.component(f"smooth_sphere_half_space:{f}").evaluate(model, mo).force
                    for f in (f"heel_{side}", front))
        np.testing.assert_allclose(np.column_stack([grf[f"{side}_ground_force_v{a}"] for a in "xyz"]), total,
                                   rtol=1e-12, atol=1e-9)
    assert grf.units["r_ground_force_vy"] == "N" and grf.units["l_ground_torque_y"] == "N*m"
    ref_path = _moco_dir() / "referenceGRF.sto"
    if ref_path.is_file():                # informative only: the reference GRF come with the solution's speeds
        ref = pinmsk.read_trial(ref_path)
        diff = {s: np.sqrt(np.mean((grf[f"{s}_ground_force_vy"] - ref[f"ground_force_{s}_vy"]) ** 2)) for s in "rl"}
        print(f"\n2D_gait contact GRF (spline speeds of referenceCoordinates) vs referenceGRF.sto: vertical RMS "
              f"difference r {diff['r']:.3g} N, l {diff['l']:.3g} N (body weight {weight:.4g} N)")
    print(f"pelvis_ty residual RMS: {rms[True]:.3g} N with the contacts, {rms[False]:.3g} N without")


def test_a_measured_grf_on_a_foot_with_contacts_is_refused(moco):
    """Contacts and a measured GRF on the same foot would count the ground twice: refused by name;
    a load on a body without contacts (a push on the torso) is not."""
    from pinmsk.errors import TrialError
    from pinmsk.skeleton import ExternalForce

    model, mo, *_ = moco
    n = mo.n_frames
    push = np.tile([0.0, 500.0, 0.0], (n, 1))
    with pytest.raises(TrialError, match=r"contacts on the bodies the trial's ground reaction forces load "
                                         r"\(smooth_sphere_half_space:heel_r on calcn_r, smooth_sphere_half_space:front_r "
                                         r"on calcn_r\): the ground would act twice"):
        inverse_dynamics_array(model, mo, external=[ExternalForce("calcn_r", push, np.zeros((n, 3)))])
    tau = inverse_dynamics_array(model, mo, external=[ExternalForce("torso", push, np.zeros((n, 3)))])
    assert np.all(np.isfinite(tau))
    assert np.all(np.isfinite(inverse_dynamics_array(model, mo, external=[ExternalForce("calcn_r", push, push * 0)],
                                                     components=False)))


def test_load_model_imports_the_contacts_by_default(tmp_path):
    path = tmp_path / "ball.osim"
    path.write_text(ball_osim())
    model, report = import_osim(path)                    # the default hooks: muscles and contacts
    assert {c.label for c in model.contacts} == {"hunt_crossley_force:ball_sphere", "smooth_sphere_half_space:ball2"}
    assert not report.not_imported


# -- a ball on a tilted half space: both laws -------------------------------------------------------

BALL_ROT = "0.3 -0.2 0.4"
FLOOR = dict(location="0.02 -0.01 0.03", orientation="0.05 -0.08 -1.4707963267948966")


def ball_osim(*, extra_forces: str = "", extra_geometry: str = "", hc_params: str | None = None) -> str:
    """A ball on a 6-dof CustomJoint; sphere 'ball' (on a turned offset frame, in a HuntCrossleyForce)
    and 'ball2' (in a SmoothSphereHalfSpaceForce) against the half space 'floor' (turned, off the origin)."""
    lin = '<LinearFunction name="function"><coefficients>1 0</coefficients></LinearFunction>'
    axes = "".join(f'<TransformAxis name="{n}"><coordinates>{c}</coordinates><axis>{a}</axis>{lin}</TransformAxis>'
                   for n, c, a in (("rotation1", "rz", "0 0 1"), ("rotation2", "rx", "1 0 0"), ("rotation3", "ry", "0 1 0"),
                                   ("translation1", "tx", "1 0 0"), ("translation2", "ty", "0 1 0"),
                                   ("translation3", "tz", "0 0 1")))
    coords = "".join(f"<Coordinate name=\"{c}\"><default_value>{d}</default_value><range>-5 5</range></Coordinate>"
                     for c, d in (("rz", 0), ("rx", 0), ("ry", 0), ("tx", 0), ("ty", 0.3), ("tz", 0)))
    hc_params = hc_params or """
          <HuntCrossleyForce::ContactParameters name="ball_params"><geometry>ball</geometry>
            <stiffness>2000000</stiffness><dissipation>1.5</dissipation><static_friction>0.9</static_friction>
            <dynamic_friction>0.5</dynamic_friction><viscous_friction>0.3</viscous_friction>
          </HuntCrossleyForce::ContactParameters>
          <HuntCrossleyForce::ContactParameters name="floor_params"><geometry>floor</geometry>
            <stiffness>2000000</stiffness><dissipation>0.5</dissipation><static_friction>0.7</static_friction>
            <dynamic_friction>0.4</dynamic_friction><viscous_friction>0.1</viscous_friction>
          </HuntCrossleyForce::ContactParameters>"""
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <Model name="ball">
    <Ground name="ground"/>
    <gravity>0 -9.80665 0</gravity>
    <BodySet name="bodyset"><objects>
      <Body name="ball"><mass>2</mass><mass_center>0.01 0 0</mass_center><inertia>0.01 0.02 0.015 0 0 0</inertia>
        <components>
          <PhysicalOffsetFrame name="shell"><socket_parent>/bodyset/ball</socket_parent>
            <translation>0.01 -0.02 0.005</translation><orientation>{BALL_ROT}</orientation></PhysicalOffsetFrame>
        </components>
      </Body>
    </objects></BodySet>
    <JointSet name="jointset"><objects>
      <CustomJoint name="free"><socket_parent_frame>/ground</socket_parent_frame>
        <socket_child_frame>/bodyset/ball</socket_child_frame>
        <coordinates>{coords}</coordinates>
        <SpatialTransform>{axes}</SpatialTransform>
      </CustomJoint>
    </objects></JointSet>
    <ForceSet name="forceset"><objects>
      <HuntCrossleyForce name="hc">
        <HuntCrossleyForce::ContactParametersSet name="contact_parameters"><objects>{hc_params}
        </objects></HuntCrossleyForce::ContactParametersSet>
        <transition_velocity>0.15</transition_velocity>
      </HuntCrossleyForce>
      <SmoothSphereHalfSpaceForce name="smooth">
        <socket_sphere>/contactgeometryset/ball2</socket_sphere>
        <socket_half_space>/contactgeometryset/floor</socket_half_space>
        <stiffness>1000000</stiffness><dissipation>1</dissipation><static_friction>0.8</static_friction>
        <dynamic_friction>0.6</dynamic_friction><viscous_friction>0.4</viscous_friction>
        <transition_velocity>0.1</transition_velocity><constant_contact_force>2e-05</constant_contact_force>
        <hertz_smoothing>250</hertz_smoothing><hunt_crossley_smoothing>40</hunt_crossley_smoothing>
      </SmoothSphereHalfSpaceForce>{extra_forces}
    </objects></ForceSet>
    <ContactGeometrySet name="contactgeometryset"><objects>
      <ContactSphere name="ball"><socket_frame>/bodyset/ball/shell</socket_frame><radius>0.05</radius>
        <location>0.02 -0.03 0.01</location><orientation>0.1 0.2 0.3</orientation></ContactSphere>
      <ContactSphere name="ball2"><socket_frame>/bodyset/ball</socket_frame><radius>0.03</radius>
        <location>-0.04 -0.05 0.02</location></ContactSphere>
      <ContactHalfSpace name="floor"><socket_frame>/ground</socket_frame><location>{FLOOR['location']}</location>
        <orientation>{FLOOR['orientation']}</orientation></ContactHalfSpace>{extra_geometry}
    </objects></ContactGeometrySet>
  </Model>
</OpenSimDocument>
"""


def _ball_states(model, rng, n=60):
    """Poses with each sphere -3..12 mm into the floor (the ball's height solved for it), speeds up to
    ~1 m/s and 3 rad/s (rebounds faster than 2 / (3 c) among them)."""
    q = np.zeros((n, model.nv))
    for c in ("rz", "rx", "ry"):
        q[:, model.coordinate_index(c)] = rng.uniform(-0.6, 0.6, n)
    for c in ("tx", "tz"):
        q[:, model.coordinate_index(c)] = rng.uniform(-0.5, 0.5, n)
    v = np.column_stack([rng.normal(0.0, 0.5 if c.startswith("t") else 1.5, n) for c in model.coordinates])
    j = model.coordinate_index("ty")
    comps = model.contacts
    half = n // 2
    out = []
    for comp, rows in ((comps[0], slice(0, half)), (comps[1], slice(half, n))):
        qq = q[rows].copy()
        mo = Motion(np.zeros(len(qq)), qq, v[rows], np.zeros_like(qq))
        depth = comp.evaluate(model, mo).penetration
        e = np.zeros(model.nv)
        e[j] = 1e-3
        slope = (comp.evaluate(model, Motion(mo.t, qq + e, v[rows], qq * 0)).penetration - depth) / 1e-3
        qq[:, j] += (rng.uniform(-0.003, 0.012, len(qq)) - depth) / slope
        out.append(qq)
    return np.vstack(out), v


def test_ball_contacts_match_opensim(tmp_path):
    """HuntCrossleyForce (different dissipation and friction for ball and floor, combined as Simbody
    does) and SmoothSphereHalfSpaceForce, sphere on a turned offset frame, turned floor off the origin."""
    osim = _opensim()
    path = tmp_path / "ball.osim"
    path.write_text(ball_osim())
    model, report = import_osim(path, hooks=(contact_hook,))
    hc = model.component("hunt_crossley_force:ball_sphere")
    assert hc.values["dissipation"] == 1.0 and hc.values["static_friction"] == pytest.approx(2 * 0.9 * 0.7 / 1.6)
    om = osim.Model(str(path))
    state = om.initSystem()
    forces = {"hc": (osim.Force.safeDownCast(om.getComponent("/forceset/hc")), hc),
              "smooth": (osim.Force.safeDownCast(om.getComponent("/forceset/smooth")),
                         model.component("smooth_sphere_half_space:ball2"))}
    rng = np.random.default_rng(3)
    q, v = _ball_states(model, rng)
    names = list(model.coordinates)
    mo = Motion(np.arange(len(q)) * 0.01, q, v, np.zeros_like(q))
    outputs = _outputs(model, mo)
    worst = {"hc": 0.0, "smooth": 0.0}
    for k in range(len(q)):
        _set_state(om, state, names, q[k], v[k])
        om.realizeDynamics(state)
        for key, (f, comp) in forces.items():
            # both record the ball's body (force, torque about its origin), then the ground's
            err, split, scale = _check_records(comp, outputs, k, _records(f, state))
            worst[key] = max(worst[key], err / max(scale, 1.0), split / max(scale, 1.0))
    out = outputs[hc.label][0]
    seen = {"touching": int(np.sum(out.normal > 0)), "rebound": int(np.sum((out.normal == 0) & (out.penetration > 0))),
            "clear": int(np.sum(out.penetration <= 0))}
    print(f"\nball vs OpenSim: HuntCrossleyForce max error {worst['hc']:.2e}, SmoothSphereHalfSpaceForce "
          f"{worst['smooth']:.2e} (relative to max(|F|, 1 N)); HC frames {seen}")
    assert min(seen.values()) >= 2          # in contact, pulling off faster than 2/(3c) (no force), clear
    assert worst["hc"] < 1e-9 and worst["smooth"] < 1e-9


# -- the import report and bad input (no OpenSim needed) ---------------------------------------------

UNSUPPORTED_GEOMETRY = """
      <ContactMesh name="plate"><socket_frame>/ground</socket_frame><filename>plate.obj</filename></ContactMesh>
      <ContactHalfSpace name="wall"><socket_frame>/bodyset/ball</socket_frame></ContactHalfSpace>
      <ContactSphere name="post"><socket_frame>/ground</socket_frame><radius>0.02</radius></ContactSphere>
      <ContactEllipsoid name="egg"><socket_frame>/bodyset/ball</socket_frame><radii>0.03 0.02 0.01</radii></ContactEllipsoid>"""


def _smooth(name, sphere, half, extra=""):
    return (f'<SmoothSphereHalfSpaceForce name="{name}"><socket_sphere>/contactgeometryset/{sphere}</socket_sphere>'
            f"<socket_half_space>/contactgeometryset/{half}</socket_half_space>{extra}</SmoothSphereHalfSpaceForce>")


UNSUPPORTED_FORCES = (
    """
      <ElasticFoundationForce name="foundation">
        <ElasticFoundationForce::ContactParametersSet name="contact_parameters"><objects>
          <ElasticFoundationForce::ContactParameters><geometry>plate ball2</geometry><stiffness>1e6</stiffness>
          </ElasticFoundationForce::ContactParameters>
        </objects></ElasticFoundationForce::ContactParametersSet>
      </ElasticFoundationForce>
      <HuntCrossleyForce name="stiff">
        <HuntCrossleyForce::ContactParametersSet name="contact_parameters"><objects>
          <HuntCrossleyForce::ContactParameters><geometry>ball2</geometry><stiffness>1e6</stiffness>
          </HuntCrossleyForce::ContactParameters>
          <HuntCrossleyForce::ContactParameters><geometry>floor</geometry><stiffness>2e6</stiffness>
          </HuntCrossleyForce::ContactParameters>
        </objects></HuntCrossleyForce::ContactParametersSet>
      </HuntCrossleyForce>
      <HuntCrossleyForce name="mixed">
        <HuntCrossleyForce::ContactParametersSet name="contact_parameters"><objects>
          <HuntCrossleyForce::ContactParameters><geometry>ball2 floor plate egg</geometry><stiffness>1e6</stiffness>
          </HuntCrossleyForce::ContactParameters>
        </objects></HuntCrossleyForce::ContactParametersSet>
      </HuntCrossleyForce>"""
    + _smooth("on_wall", "ball2", "wall") + _smooth("on_post", "post", "floor") + _smooth("on_mesh", "plate", "floor")
    + _smooth("unknown", "ball2", "nowhere") + _smooth("off", "ball2", "floor", "<appliesForce>false</appliesForce>"))


def test_report_says_what_became_what_and_names_what_is_not_imported(tmp_path):
    path = tmp_path / "ball.osim"
    path.write_text(ball_osim(extra_forces=UNSUPPORTED_FORCES, extra_geometry=UNSUPPORTED_GEOMETRY))
    model, report = import_osim(path, hooks=(contact_hook,))
    assert {c.label for c in model.contacts} == {"hunt_crossley_force:ball_sphere", "smooth_sphere_half_space:ball2",
                                                 "hunt_crossley_force:ball2"}
    assert model.component("hunt_crossley_force:ball2").target == "ball2"       # one frame, two forces
    why = {e.element.split(": ", 1)[1]: e.became for e in report.not_imported}
    assert set(why) == {'<ElasticFoundationForce name="foundation">', '<HuntCrossleyForce name="stiff">',
                        '<SmoothSphereHalfSpaceForce name="on_wall">', '<SmoothSphereHalfSpaceForce name="on_post">',
                        '<SmoothSphereHalfSpaceForce name="on_mesh">', '<SmoothSphereHalfSpaceForce name="unknown">',
                        '<ContactMesh name="plate">', '<ContactEllipsoid name="egg">', '<HuntCrossleyForce name="mixed">'}
    assert "contacts with ContactEllipsoid 'egg'" in why['<HuntCrossleyForce name="mixed">']
    assert any("ignores a ContactMesh's contacts" in e.became for e in report.find('name="mixed"'))
    assert "elastic-foundation" in why['<ElasticFoundationForce name="foundation">']
    assert "differ in stiffness" in why['<HuntCrossleyForce name="stiff">']
    assert "fixed to body 'ball'" in why['<SmoothSphereHalfSpaceForce name="on_wall">']
    assert "sphere 'post' is fixed to the ground" in why['<SmoothSphereHalfSpaceForce name="on_post">']
    assert "is a ContactMesh, not a ContactSphere" in why['<SmoothSphereHalfSpaceForce name="on_mesh">']
    assert "'nowhere' is not in the ContactGeometrySet" in why['<SmoothSphereHalfSpaceForce name="unknown">']
    assert "ContactMesh: not imported" in why['<ContactMesh name="plate">']
    (off,) = report.find('name="off"')
    assert off.status == "note" and "appliesForce false" in off.became
    # what became what: the sphere, its body and where, the half space
    (hc,) = [e for e in report.find('name="hc"') if e.status == "exact"]
    assert ("hunt_crossley_force:ball_sphere: sphere 'ball' (R = 50 mm) on body 'ball'" in hc.became
            and "half space 'floor'" in hc.became)
    assert any("combined as Simbody does" in e.became for e in report.find('name="hc"'))


@pytest.mark.parametrize("bad, message", [
    ("<stiffness>soft</stiffness>", r"ball\.osim:\d+: <SmoothSphereHalfSpaceForce name=\"smooth\">: <stiffness> must be a "
                                     "finite number, got 'soft'"),
    ("<stiffness>-5</stiffness>", r"ball\.osim:\d+: <SmoothSphereHalfSpaceForce name=\"smooth\">: "
                                   r"smooth_sphere_half_space:ball2: parameter 'stiffness' = -5 .* outside its bounds"),
    ("<transition_velocity>0</transition_velocity>", r"<SmoothSphereHalfSpaceForce name=\"smooth\">: .*"
                                                     "'transition_velocity' = 0 m/s is outside its bounds"),
])
def test_bad_contact_properties_name_the_element_and_the_property(tmp_path, bad, message):
    text = ball_osim()
    start = text.index('<SmoothSphereHalfSpaceForce name="smooth">')
    tag = bad.split(">", 1)[0] + ">"
    a = text.index(tag, start)
    b = text.index(tag.replace("<", "</"), a) + len(tag) + 1
    path = tmp_path / "ball.osim"
    path.write_text(text[:a] + bad + text[b:])
    with pytest.raises(ModelError, match=message):
        import_osim(path, hooks=(contact_hook,))


def test_a_sphere_without_radius_is_named(tmp_path):
    path = tmp_path / "ball.osim"
    path.write_text(ball_osim().replace("<radius>0.03</radius>", ""))
    with pytest.raises(ModelError, match=r"ball\.osim:\d+: <ContactSphere name=\"ball2\">: a ContactSphere needs a <radius>"):
        import_osim(path, hooks=(contact_hook,))


def test_the_hook_run_twice_on_one_skeleton_reuses_its_frames(tmp_path):
    from pinmsk.io.osim import read_osim
    from pinmsk.opensim.skeleton import build_skeleton

    path = tmp_path / "ball.osim"
    path.write_text(ball_osim())
    doc = read_osim(path)
    skel = build_skeleton(doc)
    first = contact_hook(doc, skel)
    n = skel.pin_model.nframes
    second = contact_hook(doc, skel)
    assert skel.pin_model.nframes == n and first.components == second.components
