"""Real files from the command line: lenient reads that report each repair, column maps, C3D."""
import sys
import warnings

import numpy as np
import pytest

from pinmsk import load_model
from pinmsk.io.channel_map import (GAIT10DOF_HIP_OFFSET, RAJAGOPAL_HIP_OFFSET, apply_channel_map,
                                   load_channel_map)
from pinmsk.presentation.cli import main
from pinmsk.errors import MissingDependencyError, PinmskError, RepairWarning, TrialError
from pinmsk.io.tables import read_trial, state_path_coordinate, write_trial
from pinmsk.pipeline import opensim_to_gait2d
from pinmsk.trial import Trial, parse_ground_reaction


@pytest.fixture(scope="module")
def gait2d():
    return load_model("gait2d")


def _sloppy_mot(path, n=40):
    """An OpenSim .mot in degrees (r_elbow_flex, and a column at half of it) with a wrong nColumns
    and nRows, and three rows repeating the time stamp before: lines 18 and 38 repeat their row
    exactly, line 19 has another value (+0.25 deg).  Returns the clean time and angle (rad)."""
    t = np.round(np.arange(n) / 100.0, 6)
    q = 60.0 * np.sin(2 * np.pi * t)                        # degrees
    body = []
    for k in range(n):
        line = f"{t[k]:.6f}\t{q[k]:.10g}\t{0.5 * q[k]:.10g}"
        body.append(line)
        if k == 9:
            body += [line, f"{t[k]:.6f}\t{q[k] + 0.25:.10g}\t{0.5 * q[k]:.10g}"]
        if k == 27:
            body.append(line)
    path.write_text("walk\nversion=1\nnRows=40\nnColumns=4\ninDegrees=yes\nendheader\n"
                    "time\tr_elbow_flex\tr_elbow_flex_half\n" + "\n".join(body) + "\n")
    return t, np.deg2rad(q)


# -- lenient reading ---------------------------------------------------------------------


def test_strict_read_names_both_fixes(tmp_path):
    path = tmp_path / "walk.mot"
    _sloppy_mot(path)
    with pytest.raises(TrialError) as info:
        read_trial(path)
    msg = str(info.value)
    assert "header says nColumns=4 (line 4) but the column-label line 7 has 3 columns" in msg
    assert msg.endswith("pass --lenient (command line) or strict=False (Python)")


