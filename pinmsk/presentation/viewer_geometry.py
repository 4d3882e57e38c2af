"""Geometry helpers of the meshcat viewer (no server needed; pure numpy / Pinocchio).

Everything here is in the model's own frame unless said otherwise; the viewer
puts the whole scene under one node whose transform (:func:`up_rotation`)
turns a y-up model upright in meshcat's z-up world.

Functions
---------
up_rotation
    4x4 transform from a model frame with the given up axis to meshcat's z-up world.
lateral_axis, up_index
    which model axis points to the side / up.
segment_transform
    placement (with scale) of a unit cylinder so that it spans two points.
arrow_transforms
    shaft and head placements of an arrow from a point along a vector.
color_levels, level_of, rgb_to_int
    the discrete colour scale used for activations, forces and residuals.
fallback_geometry
    capsules for bodies that carry mass but have no visual geometry.
geometry_points
    sample points on every visual geometry at a configuration (for framing the camera).
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = [
    "up_rotation", "up_index", "lateral_axis", "left_vector", "segment_transform", "arrow_transforms",
    "color_levels", "level_of", "rgb_to_int", "fallback_geometry", "geometry_points",
]

#: Unit cylinder (meshcat's Cylinder is along its local y axis) spanned by segments.
UNIT = 1.0


def up_index(up_axis: str) -> int:
    """Index (0, 1, 2) of the model's up axis ``"x"``, ``"y"`` or ``"z"``."""
    try:
        return "xyz".index(str(up_axis).lower())
    except ValueError:
        raise ValueError(f"up_axis must be 'x', 'y' or 'z', not {up_axis!r}") from None


def up_rotation(up_axis: str) -> np.ndarray:
    """4x4 homogeneous transform taking model coordinates to meshcat's z-up world.

    ``"z"``: identity.  ``"y"`` (OpenSim convention: x forward, y up, z right):
    a rotation of +90 deg about x, so model y -> world z and model z -> world -y.
    ``"x"``: a rotation of -90 deg about y (model x -> world z).
    """
    T = np.eye(4)
    ax = up_index(up_axis)
    if ax == 1:
        T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    elif ax == 0:
        T[:3, :3] = [[0, 0, -1], [0, 1, 0], [1, 0, 0]]
    return T


def lateral_axis(up_axis: str) -> int:
    """Model axis pointing to the subject's side: z for y-up models, y for z-up, y for x-up."""
    return 2 if up_index(up_axis) == 1 else 1


def left_vector(up_axis: str) -> np.ndarray:
    """Unit vector to the subject's left in the model frame: -z for y-up (z is right),
    +y for z-up (x forward, y left), +y for x-up."""
    v = np.zeros(3)
    if up_index(up_axis) == 1:
        v[2] = -1.0
    else:
        v[1] = 1.0
    return v


def segment_transform(p0, p1, radius: float) -> np.ndarray:
    """Placement of a unit-length, unit-radius cylinder along y so that it spans ``p0 -> p1``.

    The returned 4x4 matrix includes the scaling (radius in x and z, length in
    y).  A zero-length segment gives a zero-length (invisible) cylinder at ``p0``.
    """
    p0 = np.asarray(p0, dtype=float)
    p1 = np.asarray(p1, dtype=float)
    d = p1 - p0
    length = float(np.linalg.norm(d))
    T = np.eye(4)
    T[:3, 3] = 0.5 * (p0 + p1)
    if length < 1e-12:
        T[:3, :3] = np.diag([radius, 1e-9, radius])
        return T
    R = _rotation_y_to(d / length)
    T[:3, :3] = R @ np.diag([radius, length, radius])
    return T


def _rotation_y_to(u: np.ndarray) -> np.ndarray:
    """A rotation matrix taking the unit y axis onto the unit vector ``u``."""
    y = np.array([0.0, 1.0, 0.0])
    c = float(np.dot(y, u))
    if c > 1.0 - 1e-12:
        return np.eye(3)
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    return pin.Quaternion.FromTwoVectors(y, u).toRotationMatrix()


def arrow_transforms(point, vector, *, scale: float, radius: float, head_length: float):
    """Shaft and head placements of an arrow from ``point`` along ``scale * vector``.

    The shaft is the unit cylinder of :func:`segment_transform`; the head is a
    cone of height ``head_length`` along its local y axis, unscaled, placed
    at the tip.  Arrows shorter than 1e-6 m collapse to zero size.
    """
    point = np.asarray(point, dtype=float)
    vec = scale * np.asarray(vector, dtype=float)
    length = float(np.linalg.norm(vec))
    tip = point + vec
    shaft = segment_transform(point, tip, radius)
    head = np.eye(4)
    if length < 1e-6:
        head[:3, :3] *= 1e-9
        head[:3, 3] = point
        return shaft, head
    head[:3, :3] = _rotation_y_to(vec / length)
    head[:3, 3] = tip + head[:3, :3] @ np.array([0.0, 0.5 * head_length, 0.0])
    return shaft, head


