"""Tests of pinmsk.opensim.paths (geometric OpenSim muscle paths) and PolynomialPath.

Analytic cases first (straight paths, a pulley over a cylinder and a sphere, an
ellipsoid of equal radii against its closed-form polyline, conditional and
moving points); then like-for-like against the ``opensim`` package (skipped
without it or without the shared models).
"""
import math
import pickle

import numpy as np
import pytest

from conftest import require_opensim

import pinmsk.opensim.functions as osf
import pinmsk.opensim.paths as op
from pinmsk.errors import ModelError
from pinmsk.io.osim import parse_osim, read_osim
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.muscles.paths import MomentArmPath, PolynomialPath


# --- fake kinematics: body "arm" rotates about ground z by q[0]; body "slide" moves along x by q[1]
def _rz(a):
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def placements(names, q):
    q = np.atleast_2d(q)
    R = np.empty((len(q), len(names), 3, 3))
    p = np.zeros((len(q), len(names), 3))
    for b, name in enumerate(names):
        if name == "arm":
            R[:, b] = _rz(q[:, 0])
        elif name == "slide":
            R[:, b] = np.eye(3)
            p[:, b, 0] = q[:, 1]
        else:
            raise AssertionError(name)
    return R, p


COORDS = ("theta", "x")


def test_straight_two_point_path_length_and_moment_arm():
    spec = op.PathSpec("m", (op.PathPointSpec("ground", (0.3, 0.0, 0.1)), op.PathPointSpec("arm", (0.0, 0.2, 0.0))))
    gp = op.GeometricPaths([spec], coordinates=COORDS, placements=placements)
    th = np.linspace(-1.0, 2.0, 7)
    q = np.column_stack([th, np.zeros_like(th)])
    L, A = gp.lengths_and_moment_arms(q)
    b = np.column_stack([-0.2 * np.sin(th), 0.2 * np.cos(th), np.zeros_like(th)])
    d = b - np.array([0.3, 0.0, 0.1])
    l = np.linalg.norm(d, axis=1)
    np.testing.assert_allclose(L[:, 0], l, atol=1e-15)
    # dl/dtheta = d . db/dtheta / l
    dl = np.einsum("ni,ni->n", d, np.column_stack([-0.2 * np.cos(th), -0.2 * np.sin(th), 0 * th])) / l
    np.testing.assert_allclose(A[:, 0, 0], -dl, atol=1e-9)
    np.testing.assert_allclose(A[:, 0, 1], 0.0, atol=1e-12)
    assert gp.lengths(q[0]).shape == (1,)


@pytest.mark.parametrize("kind", ["cylinder", "sphere"])
def test_pulley_wraps_with_radius_as_moment_arm(kind):
    """Origin fixed in ground, insertion on the rotating arm, both at distance d from the axis in the
    plane z = 0, the object centred on the axis: l = 2 sqrt(d^2 - r^2) + r (phi - 2 acos(r/d))
    and the moment arm is r."""
    r, d = 0.05, 0.2
    kw = dict(radius=r, length=0.3) if kind == "cylinder" else dict(radius=r)
    wrap = op.WrapSpec(kind=kind, name="w", body="ground", **kw)
    spec = op.PathSpec("m", (op.PathPointSpec("ground", (d, 0.0, 0.0)), op.PathPointSpec("arm", (-d, 0.0, 0.0))),
                       wraps=(op.PathWrapSpec(wrap),))
    gp = op.GeometricPaths([spec], coordinates=COORDS, placements=placements)
    # the straight line crosses the object while |theta| < 2 asin(r/d) = 0.505
    th = np.linspace(-0.45, 0.45, 8)      # (not 0: a line through a sphere's centre is left unwrapped)
    q = np.column_stack([th, np.zeros_like(th)])
    L, A = gp.lengths_and_moment_arms(q)
    phi = np.pi - np.abs(th)
    expected = 2.0 * math.sqrt(d * d - r * r) + r * (phi - 2.0 * math.acos(r / d))
    np.testing.assert_allclose(L[:, 0], expected, atol=1e-12)
    np.testing.assert_allclose(np.abs(A[:, 0, 0]), r, atol=1e-8)
    # not wrapped when the straight line misses the object (insertion close to the origin)
    q_far = np.array([[np.pi - 0.3, 0.0]])
    straight = np.linalg.norm([-d * math.cos(np.pi - 0.3) - d, -d * math.sin(np.pi - 0.3), 0.0])
    assert gp.lengths(q_far)[0, 0] == pytest.approx(straight, abs=1e-14)


def test_ellipsoid_of_equal_radii_gives_opensims_polyline_over_the_sphere():
    """OpenSim's ellipsoid arc is a polyline of int(chord / 1 mm) segments (at most 499) between the
    tangent points; on a sphere the tangent points are exact, so the length is closed form."""
    r, d = 0.05, 0.2
    wrap = op.WrapSpec(kind="ellipsoid", name="w", body="ground", dimensions=(r, r, r))
    spec = op.PathSpec("m", (op.PathPointSpec("ground", (d, 0.0, 0.0)), op.PathPointSpec("arm", (-d, 0.0, 0.0))),
                       wraps=(op.PathWrapSpec(wrap),))
    gp = op.GeometricPaths([spec], coordinates=COORDS, placements=placements)
    th = np.array([-0.45, 0.2, 0.4])
    L = gp.lengths(np.column_stack([th, 0 * th]))[:, 0]
    psi = (np.pi - np.abs(th)) - 2.0 * math.acos(r / d)        # arc angle between the tangent points
    chord = 2.0 * r * np.sin(psi / 2.0)
    n = np.minimum((chord / 0.001).astype(int), 499)
    expected = 2.0 * math.sqrt(d * d - r * r) + 2.0 * r * n * np.sin(psi / (2.0 * n))
    np.testing.assert_allclose(L, expected, atol=1e-9)


