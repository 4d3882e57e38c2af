"""OpenSim models imported exactly (the default, ``nonlinear="exact"``) everywhere downstream, their sidecar
round trip (coordinate map and muscles), the import cache and the "did you mean" of a coordinates file.

The inline leg (tests/test_osim_import.py: a spline knee, a coupled patella whose angle drives only
dependent joints, a Thelen muscle) needs nothing; the shared models (gait10dof18musc ``subject01``, arm26)
skip cleanly without ``../shared/data``.  No test here runs OpenSim: the exact import's kinematics and ID are
checked against OpenSim in test_osim_import.py / test_osim_id.py, and these tests compare with them.
"""
from __future__ import annotations

import os
import re
import warnings

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
import test_osim_import as t
from pinmsk.dynamics import inverse_dynamics, inverse_dynamics_result
from pinmsk.errors import ModelError, TrialError
from pinmsk.io.osim import read_osim
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.kinematics import coordinate_map, source_coordinates
from pinmsk.model import clear_import_cache, import_osim
from pinmsk.opensim.importer import write_import
from pinmsk.trial import Trial

GAIT = "opensim-models/Gait10dof18musc"


@pytest.fixture(scope="module")
def leg_path(tmp_path_factory):
    p = tmp_path_factory.mktemp("exact") / "leg.osim"
    p.write_text(t.leg())
    return p


def _load(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)       # the import report's one-line summary
        return pinmsk.load_model(path, **kw)


def _walk(model, n=60, seed=0):
    """A smooth trial in OpenSim's coordinates within their ranges (locked ones at their defaults)."""
    cmap = coordinate_map(model)
    doc = {c.name: c for c in read_osim(model.meta["osim"]).coordinates}
    rng = np.random.default_rng(seed)
    time = np.linspace(0.0, 1.0, n)
    chans = {}
    for c in cmap.osim_coordinates:
        lo, hi = sorted(doc[c].range)
        mid, amp = 0.5 * (lo + hi), 0.3 * (hi - lo)
        chans[c] = (np.full(n, doc[c].default_value) if doc[c].locked
                    else mid + amp * np.sin(2 * np.pi * (time + rng.uniform())))
    return Trial(time, chans)


def _frame_positions(model, q):
    """``{body or marker frame: (N, 3) positions}`` at ``q``."""
    pm = model.pin
    data = pm.createData()
    names = sorted(f.name for f in pm.frames if f.type in (pin.FrameType.BODY, pin.FrameType.OP_FRAME))
    out = np.empty((q.shape[0], len(names), 3))
    for k in range(q.shape[0]):
        pin.framesForwardKinematics(pm, data, q[k])
        out[k] = [data.oMf[pm.getFrameId(n)].translation for n in names]
    return names, out


def _round_trip(direct, out_dir, trial, **id_options):
    """The sidecar ``pinmsk import`` writes, loaded back, against the model it was written from (its
    components too: tests/test_osim_sidecar.py checks their forces)."""
    files = write_import(direct, out_dir)
    back = pinmsk.load_model(files["sidecar"])
    assert back.effects == direct.effects and back.contacts == direct.contacts
    assert back.coordinates == direct.coordinates and back.coordinate_order == direct.coordinate_order
    ca, cb = coordinate_map(direct), coordinate_map(back)
    assert (ca is None) == (cb is None)
    # the same poses: the map (its OpenSim functions, written as such) and the skeleton
    ma, mb = direct.motion(trial), back.motion(trial)
    assert np.array_equal(ma.q, mb.q) and np.array_equal(ma.v, mb.v) and np.array_equal(ma.a, mb.a)
    names_a, pa = _frame_positions(direct, ma.q)
    names_b, pb = _frame_positions(back, mb.q)
    keep = [names_a.index(n) for n in names_b]            # the import adds a frame per contact sphere
    assert set(names_b) <= set(names_a) and len(names_b) >= direct.pin.nbodies
    assert np.max(np.abs(pa[:, keep] - pb)) < 1e-12
    # the same inverse dynamics (per OpenSim coordinate)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pinmsk.errors.ResidualWarning)       # a trial without its GRF
        ida, idb = inverse_dynamics(direct, trial, **id_options), inverse_dynamics(back, trial, **id_options)
    assert ida.names == idb.names
    for n in ida.names:
        a, b = np.asarray(ida[n]), np.asarray(idb[n])
        assert np.max(np.abs(a - b)) <= 1e-9 * max(1.0, float(np.max(np.abs(a)))), n
    # the same muscles: model, parameters, path polynomials (lengths and moment arms) and their fit errors
    if direct.muscles is not None:
        A, B = direct.muscles, back.muscles
        assert (A.names, A.model_type, A.tendon) == (B.names, B.model_type, B.tendon)
        assert np.max(np.abs(A.lengths(ma.q) - B.lengths(mb.q))) < 1e-12
        assert np.max(np.abs(A.moment_arms(ma.q) - B.moment_arms(mb.q))) < 1e-12
        fa, fb = A.force_limits(ma.q, ma.v), B.force_limits(mb.q, mb.v)
        assert all(np.max(np.abs(x - y)) < 1e-9 for x, y in zip(fa, fb))
        fits = {f.muscle: f for e in direct.meta["import_report"].entries for f in e.details.get("fits", ())}
        errors = back.meta["path_fit_errors"]
        assert set(errors) == set(A.names)
        assert all(errors[m]["length"] == fits[m].length_max and errors[m]["moment_arm"] == fits[m].moment_arm_max
                   for m in A.names)
    return files, back


