"""Lazy re-exports for packages (PEP 562).

A package lists its public names and the submodule defining each; a name's
submodule is imported when the name is first used.  This keeps ``import pinmsk``
and ``pinmsk --help`` from paying for Pinocchio, SciPy and matplotlib until a
command needs them, without function-level imports in the code that uses them.
"""
from __future__ import annotations

import importlib
import importlib.util
from typing import Callable, Mapping


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict
                 ) -> tuple[Callable[[str], object], Callable[[], list]]:
    """``(__getattr__, __dir__)`` for ``package`` re-exporting ``exports`` (name -> submodule).

    Submodules of the package stay reachable as attributes (``pinmsk.io.tables``).
    A resolved name is stored in ``namespace`` so later look-ups skip the hook.
    """
    def __getattr__(name: str):
        module = exports.get(name)
        if module is not None:
            value = getattr(importlib.import_module(f"{package}.{module}"), name)
            namespace[name] = value
            return value
        if not name.startswith("_") and importlib.util.find_spec(f"{package}.{name}") is not None:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
