"""File paths as a report shows them: relative to the working folder, never a machine's absolute path.

A report is read on other machines and shared; an absolute path tells its reader
nothing they can open and exposes the writer's folders.  :func:`shown_path`
writes one path relative to the current folder when it lies inside it, else as
its file name; :func:`portable_text` does the same to every occurrence of the
working folder, the installed package's folder and the home folder in a text.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

__all__ = ["shown_path", "portable_text"]


def shown_path(p) -> str:
    """``p`` relative to the current folder when inside it, else its file name; non-paths unchanged."""
    if p is None:
        return "-"
    s = str(p)
    if not os.path.isabs(s):
        return s
    path = Path(s)
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except (ValueError, OSError):
        return path.name or s


def _prefixes() -> list[tuple[str, str]]:
    """(absolute folder + separator, what replaces it), the longest first."""
    import pinmsk

    out = []
    cwd = os.getcwd()
    for folder in {cwd, os.path.realpath(cwd)}:
        out.append((folder.rstrip(os.sep) + os.sep, ""))
    pkg_parent = os.path.dirname(os.path.dirname(os.path.abspath(pinmsk.__file__)))
    for folder in {pkg_parent, os.path.realpath(pkg_parent)}:
        out.append((folder.rstrip(os.sep) + os.sep, ""))           # .../site-packages/pinmsk/... -> pinmsk/...
    home = os.path.expanduser("~")
    if home and home != os.sep:
        out.append((home.rstrip(os.sep) + os.sep, "~" + os.sep))
    return sorted({k: v for k, v in out if len(k) > 1}.items(), key=lambda kv: -len(kv[0]))


def portable_text(text: str) -> str:
    """``text`` with the working, package and home folders of absolute paths replaced
    (``<cwd>/a/b`` -> ``a/b``, ``<site-packages>/pinmsk/x`` -> ``pinmsk/x``, ``<home>/x`` -> ``~/x``)."""
    pairs = _prefixes()
    pattern = re.compile("|".join(re.escape(k) for k, _ in pairs))
    table = dict(pairs)
    return pattern.sub(lambda m: table[m.group(0)], text)
