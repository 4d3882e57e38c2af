"""Batch rigid-body dynamics: round trips, conservation laws and hand calculations."""
import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk import skeleton
from pinmsk.errors import ModelError

MODELS = ["finger", "forearm", "gait2d", "human3d"]

# Winter's anthropometry for the forearm model (80 kg, 1.80 m), computed here independently of the URDF.
BM, BH, G = 80.0, 1.80, 9.81
M_F, L_F = 0.016 * BM, 0.146 * BH
M_H, L_H = 0.006 * BM, 0.108 * BH
D_F = 0.430 * L_F                 # forearm COM from the elbow
D_H = L_F + 0.506 * L_H           # hand COM from the elbow
D_COM = (M_F * D_F + M_H * D_H) / (M_F + M_H)


def _random_state(model, n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.0, 1.0, (n, model.nq))
    v = rng.uniform(-2.0, 2.0, (n, model.nv))
    a = rng.uniform(-5.0, 5.0, (n, model.nv))
    return q, v, a


@pytest.mark.parametrize("name", MODELS)
def test_aba_inverts_rnea(name):
    model = pinmsk.load_model(name)
    q, v, a = _random_state(model, 40)
    tau = skeleton.rnea(model, q, v, a)
    a2 = skeleton.forward_dynamics(model, q, v, tau)
    assert np.max(np.abs(a2 - a)) < 1e-9


@pytest.mark.parametrize("name", ["forearm", "gait2d"])
def test_batch_matches_per_frame_and_mass_matrix(name):
    model = pinmsk.load_model(name)
    q, v, a = _random_state(model, 25, seed=3)
    tau = skeleton.rnea(model, q, v, a)
    pm, pd = model.pin, model.create_data().pin
    for i in (0, 7, 24):
        assert np.allclose(tau[i], pin.rnea(pm, pd, q[i], v[i], a[i]), atol=1e-12)
    M = skeleton.mass_matrix(model, q)
    h = skeleton.nonlinear_effects(model, q, v)
    assert np.allclose(np.einsum("nij,nj->ni", M, a) + h, tau, atol=1e-9)
    assert np.allclose(M, np.transpose(M, (0, 2, 1)))


def test_batched_rnea_is_the_per_frame_loop_in_chunks(monkeypatch):
    """A pinmsk model's frames go through Pinocchio's batch rneaInParallel (one thread) on the compacted
    skeleton, chunk by chunk: the per-frame pin.rnea numbers to rounding, with and without loads,
    progress told every chunk; no frames, no output rows."""
    model = pinmsk.load_model("gait2d")
    q, v, a = _random_state(model, 11, seed=5)
    pm, pd = model.pin, model.pin.createData()
    want = np.stack([pin.rnea(pm, pd, q[i], v[i], a[i]) for i in range(11)])
    monkeypatch.setattr(skeleton, "PROGRESS_CHUNK", 4)
    seen = []
    progress = type("P", (), {"update": lambda self, k: seen.append(k)})()
    np.testing.assert_allclose(skeleton.rnea(model, q, v, a, progress=progress), want, rtol=1e-13, atol=1e-11)
    assert seen == [4, 4, 3]
    ext = [skeleton.ExternalForce("foot_r", np.tile([10.0, 500.0, 0.0], (11, 1)), np.zeros((11, 3)))]
    loaded = skeleton.rnea(model, q, v, a, external=ext)
    assert np.allclose(loaded, skeleton.rnea(pm, q, v, a, external=ext), atol=1e-9)   # bare model: the loop
    assert skeleton.rnea(model, q[:0], v[:0], a[:0]).shape == (0, model.nv)


@pytest.mark.parametrize("name, joints", [("human3d", (37, 18)), ("gait2d", (12, 10)), ("forearm", (2, 2))])
def test_compact_skeleton_folds_massless_chains_and_keeps_the_dynamics(name, joints):
    """Chains of joints with nothing between them but the next joint become one composite joint: fewer
    joints, the same q/v layout, the same RNEA, mass matrix and gravity to rounding; a model with no
    such chain is returned as it is."""
    model = pinmsk.load_model(name)
    pm = model.pin
    pc = skeleton.compact_skeleton(pm)
    assert (pm.njoints, pc.njoints) == joints
    if joints[0] == joints[1]:
        assert pc is pm
        return
    assert (pc.nq, pc.nv) == (pm.nq, pm.nv)
    assert sum(i.mass for i in pc.inertias) == pytest.approx(sum(i.mass for i in pm.inertias), rel=1e-15)
    q, v, a = _random_state(model, 20, seed=3)
    d0, d1 = pm.createData(), pc.createData()
    for k in range(20):
        tau0 = pin.rnea(pm, d0, q[k], v[k], a[k])
        np.testing.assert_allclose(pin.rnea(pc, d1, q[k], v[k], a[k]), tau0, rtol=1e-12,
                                   atol=1e-12 * (1 + np.abs(tau0).max()))
        M0 = pin.crba(pm, d0, q[k])
        np.testing.assert_allclose(np.triu(pin.crba(pc, d1, q[k])), np.triu(M0), atol=1e-12 * np.abs(M0).max())


