"""``pinmsk run SETUP.xml``: OpenSim's setup files run by pinmsk, their results in OpenSim's files.

The InverseDynamicsTool setups of OpenSim's examples (Arm26, Gait10dof18musc, Gait2354) against OpenSim's
reference outputs shipped beside them; bad setups refused in one line, exit status 2, nothing written
(the checks against OpenSim run by its peer are in ``test_tools_run_peer.py``).  Needs ``../shared/data``;
skips cleanly without it.
"""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from conftest import arm26_setup, shared_folder

from pinmsk.io.opensim_setup import SetupError
from pinmsk.io.tables import read_sto_header, read_trial
from pinmsk.presentation.cli import main
from pinmsk.tools import run_setup

MODELS = "opensim-models"


def _rms_of_peak(out, ref) -> dict:
    """Per column of ``ref``: RMS of the difference as % of the reference's peak |value| (same frames; the
    same columns, whose order OpenSim 4 changed: see test_the_columns_are_in_opensim_4s_tree_order)."""
    assert sorted(out.names) == sorted(ref.names), (out.names, ref.names)
    assert out.n_frames == ref.n_frames
    assert np.allclose(out.time, ref.time, atol=1e-7)
    return {n: 100.0 * float(np.sqrt(np.mean((np.asarray(out[n]) - np.asarray(ref[n])) ** 2)))
            / float(np.max(np.abs(ref[n]))) for n in ref.names}


def _opensim_header(path, title, n_rows, n_cols):
    lines = path.read_text().splitlines()
    assert lines[:6] == [title, "version=1", f"nRows={n_rows}", f"nColumns={n_cols}", "inDegrees=no", "endheader"]


# -- inverse dynamics against OpenSim's reference outputs ----------------------------------------------

def test_arm26_id_setup_reproduces_opensims_filtered_result(tmp_path):
    d = shared_folder(f"{MODELS}/Arm26", "arm26_Setup_InverseDynamics.xml")
    files = run_setup(d / "arm26_Setup_InverseDynamics.xml", results_dir=tmp_path)
    assert files == [tmp_path / "arm26_InverseDynamics.sto"]
    ref = read_trial(d / "reference_outputs" / "InverseDynamics_Filtered" / "arm26_InverseDynamics.sto")
    out = read_trial(files[0])
    _opensim_header(files[0], "Inverse Dynamics Generalized Forces", ref.n_frames, ref.n_channels + 1)
    errs = _rms_of_peak(out, ref)
    assert max(errs.values()) < 0.01, errs


def test_arm26_id_without_the_filter_is_opensims_unfiltered_result(tmp_path):
    # a negative cut-off is OpenSim's "no filter": the setup copied with -1 and its inputs named absolutely
    d = shared_folder(f"{MODELS}/Arm26", "arm26_Setup_InverseDynamics.xml")
    text = (d / "arm26_Setup_InverseDynamics.xml").read_text()
    text = text.replace("       6.00000000 </lowpass", " -1 </lowpass")
    for f in ("arm26.osim", "arm26_InverseKinematics.mot"):
        text = text.replace(f"> {f} <", f"> {d / f} <")
    setup = tmp_path / "setup.xml"
    setup.write_text(text)
    files = run_setup(setup, results_dir=tmp_path / "out")
    ref = read_trial(d / "reference_outputs" / "InverseDynamics_Unfiltered" / "arm26_InverseDynamics.sto")
    out = read_trial(files[0])
    errs = _rms_of_peak(out, ref)
    # unpadded, the splines' end conditions show at the first and last frames (OpenSim's quintic spline is
    # natural, pinmsk's not-a-knot): 8 % of the peak at the first frame, 0.8 % RMS over all frames; inside
    # them the two agree to 0.01 %
    assert max(errs.values()) < 1.0, errs
    for n in ref.names:
        e = (np.asarray(out[n]) - np.asarray(ref[n]))[4:-4]
        assert np.max(np.abs(e)) < 1e-3 * np.max(np.abs(ref[n])), n
    # and it differs from the filtered result by more than that: the cut-off was honoured
    filt = read_trial(d / "reference_outputs" / "InverseDynamics_Filtered" / "arm26_InverseDynamics.sto")
    e = out.values - filt.values
    assert np.max(np.sqrt(np.mean(e ** 2, axis=0)) / np.max(np.abs(filt.values), axis=0)) > 0.01


def test_gait10dof18musc_id_setup_within_half_a_percent_of_opensims_reference(tmp_path):
    d = shared_folder(f"{MODELS}/Gait10dof18musc", "ID/walk_Setup_ID.xml")
    files = run_setup(d / "ID" / "walk_Setup_ID.xml", results_dir=tmp_path)
    assert files == [tmp_path / "subject01_walk_ID.sto"]
    ref = read_trial(d / "reference_outputs" / "ID" / "subject01_walk_ID.sto")
    out = read_trial(files[0])
    # OpenSim's labels: translations are forces, no coordinates before the moments
    assert [n for n in out.names if n.endswith("_force")] == ["pelvis_tx_force", "pelvis_ty_force"]
    errs = _rms_of_peak(out, ref)
    assert max(errs.values()) < 0.5, errs


