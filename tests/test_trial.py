"""Tests of pinmsk.trial: the Trial container, channel names and validation."""

import copy
import pickle
import re

import numpy as np
import pytest

from pinmsk.errors import TrialError
from pinmsk.trial import (
    DEGREES_THRESHOLD,
    GroundReactionName,
    Trial,
    activation_channels,
    coordinate_channels,
    emg_channels,
    excitation_channels,
    force_channels,
    ground_reaction_channels,
    is_angular_name,
    moment_channels,
    parse_ground_reaction,
    speed_channels,
)

W = 2 * np.pi


@pytest.fixture
def trial():
    t = np.arange(0.0, 1.0 + 1e-12, 0.01)  # 101 frames at 100 Hz
    return Trial(
        t,
        {
            "elbow_flexion": 0.5 + 0.3 * np.sin(W * t),
            "shoulder_elev": 0.2 * t,
            "elbow_flexion_moment": 2.0 * t,
            "biceps_activation": np.full(t.shape, 0.1),
        },
        units={"elbow_flexion": "rad"},
        meta={"source": "lab.mot", "in_degrees": False},
    )


# -- construction and access -------------------------------------------------------


def test_properties(trial):
    assert trial.names == ("elbow_flexion", "shoulder_elev", "elbow_flexion_moment", "biceps_activation")
    assert trial.n_frames == 101
    assert trial.n_channels == 4
    assert trial.values.shape == (101, 4)
    assert trial.duration == pytest.approx(1.0, abs=1e-12)
    assert trial.rate == pytest.approx(100.0, rel=1e-9)
    assert "shoulder_elev" in trial and "nope" not in trial
    np.testing.assert_array_equal(trial["shoulder_elev"], 0.2 * trial.time)
    assert trial.units == {"elbow_flexion": "rad"}
    assert trial.meta["source"] == "lab.mot"


def test_arrays_are_read_only_and_inputs_are_copied():
    t = np.array([0.0, 0.1, 0.2])
    x = np.array([1.0, 2.0, 3.0])
    tr = Trial(t, {"a": x})
    x[0] = 99.0
    assert tr["a"][0] == 1.0
    with pytest.raises(ValueError):
        tr["a"][0] = 5.0
    with pytest.raises(ValueError):
        tr.time[0] = 5.0
    with pytest.raises(TypeError):
        tr.meta["x"] = 1


def test_from_array_and_get(trial):
    tr = Trial.from_array(trial.time, trial.names, trial.values, meta={"k": 1})
    np.testing.assert_array_equal(tr.values, trial.values)
    got = trial.get(["shoulder_elev", "elbow_flexion"])
    assert got.shape == (101, 2)
    np.testing.assert_array_equal(got[:, 0], trial["shoulder_elev"])
    np.testing.assert_array_equal(got[:, 1], trial["elbow_flexion"])
    # one name: (N,) as trial[name], a writable copy; a list of one name keeps its column axis
    one = trial.get("shoulder_elev")
    assert one.shape == (101,) and one.flags.writeable
    np.testing.assert_array_equal(one, trial["shoulder_elev"])
    one[0] = 1e9
    assert trial["shoulder_elev"][0] != 1e9
    assert trial.get(["shoulder_elev"]).shape == (101, 1) and trial.get(("shoulder_elev",)).shape == (101, 1)
    assert trial.get("elbow_flexion", rows=[0, 2]).shape == (2,)
    np.testing.assert_array_equal(trial.get(["elbow_flexion"], rows=trial.time < 0.1)[:, 0],
                                  trial["elbow_flexion"][trial.time < 0.1])
    with pytest.raises(TrialError, match=r"values have shape \(101, 3\), expected \(N, C\) = \(101, 4\)"):
        Trial.from_array(trial.time, trial.names, trial.values[:, :3])


def test_missing_channel_suggests_close_matches(trial):
    with pytest.raises(TrialError, match=r"file 'lab.mot': missing channels: 'elbow_flex' \(did you mean 'elbow_flexion'"):
        trial["elbow_flex"]
    with pytest.raises(TrialError, match="'time' is the time base, use trial.time"):
        trial["time"]


def test_channel_shape_and_type_errors_name_the_channel():
    t = np.arange(4.0)
    with pytest.raises(TrialError, match=r"channel 'b' has shape \(3,\), expected \(4,\)"):
        Trial(t, {"a": np.zeros(4), "b": np.zeros(3)})
    with pytest.raises(TrialError, match="channel 'a': values are not numeric"):
        Trial(t, {"a": ["x", "y", "z", "w"]})


