"""Ground reaction forces: COP from plate moments, sign checks, wrenches on the feet, torso residuals."""
import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk import Trial, TrialError
from pinmsk.grf import (check_vertical_force, cop_from_plate, external_forces, torso_residuals,
                        transfer_cop)


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def test_cop_from_hand_computed_plate_moment():
    F = np.array([[100.0, 700.0, 50.0]])
    p = np.array([0.3, 0.02, -0.1])          # COP on the plate surface y = 0.02
    o = np.array([0.1, -0.05, 0.2])          # moment reference point
    Ty = 2.0
    r = p - o
    # by hand: r x F = (r_y F_z - r_z F_y, r_z F_x - r_x F_z, r_x F_y - r_y F_x)
    M = np.array([[r[1] * 50 - r[2] * 700 + 0.0, r[2] * 100 - r[0] * 50 + Ty, r[0] * 700 - r[1] * 100]])
    np.testing.assert_allclose(M, [[0.07 * 50 + 0.3 * 700, -0.3 * 100 - 0.2 * 50 + 2.0, 0.2 * 700 - 0.07 * 100]])
    cop, free = cop_from_plate(F, M, surface_height=0.02, origin=o)
    np.testing.assert_allclose(cop[0], p, atol=1e-12)
    np.testing.assert_allclose(free[0], [0.0, Ty, 0.0], atol=1e-12)


def test_cop_2d_moment_about_global_origin_with_belt_height():
    # CSU leg2d: M_z about the origin, belt surface at h: x = (M_z + h F_x) / F_y
    fx, fy, x, h = -40.0, 650.0, 0.71, 0.015
    mz = x * fy - h * fx
    cop, _ = cop_from_plate(np.array([[fx, fy, 0.0]]), np.array([mz]), surface_height=h)
    np.testing.assert_allclose(cop[0, :2], [x, h], atol=1e-12)
    cop, _ = cop_from_plate(np.array([[fx, 5.0, 0.0]]), np.array([mz]), min_force=20)
    assert np.all(np.isnan(cop))             # unloaded: undefined, not a number


def _grf_trial(fy, *, side="r", n=None):
    fy = np.asarray(fy, dtype=float)
    n = fy.size
    t = np.arange(n) / 100.0
    z = np.zeros(n)
    return Trial(t, {f"ground_force_{side}_vx": z, f"ground_force_{side}_vy": fy, f"ground_force_{side}_vz": z,
                     f"ground_force_{side}_px": z + 0.1, f"ground_force_{side}_py": z, f"ground_force_{side}_pz": z})


def test_wrong_sign_vertical_force_is_detected(gait2d):
    stance = np.concatenate([np.zeros(10), -700 * np.sin(np.linspace(0, np.pi, 30)), np.zeros(10)])
    with pytest.raises(TrialError, match=r"ground_force_r_vy.*negative during stance.*flip the sign"):
        check_vertical_force(_grf_trial(stance))
    with pytest.raises(TrialError, match="negative during stance"):
        external_forces(gait2d, _grf_trial(stance))
    check_vertical_force(_grf_trial(-stance))      # the right sign passes
    with pytest.raises(TrialError, match="below 20 % of body"):
        check_vertical_force(_grf_trial(-0.1 * stance), body_mass=70.0)


def test_grf_moments_on_the_leg_by_hand(gait2d):
    """Vertical F at x = c on the ground and horizontal F_x: ankle/knee/hip moments change by hand values."""
    F, Fx, c = 600.0, 80.0, 0.07
    q = np.zeros((1, gait2d.nq)); q[0, gait2d.coordinate_index("torso_y")] = 1.0681
    z = np.zeros_like(q)
    trial = Trial([0.0], {"ground_force_r_vx": [Fx], "ground_force_r_vy": [F], "ground_force_r_vz": [0.0],
                          "ground_force_r_px": [c], "ground_force_r_py": [0.0], "ground_force_r_pz": [0.085]})
    ext = external_forces(gait2d, trial)
    assert ext[0].frame == "foot_r"
    from pinmsk.skeleton import rnea
    d = rnea(gait2d, q, z, z, external=ext) - rnea(gait2d, q, z, z)
    ix = gait2d.coordinate_index
    pd = gait2d.pin.createData()
    pin.framesForwardKinematics(gait2d.pin, pd, q[0])
    y_ankle, y_knee, y_hip = (pd.oMf[gait2d.frame_id(f)].translation[1] for f in ("foot_r", "shank_r", "thigh_r"))
    assert (y_ankle, y_knee, y_hip) == pytest.approx((0.05268445, 0.46990045, 0.88542045), abs=1e-8)
    # tau = ... - J^T f; axes are (0, 0, -1): each joint's moment changes by +(moment of GRF about it)_z
    for j, y in (("ankle_r", y_ankle), ("knee_r", y_knee), ("hip_r", y_hip)):
        mz = c * F - (0.0 - y) * Fx
        assert d[0, ix(j)] == pytest.approx(mz, abs=1e-9)
    assert d[0, ix("torso_y")] == pytest.approx(-F, abs=1e-9)
    assert d[0, ix("torso_x")] == pytest.approx(-Fx, abs=1e-9)
    assert d[0, ix("knee_l")] == 0.0


