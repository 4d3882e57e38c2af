"""Inverse kinematics: recovers known poses from synthetic markers; gaps; errors."""
import numpy as np
import pytest

import pinmsk
from pinmsk import Trial, TrialError
from pinmsk.ik import InverseKinematics, markers_trial, model_marker_positions
from pinmsk.markers import load_marker_set


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def _motion(model, n=120, rate=100.0):
    t = np.arange(n) / rate
    q = np.zeros((n, model.nq))
    w = 2 * np.pi * 1.0
    ix = model.coordinate_index
    q[:, ix("torso_x")] = 1.2 * t
    q[:, ix("torso_y")] = 1.02 + 0.02 * np.sin(2 * w * t)
    q[:, ix("torso_angle")] = 0.05 + 0.04 * np.sin(w * t)
    q[:, ix("hip_r")] = -0.3 * np.sin(w * t)
    q[:, ix("knee_r")] = 0.6 + 0.5 * np.sin(w * t + 1.0)
    q[:, ix("ankle_r")] = 0.2 * np.sin(w * t + 2.0)
    q[:, ix("mtp_r")] = 0.15 * np.sin(w * t + 0.5)
    return t, q


def test_recovers_known_pose_from_csu_markers(gait2d):
    ms = load_marker_set("gait2d").subset("csu")
    t, q = _motion(gait2d)
    mk = markers_trial(gait2d, ms, t, q, axes="xy")
    ik = InverseKinematics(markers=ms, q0={"torso_y": 1.0}).fit(gait2d, mk)
    free = [gait2d.coordinate_index(c) for c in ("torso_x", "torso_y", "torso_angle", "hip_r", "knee_r", "ankle_r")]
    assert set(ik.free_coordinates_) == {"torso_x", "torso_y", "torso_angle", "hip_r", "knee_r", "ankle_r"}
    assert np.max(np.abs(ik.q_[:, free] - q[:, free])) < 1e-6
    assert ik.converged_.all()
    assert max(ik.marker_rms_.values()) < 1e-9
    assert ik.iterations_[1:].mean() < 6          # warm start: few iterations per frame
    # result channels are in the model's written order
    assert ik.result_.names == gait2d.coordinate_order
    np.testing.assert_allclose(ik.result_["knee_r"], q[:, gait2d.coordinate_index("knee_r")], atol=1e-6)


def test_recovers_pose_with_winter_markers_3d_axes(gait2d):
    ms = load_marker_set("gait2d").subset("winter")
    t, q = _motion(gait2d, n=40)
    mk = markers_trial(gait2d, ms, t, q, axes="xyz")
    ik = InverseKinematics(markers=ms, q0={"torso_y": 1.0}).fit(gait2d, mk)
    assert ik.axes_ == "xyz"
    assert "mtp_r" in ik.free_coordinates_
    idx = [gait2d.coordinate_index(c) for c in ik.free_coordinates_]
    assert np.max(np.abs(ik.q_[:, idx] - q[:, idx])) < 1e-6


def test_marker_gap_gets_zero_weight(gait2d):
    ms = load_marker_set("gait2d").subset("winter")
    t, q = _motion(gait2d, n=30)
    mk = markers_trial(gait2d, ms, t, q, axes="xy")
    d = mk.to_dict(); d.pop("time")
    d["RIGHT_FIBULA_x"][10:15] = np.nan
    d["RIGHT_FIBULA_y"][10:15] = np.nan
    ik = InverseKinematics(markers=ms, q0={"torso_y": 1.0}).fit(gait2d, Trial(t, d, meta=dict(mk.meta)))
    idx = [gait2d.coordinate_index(c) for c in ik.free_coordinates_]
    assert np.max(np.abs(ik.q_[:, idx] - q[:, idx])) < 1e-6
    assert np.isnan(ik.marker_error_[12, ms.names.index("RIGHT_FIBULA")])