# -- the sidecar carries the coordinate map and the muscles --------------------------------------------

def test_sidecar_round_trip_of_the_leg_keeps_its_map_muscles_and_id(leg_path, tmp_path):
    direct = _load(leg_path)
    cmap = coordinate_map(direct)
    assert cmap.couplers and "knee_beta" not in direct.coordinates     # the patella angle drives dependent joints
    files, back = _round_trip(direct, tmp_path / "leg", _walk(direct))
    text = files["sidecar"].read_text()
    assert "[coordinate_map]" in text and 'type = "SimmSpline"' in text and "[[coordinate_map.couplers]]" in text
    assert "[muscles.paths.fitted]" in text and "max_moment_arm_error" in text
    back_map = coordinate_map(back)
    assert set(back_map.dependent) == set(cmap.dependent) and len(back_map.couplers) == 1
    # pinmsk info of the sidecar says what the .osim's says
    assert back.describe().splitlines()[0].split(":", 1)[1] == direct.describe().splitlines()[0].split(":", 1)[1]


@pytest.mark.parametrize("key", ["subject01", "arm26"])
def test_sidecar_round_trip_of_shared_models(key, tmp_path):
    d = shared_data_dir()
    rel = {"subject01": (f"{GAIT}/subject01.osim", f"{GAIT}/IK/subject01_walk_IK.mot"),
           "arm26": ("opensim-models/Arm26/arm26.osim", "opensim-models/Arm26/arm26_InverseKinematics.mot")}[key]
    if d is None or not (d / rel[0]).is_file():
        pytest.skip(f"../shared/data/{rel[0]} is absent")
    direct = _load(d / rel[0])
    trial = pinmsk.read_trial(d / rel[1])
    loads = {"external_loads": d / GAIT / "ExperimentalData" / "subject01_walk_grf.xml"} if key == "subject01" else {}
    _, back = _round_trip(direct, tmp_path / key, trial, **loads)
    assert (coordinate_map(back) is not None) == (key == "subject01")


def _written_leg(leg_path, tmp_path):
    files = write_import(_load(leg_path), tmp_path / "w")
    return files["sidecar"], files["sidecar"].read_text()


