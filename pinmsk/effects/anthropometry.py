"""Plausible segment masses: de Leva's (1996) table, mapped onto a model's bodies by name.

Source: P. de Leva (1996), "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
J Biomech 29(9):1223-1230, Table 4: segment masses in per cent of the body mass of young adult
women and men (:data:`DE_LEVA_1996`).  The trunk is split into upper (UPT), middle (MPT) and
lower (LPT) parts; OpenSim's ``pelvis`` is the lower trunk, its ``torso`` the rest with the head
(and the arms, in models without arm bodies, such as gait2392 and gait10dof18musc).

A segment's plausible range is ``[(1 - ALLOWANCE) min(F, M), (1 + ALLOWANCE) max(F, M)]`` of the
body mass (:func:`body_mass`: the model's, or for a model of part of the body what its segments
imply), ``F, M`` the two sexes' means: the allowance (:data:`ALLOWANCE`, 30 %) covers
individual build and the spread between the published tables (Dempster's cadaver data after
Winter: foot 1.45 %, thigh 10.0 %, shank 4.65 % of the body mass, against de Leva's 1.37 %,
14.16 %, 4.33 % for men).

Bodies are matched to segments by name (:func:`body_segments`: ``femur``/``thigh`` -> thigh,
``tibia``/``shank`` -> shank, ``talus``/``calcn``/``toes``/``foot`` -> foot, ``humerus`` -> upper
arm, ``ulna``/``radius`` -> forearm, ``hand``, ``pelvis`` -> lower trunk, ``torso``/``hat`` ->
head and upper and middle trunk, ...); a body named after several (``r_ulna_radius_hand``,
``forearm_hand``) is their sum, and the bodies of one side that share a segment (``talus_r``,
``calcn_r``, ``toes_r``) share its range in proportion to their masses in the model.  A body of
no known segment gets no range.  The check (:func:`mass_plausibility`) flags a fitted mass outside the range widened to
include the model's own mass within the same allowance -- a model whose author chose a heavier
foot than the table (OpenSim's gait models: about 2.1 % of the body mass) is a reference too,
not an error; a fit that moves a segment well beyond both is.
"""
from __future__ import annotations

import re

import numpy as np
import pinocchio as pin

from ..skeleton import skeleton_constant

__all__ = ["DE_LEVA_1996", "ALLOWANCE", "body_mass", "body_segments", "mass_range", "mass_plausibility"]

#: de Leva (1996) Table 4: segment mass in % of body mass, (female, male)
DE_LEVA_1996 = {
    "head": (6.68, 6.94),
    "upper_trunk": (15.45, 15.96),
    "middle_trunk": (14.65, 16.33),
    "lower_trunk": (12.47, 11.17),
    "upper_arm": (2.55, 2.71),
    "forearm": (1.38, 1.62),
    "hand": (0.56, 0.61),
    "thigh": (14.78, 14.16),
    "shank": (4.81, 4.33),
    "foot": (1.29, 1.37),
}
#: relative allowance around the two sexes' means (see the module notes)
ALLOWANCE = 0.30

_ARM = ("upper_arm", "forearm", "hand")
_PATTERNS = (
    ("head", r"head|neck|skull|cranium"),
    ("torso", r"torso|trunk|thorax|chest|hat|abdomen|lumbar|spine|back|clavicle|scapula"),
    ("lower_trunk", r"pelvis|sacrum|hips?"),
    ("thigh", r"femur|thigh"),
    ("shank", r"tibia|fibula|shank|patella|calf"),
    ("foot", r"talus|calcn|calcaneus|foot|feet|toes?|heel|midfoot|forefoot"),
    ("upper_arm", r"humerus|upper_?arm|uparm"),
    ("forearm", r"ulna|radius|forearm|lower_?arm"),
    ("hand", r"hand|palm|wrist|finger|carpals?|lunate|scaphoid|capitate|pisiform"),
)


def _tokens(name: str) -> list[str]:
    return [t for t in re.split(r"[^a-z]+", name.lower()) if t]


def _side(name: str) -> str:
    """``"r"``, ``"l"`` or ``""``: the side a body name carries as a token (``femur_r``, ``r_humerus``)."""
    toks = _tokens(name)
    return next((s for s in ("r", "l") if s in toks), "")


def _named(model, joint: int) -> tuple[str, ...]:
    """The body frames on ``joint`` (from one pass over the skeleton's frames, kept per skeleton)."""
    return skeleton_constant(model.pin, "anthropometry_bodies", _bodies_by_joint).get(joint, ())


def _bodies_by_joint(pm) -> dict[int, tuple[str, ...]]:
    out: dict[int, list[str]] = {}
    for f in pm.frames:
        if f.type == pin.FrameType.BODY:
            out.setdefault(int(f.parentJoint), []).append(f.name)
    return {j: tuple(v) for j, v in out.items()}


def _raw_segments(names) -> set[str]:
    out = set()
    for name in names:
        toks = _tokens(name)
        for seg, pat in _PATTERNS:
            if any(re.fullmatch(pat, t) for t in toks):
                out.add(seg)
    return out


