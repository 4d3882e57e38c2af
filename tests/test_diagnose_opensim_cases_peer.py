"""The OpenSim-generated diagnosis cases are OpenSim's (needs the ``opensim`` peer; skips without it).

pinmsk's inverse dynamics equals OpenSim's on the case motions, the generator
(``tests/opensim_cases/make_cases.py``) reproduces the stored cases, and the walks' moments are OpenSim's
ID of the plain model.  The diagnosis itself is judged on the stored cases in
``tests/test_diagnose_opensim_cases.py``, which needs no ``opensim``.
"""
from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from conftest import REPO, require_opensim

_spec = importlib.util.spec_from_file_location("opensim_cases_follow", REPO / "tests" / "opensim_cases" / "follow.py")
follow = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(follow)


def _shared(shared_data):
    from pathlib import Path
    return Path(shared_data)


# ---------------------------------------------------------------------------
# the cases are OpenSim's: same inverse dynamics, reproducible generator
# ---------------------------------------------------------------------------

def _generator():
    spec = importlib.util.spec_from_file_location("opensim_cases_make",
                                                  REPO / "tests" / "opensim_cases" / "make_cases.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.osim = require_opensim()
    return mod


@pytest.mark.parametrize("which", ["arm26", "tug"])
def test_pinmsk_inverse_dynamics_is_opensims_on_the_case_motions(which, shared_data):
    from pinmsk import skeleton
    mc = _generator()
    rel, motion = {"arm26": (mc.ARM26, mc.ARM_MOTION), "tug": (mc.TUG, mc.TUG_MOTION)}[which]
    path = _shared(shared_data) / rel
    if not path.is_file():
        pytest.skip(f"{rel} is absent")
    t = np.arange(0.0, 5.0 + 0.005, 0.01)
    q, v, a = {}, {}, {}
    for c, terms in motion.items():
        q[c], v[c], a[c] = mc.sines(t, terms)
    ref = mc.solver_id(mc.load(path), t, q, v, a)
    model = follow.load_model(str(path))
    co = model.coordinate_order
    tau = skeleton.rnea(model, *(np.stack([x[c] for c in co], 1) for x in (q, v, a)))
    scale = max(np.max(np.abs(ref[c])) for c in co)
    assert scale > 1.0
    err = max(np.max(np.abs(tau[:, i] - ref[c])) for i, c in enumerate(co))
    assert err <= 1e-9 * scale, f"max |pinmsk - OpenSim| {err:.3g} (max |tau| {scale:.3g})"


def test_the_generator_reproduces_a_stored_case(shared_data, tmp_path):
    mc = _generator()
    if not (_shared(shared_data) / mc.ARM26).is_file():
        pytest.skip("Arm26 is absent")
    mc.arm_cases(tmp_path)
    from pinmsk.io.tables import read_trial
    for name in ("arm26_payload_styloid", "arm26_end_stop_upper"):
        new, old = read_trial(tmp_path / name / "trial.sto"), read_trial(follow.CASES / name / "trial.sto")
        assert new.names == old.names
        for n in old.names:
            assert np.allclose(new[n], old[n], rtol=1e-6, atol=1e-6), (name, n)
        assert json.loads((tmp_path / name / "truth.json").read_text()) == follow.truth(name)


def test_the_walk_cases_moments_are_opensims_id_of_the_plain_model(shared_data, tmp_path):
    # gait_plain's moment channels (noise removed by its 1 N m / 2 N scale) against pinmsk's ID on the
    # same coordinates with OpenSim's own 6 Hz filter and the GRF unfiltered, as OpenSim's ID tool runs
    from pinmsk.dynamics import inverse_dynamics_result
    from pinmsk.io.tables import read_trial
    from test_osim_id import _opensim_filtered
    mc = _generator()
    d = _shared(shared_data)
    if not (d / mc.GAIT).is_file():
        pytest.skip("Gait10dof18musc is absent")
    model = follow.load_model(str(d / mc.GAIT))
    trial = read_trial(follow.CASES / "gait_plain" / "trial.sto")
    filtered = _opensim_filtered(mc.osim, d / mc.GAIT_IK, 6.0, np.asarray(trial.time))
    out = inverse_dynamics_result(model, filtered, cutoff=0, grf_cutoff=0,
                                  external_loads=follow.CASES / "_walk" / "walk_grf.xml").trial
    rows = slice(1, -1)
    coords = [n[:-len("_moment")] for n in trial.names if n.endswith("_moment")]
    assert len(coords) == 10
    for c in coords:
        m = np.asarray(trial[c + "_moment"])[rows]
        mine = np.interp(trial.time, out.time, out[c + "_moment"])[rows]
        noise = 2.0 if c.startswith("pelvis_t") else 1.0
        assert np.sqrt(np.mean((mine - m) ** 2)) < 1.5 * noise, c
