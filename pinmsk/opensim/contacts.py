"""The contact import hook of an OpenSim model: :func:`contact_hook`.

Each ``SmoothSphereHalfSpaceForce`` becomes a
:class:`~pinmsk.contact.SmoothSphereHalfSpaceForce` and each sphere-half-space pair of a
``HuntCrossleyForce`` a :class:`~pinmsk.contact.HuntCrossleyForce`: Simbody's laws exactly, with
the force's properties under OpenSim's names (OpenSim's defaults for those the file leaves out).

Geometry.  The ``ContactSphere`` becomes a Pinocchio frame (``OP_FRAME``) on its body, named
after the sphere (``heel_r``; ``heel_r_sphere`` where a body, joint or marker has that name or a
second force of the same type uses the sphere), placed where OpenSim places it (the offset frames of its ``socket_frame``, then its
``location`` and ``orientation``); the component is fixed to that frame with its centre at the
origin.  The ``ContactHalfSpace`` must be fixed in the world (to the ground, or to a body welded to it,
as Walker's Platform): its outward normal is ``-x`` of its frame and its surface passes through its
origin.  The frames are added to the skeleton's
Pinocchio model (the hook's one side effect; the written URDF holds the skeleton only).

A HuntCrossleyForce's sphere against a half space on a body that moves (ToyLanding's platform), and
its spheres against spheres of other bodies (SoccerKick's ball against the foot), become
:class:`~pinmsk.effects.HuntCrossleyPair` forces between the two geometries' frames (each geometry a
frame of its own, placed and turned as OpenSim places it); every pair of geometries on different
bodies is one, as Simbody's contact tracker pairs them.

The report gets one entry per component (what became what, the sphere, its body and the half
space) and names what is not imported: a force on a geometry pinmsk has no law for
(``ContactMesh``, ``ContactEllipsoid``, ...), a HuntCrossleyForce whose surfaces have different
stiffness (Simbody then moves the contact point off the midway plane), an ``ElasticFoundationForce``
with a mesh (an ElasticFoundationForce between spheres and half spaces gets a note: Simbody applies
no force there).
Properties OpenSim does not read (the Moco model's ``derivative_smoothing``, an older name) get a
note, and are ignored as OpenSim ignores them.
"""
from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin

from ..contact import HuntCrossleyForce, SmoothSphereHalfSpaceForce
from ..effects import HuntCrossleyPair
from ..errors import ModelError
from ..io.osim import ContactForce, ContactGeometry, OsimDocument
from .hooks import HookResult
from .report import EXACT, NOT_IMPORTED, NOTE, ReportEntry
from .skeleton import Skeleton, _chain, _offset

__all__ = ["contact_hook", "SMOOTH_PROPERTIES", "HUNT_CROSSLEY_PROPERTIES"]

#: The SmoothSphereHalfSpaceForce properties that are the component's parameters (OpenSim's names).
SMOOTH_PROPERTIES = ("stiffness", "dissipation", "static_friction", "dynamic_friction", "viscous_friction",
                     "transition_velocity", "constant_contact_force", "hertz_smoothing", "hunt_crossley_smoothing")
#: A HuntCrossleyForce::ContactParameters' material properties (OpenSim's defaults: 0).
HUNT_CROSSLEY_PROPERTIES = ("stiffness", "dissipation", "static_friction", "dynamic_friction", "viscous_friction")
#: Properties that change no force (sockets, display) or are handled apart (appliesForce).
_NO_FORCE = {"socket_sphere", "socket_half_space", "sphere", "half_space", "force_visualization_radius",
             "force_visualization_scale_factor", "appliesForce", "isDisabled", "contact_parameters"}
_LAWS = ("SmoothSphereHalfSpaceForce", "HuntCrossleyForce")


