"""Viewer tests without a browser: geometry helpers, the commands sent to meshcat and
the scene the meshcat server holds (read back from the server, not from our own log)."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk.presentation import viewer_geometry as vg
from pinmsk.errors import ModelError, TrialError
from pinmsk.presentation.viewer import Viewer, contact_spheres, parse_static_scene, view_cli

from conftest import REPO

pytest.importorskip("meshcat")


# --------------------------------------------------------------- geometry

def test_up_rotation_stands_y_up_models_up():
    T = vg.up_rotation("y")
    np.testing.assert_allclose(T[:3, :3] @ [0, 1, 0], [0, 0, 1])   # model up -> world up
    np.testing.assert_allclose(T[:3, :3] @ [1, 0, 0], [1, 0, 0])   # forward stays forward
    np.testing.assert_allclose(T[:3, :3] @ [0, 0, 1], [0, -1, 0])  # right -> world -y
    assert np.isclose(np.linalg.det(T[:3, :3]), 1.0)
    np.testing.assert_allclose(vg.up_rotation("z"), np.eye(4))
    np.testing.assert_allclose(vg.up_rotation("x")[:3, :3] @ [1, 0, 0], [0, 0, 1])
    with pytest.raises(ValueError, match="up_axis"):
        vg.up_rotation("w")


@pytest.mark.parametrize("p0, p1", [([0, 0, 0], [0, 1, 0]), ([0.1, 0.2, 0.3], [-0.4, 0.0, 0.9]),
                                    ([0, 0, 0], [0, -2, 0]), ([1, 1, 1], [1, 1, 1])])
def test_segment_transform_spans_its_end_points(p0, p1):
    T = vg.segment_transform(p0, p1, 0.01)
    ends = [T @ [0, -0.5, 0, 1], T @ [0, 0.5, 0, 1]]
    np.testing.assert_allclose(ends[0][:3], p0, atol=1e-9)
    np.testing.assert_allclose(ends[1][:3], p1, atol=1e-9)
    if not np.allclose(p0, p1):  # radius: the x column has length 0.01, orthogonal to the axis
        assert np.isclose(np.linalg.norm(T[:3, 0]), 0.01)
        assert abs(np.dot(T[:3, 0], np.subtract(p1, p0))) < 1e-12


def test_arrow_length_is_scaled_force():
    shaft, head = vg.arrow_transforms([0.1, 0, 0], [0, 700.0, 0], scale=1e-3, radius=0.01, head_length=0.05)
    np.testing.assert_allclose((shaft @ [0, 0.5, 0, 1])[:3], [0.1, 0.7, 0])     # tip at p + s F
    np.testing.assert_allclose(head[:3, 3], [0.1, 0.725, 0])                    # cone past the tip
    shaft, head = vg.arrow_transforms([0, 0, 0], [0, 0, 0], scale=1.0, radius=0.01, head_length=0.05)
    assert np.abs(head[:3, :3]).max() < 1e-6


def test_color_levels_run_blue_to_red_and_levels_clip():
    c = vg.color_levels(8)
    assert c.shape == (8, 3)
    assert c[0, 2] > c[0, 0] and c[-1, 0] > c[-1, 2] + 0.5          # cold start, warm end
    np.testing.assert_array_equal(vg.level_of([-1, 0, 0.5, 0.999, 1, 7, np.nan], 8), [0, 0, 4, 7, 7, 7, 0])
    assert vg.rgb_to_int([1, 0, 0]) == 0xFF0000
    with pytest.raises(ValueError):
        vg.color_levels(1)


def test_fallback_geometry_adds_capsules_to_bodies_without_visuals():
    m = pin.Model()
    j1 = m.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "j1")
    m.appendBodyToJoint(j1, pin.Inertia(1.0, np.array([0, -0.2, 0]), np.eye(3) * 0.01), pin.SE3.Identity())
    j2 = m.addJoint(j1, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([0, -0.4, 0])), "j2")
    m.appendBodyToJoint(j2, pin.Inertia(0.5, np.array([0, -0.1, 0]), np.eye(3) * 0.01), pin.SE3.Identity())
    gm = vg.fallback_geometry(m, pin.GeometryModel())
    assert [g.name for g in gm.geometryObjects] == ["j1_capsule", "j2_capsule"]
    pts = vg.geometry_points(m, gm, np.zeros(2))
    assert pts[:, 1].min() < -0.55   # the second capsule reaches twice its COM below j2


# --------------------------------------------------------------- viewer

def _flexion_trial(model, *, n=101, duration=2.0, activation=True):
    t = np.linspace(0.0, duration, n)
    ch = {"elbow_flexion": 1.3 - 1.2 * np.cos(np.pi * t)}
    if activation:
        for i, name in enumerate(model.muscle_names):
            ch[f"{name}_activation"] = np.clip(np.sin(np.pi * t / duration + 0.3 * i), 0, 1)
    return pinmsk.Trial(t, ch)


@pytest.fixture(scope="module")
def forearm():
    return pinmsk.load_model("forearm")


@pytest.fixture(scope="module")
def meshcat_url(forearm):
    """The zmq address of one meshcat server shared by the tests that check what a viewer sends
    (its command log), not what a server holds: starting a server is most of a Viewer's cost."""
    with Viewer(forearm, quiet=True) as host:
        yield host.vis.window.zmq_url


