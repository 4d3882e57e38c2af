"""Batch pipeline: OpenSim -> gait2d mapping, config checks, parallel runs, summary table."""
import csv
import json

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk import Trial, TrialError
import pinmsk.pipeline as pipeline_module
from pinmsk.ik import markers_trial
from pinmsk.markers import load_marker_set
from pinmsk.io.trc import write_trc
from pinmsk.pipeline import (RAJAGOPAL_HIP_OFFSET, batch, batch_cli, load_config, opensim_to_gait2d,
                             run_trial)


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def test_opensim_mapping_signs_and_hip_position(gait2d):
    n = 4
    t = np.arange(n) / 100.0
    tilt = np.array([0.0, 0.1, -0.1, 0.05])
    ch = {"pelvis_tilt": tilt, "pelvis_tx": 0.3 + t, "pelvis_ty": np.full(n, 0.95)}
    for s, k in (("r", 1.0), ("l", -1.0)):
        ch[f"hip_flexion_{s}"] = k * np.array([0.3, 0.2, 0.1, 0.0])
        ch[f"knee_angle_{s}"] = np.array([0.1, 0.5, 1.0, 0.2])
        ch[f"ankle_angle_{s}"] = np.array([0.2, -0.1, 0.0, 0.1])   # OpenSim + = dorsiflexion
    kin = opensim_to_gait2d(Trial(t, ch), gait2d)
    assert kin.names == gait2d.coordinate_order
    np.testing.assert_allclose(kin["torso_angle"], -tilt)
    np.testing.assert_allclose(kin["hip_r"], -ch["hip_flexion_r"])       # gait2d + = extension
    np.testing.assert_allclose(kin["knee_l"], ch["knee_angle_l"])
    np.testing.assert_allclose(kin["ankle_r"], -ch["ankle_angle_r"])     # gait2d + = plantarflexion
    # the gait2d hip joint lands on the OpenSim hip centre (pelvis origin + R(tilt) offset)
    ox, oy = RAJAGOPAL_HIP_OFFSET
    pm, pd = gait2d.pin, gait2d.pin.createData()
    for k in range(n):
        q = np.array([kin[c][k] for c in gait2d.coordinates])
        pin.framesForwardKinematics(pm, pd, q)
        hip = pd.oMf[gait2d.frame_id("thigh_r")].translation
        c, s = np.cos(tilt[k]), np.sin(tilt[k])
        np.testing.assert_allclose(hip[:2], [ch["pelvis_tx"][k] + c * ox - s * oy,
                                             ch["pelvis_ty"][k] + s * ox + c * oy], atol=1e-12)


def test_opensim_mapping_reads_jointset_paths(gait2d):
    t = np.arange(3) / 100.0
    names = {"pelvis_tilt": "ground_pelvis", "pelvis_tx": "ground_pelvis", "pelvis_ty": "ground_pelvis"}
    ch = {f"/jointset/{j}/{c}/value": np.zeros(3) for c, j in names.items()}
    for s in "rl":
        for c, j in ((f"hip_flexion_{s}", f"hip_{s}"), (f"knee_angle_{s}", f"walker_knee_{s}"),
                     (f"ankle_angle_{s}", f"ankle_{s}")):
            ch[f"/jointset/{j}/{c}/value"] = np.full(3, 0.1)
    kin = opensim_to_gait2d(Trial(t, ch), gait2d)
    np.testing.assert_allclose(kin["knee_r"], 0.1)
    with pytest.raises(TrialError, match=r"lacks 9 coordinate\(s\) of model 'gait2d': torso_x \(from pelvis_tx, "
                                         r"pelvis_ty, pelvis_tilt\), .*torso_angle \(from pelvis_tilt\)"):
        opensim_to_gait2d(Trial(t, {"x": np.zeros(3)}), gait2d)


