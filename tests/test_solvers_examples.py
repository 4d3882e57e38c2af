"""The solver examples run headless and write their figures (so they cannot rot)."""
import re
import subprocess
import sys

import pytest

from conftest import REPO, run_example as run


def test_example_02_static_optimization(tmp_path):
    text = run("02_static_optimization.py", tmp_path)
    for png in ("fig3_13_reference_motion.png", "fig3_14_15_so_forces.png", "fig3_18_19_analytical.png",
                "gait2d_so_forces.png"):
        assert (tmp_path / png).stat().st_size > 10_000
    assert (tmp_path / "gait2d_so_P2.sto").exists()
    errs = [float(e) for e in re.findall(r"max \|F - F_analytical\| = ([0-9.e+-]+) N", text)]
    assert len(errs) == 5 and max(errs) < 1e-6


# examples 03 and 04 run in tests/test_examples_covered.py.


@pytest.mark.slow
def test_benchmark_runs_quick():
    res = subprocess.run([sys.executable, str(REPO / "benchmarks" / "bench_solvers.py"), "--quick"],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "Targets" in res.stdout
