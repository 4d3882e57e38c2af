"""The trial -> (motion, external loads) stage: one filter for kinematics and GRF, plates on bodies,
ExternalLoads files, residual thresholds, and SO/FSO/ID using it all by default."""
import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk import Trial, write_trial
from pinmsk.dynamics import inverse_dynamics_array, inverse_dynamics_result
from pinmsk.errors import InfeasibleError, TrialError
from pinmsk.io.external_loads import read_external_loads
from pinmsk.grf import external_forces
from pinmsk.kinematics import DEFAULT_CUTOFF, is_planar, prepare
from pinmsk.residuals import PEAK_FORCE_FRACTION
from pinmsk.solvers import StaticOptimization

RATE = 200.0
STAND_Y = 1.0681        # gait2d torso height standing on flat feet


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def bouncing(gait2d, *, rate=RATE, duration=3.0, freq=15.0, amp=0.0005, sides=("r", "l"), prefix=True):
    """gait2d standing, its torso bouncing at ``freq`` Hz, with the exactly consistent GRF.

    The joints are fixed, so the body is one rigid mass ``m``: the vertical ground force is
    ``m (g + y'')`` shared by the feet, applied under the centre of mass (no moment).  The
    15 Hz bounce (4.4 m/s^2) keeps the feet loaded.
    """
    t = np.arange(int(round(duration * rate)) + 1) / rate
    y = STAND_Y + 0.01 * np.sin(2 * np.pi * 0.7 * t) + amp * np.sin(2 * np.pi * freq * t)
    ydd = -(2 * np.pi * 0.7) ** 2 * 0.01 * np.sin(2 * np.pi * 0.7 * t) - (2 * np.pi * freq) ** 2 * amp * np.sin(
        2 * np.pi * freq * t)
    q0 = np.zeros(gait2d.nq)
    q0[gait2d.coordinate_index("torso_y")] = STAND_Y
    com = pin.centerOfMass(gait2d.pin, gait2d.pin.createData(), q0)
    m = gait2d.mass
    ch = {c: np.zeros_like(t) for c in gait2d.coordinates}
    ch["torso_y"] = y
    fy = m * (9.81 + ydd) / len(sides)
    for s, z in zip(sides, (0.085, -0.085)):
        p = f"{s}_" if prefix else ""
        ch.update({f"{p}ground_force_vx": np.zeros_like(t), f"{p}ground_force_vy": fy,
                   f"{p}ground_force_vz": np.zeros_like(t), f"{p}ground_force_px": np.full_like(t, com[0]),
                   f"{p}ground_force_py": np.zeros_like(t), f"{p}ground_force_pz": np.full_like(t, z)})
    return Trial(t, ch)


def base_rows(model):
    return [model.coordinate_index(c) for c in ("torso_x", "torso_y", "torso_angle")]


def test_default_filter_is_6_hz_on_coordinates_and_grf(gait2d):
    inputs = prepare(gait2d, bouncing(gait2d))
    assert DEFAULT_CUTOFF == 6.0 and inputs.filtering.cutoff == 6.0
    assert inputs.filtering.applied_to == ("coordinates", "ground reaction")
    meta = inputs.meta()
    assert meta["lowpass_cutoff_hz"] == 6.0 and "foot_r" in meta["ground_reaction"]
    off = prepare(gait2d, bouncing(gait2d), cutoff=0)
    assert off.filtering.cutoff is None and "coordinates and ground reaction none" in off.describe()[0]
    with pytest.raises(TrialError, match="cutoff must be >= 0"):
        prepare(gait2d, bouncing(gait2d), cutoff=-1)


def test_same_filter_on_grf_and_kinematics_leaves_no_residual(gait2d):
    """Kristianslund et al. 2012: filtering the kinematics but not the GRF creates residual peaks."""
    tr = bouncing(gait2d, rate=1000.0)
    rows = base_rows(gait2d)
    amp = gait2d.mass * (2 * np.pi * 15.0) ** 2 * 0.0005              # the 15 Hz force, ~ 290 N
    exact = inverse_dynamics_array(gait2d, gait2d.motion(tr, cutoff=0), external=external_forces(gait2d, tr))
    assert np.max(np.abs(exact[20:-20][:, rows])) < 1e-3 * amp        # the data are consistent
    inputs = prepare(gait2d, tr)                                        # both at 6 Hz
    both = inverse_dynamics_array(gait2d, inputs.motion, external=inputs.external)
    raw_grf = inverse_dynamics_array(gait2d, inputs.motion, external=external_forces(gait2d, tr))
    inner = slice(300, -300)
    assert np.max(np.abs(both[inner][:, rows])) < 0.01 * amp
    assert np.max(np.abs(raw_grf[inner][:, rows[1]])) > 0.8 * amp       # the mismatch: the whole 15 Hz force


