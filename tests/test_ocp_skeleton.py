"""The CasADi skeleton of the optimal-control engine against Pinocchio, on every built-in model.

``SymbolicSkeleton`` re-writes the RNEA on CasADi values (the pip ``pin`` wheel has no
``pinocchio.casadi``); here its value, its CasADi Jacobians, its frame kinematics and its contact
Jacobian are held to Pinocchio's own numbers to 1e-10 at 20 random states per model, and
``RneaCallback`` (``pin.rnea`` in a CasADi callback) to ``pin.computeRNEADerivatives``.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pinmsk import load_model
from pinmsk.errors import ModelError

from conftest import LazyCasadi  # noqa: E402

ca = LazyCasadi()   # imported inside the tests (tests/conftest.py)



def SymbolicSkeleton(*args, **kw):   # pinmsk.solvers.ocp.skeleton imports casadi: not at collection
    from pinmsk.solvers.ocp.skeleton import SymbolicSkeleton as cls
    return cls(*args, **kw)


def RneaCallback(*args, **kw):
    from pinmsk.solvers.ocp.skeleton import RneaCallback as cls
    return cls(*args, **kw)

BUILTIN = ["finger", "forearm", "gait2d", "foot2d", "human3d"]
N = 20
TOL = 1e-10
OSIM_2D = "opensim-models/Moco2DWalking/2D_gait.osim"


def _states(pm, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-np.pi, np.pi, (N, pm.nq)), rng.normal(0, 2, (N, pm.nv)), rng.normal(0, 5, (N, pm.nv))


def _mapped(f, *cols):
    """``f`` on N states at once (``f.map``), each output as an (N, ...) numpy array."""
    out = f.map(N)(*[c.T for c in cols])
    out = out if isinstance(out, (list, tuple)) else [out]
    return [np.asarray(o) for o in out]


def _frames_to_check(pm):
    """Every frame of the small models; about 10 spread frames of the big ones, with the last one."""
    ids = list(range(pm.nframes))
    return ids if len(ids) <= 40 else sorted(set(ids[:: len(ids) // 9] + [ids[-1]]))


def _check_skeleton(pm):
    sk = SymbolicSkeleton(pm)
    data = pm.createData()
    Q, V, A = _states(pm)
    q, v, a = ca.SX.sym("q", pm.nq), ca.SX.sym("v", pm.nv), ca.SX.sym("a", pm.nv)

    # tau and its exact Jacobians
    tau = sk.rnea(q, v, a)
    jac = ca.Function("j", [q, v, a], [tau, ca.jacobian(tau, q), ca.jacobian(tau, v), ca.jacobian(tau, a)])
    T, Jq, Jv, Ja = _mapped(jac, Q, V, A)
    T = T.T
    Jq, Jv, Ja = (J.reshape(pm.nv, N, -1).transpose(1, 0, 2) for J in (Jq, Jv, Ja))
    for k in range(N):
        np.testing.assert_allclose(T[k], pin.rnea(pm, data, Q[k], V[k], A[k]), rtol=0, atol=TOL)
        dq, dv, M = pin.computeRNEADerivatives(pm, data, Q[k], V[k], A[k])
        np.testing.assert_allclose(Jq[k], dq, rtol=0, atol=TOL)
        np.testing.assert_allclose(Jv[k], dv, rtol=0, atol=TOL)
        np.testing.assert_allclose(Ja[k], np.triu(M) + np.triu(M, 1).T, rtol=0, atol=TOL)
    # the cached Function and the numeric path give the same numbers
    np.testing.assert_allclose(np.asarray(sk.casadi_function()(Q[0], V[0], A[0])).ravel(), T[0], rtol=0, atol=TOL)
    np.testing.assert_allclose(np.asarray(sk.rnea(Q[1], V[1], A[1])).ravel(), T[1], rtol=0, atol=TOL)

    # external forces, joint-local as Pinocchio's fext (symbolic, so every joint gets its own)
    rng = np.random.default_rng(1)
    FE = rng.normal(0, 50, (pm.njoints, 6))
    fsym = ca.SX.sym("fe", 6 * (pm.njoints - 1))
    fext = {j: (fsym[6 * (j - 1): 6 * j - 3], fsym[6 * j - 3: 6 * j]) for j in range(1, pm.njoints)}
    with_f = ca.Function("f", [q, v, a, fsym], [sk.rnea(q, v, a, fext=fext)])
    pin_f = [pin.Force(FE[j, :3], FE[j, 3:]) for j in range(pm.njoints)]
    for k in range(3):
        got = np.asarray(with_f(Q[k], V[k], A[k], FE[1:].ravel())).ravel()
        np.testing.assert_allclose(got, pin.rnea(pm, data, Q[k], V[k], A[k], pin_f), rtol=0, atol=TOL)

    # frames: placement, LOCAL_WORLD_ALIGNED velocity and Jacobian transpose of a world wrench
    F, Mo = ca.SX.sym("F", 3), ca.SX.sym("M", 3)
    for fid in _frames_to_check(pm):
        name = pm.frames[fid].name
        R, p = sk.frame_placement(name, q)
        vl, w = sk.frame_velocity(name, q, v)
        gf = sk.world_wrench_torque(q, name, F, Mo)
        fr = ca.Function("fr", [q, v, F, Mo], [ca.vec(R), p, vl, w, gf])
        force, moment = rng.normal(0, 100, 3), rng.normal(0, 10, 3)
        for k in range(0, N, 4):
            Rk, pk, vk, wk, gk = (np.asarray(x).ravel() for x in fr(Q[k], V[k], force, moment))
            pin.forwardKinematics(pm, data, Q[k], V[k])
            pin.computeJointJacobians(pm, data, Q[k])
            pin.updateFramePlacements(pm, data)
            oMf = data.oMf[fid]
            np.testing.assert_allclose(Rk.reshape(3, 3, order="F"), oMf.rotation, rtol=0, atol=TOL, err_msg=name)
            np.testing.assert_allclose(pk, oMf.translation, rtol=0, atol=TOL, err_msg=name)
            vel = pin.getFrameVelocity(pm, data, fid, pin.LOCAL_WORLD_ALIGNED)
            np.testing.assert_allclose(vk, vel.linear, rtol=0, atol=TOL, err_msg=name)
            np.testing.assert_allclose(wk, vel.angular, rtol=0, atol=TOL, err_msg=name)
            J = pin.getFrameJacobian(pm, data, fid, pin.LOCAL_WORLD_ALIGNED)
            np.testing.assert_allclose(gk, J.T @ np.r_[force, moment], rtol=0, atol=TOL, err_msg=name)

    # pin.rnea in a callback: value and Jacobian
    cb = RneaCallback(pm)
    qs, vs, as_ = ca.MX.sym("q", pm.nq), ca.MX.sym("v", pm.nv), ca.MX.sym("a", pm.nv)
    out = cb(qs, vs, as_)
    cbj = ca.Function("cbj", [qs, vs, as_], [out, ca.jacobian(out, ca.vertcat(qs, vs, as_))])
    for k in range(0, N, 4):
        t, J = (np.asarray(x) for x in cbj(Q[k], V[k], A[k]))
        np.testing.assert_allclose(t.ravel(), T[k], rtol=0, atol=TOL)
        np.testing.assert_allclose(J, np.hstack([Jq[k], Jv[k], Ja[k]]), rtol=0, atol=TOL)


@pytest.mark.parametrize("name", BUILTIN)
def test_symbolic_skeleton_matches_pinocchio(name):
    _check_skeleton(load_model(name).pin)


def test_symbolic_skeleton_on_imported_opensim_model(shared_data):
    """The planar Moco 2D walking model, with its contact sites (heel_r ...) as operational frames.

    Only its skeleton and contact sites are imported (what ``load_model`` builds the ``pin`` model
    from), without the muscle-path fits that cost ~3 s and do not enter the skeleton.
    """
    from pinmsk.opensim.contacts import contact_hook
    from pinmsk.opensim.importer import read_import
    pm = read_import(shared_data / OSIM_2D, hooks=(contact_hook,)).pin_model
    assert pm.existFrame("heel_r") and pm.frames[pm.getFrameId("heel_r")].type == pin.FrameType.OP_FRAME
    _check_skeleton(pm)


def test_unsupported_joint_is_refused_by_name():
    pm = pin.Model()
    j = pm.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "shoulder_ball")
    pm.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    with pytest.raises(ModelError, match=r"joint 'shoulder_ball' \(index 1\) has type JointModelSpherical"):
        SymbolicSkeleton(pm)


def test_bad_inputs_are_refused_by_name():
    sk = SymbolicSkeleton(load_model("gait2d"))
    z = np.zeros(11)
    with pytest.raises(ModelError, match="q must have 11 entries; got 3"):
        sk.rnea(np.zeros(3), z, z)
    with pytest.raises(ModelError, match="v must be a column of length 11"):
        sk.rnea(z, ca.SX.sym("v", 4), z)
    with pytest.raises(ModelError, match="frame 'heel' is not in the model"):
        sk.frame_placement("heel", z)
    with pytest.raises(ModelError, match="fext key 12 is not a joint index"):
        sk.rnea(z, z, z, fext={12: (np.zeros(3), np.zeros(3))})
    with pytest.raises(ModelError, match=r"fext\[3\] moment must have 3 entries"):
        sk.rnea(z, z, z, fext={3: (np.zeros(3), np.zeros(2))})


def test_kept_placements_follow_q():
    """The placements kept for the last ``q`` are not reused once ``q`` is assigned to in place."""
    pm = load_model("gait2d").pin
    sk = SymbolicSkeleton(pm)
    data = pm.createData()
    q0 = ca.SX.sym("q", pm.nq)
    q = ca.SX(q0)
    first = sk.frame_placement("heel_r", q)[1]
    q[2] = 0.3                                     # the torso angle fixed in place
    second = sk.frame_placement("heel_r", q)[1]
    f = ca.Function("p", [q0], [first, second])
    x = np.random.default_rng(2).uniform(-1, 1, pm.nq)
    got1, got2 = (np.asarray(y).ravel() for y in f(x))
    fid = pm.getFrameId("heel_r")
    pin.framesForwardKinematics(pm, data, x)
    np.testing.assert_allclose(got1, data.oMf[fid].translation, rtol=0, atol=TOL)
    x[2] = 0.3
    pin.framesForwardKinematics(pm, data, x)
    np.testing.assert_allclose(got2, data.oMf[fid].translation, rtol=0, atol=TOL)


def test_every_supported_joint_type():
    """PZ and PrismaticUnaligned appear in no built-in model: a random branched chain of all eight types,
    with an operational frame, held to Pinocchio the same way."""
    pin.seed(3)
    pm = pin.Model()
    types_ = [pin.JointModelPX(), pin.JointModelPY(), pin.JointModelPZ(),
              pin.JointModelPrismaticUnaligned(np.array([0.6, 0.0, 0.8])), pin.JointModelRX(), pin.JointModelRY(),
              pin.JointModelRZ(), pin.JointModelRevoluteUnaligned(np.array([0.0, -0.8, 0.6]))]
    parent = 0
    for k, jm in enumerate(types_):
        parent = pm.addJoint(parent if k != 5 else 2, jm, pin.SE3.Random(), f"j{k}")
        pm.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
    pm.addFrame(pin.Frame("site", parent, pin.SE3.Random(), pin.FrameType.OP_FRAME))
    assert {pm.joints[i].shortname() for i in range(1, pm.njoints)} == {j.shortname() for j in types_}
    _check_skeleton(pm)
