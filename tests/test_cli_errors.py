"""Bad input on the command line: one line ``pinmsk: error: ...``, exit status 2, no output left behind.

Each test feeds one kind of bad input and checks the message names the
problem (channel, row, time, path, key) and that no output file, temporary file or
half-written set of outputs remains.
"""
import errno
import json
import os
import re
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

import pinmsk
from pinmsk.presentation.cli import main
from pinmsk.errors import ConvergenceError, ModelError, OutputError, TrialError
from pinmsk.io.tables import read_trial, write_trial
from pinmsk.io.output_files import write_json
from pinmsk.trial import Trial

from conftest import REPO

PAYLOAD = REPO / "data" / "forearm_payload.csv"


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pinmsk: error: "), err
    assert "Traceback" not in err
    return lines[0]


def _elbow_csv(path, n=201, rate=100.0):
    t = np.arange(n) / rate
    write_trial(Trial(t, {"elbow_flexion": 1.0 + 0.5 * np.sin(2 * np.pi * t)}), path)
    return path


def _payload_with(tmp_path, row: int, value: str, name="bad.csv"):
    """data/forearm_payload.csv with the measured moment of data row ``row`` replaced by ``value``."""
    lines = PAYLOAD.read_text().splitlines()
    cells = lines[1 + row].split(",")
    cells[2] = value
    lines[1 + row] = ",".join(cells)
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


# -- 1. non-finite or absurd measured moments in diagnose; JSON never holds NaN/Infinity ------

@pytest.mark.parametrize("value, kind", [("nan", "non-finite value(s) (NaN first)"),
                                         ("1e300", "implausible value(s) (1e+300 first, beyond ±1e+06)"),
                                         ("-1e300", "implausible value(s) (-1e+300 first"),
                                         ("inf", "non-finite value(s) (inf first)")])
