"""Shared test helpers: where the optional real data lives, headless matplotlib, the forearm on its Gaussian motion,
and running an example script."""
import atexit
import contextlib
import io
import os
import runpy
import shutil
import sys
import tempfile
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

# the import cache (pinmsk.io.cache) of this test run is its own temporary folder, never the user's
# (inherited by the command lines the tests run); a test that needs another one sets the variable itself
_CACHE = tempfile.mkdtemp(prefix="pinmsk-test-cache-")
os.environ["PINMSK_CACHE_DIR"] = _CACHE
os.environ.pop("PINMSK_NO_CACHE", None)
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)

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


def shared_folder(rel: str, probe: str) -> Path:
    """``../shared/data/<rel>`` when its file ``probe`` is there, else a skip naming the folder."""
    from pinmsk.io.shared_data import shared_data_dir
    d = shared_data_dir()
    p = None if d is None else d / rel
    if p is None or not (p / probe).is_file():
        pytest.skip(f"../shared/data/{rel} is absent")
    return p


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


# -- casadi and opensim in separate processes ------------------------------------------------
# The pip wheels of opensim (4.6, which bundles Moco) and casadi both ship a libcasadi.so.3.7, with
# different ABIs: whichever a process loads first, the other fails to import.  The suite therefore
# runs as two xdist groups ("opensim" and "casadi", `--dist loadgroup` in pyproject.toml), one per
# worker: modules that run OpenSim go to the first, modules that use the optimal-control engine to
# the second, the rest (no group) to whichever worker is free, which balances the two (186 -> 168 s
# of pytest time when the rest alternated between the groups).  In a single process (-n 0) the
# second library to be asked for skips with this reason.
CASADI_OPENSIM = ("casadi and opensim cannot be loaded in one process (both bundle libcasadi.so.3.7 "
                  "with different ABIs); run the suite with its default -n 2 --dist loadgroup")
_OPENSIM_MARKS = ("import_opensim(", "require_opensim(", "LazyOpenSim", "opensim_module", "bench_opensim", "import opensim")
_CASADI_MARKS = ("casadi", "LazyCasadi", "solvers.ocp", "import ocp", "optimize_task", "require_casadi", "data/tasks",
                 "finger_tapping", "forearm_dynamic_optimization", "finger_frequency_limit", "bench_ocp")


def _module_group(path: Path) -> str | None:
    text = path.read_text(errors="replace") if path.suffix == ".py" else ""
    if any(m in text for m in _OPENSIM_MARKS) and path.name != "conftest.py":
        return "opensim"
    if any(m in text for m in _CASADI_MARKS):
        return "casadi"
    return None       # neither: no group, so xdist hands its tests to whichever worker is free


_GROUPS: dict = {}


def pytest_itemcollected(item):
    # marked as each item is collected, so that xdist's own collection hook (which turns the mark
    # into the "@group" node-id suffix its loadgroup scheduler reads) finds it
    if item.path not in _GROUPS:
        _GROUPS[item.path] = _module_group(Path(item.path))
    g = _GROUPS[item.path]
    if g is not None:
        item.add_marker(pytest.mark.xdist_group(g))


class LazyOpenSim:
    """``opensim`` for a test module, imported at first use inside a test (see :class:`LazyCasadi`)."""

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(require_opensim(), name)


@pytest.fixture
def opensim_module():
    """The opensim module, or a skip naming why."""
    return require_opensim()


def require_opensim():
    """The opensim module (logger off), or a skip naming why (not installed, or casadi in this process)."""
    osim, why = import_opensim()
    if osim is None:
        pytest.skip(why)
    return osim


class LazyCasadi:
    """``casadi`` for a test module, imported at first use inside a test, never at collection:
    both workers collect every module, and a module-level import would load casadi in the OpenSim
    worker too (then opensim cannot load there)."""

    def __getattr__(self, name):
        if name.startswith("__"):      # pytest's collector inspects module attributes
            raise AttributeError(name)
        return getattr(require_casadi(), name)


def require_casadi():
    """The casadi module, or a skip naming why (not installed, or opensim already in this process)."""
    if "opensim" in sys.modules and "casadi" not in sys.modules:
        pytest.skip(CASADI_OPENSIM)
    return pytest.importorskip("casadi")


def import_opensim():
    """``(opensim, "")`` with its logger off (no ``opensim.log`` in the working directory), or
    ``(None, why)`` when the optional peer is not installed (or casadi is loaded in this process)."""
    if "casadi" in sys.modules and "opensim" not in sys.modules:
        return None, CASADI_OPENSIM
    try:
        import opensim
    except ImportError as exc:  # pragma: no cover - depends on the environment
        return None, f"opensim is not importable ({exc}); `pip install opensim` to compare with OpenSim"
    opensim.Logger.setLevelString("Off")
    with contextlib.suppress(Exception):
        opensim.Logger.removeFileSink()
    return opensim, ""


def osim_numbers(el, path: str = "", out: dict | None = None) -> dict:
    """Every numeric property of an OpenSim XML tree ``el``: ``{path: values}``, each path the tags (with
    their ``name`` where an element has one, never for a GeometryPath, the Model or a function's parts)
    and a ``#k`` index for the k-th repeat of a key.  Two trees compare number by number on it."""
    import numpy as np

    out = {} if out is None else out
    count: dict = {}
    for c in el:
        if not isinstance(c.tag, str):
            continue
        name = None if c.tag in ("GeometryPath", "Model") or path.endswith("/function") else c.get("name")
        key = c.tag + (f"[{name}]" if name else "")
        count[key] = count.get(key, 0) + 1
        p = f"{path}/{key}#{count[key]}" if count[key] > 1 else f"{path}/{key}"
        try:
            v = [float(w) for w in (c.text or "").split()]
        except ValueError:
            v = []
        if v:
            out[p] = np.array(v)
        osim_numbers(c, p, out)
    return out


def arm26_setup(tmp_path, name: str, edit):
    """Arm26's setup ``name`` (shared data) written to ``tmp_path/setup.xml`` with its model and motion as
    absolute paths and ``edit`` (text -> text) applied: a setup to change one property of."""
    d = shared_folder("opensim-models/Arm26", name)
    text = (d / name).read_text()
    for f in ("arm26.osim", "arm26_InverseKinematics.mot"):
        text = text.replace(f"> {f} <", f"> {d / f} <")
    setup = tmp_path / "setup.xml"
    setup.write_text(edit(text))
    return setup
