"""What the diagnosis hands back: the floating-base residual report of each step, the corrected model
as a sidecar (``--save-model``) and as a copy of the user's ``.osim`` (``--save-osim``).

Checked against hand computations (the residual table), the physics of a hidden mass (the mean
vertical residual is the missing weight), ``pinmsk id`` on the same inputs, a save-reload round trip
(inverse dynamics to 1e-9, parameters equal) and, with the opensim peer, OpenSim's own inverse
dynamics of the written ``.osim``.
"""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import pinmsk
from pinmsk.components import Motion
from pinmsk.diagnose import run
from pinmsk.dynamics import inverse_dynamics_array, inverse_dynamics_result
from pinmsk.effects import registry
from pinmsk.errors import ModelError
from pinmsk.io.shared_data import shipped_trial
from pinmsk.opensim.export import write_model, write_osim
from pinmsk.presentation.cli import main
from pinmsk.presentation.report import _residual_section
from pinmsk.residuals import OPENSIM_RESIDUAL_LIMITS, residual_table

from conftest import LazyOpenSim

osim = LazyOpenSim()      # imported inside the tests that need it (tests/conftest.py)


# -- the residual table --------------------------------------------------------------------------

def test_residual_table_by_hand():
    # forces [3, -4, 5, 0] N and a moment [10, -80, 20, 30] N m; 700 N body weight, 1.8 m tall
    x = np.array([[3.0, 10.0], [-4.0, -80.0], [5.0, 20.0], [0.0, 30.0]])
    tab = residual_table(x, ("fx", "mz"), ("N", "N*m"), body_weight=700.0, height=1.8,
                         peak_external_force=800.0, com_height=1.0)
    fx, mz = tab["coordinates"]["fx"], tab["coordinates"]["mz"]
    assert fx["mean"] == pytest.approx(1.0) and fx["rms"] == pytest.approx(np.sqrt(50 / 4))
    assert fx["peak"] == 5.0 and fx["peak_signed"] == 5.0
    assert fx["mean_percent"] == pytest.approx(100 / 700) and fx["peak_percent"] == pytest.approx(500 / 700)
    assert fx["status"] == "ok" and fx["percent_of"] == "body weight"          # peak 5 <= 10, rms 3.5 <= 5
    assert mz["mean"] == pytest.approx(-5.0) and mz["peak"] == 80.0 and mz["peak_signed"] == -80.0
    assert mz["rms"] == pytest.approx(np.sqrt((100 + 6400 + 400 + 900) / 4))
    assert mz["mean_percent"] == pytest.approx(-500 / (700 * 1.8))
    assert mz["status"] == "exceeds"                                            # peak 80 > 75 N m
    assert fx["threshold_peak"] == pytest.approx(40.0) and mz["threshold_peak"] == pytest.approx(8.0)
    assert mz["relative_status"] == "exceeds" and fx["relative_status"] == "ok"
    assert not tab["ok"] and tab["frames"] == 4
    # between the good and the acceptable limits: marginal
    mid = residual_table(np.array([[12.0], [-12.0]]), ("fy",), ("N",), body_weight=700.0, height=1.8)
    assert mid["coordinates"]["fy"]["status"] == "marginal" and OPENSIM_RESIDUAL_LIMITS["N"]["peak"] == (10.0, 25.0)


@pytest.fixture(scope="module")
def gait_run():
    """gait2d's shipped walk with the HAT 10 % heavier than the model, and the HAT mass added."""
    g = pinmsk.load_model("gait2d")
    trial = pinmsk.read_trial(shipped_trial("gait2d_hat_mass.csv"))
    return g, trial, run(g, trial, add=["segment_mass:hat"])