def test_lenient_read_reports_each_repair_as_a_repair_warning(tmp_path):
    path = tmp_path / "walk.mot"
    t, q = _sloppy_mot(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tr = read_trial(path, strict=False)
    got = [str(w.message) for w in caught]
    assert [w.category for w in caught] == [RepairWarning] * 3
    src = str(path)
    assert got == [
        f"{src}: header says nColumns=4 (line 4), data has 3 columns; used the data's 3",
        f"{src}: dropped 3 duplicated time stamps at lines 18, 19, 38 (kept the first of each; 1 had "
        "other values than the row before, by up to 0.25 in 'r_elbow_flex' on line 19)",
        f"{src}: header says nRows=40 (line 3), data has 43 rows (lines 8-50); used the data's 43",
    ]
    assert tr.meta["read_notes"] == tuple(got)
    # the first row of each time stamp is kept, so the data are the clean 40 frames, in radians
    np.testing.assert_array_equal(tr.time, t)
    np.testing.assert_allclose(tr["r_elbow_flex"], q, rtol=1e-9, atol=1e-12)


def test_lenient_read_refuses_a_rounded_time_column(tmp_path):
    t = np.floor(np.arange(100) / 10.0) / 100.0              # 1 kHz printed with 2 decimals
    path = tmp_path / "rounded.sto"
    path.write_text("x\nendheader\ntime\ta\n" + "\n".join(f"{v:.2f}\t{k}" for k, v in enumerate(t)) + "\n")
    with pytest.raises(TrialError, match=r"rounded.sto': 90 of 100 rows repeat the time stamp of the row before "
                                         r"\(first on line 5\); the time column looks printed with too few digits"):
        read_trial(path, strict=False)


def test_old_datacolumns_header_is_reported_by_its_name(tmp_path):
    path = tmp_path / "old.sto"
    path.write_text("old\ndatarows 2\ndatacolumns 5\nendheader\ntime\ta\n0\t1\n1\t2\n")
    with pytest.warns(RepairWarning, match=r"old.sto: header says datacolumns=5 \(line 3\), data has 2 columns; "
                                           r"used the data's 2"):
        tr = read_trial(path, strict=False)
    assert tr.n_frames == 2


@pytest.mark.parametrize("rel,repair", [
    ("real/opensim-moco-walk-emg/coordinates.sto",
     "header says nColumns=40 (line 3), data has 32 columns; used the data's 32"),
    ("real/pyomeca-box-lift-emg/inverse_kin.mot",
     "header says nRows=250 (line 3), data has 88 rows (lines 12-99); used the data's 88"),
    ("opensim-models/Gait10dof18musc/reference_outputs/RRA/subject_adjusted_Kinematics_q.sto",
     "dropped 1 duplicated time stamp at line 2548 (kept the first of each; each repeated the row before)"),
])
def test_real_sloppy_files_read_leniently_with_their_repair(shared_data, rel, repair):
    path = shared_data / rel
    if not path.is_file():
        pytest.skip(f"{rel} absent")
    with pytest.raises(TrialError, match="pass --lenient"):
        read_trial(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_trial(path, strict=False)
    assert [str(w.message) for w in caught] == [f"{path}: {repair}"]


def _cli(argv, capsys):
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_lenient_prints_one_warning_per_repair(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    t, q = _sloppy_mot(tmp_path / "walk.mot")
    mapfile = tmp_path / "elbow.toml"
    mapfile.write_text('[rename]\nr_elbow_flex = "elbow_flexion"\n')
    code, _, err = _cli(["id", "forearm", "walk.mot", "--map", "elbow.toml", "-o", "out.sto"], capsys)
    assert code == 2 and not (tmp_path / "out.sto").exists()
    assert err.startswith("pinmsk: error: file 'walk.mot': header says nColumns=4") and "--lenient" in err
    assert len(err.strip().splitlines()) == 1
    code, _, err = _cli(["id", "forearm", "walk.mot", "--lenient", "--map", "elbow.toml", "-o", "out.sto"], capsys)
    assert code == 0, err
    warn = [ln for ln in err.splitlines() if ln.startswith("pinmsk: warning: walk.mot:")]
    assert warn == [
        "pinmsk: warning: walk.mot: header says nColumns=4 (line 4), data has 3 columns; used the data's 3",
        "pinmsk: warning: walk.mot: dropped 3 duplicated time stamps at lines 18, 19, 38 (kept the first of "
        "each; 1 had other values than the row before, by up to 0.25 in 'r_elbow_flex' on line 19)",
        "pinmsk: warning: walk.mot: header says nRows=40 (line 3), data has 43 rows (lines 8-50); used the data's 43",
    ]
    # the same as ID of the clean trial under the model's own names (the map's angle read in degrees)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RepairWarning)
        clean = read_trial(tmp_path / "walk.mot", strict=False)           # the file's own digits
    np.testing.assert_allclose(clean["r_elbow_flex"], q, rtol=1e-9)
    write_trial(Trial(t, {"elbow_flexion": clean["r_elbow_flex"]}), tmp_path / "clean.sto", precision=17)
    assert _cli(["id", "forearm", "clean.sto", "-o", "ref.sto"], capsys)[0] == 0
    got, ref = read_trial(tmp_path / "out.sto"), read_trial(tmp_path / "ref.sto")
    np.testing.assert_allclose(got["elbow_flexion_moment"], ref["elbow_flexion_moment"], rtol=1e-7, atol=1e-9)
    assert np.ptp(ref["elbow_flexion_moment"]) > 0.1


def test_every_trial_command_offers_the_read_flags():
    from pinmsk.presentation.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for name in ("id", "simulate", "so", "fso", "diagnose", "view"):
        flags = {o for a in sub[name]._actions for o in a.option_strings}
        assert {"--lenient", "--map"} <= flags, name


# -- column maps -------------------------------------------------------------------------


def test_map_file_renames_scales_and_carries_speed_and_moment(tmp_path):
    m = tmp_path / "m.toml"
    m.write_text('[rename]\nknee_angle_r = "knee_r"\npelvis_ty = "torso_y"\n'
                 '[scale]\nknee_angle_r = -1\n[offset]\npelvis_ty = 0.25\n')
    t = np.arange(5) / 100.0
    k = np.linspace(-1.0, -0.2, 5)
    tr = Trial(t, {"knee_angle_r": k, "knee_angle_r_speed": np.gradient(k, t), "knee_angle_r_moment": 2 * k,
                   "pelvis_ty": np.full(5, 0.9), "ground_force_vy": np.full(5, 700.0)}, meta={"source": "w.sto"})
    out = apply_channel_map(tr, m)
    assert out.names == ("knee_r", "knee_r_speed", "knee_r_moment", "torso_y", "ground_force_vy")
    np.testing.assert_allclose(out["knee_r"], -k)
    np.testing.assert_allclose(out["knee_r_speed"], -np.gradient(k, t))      # scale, no offset
    np.testing.assert_allclose(out["knee_r_moment"], -2 * k)
    np.testing.assert_allclose(out["torso_y"], 1.15)
    np.testing.assert_allclose(out["ground_force_vy"], 700.0)                 # unmapped: kept
    assert out.meta["channel_map"]["renamed"]["knee_angle_r_moment"] == "knee_r_moment"
    # a moments trial satisfies the entry through the column it carries
    moments = tr.select(["knee_angle_r_moment", "pelvis_ty"])
    np.testing.assert_allclose(apply_channel_map(moments, m)["knee_r_moment"], -2 * k)


def test_cli_simulate_maps_the_moments_trial(tmp_path, capsys):
    t = np.arange(51) / 100.0
    write_trial(Trial(t, {"r_elbow_flex_moment": np.full(51, -2.0)}), tmp_path / "tau.sto")
    (tmp_path / "m.toml").write_text('[rename]\nr_elbow_flex = "elbow_flexion"\n[scale]\nr_elbow_flex = -1\n')
    args = ["simulate", "forearm", "--moments", str(tmp_path / "tau.sto"), "-o"]
    assert _cli(args + [str(tmp_path / "a.sto"), "--map", str(tmp_path / "m.toml")], capsys)[0] == 0
    write_trial(Trial(t, {"elbow_flexion_moment": np.full(51, 2.0)}), tmp_path / "ref_tau.sto")
    assert _cli(["simulate", "forearm", "--moments", str(tmp_path / "ref_tau.sto"), "-o",
                 str(tmp_path / "b.sto")], capsys)[0] == 0
    a, b = read_trial(tmp_path / "a.sto"), read_trial(tmp_path / "b.sto")
    np.testing.assert_allclose(a["elbow_flexion"], b["elbow_flexion"], atol=1e-12)
    assert abs(b["elbow_flexion"][-1]) > 0.01                  # the moment moved the forearm


@pytest.mark.parametrize("text,match", [
    ('[rename]\na = "b"\n[scales]\na = 2\n', r"m.toml: unknown section 'scales' \(did you mean 'scale'\?\)"),
    ('a = "b"\n', r"m.toml: unknown section 'a'.*put column renames under a \[rename\] table"),
    ('[rename]\nknee = "k"\n[offset]\nkne = 1\n',
     r"m.toml: unknown \[offset\] key \(neither an old nor a new name of a \[rename\] entry\) 'kne' "
     r"\(did you mean 'knee'\?\)"),
    ('[rename]\nknee = "k"\n[scale]\nknee = -1\nk = -1\n',
     r"m.toml: \[scale\] knee and k name the same \[rename\] entry knee = 'k'; keep one"),
    ('[rename]\na = "x"\nb = "x"\n', r"m.toml: \[rename\] 'a' and 'b' both map to 'x'"),
    ('[rename]\na = 3\n', r"m.toml: \[rename\] a = 3: the new name must be a non-empty string"),
    ('[rename]\na = "b"\n[scale]\na = "minus"\n', r"m.toml: \[scale\] a = 'minus' must be a finite number"),
    ('[rename]\na = "b"\n[scale]\na = 0\n', r"m.toml: \[scale\] a = 0 would erase the column"),
    ('[scale]\na = 1\n', r"m.toml: no \[rename\] table"),
    ('[rename\n', r"m.toml: invalid TOML"),
])
def test_map_file_errors_name_the_file_and_key(tmp_path, text, match):
    m = tmp_path / "m.toml"
    m.write_text(text)
    with pytest.raises(TrialError, match=match):
        load_channel_map(m)


def test_map_entries_must_match_and_model_coordinates_must_be_present(tmp_path, gait2d):
    m = tmp_path / "m.toml"
    m.write_text('[rename]\nhip_flexon_r = "hip_r"\n')
    tr = Trial(np.arange(3) / 100.0, {"hip_flexion_r": np.zeros(3), "hip_r": np.ones(3)},
               meta={"source": "walk.mot"})
    with pytest.raises(TrialError, match=r"m.toml: \[rename\] hip_flexon_r = 'hip_r': walk.mot has no column "
                                         r"'hip_flexon_r' \(did you mean 'hip_flexion_r'\?\)"):
        apply_channel_map(tr, m)
    m.write_text('[rename]\nhip_flexion_r = "hip_r"\n')
    with pytest.raises(TrialError, match=r"hip_flexion_r -> 'hip_r': walk.mot already has a column 'hip_r'"):
        apply_channel_map(tr, m)
    tr = tr.drop(["hip_r"])
    with pytest.raises(TrialError, match=r"walk.mot mapped with .*m.toml lacks 10 coordinate\(s\) of model "
                                         r"'gait2d': torso_x, torso_y, torso_angle, hip_l, knee_r"):
        apply_channel_map(tr, m, model=gait2d)
    assert apply_channel_map(tr, m, model=gait2d, require_coordinates=False).names == ("hip_r",)
    with pytest.raises(TrialError, match=r"column map 'opensim-gait' is neither a built-in map \(did you mean "
                                         r"'opensim-gait2d'\?\) nor a .toml file"):
        load_channel_map("opensim-gait")


def _opensim_trial(n=60, knee_flexion_negative=False, paths=False):
    t = np.arange(n) / 100.0
    w = 2 * np.pi * t
    ch = {"pelvis_tilt": 0.05 * np.sin(w), "pelvis_tx": 1.2 * t, "pelvis_ty": 0.95 + 0.01 * np.cos(2 * w)}
    for s, ph in (("r", 0.0), ("l", np.pi)):
        ch[f"hip_flexion_{s}"] = 0.4 * np.sin(w + ph)
        knee = 0.6 + 0.5 * np.sin(w + ph)                                   # flexion, 0.1 .. 1.1 rad
        ch[f"knee_angle_{s}"] = -knee if knee_flexion_negative else knee
        ch[f"ankle_angle_{s}"] = 0.2 * np.cos(w + ph)
    ch["lumbar_extension"] = np.full(n, -0.1)
    ch["ground_force_vy"] = np.full(n, 700.0)
    ch["1_ground_force_vy"] = np.full(n, 50.0)
    ch["hip_flexion_r_moment"] = np.linspace(-50, 50, n)
    if paths:
        ch = {(f"/jointset/j/{k}/value" if not k.startswith(("ground", "1_", "hip_flexion_r_m")) else k): v
              for k, v in ch.items()}
    return Trial(t, ch, meta={"source": "os.sto"})


def _reference_gait2d(tr, model, hip_offset, knee_sign):
    """gait2d coordinates by the conventions written out (the formulas of the module docstring)."""
    tilt, tx, ty = tr["pelvis_tilt"], tr["pelvis_tx"], tr["pelvis_ty"]
    ox, oy = hip_offset
    hx, hy = tx + np.cos(tilt) * ox - np.sin(tilt) * oy, ty + np.sin(tilt) * ox + np.cos(tilt) * oy
    pm = model.pin
    above = -pm.jointPlacements[pm.getJointId("hip_r")].translation[1]
    ref = {"torso_x": hx - above * np.sin(tilt), "torso_y": hy + above * np.cos(tilt), "torso_angle": -tilt}
    for s in "rl":
        ref[f"hip_{s}"] = -tr[f"hip_flexion_{s}"]
        ref[f"knee_{s}"] = knee_sign * tr[f"knee_angle_{s}"]
        ref[f"ankle_{s}"] = -tr[f"ankle_angle_{s}"]
        ref[f"mtp_{s}"] = np.zeros(tr.n_frames)
    return ref


@pytest.mark.parametrize("name,negative,sign,hip", [
    ("opensim-gait2d", False, 1, RAJAGOPAL_HIP_OFFSET),
    ("opensim-gait2d", True, -1, RAJAGOPAL_HIP_OFFSET),
    ("rajagopal-gait2d", False, 1, RAJAGOPAL_HIP_OFFSET),
    ("gait10dof-gait2d", True, -1, GAIT10DOF_HIP_OFFSET),
])
def test_builtin_maps_follow_the_sign_conventions(gait2d, name, negative, sign, hip):
    tr = _opensim_trial(knee_flexion_negative=negative)
    out = apply_channel_map(tr, name, model=gait2d)
    ref = _reference_gait2d(tr, gait2d, hip, sign)
    for c in gait2d.coordinates:
        np.testing.assert_allclose(out[c], ref[c], atol=1e-12, err_msg=c)
    assert np.all(out["knee_r"] > 0.05)                  # gait2d knee + = flexion, whatever the source
    # the hip joint of gait2d lands on the OpenSim hip centre
    import pinocchio as pin
    pd = gait2d.pin.createData()
    q = np.column_stack([out[c] for c in gait2d.coordinates])
    for k in (0, 17, 41):
        pin.framesForwardKinematics(gait2d.pin, pd, q[k])
        c, s = np.cos(tr["pelvis_tilt"][k]), np.sin(tr["pelvis_tilt"][k])
        np.testing.assert_allclose(pd.oMf[gait2d.frame_id("thigh_r")].translation[:2],
                                   [tr["pelvis_tx"][k] + c * hip[0] - s * hip[1],
                                    tr["pelvis_ty"][k] + s * hip[0] + c * hip[1]], atol=1e-12)
    # moments follow their coordinate's sign; GRF channels are kept and still parsed
    np.testing.assert_allclose(out["hip_r_moment"], -tr["hip_flexion_r_moment"])
    assert parse_ground_reaction("1_ground_force_vy") is not None and out["1_ground_force_vy"][0] == 50.0
    assert out["lumbar_extension"][0] == -0.1
    notes = out.meta["channel_map"]["notes"]
    assert notes[-1].endswith("mtp_r, mtp_l set to 0 (the OpenSim models of this map have no mtp coordinate "
                              "or lock it)")
    if name == "opensim-gait2d":
        assert ("knee = -knee_angle" if negative else "knee = +knee_angle") in notes[0]


def test_builtin_map_reads_state_paths_and_degrees(tmp_path, gait2d):
    tr = _opensim_trial(paths=True)
    out = apply_channel_map(tr, "opensim-gait2d", model=gait2d)
    np.testing.assert_allclose(out["hip_l"], -tr["/jointset/j/hip_flexion_l/value"])
    # an OpenSim IK file in degrees: the CLI reads the OpenSim angles as angles before mapping
    plain = _opensim_trial()
    deg = {n: (np.rad2deg(plain[n]) if n.startswith(("pelvis_tilt", "hip_", "knee_", "ankle_")) and
               not n.endswith("_moment") else plain[n]) for n in plain.names}
    write_trial(Trial(plain.time, deg), tmp_path / "ik.sto")
    text = (tmp_path / "ik.sto").read_text().replace("inDegrees=no", "inDegrees=yes")
    (tmp_path / "ik.mot").write_text(text)
    from pinmsk.presentation.cli import _read

    class Args:
        lenient, map = False, "opensim-gait2d"
    got = _read(tmp_path / "ik.mot", gait2d, Args())
    ref = apply_channel_map(plain, "opensim-gait2d", model=gait2d)
    for c in gait2d.coordinates:
        np.testing.assert_allclose(got[c], ref[c], atol=1e-9, err_msg=c)


def test_cli_suggests_the_builtin_map_for_opensim_names(tmp_path, capsys):
    write_trial(_opensim_trial(), tmp_path / "os.sto")
    code, _, err = _cli(["id", "gait2d", str(tmp_path / "os.sto"), "-o", str(tmp_path / "o.sto")], capsys)
    assert code == 2 and "but the columns look like OpenSim's: pass --map opensim-gait2d (command line)" in err
    assert not (tmp_path / "o.sto").exists()


def _real_coordinates(shared_data, rel):
    p = shared_data / rel
    if not p.is_file():
        pytest.skip(f"{rel} absent")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RepairWarning)
        return p, read_trial(p, strict=False)


@pytest.mark.parametrize("rel,cli_map,kw,sign", [
    ("real/opensim-moco-walk-emg/coordinates.sto", "opensim-gait2d", {}, 1),
    ("opensim-models/Gait10dof18musc/IK/subject01_walk_IK.mot", "gait10dof-gait2d",
     {"hip_offset": GAIT10DOF_HIP_OFFSET, "knee_sign": -1}, -1),
])
def test_builtin_map_agrees_with_opensim_to_gait2d_on_real_data(shared_data, gait2d, rel, cli_map, kw, sign):
    path, coords = _real_coordinates(shared_data, rel)
    kin = opensim_to_gait2d(coords, gait2d, **kw)
    from pinmsk.presentation.cli import _read

    class Args:
        lenient, map = True, cli_map
    mapped = _read(path, gait2d, Args())
    bare = Trial(coords.time, {(state_path_coordinate(n) or (n,))[0]: coords[n] for n in coords.names})
    ref = _reference_gait2d(bare, gait2d, kw.get("hip_offset", RAJAGOPAL_HIP_OFFSET), sign)
    for c in gait2d.coordinate_order:
        np.testing.assert_allclose(mapped[c], kin[c], atol=1e-12, err_msg=c)
        np.testing.assert_allclose(kin[c], ref[c], atol=1e-12, err_msg=c)
    # a stride: the knee flexes to 1 rad in swing and never hyperextends much
    assert 0.9 < np.max(kin["knee_r"]) < 1.4 and np.min(kin["knee_r"]) > -0.1


# -- C3D ---------------------------------------------------------------------------------


def _write_c3d(path, n=20):
    """A C3D with 2 markers (mm, 100 Hz), 6 force-plate channels + 1 EMG (1 kHz) and one type-2 plate."""
    ezc3d = pytest.importorskip("ezc3d")
    from ezc3d import ezc3d as swig

    rng = np.random.default_rng(3)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("RHEE", "RTOE")
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, 2, n))
    pts[:3] = rng.uniform(100.0, 1500.0, (3, 2, n))
    c["data"]["points"] = pts
    c["parameters"]["ANALOG"]["RATE"]["value"] = [1000]
    c["parameters"]["ANALOG"]["LABELS"]["value"] = ("Fx1", "Fy1", "Fz1", "Mx1", "My1", "Mz1", "EMG1")
    an = np.zeros((1, 7, 10 * n))
    an[0, 2] = 700.0                                       # N
    an[0, 3, 100:] = 700.0 * 50.0                          # N mm: the COP moves 50 mm off the centre
    an[0, 6] = np.sin(np.arange(10 * n) / 7.0)
    c["data"]["analogs"] = an

    def ints(name, values):                                # ezc3d's add_parameter stores lists as floats
        c.add_parameter("FORCE_PLATFORM", name, np.asarray(values, float))
        p = c["parameters"]["FORCE_PLATFORM"][name]
        p["type"], p["value"] = swig.INT, np.asarray(values, int)
    ints("USED", [1])
    ints("TYPE", [2])
    ints("ZERO", [1, 0])
    ints("CHANNEL", [[1], [2], [3], [4], [5], [6]])
    corners = np.array([[0, 0, 0], [600, 0, 0], [600, 400, 0], [0, 400, 0]], float).T[:, :, None]
    c.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
    c.add_parameter("FORCE_PLATFORM", "ORIGIN", np.zeros((3, 1)))
    c.write(str(path))
    return pts[:3] / 1000.0, an[0]


