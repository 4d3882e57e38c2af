"""OpenSim's ScaleTool model scaling: scale factors from marker measurements and manual scales, and the
scaled ``.osim``.

Read from OpenSim 4.x's ``ModelScaler.cpp``, ``Measurement.cpp``, ``Model::scale`` and the components'
``extendScale`` / ``scaleInertialProperties`` / ``extendPostScale``:

* **Scale factors** (:func:`scale_factors`).  Every physical frame of the model (the ground, the bodies,
  the offset frames) starts at ``1 1 1``.  The ``scaling_order`` steps are applied in turn:
  ``measurements`` -- for each applied :class:`Measurement`, the factor is the mean over its marker pairs
  of ``d_exp / d_model``, with ``d_exp`` the pair's distance averaged over the frames of the time range
  (OpenSim's ``MarkerData::findFrameRange``: from the last frame at or before the start to the first
  frame at or after the end) and ``d_model`` the distance of the two model markers in the default pose;
  the factor replaces the named axes of each :class:`BodyScale`'s body.  ``manualScale`` -- each applied
  :class:`ManualScale` replaces all three factors of its segment.
* **Geometry** (:func:`scale_model`).  A body's ``mass_center`` and the ``scale_factors`` of the geometry
  attached to any frame are multiplied by the factors of the frame's base body; an offset frame's
  ``translation``, a marker's and a path point's ``location``, and a wrap object's ``translation`` by
  those of the base body of the frame they are fixed in; a CustomJoint's translational transform axes
  (except one that is a coordinate, ``LinearFunction 1 0``) become ``MultiplierFunction``\\ s scaled by
  ``|axis| . s`` of the joint's parent body, a moving path point's location functions by ``s`` of their
  axis; wrap cylinders, spheres, ellipsoids and tori are resized along their own axes.
* **Inertia** (``Body::scaleInertialProperties``).  With equal factors ``s`` the inertia is multiplied by
  ``s^2`` (and the mass by ``s^3`` unless the mass distribution is preserved); otherwise the body is
  taken as a cylinder about its smallest principal moment and its radius and length are scaled.
* **Mass** (``Model::scale``).  With a subject mass, every body's mass and inertia are then multiplied
  by ``subject mass / model mass``: with ``preserve_mass_distribution`` this keeps every body's share.
* **Couplers.** A CoordinateCouplerConstraint whose dependent coordinate is a translation has its
  ``scale_factor`` multiplied by the (uniform) factor of the body its joint hangs from.
* **Muscles** (``extendPostScale``).  A muscle's ``optimal_fiber_length`` and ``tendon_slack_length``
  (a ligament's or path spring's ``resting_length``, a Blankevoort1991Ligament's ``slack_length``) are
  multiplied by the ratio of its path length after and before scaling, both in the default pose
  (wrapping included); a RigidTendonMuscle, UmbergerMuscle or path actuator keeps its lengths.

Only the ``.osim`` format of OpenSim 4 (``Version >= 40000``: joints with offset frames) is edited; an
older file is refused with what to do.  Everything else in the file is kept as written.
"""
from __future__ import annotations

import copy
import difflib
import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from ..errors import PinmskError
from ..io.osim import parse_osim
from ..io.output_files import atomic_write
from .paths import GeometricPaths, path_specs
from .skeleton import OsimKinematics, _motion_types

__all__ = ["ScaleError", "ScaleWarning", "BodyScale", "Measurement", "ManualScale", "MeasurementResult", "ScaleFactors",
           "read_osim_tree", "read_marker_set", "with_markers", "model_marker_positions", "default_pose", "frame_range",
           "scale_factors", "scale_model", "write_osim_tree", "write_scale_set", "total_mass",
           "measurement_from_node", "manual_scale_from_node", "SCALING_STEPS", "model_markers",
           "delete_unused_markers", "coordinate_defaults", "coordinate_paths", "rotational_coordinates", "state_coordinate", "move_markers", "write_marker_set"]

#: The steps of ``scaling_order``.
SCALING_STEPS = ("measurements", "manualScale")

_FIRST_VERSION = 40000
_AXES = {"x": 0, "y": 1, "z": 2}
_POINT_TAGS = ("PathPoint", "ConditionalPathPoint", "MovingPathPoint")
_WRAP_TAGS = ("WrapCylinder", "WrapSphere", "WrapEllipsoid", "WrapTorus", "WrapCylinderObst", "WrapDoubleCylinderObst")
#: The path forces whose lengths ``extendPostScale`` scales by the path's length ratio, and those lengths
#: (a RigidTendonMuscle, UmbergerMuscle or PathActuator keeps its own).
_MUSCLE_LENGTHS = ("optimal_fiber_length", "tendon_slack_length")
_POST_SCALED = {**{t: _MUSCLE_LENGTHS for t in (
    "Thelen2003Muscle", "Millard2012EquilibriumMuscle", "Millard2012AccelerationMuscle", "DeGrooteFregly2016Muscle",
    "MeyerFregly2016Muscle", "Thelen2003Muscle_Deprecated", "Schutte1993Muscle_Deprecated",
    "Delp1990Muscle_Deprecated")},
    "Ligament": ("resting_length",), "PathSpring": ("resting_length",),
    "ExpressionBasedPathForce": ("resting_length",), "Blankevoort1991Ligament": ("slack_length",)}
_UNSCALABLE_JOINTS = ("EllipsoidJoint", "ScapulothoracicJoint", "ConstantCurvatureJoint")


class ScaleError(PinmskError):
    """A model, marker set or scale setup that cannot be scaled as asked (named element, marker, body)."""


class ScaleWarning(UserWarning):
    """A part of a scale setup that OpenSim skips silently and pinmsk skips with this warning."""


# --------------------------------------------------------------------------------------------
# what a ScaleTool setup says
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BodyScale:
    """The axes (``"X"``, ``"Y"``, ``"Z"``) of ``body`` that a measurement's factor scales."""

    body: str
    axes: tuple = ("X", "Y", "Z")

    def __post_init__(self):
        axes = tuple(str(a) for a in self.axes)
        bad = [a for a in axes if a.lower() not in _AXES]
        if bad:
            raise ScaleError(f"body scale '{self.body}': axes {bad} are not X, Y or Z")
        object.__setattr__(self, "axes", axes)


