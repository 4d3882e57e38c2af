"""Whole-body mass scale: the model is not scaled to the subject (every segment ``m -> (1 + delta) m``).

Physics: a generic model (``gait2d``'s 75 kg, a scaled template) used for a
subject of another mass.  Every body's inertia -- mass, first moment ``m c`` and
rotational inertia, i.e. all ten dynamic parameters of every joint -- scales by
``1 + delta``, centres of mass kept.  With Pinocchio's joint torque regressor
``Y(q, v, a)`` (``rnea = Y pi``), the heavier body adds ``delta Y pi`` to the
inverse dynamics, which is ``delta`` times the skeleton's own inverse dynamics
without external loads, so::

    Q = -delta Y(q, v, a) pi

linear in ``delta`` (gravity included).  This is one candidate, not a
``segment_mass`` per segment: a whole-body mismatch loaded onto one segment
gives that segment a mass error several times too large and leaves the rest of
the residual unexplained.  The remedy it points to is to scale the model to
the subject's mass (:meth:`MassScale.describe_remedy`).  Inertial: forward
dynamics uses :meth:`MassScale.apply_inertia` (every joint's ``pi_j`` from the
model as loaded, so it composes with segment masses and payloads).
"""
from __future__ import annotations

import numpy as np

from ..components import Parameter
from ..errors import ModelError
from ._base import ScaledBasisEffect, add_dynamic_parameters, moving_bodies, torque_regressor
from .registry import register


@register
class MassScale(ScaledBasisEffect):
    """Scale ``1 + delta`` of every segment's mass and inertia (the model not scaled to the subject)."""

    family = "scale"
    level = "joint"
    target_kind = "model"
    inertial = True
    parameters = (
        Parameter("delta", 0.1, -0.6, 1.5, "", "relative change of every segment's mass and inertia "
                                                 "(0 = as modelled)"),
    )
    zero_params = {"delta": 0.0}

    def __init__(self, target: str | None = None, **values: float):
        if target not in (None, "", "model"):
            raise ModelError(f"scale acts on the whole model; it takes no target (got {target!r})")
        super().__init__(None, **values)

    @classmethod
    def candidates(cls, model, context) -> list:
        """One candidate for models of several bodies with mass (for one body it is ``segment_mass``)."""
        if context.mode == "muscle" or len(moving_bodies(model)) < 2:
            return []
        return [cls()]

    def check_target(self, model) -> None:
        if not moving_bodies(model):
            raise ModelError(f"scale: model '{model.name}' has no body with mass")

    def _pi(self, model) -> np.ndarray:
        pm = model.pin
        return np.concatenate([pm.inertias[j].toDynamicParameters() for j in range(1, pm.njoints)])

    def prepare(self, model, motion, data=None):
        """``Y pi`` over frames, ``(N, nv)``: the skeleton's inverse dynamics without external loads."""
        return torque_regressor(model, motion, data) @ self._pi(model)

    def apply_inertia(self, model, pin_model) -> None:
        d = self.values["delta"]
        if d == 0.0:
            return
        for j in range(1, model.pin.njoints):
            if model.pin.inertias[j].mass > 0:
                add_dynamic_parameters(pin_model, j, d * model.pin.inertias[j].toDynamicParameters())

    def describe_remedy(self, model) -> str:
        """What to do about a fitted scale: the subject's mass against the model's."""
        d = self.values["delta"]
        m = float(model.mass)
        return (f"the model is not scaled to the subject: every segment is {100 * d:+.1f} % off "
                f"(model {m:.1f} kg, subject about {m * (1 + d):.1f} kg); scale the model's masses "
                "and inertias to the subject (or keep this effect in the model)")