def test_residual_report_before_and_after_the_added_mass(gait_run):
    g, trial, r = gait_run
    rep = r.residual_report()
    assert [s["model"] for s in rep["steps"]] == ["as given", "+ segment_mass:hat"]
    assert rep["body_weight_N"] == pytest.approx(g.mass * 9.81)
    before, after = (s["coordinates"]["torso_y"] for s in rep["steps"])
    # the model lacks 10 % of the HAT's mass: its weight is what the floating base holds up on average
    hat = g.pin.inertias[g.pin.frames[g.frame_id("hat")].parentJoint].mass
    assert before["mean"] == pytest.approx(-0.1 * hat * 9.81, rel=0.03)
    assert abs(after["mean"]) < 0.02 * abs(before["mean"]) and after["rms"] < 0.25 * before["rms"]
    assert before["unit"] == "N" and rep["steps"][0]["coordinates"]["torso_angle"]["unit"] == "N*m"
    # each step's residuals are what `pinmsk id` gives for that step's model over the analysed frames
    t = r.steps[0].comparison.time
    for step, entry in zip(r.steps, rep["steps"]):
        res = inverse_dynamics_result(step.model, trial)
        rows = np.isin(np.round(res.trial.time, 9), np.round(t, 9))
        assert rows.sum() == entry["frames"]
        for c, row in entry["coordinates"].items():
            x = res.trial[f"{c}_moment"][rows]
            assert row["mean"] == pytest.approx(np.mean(x), abs=1e-9)
            assert row["peak"] == pytest.approx(np.max(np.abs(x)), abs=1e-9)


def test_residual_report_in_text_json_and_html(gait_run, tmp_path):
    _, _, r = gait_run
    text = r.summary_text()
    assert "floating-base residuals" in text and "step 1: model + segment_mass:hat" in text
    assert "%BW" in text and "torso_angle" in text.split("floating-base residuals")[1]
    path = r.write_json(tmp_path / "d.json")
    js = json.loads(path.read_text())
    steps = js["residual_report"]["steps"]
    assert len(steps) == 2 and set(steps[1]["coordinates"]) == {"torso_x", "torso_y", "torso_angle"}
    assert {"mean", "rms", "peak", "unit", "mean_percent", "rms_percent", "peak_percent", "limits",
            "status"} <= set(steps[0]["coordinates"]["torso_y"])
    html = "\n".join(_residual_section(r))          # the report's section (render_report puts it in the page)
    sec = html.split("<h2>Floating-base residuals</h2>")[1]
    assert sec.count("<tr>") == 1 + 3 * 2 and "+ segment_mass:hat" in sec and "% of body weight" in sec


@pytest.mark.slow
def test_residual_section_in_the_html_report(gait_run, tmp_path):
    from pinmsk.presentation.report import write_report
    _, _, r = gait_run
    html = write_report(r, tmp_path / "r.html").read_text()
    sec = html.split("<h2>Floating-base residuals</h2>")[1].split("<h2>")[0]
    assert sec == "\n" + "\n".join(_residual_section(r)[1:]) + "\n"
    assert html.index("Floating-base residuals") < html.index("Effects added")


def test_no_residual_report_without_a_floating_base(forearm):
    r = run(forearm, pinmsk.read_trial(shipped_trial("forearm_payload.csv")))
    assert r.residual_report() is None and r.to_dict()["residual_report"] is None
    assert "floating-base residuals" not in r.summary_text()


def test_subject01_walk_means_match_pinmsk_id(shared_data):
    d = shared_data / "opensim-models" / "Gait10dof18musc"
    model = pinmsk.load_model(d / "subject01.osim", nonlinear="fit")
    trial = pinmsk.read_trial(d / "IK" / "subject01_walk_IK.mot")
    xml = d / "ExperimentalData" / "subject01_walk_grf.xml"
    r = run(model, trial, external_loads=xml)
    st = r.residual_report()["steps"][0]
    assert set(st["coordinates"]) == {"pelvis_tx", "pelvis_ty", "pelvis_tilt"}
    res = inverse_dynamics_result(model, trial, external_loads=xml)
    rows = np.isin(np.round(res.trial.time, 9), np.round(r.steps[0].comparison.time, 9))
    for c, row in st["coordinates"].items():
        x = res.trial[f"{c}_moment"][rows]
        assert row["mean"] == pytest.approx(np.mean(x), abs=1e-6)
        assert row["rms"] == pytest.approx(np.sqrt(np.mean(x * x)), abs=1e-6)
    # the pelvis-tilt mean OpenSim's ID of this walk gives: near -10 N m, large against RRA's -3.4
    assert -12.0 < st["coordinates"]["pelvis_tilt"]["mean"] < -8.0


# -- the model file --------------------------------------------------------------------------------