@pytest.mark.parametrize("change, message", [
    (lambda s: s.replace("[coordinate_map]\n", "[coordinate_map]\nbogus = 1\n"),
     r"unknown key 'bogus' in \[coordinate_map\]"),
    (lambda s: s.replace('type = "SimmSpline"', 'type = "GCVSpline"', 1),
     r"dependent\]\] 'knee_translation1' function: a function is a table .* got 'GCVSpline'"),
    (lambda s: s.replace("name = \"knee_translation1\"", "name = \"knee_shift\"", 1),
     r"joint\(s\) knee_translation1 are neither OpenSim coordinates"),
    (lambda s: s.replace("of = [\"knee_angle\"]", "of = [\"knee_angel\"]", 1),
     r"'knee_translation1' of must list coordinates of osim_coordinates, got \['knee_angel'\]"),
    (lambda s: s.replace("\nl_slack = ", "\nl_slak = ", 1), r"unknown key 'l_slak' .*did you mean 'l_slack'"),
    (lambda s: s.replace("coefficients = [", "coeficients = [", 1), r"unknown key 'coeficients' .*'coefficients'"),
    (lambda s: s.replace("\n[muscle_model]\n", "\n[muscle_model]\ntau_rize = 0.01\n", 1),
     r"unknown key 'tau_rize' in \[muscle_model\] \(did you mean 'tau_rise'\?\)"),
])
def test_a_bad_sidecar_is_refused_by_key(leg_path, tmp_path, change, message):
    sidecar, text = _written_leg(leg_path, tmp_path)
    sidecar.write_text(change(text))
    with pytest.raises(ModelError, match=message) as err:
        pinmsk.load_model(sidecar)
    assert str(sidecar) in str(err.value)


def test_a_parameter_the_muscle_type_lacks_is_refused_by_name(leg_path, tmp_path):
    sidecar, text = _written_leg(leg_path, tmp_path)
    kind = re.search(r'\[muscle_model\]\ntype = "(\w+)"', text).group(1)
    sidecar.write_text(text.replace("\nl_slack = ", "\nwidth = 1.0\nl_slack = ", 1))
    with pytest.raises(ModelError, match=rf"width is not a parameter of muscle type '{kind}'|'{kind}' does not take"):
        pinmsk.load_model(sidecar)


# -- the in-process import cache ---------------------------------------------------------------------

def test_load_model_of_an_osim_is_cached_until_the_file_changes(tmp_path):
    p = tmp_path / "leg.osim"
    p.write_text(t.leg())
    a = _load(p)
    assert _load(p) is a and import_osim(p)[0] is a          # the same frozen model: no refit
    assert _load(p, nonlinear="fit") is not a                 # other options: another import
    st = p.stat()
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    b = _load(p)
    assert b is not a and b.nq == a.nq                        # a changed file is imported again
    # new content of the same size and modification time (a rewrite within the clock's resolution)
    st = p.stat()
    p.write_text(t.leg().replace("<max_isometric_force>1200<", "<max_isometric_force>1300<"))
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))
    c = _load(p)
    assert c is not b and c.muscles.f_max[c.muscle_names.index("vas")] == 1300.0
    clear_import_cache(p)                                    # this file's imports (clear_import_cache(): all)
    assert _load(p) is not c


# -- downstream analyses take OpenSim's coordinates, or refuse by name -------------------------------------

def test_simulation_fso_and_motion_level_diagnosis_refuse_dependent_joints_by_name(leg_path):
    from pinmsk.diagnose.compare import compare
    from pinmsk.dynamics import simulate
    from pinmsk.solvers.fso import ForwardStaticOptimization
    model = _load(leg_path)
    trial = _walk(model)
    deps = r"knee_translation1, knee_translation2, patellofemoral_rotation1, patellofemoral_translation1 \.\.\."
    with pytest.raises(ModelError, match=rf"simulate \(forward dynamics\) .*'leg' .*\({deps}\) are dependent "
                                         r"joints.*nonlinear='fit'"):
        simulate(model, t=np.linspace(0, 0.1, 11), q0=np.zeros(model.nq), v0=np.zeros(model.nv))
    with pytest.raises(ModelError, match=r"forward static optimization \(FSO\) .*dependent joints"):
        ForwardStaticOptimization().fit(model, trial)
    # the motion level integrates the joints forward: refused by name (the torque level runs,
    # tests/test_diagnose_osim.py)
    moments = trial.with_channels({f"{c}_moment": np.zeros(trial.n_frames) for c in model.coordinates
                                   if c in trial})
    with pytest.raises(ModelError, match=r"motion-level comparison .*dependent"):
        compare(model, moments, mode="motion")


