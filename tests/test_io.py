"""Tests of pinmsk.io: CSV and OpenSim .sto/.mot reading and atomic writing."""

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import pinmsk.io.tables as pio
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.errors import RepairWarning, TrialError
from pinmsk.io.tables import read_sto_header, read_trial, write_trial
from pinmsk.trial import Trial, parse_ground_reaction


def shared_file(relative: str) -> Path:
    root = shared_data_dir()
    if root is None or not (root / relative).is_file():
        pytest.skip(f"shared data file {relative} not available (set PINMSK_SHARED_DATA)")
    return root / relative


@pytest.fixture
def trial():
    rng = np.random.default_rng(7)
    t = np.arange(50) / 120.0
    return Trial(
        t,
        {
            "r_elbow_flex": rng.uniform(-2.0, 2.0, 50),
            "pelvis_tx": rng.uniform(-1e3, 1e3, 50),
            "r_elbow_flex_moment": rng.standard_normal(50) * 1e-7,
            "ground_force_vy": rng.uniform(0.0, 1e4, 50),
        },
        meta={"name": "Test trial"},
    )


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _error(path, match, **kw):
    with pytest.raises(TrialError) as info:
        read_trial(path, **kw)
    assert re.search(match, str(info.value)), str(info.value)
    return str(info.value)


# -- round trips ---------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".csv", ".sto", ".mot"])
def test_round_trip_is_exact_at_17_digits(trial, tmp_path, suffix):
    path = write_trial(trial, tmp_path / f"trial{suffix}", precision=17)
    back = read_trial(path)
    assert back.names == trial.names
    np.testing.assert_array_equal(back.time, trial.time)
    np.testing.assert_array_equal(back.values, trial.values)
    assert back.meta["source"] == str(path)
    assert back.meta["format"] == suffix[1:]
    assert back.meta["converted_to_radians"] == ()


@pytest.mark.parametrize("suffix", [".csv", ".sto"])
def test_default_precision_keeps_9_significant_digits(trial, tmp_path, suffix):
    path = write_trial(trial, tmp_path / f"trial{suffix}")
    back = read_trial(path)
    # each value within half a unit of its 9th significant digit
    for got, want in ((back.time, trial.time), (back.values, trial.values)):
        mag = 10.0 ** np.floor(np.log10(np.where(want == 0, 1.0, np.abs(want))))
        assert np.all(np.abs(got - want) <= 0.5e-8 * mag * (1 + 1e-12))
    # and the text is exactly %.9g (so the size is that of %.9g, ~60 % of 17 digits)
    rows = path.read_text().splitlines()[-trial.n_frames:]
    sep = "," if suffix == ".csv" else "\t"
    table = np.column_stack([trial.time, trial.values])
    assert rows == [sep.join("%.9g" % v for v in row) for row in table.tolist()]
    size17 = write_trial(trial, tmp_path / f"t17{suffix}", precision=17).stat().st_size
    assert path.stat().st_size < 0.7 * size17


def test_precision_is_settable_and_checked(trial, tmp_path):
    path = write_trial(trial, tmp_path / "p4.csv", precision=4)
    first = path.read_text().splitlines()[1].split(",")
    assert first == ["%.4g" % v for v in [trial.time[0], *trial.values[0]]]
    for bad in (0, 18, 2.5, "9", True):
        with pytest.raises(TrialError, match="precision must be a whole number .* 1 to 17"):
            write_trial(trial, tmp_path / "bad.csv", precision=bad)
    assert not (tmp_path / "bad.csv").exists()


def test_time_column_gets_the_digits_its_steps_need(tmp_path):
    # 1 kHz for 3 days: 9 digits would merge neighbouring time stamps
    t = 2.5e5 + np.arange(1000) * 1e-3
    tr = Trial(t, {"x": np.linspace(0.0, 1.0, 1000)})
    back = read_trial(write_trial(tr, tmp_path / "long.sto"))
    np.testing.assert_allclose(np.diff(back.time), 1e-3, rtol=1e-2)
    assert back["x"][1] == float("%.9g" % tr["x"][1])