def _motion(model, n=9, seed=0, base=None):
    rng = np.random.default_rng(seed)
    q = 0.3 * rng.standard_normal((n, model.nq))
    if base is not None:
        q[:, base] += 1.0
    return Motion(np.linspace(0.0, 1.0, n), q, rng.standard_normal(q.shape), rng.standard_normal(q.shape))


def test_saved_sidecar_model_reads_back(forearm, tmp_path):
    r = run(forearm, pinmsk.read_trial(shipped_trial("forearm_payload_damping.csv")),
            add=["payload:hand", "joint_damping:elbow_flexion"])
    files = write_model(r.model, tmp_path / "sub" / "forearm_fixed.toml")
    back = pinmsk.load_model(files["sidecar"])
    assert [c.label for c in back.effects] == [c.label for c in r.model.effects]
    for a, b in zip(back.effects, r.model.effects):
        assert a.values == b.values
    assert back.effects[0].values["mass"] == pytest.approx(0.5, rel=0.1)     # the hidden 0.5 kg at the hand
    assert back.effects[1].values["c"] == pytest.approx(0.2, rel=0.2)        # and 0.2 N m s/rad
    m = _motion(forearm)
    assert np.max(np.abs(inverse_dynamics_array(back, m) - inverse_dynamics_array(r.model, m))) < 1e-9


def test_every_builtin_model_saves_and_reads_back(tmp_path):
    from pinmsk.builtin_models import builtin_names
    for name in builtin_names():
        m = pinmsk.load_model(name)
        back = pinmsk.load_model(write_model(m, tmp_path / f"{name}_copy.toml")["sidecar"])
        assert back.coordinates == m.coordinates and back.muscle_names == m.muscle_names, name
        assert [c.label for c in back.components] == [c.label for c in m.components], name
        assert np.array_equal(back.gravity, m.gravity), name
        mo = _motion(m, n=4, seed=2)
        assert np.max(np.abs(inverse_dynamics_array(back, mo) - inverse_dynamics_array(m, mo))) < 1e-12, name
        if m.muscles is not None:
            q = mo.q
            assert np.allclose(back.muscles.moment_arms(q), m.muscles.moment_arms(q), rtol=0, atol=1e-15), name


def test_saved_imported_model_keeps_the_import(tmp_path, shared_data):
    src = shared_data / "opensim-models" / "Arm26" / "arm26.osim"
    m = pinmsk.load_model(src)
    fixed = m.with_effect(registry.get("payload")("r_radius_styloid", mass=1.5),
                          registry.get("joint_damping")("r_elbow_flex", c=0.5).for_model(m))
    files = write_model(fixed, tmp_path / "arm26_fixed.toml")
    assert {"urdf", "sidecar", "markers", "report"} <= set(files)
    back = pinmsk.load_model(files["sidecar"])
    assert back.coordinates == m.coordinates and back.muscle_names == m.muscle_names
    have = {c.label: c.values for c in back.effects}
    assert all(have[c.label] == c.values for c in fixed.effects)
    mo = _motion(m)
    assert np.max(np.abs(inverse_dynamics_array(back, mo) - inverse_dynamics_array(fixed, mo))) < 1e-9


def test_saved_exact_knee_model_keeps_its_coordinate_map(tmp_path, shared_data):
    d = shared_data / "opensim-models" / "Gait10dof18musc"
    m = pinmsk.load_model(d / "subject01.osim")           # exact: dependent knee joints
    cmap = m.meta["coordinate_map"]
    if cmap is None or cmap.identity:
        pytest.fail("subject01's knees are expected to import as dependent joints")
    fixed = m.with_effect(registry.get("segment_mass")("torso", delta=0.05))
    back = pinmsk.load_model(write_model(fixed, tmp_path / "s01.toml")["sidecar"])
    assert set(back.meta["coordinate_map"].dependent) == set(cmap.dependent)
    trial = pinmsk.read_trial(d / "IK" / "subject01_walk_IK.mot")
    xml = d / "ExperimentalData" / "subject01_walk_grf.xml"
    a = pinmsk.inverse_dynamics(fixed, trial, external_loads=xml)
    b = pinmsk.inverse_dynamics(back, trial, external_loads=xml)
    for n in a.names:
        assert np.max(np.abs(a[n] - b[n])) < 1e-9, n


