"""Muscle paths as polylines (``GeometricPaths.polylines``) and the viewer drawing them.

Analytic cases first (a pulley over each wrap surface, conditional points at the ends of
their ranges), then like-for-like against OpenSim's ``GeometryPath::getCurrentPath`` on
arm26 (cylinders and ellipsoids, TRIlong over three objects) and gait10dof18musc
(conditional and moving points) at poses of their IK motions, then the meshcat scene
of arm26 with its paths (a local meshcat server, no browser).  The OpenSim parts skip
without the ``opensim`` package or the shared models.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import pinmsk.opensim.paths as op
from pinmsk.errors import ModelError, PinmskError
from pinmsk.io.shared_data import shared_data_dir

from conftest import import_opensim
from test_osim_paths import COORDS, placements   # "arm" turns about ground z by q[0], "slide" moves along x by q[1]

ARM26 = "Arm26/arm26.osim"
ARM26_IK = "Arm26/arm26_InverseKinematics.mot"
GAIT = "Gait10dof18musc/gait10dof18musc.osim"
GAIT_IK = "Gait10dof18musc/IK/subject01_walk_IK.mot"


R_W, D = 0.05, 0.2
PULLEYS = {
    "cylinder": (dict(radius=R_W, length=0.3), ((D, 0, 0), (-D, 0, 0))),
    "sphere": (dict(radius=R_W), ((D, 0, 0), (-D, 0, 0))),
    "ellipsoid": (dict(dimensions=(R_W, 0.7 * R_W, 1.2 * R_W)), ((D, 0, 0.01), (-D, 0, 0))),
    "torus": (dict(inner_radius=0.02, outer_radius=0.1), ((0.1, 0.05, 0.1), (0.1, 0.05, -0.1))),
}


def _pulley(kind):
    kw, (a, b) = PULLEYS[kind]
    wrap = op.WrapSpec(kind=kind, name="w", body="ground", **kw)
    spec = op.PathSpec("m", (op.PathPointSpec("ground", a, name="o"), op.PathPointSpec("arm", b, name="i")),
                       wraps=(op.PathWrapSpec(wrap),))
    return op.GeometricPaths([spec], coordinates=COORDS, placements=placements)


def _surface_residual(kind, pts):
    """How far points (in the wrap frame, here ground) lie off the surface (m, approximately)."""
    kw = PULLEYS[kind][0]
    if kind == "cylinder":
        return np.hypot(pts[..., 0], pts[..., 1]) - kw["radius"]
    if kind == "sphere":
        return np.linalg.norm(pts, axis=-1) - kw["radius"]
    if kind == "ellipsoid":
        a = np.asarray(kw["dimensions"])
        return (np.linalg.norm(pts / a, axis=-1) - 1.0) * a.min()
    raise AssertionError(kind)


#: how close to the surface the tangent points are: exact for cylinders and spheres, OpenSim's tangent
#: iteration's tolerance over an ellipsoid (its residuals' squares sum to <= 1e-8); over a torus OpenSim
#: wraps a cylinder tangent to its ring (not checked here)
ON_SURFACE = {"cylinder": 1e-12, "sphere": 1e-12, "ellipsoid": 5e-6, "torus": None}


@pytest.mark.parametrize("kind", list(PULLEYS))
def test_polyline_of_a_wrapped_pulley_is_the_path(kind):
    """Over every wrap surface: the polyline runs origin, tangent point, arc points, tangent point,
    insertion; it is as long as the path (1e-12 m); its arc points lie on the surface (on it, without
    ``keep_length``; lifted by at most ``lift``, microns, with it); and the surface chords converge
    to the arc length the path's length is summed from."""
    gp = _pulley(kind)
    th = np.linspace(-0.45, 0.45, 7)
    q = np.column_stack([th, 0 * th])
    L = gp.lengths(q)
    pl = gp.polylines(q, arc_points=8)
    wrapped = pl.counts[:, 0] > 2
    assert wrapped.sum() >= 5, "the pulley wraps"
    np.testing.assert_allclose(pl.lengths(), L, rtol=0, atol=1e-12)
    n = int(np.argmax(pl.lift[:, 0]))          # the frame whose arc moved most
    assert pl.sources[n, 0].tolist() == [0, 2] + [op.ARC_POINT] * 7 + [3, 1]
    pts = pl.points[n, 0]
    tol = ON_SURFACE[kind]
    flat = gp.polylines(q, arc_points=8, keep_length=False)
    if tol is not None:
        assert np.abs(_surface_residual(kind, pts[[1, 9]])).max() < tol          # tangent points
        lifted = _surface_residual(kind, pts[2:9])
        assert 0 < lifted.max() <= pl.lift[n, 0] + tol
        assert np.abs(_surface_residual(kind, flat.points[n, 0, 1:10])).max() < tol
    assert 0 < pl.lift.max() < 2e-5
    assert np.all(flat.lengths() <= L + 1e-15) and np.any(flat.lengths() < L - 1e-6)
    dense = gp.polylines(q, arc_points=1000, keep_length=False)
    np.testing.assert_allclose(dense.lengths(), L, rtol=0, atol=1e-9)
    # unwrapped frames: the straight line, padded with its last point
    m = int(np.flatnonzero(~wrapped)[0]) if np.any(~wrapped) else None
    if m is not None:
        assert pl.sources[m, 0, :2].tolist() == [0, 1] and np.all(pl.points[m, 0, 2:] == pl.points[m, 0, 1])


