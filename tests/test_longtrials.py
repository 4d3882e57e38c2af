"""Long trials: progress lines, write precision, start-up cost and --version."""
import io
import subprocess
import sys
import time

import numpy as np
import pytest

import pinmsk
import pinmsk.presentation.progress as progress_mod
import pinmsk.skeleton as skeleton
from pinmsk.presentation.cli import main
from pinmsk.io.tables import read_trial, write_trial
from pinmsk.presentation.progress import Progress
from pinmsk.trial import Trial


class _Recorder:
    def __init__(self):
        self.calls = []

    def update(self, n=1):
        self.calls.append(n)


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _elbow_trial(path, n=401):
    t = np.linspace(0, 2, n)
    q = np.deg2rad(120) * np.exp(-((t - 1) ** 2) / (2 * 0.25 ** 2))
    write_trial(Trial(t, {"elbow_flexion": q}), path)


# -- the progress line ----------------------------------------------------------

def test_progress_draws_nothing_when_piped(monkeypatch):
    monkeypatch.delenv(progress_mod.ENV, raising=False)
    out = io.StringIO()          # not a terminal
    with Progress(100, "ID", unit="frames", stream=out, delay=0) as bar:
        for _ in range(10):
            bar.update(10)
    assert out.getvalue() == ""
    assert bar.count == 100


def test_progress_on_a_terminal_shows_rate_and_eta(monkeypatch):
    monkeypatch.delenv(progress_mod.ENV, raising=False)
    out = _Terminal()
    start = time.perf_counter()
    with Progress(1000, "ID", unit="frames", stream=out, delay=0) as bar:
        for _ in range(4):
            time.sleep(0.11)     # past the 0.1 s redraw interval
            bar.update(100)
        mid = out.getvalue()
        elapsed = time.perf_counter() - start
        bar.update(600)
    assert "\rID [" in mid and " 40% 400/1k frames" in mid and "frames/s" in mid and "ETA 0:0" in mid
    assert out.getvalue().endswith("done in 0:00\n")
    rate = float(mid.rsplit("frames, ", 1)[1].split(" frames/s")[0])
    assert 400 / elapsed * 0.99 < rate < 400 / 0.44 * 1.01   # 400 frames in 0.44 s or more


def test_progress_forced_by_parameter_or_environment(monkeypatch):
    monkeypatch.setenv(progress_mod.ENV, "1")
    out = io.StringIO()
    with Progress(None, "optimize", unit="iterations", stream=out, delay=0) as bar:
        bar.update(3)
    assert "optimize 3 iterations" in out.getvalue() and "iterations/s" in out.getvalue()
    monkeypatch.setenv(progress_mod.ENV, "0")     # off even on a terminal
    out = _Terminal()
    with Progress(10, "SO", stream=out, delay=0) as bar:
        bar.update(10)
    assert out.getvalue() == ""
    out = io.StringIO()
    with Progress(10, "SO", stream=out, delay=0, force=True) as bar:
        bar.update(10)
    assert "SO [" in out.getvalue()


def test_progress_waits_for_its_delay():
    out = io.StringIO()
    with Progress(10, "ID", stream=out, force=True, delay=30) as bar:
        bar.update(10)
    assert out.getvalue() == ""


def test_inverse_dynamics_reports_progress_by_chunk(monkeypatch):
    model = pinmsk.load_model("forearm")
    n = 20
    q = np.zeros((n, model.nv))
    monkeypatch.setattr(skeleton, "PROGRESS_CHUNK", 7)
    rec = _Recorder()
    tau = skeleton.rnea(model, q, q, q, progress=rec)
    assert rec.calls == [7, 7, 6]
    np.testing.assert_array_equal(tau, skeleton.rnea(model, q, q, q))


def test_cli_id_progress_only_when_asked(tmp_path, capsys, monkeypatch):
    src = tmp_path / "elbow.csv"
    _elbow_trial(src)
    monkeypatch.setattr(progress_mod, "DEFAULT_DELAY", 0.0)
    monkeypatch.delenv(progress_mod.ENV, raising=False)
    assert main(["id", "forearm", str(src), "-o", str(tmp_path / "a.sto")]) == 0
    assert capsys.readouterr().err == ""          # captured stderr is not a terminal
    monkeypatch.setenv(progress_mod.ENV, "1")
    assert main(["id", "forearm", str(src), "-o", str(tmp_path / "b.sto")]) == 0
    err = capsys.readouterr().err
    assert "ID [" in err and "401/401 frames" in err and "frames/s" in err


# -- precision on the command line ----------------------------------------------

def test_cli_precision_flag(tmp_path, capsys):
    src = tmp_path / "elbow.csv"
    _elbow_trial(src)
    out = tmp_path / "id.csv"
    assert main(["id", "forearm", str(src), "-o", str(out), "--precision", "4"]) == 0
    row = out.read_text().splitlines()[200].split(",")
    ref = pinmsk.inverse_dynamics(pinmsk.load_model("forearm"), read_trial(src))
    assert row[2] == "%.4g" % ref["elbow_flexion_moment"][199]
    for bad in ("0", "18", "x"):
        with pytest.raises(SystemExit) as info:
            main(["id", "forearm", str(src), "-o", str(tmp_path / "bad.sto"), "--precision", bad])
        assert info.value.code == 2
        assert "--precision: expected significant digits from 1 to 17" in capsys.readouterr().err
    assert not (tmp_path / "bad.sto").exists()


# -- start-up and version ---------------------------------------------------------

