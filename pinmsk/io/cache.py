"""The import cache: what an expensive import made, kept on disk between processes.

An entry is one file ``<kind>-<key>.pkl`` in the cache folder, keyed by the content that made it
(the caller's :func:`key`: for an OpenSim import, the ``.osim`` bytes, the files it references, the
import options and pinmsk's own code).  A file holds a header (format, kind, key, the payload's
digest) and the pickled payload; an entry whose header or digest does not match, or that does not
unpickle, is deleted and reported as absent (:func:`load` returns None), so the caller builds it
again: a corrupt or foreign entry is never used.  Writes go to a temporary file renamed into place,
so a reader never sees half an entry; a cache folder that cannot be written is skipped silently
(the cache only saves time).

The folder is ``$PINMSK_CACHE_DIR`` if set, else the platform's user cache folder (as platformdirs
places it: ``$XDG_CACHE_HOME/pinmsk`` or ``~/.cache/pinmsk`` on Linux, ``~/Library/Caches/pinmsk`` on
macOS, ``%LOCALAPPDATA%\\pinmsk\\Cache`` on Windows).  ``PINMSK_NO_CACHE=1`` turns the cache off.
Entries are pickles: the cache folder must be one only its user can write (as the default is).
"""
from __future__ import annotations

import hashlib
import os
import pickle
import sys
from pathlib import Path

__all__ = ["CACHE_DIR_VARIABLE", "NO_CACHE_VARIABLE", "cache_dir", "key", "load", "store", "code_fingerprint"]

#: Environment variable naming the cache folder.
CACHE_DIR_VARIABLE = "PINMSK_CACHE_DIR"
#: Environment variable that turns the cache off (``1``, ``true``, ``yes``).
NO_CACHE_VARIABLE = "PINMSK_NO_CACHE"
_MAGIC = b"pinmsk-cache 1\n"


def cache_dir() -> Path | None:
    """The cache folder (not created here), or None if ``PINMSK_NO_CACHE`` turns the cache off."""
    if os.environ.get(NO_CACHE_VARIABLE, "").strip().lower() in ("1", "true", "yes", "on"):
        return None
    given = os.environ.get(CACHE_DIR_VARIABLE, "").strip()
    if given:
        return Path(given).expanduser()
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
        return base / "pinmsk" / "Cache"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "pinmsk"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "pinmsk"


def key(*parts) -> str:
    """The key (hex digest) of ``parts``: bytes as they are, anything else by its ``repr``."""
    h = hashlib.blake2b(digest_size=20)
    for part in parts:
        b = part if isinstance(part, (bytes, bytearray)) else repr(part).encode()
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)
    return h.hexdigest()


def _file(kind: str, k: str) -> Path | None:
    folder = cache_dir()
    return None if folder is None else folder / f"{kind}-{k}.pkl"


def load(kind: str, k: str):
    """The payload stored under ``kind`` and key ``k``, or None (absent, cache off, or not sound: deleted)."""
    path = _file(kind, k)
    if path is None:
        return None
    try:
        data = path.read_bytes()
    except OSError:
        return None
    head = _MAGIC + f"{kind} {k} ".encode()
    try:
        if not data.startswith(head):
            raise ValueError("not this entry")
        digest, payload = data[len(head):].split(b"\n", 1)
        if hashlib.blake2b(payload, digest_size=20).hexdigest().encode() != digest:
            raise ValueError("digest")
        return pickle.loads(payload)
    except Exception:         # any damage (truncation, another version's classes): rebuilt by the caller
        try:
            path.unlink()
        except OSError:
            pass
        return None


def store(kind: str, k: str, payload) -> Path | None:
    """Store ``payload`` under ``kind`` and key ``k``; the file written, or None (cache off, or not writable)."""
    path = _file(kind, k)
    if path is None:
        return None
    try:
        data = pickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:         # a payload that does not pickle is simply not cached
        return None
    blob = _MAGIC + f"{kind} {k} ".encode() + hashlib.blake2b(data, digest_size=20).hexdigest().encode() + b"\n" + data
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(blob)
        os.replace(tmp, path)
    except OSError:
        if tmp is not None:
            try:
                tmp.unlink()
            except OSError:
                pass
        return None
    return path


_FINGERPRINT: list = []


def code_fingerprint() -> str:
    """A digest of pinmsk's version and its source files (names, sizes, modification times): a changed
    pinmsk, installed or edited, makes new keys."""
    if not _FINGERPRINT:
        root = Path(__file__).resolve().parents[1]
        parts = [getattr(sys.modules.get("pinmsk"), "__version__", "")]
        for p in sorted(root.rglob("*.py")):
            try:
                st = p.stat()
            except OSError:
                continue
            parts.append(f"{p.relative_to(root).as_posix()} {st.st_size} {st.st_mtime_ns}")
        _FINGERPRINT.append(key(*parts))
    return _FINGERPRINT[0]
