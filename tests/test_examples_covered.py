"""Every example script runs under test, headless, and its output is checked (so examples cannot rot).

Each script in ``examples/`` has exactly one entry below (a new script without one fails
``test_every_example_has_one_entry``):

* ``RUN_HERE``: run by ``test_example_runs`` in this file -- in-process, as ``python examples/<script>``
  would run it (``run_example`` in conftest.py), or, for the viewer examples, its ``main`` called
  with the viewer it builds captured -- and something real about its output asserted, in the
  default suite;
* ``RUN_ELSEWHERE``: run by the named test of another file, next to the code it exercises;
  ``test_example_is_run_elsewhere`` checks that this test exists, is not marked slow or skipped,
  and calls the script (parsed, not grepped: a comment or a slow test naming the script does not count);
* ``SLOW``: truly long (> 20 s even in quick mode): run by the named ``@pytest.mark.slow`` test, with
  the named default-suite test covering the same code faster.
"""
from __future__ import annotations

import ast
import contextlib
import io
import re
import runpy
from pathlib import Path

import pytest

from conftest import REPO, run_example

EXAMPLES = REPO / "examples"


# ---------------------------------------------------------------------------- run here


def _numbers(pattern: str, text: str) -> list[float]:
    found = [float(x) for x in re.findall(pattern, text, flags=re.M)]
    assert found, f"the output has no line matching {pattern!r}"
    return found


def check_01(out: str, folder: Path):
    # two rounds of rank-and-add find both hidden effects (data/README.md: 0.5 kg, 0.2 N m s/rad)
    (mass,) = _numbers(r"adding payload:hand: mass = ([0-9.]+)", out)
    (c,) = _numbers(r"adding joint_damping:elbow_flexion: c = ([0-9.]+)", out)
    assert mass == pytest.approx(0.5, rel=0.05) and c == pytest.approx(0.2, rel=0.05)
    assert "final verdict: at_noise_floor; model effects: payload:hand, joint_damping:elbow_flexion" in out
    assert (folder / "diagnosis_report.html").stat().st_size > 100_000        # figures embedded
    pngs = {p.name for p in (folder / "figures").glob("*.png")}
    assert {"comparison_before.png", "comparison_after.png", "ranking.png", "error_steps.png"} <= pngs


def check_03(out: str, folder: Path):
    # FSO with the PID tracking law reproduces SO (Figs. 3.16-3.17) and tracks the motion
    assert (folder / "fig3_16_fso_P2.png").exists() and (folder / "fig3_17_fso_P3.png").exists()
    diffs = _numbers(r"largest \|F_FSO - F_SO\|: ([0-9.]+) N", out)
    errs = _numbers(r"tracking error max \|q - q_d\| = ([0-9.]+) deg", out)
    assert len(diffs) == 2 and max(diffs) < 0.5
    assert len(errs) == 2 and max(errs) < 0.1
    assert (folder / "forearm_fso_P2.sto").exists()
    # the tracking forms side by side: Eq. 3.18 (qva) drifts beyond 1 deg, the PID form 3.19 does not
    forms = {(t, e): (float(d), "(diverged" in rest) for t, e, d, rest in
             re.findall(r"^\s+(q|qv|qva|pid)\s+as (constraint|cost)\s*: max \|q - q_d\| =\s+([0-9.]+) deg(.*)$",
                        out, flags=re.M)}
    assert len(forms) == 8
    for enforce in ("constraint", "cost"):
        assert forms[("qva", enforce)][0] > 1.0 and forms[("qva", enforce)][1]
        assert forms[("pid", enforce)][0] < 0.1 and not forms[("pid", enforce)][1]


def check_04(out: str, folder: Path):
    # per motion: SO (each frame alone) has the lowest cost, EID (optimal over the trial under the
    # activation dynamics) does no worse than MSO (greedy under the same dynamics); all balanced
    assert (folder / "so_mso_eid_2s.png").exists() and (folder / "so_mso_eid_0.8s.png").exists()
    cost = {k: _numbers(rf"^\s+{k}\s+[0-9.]+ ms\s+integral of sum a\^2 dt = ([0-9.]+)", out)
            for k in ("SO", "MSO", "EID")}
    assert all(len(v) == 2 for v in cost.values())
    for i in range(2):
        assert cost["SO"][i] < cost["EID"][i] <= cost["MSO"][i] * (1 + 1e-6)
    assert max(_numbers(r"max violation ([0-9.e+-]+) N m", out)) < 1e-6
    # the faster motion (0.8 s) makes the dynamics matter: activations move further from SO
    d_slow, d_fast = _numbers(r"max \|a_EID - a_SO\| = ([0-9.]+)", out)
    assert d_fast > 5 * d_slow