def test_unloaded_samples_get_zero_force(gait2d):
    fy = np.array([0.0, 5.0, 300.0])
    tr = _grf_trial(fy)
    d = tr.to_dict(); d.pop("time"); d["ground_force_r_px"] = np.array([np.nan, 123.0, 0.2])
    ext = external_forces(gait2d, Trial(tr.time, d))
    np.testing.assert_array_equal(ext[0].force[:2], 0.0)
    np.testing.assert_array_equal(ext[0].torque[:2], 0.0)       # the NaN / wild COP of unloaded frames never enters
    assert np.all(np.isfinite(ext[0].point)) and np.all(np.isfinite(ext[0].torque))
    # the wrench about the origin: M = p x F with the COP x = 0.2 m and F_y = 300 N
    assert ext[0].torque[2, 2] == pytest.approx(0.2 * 300.0)


def test_torso_residuals_vanish_when_grf_matches_weight(gait2d):
    q = np.zeros((3, gait2d.nq)); q[:, gait2d.coordinate_index("torso_y")] = 1.0681
    pm = gait2d.pin
    com = pin.centerOfMass(pm, pm.createData(), q[0])
    W = gait2d.mass * 9.81
    n = 3
    ch = {}
    for s, zc in (("r", 0.085), ("l", -0.085)):   # half the weight under each foot, at the COM's x
        ch.update({f"ground_force_{s}_vx": np.zeros(n), f"ground_force_{s}_vy": np.full(n, W / 2),
                   f"ground_force_{s}_vz": np.zeros(n), f"ground_force_{s}_px": np.full(n, com[0]),
                   f"ground_force_{s}_py": np.zeros(n), f"ground_force_{s}_pz": np.full(n, zc)})
    t = np.arange(n) / 100.0
    ext = external_forces(gait2d, Trial(t, ch))
    idt = pinmsk.inverse_dynamics(gait2d, pinmsk.Motion(t, q, np.zeros_like(q), np.zeros_like(q), {}),
                                  external=ext)
    res, summary = torso_residuals(gait2d, idt, body_mass=gait2d.mass)
    assert set(summary) == {"torso_x", "torso_y", "torso_angle"}
    for c in summary:
        assert summary[c]["rms"] < 1e-9
    # 5 kg too much GRF: torso_y residual = -5 g, reported as % body weight
    ch2 = dict(ch); ch2["ground_force_r_vy"] = ch["ground_force_r_vy"] + 5 * 9.81
    idt2 = pinmsk.inverse_dynamics(gait2d, pinmsk.Motion(t, q, np.zeros_like(q), np.zeros_like(q), {}),
                                   external=external_forces(gait2d, Trial(t, ch2)))
    _, s2 = torso_residuals(gait2d, idt2, body_mass=gait2d.mass)
    assert s2["torso_y"]["mean"] == pytest.approx(-5 * 9.81, rel=1e-9)
    assert s2["torso_y"]["rms_percent_bw"] == pytest.approx(100 * 5 / gait2d.mass, rel=1e-9)


def test_transfer_cop_keeps_offset_from_reference():
    cop = np.array([[0.50, 0.0, 0.1]])
    out = transfer_cop(cop, [[0.40, 0.08, 0.1]], [[0.43, 0.05, 0.085]])
    np.testing.assert_allclose(out, [[0.53, 0.0, 0.085]])


def test_duplicate_grf_channels_are_refused(gait2d):
    tr = _grf_trial(np.full(5, 500.0))
    d = tr.to_dict(); d.pop("time"); d["r_ground_force_vy"] = d["ground_force_r_vy"]
    with pytest.raises(TrialError, match="both 'ground_force_r_vy' and 'r_ground_force_vy'"):
        external_forces(gait2d, Trial(tr.time, d))


def test_wrong_axis_is_detected():
    n = 40
    load = 700 * np.sin(np.linspace(0, np.pi, n))
    z = np.zeros(n)
    t = np.arange(n) / 100.0
    tr = Trial(t, {"ground_force_vx": 0.1 * load, "ground_force_vy": 0.05 * load, "ground_force_vz": load,
                   "ground_force_px": z, "ground_force_py": z, "ground_force_pz": z})
    with pytest.raises(TrialError, match=r"force along z .*exceeds the vertical 'ground_force_vy'.*remap"):
        check_vertical_force(tr)
