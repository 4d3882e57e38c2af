"""Mass and inertia error of one body: ``m -> (1 + delta) m``, ``I -> (1 + delta) I``.

Physics: anthropometric tables give segment masses to within 10-20 %; this
effect scales the whole inertia (mass, first moment ``m c`` and rotational
inertia, i.e. all ten dynamic parameters ``pi_j``) of the joint that carries
body ``target`` by ``1 + delta``, keeping its centre of mass.  (Pinocchio
merges bodies welded by fixed joints into their joint's inertia, so e.g.
``forearm_hand`` scales forearm and hand together.)  With Pinocchio's joint
torque regressor ``Y(q, v, a)`` (``computeJointTorqueRegressor``,
``rnea = Y pi``), the scaled body adds ``delta Y_j pi_j`` to the inverse
dynamics, so its generalized force is::

    Q = -delta Y_j(q, v, a) pi_j

linear in ``delta`` (gravity included).  ``delta = 0`` is no change;
``delta`` is bounded to ``[-0.9, 5]``.  Inertial: forward dynamics uses
:meth:`SegmentMass.apply_inertia`, which adds ``delta pi_j`` to a copy of the
model's inertia (``pi_j`` from the model as loaded, so the effect composes
with a payload on the same body).

Plausibility (:meth:`SegmentMass.plausibility`): the fitted mass must lie within the body's
anthropometric range (de Leva 1996, :mod:`pinmsk.effects.anthropometry`), widened to the model's
own mass +-30 %; the diagnosis flags a fit that does not, and never suggests it.
"""
from __future__ import annotations

from ..components import Parameter
from ..errors import ModelError
from .anthropometry import mass_plausibility
from ._base import ScaledBasisEffect, add_dynamic_parameters, moving_bodies, torque_regressor
from .registry import register


@register
class SegmentMass(ScaledBasisEffect):
    """Scale ``1 + delta`` of the mass and inertia of the body ``target``."""

    family = "segment_mass"
    level = "joint"
    target_kind = "body"
    inertial = True
    parameters = (
        Parameter("delta", 0.1, -0.9, 5.0, "", "relative mass/inertia change (0 = as modelled)"),
    )
    zero_params = {"delta": 0.0}

    def _joint(self, model) -> int:
        j = model.pin.frames[model.frame_id(self.target)].parentJoint
        if j == 0 or model.pin.inertias[j].mass <= 0:
            raise ModelError(
                f"segment_mass: body '{self.target}' of model '{model.name}' does not move or has no mass; "
                f"bodies with mass: {', '.join(moving_bodies(model))}"
            )
        return j

    def check_target(self, model) -> None:
        self._joint(model)

    def plausibility(self, model, motion=None) -> list[str]:
        """Why the fitted mass is implausible (empty when it is not): outside the body's range of
        de Leva (1996), widened to the model's own mass (:func:`~.anthropometry.mass_plausibility`)."""
        j = self._joint(model)
        m = float(model.pin.inertias[j].mass)
        return mass_plausibility(model, j, (1.0 + self.values["delta"]) * m, f"{self.label} (delta = "
                                 f"{self.values['delta']:+.3g})")

    def prepare(self, model, motion, data=None):
        """``Y_j pi_j`` over frames, ``(N, nv)``: the body's own inverse-dynamics contribution."""
        j = self._joint(model)
        Y = torque_regressor(model, motion, data)
        pi = model.pin.inertias[j].toDynamicParameters()
        return Y[:, :, 10 * (j - 1):10 * j] @ pi

    def apply_inertia(self, model, pin_model) -> None:
        j = self._joint(model)
        d = self.values["delta"]
        if d != 0.0:
            add_dynamic_parameters(pin_model, j, d * model.pin.inertias[j].toDynamicParameters())
