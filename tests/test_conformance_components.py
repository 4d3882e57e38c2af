"""Conformance of the components at one state: effects' ``generalized_force_at``, paths'
``lengths_at`` / ``moment_arms_at`` and contacts' ``wrench_at`` give, on CasADi, the numbers of the
batched numpy code (rel 1e-12), and CasADi's exact Jacobians equal central finite differences of
that numpy code.  The numpy single-state forms equal the batched ones exactly."""
import numpy as np
import pytest

from pinmsk.builtin_models import builtin_sidecar, read_sidecar
from pinmsk.components import Motion
from pinmsk.errors import ModelError
from pinmsk.model import load_model
from pinmsk.muscles.paths import PolynomialPath, path_variants

from conftest import LazyCasadi  # noqa: E402

ca = LazyCasadi()   # imported inside the tests (tests/conftest.py)

# a numpy ufunc called on a CasADi value (instead of the pinmsk.backend namespace) fails the test
pytestmark = pytest.mark.filterwarnings("error::FutureWarning:casadi")

RTOL = 1e-12
H = 1e-6


@pytest.fixture(scope="module")
def forearm():
    return load_model("forearm")


@pytest.fixture(scope="module")
def gait():
    return load_model("gait2d")


def _close(a, b, rtol, atol=0.0):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    scale = max(np.abs(b).max(initial=0.0), 1e-300)
    assert a.shape == b.shape, (a.shape, b.shape)
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * scale + atol)


def _fd(f, x, h=H):
    """Central differences of the numpy function f (1-D x -> array) -> (f.size, x.size)."""
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((np.ravel(f(x + e)) - np.ravel(f(x - e))) / (2 * h))
    return np.stack(cols, axis=1)


def _dm(x):
    return np.array(ca.DM(x), dtype=float)


# -- effects ----------------------------------------------------------------------------------

def _effects(model):
    """One of every effect family with a closed form that fits ``model``, at non-default values."""
    from pinmsk.effects import (ActivationDynamics, CoulombFriction, JointDamping, JointSpring, PassiveElastic,
                                SensorGain, SensorOffset)
    c = model.coordinates[-1]
    out = [JointDamping(c, c=2.5), CoulombFriction(c, F_c=0.7), SensorGain(c, gain=1.1), SensorOffset(c, offset=0.3),
           JointSpring(c, k=12.0, q0=0.2).for_model(model),
           PassiveElastic(c, amplitude=3.0, theta_0=0.3, k_lo=4.0, k_hi=7.0).for_model(model)]
    if model.muscles is not None:
        out.append(ActivationDynamics())
    return out + list(model.effects)


@pytest.mark.parametrize("name", ["forearm", "gait"])
def test_effects_at_one_state_match_the_batched_law_with_exact_jacobians(name, request):
    model = request.getfixturevalue(name)
    nv = model.nv
    rng = np.random.default_rng(1)
    q = rng.uniform(-0.4, 0.4, (3, nv)) + 0.3          # inside gait2d's and the forearm's ranges
    v = rng.normal(0.0, 0.05, (3, nv))                # near zero: the friction's tanh is curved there
    qs, vs = ca.SX.sym("q", nv), ca.SX.sym("v", nv)
    effects = _effects(model)
    expected = {"passive_elastic", "coulomb_friction"} | ({"riener_edrich_1999"} if name == "gait" else set())
    assert expected <= {e.family for e in effects}
    for eff in effects:
        batch = eff.generalized_force(model, Motion(np.zeros(3), q, v, np.zeros_like(q)))
        Q = eff.generalized_force_at(model, qs, vs)
        assert Q.shape == (nv, 1), eff.label
        F = ca.Function("Q", [qs, vs], [Q, ca.jacobian(Q, ca.vertcat(qs, vs))])
        for k in range(3):
            np.testing.assert_array_equal(eff.generalized_force_at(model, q[k], v[k]), batch[k])
            val, jac = (_dm(x) for x in F(q[k], v[k]))
            _close(val[:, 0], batch[k], RTOL)

            def numpy_law(x):
                mo = Motion(np.zeros(1), x[None, :nv], x[None, nv:], np.zeros((1, nv)))
                return eff.generalized_force(model, mo)[0]

            _close(jac, _fd(numpy_law, np.concatenate([q[k], v[k]])), 1e-6, 1e-9)
        if eff.family == "riener_edrich_1999":       # the published moments are not zero
            assert np.abs(batch).max() > 1.0