@pytest.fixture
def viewer(forearm, meshcat_url):
    v = Viewer(forearm, quiet=True, zmq_url=meshcat_url)
    yield v
    v.close()


@pytest.fixture
def own_viewer(forearm):
    """A viewer on a server of its own, for reading the scene back from the server."""
    v = Viewer(forearm, quiet=True)
    yield v
    v.close()


def _paths(commands, kind):
    return {c.path for c in commands if c.kind == kind}


def test_viewer_builds_bodies_muscles_and_ground(own_viewer, forearm):
    viewer = own_viewer
    objects = _paths(viewer.commands, "set_object")
    geoms = [g.name for g in viewer.visual_model.geometryObjects]
    assert geoms, "the forearm URDF has visual geometry"
    for g in geoms:
        assert f"/meshcat/pinmsk/model/skeleton/visuals/{g}" in objects
    for name in forearm.muscle_names:
        segs = viewer.muscle_paths[name]
        assert segs, name
        for s in segs:      # muscle red until coloured; the colour levels are made at the first colour
            assert f"/meshcat/pinmsk/{s}/red" in objects
            assert f"/meshcat/pinmsk/{s}/c0" not in objects
    assert "/meshcat/pinmsk/ground" in objects
    # y-up model: the scene root turns it upright
    assert viewer.up_axis == "y"
    # the server holds the same scene (read back from meshcat, not from our log)
    scene = viewer.scene()
    for g in geoms:
        assert "object" in scene[f"/meshcat/pinmsk/model/skeleton/visuals/{g}"]
    assert "object" in scene[f"/meshcat/pinmsk/{viewer.muscle_paths['BICLH'][0]}/red"]
    viewer.display(activation={"BICLH": 0.3})
    objects = _paths(viewer.commands, "set_object")
    for name in forearm.muscle_names:
        for s in viewer.muscle_paths[name]:
            assert {f"/meshcat/pinmsk/{s}/c{k}" for k in range(viewer.levels)} <= objects


def test_ground_is_below_a_fixed_base_model(viewer):
    pts = vg.geometry_points(viewer.model.pin, viewer.visual_model, np.zeros(1))
    assert viewer.ground_height < pts[:, 1].min()
    assert viewer.ground_height > pts[:, 1].min() - 0.1


def test_display_moves_muscles_and_colours_them(viewer, forearm):
    n0 = len(viewer.commands)
    a = np.zeros(forearm.n_muscles)
    a[forearm.muscle_names.index("BICLH")] = 1.0
    viewer.display(np.array([1.5]), activation=a)
    new = viewer.commands[n0:]
    seg = viewer.muscle_paths["BICLH"][0]
    props = [(c.path, c.detail) for c in new if c.kind == "set_property"]
    assert (f"/meshcat/pinmsk/{seg}/c{viewer.levels - 1}", "visible") in props   # top level shown
    assert (f"/meshcat/pinmsk/{seg}/red", "visible") in props                    # muscle red (no value) hidden
    assert f"/meshcat/pinmsk/{seg}" in _paths(new, "set_transform")
    # forces are shown relative to f_max
    viewer.display(np.array([1.5]), force={"BICLH": 0.0})
    assert viewer._level_state["muscle:BICLH"] == 0
    with pytest.raises(ModelError, match="nq = 1"):
        viewer.display(np.zeros(3))
    viewer.display({"elbow_flexion": 0.7})
    with pytest.raises(ModelError, match="unknown coordinates.*elbow"):
        viewer.display({"elbow": 0.7})
    with pytest.raises(ModelError, match="unknown muscles.*BICEPS"):
        viewer.display(activation={"BICEPS": 1.0})