def test_forearm_gravity_moment_at_90_degrees_matches_hand_calculation():
    model = pinmsk.load_model("forearm")
    g = skeleton.gravity_torque(model, np.array([[np.pi / 2]]))[0, 0]
    expected = (M_F + M_H) * G * D_COM          # 3.1195 N m to hold the forearm horizontal
    assert g == pytest.approx(expected, rel=1e-9)
    assert expected == pytest.approx(3.1195, abs=1e-3)
    # and the static torque follows sin(q)
    qs = np.linspace(0, 2.6, 9)[:, None]
    assert np.allclose(skeleton.gravity_torque(model, qs)[:, 0], expected * np.sin(qs[:, 0]), atol=1e-12)


def test_forearm_total_inertia_about_elbow():
    model = pinmsk.load_model("forearm")
    i_elbow = (M_F * ((0.303 * L_F) ** 2 + D_F ** 2) + M_H * ((0.297 * L_H) ** 2 + D_H ** 2))
    M = skeleton.mass_matrix(model, np.zeros((1, 1)))[0, 0, 0]
    assert M == pytest.approx(i_elbow, rel=1e-9)


def test_unactuated_forearm_conserves_energy_rk4():
    model = pinmsk.load_model("forearm")
    t = np.arange(5001) * 1e-3                       # 5 s at 1 kHz
    q, v, _ = skeleton.integrate(model, [2.0], [0.0], t, method="rk4")
    e = skeleton.mechanical_energy(model, q, v)
    ke_max = np.max(0.5 * skeleton.mass_matrix(model, q[:1])[0, 0, 0] * v[:, 0] ** 2)
    assert ke_max > 1.0                               # it really swings
    assert np.max(np.abs(e - e[0])) / ke_max < 1e-6
    assert q[:, 0].min() < -1.9                        # swings through to the other side


def test_rk4_and_solve_ivp_agree():
    model = pinmsk.load_model("forearm")
    t = np.linspace(0, 1.0, 501)
    q1, v1, _ = skeleton.integrate(model, [1.0], [0.5], t, method="rk4")
    q2, v2, _ = skeleton.integrate(model, [1.0], [0.5], t, method="DOP853", rtol=1e-11, atol=1e-12)
    assert np.max(np.abs(q1 - q2)) < 1e-8
    assert np.max(np.abs(v1 - v2)) < 1e-7


def test_external_force_at_hand_matches_lever_arm():
    """World-frame 10 N downward load at the hand COM with the forearm horizontal: lever D_H."""
    model = pinmsk.load_model("forearm")
    q = np.array([[np.pi / 2]])
    z = np.zeros((1, 1))
    hand = model.pin.frames[model.frame_id("hand")]
    pd = model.create_data().pin
    pin.framesForwardKinematics(model.pin, pd, q[0])
    p_hand = pd.oMf[model.frame_id("hand")].translation.copy()
    # the hand COM lies D_H in front of the elbow when horizontal (+x), at elbow height
    elbow = pd.oMi[hand.parentJoint].translation
    assert np.allclose(p_hand - elbow, [D_H, 0, 0], atol=1e-12)
    ext = skeleton.ExternalForce("hand", force=[[0.0, -10.0, 0.0]], point=[p_hand])
    base = skeleton.rnea(model, q, z, z)[0, 0]
    loaded = skeleton.rnea(model, q, z, z, external=[ext])[0, 0]
    assert loaded - base == pytest.approx(10.0 * D_H, rel=1e-12)
    # the same force applied 5 cm further out needs 0.5 N m more, and a free torque adds directly
    ext2 = skeleton.ExternalForce("hand", force=[[0.0, -10.0, 0.0]], point=[p_hand + [0.05, 0, 0]],
                                  torque=[[0.0, 0.0, 2.0]])
    loaded2 = skeleton.rnea(model, q, z, z, external=[ext2])[0, 0]
    assert loaded2 - base == pytest.approx(10.0 * (D_H + 0.05) - 2.0, rel=1e-12)
    jtf = skeleton.external_generalized_force(model, q, [ext])
    assert jtf[0, 0] == pytest.approx(-10.0 * D_H, rel=1e-12)