def test_read_trial_opens_c3d_parts(tmp_path):
    path = tmp_path / "walk.c3d"
    xyz, an = _write_c3d(path)
    mk = read_trial(path)
    assert mk.meta["format"] == "c3d" and mk.meta["part"] == "markers" and mk.rate == pytest.approx(100.0)
    assert mk.names == ("RHEE_x", "RHEE_y", "RHEE_z", "RTOE_x", "RTOE_y", "RTOE_z")
    np.testing.assert_allclose(mk["RTOE_y"], xyz[1, 1], rtol=1e-6)        # mm -> m
    np.testing.assert_allclose(mk.time, np.arange(20) / 100.0)
    a = read_trial(path, part="analogs")
    assert a.rate == pytest.approx(1000.0) and a.n_frames == 200
    np.testing.assert_allclose(a["EMG1"], an[6], rtol=1e-6, atol=1e-6)
    g = read_trial(path, part="platforms")
    assert g.names[:3] == ("ground_force_vx", "ground_force_vy", "ground_force_vz")
    np.testing.assert_allclose(g["ground_force_vz"], 700.0, rtol=1e-6)
    # zero moment: the COP is the plate centre (0.3, 0.2, 0) m; 50 N m / 700 N moves it by 50 mm
    np.testing.assert_allclose([g["ground_force_px"][50], g["ground_force_py"][50]], [0.3, 0.2], atol=1e-9)
    assert abs(g["ground_force_py"][150] - 0.2) == pytest.approx(0.05, rel=1e-6)
    with pytest.raises(TrialError, match=r"walk.c3d'.*part='grf'; a C3D part is one of markers, analogs, platforms"):
        read_trial(path, part="grf")
    with pytest.raises(TrialError, match=r"part='markers' applies to .c3d files only"):
        read_trial(tmp_path / "x.sto", part="markers")
    (tmp_path / "bad.c3d").write_bytes(b"not a c3d")
    with pytest.raises(TrialError, match=r"bad.c3d: not a readable C3D file: 9 bytes, shorter than its 512-byte header"):
        read_trial(tmp_path / "bad.c3d")


