"""The force import hook of an OpenSim model: :func:`force_hook`.

===========================  ==========================================================  ==========
OpenSim                      pinmsk                                                      carried
===========================  ==========================================================  ==========
CoordinateLimitForce         :class:`~pinmsk.effects.EndStopUpper` and                   exact
                             :class:`~pinmsk.effects.EndStopLower` on its coordinate
BushingForce                 :class:`~pinmsk.effects.LinearBushing` between its frames   exact
PointToPointSpring           :class:`~pinmsk.effects.PointToPointSpring`                 exact
SpringGeneralizedForce       :class:`~pinmsk.effects.JointSpring` and                    exact
                             :class:`~pinmsk.effects.JointDamping`
ExpressionBasedCoordinateForce :class:`~pinmsk.effects.CoordinateExpressionForce`          exact
===========================  ==========================================================  ==========

CoordinateLimitForce (``CoordinateLimitForce.cpp``, ``calcLimitForce``): beyond ``upper_limit`` a
spring whose stiffness rises from 0 to ``upper_stiffness`` over ``transition`` (Simbody's
``Function::Step``), below ``lower_limit`` the same with ``lower_stiffness``, and a damping
``damping`` switched on by the same steps: the sum of one upper and one lower end stop, each in SI
(OpenSim's file gives a rotational coordinate's limits and transition in degrees, its stiffness in
N m/deg and its damping in N m s/deg).  A side whose stiffness is 0 is left out (OpenSim divides
the damping's switch by that stiffness, so its force is then not a number).

BushingForce: its two frames (``socket_frame1``, ``socket_frame2``: bodies or offset frames, the
force's own ``<frames>`` included) become Pinocchio frames on their bodies, named after the OpenSim
frame (a body's own frame where the socket names a body); the bushing acts between them with the
force's ``rotational_stiffness``, ``translational_stiffness``, ``rotational_damping`` and
``translational_damping`` (N m/rad, N/m, N m s/rad, N s/m: no conversion).  PointToPointSpring:
``socket_body1``, ``socket_body2``, ``point1``, ``point2``, ``stiffness``, ``rest_length``.

A force with ``appliesForce`` false (``isDisabled`` true) gets a note and no component, as OpenSim
applies none.  Every other force stays a "not imported" entry of the report, named by its type.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import pinocchio as pin

from ..effects import (CoordinateExpressionForce, EndStopLower, EndStopUpper, JointDamping, JointSpring,
                       LinearBushing, PointToPointSpring)
from ..errors import ModelError
from ..io.osim import OsimDocument, OtherElement
from .hooks import HookResult
from .report import EXACT, NOTE, NOT_IMPORTED, ReportEntry
from .skeleton import Skeleton, _chain

__all__ = ["force_hook", "IMPORTED_FORCES"]

#: The OpenSim force types :func:`force_hook` makes into components.
IMPORTED_FORCES = ("CoordinateLimitForce", "BushingForce", "PointToPointSpring", "SpringGeneralizedForce",
                   "ExpressionBasedCoordinateForce")


def force_hook(doc: OsimDocument, skeleton: Skeleton) -> HookResult:
    """``hook(doc, skeleton) -> HookResult``: the model's passive forces as effects (module docstring);
    adds the frames of its bushings and springs to ``skeleton.pin_model``."""
    comps, entries, handled = [], [], []
    labels: set[str] = set()
    frames = _Frames(doc, skeleton)
    for force in doc.other:
        if force.category != "force" or force.type not in IMPORTED_FORCES:
            continue
        handled.append(force.where)
        props = force.properties
        if not _applies(force, props):
            entries.append(ReportEntry(element=force.where, status=NOTE,
                                       became="disabled (appliesForce false): no force, as in OpenSim"))
            continue
        try:
            made, notes = _MAKERS[force.type](force, props, skeleton, frames)
        except _NotImported as why:
            entries.append(ReportEntry(element=force.where, status=NOT_IMPORTED, became=f"not imported: {why}"))
            continue
        except ModelError as exc:
            msg = str(exc)
            raise ModelError(msg if msg.startswith(force.source) else f"{force.where}: {msg}") from None
        twice = [c.label for c, _ in made if c.label in labels]
        if twice:
            entries.append(ReportEntry(element=force.where, status=NOT_IMPORTED, became=(
                f"not imported: {', '.join(twice)} is made by another force already (two forces of one kind on "
                "one target)")))
            continue
        for comp, text in made:
            labels.add(comp.label)
            comps.append(comp)
            entries.append(ReportEntry(element=force.where, status=EXACT, became=text))
        for n in notes:
            entries.append(ReportEntry(element=force.where, status=NOTE, became=n))
    return HookResult(components=tuple(comps), entries=tuple(entries), handled=tuple(handled))


class _NotImported(Exception):
    """Why a force is not imported (its report entry)."""


def _applies(force: OtherElement, props) -> bool:
    for key, on in (("appliesForce", True), ("isDisabled", False)):
        if key in props:
            v = props[key]
            if not isinstance(v, bool):
                raise ModelError(f"{force.where}: <{key}> must be true or false, got {v!r}")
            return v == on
    return True


def _number(force: OtherElement, props, key: str, default: float | None = None) -> float:
    v = props.get(key, default)
    if v is None or v == "":
        if default is None:
            raise ModelError(f"{force.where}: has no <{key}>")
        v = default
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ModelError(f"{force.where}: <{key}> must be a finite number, got {v!r}")
    return float(v)


def _vector(force: OtherElement, props, key: str, default=(0.0, 0.0, 0.0)) -> tuple[float, float, float]:
    v = props.get(key, default)
    vals = (v,) if isinstance(v, float) else v
    if not isinstance(vals, tuple) or len(vals) != 3 or not all(isinstance(x, float) and math.isfinite(x)
                                                                  for x in vals):
        raise ModelError(f"{force.where}: <{key}> must hold 3 finite numbers, got {v!r}")
    return vals


def _within(comp, values: dict):
    """``comp`` with ``values``, its bounds widened where a value of the file lies outside them."""
    bounds = {}
    for k, x in values.items():
        p = comp.params[k]
        if not p.min <= x <= p.max:
            bounds[k] = (min(p.min, x), max(p.max, x))
    return comp.with_params(values, bounds=bounds or None)


def _coordinate(force: OtherElement, name: str, skeleton: Skeleton) -> str | None:
    """The skeleton's joint of OpenSim coordinate ``name``; None if it is welded (locked='weld')."""
    pm = skeleton.pin_model
    if name in skeleton.welded and not pm.existJointName(name):
        return None
    if not name or not pm.existJointName(name):
        import difflib
        known = [pm.names[j] for j in range(1, pm.njoints)]
        close = difflib.get_close_matches(str(name), known, n=3)
        hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
        raise ModelError(f"{force.where}: the model has no coordinate '{name}'{hint}")
    return name


