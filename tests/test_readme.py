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
