"""Contact elements (thesis Eq. 4.4-4.17): closed forms, smoothness, wrenches, foot2d, bad input."""
import math
import pickle
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import quad

from pinmsk.components import Motion
from pinmsk.contact import (HuntCrossley, HyperVolumetric, SiteKinematics, Volumetric, cap_centroid_depth,
                            cap_volume, foot_contacts, ground_reaction, load_foot2d,
                            regularized_coulomb, site_kinematics)
from pinmsk.contact.foot import SITES, Foot2dGeometry, foot2d_site_kinematics
from pinmsk.diagnose.contact import contact_candidates
from pinmsk.errors import ModelError
from pinmsk.skeleton import ExternalForce, external_generalized_force

from conftest import REPO


@pytest.fixture(scope="module")
def foot():
    return load_foot2d()


def _kin_at_heights(h, *, vy=0.0, vx=0.0, wz=0.0):
    """Kinematics of a site at heights h (N,), unrotated, moving with (vx, vy), spinning wz."""
    n = np.size(h)
    pos = np.zeros((n, 3))
    pos[:, 1] = h
    vel = np.zeros((n, 3))
    vel[:, 0], vel[:, 1] = vx, vy
    om = np.zeros((n, 3))
    om[:, 2] = wz
    return SiteKinematics(pos, np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), vel, om)


ALL = [HuntCrossley("s"), Volumetric("s"), HyperVolumetric("s")]


# -- closed forms ------------------------------------------------------------------

@pytest.mark.parametrize("d", [0.001, 0.01, 0.03, 0.05, 0.09])
def test_cap_volume_and_centroid_match_numerical_integration(d):
    R = 0.05
    # slices perpendicular to y: area pi (R^2 - z^2), z from the centre, cap from R - d to R
    vol = quad(lambda z: math.pi * (R * R - z * z), R - d, R)[0]
    mom = quad(lambda z: z * math.pi * (R * R - z * z), R - d, R)[0]
    assert cap_volume(d, R) == pytest.approx(vol, rel=1e-12)
    assert cap_centroid_depth(d, R) == pytest.approx(mom / vol, rel=1e-10)
    # whole sphere, half sphere
    assert cap_volume(2 * R, R) == pytest.approx(4 / 3 * math.pi * R ** 3)
    assert cap_centroid_depth(R, R) == pytest.approx(3 * R / 8)


def test_hand_computed_static_volumetric_force_and_point():
    c = Volumetric("s", k_v=2e6, a_v=1.0, R=0.05, smoothing=1e-9)
    h = 0.04  # 10 mm penetration
    out = c.evaluate_kinematics(_kin_at_heights(np.array([h])))
    V = math.pi * 0.01 ** 2 * (3 * 0.05 - 0.01) / 3
    assert out.normal[0] == pytest.approx(2e6 * V, rel=1e-8)
    zbar = 3 * (0.1 - 0.01) ** 2 / (4 * (0.15 - 0.01))
    assert out.point[0, 1] == pytest.approx(h - zbar, rel=1e-9)
    assert -0.01 < out.point[0, 1] < 0  # centroid inside the penetrating cap
    assert out.friction[0] == pytest.approx(np.zeros(3))


def test_hypervolumetric_and_point_laws_by_hand():
    hv = HyperVolumetric("s", k_h=1e6, a_h=2e6, R=0.05, H=0.8, smoothing=1e-9)
    out = hv.evaluate_kinematics(_kin_at_heights(np.array([0.04]), vy=-0.1))
    V = cap_volume(0.01, 0.05)
    assert out.normal[0] == pytest.approx(1e6 * V ** 0.8 + 2e6 * V * 0.1, rel=1e-7)
    hc = HuntCrossley("s", k_s=1e4, n_s=1.5, a_s=2.0, L0=0.05, smoothing=1e-9)
    out = hc.evaluate_kinematics(_kin_at_heights(np.array([0.04]), vy=-0.1))
    assert out.normal[0] == pytest.approx(1e4 * 0.01 ** 1.5 * (1 + 2.0 * 0.1), rel=1e-6)
    assert out.point[0, 1] == pytest.approx(0.0, abs=1e-9)  # acts on the ground below the site


# -- smoothness -------------------------------------------------------------------

