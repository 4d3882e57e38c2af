"""Batch runs: resume from done markers, --force, shards, per-trial lines, the HTML report, Dask."""
import csv
import importlib.util
import re

import numpy as np
import pytest

import pinmsk
from pinmsk import TrialError
from pinmsk.pipeline import DONE, batch, batch_cli, parse_shard, shard_indices
from pinmsk.presentation.cli import main

from test_pipeline import _synthetic_trc

#: Row entries that are the run's own timings or its resume flag (not results).
_NOT_RESULTS = re.compile(r"^time_|^skipped$")


def _results(row):
    return {k: v for k, v in row.items() if not _NOT_RESULTS.match(k)}


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def _trials(names, **kw):
    return [{"name": n, "kind": "trc", "trc": f"{n}.trc", "markers": "csu", "so": False, "plots": False,
             "body_mass": 60.0, **kw} for n in names]


def _write_inputs(gait2d, folder, names, n=30):
    for k, name in enumerate(names):
        _synthetic_trc(gait2d, folder / f"{name}.trc", n=n + 2 * k)


def test_rerun_skips_done_trials_and_reruns_changed_inputs_or_options(gait2d, tmp_path):
    _write_inputs(gait2d, tmp_path, ["a", "b"])
    trials = _trials(["a", "b"])
    out = tmp_path / "out"
    first = batch(trials, out=out, base_dir=tmp_path, jobs=1)
    assert [r["skipped"] for r in first] == [False, False]
    id_a = (out / "a" / "inverse_dynamics.sto").read_bytes()

    again = batch(trials, out=out, base_dir=tmp_path, jobs=1)
    assert [r["skipped"] for r in again] == [True, True]
    assert [_results(r) for r in again] == [_results(r) for r in first]
    assert [r["time_total_s"] for r in again] == [r["time_total_s"] for r in first]   # the stored run's
    assert (out / "a" / "inverse_dynamics.sto").read_bytes() == id_a

    # a changed input file reruns its trial only; a changed option reruns its trial only
    _synthetic_trc(gait2d, tmp_path / "a.trc", n=35)
    trials[1]["cutoff"] = 4.0
    third = batch(trials, out=out, base_dir=tmp_path, jobs=1)
    assert [r["skipped"] for r in third] == [False, False]
    assert third[0]["frames"] == 35 and first[0]["frames"] == 30
    assert third[1]["lowpass_cutoff_hz"] == 4.0 and first[1]["lowpass_cutoff_hz"] == 6.0
    assert [r["skipped"] for r in batch(trials, out=out, base_dir=tmp_path, jobs=1)] == [True, True]

    # force runs all; the results are the same numbers as the resumed rows
    forced = batch(trials, out=out, base_dir=tmp_path, jobs=1, force=True)
    assert [r["skipped"] for r in forced] == [False, False]
    assert [_results(r) for r in forced] == [_results(r) for r in third]

    # a done folder that lost a file is not complete: rerun
    (out / "b" / "residuals.sto").unlink()
    assert [r["skipped"] for r in batch(trials, out=out, base_dir=tmp_path, jobs=1)] == [True, False]
    assert (out / "b" / "residuals.sto").is_file()


def test_failed_trials_are_retried_and_not_marked_done(gait2d, tmp_path):
    _write_inputs(gait2d, tmp_path, ["a"])
    trials = _trials(["a", "late"])
    rows = batch(trials, out=tmp_path / "out", base_dir=tmp_path, jobs=1)
    assert rows[1]["status"].startswith("failed: TRC file not found") and not (tmp_path / "out" / "late").exists()
    _synthetic_trc(gait2d, tmp_path / "late.trc", n=30)
    rows = batch(trials, out=tmp_path / "out", base_dir=tmp_path, jobs=1)
    assert [(r["status"], r["skipped"]) for r in rows] == [("ok", True), ("ok", False)]
    assert (tmp_path / "out" / "late" / DONE).is_file()


@pytest.mark.parametrize("count", [1, 5, 7])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 8])
def test_shards_cover_every_trial_exactly_once(count, n):
    parts = [shard_indices(count, (i, n)) for i in range(1, n + 1)]
    assert sorted(k for p in parts for k in p) == list(range(count))
    for i, p in enumerate(parts, start=1):
        assert all(k % n == i - 1 for k in p)
    assert shard_indices(count, "1/1") == list(range(count)) == shard_indices(count, None)


@pytest.mark.parametrize("text", ["0/2", "3/2", "1/0", "-1/2", "a/b", "2", "1/2/3", ""])
def test_bad_shard_is_refused_by_name(text):
    with pytest.raises(TrialError, match=re.escape(f"--shard {text!r}")):
        parse_shard(text)