def test_non_monotonic_time_reports_row_and_values():
    t = np.array([0.0, 0.01, 0.03, 0.02, 0.04])
    with pytest.raises(TrialError, match=r"time is not strictly increasing at row 3: time\[3\]=0.02 <= time\[2\]=0.03"):
        Trial(t, {"a": np.zeros(5)})
    with pytest.raises(TrialError, match=r"at row 2: time\[2\]=0.01 <= time\[1\]=0.01"):
        Trial([0.0, 0.01, 0.01], {"a": np.zeros(3)})
    with pytest.raises(TrialError, match=r"time is not finite at row 1"):
        Trial([0.0, np.nan], {})


def test_duplicate_and_reserved_names():
    with pytest.raises(TrialError, match="duplicate channel names: 'a'"):
        Trial.from_array([0.0, 1.0], ["a", "b", "a"], np.zeros((2, 3)))
    with pytest.raises(TrialError, match="reserved for the time base"):
        Trial([0.0, 1.0], {"time": [0.0, 1.0]})


# -- new trials --------------------------------------------------------------------


def test_with_channels_adds_and_replaces_without_touching_the_original(trial):
    new = trial.with_channels({"shoulder_elev": np.ones(101)}, extra=np.arange(101.0))
    assert new.names == trial.names + ("extra",)
    np.testing.assert_array_equal(new["shoulder_elev"], 1.0)
    np.testing.assert_array_equal(new["extra"], np.arange(101.0))
    np.testing.assert_array_equal(trial["shoulder_elev"], 0.2 * trial.time)
    assert new.meta["source"] == "lab.mot"
    with pytest.raises(TrialError, match=r"channel 'bad' has shape \(3,\)"):
        trial.with_channels(bad=np.zeros(3))


def test_select_drop_and_matching(trial):
    assert trial.select(["shoulder_elev", "elbow_flexion"]).names == ("shoulder_elev", "elbow_flexion")
    assert trial.drop("biceps_activation").names == trial.names[:3]
    assert trial.select("elbow_flexion").units == {"elbow_flexion": "rad"}
    assert trial.drop("elbow_flexion").units == {}
    assert trial.channels_matching("*_moment") == ("elbow_flexion_moment",)
    assert trial.channels_matching(re.compile(r"^elbow")) == ("elbow_flexion", "elbow_flexion_moment")
    with pytest.raises(TrialError, match="missing channels: 'biceps'"):
        trial.drop("biceps")


def test_slice_time_includes_both_ends(trial):
    part = trial.slice_time(0.1, 0.2)
    assert part.n_frames == 11
    assert part.time[0] == pytest.approx(0.1) and part.time[-1] == pytest.approx(0.2)
    assert trial.slice_time(None, 0.05).n_frames == 6
    with pytest.raises(TrialError, match="no samples between 2.0 and 3.0 s; the trial spans 0 to 1 s"):
        trial.slice_time(2.0, 3.0)


def test_resample_cubic_and_linear_are_exact_on_their_polynomials():
    t = np.linspace(0.0, 1.0, 11)
    tr = Trial(t, {"cubic": 1 - 2 * t + 3 * t**3, "line": 4 * t - 1})
    new_t = np.linspace(0.0, 1.0, 37)
    cub = tr.resample(new_t)
    np.testing.assert_allclose(cub["cubic"], 1 - 2 * new_t + 3 * new_t**3, rtol=0, atol=1e-12)
    lin = tr.resample(new_t, method="linear")
    np.testing.assert_allclose(lin["line"], 4 * new_t - 1, rtol=0, atol=1e-12)
    at_rate = tr.resample(40.0)
    assert at_rate.n_frames == 41
    assert at_rate.rate == pytest.approx(40.0)
    assert at_rate.meta["resampled"] == "cubic"
    with pytest.raises(TrialError, match=r"new time\[1\]=1.5 is outside the trial \[0.0, 1.0\] s"):
        tr.resample([0.5, 1.5])


def test_resample_cubic_refuses_nan_linear_keeps_it_local():
    t = np.linspace(0.0, 1.0, 11)
    x = t.copy()
    x[5] = np.nan
    tr = Trial(t, {"x": x})
    with pytest.raises(TrialError, match=r"channel 'x' has 1 non-finite value\(s\) \(NaN first\) at rows 5.*method='linear'"):
        tr.resample(20.0)
    lin = tr.resample(np.array([0.12, 0.47, 0.91]), method="linear")
    np.testing.assert_allclose(lin["x"][[0, 2]], [0.12, 0.91], rtol=1e-12)
    assert np.isnan(lin["x"][1])


