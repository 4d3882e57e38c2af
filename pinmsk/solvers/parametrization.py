"""Global and local control parametrizations with analytic time derivatives (thesis Sec. 3.2-3.3).

A parametrization maps a coefficient matrix ``P`` of shape ``(n_params, n_signals)``
to signals ``s(t) = B(t) P`` of shape ``(N, n_signals)``; every family here is
*linear* in its coefficients, so ``basis(t, deriv)`` (the ``(N, n_params)``
matrix ``d^k B / dt^k``) is all a solver needs: values, first and second time
derivatives (used by the inverse muscle model, thesis Eq. 5.2-5.4, with no
numerical differentiation) and exact parameter sensitivities.

- :class:`Polynomial` -- order ``n`` in time (thesis Eq. 3.2).  Internally the
  basis is Chebyshev ``T_k(s)`` of the scaled time ``s = 2 (t - t0)/T - 1`` in
  ``[-1, 1]`` (``T`` the duration), whose sensitivities stay bounded by 1 instead
  of growing like ``t^n`` (the ill-conditioning the thesis discusses around
  Eq. 3.11).  :meth:`Polynomial.to_monomial` converts coefficients back to the
  thesis's ``p_0 + p_1 t + ... + p_n t^n``.
- :class:`Fourier` -- ``A_0 + sum_k A_k sin(2 pi k (t + shift)/tau) + B_k cos(...)``
  (thesis Eq. 3.4 and 5.5), ``2K + 1`` coefficients ordered
  ``[A_0, A_1, B_1, ..., A_K, B_K]``.  ``tau`` is the period; for non-periodic
  motions pass a ``tau`` different from the duration (Sec. 3.3.6);
  :meth:`Fourier.basis_period_derivative` gives ``d B / d tau`` for treating it
  as a free parameter.
- :class:`Spline` -- local clamped cubic B-splines on ``n_params`` uniformly
  spread coefficients (the local-parametrization baseline of Sec. 3.1).
"""
from __future__ import annotations

import numpy as np

from ..backend import backend_of
from ..errors import ModelError

__all__ = ["Parametrization", "Polynomial", "Fourier", "Spline", "make_parametrization"]


class Parametrization:
    """Base class: ``n_params`` coefficients per signal, ``basis(t, deriv)`` linear map."""

    kind = "base"
    n_params: int

    def basis(self, t, deriv: int = 0) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def evaluate(self, coeffs, t, deriv: int = 0) -> np.ndarray:
        """Signals (N, n_signals) -- or their ``deriv``-th time derivative -- from ``coeffs``."""
        P = np.asarray(coeffs, dtype=float)
        if P.shape[0] != self.n_params:
            raise ModelError(f"{self!r} needs {self.n_params} coefficients per signal; "
                             f"got an array of shape {P.shape}")
        return self.basis(t, deriv) @ P

    def fit(self, t, y) -> np.ndarray:
        """Least-squares coefficients (n_params, n_signals) of samples ``y`` (N, n_signals) at ``t``."""
        B = self.basis(t)
        y = np.asarray(y, dtype=float)
        sol, *_ = np.linalg.lstsq(B, y.reshape(len(B), -1), rcond=None)
        return sol.reshape((self.n_params,) + y.shape[1:])

    def constant(self, value: float, n_signals: int) -> np.ndarray:
        """Coefficients of the constant signal ``value`` (exact for every family here)."""
        t = np.linspace(*self._span(), 4 * self.n_params + 4)
        return self.fit(t, np.full((t.size, n_signals), float(value)))

    def _span(self):
        return (0.0, 1.0)

    def describe(self) -> dict:
        return {"kind": self.kind, "n_params": self.n_params}

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and self.describe() == other.describe()

    def __hash__(self) -> int:
        return hash((type(self).__name__, tuple(sorted(self.describe().items()))))


