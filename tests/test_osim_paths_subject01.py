"""Geometric paths of Gait10dof18musc's scaled subject (Working_with_Static_Optimization/subject01.osim)
at the walk's IK poses against OpenSim's ``GeometryPath`` values stored in
``tests/opensim_paths/subject01_walk_paths.json`` (written by ``tests/opensim_paths/make_reference.py``).

The model's glut_max_r/l are four-point paths (pelvis, pelvis, femur, femur) and the model has no wrap
object at all (nor has the generic gait10dof18musc.osim): there is no wrap to be off.  Read from the same
file at the same poses, the exact paths of all 18 muscles agree with OpenSim to 2e-16 m of length and
1.5e-10 m of moment arm; this test holds that for glut_max as for the others."""
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import require_opensim, shared_folder

REF = Path(__file__).resolve().parent / "opensim_paths" / "subject01_walk_paths.json"


def _pinmsk(ref, folder):
    from pinmsk.opensim.muscle_import import osim_geometric_paths
    gp = osim_geometric_paths(folder / "Working_with_Static_Optimization" / "subject01.osim")
    names = ref["coordinates"]
    q_ref = np.asarray(ref["q"])
    q = np.column_stack([q_ref[:, names.index(c)] for c in gp.coordinates])
    L, A = gp.lengths_and_moment_arms(q)
    cols = [gp.coordinates.index(c) for c in names]
    rows = [gp.muscles.index(m) for m in ref["muscles"]]
    return L[:, rows], A[:, rows][:, :, cols]


def test_subject01_paths_match_the_stored_opensim_reference():
    """All 18 muscles, glut_max included: lengths and moment arms within 1e-9 m / 1e-8 m of OpenSim's
    (measured 2e-16 m, 1.5e-10 m)."""
    folder = shared_folder("opensim-models/Gait10dof18musc", "Working_with_Static_Optimization/subject01.osim")
    ref = json.loads(REF.read_text())
    L, A = _pinmsk(ref, folder)
    el = np.abs(L - np.asarray(ref["lengths"])).max(axis=0)
    ea = np.abs(A - np.asarray(ref["moment_arms"])).max(axis=(0, 2))
    assert len(ref["muscles"]) == 18 and {"glut_max_r", "glut_max_l"} <= set(ref["muscles"])
    assert el.max() < 1e-9, f"length {el.max():.3g} m at {ref['muscles'][int(el.argmax())]}"
    assert ea.max() < 1e-8, f"moment arm {ea.max():.3g} m at {ref['muscles'][int(ea.argmax())]}"
    # the reference is not trivially flat: glut_max's hip moment arm changes over the walk
    hip = ref["coordinates"].index("hip_flexion_r")
    g = np.asarray(ref["moment_arms"])[:, ref["muscles"].index("glut_max_r"), hip]
    assert np.ptp(g) > 5e-3


@pytest.mark.slow
def test_subject01_reference_regenerates_with_opensim():
    """The stored reference is what the opensim package computes now (the script beside it)."""
    require_opensim()
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_reference", REF.parent / "make_reference.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    shared = shared_folder("opensim-models", "Gait10dof18musc/Working_with_Static_Optimization/subject01.osim").parent
    new = mod.reference(shared)
    old = json.loads(REF.read_text())
    assert new["muscles"] == old["muscles"] and new["coordinates"] == old["coordinates"]
    assert np.abs(np.asarray(new["lengths"]) - old["lengths"]).max() < 1e-12
    assert np.abs(np.asarray(new["moment_arms"]) - old["moment_arms"]).max() < 1e-10


def _imported(folder):
    from pinmsk.model import import_osim
    model, _ = import_osim(folder / "Working_with_Static_Optimization" / "subject01.osim")
    return model


def _model_q(model, ref):
    q_ref = np.asarray(ref["q"])
    q = np.zeros((q_ref.shape[0], model.nv))
    for k, c in enumerate(ref["coordinates"]):
        if c in model.coordinate_order:
            q[:, model.coordinate_index(c)] = q_ref[:, k]
    return q


