"""Ideal actuators: a control ``u`` in ``[min_control, max_control]`` times an optimal force.

OpenSim's ``CoordinateActuator``, ``PointActuator`` and ``TorqueActuator`` (its
``ScalarActuator`` s without dynamics) as components: the actuation is
``F_opt u`` (``computeActuation``: ``getControl(s) * getOptimalForce()``), and it
reaches the skeleton through a generalized-force *column* ``B(q)`` per unit of
actuation, so the actuator's generalized force is

    Q(q, u) = F_opt u B(q)        (N, nv) over frames

* :class:`CoordinateActuator` -- ``B = e_i``, the unit vector of its coordinate
  (N m per unit for a rotation, N for a translation);
* :class:`PointActuator` -- a force ``d`` (a unit vector, in the ground frame
  with ``force_is_global``, else in the body's frame) at a station of a body
  (``point`` in the body's frame, or a ground point taken as the body station
  it coincides with at each frame when ``point_is_global``, as
  ``PointActuator::implProduceForces`` does): ``B = J_p^T d`` with ``J_p`` the
  station's world-aligned translation Jacobian;
* :class:`TorqueActuator` -- a torque about a unit ``axis`` (ground frame with
  ``torque_is_global``, else body A's) on body A and its opposite on body B
  (none, or the ground): ``B = (J_w,A - J_w,B)^T n`` with ``J_w`` the bodies'
  world-aligned angular Jacobians.

``optimal_force`` is the component's one :class:`~pinmsk.components.Parameter`;
the control bounds are attributes (they may be infinite, as OpenSim's default
``-Inf .. Inf``).  The control is an input: :meth:`IdealActuator.generalized_force`
applies the motion's ``<name>_control`` signal, and nothing without one (an
ideal actuator in inverse dynamics is what the moments are *for*); static
optimization solves for the controls (:mod:`pinmsk.solvers.static`).
:func:`actuator_columns` stacks the columns ``F_opt B`` of several actuators over
frames, ``(N, n_actuators, nv)``.  The law is linear in ``u`` (exact derivative
``F_opt B``); ``B`` comes from Pinocchio's frame Jacobians, shared through a
:class:`pinmsk.model.Data` with the contact spheres on the same body.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from .components import Component, Motion, Parameter, motion_cached
from .contact.sphere import site_kinematics, wrench_generalized_force
from .errors import ModelError

__all__ = ["IdealActuator", "CoordinateActuator", "PointActuator", "TorqueActuator", "actuator_columns",
           "ACTUATOR_FAMILIES"]

#: fixed (``vary=False``) unless freed: a fit of the model's parameters leaves the actuators' strength alone
_OPTIMAL_FORCE = Parameter("optimal_force", 1.0, 0.0, math.inf, "N or N m",
                           "actuation at unit control (N for forces and translations, N m for torques and rotations)",
                           vary=False)


def _unit(vec, what: str, owner: str) -> np.ndarray:
    v = np.asarray(vec, dtype=float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ModelError(f"{owner}: {what} must be 3 finite numbers, got {vec!r}")
    n = float(np.linalg.norm(v))
    if not n > 0.0:
        raise ModelError(f"{owner}: {what} is the zero vector; it needs a direction")
    return v / n


class IdealActuator(Component):
    """Base class: an actuator of actuation ``optimal_force * u``, ``min_control <= u <= max_control``.

    ``name`` is the actuator's own (OpenSim's) name: the component's label is
    ``<family>:<name>``, its channels ``<name>_control`` and ``<name>_force``.
    Subclasses implement :meth:`unit_columns` (``B``, per unit of actuation).
    """

    kind = "actuator"
    linear = True
    parameters = (_OPTIMAL_FORCE,)

    def __init__(self, name: str, target: str, *, optimal_force: float = 1.0, min_control: float = -math.inf,
                 max_control: float = math.inf):
        name = str(name or "").strip()
        if not name:
            raise ModelError(f"{type(self).__name__}: an actuator needs a name")
        self.name = name
        lo, hi = float(min_control), float(max_control)
        if math.isnan(lo) or math.isnan(hi):
            raise ModelError(f"{self.family}:{name}: min_control and max_control must be numbers, got {lo}, {hi}")
        if lo > hi:
            raise ModelError(f"{self.family}:{name}: min_control {lo:g} > max_control {hi:g}")
        self.min_control, self.max_control = lo, hi
        super().__init__(target, optimal_force=optimal_force)

    @property
    def label(self) -> str:
        return f"{self.family}:{self.name}"

    @property
    def control_channel(self) -> str:
        return f"{self.name}_control"

    @property
    def force_channel(self) -> str:
        return f"{self.name}_force"

    def actuation_unit(self, model) -> str:
        """Unit of the actuation in ``model``: ``N`` or ``N*m``."""
        return "N"

    def unit_columns(self, model, motion: Motion, cache: Any = None) -> np.ndarray:
        """``B`` (N, nv): the generalized force per unit of actuation (1 N or 1 N m)."""
        raise NotImplementedError

    def columns(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                cache: Any = None) -> np.ndarray:
        """``F_opt B`` (N, nv): the generalized force per unit of control."""
        return self._p(params)["optimal_force"] * self.unit_columns(model, motion, cache)

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        """``F_opt u B`` with ``u`` the motion's ``<name>_control`` signal (zero force without one)."""
        u = motion.signals.get(self.control_channel)
        if u is None:
            return np.zeros((motion.n_frames, model.nv))
        return np.asarray(u, dtype=float)[:, None] * self.columns(model, motion, params, cache)

    def param_jacobian(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                       cache: Any = None) -> np.ndarray:
        """``dQ/d optimal_force`` over frames, ``(N, nv, 1)``."""
        u = motion.signals.get(self.control_channel)
        if u is None:
            return np.zeros((motion.n_frames, model.nv, 1))
        return (np.asarray(u, dtype=float)[:, None] * self.unit_columns(model, motion, cache))[:, :, None]

    def _options(self) -> tuple:
        return (self.name, self.min_control, self.max_control)

    def __eq__(self, other) -> bool:
        return super().__eq__(other) and self._options() == other._options()

    def __hash__(self) -> int:
        return hash((super().__hash__(), self._options()))

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.name!r}, {self.target!r}, "
                f"optimal_force={self.values['optimal_force']:.6g}, controls [{self.min_control:g}, {self.max_control:g}])")


