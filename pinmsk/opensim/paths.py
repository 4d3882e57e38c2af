"""OpenSim muscle paths computed geometrically, and polynomial surrogates of them.

A muscle's path is an ordered list of points fixed in bodies (``PathPoint``),
points active only over a coordinate range (``ConditionalPathPoint``) and
points whose location in their body is a function of a coordinate
(``MovingPathPoint``), wrapped over cylinders, spheres, ellipsoids and tori
(``WrapCylinder`` ...).  This module describes them with small frozen
dataclasses (the *specs*: :class:`PathPointSpec`,
:class:`ConditionalPathPointSpec`, :class:`MovingPathPointSpec`,
:class:`WrapSpec`, :class:`PathWrapSpec`, :class:`PathSpec`), builds them from
a read .osim document (:func:`path_specs`, from :func:`pinmsk.io.osim.read_osim`'s
dataclasses) and evaluates them over many frames at once (:class:`GeometricPaths`), given
the placements of the bodies in ground.

The evaluation follows OpenSim 4.x (``GeometryPath::computePath``,
``applyWrapObjects``, ``WrapCylinder/Sphere/Ellipsoid/Torus::wrapLine``),
re-implemented from its description and checked against the ``opensim``
package (tests/test_osim_paths.py):

* the active points are the fixed and moving points and the conditional
  points whose coordinate lies in their range (widened by 1e-5 as OpenSim
  does); moving points clamp their coordinate to its range;
* each wrap object of the path is tried on every segment between the first
  and last active points of its ``range`` (1-based, -1 = the path's end).  A
  segment whose straight line crosses the object is a *mandatory* wrap and is
  taken; otherwise the wrap that lengthens the path least is taken; with
  several wrap objects the wraps are iterated (at most 8 passes, until the
  length changes by less than 0.5 mm), as OpenSim does;
* the arc over the object adds its length; the straight segments add theirs;
  a quadrant (``+x``, ``-y``, ...) restricts the wrap to one side.

Lengths are exact re-computations of OpenSim's algorithm for cylinders,
spheres and ellipsoids (including OpenSim's own tolerances, its tangent-point
iterations and its polyline over the ellipsoid): they agree with the
``opensim`` package to 1e-15 m.  That includes one OpenSim 4.x behaviour of
paths with several wrap objects: a tangent point's ground position is cached
the first time it is used during a path computation and the straight segments
are summed from that cached position even after a later pass moved the point
(``GeometricPaths(match_opensim=True)``, the default; False gives the length of
the path as it finally lies; arm26's TRIlong differs by up to 4.4 mm).  The
torus's closest point on the ring is found by a descent from the line's start
where OpenSim runs MINPACK's lmdif; both agree where they reach the same root
(most poses of a synthetic test) and not where lmdif stops at another.  Two
OpenSim quirks are *not* copied: a sphere wrapped the long way round gets a
positive arc (OpenSim 4.6 adds a negative one), and a straight line through a
sphere's centre is not wrapped (OpenSim reuses the previous tangent points).

Moment arms ``r_j = -dl/dq_j`` are computed as OpenSim's
``computeMomentArm`` does: the wrapped path is frozen (tangent points fixed in
their bodies, active set fixed) and the straight segments' lengths are
differentiated by central differences of the body placements (and of the
moving points' functions).  For a path whose tangent points are exact this is
the derivative of the length (the arc's change is of second order); it does not
see the polyline steps of OpenSim's ellipsoid arc, which a difference of the
total length would.

For drawing, :meth:`GeometricPaths.polylines` gives every path over many
frames as a polyline in ground (:class:`PathPolylines`): the points OpenSim's
``getCurrentPath`` returns (active points and each wrap's tangent points, at the
same locations, tests/test_viewer_paths.py) with points along each wrapped arc
in between, as long as the path's length (the arc points sit a few microns off
the surface to make up the chords' shortfall).

Arrays are time-first; units SI (m, rad).
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from itertools import combinations_with_replacement
from typing import Callable, Mapping, Sequence

import numpy as np

from ..errors import ModelError, PinmskError
from ..io.osim import OsimDocument
from .functions import Constant, from_osim

_ROUNDOFF = 2e-13     # SIMM's ROUNDOFF_ERROR (the wrap solvers' tolerance)

__all__ = [
    "PathPointSpec", "ConditionalPathPointSpec", "MovingPathPointSpec", "WrapSpec", "PathWrapSpec",
    "PathSpec", "path_specs", "GeometricPaths",
    "PolynomialFitReport", "fit_polynomial_paths", "sample_poses", "motion_ranges", "body_fixed_xyz",
    "PathPolylines", "ARC_POINT",
]

GROUND = "ground"

# wrap results, as OpenSim's WrapObject::WrapAction
NO_WRAP, INSIDE_RADIUS, WRAPPED, MANDATORY_WRAP = 0, 1, 2, 3

WRAP_KINDS = ("cylinder", "sphere", "ellipsoid", "torus")
WRAP_METHODS = ("hybrid", "midpoint", "axial")
_QUADRANTS = {"all": (0, 0), "x": (0, 1), "+x": (0, 1), "-x": (0, -1), "y": (1, 1), "+y": (1, 1),
              "-y": (1, -1), "z": (2, 1), "+z": (2, 1), "-z": (2, -1)}


# --------------------------------------------------------------------------------------------
# specs
# --------------------------------------------------------------------------------------------
def _vec3(value, what: str) -> tuple[float, float, float]:
    a = np.asarray(value, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ModelError(f"{what} must be 3 finite numbers, got {value!r}")
    return (float(a[0]), float(a[1]), float(a[2]))


@dataclass(frozen=True)
class PathPointSpec:
    """A path point fixed in a body: ``location`` (m) in the frame of ``body``."""

    body: str
    location: tuple
    name: str = ""

    def __post_init__(self):
        object.__setattr__(self, "location", _vec3(self.location, f"path point {self.name!r} location"))


@dataclass(frozen=True)
class ConditionalPathPointSpec(PathPointSpec):
    """A path point that is part of the path only while ``coordinate`` lies in ``range`` (inclusive)."""

    coordinate: str = ""
    range: tuple = (-math.inf, math.inf)

    def __post_init__(self):
        super().__post_init__()
        lo, hi = (float(v) for v in self.range)
        if not self.coordinate:
            raise ModelError(f"conditional path point {self.name!r} names no coordinate")
        if not lo <= hi:
            raise ModelError(f"conditional path point {self.name!r}: range [{lo:g}, {hi:g}] has min > max")
        object.__setattr__(self, "range", (lo, hi))


def _value_function(fn, what: str):
    """The value callable of ``fn``: a vectorised callable, or a (value, derivative) pair."""
    if isinstance(fn, (tuple, list)) and len(fn) == 2 and all(callable(f) for f in fn):
        return fn[0]
    if isinstance(fn, (int, float)):
        return Constant(float(fn))
    if not callable(fn):
        raise ModelError(f"{what} must be a callable f(x) (or a (value, derivative) pair), got {fn!r}")
    return fn


@dataclass(frozen=True)
class MovingPathPointSpec:
    """A path point of ``body`` whose location is ``(x(q_cx), y(q_cy), z(q_cz))``.

    ``x``, ``y``, ``z``: vectorised callables f(q) -> m (an object with a
    ``derivative()`` method, a ``(value, derivative)`` pair, or a number for a
    constant).  ``coordinates``: the coordinate each component depends on
    (``None``: a constant, evaluated at 0 as OpenSim does).  ``clamp``: per
    component the coordinate's range ``(min, max)`` to which OpenSim clamps the
    value before evaluating (``None``: no clamping).
    """

    body: str
    x: object
    y: object
    z: object
    coordinates: tuple
    clamp: tuple = (None, None, None)
    name: str = ""

    def __post_init__(self):
        coords = tuple(self.coordinates)
        if len(coords) != 3:
            raise ModelError(f"moving path point {self.name!r}: coordinates must name 3 (x, y, z) coordinates")
        clamp = tuple(self.clamp) if self.clamp is not None else (None, None, None)
        if len(clamp) != 3:
            raise ModelError(f"moving path point {self.name!r}: clamp must give 3 ranges or None")
        object.__setattr__(self, "coordinates", tuple(None if c in (None, "") else str(c) for c in coords))
        object.__setattr__(self, "clamp", tuple(None if c is None else (float(c[0]), float(c[1])) for c in clamp))
        for axis in "xyz":
            object.__setattr__(self, axis, _value_function(getattr(self, axis), f"moving path point "
                                                          f"{self.name!r} {axis} function"))

    def locations(self, values: Sequence[np.ndarray | None]) -> np.ndarray:
        """(N, 3) locations in the body from each component's coordinate values (N,) (None: constant)."""
        cols = []
        n = next((len(v) for v in values if v is not None), 1)
        for fn, v, c in zip((self.x, self.y, self.z), values, self.clamp):
            if v is None:
                cols.append(np.broadcast_to(np.asarray(fn(np.zeros(1)), dtype=float).reshape(-1)[:1], (n,)))
                continue
            if c is not None:
                v = np.clip(v, c[0], c[1])
            cols.append(np.broadcast_to(np.asarray(fn(v), dtype=float), (n,)))
        return np.stack(cols, axis=-1)


@dataclass(frozen=True)
class WrapSpec:
    """A wrap object fixed in ``body``.

    ``kind``: ``cylinder`` (``radius``, ``length``; axis z), ``sphere``
    (``radius``), ``ellipsoid`` (``dimensions``: the three radii) or ``torus``
    (``inner_radius`` of the tube, ``outer_radius`` of the ring; ring in the z = 0
    plane).  Pose in the body: ``rotation`` (body-fixed XYZ angles, rad) and
    ``translation`` (m); ``quadrant`` ``all``/``+x``/``-x``/... restricts the
    wrap to one side; ``active`` False leaves it out.
    """

    kind: str
    name: str
    body: str
    translation: tuple = (0.0, 0.0, 0.0)
    rotation: tuple = (0.0, 0.0, 0.0)
    radius: float | None = None
    length: float | None = None
    dimensions: tuple | None = None
    inner_radius: float | None = None
    outer_radius: float | None = None
    quadrant: str = "all"
    active: bool = True

    def __post_init__(self):
        where = f"wrap object {self.name!r}"
        if self.kind not in WRAP_KINDS:
            raise ModelError(f"{where}: unknown wrap kind {self.kind!r} (known: {', '.join(WRAP_KINDS)})")
        object.__setattr__(self, "translation", _vec3(self.translation, f"{where} translation"))
        object.__setattr__(self, "rotation", _vec3(self.rotation, f"{where} xyz_body_rotation"))
        q = str(self.quadrant).strip().lower()
        if q in ("", "unassigned"):
            q = "all"
        if q not in _QUADRANTS:
            raise ModelError(f"{where}: quadrant {self.quadrant!r} is not one of all, +x, -x, +y, -y, +z, -z")
        object.__setattr__(self, "quadrant", q)
        need = {"cylinder": ("radius", "length"), "sphere": ("radius",), "ellipsoid": ("dimensions",),
                "torus": ("inner_radius", "outer_radius")}[self.kind]
        for attr in need:
            v = getattr(self, attr)
            if v is None:
                raise ModelError(f"{where}: a {self.kind} needs {attr}")
            if attr == "dimensions":
                v = _vec3(v, f"{where} dimensions")
                if min(v) <= 0:
                    raise ModelError(f"{where}: dimensions must be positive, got {v}")
            else:
                v = float(v)
                if not v > 0:
                    raise ModelError(f"{where}: {attr} must be positive, got {v:g}")
            object.__setattr__(self, attr, v)

    @property
    def wrap_axis_sign(self) -> tuple[int, int]:
        return _QUADRANTS[self.quadrant]


@dataclass(frozen=True)
class PathWrapSpec:
    """A wrap object used by one path: ``range`` of path points (1-based, -1 = first/last) and ``method``
    (``hybrid``, ``midpoint`` or ``axial``; ellipsoids only)."""

    wrap: WrapSpec
    range: tuple = (-1, -1)
    method: str = "hybrid"

    def __post_init__(self):
        r = tuple(int(v) for v in self.range)
        if len(r) != 2:
            raise ModelError(f"path wrap over {self.wrap.name!r}: range must be two point numbers")
        object.__setattr__(self, "range", r)
        m = str(self.method).strip().lower() or "hybrid"
        if m not in WRAP_METHODS:
            m = "hybrid"          # OpenSim falls back to hybrid for an unknown method
        object.__setattr__(self, "method", m)


@dataclass(frozen=True)
class PathSpec:
    """The path of muscle ``muscle``: its points in order and the wrap objects it may wrap over."""

    muscle: str
    points: tuple
    wraps: tuple = ()

    def __post_init__(self):
        pts = tuple(self.points)
        if len(pts) < 2:
            raise ModelError(f"muscle {self.muscle!r}: a path needs at least 2 points, it has {len(pts)}")
        for p in pts:
            if not isinstance(p, (PathPointSpec, MovingPathPointSpec)):
                raise ModelError(f"muscle {self.muscle!r}: path point {p!r} is not a PathPointSpec, "
                                 "ConditionalPathPointSpec or MovingPathPointSpec")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "wraps", tuple(self.wraps))

    @property
    def bodies(self) -> tuple[str, ...]:
        """Bodies of the points and wrap objects, in order of first use."""
        names = [p.body for p in self.points] + [w.wrap.body for w in self.wraps]
        return tuple(dict.fromkeys(names))

    @property
    def coordinates(self) -> tuple[str, ...]:
        """Coordinates named by conditional and moving points."""
        out = []
        for p in self.points:
            if isinstance(p, ConditionalPathPointSpec):
                out.append(p.coordinate)
            elif isinstance(p, MovingPathPointSpec):
                out.extend(c for c in p.coordinates if c)
        return tuple(dict.fromkeys(out))


