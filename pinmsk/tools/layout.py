"""OpenSim's layout of results, for models that came from OpenSim.

A model imported from an ``.osim`` (``model.meta["osim"]``), or loaded from a sidecar that an import
wrote (``model.meta["source_osim"]``), gets its results in the files OpenSim's tools write, by
default: the runners of :mod:`pinmsk.tools` and the commands ``pinmsk id`` and ``pinmsk so``.
Built-in models keep pinmsk's layout (:func:`pinmsk.io.tables.write_trial` of the result).

* inverse dynamics (opensim-core ``InverseDynamicsTool.cpp``): ``time`` and each coordinate's
  generalized force, ``<coord>_moment`` for a rotation and ``<coord>_force`` for a translation, no
  coordinates before them, in OpenSim 4's multibody-tree order (``getCoordinatesInMultibodyTreeOrder``:
  the joints by their child body's depth below the ground, joints of one depth in the model's order;
  :func:`tree_order`); title ``Inverse Dynamics Generalized Forces``;
* static optimization (``StaticOptimization.cpp``): two files, ``..._activation`` (each muscle's
  activation, then each actuator's control) and ``..._force`` (each muscle's and actuator's force),
  their columns the bare muscle and actuator names.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..trial import Trial

__all__ = ["is_opensim_model", "generalized_force_name", "tree_order", "id_table", "so_tables", "so_paths",
           "ID_TITLE", "SO_TITLE", "FORCE_TITLE"]

#: First lines OpenSim writes: the ID tool's file, StaticOptimization's activation file, and its force
#: file (the storage of OpenSim's ForceReporter).
ID_TITLE = "Inverse Dynamics Generalized Forces"
SO_TITLE = "Static Optimization"
FORCE_TITLE = "ModelForces"


def is_opensim_model(model) -> bool:
    """Whether ``model`` came from an OpenSim ``.osim`` (imported, or a sidecar an import wrote)."""
    meta = getattr(model, "meta", None) or {}
    return bool(meta.get("osim") or meta.get("source_osim"))


def generalized_force_name(model, coordinate: str) -> str:
    """OpenSim's label of a coordinate's generalized force: ``<coord>_moment`` for a rotation, ``<coord>_force``
    for a translation (the import's motion types; a sidecar's, from its joint: prismatic = translation)."""
    types = model.meta.get("osim_motion_types") or {}
    kind = types.get(coordinate)
    if kind is None:
        kind = "Translational" if _prismatic(model, coordinate) else "Rotational"
    return f"{coordinate}_{'moment' if kind == 'Rotational' else 'force'}"


def _prismatic(model, coordinate: str) -> bool:
    pm = model.pin
    if not pm.existJointName(coordinate):
        return False
    name = pm.joints[pm.getJointId(coordinate)].shortname()
    return "Prismatic" in name or name.startswith("JointModelP")


def tree_order(model, coordinates) -> list[str]:
    """``coordinates`` in OpenSim 4's multibody-tree order: Simbody's graph of the model's joints built a
    depth at a time from the ground (a joint's depth is its child body's), joints of one depth in the
    order of the model's JointSet, each joint's coordinates in its own order.  Unchanged when the model's
    ``.osim`` cannot be read (a sidecar whose source file is gone)."""
    from ..io.osim import read_osim

    src = model.meta.get("osim") or model.meta.get("source_osim")
    try:
        doc = read_osim(src)
    except Exception:                # the order is a courtesy of the layout, never a reason to fail
        return list(coordinates)
    depth = {doc.ground.name: 0}
    joints = list(doc.joints)
    links = []
    for j in joints:
        try:
            parent, child = doc.frame_body(j.parent_frame)[0].name, doc.frame_body(j.child_frame)[0].name
        except Exception:
            return list(coordinates)
        links.append((parent, child) if not j.reverse else (child, parent))
    for _ in range(len(joints)):
        for parent, child in links:
            if parent in depth and child not in depth:
                depth[child] = depth[parent] + 1
    rank = {}
    for k, (j, (_, child)) in enumerate(sorted(zip(joints, links),
                                               key=lambda jl: depth.get(jl[1][1], len(joints) + 1))):
        for c in j.coordinates:
            rank.setdefault(c.name, (k, len(rank)))
    known = [c for c in coordinates if c in rank]
    return sorted(known, key=rank.get) + [c for c in coordinates if c not in rank]


def id_table(model, trial: Trial, *, rows=None, keep_meta: bool = False) -> Trial:
    """OpenSim's generalized forces table from an inverse dynamics result's trial (``<coord>`` then
    ``<coord>_moment`` channels, :func:`pinmsk.dynamics.inverse_dynamics_result`): the forces only, named
    by :func:`generalized_force_name`; ``rows`` selects frames; ``keep_meta`` keeps the analysis' record
    (filter, loads) as header fields after the title."""
    coordinates = tree_order(model, [n for n in trial.names if f"{n}_moment" in trial.names])
    idx = slice(None) if rows is None else np.asarray(rows)
    forces = np.column_stack([np.asarray(trial[f"{c}_moment"]) for c in coordinates])[idx]
    meta = {**(dict(trial.meta) if keep_meta else {}), "name": ID_TITLE}
    for k in ("source", "format", "in_degrees", "header"):
        meta.pop(k, None)
    return Trial.from_array(np.asarray(trial.time, dtype=float)[idx],
                            tuple(generalized_force_name(model, c) for c in coordinates), forces, meta=meta)


def so_tables(model, result: Trial, actuators=(), *, external=None) -> tuple[Trial, Trial]:
    """OpenSim's activation and force tables from a static optimization result (``<muscle>_activation``,
    ``<muscle>_force``, ``<name>_control``, ``<name>_force``; pinmsk's own ``<coord>_reserve`` forces, when
    asked for, follow in the force table).  ``external``: ``(names, (N, k) values)`` appended to the force
    table (the external loads, as OpenSim's ForceReporter records them)."""
    muscles = list(model.muscles.names) if model.muscles is not None else []
    acts = list(actuators)
    t = np.asarray(result.time, dtype=float)
    cols = [np.asarray(result[f"{m}_activation"]) for m in muscles] + [np.asarray(result[f"{n}_control"])
                                                                        for n in acts]
    act = np.column_stack(cols) if cols else np.zeros((t.size, 0))
    reserves = [n for n in result.names if n.endswith("_reserve")]
    fcols = ([np.asarray(result[f"{m}_force"]) for m in muscles] + [np.asarray(result[f"{n}_force"]) for n in acts]
             + [np.asarray(result[n]) for n in reserves])
    force = np.column_stack(fcols) if fcols else np.zeros((t.size, 0))
    force_names = muscles + acts + reserves
    if external is not None and len(external[0]):
        force_names = force_names + list(external[0])
        force = np.hstack([force, np.asarray(external[1], dtype=float)])
    return (Trial.from_array(t, tuple(muscles + acts), act, meta={"name": SO_TITLE}),
            Trial.from_array(t, tuple(force_names), force, meta={"name": FORCE_TITLE}))


def so_paths(output) -> tuple[Path, Path]:
    """The two files of ``pinmsk so -o OUT.sto`` for an OpenSim model: ``OUT_activation.sto``, ``OUT_force.sto``."""
    p = Path(output)
    return (p.with_name(f"{p.stem}_activation{p.suffix or '.sto'}"),
            p.with_name(f"{p.stem}_force{p.suffix or '.sto'}"))