def test_save_model_refuses_what_it_cannot_write(forearm, tmp_path):
    with pytest.raises(ModelError, match=r"\.toml"):
        write_model(forearm, tmp_path / "x.urdf")
    with pytest.raises(ModelError, match="not imported from an OpenSim"):
        write_osim(forearm, tmp_path / "x.osim")


# -- the .osim -------------------------------------------------------------------------------------

def _arm26_fixed(shared_data):
    src = shared_data / "opensim-models" / "Arm26" / "arm26.osim"
    m = pinmsk.load_model(src)
    return src, m, m.with_effect(
        registry.get("payload")("r_radius_styloid", mass=1.5),
        registry.get("joint_damping")("r_elbow_flex", c=0.5).for_model(m),
        registry.get("joint_spring")("r_shoulder_elev", k=3.0, q0=0.2).for_model(m),
        registry.get("segment_mass")("r_humerus", delta=0.2),
        registry.get("coulomb_friction")("r_elbow_flex"))


def test_written_osim_edits_only_what_changed(tmp_path, shared_data):
    src, _, fixed = _arm26_fixed(shared_data)
    res = write_osim(fixed, tmp_path / "arm26_fixed.osim")
    assert [lab for lab, _ in res.not_exported] == ["coulomb_friction:r_elbow_flex"]
    assert any("warning" in ln and "coulomb_friction" in ln for ln in res.lines())
    root = ET.parse(res.path).getroot()
    body = {b.get("name"): b for b in root.iter("Body")}
    orig = {b.get("name"): b for b in ET.parse(src).getroot().iter("Body")}
    assert float(body["r_humerus"].find("mass").text) == pytest.approx(1.2 * float(orig["r_humerus"].find("mass").text))
    assert float(body["payload_r_radius_styloid"].find("mass").text) == 1.5
    assert body["r_humerus"].find("mass_center").text == orig["r_humerus"].find("mass_center").text
    ebcf = {f.find("coordinate").text: f.find("expression").text for f in root.iter("ExpressionBasedCoordinateForce")}
    assert ebcf == {"r_elbow_flex": "-0.5*qdot", "r_shoulder_elev": "-3.0*(q-(0.2))"}
    # byte for byte elsewhere: drop the inserted lines and the two edited ones, the rest is the source
    new, old = res.path.read_text().splitlines(), src.read_text().splitlines()
    assert len(new) == len(old) + 5 + 11 + 8
    import difflib
    changed = [ln for ln in difflib.unified_diff(old, new, lineterm="", n=0) if ln[:1] == "-" and ln[:3] != "---"]
    assert len(changed) == 2 and all("<mass>" in ln or "<inertia>" in ln for ln in changed)


def _opensim_id(path, coordinates, q, v, a):
    """OpenSim's InverseDynamicsSolver (muscles off, the other forces on) at rows of ``q, v, a`` in
    ``coordinates``' order."""
    osim.Logger.setLevelString("Off")
    om = osim.Model(str(path))
    for i in range(om.getMuscles().getSize()):
        om.getMuscles().get(i).set_appliesForce(False)
    s = om.initSystem()
    cs = om.getCoordinateSet()
    n = s.getNU()
    order = [None] * n                     # the coordinate of each mobility
    for i in range(cs.getSize()):
        for k in range(cs.getSize()):
            cs.get(k).setSpeedValue(s, 0.0)
        cs.get(i).setSpeedValue(s, 1.0)
        order[int(np.argmax([abs(s.getU().get(k)) for k in range(n)]))] = cs.get(i).getName()
    col = [list(coordinates).index(c) for c in order]
    solver = osim.InverseDynamicsSolver(om)
    out = np.empty_like(q)
    for k in range(q.shape[0]):
        for j, c in enumerate(coordinates):
            cs.get(c).setValue(s, float(q[k, j]), False)
            cs.get(c).setSpeedValue(s, float(v[k, j]))
        om.realizeVelocity(s)
        tau = solver.solve(s, osim.Vector([float(a[k, j]) for j in col]))
        for i, j in enumerate(col):
            out[k, j] = tau.get(i)
    return out