def body_fixed_xyz(angles) -> np.ndarray:
    """Rotation matrix of body-fixed X-Y-Z angles (OpenSim's ``setRotationToBodyFixedXYZ``)."""
    a, b, c = (float(v) for v in angles)
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return rx @ ry @ rz


# --------------------------------------------------------------------------------------------
# the specs of a read .osim document
# --------------------------------------------------------------------------------------------
_WRAP_TAGS = {"WrapCylinder": "cylinder", "WrapSphere": "sphere", "WrapEllipsoid": "ellipsoid",
              "WrapTorus": "torus"}
#: OpenSim's defaults of the wrap sizes the file may leave out (WrapCylinder's length, WrapTorus's radii).
_WRAP_DEFAULTS = {"length": 1.0, "inner_radius": 0.01, "outer_radius": 0.05}


def _leaf(path: str | None) -> str | None:
    """``/bodyset/femur_r`` -> ``femur_r``; ``/jointset/knee_r/knee_angle_r`` -> ``knee_angle_r``."""
    if not path:
        return None
    return path.rstrip("/").split("/")[-1] or None


def _wrap_specs(doc: OsimDocument) -> dict[str, WrapSpec]:
    """``{name: WrapSpec}`` of every wrap object of the document's bodies (a repeated name: the last)."""
    out = {}
    for w in doc.wrap_objects:
        kind = _WRAP_TAGS.get(w.type)
        if kind is None:
            raise ModelError(f"{w.where}: unsupported wrap object type {w.type!r} "
                             f"(supported: {', '.join(_WRAP_TAGS)})")
        kw = dict(kind=kind, name=w.name, body=_leaf(w.frame), translation=w.translation,
                  rotation=w.xyz_body_rotation, quadrant=w.quadrant, active=w.active)
        need = {"cylinder": ("radius", "length"), "sphere": ("radius",), "ellipsoid": ("dimensions",),
                "torus": ("inner_radius", "outer_radius")}[kind]
        for attr in need:
            v = getattr(w, attr)
            if v is None and attr not in _WRAP_DEFAULTS:
                raise ModelError(f"{w.where}: has no <{attr}>")
            kw[attr] = _WRAP_DEFAULTS[attr] if v is None else v
        try:
            out[w.name] = WrapSpec(**kw)
        except ModelError as e:
            raise ModelError(f"{w.where}: {e}") from None
    return out


def _point_spec(p, ranges) -> PathPointSpec | MovingPathPointSpec:
    """The spec of a read path point (:class:`pinmsk.io.osim.PathPoint`); moving points' coordinates
    clamped to their ``ranges`` as OpenSim clamps them."""
    body = _leaf(p.frame)
    # a missing x/y/z_location is a constant 0 (no coordinate); from_osim names a bad function's own line
    fns = [Constant(0.0) if f is None else from_osim(f) for f in (p.x_location, p.y_location, p.z_location)]
    try:
        if p.type == "PathPoint":
            return PathPointSpec(body=body, location=p.location, name=p.name)
        if p.type == "ConditionalPathPoint":
            return ConditionalPathPointSpec(body=body, location=p.location, name=p.name,
                                            coordinate=p.coordinate, range=p.range)
        if p.type == "MovingPathPoint":
            coords = tuple(None if f is None else c for f, c in zip(
                (p.x_location, p.y_location, p.z_location), (p.x_coordinate, p.y_coordinate, p.z_coordinate)))
            clamp = tuple(ranges.get(c) if c else None for c in coords)
            return MovingPathPointSpec(body=body, x=fns[0], y=fns[1], z=fns[2], coordinates=coords,
                                       clamp=clamp, name=p.name)
    except ModelError as e:
        raise ModelError(f"{p.where}: {e}") from None
    raise ModelError(f"{p.where}: unsupported path point type {p.type!r} "
                     "(supported: PathPoint, ConditionalPathPoint, MovingPathPoint)")