def test_grf_file_at_its_own_rate_matches_grf_in_the_trial(gait2d, tmp_path):
    fast = bouncing(gait2d, rate=1000.0)
    kin = bouncing(gait2d, rate=100.0)
    kin_only = kin.select(list(gait2d.coordinates))
    grf_only = fast.select([n for n in fast.names if "ground" in n])
    path = tmp_path / "grf.mot"
    write_trial(grf_only, path)
    a = inverse_dynamics_result(gait2d, kin_only, grf=path)
    b = inverse_dynamics_result(gait2d, kin)
    assert a.inputs.grf_source == str(path)
    inner = slice(30, -30)
    for ea, eb in zip(a.inputs.external, b.inputs.external):
        assert ea.frame == eb.frame
        peak = np.max(np.abs(eb.force[inner]))
        assert np.max(np.abs(ea.force[inner] - eb.force[inner])) < 0.005 * peak
    w = gait2d.mass * 9.81
    assert np.max(np.abs(a.trial["torso_y_moment"][inner] - b.trial["torso_y_moment"][inner])) < 0.005 * w
    with pytest.raises(TrialError, match="pass only one"):
        prepare(gait2d, kin, grf=path)
    short = grf_only.slice_time(0.5, 2.0)
    with pytest.raises(TrialError, match="the GRF covers"):
        prepare(gait2d, kin_only, grf=short)


def _external_loads_xml(path, datafile, body_r="calcn_r", body_l="calcn_l", disabled_l=False, frame="ground"):
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="30000">
  <ExternalLoads name="walk">
    <objects>
      <ExternalForce name="right">
        <applied_to_body>{body_r}</applied_to_body>
        <force_expressed_in_body>{frame}</force_expressed_in_body>
        <point_expressed_in_body>ground</point_expressed_in_body>
        <force_identifier>ground_force_v</force_identifier>
        <point_identifier>ground_force_p</point_identifier>
        <torque_identifier>ground_torque_</torque_identifier>
      </ExternalForce>
      <ExternalForce name="left">
        <isDisabled>{'true' if disabled_l else 'false'}</isDisabled>
        <applied_to_body>{body_l}</applied_to_body>
        <force_identifier>1_ground_force_v</force_identifier>
        <point_identifier>1_ground_force_p</point_identifier>
        <torque_identifier>1_ground_torque_</torque_identifier>
      </ExternalForce>
    </objects>
    <datafile>{datafile}</datafile>
  </ExternalLoads>
