"""OpenSim's inverse kinematics, drop-in: ``pinmsk ik`` and the InverseKinematicsTool setup runner.

Against OpenSim's own IK outputs (the .mot files shipped with the example setups, and the opensim
peer's InverseKinematicsTool run on the same setup for the marker errors), a closed-form round trip
(markers of a known motion), and refusals of bad input.
"""
from __future__ import annotations

import os
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from conftest import require_opensim, shared_folder
from pinmsk.io.opensim_setup import SetupError, read_setup
from pinmsk.io.tables import read_sto_header, read_trial
from pinmsk.presentation.cli import main


def _osim_model(path):
    import pinmsk
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pinmsk.load_model(path)


def _compare(ours, ref, rotational):
    """Largest RMS difference over the rotations (deg) and the translations (m), row by row."""
    assert ours.n_frames == ref.n_frames
    # OpenSim 4.6 writes the .trc's Time column as printed (0.017 at 60 Hz); the shipped references, of
    # older versions, k / 60 s: the same frames
    np.testing.assert_allclose(ours.time, ref.time, atol=6e-4)
    rot, tra = 0.0, 0.0
    for c in ref.names:
        d = np.sqrt(np.mean((ours[c] - ref[c]) ** 2))
        if c in rotational:
            rot = max(rot, d)
        else:
            tra = max(tra, d)
    return rot, tra


def _read_mot(path, model):
    from pinmsk.tools.inverse_kinematics import rotational_coordinates
    t = read_trial(path, angular=rotational_coordinates(model))
    rot = set(rotational_coordinates(model))
    # both sides in degrees for the rotations, m for the translations
    return t.with_channels({c: np.rad2deg(t[c]) for c in t.names if c in rot}), rot


@pytest.fixture(scope="module")
def gait10dof(tmp_path_factory):
    """The Gait10dof18musc walk through its IK setup (the model imported once)."""
    from pinmsk.tools.inverse_kinematics import run
    d = shared_folder("opensim-models/Gait10dof18musc", "IK/walk_Setup_IK.xml")
    out = tmp_path_factory.mktemp("g10")
    written = run(read_setup(d / "IK/walk_Setup_IK.xml"), results_dir=out)
    return d, out, written


@pytest.mark.slow
def test_gait10dof_setup_reproduces_opensims_ik(gait10dof):
    d, out, written = gait10dof
    assert [p.name for p in written] == ["subject01_walk_IK.mot", "_ik_marker_errors.sto"]
    model = _osim_model(d / "subject01.osim")
    ours, rot = _read_mot(out / "subject01_walk_IK.mot", model)
    ref, _ = _read_mot(d / "IK/subject01_walk_IK.mot", model)
    assert ours.names == ref.names                      # OpenSim's coordinate order
    rot_rms, tra_rms = _compare(ours, ref, rot)
    assert rot_rms < 0.5, rot_rms
    assert tra_rms < 2e-3, tra_rms
    h = read_sto_header(out / "subject01_walk_IK.mot")
    assert h.fields["nRows"] == "151" and h.fields["nColumns"] == "11" and h.in_degrees is True


@pytest.mark.slow
def test_gait10dof_marker_errors_match_opensims_tool(gait10dof, tmp_path):
    osim = require_opensim()
    d, out, _ = gait10dof
    setup = d / "IK/walk_Setup_IK.xml"
    cwd = os.getcwd()
    try:
        os.chdir(setup.parent)                 # OpenSim resolves the setup's paths from the working folder
        tool = osim.InverseKinematicsTool(str(setup))
        tool.setResultsDir(str(tmp_path))
        tool.setOutputMotionFileName(str(tmp_path / "os.mot"))
        assert tool.run()
    finally:
        os.chdir(cwd)
    theirs = read_trial(tmp_path / "_ik_marker_errors.sto")
    ours = read_trial(out / "_ik_marker_errors.sto")
    assert ours.names == ("total_squared_error", "marker_error_RMS", "marker_error_max")
    assert ours.n_frames == theirs.n_frames == 151
    # the same optimum to OpenSim's accuracy: RMS within 0.05 mm, the worst marker within 0.2 mm
    assert np.max(np.abs(ours["marker_error_RMS"] - theirs["marker_error_RMS"])) < 5e-5
    assert np.max(np.abs(ours["marker_error_max"] - theirs["marker_error_max"])) < 2e-4
    np.testing.assert_allclose(ours["total_squared_error"], theirs["total_squared_error"], rtol=5e-3)
    # and OpenSim's motion of this run, to 0.05 deg
    model = _osim_model(d / "subject01.osim")
    a, rot = _read_mot(out / "subject01_walk_IK.mot", model)
    b, _ = _read_mot(tmp_path / "os.mot", model)
    rot_rms, tra_rms = _compare(a, b, rot)
    assert rot_rms < 0.05 and tra_rms < 2e-4, (rot_rms, tra_rms)