def test_muscle_segment_follows_the_display_points(viewer, forearm):
    q = np.array([1.2])
    data = forearm.pin.createData()
    pin.framesForwardKinematics(forearm.pin, data, q)
    pts = forearm.muscles.display_points["BRD"]
    a = data.oMf[forearm.pin.getFrameId(pts[0][0])].act(np.array(pts[0][1:]))
    b = data.oMf[forearm.pin.getFrameId(pts[1][0])].act(np.array(pts[1][1:]))
    radius, segs = viewer._muscle_segments["BRD"]
    T = vg.segment_transform(a, b, radius)
    np.testing.assert_allclose((T @ [0, 0.5, 0, 1])[:3], b)
    assert np.linalg.norm(b - a) > 0.05


def test_play_sends_a_real_time_animation(viewer, forearm):
    trial = _flexion_trial(forearm, n=101, duration=2.0)
    anim = viewer.play(trial)
    sent = [c for c in viewer.commands if c.kind == "set_animation"]
    assert len(sent) == 1
    animated = set(sent[0].detail)
    moving = [g.name for g in viewer.visual_model.geometryObjects if g.parentJoint != 0]
    for g in moving:
        assert f"/meshcat/pinmsk/model/skeleton/visuals/{g}" in animated
    for s in viewer.muscle_paths["BRD"]:
        assert f"/meshcat/pinmsk/{s}" in animated
        assert f"/meshcat/pinmsk/{s}/c{viewer.levels - 1}" in animated   # colour levels switch
    # key times are the trial's times in seconds at fps 1: the slider runs at real time
    clip = next(c for p, c in anim.clips.items() if p.lower().endswith(moving[0]))
    assert clip.fps == 1
    times = clip.tracks["position"].frames
    np.testing.assert_allclose(times, trial.time - trial.time[0])
    # the elbow key frame equals Pinocchio's placement at that time
    data = forearm.pin.createData()
    gm = viewer.visual_model
    gd = gm.createData()
    pin.forwardKinematics(forearm.pin, data, np.array([trial["elbow_flexion"][60]]))
    pin.updateGeometryPlacements(forearm.pin, data, gm, gd)
    k = [g.name for g in gm.geometryObjects].index(moving[0])
    np.testing.assert_allclose(clip.tracks["position"].values[60], gd.oMg[k].translation, atol=1e-12)
    # the server stored it (late browsers get it)
    scene = viewer.scene()
    assert "animation" in scene[f"/meshcat/pinmsk/model/skeleton/visuals/{moving[0]}"]


def test_play_resamples_dense_trials_and_honours_speed(viewer, forearm):
    trial = _flexion_trial(forearm, n=2001, duration=2.0, activation=False)
    anim = viewer.play(trial, fps=30, speed=2.0)
    clip = next(iter(c for p, c in anim.clips.items() if "forearm_hand" in p.lower()))
    times = np.asarray(clip.tracks["position"].frames)
    assert len(times) == 61
    assert np.isclose(times[-1], 1.0)   # 2 s played twice as fast


def test_play_with_ghost_residual_and_grf(viewer, forearm):
    t = np.linspace(0, 1, 51)
    q = 0.5 + t
    trial = pinmsk.Trial(t, {"elbow_flexion": q, "ground_force_vy": 100 + 0 * t,
                             "ground_force_px": 0.2 + 0 * t, "ground_force_py": -0.5 + 0 * t})
    sim = pinmsk.Trial(t, {"elbow_flexion": q + 0.2})
    results = pinmsk.Trial(t, {"elbow_flexion_residual": np.sin(3 * t)})
    anim = viewer.play(trial, ghost=sim, ghost_offset=0.5, results=results)
    objects = _paths(viewer.commands, "set_object")
    animated = {p.lower() for p in anim.clips}
    assert any(p.startswith("/meshcat/pinmsk/ghost/skeleton/visuals/") for p in objects)
    assert any(p.startswith("/meshcat/pinmsk/ghost/skeleton/visuals/") for p in animated)
    assert "/meshcat/pinmsk/model/residuals/elbow_flexion" in animated
    assert "/meshcat/pinmsk/grf/grf/shaft" in animated
    # ghost shifted to the subject's left (model -z for a y-up model)
    ghost_T = [c for c in viewer.commands if c.kind == "set_transform" and c.path == "/meshcat/pinmsk/ghost"]
    assert ghost_T and np.allclose(viewer._ghost_offset, [0, 0, -0.5])
    # arrow: 100 N at body weight scale
    shaft = anim.clips[next(p for p in anim.clips if p.lower() == "/meshcat/pinmsk/grf/grf/shaft")]
    length = shaft.tracks["scale"].values[0][1]
    assert np.isclose(length, 100 * viewer._grf_scale())
    # residual colour: the largest |residual| reaches the top level
    vis = anim.clips[next(p for p in anim.clips
                          if p.lower() == f"/meshcat/pinmsk/model/residuals/elbow_flexion/c{viewer.levels - 1}")]
    assert True in vis.tracks["visible"].values


