"""OpenSim model files (``.osim``, OpenSim 4.x and the older 3.x layout) read into frozen dataclasses.

:func:`read_osim` parses the XML (no ``opensim`` package, no physics) into an
:class:`OsimDocument`: bodies (mass, centre of mass, inertia, wrap objects,
meshes), joints (type, parent and child frames, coordinates, a CustomJoint's
SpatialTransform axes with their functions), offset frames, constraints,
markers, muscles (all their properties, GeometryPath points and PathWraps),
actuators, contact geometry and contact forces, gravity and credits.

Every element keeps the file and line it came from, so later stages can name
it in an error (``subject01.osim:814: <CustomJoint name="knee_r">: ...``,
see :attr:`OsimElement.where`).  Bad input raises :class:`~pinmsk.errors.ModelError`
naming file, line and element: a file that is not XML, an unknown joint type,
an unknown function type, a missing or malformed number.

OpenSim 3.x files (joints nested inside their child ``<Body>``, ``<parent_body>``
with ``location_in_parent`` / ``orientation_in_parent``, ``<body>`` of markers
and path points, ``<CoordinateSet>``) are read into the same 4.x structure:
the 3.x joint placements become the joint's parent and child offset frames, as
OpenSim's own updater does.  OpenSim's renamed types (``MusclePoint`` ->
``PathPoint``, ``NaturalCubicSpline`` -> ``SimmSpline``, ...) are renamed here
the same way.
"""
from __future__ import annotations

import posixpath
import xml.parsers.expat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

from ..errors import ModelError

__all__ = [
    "OsimElement", "OsimFunction", "Coordinate", "OffsetFrame", "TransformAxis", "Joint", "Mesh",
    "WrapObject", "Body", "CoordinateCoupler", "Marker", "PathPoint", "PathWrap", "GeometryPath",
    "Muscle", "Actuator", "ContactGeometry", "ContactForce", "OtherElement", "OsimDocument",
    "read_osim", "parse_osim", "ForceSetDocument", "read_force_set", "parse_force_set", "JOINT_TYPES", "FUNCTION_TYPES", "MUSCLE_TYPES", "WRAP_TYPES",
]

#: Joint types OpenSim defines (the skeleton builder says which it can represent).
JOINT_TYPES = ("CustomJoint", "PinJoint", "SliderJoint", "WeldJoint", "UniversalJoint", "PlanarJoint",
               "GimbalJoint", "BallJoint", "FreeJoint", "EllipsoidJoint", "ScapulothoracicJoint",
               "ConstantCurvatureJoint")
#: Function types OpenSim defines (:mod:`pinmsk.opensim.functions` says which it evaluates).
FUNCTION_TYPES = ("Constant", "LinearFunction", "PolynomialFunction", "SimmSpline", "NaturalCubicSpline",
                  "PiecewiseLinearFunction", "MultiplierFunction", "GCVSpline", "PiecewiseConstantFunction",
                  "StepFunction", "Sine", "MultivariatePolynomialFunction", "ExpressionBasedFunction")
#: OpenSim's renamed types (``Object::renameType`` in RegisterTypes_osimCommon/osimSimulation).
_RENAMED = {"NaturalCubicSpline": "SimmSpline", "natCubicSpline": "SimmSpline",
            "MusclePoint": "PathPoint", "MuscleViaPoint": "ConditionalPathPoint",
            "MovingMusclePoint": "MovingPathPoint", "MuscleWrap": "PathWrap",
            "MusclePointSet": "PathPointSet", "MuscleWrapSet": "PathWrapSet", "ActuatorSet": "ForceSet"}
#: Muscle types whose parameters pinmsk maps (others with a path are kept as path forces).
MUSCLE_TYPES = ("Thelen2003Muscle", "Millard2012EquilibriumMuscle", "DeGrooteFregly2016Muscle")
WRAP_TYPES = ("WrapCylinder", "WrapSphere", "WrapEllipsoid", "WrapTorus", "WrapCylinderObst",
              "WrapSphereObst", "WrapDoubleCylinderObst")
POINT_TYPES = ("PathPoint", "ConditionalPathPoint", "MovingPathPoint")
CONTACT_GEOMETRY_TYPES = ("ContactSphere", "ContactHalfSpace", "ContactMesh", "ContactEllipsoid")
CONTACT_FORCE_TYPES = ("SmoothSphereHalfSpaceForce", "HuntCrossleyForce", "ElasticFoundationForce")
ACTUATOR_TYPES = ("CoordinateActuator", "PointActuator", "TorqueActuator", "ActivationCoordinateActuator",
                  "BodyActuator")
#: Sets and containers whose children are walked into, not parsed as elements.
_CONTAINERS = ("objects", "groups", "components")


# ---------------------------------------------------------------------------
# the XML tree, with line numbers
# ---------------------------------------------------------------------------

class _Node:
    """One XML element: tag (renamed as OpenSim renames it), attributes, text, line, children."""

    __slots__ = ("tag", "written", "attrib", "line", "children", "_text")

    def __init__(self, tag, attrib, line):
        self.tag = _RENAMED.get(tag, tag)
        self.written = tag
        self.attrib = attrib
        self.line = line
        self.children: list[_Node] = []
        self._text: list[str] = []

    @property
    def text(self) -> str:
        return "".join(self._text).strip()

    @property
    def name(self) -> str:
        return self.attrib.get("name", "")

    def child(self, tag: str) -> "_Node | None":
        for c in self.children:
            if c.tag == tag:
                return c
        return None

    def all(self, tag: str) -> list["_Node"]:
        return [c for c in self.children if c.tag == tag]


