"""Centre-of-mass offset of one body: its COM moved by ``d = (dx, dy, dz)`` in the body frame, mass kept.

Physics: anthropometric tables place a segment's centre of mass on the line between its joints;
a subject's trunk leans, carries its mass forwards or backwards, and RRA (OpenSim's Residual
Reduction Algorithm) answers a mean residual moment on the pelvis by moving the torso's COM.
With the body's mass ``m``, its COM ``c`` and rotational inertia about the COM ``I_c`` kept, the
COM at ``c + d`` changes the dynamic parameters ``pi_j = [m, m c, I_o]`` of the joint that
carries the body (``I_o = I_c + m [c]_x^T [c]_x`` about the joint origin) by::

    delta pi(d) = pi(m, c + d, I_c) - pi(m, c, I_c)
                = [0, m d, m ([c]^T [d] + [d]^T [c] + [d]^T [d])]

and, with Pinocchio's joint torque regressor ``Y(q, v, a)`` (``rnea = Y pi``), its generalized
force is ``Q = -Y_j(q, v, a) delta pi(d)``: linear in ``d`` through the first moment and the
cross terms of ``I_o``, plus the small quadratic ``m [d]^T [d]`` (a 3 cm shift of a 30 kg trunk
changes ``I_o`` by 0.027 kg m^2).  The parameter Jacobian is exact (the central difference of a
quadratic), and the fit starts from the linearised least-squares solution
(:meth:`ComOffset.initial_guess`), so it needs one or two iterations.

``d`` is in the body's frame (rotated into the joint's where Pinocchio's inertia lives).  The
bounds (:meth:`ComOffset.for_model`) are a fifth of the segment's length (the distance from its
joint to the farthest child joint, else twice its COM distance), at least 2 cm and at most 10 cm:
an offset beyond that is no longer a COM that anthropometry misplaced.  Inertial: forward
dynamics uses :meth:`ComOffset.apply_inertia`.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..components import Component, Parameter
from ..errors import ModelError
from ._base import (add_dynamic_parameters, moving_bodies, torque_regressor, unactuated_coordinates,
                    visible_directions)
from .registry import register

__all__ = ["ComOffset"]

#: share of the model's mass a body must carry to be a COM-offset candidate (the trunk, the pelvis)
HEAVY = 0.12
#: at most this many COM-offset candidates per model (the heaviest bodies)
MAX_CANDIDATES = 2
_AXES = ("dx", "dy", "dz")


@register
class ComOffset(Component):
    """Centre of mass of body ``target`` moved by ``(dx, dy, dz)`` in its frame (mass and ``I_c`` kept)."""

    family = "com_offset"
    kind = "effect"
    level = "joint"
    target_kind = "body"
    inertial = True
    parameters = tuple(
        Parameter(n, 0.01, -0.1, 0.1, "m", f"shift of the centre of mass along the body frame's {n[1]} axis")
        for n in _AXES)
    zero_params = {n: 0.0 for n in _AXES}

    # -- structure ------------------------------------------------------------------
    def _joint(self, model) -> int:
        j = model.pin.frames[model.frame_id(self.target)].parentJoint
        if j == 0 or model.pin.inertias[j].mass <= 0:
            raise ModelError(
                f"com_offset: body '{self.target}' of model '{model.name}' does not move or has no mass; "
                f"bodies with mass: {', '.join(moving_bodies(model))}")
        return j

    def check_target(self, model) -> None:
        self._joint(model)

    @classmethod
    def candidates(cls, model, context) -> list:
        """The heaviest bodies (at least :data:`HEAVY` of the model's mass, :data:`MAX_CANDIDATES` at
        most, heaviest first) of a floating-base model in a torque-level comparison: the trunk that RRA
        adjusts, the pelvis."""
        if context.mode != "torque" or not (context.unactuated or unactuated_coordinates(model)):
            return []
        pm = model.pin
        total = float(model.mass)
        heavy = sorted(((pm.inertias[j].mass, b) for b, j in moving_bodies(model).items()
                        if pm.inertias[j].mass >= HEAVY * total), reverse=True)
        return [cls(b) for _, b in heavy[:MAX_CANDIDATES]]

    def segment_length(self, model) -> float:
        """Distance from the body's joint to its farthest child joint (else twice its COM distance), m."""
        pm = model.pin
        j = self._joint(model)
        kids = [float(np.linalg.norm(pm.jointPlacements[k].translation)) for k in range(1, pm.njoints)
                if pm.parents[k] == j]
        return max(kids) if kids and max(kids) > 0 else 2.0 * float(np.linalg.norm(pm.inertias[j].lever))

    def for_model(self, model) -> "ComOffset":
        """This offset bounded to a fifth of the segment's length (2-10 cm), with the axes the skeleton's
        dynamics cannot see held at 0 (:meth:`visible_axes`: the out-of-plane axis of a planar model) and
        the segment's long axis held at 0 (:meth:`long_axis`)."""
        b = float(np.clip(0.2 * self.segment_length(model), 0.02, 0.1))
        seen = self.visible_axes(model)
        along = self.long_axis(model)
        if along is not None:
            seen = seen.copy()
            seen[along] = False
        vals = {n: (float(np.clip(self.values[n], -b, b)) if k else 0.0) for n, k in zip(_AXES, seen)}
        return self.with_params(vals, bounds={n: (-b, b) for n in _AXES},
                                vary={n: bool(k) for n, k in zip(_AXES, seen)})

    def long_axis(self, model) -> int | None:
        """The body-frame axis along the segment (its joint to its centre of mass), when one axis carries
        at least 90 % of that direction, else None (and None for the floating base's body).  A shift along the segment moves the COM's lever only
        as the segment tilts, so a near-upright trunk leaves it undetermined (a flat likelihood); RRA, too,
        moves the torso's COM across the trunk only (x and z, against the mean MX and MZ residuals)."""
        pm = model.pin
        j = self._joint(model)
        if pm.names[j] in unactuated_coordinates(model):
            return None             # the floating base's own body: its joint is no segment's end
        u = self._rotation(model).T @ np.asarray(pm.inertias[j].lever, dtype=float)
        n = float(np.linalg.norm(u))
        if n <= 0.0:
            return None
        k = int(np.argmax(np.abs(u)))
        return k if abs(u[k]) >= 0.9 * n else None

    def visible_axes(self, model, samples: int = 6) -> np.ndarray:
        """Boolean (3,): the body-frame axes along which a COM shift changes some generalized force
        (:func:`~._base.visible_directions`: a planar model's dynamics are blind to the axis normal to its
        plane)."""
        return visible_directions(model, self._joint(model), self._dpi_dd(model, np.zeros(3)), samples)

    # -- the law --------------------------------------------------------------------
    def _rotation(self, model) -> np.ndarray:
        """Body frame -> joint frame."""
        return np.array(model.pin.frames[model.frame_id(self.target)].placement.rotation)

    def delta_pi(self, model, d) -> np.ndarray:
        """``delta pi(d)`` (10,) of the joint carrying the body, ``d`` (3,) in the body frame."""
        j = self._joint(model)
        I = model.pin.inertias[j]
        dj = self._rotation(model) @ np.asarray(d, dtype=float)
        moved = pin.Inertia(I.mass, np.array(I.lever) + dj, np.array(I.inertia))
        return moved.toDynamicParameters() - I.toDynamicParameters()

    def _dpi_dd(self, model, d) -> np.ndarray:
        """``d delta pi / d d`` (10, 3): central differences, exact for the quadratic ``delta pi``."""
        h = 0.05
        e = np.eye(3)
        return np.column_stack([(self.delta_pi(model, d + h * e[k]) - self.delta_pi(model, d - h * e[k])) / (2 * h)
                                for k in range(3)])

    def _d(self, params) -> np.ndarray:
        p = self._p(params)
        return np.array([p[n] for n in _AXES], dtype=float)

    #: :meth:`prepare`'s cache is indexed by frame: its rows are the cache of those frames
    frame_cache = True

    def prepare(self, model, motion, data=None):
        """``Y_j`` over frames, ``(N, nv, 10)``: the body's columns of the joint torque regressor."""
        j = self._joint(model)
        # contiguous: the fit multiplies it many times, a strided view of the regressor is several times slower
        return np.ascontiguousarray(torque_regressor(model, motion, data)[:, :, 10 * (j - 1):10 * j])

    def generalized_force(self, model, motion, params=None, cache=None):
        Yj = self.prepare(model, motion) if cache is None else cache
        return -Yj @ self.delta_pi(model, self._d(params))

    def param_jacobian(self, model, motion, params=None, cache=None):
        Yj = self.prepare(model, motion) if cache is None else cache
        return -(Yj @ self._dpi_dd(model, self._d(params)))

    def generalized_force_at(self, model, q, v):
        """Refused by name: the force needs the accelerations; fold it into the skeleton instead."""
        raise ModelError(f"component {self.label} has no closed form the optimal-control engine can use: its "
                         "generalized force depends on the accelerations; fold it into the skeleton's inertia "
                         "(apply_inertia) instead")

    def initial_guess(self, model, motion, target, cache=None) -> list[dict]:
        """The linearised least-squares offset (``delta pi`` linear at ``d = 0``), clipped to the bounds."""
        Yj = self.prepare(model, motion) if cache is None else cache
        B = -(Yj @ self._dpi_dd(model, np.zeros(3)))
        y = np.asarray(target)
        ok = np.isfinite(y)
        A = B[ok]
        d, *_ = np.linalg.lstsq(A, y[ok], rcond=None)
        lo, hi = self.bounds()
        return [dict(zip(_AXES, map(float, np.clip(d, lo, hi))))]

    def apply_inertia(self, model, pin_model) -> None:
        d = self._d(None)
        if np.any(d != 0.0):
            add_dynamic_parameters(pin_model, self._joint(model), self.delta_pi(model, d))

    def describe_remedy(self, model) -> str:
        """What a fitted offset means: where the body's centre of mass goes."""
        d = self._d(None)
        return (f"move the centre of mass of {self.target} by ({', '.join(f'{100 * x:+.1f}' for x in d)}) cm in "
                "its frame (as RRA adjusts the torso), or keep this effect in the model")
