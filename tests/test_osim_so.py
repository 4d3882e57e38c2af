"""Static optimization of imported OpenSim models, like for like against OpenSim's own StaticOptimization
(gait10dof18musc with the same reserves: activations within 0.02 of OpenSim's SO), and pinmsk's actuator columns against OpenSim's generalized forces.

OpenSim runs here (an AnalyzeTool with a StaticOptimization analysis, results in tmp_path) on a few frames;
pinmsk's SO (``convention="opensim"``: OpenSim's muscle model; the actuators of the same force set file)
runs on the same coordinates, low-passed as OpenSim's tools do (``Storage.pad`` + ``lowpassIIR``, 6 Hz,
as tests/test_osim_id.py), and its activations are compared on OpenSim's frames.  gait10dof18musc is the
Working_with_Static_Optimization ``subject01.osim`` with its ``gait10dof18musc_Strong_actuators.xml``
(pelvis residuals FX, FY, MZ and coordinate reserves), the IK motion and ``subject01_walk_grf.xml``,
imported with exact knees (``nonlinear="exact"``) and its polynomial muscle paths.  arm26 follows
``arm26_Setup_StaticOptimization.xml`` (no force set file: muscles only), against OpenSim 4.6 and against
the shipped reference outputs of an older OpenSim.  Needs ``../shared/data`` and ``opensim``; skips cleanly
without them.
"""
from pathlib import Path

import numpy as np
import pytest

from pinmsk.actuators import PointActuator, TorqueActuator, actuator_columns
from pinmsk.components import Motion
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.io.tables import read_trial
from pinmsk.model import import_osim
from pinmsk.solvers import StaticOptimization
from test_opensim_peer import _harness
from test_osim_id import _opensim, _opensim_filtered

GAIT = "opensim-models/Gait10dof18musc"
ARM = "opensim-models/Arm26"
#: OpenSim's frames of the comparison (60 Hz motion: 10 frames)
GAIT_SPAN = (0.5, 0.65)
ARM_SPAN = (0.3, 0.5)


def _dir(rel, probe):
    d = shared_data_dir()
    p = None if d is None else d / rel
    if p is None or not (p / probe).is_file():
        pytest.skip(f"../shared/data/{rel} is absent")
    return p


def opensim_static_optimization(osim, model_path, coordinates, out: Path, *, span, actuators=None, loads=None,
                                physiological=True, cutoff=6.0):
    """OpenSim's StaticOptimization (the benchmarks' runner, ``bench_opensim.static_optimization_run``) on
    ``span`` of ``coordinates``; returns (activation Trial, seconds of ``tool.run()``)."""
    dt, path = _harness().static_optimization_run(osim, model_path, coordinates, out, span=span,
                                                  actuators=actuators, loads=loads,
                                                  physiological=physiological, cutoff=cutoff)
    return read_trial(path), dt


def _on_frames(result, ref, names, suffix=""):
    """(pinmsk, OpenSim) arrays (n_ref, len(names)) of ``names`` on OpenSim's frames."""
    t = np.asarray(result.time)
    k = np.array([int(np.argmin(np.abs(t - x))) for x in np.asarray(ref.time)])
    assert np.max(np.abs(t[k] - np.asarray(ref.time))) < 1e-4
    mine = np.column_stack([np.asarray(result[f"{n}{suffix}"])[k] for n in names])
    theirs = np.column_stack([np.asarray(ref[n]) for n in names])
    return mine, theirs


@pytest.fixture(scope="module")
def gait(tmp_path_factory):
    """The imported model, its OpenSim-filtered trial, the force set and loads, OpenSim's SO on GAIT_SPAN."""
    osim = _opensim()
    d = _dir(GAIT, "Working_with_Static_Optimization/subject01.osim")
    work = d / "Working_with_Static_Optimization"
    tmp = tmp_path_factory.mktemp("gait_so")
    xml = (d / "ExperimentalData" / "subject01_walk_grf.xml").read_text()
    loads = tmp / "grf.xml"           # its datafile is named relative to the data folder
    loads.write_text(xml.replace("<datafile>subject01_walk_grf.mot</datafile>",
                                 f"<datafile>{d / 'ExperimentalData' / 'subject01_walk_grf.mot'}</datafile>"))
    actuators = work / "gait10dof18musc_Strong_actuators.xml"
    ik = d / "IK" / "subject01_walk_IK.mot"
    ref, os_time = opensim_static_optimization(osim, work / "subject01.osim", ik, tmp / "opensim", span=GAIT_SPAN,
                                               actuators=actuators, loads=loads)
    model, _ = import_osim(work / "subject01.osim", nonlinear="exact")
    trial = _opensim_filtered(osim, ik, 6.0, np.asarray(read_trial(ik).time))
    return dict(model=model, trial=trial, ref=ref, loads=loads, actuators=actuators, opensim_s=os_time)


