"""Muscles of imported OpenSim models against the opensim package: lengths, moment arms, parameters,
and the ``pinmsk muscles`` analysis (skipped without the shared data or opensim)."""
from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

from conftest import require_opensim

from pinmsk.presentation.cli import main
from test_osim_paths import OsimReference, _model, _motion

ARM26, GAIT = "Arm26/arm26.osim", "Gait10dof18musc/gait10dof18musc.osim"
MOTIONS = {ARM26: "Arm26/arm26_InverseKinematics.mot", GAIT: "Gait10dof18musc/IK/subject01_walk_IK.mot"}
_CACHE: dict = {}


def _imported(relative):
    """(model, report, import seconds) of a shared model, imported once per test run."""
    if relative not in _CACHE:
        from pinmsk import load_model
        path = _model(relative)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            model = load_model(path)
        _CACHE[relative] = (model, model.meta["import_report"], time.perf_counter() - t0)
    return _CACHE[relative]


def _reference(relative, every):
    """OpenSim's model and every ``every``-th pose of the model's IK motion."""
    osim = require_opensim()
    osim.Logger.setLevelString("Off")
    osim.Logger.removeFileSink()
    ref = OsimReference(_model(relative))
    q = _motion(ref, MOTIONS[relative])[::every]
    return ref, q


def _reference_paths(relative, every, muscles):
    """(ref, q, OpenSim's lengths, moment arms) over the IK poses, computed once per test run."""
    key = ("paths", relative, every)
    if key not in _CACHE:
        ref, q = _reference(relative, every)
        _CACHE[key] = (ref, q) + tuple(ref.paths(list(muscles), q))
    return _CACHE[key]


def _compare(relative, every, model=None):
    model, report = _imported(relative)[:2] if model is None else (model, model.meta["import_report"])
    ref, q_osim, L_ref, A_ref = _reference_paths(relative, every, model.muscle_names)
    q = np.zeros((len(q_osim), model.nv))
    for j, c in enumerate(ref.independent):
        q[:, model.coordinate_index(c)] = q_osim[:, j]
    L = model.muscles.lengths(q)
    A = model.muscles.moment_arms(q)
    A_ref_model = np.zeros_like(A)
    for j, c in enumerate(ref.independent):
        A_ref_model[:, :, model.coordinate_index(c)] = A_ref[:, :, j]
    return model, report, L, L_ref, A, A_ref_model


def _fit_error(report, muscle):
    for e in report.approximations:
        if muscle in e.details.get("muscles", ()):
            return e.details["moment_arm_max"]
    raise AssertionError(f"no fit entry for {muscle}")


def test_arm26_muscles_fitted_over_the_model_ranges_are_within_their_reported_errors():
    """load_model samples the shoulder over 180 of its 270 degrees: 1.6 mm (TRIlong) over the IK poses,
    reported 4.3 mm over the sampled range.  The reported errors are maxima over held-out random poses,
    so a pose outside them may exceed them slightly (BRA 0.037 against 0.036 mm): 0.1 mm / 0.5 mm slack."""
    model, report, L, L_ref, A, A_ref = _compare(ARM26, 1)
    assert model.n_muscles == 6
    for i, m in enumerate(model.muscle_names):
        entry = next(e for e in report.approximations if m in e.details.get("muscles", ()))
        assert np.max(np.abs(L[:, i] - L_ref[:, i])) <= entry.details["length_max"] + 1e-4, m
        assert np.max(np.abs(A[:, i] - A_ref[:, i])) <= entry.details["moment_arm_max"] + 5e-4, m


def test_arm26_muscles_fitted_over_the_ik_motion_match_opensim_within_1mm():
    """The hook fitted over the motion's ranges +- 10 degrees (as OpenSim's PolynomialPathFitter samples)."""
    from functools import partial

    from pinmsk.model import import_osim
    from pinmsk.opensim.muscle_import import muscle_hook
    from pinmsk.opensim.paths import motion_ranges
    ref, q_osim = _reference(ARM26, 1)
    ranges = motion_ranges(q_osim, ref.independent, limits=ref.ranges())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        model, report = import_osim(_model(ARM26), hooks=(partial(muscle_hook, ranges=ranges),))
    _, _, L, L_ref, A, A_ref = _compare(ARM26, 1, model=model)
    assert np.max(np.abs(L - L_ref)) < 1e-3
    assert np.max(np.abs(A - A_ref)) < 1e-3


