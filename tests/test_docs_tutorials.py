"""The tutorials in docs/tutorials run as written and print what they show.

A page's ```sh blocks are commands (``pinmsk ...`` as a user types them), its ```python blocks scripts;
the ```text block after one is an excerpt of its output.  Every line of an excerpt must appear in the
output, in order (whitespace runs count as one space); ``...`` stands for lines left out, and a line
ending in ``...`` matches any line it begins.  ``$M`` and ``$W`` are the shared data's folders (the
page's ```bash block sets them); the output's absolute paths are written back as ``$M``/``$W`` before
matching.  When the diagnosis changes what it prints, run the page's commands again and update the
excerpts and the prose that quotes their numbers.  Needs ``../shared/data``; skips without it.
"""
import json
import os
import re
import shlex
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from pinmsk.io.shared_data import shared_data_dir
from pinmsk.presentation.cli import main

ROOT = Path(__file__).resolve().parents[1]
RAJAGOPAL = ROOT / "docs" / "tutorials" / "rajagopal_walk_residuals.md"


def _blocks(page: Path) -> list[tuple[str, str]]:
    """``(language, body)`` of each fenced block of ``page``, in order."""
    return [(m.group(1), m.group(2)) for m in re.finditer(r"^```(\w*)\n(.*?)^```$", page.read_text(),
                                                          flags=re.S | re.M)]


def _steps(page: Path) -> list[tuple[str, str, list[str]]]:
    """``(language, body, excerpts)``: each ```sh / ```python block with the ```text blocks after it (each an
    excerpt of its output on its own; a page may quote one run in several places)."""
    out = []
    for lang, body in _blocks(page):
        if lang in ("sh", "python"):
            out.append((lang, body, []))
        elif lang == "text" and out:
            out[-1][2].append(body)
    return out


def _norm(line: str) -> str:
    return " ".join(line.split())


def assert_excerpt(excerpt: str, output: str, where: str) -> None:
    """Every line of ``excerpt`` in ``output``, in order (see the module notes)."""
    lines = [_norm(x) for x in output.splitlines()]
    i = 0
    for want in excerpt.splitlines():
        w = _norm(want)
        if w in ("", "..."):
            continue
        prefix = w.endswith("...")
        w = w[:-3].rstrip() if prefix else w
        while i < len(lines) and not (lines[i].startswith(w) if prefix else lines[i] == w):
            i += 1
        assert i < len(lines), (f"{where}: the output has no line {want.strip()!r} (in this order)\n"
                                f"--- output:\n{output}")
        i += 1


def _folders():
    d = shared_data_dir()
    m = None if d is None else d / "opensim-models" / "RajagopalWalk"
    w = None if d is None else d / "real" / "opensim-moco-walk-emg"
    if m is None or not (m / "subject_walk_scaled.osim").is_file() or not (w / "coordinates.sto").is_file():
        pytest.skip("../shared/data/opensim-models/RajagopalWalk or real/opensim-moco-walk-emg is absent")
    return m, w


def _shorten(text: str, m: Path, w: Path) -> str:
    return text.replace(str(m), "$M").replace(str(w), "$W")


def test_the_rajagopal_page_has_its_commands_and_excerpts():
    """The page's steps as the tests read them: every command is a ``pinmsk`` command, each has its excerpt."""
    steps = _steps(RAJAGOPAL)
    commands = [body for lang, body, _ in steps if lang == "sh"]
    assert len(commands) == 6 and all(c.startswith("pinmsk ") for c in commands)
    assert all(excerpts for lang, _, excerpts in steps if lang == "sh")