@dataclass(frozen=True)
class Measurement:
    """One OpenSim ``<Measurement>``: marker pairs whose distance ratio scales the bodies listed."""

    name: str
    pairs: tuple
    bodies: tuple
    apply: bool = True

    def __post_init__(self):
        pairs = tuple((str(a), str(b)) for a, b in self.pairs)
        object.__setattr__(self, "pairs", pairs)
        object.__setattr__(self, "bodies", tuple(b if isinstance(b, BodyScale) else BodyScale(str(b))
                                                 for b in self.bodies))


@dataclass(frozen=True)
class ManualScale:
    """One OpenSim ``<Scale>`` of a ``<ScaleSet>``: the X, Y, Z factors of ``segment``."""

    segment: str
    factors: tuple
    apply: bool = True

    def __post_init__(self):
        f = tuple(float(x) for x in self.factors)
        if len(f) != 3:
            raise ScaleError(f"manual scale of '{self.segment}': needs 3 factors, got {len(f)}")
        object.__setattr__(self, "factors", f)


@dataclass(frozen=True)
class MeasurementResult:
    """A measurement as taken: per pair ``(marker 1, marker 2, model distance, experimental distance)`` (m)
    and the factor (the mean of the pairs' ratios)."""

    name: str
    pairs: tuple
    factor: float


@dataclass
class ScaleFactors:
    """The factors of every physical frame, in the model's order (``segments``, ``factors`` (n, 3)), and the
    measurements taken.  ``factors_of(name)`` gives a segment's factors."""

    segments: tuple
    factors: np.ndarray
    measurements: tuple = ()
    bodies: tuple = ()

    def factors_of(self, name: str) -> np.ndarray:
        for s, f in zip(self.segments, self.factors):
            if s == name:
                return f.copy()
        raise ScaleError(f"no scale factors for '{name}' (segments: {', '.join(dict.fromkeys(self.segments))})")

    def as_dict(self) -> dict:
        """``{segment: (3,) factors}`` (a segment listed twice keeps its first entry, which equals the rest)."""
        out = {}
        for s, f in zip(self.segments, self.factors):
            out.setdefault(s, f.copy())
        return out

    def summary(self) -> str:
        """The measurements as OpenSim logs them (each pair's model and experimental distance, the factor),
        then every body's factors."""
        lines = []
        for m in self.measurements:
            lines.append(f"measurement '{m.name}': factor {m.factor:.6f}")
            for a, b, d_mod, d_exp in m.pairs:
                lines.append(f"  {a} - {b}: model {d_mod:.6f} m, experimental {d_exp:.6f} m")
        table = self.as_dict()
        for b in self.bodies:
            f = table[b]
            lines.append(f"{b:>16}: {' '.join(f'{x:.6f}' for x in f)}")
        return "\n".join(lines)

    def write(self, path) -> Path:
        """Write the factors as OpenSim's ``<ScaleSet>`` file (:func:`write_scale_set`)."""
        return write_scale_set(self, path)


def measurement_from_node(node) -> Measurement:
    """A :class:`Measurement` from a ``<Measurement>`` :class:`~pinmsk.io.opensim_setup.SetupNode` (its
    unread properties refused by name)."""
    pairs = []
    for p in node.objects("MarkerPairSet", "MarkerPair"):
        names = p.words("markers")
        if len(names) != 2:
            raise p.error("markers", f"a marker pair names 2 markers, got {len(names)} ({' '.join(names) or 'none'})")
        pairs.append((names[0], names[1]))
        p.finish()
    bodies = []
    for b in node.objects("BodyScaleSet", "BodyScale"):
        axes = b.words("axes")
        for a in axes:
            if a.lower() not in _AXES:
                raise b.error("axes", f"'{a}' is not an axis (X, Y or Z)")
        bodies.append(BodyScale(b.name, tuple(axes)))
        b.finish()
    apply = node.flag("apply", True)
    node.finish()
    return Measurement(node.name, tuple(pairs), tuple(bodies), apply)


def manual_scale_from_node(node) -> ManualScale:
    """A :class:`ManualScale` from a ``<Scale>`` :class:`~pinmsk.io.opensim_setup.SetupNode`."""
    factors = node.numbers("scales", 3)
    segment = node.text("segment")
    if factors is None or segment is None:
        raise node.error("scales" if factors is None else "segment", "a manual scale needs <scales> and <segment>")
    apply = node.flag("apply", True)
    node.finish()
    return ManualScale(segment, tuple(factors), apply)


# --------------------------------------------------------------------------------------------
# the .osim as an element tree
# --------------------------------------------------------------------------------------------
#: OpenSim names some elements ``Class::Property`` (``<HuntCrossleyForce::ContactParametersSet>``), which an
#: XML parser that resolves namespaces refuses; they are renamed while in the tree.
_COLONS = b"__colons__"
_TAG_COLONS = re.compile(rb"(</?[A-Za-z_][\w.\-]*)::")


def _parse(data: bytes, source: str) -> ET.Element:
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    data = _TAG_COLONS.sub(lambda m: m.group(1) + _COLONS, data)
    try:
        parser.feed(data)
        return parser.close()
    except ET.ParseError as exc:
        raise ScaleError(f"{source}: not a valid XML file ({exc})") from None


def read_osim_tree(path) -> ET.Element:
    """The ``<OpenSimDocument>`` of an OpenSim 4 ``.osim`` file as an element tree (comments kept)."""
    p = Path(path)
    if not p.exists():
        raise ScaleError(f"model file '{path}' not found (resolved to {p.resolve()})")
    root = _parse(p.read_bytes(), str(p))
    _model(root, str(p))
    root.set("__source__", str(p))
    return root


def _source(root: ET.Element) -> str:
    return root.get("__source__", "<model>")


