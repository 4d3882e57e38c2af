"""Thesis Sec. 5.3's foot-mass study: Model.with_segment_mass, predictive_gait(foot_mass=...), the
example, and ``pinmsk optimize --report`` (the gait validation report of the solved stride).

Casadi group (conftest: this module uses pinmsk.solvers.ocp); the mass-scaling tests need neither
casadi nor opensim.
"""
from __future__ import annotations

import json
import sys

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
import pinmsk.pipeline
from pinmsk.errors import ModelError
from pinmsk.fitting import FitStatistics, Result
from pinmsk.presentation.cli import main

from conftest import REPO, require_casadi, run_example

G2D = pinmsk.load_model("gait2d")
PREDICTIVE = REPO / "data" / "tasks" / "gait2d_predictive.toml"
FINGER = REPO / "data" / "tasks" / "finger_tapping_6hz.toml"


# -- Model.with_segment_mass ------------------------------------------------------------------

def _com_jacobian(pm, q, joint):
    """(3, nv) world Jacobian of the centre of mass of ``joint``'s inertia (a point of its body)."""
    d = pm.createData()
    pin.computeJointJacobians(pm, d, q)
    pin.forwardKinematics(pm, d, q)
    J = pin.getJointJacobian(pm, d, joint, pin.LOCAL_WORLD_ALIGNED)
    r = d.oMi[joint].rotation @ pm.inertias[joint].lever          # joint origin -> COM, world axes
    return J[:3] - pin.skew(r) @ J[3:]                             # v_com = v_o + w x r


def test_with_segment_mass_scales_mass_and_inertia_and_rnea_by_the_removed_gravity():
    light = G2D.with_segment_mass("foot_r", 0.67)
    j = G2D.pin.frames[G2D.frame_id("foot_r")].parentJoint
    m_foot = G2D.pin.inertias[j].mass
    assert m_foot == pytest.approx(1.2)                               # gait2d's foot (ankle_r's body)
    assert G2D.mass - light.mass == pytest.approx(0.33 * m_foot, rel=1e-12)
    I0, I1 = G2D.pin.inertias[j], light.pin.inertias[j]
    np.testing.assert_array_equal(I1.lever, I0.lever)                 # the centre of mass stays
    np.testing.assert_allclose(I1.inertia, 0.67 * I0.inertia, rtol=1e-14)
    for k in range(1, G2D.pin.njoints):                               # no other body changes, nor the model given
        if k != j:
            assert light.pin.inertias[k] == G2D.pin.inertias[k]
    assert G2D.pin.inertias[j].mass == m_foot
    # static inverse dynamics = the gravity torques: they differ by the removed 0.33 m_foot at the
    # foot's centre of mass, -J_com^T (dm g), to rounding
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = rng.uniform(-1.0, 1.0, G2D.nq)                            # gait2d: one-dof joints, nq = nv
        z = np.zeros(G2D.nv)
        diff = pin.rnea(G2D.pin, G2D.pin.createData(), q, z, z) - pin.rnea(light.pin, light.pin.createData(), q, z, z)
        expected = -_com_jacobian(G2D.pin, q, j).T @ (0.33 * m_foot * G2D.pin.gravity.linear)
        np.testing.assert_allclose(diff, expected, atol=1e-12)
        assert abs(diff[G2D.coordinate_index("torso_y")]) == pytest.approx(0.33 * m_foot * 9.81, rel=1e-9)


