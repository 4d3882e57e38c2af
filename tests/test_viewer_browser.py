"""The viewer in a real browser: headless Chromium loads the meshcat page served on
localhost, and we check the scene tree the page built, drive its animation, and
look at a screenshot.  Skipped (with the reason) only when Chromium is missing."""
from __future__ import annotations

import json
import time

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk.presentation.viewer import Viewer

import browser

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

DURATION = 2.0
N = 101


def _trial(model):
    t = np.linspace(0.0, DURATION, N)
    q = 1.3 - 1.2 * np.cos(np.pi * t)                 # 0.1 rad (hanging) -> 2.5 -> ...
    act = {f"{m}_activation": np.where(t < 1.0, 1.0, 0.0) for m in model.muscle_names}   # red, then blue
    return pinmsk.Trial(t, {"elbow_flexion": q}), pinmsk.Trial(t, act)


@pytest.fixture(scope="module")
def scene():
    browser.chromium_or_skip()
    model = pinmsk.load_model("forearm")
    trial, results = _trial(model)
    viewer = Viewer(model, quiet=True)
    viewer.play(trial, results=results, play=False)
    try:
        page = browser.chrome_or_skip(width=800, height=600)
    except BaseException:
        viewer.close()
        raise
    try:
        page.navigate(viewer.url)
        last_seg = viewer.muscle_paths[model.muscle_names[-1]][-1]
        js_path = json.dumps(["meshcat", "pinmsk", *last_seg.split("/"), f"c{viewer.levels - 1}", "<object>"])
        page.wait_for(f"""(() => {{ let n = viewer.scene_tree;
            for (const k of {js_path}) {{ n = n.children[k]; if (!n) return false; }}
            return n.object.type === 'Mesh' && viewer.animator.actions.length > 0; }})()""", timeout=30)
        # start and pause the actions: the slider (seek) moves only started actions
        page.evaluate("viewer.animator.play(); viewer.animator.pause(); viewer.animator.seek(0); true")
        yield model, trial, viewer, page
    finally:
        page.close()
        viewer.close()


def test_browser_scene_tree_holds_bodies_muscles_ground(scene):
    model, trial, viewer, page = scene
    tree = page.evaluate(browser.MESHCAT_SCENE_JS)
    for g in viewer.visual_model.geometryObjects:
        assert tree.get(f"/meshcat/pinmsk/model/skeleton/visuals/{g.name}/<object>") == "Mesh", g.name
    for name in model.muscle_names:
        for seg in viewer.muscle_paths[name]:
            for k in range(viewer.levels):
                assert tree.get(f"/meshcat/pinmsk/{seg}/c{k}/<object>") == "Mesh", (name, seg, k)
    assert tree.get("/meshcat/pinmsk/ground/<object>") == "Mesh"


def test_browser_animation_runs_on_the_trial_clock(scene):
    model, trial, viewer, page = scene
    anim = page.evaluate(browser.MESHCAT_ANIMATION_JS)
    sent = next(c for c in viewer.commands if c.kind == "set_animation")
    assert anim["actions"] == len(sent.detail)
    assert anim["duration"] == pytest.approx(DURATION)           # seconds: real time at timeScale 1
    # seek to a key frame and compare the forearm's placement with Pinocchio's
    k = 75
    t_k = float(trial.time[k])
    gm = viewer.visual_model
    names = [g.name for g in gm.geometryObjects]
    moving = next(g.name for g in gm.geometryObjects if g.parentJoint != 0)
    pos = page.evaluate(f"""(() => {{ viewer.animator.seek({t_k});
        const n = viewer.scene_tree.children.meshcat.children.pinmsk.children.model.children.skeleton
                  .children.visuals.children[{json.dumps(moving)}];
        return n.object.position.toArray(); }})()""")
    data, gd = model.pin.createData(), gm.createData()
    pin.forwardKinematics(model.pin, data, np.array([trial["elbow_flexion"][k]]))
    pin.updateGeometryPlacements(model.pin, data, gm, gd)
    np.testing.assert_allclose(pos, gd.oMg[names.index(moving)].translation, atol=1e-5)
    # muscle colour levels switch with the activation: top level before 1 s, bottom after
    seg = json.dumps(viewer.muscle_paths["BICLH"][0].split("/"))
    visible = f"""(t) => {{ viewer.animator.seek(t); let n = viewer.scene_tree.children.meshcat.children.pinmsk;
        for (const k of {seg}) n = n.children[k];
        return Object.keys(n.children).filter(c => n.children[c].object.visible); }}"""
    assert page.evaluate(f"({visible})(0.5)") == [f"c{viewer.levels - 1}"]
    assert page.evaluate(f"({visible})(1.5)") == ["c0"]
    page.evaluate("viewer.animator.seek(0)")


