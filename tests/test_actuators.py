"""Ideal actuators (pinmsk.actuators), OpenSim force set files and the actuator import hook, and static
optimization with actuators against the analytical 1-dof optimum.

The generalized-force columns are checked by virtual power against finite differences of the body
placements (independent of the Jacobians that build them); against OpenSim's own generalized forces in
tests/test_osim_so.py.
"""
import math

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk.actuators import CoordinateActuator, PointActuator, TorqueActuator, actuator_columns
from pinmsk.components import Motion
from pinmsk.dynamics import inverse_dynamics_array
from pinmsk.errors import ModelError, SolverError
from pinmsk.io.osim import parse_force_set, read_force_set
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.solvers import StaticOptimization
from pinmsk.solvers.analytical import one_dof_forces

STRONG = "opensim-models/Gait10dof18musc/Working_with_Static_Optimization/gait10dof18musc_Strong_actuators.xml"


def _random_motion(model, n=5, seed=0):
    rng = np.random.default_rng(seed)
    lo = np.clip(model.pin.lowerPositionLimit, -1.0, 1.0)
    hi = np.clip(model.pin.upperPositionLimit, -1.0, 1.0)
    q = lo + (hi - lo) * rng.random((n, model.nv))
    v = rng.normal(size=(n, model.nv))
    return Motion(np.arange(n) * 0.01, q, v, np.zeros_like(q))


def _placements(model, frame, q):
    pm, pd = model.pin, model.pin.createData()
    fid = model.frame_id(frame)
    out = []
    for qk in q:
        pin.framesForwardKinematics(pm, pd, qk)
        out.append(pd.oMf[fid].copy())
    return out


def _fd_point_velocity(model, frame, station, q, v, h=1e-6):
    """d/dt of the world position of a body station, by central differences of the placements."""
    plus = _placements(model, frame, q + h * v)
    minus = _placements(model, frame, q - h * v)
    return np.array([(p.act(station) - m.act(station)) / (2 * h) for p, m in zip(plus, minus)])


def _fd_angular_velocity(model, frame, q, v, h=1e-6):
    plus = _placements(model, frame, q + h * v)
    minus = _placements(model, frame, q - h * v)
    return np.array([pin.log3(p.rotation @ m.rotation.T) / (2 * h) for p, m in zip(plus, minus)])


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


# -- the laws -------------------------------------------------------------------------

def test_coordinate_actuator_is_a_unit_column_times_the_control(gait2d):
    act = CoordinateActuator("knee_reserve", "knee_r", optimal_force=40.0, min_control=-2.0, max_control=3.0)
    mo = _random_motion(gait2d)
    j = gait2d.coordinate_index("knee_r")
    B = act.columns(gait2d, mo)
    assert B.shape == (mo.n_frames, gait2d.nv) and np.all(B[:, j] == 40.0) and np.count_nonzero(B) == mo.n_frames
    u = np.linspace(-1.0, 2.0, mo.n_frames)
    driven = Motion(mo.t, mo.q, mo.v, mo.a, {"knee_reserve_control": u})
    assert np.allclose(act.generalized_force(gait2d, driven)[:, j], 40.0 * u)
    assert act.label == "coordinate_actuator:knee_reserve" and act.actuation_unit(gait2d) == "N*m"
    assert (act.min_control, act.max_control) == (-2.0, 3.0)


def test_point_actuator_power_equals_force_times_station_velocity(gait2d):
    mo = _random_motion(gait2d, seed=1)
    station = np.array([0.03, -0.12, 0.01])
    d = np.array([0.6, 0.8, 0.0])
    local = PointActuator("p", "shank_r", point=station, direction=d, optimal_force=2.0)
    B = local.columns(gait2d, mo)
    vp = _fd_point_velocity(gait2d, "shank_r", station, mo.q, mo.v)
    R = np.array([T.rotation for T in _placements(gait2d, "shank_r", mo.q)])
    F = 2.0 * np.einsum("nij,j->ni", R, d)               # the body-frame direction in the world
    assert np.allclose(np.sum(B * mo.v, axis=1), np.sum(F * vp, axis=1), atol=1e-7)
    # the same force given in the ground frame, at the same station given as a ground point, frame by frame
    pts = np.array([T.act(station) for T in _placements(gait2d, "shank_r", mo.q)])
    for k in range(mo.n_frames):
        glob = PointActuator("g", "shank_r", point=pts[k], direction=F[k], point_is_global=True,
                             force_is_global=True, optimal_force=2.0)
        assert np.allclose(glob.columns(gait2d, mo)[k], B[k], atol=1e-12)