def test_conditional_point_drops_out_beyond_its_range():
    """OpenSim's ConditionalPathPoint is active for q in [min - 1e-5, max + 1e-5]."""
    cond = op.ConditionalPathPointSpec(body="ground", location=(0.0, 0.1, 0.0), coordinate="x", range=(0.0, 1.0),
                                       name="via")
    spec = op.PathSpec("m", (op.PathPointSpec("ground", (0.0, 0.0, 0.0)), cond,
                             op.PathPointSpec("slide", (0.0, 0.2, 0.0))))
    gp = op.GeometricPaths([spec], coordinates=COORDS, placements=placements)
    x = np.array([-2e-5, -0.5e-5, 0.0, 0.5, 1.0, 1.0 + 0.5e-5, 1.0 + 2e-5, 3.0])
    pl = gp.polylines(np.column_stack([0 * x, x]))
    on = np.array([False, True, True, True, True, True, False, False])
    assert pl.counts[:, 0].tolist() == np.where(on, 3, 2).tolist()
    assert [1 in s for s in pl.sources[:, 0]] == on.tolist()
    np.testing.assert_allclose(pl.points[on, 0, 1], np.tile([0.0, 0.1, 0.0], (on.sum(), 1)), atol=1e-15)
    np.testing.assert_allclose(pl.lengths(), gp.lengths(np.column_stack([0 * x, x])), atol=1e-15)


def test_polylines_refuse_bad_arguments_by_name():
    gp = _pulley("cylinder")
    with pytest.raises(PinmskError, match="arc_points must be at least 2"):
        gp.polylines(np.zeros(2), arc_points=1)
    with pytest.raises(PinmskError, match=r"q must have shape \(2,\)"):
        gp.polylines(np.zeros(3))
    with pytest.raises(ModelError, match="no path for muscle 'mm'.*did you mean 'm'"):
        gp.polylines(np.zeros(2)).of("mm")


# --- the shared models ------------------------------------------------------------------------------
def _shared(relative):
    root = shared_data_dir()
    path = None if root is None else root / "opensim-models" / relative
    if path is None or not path.is_file():
        pytest.skip(f"shared model file {relative} not available (set PINMSK_SHARED_DATA)")
    return path


