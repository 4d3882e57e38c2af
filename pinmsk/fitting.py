"""Fitters: one base class and one result type, in scikit-learn's habits.

Every analysis that fits something to a trial -- static optimization and its
variants, dynamic optimization, contact identification, inverse kinematics,
the fit of an effect in the diagnosis -- is a :class:`Fitter`:

* the constructor only stores its arguments, each under its own name, and
  checks nothing (``fit`` does);
* :meth:`Fitter.get_params`, :meth:`Fitter.set_params` and
  :meth:`Fitter.clone` come from the constructor's signature, as
  ``sklearn.base.BaseEstimator``'s do (pinmsk does not depend on scikit-learn);
* ``fit(...)`` does the work and returns ``self``;
* learned values end in ``_`` and exist only after ``fit``;
* ``result_`` is a :class:`Result`: a :class:`~pinmsk.trial.Trial` of the
  output channels plus its :class:`FitStatistics`; ``report()`` is the text
  the CLI prints and ``to_dict()`` the fit's JSON-ready summary.

``tests/test_fitter_conformance.py`` checks every fitter against these rules.
"""
from __future__ import annotations

import copy
import inspect
import math
import types
from dataclasses import dataclass, fields

import numpy as np

from .errors import SolverError
from .stats import VARIANCE_CONVENTIONS, aic, aic_change, bic, bic_change
from .trial import Trial, close_matches

__all__ = ["FitStatistics", "Fitter", "Result", "format_report"]

#: width of the key column in a report row (``"  key            value"``)
REPORT_KEY_WIDTH = 14


def format_report(title: str, rows) -> str:
    """The one report format: ``title``, then one line per row.

    A row ``(key, value)`` is written ``"  key            value"`` (the key
    padded to :data:`REPORT_KEY_WIDTH`); a string row is written as it is,
    indented by two spaces (tables, notes that need their own layout).
    """
    lines = [title]
    for row in rows:
        if isinstance(row, str):
            lines.append(f"  {row}")
        else:
            key, value = row
            lines.append(f"  {key:<{REPORT_KEY_WIDTH}} {value}")
    return "\n".join(lines)


