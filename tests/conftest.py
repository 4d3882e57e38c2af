"""Shared test helpers: where the optional real data lives, headless matplotlib, the forearm on its Gaussian motion."""
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

from pinmsk import load_model  # noqa: E402  (after the headless backend is chosen)
from pinmsk.datasets import shared_data_dir  # noqa: E402
from pinmsk.solvers.analytical import gaussian_elbow_motion  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def shared_data():
    d = shared_data_dir()
    if d is None:
        pytest.skip("real data folder ../shared/data is absent")
    return d


@pytest.fixture(scope="module")
def forearm():
    """The built-in forearm model (modules that need another forearm define their own)."""
    return load_model("forearm")


@pytest.fixture(scope="module")
def motion():
    """The Gaussian 0 -> 120 deg elbow flexion of thesis Fig. 3.13 (the solver tests' forearm motion)."""
    return gaussian_elbow_motion()
