"""Fit statistics in one place: the weighted sum of squares and the information criteria.

Every fitter in pinmsk scores a model by a Gaussian log-likelihood of its
residuals, in one of two conventions, which give different numbers and are
never mixed silently -- each function takes ``variance=`` explicitly:

``variance="known"``
    The noise standard deviation ``sigma`` of every residual is known (the
    noise floor of the diagnosis).  ``-2 ln L = chi2 + const`` with
    ``chi2 = sum ((r / sigma)^2)`` (:func:`weighted_sse`), so, dropping the
    constant,

        AIC = chi2 + 2 k,        BIC = chi2 + k ln n.

``variance="estimated"``
    The residual variance is unknown and estimated by its maximum-likelihood
    value ``SSE / n``; ``-2 ln L = n ln(SSE / n) + const``, so

        AIC = n ln(SSE / n) + 2 k,        BIC = n ln(SSE / n) + k ln n.

    ``SSE`` may itself be weighted (a whitened chi2): the criteria then treat
    the weights as relative.

``n`` is the number of residuals and ``k`` the number of free parameters.
The ``*_change`` functions give criterion(after) - criterion(before) for a
model that adds ``k`` parameters, computed from the ratio ``SSE / SSE_before``
(not as the difference of two criteria, which would lose digits).  A negative
change favours the larger model.

Degenerate inputs: ``n`` is taken as at least 1, and in the ``"estimated"``
convention sums of squares as at least ``1e-300`` (a perfect fit scores a very
large negative, finite criterion instead of ``-inf``).

Only numpy is imported, so any layer may use this module.
"""
from __future__ import annotations

import numpy as np

__all__ = ["aic", "aic_change", "bic", "bic_change", "weighted_sse", "VARIANCE_CONVENTIONS"]

#: the accepted values of ``variance=``
VARIANCE_CONVENTIONS = ("known", "estimated")

#: floor of a sum of squares before its logarithm is taken
_SSE_FLOOR = 1e-300


def weighted_sse(residual, sigma, *, axis=None):
    """Weighted (noise-whitened) sum of squares ``sum ((residual / sigma)^2)``.

    ``sigma`` broadcasts against ``residual`` (e.g. one noise floor per
    channel, the last axis).  Returns a float when ``axis`` is None, else the
    array of sums over ``axis``.
    """
    r = np.asarray(residual, dtype=float) / sigma
    s = np.sum(r ** 2, axis=axis)
    return float(s) if axis is None else s


def _check(variance: str) -> None:
    if variance not in VARIANCE_CONVENTIONS:
        raise ValueError(f"variance must be one of {VARIANCE_CONVENTIONS}, got {variance!r}")


def _neg2_loglik(sse: float, n: int, variance: str) -> float:
    """``-2 ln L`` up to a constant: ``chi2`` (known) or ``n ln(SSE / n)`` (estimated)."""
    _check(variance)
    if variance == "known":
        return float(sse)
    return n * np.log(max(sse, _SSE_FLOOR) / n)


def aic(sse: float, *, n: int, k: int, variance: str) -> float:
    """Akaike's criterion of a Gaussian fit: ``chi2 + 2 k`` (known) or ``n ln(SSE / n) + 2 k`` (estimated).

    ``sse`` is the (weighted) sum of squares of the ``n`` residuals, ``k`` the
    number of free parameters; see the module docstring for ``variance``.
    """
    n = max(int(n), 1)
    return float(_neg2_loglik(sse, n, variance) + 2 * k)


def bic(sse: float, *, n: int, k: int, variance: str) -> float:
    """Schwarz's criterion of a Gaussian fit: ``chi2 + k ln n`` (known) or ``n ln(SSE / n) + k ln n`` (estimated).

    Arguments as for :func:`aic`.
    """
    n = max(int(n), 1)
    return float(_neg2_loglik(sse, n, variance) + k * np.log(n))


def _neg2_loglik_change(sse: float, sse_before: float, n: int, variance: str) -> float:
    _check(variance)
    if variance == "known":
        return sse - sse_before
    return n * np.log(max(sse, _SSE_FLOOR) / max(sse_before, _SSE_FLOOR))


def aic_change(sse: float, sse_before: float, *, n: int, k: int, variance: str) -> float:
    """``AIC(after) - AIC(before)`` when ``k`` parameters are added and the SSE goes from ``sse_before`` to ``sse``.

    ``chi2 - chi2_before + 2 k`` (known) or ``n ln(SSE / SSE_before) + 2 k``
    (estimated), over the same ``n`` residuals.
    """
    n = max(int(n), 1)
    return float(_neg2_loglik_change(sse, sse_before, n, variance) + 2 * k)


def bic_change(sse: float, sse_before: float, *, n: int, k: int, variance: str) -> float:
    """``BIC(after) - BIC(before)`` when ``k`` parameters are added and the SSE goes from ``sse_before`` to ``sse``.

    ``chi2 - chi2_before + k ln n`` (known) or ``n ln(SSE / SSE_before) +
    k ln n`` (estimated), over the same ``n`` residuals.
    """
    n = max(int(n), 1)
    return float(_neg2_loglik_change(sse, sse_before, n, variance) + k * np.log(n))
