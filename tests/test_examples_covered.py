"""Every example script is run by some test (so examples cannot rot unnoticed)."""
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_every_example_is_run_by_a_test():
    tests = "\n".join(p.read_text() for p in (REPO / "tests").glob("test_*.py") if p.name != Path(__file__).name)
    scripts = sorted(p.name for p in (REPO / "examples").glob("*.py") if not p.name.startswith("_"))
    assert scripts, "no examples found"
    missing = [s for s in scripts if s not in tests and s[:-3] not in tests]
    assert not missing, f"examples no test runs: {missing}"
