"""Lazy attributes of a package (PEP 562): public names imported from their submodule on first use.

``pinmsk`` uses it so that ``import pinmsk`` does not pay for Pinocchio and SciPy, and
``pinmsk.contact`` so that its physics imports no model while its identification does.
"""
from __future__ import annotations

import importlib
import importlib.util
import sys
from typing import Callable, Iterable, Mapping


def lazy_attributes(package: str, table: Mapping[str, str], public: Iterable[str]) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for ``package``.

    ``table`` maps a name to the submodule that defines it (imported when the name is
    first used, then kept in the package namespace); other non-private names that are
    submodules are imported as attributes, as they would be had the package imported them.
    """
    public = tuple(public)

    def __getattr__(name: str):
        module = table.get(name)
        if module is not None:
            value = getattr(importlib.import_module(f".{module}", package), name)
            vars(sys.modules[package])[name] = value          # later look-ups skip this function
            return value
        if not name.startswith("_") and importlib.util.find_spec(f"{package}.{name}") is not None:
            return importlib.import_module(f".{name}", package)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(public))

    return __getattr__, __dir__
