"""Where data lives: the trials shipped with pinmsk, and the optional shared data.

Shipped trials (``data/`` in the repository, installed as ``pinmsk._data``):
:func:`shipped_trial`, :func:`shipped_trials`.  The optional shared data (real
trials, OpenSim example models and outputs): :func:`shared_data_dir`.

The data are not shipped with pinmsk: they sit in ``../shared/data`` beside the
repository checkout, or wherever ``$PINMSK_SHARED_DATA`` points.  Examples,
benchmarks and tests that use them look the folder up here and skip (or exit
0) when it is absent.
"""
from __future__ import annotations

import importlib.resources
import os
from pathlib import Path

from ..errors import TrialError

__all__ = ["ENV_VAR", "shared_data_dir", "shipped_data_dir", "shipped_trial", "shipped_trials"]

#: Environment variable naming the shared data folder (overrides ``../shared/data``).
ENV_VAR = "PINMSK_SHARED_DATA"


def shared_data_dir(*, required: bool = False) -> Path | None:
    """The shared data folder: ``$PINMSK_SHARED_DATA``, else ``../shared/data`` beside the checkout.

    Returns the folder if it exists, else ``None``; with ``required=True`` a
    missing folder raises :class:`FileNotFoundError` instead.
    """
    env = os.environ.get(ENV_VAR)
    cand = Path(env) if env else Path(__file__).resolve().parents[3] / "shared" / "data"
    if cand.is_dir():
        return cand
    if required:
        raise FileNotFoundError(f"shared data folder {cand} not found; set ${ENV_VAR} to the folder "
                                "holding real/ and opensim-models/ (see the examples' docstrings)")
    return None


def shipped_data_dir() -> Path:
    """The folder of the trials shipped with pinmsk (``pinmsk._data``, else ``data/`` of the checkout)."""
    try:
        d = Path(str(importlib.resources.files("pinmsk._data")))
        if d.is_dir():
            return d
    except (ModuleNotFoundError, TypeError):
        pass
    return Path(__file__).resolve().parents[2] / "data"


def shipped_trials() -> list[str]:
    """Names of the hidden-effect trials shipped in ``data/``."""
    return sorted(p.name for p in shipped_data_dir().glob("*.csv"))


def shipped_trial(name: str) -> Path:
    """Path of a shipped trial (see ``data/README.md`` for how each was made)."""
    p = shipped_data_dir() / name
    if not p.exists():
        raise TrialError(f"no shipped trial '{name}'; shipped: {', '.join(shipped_trials()) or 'none'}")
    return p
