"""Examples write to a folder they are given, or to a new temporary one: never into the current folder unasked."""
import ast
import re
import sys
import tempfile
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
WRITES = re.compile(r"savefig|write_text|write_trial|save_diagnosis|contact_fit_figures|data_file_main|write_json")


def _common():
    sys.path.insert(0, str(EXAMPLES))
    try:
        import _common
        return _common
    finally:
        sys.path.remove(str(EXAMPLES))


def test_output_folder_is_the_given_one_or_a_new_temporary_one(tmp_path, monkeypatch, capsys):
    common = _common()
    monkeypatch.chdir(tmp_path)
    given = common.output_folder(tmp_path / "a" / "b", "x")
    assert given == tmp_path / "a" / "b" and given.is_dir()
    made = common.output_folder(None, "ex")
    try:
        assert made.is_dir() and made.name.startswith("pinmsk-ex-")
        assert made.parent == Path(tempfile.gettempdir()) and not list(made.iterdir())
        assert f"writing to {made}" in capsys.readouterr().out
        assert [p.name for p in tmp_path.iterdir()] == ["a"]          # nothing in the current folder
    finally:
        made.rmdir()


def test_every_writing_example_takes_its_folder_from_output_folder():
    writers = []
    for p in sorted(EXAMPLES.glob("*.py")):
        text = p.read_text()
        if p.name == "_common.py" or not WRITES.search(text):
            continue
        writers.append(p.name)
        calls = {n.func.id for n in ast.walk(ast.parse(text))
                 if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
        assert calls & {"output_folder", "data_file_main"}, f"{p.name} does not choose its folder by output_folder"
        # no default output of its own: "." or a relative folder
        assert not re.search(r"""else Path\("\."\)|"--out",[^)]*default=(Path\()?["'][^"']""", text), p.name
    assert len(writers) >= 12