def _gait_so(gait, **kw):
    so = StaticOptimization(mode="activation", actuators=gait["actuators"], **kw)
    return so.fit(gait["model"], gait["trial"], cutoff=0, grf_cutoff=0, external_loads=gait["loads"])


def test_so_of_gait10dof18musc_with_the_strong_actuators_matches_opensims(gait):
    so = _gait_so(gait, convention="opensim")
    model, ref = gait["model"], gait["ref"]
    assert ref.n_frames == 10
    mine, theirs = _on_frames(so.result_, ref, model.muscles.names, "_activation")
    worst = float(np.max(np.abs(mine - theirs)))
    assert worst <= 0.02, f"max |activation difference| {worst:.4f} > 0.02"       # measured 0.0056
    assert theirs.max() > 0.2            # the muscles work: a difference of 0.02 is not a trivial bound
    # the actuators' controls too: pelvis residuals FX, FY, MZ and the coordinate reserves
    acts = [n for n in ref.names if n not in model.muscles.names]
    assert acts == list(so.result_.meta["actuator_names"].split(", ")) and len(acts) == 10
    u_mine, u_theirs = _on_frames(so.result_, ref, acts, "_control")
    assert np.max(np.abs(u_mine - u_theirs)) < 0.01                               # measured 0.0023
    assert np.max(np.abs(u_theirs[:, :3])) > 0.2                                   # the residuals are used
    # speed against OpenSim's SO is measured in benchmarks/bench_osim_so.py, not asserted here


def test_opensims_muscle_model_is_what_makes_the_match(gait):
    # pinmsk's own muscle model (passive forces balanced, activations from 0) is a different answer:
    # what convention="opensim" changes, and a check that the comparison above can fail
    so = _gait_so(gait, convention="pinmsk")
    mine, theirs = _on_frames(so.result_, gait["ref"], gait["model"].muscles.names, "_activation")
    assert np.max(np.abs(mine - theirs)) > 0.02                                    # measured 0.028


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """arm26 imported with its muscles (the path fits take ~5 s on an idle machine: the tests using it are
    slow; the default suite covers the same code with gait10dof18musc above)."""
    osim = _opensim()
    d = _dir(ARM, "arm26.osim")
    ik = d / "arm26_InverseKinematics.mot"
    model, _ = import_osim(d / "arm26.osim")
    trial = _opensim_filtered(osim, ik, 6.0, np.asarray(read_trial(ik).time))
    return dict(osim=osim, dir=d, ik=ik, model=model, trial=trial, tmp=tmp_path_factory.mktemp("arm_so"))


@pytest.mark.slow
def test_so_of_arm26_matches_opensims(arm):
    """Slow (~7 s); test_so_of_gait10dof18musc_with_the_strong_actuators_matches_opensims covers the code."""
    ref, _ = opensim_static_optimization(arm["osim"], arm["dir"] / "arm26.osim", arm["ik"], arm["tmp"] / "physio",
                                         span=ARM_SPAN)
    so = StaticOptimization(mode="activation", convention="opensim").fit(arm["model"], arm["trial"], cutoff=0)
    mine, theirs = _on_frames(so.result_, ref, arm["model"].muscles.names, "_activation")
    assert np.max(np.abs(mine - theirs)) <= 0.02                                   # measured 0.0061
    assert theirs.min() >= 0.01 - 1e-6 and mine.min() >= 0.01 - 1e-12            # OpenSim 4.6's min_control
    assert theirs.max() > 0.1