@pytest.mark.slow
def test_gait2354_setup_reproduces_opensims_reference(tmp_path):
    """Marker and coordinate tasks (subtalar and mtp held at their defaults with weight 1000)."""
    from pinmsk.tools.inverse_kinematics import run
    d = shared_folder("opensim-models/Gait2354Pipeline", "subject01_Setup_IK.xml")
    # the setup names the scaled model beside it; the pipeline keeps it in OutputReference
    root = ET.parse(d / "subject01_Setup_IK.xml").getroot()
    tool = root.find("InverseKinematicsTool")
    tool.find("model_file").text = str(d / "OutputReference/subject01_simbody.osim")
    tool.find("marker_file").text = str(d / "subject01_walk1.trc")
    setup = tmp_path / "setup_ik.xml"
    ET.ElementTree(root).write(setup)
    written = run(read_setup(setup), results_dir=tmp_path / "out")
    assert [p.name for p in written] == ["subject01_walk1_ik.mot", "subject01_ik_marker_errors.sto"]
    model = _osim_model(d / "OutputReference/subject01_simbody.osim")
    ours, rot = _read_mot(written[0], model)
    ref, _ = _read_mot(d / "OutputReference/subject01_walk1_ik.mot", model)
    assert ours.names == ref.names and ours.n_frames == 73        # 0.4 to 1.6 s at 60 Hz
    rot_rms, tra_rms = _compare(ours, ref, rot)
    assert rot_rms < 0.5, rot_rms
    assert tra_rms < 2e-3, tra_rms
    assert np.max(np.abs(ours["subtalar_angle_r"])) < 0.05        # held by its coordinate task


def test_cli_round_trip_of_a_known_motion(tmp_path):
    """Markers of a known gait2d motion written as a .trc: ``pinmsk ik`` gives the motion back."""
    import pinmsk
    from pinmsk.ik import markers_trial
    from pinmsk.io.trc import write_trc
    from pinmsk.markers import model_marker_set
    model = pinmsk.load_model("gait2d")
    ms = model_marker_set(model)
    t = np.arange(60) / 100.0
    q = np.zeros((t.size, model.nq))
    ix = model.coordinate_index
    q[:, ix("torso_x")] = 1.1 * t
    q[:, ix("torso_y")] = 1.0 + 0.02 * np.sin(4 * np.pi * t)
    q[:, ix("torso_angle")] = 0.05 * np.sin(2 * np.pi * t)
    q[:, ix("hip_r")] = -0.3 * np.sin(2 * np.pi * t)
    q[:, ix("knee_r")] = 0.5 + 0.4 * np.sin(2 * np.pi * t + 1)
    q[:, ix("ankle_r")] = 0.2 * np.sin(2 * np.pi * t + 2)
    q[:, ix("hip_l")] = 0.3 * np.sin(2 * np.pi * t)
    q[:, ix("knee_l")] = 0.5 - 0.4 * np.sin(2 * np.pi * t + 1)
    q[:, ix("ankle_l")] = -0.2 * np.sin(2 * np.pi * t + 2)
    trc = tmp_path / "walk.trc"
    write_trc(markers_trial(model, ms, t, q), trc, units="mm")
    out = tmp_path / "q.mot"
    assert main(["ik", "gait2d", str(trc), "-o", str(out), "--time", "0.1", "0.5", "--precision", "12"]) == 0
    got = read_trial(out)
    assert read_sto_header(out).in_degrees is True
    assert got.names == tuple(model.coordinate_order)
    np.testing.assert_allclose(got.time, t[10:51], atol=1e-9)
    for c in ("torso_x", "torso_y", "torso_angle", "hip_r", "knee_r", "ankle_r", "hip_l", "knee_l", "ankle_l"):
        np.testing.assert_allclose(got[c], q[10:51, ix(c)], atol=1e-5, err_msg=c)
    err = read_trial(tmp_path / "q_ik_marker_errors.sto")
    assert err.names == ("total_squared_error", "marker_error_RMS", "marker_error_max")
    assert np.max(err["marker_error_max"]) < 1e-5            # the markers' 1e-5 mm of rounding in the file


# -- refusals --------------------------------------------------------------------------------------

def _arm26_setup(tmp_path, edit=None):
    d = shared_folder("opensim-models/Arm26", "arm26_Setup_InverseKinematics.xml")
    root = ET.parse(d / "arm26_Setup_InverseKinematics.xml").getroot()
    tool = root.find("InverseKinematicsTool")
    tool.find("model_file").text = str(d / "arm26.osim")
    tool.find("marker_file").text = str(d / "arm26_elbow_flex.trc")
    if edit is not None:
        edit(tool)
    path = tmp_path / "arm26_ik.xml"
    ET.ElementTree(root).write(path)
    return read_setup(path)


