"""OpenSim actuators as pinmsk ideal actuators: the import hook :func:`actuator_hook` and force set
files (:func:`read_actuators`).

=============================  ==========================================  ===================================
OpenSim                        pinmsk (:mod:`pinmsk.actuators`)             carried
=============================  ==========================================  ===================================
CoordinateActuator             :class:`~pinmsk.actuators.CoordinateActuator`  exact
ActivationCoordinateActuator   :class:`~pinmsk.actuators.CoordinateActuator`  its activation dynamics are not
                                                                           (a note): the control acts directly
PointActuator                  :class:`~pinmsk.actuators.PointActuator`      exact (point, direction, global flags)
TorqueActuator                 :class:`~pinmsk.actuators.TorqueActuator`     exact (both bodies, axis frame)
=============================  ==========================================  ===================================

``optimal_force``, ``min_control`` and ``max_control`` keep OpenSim's defaults
(1, -Inf, Inf) when absent.  An actuator that does not apply force
(``appliesForce`` false / ``isDisabled`` true) is left out with a note, as
OpenSim's StaticOptimization removes it.  Body names become the skeleton's body
frames (``/bodyset/pelvis`` -> ``pelvis``; ``/ground`` -> the ground, which gets
no reaction torque).  Bad input names the element and its line: an unknown
coordinate or body (with a "did you mean"), ``min_control > max_control``, a
negative optimal force, a vector that is not 3 numbers.  Other actuator types
(``BodyActuator``) stay "not imported" in a model and are refused by name in a
force set file.
"""
from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..actuators import CoordinateActuator, PointActuator, TorqueActuator
from ..errors import ModelError
from ..io.osim import Actuator, read_force_set
from .hooks import HookResult
from .report import EXACT, NOTE, ReportEntry

__all__ = ["actuator_hook", "actuator_components", "read_actuators", "IMPORTED_TYPES"]

#: The OpenSim actuator types made into pinmsk actuators.
IMPORTED_TYPES = ("CoordinateActuator", "ActivationCoordinateActuator", "PointActuator", "TorqueActuator")


def actuator_hook(doc, skeleton) -> HookResult:
    """``hook(doc, skeleton) -> HookResult``: the model's actuators as components (see the module docstring)."""
    pm = skeleton.pin_model
    comps, entries, handled = actuator_components(
        doc.actuators, pin_model=pm, coordinates=tuple(pm.names[j] for j in range(1, pm.njoints)),
        welded=dict(skeleton.welded), model_name=doc.name)
    return HookResult(components=comps, entries=entries, handled=handled)


def read_actuators(path, model) -> tuple[tuple, tuple[ReportEntry, ...]]:
    """The actuators of an OpenSim force set file (``<ForceSet>``, e.g. ``gait10dof18musc_Strong_actuators.xml``)
    as components of ``model`` (a :class:`pinmsk.Model`), with one report entry each."""
    fs = read_force_set(Path(path))
    welded = dict(model.meta.get("welded_coordinates") or {})
    comps, entries, handled = actuator_components(fs.actuators, pin_model=model.pin, coordinates=model.coordinates,
                                                  welded=welded, model_name=model.name)
    for a in fs.actuators:
        if a.where not in handled:
            raise ModelError(f"{a.where}: pinmsk makes {', '.join(IMPORTED_TYPES)} into actuators; a {a.type} "
                             "is not one of them (remove it from the force set file)")
    return comps, entries