def test_the_rajagopal_residual_report_is_the_pages(tmp_path, monkeypatch, capsys):
    """The page's residual-report command (section 2), run in this process: its excerpt, and the JSON's
    ``residual_report`` with the means the page's prose quotes."""
    m, w = _folders()
    lang, body, excerpts = next(s for s in _steps(RAJAGOPAL) if s[0] == "sh" and "--json walk.json" in s[1])
    assert len(excerpts) == 2                     # the residual report (section 2), the verdict and ranking (3)
    monkeypatch.setenv("M", str(m))
    monkeypatch.setenv("W", str(w))
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(os.path.expandvars(body.strip()))
    assert argv[0] == "pinmsk"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(argv[1:])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    for k, excerpt in enumerate(excerpts):
        assert_excerpt(excerpt, _shorten(cap.out, m, w), f"section {2 + k}")
    report = json.loads((tmp_path / "walk.json").read_text())["residual_report"]
    step = report["steps"][0]
    assert step["frames"] == 850
    assert report["body_weight_N"] == pytest.approx(85.27 * 9.80665, abs=0.05)
    means = {c: step["coordinates"][c]["mean"] for c in ("pelvis_tilt", "pelvis_list", "pelvis_ty")}
    assert means == pytest.approx({"pelvis_tilt": -5.12, "pelvis_list": 4.21, "pelvis_ty": 5.30}, abs=0.005)


@pytest.mark.slow          # six diagnoses and an inverse dynamics of the 80-muscle model, each in its own process
def test_the_rajagopal_page_runs_as_written(tmp_path):
    """Every command and script of the page, in order, in one folder (the later ones read what the earlier
    ones wrote), each output against its excerpt."""
    m, w = _folders()
    env = {**os.environ, "M": str(m), "W": str(w), "PYTHONPATH": str(ROOT)}
    for k, (lang, body, excerpts) in enumerate(_steps(RAJAGOPAL)):
        if lang == "sh":
            argv = shlex.split(body.strip().replace("$M", str(m)).replace("$W", str(w)))
            argv = [sys.executable, "-m", "pinmsk", *argv[1:]]
        else:
            script = tmp_path / f"step{k}.py"
            script.write_text(body)
            argv = [sys.executable, str(script)]
        run = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        out = _shorten(run.stdout + run.stderr, m, w)
        refused = any(x.lstrip().startswith("pinmsk: error:") for x in excerpts)
        assert run.returncode == (2 if refused else 0), f"step {k}: {body}\n{out}"
        for excerpt in excerpts:
            assert_excerpt(excerpt, out, f"step {k} ({body.strip()[:60]}...)")


# -- every page of docs/ and the README: commands that parse, pages that run ----------------------------

DOCS = ROOT / "docs"
#: Pages whose every step runs in a few seconds: run as written by the default suite.
FAST_PAGES = ("tutorials/own_csv.md", "tutorials/static_optimization.md")
#: Pages that run as written with the repository's own data only, in the slow set. The optimal-control page solves
#: with casadi in this process, so this module runs in the casadi group of tests/conftest.py.
SLOW_PAGES = ("tutorials/diagnosis.md", "tutorials/optimal_control.md")
#: What the ``$VAR``s of the pages' shell lines stand for when they are only parsed.
PLACEHOLDERS = {"M": "M", "W": "W", "SLURM_CPUS_PER_TASK": "2", "SLURM_ARRAY_TASK_ID": "1",
                "SLURM_ARRAY_TASK_COUNT": "8"}


def _pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]


def _command_lines(page: Path) -> list[str]:
    """Every ``pinmsk ...`` command of the page's shell blocks (``sh``, ``bash``), continuation lines
    joined, after any ``&&``; ``$ `` prompts are taken off."""
    out = []
    for lang, body in _blocks(page):
        if lang not in ("sh", "bash"):
            continue
        for line in body.replace("\\\n", " ").splitlines():
            line = line.strip()
            line = line[2:] if line.startswith("$ ") else line
            line = line.replace("python -m pinmsk ", "pinmsk ")
            for part in line.split("&&"):
                part = part.strip()
                if part.startswith("pinmsk "):
                    out.append(part)
    return out


def _argv(command: str) -> list[str]:
    for k, v in PLACEHOLDERS.items():
        command = command.replace("${" + k + "}", v).replace("$" + k, v)
    return shlex.split(command, comments=True)[1:]


