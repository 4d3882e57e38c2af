"""The dynamic-optimization examples run headless in quick mode and write their JSON/PNG."""
import json
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
sys.path.insert(0, str(EXAMPLES))


@pytest.mark.slow
def test_finger_tapping_quick(tmp_path):
    import finger_tapping
    finger_tapping.main(["--out", str(tmp_path), "--quick"])
    data = json.loads((tmp_path / "finger_tapping.json").read_text())
    for key in ("frequencies", "J", "J1", "J2", "max_frequency", "seconds"):
        assert key in data
    assert data["frequencies"] == [2.0, 6.0]
    assert all(data["converged"])
    assert all(j2 < 0.01 for j2 in data["J2"])          # our finger tracks 2 and 6 Hz
    assert (tmp_path / "finger_2Hz.png").exists() and (tmp_path / "finger_table.png").exists()
    assert data["half_mass_2Hz"]["converged"] and data["half_mass_2Hz"]["J2"] < 0.01


@pytest.mark.slow
def test_forearm_quick(tmp_path):
    import forearm_dynamic_optimization as fa
    fa.main(["--out", str(tmp_path), "--quick"])
    data = json.loads((tmp_path / "forearm_do.json").read_text())
    r = data["J4"]["fourier"]
    assert r["converged"]
    assert r["max_tracking_error"] <= 0.1 + 1e-3
    assert r["n_parameters"] == 77
    assert (tmp_path / "forearm_excitations_fourier.png").exists()
    d = data["designs"]["ift"]
    assert d["converged"] and d["max_tracking_error"] <= 0.1 + 1e-3
    assert d["max_bound_violation"] < 1e-4
    assert (tmp_path / "forearm_designs.png").exists()
