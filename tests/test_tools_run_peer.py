"""OpenSim's tools and pinmsk's side by side, with the opensim peer: the ID setup's columns in OpenSim 4's
order, and OpenSim's coordinate filter (pad + IIR) against OpenSim's own ``Storage``.  Skips without
opensim or ``../shared/data``."""
from __future__ import annotations

import numpy as np

from conftest import require_opensim, shared_folder
from test_tools_run import MODELS, _rms_of_peak

from pinmsk.io.tables import read_trial
from pinmsk.signals.filtering import lowpass_opensim
from pinmsk.tools import run_setup


def test_the_columns_are_in_opensim_4s_tree_order(tmp_path):
    # OpenSim 4 writes the coordinates in multibody-tree order (the joints a depth at a time from the
    # ground: pelvis, hips and back, knees, ankles); the shipped reference, older, in the file's order
    osim = require_opensim()
    d = shared_folder(f"{MODELS}/Gait10dof18musc", "ID/walk_Setup_ID.xml")
    work = tmp_path / "work" / "ID"       # its tool opens <model_file> from the working directory
    work.mkdir(parents=True)
    (work.parent / "subject01.osim").symlink_to(d / "subject01.osim")
    import os
    cwd = os.getcwd()
    try:
        os.chdir(work)
        tool = osim.InverseDynamicsTool(str(d / "ID" / "walk_Setup_ID.xml"))
        tool.setResultsDir(str(tmp_path / "opensim"))
        assert tool.run()
    finally:
        os.chdir(cwd)
    theirs = read_trial(tmp_path / "opensim" / "subject01_walk_ID.sto")
    mine = read_trial(run_setup(d / "ID" / "walk_Setup_ID.xml", results_dir=tmp_path / "pinmsk")[0])
    assert mine.names == theirs.names
    assert mine.names[3:6] == ("hip_flexion_r_moment", "hip_flexion_l_moment", "lumbar_extension_moment")
    assert max(_rms_of_peak(mine, theirs).values()) < 0.5


def test_opensims_coordinate_filter_matches_opensims_storage():
    # pad by half, resample at the smallest step (the file's times are rounded), lowpassIIR: OpenSim's own
    osim = require_opensim()
    from pinmsk.tools._common import opensim_filtered
    d = shared_folder(f"{MODELS}/Gait10dof18musc", "IK/subject01_walk_IK.mot")
    path = d / "IK" / "subject01_walk_IK.mot"
    sto = osim.Storage(str(path))
    sto.pad(sto.getSize() // 2)
    sto.lowpassIIR(6.0)
    t = np.array([sto.getStateVector(i).getTime() for i in range(sto.getSize())])
    k = sto.getColumnLabels().getSize() - 1
    X = np.array([[sto.getStateVector(i).getData().get(j) for j in range(k)] for i in range(sto.getSize())])
    mine = opensim_filtered(read_trial(path, angular=()), 6.0, str(path))
    assert np.array_equal(np.asarray(mine.time), t)
    assert np.max(np.abs(mine.values - X)) < 1e-6 * np.max(np.abs(X))


def test_same_numbers_as_opensims_storage():
    """``Storage.pad(n // 2)`` then ``Storage.lowpassIIR(fc)`` in OpenSim itself gives the same samples."""
    osim = require_opensim()
    rate, fc = 60.0, 6.0
    t = np.arange(90) / rate
    x = np.sin(2 * np.pi * 1.3 * t) + 0.1 * np.cos(2 * np.pi * 9 * t) + t ** 2
    st = osim.Storage()
    labels = osim.ArrayStr()
    labels.append("time")
    labels.append("x")
    st.setColumnLabels(labels)
    for k in range(t.size):
        row = osim.Vector(1, float(x[k]))
        st.append(float(t[k]), row)
    st.pad(t.size // 2)
    st.lowpassIIR(fc)
    theirs = np.array([st.getStateVector(i).getData().get(0) for i in range(st.getSize())])
    ours, pad = lowpass_opensim(x, rate=rate, cutoff=fc)
    assert theirs.shape == ours.shape
    assert np.max(np.abs(theirs - ours)) < 1e-10