def actuator_components(elements: Sequence[Actuator], *, pin_model, coordinates, welded=None,
                        model_name: str = "model"):
    """``(components, report entries, handled wheres)`` of OpenSim actuator elements on a skeleton with
    joints ``coordinates`` (``welded``: OpenSim coordinates fixed at a value, which an actuator cannot move)."""
    welded = dict(welded or {})
    comps, entries, handled = [], [], []
    for a in elements:
        if a.type not in IMPORTED_TYPES:
            continue
        props = a.properties
        if not _applies_force(a, props):
            handled.append(a.where)
            entries.append(ReportEntry(element=a.where, status=NOTE,
                                       became="disabled (appliesForce false): left out, as OpenSim's tools leave it"))
            continue
        kw = dict(optimal_force=_number(a, props, "optimal_force", 1.0),
                  min_control=_number(a, props, "min_control", -math.inf),
                  max_control=_number(a, props, "max_control", math.inf))
        if kw["min_control"] > kw["max_control"]:
            raise ModelError(f"{a.where}: min_control {kw['min_control']:g} > max_control {kw['max_control']:g}")
        if not kw["optimal_force"] >= 0.0 or not math.isfinite(kw["optimal_force"]):
            raise ModelError(f"{a.where}: optimal_force must be a finite value >= 0, got {kw['optimal_force']:g}")
        status, note = EXACT, ""
        try:
            if a.type in ("CoordinateActuator", "ActivationCoordinateActuator"):
                coord = a.coordinate
                if coord in welded and coord not in coordinates:
                    handled.append(a.where)
                    entries.append(ReportEntry(element=a.where, status=NOTE, became=(
                        f"left out: its coordinate '{coord}' is welded at {welded[coord]:g} (locked='weld'), so "
                        "the actuator cannot move it")))
                    continue
                _check_name(a, coord, coordinates, "coordinate", model_name)
                comp = CoordinateActuator(a.name, coord, **kw)
                on = f"coordinate {coord}"
                if a.type == "ActivationCoordinateActuator":
                    status = NOTE
                    note = ("; its activation dynamics (activation_time_constant) are not represented: the "
                            "control is the activation")
            elif a.type == "PointActuator":
                body = _body(a, 0, pin_model, model_name)
                comp = PointActuator(a.name, body, point=_vector(a, props, "point", (0.0, 0.0, 0.0)),
                                     direction=_vector(a, props, "direction", (1.0, 0.0, 0.0)),
                                     point_is_global=_flag(a, props, "point_is_global", False),
                                     force_is_global=_flag(a, props, "force_is_global", False), **kw)
                on = (f"body {body} at {'ground ' if comp.point_is_global else ''}point {list(comp.point)}, "
                      f"direction {list(np.round(comp.direction, 6))} in the "
                      f"{'ground' if comp.force_is_global else 'body'} frame")
            else:
                body_a = _body(a, 0, pin_model, model_name)
                body_b = _body(a, 1, pin_model, model_name) if len(a.bodies) > 1 else None
                ground = body_b is not None and pin_model.frames[pin_model.getFrameId(body_b)].parentJoint == 0
                comp = TorqueActuator(a.name, body_a, body_b=None if ground else body_b,
                                      axis=_vector(a, props, "axis", (0.0, 0.0, 1.0)),
                                      torque_is_global=_flag(a, props, "torque_is_global", True), **kw)
                on = (f"body {body_a}" + (f" against {body_b}" if body_b and not ground else "")
                      + f", axis {list(np.round(comp.axis, 6))} in the "
                      f"{'ground' if comp.torque_is_global else 'body A'} frame")
        except ModelError as exc:
            msg = str(exc)
            raise ModelError(msg if msg.startswith(a.source) else f"{a.where}: {msg}") from None
        comps.append(comp)
        handled.append(a.where)
        entries.append(ReportEntry(element=a.where, status=status, became=(
            f"{comp.label} on {on}: optimal force {kw['optimal_force']:g}, control "
            f"[{kw['min_control']:g}, {kw['max_control']:g}]{note}")))
    return tuple(comps), tuple(entries), tuple(handled)


def _applies_force(a: Actuator, props) -> bool:
    if "appliesForce" in props:
        return _as_flag(a, "appliesForce", props["appliesForce"])
    if "isDisabled" in props:
        return not _as_flag(a, "isDisabled", props["isDisabled"])
    return True


def _as_flag(a: Actuator, key: str, value) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, float) and value in (0.0, 1.0):
        return bool(value)
    raise ModelError(f"{a.where}: <{key}> must be true or false, got {value!r}")


def _flag(a: Actuator, props, key: str, default: bool) -> bool:
    if key not in props or props[key] == "":
        return default
    return _as_flag(a, key, props[key])


def _number(a: Actuator, props, key: str, default: float) -> float:
    v = props.get(key)
    if v is None or v == "":
        return default
    if isinstance(v, bool) or not isinstance(v, float):
        raise ModelError(f"{a.where}: <{key}> must be a number, got {v!r}")
    if math.isnan(v):
        raise ModelError(f"{a.where}: <{key}> is NaN; it must be a number")
    return v


def _vector(a: Actuator, props, key: str, default) -> tuple[float, float, float]:
    v = props.get(key)
    if v is None or v == "":
        return tuple(default)
    vals = (v,) if isinstance(v, float) else v
    finite = isinstance(vals, tuple) and all(isinstance(x, float) and math.isfinite(x) for x in vals)
    if not finite or len(vals) != 3:
        raise ModelError(f"{a.where}: <{key}> must hold 3 finite numbers, got {v!r}")
    return vals


def _check_name(a: Actuator, name, known, what: str, model_name: str) -> None:
    if name in known:
        return
    close = difflib.get_close_matches(str(name), list(known), n=3)
    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
    raise ModelError(f"{a.where}: model '{model_name}' has no {what} '{name}'{hint}")


def _body(a: Actuator, i: int, pin_model, model_name: str) -> str:
    """The skeleton's frame of the actuator's ``i``-th body (``/bodyset/x`` -> ``x``; ground -> the ground)."""
    if len(a.bodies) <= i or not a.bodies[i]:
        raise ModelError(f"{a.where}: names no body (<{'bodyA' if a.type == 'TorqueActuator' else 'body'}>)")
    path = a.bodies[i]
    name = path.rstrip("/").rsplit("/", 1)[-1]
    if path == "/ground" or name == "ground":
        for cand in ("ground", "universe"):
            if pin_model.existFrame(cand):
                return cand
    bodies = [f.name for f in pin_model.frames if str(f.type) == "BODY"]
    _check_name(a, name, bodies, "body", model_name)
    return name
