"""Forces between two body frames: a linear bushing and a point-to-point spring.

Both act between frame ``target`` (frame 1, on body 1) and frame ``frame2`` (on body 2; default the
ground), as OpenSim's ``BushingForce`` and ``PointToPointSpring`` do through Simbody's
``Force::LinearBushing`` and ``Force::TwoPointLinearSpring``:

:class:`LinearBushing` (``bushing``).  With ``F`` = frame 1 and ``M`` = frame 2 (world rotations
``R_F, R_M``, origins ``p_F, p_M``), ``R_FM = R_F^T R_M`` and ``p_FM = R_F^T (p_M - p_F)``, the six
deflections are the body-fixed X-Y-Z angles of ``R_FM`` and ``p_FM``; their rates are
``N(q) w_FM_M`` (``w_FM_M = R_M^T (w_M - w_F)``, ``N`` Simbody's ``calcNForBodyXYZInBodyFrame``)
and ``R_F^T ((v_M - v_F) - w_F x (p_M - p_F))``.  The generalized forces on the deflections are
``f = -(k q + c qdot)``; body 2 gets the moment ``R_M N^T f_rot`` and the force ``R_F f_trans`` at
``M``'s origin, body 1 the opposite force and ``-(moment + (p_M - p_F) x force)`` at ``F``'s origin
(``Force_LinearBushing.cpp``, ``ensureForceCacheValid``).  Parameters: the stiffnesses (N m/rad,
N/m) and dampings (N m s/rad, N s/m) about and along F's x, y, z; Q is linear in them.

:class:`PointToPointSpring` (``point_to_point_spring``): the points ``point1`` (in frame 1) and
``point2`` (in frame 2), ``d = x_2 - x_1``; body 1 gets ``k (|d| - L0) d / |d|`` at ``x_1`` and body
2 the opposite at ``x_2`` (``stiffness``, ``rest_length``).

The law is written once, on the components of 3-vectors and 3x3 matrices (numpy arrays over frames,
or CasADi scalars at one state): :meth:`FramePairForce.wrenches` takes both frames' world
kinematics and returns the world force and moment on each frame's origin.  ``generalized_force`` is
``J_1^T w_1 + J_2^T w_2`` with the frames' LOCAL_WORLD_ALIGNED Jacobians; the optimal-control engine
evaluates :meth:`FramePairForce.wrenches` on its symbolic frame kinematics.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
import pinocchio as pin

from ..backend import backend_of
from ..components import Component, Motion, Parameter, motion_cached, vec3
from ..errors import ModelError
from .registry import register

__all__ = ["FramePairForce", "LinearBushing", "PointToPointSpring", "frame_kinematics"]

GROUND = "universe"


def frame_kinematics(model, frame: str, motion: Motion, data=None):
    """``(R (N, 3, 3), p (N, 3), v (N, 3), w (N, 3), J (N, 6, nv))`` of a frame over the motion:
    world placement, LOCAL_WORLD_ALIGNED velocity of its origin and Jacobian (cached in ``data``)."""
    pm = model.pin
    fid = pm.getFrameId(frame)

    def compute(pd):
        n = motion.n_frames
        R, p = np.empty((n, 3, 3)), np.empty((n, 3))
        v, w, J = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 6, pm.nv))
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        for k in range(n):
            pin.forwardKinematics(pm, pd, motion.q[k], motion.v[k])
            pl = pin.updateFramePlacement(pm, pd, fid)
            R[k], p[k] = pl.rotation, pl.translation
            mv = pin.getFrameVelocity(pm, pd, fid, lwa)
            v[k], w[k] = mv.linear, mv.angular
            J[k] = np.reshape(pin.computeFrameJacobian(pm, pd, motion.q[k], fid, lwa), (6, pm.nv))
        return R, p, v, w, J

    return motion_cached(data, model, ("frame_kinematics", fid), motion, compute)


# -- 3-vector algebra on components (numpy over frames, or CasADi scalars) ------------------------

def _mv(R, x):
    return [R[i][0] * x[0] + R[i][1] * x[1] + R[i][2] * x[2] for i in range(3)]


def _mtv(R, x):
    return [R[0][i] * x[0] + R[1][i] * x[1] + R[2][i] * x[2] for i in range(3)]


def _mtm(A, B):
    """``A^T B``."""
    return [[A[0][i] * B[0][j] + A[1][i] * B[1][j] + A[2][i] * B[2][j] for j in range(3)] for i in range(3)]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _sub(a, b):
    return [x - y for x, y in zip(a, b)]


def _add(a, b):
    return [x + y for x, y in zip(a, b)]


def _neg(a):
    return [-x for x in a]


def body_xyz(R):
    """Body-fixed X-Y-Z angles of a rotation ``R = Rx(a) Ry(b) Rz(c)`` (Simbody's
    ``convertRotationToBodyFixedXYZ`` away from ``b = +-90`` degrees)."""
    xp = backend_of(R[0][0], R[0][2])
    s = xp.clip(R[0][2], -1.0, 1.0)
    return [xp.arctan2(-R[1][2], R[2][2]), xp.arcsin(s), xp.arctan2(-R[0][1], R[0][0])]


class FramePairForce(Component):
    """A force between frame ``target`` (frame 1) and frame ``frame2`` (the ground by default).

    Subclasses implement :meth:`wrenches`."""

    kind = "effect"
    level = "joint"
    target_kind = "frame"

    def __init__(self, target: str, *, frame2: str | None = None, **values: float):
        if not target:
            raise ModelError(f"{self.family}: give frame 1, the frame the force acts on")
        self.frame2 = GROUND if frame2 in (None, "", "ground") else str(frame2)
        super().__init__(target, **values)

    @classmethod
    def candidates(cls, model, context) -> list:
        """None: the diagnosis does not guess where a force between two frames would act."""
        return []

    @property
    def frames(self) -> tuple[str, str]:
        return (self.target, self.frame2)

    def check_target(self, model) -> None:
        for f in self.frames:
            if not model.pin.existFrame(f):
                raise ModelError(f"{self.label}: model '{model.name}' has no frame '{f}'")

    def affected_coordinates(self) -> tuple[str, ...]:
        return ()

    def wrenches(self, k1, k2, p):
        """``((force_1, moment_1), (force_2, moment_2))``: the world force and moment on each frame's
        origin, from each frame's ``(R, p, v, w)`` (components: ``R`` 3x3 nested, vectors of 3)."""
        raise NotImplementedError

    # -- evaluation ----------------------------------------------------------------------
    def prepare(self, model, motion: Motion, data=None):
        return tuple(frame_kinematics(model, f, motion, data) for f in self.frames)

    @staticmethod
    def _split(kin):
        R, p, v, w, _ = kin
        return ([[R[:, i, j] for j in range(3)] for i in range(3)], [p[:, i] for i in range(3)],
                [v[:, i] for i in range(3)], [w[:, i] for i in range(3)])

    def world_wrenches(self, model, motion: Motion, params=None, cache=None):
        """``(F_1, M_1, F_2, M_2)``, each ``(N, 3)``: the world force and moment on each frame's origin."""
        kin = cache if cache is not None else self.prepare(model, motion)
        (f1, m1), (f2, m2) = self.wrenches(self._split(kin[0]), self._split(kin[1]), self._p(params))
        n = motion.n_frames
        return tuple(np.column_stack([np.broadcast_to(np.asarray(c, dtype=float), (n,)) for c in x])
                     for x in (f1, m1, f2, m2))

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        """``J_1^T (F_1, M_1) + J_2^T (F_2, M_2)`` over frames, ``(N, nv)``."""
        kin = cache if cache is not None else self.prepare(model, motion)
        F1, M1, F2, M2 = self.world_wrenches(model, motion, params, kin)
        out = np.zeros((motion.n_frames, model.nv))
        for (_, _, _, _, J), F, M in ((kin[0], F1, M1), (kin[1], F2, M2)):
            out += np.einsum("nkv,nk->nv", J[:, :3, :], F) + np.einsum("nkv,nk->nv", J[:, 3:, :], M)
        return out

    def param_jacobian(self, model, motion: Motion, params=None, cache=None) -> np.ndarray:
        """``dQ/dtheta`` ``(N, nv, n_params)``, exact: :meth:`wrenches` on forward-mode
        :class:`~pinmsk.contact.dual.Dual` parameters, mapped by the frames' Jacobians."""
        from ..contact.dual import Dual
        kin = cache if cache is not None else self.prepare(model, motion)
        p = self._p(params)
        names = list(self.params)
        seeds = Dual.variables([p[n] for n in names])
        (f1, m1), (f2, m2) = self.wrenches(self._split(kin[0]), self._split(kin[1]),
                                           {n: seeds[i] for i, n in enumerate(names)})
        n, P = motion.n_frames, len(names)

        def der(vec):
            return np.stack([np.broadcast_to(c.der, (n, P)) if isinstance(c, Dual) else np.zeros((n, P))
                             for c in vec], axis=1)
        out = np.zeros((n, model.nv, P))
        for (_, _, _, _, J), F, M in ((kin[0], f1, m1), (kin[1], f2, m2)):
            out += np.einsum("nkv,nkp->nvp", J[:, :3, :], der(F)) + np.einsum("nkv,nkp->nvp", J[:, 3:, :], der(M))
        return out

    def generalized_force_on(self, skeleton, q, v):
        """The generalized force at one state on the optimal-control engine's symbolic skeleton
        (:class:`pinmsk.solvers.ocp.skeleton.SymbolicSkeleton`): :meth:`wrenches` on its frame
        kinematics, mapped by its ``world_wrench_torque``."""
        kins = []
        for f in self.frames:
            R, pos = skeleton.frame_placement(f, q)
            lin, ang = skeleton.frame_velocity(f, q, v)
            kins.append(([[R[i, j] for j in range(3)] for i in range(3)], [pos[i] for i in range(3)],
                         [lin[i] for i in range(3)], [ang[i] for i in range(3)]))
        import casadi as ca
        (f1, m1), (f2, m2) = self.wrenches(kins[0], kins[1], self.values)
        tau = 0
        for f, F, M in ((self.frames[0], f1, m1), (self.frames[1], f2, m2)):
            tau = tau + skeleton.world_wrench_torque(q, f, ca.vertcat(*F), ca.vertcat(*M))
        return tau

    def generalized_force_at(self, model, q, v):
        """Refused by name: the force needs both frames' kinematics, which the optimal-control engine
        computes on its own skeleton (:meth:`generalized_force_on`)."""
        raise ModelError(f"component {self.label} acts between two frames; evaluate generalized_force_on("
                         "skeleton, q, v) on the optimal-control engine's skeleton")

    def _options(self) -> tuple:
        return (self.frame2,)

    def __eq__(self, other) -> bool:
        return super().__eq__(other) and self._options() == other._options()

    def __hash__(self) -> int:
        return hash((super().__hash__(), self._options()))


