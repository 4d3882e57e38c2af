"""A sphere on a body against a half space fixed to the ground: OpenSim's (Simbody's) contact geometry.

The base class of :class:`~pinmsk.contact.SmoothSphereHalfSpaceForce` and
:class:`~pinmsk.contact.HuntCrossleyForce`, the two OpenSim contact forces between a
``ContactSphere`` and a ``ContactHalfSpace``.  What both compute, as Simbody computes it
(``SmoothSphereHalfSpaceForceImpl::calcForce``; ``HuntCrossleyForceImpl::calcForce`` with
``CollisionDetectionAlgorithm::HalfSpaceSphere``):

* the sphere's centre ``c`` is the body point ``location`` of the target frame; the half space
  is the solid below the plane through ``plane_point`` with outward unit normal ``n``
  (``plane_normal``, world frame; OpenSim's ContactHalfSpace fills ``x > 0`` of its own frame,
  so ``n = -R x`` of its orientation ``R``: the Moco floor, turned by -90 degrees about z, has
  ``n = +y``);
* the indentation ``delta = R - (c - p) . n`` (> 0 in contact);
* the contact point midway through the overlap, ``c - (R - delta / 2) n`` (both materials
  equally stiff, Sherman et al. 2011), and the velocity there of the sphere's body point,
  ``v = v_c + omega x (point - c)`` (the half space does not move);
* the compression rate ``-v . n`` and the tangential slip ``v - (v . n) n``;
* the force on the sphere: the normal force (the subclass's law) along ``n`` plus the friction
  of :func:`~pinmsk.contact.friction.hollars_friction` against the slip.

:func:`hertz_coefficient` is the Hertz stiffness both laws share.  Everything is vectorised over
frames and runs on :class:`~pinmsk.contact.dual.Dual` numbers (exact derivatives).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ..backend import backend_of
from ..components import Parameter, vec3
from ..errors import ModelError
from .dual import asarray, vector
from .friction import hollars_friction
from .sphere import ContactForces, FrameContact, SiteKinematics, cross

#: The parameters of both OpenSim sphere-half-space forces (OpenSim's names and meanings).
HALF_SPACE_PARAMETERS = (
    Parameter("radius", 0.05, 1e-6, 10.0, "m", "radius of the ContactSphere (OpenSim's default is 0)",
              vary=False),
    Parameter("stiffness", 1.0, 0.0, 1e12, "N/m^2", "plane-strain modulus E of both materials (Hertz "
              "stiffness 4/3 k sqrt(R k), k = E^(2/3) / 2)"),
    Parameter("dissipation", 0.0, 0.0, 1e3, "s/m", "Hunt-Crossley dissipation c: f = f_Hertz (1 + 3/2 c v_n)"),
    Parameter("static_friction", 0.0, 0.0, 10.0, "", "coefficient of static friction u_s"),
    Parameter("dynamic_friction", 0.0, 0.0, 10.0, "", "coefficient of dynamic friction u_d"),
    Parameter("viscous_friction", 0.0, 0.0, 1e3, "s/m", "coefficient of viscous friction u_v"),
    Parameter("transition_velocity", 0.01, 1e-9, 100.0, "m/s",
              "slip speed v_t at which the static friction peaks"),
)


def hertz_coefficient(stiffness, radius):
    """``4/3 k sqrt(R k)`` with ``k = E^(2/3) / 2``: Hertz's ``f = 4/3 k^(3/2) sqrt(R) delta^(3/2)``
    for a sphere of radius R on a half space of the same plane-strain modulus E, as Simbody writes
    it (``HuntCrossleyForce``: ``k = E1^(2/3) E2^(2/3) / (E1^(2/3) + E2^(2/3))``; equal materials
    give ``E^(2/3) / 2``, the ``k`` of ``SmoothSphereHalfSpaceForce``)."""
    xp = backend_of(stiffness, radius)
    k = 0.5 * xp.power(asarray(stiffness), 2.0 / 3.0)
    return (4.0 / 3.0) * k * xp.sqrt(asarray(radius) * k)


def _dot(a, n):
    """Row-wise ``a . n`` of (N, 3) ``a`` (plain or Dual) and a plain (3,) ``n``."""
    return a[:, 0] * n[0] + a[:, 1] * n[1] + a[:, 2] * n[2]


class HalfSpaceContact(FrameContact):
    """A sphere fixed to the frame ``target`` against a ground-fixed half space (module docstring).

    Keyword options (not parameters): ``location`` (3,) the sphere centre in the target frame (m,
    default its origin), ``plane_normal`` (3,) the half space's outward normal in the world
    (normalised; default +y), ``plane_point`` (3,) a point of its surface (m, default the origin),
    ``bounds`` per-element parameter bounds ``{name: (lo, hi)}``.  Parameters by keyword (OpenSim's names, see ``parameters``).  Subclasses implement
    :meth:`normal_law` and :meth:`slip_smoothing`.
    """

    radius_name = "radius"
    stiffness_name = "stiffness"

    def __init__(self, target: str, *, location=(0.0, 0.0, 0.0), plane_normal=(0.0, 1.0, 0.0),
                 plane_point=(0.0, 0.0, 0.0), bounds: Mapping[str, tuple[float, float]] | None = None,
                 **values: float):
        self._start(target, bounds)
        owner = self.label
        self.location = vec3(location, "location", owner)
        n = np.asarray(vec3(plane_normal, "plane_normal", owner))
        norm = float(np.linalg.norm(n))
        if not norm > 0.0:
            raise ModelError(f"{owner}: plane_normal {tuple(n)} has no direction")
        for _ in range(4):          # to a fixed point, so that a sphere rebuilt from its normal is equal
            n = n / norm
            norm = float(np.linalg.norm(n))
            if norm == 1.0:
                break
        self.plane_normal = tuple(float(v) for v in n)
        self.plane_point = vec3(plane_point, "plane_point", owner)
        self._finish(values)

    # -- the force law (subclasses) ---------------------------------------
    def normal_law(self, depth, rate, p: Mapping[str, Any]):
        """The normal force (N,) on the sphere from the indentation ``depth`` (m, raw: negative out of
        contact) and the compression rate ``rate`` (m/s)."""
        raise NotImplementedError

    def slip_smoothing(self, p: Mapping[str, Any]):
        """What the friction law adds to the squared slip speed (m^2/s^2)."""
        return 0.0

    # -- evaluation -------------------------------------------------------
    def evaluate_kinematics(self, kin: SiteKinematics, params: Mapping[str, Any] | None = None) -> ContactForces:
        """Forces over frames from the target frame's kinematics (parameters and kinematics may be
        :class:`~pinmsk.contact.dual.Dual` s: the outputs then carry their exact derivatives).

        ``normal`` is the force along ``plane_normal``, ``point`` the contact point midway through
        the overlap, ``penetration`` the indentation, ``slip`` the tangential velocity there."""
        p = self._p(params)
        R = asarray(p["radius"])
        n = np.asarray(self.plane_normal)
        centre, vcentre = kin.point(np.asarray(self.location))
        depth = R - _dot(centre - np.asarray(self.plane_point)[None, :], n)    # a row: CasADi's (1, 3) too
        arm = R - 0.5 * depth                                     # from the centre to the contact point
        r = vector(-arm * n[0], -arm * n[1], -arm * n[2])
        point = centre + r
        v = vcentre + cross(kin.omega, r)
        vn = _dot(v, n)
        slip = v - vector(vn * n[0], vn * n[1], vn * n[2])
        fn = self.normal_law(depth, -vn, p)
        ff = hollars_friction(slip, fn, static=p["static_friction"], dynamic=p["dynamic_friction"],
                              viscous=p["viscous_friction"], transition_velocity=p["transition_velocity"],
                              slip_smoothing=self.slip_smoothing(p))
        force = ff + vector(fn * n[0], fn * n[1], fn * n[2])
        return ContactForces(fn, ff, force, point, depth, 0.0 * depth, slip)

    def _options(self) -> tuple:
        return (self.location, self.plane_normal, self.plane_point)
