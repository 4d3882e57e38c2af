"""Sphere-against-ground contact: geometry, site kinematics and the component base class.

A contact *sphere* is fixed to a body frame (its *site*, e.g. ``heel_r``) with
its centre at the site plus an offset ``(dx, dy)`` in the site's frame (the
relaxation of thesis Sec. 4.1.4).  The ground is the plane ``y = 0`` with
upward normal ``n = (0, 1, 0)`` (world x forward, y up, z right); it may move
tangentially at ``ground_speed`` m/s along x (a treadmill belt).

Everything here is vectorised over frames: a :class:`SiteKinematics` holds the
site's world position, orientation, velocity and angular velocity for N frames
(computed once per motion by :meth:`SphereContact.prepare` through Pinocchio),
and the force laws are plain numpy on ``(N,)`` arrays, so one evaluation of 3
spheres over 1,000 frames costs tens of microseconds.  The laws go through
:mod:`pinmsk.backend` (and run on :class:`~pinmsk.contact.dual.Dual` numbers), so
:meth:`FrameContact.wrench_at` evaluates the same code at one state of the site
on CasADi values: one frame, scalars ``(1, 1)`` and vectors rows ``(1, 3)``.

Smoothness.  The penetration ``delta = R - h`` (``h`` the centre's height) is
replaced by the smooth positive part

    delta_s = (delta + sqrt(delta^2 + eps^2)) / 2,      eps = ``smoothing`` (default 0.1 mm)

which is C-infinity, equals ``delta`` to within ``eps^2 / (4 delta)`` in
contact, and decays like ``eps^2 / (4 |delta|)`` out of contact (1e-8 m at 0.25 m
clearance).  With it every force law below is C1 (indeed smooth) in the
kinematics and the parameters, so gradient-based solvers can use them; the
raw ``delta`` is still reported (``penetration``) to decide "in contact".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np
import pinocchio as pin

from ..backend import backend_of, is_symbolic
from ..components import Component, Motion, Parameter, _replace, motion_cached
from ..errors import ModelError
from .dual import asarray, vector
from .friction import regularized_coulomb

UP = np.array([0.0, 1.0, 0.0])


# -- closed-form geometry -----------------------------------------------------

def cross(a, b):
    """Row-wise cross product of (N, 3) arrays or :class:`~pinmsk.contact.dual.Dual` s
    (np.cross costs ~10x more on small arrays)."""
    if is_symbolic(a) or is_symbolic(b):       # CasADi rows (1, 3): one frame
        a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
        b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
        return vector(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return vector(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def smooth_positive(x, eps: float):
    """``(x + sqrt(x^2 + eps^2)) / 2``: a C-infinity positive part (-> max(x, 0) as eps -> 0)."""
    x = asarray(x)
    return 0.5 * (x + backend_of(x).sqrt(x * x + eps * eps))


#: force scale (N) below which :func:`no_adhesion` blends the normal force smoothly into zero
ADHESION_EPS = 1e-3


def no_adhesion(f, eps: float = ADHESION_EPS):
    """The normal force with the pulling part removed, C1: ``f`` for ``f >= eps``, 0 for ``f <= 0``,
    and ``2 f^2 / eps - f^3 / eps^2`` in between (value and slope match at both ends).

    The damping terms of Eq. 4.4, 4.8 and 4.15 turn the force negative when a sphere leaves the
    ground faster than ``1 / a``; the ground cannot pull, so that part is removed (measured on the
    CSU data before this: up to -280 N at lift-off, which a fit could use as a free force).
    """
    f = asarray(f)
    xp = backend_of(f)
    x = xp.clip(f, 0.0, eps)
    return xp.where(f >= eps, f, x * x * (2.0 / eps - x / (eps * eps)))


def cap_volume(depth, radius):
    """Volume of a spherical cap of height ``depth`` cut from a sphere of ``radius`` (Eq. 4.5).

    ``V = pi d^2 (3R - d) / 3`` for ``0 <= d <= 2R`` (``d`` is clipped to that range).
    """
    radius = asarray(radius)
    d = backend_of(depth, radius).clip(asarray(depth), 0.0, 2.0 * radius)
    return math.pi * d * d * (3.0 * radius - d) / 3.0


def cap_centroid_depth(depth, radius):
    """Distance from the sphere centre to the centroid of the cap of height ``depth``.

    ``zbar = 3 (2R - d)^2 / (4 (3R - d))``; it tends to R as d -> 0 (the centroid
    starts at the lowest point of the sphere) and to 0 at d = 2R.
    """
    radius = asarray(radius)
    d = backend_of(depth, radius).clip(asarray(depth), 0.0, 2.0 * radius)
    return 3.0 * (2.0 * radius - d) ** 2 / (4.0 * (3.0 * radius - d))


# -- kinematics ---------------------------------------------------------------

@dataclass(frozen=True)
class SiteKinematics:
    """World kinematics of a body frame over N frames (all time-first).

    ``position`` (N, 3), ``rotation`` (N, 3, 3) (site to world), ``velocity``
    (N, 3) of the frame origin, ``omega`` (N, 3) angular velocity, and
    optionally ``jacobian`` (N, 6, nv), the LOCAL_WORLD_ALIGNED frame Jacobian
    (linear rows first), used for the generalized force ``J^T w``.
    """

    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    jacobian: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return self.position.shape[0]

    def point(self, offset_local: np.ndarray):
        """World position and velocity of the body point at ``offset_local`` (3,) or (N, 3)."""
        off = asarray(offset_local)
        if is_symbolic(self.rotation):           # one frame under CasADi: rotation (3, 3), rows (1, 3)
            r = (self.rotation @ (off.T if is_symbolic(off) and off.shape == (1, 3) else off)).T
            return self.position + r, self.velocity + cross(self.omega, r)
        r = np.einsum("nij,j->ni" if off.ndim == 1 else "nij,nj->ni", self.rotation, off)
        return self.position + r, self.velocity + cross(self.omega, r)


def site_kinematics(model, frame: str, q: np.ndarray, v: np.ndarray, *,
                    jacobian: bool = True, pin_data=None) -> SiteKinematics:
    """:class:`SiteKinematics` of Pinocchio frame ``frame`` over the rows of ``q, v`` (one FK per frame).

    ``pin_data``: a Pinocchio ``Data`` of the model to work in (default: a new one)."""
    pm = model.pin if hasattr(model, "pin") else model
    fid = model.frame_id(frame) if hasattr(model, "frame_id") else pm.getFrameId(frame)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    v = np.atleast_2d(np.asarray(v, dtype=float))
    n = q.shape[0]
    pd = pm.createData() if pin_data is None else pin_data
    pos = np.empty((n, 3))
    rot = np.empty((n, 3, 3))
    vel = np.empty((n, 3))
    om = np.empty((n, 3))
    jac = np.empty((n, 6, pm.nv)) if jacobian else None
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for i in range(n):
        pin.forwardKinematics(pm, pd, q[i], v[i])
        pl = pin.updateFramePlacement(pm, pd, fid)
        pos[i] = pl.translation
        rot[i] = pl.rotation
        mv = pin.getFrameVelocity(pm, pd, fid, lwa)
        vel[i] = mv.linear
        om[i] = mv.angular
        if jacobian:
            jac[i] = pin.computeFrameJacobian(pm, pd, q[i], fid, lwa)
    return SiteKinematics(pos, rot, vel, om, jac)


# -- results ------------------------------------------------------------------

@dataclass(frozen=True)
class ContactForces:
    """What one contact element produces over N frames (world frame, SI).

    ``normal`` (N,) normal force magnitude along +y (N); ``friction`` (N, 3)
    tangential force (N); ``force`` (N, 3) = normal * n + friction, the force
    the ground applies to the body; ``point`` (N, 3) its point of application
    (the centroid of the penetrating cap, or the ground point below a point
    contact); ``penetration`` (N,) raw ``R - h`` (> 0 in contact, m);
    ``volume`` (N,) the cap volume (m^3, zero for a point contact);
    ``slip`` (N, 3) the tangential velocity of the application point relative to
    the ground (m/s).
    """

    normal: np.ndarray
    friction: np.ndarray
    force: np.ndarray
    point: np.ndarray
    penetration: np.ndarray
    volume: np.ndarray
    slip: np.ndarray


# -- component base -----------------------------------------------------------

FRICTION_PARAMETERS = (
    Parameter("mu_f", 0.2, 1e-3, 1.0, "", "friction coefficient of Eq. 4.17 (dry limit = pi/2 mu_f)"),
    Parameter("v_s", 0.02, 1e-6, 0.1, "m/s", "friction shape speed of Eq. 4.17"),
)
OFFSET_PARAMETERS = (
    Parameter("dx", 0.0, -0.02, 0.02, "m", "centre offset along the site frame's x (Sec. 4.1.4)", vary=False),
    Parameter("dy", 0.0, -0.02, 0.02, "m", "centre offset along the site frame's y (Sec. 4.1.4)", vary=False),
)


class FrameContact(Component):
    """What every contact element shares: a sphere fixed to the body frame ``target``, whose
    :meth:`evaluate_kinematics` turns the frame's :class:`SiteKinematics` into
    :class:`ContactForces`; :meth:`prepare` computes those kinematics (with Jacobians) once per
    motion, and :meth:`generalized_force` is ``J^T`` of the world wrench.  Subclasses define
    :meth:`evaluate_kinematics` and :meth:`_options` (the settings that are not parameters, which
    equality compares as it compares the parameters)."""

    kind: ClassVar[str] = "contact"
    target_kind: ClassVar[str] = "frame"

    def __init__(self, target: str, *, bounds: Mapping[str, tuple[float, float]] | None = None, **values: float):
        self._start(target, bounds)
        self._finish(values)

    def _start(self, target, bounds) -> None:
        """The parameters at their defaults, with per-element ``bounds`` ``{name: (lo, hi)}`` replacing
        the class's (subclasses check their options between this and :meth:`_finish`)."""
        if target is None:
            raise ModelError(f"{self.family}: give the frame the sphere is fixed to, e.g. 'heel_r'")
        declared = {p.name for p in self.parameters}
        # check the new bounds before the values, so a value allowed only by them passes
        self._bounds_override = {}
        for name, (lo, hi) in (bounds or {}).items():
            if name not in declared:
                raise ModelError(f"{self.family}:{target}: bounds for unknown parameter '{name}'; "
                                 f"it has {sorted(declared)}")
            if not lo <= hi:
                raise ModelError(f"{self.family}:{target}: bounds for '{name}' are [{lo}, {hi}]; lower > upper")
            self._bounds_override[name] = (float(lo), float(hi))
        Component.__init__(self, target)  # defaults first (class bounds)
        params = dict(self._params)
        for name, (lo, hi) in self._bounds_override.items():
            p = params[name]
            params[name] = _replace(p, min=lo, max=hi, value=float(np.clip(p.value, lo, hi)))
        self._params = params

    def _finish(self, values) -> None:
        """The parameter ``values`` given, checked against the (new) bounds."""
        if values:
            self._params = self.with_params(dict(values))._params

    def evaluate_kinematics(self, kin: SiteKinematics, params: Mapping[str, Any] | None = None) -> ContactForces:
        raise NotImplementedError

    def prepare(self, model, motion: Motion, data=None) -> SiteKinematics:
        """The site's :class:`SiteKinematics` with Jacobians (cached in ``data``, a
        :class:`pinmsk.model.Data`, when given)."""
        return motion_cached(
            data, model, ("site", model.frame_id(self.target)), motion,
            lambda pd: site_kinematics(model, self.target, motion.q, motion.v, jacobian=True, pin_data=pd))

    def evaluate(self, model, motion: Motion, params=None, cache: SiteKinematics | None = None) -> ContactForces:
        """:class:`ContactForces` over the frames of ``motion``."""
        kin = cache if cache is not None else self.prepare(model, motion)
        return self.evaluate_kinematics(kin, params)

    def generalized_force(self, model, motion: Motion, params=None, cache=None) -> np.ndarray:
        """``J^T w`` (N, nv): the world wrench of the contact force at its application point."""
        kin = cache if cache is not None else self.prepare(model, motion)
        if kin.jacobian is None:
            kin = site_kinematics(model, self.target, motion.q, motion.v, jacobian=True)
        out = self.evaluate_kinematics(kin, params)
        return wrench_generalized_force(kin, out.force, out.point)

    def wrench_at(self, p, R, v, w, params: Mapping[str, Any] | None = None):
        """``(force, moment)`` in the world at ONE state of the site frame, numpy or CasADi.

        ``p`` (3,) world position of the site frame's origin, ``R`` (3, 3) its rotation (site to
        world), ``v`` (3,) the linear velocity of its origin and ``w`` (3,) its angular velocity,
        all world-aligned (Pinocchio's LOCAL_WORLD_ALIGNED frame velocity).  Returns the force the
        ground applies to the body and its moment about the site origin, ``(point - p) x force``,
        so that the generalized force is ``J_lin^T force + J_ang^T moment`` with the site's
        LOCAL_WORLD_ALIGNED Jacobian, as :meth:`generalized_force` computes it.  The same
        :meth:`evaluate_kinematics` (one frame): numpy inputs give numpy (3,) arrays equal to the
        batched values; any CasADi input gives CasADi (3, 1) columns (``params`` numbers).
        """
        if backend_of(p, R, v, w).symbolic:
            import casadi as ca

            sym = ca.MX if any(isinstance(x, ca.MX) for x in (p, R, v, w)) else ca.SX

            def row(x):
                return ca.reshape(sym(x) if not is_symbolic(x) else x, 1, 3)

            R = sym(np.asarray(R, dtype=float)) if not is_symbolic(R) else R
            kin = SiteKinematics(row(p), R, row(v), row(w))
            out = self.evaluate_kinematics(kin, params)
            moment = cross(out.point - kin.position, out.force)
            return out.force.T, moment.T
        kin = SiteKinematics(*(np.asarray(x, dtype=float)[None] for x in (p, R, v, w)))
        out = self.evaluate_kinematics(kin, params)
        moment = cross(out.point - kin.position, out.force)
        return out.force[0], moment[0]

    def generalized_force_at(self, model, q, v):
        """Refused by name: a contact needs its site's kinematics, which the optimal-control engine
        computes (the skeleton is Pinocchio's); it evaluates :meth:`wrench_at` on them."""
        raise ModelError(f"component {self.label} has no closed form the optimal-control engine can use in "
                         "(q, v) alone; evaluate wrench_at(p, R, v, w) on its site's kinematics")

    def check_target(self, model) -> None:
        model.frame_id(self.target)

    def _options(self) -> tuple:
        return ()

    # the options change the force as the parameters do, so equal spheres must share them
    def __eq__(self, other) -> bool:
        return super().__eq__(other) and self._options() == other._options()

    def __hash__(self) -> int:
        return hash((super().__hash__(), self._options()))