class CoordinateActuator(IdealActuator):
    """OpenSim's ``CoordinateActuator``: a generalized force ``F_opt u`` on one coordinate (``B = e_i``)."""

    family = "coordinate_actuator"
    target_kind = "coordinate"

    def __init__(self, name: str, coordinate: str, **kw):
        super().__init__(name, coordinate, **kw)

    def unit_columns(self, model, motion: Motion, cache: Any = None) -> np.ndarray:
        out = np.zeros((motion.n_frames, model.nv))
        out[:, model.coordinate_index(self.target)] = 1.0
        return out

    def actuation_unit(self, model) -> str:
        return "N*m" if self.target in model.rotational_coordinates else "N"


class PointActuator(IdealActuator):
    """OpenSim's ``PointActuator``: a force ``F_opt u d`` at a station of ``body`` (``B = J_p^T d``).

    ``point`` (m) is in the body's frame, or in the ground frame with
    ``point_is_global``; ``direction`` (normalised) in the body's frame, or the
    ground's with ``force_is_global`` (OpenSim's defaults: both False,
    direction x).
    """

    family = "point_actuator"
    target_kind = "body"

    def __init__(self, name: str, body: str, *, point=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0),
                 point_is_global: bool = False, force_is_global: bool = False, **kw):
        owner = f"{self.family}:{name}"
        p = np.asarray(point, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ModelError(f"{owner}: point must be 3 finite numbers (m), got {point!r}")
        self.point = tuple(float(x) for x in p)
        self.direction = tuple(float(x) for x in _unit(direction, "direction", owner))
        self.point_is_global = bool(point_is_global)
        self.force_is_global = bool(force_is_global)
        super().__init__(name, body, **kw)

    def prepare(self, model, motion: Motion, data=None):
        return motion_cached(data, model, ("site", model.frame_id(self.target)), motion,
                             lambda pd: site_kinematics(model, self.target, motion.q, motion.v, jacobian=True,
                                                        pin_data=pd))

    def unit_columns(self, model, motion: Motion, cache: Any = None) -> np.ndarray:
        kin = cache if cache is not None else self.prepare(model, motion)
        d = np.asarray(self.direction)
        force = (np.broadcast_to(d, kin.position.shape) if self.force_is_global
                 else np.einsum("nij,j->ni", kin.rotation, d))
        p = np.asarray(self.point)
        # a ground point is the body station that coincides with it at each frame
        point = (np.broadcast_to(p, kin.position.shape) if self.point_is_global
                 else kin.position + np.einsum("nij,j->ni", kin.rotation, p))
        return wrench_generalized_force(kin, np.ascontiguousarray(force), np.ascontiguousarray(point))

    def _options(self) -> tuple:
        return super()._options() + (self.point, self.direction, self.point_is_global, self.force_is_global)


class TorqueActuator(IdealActuator):
    """OpenSim's ``TorqueActuator``: a torque ``F_opt u n`` on ``body_a`` and ``-F_opt u n`` on ``body_b``.

    ``axis`` (normalised) is in the ground frame with ``torque_is_global``
    (OpenSim's default), else in body A's frame.  ``body_b`` None or the
    ground: no reaction torque on a moving body.  ``B = (J_w,A - J_w,B)^T n``.
    """

    family = "torque_actuator"
    target_kind = "body"

    def __init__(self, name: str, body_a: str, *, body_b: str | None = None, axis=(0.0, 0.0, 1.0),
                 torque_is_global: bool = True, **kw):
        self.body_b = None if body_b in (None, "") else str(body_b)
        self.axis = tuple(float(x) for x in _unit(axis, "axis", f"{self.family}:{name}"))
        self.torque_is_global = bool(torque_is_global)
        super().__init__(name, body_a, **kw)

    def check_target(self, model) -> None:
        super().check_target(model)
        if self.body_b is not None:
            model.frame_id(self.body_b)

    def _kin(self, model, motion, frame, data):
        return motion_cached(data, model, ("site", model.frame_id(frame)), motion,
                             lambda pd: site_kinematics(model, frame, motion.q, motion.v, jacobian=True, pin_data=pd))

    def prepare(self, model, motion: Motion, data=None):
        return (self._kin(model, motion, self.target, data),
                None if self.body_b is None else self._kin(model, motion, self.body_b, data))

    def unit_columns(self, model, motion: Motion, cache: Any = None) -> np.ndarray:
        kin_a, kin_b = cache if cache is not None else self.prepare(model, motion)
        n = np.asarray(self.axis)
        torque = (np.broadcast_to(n, kin_a.position.shape) if self.torque_is_global
                  else np.einsum("nij,j->ni", kin_a.rotation, n))
        out = np.einsum("nkv,nk->nv", kin_a.jacobian[:, 3:, :], torque)
        if kin_b is not None:
            out -= np.einsum("nkv,nk->nv", kin_b.jacobian[:, 3:, :], torque)
        return out

    def actuation_unit(self, model) -> str:
        return "N*m"

    def _options(self) -> tuple:
        return super()._options() + (self.body_b, self.axis, self.torque_is_global)


#: The actuator classes by family.
ACTUATOR_FAMILIES = {c.family: c for c in (CoordinateActuator, PointActuator, TorqueActuator)}


def actuator_columns(model, motion: Motion, actuators: Sequence[IdealActuator], *, data=None) -> np.ndarray:
    """``F_opt B`` of each actuator over frames: ``(N, n_actuators, nv)`` (generalized force per unit control).

    ``data`` (a :class:`pinmsk.model.Data`) shares the body kinematics between actuators and with other
    components prepared on ``motion``."""
    out = np.zeros((motion.n_frames, len(actuators), model.nv))
    for i, act in enumerate(actuators):
        out[:, i, :] = act.columns(model, motion, cache=act.prepare(model, motion, data=data))
    return out
