"""The generated pages of docs/ are current: the command-line reference (every parser of
``pinmsk/presentation/cli.py``) and the task-file and sidecar key tables of the formats reference."""
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _gen():
    spec = importlib.util.spec_from_file_location("gen_cli", ROOT / "docs" / "gen_cli.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_generated_pages_are_current():
    for path, text in _gen().outputs().items():
        assert path.read_text() == text, (f"{path.relative_to(ROOT)} is not current: run "
                                          f"python docs/gen_cli.py")


def test_the_cli_page_has_every_command():
    from pinmsk.presentation.cli import build_parser

    gen = _gen()
    page = (ROOT / "docs" / "cli.md").read_text()
    names = [name for name, _ in gen._subparsers(build_parser())]
    assert len(names) > 15
    for name in names:
        assert f"## pinmsk {name}\n" in page
    assert "## pinmsk contact fit\n" in page


def test_a_block_is_replaced_and_a_missing_one_named():
    gen = _gen()
    text = "a\n<!-- begin x -->\nold\n<!-- end x -->\nb\n"
    assert gen.fill(text, {"x": "new\n"}) == "a\n<!-- begin x -->\nnew\n<!-- end x -->\nb\n"
    try:
        gen.fill("nothing", {"x": "new\n"})
    except SystemExit as exc:
        assert "begin x" in str(exc)
    else:
        raise AssertionError("a page without the block was filled")