def test_written_osim_inverse_dynamics_matches_opensim(tmp_path, shared_data):
    _, m, fixed = _arm26_fixed(shared_data)
    res = write_osim(fixed, tmp_path / "arm26_fixed.osim")
    t = np.linspace(0.0, 1.0, 11)
    q = np.column_stack([0.3 + 0.4 * np.sin(2 * t), 0.5 + 0.6 * np.cos(3 * t)])
    v = np.column_stack([0.8 * np.cos(2 * t), -1.8 * np.sin(3 * t)])
    a = np.column_stack([-1.6 * np.sin(2 * t), -5.4 * np.cos(3 * t)])
    ours = inverse_dynamics_array(fixed.without("coulomb_friction:r_elbow_flex"), Motion(t, q, v, a))
    theirs = _opensim_id(res.path, m.coordinates, q, v, a)
    plain = inverse_dynamics_array(m, Motion(t, q, v, a))
    assert np.max(np.abs(ours - plain)) > 1.0                  # the effects matter
    assert np.max(np.abs(ours - theirs)) < 1e-9 * max(1.0, np.max(np.abs(ours)))


def test_written_osim_end_stop_matches_opensim(tmp_path, shared_data):
    src = shared_data / "opensim-models" / "Arm26" / "arm26.osim"
    m = pinmsk.load_model(src)
    stop = registry.get("end_stop_upper")("r_elbow_flex", stiffness=20.0, limit=1.2, transition=0.05, damping=0.3)
    fixed = m.with_effect(stop)
    res = write_osim(fixed, tmp_path / "arm26_stop.osim")
    t = np.linspace(0.0, 1.0, 21)
    q = np.column_stack([0.2 + 0 * t, 0.9 + 0.5 * t])          # the elbow runs through the stop at 1.2 rad
    v = np.column_stack([0 * t, 0.5 + 0 * t])
    a = np.zeros_like(q)
    ours = inverse_dynamics_array(fixed, Motion(t, q, v, a))
    theirs = _opensim_id(res.path, m.coordinates, q, v, a)
    plain = inverse_dynamics_array(m, Motion(t, q, v, a))
    assert np.max(np.abs(ours - plain)) > 1.0
    assert np.max(np.abs(ours - theirs)) < 1e-6 * max(1.0, np.max(np.abs(ours)))


def test_written_osim_com_offset_and_mass_match_opensim(tmp_path, shared_data):
    src = shared_data / "opensim-models" / "Arm26" / "arm26.osim"
    m = pinmsk.load_model(src)
    fixed = m.with_effect(registry.get("com_offset")("r_ulna_radius_hand", dx=0.02, dy=-0.03, dz=0.01),
                          registry.get("segment_mass")("r_ulna_radius_hand", delta=-0.1),
                          registry.get("payload")("r_humerus@com", mass=0.7),
                          registry.get("payload")("r_ulna_radius_hand@axis", mass=0.4, distance=0.31),
                          registry.get("payload")("r_humerus@point", mass=0.3, x=0.02, y=-0.1, z=0.01))
    res = write_osim(fixed, tmp_path / "arm26_com.osim")
    assert not res.not_exported
    body = {b.get("name"): b for b in ET.parse(res.path).getroot().iter("Body")}["r_ulna_radius_hand"]
    assert float(body.find("mass").text) == pytest.approx(0.9 * 1.534315)
    t = np.linspace(0.0, 1.0, 11)
    q = np.column_stack([0.3 + 0.4 * np.sin(2 * t), 0.5 + 0.6 * np.cos(3 * t)])
    v = np.column_stack([0.8 * np.cos(2 * t), -1.8 * np.sin(3 * t)])
    a = np.column_stack([-1.6 * np.sin(2 * t), -5.4 * np.cos(3 * t)])
    ours = inverse_dynamics_array(fixed, Motion(t, q, v, a))
    theirs = _opensim_id(res.path, m.coordinates, q, v, a)
    assert np.max(np.abs(ours - inverse_dynamics_array(m, Motion(t, q, v, a)))) > 0.1
    assert np.max(np.abs(ours - theirs)) < 1e-9 * max(1.0, np.max(np.abs(ours)))