def test_merge(trial):
    other = Trial(trial.time + 1e-12, {"emg": np.zeros(101)}, meta={"source": "emg.sto", "lab": "X"})
    merged = trial.merge(other)
    assert merged.names == trial.names + ("emg",)
    assert merged.meta["source"] == "lab.mot" and merged.meta["lab"] == "X"
    with pytest.raises(TrialError, match="different time bases.*resample one onto the other"):
        trial.merge(other.slice_time(0.0, 0.5))
    with pytest.raises(TrialError, match="both trials have channels 'shoulder_elev'"):
        trial.merge(trial.select("shoulder_elev"))


def test_to_dict_and_repr(trial):
    d = trial.to_dict()
    assert list(d) == ["time", *trial.names]
    d["time"][0] = -1.0  # a copy
    assert trial.time[0] == 0.0
    text = repr(trial)
    assert "101 frames" in text and "100 Hz" in text and "4 channels" in text and "lab.mot" in text


# -- validation ---------------------------------------------------------------------


def test_validate_passes_on_good_data(trial):
    assert trial.validate(coordinates=["elbow_flexion", "shoulder_elev"]) is trial


def test_validate_reports_nan_with_channel_and_rows(trial):
    x = trial["shoulder_elev"].copy()
    x[[17, 18, 40]] = np.nan
    bad = trial.with_channels(shoulder_elev=x)
    with pytest.raises(
        TrialError,
        match=r"file 'lab.mot': channel 'shoulder_elev' has 3 non-finite value\(s\) \(NaN first\) at rows 17, 18, 40 \(time 0.17 s\)",
    ):
        bad.validate()


def test_validate_reports_degrees_where_radians_declared():
    t = np.linspace(0.0, 1.0, 51)
    tr = Trial(
        t,
        {"elbow_flexion": 118.0 * np.sin(np.pi * t / 2), "pelvis_tx": 20.0 + t},
        meta={"source": "ik.mot", "in_degrees": False},
    )
    message = (
        "file 'ik.mot': column 'elbow_flexion' looks like degrees (max 118.0) but the file declares "
        "radians; if it is in degrees, pass --degrees (command line) or in_degrees=True (Python), or set "
        "inDegrees=yes in the header"
    )
    with pytest.raises(TrialError, match=re.escape(message)):
        tr.validate(coordinates=["elbow_flexion", "pelvis_tx"])  # pelvis_tx is a translation: not checked
    with pytest.raises(TrialError, match=re.escape(message)):
        tr.validate(angular=["elbow_flexion"])
    tr.validate()  # nothing declared angular: no unit check
    in_memory = Trial(t, {"knee": np.full(51, 60.0)})
    with pytest.raises(TrialError, match=r"column 'knee' looks like degrees \(max 60.0\) but trial channels must be in radians"):
        in_memory.validate(angular=["knee"])
    # just under the threshold (540 degrees in radians) is accepted
    Trial(t, {"knee": np.full(51, DEGREES_THRESHOLD * 0.999)}).validate(angular=["knee"])


def test_require_suggests_close_matches(trial):
    assert trial.require(["elbow_flexion"]) == ("elbow_flexion",)
    with pytest.raises(
        TrialError,
        match=r"missing coordinate channel\(s\): 'elbow_flex' \(did you mean 'elbow_flexion'",
    ):
        trial.require(["shoulder_elev", "elbow_flex"])
    with pytest.raises(TrialError, match=r"missing coordinate channel\(s\): 'wrist_dev'"):
        trial.validate(coordinates=["wrist_dev"])


# -- kinematics -----------------------------------------------------------------------


def test_kinematics_returns_q_v_a(trial):
    q, v, a = trial.kinematics(["elbow_flexion", "shoulder_elev"])
    t = trial.time
    assert q.shape == v.shape == a.shape == (101, 2)
    np.testing.assert_allclose(v[:, 0], 0.3 * W * np.cos(W * t), rtol=0, atol=1e-7 * 0.3 * W)
    np.testing.assert_allclose(a[:, 0], -0.3 * W**2 * np.sin(W * t), rtol=0, atol=1e-5 * 0.3 * W**2)
    np.testing.assert_allclose(v[:, 1], 0.2, rtol=1e-9)
    np.testing.assert_allclose(a[:, 1], 0.0, atol=1e-8)


