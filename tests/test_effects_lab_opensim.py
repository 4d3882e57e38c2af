"""Lab candidates found in data OpenSim generated: arm26 with a one-sided CoordinateLimitForce, and
arm26 holding a 1.5 kg mass welded at the wrist (at the ``r_radius_styloid`` marker).

The motion is pinmsk's synthetic multi-sine of arm26's two coordinates (exact derivatives); the
"measured" moments are OpenSim's ``InverseDynamicsSolver`` on OpenSim's own arm26 (muscles off)
with the hidden effect added through OpenSim's API, plus pinmsk's realistic noise.  pinmsk
diagnoses its import of the plain ``arm26.osim``.  Skipped without the ``opensim`` peer or the
shared models."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import pinmsk
from pinmsk.components import Motion
from pinmsk.diagnose import diagnose
from pinmsk.diagnose.synth import NOISE, _add_noise, _multisine
from pinmsk.dynamics import inverse_dynamics_array
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.trial import Trial

from conftest import require_opensim

WRIST = (-0.0011, -0.23559, 0.0943)       # arm26's r_radius_styloid marker on r_ulna_radius_hand


def _arm26_path():
    root = shared_data_dir()
    p = None if root is None else root / "opensim-models" / "Arm26" / "arm26.osim"
    if p is None or not p.is_file():
        pytest.skip("../shared/data/opensim-models/Arm26/arm26.osim is absent")
    return p


def _opensim_id(osim, path, q, v, a, add=None) -> np.ndarray:
    """OpenSim's inverse dynamics of arm26 (muscles off), with ``add(model)`` applied first."""
    m = osim.Model(str(path))
    for mus in m.getMuscles():
        mus.set_appliesForce(False)
    if add is not None:
        add(osim, m)
    s = m.initSystem()
    cs = m.getCoordinateSet()
    solver = osim.InverseDynamicsSolver(m)
    out = np.empty_like(q)
    for k in range(q.shape[0]):
        for i in range(cs.getSize()):
            cs.get(i).setValue(s, float(q[k, i]), False)
            cs.get(i).setSpeedValue(s, float(v[k, i]))
        m.realizeVelocity(s)
        udot = osim.Vector(q.shape[1], 0.0)
        for i in range(q.shape[1]):
            udot.set(i, float(a[k, i]))
        tau = solver.solve(s, udot)
        out[k] = [tau.get(i) for i in range(q.shape[1])]
    return out


def _upper_stop(osim, m):
    # upper limit 100 deg at 1 N m/deg, transition 1 deg, OpenSim's default damping; the lower side
    # far outside the motion (OpenSim's usual one-sided use)
    m.addForce(osim.CoordinateLimitForce("r_elbow_flex", 100.0, 1.0, -90.0, 1.0, 0.001, 1.0))


def _wrist_mass(osim, m):
    hand = m.getBodySet().get("r_ulna_radius_hand")
    held = osim.Body("held", 1.5, osim.Vec3(0), osim.Inertia(1e-6, 1e-6, 1e-6))
    weld = osim.WeldJoint("held_weld", hand, osim.Vec3(*WRIST), osim.Vec3(0), held, osim.Vec3(0), osim.Vec3(0))
    m.addBody(held)
    m.addJoint(weld)


@pytest.fixture(scope="module")
def arm26_case():
    osim = require_opensim()
    path = _arm26_path()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arm = pinmsk.load_model(path)
    t = np.arange(801) / 100.0
    q, v, a = _multisine(arm, t, np.random.default_rng(5), 1.0)
    # the two engines agree on the plain model (the comparison below is about the hidden effect only)
    plain = _opensim_id(osim, path, q, v, a)
    np.testing.assert_allclose(inverse_dynamics_array(arm, Motion(t, q, v, a)), plain, atol=1e-9)

    def trial(add):
        tau = _opensim_id(osim, path, q, v, a, add)
        ch = {c: q[:, i] for i, c in enumerate(arm.coordinates)}
        ch.update({f"{c}_moment": tau[:, i] for i, c in enumerate(arm.coordinates)})
        return _add_noise(Trial(t, ch), arm, dict(NOISE), np.random.default_rng(1))

    return arm, trial


def test_opensim_one_sided_limit_force_is_found(arm26_case):
    arm, trial = arm26_case
    d = diagnose(arm, trial(_upper_stop))
    assert d.best is not None and d.best.label == "end_stop_upper:r_elbow_flex", d.verdict_line()
    assert d.best.identifiable and not d.best.flags
    assert d.best.params["stiffness"] == pytest.approx(180 / np.pi, rel=0.05)     # 1 N m/deg
    assert d.best.params["limit"] == pytest.approx(np.deg2rad(100.0), abs=np.deg2rad(1.0))


def test_opensim_mass_at_the_wrist_is_found_at_the_marker(arm26_case):
    arm, trial = arm26_case
    d = diagnose(arm, trial(_wrist_mass))
    assert d.best is not None and d.best.label == "payload:r_radius_styloid", d.verdict_line()
    assert d.best.params["mass"] == pytest.approx(1.5, rel=0.02)
    # the forearm's own mass taking the load instead would be far outside de Leva's range: flagged
    sm = d.score("segment_mass", "r_ulna_radius_hand")
    assert sm is not None and not sm.significant and sm.identifiability.get("plausible") is False
