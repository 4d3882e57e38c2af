"""pinmsk.stats: the weighted SSE and the information criteria against hand-computed values."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pinmsk import stats
from pinmsk.stats import aic, aic_change, bic, bic_change, weighted_sse


def test_weighted_sse_by_hand():
    r = np.array([[1.0, -2.0], [3.0, 4.0]])
    sigma = np.array([1.0, 2.0])                      # one noise floor per channel (last axis)
    # (1/1)^2 + (-2/2)^2 + (3/1)^2 + (4/2)^2 = 1 + 1 + 9 + 4
    assert weighted_sse(r, sigma) == 15.0
    assert isinstance(weighted_sse(r, sigma), float)
    np.testing.assert_array_equal(weighted_sse(r, sigma, axis=1), [2.0, 13.0])
    np.testing.assert_array_equal(weighted_sse(r, sigma, axis=0), [10.0, 5.0])


def test_known_variance_criteria_by_hand():
    # chi2 = 12.5 over n = 100 residuals, k = 3
    assert aic(12.5, n=100, k=3, variance="known") == 18.5
    assert bic(12.5, n=100, k=3, variance="known") == pytest.approx(12.5 + 3 * 4.605170185988092, abs=1e-12)
    assert bic_change(12.5, 20.0, n=100, k=3, variance="known") == pytest.approx(-7.5 + 13.815510557964274,
                                                                                 abs=1e-12)
    assert aic_change(12.5, 20.0, n=100, k=3, variance="known") == -1.5


def test_estimated_variance_criteria_by_hand():
    # SSE = 50 over n = 200 residuals: n ln(SSE/n) = 200 ln(0.25) = -400 ln 2
    ln2 = 0.6931471805599453
    assert aic(50.0, n=200, k=4, variance="estimated") == pytest.approx(-400 * ln2 + 8, abs=1e-10)
    assert bic(50.0, n=200, k=4, variance="estimated") == pytest.approx(-400 * ln2 + 4 * math.log(200), abs=1e-10)
    # halving the SSE with one extra parameter: n ln(1/2) + k_added (2 | ln n)
    assert aic_change(25.0, 50.0, n=200, k=1, variance="estimated") == pytest.approx(-200 * ln2 + 2, abs=1e-10)
    assert bic_change(25.0, 50.0, n=200, k=1, variance="estimated") == pytest.approx(-200 * ln2 + math.log(200),
                                                                                     abs=1e-10)


@pytest.mark.parametrize("variance", stats.VARIANCE_CONVENTIONS)
def test_change_equals_difference_of_criteria(variance):
    for crit, change in ((aic, aic_change), (bic, bic_change)):
        before = crit(80.0, n=500, k=2, variance=variance)
        after = crit(60.0, n=500, k=5, variance=variance)
        assert change(60.0, 80.0, n=500, k=3, variance=variance) == pytest.approx(after - before, abs=1e-9)


def test_the_two_conventions_differ_and_must_be_named():
    # same SSE, different numbers: the caller has to say which likelihood it means
    assert bic(50.0, n=200, k=4, variance="known") != bic(50.0, n=200, k=4, variance="estimated")
    with pytest.raises(ValueError, match="variance must be one of"):
        bic(50.0, n=200, k=4, variance="unknown")
    with pytest.raises(TypeError):
        aic(50.0, n=200, k=4)                                   # no default convention


def test_degenerate_inputs_stay_finite():
    assert np.isfinite(aic(0.0, n=10, k=1, variance="estimated"))      # perfect fit: SSE floored at 1e-300
    assert bic_change(1.0, 1.0, n=0, k=2, variance="known") == 0.0    # n floored at 1: ln 1 = 0
    assert bic_change(0.0, 0.0, n=5, k=0, variance="estimated") == 0.0


@pytest.mark.parametrize("variance", stats.VARIANCE_CONVENTIONS)
def test_criteria_prefer_the_true_polynomial_over_an_overfit(variance):
    """Quadratic data with known noise: degree 2 beats degree 1 (underfit) and degree 9 (overfit)."""
    rng = np.random.default_rng(0)
    x = np.linspace(-1.0, 1.0, 200)
    sigma = 0.1
    y = 1.0 - 2.0 * x + 3.0 * x ** 2 + sigma * rng.standard_normal(x.size)
    scores, sse_of = {}, {}
    for deg in (1, 2, 9):
        coef = np.polynomial.polynomial.polyfit(x, y, deg)
        r = y - np.polynomial.polynomial.polyval(x, coef)
        # known: chi2 with the true sigma; estimated: the plain SSE, sigma unknown
        sse = weighted_sse(r, sigma) if variance == "known" else float(np.sum(r ** 2))
        sse_of[deg] = sse
        scores[deg] = (aic(sse, n=x.size, k=deg + 1, variance=variance),
                       bic(sse, n=x.size, k=deg + 1, variance=variance))
    for i in (0, 1):
        assert scores[2][i] < scores[1][i] and scores[2][i] < scores[9][i], scores
    # the overfit lowers the SSE, so only the penalty ranks it below the truth
    assert sse_of[9] < sse_of[2]
    assert bic_change(sse_of[9], sse_of[2], n=x.size, k=7, variance=variance) > 0
    assert aic_change(sse_of[9], sse_of[2], n=x.size, k=7, variance=variance) > 0


def test_stats_imports_only_numpy():
    import ast
    import inspect
    tree = ast.parse(inspect.getsource(stats))
    mods = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    mods |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level == 0}
    assert mods <= {"numpy", "__future__"}, mods
    assert not any(isinstance(n, ast.ImportFrom) and n.level > 0 for n in ast.walk(tree))