def test_conditional_and_moving_points():
    cond = op.ConditionalPathPointSpec(body="ground", location=(0.0, 0.1, 0.0), coordinate="x", range=(0.0, 1.0))
    moving = op.MovingPathPointSpec(body="slide", x=osf.LinearFunction([0.5, 0.0]), y=0.2, z=osf.Constant(0.0),
                                    coordinates=("x", None, None), clamp=((-1.0, 2.0), None, None))
    spec = op.PathSpec("m", (op.PathPointSpec("ground", (0.0, 0.0, 0.0)), cond, moving))
    gp = op.GeometricPaths([spec], coordinates=COORDS, placements=placements)
    x = np.array([-0.5, 0.5, 1.5, 3.0])
    L, A = gp.lengths_and_moment_arms(np.column_stack([0 * x, x]))
    tip = np.column_stack([x + 0.5 * np.clip(x, -1.0, 2.0), np.full_like(x, 0.2), 0 * x])
    on = (x >= 0.0) & (x <= 1.0)
    via = np.where(on[:, None], [0.0, 0.1, 0.0], 0.0)
    expected = np.linalg.norm(via, axis=1) + np.linalg.norm(tip - via, axis=1)
    np.testing.assert_allclose(L[:, 0], expected, atol=1e-15)
    # moment arm: the tip moves 1.5 dx inside the clamp range, 1 dx beyond it
    u = (tip - via) / np.linalg.norm(tip - via, axis=1)[:, None]
    speed = np.where((x > -1.0) & (x < 2.0), 1.5, 1.0)
    np.testing.assert_allclose(A[:, 0, 1], -u[:, 0] * speed, atol=1e-8)


def test_polynomial_path_values_derivatives_and_pickle():
    pp = PolynomialPath(muscles=("a", "b"), coordinates=("q0", "q1", "q2"), terms=[
        dict(coordinates=("q0", "q1"), center=(0.1, -0.2), scale=(1.5, 0.5),
             exponents=[[0, 0], [1, 0], [2, 1], [0, 3]], coefficients=[0.3, 0.02, -0.01, 0.005]),
        dict(coordinates=("q2",), center=(0.0,), scale=(2.0,), exponents=[[0], [1]], coefficients=[0.2, 0.03])])

    def L(q):
        x0, x1, x2 = (q[..., 0] - 0.1) / 1.5, (q[..., 1] + 0.2) / 0.5, q[..., 2] / 2
        return np.stack([0.3 + 0.02 * x0 - 0.01 * x0 ** 2 * x1 + 0.005 * x1 ** 3, 0.2 + 0.03 * x2], -1)

    rng = np.random.default_rng(0)
    q, v, a = rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    h = 1e-6
    E = np.eye(3)
    np.testing.assert_allclose(pp.lengths(q), L(q), atol=1e-15)
    R = np.stack([-(L(q + h * E[j]) - L(q - h * E[j])) / (2 * h) for j in range(3)], -1)
    np.testing.assert_allclose(pp.moment_arms(q), R, atol=1e-9)
    assert pp.moment_arms(q)[:, 1, :2].tolist() == [[0.0, 0.0]] * 5
    np.testing.assert_allclose(pp.velocities(q, v), -np.einsum("nmj,nj->nm", R, v), atol=1e-9)
    dt = 1e-4
    path = lambda t: q + v * t + 0.5 * a * t * t  # noqa: E731
    acc = (L(path(dt)) - 2 * L(path(0)) + L(path(-dt))) / dt ** 2
    np.testing.assert_allclose(pp.accelerations(q, v, a), acc, atol=1e-6)
    for order in (1, 2):
        f = lambda x: pp.moment_arm_derivative(x, order - 1) if order > 1 else pp.moment_arms(x)  # noqa: E731
        num = np.stack([(f(q + h * E[j]) - f(q - h * E[j]))[:, :, j] / (2 * h) for j in range(3)], -1)
        np.testing.assert_allclose(pp.moment_arm_derivative(q, order), num, atol=1e-8)
    again = pickle.loads(pickle.dumps(pp))
    np.testing.assert_array_equal(again.lengths(q), pp.lengths(q))
    assert pp.lengths(q[0]).shape == (2,) and pp.degree == 3 and pp.nv == 3
    # MuscleSet calls these, as on MomentArmPath
    for name in ("lengths", "velocities", "moment_arms", "moment_arm_derivative", "accelerations", "muscles",
                 "coordinates", "n_muscles", "nv", "degree"):
        assert hasattr(pp, name) and hasattr(MomentArmPath, name)


def test_polynomial_path_rejects_bad_terms_by_name():
    with pytest.raises(ModelError, match="crosses coordinate 'kne'.*did you mean 'knee'"):
        PolynomialPath(muscles=("a",), coordinates=("knee",), terms=[
            dict(coordinates=("kne",), exponents=[[0]], coefficients=[0.1])])
    with pytest.raises(ModelError, match="muscle 'a'.*exponent rows"):
        PolynomialPath(muscles=("a",), coordinates=("knee",), terms=[
            dict(coordinates=("knee",), exponents=[[0], [1]], coefficients=[0.1])])


