"""examples/gait_robustness.py: the default predictive gait (pinmsk.solvers.ocp.gait) from several
generic guesses, and the spread of its optima (it must converge from at least 3 guesses)."""
from __future__ import annotations

import json
import sys

import pytest

from conftest import REPO, require_casadi, run_example


def _example():
    sys.path.insert(0, str(REPO / "examples"))
    try:
        import gait_robustness as ex
    finally:
        sys.path.remove(str(REPO / "examples"))
    return ex


def test_robustness_guesses_and_table_on_a_tiny_problem():
    # the example's own code (guess names, one solve, the table and its spread row) on a 4-interval,
    # 2-iteration problem: the wiring, not a gait (the slow test below solves the real ones)
    require_casadi()
    ex = _example()
    assert ex.guess_options("walking") == {"guess": "walking"}
    assert ex.guess_options("qr7") == {"guess": "quasi-random", "seed": 7}
    with pytest.raises(SystemExit, match="unknown guess 'random'"):
        ex.guess_options("random")
    row = ex.solve("qr1", {"intervals": 4, "coarse_intervals": None, "solver": {"max_iter": 2}})
    assert row["guess"] == "qr1" and row["converged"] is False and row["iterations"] == 2
    ok = dict(row, guess="walking", converged=True, objective=2.0, cost_of_transport=2.0)
    text = ex.table([ok, dict(ok, guess="standing", objective=3.0), row])
    assert "| spread (2 of 3 converged) | | | | 2 to 3 |" in text
    assert text.count("\n") == 5        # header, rule, 3 runs, spread


@pytest.mark.slow
def test_predictive_gait_converges_from_three_generic_guesses(tmp_path):
    """Walking, standing and quasi-random (seed 2) guesses all converge (measured: docs/reference/validation.md, "2D gait",
    robustness table); default-suite cover: test_robustness_guesses_and_table_on_a_tiny_problem and
    tests/test_ocp_gait.py::test_gait_task_files_build_the_half_cycle_problem."""
    require_casadi()
    out = run_example("gait_robustness.py", "--out", tmp_path, "--guesses", "walking,standing,qr2", "--jobs", "2")
    rows = json.loads((tmp_path / "robustness.json").read_text())
    assert [r["guess"] for r in rows] == ["walking", "standing", "qr2"]
    assert all(r["converged"] for r in rows), out
    assert "spread (3 of 3 converged)" in out