def _finite_or_none(x):
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class FitStatistics:
    """How well a fit went: residual count, free parameters, weighted SSE, AIC/BIC, convergence, violation.

    ``n`` is the number of residuals of a least-squares fit and ``sse`` their
    weighted sum of squares; ``variance`` says how the information criteria
    treat the noise (``"known"`` or ``"estimated"``, see :mod:`pinmsk.stats`).
    A fitter that minimises an effort rather than a sum of squares (static
    and dynamic optimization) has ``n = 0``, ``sse`` NaN and no
    ``variance``: its AIC and BIC are NaN.  ``sse_before`` is the SSE of the
    reference the fit improves on (the model without the fitted effect), for
    :attr:`aic_change` and :attr:`bic_change`.  ``k`` counts the free
    parameters (decision variables), ``objective`` is the value minimised,
    ``iterations`` the solver's iterations or function evaluations, and
    ``violation`` the largest constraint violation in the fitter's units (0
    where the fitter has bounds only).
    """

    n: int = 0
    k: int = 0
    sse: float = float("nan")
    variance: str | None = None
    sse_before: float = float("nan")
    converged: bool = True
    message: str = ""
    iterations: int = 0
    violation: float = 0.0
    objective: float = float("nan")

    def __post_init__(self):
        if self.variance is not None and self.variance not in VARIANCE_CONVENTIONS:
            raise ValueError(f"variance must be one of {VARIANCE_CONVENTIONS} or None, got {self.variance!r}")
        if int(self.n) < 0 or int(self.k) < 0:
            raise ValueError(f"n and k must be >= 0, got n = {self.n}, k = {self.k}")
        for name, cast in (("n", int), ("k", int), ("iterations", int), ("sse", float), ("sse_before", float),
                           ("violation", float), ("objective", float), ("converged", bool), ("message", str)):
            object.__setattr__(self, name, cast(getattr(self, name)))

    @property
    def least_squares(self) -> bool:
        """True for a least-squares fit (residuals and a variance convention), which has AIC/BIC."""
        return self.n > 0 and self.variance is not None and math.isfinite(self.sse)

    @property
    def aic(self) -> float:
        """Akaike's criterion (:func:`pinmsk.stats.aic`); NaN unless :attr:`least_squares`."""
        return aic(self.sse, n=self.n, k=self.k, variance=self.variance) if self.least_squares else float("nan")

    @property
    def bic(self) -> float:
        """Schwarz's criterion (:func:`pinmsk.stats.bic`); NaN unless :attr:`least_squares`."""
        return bic(self.sse, n=self.n, k=self.k, variance=self.variance) if self.least_squares else float("nan")

    @property
    def aic_change(self) -> float:
        """AIC(fit) - AIC(reference), the reference having ``sse_before`` and no free parameter; NaN without one."""
        if not (self.least_squares and math.isfinite(self.sse_before)):
            return float("nan")
        return aic_change(self.sse, self.sse_before, n=self.n, k=self.k, variance=self.variance)

    @property
    def bic_change(self) -> float:
        """BIC(fit) - BIC(reference), as :attr:`aic_change`."""
        if not (self.least_squares and math.isfinite(self.sse_before)):
            return float("nan")
        return bic_change(self.sse, self.sse_before, n=self.n, k=self.k, variance=self.variance)

    def to_dict(self) -> dict:
        """The statistics as a JSON-ready dict (NaN and infinities as None)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = _finite_or_none(v) if isinstance(v, float) else v
        for name in ("aic", "bic", "aic_change", "bic_change"):
            out[name] = _finite_or_none(getattr(self, name))
        return out

    def rows(self) -> list:
        """The report rows of a least-squares fit (none for an effort minimisation, whose fitter reports it)."""
        if not self.least_squares:
            return []
        noise = "known noise" if self.variance == "known" else "noise variance estimated"
        before = f" (reference {self.sse_before:.6g})" if math.isfinite(self.sse_before) else ""
        rows = [("fit", f"n = {self.n} residuals, k = {self.k} free parameters, weighted SSE "
                        f"{self.sse:.6g}{before}"),
                ("criteria", f"AIC {self.aic:.6g}, BIC {self.bic:.6g} ({noise})")]
        if math.isfinite(self.sse_before):
            rows.append(("change", f"AIC change {self.aic_change:+.4g}, BIC change {self.bic_change:+.4g} "
                                   "against the reference"))
        state = "converged" if self.converged else "NOT converged"
        rows.append(("convergence", f"{state} ({self.message}; {self.iterations} evaluations)"
                                    if self.message else f"{state} ({self.iterations} evaluations)"))
        return rows


#: statistics readable as attributes of a :class:`Result`
_STAT_NAMES = frozenset([f.name for f in fields(FitStatistics)]
                        + ["aic", "bic", "aic_change", "bic_change", "least_squares"])


class Result(Trial):
    """The outcome of a fit: the output channels (this :class:`~pinmsk.trial.Trial`), the statistics and details.

    ``stats`` is the :class:`FitStatistics`; its fields are also attributes of
    the result (``result.converged``, ``result.aic``, ``result.n``, ...).
    ``info`` holds what a fitter reports beyond the channels (a fitted effect
    and its parameter values, a contact fit's spheres, the coefficients of a
    dynamic optimization, ...), readable as attributes too
    (``result.params``).  :meth:`report` is the fitter's text in the one
    report format (:func:`format_report`).  As a Trial it is written,
    plotted and viewed like any other; operations that make a new Trial
    (``select``, ``resample``, ...) return a plain Trial.
    """

    __slots__ = ("_stats", "_info", "_report")

    def __init__(self, time, channels=None, *, units=None, meta=None, stats: FitStatistics,
                 info=None, report: str | None = None):
        super().__init__(time, channels, units=units, meta=meta)
        self._finish(stats, info, report)

    @classmethod
    def from_trial(cls, trial: Trial, *, stats: FitStatistics, info=None, report: str | None = None) -> Result:
        """The result whose channels are those of ``trial`` (same time, units and meta; no copy)."""
        if not isinstance(trial, Trial):
            raise TypeError(f"trial must be a Trial, got {type(trial).__name__}")
        obj = cls.__new__(cls)
        for slot in Trial.__slots__:         # read-only arrays and mappings: shared, not copied
            setattr(obj, slot, getattr(trial, slot))
        obj._finish(stats, info, report)
        return obj

    def _finish(self, stats, info, report) -> None:
        if not isinstance(stats, FitStatistics):
            raise TypeError(f"stats must be a FitStatistics, got {type(stats).__name__}")
        info = dict(info or {})
        taken = sorted(k for k in info if k.startswith("_") or hasattr(type(self), k) or k in _STAT_NAMES)
        if taken:
            raise ValueError(f"Result info keys {taken} would hide an attribute of the result or its statistics")
        self._stats = stats
        self._info = types.MappingProxyType(info)
        self._report = report

    @property
    def stats(self) -> FitStatistics:
        """The fit statistics."""
        return self._stats

    @property
    def info(self):
        """The fitter's details beyond the channels (read-only mapping), also readable as attributes."""
        return self._info

    def __getattr__(self, name):
        # only reached when normal look-up fails: the details, then the statistics
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            info = object.__getattribute__(self, "_info")
            stats = object.__getattribute__(self, "_stats")
        except AttributeError:
            raise AttributeError(name) from None
        if name in info:
            return info[name]
        if name in _STAT_NAMES:
            return getattr(stats, name)
        near = close_matches(name, list(info) + sorted(_STAT_NAMES))
        raise AttributeError(f"this Result has no attribute {name!r}"
                             + (f"; did you mean {', '.join(map(repr, near))}?" if near else "")
                             + f" (details: {', '.join(info) or 'none'}; statistics: see Result.stats)")

    def report(self) -> str:
        """The fit in the one report format: the fitter's rows, then the statistics of a least-squares fit."""
        if self._report is not None:
            return self._report
        return format_report(f"fit of {self.n_channels} channels over {self.n_frames} frames", self._stats.rows())

    def __reduce__(self):
        return (_rebuild_result, (self._time, self._names, self._values, dict(self._units), dict(self._meta),
                                  self._stats, dict(self._info), self._report))

    def __repr__(self) -> str:
        s = self._stats
        state = "converged" if s.converged else "NOT converged"
        extra = f", n={s.n}, k={s.k}, aic={s.aic:.6g}" if s.least_squares else f", k={s.k}"
        return f"Result({self.n_frames} frames, {self.n_channels} channels, {state}{extra})"


