"""Inverse dynamics of imported OpenSim models, like for like against OpenSim (issue 14, item 4).

gait10dof18musc ``subject01`` (its IK motion and ``subject01_walk_grf.xml``) against OpenSim's reference
ID output: both with OpenSim's own filter of the coordinates (``walk_Setup_ID.xml``: 6 Hz, applied by
``Storage.pad`` + ``lowpassIIR``, which the test calls), the GRF unfiltered as OpenSim's ID tool leaves it.
The knee translations are functions of the knee angle, held exactly by dependent joints
(``import_osim(..., nonlinear="exact")``) whose moments map back by ``tau = J^T tau_pin``.  Needs ``../shared/data`` and
``opensim``; skips cleanly without them.
"""
import numpy as np
import pytest

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
    d = shared_data_dir()
    p = None if d is None else d / GAIT
    if p is None or not (p / "subject01.osim").is_file():
        pytest.skip(f"../shared/data/{GAIT} is absent")
    return p


def _exact(d):
    """subject01 with its knee translations as dependent joints (``nonlinear="exact"``)."""
    model, _ = import_osim(d / "subject01.osim", nonlinear="exact")
    return model


def _opensim():
    osim = pytest.importorskip("opensim")
    osim.Logger.setLevelString("Off")
    try:
        osim.Logger.removeFileSink()
    except Exception:  # pragma: no cover - older opensim
        pass
    return osim


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


#: Rajagopal coordinates whose ID is not yet within 1 % of OpenSim's (see the test below), with a bound.
RAJAGOPAL_KNOWN = {"pelvis_tilt": 7.0, "pelvis_tx": 7.0, "pelvis_ty": 3.0, "pelvis_tz": 3.0,
                   "pelvis_list": 2.0, "pelvis_rotation": 2.0, "hip_flexion_r": 2.0, "hip_flexion_l": 2.0}


@pytest.mark.slow
def test_id_of_rajagopal_against_opensims_inverse_dynamics_tool(tmp_path):
    """RajagopalWalk against OpenSim's InverseDynamicsTool run here (results in tmp_path, no filter on
    either side).  Slow (~5 s); the fast test of the same path is
    test_id_of_gait10dof18musc_matches_opensims_reference_with_the_same_filter."""
    osim = _opensim()
    d = shared_data_dir()
    model_path = None if d is None else d / "opensim-models" / "RajagopalWalk" / "subject_walk_scaled.osim"
    walk = None if d is None else d / "real" / "opensim-moco-walk-emg"
    if model_path is None or not model_path.is_file() or not (walk / "coordinates.sto").is_file():
        pytest.skip("../shared/data RajagopalWalk or opensim-moco-walk-emg is absent")
    model, _ = import_osim(model_path, nonlinear="exact")
    cmap = coordinate_map(model)
    raw = read_trial(walk / "coordinates.sto", strict=False)    # its nColumns header is off (40 for 32)
    ch = {n.split("/")[-2]: np.asarray(raw[n]) for n in raw.names}    # /jointset/<joint>/<coord>/value
    # the file lacks the locked mtp angles (OpenSim takes their defaults) and its patella angles
    # (knee_angle_*_beta, coupled to the knee) are not the coupling's: both sides get the coupled values
    ch.update({c: np.full(raw.n_frames, cmap.defaults[c]) for c in cmap.osim_coordinates if c not in ch})
    for dep, indep, f, scale in cmap.couplers:
        ch[dep] = scale * f.value(ch[indep[0]])
    trial = Trial(raw.time, {c: ch[c] for c in cmap.osim_coordinates})
    names = list(cmap.osim_coordinates)
    X = np.column_stack([trial.time] + [trial[c] for c in names])
    coords = tmp_path / "coordinates.sto"
    with open(coords, "w") as fh:
        fh.write(f"Coordinates\nversion=1\nnRows={X.shape[0]}\nnColumns={X.shape[1]}\ninDegrees=no\nendheader\n")
        fh.write("\t".join(["time"] + names) + "\n")
        np.savetxt(fh, X, delimiter="\t", fmt="%.12g")
    xml = (model_path.parent / "grf_walk.xml").read_text()
    loads = tmp_path / "grf_walk.xml"       # its datafile is named relative to the model's folder
    loads.write_text(xml.replace("<datafile>grf_walk.mot</datafile>", f"<datafile>{walk / 'grf_walk.mot'}</datafile>"))
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
    errs = _errors(ref, out, skip_ends=5)     # 5 ms at each end: the splines' end conditions
    assert set(errs) == set(cmap.osim_coordinates)
    # within 1 % of the peak except RAJAGOPAL_KNOWN: there the error grows with the knee speed squared in
    # swing (~8 rad/s), the walker knee's velocity term that Simbody's FunctionBased mobilizer has and the
    # exact chain lacks (tests/test_osim_import.py::test_exact_mode_inverse_dynamics_matches_opensim);
    # the pelvis rows are residuals of ~20 N / 20 N m peak, so their % is of a small peak
    over = {c: round(e, 3) for c, (e, _) in errs.items() if e >= RAJAGOPAL_KNOWN.get(c, 1.0)}
    assert not over, f"ID differs from OpenSim's by more than allowed (% of peak): {over}"


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
