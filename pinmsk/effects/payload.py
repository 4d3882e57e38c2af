"""A point mass held at a frame (a dumbbell in the hand, a backpack, a sensor).

Physics: a point mass ``m`` rigidly attached at the origin of frame
``target`` (e.g. ``hand``, the hand's centre of mass).  Its contribution to the
equations of motion is ``m J_p^T (a_p - g)``, so the generalized force it
applies to the rest of the system is::

    Q = -m J_p(q)^T (a_p - g),     a_p = J_p a + Jdot_p v

with ``J_p`` the frame origin's world-aligned linear Jacobian, ``a_p`` its
classical (not spatial) acceleration and ``g`` the model's gravity vector
(both from Pinocchio: ``computeFrameJacobian`` and
``getFrameClassicalAcceleration`` in ``LOCAL_WORLD_ALIGNED``).  ``Q`` is
linear in ``m``; ``prepare`` computes ``J_p^T (a_p - g)`` once per motion.
The payload is *inertial*: forward dynamics folds it into the parent joint's
inertia (:meth:`Payload.apply_inertia`) instead of calling
:meth:`generalized_force`, which needs the acceleration.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..components import Parameter
from ._base import ScaledBasisEffect, add_dynamic_parameters, frame_point_kinematics
from .registry import register


@register
class Payload(ScaledBasisEffect):
    """Point mass ``m`` at the origin of frame ``target``."""

    family = "payload"
    level = "joint"
    target_kind = "frame"
    inertial = True
    parameters = (
        Parameter("mass", 1.0, 0.0, 200.0, "kg", "mass held at the frame origin"),
    )
    zero_params = {"mass": 0.0}

    def prepare(self, model, motion, data=None):
        """``J_p^T (a_p - g)`` over frames, ``(N, nv)``."""
        J, acc = frame_point_kinematics(model, motion, self.target, data)
        return np.einsum("nkv,nk->nv", J, acc - model.gravity[None, :])

    def apply_inertia(self, model, pin_model) -> None:
        f = model.pin.frames[model.frame_id(self.target)]
        m = self.values["mass"]
        if m == 0.0:
            return
        point = pin.Inertia(m, np.array(f.placement.translation), np.zeros((3, 3)))
        add_dynamic_parameters(pin_model, f.parentJoint, point.toDynamicParameters())
