"""Effects: the physical effects a model may be missing, as model components.

Every family is a :class:`pinmsk.components.Component` registered by name
(its ``family``) in :mod:`pinmsk.effects.registry`; the same objects serve
inverse dynamics, simulation, the solvers and the diagnosis.

=========================  ===========  ==================================================
family                     target       generalized force
=========================  ===========  ==================================================
joint_damping              coordinate   ``-c qdot``
coulomb_friction           coordinate   ``-F_c tanh(qdot / 0.01)``
joint_spring               coordinate   ``-k (q - q0)``, ``q0`` within the joint's range
passive_elastic            coordinate   ``A [exp(-k_lo (q - theta_0)) - exp(k_hi (q - theta_0))]``
end_stop_upper             coordinate   ``-K S((q - q_up) / d) (q - q_up)``: OpenSim's CoordinateLimitForce, upper side
end_stop_lower             coordinate   ``-K S((q_lo - q) / d) (q - q_lo)``: the same, lower side
coordinate_expression      coordinate   ``scale * expression(q, qdot)`` (OpenSim's ExpressionBasedCoordinateForce)
bushing                    frame pair   ``-(k q + c qdot)`` on the X-Y-Z angles and offset between two frames
                                        (Simbody's LinearBushing: OpenSim's BushingForce)
point_to_point_spring      frame pair   ``k (|d| - L0)`` between two body points (OpenSim's PointToPointSpring)
hunt_crossley_pair         frame pair   OpenSim's HuntCrossleyForce between a sphere and a moving half space or a
                                        sphere on another body
riener_edrich_1999         side r / l   thesis Eq. 5.11 on hip, knee, ankle (x ``scale``)
payload                    frame        ``-m J_p^T (a_p - g)`` (point mass; inertial)
segment_mass               body         ``-delta Y_j pi_j`` (mass/inertia scale; inertial)
com_offset                 body         ``-Y_j delta pi(d)`` (centre of mass moved by ``d``, mass kept; inertial)
scale                      model        ``-delta Y pi`` (every segment; model not scaled to the subject)
plate_offset               plate body   ``-J_b^T (b, p x b)``: zero offset of a force plate's channels (trial)
plate_cop_offset           plate body   ``-J_b^T (0, d x F)``: the plate's COP read ``d`` off (trial)
plate_tilt                 plate body   ``-J_b^T Delta``: the plate's axes turned by a small rotation (trial)
plate_gain                 plate body   ``-(1 - 1/g) J_b^T w``: the plate's calibration off (trial)
plate_lag                  plate body   ``lag J_b^T dw/dt``: the plate's samples behind the kinematics (trial)
sensor_gain                coordinate   none: the recorded ``<coord>_moment`` reads ``g tau`` (measurement)
sensor_offset              coordinate   none: the recorded ``<coord>_moment`` reads ``tau + b`` (measurement)
activation_dynamics        muscles      excitation -> activation, Eq. A.2 (muscle level)
electromechanical_delay    muscles      excitation delayed by ``delay`` (muscle level)
delayed_activation_        muscles      delay, then Eq. A.2: both fitted together (muscle level)
dynamics
=========================  ===========  ==================================================

Add your own effect with the :func:`register` decorator.  A coordinate effect
only needs its force; the diagnosis then fits it (by linear least squares
when ``linear = True``), ranks it and adds it like the built-in ones.  Write
the force against :func:`pinmsk.backend.backend_of` (``xp.abs``, ``xp.tanh``,
... instead of ``np.abs``): the same ``_force`` then serves the batched numpy
analyses and, through ``generalized_force_at(model, q, v)`` at one state, the
optimal-control engine's CasADi expressions and exact derivatives::

    >>> import numpy as np
    >>> from pinmsk.backend import backend_of
    >>> from pinmsk.components import Parameter
    >>> from pinmsk.effects import JointEffect, register
    >>> @register
    ... class QuadraticDrag(JointEffect):
    ...     '''Aerodynamic-like drag Q = -c_d |qdot| qdot.'''
    ...     family = "quadratic_drag"
    ...     linear = True
    ...     parameters = (Parameter("c_d", 0.01, 0.0, 10.0, "N m s^2/rad^2", "drag coefficient"),)
    ...     zero_params = {"c_d": 0.0}
    ...     def _force(self, q, v, p):
    ...         return -p["c_d"] * backend_of(v).abs(v) * v
    ...     def _dforce_dparams(self, q, v, p):
    ...         return (-np.abs(v) * v)[:, None]
    ...     def _dforce_dstate(self, q, v, p):
    ...         return np.zeros_like(q), -2.0 * p["c_d"] * np.abs(v)
    >>> "quadratic_drag" in families()
    True

Subclass :class:`pinmsk.components.Component` directly for any other
target (implement ``generalized_force(model, motion, params=None, cache=None)
-> (N, nv)``, ``generalized_force_at(model, q, v) -> (nv,)`` at one state if it
has a closed form in ``(q, v)`` (without it the optimal-control engine refuses
the component by name), and optionally ``prepare(model, motion, data=None)`` for the
parameter-independent work, given back as ``cache``); see
:mod:`pinmsk.diagnose.catalog` for how candidates are chosen.
"""
from ..errors import ModelError
from . import registry as _r
from ._base import JointEffect, SignalEffect
from .activation import ActivationDynamics, DelayedActivationDynamics, ExcitationPath, excitation_path
from .com_offset import ComOffset
from .damping import JointDamping
from .delay import ElectromechanicalDelay
from .end_stop import EndStop, EndStopLower, EndStopUpper
from .expression import CoordinateExpressionForce
from .friction import CoulombFriction
from .linkers import FramePairForce, HuntCrossleyPair, LinearBushing, PointToPointSpring
from .passive import PassiveElastic, RienerEdrich1999PassiveMoment
from .payload import Payload
from .plate import PlateCopOffset, PlateEffect, PlateGain, PlateLag, PlateOffset, PlateTilt
from .registry import families, from_spec, get, register
from .scale import MassScale
from .segment_mass import SegmentMass
from .sensor import MeasurementEffect, SensorGain, SensorOffset
from .spring import JointSpring


def unregister(family: str) -> None:
    """Remove a user-registered family (built-in families cannot be removed)."""
    if family in _BUILTIN:
        raise ModelError(f"'{family}' is a built-in effect family and cannot be unregistered")
    _r._REGISTRY.pop(family, None)


_BUILTIN = frozenset(families())

__all__ = [
    "ActivationDynamics", "ComOffset", "CoordinateExpressionForce", "CoulombFriction", "DelayedActivationDynamics", "ElectromechanicalDelay",
    "EndStop", "EndStopLower", "EndStopUpper", "ExcitationPath", "excitation_path",
    "FramePairForce", "HuntCrossleyPair", "JointDamping", "JointEffect", "JointSpring", "LinearBushing", "PointToPointSpring", "MassScale", "MeasurementEffect", "PassiveElastic", "Payload", "PlateCopOffset", "PlateEffect", "PlateGain", "PlateLag",
    "PlateOffset", "PlateTilt",
    "RienerEdrich1999PassiveMoment", "SegmentMass", "SensorGain", "SensorOffset", "SignalEffect", "families",
    "from_spec", "get", "register", "unregister",
]