def color_levels(n: int = 8) -> np.ndarray:
    """``(n, 3)`` RGB colours in [0, 1], from low (cool blue-grey) to high (saturated red).

    Low values are blue, not grey, so a muscle at rest is still visible and
    distinct from bone; the top level is a pure warm red.
    """
    if n < 2:
        raise ValueError(f"need at least 2 colour levels, got {n}")
    stops = np.array([[0.25, 0.35, 0.85], [0.75, 0.35, 0.65], [0.95, 0.45, 0.15], [0.85, 0.05, 0.05]])
    x = np.linspace(0.0, 1.0, n)
    xs = np.linspace(0.0, 1.0, len(stops))
    return np.stack([np.interp(x, xs, stops[:, k]) for k in range(3)], axis=1)


def level_of(values, n: int) -> np.ndarray:
    """Colour level (0 .. n-1) of values in [0, 1] (clipped; NaN -> 0)."""
    v = np.nan_to_num(np.asarray(values, dtype=float), nan=0.0)
    return np.clip(np.floor(np.clip(v, 0.0, 1.0) * n), 0, n - 1).astype(int)


def rgb_to_int(rgb) -> int:
    """``[r, g, b]`` in [0, 1] -> 0xRRGGBB."""
    r, g, b = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgb[:3])
    return (r << 16) + (g << 8) + b


def fallback_geometry(pin_model: pin.Model, geom_model: pin.GeometryModel, *,
                      radius_scale: float = 0.12, color=(0.89, 0.85, 0.79, 1.0)) -> pin.GeometryModel:
    """A copy of ``geom_model`` plus a capsule for every massive body that has no visual.

    The capsule of joint ``j`` runs from the joint origin to the mean of its
    child joints' origins, or to twice the centre of mass when it has no
    children; its radius is ``radius_scale`` times its length (at least 1 cm).
    """
    import coal

    out = geom_model.copy()
    has_visual = {g.parentJoint for g in geom_model.geometryObjects}
    children: dict[int, list[int]] = {}
    for j in range(1, pin_model.njoints):
        children.setdefault(pin_model.parents[j], []).append(j)
    for j in range(1, pin_model.njoints):
        inertia = pin_model.inertias[j]
        if j in has_visual or inertia.mass <= 0:
            continue
        kids = children.get(j, [])
        if kids:
            end = np.mean([pin_model.jointPlacements[k].translation for k in kids], axis=0)
        else:
            end = 2.0 * np.asarray(inertia.lever)
        length = float(np.linalg.norm(end))
        if length < 1e-4:
            geom = coal.Sphere(0.03)
            placement = pin.SE3.Identity()
        else:
            radius = max(0.01, radius_scale * length)
            body = max(length - 2 * radius, 1e-3)
            geom = coal.Capsule(radius, body)
            R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), end / length).toRotationMatrix()
            placement = pin.SE3(R, 0.5 * end)
        obj = pin.GeometryObject(f"{pin_model.names[j]}_capsule", j, placement, geom)
        obj.meshColor = np.asarray(color, dtype=float)
        out.addGeometryObject(obj)
    return out


def geometry_points(pin_model: pin.Model, geom_model: pin.GeometryModel, q) -> np.ndarray:
    """Corner points of each visual's bounding box at ``q`` in the model frame, ``(k, 3)``.

    Used to frame the camera and to find the ground height of fixed-base models;
    joint origins are included so a model without geometry still gives points.
    """
    data = pin_model.createData()
    gdata = geom_model.createData()
    pin.forwardKinematics(pin_model, data, np.asarray(q, dtype=float))
    pin.updateGeometryPlacements(pin_model, data, geom_model, gdata)
    pts = [np.asarray(data.oMi[j].translation) for j in range(pin_model.njoints)]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    for k, g in enumerate(geom_model.geometryObjects):
        half = _half_extent(g)
        M = gdata.oMg[k]
        for c in corners * half:
            pts.append(M.rotation @ c + M.translation)
    return np.array(pts)


def _half_extent(g: pin.GeometryObject) -> np.ndarray:
    """Half sizes of a geometry's local bounding box (meshes come scaled from Pinocchio)."""
    try:
        g.geometry.computeLocalAABB()
        bb = g.geometry.aabb_local
        half = np.maximum(np.abs(np.asarray(bb.min_)), np.abs(np.asarray(bb.max_)))
    except Exception:  # pragma: no cover - geometry types without an AABB
        half = np.full(3, 0.05)
    return np.nan_to_num(np.minimum(half, 10.0), nan=0.05, posinf=0.05, neginf=0.05)