def _synthetic_trc(gait2d, path, n=80):
    t = np.arange(n) / 100.0
    q = np.zeros((n, gait2d.nq))
    ix = gait2d.coordinate_index
    q[:, ix("torso_x")] = 1.1 * t
    q[:, ix("torso_y")] = 1.03 + 0.01 * np.sin(2 * np.pi * 2 * t)
    q[:, ix("hip_r")] = 0.3 * np.sin(2 * np.pi * t)
    q[:, ix("knee_r")] = 0.4 + 0.3 * np.sin(2 * np.pi * t + 1)
    q[:, ix("ankle_r")] = 0.1 * np.sin(2 * np.pi * t)
    ms = load_marker_set("gait2d").subset("csu")
    mk = markers_trial(gait2d, ms, t, q, axes="xyz")
    write_trc(mk, path, units="mm")
    return q


def test_batch_parallel_writes_folders_and_summary(gait2d, tmp_path):
    _synthetic_trc(gait2d, tmp_path / "a.trc")
    _synthetic_trc(gait2d, tmp_path / "b.trc", n=60)
    trials = [
        {"name": "a", "kind": "trc", "trc": "a.trc", "markers": "csu", "cutoff": 8.0, "body_mass": 65.0},
        {"name": "b", "kind": "trc", "trc": "b.trc", "markers": "csu", "so": False},
        {"name": "missing", "kind": "trc", "trc": "nope.trc"},
    ]
    rows = batch(trials, out=tmp_path / "out", base_dir=tmp_path, jobs=2)
    assert [r["name"] for r in rows] == ["a", "b", "missing"]
    assert rows[0]["status"] == "ok" and rows[1]["status"] == "ok"
    assert rows[2]["status"].startswith("failed: TRC file not found")
    assert rows[0]["ik_rms_mm_max"] < 1e-3          # markers in mm round to 1e-9 m in the file
    assert rows[0]["frames"] == 80 and "so_max_activation" in rows[0] and "so_max_activation" not in rows[1]
    for f in ("kinematics.sto", "inverse_dynamics.sto", "residuals.sto", "activations.sto", "summary.json",
              "moments.png", "residuals.png"):
        assert (tmp_path / "out" / "a" / f).exists()
    assert not (tmp_path / "out" / "b" / "activations.sto").exists()
    with open(tmp_path / "out" / "summary.csv") as fh:
        table = list(csv.DictReader(fh))
    assert [r["name"] for r in table] == ["a", "b", "missing"]
    # every number of the table names its unit (or is a count, a fraction, a status)
    unitless = {"name", "kind", "status", "frames", "so_max_activation", "so_reserve_frames", "ground_reaction",
                "figures", "skipped", "files"}
    units = ("_s", "_hz", "_kg", "_n", "_nm", "_nm_per_kg", "_mm_max")
    assert {"torso_x_residual_rms_n", "torso_y_residual_rms_n", "torso_angle_residual_rms_nm",
            "body_mass_kg"} <= set(table[0])
    assert [c for c in table[0] if c not in unitless and not c.endswith(units)] == []
    assert float(table[0]["body_mass_kg"]) == 65.0
    back = pinmsk.read_trial(tmp_path / "out" / "a" / "kinematics.sto")
    np.testing.assert_allclose(back["knee_r"], 0.4 + 0.3 * np.sin(2 * np.pi * back.time + 1), atol=1e-6)
    info = json.loads((tmp_path / "out" / "a" / "summary.json").read_text())
    assert set(info["residuals"]) == {"torso_x", "torso_y", "torso_angle"}


def test_batch_cli_from_config(gait2d, tmp_path):
    _synthetic_trc(gait2d, tmp_path / "a.trc", n=40)
    cfg = tmp_path / "batch.toml"
    cfg.write_text('[batch]\nmodel = "gait2d"\nout = "res"\n\n[defaults]\nmarkers = "csu"\nso = false\n\n'
                   '[[trials]]\nname = "one"\nkind = "trc"\ntrc = "a.trc"\n')
    s = batch_cli(cfg, jobs=1)
    assert s["failed"] == [] and s["table"].endswith("summary.csv")
    assert (tmp_path / "res" / "one" / "inverse_dynamics.sto").exists()