def test_kinematics_with_cutoff_and_smoothed(trial):
    q, v, a = trial.kinematics(["elbow_flexion"], cutoff=10.0)
    sm = trial.smoothed(10.0, names=["elbow_flexion"])
    np.testing.assert_allclose(q[:, 0], sm["elbow_flexion"], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(sm["shoulder_elev"], trial["shoulder_elev"])
    assert sm.meta["lowpass_cutoff"] == 10.0
    # a 1 Hz signal passes a 10 Hz filter nearly unchanged (gain 1 - 1e-8)
    inner = slice(20, -20)
    np.testing.assert_allclose(q[inner, 0], trial["elbow_flexion"][inner], atol=1e-4)


def test_kinematics_refuses_degrees_and_missing_coordinates(trial):
    deg = trial.with_channels(elbow_flexion=np.rad2deg(trial["elbow_flexion"]))
    with pytest.raises(TrialError, match=r"column 'elbow_flexion' looks like degrees \(max 45.8\)"):
        deg.kinematics(["elbow_flexion"])
    with pytest.raises(TrialError, match="did you mean 'shoulder_elev'"):
        trial.kinematics(["shoulder_elv"])


# -- names ------------------------------------------------------------------------------


def test_channel_name_helpers():
    assert coordinate_channels(["knee"]) == ("knee",)
    assert speed_channels(["knee", "hip"]) == ("knee_speed", "hip_speed")
    assert moment_channels("knee") == ("knee_moment",)
    assert activation_channels(["bic"]) == ("bic_activation",)
    assert excitation_channels(["bic"]) == ("bic_excitation",)
    assert emg_channels(["bic"]) == ("bic_emg",)
    assert force_channels(["bic"]) == ("bic_force",)
    assert ground_reaction_channels()[:3] == ("ground_force_vx", "ground_force_vy", "ground_force_vz")
    r = ground_reaction_channels("r")
    assert len(r) == 9 and r[1] == "r_ground_force_vy" and r[4] == "r_ground_force_py" and r[8] == "r_ground_torque_z"


@pytest.mark.parametrize(
    ("name", "parsed"),
    [
        ("ground_force_vy", GroundReactionName(None, "force", "y")),
        ("r_ground_force_vy", GroundReactionName("r", "force", "y")),
        ("1_ground_force_px", GroundReactionName("1", "point", "x")),
        ("ground_force_l_vz", GroundReactionName("l", "force", "z")),
        ("ground_torque_x", GroundReactionName(None, "torque", "x")),
        ("1_ground_torque_z", GroundReactionName("1", "torque", "z")),
        ("ground_torque_r_y", GroundReactionName("r", "torque", "y")),
        ("knee_angle_r", None),
        ("ground_force_vw", None),
    ],
)
def test_parse_ground_reaction(name, parsed):
    assert parse_ground_reaction(name) == parsed


@pytest.mark.parametrize(
    ("name", "angular"),
    [
        ("r_elbow_flex", True),
        ("knee_angle_r", True),
        ("knee_angle_r_speed", True),
        ("box_rotX", True),
        ("/jointset/hip_r/hip_flexion_r/value", True),
        ("pelvis_tx", False),
        ("pelvis_tz_u", False),
        ("/jointset/ground_pelvis/pelvis_ty/speed", False),
        ("/forceset/soleus_r/activation", False),
        ("box_transX", False),
        ("knee_angle_r_moment", False),
        ("pelvis_tx_force", False),
        ("ground_force_vy", False),
        ("1_ground_force_px", False),
        ("ground_torque_x", False),
        ("bic_activation", False),
        ("bic_excitation", False),
        ("bic_emg", False),
        ("soleus.fiber_length", False),
        ("marker_x", False),
        ("time", False),
    ],
)
def test_angular_name_heuristic(name, angular):
    assert is_angular_name(name) is angular


def test_pickle_and_deepcopy_round_trip(trial):
    for clone in (pickle.loads(pickle.dumps(trial)), copy.deepcopy(trial)):
        assert clone.names == trial.names
        np.testing.assert_array_equal(clone.values, trial.values)
        np.testing.assert_array_equal(clone.time, trial.time)
        assert dict(clone.meta) == dict(trial.meta) and dict(clone.units) == dict(trial.units)
        assert not clone.values.flags.writeable