def _rebuild_result(time, names, values, units, meta, stats, info, report) -> Result:
    obj = Result.__new__(Result)
    obj._setup(time, names, values, units, meta)
    obj._finish(stats, info, report)
    return obj


def _clone_value(value):
    """A parameter for a clone: fitters cloned, mutable containers and arrays copied, the rest shared.

    Models, components, marker sets and other objects are shared: pinmsk
    treats them as immutable values (``model.with_effect`` makes a new model).
    """
    if isinstance(value, Fitter):
        return value.clone()
    if isinstance(value, (dict, list, set, tuple, np.ndarray)):
        return copy.deepcopy(value)
    return value


def _json_value(v):
    if v is None or isinstance(v, (bool, str)):
        return v
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return _finite_or_none(v)
    if isinstance(v, np.ndarray):
        return [_json_value(x) for x in v.tolist()]
    if isinstance(v, dict):
        return {str(k): _json_value(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, set)):
        return [_json_value(x) for x in v]
    for attr in ("label", "name"):             # a component, a model, a marker set, ...: by its name
        name = getattr(v, attr, None)
        if isinstance(name, str):
            return name
    return f"<{type(v).__name__}>"


class Fitter:
    """Base of every pinmsk fitter (see the module notes).

    A subclass declares its parameters in ``__init__`` -- explicit arguments,
    no ``*args`` or ``**kwargs`` -- and stores each unchanged under its own
    name; ``fit`` returns ``self`` and sets ``result_`` (a :class:`Result`)
    and the other learned attributes, all ending in ``_``.
    """

    @classmethod
    def _param_names(cls) -> tuple[str, ...]:
        """The constructor's parameter names, in the signature's order (read once per class)."""
        cached = cls.__dict__.get("_PARAM_NAMES")
        if cached is not None:
            return cached
        names = cls._read_param_names()
        cls._PARAM_NAMES = names
        return names

    @classmethod
    def _read_param_names(cls) -> tuple[str, ...]:
        init = cls.__init__
        if init is object.__init__:
            return ()
        names = []
        for p in list(inspect.signature(init).parameters.values())[1:]:
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                raise TypeError(f"{cls.__name__}.__init__ takes {p}: a fitter's parameters are explicit "
                                "arguments (get_params reads them from the signature)")
            names.append(p.name)
        return tuple(names)

    def get_params(self, deep: bool = True) -> dict:
        """``{name: value}`` of the constructor's parameters; ``deep`` adds ``name__sub`` of nested fitters."""
        out = {}
        for name in self._param_names():
            value = getattr(self, name)
            out[name] = value
            if deep and isinstance(value, Fitter):
                out.update({f"{name}__{k}": v for k, v in value.get_params(deep=True).items()})
        return out

    def set_params(self, **params) -> Fitter:
        """Set parameters by name (``name__sub`` for a nested fitter's); returns ``self``.

        Unknown names raise :class:`~pinmsk.errors.SolverError` naming them and
        the valid ones.  Nothing is checked here: ``fit`` checks the values.
        """
        valid = self._param_names()
        nested: dict[str, dict] = {}
        for key, value in params.items():
            name, sep, sub = key.partition("__")
            if name not in valid:
                near = close_matches(name, valid)
                raise SolverError(f"{type(self).__name__} has no parameter {name!r}"
                                  + (f"; did you mean {', '.join(map(repr, near))}?" if near else "")
                                  + f" (its parameters: {', '.join(valid) or 'none'})")
            if sep:
                inner = getattr(self, name)
                if not isinstance(inner, Fitter):
                    raise SolverError(f"{type(self).__name__}: parameter {name!r} is not a fitter, so "
                                      f"{key!r} names nothing; set {name}= itself")
                nested.setdefault(name, {})[sub] = value
            else:
                setattr(self, name, value)
        for name, sub in nested.items():
            getattr(self, name).set_params(**sub)
        return self

    def clone(self) -> Fitter:
        """A new, unfitted fitter with the same parameters (nested fitters cloned, containers copied)."""
        return type(self)(**{k: _clone_value(v) for k, v in self.get_params(deep=False).items()})

    @classmethod
    def _fit_call(cls) -> str:
        """``fit(model, trial)``: how this fitter's ``fit`` is called, for messages."""
        try:
            ps = list(inspect.signature(cls.fit).parameters.values())[1:]
        except (TypeError, ValueError):  # pragma: no cover
            return "fit(...)"
        return "fit(" + ", ".join(p.name for p in ps if p.kind == p.POSITIONAL_OR_KEYWORD
                                  and p.default is p.empty) + ")"

    def _check_fitted(self) -> None:
        if "result_" not in vars(self):
            raise SolverError(f"this {type(self).__name__} has not run yet (not fitted); call {self._fit_call()} first")

    def report(self) -> str:
        """The fit in the one report format (``result_.report()``)."""
        self._check_fitted()
        return self.result_.report()

    def to_dict(self) -> dict:
        """The fit as a JSON-ready dict: the fitter, its parameters and the statistics."""
        self._check_fitted()
        return {"fitter": type(self).__name__, "params": _json_value(self.get_params(deep=False)),
                "statistics": self.result_.stats.to_dict()}

    def __repr__(self) -> str:
        defaults = {p.name: p.default for p in list(inspect.signature(type(self).__init__).parameters.values())[1:]}
        shown = []
        for name, value in self.get_params(deep=False).items():
            d = defaults.get(name, inspect.Parameter.empty)
            try:
                same = d is not inspect.Parameter.empty and bool(value is d or value == d)
            except (TypeError, ValueError):       # arrays and other objects without a plain ==
                same = False
            if not same:
                shown.append(f"{name}={value!r}")
        return f"{type(self).__name__}({', '.join(shown)})"