def test_marker_rms_reports_a_known_offset(gait2d):
    ms = load_marker_set("gait2d").subset("winter")
    t, q = _motion(gait2d, n=20)
    mk = markers_trial(gait2d, ms, t, q, axes="xy")
    d = mk.to_dict(); d.pop("time")
    d["RIB_CAGE_x"] = d["RIB_CAGE_x"] + 0.01   # 1 cm misplaced marker: IK spreads, RMS > 0
    ik = InverseKinematics(markers=ms, q0={"torso_y": 1.0}).fit(gait2d, Trial(t, d, meta=dict(mk.meta)))
    assert 0.0 < ik.marker_rms_["RIB_CAGE"] < 0.01
    assert ik.frame_rms_.shape == (20,)


def test_too_few_markers(gait2d):
    ms = load_marker_set("gait2d").subset(["RLM", "RHEE"])
    t, q = _motion(gait2d, n=5)
    mk = markers_trial(gait2d, ms, t, q, axes="xy")
    with pytest.raises(TrialError, match="cannot determine"):
        InverseKinematics(markers=ms, coordinates=["torso_x", "torso_y", "torso_angle", "hip_r", "knee_r"]
                          ).fit(gait2d, mk)


def test_no_matching_markers(gait2d):
    ms = load_marker_set("gait2d").subset("csu")
    mk = Trial(np.arange(3.0), {"X_x": np.zeros(3), "X_y": np.zeros(3)})
    with pytest.raises(TrialError, match="none of the model markers"):
        InverseKinematics(markers=ms).fit(gait2d, mk)


def test_marker_positions_follow_the_body(gait2d):
    ms = load_marker_set("gait2d").subset(["RLM", "RSHO"])
    q = np.zeros((1, gait2d.nq)); q[0, gait2d.coordinate_index("torso_y")] = 1.0681
    x = model_marker_positions(gait2d, ms, q)[0]
    np.testing.assert_allclose(x[0, :2], [0.0, 0.05268445], atol=1e-6)        # ankle centre at standing
    np.testing.assert_allclose(x[1, :2], [0.0, 1.0681 + 0.266], atol=1e-12)


def test_coordinate_task_weighs_against_markers(gait2d):
    # every marker shifted by d along x, only torso_x solved: the markers alone put it at q + d; a task on
    # q with weight w (times the frame's total marker weight n, as OpenSim's IKCoordinateTask) against n
    # markers of weight 1 gives the weighted mean q + n d / (n + w n) = q + d / (1 + w)
    ms = load_marker_set("gait2d").subset("csu")
    t, q = _motion(gait2d, n=3)
    mk = markers_trial(gait2d, ms, t, q, axes="xy")
    d = 0.05
    shifted = Trial(t, {k: mk[k] + (d if k.endswith("_x") else 0.0) for k in mk.names}, meta=dict(mk.meta))
    ix = gait2d.coordinate_index("torso_x")
    w = 7.0
    tasks = {"torso_x": (w, float(q[1, ix]))}
    q0 = {c: float(q[1, gait2d.coordinate_index(c)]) for c in gait2d.coordinates}
    one = Trial(t[1:2], {k: shifted[k][1:2] for k in shifted.names}, meta=dict(mk.meta))
    ik = InverseKinematics(markers=ms, q0=q0, coordinates=["torso_x"], coordinate_tasks=tasks,
                           tol=1e-13).fit(gait2d, one)
    assert ik.q_[0, ix] == pytest.approx(q[1, ix] + d / (1 + w), abs=1e-9)
    free = InverseKinematics(markers=ms, q0=q0, coordinates=["torso_x"]).fit(gait2d, one)
    assert free.q_[0, ix] == pytest.approx(q[1, ix] + d, abs=1e-9)
    with pytest.raises(pinmsk.ModelError, match="weights must be finite"):
        InverseKinematics(markers=ms, coordinate_tasks={"torso_x": (-1.0, 0.0)}).fit(gait2d, mk)