def test_every_documented_command_parses():
    """Each ``pinmsk`` command on a page of docs/ or in the README is one the command line accepts
    (its options and their values), so a renamed option cannot leave a page behind."""
    from pinmsk.presentation.cli import build_parser

    seen = 0
    for page in _pages():
        for command in _command_lines(page):
            argv = _argv(command)
            if "--help" in argv or "-h" in argv or "--version" in argv:
                continue
            try:
                build_parser().parse_args(argv)
            except SystemExit as exc:
                raise AssertionError(f"{page.relative_to(ROOT)}: the command line refuses {command!r}") from exc
            seen += 1
    assert seen > 40


def _run_step(lang: str, body: str, cwd: Path) -> tuple[int, str]:
    """One step of a page, in this process, in ``cwd``: ``(exit status, stdout + stderr)``."""
    import contextlib
    import io
    import traceback

    buf = io.StringIO()
    rc = 0
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if lang == "sh":
            for command in _command_lines_of(body):
                rc = main(_argv(command))
                if rc:
                    break
        else:
            try:
                exec(compile(body, "<docs>", "exec"), {"__name__": "__main__"})
            except Exception:                     # the page's script failed: show it in the assertion
                traceback.print_exc(file=buf)
                rc = 1
    return rc, buf.getvalue()


def _command_lines_of(body: str) -> list[str]:
    return [c for c in (line.strip() for line in body.replace("\\\n", " ").splitlines())
            if c.startswith("pinmsk ")]


def run_page(page: Path, tmp_path: Path, monkeypatch) -> None:
    """Every step of ``page`` in order in one empty folder holding a link to the repository's ``data/``,
    each output against its excerpts (an excerpt starting ``pinmsk: error:`` expects exit status 2)."""
    (tmp_path / "data").symlink_to(ROOT / "data")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    for k, (lang, body, excerpts) in enumerate(_steps(page)):
        rc, out = _run_step(lang, body, tmp_path)
        refused = any(x.lstrip().startswith("pinmsk: error:") for x in excerpts)
        assert rc == (2 if refused else 0), f"{page.name} step {k}: {body}\n{out}"
        for excerpt in excerpts:
            assert_excerpt(excerpt, out, f"{page.name} step {k} ({body.strip()[:60]}...)")


@pytest.mark.parametrize("name", FAST_PAGES)
def test_the_fast_pages_run_as_written(name, tmp_path, monkeypatch):
    run_page(DOCS / name, tmp_path, monkeypatch)


@pytest.mark.slow          # diagnoses and optimal-control solves, each a few seconds to minutes
@pytest.mark.parametrize("name", SLOW_PAGES)
def test_the_slow_pages_run_as_written(name, tmp_path, monkeypatch):
    run_page(DOCS / name, tmp_path, monkeypatch)


def test_every_runnable_page_has_steps_with_excerpts():
    """The pages the tests run have commands or scripts, and the commands' outputs are quoted."""
    for name in FAST_PAGES + SLOW_PAGES:
        steps = _steps(DOCS / name)
        assert any(lang == "sh" for lang, _, _ in steps), name
        assert all(excerpts for lang, _, excerpts in steps if lang == "sh"), name


def test_every_python_block_compiles_and_its_imports_exist():
    """The Python blocks the tests do not run (``py`` blocks, the README's later ones, the reference pages')
    compile, and every name they import exists, so a moved function cannot leave a page behind."""
    import ast
    import importlib

    checked = 0
    for page in _pages():
        for lang, body in _blocks(page):
            if lang not in ("python", "py"):
                continue
            tree = ast.parse(body, filename=str(page))
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module:
                    mod = importlib.import_module(node.module)
                    for alias in node.names:
                        assert hasattr(mod, alias.name) or importlib.util.find_spec(f"{node.module}.{alias.name}"), \
                            f"{page.relative_to(ROOT)}: from {node.module} import {alias.name}"
                elif isinstance(node, ast.Import):
                    for alias in node.names:
                        importlib.import_module(alias.name)
            checked += 1
    assert checked >= 8