@pytest.mark.parametrize("c", ALL, ids=lambda c: c.family)
def test_force_continuous_at_first_contact_and_zero_far_away(c):
    R = c.values[c.radius_name]
    h = R + np.array([-1e-6, 0.0, 1e-6])
    fn = c.evaluate_kinematics(_kin_at_heights(h, vy=-0.5)).normal
    assert np.all(np.abs(np.diff(fn)) < 1.0)  # N per um: no jump at first contact
    assert np.all(np.diff(fn) <= 0)
    assert abs(fn[1]) < 50.0                   # small (smoothing eps = 0.1 mm) at the nominal onset
    far = c.evaluate_kinematics(_kin_at_heights(np.array([R + 0.005, R + 0.2]), vy=-0.5)).normal
    assert abs(far[0]) < 1.0 and abs(far[1]) < 0.05  # the smoothing tail, see sphere.py


@pytest.mark.parametrize("c", ALL, ids=lambda c: c.family)
def test_c1_smooth_through_contact_onset(c):
    """The derivative df_n/dh (by central differences) has no jump across h = R."""
    R = c.values[c.radius_name]
    h = R + np.linspace(-2e-3, 2e-3, 4001)
    fn = c.evaluate_kinematics(_kin_at_heights(h, vy=-0.2)).normal
    d = np.gradient(fn, h)
    jumps = np.abs(np.diff(d))
    scale = np.abs(d).max()
    assert jumps.max() < 0.02 * scale
    assert np.all(np.isfinite(d))


@pytest.mark.parametrize("c", ALL, ids=lambda c: c.family)
def test_friction_smooth_through_zero_slip(c):
    vx = np.linspace(-1e-3, 1e-3, 2001)
    R = c.values[c.radius_name]
    out = c.evaluate_kinematics(_kin_at_heights(np.full(vx.size, R - 0.008), vx=vx))
    fx = out.friction[:, 0]
    assert np.all(np.sign(fx[vx != 0]) == -np.sign(vx[vx != 0]))  # opposes slip
    d = np.gradient(fx, vx)
    assert np.abs(np.diff(d)).max() < 0.02 * np.abs(d).max()


def test_friction_tends_to_dry_coulomb_as_vs_to_zero():
    slip = np.array([[0.05, 0.0, 0.0], [-0.2, 0.0, 0.0], [0.0, 0.0, 0.3]])
    fn = np.array([500.0, 300.0, 100.0])
    mu = 0.4
    prev = None
    for v_s in (1e-2, 1e-3, 1e-4, 1e-6):
        ff = regularized_coulomb(slip, fn, mu, v_s)
        mag = np.linalg.norm(ff, axis=1)
        err = np.abs(mag - math.pi / 2 * mu * fn).max()
        if prev is not None:
            assert err < prev
        prev = err
    assert prev < 1e-4 * (math.pi / 2 * mu * fn).max()
    unit = -slip / np.linalg.norm(slip, axis=1)[:, None]
    np.testing.assert_allclose(ff / mag[:, None], unit, atol=1e-12)


def test_treadmill_ground_speed_is_subtracted_from_slip():
    c = Volumetric("s", R=0.05, ground_speed=-1.0)
    out = c.evaluate_kinematics(_kin_at_heights(np.array([0.04]), vx=-1.0))  # riding on the belt
    assert np.abs(out.friction).max() < 1e-9


# -- wrenches and kinematics ------------------------------------------------------------

def _random_motion(model, n=40, seed=0):
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(0.03, 0.1, n), rng.uniform(-0.5, 0.5, n),
                         rng.uniform(-0.6, 0.3, n)])
    v = rng.normal(size=(n, 4))
    return Motion(np.arange(n) * 0.01, q, v, np.zeros_like(q))


@pytest.mark.parametrize("kind", ["point", "volumetric", "hypervolumetric"])
def test_generalized_force_equals_rnea_external_wrench_path(foot, kind):
    mo = _random_motion(foot)
    cs = foot_contacts(foot, kind)
    for c in cs:
        cache = c.prepare(foot, mo)
        Q = c.generalized_force(foot, mo, cache=cache)
        out = c.evaluate(foot, mo, cache=cache)
        assert np.abs(out.normal).max() > 1.0  # the motion does load the sphere
        Q2 = external_generalized_force(foot, mo.q, [ExternalForce(c.target, out.force, out.point)])
        np.testing.assert_allclose(Q, Q2, atol=1e-8 * np.abs(Q2).max())