def test_play_names_missing_coordinates(viewer):
    bad = pinmsk.Trial(np.linspace(0, 1, 5), {"elbow_flex": np.zeros(5)})
    with pytest.raises(TrialError, match="elbow_flexion.*did you mean 'elbow_flex'"):
        viewer.play(bad)
    with pytest.raises(TrialError, match="residual must be"):
        viewer.play(_flexion_trial(viewer.model, n=5), residual=np.zeros((3, 1)))


def test_nan_is_refused_by_name_and_nothing_is_sent(viewer, forearm):
    good = _flexion_trial(forearm, n=11)
    sent = len(viewer.commands)
    q = np.array(good["elbow_flexion"])
    q[3] = np.nan
    with pytest.raises(TrialError, match=r"channel 'elbow_flexion' has 1 non-finite value\(s\) \(NaN first\) "
                                         r"at rows 3 \(time 0.6 s\).*meshcat cannot draw NaN"):
        viewer.play(good.with_channels(elbow_flexion=q))
    act = np.array(good["BRD_activation"])
    act[5] = np.inf
    with pytest.raises(TrialError, match=r"channel 'BRD_activation' .*inf first.* rows 5 \(time 1 s\)"):
        viewer.play(good, results=pinmsk.Trial(good.time, {"BRD_activation": act}))
    res = np.zeros((11, 1))
    res[2, 0] = np.nan
    with pytest.raises(TrialError, match=r"residual of coordinate 'elbow_flexion' is nan at frame 2 \(time 0.4 s\)"):
        viewer.play(good, residual=res)
    assert len(viewer.commands) == sent                       # no NaN (nor anything else) reached meshcat
    with pytest.raises(TrialError, match=r"q: 'elbow_flexion' is nan"):
        viewer.display([np.nan])
    with pytest.raises(TrialError, match=r"activation: 'BICLH' is nan"):
        viewer.display(activation={"BICLH": np.nan})


def test_close_stops_the_server(forearm):
    v = Viewer(forearm, quiet=True)
    proc = v.vis.window.server_proc
    assert proc.poll() is None
    v.close()
    assert proc.poll() is not None
    v.close()  # twice is fine


def test_viewer_prints_url_and_does_not_open_a_browser(forearm, capsys, monkeypatch):
    import webbrowser
    opened = []
    monkeypatch.setattr(webbrowser, "open", lambda *a, **k: opened.append(a))
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with Viewer(forearm, open_browser=True) as v:
        out = capsys.readouterr().out
        assert f"pinmsk viewer: {v.url}" in out
        assert v.url.startswith("http://127.0.0.1:")
        assert "no display found" in out
    assert opened == []


def test_jupyter_cell_embeds_the_url(viewer):
    html = viewer.jupyter_cell(height=300)
    assert viewer.url in html.data and "300px" in html.data
    assert viewer.url in viewer._repr_html_()


def test_view_cli_plays_files(tmp_path, forearm, capsys):
    trial = _flexion_trial(forearm, n=21, activation=False)
    results = pinmsk.Trial(trial.time, {f"{n}_force": np.full(21, 100.0) for n in forearm.muscle_names})
    tp, rp = tmp_path / "motion.sto", tmp_path / "so.sto"
    pinmsk.write_trial(trial, tp)
    pinmsk.write_trial(results, rp)
    v = view_cli("forearm", str(tp), str(rp), block=False)
    try:
        out = capsys.readouterr().out
        assert v.url in out
        assert any(c.kind == "set_animation" for c in v.commands)
    finally:
        v.close()
    v = view_cli("forearm", block=True, timeout=0.2)   # returns after stopping the server
    assert v.vis.window.server_proc.poll() is not None
    with pytest.raises(TrialError, match="--results needs a TRIAL"):
        view_cli("forearm", None, str(rp), block=False)


