"""Shared test helpers: where the optional real data lives, headless matplotlib, the forearm on its Gaussian motion,
and running an example script."""
import contextlib
import io
import runpy
import sys
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

from pinmsk import load_model  # noqa: E402  (after the headless backend is chosen)
from pinmsk.io.shared_data import shared_data_dir  # noqa: E402
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


def run_example(script: str, *args: str) -> str:
    """Run ``examples/<script>`` as ``python examples/<script> ARGS`` does, in this interpreter; return its stdout.

    The script runs as ``__main__`` with that ``sys.argv`` and its folder on ``sys.path`` (for ``_common``);
    a non-zero ``SystemExit`` fails the test.  In-process rather than a subprocess because a fresh
    interpreter spends ~3 s importing pinmsk, scipy and matplotlib for every example;
    tests/test_viewer.py keeps one example run in a real subprocess without a terminal.
    """
    import matplotlib.pyplot as plt
    folder = str(REPO / "examples")
    argv, path = sys.argv, list(sys.path)
    sys.argv = [str(REPO / "examples" / script), *map(str, args)]
    sys.path.insert(0, folder)
    out = io.StringIO()
    try:
        with matplotlib.rc_context(), contextlib.redirect_stdout(out):
            runpy.run_path(sys.argv[0], run_name="__main__")
    except SystemExit as exc:
        assert exc.code in (0, None), f"{script} exited with {exc.code}:\n{out.getvalue()[-3000:]}"
    finally:
        sys.argv, sys.path[:] = argv, path
        plt.close("all")
    return out.getvalue()
