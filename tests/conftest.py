"""Shared test helpers: where the optional real data lives, and headless matplotlib."""
import os
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

REPO = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path | None:
    """``../shared/data`` beside the repository (or $PINMSK_SHARED_DATA), if present."""
    env = os.environ.get("PINMSK_SHARED_DATA")
    cand = Path(env) if env else REPO.parent / "shared" / "data"
    return cand if cand.is_dir() else None


@pytest.fixture
def shared_data():
    d = shared_data_dir()
    if d is None:
        pytest.skip("real data folder ../shared/data is absent")
    return d