def test_c3d_without_ezc3d_is_one_line_naming_the_extra(tmp_path, monkeypatch, capsys):
    path = tmp_path / "walk.c3d"
    path.write_bytes(b"\x02P")
    monkeypatch.setitem(sys.modules, "ezc3d", None)        # import ezc3d -> ImportError
    with pytest.raises(MissingDependencyError, match=r"pip install pinmsk\[c3d\]") as info:
        read_trial(path)
    assert isinstance(info.value, ImportError) and isinstance(info.value, PinmskError)
    code, _, err = _cli(["id", "forearm", str(path), "-o", str(tmp_path / "o.sto")], capsys)
    assert code == 2 and err.startswith("pinmsk: error: reading C3D files needs the optional dependency 'ezc3d'")
    assert "pip install pinmsk[c3d]" in err and len(err.strip().splitlines()) == 1


def test_read_trial_opens_the_real_c3d(shared_data):
    pytest.importorskip("ezc3d")
    path = shared_data / "real" / "pyomeca-box-lift-emg" / "markers_analogs.c3d"
    if not path.is_file():
        pytest.skip("pyomeca c3d absent")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                    # marker gaps filled
        mk = read_trial(path)
        emg = read_trial(path, part="analogs")
        with pytest.raises(TrialError, match=r"has no platforms; it has 51 markers and 38 analogs: pass "
                                             r"part='markers'"):
            read_trial(path, part="platforms")
    assert mk.n_frames == 580 and mk.rate == pytest.approx(100.0) and mk.n_channels == 3 * 51
    assert emg.rate == pytest.approx(2000.0) and "Biceps.EMG4" in emg.names