def test_contact_spheres_are_read_from_contact_components(forearm):
    class Sphere:
        kind = "contact"
        label = "contact:hand"
        frame = "hand"
        position = (0.0, -0.02, 0.0)
        radius = 0.03

    class FakeModel:
        pin = forearm.pin
        contacts = (Sphere(),)

    [(label, fid, pos, radius)] = contact_spheres(FakeModel())
    assert label == "contact:hand" and fid == forearm.pin.getFrameId("hand")
    np.testing.assert_allclose(pos, [0, -0.02, 0])
    assert radius == 0.03


def test_parse_static_scene_reads_meshcat_commands():
    import base64

    import umsgpack
    cmd = umsgpack.packb({"type": "set_object", "path": "/meshcat/a", "object": {}})
    html = f'fetch("data:application/octet-binary;base64,{base64.b64encode(cmd).decode()}")'
    assert parse_static_scene(html) == {"/meshcat/a": {"object"}}


@pytest.mark.parametrize("name", ["gait2d", "human3d", "finger"])
def test_other_builtin_models_build(name, meshcat_url):
    model = pinmsk.load_model(name)       # a built-in model that fails to load is a failure
    with Viewer(model, quiet=True, zmq_url=meshcat_url) as v:
        assert v.visual_model.ngeoms > 0
        objects = _paths(v.commands, "set_object")
        for g in v.visual_model.geometryObjects:
            assert f"/meshcat/pinmsk/model/skeleton/visuals/{g.name}" in objects
        if name == "human3d":   # meshes from example-robot-data
            meshes = [g for g in v.visual_model.geometryObjects if g.meshPath.lower().endswith(".stl")]
            assert len(meshes) >= 20
            assert "example-robot-data" in meshes[0].meshPath
            # bodies with mass but no mesh (the clavicles) get capsules
            assert all(g.name.endswith("_capsule") for g in v.visual_model.geometryObjects
                       if g not in meshes)
        if name == "gait2d":    # a floating model stands on the world's ground y = 0
            assert v.ground_height == 0.0
        t = np.linspace(0, 0.5, 11)
        ch = {c: np.zeros_like(t) for c in model.coordinates}
        v.play(pinmsk.Trial(t, ch))
        assert any(c.kind == "set_animation" for c in v.commands)


# view_gait2d.py and view_human3d.py run in tests/test_examples_covered.py; view_forearm.py runs here,
# in a real subprocess without a terminal
def test_example_without_terminal_exits_by_itself():
    # a generic "run every example" harness passes no flags and has no terminal
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    res = subprocess.run([sys.executable, str(REPO / "examples" / "view_forearm.py")], stdin=subprocess.DEVNULL,
                         capture_output=True, text=True, timeout=120, env=env, cwd=REPO)
    assert res.returncode == 0, res.stderr
    assert "http://127.0.0.1:" in res.stdout and "not serving" in res.stdout


# --------------------------------------------------------------- colour legend

def test_legend_bar_runs_from_level_0_at_the_bottom_to_the_top_level():
    import matplotlib.image as mpimg
    import io as _io
    from pinmsk.presentation.viewer import legend_png

    colors = vg.color_levels(8)
    rgb = mpimg.imread(_io.BytesIO(legend_png(colors, "activation")), format="png")[..., :3]
    h, w, _ = rgb.shape
    assert w / h == pytest.approx(pinmsk.presentation.viewer.LEGEND_ASPECT, rel=0.02)
    # the bar's column: the one where the most pixels match some level's colour
    dist = np.linalg.norm(rgb[:, :, None, :] - colors[None, None], axis=-1)       # (h, w, levels)
    match = dist.min(axis=-1) < 0.02
    col = int(np.argmax(match.sum(axis=0)))
    rows = np.flatnonzero(match[:, col])
    levels = dist[rows, col].argmin(axis=-1)
    assert set(levels) == set(range(8))                      # every level is shown
    assert levels[0] == 7 and levels[-1] == 0                # image rows run top-down: 1 on top
    assert np.all(np.diff(levels) <= 0)                      # monotone up the bar


def test_legend_is_drawn_with_colours_and_labelled_by_what_they_mean(viewer, forearm):
    viewer.display()
    assert not any(c.path.endswith("/legend") for c in viewer.commands if c.kind == "set_object")
    viewer.display(activation={forearm.muscle_names[0]: 0.5})
    assert viewer._legend == "activation"
    assert any(c.path == "/meshcat/legend" for c in viewer.commands if c.kind == "set_object")
    t = np.linspace(0, 1, 11)
    forces = pinmsk.Trial(t, {f"{forearm.muscle_names[0]}_force": 10 * t})
    viewer.play(_flexion_trial(forearm, n=11, duration=1.0, activation=False), results=forces)
    assert viewer._legend == "force / max isometric force"