def test_exact_path_kinematics_of_an_import_is_opensims_and_the_surrogate_check_names_the_worst():
    """exact_path_kinematics (model coordinates, model muscle order) reproduces the stored OpenSim values;
    check_surrogates reports the polynomials' largest errors against them, muscle and coordinate named."""
    from pinmsk.opensim.path_check import DEFAULT_TOLERANCE, check_surrogates, exact_path_kinematics
    folder = shared_folder("opensim-models/Gait10dof18musc", "Working_with_Static_Optimization/subject01.osim")
    ref = json.loads(REF.read_text())
    model = _imported(folder)
    q = _model_q(model, ref)
    L, A = exact_path_kinematics(model, q)
    rows = [ref["muscles"].index(m) for m in model.muscles.names]
    assert np.abs(L - np.asarray(ref["lengths"])[:, rows]).max() < 1e-9
    hip = ref["coordinates"].index("hip_flexion_r")
    arm = A[:, :, model.coordinate_index("hip_flexion_r")]
    assert np.abs(arm - np.asarray(ref["moment_arms"])[:, rows, hip]).max() < 1e-8
    check = check_surrogates(model, q)
    Ls, As = model.muscles.lengths(q), model.muscles.moment_arms(q)
    assert check.length_error == pytest.approx(np.abs(Ls - L).max(), rel=1e-12)
    assert check.moment_arm_error == pytest.approx(np.abs(As - A).max(), rel=1e-12)
    i = model.muscles.names.index(check.length_muscle)
    assert np.abs(Ls[:, i] - L[:, i]).max() == pytest.approx(check.length_error, rel=1e-12)
    assert check.frames == q.shape[0] and check.length_muscle in check.line()
    assert 0.0 < check.length_error < DEFAULT_TOLERANCE      # the whole-range fit of this small model is good


def test_choose_paths_takes_exact_paths_by_default_and_refuses_surrogates_above_the_tolerance():
    """Default: the muscle set's paths are the exact ones (path_kinematics = OpenSim's values); with
    surrogates the header line gives the largest error, and a tolerance below it is refused by name."""
    from pinmsk.errors import ModelError
    from pinmsk.opensim.path_check import check_surrogates, choose_paths
    folder = shared_folder("opensim-models/Gait10dof18musc", "Working_with_Static_Optimization/subject01.osim")
    ref = json.loads(REF.read_text())
    model = _imported(folder)
    q = _model_q(model, ref)
    exact, line = choose_paths(model, q)
    assert "exact" in line
    L, _, R = exact.muscles.path_kinematics(q, np.zeros_like(q))
    rows = [ref["muscles"].index(m) for m in model.muscles.names]
    assert np.abs(L - np.asarray(ref["lengths"])[:, rows]).max() < 1e-9
    worst = check_surrogates(model, q)
    # the whole-range fit misses vasti's moment arm by about 2 mm at the walk's poses: refused at 1 mm
    assert worst.worst > 1e-3
    with pytest.raises(ModelError, match="path tolerance"):
        choose_paths(model, q, surrogate=True)
    same, line = choose_paths(model, q, surrogate=True, tolerance=2.0 * worst.worst)
    assert same is model and line == worst.line()


@pytest.mark.slow
def test_so_cli_exact_by_default_and_surrogates_refused_above_the_tolerance(tmp_path, capsys):
    """``pinmsk so`` on subject01's walk: exact paths by default; ``--surrogate-paths`` refused at the
    1 mm default (exit 2, no file), accepted with ``--path-tolerance 3`` with the error in the header; the
    two runs' muscle forces differ by the surrogates' error only (within 10 % of the peak force)."""
    from pinmsk.io.tables import read_trial
    from pinmsk.presentation.cli import main
    folder = shared_folder("opensim-models/Gait10dof18musc", "Working_with_Static_Optimization/subject01.osim")
    model = str(folder / "Working_with_Static_Optimization" / "subject01.osim")
    ik = str(folder / "IK" / "subject01_walk_IK.mot")
    dofs = ["--dofs", "hip_flexion_r,knee_angle_r,ankle_angle_r,hip_flexion_l,knee_angle_l,ankle_angle_l"]
    assert main(["so", model, ik, "-o", str(tmp_path / "e.sto"), *dofs]) == 0
    assert "paths: exact" in capsys.readouterr().out
    assert main(["so", model, ik, "-o", str(tmp_path / "r.sto"), *dofs, "--surrogate-paths"]) == 2
    assert "path tolerance" in capsys.readouterr().err and not list(tmp_path.glob("r*"))
    assert main(["so", model, ik, "-o", str(tmp_path / "s.sto"), *dofs, "--surrogate-paths",
                 "--path-tolerance", "3"]) == 0
    header = (tmp_path / "s_force.sto").read_text().split("endheader")[0]
    assert "paths=path surrogates vs exact paths at 151 frames" in header
    e, s = read_trial(tmp_path / "e_force.sto"), read_trial(tmp_path / "s_force.sto")
    fe = np.column_stack([e[c] for c in e.names])
    fs = np.column_stack([s[c] for c in e.names])
    assert 0.0 < np.abs(fe - fs).max() < 0.1 * np.abs(fe).max()
