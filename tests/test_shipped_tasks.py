"""Task files ship in the wheel and are found by name, from any folder."""
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from pinmsk.errors import ModelError
from pinmsk.presentation.cli import main
from pinmsk.solvers.ocp.tasks import load_task, resolve_task, shipped_tasks

ROOT = Path(__file__).resolve().parents[1]


def test_a_shipped_task_is_found_by_name_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    names = shipped_tasks()
    assert set(names) == {p.stem for p in (ROOT / "data" / "tasks").glob("*.toml")}
    assert {"gait2d_predictive", "gait2d_tracking", "forearm_ift_j1"} <= set(names)
    for given in ("gait2d_predictive", "gait2d_predictive.toml"):
        p = resolve_task(given)
        assert p.name == "gait2d_predictive.toml" and p.is_file()
        assert "gait" in load_task(given)
    (tmp_path / "gait2d_predictive.toml").write_text("[model]\nname = 'finger'\n[motion]\nkind = 'sine'\n")
    assert resolve_task("gait2d_predictive.toml") == Path("gait2d_predictive.toml")    # a file there wins
    with pytest.raises(ModelError, match=r"task file not found: gait2d_predictve \(did you mean "
                                         r"'gait2d_predictive'\?\); shipped tasks, run by name"):
        resolve_task("gait2d_predictve")


def test_optimize_by_name_reaches_the_task(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    # --report on a task without [gait] is refused by name after the task is read: the name resolved
    assert main(["optimize", "forearm_ift_j1", "--report", "r.html"]) == 2
    assert "--report: forearm_ift_j1 has no [gait] table" in capsys.readouterr().err
    assert main(["optimize", "nope"]) == 2
    assert "shipped tasks, run by name (pinmsk optimize NAME): " in capsys.readouterr().err


def test_the_package_data_covers_every_task_file():
    try:
        import tomllib
    except ImportError:
        import tomli as tomllib
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert cfg["package-dir"]["pinmsk._data.tasks"] == "data/tasks" and "pinmsk._data.tasks" in cfg["packages"]
    globs = cfg["package-data"]["pinmsk._data.tasks"]
    files = list((ROOT / "data" / "tasks").glob("*.toml"))
    assert files and all(any(f.match(g) for g in globs) for f in files)


@pytest.mark.slow          # builds the wheel (about 5 s, and the build backend from the package index)
def test_the_wheel_holds_the_task_files(tmp_path):
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(tmp_path)],
                         capture_output=True, text=True, timeout=600)
    if run.returncode != 0:
        pytest.skip(f"no wheel built here: {run.stderr.strip().splitlines()[-1:]}")
    (wheel,) = tmp_path.glob("*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for f in (ROOT / "data" / "tasks").glob("*.toml"):
        assert f"pinmsk/_data/tasks/{f.name}" in names
