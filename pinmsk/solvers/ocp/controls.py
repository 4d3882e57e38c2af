"""Control representations of the optimal-control engine: node values or a global parametrization.

- :class:`NodeControls` -- the signal's value at every collocation point is a decision
  variable (direct collocation as in Moco and PredSim).
- :class:`GlobalControls` -- the signal is ``s(t) = B(t) P`` for a thesis
  parametrization (:class:`~pinmsk.solvers.parametrization.Polynomial`, Eq. 3.2;
  :class:`~pinmsk.solvers.parametrization.Fourier`, Eq. 3.4, with an optional free
  period, Sec. 3.3.6; or the local :class:`~pinmsk.solvers.parametrization.Spline`):
  the coefficients ``P`` are the decision variables and the collocation grid only
  integrates the dynamics, so the thesis's comparison of Fourier series and
  polynomials runs on the same engine.
"""
from __future__ import annotations

import numpy as np

from ...errors import ModelError
from ._values import ValueEq
from ..parametrization import Fourier, Parametrization

__all__ = ["NodeControls", "GlobalControls"]


class NodeControls(ValueEq):
    """The signal's values at the collocation points are the decision variables."""

    kind = "nodes"

    def describe(self) -> dict:
        return {"kind": self.kind}

    def __repr__(self) -> str:
        return "NodeControls()"


class GlobalControls(ValueEq):
    """``s(t) = B(t) P`` with ``parametrization`` (one coefficient column per signal).

    ``free_period`` (Fourier only): the period is a decision variable within
    ``period_bounds`` times the nominal one (Sec. 3.3.6).
    """

    kind = "global"

    def __init__(self, parametrization: Parametrization, *, free_period: bool = False,
                 period_bounds=(0.5, 2.0)):
        if not isinstance(parametrization, Parametrization):
            raise ModelError(f"GlobalControls needs a Parametrization, not {parametrization!r}")
        if free_period and not isinstance(parametrization, Fourier):
            raise ModelError(f"free_period needs a Fourier parametrization, not {parametrization!r}")
        lo, hi = map(float, period_bounds)
        if free_period and not 0 < lo <= 1 <= hi:
            raise ModelError(f"period_bounds {period_bounds} must satisfy 0 < lower <= 1 <= upper "
                             "(factors on the nominal period)")
        self.parametrization = parametrization
        self.free_period = bool(free_period)
        self.period_bounds = (lo, hi)

    @property
    def n_params(self) -> int:
        return self.parametrization.n_params

    def basis(self, t, period=None):
        """``B(t)`` (n_points, n_params); ``period`` a CasADi symbol with ``free_period``."""
        if self.free_period:
            return self.parametrization.basis(np.asarray(t, dtype=float), period=period)
        return self.parametrization.basis(np.asarray(t, dtype=float))

    def describe(self) -> dict:
        return {"kind": self.kind, **self.parametrization.describe(), "free_period": self.free_period}

    def __repr__(self) -> str:
        return f"GlobalControls({self.parametrization!r}{', free_period=True' if self.free_period else ''})"
