"""B-spline bases as dense numpy matrices, for the short time grids of :func:`pinmsk.signals.filtering.differentiate`.

``scipy.interpolate`` and ``scipy.sparse`` cost more to import than differentiating a short trial; up to
:data:`DENSE` samples (while SciPy's are not imported and the dense maps have cost less than
:data:`BUDGET` seconds in the process) the quintic spline's maps are built here as dense arrays, computing what
``make_interp_spline(k=5)`` (not-a-knot knots), ``BSpline.design_matrix`` and the derivative
coefficient maps of ``splder`` give:

* :func:`not_a_knot` -- the knots of the interpolating spline of odd degree ``k`` with not-a-knot end
  conditions: the end samples repeated ``k + 1`` times, the samples ``k2 .. N-1-k2`` (``k2 = (k+1)/2``)
  as interior knots (de Boor, *A Practical Guide to Splines*, ch. XIII);
* :func:`design_matrix` -- ``B[i, j] = B_j(x_i)`` by de Boor's recurrence (BSPLVB, ch. X);
* :func:`derivative_step` -- ``B @ S``, ``S`` the bidiagonal map from a spline's coefficients to those of
  its derivative, ``c'_i = k (c_(i+1) - c_i) / (t_(i+k+1) - t_(i+1))`` (Schumaker, *Spline Functions*, ch. 5).
"""
from __future__ import annotations

import numpy as np

__all__ = ["DENSE", "not_a_knot", "design_matrix", "derivative_step"]

#: Time grids up to this many samples get dense maps (an N x N collocation matrix); longer ones SciPy's sparse ones.
DENSE = 1500
#: Seconds of dense maps after which SciPy's are used for every grid (see :data:`pinmsk.signals.iir.BUDGET`).
BUDGET = 0.5
SPENT = [0.0]


def use_dense(n: int) -> bool:
    """Whether a grid of ``n`` samples gets dense maps: it is short, ``scipy.interpolate`` is not imported and
    the dense maps have not yet cost :data:`BUDGET` seconds in this process."""
    import sys
    return n <= DENSE and "scipy.interpolate" not in sys.modules and SPENT[0] < BUDGET


def not_a_knot(x: np.ndarray, k: int) -> np.ndarray:
    """The not-a-knot knots of an interpolating spline of odd degree ``k`` through samples at ``x``."""
    x = np.asarray(x, dtype=float)
    if k % 2 != 1:
        raise ValueError("not_a_knot: odd degrees only")
    k2 = (k + 1) // 2
    return np.concatenate((np.full(k + 1, x[0]), x[k2:-k2], np.full(k + 1, x[-1])))


def design_matrix(x: np.ndarray, t: np.ndarray, k: int) -> np.ndarray:
    """``(len(x), len(t) - k - 1)``: the B-splines of degree ``k`` on knots ``t`` at ``x`` (within the base
    interval ``[t[k], t[n]]``; the right end belongs to the last interval)."""
    x = np.asarray(x, dtype=float)
    t = np.asarray(t, dtype=float)
    n = t.size - k - 1
    i = np.clip(np.searchsorted(t, x, side="right") - 1, k, n - 1)       # t[i] <= x < t[i+1]
    b = np.zeros((x.size, k + 1))
    b[:, 0] = 1.0
    left = np.zeros((x.size, k + 1))
    right = np.zeros((x.size, k + 1))
    for j in range(1, k + 1):
        left[:, j] = x - t[i + 1 - j]
        right[:, j] = t[i + j] - x
        saved = np.zeros(x.size)
        for r in range(j):
            temp = b[:, r] / (right[:, r + 1] + left[:, j - r])
            b[:, r] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        b[:, j] = saved
    out = np.zeros((x.size, n))
    rows = np.arange(x.size)[:, None]
    out[rows, i[:, None] - k + np.arange(k + 1)] = b
    return out


def derivative_step(B: np.ndarray, t: np.ndarray, k: int) -> np.ndarray:
    """``B @ S`` with ``S`` ``(m - 1, m)`` the coefficient map of the derivative of a degree-``k`` spline on
    knots ``t`` (``m = len(t) - k - 1``); ``B`` has ``m - 1`` columns (the derivative's basis)."""
    m = t.size - k - 1
    w = k / (t[k + 1:k + m] - t[1:m])
    Bw = B * w
    out = np.zeros((B.shape[0], m))
    out[:, :m - 1] -= Bw
    out[:, 1:] += Bw
    return out