def _gait2354_folder(tmp_path):
    """The Gait2354 ID setup, unchanged, beside the inputs it names: the model and IK motion are OpenSim's
    reference outputs of the Scale and IK steps, and ``subject01_walk1_grf.xml`` is the repository's
    ``forces_grf.xml`` (see the folder's SOURCE.md)."""
    d = shared_folder(f"{MODELS}/Gait2354Pipeline", "subject01_Setup_InverseDynamics.xml")
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(d / "subject01_Setup_InverseDynamics.xml", run)
    shutil.copy(d / "OutputReference" / "subject01_simbody.osim", run)
    shutil.copy(d / "OutputReference" / "subject01_walk1_ik.mot", run)
    shutil.copy(d / "forces_grf.xml", run / "subject01_walk1_grf.xml")
    shutil.copy(d / "subject01_walk1_grf.mot", run)
    return d, run


def test_gait2354_id_setup_within_half_a_percent_of_opensims_reference(tmp_path):
    d, run = _gait2354_folder(tmp_path)
    files = run_setup(run / "subject01_Setup_InverseDynamics.xml")      # its own results_directory
    assert files == [run / "ResultsInverseDynamics" / "inverse_dynamics.sto"]
    ref = read_trial(d / "OutputReference" / "ResultsInverseDynamics" / "inverse_dynamics.sto")
    errs = _rms_of_peak(read_trial(files[0]), ref)
    assert max(errs.values()) < 0.5, errs


# -- the command and its refusals ----------------------------------------------------------------------

def test_cli_run_prints_the_files_written(tmp_path, capsys):
    d = shared_folder(f"{MODELS}/Arm26", "arm26_Setup_InverseDynamics.xml")
    assert main(["run", str(d / "arm26_Setup_InverseDynamics.xml"), "--results-dir", str(tmp_path / "r")]) == 0
    assert f"wrote {tmp_path / 'r' / 'arm26_InverseDynamics.sto'}" in capsys.readouterr().out.splitlines()


def _arm26_setup(tmp_path, edit):
    return arm26_setup(tmp_path, "arm26_Setup_InverseDynamics.xml", edit)


def _refused(tmp_path, capsys, setup, *words):
    out = tmp_path / "results"
    assert main(["run", str(setup), "--results-dir", str(out)]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("pinmsk: error")]
    assert len(err) == 1, err
    for w in words:
        assert w in err[0], err[0]
    assert not out.exists()
    return err[0]


def test_unknown_tool_is_refused_by_name(tmp_path, capsys):
    setup = tmp_path / "forward.xml"
    setup.write_text('<?xml version="1.0"?><OpenSimDocument Version="40000"><ForwardTool name="f">'
                     "<model_file>m.osim</model_file></ForwardTool></OpenSimDocument>")
    _refused(tmp_path, capsys, setup, "<ForwardTool>", "InverseDynamicsTool")


def test_unknown_property_is_refused_by_name(tmp_path, capsys):
    setup = _arm26_setup(tmp_path, lambda t: t.replace("</InverseDynamicsTool>",
                                                       "<speeds_file>s.sto</speeds_file></InverseDynamicsTool>"))
    _refused(tmp_path, capsys, setup, "<speeds_file>", "not supported")


def test_body_forces_at_joints_are_refused(tmp_path, capsys):
    setup = _arm26_setup(tmp_path, lambda t: t.replace(
        "</InverseDynamicsTool>", "<joints_to_report_body_forces>All</joints_to_report_body_forces>"
                                  "</InverseDynamicsTool>"))
    _refused(tmp_path, capsys, setup, "<joints_to_report_body_forces>")


def test_missing_file_is_refused_with_its_resolved_path(tmp_path, capsys):
    setup = _arm26_setup(tmp_path, lambda t: t.replace("arm26_InverseKinematics.mot", "nowhere.mot"))
    err = _refused(tmp_path, capsys, setup, "<coordinates_file>", "nowhere.mot", "resolved to")
    assert str(setup.parent) in err or "/Arm26/nowhere.mot" in err


def test_a_time_range_outside_the_data_is_refused(tmp_path, capsys):
    setup = _arm26_setup(tmp_path, lambda t: t.replace("0.00000000       1.00000000 </time_range>",
                                                       "5 6 </time_range>"))
    _refused(tmp_path, capsys, setup, "<time_range>", "5-6 s lies outside")


def test_missing_setup_is_refused(tmp_path, capsys):
    _refused(tmp_path, capsys, tmp_path / "none.xml", "none.xml", "not found")


def test_a_runner_that_is_absent_is_refused_by_name(tmp_path, monkeypatch):
    import pinmsk.tools as tools
    monkeypatch.setitem(tools.RUNNERS, "ForwardTool", "forward_absent")
    setup = tmp_path / "forward.xml"
    setup.write_text('<?xml version="1.0"?><OpenSimDocument><ForwardTool name="f"/></OpenSimDocument>')
    with pytest.raises(SetupError, match="pinmsk.tools.forward_absent is absent"):
        run_setup(setup)