def _model(root: ET.Element, source: str | None = None) -> ET.Element:
    source = source or _source(root)
    if root.tag != "OpenSimDocument" or root.find("Model") is None:
        raise ScaleError(f"{source}: not an OpenSim model (no <OpenSimDocument><Model>)")
    try:
        version = int(root.get("Version", "0"))
    except ValueError:
        version = 0
    if version < _FIRST_VERSION:
        raise ScaleError(f"{source}: an OpenSim {version} model file; scaling edits the OpenSim 4 format "
                         f"(Version >= {_FIRST_VERSION}): open and save it once with OpenSim 4 first")
    return root.find("Model")


def _to_bytes(root: ET.Element) -> bytes:
    r = copy.copy(root)
    r.attrib = {k: v for k, v in root.attrib.items() if k != "__source__"}
    body = ET.tostring(r, encoding="unicode").replace(_COLONS.decode(), "::")
    return ('<?xml version="1.0" encoding="UTF-8" ?>\n' + body + "\n").encode("utf-8")


def _doc(root: ET.Element):
    return parse_osim(_to_bytes(root), source=_source(root))


def write_osim_tree(root: ET.Element, path) -> Path:
    """Write the tree as an ``.osim`` file (atomically)."""
    data = _to_bytes(root)
    return atomic_write(path, lambda fh: fh.write(data), binary=True)


def _fmt(x: float) -> str:
    x = float(x)
    return "0" if x == 0 else format(x, ".17g")


def _vec_text(v) -> str:
    return " ".join(_fmt(x) for x in v)


def _numbers(el: ET.Element | None, where: str, n: int | None = None) -> np.ndarray:
    if el is None:
        raise ScaleError(f"{where}: missing")
    try:
        v = np.array([float(w) for w in (el.text or "").split()], dtype=float)
    except ValueError:
        raise ScaleError(f"{where}: '{(el.text or '').strip()}' is not a list of numbers") from None
    if n is not None and v.size != n:
        raise ScaleError(f"{where}: needs {n} numbers, got {v.size}")
    return v


def _set_numbers(el: ET.Element, values) -> None:
    el.text = _vec_text(np.atleast_1d(values))


class _Index:
    """Component paths of a model tree (``/bodyset/pelvis``, ``/jointset/hip_r/pelvis_offset``) and the
    base body of every frame."""

    def __init__(self, model: ET.Element, source: str):
        self.source = source
        self.by_path: dict[str, ET.Element] = {}
        self.path_of: dict[int, str] = {}
        self.parent: dict[int, ET.Element] = {}
        self._walk(model, "")

    def _walk(self, el: ET.Element, path: str) -> None:
        for c in el:
            if not isinstance(c.tag, str):
                continue
            self.parent[id(c)] = el
            name = c.get("name")
            p = f"{path}/{name}" if name else path
            if name:
                self.by_path.setdefault(p, c)
                self.path_of[id(c)] = p
            self._walk(c, p)

    def owner_path(self, el: ET.Element) -> str:
        """The path of the nearest named component that holds ``el`` (``el`` itself when named)."""
        e = el
        while e is not None:
            if id(e) in self.path_of:
                return self.path_of[id(e)]
            e = self.parent.get(id(e))
        return ""

    def owner(self, el: ET.Element, tags: Sequence[str]) -> ET.Element | None:
        """The nearest enclosing element with one of ``tags``."""
        e = self.parent.get(id(el))
        while e is not None:
            if e.tag in tags:
                return e
            e = self.parent.get(id(e))
        return None

    def resolve(self, text: str, owner: ET.Element) -> ET.Element:
        """The component a socket's path names, relative to ``owner``'s path unless absolute."""
        t = (text or "").strip()
        if not t:
            raise ScaleError(f"{self.source}: {self.owner_path(owner) or owner.tag}: empty frame path")
        if t.startswith("/"):
            parts = []
        else:
            parts = [p for p in self.owner_path(owner).split("/") if p]
        for seg in t.split("/"):
            if seg in ("", "."):
                continue
            if seg == "..":
                if parts:
                    parts.pop()
                continue
            parts.append(seg)
        p = "/" + "/".join(parts)
        el = self.by_path.get(p)
        if el is None:
            close = difflib.get_close_matches(p, list(self.by_path), n=1)
            raise ScaleError(f"{self.source}: {self.owner_path(owner) or owner.tag}: no component '{t}' "
                             f"(resolved to {p})" + (f"; did you mean '{close[0]}'?" if close else ""))
        return el

    def base_body(self, frame: ET.Element) -> str:
        """The base body (or ground) of a frame: an offset frame's chain followed to its body."""
        seen = 0
        while frame.tag not in ("Body", "Ground"):
            if frame.tag != "PhysicalOffsetFrame" and frame.find("socket_parent") is None:
                raise ScaleError(f"{self.source}: {self.owner_path(frame)}: <{frame.tag}> is not a body or an "
                                 "offset frame; its scale factors are unknown")
            frame = self.resolve(frame.findtext("socket_parent", ""), frame)
            seen += 1
            if seen > 100:
                raise ScaleError(f"{self.source}: offset frames form a loop at {self.owner_path(frame)}")
        return frame.get("name", "")


def _physical_frames(model: ET.Element) -> list[ET.Element]:
    """The physical frames in OpenSim's component order: the ground, the bodies, then the offset frames."""
    out = [model.find("Ground")] if model.find("Ground") is not None else []
    out += [b for b in model.iterfind("BodySet/objects/Body")]
    out += [f for f in model.iter("PhysicalOffsetFrame")]
    return out


def total_mass(root: ET.Element) -> float:
    """The sum of the bodies' masses (kg)."""
    model = _model(root)
    return float(sum(float(b.findtext("mass", "0")) for b in model.iterfind("BodySet/objects/Body")))