def check_viewer(animated: set[str]):
    def check(viewer, out: str):
        assert "pinmsk viewer: http://127.0.0.1:" in out
        (anim,) = [c for c in viewer.commands if c.kind == "set_animation"]
        groups = {"/".join(p.split("/")[3:5]) for p in anim.detail}     # /meshcat/pinmsk/<group>/<part>/...
        assert groups == animated
    return check


#: script: (arguments, check, None or the default-suite tests covering its code when it is marked slow).
#: The data examples get an output folder as their argument.  All run by default (4.5-6 s each
#: at most, on two test workers the suite has the room).
RUN_HERE = {
    "01_diagnose_forearm.py": (["{out}"], check_01, None),
    "03_forward_static_optimization.py": (["{out}"], check_03, None),
    "04_so_mso_eid.py": (["{out}"], check_04, None),
    "view_gait2d.py": (["--no-block"], check_viewer({"model/skeleton", "model/muscles", "model/residuals",
                                                       "grf/l", "grf/r", "ghost/skeleton"}), None),
    "view_human3d.py": (["--no-block"], check_viewer({"model/skeleton", "ghost/skeleton"}), None),
}

#: script: the default-suite test that runs it
RUN_ELSEWHERE = {
    "02_static_optimization.py": "tests/test_solvers_examples.py::test_example_02_static_optimization",
    "05_contact_identification.py": "tests/test_contact_identify.py::test_example_05_runs_headless",
    "view_forearm.py": "tests/test_viewer.py::test_example_without_terminal_exits_by_itself",
    # the gait case studies need ../shared/data (.ci/run provides it; without it these tests skip,
    # and tests/test_pipeline.py::test_examples_skip_cleanly_without_data runs the no-data path)
    "gait_csu.py": "tests/test_real_data.py::test_csu_case_study",
    "gait_rajagopal.py": "tests/test_real_data.py::test_rajagopal_case_study",
    "gait_winter.py": "tests/test_real_data.py::test_winter_case_study",
}

#: script: (the slow test that runs it, the default test covering the same code, measured time)
SLOW = {
    "finger_tapping.py": ("tests/test_dynamic_examples.py::test_finger_tapping_quick",
                          "tests/test_ocp.py::test_finger_tapping_optima_are_the_replaced_engines_or_lower",
                          "6 s in --quick mode"),
    "forearm_dynamic_optimization.py": ("tests/test_dynamic_examples.py::test_forearm_quick",
                                        "tests/test_ocp.py::test_forearm_effort_optima_match_the_replaced_engine",
                                        "7 s in --quick mode"),
    "finger_frequency_limit.py": ("tests/test_finger_literature.py::test_finger_frequency_limit_quick",
                                  "tests/test_finger_literature.py::test_tracking_cost_rises_with_frequency_across_the_limit",
                                  "4-6 s in --quick mode"),
    "gait_foot_mass.py": ("tests/test_gait_foot_mass.py::test_foot_mass_67_percent_lowers_the_objective",
                          "tests/test_gait_foot_mass.py::test_foot_mass_example_code_on_a_tiny_problem",
                          "two predictive gaits, 3-5 min each"),
    "gait_robustness.py": ("tests/test_gait_robustness.py::test_predictive_gait_converges_from_three_generic_guesses",
                           "tests/test_gait_robustness.py::test_robustness_guesses_and_table_on_a_tiny_problem",
                           "three predictive gaits, 2-5 min each"),
}


def _scripts() -> list[str]:
    return sorted(p.name for p in EXAMPLES.glob("*.py") if not p.name.startswith("_"))


def test_every_example_has_one_entry():
    scripts = _scripts()
    assert scripts, "no examples found"
    entries = [*RUN_HERE, *RUN_ELSEWHERE, *SLOW]
    assert sorted(entries) == scripts, (
        f"examples without an entry: {sorted(set(scripts) - set(entries))}; entries without an example: "
        f"{sorted(set(entries) - set(scripts))}; entries listed twice: "
        f"{sorted({e for e in entries if entries.count(e) > 1})}")


