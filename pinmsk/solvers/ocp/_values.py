"""Equality by value for the engine's small problem objects (costs, constraints, controls, targets)."""
from __future__ import annotations

import numpy as np


def same(a, b) -> bool:
    """Equal values: arrays element-wise, containers item by item, objects by their attributes."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and bool(np.array_equal(a, b))
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    return a == b


class ValueEq:
    """Mixin: two instances are equal when they are of one type with equal public attributes
    (so a cloned fitter's costs and constraints equal the originals)."""

    def _public(self) -> dict:
        return {k: v for k, v in vars(self).items() if not k.startswith("_")}

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and same(self._public(), other._public())

    def __hash__(self) -> int:
        return hash(type(self).__name__)
