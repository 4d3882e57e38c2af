"""Which effects apply to a model and a trial: the diagnosis' candidate list.

:func:`catalog` returns one default-parameter instance per applicable
``(family, target)``.  The policy lives here, not in the physics: a family
gets candidates by its ``target_kind``:

* ``"coordinate"`` -- every actuated coordinate the trial lets us compare;
* ``"frame"`` -- the frames the user names (``frames=[...]``), else the
  model's hand-like frames (hand, palm, fingertip, tool, ...);
* ``"body"`` -- every body that carries mass;
* ``"side"`` -- each leg (``r``, ``l``) with hip, knee and ankle coordinates,
  one of them compared;
* ``"model"`` -- one instance without target;
* ``"muscle"`` -- one instance for all muscles, in muscle-level comparisons;
* ``"plate"`` -- one per body the trial's measured external loads act on
  (``CatalogContext.loads``), in torque-level comparisons: none without loads.

A user family may override its rule with a classmethod ``candidates(model, context)``.

Rules of the built-in families: joint effects (damping, friction, spring,
passive elastic) on compared, actuated coordinates; the measurement effects
``sensor_offset`` (torque and motion level) and ``sensor_gain`` (torque level)
on the compared, actuated coordinates whose recorded ``<coord>_moment`` the
comparison uses; ``payload`` on hand-like frames (a frame named hand, palm,
fingertip, tool, ...) or the frames the user names; ``segment_mass`` on every
body with mass; ``scale`` (every segment's mass at once: the model not scaled
to the subject) on models of two bodies or more; ``riener_edrich_1999`` on
legs with hip, knee and ankle coordinates; ``activation_dynamics`` and
``electromechanical_delay`` only when the trial has excitation or EMG
channels and the model has muscles; ``end_stop_upper`` and ``end_stop_lower``
(one side of a CoordinateLimitForce each) on the compared, actuated
coordinates; ``com_offset`` on the heaviest bodies (at most two, each at least
12 % of the mass) of a floating-base model in a torque-level comparison; the
plate corrections (``plate_offset``, ``plate_cop_offset``, ``plate_tilt``,
``plate_gain``, ``plate_lag``) on each loaded body; ``payload`` on a
fixed-base model without hand-like frames at its distal bodies' centres of
mass, markers and joint origins (:func:`pinmsk.effects.payload.payload_sites`).  Effects the model already has (same
label) are left out.  Each candidate comes with its model-dependent bounds
(``for_model``: the rest angles of ``joint_spring`` and ``passive_elastic`` and
the end stops' limits within the joint's range of motion, a COM offset within a
fifth of its segment, the axes a planar model cannot see held at zero), so that
it stays identifiable.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..effects import registry
from ..effects._base import hand_like_frames, moving_bodies, unactuated_coordinates
from ..errors import ModelError, PinmskError
from ..kinematics import independent_coordinates
from .compare import comparison_plan


@dataclass(frozen=True)
class CatalogContext:
    """What the candidates can be judged on: the comparison mode and the compared coordinates."""

    mode: str
    coordinates: tuple[str, ...]
    unactuated: tuple[str, ...] = ()
    frames: tuple[str, ...] = field(default_factory=tuple)
    #: the bodies the trial's measured external loads act on (force plates), for the plate corrections
    loads: tuple[str, ...] = ()


def catalog(model, trial=None, *, frames=None, mode: str = "auto", families=None,
            context: CatalogContext | None = None) -> list:
    """Default instances of every effect that applies to ``model`` and ``trial``.

    ``frames`` names frames for frame-targeted effects (payload); ``families``
    restricts the list to those family names.  ``mode`` is the comparison
    (``"auto"``, ``"torque"``, ``"motion"``, ``"muscle"``, see
    :func:`pinmsk.diagnose.compare`).
    """
    if context is None:
        context = catalog_context(model, trial, mode=mode, frames=frames)
    names = registry.families() if families is None else list(families)
    for f in names:
        registry.get(f)                       # unknown names: ModelError listing the known ones
    for f in context.frames:
        model.frame_id(f)
    have = {c.label for c in model.components}
    out = []
    for fam in names:
        cls = registry.get(fam)
        if hasattr(cls, "candidates"):
            cands = cls.candidates(model, context)
        else:
            cands = _default_candidates(cls, model, context)
        for c in cands:
            if c.label in have:
                continue
            try:
                c.check_target(model)
            except ModelError:
                continue
            hook = getattr(c, "for_model", None)
            out.append(hook(model) if hook is not None else c)
    return out


def _default_candidates(cls, model, context) -> list:
    kind = getattr(cls, "target_kind", "coordinate")
    level = getattr(cls, "level", "joint")
    if level == "muscle":
        return [cls("muscles")] if context.mode == "muscle" and model.muscles is not None else []
    if kind == "coordinate":
        return [cls(c) for c in context.coordinates if c not in context.unactuated]
    if kind == "frame":
        return [cls(f) for f in (context.frames or hand_like_frames(model))]
    if kind == "side":
        legs = [s for s in ("r", "l") if all(f"{j}_{s}" in model.coordinates for j in ("hip", "knee", "ankle"))
                and any(f"{j}_{s}" in context.coordinates for j in ("hip", "knee", "ankle"))]
        return [cls(s) for s in legs]
    if kind == "body":
        return [cls(b) for b in moving_bodies(model)]
    if kind == "model":
        return [cls(None)]
    return []


def catalog_context(model, trial, *, mode: str = "auto", frames=None,
                    missing_coordinates: str = "refuse") -> CatalogContext:
    """The :class:`~pinmsk.diagnose.catalog.CatalogContext` of a model and trial (no dynamics computed).

    The coordinates are the model's independent ones (:func:`pinmsk.kinematics.independent_coordinates`):
    on an exact OpenSim import OpenSim's coordinates, so that no candidate targets a dependent joint (a
    knee's translations) or a coupled coordinate (a patella angle set by its coupler)."""
    if trial is None:
        return CatalogContext("torque", independent_coordinates(model), tuple(unactuated_coordinates(model)),
                              tuple(frames or ()))
    plan = comparison_plan(model, trial, mode, missing_coordinates=missing_coordinates)
    return CatalogContext(plan.mode, plan.coordinates, plan.unactuated, tuple(frames or ()), _load_bodies(model, trial))


def _load_bodies(model, trial) -> tuple[str, ...]:
    """The bodies the trial's ground reaction channels load (none without GRF or a body to put them on)."""
    from ..grf import plates
    try:
        return tuple(sorted({p.body for p in plates(model, trial)}))
    except PinmskError:
        return ()