def _run_viewer_example(script: str, args: list[str], monkeypatch):
    """Call the viewer example's ``main(args)``; return the Viewer it built and its stdout."""
    monkeypatch.syspath_prepend(str(EXAMPLES))            # for _common
    ns = runpy.run_path(str(EXAMPLES / script), run_name="example")   # defines main, does not run it
    built = []

    class Capturing(ns["Viewer"]):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            built.append(self)

    monkeypatch.setitem(ns["main"].__globals__, "Viewer", Capturing)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        ns["main"](args)
    assert len(built) == 1, f"{script} built {len(built)} viewers"
    return built[0], out.getvalue()


@pytest.mark.parametrize("script", [pytest.param(s, marks=pytest.mark.slow) if RUN_HERE[s][2] else s
                                    for s in sorted(RUN_HERE)])
def test_example_runs(script, tmp_path, monkeypatch):
    args, check, _ = RUN_HERE[script]
    monkeypatch.chdir(tmp_path)                          # anything written by default lands here
    if script.startswith("view_"):
        monkeypatch.delenv("DISPLAY", raising=False)
        check(*_run_viewer_example(script, args, monkeypatch))
    else:
        out = run_example(script, *[a.format(out=tmp_path) for a in args])
        check(out, tmp_path)


# ---------------------------------------------------------------------------- run elsewhere


def _function(ref: str) -> tuple[ast.Module, ast.FunctionDef]:
    path, name = ref.split("::")
    tree = ast.parse((REPO / path).read_text(encoding="utf-8"))
    fns = [n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name]
    assert len(fns) == 1, f"{ref}: no such test function"
    return tree, fns[0]


def _marks(tree: ast.Module, fn: ast.FunctionDef) -> set[str]:
    """Names of the pytest marks on ``fn`` and on its module (``pytestmark``); marks of single
    ``pytest.param(...)`` cases are not the function's and are left out."""
    nodes = list(fn.decorator_list)
    for stmt in tree.body:
        if isinstance(stmt, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in stmt.targets):
            nodes.append(stmt.value)
    names = set()

    def visit(node):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "param":
            return
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Attribute) and node.value.attr == "mark":
            names.add(node.attr)
        for child in ast.iter_child_nodes(node):
            visit(child)

    for node in nodes:
        visit(node)
    return names


def _calls_example(fn: ast.FunctionDef, script: str) -> bool:
    """Whether ``fn`` runs ``script``: a call with the file name among its arguments (run_example,
    subprocess.run, ...), or ``import <module>`` followed by ``<module>.main(...)``."""
    stem = script[:-3]
    names = {a.asname or a.name for n in ast.walk(fn) if isinstance(n, ast.Import) for a in n.names if a.name == stem}
    for node in ast.walk(fn):
        if not isinstance(node, ast.Call):
            continue
        if any(isinstance(a, ast.Constant) and a.value == script
               for arg in [*node.args, *(k.value for k in node.keywords)] for a in ast.walk(arg)):
            return True
        f = node.func
        if isinstance(f, ast.Attribute) and f.attr == "main" and getattr(f.value, "id", None) in names:
            return True
    return False


@pytest.mark.parametrize("script", sorted(RUN_ELSEWHERE))
def test_example_is_run_elsewhere(script):
    _assert_default(RUN_ELSEWHERE[script])
    assert _calls_example(_function(RUN_ELSEWHERE[script])[1], script), f"{RUN_ELSEWHERE[script]} does not run {script}"


def _assert_default(ref: str):
    tree, fn = _function(ref)
    marks = _marks(tree, fn) & {"slow", "skip", "skipif", "xfail"}
    assert not marks, f"{ref} is marked {sorted(marks)}: it is not in the default suite"


@pytest.mark.parametrize("script", sorted(SLOW))
def test_slow_example_is_run_and_its_code_covered(script):
    slow_ref, fast_ref, _ = SLOW[script]
    tree, fn = _function(slow_ref)
    assert "slow" in _marks(tree, fn) and _calls_example(fn, script), f"{slow_ref} does not run {script}"
    _assert_default(fast_ref)