def test_gait10dof18musc_muscles_match_opensim_over_the_ik_poses():
    """Every 10th frame of subject01's IK motion (the slow test below takes every frame)."""
    model, report, L, L_ref, A, A_ref = _compare(GAIT, 10)
    assert model.n_muscles == 18
    assert np.max(np.abs(L - L_ref)) < 1e-3
    # the reported error is the largest on held-out random poses; the IK poses reach the knee's full
    # extension, where vasti_l's arm is off by 1.96 mm against 1.79 mm reported (B's bound: 3.5 mm)
    for i, m in enumerate(model.muscle_names):
        err = np.max(np.abs(A[:, i] - A_ref[:, i]))
        assert err <= _fit_error(report, m) + 0.5e-3, (m, err)
    assert np.max(np.abs(A - A_ref)) < 3.5e-3


@pytest.mark.slow
def test_gait10dof18musc_muscles_match_opensim_over_every_ik_frame():
    model, report, L, L_ref, A, A_ref = _compare(GAIT, 1)
    assert np.max(np.abs(L - L_ref)) < 1e-3
    assert np.max(np.abs(A - A_ref)) < 3.5e-3



def test_max_isometric_force_round_trip_and_report():
    osim = require_opensim()
    osim.Logger.setLevelString("Off")
    for relative in (ARM26, GAIT):
        model, report, _ = _imported(relative)
        om = osim.Model(_model(relative))
        fs = om.getMuscles()
        want = {fs.get(i).getName(): fs.get(i).getMaxIsometricForce() for i in range(fs.getSize())}
        got = dict(zip(model.muscle_names, np.asarray(model.muscles.mtu.f_max, dtype=float)))
        assert got.keys() == want.keys()
        for k in want:
            assert got[k] == pytest.approx(want[k], rel=1e-12)
        assert report.find("MuscleSet") or any("MuscleSet" in e.became for e in report.entries)
        assert not [e for e in report.not_imported if "Muscle" in e.element]


def test_muscles_command_on_arm26(tmp_path, capsys):
    model, _, _ = _imported(ARM26)
    ref, q_osim, L_ref, A_ref = _reference_paths(ARM26, 1, model.muscle_names)
    out = tmp_path / "arm26_muscles.sto"
    assert main(["muscles", _model(ARM26), _model(MOTIONS[ARM26]), "-o", str(out), "--cutoff", "0"]) == 0
    from pinmsk.io.tables import read_trial
    tr = read_trial(out)
    elbow = ref.independent.index("r_elbow_flex")
    for i, m in enumerate(model.muscle_names):
        # the analysis takes the geometric paths: OpenSim's lengths to the .mot's 6 digits
        assert np.max(np.abs(tr[f"{m}_length"] - L_ref[:, i])) < 1e-3
        assert np.max(np.abs(tr[f"{m}_moment_arm_r_elbow_flex"] - A_ref[:, i, elbow])) < 1e-3
        assert f"{m}_fiber_length" in tr
    assert "BIClong_moment_arm_r_elbow_flex" in tr and "BIClong_moment_arm_r_shoulder_elev" in tr
    assert "BRA_moment_arm_r_shoulder_elev" not in tr


def test_muscles_command_refuses_a_model_without_muscles(tmp_path, capsys):
    out = tmp_path / "x.sto"
    trial = _model(MOTIONS[ARM26])
    from pinmsk.opensim.importer import write_import
    files = write_import(_model(ARM26), tmp_path / "imp")
    code = main(["muscles", str(files["urdf"]), trial, "-o", str(out)])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("pinmsk: error:") and "has no muscles" in err[-1]
    assert not out.exists()


def _leg_without_path(tmp_path):
    import test_osim_import as t
    text = t.leg()
    start = text.index('<Thelen2003Muscle name="vas">')
    a = text.index("<objects>", start)
    b = text.index("</objects", a)
    p = tmp_path / "nopath.osim"
    p.write_text(text[:a + len("<objects>")] + text[b:])
    return p


def test_a_muscle_without_a_path_is_named(tmp_path):
    from pinmsk.errors import ModelError
    from pinmsk.model import import_osim
    with pytest.raises(ModelError, match=r'nopath\.osim:\d+: <Thelen2003Muscle name="vas">: the muscle has no '
                                         r"path points"):
        import_osim(_leg_without_path(tmp_path))


def test_fit_ranges_naming_an_unknown_coordinate_are_refused(tmp_path):
    from functools import partial

    import test_osim_import as t
    from pinmsk.errors import ModelError
    from pinmsk.model import import_osim
    from pinmsk.opensim.muscle_import import muscle_hook
    p = tmp_path / "leg.osim"
    p.write_text(t.leg())
    with pytest.raises(ModelError, match=r"fit ranges name coordinate\(s\) \['knee_angel'\]"):
        import_osim(p, hooks=(partial(muscle_hook, ranges={"knee_angel": (-1.0, 0.0)}),))
