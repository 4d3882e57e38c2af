"""The table ``pinmsk models`` prints: one row per built-in model, columns aligned to the longest name,
descriptions cut to the line width with an ellipsis."""
from __future__ import annotations

import shutil

__all__ = ["models_table", "shorten"]


def shorten(text: str, width: int) -> str:
    """``text`` on one line of at most ``width`` characters: cut at a word where possible, ending in
    ``...`` when anything was left out."""
    text = " ".join(str(text).split())
    if len(text) <= width:
        return text
    room = max(width - 3, 1)
    cut = text[:room]
    if " " in cut[room // 2:]:                       # end at a word, unless that loses half the line
        cut = cut[:cut.rindex(" ")]
    return cut.rstrip(" ,;:(") + "..."


def models_table(rows, width: int | None = None) -> list[str]:
    """Lines of the table of ``rows`` ``(name, dof, muscles, description)`` (dof / muscles may be ``"?"``),
    at most ``width`` characters each (default: the terminal's width, 100 when not a terminal)."""
    if width is None:
        width = shutil.get_terminal_size((100, 24)).columns
    rows = list(rows)
    name_w = max([len("model")] + [len(r[0]) for r in rows])
    head = f"{'model':<{name_w}} {'dof':>4} {'muscles':>8}  "
    room = max(width - len(head), 20)
    out = [head + "description"]
    for name, dof, muscles, description in rows:
        out.append(f"{name:<{name_w}} {dof!s:>4} {muscles!s:>8}  {shorten(description, room)}")
    return out