def _config(tmp_path, names):
    cfg = tmp_path / "batch.toml"
    body = "".join(f'[[trials]]\nname = "{n}"\nkind = "trc"\ntrc = "{n}.trc"\n\n' for n in names)
    cfg.write_text('[batch]\nmodel = "gait2d"\nout = "res"\njobs = 1\n\n'
                   '[defaults]\nmarkers = "csu"\nso = false\nplots = false\nbody_mass = 60.0\n\n' + body)
    return cfg


def test_cli_shards_then_whole_run_skips_all_and_reports(gait2d, tmp_path, capsys):
    names = ["t1", "t2", "t3"]
    _write_inputs(gait2d, tmp_path, names)
    cfg = _config(tmp_path, names + ["nofile"])
    res = tmp_path / "res"

    assert main(["batch", str(cfg), "--shard", "2/2"]) == 1                 # t2 and nofile (indices 1, 3)
    cap = capsys.readouterr()
    assert sorted(p.name for p in res.iterdir()) == ["report-2-of-2.html", "summary-2-of-2.csv", "t2"]
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("[")]
    assert lines[0].startswith("[1/2] t2: done in ") and lines[0].endswith(" s")
    assert lines[1].startswith("[2/2] nofile: FAILED: TRC file not found") and len(lines) == 2
    assert "1/2 trials done (shard 2/2), 0 skipped" in cap.out

    assert main(["batch", str(cfg), "--shard", "1/2"]) == 0                 # t1, t3
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("[")]
    assert [ln.split(":")[0] for ln in lines] == ["[1/2] t1", "[2/2] t3"]
    with open(res / "summary-1-of-2.csv") as fh:
        assert [r["name"] for r in csv.DictReader(fh)] == ["t1", "t3"]

    # the whole batch after the shards: every finished trial is skipped, the whole table is written
    assert main(["batch", str(cfg)]) == 1
    cap = capsys.readouterr()
    assert "3/4 trials done, 3 skipped" in cap.out
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("[")]
    assert lines[:3] == ["[1/4] t1: skipped (done)", "[2/4] t2: skipped (done)", "[3/4] t3: skipped (done)"]
    assert lines[3].startswith("[4/4] nofile: FAILED: TRC file not found") and len(lines) == 4
    with open(res / "summary.csv") as fh:
        table = list(csv.DictReader(fh))
    assert [(r["name"], r["skipped"]) for r in table] == [("t1", "True"), ("t2", "True"), ("t3", "True"),
                                                          ("nofile", "False")]
    html = (res / "report.html").read_text()
    for n in names:
        assert f"href='{n}/inverse_dynamics.sto'" in html and f"href='{n}/summary.json'" in html
    assert html.count("skipped (done)</td>") == 3 and "TRC file not found" in html
    assert "3 skipped" in html and "1 failed" in html

    # --force runs them again (same numbers), a bad shard is exit 2 with one line and nothing run
    s = batch_cli(cfg, force=True)
    assert s["skipped"] == [] and s["failed"] == ["nofile"]
    capsys.readouterr()
    assert main(["batch", str(cfg), "--shard", "3/2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pinmsk: error: --shard '3/2': I must be between 1 and N") and err.count("\n") == 1


@pytest.mark.skipif(importlib.util.find_spec("distributed") is None, reason="needs Dask distributed")
def test_dask_scheduler_gives_the_serial_results(gait2d, tmp_path):
    from distributed import LocalCluster

    _write_inputs(gait2d, tmp_path, ["a", "b"])
    trials = _trials(["a", "b"])
    serial = batch(trials, out=tmp_path / "serial", base_dir=tmp_path, jobs=1)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        dask = batch(trials, out=tmp_path / "dask", base_dir=tmp_path, scheduler=cluster.scheduler_address)
    assert [r["status"] for r in dask] == ["ok", "ok"] and [r["skipped"] for r in dask] == [False, False]
    assert [_results(r) for r in dask] == [_results(r) for r in serial]
    for name in ("a", "b"):
        a = pinmsk.read_trial(tmp_path / "serial" / name / "inverse_dynamics.sto")
        b = pinmsk.read_trial(tmp_path / "dask" / name / "inverse_dynamics.sto")
        assert a.names == b.names and a.n_frames == serial[["a", "b"].index(name)]["frames"]
        for c in a.names:
            np.testing.assert_array_equal(a[c], b[c])


# -- a folder of subjects -------------------------------------------------------------------------

def test_folder_of_subjects_runs_configs_with_resume_and_shards(gait2d, tmp_path, capsys):
    lab = tmp_path / "lab"
    for sub, names in (("S01", ["w1", "w2"]), ("S02", ["w1"])):
        d = lab / sub
        d.mkdir(parents=True)
        _write_inputs(gait2d, d, names)
        _synthetic_trc(gait2d, d / f"{sub}_Static.trc", n=10)
        _config(d, names)
    (lab / "notes").mkdir()                                        # no static .trc: not a subject
    assert main(["batch", str(lab)]) == 0
    cap = capsys.readouterr()
    assert "2/2 subjects done; table" in cap.out and "not subjects (no static .trc): notes" in cap.err
    subject_lines = [ln for ln in cap.err.splitlines() if ln.startswith("subject [")]
    assert [ln.split(":")[0] for ln in subject_lines] == ["subject [1/2] S01 (config)", "subject [2/2] S02 (config)"]
    with open(lab / "subjects.csv") as fh:
        table = list(csv.DictReader(fh))
    assert [(r["subject"], r["run"], r["skipped"], r["failed"]) for r in table] == [
        ("S01", "2", "0", "0"), ("S02", "1", "0", "0")]
    assert (lab / "S01" / "res" / "w2" / DONE).is_file() and (lab / "S02" / "res" / "report.html").is_file()

    # the second subject alone (shard 2/2), resumed: its one trial skipped
    assert main(["batch", str(lab), "--shard", "2/2"]) == 0
    capsys.readouterr()
    with open(lab / "subjects-2-of-2.csv") as fh:
        assert [(r["subject"], r["run"], r["skipped"]) for r in csv.DictReader(fh)] == [("S02", "0", "1")]
    assert main(["batch", str(lab / "notes")]) == 2
    assert "no subject folders" in capsys.readouterr().err


def test_folder_subject_with_opensim_setups_gives_opensims_results(tmp_path, capsys):
    import shutil

    from conftest import shared_folder

    src = shared_folder("opensim-models/Arm26", "arm26_Setup_InverseDynamics.xml")
    sub = tmp_path / "lab" / "arm"
    sub.mkdir(parents=True)
    for f in ("arm26.osim", "arm26_InverseKinematics.mot", "arm26_Setup_InverseDynamics.xml",
              "arm26_Reserve_Actuators.xml"):          # a ForceSet: an input, not a setup to run
        shutil.copy(src / f, sub / f)
    shutil.copy(src / "arm26_elbow_flex.trc", sub / "arm_static.trc")
    assert main(["batch", str(tmp_path / "lab")]) == 0
    assert "subject [1/1] arm (setups): done in" in capsys.readouterr().err
    got = pinmsk.read_trial(sub / "FilteredResults" / "arm26_InverseDynamics.sto")
    # OpenSim's own result of that setup (as tests/test_tools_run.py checks run_setup against it)
    ref = pinmsk.read_trial(src / "reference_outputs" / "InverseDynamics_Filtered" / "arm26_InverseDynamics.sto")
    assert sorted(got.names) == sorted(ref.names) and got.n_frames == ref.n_frames > 0
    for c in ref.names:
        err = np.sqrt(np.mean((np.asarray(got[c]) - np.asarray(ref[c])) ** 2)) / np.max(np.abs(ref[c]))
        assert err < 1e-4, (c, err)
    (sub / "arm26_Setup_InverseDynamics.xml").unlink()
    assert main(["batch", str(tmp_path / "lab")]) == 1
    assert "no batch.toml and no OpenSim setup" in capsys.readouterr().err


def test_progress_note_prints_its_line_above_the_bar_drawn_or_not():
    import io

    from pinmsk.presentation.progress import Progress

    quiet = io.StringIO()
    with Progress(2, "batch", stream=quiet, force=False) as bar:
        bar.note("[1/2] a: done in 0.1 s")
        bar.update(1)
    assert quiet.getvalue() == "[1/2] a: done in 0.1 s\n"
    drawn = io.StringIO()
    with Progress(2, "batch", stream=drawn, force=True, delay=0.0) as bar:
        bar.update(1)
        bar.note("[1/2] a: skipped (done)")
    text = drawn.getvalue()
    first = text.index("\r") + 1
    bar_line = text[first:text.index("\r", first)]
    assert bar_line.startswith("batch [") and "1/2" in bar_line
    # the drawn bar is blanked, the note printed on its own line, the bar drawn again below it
    assert text[first + len(bar_line):].startswith("\r" + " " * len(bar_line) + "\r[1/2] a: skipped (done)\n\r")