def test_fit_recovers_a_pulley_exactly():
    """Over the wrapped range the pulley's length is linear in the angle: degree 1, errors ~ 0."""
    r, d = 0.05, 0.2
    wrap = op.WrapSpec(kind="cylinder", name="w", body="ground", radius=r, length=0.3)
    spec = op.PathSpec("m", (op.PathPointSpec("ground", (d, 0.0, 0.0)), op.PathPointSpec("arm", (-d, 0.0, 0.0))),
                       wraps=(op.PathWrapSpec(wrap),))
    gp = op.GeometricPaths([spec], coordinates=COORDS, placements=placements)
    path, (rep,) = op.fit_polynomial_paths(gp, ranges={"theta": (0.05, 0.45), "x": (0.0, 0.0)}, n_train=40,
                                           n_test=30)
    assert rep.coordinates == ("theta",) and rep.degree == 1
    assert rep.length_max < 1e-10 and rep.moment_arm_max < 1e-7
    assert path.moment_arms(np.array([0.5, 0.0]))[0, 0] == pytest.approx(r, abs=1e-7)


# --- the .osim reader ---------------------------------------------------------------------------
_OSIM = """<OpenSimDocument Version="40000"><Model name="t">
<Ground name="ground"><WrapObjectSet><objects>
  <WrapCylinder name="cyl"><translation>0 0 0</translation><radius>0.02</radius><length>0.1</length>
  <quadrant>-x</quadrant></WrapCylinder></objects></WrapObjectSet></Ground>
<BodySet><objects><Body name="arm"><mass>1</mass></Body></objects></BodySet>
<JointSet><objects><PinJoint name="j"><socket_parent_frame>/ground</socket_parent_frame>
<socket_child_frame>/bodyset/arm</socket_child_frame><coordinates><Coordinate name="theta"><range>-1 2</range></Coordinate>
</coordinates></PinJoint></objects></JointSet>
<ForceSet><objects><Thelen2003Muscle name="mus"><GeometryPath><PathPointSet><objects>
  <PathPoint name="p1"><socket_parent_frame>/ground</socket_parent_frame><location>0.2 0 0</location></PathPoint>
  <MovingPathPoint name="p2"><socket_parent_frame>/bodyset/arm</socket_parent_frame>
    <x_location><SimmSpline><x>-1 0 1 2</x><y>-0.2 -0.21 -0.2 -0.19</y></SimmSpline></x_location>
    <socket_x_coordinate>/jointset/j/theta</socket_x_coordinate>
    <y_location><Constant><value>0.01</value></Constant></y_location>
  </MovingPathPoint></objects></PathPointSet>
  <PathWrapSet><objects><PathWrap name="pw"><wrap_object>{wrap}</wrap_object><method>hybrid</method>
  <range>-1 -1</range></PathWrap></objects></PathWrapSet></GeometryPath></Thelen2003Muscle></objects></ForceSet>
</Model></OpenSimDocument>"""


def test_reader_builds_specs():
    doc = parse_osim(_OSIM.format(wrap="cyl"), source="t.osim")
    (spec,) = op.path_specs(doc)
    assert spec.muscle == "mus" and spec.bodies == ("ground", "arm") and spec.coordinates == ("theta",)
    moving = spec.points[1]
    assert moving.coordinates == ("theta", None, None) and moving.clamp[0] == (-1.0, 2.0)
    assert moving.locations([np.array([0.0]), None, None]).tolist() == [[-0.21, 0.01, 0.0]]
    (pw,) = spec.wraps
    assert pw.wrap.kind == "cylinder" and pw.wrap.quadrant == "-x" and pw.wrap.wrap_axis_sign == (0, -1)
    assert moving.x(np.array([0.5])).tolist() == osf.SimmSpline([-1, 0, 1, 2], [-0.2, -0.21, -0.2, -0.19])(
        np.array([0.5])).tolist()


def test_reader_names_bad_elements():
    def specs(text):
        return op.path_specs(parse_osim(text, source="t.osim"))

    with pytest.raises(ModelError, match=r"t.osim:\d+: <PathWrap name=\"pw\"> of muscle 'mus': no wrap object "
                                         "'cly'.*did you mean 'cyl'"):
        specs(_OSIM.format(wrap="cly"))
    bad = _OSIM.format(wrap="cyl").replace("<SimmSpline><x>-1 0 1 2</x><y>-0.2 -0.21 -0.2 -0.19</y></SimmSpline>",
                                           "<StepFunction/>")
    with pytest.raises(ModelError, match=r"t.osim:\d+: <StepFunction.*StepFunction is not supported"):
        specs(bad)
    bad = _OSIM.format(wrap="cyl").replace('<WrapCylinder name="cyl">', '<WrapCone name="cone">').replace(
        "</WrapCylinder>", "</WrapCone>")
    with pytest.raises(ModelError, match=r"t.osim:3: <WrapCone name=\"cone\">: unknown wrap object type"):
        specs(bad)
    bad = _OSIM.format(wrap="cyl").replace('WrapCylinder', 'WrapCylinderObst')
    with pytest.raises(ModelError, match=r"t.osim:3: <WrapCylinderObst name=\"cyl\">: unsupported wrap object "
                                         "type 'WrapCylinderObst'"):
        specs(bad)
    bad = _OSIM.format(wrap="cyl").replace("<radius>0.02</radius>", "")
    with pytest.raises(ModelError, match=r"t.osim:3: <WrapCylinder name=\"cyl\">: has no <radius>"):
        specs(bad)
    bad = _OSIM.format(wrap="cyl").replace("<quadrant>-x</quadrant>", "<quadrant>up</quadrant>")
    with pytest.raises(ModelError, match=r"t.osim:3: <WrapCylinder name=\"cyl\">: .*quadrant 'up'"):
        specs(bad)
    empty = _OSIM.format(wrap="cyl").split("<PathPointSet>")[0] + "<PathPointSet><objects/></PathPointSet>" \
        "</GeometryPath></Thelen2003Muscle></objects></ForceSet></Model></OpenSimDocument>"
    with pytest.raises(ModelError, match=r"t.osim:\d+: <Thelen2003Muscle name=\"mus\">: the muscle has no path points"):
        specs(empty)
    one = _OSIM.format(wrap="cyl").replace("<PathPoint name=\"p1\">", "<!--").replace("</PathPoint>", "-->")
    with pytest.raises(ModelError, match=r"t.osim:\d+: <Thelen2003Muscle name=\"mus\">: .*at least 2 points"):
        specs(one)
    cond = _OSIM.format(wrap="cyl").replace('<PathPoint name="p1">', '<ConditionalPathPoint name="p1">').replace(
        "</PathPoint>", "<socket_coordinate>/jointset/j/theta</socket_coordinate><range>1 0</range>"
                        "</ConditionalPathPoint>")
    with pytest.raises(ModelError, match=r"t.osim:\d+: <ConditionalPathPoint name=\"p1\">: .*min > max"):
        specs(cond)


