"""Reading the project's TOML files (model sidecars, marker sets, batch configs, task files).

One place for the Python 3.10 fallback (``tomli``) and for the errors: a
missing file or invalid TOML raises ``error`` (a :class:`~pinmsk.errors.PinmskError`
subclass) naming the file and what it was meant to be.
"""
from __future__ import annotations

import sys
from pathlib import Path

from .errors import ModelError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def read_toml(path, *, what: str = "TOML file", error: type = ModelError) -> dict:
    """Parse the TOML file at ``path``; ``error`` names the file if it is missing or invalid."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise error(f"{what} not found: {p}") from None
    except IsADirectoryError:
        raise error(f"{what} {p} is a folder, not a file") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{p}: invalid TOML ({exc})") from None