# --------------------------------------------------------------------------------------------
# markers
# --------------------------------------------------------------------------------------------
def read_marker_set(path) -> list[ET.Element]:
    """The ``<Marker>`` elements of an OpenSim marker set file, in the OpenSim 4 form (``socket_parent_frame``,
    ``location``, ``fixed``); the older ``<body>`` form is converted as OpenSim converts it."""
    p = Path(path)
    if not p.exists():
        raise ScaleError(f"marker set file '{path}' not found (resolved to {p.resolve()})")
    root = _parse(p.read_bytes(), str(p))
    ms = root if root.tag == "MarkerSet" else root.find("MarkerSet")
    if ms is None:
        raise ScaleError(f"{p}: no <MarkerSet>")
    out = []
    for k, m in enumerate(ms.iterfind("objects/Marker")):
        name = m.get("name")
        if not name:
            raise ScaleError(f"{p}: marker {k + 1} has no name")
        frame = (m.findtext("socket_parent_frame") or "").strip()
        if not frame:
            body = (m.findtext("body") or "").strip()
            if not body:
                raise ScaleError(f"{p}: marker '{name}' names no body (<socket_parent_frame> or <body>)")
            frame = "/ground" if body == "ground" else f"/bodyset/{body}"
        loc = _numbers(m.find("location"), f"{p}: marker '{name}' <location>", 3)
        fixed = (m.findtext("fixed") or "false").strip().lower() in ("true", "1")
        e = ET.Element("Marker", {"name": name})
        ET.SubElement(e, "socket_parent_frame").text = frame
        ET.SubElement(e, "location").text = _vec_text(loc)
        ET.SubElement(e, "fixed").text = "true" if fixed else "false"
        out.append(e)
    return out


def with_markers(root: ET.Element, markers: Iterable[ET.Element]) -> ET.Element:
    """A copy of the model tree with ``markers`` merged into its marker set as ``Model::updateMarkerSet``
    merges them: a marker of the same name is removed, and each new marker is appended."""
    new = copy.deepcopy(root)
    model = _model(new)
    ms = model.find("MarkerSet")
    if ms is None:
        ms = ET.SubElement(model, "MarkerSet", {"name": "markerset"})
    objs = ms.find("objects")
    if objs is None:
        objs = ET.SubElement(ms, "objects")
    for m in markers:
        for old in [o for o in objs.findall("Marker") if o.get("name") == m.get("name")]:
            objs.remove(old)
        objs.append(copy.deepcopy(m))
    index = _Index(model, _source(new))
    bodies = {b.get("name") for b in model.iterfind("BodySet/objects/Body")} | {"ground"}
    for m in objs.findall("Marker"):
        try:
            index.base_body(index.resolve(m.findtext("socket_parent_frame", ""), m))
        except ScaleError:
            frame = m.findtext("socket_parent_frame", "")
            close = difflib.get_close_matches(frame.rsplit("/", 1)[-1], sorted(bodies), n=1)
            raise ScaleError(f"marker '{m.get('name')}': its frame '{frame.strip()}' is not in the model"
                             + (f"; did you mean '{close[0]}'?" if close else "")) from None
    return new


def default_pose(doc, kin: OsimKinematics) -> np.ndarray:
    """OpenSim's default pose ``(1, n)`` in ``kin.coordinates`` order: the default values, with each coupled
    coordinate set by its enforced CoordinateCouplerConstraint (as the default state is assembled)."""
    from .functions import from_osim
    q = np.array([[kin.defaults[c] for c in kin.coordinates]])
    col = {c: i for i, c in enumerate(kin.coordinates)}
    couplers = [(col[k.dependent], [col[i] for i in k.independent], from_osim(k.function), float(k.scale_factor))
                for k in doc.constraints if k.enforced and k.function is not None and k.dependent in col
                and all(i in col for i in k.independent)]
    for _ in range(max(1, len(couplers))):       # chains of couplers settle in as many passes
        for d, ind, f, scale in couplers:
            q[:, d] = scale * np.asarray(f.value(q[:, ind[0]] if len(ind) == 1 else q[:, ind]), dtype=float)
    return q


def model_marker_positions(root: ET.Element) -> dict[str, np.ndarray]:
    """``{marker: (3,)}`` ground positions of the model's markers in the default pose (m)."""
    doc = _doc(root)
    kin = OsimKinematics(doc)
    return {k: v[0] for k, v in kin.marker_positions(default_pose(doc, kin)).items()}


# --------------------------------------------------------------------------------------------
# the scale factors
# --------------------------------------------------------------------------------------------
def frame_range(time: np.ndarray, start: float, end: float) -> tuple[int, int]:
    """First and last frame averaged for ``[start, end]`` (``MarkerData::findFrameRange``): the last frame
    at or before ``start`` (else the first) to the first frame from there at or after ``end`` (else the
    last)."""
    t = np.asarray(time, dtype=float)
    if start > end:
        raise ScaleError(f"time range {start:g} to {end:g}: the start is after the end")
    i0 = 0
    before = np.flatnonzero(t <= start)
    if before.size:
        i0 = int(before[-1])
    i1 = t.size - 1
    after = np.flatnonzero(t[i0:] >= end)
    if after.size:
        i1 = i0 + int(after[0])
    return i0, i1