def test_evaluator_names_missing_coordinates_and_bad_shapes():
    (spec,) = op.path_specs(parse_osim(_OSIM.format(wrap="cyl")))
    with pytest.raises(ModelError, match="coordinate 'theta'.*did you mean 'thetaa'"):
        op.GeometricPaths([spec], coordinates=("thetaa",), placements=placements)
    gp = op.GeometricPaths([spec], coordinates=("theta", "x"), placements=placements)
    with pytest.raises(Exception, match=r"q must have shape \(2,\) or \(N, 2\)"):
        gp.lengths(np.zeros((3, 5)))
    with pytest.raises(ModelError, match="no path for muscle 'muss'.*did you mean 'mus'"):
        gp.path_points(np.zeros(2), "muss")


# --- against OpenSim -----------------------------------------------------------------------------
def _model(relative):
    root = shared_data_dir()
    path = None if root is None else root / "opensim-models" / relative
    if path is None or not path.is_file():
        pytest.skip(f"shared model {relative} not available (set PINMSK_SHARED_DATA)")
    return str(path)


class OsimReference:
    """Body placements, path lengths and moment arms from the opensim package."""

    def __init__(self, path_or_model):
        osim = self.osim = require_opensim()
        # logger off before loading: OpenSim opens its opensim.log lazily, in the working directory of
        # the moment -- the model's folder while it reads the model (the shared data must stay clean)
        osim.Logger.setLevelString("Off")
        try:
            osim.Logger.removeFileSink()
        except Exception:  # pragma: no cover - older opensim
            pass
        self.model = osim.Model(path_or_model) if isinstance(path_or_model, str) else path_or_model
        self.state = self.model.initSystem()
        cs = self.model.getCoordinateSet()
        coords = [cs.get(i) for i in range(cs.getSize())]
        self.cindex = {c.getName(): c for c in coords}
        self.couplers = []
        for i in range(self.model.getConstraintSet().getSize()):
            cc = osim.CoordinateCouplerConstraint.safeDownCast(self.model.getConstraintSet().get(i))
            if cc is not None and cc.get_isEnforced():
                names = cc.getIndependentCoordinateNames()
                self.couplers.append((cc.getDependentCoordinateName(),
                                      [names.get(k) for k in range(names.getSize())], cc.getFunction()))
        dependent = {d for d, _, _ in self.couplers}
        self.independent = tuple(c.getName() for c in coords if c.getName() not in dependent)
        bs = self.model.getBodySet()
        self.bodies = {bs.get(i).getName(): bs.get(i) for i in range(bs.getSize())}

    def ranges(self):
        return {n: (c.getRangeMin(), c.getRangeMax()) for n, c in self.cindex.items()}

    def set(self, row):
        for name, v in zip(self.independent, row):
            self.cindex[name].setValue(self.state, float(v), False)
        for dep, ind, fn in self.couplers:
            x = self.osim.Vector(len(ind), 0.0)
            for k, name in enumerate(ind):
                x.set(k, self.cindex[name].getValue(self.state))
            self.cindex[dep].setValue(self.state, fn.calcValue(x), False)
        self.model.realizePosition(self.state)

    def placements(self, names, q):
        q = np.atleast_2d(q)
        R, p = np.empty((len(q), len(names), 3, 3)), np.empty((len(q), len(names), 3))
        for n, row in enumerate(q):
            self.set(row)
            for b, name in enumerate(names):
                T = self.bodies[name].getTransformInGround(self.state)
                R[n, b] = T.R().asMat33().to_numpy() if hasattr(T.R().asMat33(), "to_numpy") else \
                    [[T.R().get(i, j) for j in range(3)] for i in range(3)]
                p[n, b] = [T.p().get(i) for i in range(3)]
        return R, p

    def paths(self, muscles, q):
        fs = self.model.getForceSet()
        L, A = np.empty((len(q), len(muscles))), np.empty((len(q), len(muscles), len(self.independent)))
        gps = [self.osim.PathActuator.safeDownCast(fs.get(m) if fs.contains(m) else self.model.getComponent("/" + m))
               .getGeometryPath() for m in muscles]
        for n, row in enumerate(q):
            self.set(row)
            for i, gp in enumerate(gps):
                L[n, i] = gp.getLength(self.state)
                for j, c in enumerate(self.independent):
                    A[n, i, j] = gp.computeMomentArm(self.state, self.cindex[c])
        return L, A