def test_inertial_effects_and_contacts_refuse_by_name(forearm, gait):
    from pinmsk.contact import foot_contacts
    from pinmsk.effects import MassScale, Payload, SegmentMass
    from pinmsk.effects._base import hand_like_frames, moving_bodies

    q = np.zeros(forearm.nv)
    for eff in (Payload(hand_like_frames(forearm)[0]), SegmentMass(next(iter(moving_bodies(forearm)))),
                MassScale()):
        with pytest.raises(ModelError, match=f"{eff.label}.*depends on the accelerations.*apply_inertia"):
            eff.generalized_force_at(forearm, q, q)
    c = foot_contacts(gait, "volumetric", side="r")[0]
    with pytest.raises(ModelError, match=f"{c.label}.*wrench_at"):
        c.generalized_force_at(gait, np.zeros(gait.nv), np.zeros(gait.nv))
    with pytest.raises(ModelError, match="component muscles has no closed form"):
        forearm.muscles.generalized_force_at(forearm, q, q)


# -- paths ------------------------------------------------------------------------------------

def _check_path(path, qs_num, fd=True):
    nv, m = path.nv, path.n_muscles
    qs = ca.SX.sym("q", nv)
    L, R = path.lengths_at(qs), path.moment_arms_at(qs)
    assert L.shape == (m, 1) and R.shape == (m, nv)
    F = ca.Function("p", [qs], [L, R, ca.jacobian(L, qs), ca.jacobian(ca.vec(R), qs)])
    batch_l, batch_r = path.lengths(qs_num), path.moment_arms(qs_num)
    for k, q in enumerate(qs_num):
        np.testing.assert_array_equal(path.lengths_at(q), batch_l[k])
        np.testing.assert_array_equal(path.moment_arms_at(q), batch_r[k])
        l, r, dl, dr = (_dm(x) for x in F(q))
        _close(l[:, 0], batch_l[k], RTOL)
        _close(r, batch_r[k], RTOL, 1e-15)
        _close(dl, -batch_r[k], RTOL, 1e-15)            # the sign convention: r = -dl/dq
        if fd:
            _close(dl, _fd(path.lengths_at, q), 1e-6, 1e-12)
            _close(dr, _fd(lambda x: path.moment_arms_at(x).ravel(order="F"), q), 1e-6, 1e-12)


@pytest.mark.parametrize("name", ["forearm", "gait2d", "finger"])
def test_builtin_paths_at_one_pose_every_variant(name):
    for variant in path_variants(read_sidecar(builtin_sidecar(name)).get("muscles", [])):
        model = load_model(name, moment_arms=variant)
        qs = np.random.default_rng(2).uniform(-0.5, 0.5, (2, model.nv))
        _check_path(model.muscles.path, qs)
        np.testing.assert_array_equal(model.muscles.lengths_at(qs[0]), model.muscles.lengths(qs)[0])
        np.testing.assert_array_equal(model.muscles.moment_arms_at(qs[0]), model.muscles.moment_arms(qs)[0])


def test_polynomial_path_at_one_pose_with_cross_terms():
    pp = PolynomialPath(muscles=("a", "b", "c"), coordinates=("q0", "q1", "q2"), terms=[
        dict(coordinates=("q0", "q1"), center=(0.1, -0.2), scale=(1.5, 0.5),
             exponents=[[0, 0], [1, 0], [2, 1], [0, 3], [3, 2]], coefficients=[0.3, 0.02, -0.01, 0.005, 0.002]),
        dict(coordinates=("q2",), center=(0.0,), scale=(2.0,), exponents=[[0], [1]], coefficients=[0.2, 0.03]),
        dict(coordinates=("q2", "q0", "q1"), center=(0.2, 0.0, 0.1), scale=(1.0, 0.7, 1.2),
             exponents=[[0, 0, 0], [1, 1, 1], [0, 2, 0], [2, 0, 1]], coefficients=[0.25, 0.01, -0.02, 0.004])])
    _check_path(pp, np.random.default_rng(3).normal(size=(3, 3)))


def test_muscle_set_refuses_paths_without_a_closed_form(forearm):
    import copy

    ms = copy.copy(forearm.muscles)

    class GeometricLike:
        pass

    ms.__dict__["path"] = GeometricLike()
    for fn in (ms.lengths_at, ms.moment_arms_at):
        with pytest.raises(ModelError, match="GeometricLike have no closed form.*PolynomialPath"):
            fn(np.zeros(forearm.nv))