def test_torque_actuator_power_equals_torque_times_relative_angular_velocity(gait2d):
    mo = _random_motion(gait2d, seed=2)
    n = np.array([0.0, 0.0, 1.0])
    act = TorqueActuator("t", "shank_r", body_b="thigh_r", axis=(0.0, 0.0, 2.0), optimal_force=3.0)
    B = act.columns(gait2d, mo)
    w = _fd_angular_velocity(gait2d, "shank_r", mo.q, mo.v) - _fd_angular_velocity(gait2d, "thigh_r", mo.q, mo.v)
    assert np.allclose(np.sum(B * mo.v, axis=1), 3.0 * w @ n, atol=1e-7)
    # between two bodies of a planar chain it is the knee's generalized force, nothing else
    # (gait2d's knee turns about -z: a +z torque is a negative knee moment)
    assert np.allclose(B[:, gait2d.coordinate_index("knee_r")], -3.0) and np.count_nonzero(np.abs(B) > 1e-12) == 5
    # on the pelvis against the ground (body_b None): the whole chain's rotation
    hat = TorqueActuator("mz", "hat", axis=(0.0, 0.0, 1.0))
    assert np.allclose(np.abs(hat.columns(gait2d, mo)[:, gait2d.coordinate_index("torso_angle")]), 1.0)


def test_actuator_columns_stack_and_inverse_dynamics_ignores_undriven_actuators(gait2d):
    acts = [CoordinateActuator("a", "hip_r", optimal_force=5.0),
            PointActuator("b", "hat", direction=(1, 0, 0), force_is_global=True)]
    mo = _random_motion(gait2d, seed=3)
    C = actuator_columns(gait2d, mo, acts, data=gait2d.create_data())
    assert C.shape == (mo.n_frames, 2, gait2d.nv)
    assert np.allclose(C[:, 1, gait2d.coordinate_index("torso_x")], 1.0)
    model = gait2d.with_effect(*acts)
    assert [c.label for c in model.components if c.kind == "actuator"] == ["coordinate_actuator:a", "point_actuator:b"]
    # no control channel: an ideal actuator applies nothing (what the moments are for)
    assert np.allclose(inverse_dynamics_array(model, mo), inverse_dynamics_array(gait2d, mo))
    driven = Motion(mo.t, mo.q, mo.v, mo.a, {"a_control": np.ones(mo.n_frames)})
    diff = inverse_dynamics_array(gait2d, driven) - inverse_dynamics_array(model, driven)
    assert np.allclose(diff[:, gait2d.coordinate_index("hip_r")], 5.0)