def _coordinate_limit(force, props, skeleton, frames):
    coord = str(props.get("coordinate", "") or "").rsplit("/", 1)[-1]
    joint = _coordinate(force, coord, skeleton)
    if joint is None:
        return [], [f"left out: its coordinate '{coord}' is welded (locked='weld'), so it cannot move"]
    rotational = skeleton.motion_types.get(coord, "Rotational") == "Rotational"
    w = math.pi / 180.0 if rotational else 1.0
    unit = "deg" if rotational else "m"
    damping = _number(force, props, "damping", 0.001)
    transition = _number(force, props, "transition", 0.1)
    if not transition > 0:
        raise ModelError(f"{force.where}: <transition> must be > 0, got {transition:g}")
    made, notes = [], []
    for cls, side in ((EndStopUpper, "upper"), (EndStopLower, "lower")):
        k = _number(force, props, f"{side}_stiffness", 1.0)
        lim = _number(force, props, f"{side}_limit", 0.0)
        if k < 0:
            raise ModelError(f"{force.where}: <{side}_stiffness> must be >= 0, got {k:g}")
        if k == 0:
            notes.append(f"its {side} side has stiffness 0: left out (OpenSim's damping switch divides by it)")
            continue
        comp = _within(cls(joint), {"stiffness": k / w, "limit": lim * w, "transition": transition * w,
                                    "damping": damping / w})
        made.append((comp, f"{comp.label}: the {side} side, stiffness {k:g} N m/{unit} from {lim:g} {unit} over "
                           f"{transition:g} {unit}, damping {damping:g}; OpenSim's law exactly"))
    return made, notes


def _bushing(force, props, skeleton, frames):
    f1, f2 = (force.sockets.get(k) for k in ("frame1", "frame2"))
    if not f1 or not f2:
        raise ModelError(f"{force.where}: names no frames (<socket_frame1>, <socket_frame2>)")
    a, b = frames.frame(f1, force), frames.frame(f2, force)
    values = {}
    for what in ("rotational_stiffness", "translational_stiffness", "rotational_damping", "translational_damping"):
        for axis, x in zip("xyz", _vector(force, props, what)):
            if x < 0:
                raise ModelError(f"{force.where}: <{what}> must be >= 0, got {x:g}")
            values[f"{what}_{axis}"] = x
    comp = _within(LinearBushing(a, frame2=b), values)
    return [(comp, f"{comp.label}: linear bushing between frames '{a}' and '{b}' (Simbody's LinearBushing "
                   "exactly)")], []


