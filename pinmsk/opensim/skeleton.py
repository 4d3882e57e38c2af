"""The Pinocchio skeleton of an OpenSim model, OpenSim's exact kinematics, and the cost of the difference.

:class:`OsimKinematics` computes what OpenSim computes: each body's and marker's
pose in ground for given coordinate values (vectorised over samples), from the
parsed document alone.  :func:`build_skeleton` turns the document into a
Pinocchio model -- one Pinocchio body per OpenSim body (mass, centre of mass,
inertia), a chain of one-dof Pinocchio joints per OpenSim joint, welded
bodies merged as the URDF parser merges fixed links, markers as frames -- and
measures whatever the Pinocchio joints cannot hold exactly.

Conventions (Simbody's, as OpenSim uses them)
---------------------------------------------
A joint places its child offset frame M in its parent offset frame F by
``X_FM(q) = (R, p)``; the child body is at ``T_parent_body_F X_FM T_child_body_M^-1``.
An offset frame is at ``translation`` with ``orientation`` a body-fixed X-Y-Z
rotation.  A CustomJoint's SpatialTransform gives ``R = R(a1, f1) R(a2, f2) R(a3, f3)``
(each rotation about its axis, in the frame left by the previous one) and
``p = f4 t1 + f5 t2 + f6 t3`` in F, with the axes normalised.  The other joints
are the same construction with fixed axes: PinJoint rotates about z, SliderJoint
slides along x, UniversalJoint is x then y, PlanarJoint is z and x-y, GimbalJoint
and BallJoint are body-fixed X-Y-Z, FreeJoint is X-Y-Z and x-y-z.

Exact and approximated joints
-----------------------------
An axis whose function is a straight line of slope +-1 in one coordinate becomes
a revolute (rotation axes) or prismatic (translation axes) Pinocchio joint about
that axis, its intercept a fixed offset; constant axes become fixed offsets.  A
joint built only of such axes is exact.  A joint whose axes are other functions
of a coordinate (gait10dof18musc's knee translations, Rajagopal's walker knee
and patella) moves its child along a curve no fixed-axis joint follows.  By default
(``nonlinear="exact"``) each such axis becomes a Pinocchio joint of its own, a
dependent coordinate that :class:`CoordinateMap` fills from OpenSim's coordinates
(exact).  With ``nonlinear="fit"`` the joint is
replaced by the fixed-axis revolute (or prismatic) joint that best fits the
child body's motion over the coordinate's range (least squares over the
child's attached points), and the report gives the largest error of the
child-body origin (m) and of its orientation (rad) over that range.  Error
bounds for every body and marker below an approximated joint follow by the
triangle inequality (:attr:`Skeleton.bounds`).

Coordinates: ranges become Pinocchio position limits (clamped or not; the
clamped ones are listed in ``clamped``).  Locked coordinates are kept as joints
by default (``locked="joint"``: motion files still carry them; pinmsk does not
hold them) or, with ``locked="weld"``, fixed at their default value.  A
CoordinateCouplerConstraint is not enforced by the skeleton: its dependent
coordinate stays a joint of its own (as OpenSim's inverse dynamics treats it)
and the coupling is recorded in ``couplings``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ..io.osim import Joint, OsimDocument
from . import functions as fns
from .report import APPROXIMATED, EXACT, NOT_IMPORTED, NOTE, ReportEntry

__all__ = ["JointKinematics", "OsimKinematics", "Skeleton", "build_skeleton", "rotation", "rotation_xyz",
           "UrdfLink", "UrdfJoint", "DependentCoordinate", "CoordinateMap", "LOCKED_MODES", "NONLINEAR_MODES",
           "simbody_rotation_term"]

LOCKED_MODES = ("joint", "weld")
NONLINEAR_MODES = ("fit", "exact")
_AXIS_NAMES = ("rotation1", "rotation2", "rotation3", "translation1", "translation2", "translation3")
_X, _Y, _Z = np.eye(3)
#: Effort and velocity limits written for every joint (pinmsk's URDF convention; unused by the analyses).
EFFORT_LIMIT = 1000.0
VELOCITY_LIMIT = 50.0
#: |slope| this close to 1 counts as a pure rotation or translation.
_UNIT_SLOPE_TOL = 1e-12


# ---------------------------------------------------------------------------
# rigid-body helpers (time-first arrays)
# ---------------------------------------------------------------------------

def rotation(axis, angle) -> np.ndarray:
    """``(N, 3, 3)`` rotations by ``angle`` (N,) about the unit ``axis`` (3,) (Rodrigues)."""
    a = np.asarray(axis, dtype=float)
    t = np.atleast_1d(np.asarray(angle, dtype=float))
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    s, c = np.sin(t)[:, None, None], np.cos(t)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def rotation_xyz(angles) -> np.ndarray:
    """The body-fixed X-Y-Z rotation ``Rx(a) Ry(b) Rz(c)`` of OpenSim's ``orientation`` properties."""
    a = np.asarray(angles, dtype=float)
    return rotation(_X, a[0])[0] @ rotation(_Y, a[1])[0] @ rotation(_Z, a[2])[0]


def _transform(R=None, p=None) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def _inverse(T: np.ndarray) -> np.ndarray:
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def _offset(translation, orientation) -> np.ndarray:
    return _transform(rotation_xyz(orientation), np.asarray(translation, dtype=float))


def _rotation_to(u: np.ndarray) -> np.ndarray:
    """A rotation taking e_z to the unit vector ``u``."""
    u = u / np.linalg.norm(u)
    v = np.cross(_Z, u)
    s, c = np.linalg.norm(v), float(u @ _Z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else rotation(_X, np.pi)[0]
    return rotation(v / s, np.arctan2(s, c))[0]


def _project_so3(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def _angle(R: np.ndarray) -> np.ndarray:
    """Rotation angles (rad) of ``(N, 3, 3)`` rotations."""
    c = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    s = np.linalg.norm(np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                                 R[..., 1, 0] - R[..., 0, 1]], axis=-1), axis=-1) / 2.0
    return np.arctan2(s, c)