def test_read_mapped_takes_a_models_coordinates_from_opensim_state_paths(tmp_path, gait2d):
    """A Moco / OpenSim states file (columns /jointset/<joint>/<coord>/value and .../speed, in degrees):
    read_mapped gives the model's coordinates under their own names, in radians (speeds too); a
    coordinate that already has its own column keeps it; without a model nothing is renamed."""
    from pinmsk.io.channel_map import read_mapped
    t = np.linspace(0.0, 1.0, 11)
    cols = {}
    for c in gait2d.coordinates:
        cols[f"/jointset/j_{c}/{c}/value"] = (30.0 if c != "torso_x" else 0.0) * np.sin(t) + (t if c == "torso_x" else 0)
        cols[f"/jointset/j_{c}/{c}/speed"] = 30.0 * np.cos(t)
    cols["knee_r"] = np.full(t.size, 10.0)               # its own column wins over the state path
    write_trial(Trial(t, cols), tmp_path / "states.sto")
    text = (tmp_path / "states.sto").read_text().replace("inDegrees=no", "inDegrees=yes")
    (tmp_path / "states.sto").write_text(text)
    got = read_mapped(tmp_path / "states.sto", model=gait2d)
    np.testing.assert_allclose(got["hip_r"], np.radians(30.0 * np.sin(t)), atol=1e-12)
    np.testing.assert_allclose(got["hip_r_speed"], np.radians(30.0 * np.cos(t)), atol=1e-12)
    np.testing.assert_allclose(got["torso_x"], t, atol=1e-12)             # a translation stays in m
    np.testing.assert_allclose(got["knee_r"], np.radians(10.0), atol=1e-12)
    assert "hip_r" not in read_mapped(tmp_path / "states.sto").names