def test_hand_computed_generalized_force_on_foot2d(foot):
    """Flat foot at rest, 10 mm into the heel sphere: Q = (0, f, moment about the ankle, 0)."""
    geom = Foot2dGeometry.from_model(foot)
    c = Volumetric("heel", k_v=2e6, R=0.05, a_v=0.0, smoothing=1e-9)
    ay = -geom.heel[1] + 0.04
    mo = Motion(np.zeros(1), np.array([[0.3, ay, 0.0, 0.0]]), np.zeros((1, 4)), np.zeros((1, 4)))
    Q = c.generalized_force(foot, mo)
    f = 2e6 * cap_volume(0.01, 0.05)
    # the force acts at x = 0.3 + heel_x; foot_angle turns about -z, so its moment is -(r x F)_z
    np.testing.assert_allclose(Q[0], [0.0, f, -(geom.heel[0] * f), 0.0], rtol=1e-9, atol=1e-9)


def test_planar_kinematics_match_pinocchio(foot):
    mo = _random_motion(foot, n=25, seed=3)
    kin = foot2d_site_kinematics(Foot2dGeometry.from_model(foot), mo.q, mo.v)
    for s in SITES:
        ref = site_kinematics(foot, s, mo.q, mo.v, jacobian=False)
        for a in ("position", "rotation", "velocity", "omega"):
            np.testing.assert_allclose(getattr(kin[s], a), getattr(ref, a), atol=1e-12)


def test_contacts_on_gait2d_sites():
    from pinmsk.model import load_model
    gait = load_model("gait2d")
    cs = foot_contacts(gait, "hypervolumetric", side="r")
    assert [c.target for c in cs] == ["heel_r", "metatarsal_r", "toe_r"]
    m2 = gait.with_effect(*cs)
    assert len(m2.contacts) == 3


# -- totals, COP ------------------------------------------------------------------

def test_ground_reaction_cop_is_finite_without_load_and_exact_with_load(foot):
    cs = foot_contacts(foot, "hypervolumetric")
    geom = Foot2dGeometry.from_model(foot)
    q = np.array([[0.3, 0.5, 0.0, 0.0], [0.3, -geom.heel[1] + 0.04, 0.0, 0.0]])  # in the air / flat
    kin = foot2d_site_kinematics(geom, q, np.zeros_like(q))
    outs = [c.evaluate_kinematics(kin[s]) for s, c in zip(SITES, cs)]
    gr = ground_reaction(outs)
    assert np.all(np.isfinite(gr.cop)) and np.all(np.isfinite(gr.free_moment))
    assert not gr.loaded[0] and gr.loaded[1]
    fn = np.array([o.normal[1] for o in outs])
    x = np.array([o.point[1, 0] for o in outs])
    exact = (fn * x).sum() / fn.sum()
    spread = np.ptp(x)
    assert gr.cop[1, 0] == pytest.approx(exact, abs=1.0 / fn.sum() * spread)  # eps = 1 N weight
    assert gr.free_moment[1] == pytest.approx(0.0, abs=1e-9)  # sagittal: no free moment
    # with no load the COP falls back to the middle of the spheres
    assert gr.cop[0, 0] == pytest.approx(np.mean([o.point[0, 0] for o in outs]), abs=1e-6)


# -- components: parameters, pickling, bounds --------------------------------------

def test_component_declares_bounds_and_pickles():
    c = HyperVolumetric("heel", bounds={"R": (0.001, 0.055)}, k_h=1e6)
    assert c.kind == "contact" and c.label == "hypervolumetric:heel"
    assert c.params["R"].max == 0.055
    c2 = pickle.loads(pickle.dumps(c))
    assert c2 == c and c2.params["R"].max == 0.055
    with pytest.raises(ModelError, match="outside its bounds"):
        HyperVolumetric("heel", R=0.08)
    with pytest.raises(ModelError, match="unknown parameter"):
        HyperVolumetric("heel", bounds={"radius": (0, 1)})


def test_foot_contacts_thesis_bounds_and_relax(foot):
    cs = foot_contacts(foot, "volumetric")
    assert [c.params["R"].max for c in cs] == [0.055, 0.050, 0.045]
    assert not cs[0].params["dx"].vary
    assert foot_contacts(foot, "hypervolumetric", relax=True)[0].params["dy"].vary
    with pytest.raises(ModelError, match="unknown contact model"):
        foot_contacts(foot, "soft")
    with pytest.raises(ModelError, match="no frame"):
        foot_contacts(foot, "point", side="r")


