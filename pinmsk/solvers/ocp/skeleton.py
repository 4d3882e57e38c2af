"""The skeleton's dynamics as CasADi expressions, for the optimal-control engine.

The pip ``pin`` wheel has no ``pinocchio.casadi``, so the recursive Newton-Euler
algorithm is written here once more, on CasADi values (``SX``, ``MX`` or ``DM``),
from the constants of the Pinocchio model (joint placements, inertias, parents,
frames, joint axes).  Its numbers are Pinocchio's own convention, checked
against ``pin.rnea`` and ``pin.computeRNEADerivatives`` to 1e-10 on every
built-in model (tests/test_ocp_skeleton.py), and CasADi differentiates it
exactly (algorithmic differentiation, sparse).

Spatial algebra in Pinocchio's order: a motion is ``(v, w)`` (linear, angular),
a force ``(f, n)``, both expressed in the frame of the joint that carries them;
``liMi = (R, p)`` is joint ``i``'s placement in its parent's frame.  The
recursion is Featherstone, *Rigid Body Dynamics Algorithms* (2008), Table 5.1:

    v_i = liMi^-1 v_parent + S_i qd_i
    a_i = liMi^-1 a_parent + S_i qdd_i + v_i x S_i qd_i        (a_0 = -gravity)
    f_i = I_i a_i + v_i x* I_i v_i - fext_i
    tau_i = S_i^T f_i,   f_parent += liMi f_i                   (backwards)

:class:`RneaCallback` is the other road: ``pin.rnea`` as a CasADi black box with
the exact Jacobian of ``pin.computeRNEADerivatives``; benchmarks/bench_ocp_skeleton.py
measures both.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin

from ...errors import ModelError

__all__ = ["SymbolicSkeleton", "RneaCallback"]

_REVOLUTE = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0),
             "JointModelRevoluteUnaligned": None}
_PRISMATIC = {"JointModelPX": (1.0, 0.0, 0.0), "JointModelPY": (0.0, 1.0, 0.0), "JointModelPZ": (0.0, 0.0, 1.0),
              "JointModelPrismaticUnaligned": None}


def _pin_model(model) -> pin.Model:
    return model.pin if hasattr(model, "pin") else model


def _column(x, n: int, what: str):
    """``x`` as a CasADi column of length ``n`` (numbers become ``DM``)."""
    if isinstance(x, (ca.SX, ca.MX, ca.DM)):
        if x.numel() != n or min(x.shape) != 1:
            raise ModelError(f"{what} must be a column of length {n}; got shape {x.shape}")
        return x if x.shape[1] == 1 else x.T
    arr = np.asarray(x, dtype=float).ravel()
    if arr.size != n:
        raise ModelError(f"{what} must have {n} entries; got {arr.size}")
    return ca.DM(arr)


def _rotation(axis, c, s):
    """Rotation by the angle of cosine ``c``, sine ``s`` about the unit ``axis``: written out for the
    coordinate axes (as Pinocchio's RX/RY/RZ, no rounding), Rodrigues' formula
    ``c I + s [u]x + (1 - c) u u^T`` otherwise (as matrices: few CasADi operations to build)."""
    if axis == (1.0, 0.0, 0.0):
        return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))
    if axis == (0.0, 1.0, 0.0):
        return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
    if axis == (0.0, 0.0, 1.0):
        return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    u = np.array(axis)
    skew = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    return ca.DM(np.eye(3) - np.outer(u, u)) * c + ca.DM(skew) * s + ca.DM(np.outer(u, u))


def _act_inv(R, p, v, w):
    """``M^-1`` on the motion ``(v, w)`` (parent frame to child frame; ``M = (R, p)``)."""
    return ca.mtimes(R.T, v - ca.cross(p, w)), ca.mtimes(R.T, w)


def _act_force(R, p, f, n):
    """``M`` on the force ``(f, n)`` (child frame to parent frame)."""
    f2 = ca.mtimes(R, f)
    return f2, ca.mtimes(R, n) + ca.cross(p, f2)


class SymbolicSkeleton:
    """A Pinocchio skeleton's inverse dynamics and frame kinematics as CasADi expressions.

    ``SymbolicSkeleton(model)`` takes a pinmsk :class:`~pinmsk.model.Model` (or a ``pin.Model``) with
    1-dof revolute (RX/RY/RZ, RevoluteUnaligned) and prismatic (PX/PY/PZ, PrismaticUnaligned) joints,
    every joint type of the built-in models; other joint types are refused by name.  Inputs are numpy
    arrays or CasADi ``SX``/``MX``/``DM`` columns of length ``nq``/``nv``; outputs are CasADi values
    (``DM`` when every input is a number).
    """

    def __init__(self, model):
        pm = _pin_model(model)
        self.pin = pm
        self.nq, self.nv = pm.nq, pm.nv
        self.gravity = np.array(pm.gravity.linear, dtype=float)
        self.parents = [int(j) for j in pm.parents]
        self.joints = []            # per joint 1..njoints-1: (kind 'R'/'P', axis, idx_v)
        self.placements = []        # jointPlacements: (R, p) numpy
        self.inertias = []          # (mass, lever, rotational inertia about the com)
        for i in range(1, pm.njoints):
            jm = pm.joints[i]
            kind = jm.shortname()
            if kind in _REVOLUTE:
                axis = _REVOLUTE[kind] or tuple(float(a) for a in jm.extract().axis)
                self.joints.append(("R", axis, jm.idx_v))
            elif kind in _PRISMATIC:
                axis = _PRISMATIC[kind] or tuple(float(a) for a in jm.extract().axis)
                self.joints.append(("P", axis, jm.idx_v))
            else:
                raise ModelError(f"joint {pm.names[i]!r} (index {i}) has type {kind}, which the CasADi skeleton "
                                 f"does not support (supported: {', '.join([*_REVOLUTE, *_PRISMATIC])})")
            M = pm.jointPlacements[i]
            self.placements.append((np.array(M.rotation), np.array(M.translation)))
            Y = pm.inertias[i]
            self.inertias.append((float(Y.mass), np.array(Y.lever), np.array(Y.inertia)))
        self.frames = {f.name: (int(f.parentJoint), np.array(f.placement.rotation), np.array(f.placement.translation))
                       for f in pm.frames}
        self._function = None
        self._last = None

    # -- the recursion ------------------------------------------------------------------------------
    def _joint_placement(self, i, q):
        """``liMi(q) = jointPlacement * joint(q)`` of joint ``i`` (1-based) as (R, p)."""
        kind, axis, iv = self.joints[i - 1]
        R0, p0 = self.placements[i - 1]
        if kind == "R":
            return ca.mtimes(ca.DM(R0), _rotation(axis, ca.cos(q[iv]), ca.sin(q[iv]))), ca.DM(p0)
        return ca.DM(R0), ca.DM(p0) + ca.mtimes(ca.DM(R0), ca.DM(axis)) * q[iv]

    def _subspace(self, i, x):
        """``S_i x``: the joint's motion for the scalar ``x`` of its dof, as (v, w)."""
        kind, axis, _ = self.joints[i - 1]
        u = ca.DM(axis)
        return (ca.DM.zeros(3), u * x) if kind == "R" else (u * x, ca.DM.zeros(3))

    def _placements(self, q):
        """(local liMi, world oMi) of every joint; index 0 is the universe.  The last answer is kept for
        same ``q`` (the same symbols or numbers), so the frames of one node share one set of expressions."""
        last = self._last
        if last is not None and type(last[0]) is type(q) and ca.is_equal(last[0], q, 0):
            return last[1]
        local, world = [None], [(ca.DM.eye(3), ca.DM.zeros(3))]
        for i in range(1, len(self.parents)):
            R, p = self._joint_placement(i, q)
            Rp, pp = world[self.parents[i]]
            local.append((R, p))
            world.append((ca.mtimes(Rp, R), pp + ca.mtimes(Rp, p)))
        self._last = (type(q)(q), (local, world))    # a copy: q may be assigned to in place
        return local, world

    def _velocities(self, q, v, local):
        vel = [(ca.DM.zeros(3), ca.DM.zeros(3))]
        for i in range(1, len(self.parents)):
            R, p = local[i]
            vl, wl = _act_inv(R, p, *vel[self.parents[i]])
            sv, sw = self._subspace(i, v[self.joints[i - 1][2]])
            vel.append((vl + sv, wl + sw))
        return vel

    def rnea(self, q, v, a, fext=None):
        """Joint torques ``tau (nv,)`` for ``q, v, a`` under the model's gravity: ``pin.rnea``'s convention.

        ``fext``: optional ``{joint index: (force (3,), moment (3,))}``, each in that joint's LOCAL frame,
        as Pinocchio's ``fext`` (subtracted from the body's force, so ``tau`` drops by ``J^T fext``).
        """
        q, v, a = _column(q, self.nq, "q"), _column(v, self.nv, "v"), _column(a, self.nv, "a")
        fext = self._fext(fext)
        n = len(self.parents)
        local, _ = self._placements(q)
        vel = self._velocities(q, v, local)
        acc = [(ca.DM(-self.gravity), ca.DM.zeros(3))]
        forces = [None]
        for i in range(1, n):                        # forward: accelerations and body forces
            R, p = local[i]
            al, bl = _act_inv(R, p, *acc[self.parents[i]])
            iv = self.joints[i - 1][2]
            sv, sw = self._subspace(i, a[iv])
            cv, cw = self._subspace(i, v[iv])        # v_i x S qd
            vi, wi = vel[i]
            acc.append((al + sv + ca.cross(wi, cv) + ca.cross(vi, cw), bl + sw + ca.cross(wi, cw)))
            forces.append(self._body_force(i, vel[i], acc[i], fext.get(i)))
        tau = [None] * self.nv
        for i in range(n - 1, 0, -1):                # backward: torques, forces to the parent
            f, m = forces[i]
            kind, axis, iv = self.joints[i - 1]
            tau[iv] = ca.dot(ca.DM(axis), m if kind == "R" else f)
            if self.parents[i] > 0:
                R, p = local[i]
                fp, mp = _act_force(R, p, f, m)
                f0, m0 = forces[self.parents[i]]
                forces[self.parents[i]] = (f0 + fp, m0 + mp)
        return ca.vertcat(*tau)

    def _body_force(self, i, vel, acc, ext):
        """``I a + v x* I v - fext`` of body ``i`` (Pinocchio's inertia: mass, com lever, inertia at com)."""
        mass, c, Ic = self.inertias[i - 1]
        c, Ic = ca.DM(c), ca.DM(Ic)

        def inertia_times(v, w):
            f = mass * (v - ca.cross(c, w))
            return f, ca.mtimes(Ic, w) + ca.cross(c, f)
        fa, ma = inertia_times(*acc)
        hv, hw = inertia_times(*vel)
        v, w = vel
        f, m = fa + ca.cross(w, hv), ma + ca.cross(w, hw) + ca.cross(v, hv)
        if ext is not None:
            f, m = f - ext[0], m - ext[1]
        return f, m

    def _fext(self, fext):
        if fext is None:
            return {}
        out = {}
        for j, fm in dict(fext).items():
            if not isinstance(j, (int, np.integer)) or not 1 <= j < len(self.parents):
                raise ModelError(f"fext key {j!r} is not a joint index of the model (1..{len(self.parents) - 1})")
            try:
                force, moment = fm
            except (TypeError, ValueError):
                raise ModelError(f"fext[{j}] must be a pair (force (3,), moment (3,))") from None
            out[int(j)] = (_column(force, 3, f"fext[{j}] force"), _column(moment, 3, f"fext[{j}] moment"))
        return out

    # -- frames -------------------------------------------------------------------------------------
    def _frame(self, name):
        try:
            return self.frames[name]
        except KeyError:
            raise ModelError(f"frame {name!r} is not in the model (frames: {', '.join(self.frames)})") from None

    def frame_placement(self, name: str, q):
        """World placement ``(R (3x3), p (3,))`` of the Pinocchio frame ``name`` (joints, bodies and
        operational frames such as contact sites), as ``pin.updateFramePlacements``'s ``oMf``."""
        j, Rf, pf = self._frame(name)
        _, world = self._placements(_column(q, self.nq, "q"))
        R, p = world[j]
        return ca.mtimes(R, ca.DM(Rf)), p + ca.mtimes(R, ca.DM(pf))

    def frame_velocity(self, name: str, q, v):
        """``(v_lin (3,), omega (3,))`` of the origin of frame ``name``, world-aligned (Pinocchio's
        ``getFrameVelocity(..., LOCAL_WORLD_ALIGNED)``)."""
        j, _, pf = self._frame(name)
        q, v = _column(q, self.nq, "q"), _column(v, self.nv, "v")
        local, world = self._placements(q)
        vj, wj = self._velocities(q, v, local)[j]
        R = world[j][0]
        return ca.mtimes(R, vj + ca.cross(wj, ca.DM(pf))), ca.mtimes(R, wj)

    def world_wrench_torque(self, q, name: str, force, moment):
        """Generalized force ``(nv,)`` of the world-aligned ``force`` applied at frame ``name``'s origin
        plus the world ``moment``: ``J^T (force, moment)`` with the LOCAL_WORLD_ALIGNED frame Jacobian."""
        j, _, pf = self._frame(name)
        q = _column(q, self.nq, "q")
        force, moment = _column(force, 3, "force"), _column(moment, 3, "moment")
        _, world = self._placements(q)
        R, p = world[j]
        point = p + ca.mtimes(R, ca.DM(pf))
        tau = [ca.DM(0)] * self.nv
        while j > 0:                                 # the joints supporting the frame
            kind, axis, iv = self.joints[j - 1]
            Rj, pj = world[j]
            u = ca.mtimes(Rj, ca.DM(axis))
            tau[iv] = (ca.dot(ca.cross(u, point - pj), force) + ca.dot(u, moment)) if kind == "R" \
                else ca.dot(u, force)
            j = self.parents[j]
        return ca.vertcat(*tau)

    def casadi_function(self) -> ca.Function:
        """``casadi.Function('rnea', [q, v, a], [tau])`` in SX (built once)."""
        if self._function is None:
            q, v, a = ca.SX.sym("q", self.nq), ca.SX.sym("v", self.nv), ca.SX.sym("a", self.nv)
            self._function = ca.Function("rnea", [q, v, a], [self.rnea(q, v, a)], ["q", "v", "a"], ["tau"])
        return self._function


def _flat(x) -> np.ndarray:
    return np.asarray(x, dtype=float).ravel()


class RneaCallback(ca.Callback):
    """``pin.rnea`` as a CasADi black box ``(q, v, a) -> tau``, with the exact Jacobian of
    ``pin.computeRNEADerivatives`` (``[dtau/dq, dtau/dv, M]``); no second derivatives.

    Keep the Python object alive as long as any CasADi expression built with it is in use.
    """

    def __init__(self, model, name: str = "rnea_callback", opts: dict | None = None):
        ca.Callback.__init__(self)
        self.pin = _pin_model(model)
        self.data = self.pin.createData()
        self._jac = None
        self.construct(name, dict(opts or {}))

    def get_n_in(self):
        return 3

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ("q", "v", "a")[i]

    def get_name_out(self, i):
        return "tau"

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.pin.nq if i == 0 else self.pin.nv, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(self.pin.nv, 1)

    def eval(self, arg):
        return [pin.rnea(self.pin, self.data, _flat(arg[0]), _flat(arg[1]), _flat(arg[2]))]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _RneaJacobian(self.pin, name, inames, onames, opts)
        return self._jac


class _RneaJacobian(ca.Callback):
    """Jacobian of :class:`RneaCallback`: inputs ``(q, v, a, tau)``, outputs ``dtau/dq, dtau/dv, dtau/da``."""

    def __init__(self, pmodel, name, inames, onames, opts):
        ca.Callback.__init__(self)
        self.pin, self.data = pmodel, pmodel.createData()
        self._inames, self._onames = list(inames), list(onames)
        self.construct(name, dict(opts or {}))

    def get_n_in(self):
        return 4

    def get_n_out(self):
        return 3

    def get_name_in(self, i):
        return self._inames[i]

    def get_name_out(self, i):
        return self._onames[i]

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.pin.nq if i == 0 else self.pin.nv, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(self.pin.nv, self.pin.nq if i == 0 else self.pin.nv)

    def eval(self, arg):
        dq, dv, M = pin.computeRNEADerivatives(self.pin, self.data, _flat(arg[0]), _flat(arg[1]), _flat(arg[2]))
        M = np.triu(M) + np.triu(M, 1).T            # Pinocchio fills the upper triangle of M
        return [dq, dv, M]