def _paths(relative, *, match_opensim=True):
    """The model's geometric paths placed by OpenSim's kinematics of the XML (what the viewer uses)."""
    from pinmsk.opensim.muscle_import import osim_geometric_paths
    gp = osim_geometric_paths(_shared(relative))
    if not match_opensim:
        gp = op.GeometricPaths(gp.specs, coordinates=gp.coordinates, placements=gp._placements, match_opensim=False)
    return gp


def _poses(motion, ref, coordinates, n):
    """``n`` rows spread over an OpenSim .mot, in ``coordinates`` order (degrees -> rad for OpenSim's
    rotational coordinates)."""
    lines = _shared(motion).read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    cols = lines[h + 1].split()
    data = np.array([[float(v) for v in line.split()] for line in lines[h + 2:] if line.strip()])
    data = data[np.linspace(0, len(data) - 1, n).astype(int)]
    degrees = any(line.replace(" ", "").lower() == "indegrees=yes" for line in lines[:h])
    q = np.zeros((n, len(coordinates)))
    for j, c in enumerate(coordinates):
        q[:, j] = data[:, cols.index(c)]
        if degrees and ref.coords[c].getMotionType() == 1:         # Rotational
            q[:, j] = np.deg2rad(q[:, j])
    return q


class OsimPaths:
    """OpenSim's current paths: per muscle the labels and ground locations of getCurrentPath's points
    (a wrap's tangent points labelled ``(wrap object, 1 | 2)``) and each wrap's surface points."""

    def __init__(self, relative):
        osim, why = import_opensim()
        if osim is None:
            pytest.skip(why)
        self.osim = osim
        self.model = osim.Model(str(_shared(relative)))
        self.state = self.model.initSystem()
        cs = self.model.getCoordinateSet()
        self.coords = {cs.get(i).getName(): cs.get(i) for i in range(cs.getSize())}

    def set(self, names, row):
        for name, v in zip(names, row):
            self.coords[name].setValue(self.state, float(v), False)
        self.model.realizePosition(self.state)

    def length(self, muscle):
        return self.osim.PathActuator.safeDownCast(self.model.getForceSet().get(muscle)).getGeometryPath() \
            .getLength(self.state)

    def current(self, muscle):
        osim, s = self.osim, self.state
        fs = self.model.getForceSet()
        path = osim.PathActuator.safeDownCast(fs.get(muscle)).getGeometryPath().getCurrentPath(s)
        labels, locs, surfaces = [], [], []
        for i in range(path.getSize()):
            pt = path.get(i)
            w = osim.PathWrapPoint.safeDownCast(pt)
            frame = pt.getParentFrame()
            if w is None:
                labels.append(pt.getName())
                locs.append(pt.getLocationInGround(s).to_numpy())
                continue
            name = w.getWrapObject().getName()
            first = not labels or labels[-1] != (name, 1)
            labels.append((name, 1 if first else 2))
            # the location OpenSim keeps for the tangent point (getLocationInGround may hold an earlier pass's)
            locs.append(frame.findStationLocationInGround(s, w.getLocation(s)).to_numpy())
            wp = w.getWrapPath(s)
            if not first and wp.getSize():
                surfaces.append((name, np.array([frame.findStationLocationInGround(s, wp.get(k)).to_numpy()
                                                 for k in range(wp.getSize())])))
        return labels, np.array(locs), surfaces


def _labels(spec, sources):
    out = []
    for s in sources:
        if s >= len(spec.points):
            w, which = divmod(int(s) - len(spec.points), 2)
            out.append((spec.wraps[w].wrap.name, which + 1))
        elif s >= 0:
            out.append(spec.points[int(s)].name)
    return out