_AXES = ("x", "y", "z")


@register
class LinearBushing(FramePairForce):
    """Simbody's ``Force::LinearBushing`` (OpenSim's ``BushingForce``) between frame ``target`` (F)
    and frame ``frame2`` (M): ``f = -(k q + c qdot)`` on the body-fixed X-Y-Z angles and the
    translation of M in F (module docstring)."""

    family = "bushing"
    linear = True
    parameters = tuple(
        Parameter(f"{what}_{kind}_{a}", default, 0.0, 1e9, unit, f"{kind} {'about' if what == 'rotational' else 'along'} "
                  f"frame 1's {a} axis")
        for what, kind, unit, default in (("translational", "stiffness", "N/m", 1e3),
                                          ("rotational", "stiffness", "N m/rad", 10.0),
                                          ("rotational", "damping", "N m s/rad", 0.1),
                                          ("translational", "damping", "N s/m", 10.0))
        for a in _AXES)
    zero_params = {p.name: 0.0 for p in parameters}

    def wrenches(self, k1, k2, p):
        RF, pF, vF, wF = k1
        RM, pM, vM, wM = k2
        RFM = _mtm(RF, RM)
        dG = _sub(pM, pF)
        qr, qt = body_xyz(RFM), _mtv(RF, dG)
        wFM_M = _mtv(RM, _sub(wM, wF))
        xp = backend_of(qr[1], qr[2])
        c1, s1, c2, s2 = xp.cos(qr[1]), xp.sin(qr[1]), xp.cos(qr[2]), xp.sin(qr[2])
        N = [[c2 / c1, -s2 / c1, 0.0], [s2, c2, 0.0], [-s1 * c2 / c1, s1 * s2 / c1, 1.0]]
        qdr = _mv(N, wFM_M)
        qdt = _mtv(RF, _sub(_sub(vM, vF), _cross(wF, dG)))
        fr = [-(p[f"rotational_stiffness_{a}"] * qr[i] + p[f"rotational_damping_{a}"] * qdr[i])
              for i, a in enumerate(_AXES)]
        ft = [-(p[f"translational_stiffness_{a}"] * qt[i] + p[f"translational_damping_{a}"] * qdt[i])
              for i, a in enumerate(_AXES)]
        m2 = _mv(RM, _mtv(N, fr))
        f2 = _mv(RF, ft)
        m1 = _neg(_add(m2, _cross(dG, f2)))
        return (_neg(f2), m1), (f2, m2)

    def param_jacobian(self, model, motion: Motion, params=None, cache=None) -> np.ndarray:
        """``dQ/dtheta`` ``(N, nv, 12)``: Q is linear in the parameters, so column ``i`` is Q with
        parameter ``i`` at 1 and the others at 0 (exact)."""
        kin = cache if cache is not None else self.prepare(model, motion)
        names = [p.name for p in self.parameters]
        cols = [self.generalized_force(model, motion, {n: float(n == m) for n in names}, kin) for m in names]
        return np.stack(cols, axis=-1)