def scale_factors(root: ET.Element, *, measurements: Sequence[Measurement] = (),
                  manual: Sequence[ManualScale] = (), order: Sequence[str] = ("measurements",),
                  markers: Mapping[str, np.ndarray] | None = None, time: np.ndarray | None = None,
                  time_range: tuple[float, float] = (-1.0, -1.0), source: str = "the marker file",
                  unknown_bodies: str = "error") -> ScaleFactors:
    """The scale factors of every physical frame (``ModelScaler::processModel``).

    ``markers``: ``{marker: (N, 3)}`` experimental positions (m) at ``time`` (N,); needed when a
    ``measurements`` step applies a measurement.  A marker missing from the model or the data, a body or
    segment the model does not have, or a step other than ``measurements`` / ``manualScale`` is refused;
    with ``unknown_bodies="warn"`` a body or segment the model does not have is skipped with a warning, as
    OpenSim skips it silently (its own Gait2354 setup scales patellae the model does not have).
    """
    if unknown_bodies not in ("error", "warn"):
        raise ScaleError(f"unknown_bodies must be 'error' or 'warn', got {unknown_bodies!r}")

    def unknown(message):
        if unknown_bodies == "error":
            raise ScaleError(message)
        warnings.warn(message + "; skipped, as OpenSim skips it", ScaleWarning, stacklevel=3)

    model = _model(root)
    frames = _physical_frames(model)
    segments = tuple(f.get("name", "") for f in frames)
    bodies = tuple(b.get("name") for b in model.iterfind("BodySet/objects/Body"))
    factors = np.ones((len(segments), 3))
    known = set(segments)
    results = []
    model_pos = None
    for step in order:
        if step == "measurements":
            for m in measurements:
                if not m.apply:
                    continue
                if markers is None:
                    raise ScaleError(f"measurement '{m.name}': no marker file to measure (set <marker_file>)")
                for b in m.bodies:
                    if b.body not in known:
                        close = difflib.get_close_matches(b.body, bodies, n=1)
                        unknown(f"measurement '{m.name}': body '{b.body}' is not in the model"
                                + (f"; did you mean '{close[0]}'?" if close else "")
                                + f" (bodies: {', '.join(bodies)})")
                if not m.pairs:
                    warnings.warn(f"measurement '{m.name}' has no marker pairs; not used (as OpenSim skips it)",
                                  ScaleWarning, stacklevel=2)
                    continue
                if model_pos is None:
                    model_pos = model_marker_positions(root)
                res = _measure(m, model_pos, markers, time, time_range, source)
                results.append(res)
                for b in m.bodies:
                    cols = [_AXES[a.lower()] for a in b.axes]
                    for k, s in enumerate(segments):
                        if s == b.body:
                            factors[k, cols] = res.factor
        elif step == "manualScale":
            for ms in manual:
                if not ms.apply:
                    continue
                if ms.segment not in known:
                    close = difflib.get_close_matches(ms.segment, segments, n=1)
                    unknown(f"manual scale: segment '{ms.segment}' is not in the model"
                            + (f"; did you mean '{close[0]}'?" if close else ""))
                for k, s in enumerate(segments):
                    if s == ms.segment:
                        factors[k] = ms.factors
        else:
            raise ScaleError(f"scaling order: unknown step '{step}' (the steps are {', '.join(SCALING_STEPS)})")
    return ScaleFactors(segments, factors, tuple(results), bodies)


def _measure(m: Measurement, model_pos, markers, time, time_range, source) -> MeasurementResult:
    i0, i1 = frame_range(time, *time_range)
    pairs, ratio = [], 0.0
    for a, b in m.pairs:
        for name in (a, b):
            if name not in model_pos:
                close = difflib.get_close_matches(name, list(model_pos), n=1)
                raise ScaleError(f"measurement '{m.name}': marker '{name}' is not in the model's marker set"
                                 + (f"; did you mean '{close[0]}'?" if close else ""))
            if name not in markers:
                close = difflib.get_close_matches(name, list(markers), n=1)
                raise ScaleError(f"measurement '{m.name}': marker '{name}' is not in {source}"
                                 + (f"; did you mean '{close[0]}'?" if close else ""))
        d = np.linalg.norm(np.asarray(markers[b])[i0:i1 + 1] - np.asarray(markers[a])[i0:i1 + 1], axis=1)
        if not np.all(np.isfinite(d)):
            k = i0 + int(np.flatnonzero(~np.isfinite(d))[0])
            raise ScaleError(f"measurement '{m.name}': marker pair {a}, {b} is missing in frame {k + 1} of "
                             f"{source} (t = {time[k]:.6g} s); fill the gap or change the time range")
        d_exp = float(d.mean())
        d_mod = float(np.linalg.norm(model_pos[a] - model_pos[b]))
        if d_mod <= 0:
            raise ScaleError(f"measurement '{m.name}': model markers {a} and {b} coincide")
        pairs.append((a, b, d_mod, d_exp))
        ratio += d_exp / d_mod
    return MeasurementResult(m.name, tuple(pairs), ratio / len(m.pairs))


def write_scale_set(factors: ScaleFactors, path) -> Path:
    """Write the factors as OpenSim's ``<ScaleSet>`` file (one ``<Scale>`` per physical frame)."""
    lines = ['<?xml version="1.0" encoding="UTF-8" ?>', '<OpenSimDocument Version="40000">',
             '\t<ScaleSet name="ScaleSet">', "\t\t<objects>"]
    for s, f in zip(factors.segments, factors.factors):
        lines += ["\t\t\t<Scale>", f"\t\t\t\t<scales> {_vec_text(f)}</scales>", f"\t\t\t\t<segment>{s}</segment>",
                  "\t\t\t\t<apply>true</apply>", "\t\t\t</Scale>"]
    lines += ["\t\t</objects>", "\t\t<groups />", "\t</ScaleSet>", "</OpenSimDocument>", ""]
    text = "\n".join(lines)
    return atomic_write(path, lambda fh: fh.write(text))


# --------------------------------------------------------------------------------------------
# the scaled model
# --------------------------------------------------------------------------------------------
def _rotation_xyz(angles) -> np.ndarray:
    """Body-fixed X-Y-Z rotation (OpenSim's ``xyz_body_rotation``)."""
    a, b, c = angles
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    Rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return Rx @ Ry @ Rz