def _distance_to_polyline(pts, line):
    """Distance (k,) of each point of ``pts`` (k, 3) to the polyline ``line`` (n, 3)."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("kni,ni->kn", pts[:, None] - a, ab) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0, 1)
    closest = a + t[..., None] * ab
    return np.min(np.linalg.norm(pts[:, None] - closest, axis=2), axis=1)


@pytest.mark.parametrize("relative,motion,n", [(ARM26, ARM26_IK, 8), (GAIT, GAIT_IK, 5)])
def test_polylines_match_opensims_current_path(relative, motion, n):
    """At poses of the model's IK motion, every muscle's polyline holds the points of OpenSim's
    ``getCurrentPath`` in its order -- path points (conditional ones where active, moving ones where
    their functions put them) and each wrap's two tangent points -- at OpenSim's ground locations
    (measured: 4e-15 m); OpenSim's points over each wrap surface (the PathWrapPoint's wrap path) lie
    on the polyline's arc (measured 1e-8 m from its 400 chords); and the polyline is as long as
    OpenSim's path (measured 2e-16 m) for paths with at most one wrap object (TRIlong's three: see
    test_polyline_length_is_the_path_length)."""
    gp = _paths(relative)
    ref = OsimPaths(relative)
    q = _poses(motion, ref, gp.coordinates, n)
    pl = gp.polylines(q)
    dense = gp.polylines(q, arc_points=400, keep_length=False)
    worst_point = worst_surface = worst_length = 0.0
    n_wraps = n_conditional_off = 0
    for f, row in enumerate(q):
        ref.set(gp.coordinates, row)
        for i, spec in enumerate(gp.specs):
            labels, locs, surfaces = ref.current(spec.muscle)
            keep = (pl.sources[f, i] != op.ARC_POINT) & (pl.sources[f, i] >= 0)
            assert _labels(spec, pl.sources[f, i]) == labels, f"{spec.muscle} at frame {f}"
            worst_point = max(worst_point, float(np.abs(pl.points[f, i][keep] - locs).max()))
            n_conditional_off += sum(isinstance(p, op.ConditionalPathPointSpec) and p.name not in labels
                                     for p in spec.points)
            for name, pts in surfaces:
                w = [pw.wrap.name for pw in spec.wraps].index(name)
                start = int(np.flatnonzero(dense.sources[f, i] == len(spec.points) + 2 * w)[0])
                arc = dense.points[f, i, start:start + 401]
                worst_surface = max(worst_surface, float(_distance_to_polyline(pts, arc).max()))
                n_wraps += 1
            if len(spec.wraps) <= 1:
                worst_length = max(worst_length, abs(pl.lengths()[f, i] - ref.length(spec.muscle)))
    assert worst_point < 1e-9, worst_point
    assert worst_surface < 1e-7, worst_surface
    assert worst_length < 1e-9, worst_length
    if relative == ARM26:
        assert n_wraps >= 10                      # the test sees wraps ...
    else:
        assert n_conditional_off >= 3             # ... and conditional points out of their ranges


def test_polyline_length_is_the_path_length():
    """arm26 at 8 poses: the polyline is as long as the path the
    same code reports (1e-9 m) with ``match_opensim=False``; with OpenSim's own bookkeeping (the
    default) too for paths with at most one wrap object.  TRIlong wraps over three objects: OpenSim
    sums its length from tangent points cached before a later pass moved them, so its reported length
    is not the length of the path as it lies (the polyline): measured 3.6 mm apart here."""
    gp = _paths(ARM26)
    exact = _paths(ARM26, match_opensim=False)
    # shoulder 1.5 rad: TRIlong over two of its objects (the wrap iterations make these poses slow)
    q = np.array([[sh, el] for sh in (0.3, 1.5) for el in (0.1, 0.8, 1.5, 2.2)])
    np.testing.assert_allclose(exact.polylines(q).lengths(), exact.lengths(q), rtol=0, atol=1e-9)
    drawn, reported = gp.polylines(q).lengths(), gp.lengths(q)
    single = [i for i, s in enumerate(gp.specs) if len(s.wraps) <= 1]
    np.testing.assert_allclose(drawn[:, single], reported[:, single], rtol=0, atol=1e-9)
    multi = [i for i, s in enumerate(gp.specs) if len(s.wraps) > 1]
    assert [gp.muscles[i] for i in multi] == ["TRIlong"]
    assert 1e-4 < np.abs(drawn[:, multi] - reported[:, multi]).max() < 1e-2


def test_gait_conditional_points_follow_the_knee():
    """gait10dof18musc's knee muscles: each conditional point is in the polyline exactly while its
    coordinate is within its range widened by 1e-5 (as OpenSim, checked at the range ends)."""
    gp = _paths(GAIT)
    conds = [(i, k, p) for i, s in enumerate(gp.specs) for k, p in enumerate(s.points)
             if isinstance(p, op.ConditionalPathPointSpec)]
    assert len(conds) == 8
    ref = None
    osim, _ = import_opensim()
    if osim is not None:
        ref = OsimPaths(GAIT)
    for i, k, p in conds:
        lo, hi = p.range
        values = np.array([lo - 2e-5, lo - 0.5e-5, 0.5 * (lo + hi), hi + 0.5e-5, hi + 2e-5])
        q = np.zeros((len(values), len(gp.coordinates)))
        q[:, gp.coordinates.index("pelvis_ty")] = 1.0
        q[:, gp.coordinates.index(p.coordinate)] = values
        pl = gp.polylines(q)
        inside = [k in src for src in pl.sources[:, i]]
        assert inside == [False, True, True, True, False], f"{p.name} on {p.coordinate} in [{lo:g}, {hi:g}]"
        if ref is not None:
            for row, on in zip(q, inside):
                ref.set(gp.coordinates, row)
                assert (p.name in ref.current(gp.specs[i].muscle)[0]) == on, p.name


# --- the viewer ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def arm26_skeleton():
    from pinmsk.model import import_osim
    model, _ = import_osim(_shared(ARM26), hooks=())       # the skeleton only: no fit, quick
    return model


def test_viewer_draws_arm26_paths_moving_with_the_motion(arm26_skeleton):
    """The scene of arm26 (its skeleton-only import: the paths come from the .osim) and its IK motion
    with activations for two muscles: each of the 6 muscles is a strip of cylinders (one per polyline
    segment, ``levels`` colour meshes and a muscle-red one each) placed per frame from all frames'
    polylines (one batched call), the wrap objects are drawn, and the segments' key frames are the
    polylines' segment midpoints and lengths, which move with the motion."""
    pytest.importorskip("meshcat")
    import pinmsk
    from pinmsk.io.tables import read_trial
    from pinmsk.presentation.viewer import Viewer

    model = arm26_skeleton
    full = read_trial(_shared(ARM26_IK))
    trial = pinmsk.Trial(full.time[::6], {c: np.asarray(full[c])[::6] for c in model.coordinates})   # 21 frames
    t = np.asarray(trial.time)
    results = pinmsk.Trial(t, {"BIClong_activation": np.linspace(0, 1, len(t)), "TRIlong_activation": 0 * t})
    with Viewer(model, quiet=True) as v:
        assert sorted(v.muscle_paths) == sorted(["TRIlong", "TRIlat", "TRImed", "BIClong", "BICshort", "BRA"])
        anim = v.play(trial, results=results)
        lines = v.played_polylines
        objects = {c.path for c in v.commands if c.kind == "set_object"}
        for name, segs in v.muscle_paths.items():
            assert len(segs) == lines[name].shape[1] - 1 >= 1
            assert {f"/meshcat/pinmsk/{s}/{c}" for s in segs for c in [*(f"c{k}" for k in range(v.levels)), "red"]} \
                <= objects
        n_objects = sum(1 for p in objects if "/model/muscles/" in p)
        assert n_objects == (v.levels + 1) * sum(len(s) for s in v.muscle_paths.values())
        assert len(v.muscle_paths["BIClong"]) > 8          # over the humeral head: tangent and arc points
        for w in ("TRI", "TRIlonghh", "TRIlongglen", "BIClonghh"):
            assert f"/meshcat/pinmsk/model/skeleton/visuals/wrap_{w}" in objects
        pts = lines["BIClong"]
        assert pts.shape[0] == len(anim.clips[next(iter(anim.clips))].tracks["position"].frames)
        travel = np.linalg.norm(pts[-1] - pts[0], axis=1)
        assert travel[-1] > 0.05 and travel[0] < 1e-9          # the insertion moves, the origin does not
        seg = v.muscle_paths["BIClong"][-1]
        clip = anim.clips[next(p for p in anim.clips if p.lower() == f"/meshcat/pinmsk/{seg}")]
        np.testing.assert_allclose(clip.tracks["position"].values, 0.5 * (pts[:, -2] + pts[:, -1]), atol=1e-12)
        np.testing.assert_allclose(np.asarray(clip.tracks["scale"].values)[:, 1],
                                   np.linalg.norm(pts[:, -1] - pts[:, -2], axis=1), atol=1e-12)
        # activation colours: BIClong reaches the top level, TRIlong stays at the bottom, BRA (no
        # activation channel) stays muscle red
        def track(path):
            return anim.clips[next(p for p in anim.clips if p.lower() == f"/meshcat/pinmsk/{path}")].tracks
        assert True in track(f"{seg}/c{v.levels - 1}")["visible"].values
        assert track(f"{seg}/red")["visible"].values == [False, False]
        tri = v.muscle_paths["TRIlong"][0]
        assert set(track(f"{tri}/c0")["visible"].values) == {True}
        assert not any(p.lower().startswith("/meshcat/pinmsk/model/muscles/bra/") and "visible" in c.tracks
                       for p, c in anim.clips.items())
        assert v._level_state["muscle:BRA"] == -1 and v._level_state["muscle:TRIlong"] == 0
        # the scene the server holds (what a browser or the saved page gets)
        scene = v.scene()
        assert "animation" in scene[f"/meshcat/pinmsk/{seg}"]
        assert "object" in scene[f"/meshcat/pinmsk/{seg}/c0"]


