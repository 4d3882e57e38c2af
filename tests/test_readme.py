"""The README's Python walk-through runs and ends where it says it does."""
import os
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_readme_python_walkthrough_runs(capsys):
    text = (REPO / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "README has no python block"
    cwd = os.getcwd()
    os.chdir(REPO)
    try:
        ns = {}
        exec(compile(blocks[0], "README.md", "exec"), ns)
    finally:
        os.chdir(cwd)
    out = capsys.readouterr().out
    assert out.strip().endswith("at_noise_floor")
    labels = [c.label for c in ns["model"].components]
    assert labels == ["payload:hand", "joint_damping:elbow_flexion"]
    assert abs(ns["model"].components[0].values["mass"] - 0.5) < 0.05


SETUP = ('python3 -m venv .venv && . .venv/bin/activate && pip install . && pinmsk demo\n'
         'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && python -m pytest\n')


def test_readme_opens_with_the_two_setup_commands_ci_runs():
    """The README's first block is the two set-up commands, and .ci/run installs and tests as the second does."""
    text = (REPO / "README.md").read_text()
    first = re.search(r"```(\w*)\n(.*?)```", text, flags=re.S)
    assert first.group(1) == "bash" and first.group(2) == SETUP
    ci = (REPO / ".ci" / "run").read_text()
    assert 'python -m pip install -q -e ".[test]"' in ci
    assert ci.rstrip().splitlines()[-1].startswith("python -m pytest")


def test_readme_is_a_short_entrance():
    """Under 250 lines, no development-log wording and no measured figures (those are on docs/benchmarks.md),
    and every local link leads to a file."""
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) < 250
    for word in ("issue", "session", "this wave", "stop", "passed", "skipped"):
        assert not re.search(rf"\b{word}", text, flags=re.I), word
    assert not re.search(r"\b\d+(\.\d+)? ?(s|ms|min)\b", text), "a timing in the README"
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    local = [x for x in links if not x.startswith("http")]
    assert len(local) > 15
    for link in local:
        assert (REPO / link).exists(), link