def test_the_cli_refusal_is_one_line_and_fit_mode_runs(leg_path, tmp_path, capsys):
    from pinmsk.presentation.cli import main
    out = tmp_path / "sim.sto"
    assert main(["simulate", str(leg_path), "--duration", "0.01", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("pinmsk: error: simulate") and "--nonlinear fit" in err[-1] and not out.exists()
    assert main(["simulate", str(leg_path), "--duration", "0.01", "-o", str(out), "--nonlinear", "fit"]) == 0


def test_static_optimization_balances_opensims_coordinates(leg_path):
    # SO balances J^T tau at OpenSim's coordinates (the ID, matching OpenSim's: test_osim_id.py); the
    # dependent joints get neither muscles nor reserves; coordinates driving only dependent joints are named
    from pinmsk.solvers.static import StaticOptimization
    model = _load(leg_path)
    trial = _walk(model)
    # the patella's coupled angle follows the knee angle (a CoordinateCouplerConstraint): not balanced
    # on its own, as OpenSim's static optimization balances the unconstrained coordinates only
    so = StaticOptimization(reserves=True).fit(model, trial, cutoff=0)
    assert "knee_beta" not in so.plan_.dofs + so.plan_.unspanned and "knee_angle" in so.plan_.dofs
    assert not set(coordinate_map(model).dependent) & set(so.plan_.dofs + so.plan_.unspanned)
    with pytest.raises(TrialError, match=r"no coordinate 'knee_translation1' to balance"):
        StaticOptimization(reserves=True, dofs=["knee_angle", "knee_translation1"]).fit(model, trial, cutoff=0)


def test_static_optimization_of_subject01_in_opensims_coordinates():
    d = shared_data_dir()
    if d is None or not (d / GAIT / "subject01.osim").is_file():
        pytest.skip(f"../shared/data/{GAIT} is absent")
    from pinmsk.solvers.static import StaticOptimization
    model = _load(d / GAIT / "subject01.osim")
    trial = pinmsk.read_trial(d / GAIT / "IK" / "subject01_walk_IK.mot")
    loads = d / GAIT / "ExperimentalData" / "subject01_walk_grf.xml"
    so = StaticOptimization(reserves=True).fit(model, trial, external_loads=loads)
    plan = so.plan_
    deps = set(coordinate_map(model).dependent)
    assert not deps & (set(plan.dofs) | set(plan.unspanned))
    assert set(plan.dofs) == {f"{j}_{s}" for j in ("hip_flexion", "knee_angle", "ankle_angle") for s in "rl"}
    # what it balances is the inverse dynamics per OpenSim coordinate (the pinmsk id output)
    ident = inverse_dynamics(model, trial, external_loads=loads)
    for j, c in enumerate(plan.dofs):
        assert np.allclose(plan.tau[:, j], ident[f"{c}_moment"], rtol=1e-9, atol=1e-9), c
    res = so.result_
    assert not any(n.startswith("knee_r_translation") for n in res.names)
    R = model.muscles.moment_arms(so.inputs_.motion.q)
    F = np.column_stack([res[f"{m}_force"] for m in model.muscle_names])
    idx = [model.coordinate_index(c) for c in plan.dofs]
    assert np.max(np.abs(np.einsum("nmj,nm->nj", R[:, :, idx], F) - plan.tau)) < 1e-6


def test_inverse_kinematics_solves_opensims_coordinates():
    # markers placed by OpenSim's kinematics (from the XML) at the IK motion's poses: IK recovers the
    # coordinates, the knee translations following by the map
    d = shared_data_dir()
    if d is None or not (d / GAIT / "subject01.osim").is_file():
        pytest.skip(f"../shared/data/{GAIT} is absent")
    from pinmsk.ik import InverseKinematics
    from pinmsk.markers import MarkerSet, ModelMarker
    from pinmsk.opensim.skeleton import OsimKinematics
    model = _load(d / GAIT / "subject01.osim")
    cmap = coordinate_map(model)
    ik_file = pinmsk.read_trial(d / GAIT / "IK" / "subject01_walk_IK.mot")
    frames = np.arange(0, ik_file.n_frames, 15)
    q_os = np.column_stack([np.asarray(ik_file[c])[frames] for c in cmap.osim_coordinates])
    kin = OsimKinematics(read_osim(model.meta["osim"]))
    xyz = kin.marker_positions(q_os)
    names = [m["name"] for m in model.meta["markers"]]
    chans = {f"{m}_{a}": xyz[m][:, i] for m in names for i, a in enumerate("xyz")}
    markers = Trial(np.asarray(ik_file.time)[frames], chans, meta={"markers": tuple(names)})
    mset = MarkerSet(tuple(ModelMarker(m["name"], m["body"], tuple(m["position"])) for m in model.meta["markers"]),
                     {})
    ik = InverseKinematics(markers=mset).fit(model, markers)
    assert set(ik.free_coordinates_) == set(cmap.osim_coordinates)
    assert ik.result_.names == cmap.osim_coordinates and ik.converged_.all()
    got = np.column_stack([ik.result_[c] for c in cmap.osim_coordinates])
    assert np.max(np.abs(got - q_os)) < 1e-7 and max(ik.marker_rms_.values()) < 1e-8
    assert np.allclose(ik.q_, cmap.expand(q_os)[0], atol=1e-7)


def test_the_viewer_plays_opensims_coordinates(leg_path):
    from pinmsk.presentation.viewer import _coordinates_of
    model = _load(leg_path)
    trial = _walk(model)
    q = _coordinates_of(trial, model, "trial")
    assert np.array_equal(q, coordinate_map(model).expand({c: trial[c] for c in trial.names})[0])
    with pytest.raises(TrialError, match=r"knee_angle"):
        _coordinates_of(trial.drop(["knee_angle"]), model, "trial")


def test_id_reports_opensims_coordinates(leg_path):
    model = _load(leg_path)
    trial = _walk(model)
    out = inverse_dynamics(model, trial, cutoff=0)
    cmap = coordinate_map(model)
    assert [n for n in out.names if n.endswith(("_moment", "_force"))] == [f"{c}_moment" for c in cmap.osim_coordinates]
    mo = model.motion(trial, cutoff=0)
    names, _, tau = source_coordinates(model, mo, pinmsk.dynamics.inverse_dynamics_array(model, mo, actuated=False))
    assert np.allclose(np.column_stack([out[f"{c}_moment"] for c in names]), tau, rtol=1e-12, atol=1e-9)


# -- a coordinate the model lacks: "did you mean" --------------------------------------------------------

def _coordinates_file(path, columns: dict, n=20):
    time = np.linspace(0.0, 0.2, n)
    with open(path, "w") as fh:
        fh.write(f"Coordinates\nversion=1\nnRows={n}\nnColumns={len(columns) + 1}\ninDegrees=no\nendheader\n")
        fh.write("\t".join(["time", *columns]) + "\n")
        for k in range(n):
            fh.write("\t".join(repr(float(x)) for x in [time[k], *(np.broadcast_to(v, (n,))[k] for v in columns.values())])
                     + "\n")
    return path


def test_a_coordinate_the_osim_model_lacks_gets_a_did_you_mean(leg_path, tmp_path, capsys):
    model = _load(leg_path)
    cols = {c: 0.0 for c in coordinate_map(model).osim_coordinates}
    cols["pelvis_ty"] = 0.95
    cols["knee_angel_r"] = -0.3                       # a coordinate the model lacks, close to knee_angle
    trial = pinmsk.read_trial(_coordinates_file(tmp_path / "ik.mot", cols))
    with pytest.raises(TrialError, match=r"column\(s\) 'knee_angel_r' \(did you mean 'knee_angle'.*\?\) of the "
                                         r"coordinates file are not coordinates of model 'leg'"):
        model.motion(trial)
    from pinmsk.presentation.cli import main
    assert main(["id", str(leg_path), str(tmp_path / "ik.mot"), "-o", str(tmp_path / "id.sto")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("pinmsk: error:") and "did you mean 'knee_angle'" in err[-1]
    # speeds of the model's coordinates are no unknown coordinates
    del cols["knee_angel_r"]
    cols["knee_angle_speed"] = 0.0
    model.motion(pinmsk.read_trial(_coordinates_file(tmp_path / "ok.mot", cols)))


def test_coordinates_a_file_leaves_out_are_filled_as_the_model_says_or_refused(leg_path, tmp_path, capsys):
    """A states file often leaves coordinates out (Moco's: locked ones, the patella's): a locked one is held at
    its value and a coupled one set by its coupler, each noted; a free one is refused by name with the flag
    that holds it at its default value as OpenSim's ID tool does; every fill gives the moments of the trial
    filled by hand.  The trial's own values of a coupled coordinate are replaced by the coupler's (noted),
    not checked (Moco writes patella angles that are not the coupling's)."""
    from pinmsk.kinematics import MISSING_COORDINATE_MODES
    from pinmsk.presentation.cli import build_parser, main
    model = _load(leg_path)
    cmap = coordinate_map(model)
    full = _walk(model)
    beta = cmap.couplers[0][2]
    full = full.with_channels(knee_beta=cmap.couplers[0][3] * beta.value(np.asarray(full["knee_angle"])))
    want = inverse_dynamics(model, full, cutoff=0)
    # locked lumbar_extension and coupled knee_beta left out; knee_beta's values in degrees-like garbage
    partial = Trial(full.time, {c: np.asarray(full[c]) for c in full.names if c not in ("lumbar_extension", "knee_beta")})
    res = inverse_dynamics_result(model, partial, cutoff=0)
    assert any("lumbar_extension: not in the trial; locked at -0.05" in n for n in res.inputs.notes)
    assert any("knee_beta: not in the trial; set from knee_angle by its CoordinateCouplerConstraint" in n
               for n in res.inputs.notes)
    np.testing.assert_allclose(res.trial.get(want.names), want.get(want.names), rtol=0, atol=1e-9)
    odd = partial.with_channels(knee_beta=np.full(partial.n_frames, 72.0))     # 72 "rad": not checked, replaced
    res = inverse_dynamics_result(model, odd, cutoff=0)
    assert any(n.startswith("knee_beta: the trial's values replaced by its CoordinateCouplerConstraint's")
               for n in res.inputs.notes)
    np.testing.assert_allclose(res.trial.get(want.names), want.get(want.names), rtol=0, atol=1e-9)
    # a free coordinate left out: refused by name, or held at its default value on request
    no_ankle = Trial(full.time, {c: np.asarray(full[c]) for c in full.names if c != "ankle_angle"})
    with pytest.raises(TrialError, match=r"'ankle_angle'.*--missing-coordinates default"):
        inverse_dynamics(model, no_ankle, cutoff=0)
    held = full.with_channels(ankle_angle=np.full(full.n_frames, cmap.defaults["ankle_angle"]))
    res = inverse_dynamics_result(model, no_ankle, cutoff=0, missing_coordinates="default")
    assert any("ankle_angle: not in the trial; held at its default value 0" in n for n in res.inputs.notes)
    np.testing.assert_allclose(res.trial.get(want.names), inverse_dynamics(model, held, cutoff=0).get(want.names),
                               rtol=0, atol=1e-9)
    with pytest.raises(TrialError, match="missing_coordinates must be one of refuse, default"):
        inverse_dynamics(model, no_ankle, cutoff=0, missing_coordinates="zero")
    # the command line: one line naming it and the flag, exit 2, no file; the flag runs it
    cols = {c: np.asarray(no_ankle[c])[:20] for c in no_ankle.names}
    path = _coordinates_file(tmp_path / "ik.mot", cols)
    out = tmp_path / "id.sto"
    assert main(["id", str(leg_path), str(path), "-o", str(out), "--cutoff", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("pinmsk: error:") and "'ankle_angle'" in err[-1] and "--missing-coordinates default" in err[-1]
    assert not out.exists()
    assert main(["id", str(leg_path), str(path), "-o", str(out), "--cutoff", "0", "--missing-coordinates", "default"]) == 0
    assert "ankle_angle: not in the trial; held at its default value" in capsys.readouterr().out and out.is_file()
    # the CLI spells the modes out (importing kinematics would load Pinocchio for --help): the same ones
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["id"]
    assert tuple(next(a for a in sub._actions if a.dest == "missing_coordinates").choices) == MISSING_COORDINATE_MODES


def test_a_coordinate_a_builtin_model_lacks_gets_a_did_you_mean(tmp_path):
    forearm = pinmsk.load_model("forearm")
    path = _coordinates_file(tmp_path / "ik.mot", {"elbow_flexion": np.linspace(0, 1, 20), "elbow_flexon": 0.0,
                                                   "r_shoulder_elev": 0.0})
    with pytest.raises(TrialError, match=r"'elbow_flexon' \(did you mean 'elbow_flexion'\?\), 'r_shoulder_elev' "
                                         r"of the coordinates file are not coordinates of model 'forearm' "
                                         r"\(elbow_flexion\)"):
        forearm.motion(pinmsk.read_trial(path))
    # the model's coordinate missing: the file's closest column is suggested (Trial.require)
    path = _coordinates_file(tmp_path / "typo.mot", {"elbow_flexon": np.linspace(0, 1, 20)})
    with pytest.raises(TrialError, match=r"'elbow_flexon' \(did you mean 'elbow_flexion'\?\)"):
        forearm.motion(pinmsk.read_trial(path))


# -- muscles across a coupled coordinate that drives only dependent joints --------------------------------

def test_a_muscle_on_the_coupled_patella_is_fitted_along_its_coupler(tmp_path):
    # a muscle from the femur to the patella crosses only knee_beta, which (exact mode) drives only dependent
    # joints and follows the knee by its coupler: the path is fitted in knee_angle with the coupling, as OpenSim
    # enforces it, and its moment arm about the knee is -dl/dknee along the coupled motion
    from pinmsk.opensim.muscle_import import geometric_paths
    text = t.leg()
    start = text.index('<Thelen2003Muscle name="vas">')
    end = text.index("</Thelen2003Muscle>", start) + len("</Thelen2003Muscle>")
    vas = text[start:end]
    a, b = vas.index("<PathPointSet>"), vas.index("</PathWrapSet>") + len("</PathWrapSet>")
    points = ('<PathPointSet><objects>'
              '<PathPoint name="rf-P1"><socket_parent_frame>/bodyset/femur</socket_parent_frame>'
              '<location>0.03 -0.2 0.03</location></PathPoint>'
              '<PathPoint name="rf-P2"><socket_parent_frame>/bodyset/patella</socket_parent_frame>'
              '<location>0.01 0.02 0.0</location></PathPoint></objects></PathPointSet>')
    rf = vas[:a].replace('name="vas"', 'name="rf"') + points + vas[b:]
    p = tmp_path / "leg_rf.osim"
    p.write_text(text[:end] + rf + text[end:])
    model, report = import_osim(p)
    assert "knee_beta" not in model.coordinates and "rf" in model.muscle_names
    (note,) = [e for e in report.entries if "fitted along the coupling" in e.became]
    assert "knee_beta" in note.became and "knee_angle" in note.became
    i, j = model.muscle_names.index("rf"), model.coordinate_index("knee_angle")
    assert model.muscles.path.terms[i]["coordinates"] == ("knee_angle",)
    # the geometric path along the coupled motion (knee_beta = knee_angle: the leg's coupler)
    gp = geometric_paths(report)
    knee = np.linspace(-1.8, 0.1, 25)
    h = 1e-6

    def length(k):
        q = np.zeros((k.size, len(gp.coordinates)))
        q[:, gp.coordinates.index("pelvis_ty")] = 0.95
        q[:, gp.coordinates.index("knee_angle")] = q[:, gp.coordinates.index("knee_beta")] = k
        return gp.lengths_and_moment_arms(q, coordinates=())[0][:, gp.muscles.index("rf")]

    arm = -(length(knee + h) - length(knee - h)) / (2 * h)
    q = np.zeros((knee.size, model.nq))
    q[:, model.coordinate_index("pelvis_ty")] = 0.95
    q[:, j] = knee
    fit = model.muscles.moment_arms(q)[:, i, j]
    err = next(f.moment_arm_max for e in report.entries for f in e.details.get("fits", ()) if f.muscle == "rf")
    assert np.max(np.abs(arm)) > 5e-3 and np.max(np.abs(fit - arm)) <= err + 1e-6