def test_viewer_names_muscles_without_path_geometry():
    """Muscles whose paths are functions of the coordinates only (no display points): the viewer
    names them in a warning instead of leaving them out silently."""
    import pinmsk
    from pinmsk.muscles.muscle_set import MuscleSet
    from pinmsk.presentation.viewer import muscle_polylines

    model = pinmsk.load_model("forearm")
    ms = model.muscles
    bare = MuscleSet(names=ms.names, model_type=ms.model_type, mtu=ms.mtu, path=ms.path, tendon=ms.tendon)
    probe = type("Probe", (), {"muscles": bare, "meta": {}, "name": "forearm", "pin": model.pin})()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert muscle_polylines(probe) is None
        assert muscle_polylines(model) is not None
    (w,) = [w for w in caught if "no path geometry" in str(w.message)]
    assert "7 muscle(s)" in str(w.message) and "BICLH" in str(w.message) and "MomentArmPath" in str(w.message)


@pytest.mark.slow
def test_pinmsk_view_plays_an_osim_and_its_ik_motion():
    """``pinmsk view arm26.osim arm26_InverseKinematics.mot``: the full import (muscles fitted, ~5 s) and
    the motion read in degrees, played, served and stopped (--timeout).  The scene itself is checked
    without the fit by test_viewer_draws_arm26_paths_moving_with_the_motion."""
    pytest.importorskip("meshcat")
    from conftest import run_pinmsk

    out = run_pinmsk("view", _shared(ARM26), _shared(ARM26_IK), "--timeout", "0.1")
    assert "pinmsk viewer: http://127.0.0.1:" in out
    assert "pinmsk viewer: playing" in out and "(1.00 s)" in out
