"""Progress of ``pinmsk optimize``: the per-stage lines (live on a terminal, one at each stage's end
on a pipe), the summary line, IPOPT's log in --solver-log / --verbose, and --keep-unconverged."""
import io
import json
import re

import numpy as np
import pytest

from pinmsk.presentation.solve_progress import SolveProgress, stage_line, summary_line

# the finger tapping task on 8 intervals and a cubic: about 50 IPOPT iterations in well under a second
TINY = """
[model]
name = "finger"
tendon = "rigid"

[motion]
kind = "sine"
coordinate = "mcp_flexion"
amplitude = 0.21
frequency = 6.0

[parametrization]
design = "ff"
kind = "polynomial"
order = 3

[objective]
kind = "effort"
exponent = 2
weights = "none"
normalize = false
tracking_weight = 0.9

[solver]
intervals = 8
"""


class _Pipe(io.StringIO):
    def isatty(self):
        return False


class _Terminal(io.StringIO):
    def isatty(self):
        return True


class _Recorder(SolveProgress):
    """A SolveProgress that also keeps every iterate it is told of."""

    def __init__(self, stream):
        super().__init__(stream)
        self.iterates = []

    def iteration(self, iteration, objective, violation):
        self.iterates.append((iteration, objective, violation))
        super().iteration(iteration, objective, violation)


@pytest.fixture(autouse=True)
def _no_forced_progress(monkeypatch):
    monkeypatch.delenv("PINMSK_PROGRESS", raising=False)      # the streams' isatty decides