def path_specs(doc: OsimDocument) -> tuple[PathSpec, ...]:
    """The geometry paths of a read .osim document (:func:`pinmsk.io.osim.read_osim`), in its order.

    Every element with a ``<GeometryPath>`` (muscles, path actuators, ligaments,
    path springs; in the ForceSet or in a ``<components>``) gives one
    :class:`PathSpec` named after it; the moving points' functions are
    :func:`pinmsk.opensim.functions.from_osim`'s.  Raises :class:`ModelError`
    naming the element's file and line for an unsupported point, wrap or
    function type, a path without points and a PathWrap naming no wrap object
    of the model (with the closest names).
    """
    ranges = {c.name: (float(c.range[0]), float(c.range[1])) for c in doc.coordinates}
    wraps = _wrap_specs(doc)
    out = []
    for m in doc.muscles:
        gp = m.path
        if gp is None or not gp.points:
            raise ModelError(f"{m.where}: the muscle has no path points (<GeometryPath>/<PathPointSet>)")
        points = tuple(_point_spec(p, ranges) for p in gp.points)
        pws = []
        for pw in gp.wraps:
            if pw.wrap_object not in wraps:
                close = difflib.get_close_matches(pw.wrap_object, list(wraps), n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise ModelError(f"{pw.where} of muscle {m.name!r}: no wrap object {pw.wrap_object!r} on any "
                                 f"body{hint}")
            pws.append(PathWrapSpec(wrap=wraps[pw.wrap_object], range=pw.range, method=pw.method))
        try:
            out.append(PathSpec(muscle=m.name, points=points, wraps=tuple(pws)))
        except ModelError as e:
            raise ModelError(f"{m.where}: {e}") from None
    return tuple(out)


# --------------------------------------------------------------------------------------------
# vector helpers over frames: arrays (n, 3)
# --------------------------------------------------------------------------------------------
_EPS = np.finfo(float).eps


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _norm(a):
    return np.sqrt(_dot(a, a))


def _unit(a):
    """OpenSim's NormalizeOrZero: a / |a|, or 0 where |a| < machine epsilon."""
    mag = _norm(a)
    ok = mag >= _EPS
    return np.where(ok[..., None], a / np.where(ok, mag, 1.0)[..., None], 0.0)


def _unitvec(a):
    """SimTK::UnitVec3(a): a / |a| (NaN for a zero vector)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return a / _norm(a)[..., None]


def _dsign(a):
    return np.where(a >= 0.0, 1, -1)


def _sel(mask, a, b):
    """np.where with a (n,) mask over (n, ...) arrays."""
    mask = np.asarray(mask)
    return np.where(mask.reshape(mask.shape + (1,) * (np.ndim(a) - mask.ndim)), a, b)


def _closest_on_line(pt, line_pt, line):
    """WrapMath::GetClosestPointOnLineToPoint -> (closest point, t)."""
    v1 = pt - line_pt
    mag = _norm(v1)
    v1 = _unit(v1)
    mag2 = _norm(line)
    v2 = _unit(line)
    t = _dot(v1, v2) * mag
    closest = line_pt + t[..., None] * v2
    with np.errstate(invalid="ignore", divide="ignore"):
        return closest, t / mag2


def _det_rows(r0, r1, r2):
    return _dot(r0, np.cross(r1, r2))


def _intersect_lines(p1, p2, p3, p4):
    """WrapMath::IntersectLines: closest points of lines p1p2 and p3p4 -> (pint1, s, pint2, t)."""
    vec1 = p2 - p1
    mag1 = _norm(vec1)
    vec1 = _unit(vec1)
    vec2 = p4 - p3
    mag2 = _norm(vec2)
    vec2 = _unit(vec2)
    cross = np.cross(vec1, vec2)
    denom = _dot(cross, cross)
    bad = np.abs(denom) <= _ROUNDOFF
    den = np.where(bad, 1.0, denom)
    d13 = p3 - p1
    t = _det_rows(d13, vec1, cross) / den
    pint2 = p3 + t[..., None] * vec2
    s = _det_rows(d13, vec2, cross) / den
    pint1 = p1 + s[..., None] * vec1
    with np.errstate(invalid="ignore", divide="ignore"):
        s, t = s / mag1, t / mag2
    return pint1, np.where(bad, np.nan, s), pint2, np.where(bad, np.nan, t)


def _intersect_seg_plane(pt1, pt2, normal, d, eps=1e-5):
    """WrapMath::IntersectLineSegPlane -> (ok, intersection)."""
    vec = pt2 - pt1
    dp = _dot(vec, normal)
    bad = np.abs(dp) < eps
    t = (-d - _dot(normal, pt1)) / np.where(bad, 1.0, dp)
    ok = ~bad & (t >= -eps) & (t <= 1.0 + eps)
    return ok, pt1 + t[..., None] * vec


def _rot_z(angle, v):
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]], axis=-1)


class _Wrap:
    """Result of wrapping a batch of segments: code (n,), tangent points r1, r2 (n, 3) in the wrap
    object's frame, arc length (n,), and whether the result carries a path over the surface."""

    __slots__ = ("code", "r1", "r2", "arc", "ok", "curve")

    def __init__(self, n):
        self.code = np.zeros(n, dtype=int)
        self.r1 = np.zeros((n, 3))
        self.r2 = np.zeros((n, 3))
        self.arc = np.zeros(n)
        self.ok = np.zeros(n, dtype=bool)
        # curve(t) -> (points, outward normals) (n, k, 3) of the path over the surface at fractions t (k,)
        # in (0, 1) of the arc, in the wrap object's frame; built lazily (only drawing asks for it)
        self.curve = None


# --------------------------------------------------------------------------------------------
# cylinder (WrapCylinder::wrapLine, _make_spiral_path, _adjust_tangent_point)
# --------------------------------------------------------------------------------------------
_DN = np.array([0.0, 0.0, 1.0])
_P0 = np.array([0.0, 0.0, -1.0])
_TANGENCY = 0.1 * math.pi / 180.0
_MAX_SPIRAL_ITERATIONS = 100
_MAXPASS = 8


def _wrap_cylinder(p1, p2, *, radius, length, axis, sign, single):
    n = p1.shape[0]
    res = _Wrap(n)
    r_sq = radius * radius
    dn = np.broadcast_to(_DN, p1.shape)
    p0 = np.broadcast_to(_P0, p1.shape)

    def dist_sq_to_axis(p):
        v = p0 - p
        return _dot(v - _dot(v, dn)[:, None] * dn, v - _dot(v, dn)[:, None] * dn)

    live = np.ones(n, dtype=bool)
    inside = (dist_sq_to_axis(p1) < r_sq) | (dist_sq_to_axis(p2) < r_sq)
    res.code[inside] = INSIDE_RADIUS
    live &= ~inside
    cyl_start = np.broadcast_to(np.array([0.0, 0.0, -0.5 * length]), p1.shape)
    cyl_end = np.broadcast_to(np.array([0.0, 0.0, 0.5 * length]), p1.shape)
    near12, t12, near00, _ = _intersect_lines(p1, p2, cyl_start, cyl_end)
    with np.errstate(invalid="ignore"):
        hits = (_dot(near12 - near00, near12 - near00) < r_sq) & (t12 > 0.0) & (t12 < 1.0)
    code = np.full(n, WRAPPED)
    constrained = sign != 0
    if not constrained:
        code = np.where(hits, MANDATORY_WRAP, NO_WRAP)
        live &= hits
    p11, _ = _closest_on_line(p1, p0, dn)
    p22, _ = _closest_on_line(p2, p0, dn)

    def candidates(p, pc):
        vv = p - pc
        dist_p = _norm(vv)
        vv = _unit(vv)
        with np.errstate(invalid="ignore", divide="ignore"):
            sin_theta = radius / dist_p
            dist = radius * sin_theta
            pp = pc + dist[:, None] * vv
            dist = np.sqrt(r_sq - dist * dist)
        uu = np.cross(dn, vv)
        return pp + dist[:, None] * uu, pp - dist[:, None] * uu, dist_p

    r1a, r1b, p11_dist = candidates(p1, p11)
    r2a, r2b, p22_dist = candidates(p2, p22)
    far_side = np.zeros(n, dtype=bool)
    long_wrap = np.zeros(n, dtype=bool)
    if constrained:
        s1, s2 = _dsign(p1[:, axis]), _dsign(p2[:, axis])
        either = (s1 == sign) | (s2 == sign)
        potential = (s1 != s2) & (_dsign(near12[:, axis]) != sign)
        code = np.where(either, np.where(hits, MANDATORY_WRAP, WRAPPED), code)
        live &= ~(either & ~hits & ~potential)
        r1am, r1bm, r2am, r2bm = r1a - p11, r1b - p11, r2a - p22, r2b - p22
        with np.errstate(invalid="ignore", divide="ignore"):
            alpha = np.arccos(_dot(r1am, r2bm) / (_norm(r1am) * _norm(r2bm)))
            beta = np.arccos(_dot(r1bm, r2am) / (_norm(r1bm) * _norm(r2am)))
        ab = alpha > beta
        A1, B1 = _dsign(r1a[:, axis]) == sign, _dsign(r1b[:, axis]) == sign
        A2, B2 = _dsign(r2a[:, axis]) == sign, _dsign(r2b[:, axis]) == sign
        # use_a: tangent points (r1a, r2b), else (r1b, r2a); far side as OpenSim decides it
        use_a = np.where(A1 & B1, ~A2, np.where(A1, True, np.where(B1, False, np.where(A2, False, np.where(B2, True, ab)))))
        far_side = np.where(~A1 & ~B1 & ~A2 & ~B2, True, np.where(use_a, ab, ~ab))
        r1 = _sel(use_a, r1a, r1b)
        r2 = _sel(use_a, r2b, r2a)
        sum_musc = (r1 - p1) + (r2 - p2)
        sum_r = (r1 - p11) + (r2 - p22)
        long_wrap = _dot(sum_r, sum_musc) < 0.0
    else:
        u1a, u1b, u2a, u2b = _unit(r1a - p11), _unit(r1b - p11), _unit(r2a - p22), _unit(r2b - p22)
        d1, d2, d3, d4 = _dot(u1a, u2a), _dot(u1a, u2b), _dot(u1b, u2a), _dot(u1b, u2b)
        c1 = (d1 > d2) & (d1 > d3) & (d1 > d4)
        c2 = ~c1 & (d2 > d3) & (d2 > d4)
        c3 = ~c1 & ~c2 & (d3 > d4)
        r1 = _sel(c1 | c2, r1a, r1b)
        r2 = _sel(c1 | c3, r2a, r2b)
    # apex of the cylinder edge between the tangent points; plane through p1, p2 and the apex
    with np.errstate(invalid="ignore", divide="ignore"):
        t = p11_dist / (p11_dist + p22_dist)
    mpt = p1 + t[:, None] * (p2 - p1)
    axispt, _ = _closest_on_line(mpt, p0, dn)
    l1, l2 = _unit(p1 - axispt), _unit(p2 - axispt)
    pn = _unit(_unitvec(np.cross(l1, l2)))
    vert1, vert2 = _unit(np.cross(dn, pn)), _unit(np.cross(pn, dn))
    apex1, apex2 = axispt + radius * vert1, axispt + radius * vert2
    dist1, dist2 = _dot(mpt - apex1, mpt - apex1), _dot(mpt - apex2, mpt - apex2)
    apex = _sel(far_side, _sel(dist1 < dist2, apex2, apex1), _sel(dist1 < dist2, apex1, apex2))
    uu, vv = _unit(p1 - apex), _unit(p2 - apex)
    pn = _unitvec(np.cross(uu, vv))
    d = -_dot(p1, pn)
    ok1, r1p = _intersect_seg_plane(r1 - 10.0 * dn, r1 + 10.0 * dn, pn, d)
    ok2, r2p = _intersect_seg_plane(r2 - 10.0 * dn, r2 + 10.0 * dn, pn, d)
    # OpenSim passes the point p22 (not p22 - p11) as the line direction here; kept as it is
    c1, _ = _closest_on_line(r1p, p11, p22)
    c2, _ = _closest_on_line(r2p, p11, p22)
    r1 = _sel(ok1 & (_dot(c1 - p22, c1 - p22) < _dot(p11 - p22, p11 - p22)), r1p, r1)
    r2 = _sel(ok2 & (_dot(c2 - p11, c2 - p11) < _dot(p22 - p11, p22 - p11)), r2p, r2)
    half = 0.5 * length
    beyond = ((r1[:, 2] < -half) | (r1[:, 2] > half)) & ((r2[:, 2] < -half) | (r2[:, 2] > half))
    live &= ~beyond
    code = np.where(live, code, np.where(inside, INSIDE_RADIUS, NO_WRAP))
    if np.any(live):
        r1, r2, arc = _cylinder_spiral(p1, p2, r1, r2, long_wrap, radius, single, live)
        res.r1, res.r2, res.arc = r1, r2, arc
        res.curve = lambda t: _spiral_curve(r1, r2, long_wrap, radius, t)
    res.code = code
    res.ok = live
    return res


def _spiral(r1, r2, long_wrap, radius):
    """Axial travel, swept angle and length of the spiral from r1 to r2 over the cylinder (OpenSim's
    WrapCylinder::_calc_spiral_wrap_point geometry; the long way round where ``long_wrap``)."""
    axial = r2[..., 2] - r1[..., 2]
    uu = r1 * np.array([1.0, 1.0, 0.0])
    vv = r2 * np.array([1.0, 1.0, 0.0])
    theta = np.arctan2(np.cross(uu, vv)[..., 2], _dot(uu, vv))
    theta = np.where(long_wrap, 2.0 * math.pi - theta, theta)
    return axial, theta, np.sqrt((radius * theta) ** 2 + axial ** 2)


def _spiral_point(t, axial, theta, r, long_wrap):
    """The point at fraction t of the spiral that starts at r (t, axial, theta, long_wrap broadcast)."""
    sense = np.where(long_wrap, -1.0, 1.0)
    return _rot_z(sense * t * theta, r) + (t * axial)[..., None] * _DN


def _spiral_curve(r1, r2, long_wrap, radius, t):
    """Points (n, k, 3) at fractions t (k,) of the spiral r1 -> r2 and their outward normals."""
    axial, theta, _ = _spiral(r1, r2, long_wrap, radius)
    t = np.asarray(t, dtype=float)[None, :]
    pts = _spiral_point(t, axial[:, None], theta[:, None], np.broadcast_to(r1[:, None, :], (len(r1), t.size, 3)),
                        long_wrap[:, None])
    return pts, _unit(pts * np.array([1.0, 1.0, 0.0]))


def _cylinder_spiral(p1, p2, r1, r2, long_wrap, radius, single, live):
    """Arc length of the spiral from r1 to r2 over the cylinder; without ``single`` the tangent points
    slide along the axis until the path is tangent to within 0.1 degree (OpenSim's iteration)."""
    r1, r2 = r1.copy(), r2.copy()

    def spiral(r1, r2, long_wrap):
        return _spiral(r1, r2, long_wrap, radius)

    point = _spiral_point

    def adjust(pt, r, w):
        pr, rw = _unit(r - pt), _unit(w - r)
        with np.errstate(invalid="ignore"):
            alpha, omega = np.arccos(pr[:, 2]), np.arccos(rw[:, 2])
            need = np.abs(alpha - omega) > _TANGENCY
        dn = np.broadcast_to(_DN, r.shape)
        p1a, _ = _closest_on_line(pt, r, dn)
        w1a, _ = _closest_on_line(w, r, dn)
        _, _, inter, _ = _intersect_lines(pt, w, p1a, w1a)
        return need, r + 1.5 * (inter - r)

    axial, theta, arc = spiral(r1, r2, long_wrap)
    if not single:
        idx = np.flatnonzero(live)
        for _ in range(_MAX_SPIRAL_ITERATIONS):
            nseg = np.maximum((arc[idx] / 0.002).astype(int), 1)
            idx = idx[nseg >= 2]
            if idx.size == 0:
                break
            t = 1.0 / np.maximum((arc[idx] / 0.002).astype(int), 1)
            a1, a2, lw = r1[idx], r2[idx], long_wrap[idx]
            need1, new1 = adjust(p1[idx], a1, point(t, axial[idx], theta[idx], a1, lw))
            a1 = _sel(need1, new1, a1)
            # OpenSim computes the second wrap point from the already moved r1 (same theta, axial)
            need2, new2 = adjust(p2[idx], a2, point(1.0 - t, axial[idx], theta[idx], a1, lw))
            moved = need1 | need2
            idx = idx[moved]
            r1[idx] = a1[moved]
            r2[idx] = _sel(need2[moved], new2[moved], a2[moved])
            if idx.size == 0:
                break
            axial[idx], theta[idx], arc[idx] = spiral(r1[idx], r2[idx], long_wrap[idx])
    return r1, r2, arc


# --------------------------------------------------------------------------------------------
# sphere (WrapSphere::wrapLine)
# --------------------------------------------------------------------------------------------
def _wrap_sphere(p1, p2, *, radius, axis, sign):
    n = p1.shape[0]
    res = _Wrap(n)
    r_sq = radius * radius
    n1, n2 = _norm(p1), _norm(p2)
    inside = (n1 < radius) | (n2 < radius)
    ri = p1 - p2
    mp = -p2
    a = _dot(ri, ri)
    b = -2.0 * _dot(mp, ri)
    c = _dot(mp, mp) - r_sq
    disc = b * b - 4.0 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(np.maximum(disc, 0.0))
        l1, l2 = (-b + sq) / (2.0 * a), (-b - sq) / (2.0 * a)
    crosses = (disc >= 0.0) & (0.0 < l1) & (l1 < 1.0) & (0.0 < l2) & (l2 < 1.0) & (l1 >= l2)
    p1p2 = _unit(p1 - p2)
    hp2 = np.cross(p1p2, _unit(p2))
    # a line through the centre: OpenSim reuses the previous tangent points; not wrapped here
    live = ~inside & crosses & (_norm(hp2) >= 1e-5)
    code = np.where(live, WRAPPED, np.where(inside, INSIDE_RADIUS, NO_WRAP))
    nrm = _unit(hp2)

    def candidates(p, pn):
        y = _unit(-p)
        z = np.cross(nrm, y)
        with np.errstate(invalid="ignore"):
            ang = np.arcsin(np.clip(radius / pn, -1.0, 1.0))
        k = (pn * np.cos(ang))[:, None]
        ca, sa = np.cos(ang)[:, None], np.sin(ang)[:, None]
        return p + k * (ca * y - sa * z), p + k * (ca * y + sa * z)

    r1a, r1b = candidates(p1, n1)
    r2a, r2b = candidates(p2, n2)
    u1a, u1b, u2a, u2b = _unit(r1a), _unit(r1b), _unit(r2a), _unit(r2b)
    j1, j2, j3, j4 = _dot(u1a, u2a), _dot(u1a, u2b), _dot(u1b, u2a), _dot(u1b, u2b)
    c1 = (j1 > j2) & (j1 > j3) & (j1 > j4)
    c2 = ~c1 & (j2 > j3) & (j2 > j4)
    c3 = ~c1 & ~c2 & (j3 > j4)
    use1a, use2a = c1 | c2, c1 | c3
    r1 = _sel(use1a, r1a, r1b)
    r2 = _sel(use2a, r2a, r2b)
    far = np.zeros(n, dtype=bool)
    if sign != 0:
        s1, s2 = _dsign(p1[:, axis]), _dsign(p2[:, axis])
        either = (s1 == sign) | (s2 == sign)
        mm, tt = _closest_on_line(np.zeros_like(p1), p1, p1p2)
        tt = -tt      # as OpenSim: tt is a distance (m) compared with 0 and 1
        hit = (_dot(mm, mm) < r_sq) & (tt > 0.0) & (tt < 1.0)
        potential = (s1 != s2) & (_dsign(mm[:, axis]) != sign)
        code = np.where(live & either, np.where(hit, MANDATORY_WRAP, WRAPPED), code)
        drop = either & ~hit & ~potential
        code = np.where(live & drop, NO_WRAP, code)
        live &= ~drop
        off = (s1 != sign) | (s2 != sign)
        wrapaxis = np.zeros(3)
        wrapaxis[axis] = sign
        sm = _unit(-p1 - p2)
        pick1 = _dot(u1a, sm) > _dot(u1b, sm)
        pick2 = _dot(u2a, sm) > _dot(u2b, sm)
        q1, q11 = _sel(pick1, r1a, r1b), _sel(pick1, r1b, r1a)
        q2, q22 = _sel(pick2, r2a, r2b), _sel(pick2, r2b, r2a)
        flip = _dot(_unit((q1 - p1) + (q2 - p2)), wrapaxis) < 0.0
        q1, q2 = _sel(flip, q11, q1), _sel(flip, q22, q2)
        sum_musc = (q1 - p1) + (q2 - p2)
        far_q = _dot(q1 + q2, sum_musc) < 0.0
        r1, r2 = _sel(off, q1, r1), _sel(off, q2, r2)
        far = off & far_q
    with np.errstate(invalid="ignore"):
        angle = np.arccos(np.clip(_dot(_unit(r1), _unit(r2)), -1.0, 1.0))
    # OpenSim 4.6 takes -(2 pi - angle) for a far-side wrap (a negative arc); the arc is 2 pi - angle
    angle = np.where(far, 2.0 * math.pi - angle, angle)
    res.code, res.ok, res.r1, res.r2, res.arc = code, live, r1, r2, radius * angle
    res.curve = lambda t: _great_circle(r1, r2, np.where(far, -angle, angle), t)
    return res


def _great_circle(r1, r2, turn, t):
    """Points (n, k, 3) at fractions t (k,) of the arc that turns r1 by ``turn`` (rad, signed: negative
    the long way round) about r1 x r2 on a sphere centred at the origin, and their outward normals."""
    axis = _unit(np.cross(r1, r2))
    phi = turn[:, None] * np.asarray(t, dtype=float)[None, :]
    pts = (np.cos(phi)[..., None] * r1[:, None, :]
           + np.sin(phi)[..., None] * np.cross(axis, r1)[:, None, :])
    return pts, _unit(pts)


# --------------------------------------------------------------------------------------------
# ellipsoid (WrapEllipsoid::wrapLine, findClosestPoint, calcTangentPoint, CalcDistanceOnEllipsoid)
# --------------------------------------------------------------------------------------------
_MU_BLEND_MIN, _MU_BLEND_MAX = 0.7073, 0.9
_NUM_FAN_SAMPLES = 300
_SV_BOUNDARY_BLEND = 0.3


def _ellipse_closest(a, b, u, v):
    """Closest point (x, y) of the ellipse (x/a)^2 + (y/b)^2 = 1 to (u, v) (Eberly, as OpenSim)."""
    a2, b2 = a * a, b * b
    a2u2, b2v2 = a2 * u * u, b2 * v * v
    near_x = np.abs(u) <= _ROUNDOFF
    near_y = np.abs(v) <= _ROUNDOFF
    t = np.where((u / a) ** 2 + (v / b) ** 2 < 1.0, 0.0, max(a, b) * np.sqrt(u * u + v * v))
    P, Q = t + a2, t + b2
    todo = ~(near_x | near_y)
    for _ in range(64):
        if not np.any(todo):
            break
        P, Q = np.where(todo, t + a2, P), np.where(todo, t + b2, Q)
        f = P * P * Q * Q - a2u2 * Q * Q - b2v2 * P * P
        todo &= ~(np.abs(f) < 1e-9)
        fp = 2.0 * (P * Q * (P + Q) - a2u2 * Q - b2v2 * P)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(todo, t - f / fp, t)
    with np.errstate(invalid="ignore", divide="ignore"):
        x, y = a2 * u / P, b2 * v / Q
        # near the y axis (u = 0)
        yx = b2 * v / (b2 - a2) if b2 != a2 else v
        xx = a * np.sqrt(np.abs(1.0 - (yx / b) ** 2))
        top_x = (a >= b) | (np.abs(v) >= b - a2 / b)
        x_nx = np.where(top_x, u, xx)
        y_nx = np.where(top_x, np.where(v >= 0, b, -b), yx)
        # near the x axis (v = 0)
        xy = a2 * u / (a2 - b2) if a2 != b2 else u
        yy = b * np.sqrt(np.abs(1.0 - (xy / a) ** 2))
        side_y = (b >= a) | (np.abs(u) >= a - b2 / a)
        x_ny = np.where(side_y, np.where(u >= 0, a, -a), xy)
        y_ny = np.where(side_y, v, yy)
    both = near_x & near_y
    if a < b:
        x_b, y_b = np.where(u < 0.0, -a, a), v
    else:
        x_b, y_b = u, np.where(v < 0.0, -b, b)
    x = np.where(both, x_b, np.where(near_x, x_nx, np.where(near_y, x_ny, x)))
    y = np.where(both, y_b, np.where(near_x, y_nx, np.where(near_y, y_ny, y)))
    return x, y


def _ellipsoid_closest(a3, pts, special=-1):
    """Closest point of the ellipsoid with radii a3 to each of pts (n, 3); ``special`` forces the 2-D
    cross-section through that axis (OpenSim's specialCaseAxis; -1: chosen per point)."""
    a, b, c = (float(v) for v in a3)
    n = pts.shape[0]
    if special < 0:
        axis_of = np.full(n, -1)
        best = np.full(n, np.inf)
        for i in range(3):
            s = sum(float(a3[j]) for j in range(3) if j != i)
            pick = (np.abs(pts[:, i]) <= _ROUNDOFF) & (best > s)
            axis_of = np.where(pick, i, axis_of)
            best = np.where(pick, s, best)
    else:
        axis_of = np.full(n, special)
    out = np.empty_like(pts)
    general = axis_of < 0
    if np.any(general):
        out[general] = _ellipsoid_closest_general(a, b, c, pts[general])
    for i, (p, q, j, k) in enumerate(((b, c, 1, 2), (c, a, 2, 0), (a, b, 0, 1))):
        m = axis_of == i
        if np.any(m):
            x, y = _ellipse_closest(p, q, pts[m, j], pts[m, k])
            sub = np.empty((int(m.sum()), 3))
            sub[:, i], sub[:, j], sub[:, k] = pts[m, i], x, y
            out[m] = sub
    return out


def _ellipsoid_closest_general(a, b, c, pts):
    u, v, w = pts[:, 0], pts[:, 1], pts[:, 2]
    a2, b2, c2 = a * a, b * b, c * c
    a2u2, b2v2, c2w2 = a2 * u * u, b2 * v * v, c2 * w * w
    t = np.where((u / a) ** 2 + (v / b) ** 2 + (w / c) ** 2 < 1.0, 0.0, max(a, b, c) * np.sqrt(u * u + v * v + w * w))
    P, Q, R = t + a2, t + b2, t + c2
    todo = np.ones(len(u), dtype=bool)
    for _ in range(64):
        if not np.any(todo):
            break
        P, Q, R = np.where(todo, t + a2, P), np.where(todo, t + b2, Q), np.where(todo, t + c2, R)
        P2, Q2, R2 = P * P, Q * Q, R * R
        f = P2 * Q2 * R2 - a2u2 * Q2 * R2 - b2v2 * P2 * R2 - c2w2 * P2 * Q2
        todo &= ~(np.abs(f) < 1e-9)
        PQ, PR, QR, PQR = P * Q, P * R, Q * R, P * Q * R
        fp = 2.0 * (PQR * (QR + PR + PQ) - a2u2 * QR * (Q + R) - b2v2 * PR * (P + R) - c2w2 * PQ * (P + Q))
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(todo, t - f / fp, t)
    return np.stack([a2 * u / P, b2 * v / Q, c2 * w / R], axis=-1)


def _ellipsoid_tangent(p1e, r1, p1, a, vs, vs4):
    """Slide r1 (on the ellipsoid, in the plane vs.x + vs4 = 0) until the line from p1 touches the
    ellipse there: OpenSim's damped Gauss-Newton iteration (calcTangentPoint), step for step."""
    r1 = r1.copy()
    n = r1.shape[0]
    a2 = a * a
    on_surface = np.abs(p1e) < 1e-4

    def residuals(r, d1):
        nr = 2.0 * r / a2
        return np.stack([_dot(vs, r) + vs4, np.sum((r / a) ** 2, axis=1) - 1.0, _dot(nr, r) + d1,
                         _dot(nr, p1) + d1], axis=1)

    d1 = -_dot(2.0 * r1 / a2, r1)
    ee = residuals(r1, d1)
    ssq = np.sum(ee * ee, axis=1)
    ssqo = ssq.copy()
    alpha = np.full(n, 0.01)
    nit = np.zeros(n, dtype=int)
    p1m = _unit(p1)
    while True:
        act = ~on_surface & (ssq > 1e-8) & (nit < 50)
        if not np.any(act):
            break
        nit += act
        J = np.zeros((n, 4, 4))          # J[:, i, j] = d ee_j / d theta_i
        J[:, :3, 0] = vs
        J[:, :3, 1] = 2.0 * r1 / a2
        J[:, :3, 2] = 2.0 * (2.0 * r1) / a2
        J[:, :3, 3] = 2.0 * p1 / a2
        J[:, 3, 2] = J[:, 3, 3] = 1.0
        pcos = _dot(_unit(p1 - r1), p1m)
        dd = np.where(pcos > 0.1, 1.0 - pcos ** 100, 1.0)
        v = -np.einsum("nij,nj->ni", J, ee)
        JJ = np.einsum("nik,njk->nij", J, J)
        diag = np.diagonal(JJ, axis1=1, axis2=2).copy()
        vt = np.zeros((n, 4))
        nit2 = np.zeros(n, dtype=int)
        while True:
            inner = act & (ssq >= ssqo) & (nit2 < 1000)
            if not np.any(inner):
                break
            M = JJ.copy()
            idx = np.arange(4)
            M[:, idx, idx] = diag * (1.0 + alpha)[:, None]
            with np.errstate(all="ignore"):
                Minv = np.linalg.inv(np.where(inner[:, None, None], M, np.eye(4)))
            step = dd[:, None] * np.einsum("nij,nj->ni", Minv, v) / 16.0
            vt = np.where(inner[:, None], step, vt)
            r1 = np.where(inner[:, None], r1 + vt[:, :3], r1)
            d1 = np.where(inner, d1 + vt[:, 3], d1)
            ee = np.where(inner[:, None], residuals(r1, d1), ee)
            ssqo = np.where(inner, ssq, ssqo)
            ssq = np.where(inner, np.sum(ee * ee, axis=1), ssq)
            alpha = np.where(inner, alpha * 4.0, alpha)
            nit2 += inner
        alpha = np.where(act, alpha / 8.0, alpha)
        fakt = np.full(n, 0.5)
        nit2[:] = 0
        while True:
            inner = act & (ssq <= ssqo) & (nit2 < 1000)
            if not np.any(inner):
                break
            fakt = np.where(inner, fakt * 2.0, fakt)
            r1 = np.where(inner[:, None], r1 + vt[:, :3] * fakt[:, None], r1)
            d1 = np.where(inner, d1 + vt[:, 3] * fakt, d1)
            ee = np.where(inner[:, None], residuals(r1, d1), ee)
            ssqo = np.where(inner, ssq, ssqo)
            ssq = np.where(inner, np.sum(ee * ee, axis=1), ssq)
            nit2 += inner
        r1 = np.where(act[:, None], r1 - vt[:, :3] * fakt[:, None], r1)
        d1 = np.where(act, d1 - vt[:, 3] * fakt, d1)
        ee = np.where(act[:, None], residuals(r1, d1), ee)
        ssq = np.where(act, np.sum(ee * ee, axis=1), ssq)
        ssqo = np.where(act, ssq, ssqo)
    return np.where(on_surface[:, None], p1, r1)


def _ellipsoid_plane(r1, r2, vs, vs4, far, factor):
    """The wrap plane's section of CalcDistanceOnEllipsoid -> (chord (m), segments, short, centre a0,
    in-plane axes ar1 and vsy, signed turn from r1 to r2), in scaled units."""
    n = r1.shape[0]
    chord = _norm(r1 - r2) / factor
    nseg = np.clip((chord / 0.001).astype(int), 1, 499)
    short = chord < 0.001
    imax = np.argmax(np.abs(vs), axis=1)      # first of equal maxima, as OpenSim's strict '>'
    vsi = vs[np.arange(n), imax]
    a0 = np.zeros((n, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        a0[np.arange(n), imax] = -vs4 / vsi
    ar1, ar2 = _unit(r1 - a0), _unit(r2 - a0)
    with np.errstate(invalid="ignore"):
        phi0 = np.arccos(_dot(ar1, ar2))
    vsz = _unit(np.cross(ar1, ar2))
    vsy = np.cross(vsz, ar1)
    return chord, nseg, short, a0, ar1, vsy, np.where(far, -(2.0 * math.pi - phi0), phi0)


def _ellipsoid_plane_points(a0, ar1, vsy, a, phi):
    """Where the rays from a0 at angles phi (n, k) in the plane (ar1, vsy) leave the ellipsoid (n, k, 3)."""
    r = np.cos(phi)[..., None] * ar1[:, None, :] + np.sin(phi)[..., None] * vsy[:, None, :]
    f1 = r / a
    f2 = (a0 / a)[:, None, :]
    aa = np.sum(f1 * f1, axis=2)
    bb = 2.0 * np.sum(f1 * f2, axis=2)
    cc = np.sum(f2 * f2, axis=2) - 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        mu3 = (-bb + np.sqrt(bb * bb - 4.0 * aa * cc)) / (2.0 * aa)
    return a0[:, None, :] + mu3[..., None] * r


def _ellipsoid_curve(r1, r2, a, vs, vs4, far, factor, t):
    """Points (n, k, 3) of OpenSim's polyline over the ellipsoid near fractions t (k,) of its turn -- each
    t moved to the nearest of the polyline's own vertices, so the points' chords never exceed its
    length -- and their outward normals (0 at the tangent points), in the wrap frame (m)."""
    _, nseg, short, a0, ar1, vsy, turn = _ellipsoid_plane(r1, r2, vs, vs4, far, factor)
    t = np.asarray(t, dtype=float)[None, :]
    ts = np.round(t * nseg[:, None]) / nseg[:, None]
    pts = _ellipsoid_plane_points(a0, ar1, vsy, a, ts * turn[:, None])
    pts = np.where((ts <= 0.0)[..., None], r1[:, None, :], np.where((ts >= 1.0)[..., None], r2[:, None, :], pts))
    chord = r1[:, None, :] + t[..., None] * (r2 - r1)[:, None, :]      # OpenSim's straight arc below 1 mm
    pts = np.where(short[:, None, None], chord, pts)
    ends = (ts <= 0.0) | (ts >= 1.0) | short[:, None]
    normals = np.where(ends[..., None], 0.0, _unit(pts / (a * a)))
    return pts / factor, normals


def _ellipsoid_arc(r1, r2, a, vs, vs4, far, factor):
    """OpenSim's CalcDistanceOnEllipsoid: the polyline over the surface in the wrap plane (1 mm
    segments, at most 499) -> (length, second point, second-last point), in scaled units."""
    n = r1.shape[0]
    chord, nseg, short, a0, ar1, vsy, turn = _ellipsoid_plane(r1, r2, vs, vs4, far, factor)
    k = np.arange(1, 499)[None, :]                       # interior points 1 .. nseg-1
    s = _ellipsoid_plane_points(a0, ar1, vsy, a, k * (turn / nseg)[:, None])
    interior = k < nseg[:, None]
    s = np.where(interior[..., None], s, r2[:, None, :])
    pts = np.concatenate([r1[:, None, :], s, r2[:, None, :]], axis=1)
    length = np.sum(_norm(np.diff(pts, axis=1)), axis=1)
    length = np.where(short, chord * factor, length)
    second = np.where(short[:, None], r2, pts[:, 1])
    before_last = np.where(short[:, None], r1, pts[np.arange(n), nseg - 1])
    npts = np.where(short, 2, nseg + 1)
    return length, second, before_last, npts


def _wrap_ellipsoid(P1, P2, *, dims, axis, sign, method):
    n = P1.shape[0]
    res = _Wrap(n)
    dims = np.asarray(dims, dtype=float)
    factor = 3.0 / dims.sum()
    p1, p2, a = P1 * factor, P2 * factor, dims * factor
    p1e = np.sum((p1 / a) ** 2, axis=1) - 1.0
    p2e = np.sum((p2 / a) ** 2, axis=1) - 1.0
    inside = (p1e < -0.0001) | (p2e < -0.0001)
    p1p2 = p1 - p2
    ppm = _dot(_unit(p1), _unit(p2)) - 1.0
    f1, f2 = p1p2 / a, p2 / a
    aa, bb, cc = _dot(f1, f1), 2.0 * _dot(f1, f2), _dot(f2, f2) - 1.0
    disc = bb * bb - 4.0 * aa * cc
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(np.maximum(disc, 0.0))
        l1, l2 = (-bb + sq) / (2.0 * aa), (-bb - sq) / (2.0 * aa)
    live = (~inside & ~(np.abs(ppm) < 0.0001) & (disc >= 0.0) & (0.0 < l1) & (l1 < 1.0)
            & (0.0 < l2) & (l2 < 1.0))
    res.code = np.where(live, MANDATORY_WRAP, np.where(inside, INSIDE_RADIUS, NO_WRAP))
    res.ok = live
    if not np.any(live):
        return res
    idx = np.flatnonzero(live)
    p1, p2, p1p2, p1e, p2e = p1[idx], p2[idx], p1p2[idx], p1e[idx], p2e[idx]
    l1, l2 = l1[idx], l2[idx]
    k = len(idx)
    r1 = p2 + l1[:, None] * p1p2
    r2 = p2 + l2[:, None] * p1p2
    r1r2 = r2 - r1
    mu = np.abs(_unit(p1p2))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = -r1 / r1r2
    t_sv = [r1 + t[:, i:i + 1] * r1r2 for i in range(3)]
    t_c1 = [_ellipsoid_closest(a, t_sv[i], special=i) for i in range(3)]
    best = np.argmax(mu, axis=1)
    rows = np.arange(k)
    mu_b = mu[rows, best]
    t_b = t[rows, best]
    sv_frans = np.stack(t_sv, axis=1)[rows, best]
    c1_frans = np.stack(t_c1, axis=1)[rows, best]
    c1 = np.zeros((k, 3))
    sv = np.zeros((k, 3))
    fan_weight = np.full(k, -np.inf)
    if method in ("hybrid", "axial"):
        if method == "hybrid":
            s = np.where((t_b < 0.0) | (t_b > 1.0), 0.0,
                         np.where(t_b < _SV_BOUNDARY_BLEND, t_b / _SV_BOUNDARY_BLEND,
                                  np.where(t_b > 1.0 - _SV_BOUNDARY_BLEND, (1.0 - t_b) / _SV_BOUNDARY_BLEND, 1.0)))
            blend = (mu_b > _MU_BLEND_MIN) & (s < 1.0)
            mu_b = np.where(blend, _MU_BLEND_MIN + s * (mu_b - _MU_BLEND_MIN), mu_b)
        frans = np.full(k, True) if method == "axial" else mu_b > _MU_BLEND_MIN
        c1 = _sel(frans, c1_frans, c1)
        sv = _sel(frans, sv_frans, sv)
        if method == "hybrid":
            fan = mu_b < _MU_BLEND_MAX
            if np.any(fan):
                j = np.flatnonzero(fan)
                tt = np.arange(1, _NUM_FAN_SAMPLES - 1) / _NUM_FAN_SAMPLES
                svs = r1[j, None, :] + tt[None, :, None] * r1r2[j, None, :]
                flat = svs.reshape(-1, 3)
                blades = _unit(_ellipsoid_closest(a, flat) - flat).reshape(svs.shape)
                v_sum = _unit(blades.sum(axis=1))
                sv_mid = r1[j] + 0.5 * r1r2[j]
                tc = sv_mid + v_sum
                pure = mu_b[j] <= _MU_BLEND_MIN
                c_pure = _ellipsoid_closest(a, tc)
                w = (mu_b[j] - _MU_BLEND_MIN) / (_MU_BLEND_MAX - _MU_BLEND_MIN)
                tc1 = c_pure           # the closest point to tc, as for the pure fan
                c_blend = _ellipsoid_closest(a, w[:, None] * c1[j] + (1.0 - w)[:, None] * tc1)
                sv_blend = w[:, None] * sv[j] + (1.0 - w)[:, None] * sv_mid
                c1[j] = _sel(pure, c_pure, c_blend)
                sv[j] = _sel(pure, sv_mid, sv_blend)
                fan_weight[j] = np.where(pure, 1.0, 1.0 - w)
        use_c1 = (t_b > 0.0) & (t_b < 1.0) if method == "axial" else np.full(k, True)
    else:
        sv = r1 + 0.5 * (r2 - r1)
        c1 = _ellipsoid_closest(a, sv)
        use_c1 = np.full(k, True)
    r1 = _sel(use_c1, c1, r1)
    r2 = _sel(use_c1, c1, r2)
    if sign != 0:
        flip = _dsign(c1[:, axis]) != sign
        orig = c1[:, axis].copy()
        c1 = c1.copy()
        c1[:, axis] = np.where(flip, -c1[:, axis], c1[:, axis])
        r1, r2 = _sel(flip, c1, r1), _sel(flip, c1, r2)
        fw = np.minimum(fan_weight, 1.0)
        shift = flip & (fw > 0.0)
        if np.any(shift):
            bis = 0.5 * (orig + c1[:, axis])
            tc1 = c1.copy()
            with np.errstate(invalid="ignore"):
                tc1[:, axis] = c1[:, axis] + np.where(shift, fw, 0.0) * (bis - c1[:, axis])
            c1 = _sel(shift, _ellipsoid_closest(a, np.where(shift[:, None], tc1, c1)), c1)
    vs = _unit(np.cross(p1p2, p1 - c1))
    vs4 = -_dot(vs, c1)
    r1 = _ellipsoid_tangent(p1e, r1, p1, a, vs, vs4)
    r2 = _ellipsoid_tangent(p2e, r2, p2, a, vs, vs4)
    far = np.zeros(k, dtype=bool)
    length, w1, w2, npts = _ellipsoid_arc(r1, r2, a, vs, vs4, far, factor)
    if sign != 0:
        wrong = (npts > 2) & ((_dot(_unit(p1 - r1), _unit(w1 - r1)) > 0.0) | (_dot(_unit(p2 - r2), _unit(w2 - r2)) > 0.0))
        if np.any(wrong):
            far = wrong
            length_far, _, _, _ = _ellipsoid_arc(r1, r2, a, vs, vs4, far, factor)
            length = np.where(wrong, length_far, length)
    res.r1[idx] = r1 / factor
    res.r2[idx] = r2 / factor
    res.arc[idx] = length / factor

    def curve(t):
        pts, normals = _ellipsoid_curve(r1, r2, a, vs, vs4, far, factor, t)
        P, Nrm = np.zeros((n,) + pts.shape[1:]), np.zeros((n,) + pts.shape[1:])
        P[idx], Nrm[idx] = pts, normals
        return P, Nrm

    res.curve = curve
    return res


# --------------------------------------------------------------------------------------------
# torus (WrapTorus::wrapLine): a cylinder of the tube's radius, tangent to the ring where the line
# passes closest to it
# --------------------------------------------------------------------------------------------
def _torus_line_point(p1, p2, ring):
    """Point of the line p1 -> p2 where OpenSim's residual (WrapTorus::calcCircleResids) is least in
    the valley of residual^2 reached downhill from u = 0 (OpenSim: lmdif from u = 0 with 1e-4
    tolerances; here Gauss-Newton steps of at most 1 cm that must lower residual^2) -> (point, distance)."""
    d = p2 - p1
    nrm = _unit(d)
    c2 = 2.0 * _dot(p1, nrm)
    c3 = p1[:, 0] * nrm[:, 0] + p1[:, 1] * nrm[:, 1]
    c4 = nrm[:, 0] ** 2 + nrm[:, 1] ** 2
    c5 = p1[:, 0] ** 2 + p1[:, 1] ** 2

    def resid(u):
        rho2 = np.maximum(u * u * c4 + 2.0 * c3 * u + c5, 1e-300)
        rho = np.sqrt(rho2)
        g = (c4 * u + c3) / rho
        r = c2 + 2.0 * u - 4.0 * ring * g
        dr = 2.0 - 4.0 * ring * (c4 * rho2 - (c4 * u + c3) ** 2) / (rho2 * rho)
        return r, dr

    u = np.zeros(len(p1))
    r, dr = resid(u)
    limit = 0.01
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for _ in range(2000):
            step = np.where(np.abs(dr) > 1e-300, -r * dr / np.maximum(dr * dr, 1e-300), 0.0)
            step = np.clip(step, -limit, limit)
            for _ in range(30):            # halve until residual^2 does not grow
                rn, drn = resid(u + step)
                worse = rn * rn > r * r
                if not np.any(worse):
                    break
                step = np.where(worse, 0.5 * step, step)
            u, r, dr = u + step, rn, drn
            if np.all(np.abs(step) < 1e-15 * np.maximum(1.0, np.abs(u))):
                break
    x = p1 + u[:, None] * nrm
    rxy = np.sqrt(x[:, 0] ** 2 + x[:, 1] ** 2)
    dist = np.sqrt(np.maximum(_dot(x, x) + ring * ring - 2.0 * ring * rxy, 0.0))
    return x, dist


def _wrap_torus(p1, p2, *, inner, outer, axis, sign, single):
    n = p1.shape[0]
    res = _Wrap(n)
    a1, d1 = _torus_line_point(p1, p2, outer)
    a2, d2 = _torus_line_point(p2, p1, outer)
    if sign != 0:
        ok1, ok2 = _dsign(a1[:, axis]) == sign, _dsign(a2[:, axis]) == sign
        first = np.where(ok1 & ok2, d1 < d2, ok1)
        found = ok1 | ok2
    else:
        first = d1 < d2
        found = np.ones(n, dtype=bool)
    a = _sel(first, a1, a2)
    rxy = np.sqrt(a[:, 0] ** 2 + a[:, 1] ** 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.stack([a[:, 0] * outer / rxy, a[:, 1] * outer / rxy, np.zeros(n)], axis=-1)
    X = _unit(-c)
    Y = np.broadcast_to(np.array([0.0, 0.0, -1.0]), X.shape)
    Z = np.cross(X, Y)
    R = np.stack([X, Y, Z], axis=1)                 # rows: cylinder axes in the torus frame
    q1 = np.einsum("nij,nj->ni", R, p1 - c)
    q2 = np.einsum("nij,nj->ni", R, p2 - c)
    cyl = _wrap_cylinder(q1, q2, radius=inner, length=10000.0, axis=0, sign=1, single=single)
    ok = found & cyl.ok & (cyl.code > 0)
    res.ok = ok
    res.code = np.where(ok, WRAPPED, NO_WRAP)     # OpenSim's torus reports every wrap as 'wrapped'
    res.r1 = np.einsum("nji,nj->ni", R, cyl.r1) + c
    res.r2 = np.einsum("nji,nj->ni", R, cyl.r2) + c
    res.arc = np.where(ok, cyl.arc, 0.0)
    if cyl.curve is not None:
        def curve(t):
            pts, normals = cyl.curve(t)
            return np.einsum("nji,nkj->nki", R, pts) + c[:, None, :], np.einsum("nji,nkj->nki", R, normals)
        res.curve = curve
    return res


def _wrap_segments(wrap: WrapSpec, method: str, single: bool, p1, p2) -> _Wrap:
    axis, sign = wrap.wrap_axis_sign
    if wrap.kind == "cylinder":
        return _wrap_cylinder(p1, p2, radius=wrap.radius, length=wrap.length, axis=axis, sign=sign, single=single)
    if wrap.kind == "sphere":
        return _wrap_sphere(p1, p2, radius=wrap.radius, axis=axis, sign=sign)
    if wrap.kind == "ellipsoid":
        return _wrap_ellipsoid(p1, p2, dims=wrap.dimensions, axis=axis, sign=sign, method=method)
    return _wrap_torus(p1, p2, inner=wrap.inner_radius, outer=wrap.outer_radius, axis=axis, sign=sign,
                       single=single)


# --------------------------------------------------------------------------------------------
# paths over frames
# --------------------------------------------------------------------------------------------
class _Compiled:
    """One path's fixed data: slot bodies (points, then two tangent points per wrap object)."""

    __slots__ = ("spec", "P", "W", "S", "slot_body", "slot_wrap", "fixed", "moving", "conditional",
                 "wrap_body", "wrap_R", "wrap_t", "single")

    def __init__(self, spec: PathSpec, body_index: Mapping[str, int], coord_index: Mapping[str, int]):
        self.spec = spec
        self.P, self.W = len(spec.points), len(spec.wraps)
        self.S = self.P + 2 * self.W
        self.slot_body = np.array([body_index[p.body] for p in spec.points]
                                  + [body_index[w.wrap.body] for w in spec.wraps for _ in (0, 1)], dtype=int)
        self.slot_wrap = np.array([-1] * self.P + [w for w in range(self.W) for _ in (0, 1)], dtype=int)
        self.fixed = np.array([p.location if isinstance(p, PathPointSpec) else (0.0, 0.0, 0.0)
                               for p in spec.points])
        self.moving = [(i, p, tuple(None if c is None else coord_index[c] for c in p.coordinates))
                       for i, p in enumerate(spec.points) if isinstance(p, MovingPathPointSpec)]
        self.conditional = [(i, coord_index[p.coordinate], p.range) for i, p in enumerate(spec.points)
                            if isinstance(p, ConditionalPathPointSpec)]
        self.wrap_body = np.array([body_index[w.wrap.body] for w in spec.wraps], dtype=int)
        self.wrap_R = np.array([body_fixed_xyz(w.wrap.rotation) for w in spec.wraps]).reshape(-1, 3, 3)
        self.wrap_t = np.array([w.wrap.translation for w in spec.wraps]).reshape(-1, 3)
        self.single = self.W == 1

    def point_locals(self, q):
        """(N, P, 3) point locations in their bodies and (N, P) activity, at coordinates q (N, nq)."""
        N = q.shape[0]
        L = np.broadcast_to(self.fixed, (N, self.P, 3)).copy()
        for i, p, cols in self.moving:
            L[:, i] = p.locations([None if c is None else q[:, c] for c in cols])
        active = np.ones((N, self.P), dtype=bool)
        for i, c, (lo, hi) in self.conditional:
            active[:, i] = (q[:, c] >= lo - 1e-5) & (q[:, c] <= hi + 1e-5)
        return L, active


def _to_ground(R, p, body, L):
    """Ground positions of local points L (N, S, 3) fixed in bodies ``body`` (S,)."""
    return np.einsum("nsij,nsj->nsi", R[:, body], L) + p[:, body]


def _compact(order, keep):
    idx = np.argsort(~keep, axis=1, kind="stable")
    out = np.take_along_axis(order, idx, axis=1)
    out[~np.take_along_axis(keep, idx, axis=1)] = -1
    return out


def _remove_slots(order, s1, s2):
    return _compact(order, (order >= 0) & (order != s1) & (order != s2))


def _insert_two(order, pos, s1, s2):
    cols = np.arange(order.shape[1])[None, :]
    src = np.where(cols < pos[:, None], cols, cols - 2)
    out = np.take_along_axis(order, np.clip(src, 0, None), axis=1)
    out = np.where(cols == pos[:, None], s1, out)
    return np.where(cols == pos[:, None] + 1, s2, out)


class _State:
    """A wrapped path over frames: slot order, local positions, arcs, length, and the ground positions
    the length was summed from (OpenSim's per-realization cache of each point's ground location)."""

    __slots__ = ("order", "L", "arc", "length", "G", "curve")

    def __init__(self, order, L, arc, length, G, curve=None):
        self.order, self.L, self.arc, self.length, self.G = order, L, arc, length, G
        # with arc sampling: (points, outward normals) (N, W, k, 3) in ground of each wrap's arc
        self.curve = curve


class _Cache:
    """Ground positions as OpenSim's ``Point::getLocationInGround`` returns them during one path
    computation: a tangent point's ground location is cached the first time it is asked for and not
    refreshed when a later wrapping pass moves the point (with ``stale`` False: always fresh)."""

    __slots__ = ("X", "G", "cached", "stale", "is_wrap")

    def __init__(self, X, P, stale):
        self.X = X                       # fresh ground positions (N, S, 3)
        self.G = X.copy()
        self.cached = np.zeros(X.shape[:2], dtype=bool)
        self.cached[:, :P] = True        # path points do not move during a computation
        self.stale = stale
        self.is_wrap = np.arange(X.shape[1]) >= P

    def get(self, rows, slots):
        """Ground positions of ``slots`` (n, k) in frames ``rows`` (n, 1), caching them."""
        if not self.stale:
            return self.X[rows, slots]
        new = ~self.cached[rows, slots]
        if np.any(new):
            r = np.broadcast_to(rows, slots.shape)[new]
            s = slots[new]
            self.G[r, s] = self.X[r, s]
            self.cached[r, s] = True
        return self.G[rows, slots]

    def length(self, order, arc, slot_wrap, rows=None):
        rows = np.arange(order.shape[0])[:, None] if rows is None else rows[:, None]
        a, b = order[:, :-1], order[:, 1:]
        valid = (a >= 0) & (b >= 0)
        o0 = np.maximum(order, 0)
        Xg = self.get(rows, np.where(order >= 0, o0, 0))
        seg = _norm(Xg[:, 1:] - Xg[:, :-1])
        wa, wb = slot_wrap[np.maximum(a, 0)], slot_wrap[np.maximum(b, 0)]
        over = valid & (wa >= 0) & (wa == wb)
        if arc.shape[1]:
            local = np.arange(order.shape[0])[:, None]
            seg = np.where(over, arc[local, np.maximum(wa, 0)], seg)
        return np.sum(np.where(valid, seg, 0.0), axis=1)


class GeometricPaths:
    """Muscle paths evaluated geometrically over frames, as OpenSim computes them.

    Parameters (keyword-only after ``specs``)
    -----------------------------------------
    specs : sequence of :class:`PathSpec`
    coordinates : names of the columns of ``q`` (every coordinate a conditional or moving point
        names must be among them)
    placements : callable ``placements(body_names, q) -> (R, p)``, with ``q`` (N, nq) and
        ``body_names`` a tuple of B names, returning rotations ``R`` (N, B, 3, 3) (body to ground)
        and origins ``p`` (N, B, 3) in ground.  ``ground`` is never asked for (identity).
    match_opensim : bool, default True
        Reproduce OpenSim 4.x exactly where a path has several wrap objects: OpenSim caches
        each tangent point's ground position the first time it is used while it computes a path
        and sums the straight segments (and takes the moment arms' directions) from those cached
        positions even after a later wrapping pass moved the point.  False: the length of the
        wrapped path as it finally lies (the same for paths with at most one wrap object).

    Lengths are (N, m) in the order of ``specs``; moment arms (N, m, nc) for the
    coordinates asked (default: all).
    """

    def __init__(self, specs: Sequence[PathSpec], *, coordinates: Sequence[str], placements: Callable,
                 match_opensim: bool = True):
        self.specs = tuple(specs)
        if not self.specs:
            raise ModelError("GeometricPaths needs at least one path")
        self.muscles = tuple(s.muscle for s in self.specs)
        dup = sorted({m for m in self.muscles if self.muscles.count(m) > 1})
        if dup:
            raise ModelError(f"GeometricPaths: repeated muscle names: {', '.join(dup)}")
        self.coordinates = tuple(str(c) for c in coordinates)
        coord_index = {c: j for j, c in enumerate(self.coordinates)}
        for s in self.specs:
            for c in s.coordinates:
                if c not in coord_index:
                    close = difflib.get_close_matches(c, self.coordinates, n=1)
                    hint = f"; did you mean {close[0]!r}?" if close else ""
                    raise ModelError(f"muscle {s.muscle!r}: its path depends on coordinate {c!r}, which is not "
                                     f"among the coordinates given{hint}")
        names = [b for s in self.specs for b in s.bodies if b != GROUND]
        self.bodies = tuple(dict.fromkeys(names))
        body_index = {b: i for i, b in enumerate(self.bodies)}
        body_index[GROUND] = len(self.bodies)
        self._placements = placements
        self.match_opensim = bool(match_opensim)
        self._paths = [_Compiled(s, body_index, coord_index) for s in self.specs]

    def __repr__(self):
        return f"GeometricPaths({len(self.muscles)} paths over {len(self.coordinates)} coordinates)"

    # -- placements ----------------------------------------------------------------------
    def _q(self, q):
        q = np.asarray(q, dtype=float)
        nq = len(self.coordinates)
        if q.ndim not in (1, 2) or q.shape[-1] != nq:
            raise PinmskError(f"q must have shape ({nq},) or (N, {nq}) for coordinates "
                              f"({', '.join(self.coordinates)}), got {q.shape}")
        return q.reshape(-1, nq), q.ndim == 1

    def _place(self, q):
        N, B = q.shape[0], len(self.bodies)
        R = np.empty((N, B + 1, 3, 3))
        p = np.empty((N, B + 1, 3))
        if B:
            Rb, pb = self._placements(self.bodies, q)
            Rb, pb = np.asarray(Rb, dtype=float), np.asarray(pb, dtype=float)
            if Rb.shape != (N, B, 3, 3) or pb.shape != (N, B, 3):
                raise PinmskError(f"placements must return rotations of shape {(N, B, 3, 3)} and positions of "
                                  f"shape {(N, B, 3)} for {B} bodies; got {Rb.shape} and {pb.shape}")
            R[:, :B], p[:, :B] = Rb, pb
        R[:, B], p[:, B] = np.eye(3), 0.0
        return R, p

    # -- one path over frames ------------------------------------------------------------------
    def _wrap_path(self, c: _Compiled, q, R, p, arc_t=None) -> _State:
        """The wrapped path over frames; with ``arc_t`` (k,) also the points of each taken arc at
        those fractions of it (:attr:`_State.curve`)."""
        N, P, W, S = q.shape[0], c.P, c.W, c.S
        curve = None if arc_t is None else (np.zeros((N, W, len(arc_t), 3)), np.zeros((N, W, len(arc_t), 3)))
        Lp, active = c.point_locals(q)
        L = np.zeros((N, S, 3))
        L[:, :P] = Lp
        cache = _Cache(_to_ground(R, p, c.slot_body, L), P, self.match_opensim and W > 1)
        order = _compact(np.broadcast_to(np.arange(S), (N, S)).copy(),
                         np.concatenate([active, np.zeros((N, 2 * W), dtype=bool)], axis=1))
        arc = np.zeros((N, W))
        if W:
            Rw = np.einsum("nwij,wjk->nwik", R[:, c.wrap_body], c.wrap_R)
            ow = np.einsum("nwij,wj->nwi", R[:, c.wrap_body], c.wrap_t) + p[:, c.wrap_body]
            worder = np.tile(np.arange(W), (N, 1))
            result = np.zeros((N, W), dtype=int)
            running = np.ones(N, dtype=bool)
            last = np.full(N, np.inf)
            for kk in range(1 if W < 2 else _MAXPASS):
                for i in range(W):
                    for w in range(W):
                        f = np.flatnonzero(running & (worder[:, i] == w))
                        if f.size == 0:
                            continue
                        codes, returned = self._apply_wrap(c, w, f, order, cache, L, arc, active, Rw, ow, R, p,
                                                           arc_t=arc_t, curve=curve)
                        result[f, i] = codes
                        running[f[returned]] = False
                g = np.flatnonzero(running)
                length = np.full(N, np.inf)
                length[g] = cache.length(order[g], arc[g], c.slot_wrap, rows=g)
                converged = running & (np.abs(length - last) < 0.0005)
                running &= ~converged
                last = np.where(running, length, last)
                if kk == 0 and W > 1:
                    swap = running & (result[:, 0] == NO_WRAP) & (result[:, 1] == INSIDE_RADIUS)
                    if np.any(swap):
                        worder[swap, 0], worder[swap, 1] = 1, 0
                        order[swap] = _remove_slots(order[swap], P, P + 1)
                if not np.any(running):
                    break
        length = cache.length(order, arc, c.slot_wrap)
        return _State(order, L, arc, length, cache.G if cache.stale else cache.X, curve)

    def _apply_wrap(self, c, w, f, order, cache, L, arc, active, Rw, ow, R, p, arc_t=None, curve=None):
        """Wrap object w of path c over frames f (in place on order, cache, L, arc, and ``curve``, the
        arcs' points at fractions ``arc_t``, when given) -> (codes, returned)."""
        pw = c.spec.wraps[w]
        P, S = c.P, c.S
        X = cache.X
        s1, s2 = P + 2 * w, P + 2 * w + 1
        o = _remove_slots(order[f], s1, s2)
        n = f.size
        codes = np.zeros(n, dtype=int)
        returned = np.zeros(n, dtype=bool)
        if not pw.wrap.active:
            order[f] = o
            return codes, returned
        ws = 0 if pw.range[0] < 1 else pw.range[0] - 1
        we = P - 1 if pw.range[1] < 1 else pw.range[1] - 1
        ws, we = min(ws, P - 1), min(we, P - 1)
        act = active[f, ws:we + 1] if we >= ws else np.zeros((n, 0), dtype=bool)
        has = act.any(axis=1) if act.shape[1] else np.zeros(n, dtype=bool)
        returned = ~has          # OpenSim stops wrapping this path when a range has no active point
        smp = ws + np.argmax(act, axis=1) if act.shape[1] else np.zeros(n, dtype=int)
        emp = we - np.argmax(act[:, ::-1], axis=1) if act.shape[1] else np.zeros(n, dtype=int)
        start = np.argmax(o == smp[:, None], axis=1)
        end = np.argmax(o == emp[:, None], axis=1)
        best_pos = np.full(n, -1)
        best_change = np.full(n, np.inf)
        best_r1 = np.zeros((n, 3))
        best_r2 = np.zeros((n, 3))
        best_arc = np.zeros(n)
        if arc_t is not None:
            best_pts, best_nrm = np.zeros((n, len(arc_t), 3)), np.zeros((n, len(arc_t), 3))
        mandatory = np.zeros(n, dtype=bool)
        Rwf, owf = Rw[f, w], ow[f, w]
        for j in range(S - 1):
            a, b = o[:, j], o[:, j + 1]
            cand = has & ~mandatory & (start <= j) & (j < end) & (a >= 0) & (b >= 0)
            a0, b0 = np.maximum(a, 0), np.maximum(b, 0)
            cand &= ~((c.slot_wrap[a0] >= 0) & (c.slot_wrap[a0] == c.slot_wrap[b0]))
            ci = np.flatnonzero(cand)
            if ci.size == 0:
                continue
            fa, fb = X[f[ci], a0[ci]], X[f[ci], b0[ci]]
            Rc, oc = Rwf[ci], owf[ci]
            qa = np.einsum("nji,nj->ni", Rc, fa - oc)
            qb = np.einsum("nji,nj->ni", Rc, fb - oc)
            res = _wrap_segments(pw.wrap, pw.method, c.single, qa, qb)
            codes[ci] = res.code
            r1 = np.einsum("nij,nj->ni", Rc, res.r1) + oc
            r2 = np.einsum("nij,nj->ni", Rc, res.r2) + oc
            mand = res.ok & (res.code == MANDATORY_WRAP)
            wrapped = res.ok & (res.code == WRAPPED)
            change = np.full(ci.size, np.inf)
            if np.any(wrapped):
                k = np.flatnonzero(wrapped)
                ga = cache.get(f[ci[k]][:, None], a0[ci[k]][:, None])[:, 0]
                gb = cache.get(f[ci[k]][:, None], b0[ci[k]][:, None])[:, 0]
                change[k] = _norm(ga - r1[k]) + res.arc[k] + _norm(gb - r2[k]) - _norm(ga - gb)
            take = mand | (wrapped & (change < best_change[ci]))
            t = ci[take]
            best_pos[t], best_change[t] = j, change[take]
            best_r1[t], best_r2[t], best_arc[t] = r1[take], r2[take], res.arc[take]
            if arc_t is not None and t.size:
                pts, nrm = res.curve(arc_t)
                best_pts[t] = np.einsum("nij,nkj->nki", Rc[take], pts[take]) + oc[take][:, None, :]
                best_nrm[t] = np.einsum("nij,nkj->nki", Rc[take], nrm[take])
            mandatory[ci[mand]] = True
        got = best_pos >= 0
        arc[f[~got], w] = 0.0
        if np.any(got):
            g = f[got]
            X[g, s1], X[g, s2] = best_r1[got], best_r2[got]
            Rb, pb = R[g, c.wrap_body[w]], p[g, c.wrap_body[w]]
            L[g, s1] = np.einsum("nji,nj->ni", Rb, best_r1[got] - pb)
            L[g, s2] = np.einsum("nji,nj->ni", Rb, best_r2[got] - pb)
            arc[g, w] = best_arc[got]
            if arc_t is not None:
                curve[0][g, w], curve[1][g, w] = best_pts[got], best_nrm[got]
            o[got] = _insert_two(o[got], best_pos[got] + 1, s1, s2)
        order[f] = o
        return codes, returned

    # -- public evaluation -----------------------------------------------------------------
    def _states(self, q):
        R, p = self._place(q)
        return [self._wrap_path(c, q, R, p) for c in self._paths]

    def lengths(self, q) -> np.ndarray:
        """Path lengths (N, m), or (m,) for one frame."""
        q, single = self._q(q)
        out = np.stack([s.length for s in self._states(q)], axis=1)
        return out[0] if single else out

    def lengths_and_moment_arms(self, q, *, coordinates=None, step: float = 1e-6):
        """Lengths (N, m) and moment arms ``-dl/dq`` (N, m, nc) for ``coordinates`` (default all).

        The wrapped path is frozen at each frame (active points, tangent points fixed in the wrap
        objects' bodies) and the motion of each straight segment's ends, by central differences
        of step ``step`` in each coordinate, is projected on the segment's direction: OpenSim's
        ``computeMomentArm`` (a unit tension's generalized force), and ``-dl/dq`` wherever the
        tangent points are exact.
        """
        q, single = self._q(q)
        cols = self._coordinate_columns(coordinates)
        states = self._states(q)
        lengths = np.stack([s.length for s in states], axis=1)
        N, nc = q.shape[0], len(cols)
        arms = np.zeros((N, len(self._paths), nc))
        if nc:
            qp = np.repeat(q[None], 2 * nc, axis=0)
            for k, j in enumerate(cols):
                qp[2 * k, :, j] += step
                qp[2 * k + 1, :, j] -= step
            qp = qp.reshape(-1, q.shape[1])
            R, p = self._place(qp)
            rows = np.arange(N)[:, None]
            for m, (c, st) in enumerate(zip(self._paths, states)):
                Lp, _ = c.point_locals(qp)
                L = np.repeat(st.L[None], 2 * nc, axis=0).reshape(-1, c.S, 3)
                L[:, :c.P] = Lp
                X = _to_ground(R, p, c.slot_body, L).reshape(nc, 2, N, c.S, 3)
                dX = (X[:, 0] - X[:, 1]) / (2.0 * step)                    # (nc, N, S, 3)
                a, b = st.order[:, :-1], st.order[:, 1:]
                a0, b0 = np.maximum(a, 0), np.maximum(b, 0)
                wa, wb = c.slot_wrap[a0], c.slot_wrap[b0]
                use = (a >= 0) & (b >= 0) & ~((wa >= 0) & (wa == wb))
                if self.match_opensim:
                    # OpenSim applies no force between two points of one body
                    use &= c.slot_body[a0] != c.slot_body[b0]
                u = _unit(st.G[rows, b0] - st.G[rows, a0])                 # (N, S-1, 3)
                dseg = dX[:, rows, b0] - dX[:, rows, a0]                     # (nc, N, S-1, 3)
                arms[:, m, :] = -np.einsum("knsi,nsi,ns->nk", dseg, u, use.astype(float))
        if single:
            return lengths[0], arms[0]
        return lengths, arms

    def moment_arms(self, q, *, coordinates=None, step: float = 1e-6) -> np.ndarray:
        """Moment arms ``-dl/dq`` (N, m, nc) (see :meth:`lengths_and_moment_arms`)."""
        return self.lengths_and_moment_arms(q, coordinates=coordinates, step=step)[1]

    def path_points(self, q, muscle: str) -> list[np.ndarray]:
        """The ground polyline of one muscle per frame: active points and tangent points (k_n, 3) each."""
        q, _ = self._q(q)
        try:
            m = self.muscles.index(muscle)
        except ValueError:
            close = difflib.get_close_matches(muscle, self.muscles, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ModelError(f"no path for muscle {muscle!r}{hint}") from None
        c = self._paths[m]
        R, p = self._place(q)
        st = self._wrap_path(c, q, R, p)
        X = _to_ground(R, p, c.slot_body, st.L)
        return [X[n, o[o >= 0]] for n, o in enumerate(st.order)]

    def polylines(self, q, *, arc_points: int = 8, keep_length: bool = True) -> "PathPolylines":
        """Every path as a polyline in ground over frames ``q`` (N, nq) (or (nq,): N = 1), in one batch.

        The vertices of muscle i at frame n are its active points in order with, where the path wraps,
        the two tangent points and ``arc_points - 1`` points along the arc between them (the spiral
        over a cylinder, the great circle over a sphere, OpenSim's polyline over an ellipsoid -- at its
        own vertices nearest to even fractions of the turn -- and the torus's local cylinder), as
        OpenSim's ``GeometryPath::getCurrentPath`` and each ``PathWrapPoint``'s wrap path lay them.

        ``keep_length`` (default): the points along each arc are moved out along the surface's normal
        by the one distance (``lift``, a Newton solve per arc) that makes the arc's chords as long as
        the arc length the path's length is summed from, so the polyline is as long as the path:
        its length is :meth:`lengths` of the same paths with ``match_opensim=False`` (to round-off),
        which is :meth:`lengths` itself for paths with at most one wrap object (several: see the
        class docstring).  False: the arc points lie on the surface and the chords are shorter.
        """
        q, _ = self._q(q)
        k = int(arc_points)
        if k < 2:
            raise PinmskError(f"arc_points must be at least 2 (the arc's segments), got {arc_points!r}")
        arc_t = np.arange(1, k) / k
        R, p = self._place(q)
        N = q.shape[0]
        rows = np.arange(N)[:, None]
        parts = []
        for c in self._paths:
            st = self._wrap_path(c, q, R, p, arc_t=arc_t if c.W else None)
            P, W, S = c.P, c.W, c.S
            X = _to_ground(R, p, c.slot_body, st.L)                            # (N, S, 3) where the path lies
            lift = np.zeros((N, W))
            if W:
                C, Nrm = st.curve
                taken = np.stack([np.any(st.order == P + 2 * w, axis=1) for w in range(W)], axis=1)
                if keep_length:
                    lift = _lift_arcs(X[:, P::2][:, :W], X[:, P + 1::2][:, :W], C, Nrm, st.arc, taken)
                C = C + lift[..., None, None] * Nrm
                pos = np.concatenate([X, C.reshape(N, W * (k - 1), 3)], axis=1)
            else:
                pos = X
            # each slot of the order expands to itself and, for a wrap's first tangent point, its arc points
            table = np.full((S, k), -1)
            table[:, 0] = np.arange(S)
            for w in range(W):
                table[P + 2 * w, 1:] = S + w * (k - 1) + np.arange(k - 1)
            ids = np.where(st.order[..., None] >= 0, table[np.maximum(st.order, 0)], -1).reshape(N, -1)
            ids = _compact(ids, ids >= 0)
            counts = np.sum(ids >= 0, axis=1)
            ids = ids[:, :max(int(counts.max()), 1)]
            pts = pos[rows, np.maximum(ids, 0)]
            last = pts[np.arange(N), counts - 1]
            pts = np.where((ids >= 0)[..., None], pts, last[:, None, :])
            sources = np.where(ids >= S, ARC_POINT, ids)
            parts.append((pts, counts, sources, np.max(lift, axis=1, initial=0.0)))
        K = max(pt.shape[1] for pt, *_ in parts)
        points = np.empty((N, len(parts), K, 3))
        sources = np.full((N, len(parts), K), -1)
        for i, (pt, cnt, src, _) in enumerate(parts):
            points[:, i, :pt.shape[1]] = pt
            points[:, i, pt.shape[1]:] = pt[:, -1:]
            sources[:, i, :src.shape[1]] = src
        return PathPolylines(muscles=self.muscles, points=points, counts=np.stack([p[1] for p in parts], axis=1),
                             sources=sources, lift=np.stack([p[3] for p in parts], axis=1))

    def _coordinate_columns(self, coordinates):
        if coordinates is None:
            return list(range(len(self.coordinates)))
        cols = []
        for name in coordinates:
            if name not in self.coordinates:
                close = difflib.get_close_matches(str(name), self.coordinates, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise ModelError(f"no coordinate {name!r} among the paths' coordinates{hint}")
            cols.append(self.coordinates.index(name))
        return cols


#: :attr:`PathPolylines.sources` of a point along a wrap's arc (-1: padding)
ARC_POINT = -2


@dataclass(frozen=True, eq=False)
class PathPolylines:
    """Muscle paths as polylines in ground over N frames (:meth:`GeometricPaths.polylines`).

    ``points`` (N, m, K, 3): muscle i's vertices at frame n in order, ``counts[n, i]`` of them; the
    rest repeat the last one (zero-length segments), so every frame has K vertices.  ``sources``
    (N, m, K): what each vertex is -- ``p`` in 0..P-1 the path's point p (in its spec's order),
    ``P + 2w`` and ``P + 2w + 1`` the first and second tangent points on its wrap object w,
    :data:`ARC_POINT` a point along an arc, -1 padding.  ``lift`` (N, m): the largest distance (m)
    the arc points were moved off their surfaces to keep the polyline's length (0 without wraps).
    """

    muscles: tuple
    points: np.ndarray
    counts: np.ndarray
    sources: np.ndarray
    lift: np.ndarray

    def lengths(self) -> np.ndarray:
        """The polylines' lengths (N, m), summed over their segments."""
        return np.sum(_norm(np.diff(self.points, axis=2)), axis=2)

    def of(self, muscle: str) -> tuple[np.ndarray, np.ndarray]:
        """``(points (N, K, 3), counts (N,))`` of one muscle."""
        if muscle not in self.muscles:
            close = difflib.get_close_matches(str(muscle), self.muscles, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ModelError(f"no path for muscle {muscle!r}{hint}")
        i = self.muscles.index(muscle)
        return self.points[:, i], self.counts[:, i]


def _lift_arcs(T1, T2, C, Nrm, arc, taken, iterations: int = 50):
    """Offsets s (N, W) along the normals Nrm of the arc points C (N, W, k-1, 3) that make the chords
    T1 -> C + s Nrm -> T2 as long as ``arc`` (N, W), where ``taken``.  The chords' length is convex in
    s, so Newton's method from s = 0 (chords <= arc) converges from above after its first step."""
    ends = np.zeros(T1.shape[:2] + (1, 3))
    s = np.zeros(arc.shape)
    D = np.diff(np.concatenate([ends, Nrm, ends], axis=2), axis=2)
    todo = taken.copy()
    for _ in range(iterations):
        V = np.concatenate([T1[:, :, None], C + s[..., None, None] * Nrm, T2[:, :, None]], axis=2)
        d = np.diff(V, axis=2)
        seg = _norm(d)
        f = np.sum(seg, axis=2) - arc
        fp = np.sum(_dot(d, D) / np.where(seg > 0.0, seg, 1.0), axis=2)
        todo &= (np.abs(f) > 1e-15 * np.maximum(arc, 1.0)) & (fp > 0.0)
        if not np.any(todo):
            break
        s = np.where(todo, s - f / np.where(todo, fp, 1.0), s)
    return np.where(taken, s, 0.0)


# --------------------------------------------------------------------------------------------
# polynomial surrogates (OpenSim's PolynomialPathFitter, PredSim)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PolynomialFitReport:
    """How well one muscle's polynomial reproduces its geometric path on held-out poses (m)."""

    muscle: str
    coordinates: tuple
    degree: int
    n_terms: int
    length_max: float
    length_rms: float
    moment_arm_max: float
    moment_arm_rms: float
    n_train: int
    n_test: int

    def line(self) -> str:
        return (f"{self.muscle}: degree {self.degree} in {', '.join(self.coordinates) or 'no coordinate'} "
                f"({self.n_terms} terms): length error max {1e3 * self.length_max:.3f} mm, rms "
                f"{1e3 * self.length_rms:.3f} mm; moment-arm error max {1e3 * self.moment_arm_max:.3f} mm, rms "
                f"{1e3 * self.moment_arm_rms:.3f} mm ({self.n_test} held-out poses)")


def sample_poses(ranges: Mapping[str, tuple], coordinates: Sequence[str], n: int, *, seed: int = 0) -> np.ndarray:
    """``n`` poses (n, nq), each coordinate uniform in its range (Latin hypercube: every range is cut
    into n strata, one sample in each)."""
    rng = np.random.default_rng(seed)
    out = np.empty((int(n), len(coordinates)))
    for j, c in enumerate(coordinates):
        if c not in ranges:
            raise ModelError(f"no range for coordinate {c!r} to sample poses in")
        lo, hi = (float(v) for v in ranges[c])
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ModelError(f"coordinate {c!r}: range [{lo:g}, {hi:g}] must be finite with min <= max to sample")
        u = (rng.permutation(int(n)) + rng.random(int(n))) / int(n)
        out[:, j] = lo + (hi - lo) * u
    return out


def _monomials(k: int, degree: int) -> np.ndarray:
    """Exponents (T, k) of every monomial of total degree <= degree in k variables, by degree."""
    rows = [np.zeros(k, dtype=int)]
    for d in range(1, degree + 1):
        for combo in combinations_with_replacement(range(k), d):
            e = np.zeros(k, dtype=int)
            for v in combo:
                e[v] += 1
            rows.append(e)
    return np.array(rows, dtype=int).reshape(len(rows), k)     # k = 0: the constant term alone (a path crossing only locked coordinates)


def _design(x, scale, exps):
    """Length rows (n, T) and derivative rows d/dq_v (n, k, T) of the monomials at scaled x (n, k)."""
    n, k = x.shape
    K = int(exps.max()) if exps.size else 0
    pw = x[:, :, None] ** np.arange(K + 1)                                     # (n, k, K+1)
    parts = pw[:, np.arange(k)[None, :], exps]                                  # (n, T, k)
    A = np.prod(parts, axis=2) if k else np.ones((n, exps.shape[0]))
    D = np.zeros((n, k, exps.shape[0]))
    for v in range(k):
        dv = np.where(exps[:, v] > 0, exps[:, v] * pw[:, v, np.maximum(exps[:, v] - 1, 0)], 0.0)
        others = np.prod(np.delete(parts, v, axis=2), axis=2) if k > 1 else 1.0
        D[:, v] = dv * others / scale[v]
    return A, D


def _apply_couplings(q, names, couplings, fit_cols):
    """Set the coupled coordinates of poses ``q`` (n, nq) from their independent ones, in the order given,
    and return the Jacobian ``d q / d q[:, fit_cols]`` (n, nq, nf) of the whole pose in the sampled
    coordinates (the chain rule through each coupling)."""
    n, nq = q.shape
    J = np.zeros((n, nq, len(fit_cols)))
    J[:, fit_cols, np.arange(len(fit_cols))] = 1.0
    index = {c: j for j, c in enumerate(names)}
    for dep, indep, function, scale in couplings:
        cols = [index[c] for c in indep]
        x = q[:, cols[0]] if len(cols) == 1 else q[:, cols]
        q[:, index[dep]] = scale * function.value(x)
        J[:, index[dep]] = scale * sum(function.derivative(x, 1, k)[:, None] * J[:, j] for k, j in enumerate(cols))
    return J


def _lengths_and_total_arms(paths: GeometricPaths, q, J, fit_names, dependent, crossing):
    """Lengths (n, m) and moment arms about ``fit_names`` (n, m, nf), total derivatives through the
    couplings (``J`` = d q / d q_fit, (n, nq, nf)).  With ``crossing``, muscles are evaluated in sets
    that share no coordinate (e.g. one leg's, the other's), each differentiated only in its own
    coordinates: the finite differences' cost is per coordinate."""
    names = paths.coordinates
    every = fit_names + dependent
    jcols = [names.index(c) for c in every]
    sets = [[i] for i in range(len(paths.muscles))] if crossing is not None else [list(range(len(paths.muscles)))]
    need = [set(every) if crossing is None else set(crossing.get(paths.muscles[i], ())) & set(every)
            for i in range(len(paths.muscles))]
    merged: list[tuple[list[int], set]] = []
    for members, c in zip(sets, need if crossing is not None else [set(every)]):
        joined = [k for k, (_, s) in enumerate(merged) if s & c]
        for k in reversed(joined):
            m2, s2 = merged.pop(k)
            members, c = m2 + members, s2 | c
        merged.append((members, c))
    n = q.shape[0]
    lengths = np.zeros((n, len(paths.muscles)))
    arms = np.zeros((n, len(paths.muscles), len(fit_names)))
    for members, c in merged:
        members = sorted(members)
        sub = paths if len(members) == len(paths.muscles) else GeometricPaths(
            [paths.specs[i] for i in members], coordinates=names, placements=paths._placements,
            match_opensim=paths.match_opensim)
        use = [k for k, name in enumerate(every) if name in c]
        l, r = sub.lengths_and_moment_arms(q, coordinates=[every[k] for k in use])
        lengths[:, members] = l
        arms[:, members] = np.einsum("nmc,ncf->nmf", r, J[:, [jcols[k] for k in use]])
    return lengths, arms


def _fit_group(members, x_tr, x_te, scale, l_tr, r_tr, l_te, r_te, r_rest, *, max_degree, tolerance):
    """Polynomials of the muscles ``members`` that cross the same k coordinates (scaled poses ``x_tr``,
    ``x_te`` (n, k)), fitted together: one design matrix per degree, the muscles as right-hand sides.
    ``r_tr``/``r_te`` (n, m, k) are the moment arms about those coordinates, ``r_rest`` (n_te, m, *) the
    held-out arms about the others (the polynomial's are 0 there).  Returns ``{muscle: (degree,
    exponents, coefficients, (length max, length rms, arm max, arm rms))}``, each muscle at the lowest
    degree whose held-out errors are below ``tolerance``, else at its best one."""
    import scipy.linalg

    n_tr, k = x_tr.shape
    top = 0            # the degrees tried: 1 .. max_degree while the terms do not outnumber half the equations
    for degree in range(1, (max_degree if k else 0) + 1):
        if _monomials(k, degree).shape[0] > n_tr * (1 + k) // 2:
            break
        top = degree
    exps = _monomials(k, top)                           # by degree: a lower degree's design is a leading slice
    A_tr, D_tr = _design(x_tr, scale, exps)
    A_te, D_te = _design(x_te, scale, exps)
    total = exps.sum(axis=1)
    rest = np.abs(r_rest).max(axis=(0, 2), initial=0.0)
    rest_sq = (r_rest ** 2).sum(axis=(0, 2))
    n_arm = r_te.shape[0] * (k + r_rest.shape[2])
    todo, best = list(members), {}
    for degree in range(1 if k else 0, top + 1):
        T = int(np.count_nonzero(total <= degree))
        M = np.concatenate([A_tr[:, :T], -D_tr[:, :, :T].transpose(1, 0, 2).reshape(-1, T)])
        Y = np.concatenate([l_tr[:, todo], r_tr[:, todo].transpose(2, 0, 1).reshape(-1, len(todo))])
        # QR with column pivoting (LAPACK gelsy): the minimum-norm least-squares solution, faster than SVD
        coef = scipy.linalg.lstsq(M, Y, lapack_driver="gelsy", check_finite=False)[0]      # (T, len(todo))
        el = A_te[:, :T] @ coef - l_te[:, todo]                                              # (n_te, len(todo))
        er = -np.einsum("nvt,tm->nmv", D_te[:, :, :T], coef) - r_te[:, todo]                 # (n_te, len(todo), k)
        still = []
        for col, i in enumerate(todo):
            stats = (float(np.abs(el[:, col]).max()), float(np.sqrt(np.mean(el[:, col] ** 2))),
                     float(max(np.abs(er[:, col]).max(initial=0.0), rest[i])) if n_arm else 0.0,
                     float(np.sqrt(((er[:, col] ** 2).sum() + rest_sq[i]) / n_arm)) if n_arm else 0.0)
            worst = max(stats[0], stats[2])
            if i not in best or worst < best[i][0]:
                best[i] = (worst, degree, exps[:T], coef[:, col].copy(), stats)
            if worst >= tolerance:
                still.append(i)
        todo = still
        if not todo:
            break
    return {i: b[1:] for i, b in best.items()}


def fit_polynomial_paths(paths: GeometricPaths, *, ranges: Mapping[str, tuple], coordinates=None, couplings=(),
                         crossing: Mapping[str, Sequence[str]] | None = None, n_train: int = 2000, n_test: int = 500, max_degree: int = 6,
                         tolerance: float = 1e-4, threshold: float = 1e-6, seed: int = 0,
                         model_coordinates=None):
    """Fit each muscle's length with a polynomial in the coordinates it crosses.

    Poses are sampled in ``ranges`` (Latin hypercube) over ``coordinates``
    (default: all of ``paths.coordinates`` but the coupled ones; the others stay at 0).
    ``couplings`` -- ``(dependent, independent names, function, scale)`` each, OpenSim's
    CoordinateCouplerConstraint ``dependent = scale * function(*independent)`` (as
    :attr:`pinmsk.opensim.skeleton.CoordinateMap.couplers` holds them) -- sets each
    dependent coordinate in every pose as the model ties it, so no pose is one the model
    cannot take; the dependent coordinates are no variables of the polynomials and the
    moment arms about the independent ones are total derivatives, the coupling included
    (as OpenSim's ``MomentArmSolver`` computes them).  A muscle crosses coordinate j where
    some sampled moment arm exceeds ``threshold`` (m) and, if ``crossing`` (``{muscle:
    coordinates}``, e.g. those of the joints between its bodies) is given, j is among its
    coordinates there: OpenSim's moment arm of a path over several wrap objects is not
    always zero about a joint that moves all its bodies together (its cached tangent
    points, :class:`GeometricPaths` ``match_opensim``), while the length does not change.  Lengths and moment arms are fitted
    together by least squares (the moment arms are ``-dl/dq`` of the same polynomial); the
    degree is the lowest (1 .. ``max_degree``) whose largest length and moment-arm errors on
    ``n_test`` held-out poses are below ``tolerance`` (m), else the one with the smallest
    such error.  Returns ``(PolynomialPath, reports)``; the path's coordinates are
    ``model_coordinates`` (default ``paths.coordinates``).
    """
    from threadpoolctl import threadpool_limits

    from ..muscles.paths import PolynomialPath

    names = tuple(paths.coordinates)
    couplings = tuple(c for c in couplings if c[0] in names)
    dependent = tuple(c[0] for c in couplings)
    for dep, indep, _, _ in couplings:
        missing = [c for c in indep if c not in names]
        if missing:
            raise ModelError(f"coupling of {dep!r}: its independent coordinate(s) {missing} are not among the "
                             f"paths' coordinates")
    fit_names = tuple(c for c in names if c not in dependent) if coordinates is None else tuple(coordinates)
    tied = [c for c in fit_names if c in dependent]
    if tied:
        raise ModelError(f"coordinate(s) {tied} are coupled to others (couplings=): they are set from the "
                         "coupling in every pose, not sampled; leave them out of coordinates=")
    cols = paths._coordinate_columns(fit_names)
    model_coordinates = tuple(names if model_coordinates is None else model_coordinates)

    def poses(n, s):
        q = np.zeros((int(n), len(names)))
        q[:, cols] = sample_poses(ranges, fit_names, n, seed=s)
        return q

    q_all = np.concatenate([poses(n_train, seed), poses(n_test, seed + 1)])
    J = _apply_couplings(q_all, names, couplings, cols)
    # one evaluation of both sets: the wrapping code's cost is mostly per call, not per pose
    l_all, r_all = _lengths_and_total_arms(paths, q_all, J, fit_names, dependent, crossing)
    ntr = int(n_train)
    l_tr, r_tr, l_te, r_te = l_all[:ntr], r_all[:ntr], l_all[ntr:], r_all[ntr:]
    q_tr, q_te = q_all[:ntr], q_all[ntr:]
    # muscles crossing the same coordinates share their design matrices: one least-squares solve per
    # group and degree, with the group's muscles as right-hand sides (the same numbers as one by one)
    crossed = [tuple(k for k in range(len(cols)) if np.max(np.abs(r_tr[:, i, k]), initial=0.0) > threshold
                     and (crossing is None or fit_names[k] in crossing.get(muscle, ())))
               for i, muscle in enumerate(paths.muscles)]
    groups: dict[tuple, list[int]] = {}
    for i, c in enumerate(crossed):
        groups.setdefault(c, []).append(i)
    terms, reports = [None] * len(paths.muscles), [None] * len(paths.muscles)
    # one BLAS thread: OpenBLAS's threads slow these many mid-sized solves down several-fold on a busy
    # machine (Rajagopal's 80 muscles: 18 s with two threads, 4.4 s with one, on 2 loaded cores)
    with threadpool_limits(limits=1):
        for group, members in groups.items():
            cnames = tuple(fit_names[j] for j in group)
            lo = np.array([ranges[c][0] for c in cnames], dtype=float)
            hi = np.array([ranges[c][1] for c in cnames], dtype=float)
            center, scale = 0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 1e-9)
            sel = [cols[j] for j in group]
            others = [j for j in range(len(cols)) if j not in group]
            fits = _fit_group(members, (q_tr[:, sel] - center) / scale, (q_te[:, sel] - center) / scale, scale,
                              l_tr, r_tr[:, :, list(group)], l_te, r_te[:, :, list(group)], r_te[:, :, others],
                              max_degree=max_degree, tolerance=tolerance)
            for i, (degree, exps, coef, stats) in fits.items():
                terms[i] = {"coordinates": cnames, "center": center, "scale": scale, "exponents": exps,
                            "coefficients": coef}
                reports[i] = PolynomialFitReport(muscle=paths.muscles[i], coordinates=cnames, degree=degree,
                                                 n_terms=len(coef), length_max=stats[0], length_rms=stats[1],
                                                 moment_arm_max=stats[2], moment_arm_rms=stats[3], n_train=ntr,
                                                 n_test=int(n_test))
    path = PolynomialPath(muscles=paths.muscles, coordinates=model_coordinates, terms=terms)
    return path, tuple(reports)


def motion_ranges(q, coordinates: Sequence[str], *, margin: float = math.radians(10.0),
                  limits: Mapping[str, tuple] | None = None) -> dict[str, tuple[float, float]]:
    """Sampling ranges around a motion, as OpenSim's PolynomialPathFitter samples them: each
    coordinate's min and max over the frames ``q`` (N, nq), widened by ``margin`` (rad or m) and
    clipped to ``limits`` (the model's ranges) where given."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    out = {}
    for j, c in enumerate(coordinates):
        lo, hi = float(np.min(q[:, j])) - margin, float(np.max(q[:, j])) + margin
        if limits is not None and c in limits:
            lo, hi = max(lo, float(limits[c][0])), min(hi, float(limits[c][1]))
        out[c] = (lo, hi)
    return out