def _parse_xml(data: bytes, source: str) -> _Node:
    parser = xml.parsers.expat.ParserCreate()
    stack: list[_Node] = []
    root: list[_Node] = []

    def start(tag, attrib):
        node = _Node(tag, attrib, parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    def chars(text):
        if stack:
            stack[-1]._text.append(text)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.buffer_text = True
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        raise ModelError(f"{source}:{exc.lineno}: not a valid .osim file: the XML is malformed "
                         f"({xml.parsers.expat.ErrorString(exc.code)}, column {exc.offset + 1})") from None
    except (LookupError, UnicodeError, ValueError) as exc:     # an encoding the declaration names but Python lacks
        raise ModelError(f"{source}: not a readable .osim file ({' '.join(str(exc).split())})") from None
    if not root:
        raise ModelError(f"{source}: not a valid .osim file: no root element")
    return root[0]


# ---------------------------------------------------------------------------
# the dataclasses
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class OsimElement:
    """Where an element came from: its XML tag (``type``), ``name``, ``source`` file and ``line``."""

    type: str
    name: str
    source: str
    line: int

    @property
    def where(self) -> str:
        """``file:line: <Type name="...">``, the prefix of every message about this element."""
        return f"{self.source}:{self.line}: <{self.type} name=\"{self.name}\">"


@dataclass(frozen=True)
class OsimFunction(OsimElement):
    """An OpenSim Function (``type`` after OpenSim's renames, e.g. NaturalCubicSpline -> SimmSpline).

    ``value`` (Constant), ``coefficients`` (LinearFunction: slopes then intercept;
    PolynomialFunction: highest order first), ``x``/``y`` (splines, piecewise
    functions), ``scale`` and ``function`` (MultiplierFunction), and every other
    property as read in ``properties``.  ``written_type`` is the tag in the file.
    """

    written_type: str = ""
    value: float | None = None
    coefficients: tuple[float, ...] = ()
    x: tuple[float, ...] = ()
    y: tuple[float, ...] = ()
    scale: float = 1.0
    function: "OsimFunction | None" = None
    properties: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Coordinate(OsimElement):
    """A generalized coordinate of ``joint`` (rad or m): default, range, clamped/locked/prescribed flags."""

    joint: str = ""
    default_value: float = 0.0
    default_speed_value: float = 0.0
    range: tuple[float, float] = (-10.0, 10.0)
    clamped: bool = False
    locked: bool = False
    prescribed: bool = False
    prescribed_function: OsimFunction | None = None


@dataclass(frozen=True)
class OffsetFrame(OsimElement):
    """A PhysicalOffsetFrame: ``path`` (absolute, e.g. ``/jointset/knee_r/femur_r_offset``), its
    ``parent`` frame (absolute path), ``translation`` (m) and ``orientation`` (rad, body-fixed X-Y-Z)."""

    path: str = ""
    parent: str = ""
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TransformAxis(OsimElement):
    """One of a CustomJoint's six SpatialTransform axes (``name`` rotation1..3, translation1..3)."""

    index: int = 0
    coordinates: tuple[str, ...] = ()
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    function: OsimFunction | None = None

    @property
    def is_rotation(self) -> bool:
        return self.index < 3


@dataclass(frozen=True)
class Joint(OsimElement):
    """A joint: ``parent_frame``/``child_frame`` (absolute frame paths), its ``coordinates``, the offset
    ``frames`` it owns, and a CustomJoint's six ``spatial_transform`` axes (empty for other types)."""

    parent_frame: str = ""
    child_frame: str = ""
    coordinates: tuple[Coordinate, ...] = ()
    frames: tuple[OffsetFrame, ...] = ()
    spatial_transform: tuple[TransformAxis, ...] = ()
    reverse: bool = False
    properties: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Mesh(OsimElement):
    """Attached display geometry: a mesh file (or a shape ``type``), scale factors, its frame."""

    frame: str = ""
    mesh_file: str = ""
    scale_factors: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class WrapObject(OsimElement):
    """A wrap surface fixed in ``frame`` (absolute path): WrapCylinder (radius, length),
    WrapSphere (radius), WrapEllipsoid (dimensions), WrapTorus (inner_radius, outer_radius), placed by
    ``xyz_body_rotation`` (rad, body-fixed X-Y-Z) and ``translation``; ``quadrant`` as in the file."""

    frame: str = ""
    active: bool = True
    xyz_body_rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quadrant: str = "all"
    radius: float | None = None
    length: float | None = None
    dimensions: tuple[float, float, float] | None = None
    inner_radius: float | None = None
    outer_radius: float | None = None
    properties: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Body(OsimElement):
    """A rigid body: ``mass`` (kg), ``mass_center`` (m, body frame), ``inertia`` (Ixx Iyy Izz Ixy Ixz Iyz,
    kg m^2, about the centre of mass), with its wrap objects and meshes.  ``path`` is ``/bodyset/<name>``
    (``/ground`` for the ground)."""

    path: str = ""
    mass: float = 0.0
    mass_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[float, float, float, float, float, float] = (0.0,) * 6
    wrap_objects: tuple[WrapObject, ...] = ()
    meshes: tuple[Mesh, ...] = ()


@dataclass(frozen=True)
class CoordinateCoupler(OsimElement):
    """A CoordinateCouplerConstraint: ``dependent = scale_factor * function(independent...)``."""

    dependent: str = ""
    independent: tuple[str, ...] = ()
    function: OsimFunction | None = None
    scale_factor: float = 1.0
    enforced: bool = True


@dataclass(frozen=True)
class Marker(OsimElement):
    """A model marker at ``location`` (m) in ``frame`` (absolute path)."""

    frame: str = ""
    location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fixed: bool = False


@dataclass(frozen=True)
class PathPoint(OsimElement):
    """A point of a GeometryPath: PathPoint (``location`` in ``frame``), ConditionalPathPoint (active
    while ``coordinate`` is within ``range``) or MovingPathPoint (``x/y/z_location`` functions of the
    ``x/y/z_coordinate``)."""

    frame: str = ""
    location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    coordinate: str | None = None
    range: tuple[float, float] | None = None
    x_location: OsimFunction | None = None
    y_location: OsimFunction | None = None
    z_location: OsimFunction | None = None
    x_coordinate: str | None = None
    y_coordinate: str | None = None
    z_coordinate: str | None = None


@dataclass(frozen=True)
class PathWrap(OsimElement):
    """A path's use of a wrap object: ``wrap_object`` (name), ``method``, point ``range`` (1-based, -1 = all)."""

    wrap_object: str = ""
    method: str = "hybrid"
    range: tuple[int, int] = (-1, -1)


@dataclass(frozen=True)
class GeometryPath(OsimElement):
    """A muscle's (or path force's) points in order, and the wrap objects it may wrap over."""

    points: tuple[PathPoint, ...] = ()
    wraps: tuple[PathWrap, ...] = ()


@dataclass(frozen=True)
class Muscle(OsimElement):
    """A muscle or other path-based force: ``path`` and every property as read (``properties``: numbers,
    flags, strings; ``curves``: the curve sub-objects' properties, e.g. ``ActiveForceLengthCurve``)."""

    path: GeometryPath | None = None
    properties: dict = field(default_factory=dict, compare=False)
    curves: dict = field(default_factory=dict, compare=False)

    @property
    def is_muscle(self) -> bool:
        return self.type.endswith("Muscle") or self.type.endswith("Muscle_Deprecated")


@dataclass(frozen=True)
class Actuator(OsimElement):
    """A CoordinateActuator (``coordinate``), PointActuator or TorqueActuator (``bodies``), with all
    its properties (``optimal_force``, ``min_control``, ``point``, ``direction``, ``axis``, ...)."""

    coordinate: str | None = None
    bodies: tuple[str, ...] = ()
    properties: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class ContactGeometry(OsimElement):
    """ContactSphere (``radius``) or ContactHalfSpace (a solid filling x > 0 of its own frame, as
    Simbody's HalfSpace) at ``location``/``orientation`` (rad, body-fixed X-Y-Z) in ``frame``."""

    frame: str = ""
    location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float | None = None
    properties: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class ContactForce(OsimElement):
    """SmoothSphereHalfSpaceForce (``geometry`` = sphere, half space) or HuntCrossleyForce
    (``geometry`` = the names in its contact parameters; ``properties["contact_parameters"]`` = one dict
    per ContactParameters) with their parameters."""

    geometry: tuple[str, ...] = ()
    properties: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class OtherElement(OsimElement):
    """An element pinmsk reads but does not interpret (controllers, probes, other forces and
    constraints): kept so the importer can report it by name, never dropped silently."""

    category: str = ""
    properties: dict = field(default_factory=dict, compare=False)
    #: a force's sockets as absolute paths (``{"frame1": "/forceset/b/pelvis_offset", ...}``)
    sockets: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class OsimDocument:
    """A whole .osim file.  Sequences are tuples in file order; frames are absolute paths."""

    source: str
    name: str
    version: int
    gravity: tuple[float, float, float]
    credits: str
    publications: str
    length_units: str
    force_units: str
    ground: Body
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    frames: tuple[OffsetFrame, ...]
    constraints: tuple[CoordinateCoupler, ...]
    markers: tuple[Marker, ...]
    muscles: tuple[Muscle, ...]
    actuators: tuple[Actuator, ...]
    contact_geometry: tuple[ContactGeometry, ...]
    contact_forces: tuple[ContactForce, ...]
    other: tuple[OtherElement, ...]

    @property
    def coordinates(self) -> tuple[Coordinate, ...]:
        """Every coordinate, in joint order then each joint's own order (OpenSim's CoordinateSet order)."""
        return tuple(c for j in self.joints for c in j.coordinates)

    @property
    def wrap_objects(self) -> tuple[WrapObject, ...]:
        return tuple(w for b in (self.ground,) + self.bodies for w in b.wrap_objects)

    def body(self, name: str) -> Body:
        return _find(self.bodies + (self.ground,), name, "body", self.source)

    def joint(self, name: str) -> Joint:
        return _find(self.joints, name, "joint", self.source)

    def coordinate(self, name: str) -> Coordinate:
        return _find(self.coordinates, name, "coordinate", self.source)

    def frame_body(self, path: str) -> tuple[Body, list[OffsetFrame]]:
        """The body a frame path is fixed to, and the chain of offset frames from that body to it."""
        bodies = {b.path: b for b in self.bodies + (self.ground,)}
        frames = {f.path: f for f in self.frames}
        chain: list[OffsetFrame] = []
        p = path
        while p not in bodies:
            f = frames.get(p)
            if f is None or len(chain) > len(frames):
                raise ModelError(f"{self.source}: frame '{path}' is not a body or an offset frame of one")
            chain.insert(0, f)
            p = f.parent
        return bodies[p], chain


def _find(items, name, what, source):
    for it in items:
        if it.name == name:
            return it
    import difflib
    close = difflib.get_close_matches(name, [it.name for it in items], n=3)
    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
    raise ModelError(f"{source}: the model has no {what} '{name}'{hint}")


# ---------------------------------------------------------------------------
# value parsing
# ---------------------------------------------------------------------------

class _Reader:
    """Parses one document: values with file:line messages, frame paths, the element kinds."""

    def __init__(self, source: str, version: int):
        self.source = source
        self.version = version
        self.frames: list[OffsetFrame] = []
        self.other: list[OtherElement] = []

    # -- messages and scalars ------------------------------------------
    def error(self, node: _Node, problem: str) -> ModelError:
        return ModelError(f"{self.source}:{node.line}: <{node.tag} name=\"{node.name}\">: {problem}")

    def base(self, node: _Node, name: str | None = None) -> dict:
        return {"type": node.tag, "name": node.name if name is None else name, "source": self.source,
                "line": node.line}

    def numbers(self, owner: _Node, tag: str, n: int | None = None, default=None):
        node = owner.child(tag)
        if node is None or not node.text:
            if default is None:
                raise self.error(owner, f"has no <{tag}>")
            return default
        return self._numbers_of(node, owner, n)

    def _numbers_of(self, node: _Node, owner: _Node, n: int | None):
        text = node.text.replace(",", " ").replace("(", " ").replace(")", " ").replace("~[", " ").replace("]", " ")
        try:
            vals = tuple(float(t) for t in text.split())
        except ValueError:
            raise ModelError(f"{self.source}:{node.line}: <{owner.tag} name=\"{owner.name}\">: <{node.tag}> must "
                             f"hold numbers, got {node.text[:60]!r}") from None
        if n is not None and len(vals) != n:
            raise ModelError(f"{self.source}:{node.line}: <{owner.tag} name=\"{owner.name}\">: <{node.tag}> must "
                             f"hold {n} number{'s' if n > 1 else ''}, got {len(vals)}")
        return vals

    def number(self, owner: _Node, tag: str, default=None):
        vals = self.numbers(owner, tag, 1, default=None if default is None else (default,))
        return vals[0]

    def vec3(self, owner: _Node, tag: str, default=(0.0, 0.0, 0.0)):
        return self.numbers(owner, tag, 3, default=default)

    def flag(self, owner: _Node, tag: str, default: bool) -> bool:
        node = owner.child(tag)
        if node is None or not node.text:
            return default
        t = node.text.lower()
        if t in ("true", "1"):
            return True
        if t in ("false", "0"):
            return False
        raise ModelError(f"{self.source}:{node.line}: <{owner.tag} name=\"{owner.name}\">: <{tag}> must be "
                         f"true or false, got {node.text!r}")

    @staticmethod
    def string(owner: _Node, tag: str, default: str = "") -> str:
        node = owner.child(tag)
        return default if node is None else node.text

    def socket(self, owner: _Node, owner_path: str, *tags: str) -> str | None:
        """The absolute path a socket (first of ``tags`` present, e.g. ``socket_parent_frame``) names."""
        for tag in tags:
            node = owner.child(tag)
            if node is not None and node.text:
                return _absolute(node.text, owner_path)
        return None

    def properties(self, node: _Node, skip: Iterable[str] = ()) -> dict:
        """Every simple child as a Python value (bool, float, tuple of floats or str), sub-objects as dicts
        (a tag that repeats gives a list of them)."""
        out: dict[str, Any] = {}
        skip = set(skip)
        for c in node.children:
            if c.tag in skip:
                continue
            if c.children:
                if c.tag in ("Appearance", "FrameGeometry", "attached_geometry", "VisibleObject"):
                    continue
                value = self.properties(c)
                if c.name:
                    value = {"name": c.name, **value}
            else:
                value = _value(c.text)
            if c.tag in out:
                prev = out[c.tag]
                out[c.tag] = (prev if isinstance(prev, list) else [prev]) + [value]
            else:
                out[c.tag] = value
        return out

    # -- functions -------------------------------------------------------
    def function(self, node: _Node, owner: _Node) -> OsimFunction:
        """An OpenSim Function element (``node`` is the function itself)."""
        if node.tag not in FUNCTION_TYPES and node.tag != "SimmSpline":
            raise ModelError(f"{self.source}:{node.line}: <{owner.tag} name=\"{owner.name}\">: unknown function "
                             f"type <{node.tag}> (OpenSim functions: {', '.join(FUNCTION_TYPES)})")
        kw = self.base(node)
        written = node.written
        kind = node.tag
        if kind == "Constant":
            return OsimFunction(**kw, written_type=written, value=self.number(node, "value", 0.0))
        if kind in ("LinearFunction", "PolynomialFunction"):
            default = (1.0, 0.0) if kind == "LinearFunction" else (1.0,)
            return OsimFunction(**kw, written_type=written, coefficients=self.numbers(node, "coefficients",
                                                                                       default=default))
        if kind in ("SimmSpline", "PiecewiseLinearFunction", "GCVSpline", "PiecewiseConstantFunction"):
            x = self.numbers(node, "x", default=())
            y = self.numbers(node, "y", default=())
            if len(x) != len(y):
                raise self.error(node, f"<x> has {len(x)} values but <y> has {len(y)}")
            return OsimFunction(**kw, written_type=written, x=x, y=y,
                                properties=self.properties(node, skip=("x", "y")))
        if kind == "MultiplierFunction":
            holder = node.child("function")
            inner_nodes = [] if holder is None else [c for c in holder.children]
            if len(inner_nodes) != 1:
                raise self.error(node, "must hold exactly one function in its <function> element")
            return OsimFunction(**kw, written_type=written, scale=self.number(node, "scale", 1.0),
                                function=self.function(inner_nodes[0], node))
        return OsimFunction(**kw, written_type=written, properties=self.properties(node))

    def function_in(self, holder: _Node | None, owner: _Node) -> OsimFunction | None:
        """The function inside a wrapper element (``<x_location>``, ``<coupled_coordinates_function>``)."""
        if holder is None or not holder.children:
            return None
        if len(holder.children) != 1:
            raise self.error(owner, f"<{holder.tag}> must hold one function, it holds {len(holder.children)}")
        return self.function(holder.children[0], owner)

    # -- frames ------------------------------------------------------------
    def offset_frame(self, node: _Node, owner_path: str) -> OffsetFrame:
        path = f"{owner_path.rstrip('/')}/{node.name}"
        parent = self.socket(node, path, "socket_parent")
        if parent is None:
            raise self.error(node, "has no <socket_parent> (the frame it is offset from)")
        f = OffsetFrame(**self.base(node), path=path, parent=parent,
                        translation=self.vec3(node, "translation"), orientation=self.vec3(node, "orientation"))
        self.frames.append(f)
        return f

    def components(self, node: _Node, owner_path: str, sink: "_Sink") -> None:
        """Sub-components of a body, the ground or the model (``<components>``): frames and forces."""
        holder = node.child("components")
        if holder is None:
            return
        for c in holder.children:
            if c.tag == "PhysicalOffsetFrame":
                self.offset_frame(c, owner_path)
            else:
                sink.add(self, c, f"{owner_path.rstrip('/')}/{c.name}")

    # -- bodies ------------------------------------------------------------
    def body(self, node: _Node, path: str, ground: bool = False) -> Body:
        if ground:
            mass, com, inertia = 0.0, (0.0, 0.0, 0.0), (0.0,) * 6
        else:
            mass_node = node.child("mass")
            if mass_node is None or not mass_node.text:
                raise self.error(node, "has no <mass>")
            mass = self.number(node, "mass")
            com = self.vec3(node, "mass_center")
            if node.child("inertia") is not None:
                inertia = self.numbers(node, "inertia", 6)
            else:   # 3.x: six scalars
                inertia = tuple(self.number(node, f"inertia_{k}", 0.0) for k in ("xx", "yy", "zz", "xy", "xz", "yz"))
            if not mass >= 0.0:
                raise self.error(node, f"mass must be >= 0 kg, got {mass}")
        wraps = []
        ws = node.child("WrapObjectSet")
        for w in _objects(ws):
            wraps.append(self.wrap_object(w, path))
        meshes = []
        for holder in (node.child("attached_geometry"), ):
            for g in [] if holder is None else holder.children:
                meshes.append(Mesh(**self.base(g), frame=path, mesh_file=self.string(g, "mesh_file"),
                                   scale_factors=self.vec3(g, "scale_factors", (1.0, 1.0, 1.0))))
        vis = node.child("VisibleObject")    # 3.x display geometry
        if vis is not None:
            for g in _objects(vis.child("GeometrySet")):
                meshes.append(Mesh(**self.base(g), frame=path, mesh_file=self.string(g, "geometry_file"),
                                   scale_factors=self.vec3(g, "scale_factors", (1.0, 1.0, 1.0))))
            files = self.string(vis, "geometry_files")
            for f in files.split():
                meshes.append(Mesh(type="Mesh", name=f, source=self.source, line=vis.line, frame=path, mesh_file=f))
        return Body(**self.base(node), path=path, mass=mass, mass_center=com, inertia=inertia,
                    wrap_objects=tuple(wraps), meshes=tuple(meshes))

    def wrap_object(self, node: _Node, body_path: str) -> WrapObject:
        if node.tag not in WRAP_TYPES:
            raise self.error(node, f"unknown wrap object type (OpenSim's: {', '.join(WRAP_TYPES)})")

        def opt(tag):
            return self.number(node, tag) if node.child(tag) is not None and node.child(tag).text else None

        dims = self.numbers(node, "dimensions", 3) if node.child("dimensions") is not None else None
        return WrapObject(**self.base(node), frame=body_path, active=self.flag(node, "active", True),
                          xyz_body_rotation=self.vec3(node, "xyz_body_rotation"),
                          translation=self.vec3(node, "translation"),
                          quadrant=self.string(node, "quadrant", "all") or "all",
                          radius=opt("radius"), length=opt("length"), dimensions=dims,
                          inner_radius=opt("inner_radius"), outer_radius=opt("outer_radius"),
                          properties=self.properties(node))

    # -- joints ------------------------------------------------------------
    def coordinate(self, node: _Node, joint: str) -> Coordinate:
        rng = self.numbers(node, "range", 2, default=(-10.0, 10.0))
        presc = self.function_in(node.child("prescribed_function"), node)
        return Coordinate(**self.base(node), joint=joint, default_value=self.number(node, "default_value", 0.0),
                          default_speed_value=self.number(node, "default_speed_value", 0.0),
                          range=(rng[0], rng[1]), clamped=self.flag(node, "clamped", False),
                          locked=self.flag(node, "locked", False), prescribed=self.flag(node, "prescribed", False),
                          prescribed_function=presc)

    def transform_axis(self, node: _Node, index: int) -> TransformAxis:
        coords = tuple(self.string(node, "coordinates").split())
        fn = None
        for c in node.children:
            if c.tag in ("coordinates", "axis", "is_rotation", "coordinate"):
                continue
            if c.tag == "function":    # 3.x wrapper
                fn = self.function_in(c, node)
            else:
                fn = self.function(c, node)
        if node.child("coordinate") is not None and not coords:   # very old single-coordinate form
            coords = tuple(self.string(node, "coordinate").split())
        return TransformAxis(**self.base(node), index=index, coordinates=coords,
                             axis=self.vec3(node, "axis", (1.0, 0.0, 0.0)), function=fn)

    def spatial_transform(self, node: _Node) -> tuple[TransformAxis, ...]:
        st = node.child("SpatialTransform")
        if st is None:
            raise self.error(node, "a CustomJoint needs a <SpatialTransform>")
        axes = st.all("TransformAxis")
        if len(axes) != 6:
            raise self.error(st, f"needs 6 TransformAxis elements (3 rotations, 3 translations), has {len(axes)}")
        return tuple(self.transform_axis(a, i) for i, a in enumerate(axes))

    def joint4(self, node: _Node) -> Joint:
        if node.tag not in JOINT_TYPES:
            raise self.error(node, f"unknown joint type <{node.tag}> (OpenSim joints: {', '.join(JOINT_TYPES)})")
        path = f"/jointset/{node.name}"
        frames = tuple(self.offset_frame(f, path) for f in _children_of(node.child("frames")))
        coords = tuple(self.coordinate(c, node.name) for c in _children_of(node.child("coordinates")))
        parent = self.socket(node, path, "socket_parent_frame")
        child = self.socket(node, path, "socket_child_frame")
        if parent is None or child is None:
            raise self.error(node, "needs <socket_parent_frame> and <socket_child_frame>")
        st = self.spatial_transform(node) if node.tag == "CustomJoint" else ()
        return Joint(**self.base(node), parent_frame=parent, child_frame=child, coordinates=coords, frames=frames,
                     spatial_transform=st,
                     properties=self.properties(node, skip=("frames", "coordinates", "SpatialTransform")))

    def joint3(self, node: _Node, child_body: str) -> Joint:
        """A 3.x joint nested in its child body: its placements become two offset frames, as OpenSim's
        updater makes them (``<parent>_offset``, ``<child>_offset``)."""
        if node.tag not in JOINT_TYPES:
            raise self.error(node, f"unknown joint type <{node.tag}> (OpenSim joints: {', '.join(JOINT_TYPES)})")
        path = f"/jointset/{node.name}"
        parent_body = self.string(node, "parent_body")
        if not parent_body:
            raise self.error(node, "has no <parent_body>")
        parent_path = "/ground" if parent_body == "ground" else f"/bodyset/{parent_body}"
        child_path = f"/bodyset/{child_body}"
        pf = OffsetFrame(type="PhysicalOffsetFrame", name=f"{parent_body}_offset", source=self.source, line=node.line,
                         path=f"{path}/{parent_body}_offset", parent=parent_path,
                         translation=self.vec3(node, "location_in_parent"),
                         orientation=self.vec3(node, "orientation_in_parent"))
        cf = OffsetFrame(type="PhysicalOffsetFrame", name=f"{child_body}_offset", source=self.source, line=node.line,
                         path=f"{path}/{child_body}_offset", parent=child_path,
                         translation=self.vec3(node, "location"), orientation=self.vec3(node, "orientation"))
        self.frames += [pf, cf]
        coords = tuple(self.coordinate(c, node.name) for c in _objects(node.child("CoordinateSet")))
        st = self.spatial_transform(node) if node.tag == "CustomJoint" else ()
        return Joint(**self.base(node), parent_frame=pf.path, child_frame=cf.path, coordinates=coords,
                     frames=(pf, cf), spatial_transform=st, reverse=self.flag(node, "reverse", False),
                     properties=self.properties(node, skip=("CoordinateSet", "SpatialTransform")))

    # -- markers, paths ------------------------------------------------------
    def marker(self, node: _Node) -> Marker:
        path = f"/markerset/{node.name}"
        frame = self.socket(node, path, "socket_parent_frame") or _body3(self.string(node, "body"))
        if frame is None:
            raise self.error(node, "names no frame (<socket_parent_frame>)")
        return Marker(**self.base(node), frame=frame, location=self.vec3(node, "location"),
                      fixed=self.flag(node, "fixed", False))

    def path_point(self, node: _Node, owner_path: str) -> PathPoint:
        if node.tag not in POINT_TYPES:
            raise self.error(node, f"unknown path point type (OpenSim's: {', '.join(POINT_TYPES)})")
        path = f"{owner_path}/{node.name}"
        frame = self.socket(node, path, "socket_parent_frame") or _body3(self.string(node, "body"))
        if frame is None:
            raise self.error(node, "names no frame (<socket_parent_frame>)")
        kw: dict[str, Any] = dict(frame=frame, location=self.vec3(node, "location"))
        if node.tag == "ConditionalPathPoint":
            kw["coordinate"] = _coord_name(self.socket(node, path, "socket_coordinate") or self.string(node, "coordinate"))
            if not kw["coordinate"]:
                raise self.error(node, "names no coordinate (<socket_coordinate>)")
            rng = self.numbers(node, "range", 2)
            kw["range"] = (rng[0], rng[1])
        elif node.tag == "MovingPathPoint":
            for a in "xyz":
                kw[f"{a}_location"] = self.function_in(node.child(f"{a}_location"), node)
                kw[f"{a}_coordinate"] = _coord_name(self.socket(node, path, f"socket_{a}_coordinate")
                                                    or self.string(node, f"{a}_coordinate")) or None
        return PathPoint(**self.base(node), **kw)

    def geometry_path(self, node: _Node, owner_path: str) -> GeometryPath:
        path = f"{owner_path}/{node.name or 'geometrypath'}"
        points = tuple(self.path_point(p, path) for p in _objects(node.child("PathPointSet")))
        wraps = []
        for w in _objects(node.child("PathWrapSet")):
            rng = self.numbers(w, "range", 2, default=(-1.0, -1.0))
            wraps.append(PathWrap(**self.base(w), wrap_object=self.string(w, "wrap_object"),
                                  method=self.string(w, "method", "hybrid") or "hybrid",
                                  range=(int(rng[0]), int(rng[1]))))
        return GeometryPath(**self.base(node), points=points, wraps=tuple(wraps))

    # -- forces -----------------------------------------------------------------
    def force(self, node: _Node, path: str, sink: "_Sink") -> None:
        tag = node.tag
        gp = node.child("GeometryPath")
        if gp is not None:
            curves = {c.tag: {"name": c.name, **self.properties(c)} for c in node.children
                      if c.children and c.tag.endswith("Curve")}
            props = self.properties(node, skip=("GeometryPath",) + tuple(curves))
            sink.muscles.append(Muscle(**self.base(node), path=self.geometry_path(gp, path),
                                       properties=props, curves=curves))
        elif tag in ACTUATOR_TYPES:
            props = self.properties(node)
            coord = None
            if tag in ("CoordinateActuator", "ActivationCoordinateActuator"):
                coord = _coord_name(self.socket(node, path, "socket_coordinate") or self.string(node, "coordinate"))
                if not coord:
                    raise self.error(node, "names no coordinate (<coordinate> or <socket_coordinate>)")
            bodies = tuple(b for b in (self.socket(node, path, "socket_bodyA", "socket_body") or
                                       _body3(self.string(node, "bodyA") or self.string(node, "body")),
                                       self.socket(node, path, "socket_bodyB") or _body3(self.string(node, "bodyB")))
                           if b)
            sink.actuators.append(Actuator(**self.base(node), coordinate=coord, bodies=bodies, properties=props))
        elif tag in CONTACT_FORCE_TYPES:
            props = self.properties(node)
            if tag == "SmoothSphereHalfSpaceForce":
                geo = tuple(_leaf(self.socket(node, path, t) or self.string(node, t.replace("socket_", "")))
                            for t in ("socket_sphere", "socket_half_space"))
            else:
                geo, params = [], []
                for p in _find_nodes(node, "HuntCrossleyForce::ContactParameters") + \
                        _find_nodes(node, "ElasticFoundationForce::ContactParameters"):
                    geo += self.string(p, "geometry").split()
                    params.append(self.properties(p))
                geo = tuple(dict.fromkeys(geo))
                props = {k: v for k, v in props.items() if not k.endswith("::ContactParametersSet")}
                props["contact_parameters"] = tuple(params)
            sink.contact_forces.append(ContactForce(**self.base(node), geometry=geo, properties=props))
        else:
            # the frames a force owns (a BushingForce's offset frames) and its sockets, as absolute paths
            for f in _children_of(node.child("frames")):
                if f.tag == "PhysicalOffsetFrame":
                    self.offset_frame(f, path)
            sockets = {c.tag[len("socket_"):]: self.socket(node, path, c.tag) for c in node.children
                       if c.tag.startswith("socket_") and c.text}
            sink.other.append(OtherElement(**self.base(node), category="force", sockets=sockets,
                                           properties=self.properties(node, skip=("frames",))))


class _Sink:
    """Where the model-level elements found in ForceSet, ``<components>`` and the other sets go."""

    def __init__(self):
        self.muscles: list[Muscle] = []
        self.actuators: list[Actuator] = []
        self.contact_forces: list[ContactForce] = []
        self.other: list[OtherElement] = []
        self.constraints: list[CoordinateCoupler] = []

    def add(self, reader: _Reader, node: _Node, path: str) -> None:
        if node.tag == "PhysicalOffsetFrame":
            reader.offset_frame(node, path.rsplit("/", 1)[0] or "/")
        elif node.tag in JOINT_TYPES:
            self.other.append(OtherElement(**reader.base(node), category="joint outside the JointSet"))
        elif node.child("GeometryPath") is not None or node.tag in ACTUATOR_TYPES + CONTACT_FORCE_TYPES \
                or node.tag.endswith(("Force", "Muscle", "Actuator", "Ligament")):
            reader.force(node, path, self)
        else:
            self.other.append(OtherElement(**reader.base(node), category="component",
                                           properties=reader.properties(node)))


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------

def _value(text: str):
    t = text.strip()
    low = t.lower()
    if low in ("true", "false"):
        return low == "true"
    parts = t.split()
    try:
        nums = tuple(float(p) for p in parts)
    except ValueError:
        return t
    if len(nums) == 1:
        return nums[0]
    return nums if nums else t


def _objects(set_node: _Node | None) -> list[_Node]:
    """The elements of an OpenSim Set (``<XSet><objects>...``)."""
    if set_node is None:
        return []
    objs = set_node.child("objects")
    return [] if objs is None else list(objs.children)


def _children_of(node: _Node | None) -> list[_Node]:
    return [] if node is None else list(node.children)


def _find_nodes(node: _Node, tag: str) -> list[_Node]:
    out = []
    for c in node.children:
        if c.tag == tag:
            out.append(c)
        out += _find_nodes(c, tag)
    return out


def _absolute(text: str, owner_path: str) -> str:
    """An OpenSim component path made absolute: ``/x`` as is, otherwise relative to the socket's owner."""
    t = text.strip()
    if t.startswith("/"):
        return posixpath.normpath(t)
    return posixpath.normpath(posixpath.join(owner_path, t))


def _leaf(path: str | None) -> str:
    return "" if not path else path.rstrip("/").rsplit("/", 1)[-1]


def _coord_name(path: str | None) -> str:
    """A coordinate's name from its socket path (``/jointset/knee_r/knee_angle_r`` -> ``knee_angle_r``)."""
    return _leaf(path)


def _body3(name: str) -> str | None:
    """A 3.x body name as a 4.x frame path."""
    if not name:
        return None
    return "/ground" if name == "ground" else f"/bodyset/{name}"


# ---------------------------------------------------------------------------
# the document
# ---------------------------------------------------------------------------

def read_osim(path) -> OsimDocument:
    """Read an ``.osim`` file (OpenSim 3.x or 4.x) into an :class:`OsimDocument` (ModelError if it cannot)."""
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"OpenSim model file not found: {p}")
    return parse_osim(p.read_bytes(), source=str(p))