class SphereContact(FrameContact):
    """Base class of the contact elements: a sphere fixed to ``target`` (a frame) against y = 0.

    Subclasses implement :meth:`normal_law`, returning ``(f_n, volume,
    centroid_depth)`` from the smoothed penetration, the penetration rate and
    the parameters.  Keyword options (not fitted):

    ``ground_speed``  x-velocity of the ground surface (m/s; a treadmill belt
                      moving backwards is negative); friction and damping see
                      the slip relative to it.
    ``smoothing``     eps of the smooth positive part of the penetration (m).
    ``bounds``        per-element parameter bounds ``{name: (lo, hi)}`` that
                      replace the class defaults (e.g. Table 4.2's radius bound
                      differs between heel, metatarsal and toe).
    ``center``        where the sphere centre sits relative to the site, in the
                      site's frame (the fitted dx, dy add to it): ``None`` (at the
                      site, the thesis foot2d convention: sites H, P, T are the
                      centres), ``"sole"`` (``(0, +R)``: the site is the sphere's
                      lowest point when the frame is level, so a site on the sole
                      touches the ground without penetrating; follows the fitted
                      radius / rest length), or a fixed ``(x, y)`` in m.
    """

    #: name of the parameter playing the sphere radius / rest length
    radius_name: ClassVar[str] = "R"
    #: name of the stiffness parameter (for sensitivity studies)
    stiffness_name: ClassVar[str] = "k"

    def __init__(self, target: str, *, ground_speed: float = 0.0, smoothing: float = 1e-4,
                 bounds: Mapping[str, tuple[float, float]] | None = None, center=None, **values: float):
        self._start(target, bounds)
        if not smoothing > 0:
            raise ModelError(f"{self.label}: smoothing must be > 0 (m), got {smoothing}")
        self.ground_speed = float(ground_speed)
        self.smoothing = float(smoothing)
        if center is None or (isinstance(center, str) and center == "sole"):
            self.center = center
        else:
            try:
                cx, cy = (float(x) for x in center)
            except (TypeError, ValueError):
                raise ModelError(f"{self.label}: center must be None, 'sole' or (x, y) in m in the site frame, "
                                 f"got {center!r}") from None
            if not (math.isfinite(cx) and math.isfinite(cy)):
                raise ModelError(f"{self.label}: center {center!r} is not finite")
            self.center = (cx, cy)
        self._finish(values)

    # -- the force law (subclasses) ---------------------------------------
    def normal_law(self, delta_s, rate, p: Mapping[str, Any]):
        """``(f_n, volume, centroid_depth)`` for smoothed penetration ``delta_s`` and rate ``rate`` (m/s, + compressing)."""
        raise NotImplementedError

    # -- evaluation -------------------------------------------------------
    def evaluate_kinematics(self, kin: SiteKinematics, params: Mapping[str, Any] | None = None) -> ContactForces:
        """Forces over frames from the site's kinematics (pure numpy; parameters may be arrays).

        Parameters and kinematics may also be :class:`~pinmsk.contact.dual.Dual` s: the outputs
        then carry their exact derivatives (what :class:`~pinmsk.contact.ContactFit` uses for its
        Jacobian), from this same code.
        """
        p = self._p(params)
        R = p[self.radius_name]
        ox, oy = p["dx"], p["dy"]
        if self.center == "sole":
            oy = oy + R
        elif self.center is not None:
            ox, oy = ox + self.center[0], oy + self.center[1]
        centre, vcentre = kin.point(vector(ox, oy, 0.0 * ox))
        h = centre[:, 1]
        delta = R - h
        delta_s = smooth_positive(delta, self.smoothing)
        rate = -vcentre[:, 1]
        fn, vol, zbar = self.normal_law(delta_s, rate, p)
        fn = no_adhesion(fn)
        # application point: zbar below the centre (r = -zbar y); velocity of that body point,
        # v + omega x r, with omega x (0, -zbar, 0) = zbar (omega_z, 0, -omega_x)
        zero = 0.0 * zbar
        point = centre + vector(zero, -zbar, zero)
        om = kin.omega
        # tangential slip relative to the moving ground (its y component is not a slip)
        slip = vector(vcentre[:, 0] + zbar * om[:, 2] - self.ground_speed, zero, vcentre[:, 2] - zbar * om[:, 0])
        ff = regularized_coulomb(slip, fn, p["mu_f"], p["v_s"])
        force = ff + vector(zero, fn, zero)
        return ContactForces(fn, ff, force, point, delta, vol, slip)

    def _options(self) -> tuple:
        return (self.ground_speed, self.smoothing, self.center)


def wrench_generalized_force(kin: SiteKinematics, force: np.ndarray, point: np.ndarray) -> np.ndarray:
    """``J_lin^T f + J_ang^T ((p - o) x f)`` over frames for a world force ``f`` at world point ``p``."""
    moment = cross(point - kin.position, force)
    J = kin.jacobian
    return np.einsum("nkv,nk->nv", J[:, :3, :], force) + np.einsum("nkv,nk->nv", J[:, 3:, :], moment)