def test_derivatives_match_finite_differences():
    model = pinmsk.load_model("gait2d")
    q, v, a = _random_state(model, 2, seed=5)
    dq, dv, M = skeleton.rnea_derivatives(model, q, v, a)
    eps = 1e-6
    for j in (0, 3, 6):
        e = np.zeros(model.nv)
        e[j] = eps
        fd = (skeleton.rnea(model, q + e, v, a) - skeleton.rnea(model, q - e, v, a)) / (2 * eps)
        assert np.allclose(dq[:, :, j], fd, atol=1e-5)
        fdv = (skeleton.rnea(model, q, v + e, a) - skeleton.rnea(model, q, v - e, a)) / (2 * eps)
        assert np.allclose(dv[:, :, j], fdv, atol=1e-5)
    tau = skeleton.rnea(model, q, v, a)
    daq, dav, dtau = skeleton.aba_derivatives(model, q, v, tau)
    assert np.allclose(np.einsum("nij,njk->nik", dtau, M), np.eye(model.nv), atol=1e-8)


def test_shape_errors_are_clear():
    model = pinmsk.load_model("forearm")
    with pytest.raises(ModelError, match=r"q must have shape \(N, 1\)"):
        skeleton.rnea(model, np.zeros((3, 2)), np.zeros((3, 1)), np.zeros((3, 1)))
    with pytest.raises(ModelError, match="frames"):
        skeleton.rnea(model, np.zeros((3, 1)), np.zeros((2, 1)), np.zeros((3, 1)))
    with pytest.raises(ModelError, match="no frame or body 'hnad'.*'hand'"):
        skeleton.rnea(model, np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)),
                                  external=[skeleton.ExternalForce("hnad", [[0, 1, 0]], [[0, 0, 0]])])


def _branched_model(extra_root=None):
    """Two branches off a common trunk, every joint type the batched load path poses itself (and, with
    ``extra_root``, a joint it does not), random placements and inertias."""
    rng = np.random.default_rng(3)
    pm = pin.Model()

    def add(parent, jm, name):
        M = pin.SE3(pin.exp3(rng.uniform(-1, 1, 3)), rng.uniform(-0.3, 0.3, 3))
        j = pm.addJoint(parent, jm, M, name)
        pm.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
        return j

    trunk = 0 if extra_root is None else add(0, extra_root, "extra")
    for jm, name in [(pin.JointModelPX(), "px"), (pin.JointModelPY(), "py"), (pin.JointModelPZ(), "pz"),
                     (pin.JointModelRZ(), "rz"), (pin.JointModelRX(), "rx"), (pin.JointModelRY(), "ry")]:
        trunk = add(trunk, jm, name)
    a, b = trunk, trunk
    for k, jm in enumerate([pin.JointModelRevoluteUnaligned(np.array([0.3, -0.5, 0.8]) / np.sqrt(0.98)),
                            pin.JointModelPrismaticUnaligned(np.array([-0.2, 0.9, 0.1]) / np.sqrt(0.86)),
                            pin.JointModelRX()]):
        a = add(a, jm, f"a{k}")
    for k, jm in enumerate([pin.JointModelRY(), pin.JointModelPX(), pin.JointModelRZ()]):
        b = add(b, jm, f"b{k}")
    return pm


@pytest.mark.parametrize("extra_root", [None, pin.JointModelSpherical()], ids=["batched", "jacobians"])
def test_external_loads_match_pinocchios_local_fext(extra_root):
    """World wrenches on a branched skeleton (loads on both leaves, on the trunk, two on one body) give
    Pinocchio's own rnea with each wrench moved into its joint's frame (oMi.actInv), frame by frame."""
    pm = _branched_model(extra_root)
    rng = np.random.default_rng(4)
    n = 7
    q = np.stack([pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq)) for _ in range(n)])
    v, a = rng.uniform(-2, 2, (n, pm.nv)), rng.uniform(-5, 5, (n, pm.nv))
    loads = [skeleton.ExternalForce(body, rng.normal(0, 300, (n, 3)), rng.normal(0, 0.5, (n, 3)),
                                    rng.normal(0, 20, (n, 3))) for body in ("a2", "b2", "b2", "rx")]
    got = skeleton.rnea(pm, q, v, a, external=loads)
    loaded = tuple(sorted({pm.getJointId(e.frame) for e in loads}))
    assert (skeleton._support_tree(pm, loaded) is None) == (extra_root is not None)   # the path under test
    pd = pm.createData()
    for i in range(n):
        pin.forwardKinematics(pm, pd, q[i])
        fext = pin.StdVec_Force()
        for _ in range(pm.njoints):
            fext.append(pin.Force.Zero())
        for e in loads:
            j = pm.getJointId(e.frame)
            W = skeleton.world_wrench(e, n)[i]
            fext[j] = fext[j] + pd.oMi[j].actInv(pin.Force(W[:3], W[3:]))
        want = pin.rnea(pm, pd, q[i], v[i], a[i], fext)
        assert np.abs(got[i] - want).max() < 1e-9 * max(1.0, np.abs(want).max())