def _poses(ref, n, seed=0):
    rng = ref.ranges()
    return op.sample_poses({c: (max(rng[c][0], -3.0), min(rng[c][1], 3.0)) for c in ref.independent},
                           ref.independent, n, seed=seed)


def _compare(relative, n=30):
    path = _model(relative)
    ref = OsimReference(path)
    specs = op.path_specs(read_osim(path))
    gp = op.GeometricPaths(specs, coordinates=ref.independent, placements=ref.placements)
    q = _poses(ref, n)
    L, A = gp.lengths_and_moment_arms(q)
    Lr, Ar = ref.paths(gp.muscles, q)
    el, ea = np.abs(L - Lr).max(axis=0), np.abs(A - Ar).max(axis=(0, 2))
    return gp, el, ea


@pytest.mark.parametrize("relative", ["Arm26/arm26.osim", "Gait10dof18musc/gait10dof18musc.osim",
                                      "Moco2DWalking/2D_gait.osim"])
def test_every_muscle_matches_opensim(relative):
    """Cylinders, ellipsoids (arm26, TRIlong over three objects), conditional and moving points
    (gait10dof18musc, 2D_gait): lengths to 1e-6 m, moment arms to 1e-4 m (measured: 1e-14, 1e-9)."""
    gp, el, ea = _compare(relative)
    worst = gp.muscles[int(np.argmax(el))]
    assert el.max() < 1e-6, f"worst length error {el.max():.3g} m ({worst})"
    assert ea.max() < 1e-4, f"worst moment-arm error {ea.max():.3g} m ({gp.muscles[int(np.argmax(ea))]})"


@pytest.mark.slow
def test_rajagopal_matches_opensim():
    """80 muscles, 46 cylinder wraps (gastrocnemii over two); measured 1e-15 m and 1e-9 m."""
    gp, el, ea = _compare("RajagopalWalk/subject_walk_scaled.osim")
    assert el.max() < 1e-3 and ea.max() < 1e-3
    assert el.max() < 1e-6 and ea.max() < 1e-4


def _synthetic(kind, quadrant, second=None):
    osim = require_opensim()
    m = osim.Model()
    b1 = osim.Body("b1", 1.0, osim.Vec3(0), osim.Inertia(0.1, 0.1, 0.1))
    b2 = osim.Body("b2", 1.0, osim.Vec3(0), osim.Inertia(0.1, 0.1, 0.1))
    j1 = osim.PinJoint("j1", m.getGround(), osim.Vec3(0), osim.Vec3(0.1, 0.2, 0.0), b1, osim.Vec3(0), osim.Vec3(0))
    j2 = osim.PinJoint("j2", b1, osim.Vec3(0.0, -0.3, 0.0), osim.Vec3(0.3, 0, 0), b2, osim.Vec3(0), osim.Vec3(0))
    for b in (b1, b2):
        m.addBody(b)
    for j, name in ((j1, "q1"), (j2, "q2")):
        m.addJoint(j)
        j.upd_coordinates(0).setName(name)

    def make(kind, name):
        w = {"sphere": osim.WrapSphere, "cylinder": osim.WrapCylinder, "ellipsoid": osim.WrapEllipsoid}[kind]()
        if kind == "sphere":
            w.set_radius(0.04)
        elif kind == "cylinder":
            w.set_radius(0.03)
            w.set_length(0.2)
        else:
            w.set_dimensions(osim.Vec3(0.05, 0.03, 0.04))
        w.setName(name)
        return w

    w = make(kind, "wrap1")
    w.set_translation(osim.Vec3(0.01, -0.3, 0.005))
    w.set_xyz_body_rotation(osim.Vec3(0.2, -0.1, 0.3))
    w.set_quadrant(quadrant)
    b1.addWrapObject(w)
    mus = osim.Thelen2003Muscle("mus", 100, 0.1, 0.1, 0.0)
    mus.addNewPathPoint("o", b1, osim.Vec3(0.04, -0.05, 0.01))
    mus.addNewPathPoint("i", b2, osim.Vec3(0.15, 0.03, -0.01))
    mus.addNewPathPoint("i2", b2, osim.Vec3(0.25, 0.02, 0.0))
    m.addForce(mus)
    mus.updGeometryPath().addPathWrap(w)
    if second:
        w2 = make(second, "wrap2")
        w2.set_translation(osim.Vec3(0.08, 0.0, 0.0))
        b2.addWrapObject(w2)
        mus.updGeometryPath().addPathWrap(w2)
    m.finalizeConnections()
    return m, parse_osim(m.dump() if hasattr(m, "dump") else _xml_of(m))


def _xml_of(model):
    import tempfile
    import os
    with tempfile.TemporaryDirectory() as d:
        f = os.path.join(d, "m.osim")
        model.printToXML(f)
        return open(f).read()


@pytest.mark.parametrize("kind,quadrant,second", [("sphere", "all", None), ("sphere", "+x", None),
                                                   ("cylinder", "-x", None), ("ellipsoid", "+y", None),
                                                   ("sphere", "all", "cylinder"), ("ellipsoid", "all", "sphere")])