def _all_raw(model) -> dict[int, frozenset[str]]:
    """Each massive joint's table segments by its body names (kept per skeleton: asked per body and fit)."""
    return skeleton_constant(model.pin, "anthropometry_segments", lambda pm: {
        j: frozenset(_raw_segments(_named(model, j))) for j in range(1, pm.njoints) if pm.inertias[j].mass > 0})


def body_segments(model, joint: int) -> tuple[str, ...]:
    """The table segments (keys of :data:`DE_LEVA_1996`) whose mass the body(ies) of ``joint`` carry."""
    raw = _all_raw(model)
    segs = raw.get(joint, set())
    every = set().union(*raw.values()) if raw else set()
    out = set(segs - {"torso"})
    if "torso" in segs:
        out |= {"upper_trunk", "middle_trunk"}
        if "head" not in every:
            out.add("head")
        if "lower_trunk" not in every:
            out.add("lower_trunk")                 # gait2d's HAT: head, arms and the whole trunk
        for s in _ARM:
            if s not in every:
                out.add(s)
    return tuple(sorted(out))


def _group(model, joint: int) -> list[int]:
    """The joints of the same side whose bodies carry the same segments (talus, calcn and toes)."""
    pm = model.pin
    segs = body_segments(model, joint)
    side = {_side(n) for n in _named(model, joint)}
    out = []
    for j in range(1, pm.njoints):
        if pm.inertias[j].mass <= 0:
            continue
        if body_segments(model, j) == segs and {_side(n) for n in _named(model, j)} == side:
            out.append(j)
    return out


def _mean_fraction(segs) -> float:
    return sum(sum(DE_LEVA_1996[s]) / 2 for s in segs) / 100


def body_mass(model) -> float:
    """The subject's body mass (kg) the table's fractions refer to: ``model.meta["body_mass"]`` when
    given; the model's mass for a whole body (trunk, thighs and shanks); else, for a part of the body
    (an arm, a forearm), the median over its bodies of the mass each implies through its table share
    (the model's segments then sit at the table's means, and a fit is judged by its change)."""
    given = model.meta.get("body_mass") if hasattr(model, "meta") else None
    if given:
        return float(given)
    pm = model.pin
    segs = {j: body_segments(model, j) for j in range(1, pm.njoints) if pm.inertias[j].mass > 0}
    every = set().union(*segs.values()) if segs else set()
    if {"thigh", "shank"} <= every and every & {"lower_trunk", "middle_trunk"}:
        return float(model.mass)
    est = []
    for j, sg in segs.items():
        if sg:
            share = pm.inertias[j].mass / sum(pm.inertias[k].mass for k in _group(model, j))
            est.append(pm.inertias[j].mass / share / _mean_fraction(sg))
    return float(np.median(est)) if est else float(model.mass)


def mass_range(model, joint: int) -> tuple[float, float, str] | None:
    """Plausible mass ``(low, high)`` in kg of the body(ies) of ``joint`` and a description, or None.

    The segments' ranges (:data:`DE_LEVA_1996` with :data:`ALLOWANCE`) times the model's body mass,
    shared among the joints of the same segments and side in proportion to their masses."""
    segs = body_segments(model, joint)
    if not segs:
        return None
    arms = sum(1 for s in segs if s in _ARM and "upper_trunk" in segs)
    lo = hi = 0.0
    for s in segs:
        f, m = DE_LEVA_1996[s]
        k = 2.0 if s in _ARM and "upper_trunk" in segs else 1.0          # both arms in a HAT / torso
        lo += k * (1 - ALLOWANCE) * min(f, m)
        hi += k * (1 + ALLOWANCE) * max(f, m)
    pm = model.pin
    group = _group(model, joint)
    share = pm.inertias[joint].mass / sum(pm.inertias[j].mass for j in group)
    body = body_mass(model)
    what = " + ".join(s.replace("_", " ") for s in segs) + (" (with both arms)" if arms else "")
    if share < 1.0:
        what += f"; this body's {100 * share:.0f} % share of it in the model"
    return share * lo / 100 * body, share * hi / 100 * body, what


def mass_plausibility(model, joint: int, new_mass: float, label: str) -> list[str]:
    """Flags (empty when plausible) for the body(ies) of ``joint`` getting ``new_mass`` kg: outside
    de Leva's range widened to the model's own mass +- :data:`ALLOWANCE`."""
    rng = mass_range(model, joint)
    if rng is None:
        return []
    lo, hi, what = rng
    old = float(model.pin.inertias[joint].mass)
    # the model's own mass counts as plausible too, with the same allowance (its author's table)
    lo, hi = min(lo, (1 - ALLOWANCE) * old), max(hi, (1 + ALLOWANCE) * old)
    if lo <= new_mass <= hi:
        return []
    body = body_mass(model)
    return [f"{label} gives {new_mass:.4g} kg ({100 * new_mass / body:.3g} % of the body mass), outside the "
            f"plausible {lo:.3g}-{hi:.3g} kg for {what} (de Leva 1996, +-{100 * ALLOWANCE:.0f} %): "
            "implausible as a segment mass"]
