"""Components: things that add generalized forces to a skeleton.

A component (a muscle set, an effect such as joint damping or a held
payload, a contact sphere) declares named :class:`Parameter` s with default,
bounds and unit, and a *target* (a coordinate, a body/frame, or a muscle).
Its core is one function vectorised over frames::

    component.generalized_force(model, motion, params=None, cache=None) -> (N, nv)

returning the generalized force the component applies to the system (so joint
damping returns ``-c * v``).  The equation of motion reads

    M(q) a + h(q, v) = tau_actuators + sum_k Q_k(q, v, a, t) + J^T f_ext,

so inverse dynamics of a model with components subtracts their sum.  The same
object serves forward simulation, inverse dynamics, the QPs and the diagnosis.
Parameter-independent work (Jacobians, regressors) goes into ``prepare`` and is
passed back as ``cache`` so fitting a parameter does not repeat it.

Components are immutable: :meth:`Component.with_params` returns a copy.
"""
from __future__ import annotations

import copy
import difflib
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Mapping

import numpy as np

from .errors import ModelError


@dataclass(frozen=True)
class Parameter:
    """A named, bounded physical parameter of a component (SI units)."""

    name: str
    value: float
    min: float = -math.inf
    max: float = math.inf
    unit: str = ""
    doc: str = ""
    vary: bool = True
    stderr: float | None = None

    def check(self, owner: str) -> None:
        if not np.isfinite(self.value):
            raise ModelError(f"{owner}: parameter '{self.name}' is {self.value}; it must be finite")
        if not (self.min <= self.value <= self.max):
            raise ModelError(
                f"{owner}: parameter '{self.name}' = {self.value:g} {self.unit} is outside its "
                f"bounds [{self.min:g}, {self.max:g}]"
            )


@dataclass(frozen=True)
class Motion:
    """Motion of a model over a trial, time-first and in SI units.

    ``q, v, a`` are ``(N, nv)``; ``t`` is ``(N,)``.  ``signals`` holds other
    measured channels a component may need (excitations, EMG, ground reaction
    forces), each ``(N,)``, keyed by channel name.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    signals: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return self.q.shape[0]

    def __post_init__(self):
        for name in ("t", "q", "v", "a"):
            arr = np.ascontiguousarray(np.asarray(getattr(self, name), dtype=float))
            object.__setattr__(self, name, arr)
        if self.q.ndim != 2 or self.v.shape != self.q.shape or self.a.shape != self.q.shape:
            raise ModelError(
                f"Motion: q, v, a must all be (N, nv); got {self.q.shape}, {self.v.shape}, {self.a.shape}"
            )
        if self.t.shape != (self.q.shape[0],):
            raise ModelError(f"Motion: t must be ({self.q.shape[0]},); got {self.t.shape}")

    def signal(self, name: str) -> np.ndarray:
        try:
            return np.asarray(self.signals[name], dtype=float)
        except KeyError:
            close = difflib.get_close_matches(name, list(self.signals), n=3)
            hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise ModelError(f"the trial has no channel '{name}'{hint}") from None

    def subset(self, index) -> "Motion":
        """The frames selected by ``index`` (a slice or an index array)."""
        return Motion(
            self.t[index], self.q[index], self.v[index], self.a[index],
            {k: np.asarray(s)[index] for k, s in self.signals.items()},
        )


class Component:
    """Base class of muscles, effects and contacts.

    Subclasses set ``family`` (registry name), ``kind`` (``"effect"``,
    ``"muscle"`` or ``"contact"``), ``target_kind`` (``"coordinate"``,
    ``"frame"``, ``"body"``, ``"muscle"``, ``"model"``) and ``parameters`` (a
    tuple of :class:`Parameter` declarations with defaults and bounds), and
    implement :meth:`generalized_force`.
    """

    family: ClassVar[str] = "component"
    kind: ClassVar[str] = "effect"
    target_kind: ClassVar[str] = "coordinate"
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: True where Q is linear in the parameter vector (then fits are exact LS).
    linear: ClassVar[bool] = False
    #: True for components that change the skeleton's inertia (a payload, a
    #: segment-mass correction): their Q depends on the acceleration, so forward
    #: dynamics folds them into a copy of the Pinocchio model via apply_inertia.
    inertial: ClassVar[bool] = False

    def __init__(self, target: str | None = None, **values: float):
        self.target = target
        declared = {p.name: p for p in self.parameters}
        unknown = set(values) - set(declared)
        if unknown:
            raise ModelError(
                f"{self.family}: unknown parameter(s) {sorted(unknown)}; it has {sorted(declared)}"
            )
        params = {}
        for name, decl in declared.items():
            p = decl if name not in values else _replace(decl, value=float(values[name]))
            p.check(self.label)
            params[name] = p
        self._params = params

    # -- parameters -------------------------------------------------------
    @property
    def label(self) -> str:
        """``family:target``, the name the component goes by in reports."""
        return f"{self.family}:{self.target}" if self.target else self.family

    @property
    def params(self) -> dict[str, Parameter]:
        return dict(self._params)

    @property
    def values(self) -> dict[str, float]:
        return {k: p.value for k, p in self._params.items()}

    def param_vector(self) -> np.ndarray:
        return np.array([p.value for p in self._params.values()], dtype=float)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.array([p.min for p in self._params.values()], dtype=float)
        hi = np.array([p.max for p in self._params.values()], dtype=float)
        return lo, hi

    def with_params(self, values: Mapping[str, float] | None = None, *,
                    stderr: Mapping[str, float] | None = None, **kw: float) -> "Component":
        """A copy with new parameter values (and optional standard errors)."""
        values = {**(values or {}), **kw}
        new = copy.copy(self)
        params = dict(self._params)
        for name, val in values.items():
            if name not in params:
                raise ModelError(f"{self.label}: no parameter '{name}'; it has {sorted(params)}")
            params[name] = _replace(params[name], value=float(val))
            params[name].check(self.label)
        for name, err in (stderr or {}).items():
            params[name] = _replace(params[name], stderr=float(err))
        new._params = params
        return new

    def with_vector(self, x: np.ndarray) -> "Component":
        return self.with_params(dict(zip(self._params, np.asarray(x, dtype=float))))

    # -- physics ----------------------------------------------------------
    def check_target(self, model) -> None:
        """Raise ModelError if the target does not exist in ``model``."""
        if self.target_kind == "coordinate":
            model.coordinate_index(self.target)
        elif self.target_kind in ("frame", "body"):
            model.frame_id(self.target)

    def apply_inertia(self, model, pin_model) -> None:
        """Add this component's inertia to ``pin_model`` (a copy); inertial components only."""
        raise ModelError(f"{self.label} does not change the skeleton's inertia")

    def prepare(self, model, motion: Motion) -> Any:
        """Parameter-independent precomputation for ``motion`` (default: none)."""
        return None

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        """Generalized force ``(N, nv)`` this component applies to the model."""
        raise NotImplementedError

    def _p(self, params: Mapping[str, float] | None) -> dict[str, float]:
        out = self.values
        if params:
            out.update(params)
        return out

    def __repr__(self) -> str:
        vals = ", ".join(f"{k}={p.value:.4g}" for k, p in self._params.items())
        return f"{type(self).__name__}({self.target!r}, {vals})"

    def __eq__(self, other) -> bool:
        return (type(self) is type(other) and self.target == other.target
                and self.values == other.values)

    def __hash__(self) -> int:
        return hash((type(self).__name__, self.target, tuple(self.values.items())))


def _replace(p: Parameter, **kw) -> Parameter:
    d = dict(p.__dict__)
    d.update(kw)
    return Parameter(**d)