@pytest.mark.slow
def test_so_of_arm26_against_the_shipped_reference_outputs(arm, tmp_path):
    """The reference outputs come from an older OpenSim whose muscles' min_control was 0 (activations down
    to 2e-5): the same model with ``min_control = 0`` written into its muscles.  Slow (~10 s); covered as
    test_so_of_arm26_matches_opensims."""
    text = (arm["dir"] / "arm26.osim").read_text()
    text = text.replace("<max_isometric_force>", "<min_control>0</min_control><max_isometric_force>")
    zero = tmp_path / "arm26_min_control_0.osim"
    zero.write_text(text)
    model, _ = import_osim(zero)
    refs = arm["dir"] / "reference_outputs"
    for mode, sub, bound in (("force", "StaticOptimization_Nonphysiological", 0.01),     # measured 0.0053
                             ("activation", "StaticOptimization_Physiological", 0.025)):  # measured 0.0204
        ref = read_trial(refs / sub / "arm26_StaticOptimization_activation.sto")
        so = StaticOptimization(mode=mode, convention="opensim").fit(model, arm["trial"], cutoff=0)
        mine, theirs = _on_frames(so.result_, ref, model.muscles.names, "_activation")
        assert theirs.min() < 1e-3 and np.max(np.abs(mine - theirs)) <= bound, sub


def test_actuator_columns_match_opensims_generalized_forces():
    """Point and torque actuators in body frames, a ground point and a torque between two bodies: pinmsk's
    ``F_opt B(q)`` against OpenSim's (inverse dynamics with and without a unit actuation), on arm26."""
    osim = _opensim()
    arm = {"dir": _dir(ARM, "arm26.osim")}
    model = import_osim(arm["dir"] / "arm26.osim", hooks=())[0]
    specs = [("p", "r_ulna_radius_hand", dict(point=(0.01, -0.2, 0.03), direction=(0.3, 1.0, -0.2))),
             ("pg", "r_humerus", dict(point=(0.05, -0.1, 0.1), direction=(1.0, 0.5, 0.2), point_is_global=True,
                                      force_is_global=True)),
             ("t", "r_ulna_radius_hand", dict(body_b="r_humerus", axis=(0.2, 0.1, 1.0), torque_is_global=False))]
    ours = [PointActuator(n, b, **kw) if n != "t" else TorqueActuator(n, b, **kw) for n, b, kw in specs]
    om = osim.Model(str(arm["dir"] / "arm26.osim"))
    theirs = []
    for (name, body, kw), a in zip(specs, ours):
        if isinstance(a, PointActuator):
            oa = osim.PointActuator()
            oa.set_body(body)
            oa.set_point(osim.Vec3(*kw["point"]))
            oa.set_direction(osim.Vec3(*kw["direction"]))
            oa.set_point_is_global(kw.get("point_is_global", False))
            oa.set_force_is_global(kw.get("force_is_global", False))
        else:
            oa = osim.TorqueActuator()
            oa.set_bodyA(body)
            oa.set_bodyB(kw["body_b"])
            oa.setAxis(osim.Vec3(*kw["axis"]))
            oa.setTorqueIsGlobal(kw["torque_is_global"])
        oa.setName(name)
        om.addForce(oa)
        theirs.append(oa)
    for i in range(om.getMuscles().getSize()):
        om.getMuscles().get(i).set_appliesForce(False)
    s = om.initSystem()
    solver = osim.InverseDynamicsSolver(om)
    cs = om.getCoordinateSet()      # arm26's order is its tree's (a serial chain): the solver's u order
    names = [cs.get(i).getName() for i in range(cs.getSize())]
    q = np.array([[0.3, 1.2], [-0.4, 0.4], [1.1, 2.0]])
    mo = Motion(np.arange(3.0), q, np.zeros_like(q), np.zeros_like(q))
    mine = actuator_columns(model, mo, ours)[:, :, [model.coordinate_index(c) for c in names]]
    for a in theirs:
        a.overrideActuation(s, True)
    for k in range(q.shape[0]):
        for c in names:
            om.getCoordinateSet().get(c).setValue(s, float(q[k, model.coordinate_index(c)]))
        ref = []
        for j in range(len(theirs)):
            tau = []
            for actuation in (0.0, 1.0):
                for i, a in enumerate(theirs):
                    a.setOverrideActuation(s, actuation if i == j else 0.0)
                om.realizeDynamics(s)
                tau.append(np.array(solver.solve(s, osim.Vector(len(names), 0.0)).to_numpy()))
            ref.append(tau[0] - tau[1])       # what the unit actuation supplies
        np.testing.assert_allclose(mine[k], np.array(ref), atol=1e-12)      # measured 1e-15
