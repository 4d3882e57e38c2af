"""Inverse dynamics of imported OpenSim models, like for like against OpenSim.

gait10dof18musc ``subject01`` (its IK motion and ``subject01_walk_grf.xml``) against OpenSim's reference
ID output: both with OpenSim's own filter of the coordinates (``walk_Setup_ID.xml``: 6 Hz, applied by
``Storage.pad`` + ``lowpassIIR``, which the test calls), the GRF unfiltered as OpenSim's ID tool leaves it.
The knee translations are functions of the knee angle, held exactly by dependent joints
(``import_osim(..., nonlinear="exact")``) whose moments map back by ``tau = J^T tau_pin``.

RajagopalWalk against OpenSim's InverseDynamicsTool: its walker knee turns about three axes, all functions of
the knee angle, and there Simbody's FunctionBased mobilizer adds a velocity-product term to the exact
acceleration (``_simbody_hdot_term``; OpenSim's tibia acceleration is off the finite difference of its own
poses, pinmsk's is not).  With that term accounted for, the two agree to 1e-9 at single states and within
0.15 % of each coordinate's peak over the walk.  Needs ``../shared/data`` and ``opensim``; skips cleanly
without them.
"""
import numpy as np
import pytest

from conftest import require_opensim, shared_folder

from pinmsk import errors as pinmsk_errors
from pinmsk.dynamics import inverse_dynamics_result
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.io.tables import read_trial
from pinmsk.kinematics import coordinate_map, motion, source_coordinates
from pinmsk.model import import_osim
from pinmsk.trial import Trial

GAIT = "opensim-models/Gait10dof18musc"
TRANSLATIONS = ("pelvis_tx", "pelvis_ty", "pelvis_tz")


def _gait_dir():
    return shared_folder(GAIT, "subject01.osim")


def _exact(d):
    """subject01 with its knee translations as dependent joints (``nonlinear="exact"``)."""
    model, _ = import_osim(d / "subject01.osim", nonlinear="exact")
    return model


def _opensim():
    return require_opensim()         # its logger off (conftest.import_opensim)