@pytest.mark.parametrize("words, message", [
    ("", "muscle(s) applying force"),
    ("Nothing", "'Nothing' is not a force of model"),
])
def test_forces_that_cannot_be_honoured_are_refused(tmp_path, capsys, words, message):
    setup = _arm26_setup(tmp_path, lambda t: t.replace("<forces_to_exclude> Muscles </forces_to_exclude>",
                                                       f"<forces_to_exclude>{words}</forces_to_exclude>"))
    _refused(tmp_path, capsys, setup, "<forces_to_exclude>", message)


@pytest.mark.parametrize("words", ["All", "actuators", "muscles TRIlong TRIlat TRImed BIClong BICshort BRA"])
def test_forces_excluded_as_opensim_names_them(tmp_path, words):
    # every way of excluding arm26's six muscles gives OpenSim's result
    d = shared_folder(f"{MODELS}/Arm26", "arm26_Setup_InverseDynamics.xml")
    setup = _arm26_setup(tmp_path, lambda t: t.replace("<forces_to_exclude> Muscles </forces_to_exclude>",
                                                       f"<forces_to_exclude>{words}</forces_to_exclude>"))
    files = run_setup(setup, results_dir=tmp_path / "out")
    ref = read_trial(d / "reference_outputs" / "InverseDynamics_Filtered" / "arm26_InverseDynamics.sto")
    assert max(_rms_of_peak(read_trial(files[0]), ref).values()) < 0.01
    assert read_sto_header(files[0]).in_degrees is False


# -- OpenSim's layout for models from OpenSim, outside setups too ------------------------------------------

def test_cli_id_of_an_opensim_model_writes_opensims_layout(tmp_path, capsys):
    d = shared_folder(f"{MODELS}/Gait10dof18musc", "subject01.osim")
    out = tmp_path / "id.sto"
    assert main(["id", str(d / "subject01.osim"), str(d / "IK" / "subject01_walk_IK.mot"), "--external-loads",
                 str(d / "ExperimentalData" / "subject01_walk_grf.xml"), "-o", str(out)]) == 0
    ref = read_trial(d / "reference_outputs" / "ID" / "subject01_walk_ID.sto")
    got = read_trial(out)
    assert sorted(got.names) == sorted(ref.names)       # translations as forces, no coordinates before them
    assert got.names[:3] == ("pelvis_tilt_moment", "pelvis_tx_force", "pelvis_ty_force")
    assert out.read_text().splitlines()[0] == "Inverse Dynamics Generalized Forces"
    # pinmsk's own 6 Hz filter here (not OpenSim's): the same moments as the library's
    from pinmsk.dynamics import inverse_dynamics
    from pinmsk.model import load_model
    lib = inverse_dynamics(load_model(d / "subject01.osim"), read_trial(d / "IK" / "subject01_walk_IK.mot"),
                           external_loads=d / "ExperimentalData" / "subject01_walk_grf.xml")
    np.testing.assert_allclose(got["pelvis_tx_force"], lib["pelvis_tx_moment"], rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(got["knee_angle_r_moment"], lib["knee_angle_r_moment"], rtol=1e-8, atol=1e-8)


def test_cli_so_of_an_opensim_model_writes_opensims_two_files(tmp_path, capsys):
    d = shared_folder(f"{MODELS}/Arm26", "arm26.osim")
    out = tmp_path / "so.sto"
    assert main(["so", str(d / "arm26.osim"), str(d / "arm26_InverseKinematics.mot"), "--convention", "opensim",
                 "--mode", "activation", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    act, force = tmp_path / "so_activation.sto", tmp_path / "so_force.sto"
    assert f"wrote {act}" in printed and f"wrote {force}" in printed and not out.exists()
    muscles = ["TRIlong", "TRIlat", "TRImed", "BIClong", "BICshort", "BRA"]
    assert read_trial(act).names == tuple(muscles) and read_trial(force).names == tuple(muscles)
    # the reference's layout (its values are an older OpenSim's: tests/test_tools_analyze.py)
    ref = read_trial(d / "reference_outputs" / "StaticOptimization_Physiological" / "arm26_StaticOptimization_force.sto")
    assert read_trial(force).names == ref.names


def test_builtin_models_keep_pinmsks_layout(tmp_path):
    from pinmsk.io.shared_data import shipped_trial
    out = tmp_path / "id.sto"
    assert main(["id", "forearm", str(shipped_trial("forearm_payload.csv")), "-o", str(out)]) == 0
    names = read_trial(out).names
    assert "elbow_flexion" in names and "elbow_flexion_moment" in names
    assert main(["so", "forearm", str(shipped_trial("forearm_payload.csv")), "-o", str(tmp_path / "so.sto")]) == 0
    so = read_trial(tmp_path / "so.sto")
    assert any(n.endswith("_activation") for n in so.names) and any(n.endswith("_force") for n in so.names)
