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
object serves forward simulation, inverse dynamics, the QPs and the diagnosis;
``component.generalized_force_at(model, q, v) -> (nv,)`` evaluates the same law
at one state on numpy or CasADi (:mod:`pinmsk.backend`), for the
optimal-control engine (components without a closed form in ``(q, v)`` refuse
by name).
Parameter-independent work (Jacobians, regressors) goes into
``prepare(model, motion, data=None)`` and is passed back as ``cache`` so fitting a
parameter does not repeat it; ``data`` is a workspace the caller owns
(:meth:`pinmsk.Model.create_data`), which shares kinematics between the
components prepared on one motion.  The force law itself stays a pure function
of arrays and parameter values.

Components are immutable: attributes cannot be assigned, and
:meth:`Component.with_params` (values, bounds, ``vary``), :meth:`Component.fix`
and :meth:`Component.free` return copies.  :class:`Parameters` is a read-only
table of parameters (``pinmsk.Model.parameters`` lists every parameter of a model).
"""
from __future__ import annotations

import copy
import difflib
import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, Iterable, Iterator, Mapping

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


class ParameterKeyError(ModelError, KeyError):
    """No parameter of that name (a :class:`ModelError` and, for mappings, a ``KeyError``)."""

    def __str__(self) -> str:           # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class Parameters(Mapping):
    """A read-only, ordered table of :class:`Parameter` s by name (lmfit's ``Parameters``, frozen).

    ``pinmsk.Model.parameters`` is one of these, with names prefixed by the
    component that owns them (``joint_damping:elbow_flexion.c``,
    ``hypervolumetric:heel_r.k_h``, ``muscle:BIClong.f_max``).  :meth:`fix`,
    :meth:`free` and :meth:`with_values` return new tables; a model takes one
    back with ``model.with_parameters(table)``.
    """

    __slots__ = ("_table",)

    def __init__(self, parameters: Iterable[Parameter] = ()):
        table = {}
        for p in parameters:
            if p.name in table:
                raise ModelError(f"parameter '{p.name}' appears twice")
            table[p.name] = p
        object.__setattr__(self, "_table", table)

    def __setattr__(self, key, value):
        raise AttributeError("Parameters is read-only; use fix(), free() or with_values(), "
                             "which return a new table")

    def __getitem__(self, name: str) -> Parameter:
        try:
            return self._table[name]
        except KeyError:
            raise ParameterKeyError(_unknown(name, self._table, "parameter")) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._table)

    def __len__(self) -> int:
        return len(self._table)

    def __eq__(self, other) -> bool:
        return isinstance(other, Parameters) and list(self._table.values()) == list(other._table.values())

    __hash__ = None

    def __reduce__(self):
        return (Parameters, (tuple(self._table.values()),))

    def valuesdict(self) -> dict[str, float]:
        """``{name: value}`` (as lmfit's ``Parameters.valuesdict``)."""
        return {k: p.value for k, p in self._table.items()}

    @property
    def free_names(self) -> tuple[str, ...]:
        """Names of the parameters a fit may change (``vary=True``)."""
        return tuple(k for k, p in self._table.items() if p.vary)

    def _changed(self, names, **kw) -> "Parameters":
        table = dict(self._table)
        for n in names:
            table[n] = _replace(self[n], **kw)
        return Parameters(table.values())

    def fix(self, *names: str) -> "Parameters":
        """A copy with ``names`` fixed (``vary=False``)."""
        return self._changed(names, vary=False)

    def free(self, *names: str) -> "Parameters":
        """A copy with ``names`` free (``vary=True``)."""
        return self._changed(names, vary=True)

    def with_values(self, values: Mapping[str, float] | None = None, **kw: float) -> "Parameters":
        """A copy with new values (checked against the bounds)."""
        table = dict(self._table)
        for n, v in {**(values or {}), **kw}.items():
            table[n] = _replace(self[n], value=float(v))
            table[n].check("Parameters")
        return Parameters(table.values())

    def pretty(self) -> str:
        """The table as text: name, value, min, max, vary, unit (and stderr where known)."""
        rows = [("name", "value", "min", "max", "vary", "unit", "stderr")]
        for p in self._table.values():
            rows.append((p.name, f"{p.value:.6g}", f"{p.min:.4g}", f"{p.max:.4g}", str(p.vary), p.unit,
                         "" if p.stderr is None else f"{p.stderr:.3g}"))
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)

    def __repr__(self) -> str:
        return f"<Parameters: {len(self)} ({len(self.free_names)} free)>"


def _unknown(name, known, what: str) -> str:
    close = difflib.get_close_matches(str(name), list(known), n=3)
    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
    return f"no {what} '{name}'{hint}"


def _read_only(x) -> np.ndarray:
    """A read-only float copy of ``x`` (C order); ``x`` itself when it is one already (a read-only float
    array in C order that owns its data: no other view can write to it)."""
    if (isinstance(x, np.ndarray) and x.dtype == np.float64 and x.flags.c_contiguous and not x.flags.writeable
            and x.flags.owndata):
        return x
    arr = np.array(x, dtype=float, order="C")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class Motion:
    """Motion of a model over a trial, time-first and in SI units.

    ``q, v, a`` are ``(N, nv)``; ``t`` is ``(N,)``.  ``signals`` holds other
    measured channels a component may need (excitations, EMG, ground reaction
    forces), each ``(N,)``, keyed by channel name.

    A Motion is immutable: its arrays are read-only copies and ``signals`` a
    read-only mapping, so a :class:`pinmsk.model.Data` may cache kinematics
    computed from it by its identity.
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
            object.__setattr__(self, name, _read_only(getattr(self, name)))
        object.__setattr__(self, "signals", MappingProxyType(
            {k: _read_only(s) for k, s in dict(self.signals).items()}))
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

    def __reduce__(self):
        return (Motion, (self.t, self.q, self.v, self.a, dict(self.signals)))


def vec3(x, what: str, owner: str) -> tuple[float, float, float]:
    """``x`` as three finite floats (a point, a normal), else a ModelError naming ``owner``'s ``what``."""
    try:
        out = tuple(float(v) for v in np.asarray(x, dtype=float).reshape(-1))
    except (TypeError, ValueError):
        raise ModelError(f"{owner}: {what} must be 3 numbers, got {x!r}") from None
    if len(out) != 3 or not all(math.isfinite(v) for v in out):
        raise ModelError(f"{owner}: {what} must be 3 finite numbers, got {x!r}")
    return out


class _Frozen(type):
    """Metaclass of :class:`Component`: instances become read-only once constructed."""

    def __call__(cls, *args, **kwargs):
        obj = super().__call__(*args, **kwargs)
        obj.__dict__["_frozen"] = True
        return obj


class Component(metaclass=_Frozen):
    """Base class of muscles, effects and contacts.

    Subclasses set ``family`` (registry name), ``kind`` (``"effect"``,
    ``"muscle"`` or ``"contact"``), ``target_kind`` (``"coordinate"``,
    ``"frame"``, ``"body"``, ``"muscle"``, ``"model"``) and ``parameters`` (a
    tuple of :class:`Parameter` declarations with defaults and bounds), and
    implement :meth:`generalized_force`.  Their ``__init__`` may set attributes;
    once it returns the instance is read-only (assignment raises
    ``AttributeError``), as a :class:`pinmsk.Model` is.
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

    # -- immutability -----------------------------------------------------
    def __setattr__(self, key, value):
        if self.__dict__.get("_frozen"):
            raise AttributeError(
                f"{type(self).__name__} '{self.label}' is immutable (cannot set '{key}'); build a new one, "
                "or use with_params(...), fix(...) or free(...), which return a copy")
        object.__setattr__(self, key, value)

    def __delattr__(self, key):
        if self.__dict__.get("_frozen"):
            raise AttributeError(f"{type(self).__name__} '{self.label}' is immutable (cannot delete '{key}')")
        object.__delattr__(self, key)

    def _evolve(self, params: dict[str, Parameter]) -> "Component":
        """A copy with the parameter table ``params`` (already checked)."""
        new = copy.copy(self)
        new.__dict__["_params"] = params
        return new

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
                    stderr: Mapping[str, float] | None = None, vary: Mapping[str, bool] | None = None,
                    bounds: Mapping[str, tuple[float, float]] | None = None, **kw: float) -> "Component":
        """A copy with new parameter values, and optionally standard errors, ``vary`` flags
        (False: a fit keeps the parameter at its value) and bounds ``{name: (lo, hi)}``.

        The values are checked against the (new) bounds once everything is applied.
        """
        values = {**(values or {}), **kw}
        params = dict(self._params)
        for what, changes in (("values", values), ("stderr", stderr), ("vary", vary), ("bounds", bounds)):
            for name in changes or ():
                if name not in params:
                    where = "" if what == "values" else f" (in {what}=)"
                    raise ModelError(f"{self.label}: no parameter '{name}'{where}; it has {sorted(params)}")
        for name, (lo, hi) in (bounds or {}).items():
            lo, hi = float(lo), float(hi)
            if not lo <= hi:
                raise ModelError(f"{self.label}: bounds for '{name}' are [{lo:g}, {hi:g}]; lower > upper")
            params[name] = _replace(params[name], min=lo, max=hi)
        for name, val in values.items():
            params[name] = _replace(params[name], value=float(val))
        for name, flag in (vary or {}).items():
            params[name] = _replace(params[name], vary=bool(flag))
        for name, err in (stderr or {}).items():
            params[name] = _replace(params[name], stderr=float(err))
        for name in {*values, *(bounds or {})}:
            params[name].check(self.label)
        return self._evolve(params)

    def fix(self, *names: str) -> "Component":
        """A copy in which a fit keeps ``names`` at their values (``vary=False``)."""
        return self.with_params(vary={n: False for n in names})

    def free(self, *names: str) -> "Component":
        """A copy in which a fit may change ``names`` (``vary=True``)."""
        return self.with_params(vary={n: True for n in names})

    def parameter_table(self, prefix: str | None = None) -> Parameters:
        """This component's parameters as a :class:`Parameters` table named ``<prefix>.<name>``
        (``prefix`` defaults to :attr:`label`)."""
        pre = self.label if prefix is None else prefix
        return Parameters(_replace(p, name=f"{pre}.{k}") for k, p in self._params.items())

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

    def prepare(self, model, motion: Motion, data=None) -> Any:
        """Parameter-independent precomputation for ``motion`` (default: none).

        ``data`` (a :class:`pinmsk.model.Data` of ``model``, owned by the caller) shares
        kinematics between components prepared on the same motion; without it the
        work is done afresh.  Pass the result as ``cache`` to :meth:`generalized_force`.
        """
        return None

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        """Generalized force ``(N, nv)`` this component applies to the model."""
        raise NotImplementedError

    def generalized_force_at(self, model, q, v):
        """The generalized force ``(nv,)`` this component applies at ONE state ``(q, v)``, on any
        backend (:mod:`pinmsk.backend`): numpy 1-D ``q, v`` give a numpy ``(nv,)``; CasADi
        ``(nv, 1)`` ``SX``/``MX`` give a CasADi ``(nv, 1)`` expression (what the optimal-control
        engine differentiates).  The same force law as :meth:`generalized_force`, at the
        component's current parameter values.  Components without a closed form in ``(q, v)``
        refuse by name (ModelError)."""
        raise ModelError(f"component {self.label} has no closed form the optimal-control engine can use")

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


def state_vector(nv: int, entries: Mapping[int, Any], like=None):
    """A generalized-force vector of ``nv`` zeros with ``entries`` ``{index: value}`` set, on the
    backend of ``like`` and the values: numpy ``(nv,)``, or CasADi ``(nv, 1)`` when any is a CasADi
    value (what :meth:`Component.generalized_force_at` returns)."""
    from .backend import backend_of

    xp = backend_of(like, *entries.values())
    if not xp.symbolic:
        out = np.zeros(nv)
        for i, f in entries.items():
            out[i] = f
        return out
    import casadi as ca

    cls = ca.MX if any(isinstance(x, ca.MX) for x in (like, *entries.values())) else ca.SX
    out = cls.zeros(nv, 1)
    for i, f in entries.items():
        out[i] = f
    return out


def motion_cached(data, model, key, motion: Motion, compute):
    """``compute(pinocchio_data)`` for ``motion``: through ``data``'s cache when a
    :class:`pinmsk.model.Data` is given (computed once per ``key`` and motion), else afresh
    in a new Pinocchio workspace.  What components' ``prepare`` methods use."""
    if data is None:
        return compute(model.pin.createData())
    return data.cached(model, key, motion, compute)


def parameter_settings(component: Component) -> dict:
    """How ``component``'s parameters differ from its class's declaration in bounds and ``vary``, as a sidecar
    entry writes them: ``{"bounds": {name: [lo, hi]}, "fixed": [...], "free": [...]}``, each key only where
    something differs (:func:`read_parameter_settings` reads them back; values are written apart)."""
    declared = {p.name: p for p in type(component).parameters}
    params = component.params
    out: dict[str, Any] = {
        "bounds": {n: [p.min, p.max] for n, p in params.items()
                   if (p.min, p.max) != (declared[n].min, declared[n].max)},
        "fixed": [n for n, p in params.items() if not p.vary and declared[n].vary],
        "free": [n for n, p in params.items() if p.vary and not declared[n].vary]}
    return {k: v for k, v in out.items() if v}


def read_parameter_settings(spec: Mapping, names: Iterable[str], *, where: str
                            ) -> tuple[dict[str, tuple[float, float]], dict[str, bool]]:
    """``(bounds, vary)`` from a sidecar entry's optional ``bounds = { name = [lo, hi] }``, ``fixed = [...]``
    (parameters a fit keeps) and ``free = [...]`` (parameters a fit may change) keys, for a component with
    parameters ``names``; a ModelError names ``where`` and the bad entry (with a "did you mean")."""
    names = list(names)

    def check(key, k):
        if k not in names:
            close = difflib.get_close_matches(str(k), names, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ModelError(f"{where}: '{key}' names unknown parameter '{k}'{hint}; parameters: {', '.join(names)}")

    bounds = {}
    table = spec.get("bounds") or {}
    if not isinstance(table, Mapping):
        raise ModelError(f"{where}: 'bounds' must be a table {{ name = [lo, hi] }}, got {table!r}")
    for k, b in table.items():
        check("bounds", k)
        try:
            lo, hi = (float(x) for x in b)
        except (TypeError, ValueError):
            raise ModelError(f"{where}: bounds for '{k}' must be [lo, hi], got {b!r}") from None
        bounds[k] = (lo, hi)
    vary = {}
    for key, flag in (("fixed", False), ("free", True)):
        given = spec.get(key) or ()
        for k in (given,) if isinstance(given, str) else given:
            check(key, k)
            if vary.get(k, flag) != flag:
                raise ModelError(f"{where}: parameter '{k}' is both fixed and free")
            vary[k] = flag
    return bounds, vary


def _replace(p: Parameter, **kw) -> Parameter:
    d = dict(p.__dict__)
    d.update(kw)
    return Parameter(**d)

