"""The command line refuses bad outputs and misspelt effects before any work, and its help and tables read well."""
from __future__ import annotations

from pathlib import Path

import pytest

import pinmsk.model
from pinmsk.presentation.cli import build_parser, main
from pinmsk.presentation.model_table import models_table, shorten

DATA = Path(__file__).resolve().parents[1] / "data"
TRIAL = str(DATA / "forearm_payload.csv")


@pytest.fixture
def no_work(monkeypatch):
    """Loading a model (the first work of every command below) fails the test."""
    def refuse(*a, **kw):
        raise AssertionError("the command started its work before checking its arguments")
    monkeypatch.setattr(pinmsk.model, "load_model", refuse)
    monkeypatch.setattr(pinmsk.model, "import_osim", refuse)


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("pinmsk: error: ") and "\n" not in err and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("argv,flag,kinds", [
    (["id", "forearm", TRIAL, "-o", "{d}/x.txt"], "-o/--output", ".sto or .mot or .csv"),
    (["so", "forearm", TRIAL, "-o", "{d}/x.xlsx"], "-o/--output", ".sto or .mot or .csv"),
    (["so", "forearm", TRIAL, "-o", "{d}/x.sto", "--report", "{d}/r.txt"], "--report", ".html or .htm"),
    (["fso", "forearm", TRIAL, "-o", "{d}/x"], "-o/--output", ".sto or .mot or .csv"),
    (["muscles", "forearm", TRIAL, "-o", "{d}/x.json"], "-o/--output", ".sto or .mot or .csv"),
    (["simulate", "forearm", "--duration", "1", "-o", "{d}/x.dat"], "-o/--output", ".sto or .mot or .csv"),
    (["diagnose", "forearm", TRIAL, "--json", "{d}/x.txt"], "--json", ".json"),
    (["diagnose", "forearm", TRIAL, "--save-model", "{d}/x.urdf"], "--save-model", ".toml"),
    (["synth", "forearm", "-o", "{d}/x.txt"], "-o/--output", ".sto or .mot or .csv"),
    (["ik", "gait2d", "{d}/walk.trc", "-o", "{d}/q.csv"], "-o/--output", ".mot or .sto"),
    (["scale", "{d}/m.osim", "{d}/s.trc", "--mass", "70", "-o", "{d}/scaled.xml"], "-o/--output", ".osim"),
    (["optimize", str(DATA / "tasks" / "forearm_ift_j1.toml"), "-o", "{d}/x.txt"], "-o/--output", ".sto or .mot or .csv"),
])
def test_an_output_of_the_wrong_type_is_refused_before_any_work(argv, flag, kinds, tmp_path, capsys, no_work):
    argv = [a.format(d=tmp_path) for a in argv]
    assert main(argv) == 2
    err = _error(capsys)
    assert f"{flag} " in err and f"writes {kinds} there" in err and "nothing was run" in err
    assert list(tmp_path.iterdir()) == []


def test_an_output_in_a_missing_or_read_only_folder_is_refused_before_any_work(tmp_path, capsys, no_work):
    assert main(["id", "forearm", TRIAL, "-o", str(tmp_path / "nope" / "x.sto")]) == 2
    assert "does not exist; create it first" in _error(capsys)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        import os
        if os.access(ro, os.W_OK):          # root writes anyway: the probe file is then created and removed
            pytest.skip("this user writes into read-only folders")
        assert main(["id", "forearm", TRIAL, "-o", str(ro / "x.sto")]) == 2
        assert "cannot write" in _error(capsys)
    finally:
        ro.chmod(0o700)


def test_the_right_suffixes_pass_the_check():
    from pinmsk.presentation.cli_checks import check_output_suffixes
    p = build_parser()
    for argv in (["id", "forearm", TRIAL, "-o", "x.STO"], ["so", "forearm", TRIAL, "-o", "x.csv", "--report", "r.html"],
                 ["ik", "gait2d", "w.trc", "-o", "q.mot"], ["diagnose", "forearm", TRIAL, "--json", "d.json",
                                                            "--save-model", "m.toml", "--save-osim", "m.osim"]):
        check_output_suffixes(p.parse_args(argv))


def test_a_misspelt_effect_gets_a_did_you_mean_before_any_work(tmp_path, capsys, no_work):
    assert main(["diagnose", "forearm", TRIAL, "--add", "paylod:hand"]) == 2
    err = _error(capsys)
    assert "unknown effect 'paylod' (did you mean 'payload'?); known effects: " in err and "joint_damping" in err
    assert main(["synth", "forearm", "--effect", "joint_dampng:elbow_flexion:c=0.2", "-o", str(tmp_path / "s.sto")]) == 2
    assert "did you mean 'joint_damping' or" in _error(capsys)


def test_diagnose_help_lists_the_effects(capsys):
    from pinmsk.effects import families
    with pytest.raises(SystemExit):
        main(["diagnose", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "effect families (--add FAMILY[:TARGET]" in out
    assert all(f in out for f in families()) and len(families()) > 10


def test_every_moment_arms_flag_has_help():
    p = build_parser()
    sub = next(a for a in p._actions if a.__class__.__name__ == "_SubParsersAction")
    found = 0
    for name, parser in sub.choices.items():
        for a in parser._actions:
            if "--moment-arms" in a.option_strings:
                found += 1
                assert a.help and "path variant" in a.help and "constant" in a.help, name
    assert found >= 5          # info, id, so, fso, diagnose


def test_the_models_table_is_aligned_and_cuts_with_an_ellipsis(capsys):
    assert main(["models"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("model") and any(x.startswith("finger_literature ") for x in lines)
    dof_end = lines[0].index("dof") + 3
    desc = lines[0].index("description")
    for line in lines[1:]:
        assert line[dof_end - 1] != " " and line[dof_end] == " ", line      # right-aligned counts
        assert line[desc - 2:desc] == "  " and line[desc] != " ", line
        assert len(line) <= 100
    assert any(x.endswith("...") for x in lines[1:])
    rows = [("a_very_long_model_name", 3, 0, "word " * 40)]
    (head, row) = models_table(rows, width=60)
    assert len(row) <= 60 and row.endswith("...") and row.index("3") == head.index("dof") + 2
    assert shorten("short", 10) == "short"
    assert shorten("one two three four", 12) == "one two..."