def contact_hook(doc: OsimDocument, skeleton: Skeleton) -> HookResult:
    """``hook(doc, skeleton) -> HookResult``: the model's contact forces as contact components (see
    the module docstring); adds one frame per imported sphere to ``skeleton.pin_model``."""
    geometry = {g.name: g for g in doc.contact_geometry}
    components, entries, handled = [], [], []
    frames = _Frames(doc, skeleton)
    for force in doc.contact_forces:
        handled.append(force.where)
        if force.type not in _LAWS:
            kinds = {geometry[n].type if n in geometry else "?" for n in force.geometry}
            if force.type == "ElasticFoundationForce" and kinds <= {"ContactSphere", "ContactHalfSpace"}:
                # Simbody's ElasticFoundationForce acts on the faces of a ContactMesh only
                entries.append(ReportEntry(element=force.where, status=NOTE, became=(
                    f"no force between {', '.join(force.geometry)} (spheres and half spaces): Simbody's "
                    "ElasticFoundationForce acts only where a ContactMesh takes part, so OpenSim applies none")))
                continue
            entries.append(_not_imported(force, f"{force.type} (a contact between {', '.join(force.geometry)}): "
                                                "pinmsk has no elastic-foundation (mesh) contact"))
            continue
        if force.properties.get("appliesForce") is False or force.properties.get("isDisabled") is True:
            entries.append(ReportEntry(element=force.where, status=NOTE,
                                       became="disabled in the .osim (appliesForce false): no force, as in OpenSim"))
            continue
        try:
            made, notes = (_smooth if force.type == "SmoothSphereHalfSpaceForce" else _hunt_crossley)(
                force, geometry, frames)
        except _NotImported as why:
            entries.append(_not_imported(force, str(why)))
            continue
        for comp, text in made:
            components.append(comp)
            entries.append(ReportEntry(element=force.where, became=text, status=EXACT))
        for n in notes:             # a note, or (status, text)
            status, text = n if isinstance(n, tuple) else (NOTE, n)
            entries.append(ReportEntry(element=force.where, became=text, status=status))
    for g in doc.contact_geometry:
        if g.type not in ("ContactSphere", "ContactHalfSpace"):
            entries.append(ReportEntry(element=g.where, status=NOT_IMPORTED,
                                       became=f"{g.type}: not imported (pinmsk's contacts are spheres against "
                                              "half spaces)"))
    return HookResult(components=tuple(components), entries=tuple(entries), handled=tuple(handled))


class _NotImported(Exception):
    """Why a contact force is not imported (its report entry)."""


def _not_imported(force: ContactForce, why: str) -> ReportEntry:
    return ReportEntry(element=force.where, became=f"not imported: {why}", status=NOT_IMPORTED)