@pytest.fixture
def task(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def test_a_pipe_gets_one_line_per_stage_with_the_solves_numbers(task):
    from pinmsk.pipeline import optimize_task
    stream = _Pipe()
    mon = _Recorder(stream)
    res = optimize_task(task, monitor=mon)
    assert res.converged
    lines = stream.getvalue().splitlines()
    assert lines == mon.lines and len(lines) == 1          # one stage, one line, no live redraws
    assert "\r" not in stream.getvalue()
    m = re.fullmatch(r"optimize stage 1 \(8 intervals\): converged \(Solve_Succeeded\), iter (\d+), "
                     r"objective (\S+), inf_pr (\S+), (\S+) s", lines[0])
    assert m, lines[0]
    assert int(m[1]) == res.iterations
    assert float(m[2]) == pytest.approx(res.objective, rel=1e-5)
    assert float(m[3]) == pytest.approx(res.violation, rel=0.01, abs=1e-15) and res.violation < 1e-6
    # IPOPT told the monitor of its start and of every iteration, the last one being the solution
    its = [k for k, _, _ in mon.iterates]
    assert its == list(range(res.iterations + 1))
    assert mon.iterates[-1][1] == pytest.approx(res.objective, rel=1e-9)
    assert mon.iterates[0][2] > 1e3 * mon.iterates[-1][2]   # the guess violates the dynamics, the solution does not


def test_progress_env_forces_the_live_line_on_or_off(monkeypatch):
    monkeypatch.setenv("PINMSK_PROGRESS", "1")
    assert SolveProgress(_Pipe()).live
    monkeypatch.setenv("PINMSK_PROGRESS", "0")
    assert not SolveProgress(_Terminal()).live


def test_a_terminal_gets_a_live_line_replaced_by_the_stage_line():
    stream = _Terminal()
    p = SolveProgress(stream)
    assert p.live
    p.start("15 intervals")
    for k in range(3):
        p.iteration(k, 10.0 / (k + 1), 10.0 ** -k)
    rec = {"converged": False, "status": "Maximum_Iterations_Exceeded; largest violation: x", "iterations": 2,
           "objective": 3.25, "violation": 0.01, "seconds": 75.0}
    p.end(rec)
    out = stream.getvalue()
    assert "\roptimize stage 1 (15 intervals): starting, 00:00" in out
    final = out.rsplit("\r", 1)[-1]
    assert final == ("optimize stage 1 (15 intervals): NOT CONVERGED (Maximum_Iterations_Exceeded), iter 2, "
                     "objective 3.25, inf_pr 1.00e-02, 1:15\n")


def test_an_interrupted_stage_shows_its_last_iterate():
    stream = _Pipe()
    p = SolveProgress(stream)
    p.start("25 intervals")
    p.iteration(0, 5.0, 1.0)
    p.iteration(1, 4.5, 0.5)
    p.end(None)
    assert stream.getvalue().startswith("optimize stage 1 (25 intervals): interrupted, iter 1, objective 4.5, "
                                        "inf_pr 5.00e-01, ")


def test_summary_line_has_status_objective_time_and_the_gaits_numbers():
    base = {"converged": True, "status": "Solve_Succeeded", "objective": 1.234567891, "iterations": 812,
            "seconds": 151.4}
    assert summary_line(base) == "optimize: converged (Solve_Succeeded), objective 1.23457, 812 iterations, 2:31"
    gait = dict(base, speed=1.29961, stride_length=1.4296, cost_of_transport=3.4127, body_weight=735.0)
    assert summary_line(gait).endswith("; speed 1.300 m/s, stride 1.430 m, cost of transport 3.413 J/kg/m")
    tracked = dict(gait, converged=False, status="Maximum_Iterations_Exceeded", stride_length=None,
                   cost_of_transport=None, seconds=4.25)
    assert summary_line(tracked) == (
        "optimize: NOT CONVERGED (not a solution) (Maximum_Iterations_Exceeded), objective 1.23457, "
        "812 iterations, 4.2 s; speed 1.300 m/s, stride n/a m (not a full stride), cost of transport n/a J/kg/m")
    assert stage_line(3, "x", None, iteration=7, objective=2.0, violation=0.5, seconds=1.0) == \
        "optimize stage 3 (x): interrupted, iter 7, objective 2, inf_pr 5.00e-01, 1.0 s"


def test_cli_writes_ipopts_log_to_the_solver_log_only(task, tmp_path, capfd):
    from pinmsk.presentation.cli import main
    out, log = tmp_path / "out.sto", tmp_path / "ipopt.log"
    log.write_text("an older run\n")
    assert main(["optimize", str(task), "-o", str(out), "--solver-log", str(log)]) == 0
    stdout, stderr = capfd.readouterr()              # file descriptors: IPOPT prints from C
    assert "Ipopt" not in stdout and "Ipopt" not in stderr
    text = log.read_text()
    assert text.startswith("# pinmsk: IPOPT solve of model 'finger', 8 intervals\n")
    assert "an older run" not in text
    assert "This is Ipopt version" in text and "EXIT: Optimal Solution Found." in text
    summary = json.loads((tmp_path / "out.sto.json").read_text())
    n_rows = len(re.findall(r"^\s*\d+r?\s+[-+]?\d\.\d+e[-+]\d+", text, flags=re.M))
    assert n_rows == summary["iterations"] + 1       # IPOPT's table: the start and every iteration
    assert summary_line(summary) in stdout.splitlines()
    assert re.search(r"^optimize stage 1 \(8 intervals\): converged \(Solve_Succeeded\), iter "
                     f"{summary['iterations']}, ", stderr, flags=re.M)


def test_cli_verbose_prints_ipopts_log_on_stdout(task, capfd):
    from pinmsk.presentation.cli import main
    assert main(["optimize", str(task), "--verbose"]) == 0
    stdout, stderr = capfd.readouterr()
    assert "This is Ipopt version" in stdout and "EXIT: Optimal Solution Found." in stdout
    assert "optimize stage 1 (8 intervals): converged" in stderr


def test_keep_unconverged_writes_the_last_iterate_flagged(task, tmp_path, capfd):
    from pinmsk.presentation.cli import main
    out = tmp_path / "last.sto"
    assert main(["optimize", str(task), "-o", str(out), "--max-iter", "3", "--keep-unconverged"]) == 2
    stdout, stderr = capfd.readouterr()
    summary = json.loads((tmp_path / "last.sto.json").read_text())
    assert summary["converged"] is False and summary["iterations"] == 3
    assert summary["status"].startswith("Maximum_Iterations_Exceeded")
    import pinmsk
    trial = pinmsk.read_trial(out)
    assert trial.time.size == 2 * 8 + 1 and np.all(np.isfinite(trial["mcp_flexion"]))
    errors = [ln for ln in stderr.splitlines() if ln.startswith("pinmsk: error:")]
    assert len(errors) == 1 and "did not converge" in errors[0]
    assert f"written to {out} and {out}.json (converged=false)" in errors[0]
    assert "NOT CONVERGED (Maximum_Iterations_Exceeded), iter 3," in stderr
    assert "optimize: " not in stdout          # no summary line: it is not a solution


def test_keep_unconverged_needs_an_output_and_is_refused_before_the_solve(task, capfd):
    from pinmsk.presentation.cli import main
    assert main(["optimize", str(task), "--keep-unconverged"]) == 2
    stdout, stderr = capfd.readouterr()
    assert stderr.strip() == "pinmsk: error: --keep-unconverged writes the last iterate to -o OUT: give -o; nothing was run"


@pytest.mark.slow   # the gait2d problem's build and two stages of 2 iterations each: ~25 s
def test_gait_keep_unconverged_has_two_stages_and_the_gaits_numbers(tmp_path, capfd):
    from pinmsk.presentation.cli import main
    out = tmp_path / "gait.sto"
    assert main(["optimize", "gait2d_predictive", "-o", str(out), "--max-iter", "2", "--keep-unconverged"]) == 2
    stderr = capfd.readouterr().err
    assert re.search(r"^optimize stage 1 \(15 intervals\): NOT CONVERGED .*, iter 2, ", stderr, flags=re.M)
    assert re.search(r"^optimize stage 2 \(25 intervals\): NOT CONVERGED .*, iter 2, ", stderr, flags=re.M)
    summary = json.loads((tmp_path / "gait.sto.json").read_text())
    assert summary["converged"] is False and summary["iterations"] == 4
    for key in ("speed", "stride_length", "cost_of_transport"):
        assert np.isfinite(summary[key])
    assert summary["stride_length"] == pytest.approx(summary["speed"] * summary["duration"], rel=1e-9)
    assert " m/s, stride " in summary_line(summary)


def test_ctrl_c_ends_the_fit_with_the_stage_marked_interrupted(task):
    """SIGINT inside IPOPT stops it at the next iteration and the fit raises KeyboardInterrupt (CasADi alone
    would report a failed stage and let a coarse-to-fine fit go on to its next one)."""
    import os
    import signal
    from pinmsk.pipeline import optimize_task

    class CtrlC(_Recorder):
        def iteration(self, iteration, objective, violation):
            super().iteration(iteration, objective, violation)
            if iteration == 4:
                os.kill(os.getpid(), signal.SIGINT)

    stream = _Pipe()
    mon = CtrlC(stream)
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)   # as in a command line
    try:
        with pytest.raises(KeyboardInterrupt):
            optimize_task(task, monitor=mon)
    finally:
        signal.signal(signal.SIGINT, saved)
    assert signal.getsignal(signal.SIGINT) is saved
    assert [k for k, _, _ in mon.iterates] == [0, 1, 2, 3, 4]        # no iteration after the one interrupted
    assert stream.getvalue().startswith("optimize stage 1 (8 intervals): interrupted, iter 4, ")