class Polynomial(Parametrization):
    """Polynomial of order ``order`` on ``[t0, t0 + duration]`` (thesis Eq. 3.2), Chebyshev basis."""

    kind = "polynomial"

    def __init__(self, order: int, *, duration: float, t0: float = 0.0):
        if int(order) != order or order < 0:
            raise ModelError(f"polynomial order must be a non-negative integer, got {order}")
        if not duration > 0:
            raise ModelError(f"polynomial duration must be > 0, got {duration}")
        self.order = int(order)
        self.duration = float(duration)
        self.t0 = float(t0)
        self.n_params = self.order + 1

    def _span(self):
        return (self.t0, self.t0 + self.duration)

    def basis(self, t, deriv: int = 0) -> np.ndarray:
        """``d^deriv/dt^deriv T_k(s(t))``, (N, order + 1); ``s = 2 (t - t0)/T - 1``."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        s = 2.0 * (t - self.t0) / self.duration - 1.0
        n = self.n_params
        # Recurrences for T_k and its s-derivatives:
        # T_{k+1} = 2 s T_k - T_{k-1};  T'_{k+1} = 2 T_k + 2 s T'_k - T'_{k-1};
        # T''_{k+1} = 4 T'_k + 2 s T''_k - T''_{k-1}.
        T = np.zeros((deriv + 1, t.size, n))
        T[0, :, 0] = 1.0
        if n > 1:
            T[0, :, 1] = s
            if deriv >= 1:
                T[1, :, 1] = 1.0
        for k in range(1, n - 1):
            T[0, :, k + 1] = 2 * s * T[0, :, k] - T[0, :, k - 1]
            for d in range(1, deriv + 1):
                T[d, :, k + 1] = 2 * d * T[d - 1, :, k] + 2 * s * T[d, :, k] - T[d, :, k - 1]
        return T[deriv] * (2.0 / self.duration) ** deriv

    def to_monomial(self, coeffs) -> np.ndarray:
        """Coefficients ``p_0..p_n`` (rows) of thesis Eq. 3.2 in plain time ``t``."""
        from numpy.polynomial import Chebyshev
        P = np.asarray(coeffs, dtype=float).reshape(self.n_params, -1)
        out = np.empty_like(P)
        for j in range(P.shape[1]):
            c = Chebyshev(P[:, j], domain=list(self._span())).convert(kind=np.polynomial.Polynomial)
            coef = np.zeros(self.n_params)
            coef[:c.coef.size] = c.coef
            out[:, j] = coef
        return out

    def __repr__(self):
        return f"Polynomial(order={self.order}, duration={self.duration:g})"

    def describe(self):
        return {"kind": self.kind, "order": self.order, "duration": self.duration,
                "n_params": self.n_params, "basis": "chebyshev(2 (t - t0)/T - 1)"}


class Fourier(Parametrization):
    """Fourier series with ``K`` harmonics of period ``tau`` (thesis Eq. 3.4, 5.5): 2K + 1 coefficients."""

    kind = "fourier"

    def __init__(self, n_harmonics: int, *, period: float, shift: float = 0.0):
        if int(n_harmonics) != n_harmonics or n_harmonics < 0:
            raise ModelError(f"Fourier n_harmonics must be a non-negative integer, got {n_harmonics}")
        if not period > 0:
            raise ModelError(f"Fourier period must be > 0, got {period}")
        self.n_harmonics = int(n_harmonics)
        self.period = float(period)
        self.shift = float(shift)
        self.n_params = 2 * self.n_harmonics + 1

    def _span(self):
        return (0.0, self.period)

    def _omega(self):
        return 2.0 * np.pi * np.arange(1, self.n_harmonics + 1) / self.period

    def basis(self, t, deriv: int = 0, *, period=None) -> np.ndarray:
        """``[1, sin(w_1 t'), cos(w_1 t'), ...]`` differentiated ``deriv`` times, t' = t + shift.

        ``period`` (default: this series' tau) may be a CasADi symbol: the optimal-control
        engine's free period (Sec. 3.3.6) then gets the exact derivative d B / d tau.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float)) + self.shift
        if period is not None and backend_of(period).symbolic:
            import casadi as ca
            k = np.arange(1, self.n_harmonics + 1, dtype=float)
            ph = ca.DM(np.outer(t, k)) * (2.0 * np.pi / period)
            cols = [ca.DM.ones(t.size, 1) if deriv == 0 else ca.DM.zeros(t.size, 1)]
            for j in range(self.n_harmonics):
                wd = (2.0 * np.pi * k[j] / period) ** deriv
                cols += [wd * ca.sin(ph[:, j] + deriv * np.pi / 2), wd * ca.cos(ph[:, j] + deriv * np.pi / 2)]
            return ca.horzcat(*cols)
        w = self._omega() if period is None else 2.0 * np.pi * np.arange(1, self.n_harmonics + 1) / float(period)
        ph = np.outer(t, w)
        out = np.empty((t.size, self.n_params))
        out[:, 0] = 1.0 if deriv == 0 else 0.0
        # d^d/dt^d sin(w t) = w^d sin(w t + d pi/2)
        out[:, 1::2] = w ** deriv * np.sin(ph + deriv * np.pi / 2)
        out[:, 2::2] = w ** deriv * np.cos(ph + deriv * np.pi / 2)
        return out

    def basis_period_derivative(self, t) -> np.ndarray:
        """``d B(t) / d tau`` (N, 2K + 1), for a free period (Sec. 3.3.6)."""
        t = np.atleast_1d(np.asarray(t, dtype=float)) + self.shift
        w = self._omega()
        ph = np.outer(t, w)
        dph = -ph / self.period
        out = np.zeros((t.size, self.n_params))
        out[:, 1::2] = np.cos(ph) * dph
        out[:, 2::2] = -np.sin(ph) * dph
        return out

    def with_period(self, period: float) -> "Fourier":
        return Fourier(self.n_harmonics, period=period, shift=self.shift)

    def __repr__(self):
        return f"Fourier(n_harmonics={self.n_harmonics}, period={self.period:g})"

    def describe(self):
        return {"kind": self.kind, "n_harmonics": self.n_harmonics, "period": self.period,
                "shift": self.shift, "n_params": self.n_params}


class Spline(Parametrization):
    """Clamped cubic B-spline with ``n_params`` coefficients on ``[t0, t0 + duration]`` (local baseline)."""

    kind = "spline"

    def __init__(self, n_params: int, *, duration: float, t0: float = 0.0, degree: int = 3):
        if int(n_params) != n_params or n_params < degree + 1:
            raise ModelError(f"a degree-{degree} spline needs at least {degree + 1} coefficients, "
                             f"got {n_params}")
        if not duration > 0:
            raise ModelError(f"spline duration must be > 0, got {duration}")
        self.n_params = int(n_params)
        self.degree = int(degree)
        self.duration = float(duration)
        self.t0 = float(t0)
        n_inner = self.n_params - self.degree - 1
        inner = np.linspace(self.t0, self.t0 + self.duration, n_inner + 2)[1:-1]
        self.knots = np.concatenate([[self.t0] * (self.degree + 1), inner,
                                     [self.t0 + self.duration] * (self.degree + 1)])

    def _span(self):
        return (self.t0, self.t0 + self.duration)

    def basis(self, t, deriv: int = 0) -> np.ndarray:
        from scipy.interpolate import BSpline
        t = np.atleast_1d(np.asarray(t, dtype=float))
        tt = np.clip(t, self.t0, self.t0 + self.duration)
        out = np.empty((t.size, self.n_params))
        eye = np.eye(self.n_params)
        spl = BSpline(self.knots, eye, self.degree, extrapolate=False)
        out[:] = np.nan_to_num(spl(tt, nu=deriv) if deriv else spl(tt))
        return out

    def __repr__(self):
        return f"Spline(n_params={self.n_params}, duration={self.duration:g})"

    def describe(self):
        return {"kind": self.kind, "n_params": self.n_params, "degree": self.degree,
                "duration": self.duration}


def make_parametrization(kind: str, *, duration: float, order: int | None = None,
                         n_harmonics: int | None = None, period: float | None = None,
                         n_params: int | None = None) -> Parametrization:
    """Build a parametrization by name (``polynomial``, ``fourier``, ``spline``)."""
    if kind == "polynomial":
        return Polynomial(6 if order is None else order, duration=duration)
    if kind == "fourier":
        return Fourier(5 if n_harmonics is None else n_harmonics,
                       period=duration if period is None else period)
    if kind == "spline":
        return Spline(10 if n_params is None else n_params, duration=duration)
    raise ModelError(f"unknown parametrization '{kind}'; valid: polynomial, fourier, spline")