def _number(force: ContactForce, props: dict, name: str, default: float, where: str | None = None) -> float:
    v = props.get(name, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise ModelError(f"{where or force.where}: <{name}> must be a finite number, got {v!r}")
    return float(v)


def _unread(force: ContactForce, props: dict, known) -> list[str]:
    """A note naming the properties OpenSim does not read (it ignores unknown XML elements)."""
    extra = sorted(k for k in props if k not in known and k not in _NO_FORCE)
    if not extra:
        return []
    text = (f"<{'>, <'.join(extra)}> {'is' if len(extra) == 1 else 'are'} not read by OpenSim's {force.type}: "
            "ignored, as OpenSim ignores unknown properties")
    missing = [k for k in known if k not in props]
    if missing:
        text += f" (its defaults apply: {', '.join(f'{k} = {_default(force.type, k):g}' for k in missing)})"
    return [text]


def _default(force_type: str, name: str) -> float:
    cls = SmoothSphereHalfSpaceForce if force_type == "SmoothSphereHalfSpaceForce" else HuntCrossleyForce
    if force_type == "HuntCrossleyForce" and name in HUNT_CROSSLEY_PROPERTIES:
        return 0.0                                    # ContactParameters' defaults
    return next(p.value for p in cls.parameters if p.name == name)


def _geometry(force: ContactForce, geometry: dict, name: str) -> ContactGeometry:
    g = geometry.get(name)
    if g is None:
        raise _NotImported(f"its contact geometry '{name}' is not in the ContactGeometrySet")
    return g


def _smooth(force: ContactForce, geometry: dict, frames: "_Frames"):
    if len(force.geometry) != 2 or not all(force.geometry):
        raise ModelError(f"{force.where}: names no sphere and half space (<socket_sphere>, <socket_half_space>)")
    sphere, half = (_geometry(force, geometry, n) for n in force.geometry)
    for g, want in ((sphere, "ContactSphere"), (half, "ContactHalfSpace")):
        if g.type != want:
            raise _NotImported(f"its {'sphere' if want == 'ContactSphere' else 'half space'} '{g.name}' is a "
                               f"{g.type}, not a {want}")
    props = force.properties
    values = {k: _number(force, props, k, _default(force.type, k)) for k in SMOOTH_PROPERTIES}
    plane = frames.half_space(half)
    comp, text = frames.component(SmoothSphereHalfSpaceForce, force, sphere, half, plane, values)
    return [(comp, text)], _unread(force, props, SMOOTH_PROPERTIES)


def _hunt_crossley(force: ContactForce, geometry: dict, frames: "_Frames"):
    material: dict[str, dict] = {}
    for params in force.properties.get("contact_parameters", ()):
        values = {k: _number(force, params, k, 0.0, f"{force.where} <ContactParameters>")
                  for k in HUNT_CROSSLEY_PROPERTIES}
        for name in str(params.get("geometry", "")).split():
            if name in material:
                raise _NotImported(f"geometry '{name}' is listed in two ContactParameters (Simbody makes it two "
                                   "contact surfaces)")
            material[name] = values
    geoms = [_geometry(force, geometry, n) for n in material]
    spheres = [g for g in geoms if g.type == "ContactSphere"]
    halves = [g for g in geoms if g.type == "ContactHalfSpace"]
    others = [g for g in geoms if g not in spheres and g not in halves]
    body = {g.name: frames.doc.frame_body(g.frame)[0].name for g in spheres + halves}
    pairs = [(s, h) for h in halves for s in spheres if body[s.name] != body[h.name]]
    pairs += [(a, b) for i, a in enumerate(spheres) for b in spheres[i + 1:] if body[a.name] != body[b.name]]
    uses = {g.name: sum(g in pr for pr in pairs) for g in spheres + halves}
    # the sphere in fewer pairs acts as frame 1 (a ball against a foot's spheres: the foot's name each pair)
    pairs = [(b, a) if b.type == "ContactSphere" and uses[b.name] < uses[a.name] else (a, b) for a, b in pairs]
    if not pairs:
        raise _NotImported(f"it has {len(spheres)} sphere(s) and {len(halves)} half space(s) on "
                           f"{len(set(body.values()))} bodies: no sphere touches a half space or a sphere of "
                           "another body")
    for a, b in pairs:                 # checked before any frame is added
        ka, kb = material[a.name]["stiffness"], material[b.name]["stiffness"]
        if ka != kb:
            raise _NotImported(f"'{a.name}' (stiffness {ka:g}) and '{b.name}' ({kb:g}) differ in stiffness: "
                               "Simbody then moves the contact point off the midway plane, which pinmsk's "
                               "Hunt-Crossley contacts do not")
    vt = _number(force, force.properties, "transition_velocity", 0.01)
    made = []
    for a, b in pairs:
        ma, mb = material[a.name], material[b.name]
        values = {"stiffness": ma["stiffness"], "dissipation": 0.5 * (ma["dissipation"] + mb["dissipation"]),
                  "transition_velocity": vt}
        for k in ("static_friction", "dynamic_friction", "viscous_friction"):
            values[k] = _combined(ma[k], mb[k])
        if b.type == "ContactHalfSpace":
            try:
                plane = frames.half_space(b)
            except _NotImported:       # a half space on a body that moves: a force between two bodies
                made.append(frames.pair(force, a, b, values))
            else:
                made.append(frames.component(HuntCrossleyForce, force, a, b, plane, values))
        else:
            made.append(frames.pair(force, a, b, values))
    notes = []
    meshes = [g for g in others if g.type == "ContactMesh"]
    if meshes:
        notes.append(f"{', '.join(repr(g.name) for g in meshes)}: Simbody's HuntCrossleyForce applies forces at "
                     "point contacts only, so it ignores a ContactMesh's contacts, as pinmsk does")
    if len(meshes) < len(others):
        notes.append((NOT_IMPORTED, "not imported: its contacts with "
                      + ", ".join(f"{g.type} {g.name!r}" for g in others if g not in meshes)
                      + " (pinmsk's Hunt-Crossley contacts are between spheres and half spaces)"))
    if len(pairs) > 1:
        notes.append(f"{len(pairs)} contact pairs in one force: where one would pull, Simbody skips the pairs "
                     "after it in its sweep order, while pinmsk gives that pair no force and keeps the others")
    if any(material[a.name] != material[b.name] for a, b in pairs):
        notes.append("its surfaces have different dissipation or friction: combined as Simbody does "
                     "(c = (c1 + c2) / 2 at equal stiffness, u = 2 u1 u2 / (u1 + u2))")
    return made, notes + _unread(force, force.properties, ("transition_velocity",))


def _combined(a: float, b: float) -> float:
    """Simbody's combination of two surfaces' friction coefficients (0 if both are 0)."""
    return 0.0 if a + b == 0.0 else 2.0 * a * b / (a + b)


class _Frames:
    """The spheres' frames added to the skeleton's Pinocchio model, and the half spaces' planes."""

    def __init__(self, doc: OsimDocument, skeleton: Skeleton):
        self.doc, self.skeleton, self.pm = doc, skeleton, skeleton.pin_model
        self.labels: set[str] = set()

    def half_space(self, g: ContactGeometry):
        body, chain = self.doc.frame_body(g.frame)
        T = _chain(chain) @ _offset(g.location, g.orientation)
        if body is not self.doc.ground:
            # a body welded to the ground (Walker's Platform): a fixed place in the world
            pm = self.pm
            if not pm.existFrame(body.name, pin.FrameType.BODY):
                raise ModelError(f"{self.doc.source}: body '{body.name}' has no frame in the skeleton")
            bf = pm.frames[pm.getFrameId(body.name, pin.FrameType.BODY)]
            if bf.parentJoint != 0:
                raise _NotImported(f"its half space '{g.name}' is fixed to body '{body.name}', which moves; "
                                   "pinmsk's half spaces are fixed in the world")
            T = bf.placement.homogeneous @ T
        return tuple(-T[:3, 0]), tuple(T[:3, 3])

    def component(self, cls, force: ContactForce, sphere: ContactGeometry, half: ContactGeometry, plane, values):
        body, chain = self.doc.frame_body(sphere.frame)
        if body is self.doc.ground:
            raise _NotImported(f"its sphere '{sphere.name}' is fixed to the ground; pinmsk's spheres are on bodies")
        if sphere.radius is None:
            raise ModelError(f"{sphere.where}: a ContactSphere needs a <radius>")
        T = _chain(chain) @ _offset(sphere.location, sphere.orientation)
        name = self._frame(sphere.name, body.name, T, cls.family)
        normal, point = plane
        try:
            comp = cls(name, plane_normal=normal, plane_point=point, radius=sphere.radius, **values)
        except ModelError as exc:
            raise ModelError(f"{force.where}: {exc}") from None
        self.labels.add(comp.label)
        p = T[:3, 3]
        text = (f"{comp.label}: sphere '{sphere.name}' (R = {1e3 * sphere.radius:.4g} mm) on body '{body.name}' at "
                f"({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m (frame '{name}') against half space '{half.name}' (outward "
                f"normal ({normal[0]:.3g}, {normal[1]:.3g}, {normal[2]:.3g}) through ({point[0]:.3g}, {point[1]:.3g}, "
                f"{point[2]:.3g}) m); Simbody's law exactly")
        return comp, text

    def pair(self, force: ContactForce, sphere: ContactGeometry, other: ContactGeometry, values):
        """A :class:`~pinmsk.effects.HuntCrossleyPair` between ``sphere`` and ``other`` (a half space on a
        body that moves, or a sphere on another body), each on a frame of its own; the sphere on the
        ground, if any, is the second."""
        ground = self.doc.ground
        if self.doc.frame_body(sphere.frame)[0] is ground:
            sphere, other = other, sphere
        for g in (sphere, other):
            if g.type == "ContactSphere" and g.radius is None:
                raise ModelError(f"{g.where}: a ContactSphere needs a <radius>")
        family = HuntCrossleyPair.family
        f1 = self.geometry_frame(sphere, family)
        f2 = self.geometry_frame(other, family + ":other")
        kind = "sphere" if other.type == "ContactSphere" else "half_space"
        comp = HuntCrossleyPair(f1, frame2=f2, other=kind, other_radius=other.radius if kind == "sphere" else 0.0)
        comp = comp.with_params({"radius": sphere.radius, **values},
                                bounds={k: (min(v, comp.params[k].min), max(v, comp.params[k].max))
                                        for k, v in {"radius": sphere.radius, **values}.items()})
        if comp.label in self.labels:
            raise ModelError(f"{force.where}: sphere '{sphere.name}' would get two Hunt-Crossley pairs of one label")
        self.labels.add(comp.label)
        what = (f"sphere '{other.name}' (R = {1e3 * other.radius:.4g} mm)" if kind == "sphere"
                else f"half space '{other.name}'")
        return comp, (f"{comp.label}: sphere '{sphere.name}' (R = {1e3 * sphere.radius:.4g} mm, frame '{f1}') against "
                      f"{what} on body '{self.doc.frame_body(other.frame)[0].name}' (frame '{f2}'); Simbody's law "
                      "exactly")

    def geometry_frame(self, g: ContactGeometry, family: str) -> str:
        """A frame at a contact geometry's place and orientation (on the ground too)."""
        body, chain = self.doc.frame_body(g.frame)
        T = _chain(chain) @ _offset(g.location, g.orientation)
        if body is self.doc.ground:
            return self._frame(g.name, None, T, family)
        return self._frame(g.name, body.name, T, family)

    def _frame(self, name: str, body: str, T: np.ndarray, family: str) -> str:
        """The frame of a sphere (added once; reused by the hook run again on the same skeleton)."""
        pm = self.pm
        if body is None:                      # on the ground
            joint, parent, placement = 0, 0, pin.SE3(T)
        else:
            if not pm.existFrame(body, pin.FrameType.BODY):
                raise ModelError(f"{self.doc.source}: body '{body}' has no frame in the skeleton")
            parent = pm.getFrameId(body, pin.FrameType.BODY)
            bf = pm.frames[parent]
            joint, placement = bf.parentJoint, bf.placement * pin.SE3(T)
        for candidate in itertools.chain((name, f"{name}_sphere"), (f"{name}_sphere_{i}" for i in itertools.count(2))):
            if f"{family}:{candidate}" not in self.labels:
                if not pm.existFrame(candidate):
                    pm.addFrame(pin.Frame(candidate, joint, parent, placement, pin.FrameType.OP_FRAME))
                    return candidate
                f = pm.frames[pm.getFrameId(candidate)]
                if f.type == pin.FrameType.OP_FRAME and f.parentJoint == joint and \
                        f.placement.isApprox(placement, 1e-14):
                    return candidate
