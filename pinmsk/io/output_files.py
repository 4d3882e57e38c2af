"""Output files: checks before a command runs, atomic writes and roll-back.

Every file pinmsk writes goes through :func:`atomic_write` (written to a temporary
file beside the target, then renamed), so an error never leaves a half-written
file; :func:`output_transaction` removes the files a failing command already
wrote.  :func:`check_output_file` / :func:`output_folder` test an output's folder
before the work starts.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import OutputError

__all__ = ["atomic_write", "write_json", "check_output_file", "output_folder", "output_transaction"]


#: Output transactions open in this process (innermost last); see :func:`output_transaction`.
_TRANSACTIONS: list[list[tuple[Path, bool]]] = []


def _folder_problem(folder: Path) -> str:
    """Why ``folder`` cannot hold an output (it, or a parent, is missing or a file)."""
    part = folder
    while not part.parent.exists() and part.parent != part:
        part = part.parent
    if part.exists():
        return f"{str(part)!r} is a file, not a folder"
    if not part.parent.is_dir():
        return f"{str(part.parent)!r} is a file, not a folder"
    return f"the folder {str(part)!r} does not exist; create it first (mkdir -p {folder})"


def _probe(folder: Path, what: str) -> None:
    """Create and remove a temporary file in ``folder``; OutputError if the OS refuses."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".pinmsk-probe.", dir=folder)
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise OutputError(f"cannot write {what}: {exc.strerror or exc}") from None


def check_output_file(path) -> Path:
    """Check, before any work, that a file can be written at ``path``; return it as a Path.

    The folder must exist (it is not created: a mistyped folder is an error)
    and accept a new file (a temporary file is created and removed, which also
    catches read-only file systems where permission bits do not tell);
    ``path`` must not be a folder.  Raises :class:`~pinmsk.errors.OutputError`
    naming the path and the missing or read-only folder.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"cannot write {str(path)!r}: it is a folder; give a file name")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise OutputError(f"cannot write {str(path)!r}: {_folder_problem(folder)}")
    _probe(folder, f"{str(path)!r} (folder {str(folder)!r})")
    return path


def output_folder(path) -> Path:
    """Create the output folder ``path`` (and its parents) if needed and check it is writable.

    Folders it creates are recorded in the open :func:`output_transaction`, so
    a failed command removes them again (when empty).  Raises
    :class:`~pinmsk.errors.OutputError` if a part of the path is a file or the
    folder does not accept files.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"cannot write in {str(path)!r}: it is a file, not a folder")
    created = []
    part = path
    while not part.exists() and part.parent != part:
        created.append(part)
        part = part.parent
    if not part.is_dir():
        raise OutputError(f"cannot write in {str(path)!r}: {_folder_problem(path)}")
    for d in reversed(created):
        try:
            d.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputError(f"cannot create the folder {str(d)!r}: {exc.strerror or exc}") from None
        _record(d, folder=True)
    _probe(path, f"in {str(path)!r}")
    return path


def _record(path: Path, *, folder: bool = False) -> None:
    if _TRANSACTIONS:
        _TRANSACTIONS[-1].append((path, folder))


@contextlib.contextmanager
def output_transaction():
    """Group the outputs of one command: if the block raises, the files written in it are removed.

    Every :func:`atomic_write` (trials, JSON, reports, figures) and every folder
    made by :func:`output_folder` inside the block is recorded; on any exception
    (including ``KeyboardInterrupt``) they are deleted, newest first (folders
    only when empty), so a command that fails leaves no partial set of
    outputs.  A file that existed before and was replaced in the block is
    deleted too (its old content is already gone).  Nested blocks hand their
    records to the enclosing one when they succeed.  Yields the list of
    ``(path, is_folder)`` records.
    """
    records: list[tuple[Path, bool]] = []
    _TRANSACTIONS.append(records)
    try:
        yield records
    except BaseException:
        for path, folder in reversed(records):
            with contextlib.suppress(OSError):
                path.rmdir() if folder else path.unlink()
        raise
    finally:
        _TRANSACTIONS.remove(records)
    if _TRANSACTIONS:
        _TRANSACTIONS[-1].extend(records)


def atomic_write(path, write, *, binary: bool = False, parents: bool = False) -> Path:
    """Call ``write(fh)`` on a temporary file next to ``path``, then move it over ``path``.

    ``fh`` is a text file (UTF-8, ``\\n`` line ends) or, with ``binary``, a binary
    one.  The folder must exist unless ``parents`` (then it is created).  On
    any error the temporary file is removed and an existing ``path`` is left
    as it was; a new file gets the permissions of any new file (umask), a
    replaced one keeps its own.  Errors of the file system are raised as
    :class:`~pinmsk.errors.OutputError` naming the path.  The path is recorded
    in the open :func:`output_transaction`.  Returns ``path`` as a Path.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if parents and not directory.exists():
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError:
            raise OutputError(f"cannot write {str(path)!r}: {_folder_problem(directory)}") from None
    if not directory.is_dir():
        raise OutputError(f"cannot write {str(path)!r}: {_folder_problem(directory)}")
    if path.is_dir():
        raise OutputError(f"cannot write {str(path)!r}: it is a folder")
    if path.exists():
        mode = path.stat().st_mode & 0o777
    else:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise OutputError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    try:
        try:
            fh = os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="\n")
        except BaseException:
            os.close(fd)
            raise
        with fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, OutputError):
            raise OutputError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from exc
        raise
    _record(path)
    return path


def _first_non_finite(obj, where: str = ""):
    """``(where, value)`` of the first float in ``obj`` (dicts, lists) that is NaN or infinite."""
    if isinstance(obj, float):
        return None if np.isfinite(obj) else (where or "the value", obj)
    if isinstance(obj, Mapping):
        items = ((f"{where}.{k}" if where else str(k), v) for k, v in obj.items())
    elif isinstance(obj, (list, tuple)):
        items = ((f"{where}[{i}]", v) for i, v in enumerate(obj))
    elif isinstance(obj, np.ndarray):
        return _first_non_finite(obj.tolist(), where)
    elif isinstance(obj, np.generic):
        return _first_non_finite(obj.item(), where)
    else:
        return None
    for key, value in items:
        found = _first_non_finite(value, key)
        if found is not None:
            return found
    return None


def write_json(path, obj, *, default=None, parents: bool = False) -> Path:
    """Write ``obj`` as indented JSON to ``path`` atomically (see :func:`atomic_write`).

    JSON has no NaN or Infinity: a non-finite number anywhere in ``obj`` is an
    :class:`~pinmsk.errors.OutputError` naming its key (``ranking[2].rmse_after``)
    and nothing is written.
    """
    bad = _first_non_finite(obj)
    if bad is not None:
        raise OutputError(f"refusing to write {str(path)!r}: {bad[0]} is {bad[1]!r}, and JSON has no "
                          "NaN or Infinity (a non-finite result upstream)")
    text = json.dumps(obj, indent=2, default=default, allow_nan=False)
    return atomic_write(path, lambda fh: fh.write(text), parents=parents)