def test_diagnose_refuses_bad_measured_moment_by_channel_row_and_time(tmp_path, capsys, value, kind):
    src = _payload_with(tmp_path, 50, value)
    js, report, plots = tmp_path / "d.json", tmp_path / "d.html", tmp_path / "figs"
    assert main(["diagnose", "forearm", str(src), "--json", str(js), "--report", str(report),
                 "--plot", str(plots)]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "channel 'elbow_flexion_moment'" in line and kind in line
    assert "at rows 50 (time 0.5 s)" in line and "bad.csv" in line
    assert not js.exists() and not report.exists() and not plots.exists()   # --plot folder removed again
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


def test_check_finite_limit_and_unloaded_centre_of_pressure():
    t = np.arange(6) / 100.0
    cop = np.array([np.nan, np.nan, 0.1, 0.2, np.nan, np.nan])        # undefined while unloaded
    tr = Trial(t, {"ground_force_px": cop, "ground_force_vy": np.array([0, 0, 500.0, 600, 0, 0])})
    assert tr.check_finite(["ground_force_px"], limit=1e6, nan_ok=True) is tr
    with pytest.raises(TrialError, match=r"'ground_force_px' has 4 non-finite value\(s\) \(NaN first\) at rows "
                                         r"0, 1, 4, 5 \(time 0 s\)"):
        tr.check_finite(["ground_force_px"])
    cop[3] = np.inf
    with pytest.raises(TrialError, match=r"1 non-finite value\(s\) \(inf first\) at rows 3 \(time 0.03 s\)"):
        Trial(t, {"ground_force_px": cop}).check_finite(nan_ok=True)
    with pytest.raises(TrialError, match=r"'ground_force_vy' has 1 implausible value\(s\) \(2e\+07 first, "
                                         r"beyond ±1e\+06\) at rows 2 \(time 0.02 s\)"):
        tr.with_channels(ground_force_vy=np.array([0, 0, 2e7, 600, 0, 0])).check_finite(limit=1e6, nan_ok=True)


def test_json_refuses_nan_and_infinity_naming_the_key(tmp_path):
    target = tmp_path / "s.json"
    for bad, key in ((float("nan"), "ranking[1].rmse_after"), (np.float64("inf"), "ranking[1].rmse_after"),
                     (np.array([1.0, -np.inf]), "ranking[1].rmse_after[1]")):
        obj = {"verdict": "ok", "ranking": [{"rmse_after": 1.0}, {"rmse_after": bad}]}
        with pytest.raises(OutputError, match=re.escape(f"refusing to write '{target}': {key} is ")):
            write_json(target, obj)
        assert list(tmp_path.iterdir()) == []
    write_json(target, {"a": [1.0, 2], "b": np.float64(0.5)})
    assert json.loads(target.read_text()) == {"a": [1.0, 2], "b": 0.5}


# -- 2. an output folder that does not exist -------------------------------------------------

def test_missing_output_folder_is_named_before_any_work(tmp_path, capsys):
    src = _elbow_csv(tmp_path / "e.csv")
    for flag, name, cmd in (("-o", "x.sto", ["id", "forearm", str(src)]),
                            ("-o", "x.csv", ["so", "forearm", str(src)]),
                            ("--json", "x.json", ["diagnose", "forearm", str(src)]),
                            ("--report", "x.html", ["so", "forearm", str(src), "-o", str(tmp_path / "so.sto")])):
        out = tmp_path / "nope" / "deeper" / name
        assert main(cmd + [flag, str(out)]) == 2, (cmd, flag)
        line = _one_error_line(capsys.readouterr().err)
        assert f"cannot write '{out}'" in line
        assert f"the folder '{tmp_path / 'nope'}' does not exist" in line and "None" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["e.csv"]     # and no so.sto from the last one


def test_plot_folder_is_created(tmp_path):
    src = _elbow_csv(tmp_path / "e.csv")
    figs = tmp_path / "new" / "figs"
    assert main(["id", "forearm", str(src), "-o", str(tmp_path / "id.sto"), "--plot", str(figs)]) == 0
    assert [p.suffix for p in figs.iterdir()] == [".png"]


# -- 3. read-only or impossible output places; all-or-nothing outputs -------------------------

def test_output_under_a_file_is_refused(tmp_path, capsys):
    """A parent that is a regular file fails for root too (permission bits do not)."""
    src = _elbow_csv(tmp_path / "e.csv")
    blocker = tmp_path / "notes.txt"
    blocker.write_text("a file, not a folder\n")
    assert main(["id", "forearm", str(src), "-o", str(blocker / "id.sto")]) == 2
    assert f"'{blocker}' is a file, not a folder" in _one_error_line(capsys.readouterr().err)
    out = tmp_path / "id.sto"
    assert main(["id", "forearm", str(src), "-o", str(out), "--plot", str(blocker / "figs")]) == 2
    assert f"'{blocker}' is a file, not a folder" in _one_error_line(capsys.readouterr().err)
    assert not out.exists()                                              # checked before the analysis
    assert sorted(p.name for p in tmp_path.iterdir()) == ["e.csv", "notes.txt"]


def test_read_only_file_system_is_refused_before_the_analysis(tmp_path, capsys, monkeypatch):
    """Simulated: the OS refuses to create files (EROFS), as a read-only mount does even for root."""
    import pinmsk.io.output_files as pio
    src = _elbow_csv(tmp_path / "e.csv")

    def refuse(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(pio.tempfile, "mkstemp", refuse)
    assert main(["id", "forearm", str(src), "-o", str(tmp_path / "id.sto")]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert f"cannot write '{tmp_path / 'id.sto'}'" in line and "Read-only file system" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["e.csv"]


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root ignores permission bits; the two tests above cover root")
def test_read_only_folder_by_permissions(tmp_path, capsys):
    src = _elbow_csv(tmp_path / "e.csv")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert main(["id", "forearm", str(src), "-o", str(ro / "id.sto")]) == 2
        assert "Permission denied" in _one_error_line(capsys.readouterr().err)
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)


def test_a_later_output_failing_removes_the_earlier_ones(tmp_path, capsys, monkeypatch):
    """The .sto is written, then the figures fail (disk full): the .sto and the new --plot folder go."""
    from pinmsk.presentation import plots
    src = _elbow_csv(tmp_path / "e.csv")
    keep = tmp_path / "old.sto"
    keep.write_text("an earlier result\n")

    def disk_full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(plots.Figure, "savefig", disk_full)
    out, figs = tmp_path / "id.sto", tmp_path / "figs"
    assert main(["id", "forearm", str(src), "-o", str(out), "--plot", str(figs)]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "No space left on device" in line and str(figs) in line
    assert not out.exists() and not figs.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["e.csv", "old.sto"]   # other files untouched
    assert keep.read_text() == "an earlier result\n"


# -- 4. a closed output pipe --------------------------------------------------------------------

def test_broken_pipe_exits_quietly():
    """``pinmsk models | head -1``: the reader is gone before pinmsk writes; no traceback.

    Status 1 is what the SIGPIPE recipe of the Python docs ("Note on SIGPIPE") returns.
    """
    p = subprocess.Popen([sys.executable, "-m", "pinmsk", "models"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, cwd=REPO)
    p.stdout.close()                      # as `head` does once it has its line
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 1
    assert err == ""


# -- 5. NaN for the viewer ---------------------------------------------------------------------

def test_view_refuses_nan_before_starting_a_server(tmp_path, capsys):
    t = np.arange(101) / 100.0
    q = 1.0 + 0.2 * t
    q[7] = np.nan
    src = tmp_path / "m.csv"
    write_trial(Trial(t, {"elbow_flexion": q}), src)
    assert main(["view", "forearm", str(src), "--no-block"]) == 2
    captured = capsys.readouterr()
    line = _one_error_line(captured.err)
    assert "channel 'elbow_flexion'" in line and "rows 7 (time 0.07 s)" in line and "NaN" in line
    assert captured.out == ""                                           # no server URL printed


# -- 6. time in milliseconds --------------------------------------------------------------------

def test_time_in_milliseconds_is_refused_and_can_be_declared(tmp_path, capsys):
    t_ms = np.arange(201) * 10.0                                        # 100 Hz written in ms
    q = 1.0 + 0.5 * np.sin(2 * np.pi * t_ms / 1000.0)
    src = tmp_path / "ms.csv"
    src.write_text("time,elbow_flexion\n" + "".join(f"{a:g},{float(b)!r}\n" for a, b in zip(t_ms, q)))
    with pytest.raises(TrialError, match=r"looks like milliseconds: its median step is 10, which in seconds "
                                         r"would be a 0\.1 Hz recording \(100 Hz if it is ms\).*"
                                         r"label the column 'Time \(ms\)', pass --time-unit ms.*time_unit='ms'"):
        read_trial(src)
    tr = read_trial(src, time_unit="ms")
    np.testing.assert_allclose(tr.time, t_ms / 1000.0)
    assert tr.rate == pytest.approx(100.0)
    assert read_trial(src, time_unit="s").time[-1] == 2000.0            # a real slow recording stays possible
    assert main(["id", "forearm", str(src), "-o", str(tmp_path / "id.sto")]) == 2
    assert "looks like milliseconds" in _one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "id.sto").exists()
    assert main(["id", "forearm", str(src), "-o", str(tmp_path / "id.sto"), "--time-unit", "ms"]) == 0
    np.testing.assert_allclose(read_trial(tmp_path / "id.sto").time, t_ms / 1000.0)
    with pytest.raises(TrialError, match="time_unit must be one of s, ms"):
        read_trial(src, time_unit="min")
    _elbow_csv(tmp_path / "ok.csv", n=11, rate=2.0)                     # 2 Hz in seconds: also refused
    with pytest.raises(TrialError, match="looks like milliseconds"):
        read_trial(tmp_path / "ok.csv")
    _elbow_csv(tmp_path / "fine.csv", n=11, rate=10.0)                  # 10 Hz: accepted as seconds
    assert read_trial(tmp_path / "fine.csv").rate == pytest.approx(10.0)


# -- 7. FSO divergence ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def payload_3s(tmp_path_factory):
    """The first 3 s of data/forearm_payload.csv (300 frames at 100 Hz)."""
    path = tmp_path_factory.mktemp("fso") / "payload3.csv"
    path.write_text("\n".join(PAYLOAD.read_text().splitlines()[:302]) + "\n")
    return path


def test_fso_unstable_sampling_is_an_error_and_the_default_tracks(payload_3s, tmp_path, capsys):
    out = tmp_path / "fso.sto"
    # 20 control points over 3 s hold the forces for 0.158 s: omega h = 3.2, the PID loop diverges
    assert main(["fso", "forearm", str(payload_3s), "--cutoff", "6", "--reserves", "--control-points", "20",
                 "-o", str(out)]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "20 control points over 3 s" in line and "unstable" in line and "control_points >= 121" in line
    assert not out.exists()
    # the default count (121 here: omega h = 0.5) tracks within 1 deg
    assert main(["fso", "forearm", str(payload_3s), "--cutoff", "6", "--reserves", "-o", str(out)]) == 0
    res = read_trial(out)
    assert res.n_frames == 121 and "diverged" not in res.names
    assert np.max(np.abs(res["elbow_flexion_error"])) < np.deg2rad(0.2)


def test_fso_allow_divergence_writes_a_flagged_result(payload_3s, tmp_path, capsys):
    out = tmp_path / "fso.sto"
    assert main(["fso", "forearm", str(payload_3s), "--cutoff", "6", "--reserves", "--control-points", "20",
                 "--allow-divergence", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    warns = [ln for ln in captured.err.splitlines() if ln.startswith("pinmsk: warning: ")]
    assert len(warns) == 2 and "unstable" in warns[0] and "tracking error of 'elbow_flexion'" in warns[1]
    assert "DIVERGED" in captured.out
    res = read_trial(out)
    bad = np.abs(res["elbow_flexion_error"]) > np.deg2rad(1.0)
    assert bad.any() and np.array_equal(res["diverged"], bad.astype(float))


def test_fso_tracking_error_above_tolerance_names_time_and_coordinate(forearm, motion):
    from pinmsk.solvers.fso import ForwardStaticOptimization, pid_spectral_radius
    with pytest.raises(ConvergenceError, match=r"tracking error of 'elbow_flexion' reached .* deg, above "
                                               r"max_tracking_error = 1e-05 deg at t = [\d.]+ s \(control point \d+\)"):
        ForwardStaticOptimization(max_tracking_error=np.deg2rad(1e-5)).fit(forearm, motion)
    fso = ForwardStaticOptimization(max_tracking_error=np.deg2rad(1e-5), allow_divergence=True)
    with pytest.warns(UserWarning, match="result kept and flagged"):
        fso.fit(forearm, motion)
    assert fso.diverged_ and fso.divergence_["coordinate"] == "elbow_flexion"
    first = fso.divergence_["control_point"]
    np.testing.assert_array_equal(fso.result_["diverged"][:first], 0.0)
    assert fso.result_["diverged"][first] == 1.0 and fso.result_.meta["diverged"].startswith("FSO:")
    # the sampled loop of the default gains (omega = 20 rad/s): stable below omega h ~ 0.67
    gains = (60.0, 1200.0, 8000.0)
    assert pid_spectral_radius(gains, 0.5 / 20) < 0.75 < 1.0 < pid_spectral_radius(gains, 0.7 / 20)


# -- 8, 9: batch (in tests/test_pipeline.py, which has the synthetic trials) -------------------

def test_batch_prints_the_reason_of_each_failed_trial(tmp_path, capsys):
    cfg = tmp_path / "batch.toml"
    cfg.write_text('[batch]\nmodel = "gait2d"\nout = "res"\njobs = 1\n\n'
                   '[[trials]]\nname = "lost"\nkind = "trc"\ntrc = "nope.trc"\nmarkers = "csu"\n')
    assert main(["batch", str(cfg)]) == 1
    err = capsys.readouterr().err
    assert "failed: lost: TRC file not found" in err and "nope.trc" in err and "Traceback" not in err


# -- 10. unknown keys in a model sidecar -------------------------------------------------------

@pytest.mark.parametrize("old, new, message", [
    ("gravity = ", "gravty = ", r"unknown key 'gravty' in \[model\] \(did you mean 'gravity'\?\)"),
    ("pennation = ", "pennaton = ", r"unknown key 'pennaton' in \[\[muscles\]\] 'BRD' \(did you mean 'pennation'\?\)"),
    ("[muscle_model]", "[muscle_modle]", r"unknown table 'muscle_modle' \(did you mean 'muscle_model'\?\)"),
    ("l0 = ", "l_0 = ", r"unknown key 'l_0' in \[\[muscles\]\] 'BRD' paths.constant \(did you mean 'l0'\?\)"),
    ('tendon = "rigid"', 'tendon = "rigid"\ntendon_model = "winters_quadratic"',
     r"\[muscle_model\] tendon_model = 'winters_quadratic', but type 'thelen2003' has the 'thelen2003' tendon"),
])
def test_sidecar_typos_are_refused_with_did_you_mean(tmp_path, capsys, old, new, message):
    from pinmsk.builtin_models import builtin_dir
    shutil.copy(builtin_dir() / "forearm.urdf", tmp_path / "forearm.urdf")
    text = (builtin_dir() / "forearm.toml").read_text()
    assert old in text
    bad = tmp_path / "typo.toml"
    bad.write_text(text.replace(old, new, 1))
    with pytest.raises(ModelError, match=str(bad).replace(".", r"\.") + ": " + message):
        pinmsk.load_model(bad)
    assert main(["info", str(bad)]) == 2
    assert re.search(message, _one_error_line(capsys.readouterr().err))


def test_effect_typo_in_sidecar_is_named(tmp_path):
    from pinmsk.builtin_models import builtin_dir
    for f in ("gait2d.urdf", "gait2d.toml"):
        shutil.copy(builtin_dir() / f, tmp_path / f)
    text = (tmp_path / "gait2d.toml").read_text()
    assert 'side = "r"' in text
    (tmp_path / "gait2d.toml").write_text(text.replace('side = "r"', 'sied = "r"', 1))
    with pytest.raises(ModelError, match=r"\[\[effects\]\] #1: unknown key 'sied' in an effect of type "
                                         r"'riener_edrich_1999' \(did you mean 'side'\?\)"):
        pinmsk.load_model(tmp_path / "gait2d.toml")


def test_every_builtin_sidecar_loads_without_warnings():
    from pinmsk.builtin_models import builtin_names
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        models = {n: pinmsk.load_model(n) for n in builtin_names()}
    assert set(models) >= {"finger", "forearm", "gait2d", "human3d", "foot2d"}
    assert models["gait2d"].muscles.mtu.tendon_strain0 == 0.04   # [muscle_model] tendon_strain is used


# -- 11. bare URDF without gravity --------------------------------------------------------------

def test_bare_urdf_warns_once_about_default_gravity(tmp_path, capsys):
    from pinmsk.builtin_models import builtin_dir
    urdf = tmp_path / "arm.urdf"
    shutil.copy(builtin_dir() / "forearm.urdf", urdf)
    assert main(["info", str(urdf)]) == 0
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pinmsk: warning: ")
    assert "Pinocchio's default [0.0, 0.0, -9.81]" in lines[0] and "gravity = [0.0, -9.81, 0.0]" in lines[0]
    assert "gravity [0.0, 0.0, -9.81]" in captured.out
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.allclose(pinmsk.load_model(urdf, gravity=[0, -9.81, 0]).gravity, [0, -9.81, 0])
