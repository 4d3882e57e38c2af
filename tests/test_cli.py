"""The pinmsk command line: commands run, write files, and fail with one clear line."""
import subprocess
import sys

import numpy as np
import pytest

import pinmsk
from pinmsk.presentation.cli import main
from pinmsk.io.tables import read_trial, write_trial
from pinmsk.trial import Trial


def _elbow_trial(path, n=401):
    t = np.linspace(0, 2, n)
    q = np.deg2rad(120) * np.exp(-((t - 1) ** 2) / (2 * 0.25 ** 2))
    write_trial(Trial(t, {"elbow_flexion": q}), path)
    return t, q


def test_models_lists_builtins_with_counts(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert "forearm" in out and "gait2d" in out and "human3d" in out
    line = next(ln for ln in out.splitlines() if ln.startswith("gait2d"))
    assert line.split()[1:3] == ["11", "16"]


def test_info_and_unknown_model(capsys):
    assert main(["info", "forearm"]) == 0
    assert "BICLH" in capsys.readouterr().out
    assert main(["info", "forarm"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pinmsk: error:") and "did you mean 'forearm'" in err


def test_id_writes_sto_matching_library(tmp_path):
    src = tmp_path / "elbow.csv"
    _elbow_trial(src)
    out = tmp_path / "id.sto"
    assert main(["id", "forearm", str(src), "-o", str(out)]) == 0
    got = read_trial(out)
    ref = pinmsk.inverse_dynamics(pinmsk.load_model("forearm"), read_trial(src))
    # written at the default 9 significant digits
    np.testing.assert_allclose(got["elbow_flexion_moment"], ref["elbow_flexion_moment"], rtol=5e-9, atol=1e-12)
    assert main(["id", "forearm", str(src), "-o", str(out), "--precision", "17"]) == 0
    np.testing.assert_array_equal(read_trial(out)["elbow_flexion_moment"], ref["elbow_flexion_moment"])


def test_id_reports_bad_trial_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,elbow_flexon\n0,0\n0.01,0.1\n")
    assert main(["id", "forearm", str(bad), "-o", str(tmp_path / "o.sto")]) == 2
    err = capsys.readouterr().err
    assert "elbow_flexion" in err and "Traceback" not in err
    assert not (tmp_path / "o.sto").exists()
    assert main(["id", "forearm", str(tmp_path / "missing.csv"), "-o", str(tmp_path / "o.sto")]) == 2
    assert "missing.csv" in capsys.readouterr().err


def test_simulate_round_trip_through_files(tmp_path):
    src = tmp_path / "elbow.csv"
    t, q = _elbow_trial(src, n=2001)
    tau = tmp_path / "tau.sto"
    assert main(["id", "forearm", str(src), "-o", str(tau)]) == 0
    sim = tmp_path / "sim.csv"
    model = pinmsk.load_model("forearm")
    v0 = model.motion(read_trial(src)).v[0, 0]
    assert main(["simulate", "forearm", "--moments", str(tau), "--q0", f"elbow_flexion={float(q[0])!r}",
                 "--v0", f"elbow_flexion={float(v0)!r}", "-o", str(sim)]) == 0
    got = read_trial(sim)
    assert np.max(np.abs(got["elbow_flexion"] - q)) < 1e-3


def test_every_command_has_help(capsys):
    for cmd in ([], ["models"], ["info"], ["id"], ["simulate"], ["demo"], ["view"], ["batch"], ["so"], ["fso"],
                ["diagnose"], ["synth"], ["contact", "fit"], ["optimize"]):
        with pytest.raises(SystemExit) as exc:
            main([*cmd, "--help"])
        assert exc.value.code == 0, cmd
        assert "usage: pinmsk" in capsys.readouterr().out, cmd
    r = subprocess.run([sys.executable, "-m", "pinmsk", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "usage: pinmsk" in r.stdout, r.stderr


def test_so_and_fso_write_forces_matching_library(tmp_path):
    from pinmsk.solvers.analytical import gaussian_elbow_trial
    from pinmsk.solvers.static import StaticOptimization
    src = tmp_path / "gauss.csv"
    trial = gaussian_elbow_trial()
    write_trial(trial, src)
    out = tmp_path / "so.sto"
    assert main(["so", "forearm", str(src), "-o", str(out), "--exponent", "3"]) == 0
    got = read_trial(out)
    ref = StaticOptimization(exponent=3).fit(pinmsk.load_model("forearm"), read_trial(src)).result_
    for m in ("BRD", "TRILH"):
        assert np.allclose(got[f"{m}_force"], ref[f"{m}_force"], atol=1e-6)
    fso = tmp_path / "fso.csv"
    assert main(["fso", "forearm", str(src), "-o", str(fso)]) == 0
    f = read_trial(fso)
    assert "BICLH_force" in f.names and f.n_frames >= 100


def test_synth_then_diagnose_json(tmp_path, capsys):
    import json
    src = tmp_path / "syn.csv"
    assert main(["synth", "forearm", "--effect", "joint_damping:elbow_flexion:c=0.3", "--duration", "8",
                 "--seed", "3", "-o", str(src)]) == 0
    js = tmp_path / "d.json"
    assert main(["diagnose", "forearm", str(src), "--add", "joint_damping", "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    assert {"inputs", "rmse", "noise_floor", "worst_windows", "ranking", "verdict", "added", "noise_model", "refit",
                "pairs", "outside_catalog", "stopping"} <= set(d)
    assert d["inputs"]["lowpass_cutoff_hz"] == 6.0          # what was applied is in the JSON
    assert d["added"][0]["effect"] == "joint_damping"
    assert d["added"][0]["params"]["c"] == pytest.approx(0.3, rel=0.15)
    assert d["verdict"] == "at_noise_floor"
    assert main(["diagnose", "forearm", str(src), "--add", "joint_dampng"]) == 2
    assert "joint_damping" in capsys.readouterr().err
