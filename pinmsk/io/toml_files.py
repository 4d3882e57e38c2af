"""Reading the project's TOML files (model sidecars, marker sets, batch configs, task files).

One place for the Python 3.10 fallback (``tomli``) and for the errors: a
missing file or invalid TOML raises ``error`` (a :class:`~pinmsk.errors.PinmskError`
subclass) naming the file and what it was meant to be; :func:`check_keys`
refuses unknown keys with a "did you mean".
"""
from __future__ import annotations

import difflib
import sys
from pathlib import Path

from ..errors import ModelError

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
        raise error(f"{p}: invalid TOML ({' '.join(str(exc).split())})") from None
    except UnicodeDecodeError as exc:
        raise error(f"{p}: invalid TOML (not UTF-8: byte {exc.object[exc.start]:#04x} at offset {exc.start})") from None


def check_keys(table, valid, *, where: str, section: str, error: type = ModelError) -> None:
    """Refuse keys of ``table`` not in ``valid``, naming the file, the table and a close match.

    ``where`` is the file (and entry), ``section`` the table as written (``[model]``,
    ``[[muscles]] 'BRD'``); ``valid`` any collection of key names.
    """
    if not isinstance(table, dict):
        raise error(f"{where}: {section} must be a table")
    for key in table:
        if key not in valid:
            close = difflib.get_close_matches(str(key), list(valid), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise error(f"{where}: unknown key '{key}' in {section}{hint}; valid keys: "
                        f"{', '.join(valid)}")