@register
class PointToPointSpring(FramePairForce):
    """Simbody's ``Force::TwoPointLinearSpring`` (OpenSim's ``PointToPointSpring``): ``stiffness``
    times the stretch beyond ``rest_length`` between ``point1`` (in frame ``target``) and ``point2``
    (in frame ``frame2``), pulling the points together."""

    family = "point_to_point_spring"
    parameters = (
        Parameter("stiffness", 1.0, 0.0, 1e9, "N/m", "spring stiffness k"),
        Parameter("rest_length", 0.0, 0.0, 100.0, "m", "length L0 at which the spring is slack"),
    )
    zero_params = {"stiffness": 0.0}

    def __init__(self, target: str, *, frame2: str | None = None, point1=(0.0, 0.0, 0.0), point2=(0.0, 0.0, 0.0),
                 **values: float):
        self.point1, self.point2 = (vec3(x, n, f"{self.family}:{target}") for x, n in ((point1, "point1"),
                                                                                      (point2, "point2")))
        super().__init__(target, frame2=frame2, **values)

    def wrenches(self, k1, k2, p):
        R1, p1, _, _ = k1
        R2, p2, _, _ = k2
        r1, r2 = _mv(R1, list(self.point1)), _mv(R2, list(self.point2))
        d = _sub(_add(p2, r2), _add(p1, r1))
        xp = backend_of(d[0], d[1], d[2])
        length = xp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        scale = p["stiffness"] * (length - p["rest_length"]) / length
        f1 = [scale * x for x in d]
        return (f1, _cross(r1, f1)), (_neg(f1), _cross(r2, _neg(f1)))

    def _options(self) -> tuple:
        return (self.frame2, self.point1, self.point2)