# ---------------------------------------------------------------------------
# OpenSim's kinematics
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class _Axis:
    """One of a joint's six axes: unit direction, the coordinates its function takes, the function."""

    index: int
    direction: np.ndarray
    coordinates: tuple[str, ...]
    function: fns.Function
    where: str

    def value(self, values: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        if not self.coordinates:
            return self.function.value(np.zeros(n))
        if len(self.coordinates) == 1:
            return self.function.value(values[self.coordinates[0]])
        return self.function.value(np.stack([values[c] for c in self.coordinates], axis=1))


#: The built-in joints as SpatialTransforms: (axis, coordinate index or None) for rotations 1-3, translations 1-3.
_BUILTIN_AXES = {
    "WeldJoint": ((_X, None), (_Y, None), (_Z, None), (_X, None), (_Y, None), (_Z, None)),
    "PinJoint": ((_Z, 0), (_X, None), (_Y, None), (_X, None), (_Y, None), (_Z, None)),
    "SliderJoint": ((_X, None), (_Y, None), (_Z, None), (_X, 0), (_Y, None), (_Z, None)),
    "UniversalJoint": ((_X, 0), (_Y, 1), (_Z, None), (_X, None), (_Y, None), (_Z, None)),
    "PlanarJoint": ((_Z, 0), (_X, None), (_Y, None), (_X, 1), (_Y, 2), (_Z, None)),
    "GimbalJoint": ((_X, 0), (_Y, 1), (_Z, 2), (_X, None), (_Y, None), (_Z, None)),
    "BallJoint": ((_X, 0), (_Y, 1), (_Z, 2), (_X, None), (_Y, None), (_Z, None)),
    "FreeJoint": ((_X, 0), (_Y, 1), (_Z, 2), (_X, 3), (_Y, 4), (_Z, 5)),
}


class JointKinematics:
    """One OpenSim joint: its child body's pose in its parent body's frame, from its coordinates."""

    def __init__(self, doc: OsimDocument, joint: Joint):
        self.joint = joint
        if joint.reverse:
            raise ModelError(f"{joint.where}: <reverse>true</reverse> joints are not supported; swap its parent "
                             "and child bodies (and invert its motion) in the model")
        parent, chain_p = doc.frame_body(joint.parent_frame)
        child, chain_c = doc.frame_body(joint.child_frame)
        self.parent = parent.name
        self.child = child.name
        self.child_path = child.path
        self.parent_offset = _chain(chain_p)      # parent body -> F
        self.child_offset = _chain(chain_c)       # child body -> M
        self.coordinates = tuple(c.name for c in joint.coordinates)
        self.axes = self._axes(joint)

    def _axes(self, joint: Joint) -> tuple[_Axis, ...]:
        if joint.type == "CustomJoint":
            axes = []
            for ta in joint.spatial_transform:
                d = np.asarray(ta.axis, dtype=float)
                if not np.linalg.norm(d) > 0:
                    raise ModelError(f"{ta.where}: the axis of {joint.where.split(': ', 1)[1]} is zero")
                for c in ta.coordinates:
                    if c not in self.coordinates:
                        raise ModelError(f"{ta.where}: names coordinate '{c}', which joint '{joint.name}' does not "
                                         f"list (its coordinates: {', '.join(self.coordinates) or 'none'})")
                if ta.function is None:
                    if len(ta.coordinates) > 1:
                        raise ModelError(f"{ta.where}: has {len(ta.coordinates)} coordinates but no function")
                    f = fns.LinearFunction([1.0, 0.0]) if ta.coordinates else fns.Constant(0.0)
                else:
                    f = fns.from_osim(ta.function)
                if f.n_args and f.n_args != max(1, len(ta.coordinates)):
                    raise ModelError(f"{ta.where}: its function takes {f.n_args} arguments but the axis names "
                                     f"{len(ta.coordinates)} coordinate(s)")
                axes.append(_Axis(ta.index, d / np.linalg.norm(d), ta.coordinates, f, ta.where))
            for start in (0, 3):
                a = [axes[start + i].direction for i in range(3)]
                if min(np.linalg.norm(np.cross(a[i], a[k])) for i, k in ((0, 1), (0, 2), (1, 2))) < 1e-5:
                    raise ModelError(f"{joint.where}: its {'rotation' if start == 0 else 'translation'} axes are "
                                     "collinear (OpenSim refuses this joint too)")
            return tuple(axes)
        spec = _BUILTIN_AXES.get(joint.type)
        if spec is None:
            raise ModelError(f"{joint.where}: {joint.type} is not supported by pinmsk (supported: "
                             f"CustomJoint, {', '.join(_BUILTIN_AXES)})")
        n = 1 + max([i for _, i in spec if i is not None], default=-1)
        if len(self.coordinates) != n:
            raise ModelError(f"{joint.where}: a {joint.type} has {n} coordinate(s), this one lists "
                             f"{len(self.coordinates)}")
        return tuple(_Axis(k, d, () if i is None else (self.coordinates[i],),
                           fns.Constant(0.0) if i is None else fns.LinearFunction([1.0, 0.0]), joint.where)
                     for k, (d, i) in enumerate(spec))

    def motion(self, values: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """``X_FM`` (N, 4, 4): the child offset frame in the parent offset frame."""
        f = [ax.value(values, n) for ax in self.axes]
        R = rotation(self.axes[0].direction, f[0]) @ rotation(self.axes[1].direction, f[1]) \
            @ rotation(self.axes[2].direction, f[2])
        p = sum(f[3 + i][:, None] * self.axes[3 + i].direction for i in range(3))
        X = np.zeros((n, 4, 4))
        X[:, :3, :3] = R
        X[:, :3, 3] = p
        X[:, 3, 3] = 1.0
        return X

    def child_in_parent(self, values: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """The child body's pose in the parent body's frame (N, 4, 4)."""
        return self.parent_offset @ self.motion(values, n) @ _inverse(self.child_offset)


def _chain(frames) -> np.ndarray:
    T = np.eye(4)
    for f in frames:
        T = T @ _offset(f.translation, f.orientation)
    return T


def simbody_rotation_term(jk: JointKinematics, values: Mapping[str, np.ndarray],
                           speeds: Mapping[str, np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
    """The angular acceleration (N, 3), in the joint's parent frame F, that Simbody's FunctionBased
    mobilizer (OpenSim's CustomJoint) adds to the exact one, and the matrix W (N, 3, 3) whose columns
    ``a1, R1 a2, R1 R2 a3`` turn rotation rates into the angular velocity.

    ``FunctionBasedImpl::CacheInfo::buildHdot`` (simbody, MobilizedBodyImpl.h) differentiates W's second
    and third columns with the angular velocity of the first mobility alone and of all but the third,
    where the derivatives are those of the first rotation and of the first two.  The two agree when
    rotation i is driven by mobility i only (or a rotation's axis is constant); otherwise -- Rajagopal's
    walker knee turns about three axes, all functions of the knee angle -- OpenSim's accelerations (and so
    its inverse dynamics) carry this velocity-product term, ``theta2' theta3' u^2 (R1 R2 a3 x R1 a2)``
    for one coordinate.  pinmsk's chains are exact: this is for reporting and comparing."""
    ax = jk.axes[:3]
    mob = list(jk.coordinates)                       # Simbody's mobilities, in the joint's order
    U = np.column_stack([np.broadcast_to(speeds[c], (n,)) for c in mob]) if mob else np.zeros((n, 0))
    th, F = [], []
    for a in ax:
        x = np.column_stack([np.broadcast_to(values[c], (n,)) for c in a.coordinates]) if a.coordinates else None
        arg = np.zeros(n) if x is None else (x[:, 0] if x.shape[1] == 1 else x)
        th.append(a.function.value(arg))
        d = np.zeros((n, len(mob)))
        for k, c in enumerate(a.coordinates):
            d[:, mob.index(c)] = a.function.derivative(arg, 1, k)
        F.append(d)
    R1 = rotation(ax[0].direction, th[0])
    R2 = R1 @ rotation(ax[1].direction, th[1])
    W = np.stack([np.broadcast_to(ax[0].direction, (n, 3)), R1 @ ax[1].direction, R2 @ ax[2].direction], axis=2)
    Fm = np.stack(F, axis=1)                                             # (N, 3 rotations, n_mobilities)
    rates = np.einsum("nrk,nk->nr", Fm, U)
    U1 = U.copy()
    U1[:, 1:] = 0.0
    U2 = U.copy()
    if len(mob) > 2:
        U2[:, 2] = 0.0
    V1 = np.einsum("nij,njk,nk->ni", W, Fm, U1)
    V2 = np.einsum("nij,njk,nk->ni", W, Fm, U2)
    w1 = W[:, :, 0] * rates[:, :1]
    w12 = w1 + W[:, :, 1] * rates[:, 1:2]
    dA = np.cross(V1 - w1, W[:, :, 1]) * rates[:, 1:2] + np.cross(V2 - w12, W[:, :, 2]) * rates[:, 2:3]
    return dA, W


class OsimKinematics:
    """OpenSim's forward kinematics of a parsed model: body, marker and point positions in ground.

    ``q`` arguments are a mapping ``{coordinate: (N,) values}`` (missing
    coordinates take their default values) or an ``(N, n)`` / ``(n,)`` array in
    :attr:`coordinates` order (OpenSim's coordinate order).
    """

    def __init__(self, doc: OsimDocument):
        self.doc = doc
        self.coordinates = tuple(c.name for c in doc.coordinates)
        dup = sorted({c for c in self.coordinates if self.coordinates.count(c) > 1})
        if dup:
            raise ModelError(f"{doc.source}: coordinate names {dup} appear in more than one joint")
        self.defaults = {c.name: c.default_value for c in doc.coordinates}
        self.joints = _tree_order(doc, [JointKinematics(doc, j) for j in doc.joints])
        self.body_names = (doc.ground.name,) + tuple(jk.child for jk in self.joints)
        self._marker_frames = {}
        for m in doc.markers:
            body, chain = doc.frame_body(m.frame)
            self._marker_frames[m.name] = (body.name, _chain(chain) @ _transform(p=np.asarray(m.location)))

    def values(self, q) -> tuple[dict[str, np.ndarray], int]:
        """``({coordinate: (N,)}, N)`` from any accepted form of ``q``."""
        a = _columns(q, self.coordinates, self.defaults, f"{self.doc.source}: q")
        return {c: a[:, i] for i, c in enumerate(self.coordinates)}, a.shape[0]

    def body_poses(self, q) -> dict[str, np.ndarray]:
        """``{body: (N, 4, 4)}`` poses in ground (the ground included)."""
        vals, n = self.values(q)
        poses = {self.doc.ground.name: np.broadcast_to(np.eye(4), (n, 4, 4))}
        for jk in self.joints:
            poses[jk.child] = poses[jk.parent] @ jk.child_in_parent(vals, n)
        return poses

    def marker_positions(self, q) -> dict[str, np.ndarray]:
        """``{marker: (N, 3)}`` positions in ground."""
        poses = self.body_poses(q)
        return {name: (poses[body] @ T)[:, :3, 3] for name, (body, T) in self._marker_frames.items()}

    def center_of_mass(self, q) -> np.ndarray:
        """The whole model's centre of mass in ground (N, 3)."""
        poses = self.body_poses(q)
        total, acc = 0.0, 0.0
        for b in self.doc.bodies:
            c = np.append(np.asarray(b.mass_center, dtype=float), 1.0)
            acc = acc + b.mass * (poses[b.name] @ c)[:, :3]
            total += b.mass
        return acc / total


def _columns(q, names: Sequence[str], defaults: Mapping[str, float], what: str) -> np.ndarray:
    """``(N, n)`` values of the coordinates ``names`` from a ``{name: (N,)}`` mapping (missing names take
    ``defaults``) or from an ``(N, n)`` / ``(n,)`` array in ``names`` order (a copy either way)."""
    if isinstance(q, Mapping):
        unknown = sorted(set(q) - set(names))
        if unknown:
            raise ModelError(f"{what} names coordinate(s) {unknown} the model does not have")
        arrs = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in q.items()}
        n = max([a.shape[0] for a in arrs.values()], default=1)
        return np.stack([np.broadcast_to(arrs.get(c, defaults[c]), (n,)) for c in names], axis=1).astype(float)
    a = np.array(q, dtype=float)
    a = a[None, :] if a.ndim == 1 else a
    if a.ndim != 2 or a.shape[1] != len(names):
        raise ModelError(f"{what} must have {len(names)} columns (OpenSim's coordinates {', '.join(names)}), "
                         f"got shape {np.shape(q)}")
    return a


def _tree_order(doc: OsimDocument, joints: list[JointKinematics]) -> tuple[JointKinematics, ...]:
    """Joints from the ground outwards (each joint after the one that places its parent)."""
    by_child: dict[str, JointKinematics] = {}
    for jk in joints:
        if jk.child == doc.ground.name:
            raise ModelError(f"{jk.joint.where}: its child frame is on the ground; pinmsk needs joints whose "
                             "parent is nearer the ground (reverse the joint)")
        if jk.child in by_child:
            other = by_child[jk.child].joint
            raise ModelError(f"{jk.joint.where}: body '{jk.child}' is already the child of joint '{other.name}' "
                             f"({other.source}:{other.line}); closed kinematic loops are not supported")
        by_child[jk.child] = jk
    order, placed = [], {doc.ground.name}
    remaining = list(joints)
    while remaining:
        ready = [jk for jk in remaining if jk.parent in placed]
        if not ready:
            jk = remaining[0]
            raise ModelError(f"{jk.joint.where}: its parent body '{jk.parent}' is not connected to the ground")
        for jk in ready:
            order.append(jk)
            placed.add(jk.child)
        remaining = [jk for jk in remaining if all(jk is not r for r in ready)]
    unplaced = [b.name for b in doc.bodies if b.name not in placed]
    if unplaced:
        raise ModelError(f"{doc.source}: bodies {unplaced} have no joint to the rest of the model")
    return tuple(order)


# ---------------------------------------------------------------------------
# dependent coordinates and the map from OpenSim's coordinates to Pinocchio's
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class DependentCoordinate:
    """A Pinocchio joint whose value is a function of OpenSim coordinates: ``function(*of)`` (the nonlinear
    ``axis`` of CustomJoint ``joint``, in ``nonlinear="exact"`` skeletons)."""

    name: str
    joint: str
    axis: str
    of: tuple[str, ...]
    function: fns.Function
    where: str
    welded: Mapping[str, float] = field(default_factory=dict)


def _image_range(d: DependentCoordinate, fit_ranges) -> tuple[float, float]:
    """The values a dependent coordinate takes over its coordinates' (fit) ranges."""
    free = [c for c in d.of if c not in d.welded]
    grids = np.meshgrid(*[np.linspace(*fit_ranges[c], 401 if len(free) == 1 else 21) if c not in d.welded
                          else np.array([d.welded[c]]) for c in d.of], indexing="ij")
    x = np.stack([g.ravel() for g in grids], axis=1)
    v = d.function.value(x[:, 0] if x.shape[1] == 1 else x) if d.of else d.function.value(np.zeros(1))
    return float(np.min(v)), float(np.max(v))


def _coupler_functions(doc) -> tuple:
    return tuple((con.dependent, con.independent, fns.from_osim(con.function), float(con.scale_factor))
                 for con in doc.constraints if con.enforced)


#: Keys of a sidecar's ``[coordinate_map]`` table (:meth:`CoordinateMap.to_spec`), of its dependent joints and
#: of its couplers.
MAP_KEYS = {"osim_coordinates": "OpenSim's coordinates, in its order",
            "defaults": "{ coordinate = default value }", "welded": "{ coordinate = value } (locked='weld')",
            "dependent": "[[coordinate_map.dependent]]: the joints that are functions of coordinates",
            "couplers": "[[coordinate_map.couplers]]: enforced CoordinateCouplerConstraints"}
DEPENDENT_KEYS = {"name": "the Pinocchio joint", "joint": "the OpenSim joint", "axis": "its SpatialTransform axis",
                  "of": "the coordinates it is a function of", "function": "the OpenSim function { type = ... }",
                  "welded": "{ coordinate = value } of welded arguments"}
COUPLER_KEYS = {"dependent": "coordinate", "independent": "coordinates", "scale_factor": "number",
                "function": "the OpenSim function { type = ... }"}


#: id(function) -> (function, argument, slope) of the last evaluation with a slope: the moments mapped back
#: (``generalized_forces``) need the slopes the motion's mapping (``expand``) computed at the same angles
_SLOPES: dict[int, tuple[fns.Function, np.ndarray, np.ndarray]] = {}


def _slope(f: fns.Function, arg: np.ndarray) -> np.ndarray:
    """``f.derivative(arg)`` of a one-argument function, reused when ``arg`` equals the last argument it was
    evaluated at (``evaluate`` and ``derivative`` compute the slope with the same operations)."""
    hit = _SLOPES.get(id(f))
    if hit is not None and hit[0] is f and hit[1].shape == arg.shape and np.array_equal(hit[1], arg):
        return hit[2]
    return _remember_slope(f, arg, f.derivative(arg, 1, 0))


def _remember_slope(f: fns.Function, arg: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Keep ``d = f'(arg)`` for :func:`_slope`; returns it read-only (every later hit shares it)."""
    d = d.view()
    d.flags.writeable = False
    if len(_SLOPES) >= 256 and id(f) not in _SLOPES:
        _SLOPES.pop(next(iter(_SLOPES)))
    _SLOPES[id(f)] = (f, arg.copy(), d)
    return d


class CoordinateMap:
    """OpenSim's coordinates -> the Pinocchio model's ``q`` (with speeds, accelerations, Jacobian).

    A Pinocchio joint is either an OpenSim coordinate or a :class:`DependentCoordinate`
    (``x = f(q_of)``, so ``v = f' v_of`` and ``a = f' a_of + f'' v_of^2``).  With ``couplers=True``
    the dependent coordinate of each enforced CoordinateCouplerConstraint is first set from its
    independent ones (``q_dep = s f(q_ind)``, same chain rule), as OpenSim's solvers enforce it.
    Generalized forces map back by virtual work: ``tau_osim = J^T tau_pinocchio``
    (:meth:`generalized_forces`).  Inputs are ``{name: (N,)}`` mappings (missing coordinates take their
    default values) or ``(N, n)`` arrays in :attr:`osim_coordinates` order; outputs are time-first arrays
    in Pinocchio order (:attr:`joints`).
    """

    def __init__(self, *, osim_coordinates, joints, dependent, couplers, defaults, welded):
        self.osim_coordinates = tuple(osim_coordinates)
        self.joints = tuple(joints)
        self.dependent = dict(dependent)
        self.couplers = tuple(couplers)
        self.defaults = dict(defaults)
        self.welded = dict(welded)
        self._col = {c: i for i, c in enumerate(self.osim_coordinates)}
        # the one-argument dependent joints grouped by their argument, each group one FunctionBank: a knee's
        # five to eight functions of its angle evaluated together (the numbers of one by one, to rounding)
        groups: dict[str, list[int]] = {}
        for j, name in enumerate(self.joints):
            d = self.dependent.get(name)
            if d is not None and len(d.of) == 1 and d.function.n_args <= 1:
                groups.setdefault(d.of[0], []).append(j)
        self._banks = tuple((self._col[c], np.array(js), fns.FunctionBank(
            [self.dependent[self.joints[j]].function for j in js])) for c, js in groups.items())
        self._banked = frozenset(j for _, js, _ in self._banks for j in js)
        self._all_banked = all(j in self._banked for j, n in enumerate(self.joints) if n in self.dependent)
        # the joints that are OpenSim coordinates, and their columns
        same = [(j, self._col[n]) for j, n in enumerate(self.joints) if n not in self.dependent]
        self._same_j = np.array([j for j, _ in same], dtype=np.intp)
        self._same_i = np.array([i for _, i in same], dtype=np.intp)

    @property
    def identity(self) -> bool:
        """True if every Pinocchio joint is an OpenSim coordinate (no dependent coordinates)."""
        return not self.dependent

    # -- serialisation (the sidecar of ``pinmsk import``) ----------------------
    def to_spec(self) -> dict:
        """The map as plain data (the ``[coordinate_map]`` table of a sidecar): OpenSim's coordinates, their
        defaults and welded values, each dependent joint's coordinates and OpenSim function definition
        (:func:`pinmsk.opensim.functions.to_spec`: the function itself, not samples), and the enforced
        couplers.  :meth:`from_spec` reads it back; the Pinocchio joints come from the skeleton."""
        deps = []
        for d in self.dependent.values():
            rec = {"name": d.name, "joint": d.joint, "axis": d.axis, "of": list(d.of),
                   "function": fns.to_spec(d.function)}
            if d.welded:
                rec["welded"] = {c: float(v) for c, v in d.welded.items()}
            deps.append(rec)
        return {"osim_coordinates": list(self.osim_coordinates),
                "defaults": {c: float(self.defaults[c]) for c in self.osim_coordinates},
                "welded": {c: float(v) for c, v in self.welded.items()},
                "dependent": deps,
                "couplers": [{"dependent": dep, "independent": list(indep), "scale_factor": float(scale),
                              "function": fns.to_spec(f)} for dep, indep, f, scale in self.couplers]}

    @classmethod
    def from_spec(cls, spec, *, joints: Sequence[str], where: str) -> "CoordinateMap":
        """The map :meth:`to_spec` wrote, on a skeleton with Pinocchio ``joints`` (in order); ModelError naming
        ``where`` and the key for an unknown key, an unknown coordinate or a joint the map does not explain."""
        from ..io.toml_files import check_keys

        check_keys(spec, MAP_KEYS, where=where, section="[coordinate_map]")
        for key in ("osim_coordinates", "defaults"):
            if key not in spec:
                raise ModelError(f"{where}: [coordinate_map] needs '{key}'")
        coords = spec["osim_coordinates"]
        if not (isinstance(coords, list) and coords and all(isinstance(c, str) for c in coords)):
            raise ModelError(f"{where}: [coordinate_map] osim_coordinates must be a list of coordinate names")
        known = set(coords)

        def values(table, what):
            if not isinstance(table, dict):
                raise ModelError(f"{where}: [coordinate_map] {what} must be a table {{ coordinate = value }}")
            for c, v in table.items():
                if c not in known:
                    raise ModelError(f"{where}: [coordinate_map] {what} names '{c}', which is not one of "
                                     "osim_coordinates")
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise ModelError(f"{where}: [coordinate_map] {what}.{c} must be a number, got {v!r}")
            return {c: float(v) for c, v in table.items()}

        defaults = values(spec["defaults"], "defaults")
        absent = [c for c in coords if c not in defaults]
        if absent:
            raise ModelError(f"{where}: [coordinate_map] defaults lacks {', '.join(absent)}")
        welded = values(spec.get("welded", {}), "welded")

        def names(v, label):
            if not (isinstance(v, list) and all(isinstance(c, str) and c in known for c in v)):
                raise ModelError(f"{where}: {label} must list coordinates of osim_coordinates, got {v!r}")
            return tuple(v)

        dependent = {}
        for i, rec in enumerate(spec.get("dependent", [])):
            label = f"[[coordinate_map.dependent]] #{i + 1}"
            check_keys(rec, DEPENDENT_KEYS, where=where, section=label)
            missing = [k for k in ("name", "of", "function") if k not in rec]
            if missing:
                raise ModelError(f"{where}: {label} needs {', '.join(missing)}")
            name = str(rec["name"])
            label = f"[[coordinate_map.dependent]] '{name}'"
            f = fns.from_spec(rec["function"], where=f"{where}: {label} function")
            of = names(rec["of"], f"{label} of")
            if not of or (f.n_args and f.n_args != len(of)):
                raise ModelError(f"{where}: {label}: its function takes {f.n_args} argument(s) but 'of' names "
                                 f"{len(of)} coordinate(s)")
            dependent[name] = DependentCoordinate(
                name=name, joint=str(rec.get("joint", "")), axis=str(rec.get("axis", "")), of=of, function=f,
                where=f"{where}: {label}", welded=values(rec.get("welded", {}), f"{label} welded"))
        couplers = []
        for i, rec in enumerate(spec.get("couplers", [])):
            label = f"[[coordinate_map.couplers]] #{i + 1}"
            check_keys(rec, COUPLER_KEYS, where=where, section=label)
            missing = [k for k in COUPLER_KEYS if k not in rec]
            if missing:
                raise ModelError(f"{where}: {label} needs {', '.join(missing)}")
            dep = names([rec["dependent"]], f"{label} dependent")[0]
            couplers.append((dep, names(rec["independent"], f"{label} independent"),
                             fns.from_spec(rec["function"], where=f"{where}: {label} function"),
                             float(rec["scale_factor"])))
        joints = tuple(joints)
        stray = [j for j in joints if j not in known and j not in dependent]
        if stray:
            raise ModelError(f"{where}: the skeleton's joint(s) {', '.join(stray)} are neither OpenSim coordinates "
                             "(osim_coordinates) nor dependent joints of [coordinate_map]")
        lost = [d for d in dependent if d not in joints]
        if lost:
            raise ModelError(f"{where}: [coordinate_map] dependent joint(s) {', '.join(lost)} are not joints of the "
                             "skeleton")
        return cls(osim_coordinates=coords, joints=joints, dependent=dependent, couplers=couplers,
                   defaults=defaults, welded=welded)

    def _osim(self, q, what):
        if q is None:
            return None
        defaults = ({c: self.welded.get(c, self.defaults[c]) for c in self.osim_coordinates} if what == "q"
                    else dict.fromkeys(self.osim_coordinates, 0.0))
        return _columns(q, self.osim_coordinates, defaults, f"CoordinateMap: {what}")

    def _chain(self, f: fns.Function, cols, Q, V, A, rows, *, value: bool = True):
        """Value, Jacobian row, speed and acceleration of ``x = f(Q[:, cols])`` (None where not asked).

        ``rows[c]`` is the Jacobian row of column ``c`` as ``{OpenSim column: (N,) coefficient}`` (the
        sparse form: a coordinate depends on one or two others, so a dense (N, n, n) matrix would be
        mostly zeros); the result's row is the chain rule through them."""
        k = len(cols)       # >= 1: a dependent coordinate or coupler always has an argument
        arg = Q[:, cols[0]] if k == 1 else Q[:, cols]
        if k == 1 and A is not None:       # value, slope and curvature from one evaluation
            val, d, dd = f.evaluate(arg)
            d1 = [_remember_slope(f, arg, d)]
        else:
            val = f.value(arg) if value else None
            d1 = [_slope(f, arg) if k == 1 else f.derivative(arg, 1, i) for i in range(k)]
            dd = None
        row: dict[int, np.ndarray] = {}
        for i, c in enumerate(cols):
            for j, coef in rows[c].items():
                row[j] = row[j] + d1[i] * coef if j in row else d1[i] * coef
        vel = None if V is None else sum(d1[i] * V[:, c] for i, c in enumerate(cols))
        acc = None
        if A is not None:
            acc = sum(d1[i] * A[:, c] for i, c in enumerate(cols))
            if k == 1:     # multi-argument functions are linear (LinearFunction): no curvature term
                acc = acc + dd * V[:, cols[0]] ** 2
        return val, row, vel, acc

    def _resolve(self, q, v, a, couplers):
        """OpenSim's ``(Q, V, A)`` with the couplers applied (if asked) and each column's sparse Jacobian row."""
        Q = self._osim(q, "q")
        V = self._osim(v, "v") if v is not None else None
        A = self._osim(a, "a") if a is not None else None
        if A is not None and V is None:
            raise ModelError("CoordinateMap: accelerations need speeds too")
        n = Q.shape[0]
        one = np.ones(n)
        rows = [{i: one} for i in range(Q.shape[1])]
        if couplers:
            for dep, indep, f, scale in self.couplers:
                val, row, vel, acc = self._chain(f, [self._col[c] for c in indep], Q, V, A, rows)
                i = self._col[dep]
                Q[:, i] = scale * val
                rows[i] = {j: scale * c for j, c in row.items()}
                if V is not None:
                    V[:, i] = scale * vel
                if A is not None:
                    A[:, i] = scale * acc
        return Q, V, A, rows

    def expand(self, q, v=None, a=None, *, couplers: bool = True, with_source: bool = False):
        """Pinocchio ``(q, v, a)`` (N, nq) from OpenSim coordinates (``v``/``a`` None if not given); with
        ``with_source``, also OpenSim's ``q`` as mapped (N, n_osim), the couplers applied."""
        out = self._expand(q, v, a, couplers)
        return out if with_source else out[:3]

    def jacobian(self, q, *, couplers: bool = True) -> np.ndarray:
        """``d q_pinocchio / d q_osim`` (N, nq, n_osim)."""
        Q, rows = self._rows(q, couplers)
        J = np.zeros((Q.shape[0], len(self.joints), Q.shape[1]))
        for jp, row in enumerate(rows):
            for i, c in row.items():
                J[:, jp, i] = c
        return J

    def generalized_forces(self, q, tau, *, couplers: bool = True) -> np.ndarray:
        """OpenSim coordinates' generalized forces (N, n_osim) from Pinocchio's ``tau`` (N, nq): J^T tau."""
        tau = np.atleast_2d(np.asarray(tau, dtype=float))
        if couplers or not self._all_banked:
            Q, rows = self._rows(q, couplers)
            out = np.zeros((Q.shape[0], Q.shape[1]))
            for jp, row in enumerate(rows):
                for i, c in row.items():
                    out[:, i] += c * tau[:, jp]
            return out
        # no couplers applied, every dependent joint in a bank: each joint's row is its own column (an
        # OpenSim coordinate) or its bank's slope on its argument's column, so J^T tau is one gather plus
        # a weighted sum per bank
        Q = self._osim(q, "q")
        out = np.zeros((Q.shape[0], Q.shape[1]))
        out[:, self._same_i] = tau[:, self._same_j]
        for col, js, bank in self._banks:
            out[:, col] += np.einsum("gn,ng->n", bank.slope(Q[:, col]), tau[:, js])
        return out

    def _rows(self, q, couplers):
        """OpenSim's ``Q`` and the sparse Jacobian row of each Pinocchio joint (no values of the dependent
        joints computed: the rows need the functions' slopes only)."""
        Q, _, _, rows = self._resolve(q, None, None, couplers)
        out = [None] * len(self.joints)
        for col, js, bank in self._banks:
            D1 = bank.slope(Q[:, col])
            for g, j in enumerate(js):
                out[j] = {i: D1[g] * c for i, c in rows[col].items()}
        for j, name in enumerate(self.joints):
            if j in self._banked:
                continue
            d = self.dependent.get(name)
            if d is None:
                out[j] = rows[self._col[name]]
            else:
                out[j] = self._chain(d.function, [self._col[c] for c in d.of], Q, None, None, rows,
                                     value=False)[1]
        return Q, out

    def _expand(self, q, v, a, couplers):
        Q, V, A, rows = self._resolve(q, v, a, couplers)
        n = Q.shape[0]
        nq = len(self.joints)
        qp = np.empty((n, nq))
        vp = None if V is None else np.empty((n, nq))
        ap = None if A is None else np.empty((n, nq))
        for col, js, bank in self._banks:   # v = f' v_of, a = f' a_of + f'' v_of^2, a group at a time
            F, D1, D2 = bank.evaluate(Q[:, col])
            qp[:, js] = F.T
            if vp is not None:
                vv = V[:, col]
                vp[:, js] = (D1 * vv).T
                if ap is not None:
                    ap[:, js] = (D1 * A[:, col] + D2 * vv ** 2).T
        for j, name in enumerate(self.joints):
            d = self.dependent.get(name)
            if d is None or j in self._banked:
                continue
            val, _, vel, acc = self._chain(d.function, [self._col[c] for c in d.of], Q, V, A, rows)
            qp[:, j] = val
            if vp is not None:
                vp[:, j] = vel
            if ap is not None:
                ap[:, j] = acc
        for out, src in ((qp, Q), (vp, V), (ap, A)):
            if out is not None:
                out[:, self._same_j] = src[:, self._same_i]     # the joints that are OpenSim coordinates
        return qp, vp, ap, Q


# ---------------------------------------------------------------------------
# the Pinocchio skeleton
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class UrdfLink:
    """A link of the skeleton: an OpenSim body (``body``), a massless link inside a joint chain, or a marker."""

    name: str
    mass: float = 0.0
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[tuple[float, ...], ...] | None = None   # 3x3 about the centre of mass; None: no inertial
    body: str | None = None
    marker: str | None = None


@dataclass(frozen=True)
class UrdfJoint:
    """A joint of the skeleton: ``revolute``/``prismatic`` (a coordinate) or ``fixed``; ``origin`` is the
    4x4 placement of the child link in the parent link's frame at q = 0, ``axis`` in the child link frame."""

    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: tuple[float, float, float] | None = None
    limits: tuple[float, float] | None = None


@dataclass(frozen=True)
class _Fit:
    """A fixed-axis joint fitted to a coordinate-driven motion: ``P kind(q) C``."""

    kind: str             # "revolute" | "prismatic" (about / along z)
    P: np.ndarray
    C: np.ndarray
    q_range: tuple[float, float]
    max_translation_error: float
    max_rotation_error: float          # rad
    operator_rotation_error: float     # max ||R - R'||_2 = 2 sin(theta / 2)
    sampled: bool = False


@dataclass(frozen=True)
class Skeleton:
    """The result of :func:`build_skeleton` (see the module docstring)."""

    doc: OsimDocument
    kinematics: OsimKinematics
    pin_model: pin.Model
    links: Mapping[str, UrdfLink]
    joints: tuple[UrdfJoint, ...]              # depth-first, as Pinocchio's URDF parser orders them
    markers: Mapping[str, tuple[str, np.ndarray]]  # marker frame -> (link, 4x4 placement)
    entries: tuple[ReportEntry, ...]
    bounds: Mapping[str, float]
    coordinate_order: tuple[str, ...]          # OpenSim's order of the coordinates that are joints
    locked: Mapping[str, float]
    welded: Mapping[str, float]
    clamped: tuple[str, ...]
    couplings: tuple[Mapping, ...]
    motion_types: Mapping[str, str]
    dependent: Mapping[str, "DependentCoordinate"] = field(default_factory=dict)
    virtual: tuple[str, ...] = ()               # OpenSim coordinates that are no Pinocchio joint (exact mode)
    coordinate_map: "CoordinateMap | None" = None
    options: Mapping = field(default_factory=dict)


def build_skeleton(doc: OsimDocument, *, locked: str = "joint", nonlinear: str = "exact", fit_samples: int = 81,
                   check_samples: int = 2001) -> Skeleton:
    """The Pinocchio skeleton of ``doc``, with report entries for each joint and the error bounds.

    ``locked``: ``"joint"`` keeps locked coordinates as joints (default), ``"weld"`` fixes them at
    their default values.  ``nonlinear``: ``"exact"`` (default) gives each axis that is a nonlinear
    function of a coordinate a Pinocchio joint of its own, a *dependent coordinate* (``dependent``) whose
    value is the axis function of its coordinate(s): exact when filled by :class:`CoordinateMap`;
    ``"fit"`` replaces such a joint by the best-fitting fixed-axis joint (measured, reported).
    ``fit_samples`` / ``check_samples``: coordinate samples for fitting an approximated joint and for
    measuring its error.
    """
    if locked not in LOCKED_MODES:
        raise ModelError(f"locked must be one of {LOCKED_MODES}, got {locked!r}")
    if nonlinear not in NONLINEAR_MODES:
        raise ModelError(f"nonlinear must be one of {NONLINEAR_MODES}, got {nonlinear!r}")
    kin = OsimKinematics(doc)
    coords = {c.name: c for c in doc.coordinates}
    entries: list[ReportEntry] = []
    welded = {c.name: c.default_value for c in doc.coordinates if c.locked and locked == "weld"}
    ranges = {c.name: (min(c.range), max(c.range)) for c in doc.coordinates}
    couplings, fit_ranges = _couplings(doc, coords, ranges, entries)

    links: dict[str, UrdfLink] = {doc.ground.name: UrdfLink(doc.ground.name, body=doc.ground.name)}
    for b in doc.bodies:
        if b.name in links:
            raise ModelError(f"{b.where}: a second body named '{b.name}'")
        links[b.name] = UrdfLink(b.name, mass=float(b.mass), com=tuple(map(float, b.mass_center)),
                                 inertia=_inertia_matrix(b.inertia), body=b.name)
    ujoints: list[UrdfJoint] = []
    dependent: dict[str, DependentCoordinate] = {}
    approx: dict[str, tuple[_Fit, JointKinematics]] = {}
    reach: dict[str, float] = {}
    names_used = set(links)
    for jk in kin.joints:
        segs, fit, text, deps = _convert(jk, welded=welded, fit_ranges=fit_ranges, kin=kin, fit_samples=fit_samples,
                                         check_samples=check_samples, nonlinear_mode=nonlinear)
        for d in deps.values():
            if d.name in coords or d.name in dependent:
                raise ModelError(f"{d.where}: pinmsk names this axis' coordinate '{d.name}', which the model "
                                 "already uses; rename that coordinate or use nonlinear='fit'")
            ranges[d.name] = _image_range(d, fit_ranges)
        dependent.update(deps)
        new = _chain_joints(jk, segs, ranges, names_used)
        ujoints += new
        for uj in new:
            if uj.child not in links:
                links[uj.child] = UrdfLink(uj.child)
        reach[jk.child] = _max_translation(jk, fit, ranges, welded)
        entries.append(_joint_entry(jk, new, fit, text, deps))
        note = _simbody_note(jk, welded, fit_ranges)
        if note is not None:
            entries.append(note)
        if fit is not None:
            approx[jk.child] = (fit, jk)

    ordered = _depth_first(doc.ground.name, ujoints)
    markers = _marker_frames(doc, kin, names_used, entries)
    pm = _pinocchio(doc, links, ordered, markers)
    bounds = _bounds(doc, kin, approx, reach)
    joint_names = set(pm.names)
    coordinate_order = []
    for c in kin.coordinates:
        if c not in welded and c in joint_names:
            coordinate_order.append(c)
        coordinate_order += [d for d, rec in dependent.items() if c in rec.of and d not in coordinate_order]
    coordinate_order += [d for d in dependent if d not in coordinate_order]
    coordinate_order = tuple(coordinate_order)
    virtual = tuple(c for c in kin.coordinates if c not in welded and c not in joint_names)
    cmap = CoordinateMap(osim_coordinates=kin.coordinates, joints=tuple(pm.names[j] for j in range(1, pm.njoints)),
                         dependent=dependent, couplers=_coupler_functions(doc), defaults=kin.defaults,
                         welded=welded)
    entries += _coordinate_entries(doc, coords, welded, locked, coordinate_order)
    clamped = tuple(c.name for c in doc.coordinates if c.clamped and c.name not in welded)
    g = np.asarray(doc.gravity, dtype=float)
    entries.append(ReportEntry(element=f"{doc.source}: <gravity>", became=f"gravity {g.tolist()} m/s^2 (y up)"))
    if doc.length_units.lower() not in ("meters", "meter", "m") or doc.force_units.lower() not in ("n", "newtons"):
        entries.append(ReportEntry(element=f"{doc.source}: <length_units>/<force_units>",
                                   became=f"{doc.length_units!r}, {doc.force_units!r} are labels only: OpenSim "
                                          "reads every number as m, kg, N, rad, and so does pinmsk", status=NOTE))
    nb = len(doc.bodies)
    entries.append(ReportEntry(
        element=f"{doc.source}: <BodySet>", became=f"{nb} bodies -> Pinocchio bodies with their mass, centre of "
        f"mass and inertia (total mass {sum(b.mass for b in doc.bodies):.4f} kg)"))
    if dependent:
        entries.append(ReportEntry(
            element=f"{doc.source}: nonlinear joint axes",
            became=(f"{len(dependent)} dependent coordinates ({', '.join(dependent)}) -> Pinocchio joints of "
                    "their own, exact when their values are the axis functions of their coordinates "
                    f"(CoordinateMap, model.meta['coordinate_map'])"
                    + (f"; OpenSim coordinates {', '.join(virtual)} drive only such axes and are not Pinocchio "
                       "joints" if virtual else "")), status=NOTE))
    return Skeleton(doc=doc, kinematics=kin, pin_model=pm, links=links, joints=tuple(ordered), markers=markers,
                    entries=tuple(entries), bounds=bounds, coordinate_order=coordinate_order,
                    dependent=dependent, virtual=virtual, coordinate_map=cmap,
                    locked={c.name: c.default_value for c in doc.coordinates if c.locked},
                    welded=welded, clamped=clamped, couplings=tuple(couplings),
                    motion_types=_motion_types(kin), options={"locked": locked, "nonlinear": nonlinear})


def _inertia_matrix(v) -> tuple[tuple[float, ...], ...]:
    xx, yy, zz, xy, xz, yz = map(float, v)
    return ((xx, xy, xz), (xy, yy, yz), (xz, yz, zz))


def _couplings(doc, coords, ranges, entries):
    """The coupler constraints as records, and the ranges over which to fit their dependent coordinates."""
    out, fit_ranges = [], dict(ranges)
    for con in doc.constraints:
        for c in (con.dependent,) + con.independent:
            if c not in coords:
                raise ModelError(f"{con.where}: names coordinate '{c}', which the model does not have")
        f = fns.from_osim(con.function)
        rec = {"name": con.name, "dependent": con.dependent, "independent": list(con.independent),
               "scale_factor": con.scale_factor, "enforced": con.enforced, "function": repr(f)}
        out.append(rec)
        if con.enforced and len(con.independent) == 1:
            lo, hi = ranges[con.independent[0]]
            vals = con.scale_factor * f.value(np.linspace(lo, hi, 2001))
            fit_ranges[con.dependent] = (float(vals.min()), float(vals.max()))
        entries.append(ReportEntry(
            element=con.where,
            became=(f"{con.dependent} = {con.scale_factor:g} * {f!r}({', '.join(con.independent)}) recorded in "
                    f"model.meta['coupled_coordinates']; not enforced by the skeleton: '{con.dependent}' keeps a "
                    "value of its own, as in OpenSim's inverse dynamics (motions must give it; "
                    "CoordinateMap(couplers=True) sets it from the coupling)"),
            status=NOTE, details=rec))
    return out, fit_ranges


def _classify(ax: _Axis, welded: Mapping[str, float]):
    """('const', value) | ('pure', coordinate, slope, intercept) | ('nonlinear', coordinates)."""
    free = tuple(c for c in ax.coordinates if c not in welded)
    if not free:
        if not ax.coordinates:
            return ("const", float(ax.function.value(np.zeros(1))[0]))
        vals = {c: np.array([welded[c]]) for c in ax.coordinates}
        return ("const", float(ax.value(vals, 1)[0]))
    if len(ax.coordinates) == 1:
        a = ax.function.affine()
        if a is not None and abs(abs(a[0]) - 1.0) <= _UNIT_SLOPE_TOL:
            return ("pure", free[0], float(np.sign(a[0])), a[1])
    return ("nonlinear", free)


def _convert(jk: JointKinematics, *, welded, fit_ranges, kin, fit_samples, check_samples, nonlinear_mode):
    """The segments (('fixed', T) | (kind, axis, coordinate)) of one joint, its fit (or None), a note, and
    its dependent coordinates (``nonlinear_mode="exact"``)."""
    cls = [_classify(ax, welded) for ax in jk.axes]
    pure_coords = [c[1] for c in cls if c[0] == "pure"]
    nonlinear = [c for c in cls if c[0] == "nonlinear"]
    free = sorted({c for k in cls if k[0] != "const" for c in (k[1:2] if k[0] == "pure" else k[1])})
    exact = not nonlinear and len(pure_coords) == len(set(pure_coords))
    if exact:
        return _exact_segments(jk, cls), None, "", {}
    if nonlinear_mode == "exact":
        deps = {}
        seen = set()
        for i, (ax, k) in enumerate(zip(jk.axes, cls)):
            if k[0] == "pure" and k[1] in seen:      # a second axis driven by the same coordinate
                k = ("nonlinear", (k[1],))
            if k[0] == "nonlinear":
                name = f"{jk.joint.name}_{_AXIS_NAMES[ax.index]}"
                deps[name] = DependentCoordinate(name=name, joint=jk.joint.name, axis=_AXIS_NAMES[ax.index],
                                                 of=ax.coordinates, function=ax.function, where=ax.where,
                                                 welded={c: welded[c] for c in ax.coordinates if c in welded})
                k = ("pure", name, 1.0, 0.0)
            elif k[0] == "pure":
                seen.add(k[1])
            cls[i] = k
        return _exact_segments(jk, cls), None, "", deps
    if len(free) == 1:
        c = free[0]
        fit = _fit_one_dof(jk, c, fit_ranges[c], welded, kin, fit_samples, check_samples)
        segs = [("fixed", fit.P), (fit.kind, _Z, c), ("fixed", fit.C)]
        return segs, fit, "", {}
    return _fallback(jk, cls, welded, fit_ranges, kin, check_samples) + ({},)


def _exact_segments(jk: JointKinematics, cls) -> list:
    segs: list = [("fixed", jk.parent_offset)]
    shift = np.zeros(3)
    prismatic = []
    for ax, k in zip(jk.axes[3:], cls[3:]):
        if k[0] == "const":
            shift += k[1] * ax.direction
        else:
            _, c, sign, b = k
            shift += b * ax.direction
            prismatic.append(("prismatic", sign * ax.direction, c))
    segs.append(("fixed", _transform(p=shift)))
    segs += prismatic
    for ax, k in zip(jk.axes[:3], cls[:3]):
        if k[0] == "const":
            segs.append(("fixed", _transform(rotation(ax.direction, k[1])[0])))
        else:
            _, c, sign, b = k
            if b != 0.0:
                segs.append(("fixed", _transform(rotation(ax.direction, b)[0])))
            segs.append(("revolute", sign * ax.direction, c))
    segs.append(("fixed", _inverse(jk.child_offset)))
    return segs


def _probes(jk: JointKinematics, kin: OsimKinematics) -> np.ndarray:
    """Points fixed in the child body that the fit should keep in place: its origin, its centre of mass,
    its markers, the joints it carries, and +-L along its axes (L: the size of the rest)."""
    doc = kin.doc
    pts = [np.zeros(3)]
    body = doc.body(jk.child)
    pts.append(np.asarray(body.mass_center, dtype=float))
    for name, (b, T) in kin._marker_frames.items():
        if b == jk.child:
            pts.append(T[:3, 3])
    for other in kin.joints:
        if other.parent == jk.child:
            pts.append(other.parent_offset[:3, 3])
    pts = np.array(pts)
    L = max(0.05, float(np.max(np.linalg.norm(pts, axis=1))))
    return np.vstack([pts, L * np.eye(3), -L * np.eye(3)])


def _sampled_motion(jk, c, qs, welded, kin):
    vals = {name: np.full(qs.size, kin.defaults[name]) for name in jk.coordinates}
    vals.update({name: np.full(qs.size, v) for name, v in welded.items() if name in vals})
    vals[c] = qs
    return jk.child_in_parent(vals, qs.size)


def _model_motion(kind, P, C, qs):
    M = np.zeros((qs.size, 4, 4))
    M[:, 3, 3] = 1.0
    if kind == "revolute":
        M[:, :3, :3] = rotation(_Z, qs)
    else:
        M[:, :3, :3] = np.eye(3)
        M[:, 2, 3] = qs
    return P @ M @ C


def _fit_one_dof(jk, c, q_range, welded, kin, n_fit, n_check) -> _Fit:
    """The fixed-axis joint ``P R_z(q) C`` (or ``P T_z(q) C``) closest to the child's motion over the range."""
    from scipy.optimize import least_squares

    lo, hi = q_range
    qs = np.linspace(lo, hi, n_fit) if hi > lo else np.array([lo])
    D = _sampled_motion(jk, c, qs, welded, kin)
    probes = _probes(jk, kin)
    R, p = D[:, :3, :3], D[:, :3, 3]
    rotates = any(k == c for ax in jk.axes[:3] for k in ax.coordinates)
    kind = "revolute" if rotates else "prismatic"
    i0 = qs.size // 2
    dq = qs - qs[i0]
    if kind == "revolute":
        rv = np.array([pin.log3(R[s] @ R[i0].T) for s in range(qs.size)])
        u = (rv * dq[:, None]).sum(0) / max(float(dq @ dq), 1e-300)
        if not np.linalg.norm(u) > 1e-9:
            u = jk.axes[0].direction
        PR = _rotation_to(u / np.linalg.norm(u))
        CR = _project_so3(sum((PR @ rotation(_Z, qs[s])[0]).T @ R[s] for s in range(qs.size)))
        A = np.concatenate([np.broadcast_to(np.eye(3), (qs.size, 3, 3)), PR @ rotation(_Z, qs)], axis=2)
    else:
        slope = (p - p[i0]).T @ dq / max(float(dq @ dq), 1e-300)
        u = slope / np.linalg.norm(slope) if np.linalg.norm(slope) > 1e-12 else _Z
        PR = _rotation_to(u)
        CR = _project_so3(sum(PR.T @ R[s] for s in range(qs.size)))
        A = np.concatenate([np.broadcast_to(np.eye(3), (qs.size, 3, 3)),
                            np.broadcast_to(PR, (qs.size, 3, 3))], axis=2)
        p = p - qs[:, None] * u
    sol = np.linalg.lstsq(A.reshape(-1, 6), p.reshape(-1), rcond=None)[0]
    P0, C0 = _transform(PR, sol[:3]), _transform(CR, sol[3:])
    target = (D[:, None, :3, :3] @ probes[None, :, :, None])[..., 0] + D[:, None, :3, 3]

    def unpack(x):
        return P0 @ pin.exp6(x[:6]).homogeneous, pin.exp6(x[6:]).homogeneous @ C0

    J = _model_motion(kind, np.eye(4), np.eye(4), qs)     # the joint's own motion: fixed samples

    def residual(x):
        P, C = unpack(x)
        y = probes @ C[:3, :3].T + C[:3, 3]                    # probes in the joint's moving frame
        y = np.einsum("nij,kj->nki", J[:, :3, :3], y) + J[:, None, :3, 3]
        got = y @ P[:3, :3].T + P[:3, 3]
        return np.concatenate([(got - target).ravel(), 1e-6 * x])

    x = np.zeros(12)
    if np.max(np.abs(residual(x)[:-12])) > 1e-12:
        x = least_squares(residual, x, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000).x
    P, C = unpack(x)
    if kind == "revolute":   # slide the joint frame along its axis to the point nearest the joint centre
        delta = float((jk.parent_offset[:3, 3] - P[:3, 3]) @ P[:3, 2])
        P, C = P @ _transform(p=delta * _Z), _transform(p=-delta * _Z) @ C
    qc = np.linspace(lo, hi, n_check) if hi > lo else np.array([lo])
    De = _sampled_motion(jk, c, qc, welded, kin)
    Da = _model_motion(kind, P, C, qc)
    et = float(np.max(np.linalg.norm(De[:, :3, 3] - Da[:, :3, 3], axis=1)))
    theta = _angle(np.swapaxes(De[:, :3, :3], 1, 2) @ Da[:, :3, :3])
    return _Fit(kind, P, C, (lo, hi), et, float(theta.max()), float(np.max(2 * np.sin(theta / 2))))


def _fallback(jk, cls, welded, fit_ranges, kin, n_check):
    """A joint whose several coordinates drive nonlinear axes: pure axes exact, each nonlinear axis frozen at
    the coordinates' default values (a coordinate with no pure axis drives its first axis as if of slope 1);
    the error is sampled at random poses within the ranges."""
    have_pure = {k[1] for k in cls if k[0] == "pure"}
    new = []
    for ax, k in zip(jk.axes, cls):
        if k[0] != "nonlinear":
            new.append(k)
            continue
        own = [c for c in k[1] if c not in have_pure]
        if len(ax.coordinates) == 1 and own:
            new.append(("pure", own[0], 1.0, 0.0))
            have_pure.add(own[0])
        else:
            vals = {c: np.array([welded.get(c, kin.defaults[c])]) for c in ax.coordinates}
            new.append(("const", float(ax.value(vals, 1)[0])))
    segs = _exact_segments(jk, new)
    # a grid over the ranges (ends included, where the extremes usually are) plus random poses
    free = [c for c in jk.coordinates if c not in welded]
    k = max(3, int(round(4000 ** (1.0 / max(1, len(free))))))
    grids = np.meshgrid(*[np.linspace(*fit_ranges[c], k) for c in free], indexing="ij")
    rng = np.random.default_rng(0)
    vals = {c: np.full(grids[0].size + n_check, welded.get(c, kin.defaults[c])) for c in jk.coordinates}
    for c, g in zip(free, grids):
        vals[c] = np.concatenate([g.ravel(), rng.uniform(*fit_ranges[c], n_check)])
    n_check = grids[0].size + n_check
    De = jk.child_in_parent(vals, n_check)
    Da = np.broadcast_to(np.eye(4), (n_check, 4, 4)).copy()
    for s in segs:
        if s[0] == "fixed":
            Da = Da @ s[1]
        else:
            M = np.zeros((n_check, 4, 4))
            M[:, 3, 3] = 1.0
            if s[0] == "revolute":
                M[:, :3, :3] = rotation(s[1], vals[s[2]])
            else:
                M[:, :3, :3] = np.eye(3)
                M[:, :3, 3] = vals[s[2]][:, None] * s[1]
            Da = Da @ M
    et = float(np.max(np.linalg.norm(De[:, :3, 3] - Da[:, :3, 3], axis=1)))
    theta = _angle(np.swapaxes(De[:, :3, :3], 1, 2) @ Da[:, :3, :3])
    fit = _Fit("chain", np.eye(4), np.eye(4), (np.nan, np.nan), et, float(theta.max()),
               float(np.max(2 * np.sin(theta / 2))), sampled=True)
    return segs, fit, "nonlinear axes frozen at the default values"


def _chain_joints(jk: JointKinematics, segs, ranges, names_used: set) -> list[UrdfJoint]:
    """URDF joints for one OpenSim joint: movable joints named after their coordinates, fixed placements
    folded into the next joint's origin, a fixed joint where the child body is not at the last joint frame."""
    out: list[UrdfJoint] = []
    M = np.eye(4)
    parent = jk.parent
    movable = [s for s in segs if s[0] != "fixed"]
    for s in segs:
        if s[0] == "fixed":
            M = M @ s[1]
            continue
        last = s is movable[-1]
        child = jk.child if last else _unique(f"{jk.joint.name}_{s[2]}", names_used)
        out.append(UrdfJoint(name=s[2], kind=s[0], parent=parent, child=child, origin=M,
                             axis=tuple(float(a) for a in s[1]), limits=ranges[s[2]]))
        parent, M = child, np.eye(4)
    if not movable:
        out.append(UrdfJoint(name=_unique(jk.joint.name, names_used), kind="fixed", parent=parent,
                             child=jk.child, origin=M))
    elif not np.allclose(M, np.eye(4), rtol=0.0, atol=1e-15):
        # the child body sits at an offset from the last joint frame: rename the last link, add a fixed joint
        tail = out[-1]
        link = _unique(f"{jk.joint.name}_{tail.name}", names_used)
        out[-1] = UrdfJoint(tail.name, tail.kind, tail.parent, link, tail.origin, tail.axis, tail.limits)
        out.append(UrdfJoint(name=_unique(f"{jk.joint.name}_offset", names_used), kind="fixed", parent=link,
                             child=jk.child, origin=M))
    return out


def _unique(name: str, used: set) -> str:
    out, i = name, 1
    while out in used:
        out = f"{name}_{i}"
        i += 1
    used.add(out)
    return out


def _depth_first(root: str, joints: Sequence[UrdfJoint]) -> list[UrdfJoint]:
    """The joints in the order Pinocchio's URDF parser visits them: depth first, children by joint name."""
    children: dict[str, list[UrdfJoint]] = {}
    for uj in joints:
        children.setdefault(uj.parent, []).append(uj)
    out: list[UrdfJoint] = []

    def visit(link):
        for uj in sorted(children.get(link, []), key=lambda j: j.name):
            out.append(uj)
            visit(uj.child)

    visit(root)
    return out


def _marker_frames(doc, kin, names_used, entries) -> dict[str, tuple[str, np.ndarray]]:
    out = {}
    renamed = []
    for m in doc.markers:
        body, T = kin._marker_frames[m.name]
        name = m.name if m.name not in names_used else _unique(f"{m.name}_marker", names_used)
        if name != m.name:
            renamed.append(f"{m.name} -> {name}")
        names_used.add(name)
        out[name] = (body, T)
    if doc.markers:
        text = f"{len(doc.markers)} markers -> Pinocchio frames on their bodies"
        if renamed:
            text += f" (renamed where a body or joint has the name: {', '.join(renamed)})"
        entries.append(ReportEntry(element=f"{doc.source}: <MarkerSet>", became=text,
                                   status=NOTE if renamed else EXACT))
    return out


def _joint_model(kind: str, axis) -> pin.JointModel:
    a = np.asarray(axis, dtype=float)
    for i, name in enumerate("XYZ"):
        if np.array_equal(a, np.eye(3)[i]):
            return getattr(pin, f"JointModel{'R' if kind == 'revolute' else 'P'}{name}")()
    return pin.JointModelRevoluteUnaligned(a) if kind == "revolute" else pin.JointModelPrismaticUnaligned(a)


def _inertia(link: UrdfLink, source: str = "") -> pin.Inertia:
    if link.inertia is None:
        return pin.Inertia.Zero()
    com, inertia = np.asarray(link.com, dtype=float), np.asarray(link.inertia, dtype=float)
    if not (np.isfinite(link.mass) and np.all(np.isfinite(com)) and np.all(np.isfinite(inertia))):
        where = f"{source}: " if source else ""
        raise ModelError(f"{where}body {link.name!r}: mass {link.mass!r}, mass_center {com.tolist()} and "
                         f"inertia {inertia.ravel().tolist()} must be finite numbers")
    return pin.Inertia(link.mass, com, inertia)


def _pinocchio(doc, links, ordered, markers) -> pin.Model:
    """The Pinocchio model, built as ``pinocchio.buildModelFromUrdf`` builds it from the written URDF."""
    pm = pin.Model()
    pm.name = doc.name
    root = doc.ground.name
    fid = pm.addFrame(pin.Frame(root, 0, 0, pin.SE3.Identity(), pin.FrameType.BODY))
    at = {root: (0, pin.SE3.Identity(), fid)}
    for uj in ordered:
        pj, pM, pf = at[uj.parent]
        placement = pM * pin.SE3(uj.origin)
        Y = _inertia(links[uj.child], doc.source)
        if uj.kind == "fixed":
            ff = pm.addFrame(pin.Frame(uj.name, pj, pf, placement, pin.FrameType.FIXED_JOINT))
            pm.appendBodyToJoint(pj, Y, placement)
            bf = pm.addBodyFrame(uj.child, pj, placement, ff)
            at[uj.child] = (pj, placement, bf)
        else:
            lo, hi = uj.limits
            jid = pm.addJoint(pj, _joint_model(uj.kind, uj.axis), placement, uj.name,
                              np.array([EFFORT_LIMIT]), np.array([VELOCITY_LIMIT]), np.array([lo]), np.array([hi]))
            jf = pm.addJointFrame(jid, pf)
            pm.appendBodyToJoint(jid, Y, pin.SE3.Identity())
            bf = pm.addBodyFrame(uj.child, jid, pin.SE3.Identity(), jf)
            at[uj.child] = (jid, pin.SE3.Identity(), bf)
    for name, (body, T) in markers.items():
        pj, pM, pf = at[body]
        pm.addFrame(pin.Frame(name, pj, pf, pM * pin.SE3(T), pin.FrameType.OP_FRAME))
    pm.gravity = pin.Motion(np.concatenate([np.asarray(doc.gravity, dtype=float), np.zeros(3)]))
    return pm


def _max_translation(jk, fit, ranges, welded) -> float:
    """An upper bound of |child origin in the parent body frame| over the coordinates' ranges (exact and model)."""
    total = float(np.linalg.norm(jk.parent_offset[:3, 3]) + np.linalg.norm(jk.child_offset[:3, 3]))
    for ax in jk.axes[3:]:
        free = [c for c in ax.coordinates if c not in welded]
        if not ax.coordinates:
            total += abs(float(ax.function.value(np.zeros(1))[0]))
            continue
        grids = np.meshgrid(*[np.linspace(*ranges[c], 201 if len(free) == 1 else 21) if c in free
                              else np.array([welded[c]]) for c in ax.coordinates], indexing="ij")
        vals = {c: g.ravel() for c, g in zip(ax.coordinates, grids)}
        total += float(np.max(np.abs(ax.value(vals, grids[0].size)))) * 1.01
    if fit is not None:
        total = max(total, float(np.linalg.norm(fit.P[:3, 3]) + np.linalg.norm(fit.C[:3, 3])))
    return total


def _bounds(doc, kin, approx, reach) -> dict[str, float]:
    """Triangle-inequality bounds of each body's, marker's and the centre of mass's position error."""
    parent_of = {jk.child: jk.parent for jk in kin.joints}

    def point_bound(body: str, r: float) -> float:
        total, below = 0.0, r
        b = body
        while b in parent_of:
            if b in approx:
                fit, _ = approx[b]
                total += fit.max_translation_error + fit.operator_rotation_error * below
            below += reach[b]
            b = parent_of[b]
        return total

    out = {}
    if not approx:
        return out
    for b in doc.bodies:
        v = point_bound(b.name, 0.0)
        if v > 0:
            out[b.name] = v
    for name, (body, T) in kin._marker_frames.items():
        v = point_bound(body, float(np.linalg.norm(T[:3, 3])))
        if v > 0:
            out[name] = v
    m = sum(b.mass for b in doc.bodies)
    if m > 0:
        v = sum(b.mass * point_bound(b.name, float(np.linalg.norm(b.mass_center))) for b in doc.bodies) / m
        if v > 0:
            out["center_of_mass"] = v
    return out


#: What OpenSim's InverseDynamicsTool does differently on a FreeJoint or BallJoint (Simbody's Free and Ball
#: mobilizers: speeds u = angular velocity, q' = N(q) u), and what that changes.
EULER_RATE_NOTE = (
    "OpenSim's InverseDynamicsTool reads the Euler-angle rates of the motion's FreeJoint/BallJoint rotations "
    "as the joint's speeds (angular-velocity components) and their second derivatives as its accelerations, "
    "so its results follow a different motion: the moments of these rotations, the forces of the joint's "
    "translations and the moments of every joint beyond it differ from pinmsk's, which differentiate the "
    "angles (physically consistent, as OpenSim's own solver gives with consistent speeds)")


def _joint_entry(jk: JointKinematics, new: list[UrdfJoint], fit: _Fit | None, text: str, deps) -> ReportEntry:
    movable = [uj for uj in new if uj.kind != "fixed"]
    if not movable:
        became = f"fixed: '{jk.child}' welded to '{jk.parent}'"
    elif fit is not None and not fit.sampled:
        axis = fit.P[:3, 2]
        became = (f"{fit.kind} '{movable[0].name}' {'about' if fit.kind == 'revolute' else 'along'} a fitted fixed "
                  f"axis {_axis_text(axis)} (in '{jk.parent}', through {np.round(fit.P[:3, 3], 5).tolist()} m) "
                  f"('{jk.parent}' -> '{jk.child}')")
    else:
        became = "; ".join(f"{uj.kind} '{uj.name}' about {_axis_text(uj.axis)}" if uj.kind == "revolute"
                           else f"{uj.kind} '{uj.name}' along {_axis_text(uj.axis)}" for uj in movable)
        became = f"{'chain of ' if len(movable) > 1 else ''}{became} ('{jk.parent}' -> '{jk.child}')"
    if fit is None:
        if deps:
            became += (f"; exact with dependent coordinates {', '.join(deps)} (the nonlinear axes' "
                       "functions of their coordinates)")
        if jk.joint.type in ("FreeJoint", "BallJoint"):
            # Simbody's Free and Ball mobilizers take the angular velocity as their speeds, not the angles' rates
            became += ("; NOTE: " + EULER_RATE_NOTE)
            return ReportEntry(element=jk.joint.where, became=became, status=NOTE)
        return ReportEntry(element=jk.joint.where, became=became)
    details = {"max_origin_error_m": fit.max_translation_error, "max_rotation_error_rad": fit.max_rotation_error,
               "range": list(fit.q_range), "sampled": fit.sampled}
    nonlinear = [f"{('rotation', 'translation')[ax.index // 3]}{ax.index % 3 + 1} = {ax.function!r}"
                 for ax in jk.axes if not (isinstance(ax.function, fns.Constant)
                                           or (ax.function.affine() is not None
                                               and abs(abs(ax.function.affine()[0]) - 1) <= _UNIT_SLOPE_TOL))]
    what = (f"its axes {'; '.join(_short(n) for n in nonlinear)} are nonlinear in the coordinate; "
            if nonlinear else "")
    if fit.sampled:
        approx_text = f"{what}{text}; error sampled on a grid over the ranges and at random poses"
    else:
        approx_text = (f"{what}replaced by the best-fitting fixed-axis {fit.kind} joint over "
                       f"[{fit.q_range[0]:.4g}, {fit.q_range[1]:.4g}]")
    approx_text += (f"; child-body origin off by up to {fit.max_translation_error * 1000:.3g} mm, orientation by "
                    f"up to {np.degrees(fit.max_rotation_error):.3g} deg")
    return ReportEntry(element=jk.joint.where, became=became, approximation=approx_text,
                       max_error=fit.max_translation_error, status=APPROXIMATED, details=details)


def _simbody_note(jk: JointKinematics, welded, fit_ranges) -> ReportEntry | None:
    """A note where OpenSim's own accelerations of a CustomJoint carry Simbody's FunctionBased velocity
    term (:func:`simbody_rotation_term`): its largest size over the coordinates' ranges at unit speeds."""
    free = [c for c in jk.coordinates if c not in welded]
    if jk.joint.type != "CustomJoint" or not free:
        return None
    # a grid of about 2,000 poses whatever the number of coordinates (a 6-coordinate pelvis at 9 per axis
    # would be half a million, seconds of import for a note)
    k = 41 if len(free) == 1 else max(3, int(round(2000.0 ** (1.0 / len(free)))))
    grids = np.meshgrid(*[np.linspace(*fit_ranges[c], k) for c in free], indexing="ij")
    n = grids[0].size
    values = {c: np.full(n, welded[c]) for c in jk.coordinates if c in welded}
    values.update({c: g.ravel() for c, g in zip(free, grids)})
    speeds = {c: np.zeros(n) if c in welded else np.ones(n) for c in jk.coordinates}
    dA, _ = simbody_rotation_term(jk, values, speeds, n)
    worst = float(np.max(np.linalg.norm(dA, axis=1)))
    if not worst > 1e-9:
        return None
    return ReportEntry(element=jk.joint.where, status=NOTE, details={"max_term_rad_s2": worst}, became=(
        f"OpenSim's accelerations of this joint carry Simbody's FunctionBased velocity term (its rotations "
        f"are functions of shared coordinates; simbody_rotation_term): up to {worst:.3g} rad/s^2 at 1 rad/s "
        f"of {', '.join(free)} (it grows with the speed squared), so OpenSim's inverse dynamics differs from "
        "the exact one pinmsk computes by it (tests/test_osim_id.py)"))


def _short(text: str, n: int = 60) -> str:
    return text if len(text) <= n else text[:n - 3] + "..."


def _axis_text(axis) -> str:
    a = np.asarray(axis, dtype=float)
    for i, name in enumerate("xyz"):
        if np.allclose(a, np.eye(3)[i], atol=1e-12):
            return name
        if np.allclose(a, -np.eye(3)[i], atol=1e-12):
            return f"-{name}"
    return "[" + ", ".join(f"{v:.4g}" for v in a) + "]"


def _coordinate_entries(doc, coords, welded, locked, coordinate_order) -> list[ReportEntry]:
    out = []
    for c in doc.coordinates:
        if c.locked:
            if c.name in welded:
                text = (f"locked at {c.default_value:g}: welded at that value (locked='weld'), so it is not a "
                        "coordinate of the pinmsk model")
            else:
                text = (f"locked at {c.default_value:g} in OpenSim: kept as a joint (locked='joint'; pinmsk does "
                        "not hold it, motions must give it; locked='weld' fixes it instead), listed in "
                        "model.meta['locked_coordinates']")
            out.append(ReportEntry(element=c.where, became=text, status=NOTE))
        if c.prescribed and c.prescribed_function is not None:
            out.append(ReportEntry(element=c.where, became="its prescribed motion (prescribed_function) is not "
                                   "imported; the coordinate is free", status=NOT_IMPORTED))
    ncl = sum(1 for c in doc.coordinates if c.clamped and c.name not in welded)
    out.append(ReportEntry(
        element=f"{doc.source}: <Coordinate> ranges",
        became=(f"{len(coordinate_order)} coordinates -> Pinocchio joints with their ranges as position limits "
                f"({ncl} clamped in OpenSim, listed in model.meta['clamped_coordinates']; the others' ranges are "
                "informational in OpenSim too)")))
    return out


def _motion_types(kin: OsimKinematics) -> dict[str, str]:
    """OpenSim's motion type of each coordinate: Rotational or Translational if it drives some axis as a
    pure line of slope +-1 (the last such axis decides), else Coupled (CustomJoint::constructCoordinates)."""
    out = {}
    for jk in kin.joints:
        for c in jk.coordinates:
            mt = "Undefined"
            for ax in jk.axes:
                if c not in ax.coordinates:
                    continue
                a = ax.function.affine() if isinstance(ax.function, fns.LinearFunction) else None
                if a is not None and abs(a[0]) == 1.0:
                    mt = "Rotational" if ax.index < 3 else "Translational"
                elif mt == "Undefined":
                    mt = "Coupled"
            out[c] = mt
    return out
