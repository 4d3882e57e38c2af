"""OpenSim's Function types, evaluated exactly as OpenSim evaluates them, vectorised over samples.

Each function gives its value and its first and second derivatives at an array
of abscissae (``value(x)``, ``derivative(x, order)``, ``evaluate(x) -> (f, df,
ddf)``); ``x`` is ``(N,)`` for one-argument functions and ``(N, k)`` for a
``k``-argument LinearFunction.  :func:`from_osim` builds one from a parsed
:class:`~pinmsk.io.osim.OsimFunction`.

* :class:`Constant`, :class:`LinearFunction` (slopes, then intercept),
  :class:`PolynomialFunction` (highest order first), :class:`MultiplierFunction`
  (``scale * f``, nesting any function).
* :class:`SimmSpline` -- OpenSim's interpolating cubic spline (the Forsythe,
  Malcolm & Moler construction: the end conditions match the third derivative
  of the cubic through the first, and last, four points; with three points the
  end second-derivative parameters are zero; with two points it is a line).
  Outside its knots it continues as the straight line of the end slope (zero
  second derivative), as OpenSim does; abscissae within 2e-13 of an end knot
  return the knot's value; knot spacings below 1e-7 are raised to 1e-7.  The
  interval of an abscissa is found by the same bisection OpenSim uses, so the
  value at an interior knot comes from the same piece.
* :class:`PiecewiseLinearFunction` -- straight pieces, extrapolated with the
  end slopes; its second derivative is zero.
* ``NaturalCubicSpline`` (and ``natCubicSpline``): OpenSim 4 reads these 3.x
  names as SimmSpline (``Object::renameType`` in RegisterTypes_osimCommon), so
  :data:`FUNCTIONS` maps them to :class:`SimmSpline` -- a model that says
  NaturalCubicSpline behaves in pinmsk as it behaves in OpenSim.

:func:`to_spec` and :func:`from_spec` write a function as its OpenSim definition (type and
properties: ``{"type": "SimmSpline", "x": [...], "y": [...]}``, nested for MultiplierFunction), not as
samples, and read it back: the same class from the same numbers, so the same values bit for bit
(the sidecar of ``pinmsk import`` stores the coordinate map's functions so).

Other OpenSim functions (GCVSpline, StepFunction, Sine, PiecewiseConstantFunction,
MultivariatePolynomialFunction, ExpressionBasedFunction) are refused by name
(:class:`~pinmsk.errors.ModelError` with the element and line).
"""
from __future__ import annotations

import numpy as np

from ..errors import ModelError

__all__ = ["Function", "Constant", "LinearFunction", "PolynomialFunction", "SimmSpline",
           "PiecewiseLinearFunction", "MultiplierFunction", "FunctionBank", "FUNCTIONS", "from_osim", "to_spec",
           "from_spec"]

#: OpenSim's SimmMacros: knot spacings are at least TINY_NUMBER; "equal" means within ROUNDOFF_ERROR.
TINY_NUMBER = 1e-7
ROUNDOFF_ERROR = 2e-13


def _coefficients(values, at_least: int, what: str) -> np.ndarray:
    c = np.asarray(values, dtype=float).ravel()
    if c.size < at_least or not np.all(np.isfinite(c)):
        raise ValueError(f"a {what} needs at least {at_least} finite coefficient(s), got {c.tolist()}")
    return c


def _samples(x) -> tuple[int, ...]:
    """The sample shape of an argument array: ``(N,)`` (``()`` for a scalar)."""
    return np.shape(np.asarray(x, dtype=float))[:1]


