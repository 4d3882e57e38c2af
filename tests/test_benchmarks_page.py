"""docs/benchmarks.md is written by the benchmark scripts (benchmarks/_record.py): each script records its
output in its own section, with the command, the date and the machine."""
import importlib.util
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "benchmarks.md"


def _record():
    spec = importlib.util.spec_from_file_location("_record", ROOT / "benchmarks" / "_record.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_benchmark_records_into_its_section():
    page = PAGE.read_text()
    scripts = sorted((ROOT / "benchmarks").glob("bench_*.py"))
    assert len(scripts) > 10
    for script in scripts:
        text = script.read_text()
        assert re.search(r"from _record import run\n    (sys\.exit\(|raise SystemExit\()?run\(main\)", text), script.name
        assert f"<!-- begin {script.stem} -->" in page and f"<!-- end {script.stem} -->" in page, script.name


def test_a_run_replaces_only_its_own_section(tmp_path):
    rec = _record()
    page = tmp_path / "benchmarks.md"
    page.write_text("# Benchmarks\n\n<!-- begin bench_a -->\nold a\n<!-- end bench_a -->\n\n"
                    "<!-- begin bench_b -->\nold b\n<!-- end bench_b -->\n")
    rec.record("bench_a", "python benchmarks/bench_a.py", "x 1.0\n", page=page)
    text = page.read_text()
    assert "old a" not in text and "old b" in text
    block = text[text.index("<!-- begin bench_a -->"):text.index("<!-- end bench_a -->")]
    assert "`python benchmarks/bench_a.py`" in block and "```text\nx 1.0\n```" in block
    assert re.search(r"Last run \d{4}-\d\d-\d\d \d\d:\d\d UTC", block)
    assert "Machine: " in block and "Python " in block and "logical CPUs" in block
    rec.record("bench_c", "python benchmarks/bench_c.py", "y\n", page=page)      # a new section is appended
    assert page.read_text().rstrip().endswith("<!-- end bench_c -->")


def test_no_record_and_quick_runs_leave_the_page_alone(tmp_path, monkeypatch):
    rec = _record()
    page = tmp_path / "benchmarks.md"
    page.write_text("# Benchmarks\n")
    monkeypatch.setattr(rec, "PAGE", page)
    monkeypatch.delenv(rec.ENV, raising=False)
    seen = []
    for flag in ("--no-record", "--quick"):
        monkeypatch.setattr(sys, "argv", ["benchmarks/bench_x.py", flag])
        assert rec.run(lambda: seen.append(list(sys.argv[1:])) or 0) == 0
        assert page.read_text() == "# Benchmarks\n"
    assert seen == [[], ["--quick"]]                # --no-record is taken off before main reads it
    monkeypatch.setattr(sys, "argv", ["benchmarks/bench_x.py"])
    assert rec.run(lambda: 3) == 3                  # a failed run is not recorded
    assert page.read_text() == "# Benchmarks\n"
    monkeypatch.delenv(rec.ENV, raising=False)
    rec.run(lambda: print("z 2.0"))
    assert "<!-- begin bench_x -->" in page.read_text() and "z 2.0" in page.read_text()
