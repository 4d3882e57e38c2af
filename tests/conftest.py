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


@contextlib.contextmanager
def _as_command(argv: list[str], *, path: str | None = None):
    """Run the body as a command line: ``sys.argv = argv`` (and ``path`` first on ``sys.path``), stdout
    collected into the yielded StringIO, figures closed afterwards; a non-zero ``SystemExit`` fails the test
    with the end of the output and the error line."""
    import matplotlib.pyplot as plt
    saved_argv, saved_path = sys.argv, list(sys.path)
    sys.argv = list(argv)
    if path is not None:
        sys.path.insert(0, path)
    out, err = io.StringIO(), io.StringIO()
    try:
        with matplotlib.rc_context(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            yield out
    except SystemExit as exc:
        assert exc.code in (0, None), (f"{argv[0]} exited with {exc.code}:\n{out.getvalue()[-3000:]}"
                                       f"\n{err.getvalue()[-2000:]}")
    finally:
        sys.argv, sys.path[:] = saved_argv, saved_path
        plt.close("all")


def run_example(script: str, *args: str) -> str:
    """Run ``examples/<script>`` as ``python examples/<script> ARGS`` does, in this interpreter; return its stdout.

    The script runs as ``__main__`` with that ``sys.argv`` and its folder on ``sys.path`` (for ``_common``);
    a non-zero ``SystemExit`` fails the test.  In-process rather than a subprocess because a fresh
    interpreter spends ~3 s importing pinmsk, scipy and matplotlib for every example;
    tests/test_viewer.py keeps one example run in a real subprocess without a terminal.
    """
    argv = [str(REPO / "examples" / script), *map(str, args)]
    with _as_command(argv, path=str(REPO / "examples")) as out:
        runpy.run_path(argv[0], run_name="__main__")
    return out.getvalue()


def run_pinmsk(*args: str) -> str:
    """Run ``pinmsk ARGS`` as ``python -m pinmsk ARGS`` does, in this interpreter; return its stdout.

    Through the package's ``__main__`` rather than a module path, so it keeps working wherever the
    CLI module lives; an exit status other than 0 fails the test (with the end of the output).
    """
    with _as_command(["pinmsk", *map(str, args)]) as out:
        runpy.run_module("pinmsk", run_name="__main__")
    return out.getvalue()


def import_opensim():
    """``(opensim, "")`` with its logger off (no ``opensim.log`` in the working directory), or
    ``(None, why)`` when the optional peer is not installed."""
    try:
        import opensim
    except ImportError as exc:  # pragma: no cover - depends on the environment
        return None, f"opensim is not importable ({exc}); `pip install opensim` to compare with OpenSim"
    opensim.Logger.setLevelString("Off")
    with contextlib.suppress(Exception):
        opensim.Logger.removeFileSink()
    return opensim, ""