class Function:
    """An OpenSim function of ``n_args`` arguments (value and derivatives, vectorised)."""

    n_args = 1

    def value(self, x) -> np.ndarray:
        raise NotImplementedError

    def derivative(self, x, order: int = 1, component: int = 0) -> np.ndarray:
        """The ``order``-th (1 or 2) derivative with respect to argument ``component``."""
        raise NotImplementedError

    def evaluate(self, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(f, df/dx, d2f/dx2)`` of a one-argument function."""
        return self.value(x), self.derivative(x, 1), self.derivative(x, 2)

    def __call__(self, x) -> np.ndarray:
        return self.value(x)

    def affine(self) -> tuple[float, float] | None:
        """``(slope, intercept)`` if this one-argument function is a straight line everywhere, else None."""
        return None

    @staticmethod
    def _check_order(order: int) -> None:
        if order not in (1, 2):
            raise ValueError(f"derivative order must be 1 or 2, got {order}")


class Constant(Function):
    """``f(x) = value`` (OpenSim's Constant takes any argument and ignores it)."""

    n_args = 0

    def __init__(self, value: float):
        self.c = float(value)

    def value(self, x):
        return np.full(_samples(x), self.c)

    def derivative(self, x, order=1, component=0):
        self._check_order(order)
        return np.zeros(_samples(x))

    def affine(self):
        return 0.0, self.c

    def __repr__(self):
        return f"Constant({self.c!r})"


class LinearFunction(Function):
    """``f(x) = a_0 x_0 + ... + a_{k-1} x_{k-1} + b`` from OpenSim's coefficients ``[a_0 .. a_{k-1}, b]``."""

    def __init__(self, coefficients):
        self.coefficients = _coefficients(coefficients, 2, "LinearFunction (slopes, then the intercept)")
        self.n_args = self.coefficients.size - 1

    def value(self, x):
        x = np.asarray(x, dtype=float)
        if self.n_args == 1:
            return self.coefficients[0] * (x[:, 0] if x.ndim == 2 else x) + self.coefficients[1]
        return x.reshape(-1, self.n_args) @ self.coefficients[:-1] + self.coefficients[-1]

    def derivative(self, x, order=1, component=0):
        self._check_order(order)
        return np.full(_samples(x), self.coefficients[component] if order == 1 else 0.0)

    def affine(self):
        return (float(self.coefficients[0]), float(self.coefficients[1])) if self.n_args == 1 else None

    def __repr__(self):
        return f"LinearFunction({self.coefficients.tolist()})"


class PolynomialFunction(Function):
    """``f(x) = c_0 x^n + c_1 x^(n-1) + ... + c_n`` (OpenSim's order: highest power first)."""

    def __init__(self, coefficients):
        self.coefficients = c = _coefficients(coefficients, 1, "PolynomialFunction")
        self._d1 = np.polyder(c) if c.size > 1 else np.zeros(1)
        self._d2 = np.polyder(self._d1) if self._d1.size > 1 else np.zeros(1)

    def value(self, x):
        return np.polyval(self.coefficients, np.asarray(x, dtype=float))

    def derivative(self, x, order=1, component=0):
        self._check_order(order)
        return np.polyval(self._d1 if order == 1 else self._d2, np.asarray(x, dtype=float))

    def affine(self):
        nz = np.flatnonzero(self.coefficients)
        degree = 0 if nz.size == 0 else self.coefficients.size - 1 - nz[0]
        if degree > 1:
            return None
        return (float(self.coefficients[-2]) if self.coefficients.size > 1 else 0.0), float(self.coefficients[-1])

    def __repr__(self):
        return f"PolynomialFunction({self.coefficients.tolist()})"


class MultiplierFunction(Function):
    """``f(x) = scale * g(x)`` for any function ``g`` (nests)."""

    def __init__(self, function: Function, scale: float = 1.0):
        self.function = function
        self.scale = float(scale)
        self.n_args = function.n_args

    def value(self, x):
        return self.scale * self.function.value(x)

    def derivative(self, x, order=1, component=0):
        return self.scale * self.function.derivative(x, order, component)

    def evaluate(self, x):
        return tuple(self.scale * v for v in self.function.evaluate(x))

    def affine(self):
        a = self.function.affine()
        return None if a is None else (self.scale * a[0], self.scale * a[1])

    def __repr__(self):
        return f"MultiplierFunction({self.function!r}, scale={self.scale!r})"


class _Knotted(Function):
    """The knot-based functions: validated knots, OpenSim's end handling and bisection, and the pieces
    ``y_k + t (b_k + t (c_k + t d_k))`` with ``t = x - x_k`` (subclasses set ``b``, ``c``, ``d``)."""

    def __init__(self, x, y, *, what: str):
        x = np.asarray(x, dtype=float).ravel()
        y = np.asarray(y, dtype=float).ravel()
        if x.size != y.size:
            raise ValueError(f"{what}: x has {x.size} values but y has {y.size}")
        if x.size < 2:
            raise ValueError(f"{what} needs at least 2 points, got {x.size}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise ValueError(f"{what}: the points must be finite numbers")
        if np.any(np.diff(x) < 0):
            raise ValueError(f"{what}: x must not decrease (x = {x.tolist()})")
        self.x, self.y = x, y
        self._xpad = np.append(x, np.inf)   # x[k + 1] for the bisection, never used past the end

    def _interval(self, a: np.ndarray) -> np.ndarray:
        """The piece ``k`` (x[k] <= a <= x[k+1]) OpenSim's bisection settles on, for interior ``a``."""
        n = self.x.size
        if n < 3:
            return np.zeros(a.shape, dtype=int)
        # strictly between two knots the piece is unique: a sorted search finds it; only a value on a
        # knot (where the bisection's choice of the two pieces matters) goes through the bisection
        k = np.clip(np.searchsorted(self.x, a, side="right") - 1, 0, n - 2)
        tie = (a == self.x[k]) | (a == self.x[k + 1])
        if tie.any():
            k[tie] = self._bisect(a[tie])
        return k

    def _bisect(self, a: np.ndarray) -> np.ndarray:
        """OpenSim's bisection (SimmSpline::calcValue's search), vectorised over ``a``."""
        n = self.x.size
        i = np.zeros(a.shape, dtype=int)
        j = np.full(a.shape, n)
        k = np.zeros(a.shape, dtype=int)
        todo = np.ones(a.shape, dtype=bool)
        for _ in range(2 * n.bit_length() + 2):
            if not todo.any():
                break
            kk = (i + j) // 2
            below = todo & (a < self.x[np.minimum(kk, n - 1)])
            above = todo & ~below & (a > self._xpad[kk + 1])
            found = todo & ~below & ~above
            k[found] = kk[found]
            j[below] = kk[below]
            i[above] = kk[above]
            todo = below | above
        return k

    def _inner_only(self, x):
        """``x`` as a 1-D float array when every sample is strictly inside the knots (beyond the roundoff
        band of the ends, none NaN: the usual case, where the region masks below change nothing), else None."""
        a = np.asarray(x, dtype=float)
        if a.ndim != 1 or a.size == 0:
            return None
        lo, hi = a.min(), a.max()       # NaN propagates: the comparisons fail, the general path runs
        if lo >= self.x[0] and hi <= self.x[-1] and lo - self.x[0] > ROUNDOFF_ERROR \
                and self.x[-1] - hi > ROUNDOFF_ERROR:
            return a
        return None

    def _regions(self, x):
        a = np.asarray(x, dtype=float)
        scalar = a.ndim == 0
        a = np.atleast_1d(a).astype(float)
        lo = a < self.x[0]
        hi = ~lo & (a > self.x[-1])
        at0 = ~lo & ~hi & (np.abs(a - self.x[0]) <= ROUNDOFF_ERROR)
        at1 = ~lo & ~hi & ~at0 & (np.abs(a - self.x[-1]) <= ROUNDOFF_ERROR)
        inner = ~(lo | hi | at0 | at1)
        return a, scalar, lo, hi, at0, at1, inner

    @staticmethod
    def _out(v, scalar):
        return v[0] if scalar else v

    def value(self, x):
        ai = self._inner_only(x)
        if ai is not None:
            k = self._interval(ai)
            t = ai - self.x[k]
            return self.y[k] + t * (self.b[k] + t * (self.c[k] + t * self.d[k]))
        a, scalar, lo, hi, at0, at1, inner = self._regions(x)
        out = np.empty(a.shape)
        out[lo] = self.y[0] + (a[lo] - self.x[0]) * self.b[0]
        out[hi] = self.y[-1] + (a[hi] - self.x[-1]) * self.b[-1]
        out[at0] = self.y[0]
        out[at1] = self.y[-1]
        ai = a[inner]
        k = self._interval(ai)
        t = ai - self.x[k]
        out[inner] = self.y[k] + t * (self.b[k] + t * (self.c[k] + t * self.d[k]))
        out[np.isnan(a)] = np.nan
        return self._out(out, scalar)

    def derivative(self, x, order=1, component=0):
        self._check_order(order)
        ai = self._inner_only(x)
        if ai is not None:
            k = self._interval(ai)
            t = ai - self.x[k]
            if order == 1:
                return self.b[k] + t * (2.0 * self.c[k] + 3.0 * t * self.d[k])
            return 2.0 * self.c[k] + 6.0 * t * self.d[k]
        a, scalar, lo, hi, at0, at1, inner = self._regions(x)
        out = np.empty(a.shape)
        if order == 1:
            out[lo | at0] = self.b[0]
            out[hi | at1] = self.b[-1]
        else:
            out[lo | hi] = 0.0
            out[at0] = 2.0 * self.c[0]
            out[at1] = 2.0 * self.c[-1]
        ai = a[inner]
        k = self._interval(ai)
        t = ai - self.x[k]
        if order == 1:
            out[inner] = self.b[k] + t * (2.0 * self.c[k] + 3.0 * t * self.d[k])
        else:
            out[inner] = 2.0 * self.c[k] + 6.0 * t * self.d[k]
        out[np.isnan(a)] = np.nan
        return self._out(out, scalar)

    def evaluate(self, x):
        # value() and both derivative()s from one region split and one bisection (the same numbers)
        ai = self._inner_only(x)
        if ai is not None:
            k = self._interval(ai)
            t = ai - self.x[k]
            b, c, d = self.b[k], self.c[k], self.d[k]
            return (self.y[k] + t * (b + t * (c + t * d)), b + t * (2.0 * c + 3.0 * t * d),
                    2.0 * c + 6.0 * t * d)
        a, scalar, lo, hi, at0, at1, inner = self._regions(x)
        f, d1, d2 = np.empty(a.shape), np.empty(a.shape), np.empty(a.shape)
        f[lo] = self.y[0] + (a[lo] - self.x[0]) * self.b[0]
        f[hi] = self.y[-1] + (a[hi] - self.x[-1]) * self.b[-1]
        f[at0], f[at1] = self.y[0], self.y[-1]
        d1[lo | at0], d1[hi | at1] = self.b[0], self.b[-1]
        d2[lo | hi] = 0.0
        d2[at0], d2[at1] = 2.0 * self.c[0], 2.0 * self.c[-1]
        ai = a[inner]
        k = self._interval(ai)
        t = ai - self.x[k]
        b, c, d = self.b[k], self.c[k], self.d[k]
        f[inner] = self.y[k] + t * (b + t * (c + t * d))
        d1[inner] = b + t * (2.0 * c + 3.0 * t * d)
        d2[inner] = 2.0 * c + 6.0 * t * d
        nan = np.isnan(a)
        f[nan] = d1[nan] = d2[nan] = np.nan
        return self._out(f, scalar), self._out(d1, scalar), self._out(d2, scalar)

    def affine(self):
        if self.x.size == 2:
            return float(self.b[0]), float(self.y[0] - self.b[0] * self.x[0])
        return None

    def __repr__(self):
        return f"{type(self).__name__}(x={self.x.tolist()}, y={self.y.tolist()})"


class SimmSpline(_Knotted):
    """OpenSim's SimmSpline through the points ``(x, y)``: value, first and second derivatives.

    Coefficients ``b, c, d`` give ``y_k + t (b_k + t (c_k + t d_k))`` with
    ``t = x - x_k`` on piece ``k``; see the module docstring for the end
    conditions and the behaviour outside the knots.
    """

    def __init__(self, x, y):
        super().__init__(x, y, what="SimmSpline")
        self.b, self.c, self.d = self._coefficients(self.x, self.y)

    @staticmethod
    def _coefficients(x, y):
        n = x.size
        h = np.maximum(TINY_NUMBER, np.diff(x))
        slope = np.diff(y) / h
        if n == 2:
            return np.full(2, slope[0]), np.zeros(2), np.zeros(2)
        # Unknowns s_i (a third of the second derivative at knot i): a symmetric tridiagonal system.
        # Interior rows: h_{i-1} s_{i-1} + 2 (h_{i-1} + h_i) s_i + h_i s_{i+1} = slope_i - slope_{i-1}.
        # End rows: -h_0 s_0 + h_0 s_1 = r_0 and h_{n-2} s_{n-2} - h_{n-2} s_{n-1} = r_{n-1}, with r from the
        # third divided differences of the first (last) four points, or 0 with only three points.
        diag = np.empty(n)
        rhs = np.empty(n)
        diag[1:-1] = 2.0 * (h[:-1] + h[1:])
        rhs[1:-1] = slope[1:] - slope[:-1]
        diag[0], diag[-1] = -h[0], -h[-1]
        rhs[0] = rhs[-1] = 0.0
        if n > 3:
            d31 = max(TINY_NUMBER, x[3] - x[1])
            d20 = max(TINY_NUMBER, x[2] - x[0])
            d30 = max(TINY_NUMBER, x[3] - x[0])
            e1 = max(TINY_NUMBER, x[-1] - x[-3])
            e2 = max(TINY_NUMBER, x[-2] - x[-4])
            e3 = max(TINY_NUMBER, x[-1] - x[-4])
            rhs[0] = (rhs[2] / d31 - rhs[1] / d20) * h[0] * h[0] / d30
            rhs[-1] = -(rhs[-2] / e1 - rhs[-3] / e2) * h[-1] * h[-1] / e3
        # Thomas algorithm (the system is diagonally dominant in its interior; the end rows are OpenSim's)
        for i in range(1, n):
            t = h[i - 1] / diag[i - 1]
            diag[i] -= t * h[i - 1]
            rhs[i] -= t * rhs[i - 1]
        s = np.empty(n)
        s[-1] = rhs[-1] / diag[-1]
        for i in range(n - 2, -1, -1):
            s[i] = (rhs[i] - h[i] * s[i + 1]) / diag[i]
        b = np.empty(n)
        d = np.empty(n)
        b[:-1] = slope - h * (s[1:] + 2.0 * s[:-1])
        b[-1] = slope[-1] + h[-1] * (s[-2] + 2.0 * s[-1])
        d[:-1] = (s[1:] - s[:-1]) / h
        d[-1] = d[-2]
        return b, 3.0 * s, d

class PiecewiseLinearFunction(_Knotted):
    """OpenSim's PiecewiseLinearFunction: straight pieces, end slopes outside the knots, zero curvature.

    The pieces are cubics with zero quadratic and cubic coefficients, evaluated as the spline's are: the
    arithmetic is OpenSim's ``y_k + (x - x_k) b_k`` exactly (OpenSim's second derivative is zero too).
    """

    def __init__(self, x, y):
        super().__init__(x, y, what="PiecewiseLinearFunction")
        s = np.diff(self.y) / np.maximum(TINY_NUMBER, np.diff(self.x))
        self.b = np.append(s, s[-1])
        self.c = self.d = np.zeros(self.x.size)


def _lowered(f: Function) -> tuple[float | None, Function]:
    """``(scale, base)`` with ``f = scale * base`` for one MultiplierFunction level (scale None: ``f`` itself)."""
    if isinstance(f, MultiplierFunction) and not isinstance(f.function, MultiplierFunction):
        return f.scale, f.function
    return None, f


class FunctionBank:
    """Several one-argument functions evaluated at one argument together.

    The coordinate map of an imported knee evaluates five to eight functions of the same knee angle
    (Rajagopal's walker knee: five polynomials; its patella: three splines on the same knots), each a
    dozen small array operations when evaluated alone.  A bank groups them once:

    * the PolynomialFunctions, and MultiplierFunctions of one (the scale folded into the coefficients),
      into one power-basis product: ``F = X P`` with ``X = [x^d ... x 1]``, and the same for the first
      and second derivatives;
    * the SimmSplines and PiecewiseLinearFunctions on the same knots (one MultiplierFunction level folded
      in too) into one interval search (OpenSim's, :meth:`_Knotted._interval`) and one gather of the
      stacked piece coefficients.

    Any other function, or an argument a group's fast path does not cover (outside the knots' interior,
    not finite), goes through the function's own :meth:`Function.evaluate`.  The results agree with the
    separate evaluations to rounding (the power basis and the folded scale reorder the arithmetic: a
    few 1e-16 relative).  The argument is ``(N,)``; the results have one row per function, ``(size, N)``
    (the arithmetic runs along contiguous rows of frames: on ``(N, size)`` arrays numpy's inner loops
    would be ``size`` long).  :meth:`slope` keeps the last argument's slopes: the moments mapped back
    (``J^T tau``) need the slopes the motion's mapping computed at the same angles.
    """

    def __init__(self, functions):
        self.functions = tuple(functions)
        self.size = len(self.functions)
        poly, knots, other = [], {}, []
        for i, f in enumerate(self.functions):
            scale, base = _lowered(f)
            scale = 1.0 if scale is None else scale
            if isinstance(base, PolynomialFunction):
                poly.append((i, scale, base))
            elif isinstance(base, _Knotted):
                knots.setdefault(base.x.tobytes(), []).append((i, scale, base))
            else:
                other.append(i)
        self._poly = None
        if poly:
            idx = np.array([i for i, _, _ in poly])
            width = max(b.coefficients.size for _, _, b in poly)
            mats = []
            for part, drop in (("coefficients", 0), ("_d1", 1), ("_d2", 2)):
                # (m, w), padded at the front: column k multiplies x^(w - 1 - k)
                w = max(width - drop, 1)
                rows = [s * getattr(b, part) for _, s, b in poly]
                mats.append(np.array([np.concatenate([np.zeros(w), r])[-w:] for r in rows]))
            self._poly = (idx, width, mats)
        self._knots = []
        for members in knots.values():
            idx = np.array([i for i, _, _ in members])
            first = members[0][2]
            # (4 m, pieces): the y, b, c, d rows of every member, gathered at the frames' pieces in one take
            coef = np.concatenate([np.array([s * getattr(b, k) for _, s, b in members]) for k in ("y", "b", "c", "d")])
            self._knots.append((idx, first, coef))
        self._other = tuple(other)
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def evaluate(self, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(F, dF/dx, d2F/dx2)``, each ``(size, N)``: row ``i`` is ``functions[i].evaluate(x)``."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 1:
            raise ValueError(f"FunctionBank.evaluate takes one argument per frame, shape (N,); got {x.shape}")
        n = x.shape[0]
        F, D1, D2 = np.empty((self.size, n)), np.empty((self.size, n)), np.empty((self.size, n))
        rest = list(self._other)
        if self._poly is not None:
            idx, width, (P0, P1, P2) = self._poly
            if np.isfinite(x).all():
                X = np.empty((width, n))        # rows x^(w-1) ... x, 1
                X[-1] = 1.0
                for k in range(width - 2, -1, -1):
                    np.multiply(X[k + 1], x, out=X[k])
                F[idx] = P0 @ X
                D1[idx] = P1 @ X[1:] if width > 1 else 0.0
                D2[idx] = P2 @ X[2:] if width > 2 else 0.0
            else:
                rest += idx.tolist()
        for idx, first, coef in self._knots:
            xi = first._inner_only(x)
            if xi is None:
                rest += idx.tolist()
                continue
            k = first._interval(xi)
            t = xi - first.x[k]
            y, b, c, d = np.take(coef, k, axis=1).reshape(4, idx.size, n)
            F[idx] = y + t * (b + t * (c + t * d))
            D1[idx] = b + t * (2.0 * c + 3.0 * t * d)
            D2[idx] = 2.0 * c + 6.0 * t * d
        for i in rest:
            F[i], D1[i], D2[i] = self.functions[i].evaluate(x)
        D1.flags.writeable = False
        self._last = (x.copy(), D1)
        return F, D1, D2

    def slope(self, x) -> np.ndarray:
        """``dF/dx`` ``(size, N)``, the last :meth:`evaluate`'s when ``x`` equals its argument (read-only)."""
        x = np.asarray(x, dtype=float)
        last = self._last
        if last is not None and last[0].shape == x.shape and np.array_equal(last[0], x):
            return last[1]
        return self.evaluate(x)[1]


#: OpenSim function type -> pinmsk class (the 3.x spline names read as SimmSpline, as in OpenSim 4).
FUNCTIONS = {"Constant": Constant, "LinearFunction": LinearFunction, "PolynomialFunction": PolynomialFunction,
             "SimmSpline": SimmSpline, "NaturalCubicSpline": SimmSpline, "natCubicSpline": SimmSpline,
             "PiecewiseLinearFunction": PiecewiseLinearFunction, "MultiplierFunction": MultiplierFunction}


def from_osim(fn) -> Function:
    """The evaluable function of a parsed :class:`~pinmsk.io.osim.OsimFunction` (ModelError if unsupported)."""
    kind = fn.type
    if kind not in FUNCTIONS:
        raise ModelError(f"{fn.where}: OpenSim function type {fn.written_type or kind} is not supported by pinmsk "
                         f"(supported: {', '.join(sorted(set(FUNCTIONS) - {'natCubicSpline'}))})")
    try:
        if kind == "Constant":
            return Constant(fn.value if fn.value is not None else 0.0)
        if kind == "LinearFunction":
            return LinearFunction(fn.coefficients)
        if kind == "PolynomialFunction":
            return PolynomialFunction(fn.coefficients)
        if kind == "MultiplierFunction":
            return MultiplierFunction(from_osim(fn.function), fn.scale)
        return FUNCTIONS[kind](fn.x, fn.y)
    except ValueError as exc:
        raise ModelError(f"{fn.where}: {exc}") from None


#: The properties of each function type in :func:`to_spec` / :func:`from_spec` (besides ``type``).
SPEC_KEYS = {"Constant": ("value",), "LinearFunction": ("coefficients",), "PolynomialFunction": ("coefficients",),
             "SimmSpline": ("x", "y"), "PiecewiseLinearFunction": ("x", "y"), "MultiplierFunction": ("scale", "function")}


def to_spec(f: Function) -> dict:
    """The OpenSim definition of ``f``: ``{"type": ..., <its properties>}`` (plain lists and floats)."""
    if isinstance(f, Constant):
        return {"type": "Constant", "value": f.c}
    if isinstance(f, MultiplierFunction):
        return {"type": "MultiplierFunction", "scale": f.scale, "function": to_spec(f.function)}
    if isinstance(f, (LinearFunction, PolynomialFunction)):
        return {"type": type(f).__name__, "coefficients": f.coefficients.tolist()}
    if isinstance(f, (SimmSpline, PiecewiseLinearFunction)):
        return {"type": type(f).__name__, "x": f.x.tolist(), "y": f.y.tolist()}
    raise ModelError(f"no OpenSim definition for the function {f!r}")


def from_spec(spec, *, where: str) -> Function:
    """The function :func:`to_spec` wrote (ModelError naming ``where`` and the key for a bad one)."""
    from ..io.toml_files import check_keys

    if not isinstance(spec, dict) or spec.get("type") not in SPEC_KEYS:
        kind = spec.get("type") if isinstance(spec, dict) else spec
        raise ModelError(f"{where}: a function is a table {{ type = ..., ... }} with type one of "
                         f"{', '.join(SPEC_KEYS)}; got {kind!r}")
    kind = spec["type"]
    keys = SPEC_KEYS[kind]
    check_keys(spec, ("type",) + keys, where=where, section=f"the {kind}")
    missing = [k for k in keys if k not in spec]
    if missing:
        raise ModelError(f"{where}: the {kind} needs {', '.join(missing)}")
    try:
        if kind == "Constant":
            return Constant(_scalar(spec["value"], where, "value"))
        if kind == "MultiplierFunction":
            return MultiplierFunction(from_spec(spec["function"], where=f"{where}: function"),
                                      _scalar(spec["scale"], where, "scale"))
        if kind in ("LinearFunction", "PolynomialFunction"):
            return FUNCTIONS[kind](_numbers(spec["coefficients"], where, "coefficients"))
        return FUNCTIONS[kind](_numbers(spec["x"], where, "x"), _numbers(spec["y"], where, "y"))
    except ValueError as exc:
        raise ModelError(f"{where}: {exc}") from None


def _scalar(v, where, key) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ModelError(f"{where}: {key} must be a number, got {v!r}")
    return float(v)


def _numbers(v, where, key) -> list:
    if not isinstance(v, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise ModelError(f"{where}: {key} must be a list of numbers, got {v!r}")
    return [float(x) for x in v]
