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

import difflib
import math
from typing import Any, Mapping, Sequence

import numpy as np

from .components import (Component, Motion, Parameter, motion_cached, parameter_settings,
                         read_parameter_settings)
from .contact.sphere import site_kinematics, wrench_generalized_force
from .errors import ModelError
from .io.toml_files import check_keys

__all__ = ["IdealActuator", "CoordinateActuator", "PointActuator", "TorqueActuator", "actuator_columns",
           "ACTUATOR_FAMILIES", "ACTUATOR_TYPES", "from_spec", "to_spec"]

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

    def _spec_options(self) -> dict:
        """The sidecar keys of the target and the options (subclasses)."""
        raise NotImplementedError

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

    def _spec_options(self) -> dict:
        return {"coordinate": self.target}


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

    def _spec_options(self) -> dict:
        return {"body": self.target, "point": list(self.point), "direction": list(self.direction),
                "point_is_global": self.point_is_global, "force_is_global": self.force_is_global}


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

    def _spec_options(self) -> dict:
        return {"body_a": self.target, **({} if self.body_b is None else {"body_b": self.body_b}),
                "axis": list(self.axis), "torque_is_global": self.torque_is_global}


#: The actuator classes by family.
ACTUATOR_FAMILIES = {c.family: c for c in (CoordinateActuator, PointActuator, TorqueActuator)}
#: The actuator classes by OpenSim's class names (the ``type`` of a sidecar's ``[[actuators]]`` entry).
ACTUATOR_TYPES = {c.__name__: c for c in (CoordinateActuator, PointActuator, TorqueActuator)}
#: Keys of an ``[[actuators]]`` entry: the common ones, then the target and options of each type.
_COMMON_KEYS = ("type", "name", "optimal_force", "min_control", "max_control", "bounds", "fixed", "free")
_TYPE_KEYS = {CoordinateActuator: ("coordinate",),
              PointActuator: ("body", "point", "direction", "point_is_global", "force_is_global"),
              TorqueActuator: ("body_a", "body_b", "axis", "torque_is_global")}


def to_spec(actuator: IdealActuator) -> dict:
    """The sidecar ``[[actuators]]`` table of an actuator (OpenSim's property names; :func:`from_spec` reads
    it back to an equal actuator with the same bounds and ``vary`` flag; infinite control bounds are TOML's
    ``inf``)::

        [[actuators]]
        type = "CoordinateActuator"      # | "PointActuator" | "TorqueActuator" (or their families)
        name = "lumbarAct"
        coordinate = "lumbar"            # PointActuator: body, point, direction, point_is_global,
        optimal_force = 1.0              #   force_is_global; TorqueActuator: body_a, body_b (optional),
        min_control = -150.0             #   axis, torque_is_global (OpenSim's defaults where absent)
        max_control = 150.0
    """
    if type(actuator) not in _TYPE_KEYS:
        raise ModelError(f"{actuator.label}: a sidecar [[actuators]] entry holds the types "
                         f"{', '.join(ACTUATOR_TYPES)}, not a {type(actuator).__name__}")
    return {"type": type(actuator).__name__, "name": actuator.name, **actuator._spec_options(),
            "optimal_force": actuator.values["optimal_force"], "min_control": actuator.min_control,
            "max_control": actuator.max_control, **parameter_settings(actuator)}


def from_spec(spec: Mapping[str, Any], *, where: str = "[[actuators]]") -> IdealActuator:
    """The actuator of a sidecar ``[[actuators]]`` table (:func:`to_spec` gives the schema); unknown keys are
    refused with a "did you mean", bad values by name (``where`` names the entry)."""
    if not isinstance(spec, Mapping):
        raise ModelError(f"{where}: expected a table, got {type(spec).__name__}")
    typ = spec.get("type")
    cls = ACTUATOR_TYPES.get(typ) or ACTUATOR_FAMILIES.get(typ)
    if cls is None:
        known = [*ACTUATOR_TYPES, *ACTUATOR_FAMILIES]
        close = difflib.get_close_matches(str(typ), known, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ModelError(f"{where}: 'type' must be one of {', '.join(known)}, got {typ!r}{hint}")
    name = spec.get("name")
    entry = f"{where} '{name}'" if isinstance(name, str) and name else where
    check_keys(spec, [*_COMMON_KEYS, *_TYPE_KEYS[cls]], where=entry, section=f"a {cls.__name__}")
    target_key = _TYPE_KEYS[cls][0]
    if not isinstance(name, str) or not name:
        raise ModelError(f"{where}: give the actuator's 'name'")
    if not isinstance(spec.get(target_key), str) or not spec[target_key]:
        raise ModelError(f"{entry}: give '{target_key}', the {cls.target_kind} it acts on")
    kw = {}
    for key in ("optimal_force", "min_control", "max_control"):
        if key in spec:
            v = spec[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ModelError(f"{entry}: {key} must be a number, got {v!r}")
            kw[key] = float(v)
    for key in _TYPE_KEYS[cls][1:]:
        if key in spec:
            v = spec[key]
            flag = key.endswith("_global")
            if (flag and not isinstance(v, bool)) or (key == "body_b" and not isinstance(v, str)):
                raise ModelError(f"{entry}: {key} must be {'true or false' if flag else 'a body name'}, got {v!r}")
            kw[key] = v
    bounds, vary = read_parameter_settings(spec, [p.name for p in cls.parameters], where=entry)
    value = kw.pop("optimal_force", None)
    try:
        act = cls(name, spec[target_key], **kw)
        if value is not None or bounds or vary:
            act = act.with_params({} if value is None else {"optimal_force": value}, bounds=bounds, vary=vary)
    except ModelError as exc:
        raise ModelError(f"{entry}: {exc}") from None
    return act


def actuator_columns(model, motion: Motion, actuators: Sequence[IdealActuator], *, data=None) -> np.ndarray:
    """``F_opt B`` of each actuator over frames: ``(N, n_actuators, nv)`` (generalized force per unit control).

    ``data`` (a :class:`pinmsk.model.Data`) shares the body kinematics between actuators and with other
    components prepared on ``motion``."""
    out = np.zeros((motion.n_frames, len(actuators), model.nv))
    for i, act in enumerate(actuators):
        out[:, i, :] = act.columns(model, motion, cache=act.prepare(model, motion, data=data))
    return out
