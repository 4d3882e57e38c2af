"""Write the generated parts of the documentation from the code.

    python docs/gen_cli.py            # rewrite them
    python docs/gen_cli.py --check    # exit 1 if any is not current (tests/test_docs_reference.py)

* ``docs/cli.md``: every command's ``--help``, from the argparse parsers of
  :func:`pinmsk.presentation.cli.build_parser`, at a fixed width of 100 columns;
* the tables of ``docs/reference/formats.md`` between ``<!-- begin NAME -->`` and
  ``<!-- end NAME -->``: the task-file keys (:data:`pinmsk.solvers.ocp.tasks.TASK_SCHEMA`) and the
  model sidecar's keys (:data:`pinmsk.model.SIDECAR_SCHEMA`).
"""
from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
WIDTH = "100"


def _subparsers(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices.items())
    return []


def _help(parser: argparse.ArgumentParser) -> str:
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = WIDTH          # argparse's formatter reads the width when it is made
    try:
        return parser.format_help().rstrip() + "\n"
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old


def cli_page() -> str:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from pinmsk.presentation.cli import build_parser

    top = build_parser()
    top.prog = "pinmsk"
    out = ["# Command line", "",
           "Every `pinmsk` command and its options, as `pinmsk COMMAND --help` prints them. This page is",
           "generated from the parsers in `pinmsk/presentation/cli.py` by `python docs/gen_cli.py`; do not edit it.",
           "", "```text", _help(top).rstrip(), "```", ""]

    def walk(parser, path):
        for name, sub in _subparsers(parser):
            full = f"{path} {name}"
            inner = _subparsers(sub)
            out.extend([f"## {full}", "", "```text", _help(sub).rstrip(), "```", ""])
            if inner:
                walk(sub, full)

    walk(top, "pinmsk")
    return "\n".join(out)


def _table(schema: dict, what: str) -> str:
    rows = [f"| section | key | {what} |", "|---|---|---|"]
    for section, keys in schema.items():
        if not isinstance(keys, dict):
            rows.append(f"| `{section}` | | {_cell(keys) if keys else 'the entry’s own keys (see below)'} |")
            continue
        for key, doc in keys.items():
            rows.append(f"| `[{section}]` | `{key}` | {_cell(doc)} |")
    return "\n".join(rows) + "\n"


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def tables() -> dict[str, str]:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from pinmsk.model import SIDECAR_SCHEMA
    from pinmsk.solvers.ocp.tasks import TASK_SCHEMA

    return {"task-keys": _table(TASK_SCHEMA, "meaning"), "sidecar-keys": _table(SIDECAR_SCHEMA, "meaning")}


def fill(text: str, blocks: dict[str, str]) -> str:
    """``text`` with each ``<!-- begin NAME -->...<!-- end NAME -->`` block replaced by ``blocks[NAME]``."""
    for name, body in blocks.items():
        pattern = re.compile(rf"(<!-- begin {re.escape(name)} -->\n).*?(<!-- end {re.escape(name)} -->)", re.S)
        if not pattern.search(text):
            raise SystemExit(f"docs/gen_cli.py: no '<!-- begin {name} -->' block in the page")
        text = pattern.sub(lambda m: m.group(1) + body + m.group(2), text)
    return text


def outputs() -> dict[Path, str]:
    """Each generated file and the text it must hold."""
    formats = DOCS / "reference" / "formats.md"
    return {DOCS / "cli.md": cli_page(), formats: fill(formats.read_text(), tables())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check that the files are current")
    args = ap.parse_args(argv)
    stale = []
    for path, text in outputs().items():
        if path.is_file() and path.read_text() == text:
            continue
        stale.append(path)
        if not args.check:
            path.write_text(text)
            print(f"wrote {path.relative_to(ROOT)}")
    if args.check and stale:
        print("not current: " + ", ".join(str(p.relative_to(ROOT)) for p in stale) + "; run python docs/gen_cli.py")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
