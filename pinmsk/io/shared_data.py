"""Where the optional shared data lives (real trials, OpenSim example models and outputs).

The data are not shipped with pinmsk: they sit in ``../shared/data`` beside the
repository checkout, or wherever ``$PINMSK_SHARED_DATA`` points.  Examples,
benchmarks and tests that use them look the folder up here and skip (or exit
0) when it is absent.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["ENV_VAR", "shared_data_dir"]

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
