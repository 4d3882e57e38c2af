"""OpenSim IK task sets (``<IKTaskSet>``): which markers and coordinates inverse kinematics tracks.

An ``IKMarkerTask`` names a model marker, whether it is used (``apply``) and its
weight; an ``IKCoordinateTask`` names a coordinate, its weight and where its
target comes from (``value_type``: ``default_value``, the coordinate's default
in the model; ``manual_value``, the task's ``value`` in the model's units, rad
or m; ``from_file``, the coordinate file of the IK setup).  These are the
fields OpenSim's ``InverseKinematicsTool::populateReferences`` reads
(OpenSim/Tools/InverseKinematicsTool.cpp); any other field with a value is
refused by name.

A task set is read from a setup's inline ``<IKTaskSet>`` (:func:`ik_tasks_from_node`)
or from its own file ``<OpenSimDocument><IKTaskSet>`` (:func:`read_ik_tasks`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .opensim_setup import SetupError, SetupNode, read_setup

__all__ = ["IKTask", "VALUE_TYPES", "read_ik_tasks", "ik_tasks_from_node"]

#: The sources of a coordinate task's target, as OpenSim names them.
VALUE_TYPES = ("default_value", "manual_value", "from_file")


@dataclass(frozen=True)
class IKTask:
    """One IK task: ``kind`` ``"marker"`` or ``"coordinate"``, the marker's or coordinate's ``name``,
    ``apply``, ``weight``; a coordinate task's ``value_type`` (:data:`VALUE_TYPES`) and ``value``
    (rad or m).  ``where`` names the element in its file for messages."""

    kind: str
    name: str
    apply: bool = True
    weight: float = 1.0
    value_type: str = "default_value"
    value: float = 0.0
    where: str = ""


def _task(node: SetupNode) -> IKTask:
    if not node.name:
        raise node.error(None, "a task needs a name attribute (the marker or coordinate it tracks)")
    apply = node.flag("apply", True)
    weight = node.number("weight", 1.0)
    if not weight >= 0:
        raise node.error("weight", f"a weight is >= 0, got {weight:g}")
    if node.tag == "IKMarkerTask":
        node.finish()
        return IKTask("marker", node.name, apply, weight, where=f"{node.setup.path}: {node.where}")
    value_type = node.text("value_type", "default_value")
    if value_type not in VALUE_TYPES:
        raise node.error("value_type", f"'{value_type}' is not one of {', '.join(VALUE_TYPES)}")
    value = node.number("value", 0.0)
    node.finish()
    return IKTask("coordinate", node.name, apply, weight, value_type, value,
                  where=f"{node.setup.path}: {node.where}")


def ik_tasks_from_node(node: SetupNode, prop: str = "IKTaskSet") -> tuple[IKTask, ...]:
    """The tasks of the set ``prop`` of a setup node (its ``<objects>`` list of IKMarkerTask and
    IKCoordinateTask); a set given as ``<IKTaskSet file="tasks.xml"/>`` is read from that file
    (relative to the setup's folder).  Empty when the set is absent or empty."""
    el = node.element.find(prop)
    if el is not None and el.get("file"):
        node.ignore(prop)
        p = Path(el.get("file"))
        if not p.is_absolute():
            p = node.setup.folder / p
        if not p.exists():
            raise node.error(prop, f"task set file '{el.get('file')}' not found (resolved to {p})")
        return read_ik_tasks(p)
    tasks = []
    for member in node.objects(prop):
        if member.tag not in ("IKMarkerTask", "IKCoordinateTask"):
            raise member.error(None, "an IK task set holds IKMarkerTask and IKCoordinateTask elements")
        tasks.append(_task(member))
    return _unique(tasks)


def read_ik_tasks(path) -> tuple[IKTask, ...]:
    """Read an OpenSim IK task set file (``<OpenSimDocument><IKTaskSet><objects>...``)."""
    setup = read_setup(path)
    if setup.tool != "IKTaskSet":
        raise SetupError(f"{setup.path}: holds a <{setup.tool}>, not an <IKTaskSet>")
    tasks = []
    for member in setup.node.objects("objects"):
        if member.tag not in ("IKMarkerTask", "IKCoordinateTask"):
            raise member.error(None, "an IK task set holds IKMarkerTask and IKCoordinateTask elements")
        tasks.append(_task(member))
    setup.node.finish()
    return _unique(tasks)


def _unique(tasks: list) -> tuple[IKTask, ...]:
    seen = {}
    for t in tasks:
        key = (t.kind, t.name)
        if key in seen:
            raise SetupError(f"{t.where}: a second {t.kind} task for '{t.name}' (the first: {seen[key].where})")
        seen[key] = t
    return tuple(tasks)