def test_synthetic_wraps_match_opensim(kind, quadrant, second):
    model, doc = _synthetic(kind, quadrant, second)
    ref = OsimReference(model)
    gp = op.GeometricPaths(op.path_specs(doc), coordinates=ref.independent, placements=ref.placements)
    rng = np.random.default_rng(1)
    q = np.column_stack([rng.uniform(-1.5, 1.5, 60), rng.uniform(-2, 2, 60)])
    L, A = gp.lengths_and_moment_arms(q)
    Lr, Ar = ref.paths(["mus"], q)
    straight = op.GeometricPaths([op.PathSpec("mus", gp.specs[0].points)], coordinates=ref.independent,
                                 placements=ref.placements).lengths(q)
    assert np.sum(np.abs(Lr - straight) > 1e-6) >= 5        # the test wraps
    np.testing.assert_allclose(L, Lr, atol=1e-9)
    np.testing.assert_allclose(A, Ar, atol=1e-6)


def _motion(ref, relative):
    path = _model(relative)
    lines = open(path).read().splitlines()
    h = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    cols = lines[h + 1].split()
    data = np.array([[float(v) for v in line.split()] for line in lines[h + 2:] if line.strip()])
    degrees = any("inDegrees=yes" in line for line in lines[:h])
    q = np.zeros((len(data), len(ref.independent)))
    for j, c in enumerate(ref.independent):
        if c in cols:
            v = data[:, cols.index(c)]
            rotational = ref.cindex[c].getMotionType() == 1
            q[:, j] = np.deg2rad(v) if degrees and rotational else v
    return q


def _fit(model, motion, coordinates, n_train):
    path = _model(model)
    ref = OsimReference(path)
    gp = op.GeometricPaths(op.path_specs(read_osim(path)), coordinates=ref.independent,
                           placements=ref.placements)
    ranges = op.motion_ranges(_motion(ref, motion), ref.independent, limits=ref.ranges())
    return op.fit_polynomial_paths(gp, ranges=ranges, coordinates=coordinates, n_train=n_train, n_test=200)


def test_polynomial_surrogates_of_arm26_within_1mm():
    """Over the IK motion's ranges +- 10 degrees: measured worst 0.05 mm length (BRA), 0.93 mm arm (BRA)."""
    path, reports = _fit("Arm26/arm26.osim", "Arm26/arm26_InverseKinematics.mot", None, 300)
    assert max(r.length_max for r in reports) < 1e-3
    assert max(r.moment_arm_max for r in reports) < 1e-3
    assert {r.muscle: r.coordinates for r in reports}["BICshort"] == ("r_shoulder_elev", "r_elbow_flex")


@pytest.mark.slow
def test_polynomial_surrogates_of_gait10dof18musc():
    """Lengths within 1 mm; moment arms within 1 mm rms but not max (3 mm): the knee extensors'
    moving points are SimmSplines with knots 0.17 mrad apart at full extension, a kink no
    polynomial of degree <= 6 follows."""
    coords = ["hip_flexion_r", "knee_angle_r", "ankle_angle_r", "hip_flexion_l", "knee_angle_l", "ankle_angle_l",
              "lumbar_extension", "pelvis_tilt"]
    path, reports = _fit("Gait10dof18musc/gait10dof18musc.osim", "Gait10dof18musc/IK/subject01_walk_IK.mot",
                         coords, 500)
    assert max(r.length_max for r in reports) < 1e-3
    assert max(r.moment_arm_rms for r in reports) < 1e-3
    assert max(r.moment_arm_max for r in reports) < 3.5e-3


def _surrogate_errors(model, report, q_os, names):
    """Max length and moment-arm errors (m) per muscle of the model's polynomial paths against the import's
    geometric paths at OpenSim coordinates ``q_os`` (N, len(names)); the coupled patella-free models only."""
    from pinmsk.opensim.muscle_import import geometric_paths
    gp = geometric_paths(report)
    cmap = model.meta["coordinate_map"]
    q = np.column_stack([q_os[:, names.index(c)] if c in names else np.full(q_os.shape[0], cmap.defaults[c])
                         for c in gp.coordinates])
    L, A = gp.lengths_and_moment_arms(q)
    poly = model.muscles.path
    qm = np.column_stack([q[:, gp.coordinates.index(c)] if c in gp.coordinates else np.zeros(q.shape[0])
                          for c in poly.coordinates])
    common = [c for c in gp.coordinates if c in poly.coordinates]
    arms = poly.moment_arms(qm)[:, :, [poly.coordinates.index(c) for c in common]]
    return (np.abs(poly.lengths(qm) - L).max(axis=0),
            np.abs(arms - A[:, :, [gp.coordinates.index(c) for c in common]]).max(axis=(0, 2)))