def test_with_segment_mass_matches_the_segment_mass_effect():
    # the same law as the segment_mass effect (delta = scale - 1), folded into the skeleton
    from pinmsk.dynamics import skeleton_with_inertias
    from pinmsk.effects import SegmentMass
    pm = skeleton_with_inertias(G2D + SegmentMass("foot_l", delta=-0.33))
    light = G2D.with_segment_mass("foot_l", 0.67)
    q = np.random.default_rng(4).uniform(-1.0, 1.0, G2D.nq)
    v, a = np.linspace(-1, 1, G2D.nv), np.linspace(2, -2, G2D.nv)
    np.testing.assert_allclose(pin.rnea(light.pin, light.pin.createData(), q, v, a),
                               pin.rnea(pm, pm.createData(), q, v, a), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("body, scale, match", [
    ("foot_r", 0.0, "scale of body 'foot_r' must be a finite number > 0"),
    ("foot_r", float("nan"), "scale of body 'foot_r' must be a finite number > 0"),
    ("ground", 0.5, "body 'ground' of model 'gait2d' does not move or has no mass"),
    ("fot_r", 0.5, "no frame 'fot_r'; did you mean 'foot_r'"),
])
def test_with_segment_mass_refuses_bad_input_by_name(body, scale, match):
    with pytest.raises(ModelError, match=match):
        G2D.with_segment_mass(body, scale)


# -- predictive_gait(foot_mass=...) and the example ------------------------------------------

def test_predictive_gait_foot_mass_scales_both_feet_of_the_problem():
    require_casadi()
    from pinmsk.solvers.ocp.gait import predictive_gait
    ref = predictive_gait(coarse_intervals=None, intervals=6)
    light = predictive_gait(foot_mass=0.67, coarse_intervals=None, intervals=6)
    assert ref.model.mass - light.model.mass == pytest.approx(0.33 * 2 * 1.2, rel=1e-12)
    for side in "rl":
        j = light.model.pin.frames[light.model.frame_id(f"foot_{side}")].parentJoint
        assert light.model.pin.inertias[j].mass == pytest.approx(0.67 * 1.2)
    assert [c.label for c in light.model.components] == [c.label for c in ref.model.components]


def test_foot_mass_example_code_on_a_tiny_problem(tmp_path):
    # the example's own functions (solve, numbers, table, figure) on one 4-interval, 2-iteration
    # problem at 67 %, compared with itself: the wiring, not a gait (the slow test below solves the
    # real pair; test_predictive_gait_foot_mass_scales_both_feet_of_the_problem checks the masses)
    require_casadi()
    sys.path.insert(0, str(REPO / "examples"))
    try:
        import gait_foot_mass as ex
    finally:
        sys.path.remove(str(REPO / "examples"))
    run = ex.solve(0.67, intervals=4, coarse_intervals=None, solver={"max_iter": 2})
    assert run["mass"] == pytest.approx(G2D.mass - 0.33 * 2 * 1.2, rel=1e-12)
    runs = [dict(run, scale=1.0), run]
    rows = [ex.numbers(r) for r in runs]
    assert set(rows[0]["mean_activation"]) == {m[:-2] for m in G2D.muscle_names}
    assert rows[1]["metabolic_energy_per_distance_j_per_m"] == pytest.approx(
        rows[1]["cost_of_transport_j_per_kg_m"] * rows[1]["model_mass_kg"])
    text = ex.table(rows)
    assert "100 % foot mass" in text and "67 % foot mass" in text and "mean activation soleus" in text
    assert f" {rows[1]['objective']:.4g} |" in text and "+0.0 %" in text
    assert ex.figure(runs, tmp_path / "f.png").stat().st_size > 10_000


@pytest.mark.slow
def test_foot_mass_67_percent_lowers_the_objective(tmp_path):
    """The default predictive gait and the 67 % one warm-started from its optimum (measured: 160 s +
    77 s, objective -2.4 %; docs/reference/validation.md, "2D gait"); default-suite cover of the same code:
    test_foot_mass_example_code_on_a_tiny_problem and test_predictive_gait_foot_mass_scales_both_feet_of_the_problem."""
    require_casadi()
    out = run_example("gait_foot_mass.py", "--out", tmp_path)
    rows = json.loads((tmp_path / "foot_mass.json").read_text())
    assert [r["foot_mass_scale"] for r in rows] == [1.0, 0.67]
    assert all(r["converged"] for r in rows), out
    assert rows[1]["objective"] < rows[0]["objective"]
    assert "objective change" in out and (tmp_path / "fig5_10_foot_mass.png").exists()


# -- pinmsk optimize --report -----------------------------------------------------------------

def _stride_result():
    """A synthetic gait2d stride (tests/test_gait_validation.py's) as the Result optimize_task
    returns for a [gait] task: the summary numbers in its info."""
    from test_gait_validation import _synthetic_stride
    tr = _synthetic_stride(bw=700.0)
    return Result.from_trial(tr, stats=FitStatistics(converged=True, iterations=7, objective=2.5),
                             info={"speed": 1.3, "body_weight": 700.0, "cost_of_transport": 2.345,
                                   "stride_length": 1.43,
                                   # what the solve's OUT.json holds, for the summary line
                                   "summary": {"converged": True, "status": "Solve_Succeeded", "objective": 2.5,
                                               "iterations": 7, "seconds": 1.0, "speed": 1.3,
                                               "stride_length": 1.43, "cost_of_transport": 2.345}})


def _fake_optimize(calls):
    def optimize_task(task, out, progress=None, *, precision=None, **_):
        calls.append(task)
        res = _stride_result()
        if out is not None:
            from pinmsk.io.tables import write_trial
            write_trial(res, out)
        return res
    return optimize_task


def test_optimize_report_validates_the_solved_stride(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(pinmsk.pipeline, "optimize_task", _fake_optimize(calls))
    html = tmp_path / "gait.html"
    assert main(["optimize", str(PREDICTIVE), "-o", str(tmp_path / "g.sto"), "--report", str(html)]) == 0
    assert calls == [str(PREDICTIVE)]
    text = html.read_text()
    assert "pinmsk optimize" in text and "data:image/png;base64" in text
    assert "Vertical GRF double hump" in text and "2.345" in text          # the stride's own CoT, its band
    assert f"wrote {html}" in capsys.readouterr().out


def test_optimize_report_refuses_a_task_without_gait(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(pinmsk.pipeline, "optimize_task", _fake_optimize(calls))
    html = tmp_path / "r.html"
    assert main(["optimize", str(FINGER), "-o", str(tmp_path / "f.sto"), "--report", str(html)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pinmsk: error: --report:") and "no [gait] table" in err[0]
    assert calls == [] and list(tmp_path.iterdir()) == []


def test_optimize_report_without_matplotlib_is_refused_before_the_solve(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(pinmsk.pipeline, "optimize_task", _fake_optimize(calls))
    monkeypatch.setitem(sys.modules, "matplotlib", None)                  # import matplotlib -> ImportError
    assert main(["optimize", str(PREDICTIVE), "-o", str(tmp_path / "g.sto"), "--report",
                 str(tmp_path / "g.html")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--report needs matplotlib" in err[0] and "nothing solved or written" in err[0]
    assert calls == [] and list(tmp_path.iterdir()) == []