def _scale_inertia(body: ET.Element, s: np.ndarray, scale_mass: bool, where: str) -> None:
    """``Body::scaleInertialProperties``."""
    mass_el = body.find("mass")
    m0 = float(mass_el.text) if mass_el is not None and (mass_el.text or "").strip() else 0.0
    mass_factor = abs(s[0] * s[1] * s[2])
    m = m0 * mass_factor if scale_mass else m0
    if scale_mass and mass_el is not None:
        mass_el.text = _fmt(m)
    in_el = body.find("inertia")
    if in_el is None:
        return
    v = _numbers(in_el, f"{where} <inertia>", 6)
    I = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    if m <= np.finfo(float).eps:
        I = I * 0.0
    elif _numerically_equal(s[0], s[1]) and _numerically_equal(s[1], s[2]):
        if scale_mass:
            I = I * mass_factor
        I = I * (s[0] * s[0])
    else:
        d = np.diag(I)
        if d[0] <= d[1]:
            axis = 0 if d[0] <= d[2] else 2
        else:
            axis = 1 if d[1] <= d[2] else 2
        term = 2.0 * I[axis, axis] / m0
        radius = np.sqrt(term) if term >= 0 else 0.0
        oa = 1 if axis == 0 else 0
        term = 12.0 * (I[oa, oa] - 0.25 * m0 * radius * radius) / m0
        length = np.sqrt(term) if term >= 0 else 0.0
        length *= s[axis]
        others = [k for k in range(3) if k != axis]
        rad_sqr = radius * s[others[0]] * radius * s[others[1]]
        for k in range(3):
            I[k, k] = 0.5 * m * rad_sqr if k == axis else m * (length * length / 12.0 + 0.25 * rad_sqr)
        for i in range(3):
            for j in range(3):
                if i != j:
                    I[i, j] *= s[i] * s[j] * (mass_factor if scale_mass else 1.0)
    _set_numbers(in_el, [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def _numerically_equal(a: float, b: float) -> bool:
    """``SimTK::isNumericallyEqual`` at its default tolerance (relative, absolute below 1)."""
    tol = 1e-14 * max(abs(a), abs(b), 1.0)
    return abs(a - b) <= tol


def _multiply_function(holder: ET.Element, factor: float) -> None:
    """Make the function held in ``holder`` a ``MultiplierFunction`` (or multiply an existing one's scale)."""
    fns = [c for c in holder if isinstance(c.tag, str)]
    if fns:
        _multiply_function_el(holder, fns[0], factor)


def _is_identity_linear(f: ET.Element) -> bool:
    if f.tag != "LinearFunction":
        return False
    c = (f.findtext("coefficients") or "").split()
    try:
        return len(c) >= 2 and float(c[0]) == 1.0 and float(c[1]) == 0.0
    except ValueError:
        return False


def _path_lengths(root: ET.Element) -> dict[str, float]:
    """``{path owner: length}`` of every geometry path in the default pose (m)."""
    doc = _doc(root)
    specs = path_specs(doc)
    if not specs:
        return {}
    kin = OsimKinematics(doc)

    def placements(bodies, q):
        poses = kin.body_poses(q)
        T = np.stack([poses[b] for b in bodies], axis=1)
        return T[..., :3, :3], T[..., :3, 3]

    gp = GeometricPaths(specs, coordinates=kin.coordinates, placements=placements)
    q = default_pose(doc, kin)
    L = gp.lengths(q)[0]
    return dict(zip(gp.muscles, (float(x) for x in L)))


def scale_model(root: ET.Element, factors: ScaleFactors | Mapping[str, Sequence[float]], *,
                mass: float | None = None, preserve_mass_distribution: bool = True,
                name: str | None = None) -> ET.Element:
    """The model tree scaled as ``Model::scale`` scales it (a copy; the input is not changed).

    ``factors``: a :class:`ScaleFactors` or ``{body: (sx, sy, sz)}`` (bodies not named keep 1).
    ``mass`` (kg): the subject's mass the scaled bodies are brought to (None or <= 0: no mass step).
    ``name``: the scaled model's name (OpenSim's ScaleTool gives it the tool's name).
    """
    new = copy.deepcopy(root)
    model = _model(new)
    source = _source(new)
    table = factors.as_dict() if isinstance(factors, ScaleFactors) else \
        {k: np.asarray(v, dtype=float) for k, v in factors.items()}
    for k, v in table.items():
        if np.shape(v) != (3,):
            raise ScaleError(f"scale factors of '{k}': need 3, got {np.shape(v)}")
    index = _Index(model, source)
    body_names = {b.get("name") for b in model.iterfind("BodySet/objects/Body")} | {"ground"}
    unknown = sorted(set(table) - body_names - {f.get("name") for f in model.iter("PhysicalOffsetFrame")})
    if unknown:
        raise ScaleError(f"{source}: scale factors for {unknown}, which the model does not have")

    def sf(body: str) -> np.ndarray | None:
        # a body without factors is left alone (OpenSim's InvalidScaleFactors), as one with 1 1 1 is not:
        # a constant joint translation still becomes a MultiplierFunction of 1 then
        return None if body not in table else np.asarray(table[body], dtype=float)

    def of_frame(frame_el: ET.Element) -> np.ndarray:
        return sf(index.base_body(frame_el))

    for tag in _UNSCALABLE_JOINTS:
        j = model.find(f".//{tag}")
        if j is not None:
            raise ScaleError(f"{source}: {tag} '{j.get('name')}' cannot be scaled by pinmsk (its own scaling "
                             "rule is not implemented); scale the model with OpenSim")
    before = _path_lengths(new)

    # coupler constraints of a translation: the factor of the dependent coordinate's joint's parent body
    couplers = list(model.iter("CoordinateCouplerConstraint"))
    if couplers:
        doc = _doc(new)
        motion = _motion_types(OsimKinematics(doc))
        joint_of = {c.name: c.joint for c in doc.coordinates}
        joints = {j.get("name"): j for j in model.iterfind("JointSet/objects/*")}
        for cc in couplers:
            dep = (cc.findtext("dependent_coordinate_name") or "").strip()
            if motion.get(dep) != "Translational" or joint_of.get(dep) not in joints:
                continue
            j = joints[joint_of[dep]]
            s = of_frame(index.resolve(j.findtext("socket_parent_frame", ""), j))
            if s is None:
                continue
            if not (s[0] == s[1] == s[2]):
                raise ScaleError(f"{source}: coupler '{cc.get('name')}' drives the translation '{dep}' of joint "
                                 f"'{j.get('name')}', whose parent body is scaled unevenly ({_vec_text(s)}): "
                                 "OpenSim does not define that scaling either; scale that body uniformly")
            el = cc.find("scale_factor")
            if el is None:
                el = ET.SubElement(cc, "scale_factor")
                el.text = "1"
            el.text = _fmt(float(el.text) * s[0])

    # bodies: centre of mass
    for b in model.iterfind("BodySet/objects/Body"):
        mc = b.find("mass_center")
        if mc is not None:
            s = sf(b.get("name"))
            if s is not None:
                _set_numbers(mc, _numbers(mc, f"{source}: body '{b.get('name')}' <mass_center>", 3) * s)
    # geometry attached to any frame
    for fr in [model.find("Ground")] + list(model.iterfind("BodySet/objects/Body")) + list(model.iter("PhysicalOffsetFrame")):
        if fr is None:
            continue
        ag = fr.find("attached_geometry")
        if ag is None:
            continue
        s = of_frame(fr)
        if s is None:
            continue
        for g in ag:
            if isinstance(g.tag, str) and g.find("scale_factors") is not None:
                el = g.find("scale_factors")
                _set_numbers(el, _numbers(el, f"{source}: {index.owner_path(g)} <scale_factors>", 3) * s)
    # offset frames: translation by the base body of their parent
    for fr in model.iter("PhysicalOffsetFrame"):
        tr = fr.find("translation")
        if tr is None:
            continue
        s = of_frame(index.resolve(fr.findtext("socket_parent", ""), fr))
        if s is not None:
            _set_numbers(tr, _numbers(tr, f"{source}: {index.owner_path(fr)} <translation>", 3) * s)
    # custom joints: translational transform axes
    for j in model.iterfind("JointSet/objects/CustomJoint"):
        pf = j.findtext("socket_parent_frame", "")
        s = of_frame(index.resolve(pf, j))
        st = j.find("SpatialTransform")
        if st is None or s is None:
            continue
        for axis_name in ("translation1", "translation2", "translation3"):
            ta = st.find(f"TransformAxis[@name='{axis_name}']")
            if ta is None:
                continue
            holder = ta
            fns = [c for c in holder if isinstance(c.tag, str) and c.tag not in ("coordinates", "axis")]
            if not fns or _is_identity_linear(fns[0]):
                continue
            ax = np.abs(_numbers(ta.find("axis"), f"{source}: joint '{j.get('name')}' {axis_name} <axis>", 3))
            _multiply_function_el(holder, fns[0], float(ax @ s))
    # markers
    ms = model.find("MarkerSet/objects")
    for m in (ms if ms is not None else []):
        if m.tag != "Marker":
            continue
        loc = m.find("location")
        s = of_frame(index.resolve(m.findtext("socket_parent_frame", ""), m))
        if s is None:
            continue
        _set_numbers(loc, _numbers(loc, f"{source}: marker '{m.get('name')}' <location>", 3) * s)
    # path points
    for tag in _POINT_TAGS:
        for p in model.iter(tag):
            s = of_frame(index.resolve(p.findtext("socket_parent_frame", ""), p))
            if s is None:
                continue
            if tag == "MovingPathPoint":
                for k, a in enumerate("xyz"):
                    if (p.findtext(f"socket_{a}_coordinate") or "").strip():
                        holder = p.find(f"{a}_location")
                        if holder is not None:
                            _multiply_function(holder, float(s[k]))
            else:
                loc = p.find("location")
                if loc is not None:
                    _set_numbers(loc, _numbers(loc, f"{source}: {index.owner_path(p)} <location>", 3) * s)
    # wrap objects
    for ws in model.iter("WrapObjectSet"):
        owner = index.parent.get(id(ws))
        s = of_frame(owner)
        objs = ws.find("objects")
        if s is None:
            continue
        for w in (objs if objs is not None else []):
            if not isinstance(w.tag, str):
                continue
            where = f"{source}: wrap object '{w.get('name')}'"
            tr = w.find("translation")
            if tr is not None:
                _set_numbers(tr, _numbers(tr, f"{where} <translation>", 3) * s)
            rot = w.find("xyz_body_rotation")
            R = _rotation_xyz(_numbers(rot, f"{where} <xyz_body_rotation>", 3) if rot is not None else np.zeros(3))
            local = [np.linalg.norm(R[:, k] * s) for k in range(3)]
            if w.tag in ("WrapCylinder", "WrapCylinderObst"):
                for prop, f in (("radius", 0.5 * (local[0] + local[1])), ("length", local[2])):
                    el = w.find(prop)
                    if el is not None:
                        el.text = _fmt(float(el.text) * f)
            elif w.tag == "WrapSphere":
                el = w.find("radius")
                if el is not None:
                    el.text = _fmt(float(el.text) * (s.sum() / 3.0))
            elif w.tag == "WrapEllipsoid":
                el = w.find("dimensions")
                if el is not None:
                    _set_numbers(el, _numbers(el, f"{where} <dimensions>", 3) * np.array(local))
            elif w.tag == "WrapTorus":
                f = 0.5 * (local[0] + local[1])
                for prop in ("inner_radius", "outer_radius"):
                    el = w.find(prop)
                    if el is not None:
                        el.text = _fmt(float(el.text) * f)
            else:
                raise ScaleError(f"{where}: <{w.tag}> cannot be scaled by pinmsk; scale the model with OpenSim")
    # inertial properties, then the subject's mass
    bodies = list(model.iterfind("BodySet/objects/Body"))
    for b in bodies:
        if sf(b.get("name")) is not None:
            _scale_inertia(b, sf(b.get("name")), not preserve_mass_distribution, f"{source}: body '{b.get('name')}'")
    if mass is not None and mass > 0:
        m_total = sum(float(b.findtext("mass", "0")) for b in bodies)
        if m_total > 0:
            factor = float(mass) / m_total
            for b in bodies:
                el = b.find("mass")
                if el is not None:
                    el.text = _fmt(float(el.text) * factor)
                iel = b.find("inertia")
                if iel is not None:
                    _set_numbers(iel, _numbers(iel, f"{source}: body '{b.get('name')}' <inertia>", 6) * factor)
    # muscles and other path forces: lengths by the path's length ratio
    after = _path_lengths(new)
    owners = {el.get("name"): el for el in model.iter() if el.tag in _POST_SCALED and el.find("GeometryPath") is not None}
    for owner_name, L0 in before.items():
        el = owners.get(owner_name)
        if L0 <= 0 or owner_name not in after or el is None:
            continue
        ratio = after[owner_name] / L0
        for prop in _POST_SCALED[el.tag]:
            p = el.find(prop)
            if p is not None and (p.text or "").strip():
                p.text = _fmt(float(p.text) * ratio)
    if name is not None:
        model.set("name", name)
    return new


def _multiply_function_el(holder: ET.Element, f: ET.Element, factor: float) -> None:
    """:func:`_multiply_function` for a holder whose function is ``f`` among other properties."""
    if f.tag == "MultiplierFunction":
        sc = f.find("scale")
        if sc is None:
            sc = ET.SubElement(f, "scale")
            sc.text = "1"
        sc.text = _fmt(float(sc.text) * factor)
        return
    idx = list(holder).index(f)
    name = f.get("name")
    mf = ET.Element("MultiplierFunction", {"name": name} if name is not None else {})
    mf.tail = f.tail
    inner = ET.SubElement(mf, "function")
    inner.append(f)
    f.tail = None
    ET.SubElement(mf, "scale").text = _fmt(factor)
    holder.remove(f)
    holder.insert(idx, mf)


# --------------------------------------------------------------------------------------------
# marker placement on the model tree (the pose is solved elsewhere)
# --------------------------------------------------------------------------------------------
def model_markers(root: ET.Element) -> list[dict]:
    """The model's markers: ``{"name", "frame", "location" (3,), "fixed"}`` in marker-set order."""
    out = []
    ms = _model(root).find("MarkerSet/objects")
    for m in (ms if ms is not None else []):
        if m.tag != "Marker":
            continue
        out.append({"name": m.get("name"), "frame": (m.findtext("socket_parent_frame") or "").strip(),
                    "location": _numbers(m.find("location"), f"marker '{m.get('name')}' <location>", 3),
                    "fixed": (m.findtext("fixed") or "false").strip().lower() in ("true", "1")})
    return out


def delete_unused_markers(root: ET.Element, keep: Iterable[str]) -> tuple[ET.Element, list[str]]:
    """A copy without the markers not named in ``keep`` (``Model::deleteUnusedMarkers``), and their names."""
    new = copy.deepcopy(root)
    keep = set(keep)
    ms = _model(new).find("MarkerSet/objects")
    gone = []
    for m in list(ms if ms is not None else []):
        if m.tag == "Marker" and m.get("name") not in keep:
            ms.remove(m)
            gone.append(m.get("name"))
    return new, gone


def coordinate_defaults(root: ET.Element) -> dict[str, float]:
    """``{coordinate: default value}`` in OpenSim's order."""
    return {c.name: float(c.default_value) for c in _doc(root).coordinates}


def rotational_coordinates(root: ET.Element) -> list[str]:
    """The coordinates OpenSim calls Rotational (converted from degrees in its files)."""
    doc = _doc(root)
    return [c for c, t in _motion_types(OsimKinematics(doc)).items() if t == "Rotational"]


def state_coordinate(name: str) -> str:
    """A coordinate's name from an OpenSim 4 state path (``/jointset/hip_r/hip_flexion_r/value``) or itself."""
    parts = name.strip("/").split("/")
    if len(parts) >= 3 and parts[0] == "jointset" and parts[-1] == "value":
        return parts[-2]
    return name


def coordinate_paths(root: ET.Element) -> dict[str, str]:
    """``{coordinate: "/jointset/<joint>/<coordinate>"}`` (OpenSim's state names without ``/value``)."""
    out = {}
    for j in _doc(root).joints:
        for c in j.coordinates:
            out[c.name] = f"/jointset/{j.name}/{c.name}"
    return out


def move_markers(root: ET.Element, q: Mapping[str, float], targets: Mapping[str, np.ndarray]) -> tuple[ET.Element, list[str]]:
    """A copy with every marker that is not ``fixed`` and has a finite target moved, in its own frame, onto
    its target (ground, m) at the pose ``q`` (``{coordinate: value}``; others at their defaults), as
    ``MarkerPlacer::moveModelMarkersToPose`` moves them; and the names moved."""
    from .skeleton import _chain
    new = copy.deepcopy(root)
    doc = _doc(new)
    kin = OsimKinematics(doc)
    poses = kin.body_poses({c: np.array([float(v)]) for c, v in q.items()})
    frames = {}
    for m in doc.markers:
        body, chain = doc.frame_body(m.frame)
        frames[m.name] = poses[body.name][0] @ _chain(chain)
    moved = []
    ms = _model(new).find("MarkerSet/objects")
    for m in (ms if ms is not None else []):
        if m.tag != "Marker" or (m.findtext("fixed") or "false").strip().lower() in ("true", "1"):
            continue
        y = targets.get(m.get("name"))
        if y is None or not np.all(np.isfinite(y)):
            continue
        T = frames[m.get("name")]
        loc = T[:3, :3].T @ (np.asarray(y, dtype=float) - T[:3, 3])
        _set_numbers(m.find("location"), loc)
        moved.append(m.get("name"))
    return new, moved


def write_marker_set(root: ET.Element, path) -> Path:
    """Write the model's markers as an OpenSim ``<MarkerSet>`` file."""
    lines = ['<?xml version="1.0" encoding="UTF-8" ?>', '<OpenSimDocument Version="40000">',
             '\t<MarkerSet name="markerset">', "\t\t<objects>"]
    for m in model_markers(root):
        lines += [f'\t\t\t<Marker name="{m["name"]}">',
                  f'\t\t\t\t<socket_parent_frame>{m["frame"]}</socket_parent_frame>',
                  f'\t\t\t\t<location>{_vec_text(m["location"])}</location>',
                  f'\t\t\t\t<fixed>{"true" if m["fixed"] else "false"}</fixed>', "\t\t\t</Marker>"]
    lines += ["\t\t</objects>", "\t\t<groups />", "\t</MarkerSet>", "</OpenSimDocument>", ""]
    text = "\n".join(lines)
    return atomic_write(path, lambda fh: fh.write(text))