def _opensim_filtered(osim, path, cutoff, times):
    """The coordinates of ``path`` low-passed as OpenSim's ID tool does (pad by half, lowpassIIR), in SI,
    on the frames ``times`` (the trial's own: the pad adds frames either side)."""
    sto = osim.Storage(str(path))
    sto.pad(sto.getSize() // 2)
    sto.lowpassIIR(float(cutoff))
    labels = sto.getColumnLabels()
    names = [labels.get(i) for i in range(1, labels.getSize())]
    rows = [sto.getStateVector(i) for i in range(sto.getSize())]
    t = np.array([r.getTime() for r in rows])
    X = np.array([[r.getData().get(j) for j in range(len(names))] for r in rows])
    keep = np.flatnonzero((t >= times[0] - 1e-4) & (t <= times[-1] + 1e-4))
    assert keep.size == times.size
    return Trial(times, {c: X[keep, j] if c in TRANSLATIONS else np.radians(X[keep, j])
                         for j, c in enumerate(names)})


def _errors(ref: Trial, out: Trial, *, skip_ends: int = 1):
    """Per coordinate: (max |error| as % of OpenSim's peak |moment|, peak), frames at the ends skipped."""
    res = {}
    for n in ref.names:
        c = n.rsplit("_", 1)[0]
        r = np.asarray(ref[n])
        mine = np.interp(ref.time, out.time, out[f"{c}_moment"])
        e = np.abs(mine - r)[skip_ends: r.size - skip_ends]
        peak = float(np.max(np.abs(r)))
        res[c] = (100.0 * float(e.max()) / peak, peak)
    return res


def test_id_of_gait10dof18musc_matches_opensims_reference_with_the_same_filter():
    d = _gait_dir()
    osim = _opensim()
    model = _exact(d)
    cmap = coordinate_map(model)
    assert cmap is not None and "knee_r_translation1" in cmap.dependent
    # one rotation axis per coordinate: Simbody's FunctionBased term does not arise (no report note)
    assert not [e for e in model.meta["import_report"].entries if "FunctionBased velocity term" in e.became]
    ik = read_trial(d / "IK" / "subject01_walk_IK.mot")
    trial = _opensim_filtered(osim, d / "IK" / "subject01_walk_IK.mot", 6.0, np.asarray(ik.time))
    res = inverse_dynamics_result(model, trial, cutoff=0, grf_cutoff=0,
                                  external_loads=d / "ExperimentalData" / "subject01_walk_grf.xml")
    out = res.trial
    # reported per OpenSim coordinate: no dependent joint among the channels
    assert set(out.names) == set(cmap.osim_coordinates) | {f"{c}_moment" for c in cmap.osim_coordinates}
    ref = read_trial(d / "reference_outputs" / "ID" / "subject01_walk_ID.sto")
    errs = _errors(ref, out)
    assert set(errs) == set(cmap.osim_coordinates)
    worst = {c: e for c, (e, _) in errs.items() if e >= 1.0}
    assert not worst, f"ID differs from OpenSim's by >= 1 % of the peak: {worst}"
    # the first and last frame (skipped above) differ by the splines' end conditions only: below 3 %
    ends = _errors(ref, out, skip_ends=0)
    assert max(e for e, _ in ends.values()) < 3.0


def test_the_fitted_knee_is_what_exact_mode_fixes():
    # the same comparison with the fixed-axis knee (nonlinear="fit"; load_model's default is exact) is off by
    # several % of the peak on the knees: what exact mode removes (and a check that the test above can fail)
    d = _gait_dir()
    osim = _opensim()
    model, _ = import_osim(d / "subject01.osim", nonlinear="fit")
    assert coordinate_map(model) is None
    ik = read_trial(d / "IK" / "subject01_walk_IK.mot")
    trial = _opensim_filtered(osim, d / "IK" / "subject01_walk_IK.mot", 6.0, np.asarray(ik.time))
    out = inverse_dynamics_result(model, trial, cutoff=0, grf_cutoff=0,
                                  external_loads=d / "ExperimentalData" / "subject01_walk_grf.xml").trial
    errs = _errors(read_trial(d / "reference_outputs" / "ID" / "subject01_walk_ID.sto"), out)
    assert errs["knee_angle_r"][0] > 2.0 and errs["knee_angle_l"][0] > 2.0


def test_motion_and_moments_map_by_virtual_work():
    # q_pin = f(q), v_pin = J v, a_pin = J a + dJ v; tau = J^T tau_pin, so power is the same either side
    d = _gait_dir()
    model = _exact(d)
    cmap = coordinate_map(model)
    ik = read_trial(d / "IK" / "subject01_walk_IK.mot")
    mo = motion(model, ik, cutoff=6)
    rng = np.random.default_rng(1)
    tau_pin = rng.normal(size=mo.q.shape)
    names, q_os, tau_os = source_coordinates(model, mo, tau_pin)
    assert names == cmap.osim_coordinates
    q, v, a = ik.kinematics(names, cutoff=6)
    assert np.allclose(q_os, q, atol=1e-12)
    assert np.allclose(np.sum(tau_os * v, axis=1), np.sum(tau_pin * mo.v, axis=1), rtol=1e-10, atol=1e-9)
    # the knee translation's acceleration is the curvature term f''(q) w^2 at a constant knee speed w
    t = np.linspace(0.0, 1.0, 101)
    w = -1.5
    knee = -0.1 + w * t
    const = Trial(t, {c: (knee if c == "knee_angle_r" else np.full(t.size, 0.9 if c == "pelvis_ty" else 0.0))
                      for c in cmap.osim_coordinates})
    mo = motion(model, const, cutoff=0)
    dep = cmap.dependent["knee_r_translation1"]
    j = model.coordinate_index("knee_r_translation1")
    assert np.allclose(mo.q[:, j], dep.function.value(knee), atol=1e-12)
    assert np.allclose(mo.v[:, j], dep.function.derivative(knee, 1) * w, atol=1e-9)
    curv = dep.function.derivative(knee, 2) * w ** 2
    assert np.max(np.abs(curv)) > 1e-3      # the term is there to be missed
    assert np.allclose(mo.a[:, j], curv, atol=1e-6)


RAJAGOPAL = "opensim-models/RajagopalWalk/subject_walk_scaled.osim"


def _rajagopal():
    d = shared_data_dir()
    p = None if d is None else d / RAJAGOPAL
    if p is None or not p.is_file():
        pytest.skip(f"../shared/data/{RAJAGOPAL} is absent")
    return p


def _rajagopal_walk(tmp_path):
    """RajagopalWalk's model path, the Moco walk's folder, the skeleton import, its coordinate map and
    ``grf_walk.xml`` copied into ``tmp_path`` (its datafile is named relative to the model's folder)."""
    model_path = _rajagopal()
    walk = shared_data_dir() / "real" / "opensim-moco-walk-emg"
    if not (walk / "coordinates.sto").is_file():
        pytest.skip("../shared/data/real/opensim-moco-walk-emg is absent")
    model, _ = import_osim(model_path, nonlinear="exact", hooks=())
    loads = tmp_path / "grf_walk.xml"
    loads.write_text((model_path.parent / "grf_walk.xml").read_text().replace(
        "<datafile>grf_walk.mot</datafile>", f"<datafile>{walk / 'grf_walk.mot'}</datafile>"))
    return model_path, walk, model, coordinate_map(model), loads


def _filled_by_hand(cmap, time, channels):
    """A Trial of every OpenSim coordinate, filled as OpenSim's ID tool fills a file that lacks some (their
    defaults), the coupled ones set by their couplers."""
    ch = dict(channels)
    ch.update({c: np.full(len(time), cmap.defaults[c]) for c in cmap.osim_coordinates if c not in ch})
    for dep, indep, f, scale in cmap.couplers:
        ch[dep] = scale * f.value(ch[indep[0]])
    return Trial(time, {c: ch[c] for c in cmap.osim_coordinates})


def _simbody_hdot_term(model, path, q, v):
    """The acceleration term Simbody's FunctionBased mobilizer (OpenSim's CustomJoint) adds to the exact
    one (:func:`pinmsk.opensim.skeleton.simbody_rotation_term`: Rajagopal's walker knee), as extra
    accelerations (N, nv) of the model's joints: ``W^-1 dA`` on the chain's rotations (they all turn
    about the origin of the joint's M frame).  ``q``, ``v``: ``{OpenSim coordinate: (N,)}``."""
    from pinmsk.io.osim import read_osim
    from pinmsk.opensim.skeleton import OsimKinematics, simbody_rotation_term
    n = len(next(iter(q.values())))
    out = np.zeros((n, model.nv))
    for jk in OsimKinematics(read_osim(path)).joints:
        if jk.joint.type != "CustomJoint" or not jk.coordinates:
            continue
        dA, W = simbody_rotation_term(jk, q, v, n)
        if not np.any(np.abs(dA) > 0):
            continue
        dth = np.linalg.solve(W, dA[..., None])[..., 0]
        for i, a in enumerate(jk.axes[:3]):
            dep = f"{jk.joint.name}_rotation{i + 1}"
            if dep in model.coordinates:
                out[:, model.coordinate_index(dep)] += dth[:, i]
            else:                                 # a pure axis: the coordinate with its slope +-1
                out[:, model.coordinate_index(a.coordinates[0])] += dth[:, i] / a.function.affine()[0]
    return out


def test_rajagopal_id_is_opensims_but_for_simbodys_walker_knee_term():
    """At random states (knee speeds up to 8 rad/s): pinmsk's ID of the exact chain plus the term Simbody's
    FunctionBased mobilizer adds (``_simbody_hdot_term``) is OpenSim's InverseDynamicsSolver to 1e-9 of
    the moments; without it they differ by up to ~1 N m, and without knee speed not at all.  The term is
    Simbody's: the tibia's angular acceleration that OpenSim computes is off the finite difference of its
    own tibia orientations, pinmsk's is on it."""
    import pinocchio as pin
    osim = _opensim()
    path = _rajagopal()
    from test_osim_import import _opensim_inverse_dynamics
    model, report = import_osim(path, nonlinear="exact", hooks=())
    cmap = coordinate_map(model)
    # the import report says which joints carry the term: the walker knees (not the hips, pelvis, ...)
    noted = {e.element.split('"')[1] for e in report.entries if "FunctionBased velocity term" in e.became}
    assert noted == {"walker_knee_r", "walker_knee_l"}
    rng = np.random.default_rng(3)
    n = 6
    q = {c: np.full(n, cmap.defaults[c]) for c in cmap.osim_coordinates}
    q.update({c: rng.uniform(-0.4, 0.4, n) for c in ("hip_flexion_r", "hip_adduction_r", "hip_flexion_l",
                                                       "pelvis_tilt", "lumbar_extension", "ankle_angle_r")})
    for side in "rl":
        q[f"knee_angle_{side}"] = q[f"knee_angle_{side}_beta"] = rng.uniform(0.05, 1.9, n)
    u = {c: rng.normal(size=n) for c in cmap.osim_coordinates}
    for side in "rl":
        u[f"knee_angle_{side}"] = u[f"knee_angle_{side}_beta"] = rng.uniform(-8.0, 8.0, n)
    a = {c: rng.normal(size=n) for c in cmap.osim_coordinates}
    u0 = {c: (np.zeros(n) if c.startswith("knee_angle") else u[c]) for c in u}     # no knee speed
    samples = [tuple({c: x[c][k] for c in x} for x in (q, speeds, a)) for speeds in (u, u0) for k in range(n)]
    ref_all = np.array([[r[c] for c in cmap.osim_coordinates] for r in _opensim_inverse_dynamics(path, samples)])
    qp, vp, ap = cmap.expand(q, u, a, couplers=False)      # OpenSim's ID does not enforce the couplers
    extra = _simbody_hdot_term(model, path, q, u)
    data = model.pin.createData()
    exact = np.array([pin.rnea(model.pin, data, qp[k], vp[k], ap[k]) for k in range(n)])
    simbody = np.array([pin.rnea(model.pin, data, qp[k], vp[k], ap[k] + extra[k]) for k in range(n)])
    exact = cmap.generalized_forces(q, exact, couplers=False)
    simbody = cmap.generalized_forces(q, simbody, couplers=False)
    ref = ref_all[:n]
    scale = np.max(np.abs(ref))
    assert np.max(np.abs(simbody - ref)) < 1e-9 * scale
    assert np.max(np.abs(exact - ref)) > 1e-4 * scale          # the term is there (~1 N m)
    # without knee speed the term vanishes and the two agree to round-off
    qp, vp, ap = cmap.expand(q, u0, a, couplers=False)
    assert not np.any(_simbody_hdot_term(model, path, q, u0))
    exact = cmap.generalized_forces(q, np.array([pin.rnea(model.pin, data, qp[k], vp[k], ap[k])
                                                 for k in range(n)]), couplers=False)
    assert np.max(np.abs(exact - ref_all[n:])) < 1e-9 * scale
    # which is right: the tibia's angular acceleration at a knee speed of 8 rad/s (no acceleration), against
    # the finite difference of OpenSim's own tibia orientations along q(t) = q0 + u t
    om = osim.Model(str(path))
    s = om.initSystem()
    cs = om.getCoordinateSet()
    tibia = om.getBodySet().get("tibia_r")
    q0, w, h = 0.9, 8.0, 1e-4

    def orientation(x):
        for c in ("knee_angle_r", "knee_angle_r_beta"):
            cs.get(c).setValue(s, x, False)
        om.realizePosition(s)
        R = tibia.getTransformInGround(s).R()
        return np.array([[R.get(i, j) for j in range(3)] for i in range(3)])

    for c in cmap.osim_coordinates:
        cs.get(c).setValue(s, cmap.defaults[c], False)
        cs.get(c).setSpeedValue(s, 0.0)
    Rm, R0, Rp = orientation(q0 - w * h), orientation(q0), orientation(q0 + w * h)
    alpha_fd = (pin.log3(Rp @ R0.T) - pin.log3(R0 @ Rm.T)) / h ** 2
    for c in ("knee_angle_r", "knee_angle_r_beta"):
        cs.get(c).setSpeedValue(s, w)
    om.realizeVelocity(s)
    acc = osim.VectorOfSpatialVec()
    om.getMatterSubsystem().calcBodyAccelerationFromUDot(s, osim.Vector(s.getNU(), 0.0), acc)
    alpha_os = np.array([acc.get(int(tibia.getMobilizedBodyIndex())).get(0).get(i) for i in range(3)])
    one = {c: np.array([cmap.defaults[c]]) for c in cmap.osim_coordinates}
    one.update({"knee_angle_r": np.array([q0]), "knee_angle_r_beta": np.array([q0])})
    speed = {c: np.array([w if c in ("knee_angle_r", "knee_angle_r_beta") else 0.0]) for c in one}
    qp, vp, ap = cmap.expand(one, speed, {c: np.zeros(1) for c in one}, couplers=False)
    pin.forwardKinematics(model.pin, data, qp[0], vp[0], ap[0])
    pin.updateFramePlacements(model.pin, data)
    alpha_pin = pin.getFrameClassicalAcceleration(model.pin, data, model.pin.getFrameId("tibia_r"),
                                                  pin.LOCAL_WORLD_ALIGNED).angular
    assert np.max(np.abs(alpha_pin - alpha_fd)) < 1e-4          # measured 2e-6 rad/s^2
    assert np.max(np.abs(alpha_os - alpha_fd)) > 0.05           # measured 0.078 rad/s^2 (of ~12.5)


def test_id_of_rajagopal_reads_mocos_own_coordinates_file(tmp_path):
    """Moco's ``coordinates.sto`` as the user has it (state-path labels, an nColumns header that is off, no
    mtp angles, patella angles that are not the coupling's): refused by name with the flag; with
    ``missing_coordinates="default"`` the moments of the trial filled by hand as OpenSim fills it (mtp
    angles at their defaults) with the couplers applied, which
    test_id_of_rajagopal_against_opensims_inverse_dynamics_tool compares with OpenSim's tool."""
    import warnings
    from pinmsk.io.channel_map import read_mapped
    _, walk, model, cmap, loads = _rajagopal_walk(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pinmsk_errors.RepairWarning)      # the nColumns header
        trial = read_mapped(walk / "coordinates.sto", model=model, strict=False)
    with pytest.raises(pinmsk_errors.TrialError, match=r"'mtp_angle_r'.*'mtp_angle_l'.*--missing-coordinates default"):
        inverse_dynamics_result(model, trial, cutoff=0, grf_cutoff=0, external_loads=loads)
    res = inverse_dynamics_result(model, trial, cutoff=0, grf_cutoff=0, external_loads=loads,
                                  missing_coordinates="default")
    notes = "\n".join(res.inputs.notes)
    for c in ("mtp_angle_r", "mtp_angle_l"):
        assert f"{c}: not in the trial; held at its default value 0" in notes
    for c in ("knee_angle_r_beta", "knee_angle_l_beta"):      # Moco wrote ~72 (rad) for them
        assert f"{c}: the trial's values replaced by its CoordinateCouplerConstraint's" in notes
    hand = _filled_by_hand(cmap, trial.time, {c: np.asarray(trial[c]) for c in cmap.osim_coordinates if c in trial})
    by_hand = inverse_dynamics_result(model, hand, cutoff=0, grf_cutoff=0, external_loads=loads)
    names = [n for n in by_hand.trial.names if n.endswith("_moment")]
    assert len(names) == len(cmap.osim_coordinates)
    np.testing.assert_allclose(res.trial.get(names), by_hand.trial.get(names), rtol=0, atol=1e-9)


@pytest.mark.slow
def test_id_of_rajagopal_against_opensims_inverse_dynamics_tool(tmp_path):
    """RajagopalWalk against OpenSim's InverseDynamicsTool run here (results in tmp_path, no filter on
    either side): within 1 % of each coordinate's peak on every coordinate once Simbody's walker-knee
    term (``_simbody_hdot_term``, measured at single states to 1e-9 by
    test_rajagopal_id_is_opensims_but_for_simbodys_walker_knee_term) is taken out of OpenSim's moments.
    Measured: 0.15 % at worst (pelvis_tx) with it out, 5.6 % (pelvis_tilt, of a 20 N m peak) with it in.
    Slow (~5 s); the fast tests of the same path are that test and
    test_id_of_gait10dof18musc_matches_opensims_reference_with_the_same_filter."""
    from pinmsk.skeleton import rnea
    osim = _opensim()
    model_path, walk, model, cmap, loads = _rajagopal_walk(tmp_path)
    raw = read_trial(walk / "coordinates.sto", strict=False)    # its nColumns header is off (40 for 32)
    # /jointset/<joint>/<coord>/value; the file lacks the mtp angles (OpenSim takes their defaults) and its
    # patella angles (knee_angle_*_beta, coupled to the knee) are not the coupling's: both sides get the
    # coupled values
    trial = _filled_by_hand(cmap, raw.time, {n.split("/")[-2]: np.asarray(raw[n]) for n in raw.names})
    names = list(cmap.osim_coordinates)
    X = np.column_stack([trial.time] + [trial[c] for c in names])
    coords = tmp_path / "coordinates.sto"
    with open(coords, "w") as fh:
        fh.write(f"Coordinates\nversion=1\nnRows={X.shape[0]}\nnColumns={X.shape[1]}\ninDegrees=no\nendheader\n")
        fh.write("\t".join(["time"] + names) + "\n")
        np.savetxt(fh, X, delimiter="\t", fmt="%.12g")
    om = osim.Model(str(model_path))
    om.initSystem()
    tool = osim.InverseDynamicsTool()
    tool.setModel(om)
    tool.setCoordinatesFileName(str(coords))
    tool.setExternalLoadsFileName(str(loads))
    tool.setLowpassCutoffFrequency(-1)
    tool.setStartTime(float(trial.time[0]))
    tool.setEndTime(float(trial.time[-1]))
    excluded = osim.ArrayStr()
    excluded.append("Muscles")
    tool.setExcludedForces(excluded)
    tool.setResultsDir(str(tmp_path))
    tool.setOutputGenForceFileName("id.sto")
    assert tool.run()
    ref = read_trial(tmp_path / "id.sto")
    out = inverse_dynamics_result(model, trial, cutoff=0, grf_cutoff=0, external_loads=loads).trial
    raw_errs = _errors(ref, out, skip_ends=5)     # 5 ms at each end: the splines' end conditions
    assert set(raw_errs) == set(cmap.osim_coordinates)
    # OpenSim's moments without Simbody's term: M(q) dA mapped to the coordinates (RNEA is linear in a)
    mo = motion(model, trial, cutoff=0)
    q = {c: (mo.q[:, model.coordinate_index(c)] if c in model.coordinates else mo.signals[c]) for c in names}
    # (the coordinates that are no joint, the patella angles, drive no rotation pair: their rates do not enter)
    v = {c: (mo.v[:, model.coordinate_index(c)] if c in model.coordinates else np.gradient(q[c], mo.t)) for c in names}
    zero = np.zeros_like(mo.v)
    dtau = rnea(model, mo.q, zero, _simbody_hdot_term(model, model_path, q, v)) - rnea(model, mo.q, zero, zero)
    _, _, dtau = source_coordinates(model, mo, dtau)
    fixed = Trial(out.time, {f"{c}_moment": np.asarray(out[f"{c}_moment"]) + dtau[:, i] for i, c in enumerate(names)})
    errs = _errors(ref, fixed, skip_ends=5)
    over = {c: round(e, 3) for c, (e, _) in errs.items() if e >= 1.0}
    assert not over, f"ID differs from OpenSim's by >= 1 % of the peak (Simbody's term out): {over}"
    assert max(e for e, _ in errs.values()) < 0.5
    # with the term in, the pelvis rows (residuals of ~20 N, 20 N m peak) are off by several %: the term
    assert max(e for e, _ in raw_errs.values()) > 2.0


def test_a_trial_needs_opensims_coordinates_not_the_dependent_joints():
    d = _gait_dir()
    model = _exact(d)
    ik = read_trial(d / "IK" / "subject01_walk_IK.mot")
    mo = motion(model, ik, cutoff=6)        # the trial has no knee_r_translation1: the map fills it
    assert mo.q.shape == (ik.n_frames, model.nv)
    short = Trial(ik.time, {n: ik[n] for n in ik.names if n != "knee_angle_r"})
    with pytest.raises(pinmsk_errors.TrialError, match=r"missing coordinate channel\(s\): 'knee_angle_r'") as e:
        motion(model, short, cutoff=6)
    assert "translation" not in str(e.value).split(";")[0]