def parse_osim(data: bytes | str, *, source: str = "<string>") -> OsimDocument:
    """Parse the text of an ``.osim`` file; ``source`` names it in messages."""
    if isinstance(data, str):
        data = data.encode("utf-8")
    root = _parse_xml(data, source)
    if root.tag == "OpenSimDocument":
        text = root.attrib.get("Version", "0") or "0"
        try:
            version = int(float(text))
        except (ValueError, OverflowError):
            raise ModelError(f"{source}:{root.line}: <OpenSimDocument Version={text!r}> is not a version number "
                             "(OpenSim 4 writes 40000)") from None
        model = root.child("Model")
    elif root.tag == "Model":
        version, model = 0, root
    else:
        raise ModelError(f"{source}:{root.line}: not an OpenSim model: the root element is <{root.tag}>, "
                         "not <OpenSimDocument> with a <Model>")
    if model is None:
        raise ModelError(f"{source}:{root.line}: <OpenSimDocument> holds no <Model>")
    plugin = _plugin_elements(model)
    if plugin:
        node, name = plugin[0]
        kinds = ", ".join(dict.fromkeys(n.written for n, _ in plugin))
        raise ModelError(f"{source}:{node.line}: <{node.written} name=\"{node.attrib.get('name', '')}\">: "
                         f"the model needs the {name} plugin ({kinds}), which OpenSim 4.x loads only with "
                         "that plugin and pinmsk does not import")
    if BETA_VERSIONS[0] <= version < BETA_VERSIONS[1]:
        try:
            return _parse_model(model, source, version)
        except ModelError as exc:
            raise ModelError(f"{source}: OpenSim 4.0-beta format (Version=\"{version}\"); open and save it in "
                             f"OpenSim 4.x ({exc})") from None
    return _parse_model(model, source, version)