def test_setup_refuses_an_unknown_property_by_name(tmp_path):
    from pinmsk.tools.inverse_kinematics import run

    def edit(tool):
        ET.SubElement(tool, "optimizer_algorithm").text = "ipopt"
    with pytest.raises(SetupError, match=r"<optimizer_algorithm> not supported"):
        run(_arm26_setup(tmp_path, edit), results_dir=tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_setup_refuses_a_missing_marker_file_with_its_resolved_path(tmp_path):
    from pinmsk.tools.inverse_kinematics import run

    def edit(tool):
        tool.find("marker_file").text = "no_such_walk.trc"
    with pytest.raises(SetupError) as info:
        run(_arm26_setup(tmp_path, edit), results_dir=tmp_path / "out")
    msg = str(info.value)
    assert "<marker_file>" in msg and str(tmp_path / "no_such_walk.trc") in msg and "\n" not in msg


def test_setup_refuses_marker_locations(tmp_path):
    from pinmsk.tools.inverse_kinematics import run

    def edit(tool):
        tool.find("report_marker_locations").text = "true"
    with pytest.raises(SetupError, match="report_marker_locations"):
        run(_arm26_setup(tmp_path, edit), results_dir=tmp_path / "out")


def test_cli_task_naming_a_marker_the_model_lacks_exits_2_without_files(tmp_path, capsys):
    d = shared_folder("opensim-models/Arm26", "arm26_Setup_InverseKinematics.xml")
    tasks = tmp_path / "tasks.xml"
    tasks.write_text('<?xml version="1.0"?>\n<OpenSimDocument Version="40000"><IKTaskSet><objects>'
                     '<IKMarkerTask name="r_acromion"><apply>true</apply><weight>1</weight></IKMarkerTask>'
                     '<IKMarkerTask name="r_ulna_head"><apply>true</apply><weight>2</weight></IKMarkerTask>'
                     '</objects></IKTaskSet></OpenSimDocument>\n')
    out = tmp_path / "q.mot"
    capsys.readouterr()
    assert main(["ik", str(d / "arm26.osim"), str(d / "arm26_elbow_flex.trc"), "-o", str(out),
                 "--tasks", str(tasks)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    line = [e for e in err if e.startswith("pinmsk: error:")]
    assert len(line) == 1 and "r_ulna_head" in line[0] and "no such marker" in line[0]
    assert not out.exists() and not (tmp_path / "q_ik_marker_errors.sto").exists()


def test_task_set_refuses_an_unknown_field(tmp_path):
    from pinmsk.io.ik_tasks import read_ik_tasks
    tasks = tmp_path / "tasks.xml"
    tasks.write_text('<OpenSimDocument Version="40000"><IKTaskSet><objects>'
                     '<IKMarkerTask name="r_acromion"><apply>true</apply><weight>1</weight><gain>3</gain>'
                     '</IKMarkerTask></objects></IKTaskSet></OpenSimDocument>\n')
    with pytest.raises(SetupError, match=r"IKMarkerTask 'r_acromion'.*<gain>"):
        read_ik_tasks(tasks)


# -- the batched kinematics ------------------------------------------------------------------------

def test_batch_kinematics_matches_pinocchio_frames():
    """Positions and LOCAL_WORLD_ALIGNED Jacobians of the markers, to rounding, at random poses."""
    import pinocchio as pin

    import pinmsk
    from pinmsk.ik import BatchKinematics, add_marker_frames
    from pinmsk.markers import model_marker_set
    model = pinmsk.load_model("gait2d")
    ms = model_marker_set(model)
    kin = BatchKinematics(model.pin, [m.body for m in ms.markers], [m.position for m in ms.markers])
    pm, fids = add_marker_frames(model, ms)
    pd = pm.createData()
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.0, 1.0, (5, model.nq))
    X, J = kin(q)
    for k in range(q.shape[0]):
        pin.computeJointJacobians(pm, pd, q[k])
        pin.updateFramePlacements(pm, pd)
        for j, fid in enumerate(fids):
            np.testing.assert_allclose(X[k, j], pd.oMf[fid].translation, atol=1e-12)
            np.testing.assert_allclose(J[k, j], pin.getFrameJacobian(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED)[:3],
                                       atol=1e-12)


@pytest.mark.slow
def test_knee_map_in_one_pass_matches_the_coordinate_map(gait10dof):
    from pinmsk.ik import _fast_map
    from pinmsk.kinematics import coordinate_map
    d, _, _ = gait10dof
    cmap = coordinate_map(_osim_model(d / "subject01.osim"))
    rng = np.random.default_rng(5)
    n_os = len(cmap.osim_coordinates)
    Q = np.array([cmap.defaults[c] for c in cmap.osim_coordinates]) + rng.uniform(-1.0, 0.1, (40, n_os))
    mapping = _fast_map(cmap)
    qp, slopes = mapping(Q)
    np.testing.assert_allclose(qp, cmap.expand(Q)[0], atol=1e-13)
    J = np.zeros((Q.shape[0], len(cmap.joints), Q.shape[1]))
    J[:, mapping.same[0], mapping.same[1]] = 1.0
    for js, col, D1 in slopes:
        J[:, js, col] = D1.T
    np.testing.assert_allclose(J, cmap.jacobian(Q), atol=1e-12)


@pytest.mark.slow
def test_rajagopal_walk_reaches_opensims_optimum(tmp_path):
    """A 39-coordinate model with coupled knees and clamped ranges, no task set (every marker, weight 1):
    on every frame pinmsk's objective (the total squared marker error, the weights being 1) is at most
    OpenSim's, and the lower body's coordinates agree with OpenSim's."""
    osim = require_opensim()
    from pinmsk.tools.inverse_kinematics import run, rotational_coordinates
    d = shared_folder("opensim-models/RajagopalWalk", "subject_walk_scaled.osim")
    trc = shared_folder("real/opensim-moco-walk-emg", "markers_walk.trc") / "markers_walk.trc"
    setup = tmp_path / "raj_ik.xml"
    setup.write_text(f'<?xml version="1.0" encoding="UTF-8" ?>\n<OpenSimDocument Version="40600">'
                     f'<InverseKinematicsTool name="raj"><model_file>{d / "subject_walk_scaled.osim"}</model_file>'
                     f'<marker_file>{trc}</marker_file><time_range>0.5 0.8</time_range>'
                     f'<output_motion_file>raj_ik.mot</output_motion_file><results_directory>.</results_directory>'
                     f'<constraint_weight>Inf</constraint_weight><accuracy>1e-5</accuracy>'
                     f'<report_errors>true</report_errors></InverseKinematicsTool></OpenSimDocument>\n')
    ours = run(read_setup(setup), results_dir=tmp_path / "pinmsk")
    (tmp_path / "opensim").mkdir()
    tool = osim.InverseKinematicsTool(str(setup))
    tool.setResultsDir(str(tmp_path / "opensim"))
    tool.setOutputMotionFileName(str(tmp_path / "opensim" / "raj_ik.mot"))
    assert tool.run()
    a, b = read_trial(ours[1]), read_trial(tmp_path / "opensim" / "raj_ik_marker_errors.sto")
    assert a.n_frames == b.n_frames == 31
    assert np.all(a["total_squared_error"] <= b["total_squared_error"] * (1 + 1e-4))
    assert abs(np.mean(a["marker_error_RMS"]) - np.mean(b["marker_error_RMS"])) < 5e-5
    model = _osim_model(d / "subject_walk_scaled.osim")
    rot = set(rotational_coordinates(model))
    qa = read_trial(ours[0], angular=rot)
    qb = read_trial(tmp_path / "opensim" / "raj_ik.mot", angular=rot)
    assert qa.names == qb.names
    legs = [c for c in qb.names if c.startswith(("pelvis", "hip", "knee_angle", "ankle", "lumbar"))]
    for c in legs:
        tol = np.deg2rad(1.0) if c in rot or c.endswith("_beta") else 2e-3
        assert np.sqrt(np.mean((qa[c] - qb[c]) ** 2)) < tol, c


def test_arm26_setup_with_its_task_set_in_a_file_reproduces_opensims_motion(tmp_path):
    """The task set given as ``<IKTaskSet file=...>`` (read from that file, relative to the setup);
    the elbow flexion trial against OpenSim's shipped IK motion."""
    from pinmsk.tools.inverse_kinematics import run

    def edit(tool):
        tasks = tool.find("IKTaskSet")
        doc = ET.Element("OpenSimDocument", Version="30000")
        doc.append(tasks)
        ET.ElementTree(doc).write(tmp_path / "arm26_tasks.xml")
        tool.remove(tasks)
        ET.SubElement(tool, "IKTaskSet", file="arm26_tasks.xml")
    written = run(_arm26_setup(tmp_path, edit), results_dir=tmp_path / "out")
    assert [p.name for p in written] == ["arm26_InverseKinematics.mot", "arm26_ik_marker_errors.sto"]
    d = shared_folder("opensim-models/Arm26", "arm26_Setup_InverseKinematics.xml")
    model = _osim_model(d / "arm26.osim")
    ours, rot = _read_mot(written[0], model)
    ref, _ = _read_mot(d / "arm26_InverseKinematics.mot", model)
    rot_rms, _ = _compare(ours, ref, rot)
    assert ours.names == ("r_shoulder_elev", "r_elbow_flex") and rot_rms < 0.5, rot_rms
