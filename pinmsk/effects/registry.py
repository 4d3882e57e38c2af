"""The effect registry: every effect family by name, for sidecars, the CLI and the diagnosis catalog.

Register a user effect with the :func:`register` decorator on a
:class:`pinmsk.components.Component` subclass whose ``family`` is unique::

    from pinmsk.effects import register
    from pinmsk.components import Component, Parameter

    @register
    class LinearDrag(Component):
        family = "linear_drag"
        target_kind = "coordinate"
        parameters = (Parameter("c", 0.1, 0.0, 10.0, "N m s/rad", "drag coefficient"),)
        def generalized_force(self, model, motion, params=None, cache=None):
            ...
"""
from __future__ import annotations

import difflib
import inspect

from ..errors import ModelError
from ..io.toml_files import check_keys

_REGISTRY: dict[str, type] = {}


def register(cls):
    """Class decorator adding an effect family to the registry (names must be unique)."""
    fam = getattr(cls, "family", None)
    if not fam or fam == "component":
        raise ModelError(f"{cls.__name__}: set a class attribute 'family' before registering it")
    if fam in _REGISTRY and _REGISTRY[fam] is not cls:
        raise ModelError(f"effect family '{fam}' is already registered by {_REGISTRY[fam].__name__}")
    _REGISTRY[fam] = cls
    return cls


def get(family: str) -> type:
    """The effect class registered under ``family`` (ModelError listing what exists)."""
    try:
        return _REGISTRY[family]
    except KeyError:
        close = difflib.get_close_matches(family, list(_REGISTRY), n=3)
        hint = f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""
        raise ModelError(
            f"unknown effect '{family}'{hint}; known effects: {', '.join(sorted(_REGISTRY))}"
        ) from None


def families() -> list[str]:
    """Names of all registered effect families, sorted."""
    return sorted(_REGISTRY)


def from_spec(spec: dict, *, where: str = "[[effects]]"):
    """Build an effect from a sidecar ``[[effects]]`` table: ``type``, optional ``target``, parameters.

    Keys other than ``type``, ``target``, ``params``, the effect's keyword options and its
    parameter names are refused with a "did you mean" (``where`` names the entry).
    """
    spec = dict(spec)
    try:
        family = spec.pop("type")
    except KeyError:
        raise ModelError(f"{where}: an [[effects]] entry has no 'type': {spec}") from None
    cls = get(family)
    options = [n for n, p in inspect.signature(cls.__init__).parameters.items()
               if p.kind is inspect.Parameter.KEYWORD_ONLY]
    declared = cls.parameters_for(spec.get("target")) if hasattr(cls, "parameters_for") else cls.parameters
    check_keys(spec, ["target", "params", *options, *(p.name for p in declared)], where=where,
               section=f"an effect of type '{family}'")
    target = spec.pop("target", None)
    params = spec.pop("params", {})
    return cls(target, **params, **spec)