def test_config_errors(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('[[trials]]\nname = "x"\nkind = "csu"\npath = "a"\n[[trials]]\nname = "x"\nkind = "csu"\npath = "b"\n')
    with pytest.raises(TrialError, match="two trials are named 'x'"):
        load_config(p)
    p.write_text('[[trials]]\nname = "x"\nkind = "c3d"\n')
    with pytest.raises(TrialError, match="kind 'c3d'; use one of csu, opensim, trc"):
        load_config(p)
    p.write_text('[batch]\n')
    with pytest.raises(TrialError, match=r"no \[\[trials\]\]"):
        load_config(p)


def test_scheduler_needs_distributed(tmp_path):
    import importlib.util
    if importlib.util.find_spec("distributed") is not None:
        pytest.skip("distributed is installed")
    with pytest.raises(ImportError, match="pip install distributed"):
        batch([{"name": "a", "kind": "trc", "trc": "x"}], scheduler="tcp://127.0.0.1:1", jobs=1)


def test_run_trial_never_raises_on_bad_input():
    row = run_trial({"name": "z", "kind": "opensim", "coordinates": "/nonexistent.sto", "grf": "/x.mot"})
    assert row["status"].startswith("failed")


@pytest.mark.parametrize("name", ["gait_rajagopal", "gait_csu", "gait_winter"])
def test_examples_skip_cleanly_without_data(name, tmp_path, capsys):
    import importlib
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
    mod = importlib.import_module(name)
    assert mod.main(["--out", str(tmp_path / "o"), "--data", str(tmp_path / "no_data")]) == 0
    assert "absent" in capsys.readouterr().out
    assert not (tmp_path / "o").exists()


def test_interrupted_batch_leaves_complete_trial_folders_or_none(gait2d, tmp_path, monkeypatch):
    """Ctrl-C while the second trial writes its files: the first folder stays whole, the second
    (two .sto files already written) leaves nothing, not even its temporary folder."""
    _synthetic_trc(gait2d, tmp_path / "a.trc", n=40)
    trials = [{"name": n, "kind": "trc", "trc": "a.trc", "markers": "csu", "so": False, "plots": False}
              for n in ("one", "two")]
    write = pipeline_module.write_trial

    def interrupt_second_trial(trial, path, **kw):
        if path.parent.name.startswith(".two.") and path.name == "residuals.sto":
            assert (path.parent / "inverse_dynamics.sto").exists()      # mid-trial: half written
            raise KeyboardInterrupt
        return write(trial, path, **kw)

    monkeypatch.setattr(pipeline_module, "write_trial", interrupt_second_trial)
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        batch(trials, out=out, base_dir=tmp_path, jobs=1)
    assert sorted(p.name for p in out.iterdir()) == ["one"]   # no "two", no ".two.partial-*", no summary
    assert sorted(p.name for p in (out / "one").iterdir()) == [
        "done.json", "inverse_dynamics.sto", "kinematics.sto", "residuals.sto", "summary.json"]
    # a rerun finds "one" complete and runs only "two"
    before = (out / "one" / "summary.json").read_text()
    monkeypatch.setattr(pipeline_module, "write_trial", write)
    rows = batch(trials, out=out, base_dir=tmp_path, jobs=1)
    assert [(r["status"], r["skipped"]) for r in rows] == [("ok", True), ("ok", False)]
    assert (out / "one" / "summary.json").read_text() == before
    # --force replaces the complete folder only once the new one is complete
    rows = batch(trials[:1], out=out, base_dir=tmp_path, jobs=1, force=True)
    assert rows[0]["status"] == "ok" and not rows[0]["skipped"]
    assert sorted(p.name for p in out.iterdir()) == ["one", "report.html", "summary.csv", "two"]
    assert (out / "one" / "summary.json").read_text() != before          # the new run's timings