# -- foot2d ------------------------------------------------------------------------

def test_foot2d_model(foot):
    assert foot.coordinates == ("ankle_x", "ankle_y", "foot_angle", "mtp")
    assert foot.mass == pytest.approx(1.4)
    geom = Foot2dGeometry.from_model(foot)
    assert np.hypot(*geom.heel[:2]) == pytest.approx(0.074)          # AH
    assert np.hypot(*geom.metatarsal[:2]) == pytest.approx(0.110)    # AP
    assert np.hypot(*geom.toe[:2]) == pytest.approx(0.073)           # PT
    cosb = geom.heel[:2] @ geom.metatarsal[:2] / (0.074 * 0.110)
    assert math.degrees(math.acos(cosb)) == pytest.approx(106.0)     # beta
    assert geom.heel[1] == pytest.approx(geom.metatarsal[1])         # sole flat at foot_angle = 0


def test_foot2d_files_are_generated():
    r = subprocess.run([sys.executable, str(REPO / "urdf" / "generate_foot2d.py"), "--check"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_contact_candidates(foot):
    from pinmsk.contact import synthetic_foot_trial
    tr = synthetic_foot_trial()
    cands = contact_candidates(foot, tr)
    assert [c.name for c in cands] == ["point", "volumetric", "hypervolumetric", "hypervolumetric_relaxed"]
    assert all(c.drivable for c in cands)
    assert cands[3].n_params > cands[2].n_params
    assert contact_candidates(foot, tr.drop(["ground_force_vy"])) == []


# -- contacts inside the model's dynamics ----------------------------------------------

def test_inverse_dynamics_with_contacts_equals_external_wrenches(foot):
    from pinmsk.dynamics import inverse_dynamics_array
    from pinmsk.skeleton import rnea
    mo = _random_motion(foot, n=20, seed=5)
    cs = foot_contacts(foot, "hypervolumetric")
    model = foot.with_effect(*cs)
    assert len(model.contacts) == 3
    tau = inverse_dynamics_array(model, mo)
    outs = [c.evaluate(foot, mo) for c in cs]
    ext = [ExternalForce(c.target, o.force, o.point) for c, o in zip(cs, outs)]
    np.testing.assert_allclose(tau, rnea(foot, mo.q, mo.v, mo.a, external=ext), atol=1e-8)


def test_dropped_foot_comes_to_rest_on_its_spheres(foot):
    """Forward dynamics: the unactuated foot falls 10 mm onto the ground and settles with F_y = m g."""
    from pinmsk.dynamics import simulate
    cs = foot_contacts(foot, "hypervolumetric", values={s: {"a_h": 5e8} for s in SITES})
    geom = Foot2dGeometry.from_model(foot)
    t = np.arange(0.0, 0.6 + 1e-9, 1e-3)
    q0 = np.array([0.0, -geom.heel[1] + 0.06, 0.0, 0.0])
    tr = simulate(foot.with_effect(*cs), t=t, q0=q0, v0=np.zeros(4))
    q = np.column_stack([tr[c] for c in foot.coordinates])
    v = np.column_stack([tr[f"{c}_speed"] for c in foot.coordinates])
    assert np.abs(v[-1]).max() < 1e-3
    mo = Motion(t[-1:], q[-1:], v[-1:], np.zeros((1, 4)))
    gr = ground_reaction([c.evaluate(foot, mo) for c in cs])
    assert gr.normal[0] == pytest.approx(foot.mass * 9.81, rel=1e-3)
    assert abs(gr.friction[0]) < 1e-6


# -- sphere centre offset and sidecar specs ------------------------------------------

@pytest.mark.parametrize("cls", [Volumetric, HyperVolumetric, HuntCrossley])
def test_center_offsets_the_sphere_in_the_site_frame(cls):
    h = np.array([0.0, 0.01, 0.03])
    sole = cls("s", center="sole")
    R = sole.values[sole.radius_name]
    plain = cls("s")
    # "sole": the centre is R above the site, i.e. the same as the plain sphere R higher
    np.testing.assert_allclose(sole.evaluate_kinematics(_kin_at_heights(h)).normal,
                               plain.evaluate_kinematics(_kin_at_heights(h + R)).normal, rtol=1e-12, atol=1e-12)
    # follows the radius
    big = sole.with_params({sole.radius_name: R * 0.9})
    np.testing.assert_allclose(big.evaluate_kinematics(_kin_at_heights(h)).penetration,
                               -h, atol=1e-12)
    fixed = cls("s", center=(0.0, 0.02))
    np.testing.assert_allclose(fixed.evaluate_kinematics(_kin_at_heights(h)).penetration, R - h - 0.02, atol=1e-12)
    assert pickle.loads(pickle.dumps(sole)).center == "sole"
    with pytest.raises(ModelError, match="center must be None, 'sole' or"):
        cls("s", center="top")


def test_from_spec_builds_components_and_names_bad_entries():
    from pinmsk.contact import from_spec
    c = from_spec({"type": "hypervolumetric", "frame": "heel_r", "radius": 0.048, "k_h": 9e5,
                   "params": {"mu_f": 0.3}, "bounds": {"k_h": [1e4, 1e7]}, "fixed": ["mu_f"]})
    assert isinstance(c, HyperVolumetric) and c.target == "heel_r" and c.center == "sole"
    assert c.values["R"] == 0.048 and c.values["k_h"] == 9e5 and c.values["mu_f"] == 0.3
    assert c.values["H"] == 0.74  # thesis heel value (Table 4.4) for the unspecified ones
    assert (c.params["k_h"].min, c.params["k_h"].max) == (1e4, 1e7) and c.params["R"].max == 0.055
    assert not c.params["mu_f"].vary and c.params["k_h"].vary
    p = from_spec({"type": "hunt_crossley", "frame": "toe", "radius": 0.04})
    assert isinstance(p, HuntCrossley) and p.values["L0"] == 0.04 and p.center is None
    v = from_spec({"type": "volumetric", "frame": "calcn", "center": [0.01, 0.02]})
    assert v.center == (0.01, 0.02) and v.values["k_v"] == Volumetric("x").values["k_v"]
    bad = [({"frame": "heel_r"}, "'type' must be one of"),
           ({"type": "elastic", "frame": "heel_r"}, "'type' must be one of"),
           ({"type": "volumetric"}, "give 'frame'"),
           ({"type": "volumetric", "frame": "heel_r", "k_h": 1.0}, "unknown key 'k_h'"),
           ({"type": "volumetric", "frame": "heel_r", "params": {"zz": 1}}, "no parameter 'zz'"),
           ({"type": "volumetric", "frame": "heel_r", "radius": 0.05, "R": 0.05}, "give the radius once"),
           ({"type": "volumetric", "frame": "heel_r", "center": "up"}, "center must be"),
           ({"type": "volumetric", "frame": "heel_r", "radius": 0.09}, "heel_r"),
           ({"type": "volumetric", "frame": "heel_r", "bounds": {"R": 3}}, "must be \\[lo, hi\\]"),
           ({"type": "volumetric", "frame": "heel_r", "fixed": ["zz"]}, "unknown parameter 'zz'")]
    for spec, msg in bad:
        with pytest.raises(ModelError, match=msg):
            from_spec(spec, where="gait2d.toml [[contacts]] #1")


@pytest.mark.parametrize("c", ALL, ids=lambda c: c.family)
def test_no_pulling_force_when_leaving_the_ground_fast(c):
    """The damping terms would make the force negative at fast lift-off; the ground cannot pull."""
    R = c.values[c.radius_name]
    c = c.with_params({k: v for k, v in (("a_s", 100.0), ("a_v", 100.0), ("a_h", 1e9)) if k in c.values})
    out = c.evaluate_kinematics(_kin_at_heights(np.full(3, R - 0.004), vy=np.array([0.0, 0.5, 5.0])))
    assert out.normal[0] > 1.0 and np.all(out.normal >= 0) and out.normal[2] == 0.0
    assert np.all(out.friction[2] == 0.0)


def test_no_adhesion_is_c1_and_exact_above_eps():
    from pinmsk.contact.sphere import ADHESION_EPS, no_adhesion
    e = ADHESION_EPS
    x = np.linspace(-2 * e, 3 * e, 2001)
    g = no_adhesion(x)
    assert np.all(g[x <= 0] == 0) and np.array_equal(g[x >= e], x[x >= e])
    assert np.all(np.diff(g) >= 0)
    dg = np.gradient(g, x)
    assert np.max(np.abs(np.diff(dg))) < 0.02  # no jump in slope
