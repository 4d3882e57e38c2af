"""Lab files that open: time columns by their common names and units, --degrees / --time-unit on every
command that reads a trial, map files keyed by the old or the new names, and a missing coordinate's
error that hands over a map to start from."""
from __future__ import annotations

import re
try:
    import tomllib
except ImportError:                     # Python 3.10
    import tomli as tomllib

import numpy as np
import pytest

from pinmsk import read_trial
from pinmsk.errors import TrialError
from pinmsk.io.channel_map import load_channel_map
from pinmsk.presentation.cli import build_parser, main

T = np.arange(0.0, 2.0, 0.01)                       # 100 Hz, 2 s
Q = 1.0 + 0.5 * np.sin(2 * np.pi * T)               # elbow angle, rad
M = 5.0 * np.sin(2 * np.pi * T)                     # elbow moment, N m


def _csv(path, label, time, columns):
    names = ",".join(columns)
    rows = "".join(f"{float(t)!r}," + ",".join(repr(float(c[i])) for c in columns.values()) + "\n"
                   for i, t in enumerate(time))
    path.write_text(f"{label},{names}\n{rows}")
    return path


@pytest.mark.parametrize("label,factor", [
    ("time", 1.0), ("Time", 1.0), ("t", 1.0), ("Time (s)", 1.0), ("time [s]", 1.0), ("Time (sec)", 1.0),
    ("TIME (seconds)", 1.0), ("t_s", 1.0), ("Time [ms]", 1e-3), ("time (ms)", 1e-3), ("t_ms", 1e-3),
    ("Time (milliseconds)", 1e-3),
])
def test_time_columns_are_recognised_by_their_common_names_and_units(tmp_path, label, factor):
    path = _csv(tmp_path / "a.csv", label, T / factor, {"elbow_flexion": Q})
    got = read_trial(path)
    np.testing.assert_allclose(got.time, T, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(got["elbow_flexion"], Q)


def test_time_unit_errors_name_the_label(tmp_path):
    path = _csv(tmp_path / "m.csv", "Time (min)", T, {"elbow_flexion": Q})
    with pytest.raises(TrialError, match=r"m.csv', line 1: time column 'Time \(min\)': unit 'min' is not one of s, ms"):
        read_trial(path)
    path = _csv(tmp_path / "f.csv", "frame", T, {"elbow_flexion": Q})
    with pytest.raises(TrialError, match=r"the first column is 'frame' but must be the time: 'time', 't', 'Time \(s\)'"):
        read_trial(path)
    ms = _csv(tmp_path / "ms.csv", "Time [ms]", 1000 * T, {"elbow_flexion": Q})
    with pytest.raises(TrialError, match=r"label declares ms but the time unit asked for is s"):
        read_trial(ms, time_unit="s")
    np.testing.assert_allclose(read_trial(ms, time_unit="ms").time, T)        # agreeing: fine


def test_a_sto_time_label_with_a_unit(tmp_path):
    path = tmp_path / "a.sto"
    path.write_text("x\nversion=1\nnRows=3\nnColumns=2\ninDegrees=yes\nendheader\nTime (ms)\tknee\n"
                    "0\t10\n10\t20\n20\t30\n")
    got = read_trial(path)
    np.testing.assert_allclose(got.time, [0.0, 0.01, 0.02])
    np.testing.assert_allclose(got["knee"], np.deg2rad([10.0, 20.0, 30.0]))


def test_a_csv_in_degrees_and_milliseconds_opens_with_the_flags(tmp_path, capsys):
    src = _csv(tmp_path / "lab.csv", "time", 1000 * T, {"elbow_flexion": np.rad2deg(Q), "elbow_flexion_moment": M})
    out = tmp_path / "id.sto"
    assert main(["id", "forearm", str(src), "-o", str(out), "--time-unit", "ms"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "looks like degrees" in err and "pass --degrees (command line)" in err
    assert "inDegrees=yes" not in err                       # a CSV cannot have a header saying so
    assert not out.exists()
    assert main(["id", "forearm", str(src), "-o", str(out), "--time-unit", "ms", "--degrees"]) == 0
    ref = tmp_path / "ref.sto"
    _csv(tmp_path / "si.csv", "time", T, {"elbow_flexion": Q, "elbow_flexion_moment": M})
    assert main(["id", "forearm", str(tmp_path / "si.csv"), "-o", str(ref)]) == 0
    a, b = read_trial(out), read_trial(ref)
    np.testing.assert_allclose(a.time, b.time, atol=1e-12)
    np.testing.assert_allclose(a["elbow_flexion_moment"], b["elbow_flexion_moment"], rtol=1e-6, atol=1e-6)


def _commands_reading_a_trial():
    """(name, parser) of every subcommand with a trial argument (or one reading a motion file)."""
    p = build_parser()
    sub = next(a for a in p._actions if a.__class__.__name__ == "_SubParsersAction")
    found = {}

    def visit(name, parser):
        subs = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
        for a in subs:
            for n, child in a.choices.items():
                visit(f"{name} {n}", child)
        dests = {a.dest for a in parser._actions}
        if dests & {"trial", "moments", "fit_over"}:
            found[name] = parser
    for name, parser in sub.choices.items():
        visit(name, parser)
    return found


def test_every_command_that_reads_a_trial_takes_degrees_and_time_unit():
    found = _commands_reading_a_trial()
    assert {"id", "so", "fso", "muscles", "diagnose", "view", "simulate", "import", "contact fit"} <= set(found)
    for name, parser in found.items():
        flags = {o for a in parser._actions for o in a.option_strings}
        assert {"--degrees", "--time-unit"} <= flags, name
        unit = next(a for a in parser._actions if "--time-unit" in a.option_strings)
        assert tuple(unit.choices) == ("s", "ms"), name


# -- map files -------------------------------------------------------------------------------------

def test_map_scale_and_offset_take_the_new_or_the_old_names(tmp_path):
    src = _csv(tmp_path / "lab.csv", "Time (s)", T, {"elbow": -Q, "elbow_moment": -M})
    for key in ("elbow", "elbow_flexion"):
        m = tmp_path / f"{key}.toml"
        m.write_text(f'[rename]\nelbow = "elbow_flexion"\n[scale]\n{key} = -1\n[offset]\n{key} = 0.25\n')
        (entry,) = load_channel_map(m).entries
        assert (entry.source, entry.target, entry.scale, entry.offset) == ("elbow", "elbow_flexion", -1.0, 0.25)
        out = tmp_path / f"{key}.sto"
        assert main(["id", "forearm", str(src), "-o", str(out), "--map", str(m), "--cutoff", "0"]) == 0
        assert "elbow_flexion_moment" in read_trial(out).names


def test_a_missing_coordinate_suggests_a_map_and_the_template_works(tmp_path, capsys):
    src = _csv(tmp_path / "lab.csv", "Time (s)", T, {"elbow": Q, "elbow_flexion_moment": M})
    out = tmp_path / "id.sto"
    assert main(["id", "forearm", str(src), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "missing coordinate channel(s): 'elbow_flexion'" in err and "--map MAP.toml" in err
    template = re.search(r"MAP.toml holding: (rename = \{.*?\})", err)[1]
    assert template == 'rename = {elbow = "elbow_flexion"}'          # the derived _moment column is no guess
    m = tmp_path / "map.toml"
    m.write_text(template + "\n")
    assert tomllib.loads(m.read_text()) == {"rename": {"elbow": "elbow_flexion"}}
    assert main(["id", "forearm", str(src), "-o", str(out), "--map", str(m)]) == 0


def test_the_template_for_columns_with_no_guess_is_valid_toml(tmp_path, capsys):
    src = _csv(tmp_path / "lab.csv", "time", T, {"xyz": Q})
    assert main(["id", "gait2d", str(src), "-o", str(tmp_path / "id.sto")]) == 2
    err = capsys.readouterr().err
    template = re.search(r"MAP.toml holding: (rename = \{.*?\})", err)[1]
    assert "YOUR_torso_x_COLUMN" in template and "..." in template
    parsed = tomllib.loads(template.replace(", ...", ""))      # the six shown, one key each
    assert len(parsed["rename"]) == 6

