"""Parametrizations (thesis Eq. 3.2, 3.4): analytic time derivatives vs finite differences."""
import numpy as np
import pytest

from pinmsk.errors import ModelError
from pinmsk.solvers.parametrization import Fourier, Polynomial, Spline, make_parametrization

PARS = [Polynomial(6, duration=0.5), Polynomial(10, duration=1.9), Fourier(5, period=1.9),
        Fourier(3, period=2.5, shift=0.3), Spline(9, duration=1.0)]


@pytest.mark.parametrize("par", PARS, ids=repr)
def test_derivatives_match_central_differences(par):
    rng = np.random.default_rng(0)
    P = rng.normal(size=(par.n_params, 3))
    t = np.linspace(0.05, 0.45, 17)
    h = 1e-5
    for d in (1, 2):
        num = (par.evaluate(P, t + h, d - 1) - par.evaluate(P, t - h, d - 1)) / (2 * h)
        ana = par.evaluate(P, t, d)
        scale = np.abs(ana).max() + 1.0
        assert np.abs(num - ana).max() < 1e-6 * scale


def test_polynomial_chebyshev_matches_thesis_monomials():
    par = Polynomial(6, duration=0.5)
    rng = np.random.default_rng(1)
    P = rng.normal(size=(7, 2))
    p = par.to_monomial(P)                       # thesis Eq. 3.2: u = sum p_k t^k
    t = np.linspace(0, 0.5, 11)
    mono = np.stack([t ** k for k in range(7)], axis=1) @ p
    assert np.allclose(mono, par.evaluate(P, t), atol=1e-10)
    # Chebyshev basis is bounded by 1 on the interval (conditioning, Eq. 3.11 discussion)
    assert np.abs(par.basis(t)).max() <= 1.0 + 1e-12


def test_fourier_is_eq_3_4_and_periodic():
    par = Fourier(2, period=2.0)
    P = np.array([0.1, 0.2, -0.3, 0.05, 0.07])    # A0, A1, B1, A2, B2
    t = np.array([0.0, 0.3, 1.1])
    w = 2 * np.pi / 2.0
    hand = (0.1 + 0.2 * np.sin(w * t) - 0.3 * np.cos(w * t)
            + 0.05 * np.sin(2 * w * t) + 0.07 * np.cos(2 * w * t))
    assert np.allclose(par.evaluate(P, t), hand, atol=1e-14)
    assert np.allclose(par.evaluate(P, t + 2.0), hand, atol=1e-12)


def test_fourier_period_derivative_matches_finite_difference():
    par = Fourier(4, period=1.7)
    t = np.linspace(0, 2, 9)
    h = 1e-6
    num = (par.with_period(1.7 + h).basis(t) - par.with_period(1.7 - h).basis(t)) / (2 * h)
    assert np.abs(num - par.basis_period_derivative(t)).max() < 1e-6


@pytest.mark.parametrize("par", PARS, ids=repr)
def test_fit_reproduces_a_member_and_constant(par):
    t = np.linspace(*par._span(), 60)
    P = np.random.default_rng(2).normal(size=(par.n_params, 2))
    assert np.allclose(par.fit(t, par.evaluate(P, t)), P, atol=1e-7)
    c = par.constant(0.3, 2)
    assert np.allclose(par.evaluate(c, t), 0.3, atol=1e-10)


def test_bad_parametrizations_are_named():
    with pytest.raises(ModelError, match="order"):
        Polynomial(-1, duration=1.0)
    with pytest.raises(ModelError, match="period"):
        Fourier(3, period=0.0)
    with pytest.raises(ModelError, match="valid: polynomial, fourier, spline"):
        make_parametrization("wavelet", duration=1.0)
    with pytest.raises(ModelError, match="coefficients per signal"):
        Polynomial(3, duration=1.0).evaluate(np.zeros((3, 1)), [0.0])