def test_vectorised_formatter_is_exactly_percent_g():
    rng = np.random.default_rng(3)
    n = 6000
    values = np.concatenate([
        rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n),       # every notation
        rng.integers(-999, 1000, n) / 1000.0,                            # short decimals
        (rng.integers(1, 10 ** 9, n) + 0.5) * 10.0 ** rng.integers(-12, 3, n),  # near ties
        np.nextafter(10.0 ** rng.integers(-12, 12, n), 0.0),            # just below powers of ten
        [0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324, -1e-310, 1.7976931348623157e308,
         9.9999999995, 0.99999999995, 999999999.5, 1e-5, 1e-4, 123456789.0, 1234567890.0,
         0.5, 1.5, 2.5, 0.95, 9.5, 1e100, -1e-100],
    ])
    values = values[: values.size // 4 * 4].reshape(-1, 4)
    for p in (1, 3, 6, 9, 12):
        prec = np.array([min(p + 2, 12), p, p, p])
        seps = np.frombuffer(b",,\t\n", dtype=np.uint8)
        got = pio._format_block(values, pio._columns(prec, seps)).decode()
        want = "".join(",".join("%.*g" % (int(q), v) for q, v in zip(prec[:2], row[:2])) + ","
                       + "\t".join("%.*g" % (p, v) for v in row[2:]) + "\n" for row in values.tolist())
        assert got == want


def test_sto_header_written_and_read(trial, tmp_path):
    path = write_trial(trial, tmp_path / "trial.sto")
    lines = path.read_text().splitlines()
    assert lines[:7] == [
        "Test trial", "version=1", "nRows=50", "nColumns=5", "inDegrees=no", "endheader",
        "time\tr_elbow_flex\tpelvis_tx\tr_elbow_flex_moment\tground_force_vy",
    ]  # fmt: skip
    header = read_sto_header(path)
    assert header.name == "Test trial"
    assert (header.n_rows, header.n_columns, header.in_degrees, header.n_lines) == (50, 5, False, 6)
    assert read_trial(path).meta["name"] == "Test trial"


def test_write_in_degrees_converts_only_angles_and_reads_back(trial, tmp_path):
    path = write_trial(trial, tmp_path / "deg.mot", in_degrees=True, precision=17)
    assert "inDegrees=yes" in path.read_text().splitlines()
    raw = np.loadtxt(path, skiprows=7)
    np.testing.assert_allclose(raw[:, 1], np.rad2deg(trial["r_elbow_flex"]), rtol=1e-15)
    np.testing.assert_array_equal(raw[:, 2], trial["pelvis_tx"])
    np.testing.assert_array_equal(raw[:, 4], trial["ground_force_vy"])
    back = read_trial(path)
    assert back.meta["converted_to_radians"] == ("r_elbow_flex",)
    np.testing.assert_allclose(back.values, trial.values, rtol=1e-12, atol=0)
    with pytest.raises(TrialError, match="CSV file cannot declare degrees"):
        write_trial(trial, tmp_path / "deg.csv", in_degrees=True)


def test_in_degrees_file_is_converted_to_radians(tmp_path):
    path = _write(
        tmp_path / "ik.mot",
        "Coordinates\nversion=1\nnRows=3\nnColumns=5\ninDegrees=yes\n\n"
        "Angles are in degrees.\nendheader\n"
        "time\tknee_angle_r\tpelvis_tx\tknee_angle_r_moment\tankle_angle_r\n"
        "0.00\t90\t0.5\t10\t-45\n"
        "0.01\t180\t0.6\t20\t30\n"
        "0.02\t-60\t0.7\t30\t1\n",
    )
    tr = read_trial(path)
    np.testing.assert_allclose(tr["knee_angle_r"], [np.pi / 2, np.pi, -np.pi / 3], rtol=1e-15)
    np.testing.assert_allclose(tr["ankle_angle_r"], [-np.pi / 4, np.pi / 6, np.pi / 180], rtol=1e-15)
    np.testing.assert_array_equal(tr["pelvis_tx"], [0.5, 0.6, 0.7])  # metres, untouched
    np.testing.assert_array_equal(tr["knee_angle_r_moment"], [10, 20, 30])
    assert tr.meta["in_degrees"] is True
    assert tr.meta["converted_to_radians"] == ("knee_angle_r", "ankle_angle_r")
    assert read_sto_header(path).comments == ("Angles are in degrees.",)
    only = read_trial(path, angular=["ankle_angle_r"])
    np.testing.assert_array_equal(only["knee_angle_r"], [90, 180, -60])
    # names that are not columns (e.g. all of a model's coordinates) are ignored
    some = read_trial(path, angular=["ankle_angle_r", "hip_flexion_r"])
    assert some.meta["converted_to_radians"] == ("ankle_angle_r",)


def test_whitespace_and_comma_separated_sto(tmp_path):
    spaced = _write(tmp_path / "a.sto", "x\nnRows=2\nendheader\ntime  a   b\n 0  1 2\n 1  3 4\n")
    np.testing.assert_array_equal(read_trial(spaced).values, [[1, 2], [3, 4]])
    commas = _write(
        tmp_path / "b.mot", "x,,,\nversion=1,,,\nnRows=2,,,\nnColumns=3,,,\nendheader,,,\ntime,a,b\n0,1,2,\n1,3,4\n"
    )
    tr = read_trial(commas)
    assert tr.names == ("a", "b")
    np.testing.assert_array_equal(tr.values, [[1, 2], [3, 4]])


# -- bad input --------------------------------------------------------------------------


def test_missing_time_column(tmp_path):
    _error(_write(tmp_path / "a.csv", "frame,a\n0,1\n1,2\n"), r"a.csv', line 1: missing time column; the first column is 'frame'")
    _error(
        _write(tmp_path / "a.sto", "x\nendheader\nknee\ttime\n1\t0\n"),
        r"a.sto', line 3: missing time column; the first column is 'knee'",
    )


def test_non_monotonic_time_names_the_line(tmp_path):
    path = _write(tmp_path / "t.csv", "time,a\n0.0,1\n0.1,2\n0.05,3\n0.2,4\n")
    _error(path, r"t.csv', line 4 \(data row 2\): time 0.05 is not greater than 0.1 on line 3")


def test_ragged_row_names_the_line(tmp_path):
    path = _write(tmp_path / "r.csv", "time,a,b\n0,1,2\n0.1,1\n0.2,1,2\n0.3,1,2,3\n")
    _error(path, r"r.csv', line 3: ragged row with 2 values but 3 column labels on line 1 \(1 more ragged rows, lines 5\)")
    sto = _write(tmp_path / "r.sto", "x\nendheader\ntime\ta\n0\t1\n0.1\t1\t5\n")
    _error(sto, r"r.sto', line 5: ragged row with 3 values but 2 column labels on line 3")


def test_non_numeric_cell_names_line_and_column(tmp_path):
    path = _write(tmp_path / "n.csv", "time,a,b\n0,1,2\n0.1,1,oops\n")
    _error(path, r"n.csv', line 3, column 3 \('b'\): cannot read 'oops' as a number")
    sto = _write(tmp_path / "n.sto", "x\nendheader\ntime\ta\tb\n0\t1\t2\n0.1\t\t3\n")
    _error(sto, r"n.sto', line 5, column 2 \('a'\): cannot read '' as a number")


def test_duplicate_columns_are_named(tmp_path):
    path = _write(tmp_path / "d.csv", "time,a,b,a\n0,1,2,3\n")
    _error(path, r"d.csv', line 1: duplicate column names 'a' \(columns 2, 4\)")


def test_nrows_and_ncolumns_mismatch(tmp_path):
    rows = _write(tmp_path / "rows.sto", "x\nversion=1\nnRows=3\nnColumns=2\ninDegrees=no\nendheader\ntime\ta\n0\t1\n1\t2\n")
    _error(rows, r"rows.sto': header says nRows=3 \(line 3\) but there are 2 data rows \(lines 8-9\).*"
                 r"pass --lenient \(command line\) or strict=False \(Python\)")
    cols = _write(tmp_path / "cols.sto", "x\nversion=1\nnRows=2\nnColumns=3\ninDegrees=no\nendheader\ntime\ta\n0\t1\n1\t2\n")
    _error(cols, r"cols.sto': header says nColumns=3 \(line 4\) but the column-label line 7 has 2 columns \(time, a\)")
    with pytest.warns(RepairWarning, match=r"rows.sto: header says nRows=3 \(line 3\), data has 2 rows \(lines 8-9\); "
                                           r"used the data's 2$"):
        tr = read_trial(rows, strict=False)
    assert tr.n_frames == 2 and "nRows=3" in tr.meta["read_notes"][0]


def test_repeated_time_stamps_need_strict_false(tmp_path):
    path = _write(tmp_path / "rep.sto", "x\nendheader\ntime\ta\n0\t1\n1\t2.0000000001\n1\t2.0000000002\n")
    _error(path, r"line 6 \(data row 2\): time 1.0 is not greater than 1.0 on line 5.*it repeats the time stamp "
                 r"of the line before; to read the file anyway, pass --lenient")
    with pytest.warns(RepairWarning, match=r"rep.sto: dropped 1 duplicated time stamp at line 6 \(kept the first "
                                           r"of each; each repeated the row before\)"):
        tr = read_trial(path, strict=False)
    assert tr.n_frames == 2
    different = _write(tmp_path / "diff.sto", "x\nendheader\ntime\ta\n0\t1\n1\t2\n1\t3\n")
    with pytest.raises(TrialError, match="not greater"):
        read_trial(different)
def test_empty_and_header_only_files(tmp_path):
    _error(_write(tmp_path / "e.csv", ""), r"e.csv' is empty")
    _error(_write(tmp_path / "e.sto", "\n\n"), r"e.sto' is empty")
    _error(_write(tmp_path / "h.csv", "time,a\n"), r"h.csv': header only; column labels on line 1 but no data rows")
    _error(_write(tmp_path / "h.sto", "x\nnRows=0\nendheader\n"), r"h.sto': header only; nothing after 'endheader' on line 3")
    _error(_write(tmp_path / "h2.sto", "x\nendheader\ntime\ta\n"), r"h2.sto': header only")
    _error(_write(tmp_path / "n.sto", "x\nversion=1\ntime\ta\n0\t1\n"), r"n.sto': no 'endheader' line")


def test_bad_header_values_and_types(tmp_path):
    _error(_write(tmp_path / "d.sto", "x\ninDegrees=maybe\nendheader\ntime\ta\n0\t1\n"), r"line 2: inDegrees='maybe' must be yes or no")
    _error(_write(tmp_path / "v.sto", "x\nDataType=Vec3\nendheader\ntime\ta\n0\t1\n"), r"line 2: DataType='Vec3' is not supported")
    with pytest.raises(TrialError, match=r"unsupported file type '.txt'"):
        read_trial(tmp_path / "x.txt")


def test_degrees_in_a_radians_file_are_caught_by_validate(tmp_path):
    path = _write(
        tmp_path / "ik.mot",
        "Coordinates\nversion=1\nnRows=2\nnColumns=2\ninDegrees=no\nendheader\n"
        "time\telbow_flexion\n0\t12.5\n0.01\t118\n",
    )
    tr = read_trial(path)
    message = (
        f"file '{path}': column 'elbow_flexion' looks like degrees (max 118.0) but the file "
        "declares radians; if it is in degrees, pass --degrees (command line) or in_degrees=True (Python), "
        "or set inDegrees=yes in the header"
    )
    with pytest.raises(TrialError, match=re.escape(message)):
        tr.validate(coordinates=["elbow_flexion"])
    # told so, the reader converts it (the header's inDegrees=no overridden)
    told = read_trial(path, in_degrees=True)
    np.testing.assert_allclose(told["elbow_flexion"], np.deg2rad([12.5, 118.0]))
    assert told.meta["in_degrees"] is True and told.meta["converted_to_radians"] == ("elbow_flexion",)
    told.validate(coordinates=["elbow_flexion"])


# -- atomic writes ------------------------------------------------------------------------


def test_failed_write_leaves_no_file_and_no_temp_file(trial, tmp_path, monkeypatch):
    def fail_midway(fh, table, *args):
        fh.write("0\t1\t2\n")  # part of the body reaches the temporary file
        raise OSError("disk full")

    monkeypatch.setattr(pio, "_write_rows", fail_midway)
    for name in ("out.sto", "out.csv"):
        with pytest.raises(OSError, match="disk full"):
            write_trial(trial, tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_existing_file(trial, tmp_path, monkeypatch):
    target = write_trial(trial, tmp_path / "keep.sto")
    before = target.read_bytes()

    def fail(fh, table, *args):
        raise ValueError("cannot format")

    monkeypatch.setattr(pio, "_write_rows", fail)
    with pytest.raises(ValueError, match="cannot format"):
        write_trial(trial.with_channels(extra=np.zeros(50)), target)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["keep.sto"]


def test_write_rejects_names_with_tabs(tmp_path):
    bad = Trial([0.0, 1.0], {"a\tb": [1.0, 2.0]})
    with pytest.raises(TrialError, match="channel names contain tabs or line breaks"):
        write_trial(bad, tmp_path / "bad.sto")
    assert list(tmp_path.iterdir()) == []


# -- the OpenSim example files (skipped when /work/shared/data is absent) -----------------


def test_reads_arm26_inverse_kinematics_mot():
    path = shared_file("opensim-models/Arm26/arm26_InverseKinematics.mot")
    tr = read_trial(path)
    assert tr.names == ("r_shoulder_elev", "r_elbow_flex")
    assert tr.n_frames == 121
    assert tr.rate == pytest.approx(120.0, rel=1e-4)
    assert tr.meta["in_degrees"] is True
    # first row of the file: 0.00000000  -0.03394423  -0.05440752 (degrees)
    np.testing.assert_allclose(tr.values[0], np.deg2rad([-0.03394423, -0.05440752]), rtol=1e-15)
    tr.validate(coordinates=["r_shoulder_elev", "r_elbow_flex"])
    q, v, a = tr.kinematics(["r_shoulder_elev", "r_elbow_flex"], cutoff=6.0)
    assert q.shape == v.shape == a.shape == (121, 2)


def test_reads_arm26_inverse_dynamics_sto():
    path = shared_file("opensim-models/Arm26/reference_outputs/InverseDynamics_Filtered/arm26_InverseDynamics.sto")
    tr = read_trial(path)
    assert tr.names == ("r_shoulder_elev_moment", "r_elbow_flex_moment")
    assert tr.meta["in_degrees"] is False and tr.meta["name"] == "Inverse Dynamics"
    assert tr.time[0] == -0.00000020
    np.testing.assert_array_equal(tr.values[0], [0.07203129, -0.00419195])


def test_reads_gait_grf_mot_without_converting_forces():
    path = shared_file("opensim-models/Gait10dof18musc/ExperimentalData/subject01_walk_grf.mot")
    header = read_sto_header(path)
    assert (header.n_rows, header.n_columns, header.in_degrees) == (1501, 19, True)
    tr = read_trial(path)  # inDegrees=yes, but no column is an angle
    assert tr.n_frames == 1501 and tr.n_channels == 18
    assert tr.meta["converted_to_radians"] == ()
    np.testing.assert_array_equal(tr.values[0, :3], [101.5119767, 745.4661142, -47.44870554])
    assert tr["1_ground_force_vy"][0] == 20.49185173
    sides = {parse_ground_reaction(n).side for n in tr.names}
    assert sides == {None, "1"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tr.validate()