#: OpenSim's document versions of the 4.0 development line (30500 <= Version < 40000): its joints and
#: paths name their frames by properties later renamed to sockets; OpenSim 4.x upgrades them when it
#: opens the file (``XMLDocument::getLatestVersion``), pinmsk reads only what the 4.x layout also holds.
BETA_VERSIONS = (30500, 40000)

#: Components that OpenSim 4.x loads only with a plugin library: type -> the plugin.
PLUGIN_TYPES = {
    "Smith2018ArticularContactForce": "opensim-jam (JAM)",
    "Smith2018ContactMesh": "opensim-jam (JAM)",
    "Blankevoort1991Ligament": "opensim-jam (JAM)",
}


def _plugin_elements(node: _Node) -> list:
    """``(element, plugin name)`` of every element (in document order) whose type needs a plugin."""
    out, stack = [], [node]
    while stack:
        n = stack.pop()
        if n.written in PLUGIN_TYPES:
            out.append((n, PLUGIN_TYPES[n.written]))
        stack.extend(reversed(n.children))
    return out


def _parse_model(model: _Node, source: str, version: int) -> OsimDocument:
    """The :class:`OsimDocument` of a document's ``<Model>`` element."""
    rd = _Reader(source, version)
    sink = _Sink()

    # ground and bodies (3.x: ground is a Body named "ground", joints are nested in their child body)
    ground_node = model.child("Ground")
    ground = rd.body(ground_node, "/ground", ground=True) if ground_node is not None else None
    if ground_node is not None:
        rd.components(ground_node, "/ground", sink)
    bodies, joints = [], []
    for b in _objects(model.child("BodySet")):
        if b.tag != "Body":
            raise rd.error(b, "the BodySet holds only <Body> elements")
        if ground is None and b.name == "ground":
            ground = rd.body(b, "/ground", ground=True)
        else:
            bodies.append(rd.body(b, f"/bodyset/{b.name}"))
            rd.components(b, f"/bodyset/{b.name}", sink)
        jholder = b.child("Joint")
        if jholder is not None:
            for j in jholder.children:
                joints.append(rd.joint3(j, b.name))
    if ground is None:
        ground = Body(type="Ground", name="ground", source=source, line=model.line, path="/ground")
    for j in _objects(model.child("JointSet")):
        joints.append(rd.joint4(j))

    # constraints
    for c in _objects(model.child("ConstraintSet")):
        if c.tag == "CoordinateCouplerConstraint":
            indep = tuple(rd.string(c, "independent_coordinate_names").split())
            dep = rd.string(c, "dependent_coordinate_name")
            fn = rd.function_in(c.child("coupled_coordinates_function"), c)
            if not indep or not dep or fn is None:
                raise rd.error(c, "needs <independent_coordinate_names>, <dependent_coordinate_name> and "
                                  "<coupled_coordinates_function>")
            enforced = rd.flag(c, "isEnforced", True) and not rd.flag(c, "isDisabled", False)
            sink.constraints.append(CoordinateCoupler(**rd.base(c), dependent=dep, independent=indep, function=fn,
                                                      scale_factor=rd.number(c, "scale_factor", 1.0),
                                                      enforced=enforced))
        else:
            sink.other.append(OtherElement(**rd.base(c), category="constraint", properties=rd.properties(c)))

    # forces: the ForceSet and the model's own components
    for f in _objects(model.child("ForceSet")):
        rd.force(f, f"/forceset/{f.name}", sink)
    rd.components(model, "", sink)
    for f in _objects(model.child("ComponentSet")):
        sink.add(rd, f, f"/componentset/{f.name}")

    markers = tuple(rd.marker(m) for m in _objects(model.child("MarkerSet")))
    contact_geometry = []
    for g in _objects(model.child("ContactGeometrySet")):
        path = f"/contactgeometryset/{g.name}"
        frame = rd.socket(g, path, "socket_frame") or _body3(rd.string(g, "body_name"))
        if frame is None:
            raise rd.error(g, "names no frame (<socket_frame>)")
        radius = rd.number(g, "radius") if g.child("radius") is not None else None
        contact_geometry.append(ContactGeometry(**rd.base(g), frame=frame, location=rd.vec3(g, "location"),
                                                orientation=rd.vec3(g, "orientation"), radius=radius,
                                                properties=rd.properties(g)))
    for setname, category in (("ControllerSet", "controller"), ("ProbeSet", "probe")):
        for c in _objects(model.child(setname)):
            sink.other.append(OtherElement(**rd.base(c), category=category))

    gravity = rd.vec3(model, "gravity", (0.0, -9.80665, 0.0))
    return OsimDocument(
        source=source, name=model.name or Path(source).stem, version=version, gravity=gravity,
        credits=rd.string(model, "credits"), publications=rd.string(model, "publications"),
        length_units=rd.string(model, "length_units", "meters") or "meters",
        force_units=rd.string(model, "force_units", "N") or "N",
        ground=ground, bodies=tuple(bodies), joints=tuple(joints), frames=tuple(rd.frames),
        constraints=tuple(sink.constraints), markers=markers, muscles=tuple(sink.muscles),
        actuators=tuple(sink.actuators), contact_geometry=tuple(contact_geometry),
        contact_forces=tuple(sink.contact_forces), other=tuple(sink.other))