def _point_spring(force, props, skeleton, frames):
    f1, f2 = (force.sockets.get(k) for k in ("body1", "body2"))
    if not f1 or not f2:
        raise ModelError(f"{force.where}: names no bodies (<socket_body1>, <socket_body2>)")
    a, b = frames.frame(f1, force), frames.frame(f2, force)
    comp = PointToPointSpring(a, frame2=b, point1=_vector(force, props, "point1"),
                              point2=_vector(force, props, "point2"))
    comp = _within(comp, {"stiffness": _number(force, props, "stiffness", 1.0),
                          "rest_length": _number(force, props, "rest_length", 0.0)})
    return [(comp, f"{comp.label}: spring between frames '{a}' and '{b}' (Simbody's TwoPointLinearSpring "
                   "exactly)")], []


def _generalized_spring(force, props, skeleton, frames):
    coord = str(props.get("coordinate", "") or "").rsplit("/", 1)[-1]
    joint = _coordinate(force, coord, skeleton)
    if joint is None:
        return [], [f"left out: its coordinate '{coord}' is welded (locked='weld'), so it cannot move"]
    made = []
    k, q0, c = (_number(force, props, n, 0.0) for n in ("stiffness", "rest_length", "viscosity"))
    if k:
        comp = _within(JointSpring(joint), {"k": k, "q0": q0})
        made.append((comp, f"{comp.label}: stiffness {k:g} about {q0:g}; OpenSim's law exactly"))
    if c:
        comp = _within(JointDamping(joint), {"c": c})
        made.append((comp, f"{comp.label}: viscosity {c:g}; OpenSim's law exactly"))
    return made, ([] if made else ["stiffness and viscosity 0: no force"])


def _expression(force, props, skeleton, frames):
    coord = str(props.get("coordinate", "") or "").rsplit("/", 1)[-1]
    joint = _coordinate(force, coord, skeleton)
    if joint is None:
        return [], [f"left out: its coordinate '{coord}' is welded (locked='weld'), so it cannot move"]
    text = props.get("expression", "0.0")
    text = "0.0" if text in ("", None) else str(text) if not isinstance(text, float) else repr(text)
    comp = CoordinateExpressionForce(joint, expression=text)
    return [(comp, f"{comp.label}: Q = {text} (q, qdot in SI); OpenSim's expression exactly")], []


_MAKERS = {"ExpressionBasedCoordinateForce": _expression, "CoordinateLimitForce": _coordinate_limit, "BushingForce": _bushing,
           "PointToPointSpring": _point_spring, "SpringGeneralizedForce": _generalized_spring}


class _Frames:
    """Pinocchio frames for OpenSim frame paths (bodies or offset frames), added once each."""

    def __init__(self, doc: OsimDocument, skeleton: Skeleton):
        self.doc, self.pm = doc, skeleton.pin_model
        self.made: dict[str, str] = {}

    def frame(self, path: str, force: OtherElement) -> str:
        if path in self.made:
            return self.made[path]
        pm = self.pm
        body, chain = self.doc.frame_body(path)
        T = _chain(chain)
        if body is self.doc.ground and not chain:
            self.made[path] = "universe"
            return "universe"
        if body is self.doc.ground:
            parent_frame, joint, placement = 0, 0, pin.SE3(T)
        else:
            if not pm.existFrame(body.name, pin.FrameType.BODY):
                raise ModelError(f"{force.where}: body '{body.name}' has no frame in the skeleton")
            parent_frame = pm.getFrameId(body.name, pin.FrameType.BODY)
            bf = pm.frames[parent_frame]
            if not chain:
                self.made[path] = body.name
                return body.name
            joint, placement = bf.parentJoint, bf.placement * pin.SE3(T)
        leaf = path.rstrip("/").rsplit("/", 1)[-1] or "ground"
        for name in itertools.chain((leaf, f"{force.name}_{leaf}"), (f"{force.name}_{leaf}_{i}" for i in
                                                                     itertools.count(2))):
            if not pm.existFrame(name):
                pm.addFrame(pin.Frame(name, joint, parent_frame, placement, pin.FrameType.OP_FRAME))
                break
            f = pm.frames[pm.getFrameId(name)]
            if f.type == pin.FrameType.OP_FRAME and f.parentJoint == joint and f.placement.isApprox(placement, 1e-14):
                break                      # the hook run again on the same skeleton
        self.made[path] = name
        return name