@pytest.mark.filterwarnings("ignore:.*fitted by polynomials")
def test_imported_polynomial_paths_at_one_pose(shared_data):
    model = load_model(shared_data / "opensim-models/Gait10dof18musc/gait10dof18musc.osim")
    assert isinstance(model.muscles.path, PolynomialPath)
    lo, hi = model.pin.lowerPositionLimit, model.pin.upperPositionLimit
    rng = np.random.default_rng(4)
    mid = np.where(np.isfinite(lo) & np.isfinite(hi) & (hi - lo < 20), 0.5 * (lo + hi), 0.0)
    _check_path(model.muscles.path, mid + rng.uniform(-0.2, 0.2, (2, model.nv)))


# -- contacts ---------------------------------------------------------------------------------

def _contacts(foot2d, gait):
    from pinmsk.contact import (HuntCrossleyForce, SmoothSphereHalfSpaceForce, foot_contacts)
    out = [(foot2d, c) for kind in ("point", "volumetric", "hypervolumetric") for c in foot_contacts(foot2d, kind)]
    out += [(gait, c) for kind in ("point", "volumetric", "hypervolumetric")
            for c in foot_contacts(gait, kind, side="r", ground_speed=-1.2)[:2]]
    half = dict(radius=0.03, stiffness=3e6, dissipation=2.0, static_friction=0.8, dynamic_friction=0.6,
                viscous_friction=0.2, transition_velocity=0.05)
    normal = (0.1, 1.0, -0.05)
    out += [(gait, SmoothSphereHalfSpaceForce("heel_r", location=(0.01, 0.02, 0.0), plane_normal=normal,
                                              plane_point=(0.0, 0.01, 0.0), **half)),
            (gait, HuntCrossleyForce("heel_r", location=(0.01, 0.02, 0.0), plane_normal=normal, **half))]
    return out


def _site_state(rng, c):
    """A site state in contact: the sphere centre a little below its radius / rest length."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(rng.normal(0.0, 0.2, 3)).as_matrix()
    radius = c.values.get(getattr(c, "radius_name", "R"), 0.05)
    p = np.array([rng.normal(0.0, 0.1), radius - 0.004 - 0.004 * rng.random(), rng.normal(0.0, 0.02)])
    p = p - R @ np.asarray(getattr(c, "location", (0.0, 0.0, 0.0)))
    if getattr(c, "center", None) == "sole":
        p = p - R @ np.array([0.0, radius, 0.0])
    v = rng.normal(0.0, 0.3, 3)
    v[1] = -abs(v[1]) - 0.05                 # compressing: the damping factors stay positive
    w = rng.normal(0.0, 0.5, 3)
    return p, R, v, w


def test_contact_wrench_at_one_state_matches_the_batched_law_with_exact_jacobians(gait):
    from pinmsk.contact import SiteKinematics
    from pinmsk.contact.sphere import cross

    foot2d = load_model("foot2d")
    rng = np.random.default_rng(5)
    sym = [ca.SX.sym("p", 3), ca.SX.sym("R", 3, 3), ca.SX.sym("v", 3), ca.SX.sym("w", 3)]
    x_sym = ca.vertcat(sym[0], ca.vec(sym[1]), sym[2], sym[3])
    families = set()
    for model, c in _contacts(foot2d, gait):
        families.add(c.family)
        f_s, m_s = c.wrench_at(*sym)
        assert f_s.shape == (3, 1) and m_s.shape == (3, 1)
        W = ca.vertcat(f_s, m_s)
        F = ca.Function("w", sym, [W, ca.jacobian(W, x_sym)])
        states = [_site_state(rng, c) for _ in range(2)]
        kin = SiteKinematics(*(np.stack(s) for s in zip(*states)))
        out = c.evaluate_kinematics(kin)
        batch_moment = cross(out.point - kin.position, out.force)
        for k, (p, R, v, w) in enumerate(states):
            f, mo = c.wrench_at(p, R, v, w)
            np.testing.assert_array_equal(f, out.force[k])
            np.testing.assert_array_equal(mo, batch_moment[k])
            assert f[1] > 1.0, c.label                    # in contact: the test sees the law
            val, jac = (_dm(x) for x in F(p, R, v, w))
            _close(val[:, 0], np.concatenate([f, mo]), RTOL)

            def numpy_law(x):
                ff, mm = c.wrench_at(x[:3], x[3:12].reshape(3, 3, order="F"), x[12:15], x[15:])
                return np.concatenate([ff, mm])

            x = np.concatenate([p, R.ravel(order="F"), v, w])
            _close(jac, _fd(numpy_law, x, 1e-7), 2e-6)
    assert families == {"hunt_crossley", "volumetric", "hypervolumetric", "smooth_sphere_half_space",
                        "hunt_crossley_force"}