</OpenSimDocument>
""")
    return path


def test_opensim_external_loads_file_maps_plates_to_bodies(gait2d, tmp_path):
    tr = bouncing(gait2d)
    # OpenSim's column names for two plates: ground_force_v* and 1_ground_force_v*
    ren = {}
    for n in tr.names:
        if n.startswith("r_ground"):
            ren[n] = n[2:]
        elif n.startswith("l_ground"):
            ren[n] = "1_" + n[2:]
    grf = Trial(tr.time, {ren[n]: tr[n] for n in ren})
    write_trial(grf, tmp_path / "walk_grf.mot")
    xml = _external_loads_xml(tmp_path / "walk_grf.xml", "walk_grf.mot")
    loads = read_external_loads(xml)
    assert [s.body for s in loads.loads] == ["calcn_r", "calcn_l"]
    kin = tr.select(list(gait2d.coordinates))
    a = inverse_dynamics_result(gait2d, kin, external_loads=xml)      # reads the datafile beside the XML
    # OpenSim's ExternalLoads convention: the loads unfiltered, as its ID tool applies them, and said so
    assert a.inputs.filtering.grf_cutoff is None and "ExternalLoads convention" in a.inputs.filtering.describe()
    # ... and the coordinates filtered as its ID tool filters them
    assert a.inputs.filtering.method == "opensim" and a.trial.meta["lowpass_method"] == "opensim"
    assert [p.body for p in a.inputs.plates] == ["foot_r", "foot_l"]
    assert "calcn_r" in a.inputs.plates[0].reason
    # an explicit GRF cut-off leaves OpenSim's convention: pinmsk's filter on the coordinates, and the
    # same loads as the trial's own columns
    a0 = inverse_dynamics_result(gait2d, kin, external_loads=xml, grf_cutoff=0)
    b = inverse_dynamics_result(gait2d, tr, grf_cutoff=0)
    assert a0.inputs.filtering.method == "butterworth"
    np.testing.assert_allclose(a0.trial["hip_r_moment"], b.trial["hip_r_moment"], atol=1e-6)
    # the two filters differ by less than their difference in order would allow to pass unseen
    assert not np.allclose(a.trial["hip_r_moment"], b.trial["hip_r_moment"], atol=1e-6)
    # what cannot be honoured is refused by name
    with pytest.raises(TrialError, match="pelvis_frame"):
        read_external_loads(_external_loads_xml(tmp_path / "bad.xml", "walk_grf.mot", frame="pelvis_frame"))
    with pytest.raises(TrialError, match="'hand'"):
        prepare(gait2d, kin, external_loads=_external_loads_xml(tmp_path / "b2.xml", "walk_grf.mot", body_r="hand"))
    half = read_external_loads(_external_loads_xml(tmp_path / "b3.xml", "walk_grf.mot", disabled_l=True))
    assert half.disabled == ("left",) and len(half.loads) == 1


def test_plate_without_side_goes_to_the_nearest_foot(gait2d):
    tr = bouncing(gait2d, sides=("r",), prefix=False)       # one plate, columns ground_force_v*
    d = tr.to_dict(); d.pop("time")
    q0 = np.zeros(gait2d.nq); q0[gait2d.coordinate_index("torso_y")] = STAND_Y
    data = gait2d.pin.createData()
    pin.framesForwardKinematics(gait2d.pin, data, q0)
    foot_l = data.oMf[gait2d.frame_id("foot_l")].translation
    d["ground_force_px"] = np.full(tr.n_frames, foot_l[0])
    d["ground_force_pz"] = np.full(tr.n_frames, foot_l[2])
    inputs = prepare(gait2d, Trial(tr.time, d))
    assert inputs.plates[0].body == "foot_l" and "nearest foot" in inputs.plates[0].reason


def test_grf_on_a_model_without_feet_is_refused_by_name(forearm):
    t = np.arange(200) / 100.0
    tr = Trial(t, {"elbow_flexion": 0.5 + 0.1 * np.sin(t), "r_ground_force_vx": np.zeros_like(t),
                   "r_ground_force_vy": np.full_like(t, 100.0), "r_ground_force_vz": np.zeros_like(t),
                   "r_ground_force_px": np.zeros_like(t), "r_ground_force_py": np.zeros_like(t),
                   "r_ground_force_pz": np.zeros_like(t)})
    with pytest.raises(TrialError, match="side 'r'"):
        prepare(forearm, tr)
    ok = prepare(forearm, tr, ground_reaction="ignore")        # explicit opt-out, recorded
    assert not ok.external and "left out on request" in ok.meta()["notes"]


def test_planar_detection(gait2d, forearm):
    assert is_planar(gait2d) and is_planar(forearm)
    assert not is_planar(pinmsk.load_model("human3d"))


def test_residual_thresholds_follow_opensim_guidance(gait2d):
    tr = bouncing(gait2d, amp=0.0)
    res = inverse_dynamics_result(gait2d, tr).residuals
    assert res.coordinates == ("torso_x", "torso_y", "torso_angle")
    assert res.units == ("N", "N", "N*m")
    w = gait2d.mass * 9.81
    assert res.peak_external_force == pytest.approx(w * (1 + (2 * np.pi * 0.7) ** 2 * 0.01 / 9.81), rel=2e-3)
    assert res.thresholds[1] == pytest.approx(PEAK_FORCE_FRACTION * res.peak_external_force)
    q0 = np.zeros(gait2d.nq); q0[gait2d.coordinate_index("torso_y")] = STAND_Y
    h = pin.centerOfMass(gait2d.pin, gait2d.pin.createData(), q0)[1]
    assert res.com_height == pytest.approx(h, abs=0.011)
    assert res.thresholds[2] == pytest.approx(0.01 * res.com_height * res.peak_external_force)
    assert res.ok and res.warning() is None
    # a missing 5 % of body weight fails the force threshold at every frame
    short = tr.with_channels({n: 0.9 * tr[n] for n in ("r_ground_force_vy", "l_ground_force_vy")})
    bad = inverse_dynamics_result(gait2d, short).residuals
    assert not bad.ok and bad.failing[:, 1].mean() > 0.9
    assert "torso_y" in "\n".join(bad.lines()) and "FAILS" in "\n".join(bad.lines())
    # no GRF at all: the residual is the body weight, said by name
    from pinmsk.errors import ResidualWarning
    with pytest.warns(ResidualWarning, match="torso_y peak"):
        none = inverse_dynamics_result(gait2d, tr, ground_reaction="ignore").residuals
    assert none.peak[1] == pytest.approx(w, rel=0.02)
    assert "torso_y" in none.warning() and "1.0" in none.warning()


def test_so_balances_measured_moments_when_asked(forearm):
    from pinmsk.solvers.analytical import gaussian_elbow_trial
    tr = gaussian_elbow_trial()
    tau = pinmsk.inverse_dynamics(forearm, tr)["elbow_flexion_moment"] + 2.0     # a dynamometer reading
    tr = tr.with_channels({"elbow_flexion_moment": tau})
    so = StaticOptimization().fit(forearm, tr, moments="measured")
    from pinmsk.signals.filtering import lowpass
    want = lowpass(tau, rate=tr.rate, cutoff=6.0)
    np.testing.assert_allclose(so.problem_.tau[:, 0], want, atol=1e-9)
    assert "measured" in so.report() and "measured" in so.result_.meta["balanced_moments"]
    ident = StaticOptimization().fit(forearm, tr)
    assert "elbow_flexion_moment" in " ".join(ident.plan_.notes)         # says what it did not balance
    assert abs(np.mean(so.problem_.tau[:, 0] - ident.problem_.tau[:, 0]) - 2.0) < 0.05
    with pytest.raises(TrialError, match="elbow_flexion_moment"):
        StaticOptimization().fit(forearm, tr.drop(["elbow_flexion_moment"]), moments="measured")


def test_so_on_a_walk_uses_its_grf_and_names_the_floating_base(gait2d):
    tr = bouncing(gait2d, amp=0.0)
    so = StaticOptimization(reserves=True).fit(gait2d, tr)
    assert so.residuals_.ok
    assert np.max(np.abs(so.result_["torso_y_reserve"][60:-60])) < 0.01 * gait2d.mass * 9.81   # GRF holds it up
    with pytest.raises(InfeasibleError, match="free fall"):
        StaticOptimization().fit(gait2d, tr, ground_reaction="ignore")


def test_fso_drive_is_the_generalized_force_of_the_measured_wrenches(gait2d):
    """FSO applies the GRF at the simulated configuration: J(q)^T f_ext(t), interpolated in time."""
    from pinmsk.skeleton import external_generalized_force
    from pinmsk.solvers.fso import _external_drive
    inputs = prepare(gait2d, bouncing(gait2d, amp=0.0, duration=1.0))
    drive = _external_drive(gait2d, inputs.motion.t, inputs.external)
    k = 57
    q = inputs.motion.q[k]
    want = external_generalized_force(gait2d, q[None, :], [
        type(e)(e.frame, e.force[k:k + 1], e.point[k:k + 1], e.torque[k:k + 1]) for e in inputs.external])[0]
    np.testing.assert_allclose(drive(inputs.motion.t[k], q), want, rtol=1e-12, atol=1e-9)
    j = gait2d.coordinate_index("torso_y")
    assert want[j] == pytest.approx(gait2d.mass * 9.81, rel=0.02)        # the ground holds the body up
    half = 0.5 * (inputs.motion.t[k] + inputs.motion.t[k + 1])
    mid = drive(half, q)
    nxt = drive(inputs.motion.t[k + 1], q)
    np.testing.assert_allclose(mid, 0.5 * (want + nxt), rtol=1e-9, atol=1e-9)


def test_grf_cutoff_zero_leaves_the_grf_unfiltered_as_opensim(gait2d):
    tr = bouncing(gait2d, rate=1000.0)
    raw = prepare(gait2d, tr, grf_cutoff=0)
    assert raw.filtering.cutoff == 6.0 and raw.filtering.grf_cutoff is None
    assert "ground reaction none" in raw.describe()[0] and raw.meta()["grf_lowpass_cutoff_hz"] == 0.0
    np.testing.assert_allclose(raw.external[0].force, external_forces(gait2d, tr)[0].force)


@pytest.mark.parametrize("rel", ["opensim-models/Gait10dof18musc/ExperimentalData/subject01_walk_grf.xml",
                                 "opensim-models/Moco2DWalking/referenceGRF.xml"])
def test_real_opensim_external_loads_files(shared_data, rel, gait2d):
    path = shared_data / rel
    if not path.exists():
        pytest.skip(f"{rel} absent")
    loads = read_external_loads(path)
    assert [s.body for s in loads.loads] == ["calcn_r", "calcn_l"]
    grf = pinmsk.read_trial(loads.datafile)
    for spec in loads.loads:
        for kind in ("force", "point", "torque"):
            assert all(c in grf for c in spec.columns(kind)), (spec.name, kind)
    # the plates land on gait2d's feet, and the loaded vertical force is about body weight
    from pinmsk.grf import plate_wrench, plates
    pl = plates(gait2d, grf, external_loads=loads)
    assert [p.body for p in pl] == ["foot_r", "foot_l"]
    fy = sum(plate_wrench(grf, p, planar=True)[0][:, 1] for p in pl)
    assert 500 < np.median(fy[fy > 100]) < 1200


def test_so_checks_the_unspanned_coordinates_of_given_moments_too(gait2d):
    tr = bouncing(gait2d, amp=0.0)
    idt = pinmsk.inverse_dynamics(gait2d, tr, ground_reaction="ignore")       # torso_y carries body weight
    with pytest.raises(InfeasibleError, match=r"torso_y \(peak"):
        StaticOptimization().fit(gait2d, tr, moments=idt)
    so = StaticOptimization(reserves=True).fit(gait2d, tr, moments=idt)
    np.testing.assert_allclose(so.result_["torso_y_reserve"], idt["torso_y_moment"])


def test_unfiltered_grf_at_its_own_rate_is_np_interp_of_the_full_wrenches(gait2d):
    """Unfiltered (grf_cutoff=0), a faster GRF's wrenches are made only at the frames bracketing the motion's
    times: the same numbers as every frame's wrench linearly interpolated (np.interp), COP moving (the moment
    p x F is not linear in the samples); a non-finite sample is named by its frame in the GRF file."""
    from pinmsk import grf as _grf
    from pinmsk.kinematics import MIN_FORCE

    fast = bouncing(gait2d, rate=1000.0)
    ch = {n: np.asarray(fast[n]).copy() for n in fast.names if "ground" in n}
    t_g = np.asarray(fast.time)
    ch["r_ground_force_px"] = ch["r_ground_force_px"] + 0.05 * np.sin(2 * np.pi * 3.0 * t_g)
    ch["l_ground_force_vx"] = 40.0 * np.cos(2 * np.pi * 2.0 * t_g)
    grf = Trial(t_g, ch)
    t = np.arange(0.0, 2.9, 0.01) + 0.0004              # between the GRF's samples, and on one
    t[100] = t_g[1000]
    kin = Trial(t, {c: np.interp(t, t_g, fast[c]) for c in gait2d.coordinates})
    got = prepare(gait2d, kin, grf=grf, grf_cutoff=0)
    for plate, e in zip(_grf.plates(gait2d, grf), got.external):
        F, M = _grf.plate_wrench(grf, plate, min_force=MIN_FORCE, planar=True)
        want = np.column_stack([np.interp(t, t_g, x) for x in np.hstack([F, M]).T])
        np.testing.assert_allclose(np.hstack([e.force, e.torque]), want, rtol=0, atol=1e-9)
    used = int(np.searchsorted(t_g, t[5]))              # a frame the interpolation reads
    bad = dict(ch, r_ground_force_vz=np.where(np.arange(t_g.size) == used, np.nan, ch["r_ground_force_vz"]))
    with pytest.raises(TrialError, match=f"not finite at frame {used} "):
        prepare(gait2d, kin, grf=Trial(t_g, bad), grf_cutoff=0)