def test_import_fits_the_muscle_paths_over_a_motion_as_opensims_path_fitter(tmp_path, capsys):
    """``import_osim(path, fit_over=trial)`` (``pinmsk import --fit-over``) fits the surrogates over the
    motion's ranges +- 10 degrees, as OpenSim's PolynomialPathFitter: at the motion's own poses the
    errors against the geometric paths fall, the report says which ranges; a motion without the model's
    coordinates, or both
    ``hooks`` and ``fit_over``, is refused by name."""
    from pinmsk.io.tables import read_trial
    from pinmsk.model import import_osim
    from pinmsk.trial import Trial
    from pathlib import Path
    path = Path(_model("Gait10dof18musc/subject01.osim"))
    ik = read_trial(path.parent / "IK" / "subject01_walk_IK.mot")
    names = list(ik.names)
    q = ik.get(names)
    whole, rep_whole = import_osim(path)
    fitted, rep_fit = import_osim(path, fit_over=ik)
    el0, ea0 = _surrogate_errors(whole, rep_whole, q, names)
    el1, ea1 = _surrogate_errors(fitted, rep_fit, q, names)
    # measured: lengths 0.29 -> 0.27 mm, moment arms 2.83 -> 1.64 mm at worst (the knee extensors' kink at
    # full extension, test_polynomial_surrogates_of_gait10dof18musc, bounds the rest)
    assert el1.max() < 1e-3 and ea1.max() < 2e-3
    assert ea1.max() < 0.7 * ea0.max()
    note = [e.became for e in rep_fit.entries if "fitted over the motion" in e.became]
    assert note and "151 frames" in note[0] and "10 coordinates widened by 10 degrees" in note[0]
    lo, hi = float(np.min(ik["knee_angle_r"])), float(np.max(ik["knee_angle_r"]))
    span = f"knee_angle_r [{lo - math.radians(10):.3g}, {min(hi + math.radians(10), 0.175):.3g}]"
    assert any(span in (e.approximation or "") for e in rep_fit.entries), span
    with pytest.raises(ModelError, match="has none of the model's coordinates"):
        import_osim(path, fit_over=Trial(ik.time, {"elbow": np.zeros(ik.n_frames)}))
    with pytest.raises(ModelError, match="give hooks= or fit_over=, not both"):
        import_osim(path, fit_over=ik, hooks=())
    from pinmsk.presentation.cli import main
    ik_file = path.parent / "IK" / "subject01_walk_IK.mot"
    assert main(["import", str(path), "-o", str(tmp_path / "fit"), "--fit-over", str(ik_file)]) == 0
    assert "fitted over the motion" in (tmp_path / "fit" / "subject01_import_report.txt").read_text()
    capsys.readouterr()
    assert main(["import", str(path), "-o", str(tmp_path / "bad"), "--fit-over", str(tmp_path / "none.mot")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pinmsk: error:") and "none.mot" in err[0]
    assert not (tmp_path / "bad").exists()


def test_couplings_tie_the_sampled_poses_and_fold_into_the_moment_arms():
    """A path between the rotating arm and the slide, with the slide coupled to the arm (x = 2 * 0.25 theta):
    the fit samples theta only, sets x from the coupling, and its moment arm about theta is the total
    derivative -d/dtheta l(theta, x(theta)) (OpenSim's MomentArmSolver includes the coupling so)."""
    spec = op.PathSpec("m", (op.PathPointSpec("arm", (0.0, 0.2, 0.0)), op.PathPointSpec("slide", (0.1, -0.1, 0.05))))
    gp = op.GeometricPaths([spec], coordinates=COORDS, placements=placements)
    coupling = ("x", ("theta",), osf.LinearFunction([0.25, 0.0]), 2.0)
    path, (rep,) = op.fit_polynomial_paths(gp, ranges={"theta": (0.0, 0.8)}, couplings=(coupling,), n_train=60,
                                           n_test=30, max_degree=10, tolerance=1e-7)
    assert rep.coordinates == ("theta",) and rep.length_max < 1e-6 and rep.moment_arm_max < 1e-5
    th = np.linspace(0.05, 0.75, 9)
    q = np.column_stack([th, 0.5 * th])
    h = 1e-6
    total = -(gp.lengths(q + h * np.array([1.0, 0.5]))[:, 0] - gp.lengths(q - h * np.array([1.0, 0.5]))[:, 0]) / (2 * h)
    np.testing.assert_allclose(path.lengths(q)[:, 0], gp.lengths(q)[:, 0], atol=1e-6)
    np.testing.assert_allclose(path.moment_arms(q)[:, 0, 0], total, atol=1e-5)
    assert np.all(path.moment_arms(q)[:, 0, 1] == 0.0)        # none about the coupled coordinate
    partial = gp.moment_arms(q)[:, 0, 0]
    assert np.max(np.abs(partial - total)) > 1e-2             # the coupling's share is there to be missed
    with pytest.raises(ModelError, match=r"\['x'\] are coupled to others"):
        op.fit_polynomial_paths(gp, ranges={"theta": (0.0, 1.2), "x": (0.0, 1.0)}, coordinates=("theta", "x"),
                                couplings=(coupling,), n_train=20, n_test=10)


_RAJAGOPAL_FIT = {}


def _rajagopal_fitted_over_the_walk():
    """RajagopalWalk with its muscles fitted over the walk's ranges +- 10 degrees (``fit_over``, as OpenSim's
    PolynomialPathFitter samples), the walk's poses with the patella coupled, and the import report."""
    if not _RAJAGOPAL_FIT:
        from pinmsk.io.tables import read_trial
        from pinmsk.model import import_osim
        from pinmsk.opensim.muscle_import import geometric_paths
        path = _model("RajagopalWalk/subject_walk_scaled.osim")
        root = shared_data_dir() / "real" / "opensim-moco-walk-emg" / "coordinates.sto"
        if not root.is_file():
            pytest.skip("../shared/data/real/opensim-moco-walk-emg is absent")
        raw = read_trial(root, strict=False)
        ch = {n.split("/")[-2]: np.asarray(raw[n])[::10] for n in raw.names}
        walked = [c for c in ch if not c.endswith("_beta")]          # its patella angles are not the coupling's
        model, report = import_osim(path, fit_over=raw)      # as `pinmsk import --fit-over coordinates.sto`
        gp = geometric_paths(report)
        cmap = model.meta["coordinate_map"]
        q = np.column_stack([ch[c] if c in walked else np.full(len(ch[walked[0]]), cmap.defaults[c])
                             for c in gp.coordinates])
        for dep, ind, f, s in cmap.couplers:
            q[:, gp.coordinates.index(dep)] = s * f.value(q[:, gp.coordinates.index(ind[0])])
        _RAJAGOPAL_FIT.update(model=model, report=report, gp=gp, q=q, cmap=cmap, path=path)
    return _RAJAGOPAL_FIT


@pytest.mark.slow
def test_rajagopal_polynomials_over_the_walk_match_the_geometric_paths():
    """All 80 muscles over every 10th frame of the walk: within 1 mm (length and moment arm) except
    the gastrocnemii lateral and gluteus maximus 1.  Measured worst: 0.06 mm / 0.62 mm for the others;
    gaslat 4.8 mm / 4.1 mm, because OpenSim's own gaslat is not one function -- over two wrap objects its
    length (the tangent points' cached ground positions, GeometricPaths match_opensim) and its moment
    arm differ by up to 15 mm of arm at an extended knee (asserted below), so no one polynomial follows
    both; glmax1 0.5 mm / 2.8 mm, its cylinder wrap jumping inside the sampled box.  Slow (~8 s); the
    default tests of the same code: test_couplings_tie_the_sampled_poses_and_fold_into_the_moment_arms,
    test_polynomial_surrogates_of_arm26_within_1mm."""
    fit = _rajagopal_fitted_over_the_walk()
    gp, q, model = fit["gp"], fit["q"], fit["model"]
    L, A = gp.lengths_and_moment_arms(q)
    C = gp.coordinates
    for dep, ind, f, s in fit["cmap"].couplers:      # total moment arms about the independent coordinates
        j, d = C.index(ind[0]), C.index(dep)
        A[:, :, j] += A[:, :, d] * (s * f.derivative(q[:, j], 1))[:, None]
        A[:, :, d] = 0.0
    poly = model.muscles.path       # over the skeleton's joints: the dependent ones carry no moment arm
    qm = np.column_stack([q[:, C.index(c)] if c in C else np.zeros(q.shape[0]) for c in poly.coordinates])
    common = [c for c in C if c in poly.coordinates]     # the patella angles are no joint: folded above
    el = np.abs(poly.lengths(qm) - L).max(axis=0)
    ea = np.abs(poly.moment_arms(qm)[:, :, [poly.coordinates.index(c) for c in common]]
                - A[:, :, [C.index(c) for c in common]]).max(axis=(0, 2))
    known = {"gaslat_r": (5.5e-3, 5e-3), "gaslat_l": (5.5e-3, 5e-3), "glmax1_r": (1e-3, 3.5e-3),
             "glmax1_l": (1e-3, 3.5e-3)}
    over = {m: (round(1e3 * el[i], 3), round(1e3 * ea[i], 3)) for i, m in enumerate(gp.muscles)
            if el[i] > known.get(m, (1e-3, 1e-3))[0] or ea[i] > known.get(m, (1e-3, 1e-3))[1]}
    assert not over, f"length / moment-arm errors (mm) over the walk: {over}"
    # gaslat: OpenSim's moment arm about the knee against the derivative of OpenSim's length
    i = gp.muscles.index("gaslat_r")
    k, b = C.index("knee_angle_r"), C.index("knee_angle_r_beta")
    h = 1e-4
    dq = np.zeros(len(C))
    dq[[k, b]] = h
    slope = -(gp.lengths(q + dq)[:, i] - gp.lengths(q - dq)[:, i]) / (2 * h)
    assert np.max(np.abs(slope - A[:, i, k])) > 5e-3


@pytest.mark.slow
def test_rajagopal_polynomial_lengths_match_opensim_at_walk_poses():
    """Five poses of the walk, all 80 muscles: the polynomials' lengths against OpenSim's GeometryPath
    (the patella coupled by OpenSim's own constraint function) within 1 mm but gaslat's (above), and the
    knee extensors' knee moment arms against OpenSim's computeMomentArm, which includes the coupling."""
    fit = _rajagopal_fitted_over_the_walk()
    ref = OsimReference(fit["path"])
    gp, model = fit["gp"], fit["model"]
    q = fit["q"][np.linspace(0, len(fit["q"]) - 1, 5).astype(int)]
    C = gp.coordinates
    rows = np.column_stack([q[:, C.index(c)] for c in ref.independent])
    quads = [m for m in gp.muscles if m.startswith(("vas", "recfem"))]
    fs = ref.model.getForceSet()
    L_os = np.empty((len(q), len(gp.muscles)))
    A_os = np.empty((len(q), len(quads)))
    for n, row in enumerate(rows):
        ref.set(row)
        for i, m in enumerate(gp.muscles):
            L_os[n, i] = ref.osim.PathActuator.safeDownCast(fs.get(m)).getGeometryPath().getLength(ref.state)
        for i, m in enumerate(quads):
            side = m[-1]
            A_os[n, i] = ref.osim.PathActuator.safeDownCast(fs.get(m)).getGeometryPath().computeMomentArm(
                ref.state, ref.cindex[f"knee_angle_{side}"])
    poly = model.muscles.path       # over the skeleton's joints: the dependent ones carry no moment arm
    qm = np.column_stack([q[:, C.index(c)] if c in C else np.zeros(q.shape[0]) for c in poly.coordinates])
    el = np.abs(poly.lengths(qm) - L_os)
    worst = {m: round(1e3 * el[:, i].max(), 3) for i, m in enumerate(gp.muscles) if el[:, i].max() > 1e-3}
    assert set(worst) <= {"gaslat_r", "gaslat_l"}, worst
    arms = poly.moment_arms(qm)
    mine = np.column_stack([arms[:, poly.muscles.index(m), poly.coordinates.index(f"knee_angle_{m[-1]}")]
                            for m in quads])
    assert np.max(np.abs(mine - A_os)) < 1e-3