def test_written_gait_osim_changes_opensim_id_as_pinmsk(tmp_path, shared_data):
    # subject01's walk model: the torso 10 % heavier (and its COM moved, when com_offset exists); OpenSim's
    # inverse dynamics of the written file changes by what pinmsk's does (the external loads cancel)
    d = shared_data / "opensim-models" / "Gait10dof18musc"
    m = pinmsk.load_model(d / "subject01.osim", nonlinear="fit")
    effs = [registry.get("segment_mass")("torso", delta=0.1)]
    if "com_offset" in registry.families():
        effs.append(registry.get("com_offset")("torso", dx=0.04, dy=-0.02, dz=0.0))
    fixed = m.with_effect(*effs)
    res = write_osim(fixed, tmp_path / "s01.osim")
    mo = m.motion(pinmsk.read_trial(d / "IK" / "subject01_walk_IK.mot"))
    k = np.arange(20, 130, 22)
    q, v, a = mo.q[k], mo.v[k], mo.a[k]
    ours = (inverse_dynamics_array(fixed, Motion(mo.t[k], q, v, a))
            - inverse_dynamics_array(m, Motion(mo.t[k], q, v, a)))
    theirs = _opensim_id(res.path, m.coordinates, q, v, a) - _opensim_id(d / "subject01.osim", m.coordinates, q, v, a)
    assert np.max(np.abs(ours)) > 5.0
    assert np.max(np.abs(ours - theirs)) < 1e-9 * np.max(np.abs(ours))


# -- the command line ------------------------------------------------------------------------------

def test_cli_save_model_then_id(tmp_path, capsys):
    trial = shipped_trial("forearm_payload.csv")
    out = tmp_path / "forearm_fixed.toml"
    assert main(["diagnose", "forearm", str(trial), "--add", "payload:hand", "--save-model", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    back = pinmsk.load_model(out)
    assert back.effects[-1].label == "payload:hand"
    assert main(["id", str(out), str(trial), "-o", str(tmp_path / "id.sto")]) == 0


def test_cli_refuses_bad_save_paths_before_any_work(tmp_path, capsys):
    trial = str(shipped_trial("forearm_payload.csv"))
    cases = [(["--save-model", str(tmp_path / "m.urdf")], ".toml"),
             (["--save-osim", str(tmp_path / "m.xml")], ".osim"),
             (["--save-osim", str(tmp_path / "m.osim")], "not an .osim"),
             (["--save-model", str(tmp_path / "nope" / "m.toml")], "nope")]
    for extra, what in cases:
        assert main(["diagnose", "forearm", trial, "--json", str(tmp_path / "d.json"), *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith("pinmsk: error:") and what in err and "Traceback" not in err
        assert not (tmp_path / "d.json").exists()


def test_cli_diagnose_arm26_saves_model_and_osim(tmp_path, shared_data, capsys):
    # a synthetic arm26 trial with 1.5 kg at the wrist and elbow damping 0.5 N m s/rad; the two effects
    # added, then saved both ways
    from pinmsk.diagnose import make_trial
    from pinmsk.io.tables import write_trial
    src = shared_data / "opensim-models" / "Arm26" / "arm26.osim"
    m = pinmsk.load_model(src)
    trial = tmp_path / "arm26.csv"
    write_trial(make_trial(m, ["payload:r_radius_styloid:mass=1.5", "joint_damping:r_elbow_flex:c=0.5"],
                           duration=6.0, seed=3), trial)
    toml, out = tmp_path / "arm26_fixed.toml", tmp_path / "arm26_fixed.osim"
    assert main(["diagnose", str(src), str(trial), "--add", "payload:r_radius_styloid",
                 "--add", "joint_damping:r_elbow_flex", "--save-model", str(toml), "--save-osim", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"wrote {toml}" in text and f"wrote {out}" in text
    root = ET.parse(out).getroot()
    payload = [b for b in root.iter("Body") if b.get("name") == "payload_r_radius_styloid"]
    assert float(payload[0].find("mass").text) == pytest.approx(1.5, rel=0.1)
    expr = [f.find("expression").text for f in root.iter("ExpressionBasedCoordinateForce")]
    assert len(expr) == 1 and float(expr[0].split("*")[0]) == pytest.approx(-0.5, rel=0.1)
    back = pinmsk.load_model(toml)
    assert {c.label for c in back.effects} >= {"payload:r_radius_styloid", "joint_damping:r_elbow_flex"}
    assert float(payload[0].find("mass").text) == back.component("payload:r_radius_styloid").values["mass"]
    assert main(["id", str(toml), str(trial), "-o", str(tmp_path / "id.sto")]) == 0
