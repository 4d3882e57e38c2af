"""Reports show no absolute machine paths: relative to the working folder, or the file name."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

import pinmsk
from pinmsk.presentation import report
from pinmsk.presentation.shown_paths import portable_text, shown_path


def _trial(source):
    t = np.linspace(0.0, 1.0, 11)
    return pinmsk.Trial(t, {"elbow_flexion": 0.5 * t}, meta={"source": str(source)})


def test_shown_path_is_relative_inside_the_working_folder_else_the_name(tmp_path, monkeypatch):
    (tmp_path / "lab").mkdir()
    monkeypatch.chdir(tmp_path)
    assert shown_path(tmp_path / "lab" / "walk.mot") == os.path.join("lab", "walk.mot")
    assert shown_path("/elsewhere/data/run.sto") == "run.sto"
    assert shown_path("lab/walk.mot") == "lab/walk.mot"            # relative: as given
    assert shown_path("static_optimization") == "static_optimization"


def test_portable_text_rewrites_working_package_and_home_folders(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    pkg = Path(pinmsk.__file__).resolve().parent
    text = (f"a {tmp_path}/x/y.sto b {pkg}/models/forearm.toml c "
            f"{os.path.expanduser('~')}/notes.txt d /usr/share/x")
    out = portable_text(text)
    assert out == "a x/y.sto b pinmsk/models/forearm.toml c ~/notes.txt d /usr/share/x"


def test_results_report_holds_no_absolute_path(tmp_path, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    model = pinmsk.load_model("forearm")
    pkg = Path(pinmsk.__file__).resolve().parent
    trial = _trial(pkg / "data" / "elbow.mot")                          # a file shipped in the package
    results = _trial(work / "out" / "so.sto")
    html = report.render_results_report(model=model, trial=trial, results=results,
                                        text=f"read {work}/out/so.sto")
    assert str(tmp_path) not in html and str(pkg.parent) not in html
    assert "<td class=\"l\">elbow.mot</td>" in html                  # outside the folder: its name
    assert f"<td class=\"l\">{os.path.join('out', 'so.sto')}</td>" in html