_HEAVY = ("scipy.signal", "scipy.interpolate", "scipy.optimize", "matplotlib", "pinocchio", "meshcat")


def test_help_and_import_do_not_load_heavy_modules():
    probe = f"""
import contextlib, io, sys
heavy = lambda: [m for m in {_HEAVY!r} if m in sys.modules]
from pinmsk.presentation.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        main(["--help"])
    except SystemExit:
        pass
print(heavy())
import pinmsk
from pinmsk import Trial, read_trial, write_trial, PinmskError
print(heavy())
"""
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    after_help, after_import = (eval(line) for line in done.stdout.split("\n")[-3:-1])
    assert after_help == [] and after_import == []


def test_version(capsys):
    from importlib.metadata import version
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out == f"pinmsk {version('pinmsk')}\n"
    assert version("pinmsk") == pinmsk.__version__


def test_lazy_package_attributes():
    # the public names import on first use, and submodules stay reachable as attributes
    assert pinmsk.inverse_dynamics is pinmsk.dynamics.inverse_dynamics
    assert pinmsk.load_model("forearm").nv == 1
    assert set(pinmsk.__all__) <= set(dir(pinmsk))
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        pinmsk.not_a_name


# -- static optimization in chunks ---------------------------------------------------

GAIT_DOFS = ("hip_l", "knee_l", "ankle_l", "hip_r", "knee_r", "ankle_r")


@pytest.fixture(scope="module")
def walk():
    from pinmsk.diagnose.synth import walking_motion
    model = pinmsk.load_model("gait2d")
    return model, walking_motion(model, n_frames=150, duration=0.75)


@pytest.mark.parametrize("options", [{}, {"exponent": 3}, {"mode": "activation"}, {"reserves": True}],
                         ids=["P2", "P3", "activation", "reserves"])
def test_so_in_chunks_equals_one_piece(walk, options):
    from pinmsk.solvers.static import ChunkedSOProblem, StaticOptimization
    model, motion = walk
    whole = StaticOptimization(dofs=GAIT_DOFS, **options).fit(model, motion)
    parts = StaticOptimization(dofs=GAIT_DOFS, chunk_size=7, **options).fit(model, motion)
    assert isinstance(parts.problem_, ChunkedSOProblem) and not isinstance(whole.problem_, ChunkedSOProblem)
    f_max = whole.problem_.f_max
    # the batched solve is per frame and its warm starts span chunks: the same numbers
    np.testing.assert_allclose(parts.forces_, whole.forces_, rtol=0, atol=1e-12 * f_max.max())
    np.testing.assert_allclose(parts.activations_, whole.activations_, rtol=0, atol=1e-12)
    np.testing.assert_allclose(parts.cost_, whole.cost_, rtol=1e-12, atol=0)
    np.testing.assert_allclose(parts.violation_, whole.violation_, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(parts.status_, whole.status_)
    assert parts.n_iter_ == whole.n_iter_
    if options.get("reserves"):
        np.testing.assert_allclose(parts.reserves_, whole.reserves_, rtol=0, atol=1e-12)
    # the chunked problem still shows its arrays (built on demand) as one piece
    np.testing.assert_array_equal(parts.problem_.A, whole.problem_.A)
    np.testing.assert_array_equal(parts.problem_.scale, whole.problem_.scale)


@pytest.mark.parametrize("options", [{"exponent": 1}, {"exponent": 10}, {"method": "proxsuite"}],
                         ids=["LP", "SQP", "proxsuite"])
def test_so_in_chunks_other_paths_reach_the_same_optimum(walk, options):
    from pinmsk.solvers.static import StaticOptimization
    from pinmsk.components import Motion
    model, full = walk
    motion = Motion(full.t[:48], full.q[:48], full.v[:48], full.a[:48])
    whole = StaticOptimization(dofs=GAIT_DOFS, **options).fit(model, motion)
    parts = StaticOptimization(dofs=GAIT_DOFS, chunk_size=16, **options).fit(model, motion)
    # LP basis guesses stop at a chunk's end and proxsuite's last digits follow memory
    # layout, so these agree to the solvers' tolerance rather than to the bit
    np.testing.assert_allclose(parts.cost_, whole.cost_, rtol=1e-9, atol=0)
    np.testing.assert_allclose(parts.forces_, whole.forces_, rtol=0, atol=1e-6 * whole.problem_.f_max.max())


def test_so_chunk_size_is_checked(walk):
    from pinmsk.errors import SolverError
    from pinmsk.solvers.static import StaticOptimization
    model, motion = walk
    for bad in (0, 2.5, True):
        with pytest.raises(SolverError, match="chunk_size must be a whole number of frames >= 1"):
            StaticOptimization(dofs=GAIT_DOFS, chunk_size=bad).fit(model, motion)


def test_so_infeasible_frames_found_across_chunks():
    from pinmsk.errors import InfeasibleError
    from pinmsk.solvers.analytical import gaussian_elbow_motion
    from pinmsk.solvers.static import StaticOptimization
    model = pinmsk.load_model("forearm")
    motion = gaussian_elbow_motion(n_frames=60)
    tau = pinmsk.dynamics.inverse_dynamics_array(model, motion)
    tau[[5, 33, 47]] = 1e5            # far beyond the muscles
    messages = []
    for cs in (20000, 8):
        with pytest.raises(InfeasibleError) as info:
            StaticOptimization(chunk_size=cs).fit(model, motion, moments=tau)
        messages.append(str(info.value))
    assert "at 3 of 60 frames" in messages[0] and "frame 33" in messages[0]
    assert messages[0] == messages[1]