# ---------------------------------------------------------------------------
# a force set file (OpenSim's ``force_set_files``: reserve and residual actuators)
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class ForceSetDocument:
    """An OpenSim ``<ForceSet>`` file (the ``force_set_files`` of OpenSim's tools): its actuators."""

    source: str
    name: str
    actuators: tuple[Actuator, ...]


def read_force_set(path) -> ForceSetDocument:
    """Read an OpenSim force set file (``<OpenSimDocument><ForceSet>``, e.g. ``*_Reserve_Actuators.xml``)."""
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"OpenSim force set file not found: {p}")
    return parse_force_set(p.read_bytes(), source=str(p))


def parse_force_set(data: bytes | str, *, source: str = "<string>") -> ForceSetDocument:
    """Parse a force set file's text; ``source`` names it in messages.  pinmsk reads its actuators
    (:data:`ACTUATOR_TYPES`); any other force in it is refused by name, never dropped."""
    if isinstance(data, str):
        data = data.encode("utf-8")
    try:
        root = _parse_xml(data, source)
    except ModelError as exc:
        raise ModelError(str(exc).replace("not a valid .osim file", "not a valid force set file")) from None
    fs = root.child("ForceSet") if root.tag == "OpenSimDocument" else root
    if fs is None or fs.tag != "ForceSet":
        inside = ", ".join(f"<{c.tag}>" for c in root.children[:3]) or "nothing"
        what = (f"<OpenSimDocument> holds {inside}" if root.tag == "OpenSimDocument"
                else f"the root element is <{root.tag}>")
        raise ModelError(f"{source}:{root.line}: not an OpenSim force set file: {what}, not a <ForceSet> "
                         "(of CoordinateActuator, PointActuator and TorqueActuator elements)")
    version = int(float(root.attrib.get("Version", "0") or 0)) if root.tag == "OpenSimDocument" else 0
    rd = _Reader(source, version)
    sink = _Sink()
    for f in _objects(fs):
        if f.tag not in ACTUATOR_TYPES:
            raise rd.error(f, f"pinmsk reads actuators ({', '.join(ACTUATOR_TYPES)}) from a force set file; "
                              "this element is not one")
        rd.force(f, f"/forceset/{f.name}", sink)
    return ForceSetDocument(source=source, name=fs.name, actuators=tuple(sink.actuators))