def test_screenshot_shows_the_model(scene, tmp_path):
    model, trial, viewer, page = scene
    page.evaluate("viewer.animator.seek(0)")   # activation 1: red muscles over the bones
    time.sleep(0.3)
    shot = page.screenshot(tmp_path / "forearm.png")
    rgb = browser.read_png(shot)
    assert rgb.shape == (600, 800, 3)
    assert browser.distinct_colors(rgb) > 30, "blank screenshot"
    with_model = browser.warm_fraction(rgb)
    # the same view with the model hidden: the warm (bone/muscle) pixels must go away
    viewer.vis["pinmsk/model"].set_property("visible", False)
    viewer.vis["legend"].set_property("visible", False)
    try:
        page.wait_for("!viewer.scene_tree.children.meshcat.children.pinmsk.children.model.object.visible"
                      " && !viewer.scene_tree.children.meshcat.children.legend.object.visible")
        time.sleep(0.3)
        empty = browser.warm_fraction(browser.read_png(page.screenshot(tmp_path / "empty.png")))
    finally:
        viewer.vis["pinmsk/model"].set_property("visible", True)
        viewer.vis["legend"].set_property("visible", True)
    assert with_model > 0.004, f"only {with_model:.4f} of the pixels have the model's colours"
    assert empty < 0.1 * with_model, (with_model, empty)


def test_colour_legend_is_on_screen_beside_the_model(scene, tmp_path):
    model, trial, viewer, page = scene
    # the legend is a textured card: on screen, white with every colour level on it
    box = page.evaluate("""(() => { let mesh = null;
        viewer.scene_tree.children.meshcat.children.legend.object.traverse(o => { if (o.isMesh) mesh = o; });
        mesh.updateMatrixWorld(true); mesh.geometry.computeBoundingBox();
        const b = mesh.geometry.boundingBox, V = mesh.position.constructor;
        return [[b.min.x, b.min.y], [b.max.x, b.max.y]].map(([x, y]) => {
            const v = mesh.localToWorld(new V(x, y, 0)).project(viewer.camera);
            return [(v.x + 1) / 2, (1 - v.y) / 2]; }); })()""")
    (x0, y0), (x1, y1) = box
    assert all(0.0 <= v <= 1.0 for v in (x0, y0, x1, y1)), f"the legend is off screen: {box}"
    rgb = browser.read_png(page.screenshot(tmp_path / "legend.png")).astype(float) / 255
    h, w, _ = rgb.shape
    card = rgb[int(h * min(y0, y1)):int(h * max(y0, y1)), int(w * min(x0, x1)):int(w * max(x0, x1))]
    colours = viewer._colors
    dist = np.linalg.norm(card[:, :, None] - colours[None, None], axis=-1)
    nearest = np.where(dist.min(axis=-1) < 0.15, dist.argmin(axis=-1), -1)
    seen = np.array([np.mean(nearest == k) for k in range(len(colours))])
    assert seen.min() > 0.001, f"share of the card in each colour level: {np.round(seen, 4)}"
    assert np.mean(card.min(axis=-1) > 0.9) > 0.3, "the card is not mostly white"
