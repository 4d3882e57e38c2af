"""OpenSim's passive forces imported (pinmsk/opensim/forces.py, pinmsk/opensim/contacts.py), against
OpenSim's own numbers.

The zoo models (``../shared/data/osim-zoo``) Walker, Jumper, BouncingBlock, ToyLanding and SoccerKick
hold CoordinateLimitForces, HuntCrossleyForces (Walker's against a half space on a body welded to the
ground, ToyLanding's against a platform that moves, SoccerKick's between the foot's or the goalie's
spheres and a free ball), BushingForces and a PointToPointSpring.  At states that press the limits and sink the
spheres (tests/osim_forces/cases.py), each force's generalized forces -- OpenSim's
InverseDynamicsSolver with only that force applied minus with none, which is minus the force's
generalized force -- are stored in tests/osim_forces/references.npz by
tests/osim_forces/make_references.py, with Walker's whole inverse dynamics.  The tests compare
pinmsk's components with those numbers (no opensim needed); one peer test recomputes a few of them
with OpenSim to check that the stored numbers are OpenSim's.  The import report and the warning
name what is still left out.
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from pinmsk.components import Motion
from pinmsk.dynamics import component_forces, inverse_dynamics_array
from pinmsk.effects import EndStopLower, EndStopUpper, LinearBushing, PointToPointSpring
from pinmsk.model import import_osim
from pinmsk.opensim.contacts import contact_hook
from pinmsk.opensim.forces import force_hook

from conftest import import_opensim, shared_folder

sys.path.insert(0, str(Path(__file__).resolve().parent / "osim_forces"))
import cases  # noqa: E402

REF = np.load(cases.REFERENCES)


@pytest.fixture(scope="module")
def zoo(tmp_path_factory):
    d = shared_folder("osim-zoo", "zoo_models.tar.xz")
    return cases.extract(d / "zoo_models.tar.xz", [*sorted(cases.FORCES), "Wrist"], tmp_path_factory.mktemp("zoo"))


def _stored(name):
    names = [str(n) for n in REF[f"{name}/__names__"]]
    return names, *(REF[f"{name}/__{k}__"] for k in ("t", "q", "v", "a"))


def _motion(model, name):
    """The stored states as a pinmsk Motion (Pinocchio's joints) and OpenSim's coordinate names."""
    names, t, Q, V, A = _stored(name)
    cmap = model.meta["coordinate_map"]
    if cmap is not None and not cmap.identity:
        cols = [names.index(c) for c in cmap.osim_coordinates]
        q, v, a = cmap.expand(Q[:, cols], V[:, cols], A[:, cols], couplers=False)   # the states OpenSim got
        return Motion(t, q, v, a), names, Q[:, cols], list(cmap.osim_coordinates)
    cols = [names.index(c) for c in model.coordinates]
    return Motion(t, Q[:, cols], V[:, cols], A[:, cols]), names, Q[:, cols], list(model.coordinates)


def _to_osim(model, tau, names, Qm, order):
    """Pinocchio generalized forces (N, nv) -> OpenSim's coordinates (N, n) in ``names`` order."""
    cmap = model.meta["coordinate_map"]
    mapped = cmap.generalized_forces(Qm, tau, couplers=False) if cmap is not None and not cmap.identity else tau
    out = np.zeros((tau.shape[0], len(names)))
    for i, c in enumerate(order):
        out[:, names.index(c)] = mapped[:, i]
    return out


def _euler_to_speeds(name, names, Q, tau):
    """OpenSim's generalized forces of a FreeJoint's rotations: its speeds are the angular velocity in
    the parent frame, ``w = W(q) qdot`` with ``W = [e_x, Rx e_y, Rx Ry e_z]`` of the body-fixed X-Y-Z
    angles, so ``Q_u = W^-T Q_qdot`` (pinmsk's are the angles' forces; the rest is the same)."""
    rot = list(np.flatnonzero(REF[f"{name}/__free__"]))
    if not rot:
        return tau
    out = tau.copy()
    for k in range(tau.shape[0]):
        a, b = Q[k, rot[0]], Q[k, rot[1]]
        W = np.array([[1.0, 0.0, np.sin(b)], [0.0, np.cos(a), -np.sin(a) * np.cos(b)],
                      [0.0, np.sin(a), np.cos(a) * np.cos(b)]])
        out[k, rot] = np.linalg.solve(W.T, tau[k, rot])
    return out


def _labels(report, force: str) -> list[str]:
    """The component labels the import made of OpenSim force ``force`` (its exact report entries)."""
    return [e.became.split(": ", 1)[0] for e in report.find(f'name="{force}">') if e.status == "exact"]


@pytest.fixture(scope="module")
def imported(zoo):
    """``{model: (Model, ImportReport)}``: skeleton, passive forces and contacts (no muscles)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {n: import_osim(p, hooks=(force_hook, contact_hook)) for n, p in zoo.items() if n in cases.FORCES}


@pytest.mark.parametrize("name", sorted(cases.FORCES))
def test_each_force_matches_opensim(imported, name):
    """Every listed force of the model, force by force: pinmsk's generalized force is minus OpenSim's
    (ID with the force on minus off), to 1e-9 of its peak."""
    model, report = imported[name]
    mo, names, Qm, order = _motion(model, name)
    forces = component_forces(model, mo)
    stored = [k.split("/", 1)[1] for k in REF.files if k.startswith(f"{name}/") and "__" not in k]
    assert stored
    lines = []
    for f in stored:
        labels = _labels(report, f)
        ref = REF[f"{name}/{f}"]
        peak = np.abs(ref).max()
        if not labels:               # a side left out or a locked leg: OpenSim's force is zero too
            assert peak == 0.0, f"{name}/{f}: not imported, but OpenSim's force reaches {peak:g}"
            continue
        mine = -_euler_to_speeds(name, names, _stored(name)[2],
                                 _to_osim(model, sum(forces[lbl] for lbl in labels), names, Qm, order))
        err = np.abs(mine - ref).max()
        lines.append(f"{f} ({', '.join(labels)}): peak {peak:.4g}, max error {err:.2e}")
        assert err <= 1e-9 * max(peak, 1.0), lines[-1]
    print(f"\n{name}:\n  " + "\n  ".join(lines))


def test_the_forces_press_at_the_stored_states():
    """The states exercise the laws: the limits press, the bushings and the spring are loaded."""
    for key, floor in (("Walker/LKneeLimitTorque", 1.0), ("Walker/RFootForce", 1e3), ("ToyLanding/BackBushing", 10.0),
                       ("ToyLanding/ankle_r_bushing", 10.0), ("BouncingBlock/spring", 10.0),
                       ("BouncingBlock/hip_bushing", 1.0), ("Jumper/KneeLimit_r", 10.0)):
        assert np.abs(REF[key]).max() > floor, key


def test_walker_inverse_dynamics_matches_opensim(zoo):
    """Walker (4 CoordinateLimitForces, 6 HuntCrossley contacts against the Platform welded to the
    ground) imported with the default hooks: its inverse dynamics within 0.5 % RMS of peak of
    OpenSim's on every coordinate (they agree to rounding)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, report = import_osim(zoo["Walker"])
    assert not report.not_imported
    assert sum(c.family.startswith("end_stop") for c in model.effects) == 8
    assert len(model.contacts) == 6
    mo, names, Qm, order = _motion(model, "Walker")
    tau = _to_osim(model, inverse_dynamics_array(model, mo), names, Qm, order)
    ref = REF["Walker/__id__"]
    rms = np.sqrt(np.mean((tau - ref) ** 2, axis=0)) / np.abs(ref).max(axis=0)
    print(f"\nWalker ID vs OpenSim: worst {100 * rms.max():.2e} % RMS of peak")
    assert rms.max() < 0.005
    assert rms.max() < 1e-12


def test_imported_components(imported):
    model, report = imported["Walker"]
    up, lo = model.component("end_stop_upper:LKnee_rz"), model.component("end_stop_lower:LKnee_rz")
    assert isinstance(up, EndStopUpper) and isinstance(lo, EndStopLower)
    w = np.pi / 180
    # <upper_stiffness>0.5</upper_stiffness> N m/deg, limits 0 / -140 deg, transition 5 deg, damping 0.025
    np.testing.assert_allclose([up.values[k] for k in ("stiffness", "limit", "transition", "damping")],
                               [0.5 / w, 0.0, 5 * w, 0.025 / w], rtol=1e-15)
    np.testing.assert_allclose(lo.values["limit"], -140 * w, rtol=1e-15)
    hc = model.component("hunt_crossley_force:LFootContact")
    # the Platform is turned by -10 degrees about z: the half space's outward normal is tilted with it
    np.testing.assert_allclose(hc.plane_normal, (np.sin(0.174533), np.cos(0.174533), 0.0), atol=1e-6)
    model, report = imported["ToyLanding"]
    b = model.component("bushing:tibia_r_offset")
    assert isinstance(b, LinearBushing) and b.frame2 == "calcn_r_offset"
    assert b.values["rotational_stiffness_x"] > 0
    model, report = imported["BouncingBlock"]
    s = model.component("point_to_point_spring:block")
    assert isinstance(s, PointToPointSpring) and s.frame2 == "link2"
    assert s.values == {"stiffness": 2000.0, "rest_length": 0.8}


def test_left_out_forces_are_named(imported, zoo):
    """Every force of these models is imported (what is left in their reports is no force); what is not
    imported elsewhere (Wrist's Schutte 1993 muscles) is named in the report and in the one warning line."""
    from pinmsk.opensim.importer import warn_report
    for name, (_, report) in imported.items():
        left = [e.element for e in report.not_imported if "Force" in e.element or "Spring" in e.element]
        assert not left, left
    _, report = imported["ToyLanding"]
    kinds = {e.element.split("<")[1].split(" ")[0] for e in report.not_imported}
    assert kinds == {"ToyReflexController", "PrescribedController", "Thelen2003Muscle"}     # no muscle hook here
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, wrist = import_osim(zoo["Wrist"], hooks=(force_hook, contact_hook))
    assert len(wrist.not_imported) == 25
    with pytest.warns(UserWarning) as rec:
        warn_report(wrist)
    (w,) = [r for r in rec if "not imported" in str(r.message)]
    assert "25 element(s) not imported yet (Schutte1993Muscle_Deprecated FCR, FCU, " in str(w.message)
    assert "and 19 more" in str(w.message)


def test_elastic_foundation_between_spheres_is_no_force(imported):
    """An ElasticFoundationForce between Walker's foot spheres and its Platform: OpenSim applies no force
    at states where the same spheres' HuntCrossleyForces press (Simbody's elastic foundation acts on
    ContactMesh faces only); pinmsk makes no component and says so."""
    np.testing.assert_array_equal(REF["WalkerElasticFoundation/__q__"], REF["Walker/__q__"])
    assert np.abs(REF["Walker/LFootForce"]).max() > 1e3 and np.abs(REF["Walker/RFootForce"]).max() > 1e3
    assert np.abs(REF["WalkerElasticFoundation/foot_foundation"]).max() == 0.0
    model, report = imported["WalkerElasticFoundation"]
    (entry,) = report.find('name="foot_foundation">')
    assert entry.status == "note" and "ContactMesh" in entry.became
    assert len(model.components) == len(imported["Walker"][0].components)


def test_bushing_parameter_jacobian_is_exact(imported):
    """Q is linear in the bushing's 12 parameters: its Jacobian reproduces Q."""
    model, _ = imported["ToyLanding"]
    mo, *_ = _motion(model, "ToyLanding")
    b = model.component("bushing:pelvis_offset")
    J = b.param_jacobian(model, mo)
    np.testing.assert_allclose(J @ b.param_vector(), b.generalized_force(model, mo), rtol=1e-12, atol=1e-9)


def test_stored_numbers_are_opensims(zoo):
    """The opensim peer recomputes two stored forces (a bushing and a limit) at three frames."""
    osim, why = import_opensim()
    if osim is None:
        pytest.skip(why)
    # by its path: tests/data/zoo has a make_references.py too, and a worker may have imported that one
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "osim_forces_make_references", Path(__file__).resolve().parent / "osim_forces" / "make_references.py")
    mk = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mk)
    for name, force in (("ToyLanding", "BackBushing"), ("Walker", "LKneeLimitTorque")):
        names, t, Q, V, A = _stored(name)
        rows = slice(0, 3)
        on = mk._solve(osim, *mk._model(osim, zoo[name], (force,)), names, Q[rows], V[rows], A[rows])
        off = mk._solve(osim, *mk._model(osim, zoo[name], ()), names, Q[rows], V[rows], A[rows])
        np.testing.assert_allclose(on - off, REF[f"{name}/{force}"][rows], rtol=1e-12, atol=1e-9)


def test_sidecar_keeps_the_pair_forces(zoo, tmp_path):
    """``write_import`` writes the bushings, the spring and their frames; the model read back computes
    the same generalized forces."""
    from pinmsk import load_model
    from pinmsk.opensim.importer import write_import
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, _ = import_osim(zoo["BouncingBlock"], hooks=(force_hook, contact_hook))
        files = write_import(model, tmp_path, name="bb")
        back = load_model(files["toml"] if "toml" in files else tmp_path / "bb.toml")
    mo, *_ = _motion(model, "BouncingBlock")
    for label in ("bushing:block", "point_to_point_spring:block", "end_stop_lower:pin2_rot"):
        np.testing.assert_allclose(back.component(label).generalized_force(back, mo),
                                   model.component(label).generalized_force(model, mo), rtol=1e-12, atol=1e-9)