def test_actuators_are_components_with_one_parameter(gait2d):
    act = PointActuator("fx", "hat", point=(0.1, 0, 0), direction=(2, 0, 0), optimal_force=100.0)
    assert act.direction == (1.0, 0.0, 0.0)
    model = gait2d + act
    row = model.parameters["point_actuator:fx.optimal_force"]
    assert row.value == 100.0 and not row.vary            # a fit leaves the actuator's strength alone
    # the force is linear in the control and in F_opt: the parameter Jacobian is exact; the cache and a
    # Data change nothing; vectorised = frame by frame
    mo = _random_motion(gait2d, seed=4)
    driven = Motion(mo.t, mo.q, mo.v, mo.a, {"fx_control": np.linspace(-1, 1, mo.n_frames)})
    Q = act.generalized_force(gait2d, driven)
    J = act.param_jacobian(gait2d, driven)
    np.testing.assert_allclose(J[:, :, 0] * 100.0, Q, rtol=1e-13, atol=1e-12)
    fd = (act.generalized_force(gait2d, driven, {"optimal_force": 101.0})
          - act.generalized_force(gait2d, driven, {"optimal_force": 99.0})) / 2.0
    np.testing.assert_allclose(J[:, :, 0], fd, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(act.generalized_force(gait2d, driven, cache=act.prepare(gait2d, driven,
                                                                                       data=gait2d.create_data())), Q)
    one = np.vstack([act.generalized_force(gait2d, driven.subset(slice(k, k + 1))) for k in range(mo.n_frames)])
    np.testing.assert_allclose(one, Q, rtol=1e-12, atol=1e-12)
    other = act.with_params(optimal_force=50.0)
    assert other != act and other.direction == act.direction and other.name == "fx"
    import pickle
    assert pickle.loads(pickle.dumps(act)) == act
    with pytest.raises(AttributeError):
        act.name = "x"


@pytest.mark.parametrize("make,message", [
    (lambda: CoordinateActuator("r", "knee_r", min_control=1.0, max_control=-1.0), r"min_control 1 > max_control -1"),
    (lambda: PointActuator("p", "hat", direction=(0, 0, 0)), "direction is the zero vector"),
    (lambda: TorqueActuator("t", "hat", axis=(1, 2)), "axis must be 3 finite numbers"),
    (lambda: CoordinateActuator("r", "knee_r", optimal_force=-1.0), "outside its bounds"),
    (lambda: CoordinateActuator("", "knee_r"), "needs a name"),
])
def test_bad_actuators_are_refused_by_name(make, message):
    with pytest.raises(ModelError, match=message):
        make()


def test_an_actuator_on_a_missing_coordinate_or_body_is_refused(gait2d):
    with pytest.raises(ModelError, match=r"no coordinate 'knee_x'.*did you mean 'knee_r'"):
        gait2d + CoordinateActuator("r", "knee_x")
    with pytest.raises(ModelError, match=r"no frame 'shank'"):
        gait2d + TorqueActuator("t", "shank_r", body_b="shank")


# -- force set files ------------------------------------------------------------------

def _xml(body: str) -> str:
    return ('<?xml version="1.0"?>\n<OpenSimDocument Version="30000">\n<ForceSet name="r">\n<objects>\n'
            f'{body}</objects>\n</ForceSet>\n</OpenSimDocument>\n')


def test_a_force_set_file_is_read_with_its_defaults():
    fs = parse_force_set(_xml('<CoordinateActuator name="a">\n<coordinate> knee_r </coordinate>\n'
                              '<min_control> -infinity </min_control><optimal_force> 3 </optimal_force>\n'
                              '</CoordinateActuator>\n'
                              '<PointActuator name="fx"><body>hat</body><point>0 0.1 0</point>'
                              '<direction>1 0 0</direction><force_is_global>true</force_is_global></PointActuator>\n'
                              '<TorqueActuator name="mz"><bodyA>hat</bodyA><bodyB>ground</bodyB></TorqueActuator>\n'),
                         source="r.xml")
    a, fx, mz = fs.actuators
    assert (a.coordinate, a.properties["min_control"], a.properties["optimal_force"], a.line) == ("knee_r", -math.inf, 3.0, 5)
    assert fx.bodies == ("/bodyset/hat",) and fx.properties["point"] == (0.0, 0.1, 0.0)
    assert mz.bodies == ("/bodyset/hat", "/ground")


def test_the_strong_actuators_file_makes_ten_actuators(shared_data):
    from pinmsk.opensim.actuators import read_actuators
    path = shared_data / STRONG
    if not path.is_file():
        pytest.skip(f"{STRONG} is absent")
    fs = read_force_set(path)
    assert [a.name for a in fs.actuators][:3] == ["FX", "FY", "MZ"] and len(fs.actuators) == 10
    model = pinmsk.load_model("gait2d")
    with pytest.raises(ModelError, match=r"gait10dof18musc_Strong_actuators.xml:\d+: <PointActuator name=\"FX\">: "
                                         r"model 'gait2d' has no body 'pelvis'"):
        read_actuators(path, model)


@pytest.mark.parametrize("body,message", [
    ('<CoordinateActuator name="a"><coordinate>knee_x</coordinate></CoordinateActuator>\n',
     r"r.xml:5: <CoordinateActuator name=\"a\">: model 'gait2d' has no coordinate 'knee_x'; did you mean 'knee_r'"),
    ('<PointActuator name="p"><body>shank</body></PointActuator>\n',
     r"r.xml:5: <PointActuator name=\"p\">: model 'gait2d' has no body 'shank'; did you mean"),
    ('<CoordinateActuator name="a"><coordinate>knee_r</coordinate><min_control>2</min_control>'
     '<max_control>1</max_control></CoordinateActuator>\n',
     r"r.xml:5: <CoordinateActuator name=\"a\">: min_control 2 > max_control 1"),
    ('<CoordinateActuator name="a"><coordinate>knee_r</coordinate><optimal_force>big</optimal_force>'
     '</CoordinateActuator>\n', r"r.xml:5: .*<optimal_force> must be a number, got 'big'"),
    ('<PointActuator name="p"><body>hat</body><direction>1 0</direction></PointActuator>\n',
     r"r.xml:5: .*<direction> must hold 3 finite numbers"),
    ('<CoordinateActuator name="a"><coordinate>knee_r</coordinate><optimal_force>-5</optimal_force>'
     '</CoordinateActuator>\n', r"r.xml:5: <CoordinateActuator name=\"a\">: optimal_force must be a finite value >= 0, got -5"),
    ('<TorqueActuator name="t"><axis>0 0 1</axis></TorqueActuator>\n',
     r"r.xml:5: <TorqueActuator name=\"t\">: names no body \(<bodyA>\)"),
    ('<BodyActuator name="b"><body>hat</body></BodyActuator>\n',
     r"r.xml:5: <BodyActuator name=\"b\">: pinmsk makes CoordinateActuator, .* a BodyActuator is not one of them"),
])
def test_bad_force_set_entries_are_named_with_file_and_line(tmp_path, gait2d, body, message):
    from pinmsk.opensim.actuators import read_actuators
    p = tmp_path / "r.xml"
    p.write_text(_xml(body))
    with pytest.raises(ModelError, match=message):
        read_actuators(p, gait2d)


@pytest.mark.parametrize("text,message", [
    ('<?xml version="1.0"?>\n<OpenSimDocument Version="30000">\n<ExternalLoads name="x"/>\n</OpenSimDocument>\n',
     r"f.xml:2: not an OpenSim force set file: <OpenSimDocument> holds <ExternalLoads>, not a <ForceSet>"),
    ('<Model name="m"/>\n', r"f.xml:1: not an OpenSim force set file: the root element is <Model>"),
    ('<OpenSimDocument><ForceSet>\n', r"f.xml:2: not a valid force set file: the XML is malformed"),
    (_xml('<Thelen2003Muscle name="m"><max_isometric_force>1</max_isometric_force></Thelen2003Muscle>\n'),
     r"f.xml:5: <Thelen2003Muscle name=\"m\">: pinmsk reads actuators .* from a force set file; this element is not one"),
])
def test_a_file_that_is_not_a_force_set_of_actuators_is_refused(tmp_path, text, message):
    p = tmp_path / "f.xml"
    p.write_text(text)
    with pytest.raises(ModelError, match=message):
        read_force_set(p)


def test_a_disabled_actuator_is_left_out_with_a_note(tmp_path, gait2d):
    from pinmsk.opensim.actuators import read_actuators
    p = tmp_path / "r.xml"
    p.write_text(_xml('<CoordinateActuator name="off"><appliesForce>false</appliesForce><coordinate>knee_r'
                      '</coordinate></CoordinateActuator>\n<CoordinateActuator name="on"><isDisabled>false'
                      '</isDisabled><coordinate>knee_r</coordinate></CoordinateActuator>\n'))
    comps, entries = read_actuators(p, gait2d)
    assert [c.name for c in comps] == ["on"]
    assert entries[0].status == "note" and "disabled" in entries[0].became and 'name="off"' in entries[0].element


def test_a_missing_force_set_file_is_named(tmp_path):
    with pytest.raises(ModelError, match="force set file not found: .*nothing.xml"):
        read_force_set(tmp_path / "nothing.xml")


# -- the import hook --------------------------------------------------------------------

def _osim(name):
    d = shared_data_dir()
    p = None if d is None else d / "opensim-models" / name
    if p is None or not p.is_file():
        pytest.skip(f"../shared/data/opensim-models/{name} is absent")
    return p


def test_the_import_makes_the_models_actuators_components():
    from pinmsk.model import import_osim
    from pinmsk.opensim.actuators import actuator_hook
    model, report = import_osim(_osim("Moco2DWalking/2D_gait.osim"), hooks=(actuator_hook,))
    (act,) = [c for c in model.components if c.kind == "actuator"]
    assert act.label == "coordinate_actuator:lumbarAct" and act.target == "lumbar"
    assert (act.min_control, act.max_control, act.values["optimal_force"]) == (-150.0, 150.0, 1.0)
    (entry,) = report.find('name="lumbarAct"')
    assert entry.status == "exact" and "coordinate_actuator:lumbarAct on coordinate lumbar" in entry.became
    assert not [e for e in report.not_imported if "Actuator" in e.element]


def test_rajagopals_thirteen_coordinate_actuators_are_imported():
    from pinmsk.model import import_osim
    from pinmsk.opensim.actuators import actuator_hook
    model, report = import_osim(_osim("RajagopalWalk/subject_walk_scaled.osim"), hooks=(actuator_hook,))
    acts = [c for c in model.components if c.kind == "actuator"]
    assert len(acts) == 13 and all(isinstance(a, CoordinateActuator) for a in acts)
    assert {(a.min_control, a.max_control) for a in acts} == {(-1.0, 1.0)}
    assert not [e for e in report.not_imported if "Actuator" in e.element]


def test_the_default_import_hooks_include_the_actuators():
    from pinmsk.opensim.actuators import actuator_hook
    from pinmsk.opensim.muscle_import import DEFAULT_HOOKS
    assert actuator_hook in DEFAULT_HOOKS


# -- static optimization with actuators ---------------------------------------------------

@pytest.mark.parametrize("P", [2, 3])
@pytest.mark.parametrize("bounds", [(-math.inf, math.inf), (-0.002, 0.02)])
def test_so_with_a_reserve_matches_the_analytical_optimum(forearm, motion, P, bounds):
    """One dof: the reserve is a two-sided 'muscle' of moment arm 1 N m per N m, normaliser F_opt."""
    f = 30.0
    res = CoordinateActuator("elbow_reserve", "elbow_flexion", optimal_force=f, min_control=bounds[0],
                             max_control=bounds[1])
    so = StaticOptimization(exponent=P, weights="fmax", actuators=[res]).fit(forearm, motion)
    R = so.problem_.R[:, :, 0]
    T = so.problem_.tau[:, 0]
    n = forearm.n_muscles
    R_aug = np.column_stack([R, np.ones(len(T)), -np.ones(len(T))])
    upper = np.concatenate([forearm.muscles.f_max, [bounds[1] * f, -bounds[0] * f]])
    Fa = one_dof_forces(R_aug, T, exponent=P, n=np.concatenate([forearm.muscles.f_max, [f, f]]), upper=upper)
    u = (Fa[:, n] - Fa[:, n + 1]) / f
    assert np.max(np.abs(so.forces_ - Fa[:, :n])) < 1e-6 * forearm.muscles.f_max.max()
    assert np.max(np.abs(so.controls_[:, 0] - u)) < 1e-8
    out = so.result_
    assert np.allclose(out["elbow_reserve_control"], u, atol=1e-8)
    assert np.allclose(out["elbow_reserve_force"], f * u, atol=1e-6) and out.units["elbow_reserve_force"] == "N*m"
    if np.isfinite(bounds[1]):
        assert u.max() == pytest.approx(bounds[1]) and u.min() == pytest.approx(bounds[0])   # both bounds used
    else:
        assert u.min() < 0 < u.max()
    assert "actuator elbow_reserve" in so.report() and "sum_k |u_k|^" in so.report()
    assert so.violation_.max() < 1e-6


def test_so_with_actuators_in_chunks_is_the_same_problem(forearm, motion):
    res = CoordinateActuator("elbow_reserve", "elbow_flexion", optimal_force=30.0, min_control=-0.002)
    whole = StaticOptimization(weights="fmax", actuators=[res]).fit(forearm, motion)
    parts = StaticOptimization(weights="fmax", actuators=[res], chunk_size=16).fit(forearm, motion)
    np.testing.assert_allclose(parts.controls_, whole.controls_, atol=1e-9)
    np.testing.assert_allclose(parts.forces_, whole.forces_, atol=1e-6)
    assert parts.violation_.max() < 1e-6


def test_so_takes_the_models_own_actuators(forearm, motion):
    res = CoordinateActuator("elbow_reserve", "elbow_flexion", optimal_force=30.0)
    given = StaticOptimization(weights="fmax", actuators=[res]).fit(forearm, motion)
    own = StaticOptimization(weights="fmax").fit(forearm + res, motion)
    assert np.allclose(own.controls_, given.controls_) and own.result_.meta["actuator_names"] == "elbow_reserve"
    with pytest.raises(SolverError, match=r"actuator\(s\) \['elbow_reserve'\] appear twice \(the model has them"):
        StaticOptimization(actuators=[res]).fit(forearm + res, motion)
    with pytest.raises(SolverError, match="actuators= takes a force set file or pinmsk.actuators components"):
        StaticOptimization(actuators=["elbow"]).fit(forearm, motion)


@pytest.mark.filterwarnings("ignore::pinmsk.errors.ResidualWarning")
def test_residual_actuators_let_so_balance_a_floating_base(gait2d):
    from pinmsk.diagnose.synth import walking_motion
    from pinmsk.errors import InfeasibleError
    mo = walking_motion(gait2d, n_frames=40)
    residuals = [CoordinateActuator(f"mtp_{s}_reserve", f"mtp_{s}") for s in "lr"] + [
                 PointActuator("FX", "hat", direction=(1, 0, 0), force_is_global=True, optimal_force=1000.0),
                 PointActuator("FY", "hat", direction=(0, 1, 0), force_is_global=True, optimal_force=1000.0),
                 TorqueActuator("MZ", "hat", axis=(0, 0, 1), optimal_force=1000.0)]
    with pytest.raises(InfeasibleError, match="no muscle spans .*torso_x"):
        StaticOptimization().fit(gait2d, mo)
    so = StaticOptimization(mode="activation", actuators=residuals).fit(gait2d, mo)
    assert {"torso_x", "torso_y", "torso_angle"} <= set(so.dofs_)
    # the residuals carry the floating base's whole inverse-dynamics force (muscles are internal)
    tau = inverse_dynamics_array(gait2d, so.inputs_.motion)
    j = [gait2d.coordinate_index(c) for c in ("torso_x", "torso_y")]
    assert np.allclose(so.actuator_forces_[:, 2:4], tau[:, j], atol=1e-6 * np.abs(tau[:, j]).max())
    assert so.violation_.max() < 1e-6


def test_an_unbounded_actuator_at_its_stand_in_bound_is_refused(forearm, motion, monkeypatch):
    # the stand-in of an infinite bound is far beyond any control the problem needs; shrunk below the
    # reserve's optimal control, the solution would sit on it: refused rather than returned
    from pinmsk.solvers import static
    res = CoordinateActuator("elbow_reserve", "elbow_flexion", optimal_force=30.0)
    monkeypatch.setattr(static, "STAND_IN_FACTOR", 1e-3)
    with pytest.raises(SolverError, match=r"actuator 'elbow_reserve' \(no control bound\) reached the solver's "
                                          r"stand-in bound .* at frame \d+"):
        StaticOptimization(weights="fmax", actuators=[res]).fit(forearm, motion)


def test_so_from_the_command_line_with_an_actuator_file(tmp_path, capsys):
    from pathlib import Path

    from pinmsk import read_trial
    from pinmsk.presentation.cli import main
    trial = str(Path(__file__).resolve().parents[1] / "data" / "gait2d_hat_mass.csv")
    xml = tmp_path / "residuals.xml"
    xml.write_text(_xml(
        '<PointActuator name="FX"><body>hat</body><direction>1 0 0</direction><force_is_global>true</force_is_global>'
        '<optimal_force>100</optimal_force></PointActuator>\n'
        '<PointActuator name="FY"><body>hat</body><direction>0 1 0</direction><force_is_global>true</force_is_global>'
        '<optimal_force>100</optimal_force></PointActuator>\n'
        '<TorqueActuator name="MZ"><bodyA>hat</bodyA><bodyB>ground</bodyB><optimal_force>100</optimal_force>'
        '</TorqueActuator>\n'
        '<CoordinateActuator name="mtp_r_reserve"><coordinate>mtp_r</coordinate></CoordinateActuator>\n'
        '<CoordinateActuator name="mtp_l_reserve"><coordinate>mtp_l</coordinate></CoordinateActuator>\n'
        # the trial's ankles need more than the muscles have at some frames (pinmsk so --reserves says so)
        '<CoordinateActuator name="ankle_l_reserve"><coordinate>ankle_l</coordinate><optimal_force>10'
        '</optimal_force></CoordinateActuator>\n'
        '<CoordinateActuator name="ankle_r_reserve"><coordinate>ankle_r</coordinate><optimal_force>10'
        '</optimal_force></CoordinateActuator>\n'))
    out = tmp_path / "so.sto"
    assert main(["so", "gait2d", trial, "-o", str(out), "--actuators", str(xml)]) == 0
    assert "actuator FY" in capsys.readouterr().out
    got = read_trial(out)
    assert {"FX_control", "FX_force", "MZ_force", "mtp_r_reserve_control"} <= set(got.names)
    assert np.max(np.abs(got["FY_force"])) > 1.0 and got.meta["header"]["actuators"] == str(xml)
    assert np.max(np.abs(got["ankle_l_reserve_force"])) > 50.0      # what the muscles cannot supply
    bad = tmp_path / "bad.xml"
    bad.write_text(_xml('<CoordinateActuator name="k"><coordinate>knee</coordinate></CoordinateActuator>\n'))
    assert main(["so", "gait2d", trial, "-o", str(tmp_path / "no.sto"), "--actuators", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "pinmsk: error: " in err and "bad.xml:5: <CoordinateActuator name=\"k\">: model 'gait2d' has no " \
                                        "coordinate 'knee'" in err
    assert not (tmp_path / "no.sto").exists()


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_so_of_an_exact_import_balances_opensims_coordinates(tmp_path):
    """Dependent joints (knee translations, a coupled patella): SO balances OpenSim's independent
    coordinates, tau = J^T tau_pin, so the power of the balanced moments is that of the joint torques."""
    from pinmsk.kinematics import coordinate_map
    from pinmsk.model import import_osim
    from pinmsk.solvers.moments import balance_space
    from pinmsk.trial import Trial
    from test_osim_import import leg
    p = tmp_path / "leg.osim"
    p.write_text(leg())
    model, _ = import_osim(p, nonlinear="exact")
    cmap = coordinate_map(model)
    assert cmap is not None and cmap.couplers and "knee_translation1" in model.coordinates
    t = np.linspace(0.0, 1.0, 101)
    base = {"pelvis_ty": 0.9, "knee_angle": -0.6}
    trial = Trial(t, {c: base.get(c, 0.0) + 0.2 * np.sin(2 * np.pi * t + i)
                      for i, c in enumerate(cmap.osim_coordinates)})
    so = StaticOptimization(reserves=True).fit(model, trial, cutoff=0)
    mo, plan = so.inputs_.motion, so.plan_
    space = balance_space(model, mo)
    assert "knee_beta" not in space.names and "knee_translation1" not in space.names     # coupled, dependent
    assert set(plan.dofs) | set(plan.unspanned) == set(space.names)
    tau = np.zeros((mo.n_frames, space.n))
    tau[:, [space.names.index(c) for c in plan.dofs]] = plan.tau
    tau[:, [space.names.index(c) for c in plan.unspanned]] = plan.unspanned_tau
    v = mo.v[:, [model.coordinate_index(c) for c in space.names]]
    power_pin = np.sum(plan.tau_full * mo.v, axis=1)
    np.testing.assert_allclose(np.sum(tau * v, axis=1), power_pin, rtol=1e-9, atol=1e-9 * np.abs(power_pin).max())
    assert np.abs(power_pin).max() > 1.0
    # the model's actuators (lumbar reserve, pelvis FX and MZ) are in the problem, in the same coordinates
    assert so.actuators_ and {a.name for a in so.actuators_} == {"lumbar_reserve", "FX", "MZ"}
    assert so.violation_.max() < 1e-6


def test_actuator_channels_are_not_plotted_as_muscles(forearm, motion, tmp_path):
    from pinmsk import read_trial, write_trial
    from pinmsk.presentation.plots import muscles_in
    res = CoordinateActuator("elbow_reserve", "elbow_flexion", optimal_force=30.0)
    out = StaticOptimization(weights="fmax", actuators=[res]).fit(forearm, motion).result_
    assert "elbow_reserve_force" in out.names and muscles_in(out) == list(forearm.muscle_names)
    write_trial(out, tmp_path / "so.sto")
    assert muscles_in(read_trial(tmp_path / "so.sto")) == list(forearm.muscle_names)