@register
class HuntCrossleyPair(FramePairForce):
    """Simbody's ``HuntCrossleyForce`` (OpenSim's) between a ContactSphere centred at frame ``target``'s
    origin and, on another body (frame ``frame2``), a ContactHalfSpace (``other="half_space"``: the solid
    ``x > 0`` of ``frame2``, outward normal ``-x``) or a ContactSphere centred at its origin
    (``other="sphere"``, radius ``other_radius``), both of the same material (Simbody's
    ``HuntCrossleyForceImpl::calcForce`` with its HalfSpaceSphere / SphereSphere contact geometry):

        f_n = max(0, 4/3 k sqrt(R k) x^(3/2) (1 + 3/2 c v_n)),   k = E^(2/3) / 2,

    ``x`` the overlap, ``R`` the sphere's radius (``R_1 R_2 / (R_1 + R_2)`` for two spheres), ``v_n``
    the compression rate of the sphere's point against the other body's point at the contact point
    midway through the overlap, and Simbody's friction (M. Hollars) on their relative slip there.  The
    sphere gets the force, the other body its opposite at the same point.  Use it where the half space
    moves or the other geometry is a sphere; a half space fixed in the world is
    :class:`pinmsk.contact.HuntCrossleyForce`, the same law.
    """

    family = "hunt_crossley_pair"
    parameters = (
        Parameter("radius", 0.05, 1e-6, 10.0, "m", "radius of the sphere on frame 1", vary=False),
        Parameter("stiffness", 1e6, 0.0, 1e12, "N/m^2", "plane-strain modulus E of both materials"),
        Parameter("dissipation", 0.5, 0.0, 1e3, "s/m", "Hunt-Crossley dissipation c"),
        Parameter("static_friction", 0.0, 0.0, 10.0, "", "coefficient of static friction u_s"),
        Parameter("dynamic_friction", 0.0, 0.0, 10.0, "", "coefficient of dynamic friction u_d"),
        Parameter("viscous_friction", 0.0, 0.0, 1e3, "s/m", "coefficient of viscous friction u_v"),
        Parameter("transition_velocity", 0.01, 1e-9, 100.0, "m/s", "slip speed at which static friction peaks"),
    )
    zero_params = {"stiffness": 0.0}

    def __init__(self, target: str, *, frame2: str | None = None, other: str = "half_space",
                 other_radius: float = 0.0, **values: float):
        if other not in ("half_space", "sphere"):
            raise ModelError(f"{self.family}:{target}: other must be 'half_space' or 'sphere', got {other!r}")
        if other == "sphere" and not (math.isfinite(other_radius) and other_radius > 0):
            raise ModelError(f"{self.family}:{target}: a sphere needs other_radius > 0 (m), got {other_radius!r}")
        self.other = other
        self.other_radius = float(other_radius) if other == "sphere" else 0.0
        super().__init__(target, frame2=frame2, **values)

    def wrenches(self, k1, k2, p):
        R1, c1, v1, w1 = k1
        R2, p2, v2, w2 = k2
        xp = backend_of(c1[0], p2[0])
        R = p["radius"]
        if self.other == "half_space":
            n = [-R2[0][0], -R2[1][0], -R2[2][0]]                 # -x of the half space's frame
            depth = R - sum((a - b) * m for a, b, m in zip(c1, p2, n))
            radius = R
            point = [a - (R - 0.5 * depth) * m for a, m in zip(c1, n)]
        else:
            d = _sub(c1, p2)
            dist = xp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            n = [x / dist for x in d]                              # from sphere 2 towards sphere 1
            depth = R + self.other_radius - dist
            radius = R * self.other_radius / (R + self.other_radius)
            point = [a + (self.other_radius - 0.5 * depth) * m for a, m in zip(p2, n)]
        r1, r2 = _sub(point, c1), _sub(point, p2)
        vel = _sub(_add(v1, _cross(w1, r1)), _add(v2, _cross(w2, r2)))      # sphere's point relative to the other's
        vn = vel[0] * n[0] + vel[1] * n[1] + vel[2] * n[2]
        x = xp.maximum(depth, 0.0)
        k = 0.5 * xp.power(p["stiffness"], 2.0 / 3.0)
        fh = (4.0 / 3.0) * k * x * xp.sqrt(radius * k * x)
        fn = xp.maximum(fh * (1.0 - 1.5 * p["dissipation"] * vn), 0.0)
        slip = [a - vn * m for a, m in zip(vel, n)]
        v2s = slip[0] * slip[0] + slip[1] * slip[1] + slip[2] * slip[2]
        vt = p["transition_velocity"]
        below = v2s < vt * vt
        vs = xp.sqrt(xp.where(below, vt * vt, v2s))                # only the branch v >= v_t divides by v
        g = xp.where(below, 1.0 / vt, 1.0 / vs)
        us, ud, uv = p["static_friction"], p["dynamic_friction"], p["viscous_friction"]
        mu = g * (ud + 2.0 * (us - ud) / (1.0 + v2s / (vt * vt))) + uv
        f1 = [fn * m - fn * mu * s for m, s in zip(n, slip)]
        return (f1, _cross(r1, f1)), (_neg(f1), _cross(r2, _neg(f1)))

    def _options(self) -> tuple:
        return (self.frame2, self.other, self.other_radius)
