"""Nagano-Gerritsen muscle with the Winters tendon (thesis App. A.4-A.5)."""
import math
import pickle

import numpy as np
import pytest

from pinmsk.errors import ModelError, TrialError
from pinmsk.muscles import (NaganoGerritsen, ng_activation_from_force, ng_activation_hat,
                            ng_fiber_force, ng_fiber_force_partials, ng_fiber_velocity,
                            ng_force_length, ng_force_length_derivative, winters_tendon_force,
                            winters_tendon_stiffness, winters_tendon_stiffness_derivative,
                            winters_tendon_strain)

A, B, FH = 0.41, 5.2, 1.4


def fd(f, x, h=1e-6):
    return (f(x + h) - f(x - h)) / (2 * h)


def printed_A12(f_ce, a, fi):
    """Eq. A.12 with the Eq. A.14 coefficients exactly as printed (Gamma = 1), in l_opt/s."""
    ah = np.minimum(1.0, 10.0 * a / 3.0)
    q = f_ce / a
    c2 = -fi * FH
    c1 = ah * B * (fi + c2) ** 2 / (fi + A * 1.0)
    c3 = c1 / (fi + c2)
    con = -ah * ((fi + A) * B / (q + A) - B)
    ecc = -(c1 / (q + c2) - c3)
    return np.where(q <= fi, con, ecc)


def gait():
    """Thesis Table 5.3 (Gl, Vas, Sol)."""
    return NaganoGerritsen(f_max=[1705.0, 7403.0, 3883.0], l_opt=[0.200, 0.093, 0.055],
                           l_slack=[0.157, 0.223, 0.245], pennation=np.deg2rad([3.0, 4.4, 23.6]),
                           width=[0.625, 0.627, 1.039], names=["Gl", "Vas", "Sol"],
                           fast_fraction=[0.45, 0.50, 0.20])


# ----------------------------------------------------------------------------- Winters tendon
def test_winters_tendon():
    assert winters_tendon_force(0.04) == pytest.approx(1.0, rel=1e-15)
    assert winters_tendon_force(0.02) == pytest.approx(0.25, rel=1e-15)
    assert winters_tendon_force(-0.01) == 0.0
    # Eq. A.10-A.11 in newtons: k_t (l_t - l_slack)^2, k_t = F_max/(0.04 l_slack)^2
    mus = gait()
    l_t = mus.l_slack * 1.031
    k_t = mus.f_max / (0.04 * mus.l_slack) ** 2
    np.testing.assert_allclose(mus.tendon_force(l_t), k_t * (l_t - mus.l_slack) ** 2, rtol=1e-12)
    np.testing.assert_array_equal(mus.tendon_force(mus.l_slack * 0.99), 0.0)
    eps = np.linspace(0, 0.1, 1001)
    np.testing.assert_allclose(winters_tendon_strain(winters_tendon_force(eps)), eps, atol=1e-15)
    e = eps[1:]
    np.testing.assert_allclose(winters_tendon_stiffness(e), fd(winters_tendon_force, e, 1e-7),
                               rtol=1e-7)
    np.testing.assert_allclose(winters_tendon_stiffness_derivative(e),
                               fd(winters_tendon_stiffness, e, 1e-7), rtol=1e-7)


# ----------------------------------------------------------------------------- CE curves
def test_force_length_A13():
    w = 0.627
    assert ng_force_length(1.0, w) == 1.0
    assert ng_force_length(1 + w, w) == pytest.approx(0.0, abs=1e-15)
    assert ng_force_length(1 - w, w) == pytest.approx(0.0, abs=1e-15)
    assert ng_force_length(1 + 1.5 * w, w) == 0.0         # parabola clipped, no pushing fiber
    l = np.linspace(1 - 0.99 * w, 1 + 0.99 * w, 1001)
    c = -1 / w ** 2
    np.testing.assert_allclose(ng_force_length(l, w), c * l ** 2 - 2 * c * l + c + 1, rtol=1e-12,
                               atol=1e-14)
    assert l[np.argmax(ng_force_length(l, w))] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(ng_force_length_derivative(l, w),
                               fd(lambda x: ng_force_length(x, w), l), rtol=1e-7, atol=1e-9)


def test_activation_hat():
    np.testing.assert_allclose(ng_activation_hat([0.0, 0.15, 0.3, 0.7]), [0.0, 0.5, 1.0, 1.0])


def test_fiber_velocity_is_printed_A12_A14():
    rng = np.random.default_rng(1)
    a = rng.uniform(0.02, 1, 5000)
    fi = rng.uniform(0.05, 1, 5000)
    q = rng.uniform(0.001, 1.399, 5000) * fi            # -A < q < f_hat f_isom
    f = a * q
    np.testing.assert_allclose(ng_fiber_velocity(f, a, fi), printed_A12(f, a, fi), rtol=1e-10,
                               atol=1e-12)


def test_curve_points():
    # isometric: f = a f_isom; max shortening at f = 0: v = -a_hat B f_isom / A (l_opt/s)
    assert ng_fiber_force(0.0, 0.6, 0.8) == pytest.approx(0.48, rel=1e-15)
    assert ng_fiber_velocity(0.0, 1.0, 1.0) == pytest.approx(-B / A, rel=1e-14)
    assert ng_fiber_velocity(0.0, 0.15, 1.0) == pytest.approx(-0.5 * B / A, rel=1e-14)
    assert ng_fiber_force(-0.5 * B / A, 0.15, 1.0) == pytest.approx(0.0, abs=1e-15)
    # eccentric asymptote a f_hat f_isom
    assert ng_fiber_force(1e6, 0.5, 0.9) == pytest.approx(0.5 * 1.4 * 0.9, rel=1e-5)
    assert ng_fiber_velocity(0.5 * 1.4 * 0.9, 0.5, 0.9) == np.inf
    # Gamma = 1: the slopes of the two branches match at v = 0 (C1)
    for a in (0.1, 0.6):
        left = (ng_fiber_force(0.0, a, 0.7) - ng_fiber_force(-1e-7, a, 0.7)) / 1e-7
        right = (ng_fiber_force(1e-7, a, 0.7) - ng_fiber_force(0.0, a, 0.7)) / 1e-7
        assert left == pytest.approx(right, rel=1e-5)
    v = np.linspace(-15, 15, 30001)
    assert np.all(np.diff(ng_fiber_force(v, 0.4, 0.8)) > 0)


def test_force_velocity_round_trip():
    rng = np.random.default_rng(2)
    a = rng.uniform(0.01, 1, 20000)
    fi = rng.uniform(0.05, 1, 20000)
    v = rng.uniform(-12, 12, 20000)
    f = ng_fiber_force(v, a, fi)
    ok = f / a > -A * 0.999
    np.testing.assert_allclose(ng_fiber_velocity(f[ok], a[ok], fi[ok]), v[ok], rtol=1e-9, atol=1e-10)
    q = rng.uniform(-0.4, 1.399, 20000) * fi
    np.testing.assert_allclose(ng_fiber_force(ng_fiber_velocity(a * q, a, fi), a, fi), a * q,
                               rtol=1e-10, atol=1e-12)


def test_partials_fd():
    rng = np.random.default_rng(3)
    a = rng.uniform(0.02, 1, 4000)
    fi = rng.uniform(0.1, 1, 4000)
    v = rng.uniform(-6, 6, 4000)
    f, dv, da, dfi = ng_fiber_force_partials(v, a, fi)
    np.testing.assert_allclose(f, ng_fiber_force(v, a, fi), rtol=1e-14)
    np.testing.assert_allclose(dv, fd(lambda x: ng_fiber_force(x, a, fi), v), rtol=1e-6, atol=1e-9)
    ok = np.abs(a - 0.3) > 1e-4                    # a_hat = min(1, a/0.3) has a kink at 0.3
    np.testing.assert_allclose(da[ok], fd(lambda x: ng_fiber_force(v, x, fi), a)[ok], rtol=1e-6,
                               atol=1e-9)
    np.testing.assert_allclose(dfi, fd(lambda x: ng_fiber_force(v, a, x), fi), rtol=1e-6,
                               atol=1e-9)


def test_zero_activation_gives_zero_force_and_one_sided_partials():
    """a = 0 makes a_hat = 0 and Eq. A.12 a 0/0; the force is its limit, 0 (it was NaN)."""
    v = np.array([-3.0, -0.1, 0.0, 0.1, 3.0])
    fi = np.array([0.9, 0.5, 0.7, 0.6, 0.8])
    a = np.zeros(5)
    assert np.array_equal(ng_fiber_force(v, a, fi), np.zeros(5))
    f, dv, da, dfi = ng_fiber_force_partials(v, a, fi)
    assert np.array_equal(f, np.zeros(5)) and np.array_equal(dv, np.zeros(5)) and np.array_equal(dfi, np.zeros(5))
    h = 1e-9
    np.testing.assert_allclose(da, ng_fiber_force(v, h, fi) / h, rtol=1e-6)   # one-sided, a >= 0
    assert da[0] == pytest.approx(-A) and da[2] == pytest.approx(0.7)


def test_activation_closed_form():
    rng = np.random.default_rng(4)
    a = rng.uniform(0.0, 1.3, (500, 6))          # both a_hat branches
    fi = rng.uniform(0.05, 1, (500, 6))
    v = rng.uniform(-4, 4, (500, 6))             # both velocity branches
    f = ng_fiber_force(v, a, fi)
    ok = f > 0
    a2 = ng_activation_from_force(f, fi, v)
    np.testing.assert_allclose(a2[ok], a[ok], rtol=0, atol=1e-12)
    assert np.all(a2[~ok] == 0)
    assert ng_activation_from_force(0.24, 0.8, 0.0) == pytest.approx(0.3, rel=1e-15)
    assert ng_activation_from_force(0.5, 0.0, 0.0) == np.inf       # no force-length capacity


# ----------------------------------------------------------------------------- model object
def test_model_parameters_and_immutability():
    mus = gait()
    assert mus.n == 3 and mus.names == ("Gl", "Vas", "Sol")
    np.testing.assert_allclose(mus.fast_fraction, [0.45, 0.50, 0.20])
    assert not hasattr(mus, "v_max")
    with pytest.raises(AttributeError):
        mus.width = 1.0
    assert pickle.loads(pickle.dumps(mus)) == mus
    with pytest.raises(ModelError, match=r"width = 0.0 for muscle 1"):
        NaganoGerritsen(f_max=1.0, l_opt=0.1, l_slack=0.2, width=[0.5, 0.0])
    with pytest.raises(ModelError, match=r"f_max = 0.0 for muscle 0"):
        NaganoGerritsen(f_max=[0.0, 1.0], l_opt=0.1, l_slack=0.2, width=0.5)
    with pytest.raises(ModelError, match="fast_fraction"):
        NaganoGerritsen(f_max=1.0, l_opt=0.1, l_slack=0.2, width=0.5, fast_fraction=1.5)


def states(mus, n, seed=0):
    rng = np.random.default_rng(seed)
    l_norm = rng.uniform(0.7, 1.3, (n, mus.n))
    x = np.sqrt((l_norm * mus.l_opt) ** 2 - mus.height ** 2)
    l_mt = mus.l_slack * (1 + rng.uniform(0.0, 0.04, (n, mus.n))) + x
    return l_mt, rng.uniform(-0.3, 0.3, (n, mus.n)), rng.uniform(0.0, 1.0, (n, mus.n))


def test_force_limits_and_rigid_force():
    mus = gait()
    l_mt, v_mt, a = states(mus, 400)
    Fa, Fp = mus.force_limits(l_mt, v_mt)
    np.testing.assert_array_equal(Fp, 0.0)
    np.testing.assert_allclose(Fa, mus.force(1.0, l_mt, v_mt), rtol=1e-14)
    hi = a >= 0.3                         # a_hat = 1: force is linear in activation
    np.testing.assert_allclose((a * Fa)[hi], mus.force(a, l_mt, v_mt)[hi], rtol=1e-13)
    Fa0, _ = mus.force_limits(l_mt, 0.0)  # isometric: linear for every a
    np.testing.assert_allclose(a * Fa0, mus.force(a, l_mt, 0.0), rtol=1e-13)
    Fa, _ = mus.force_limits(mus.l_slack + mus.l_opt * np.cos(mus.pennation), 0.0)
    np.testing.assert_allclose(Fa, mus.f_max * np.cos(mus.pennation), rtol=1e-14)


def test_equilibrium():
    mus = gait()
    l_mt, v_mt, a = states(mus, 3000, seed=1)
    a = np.maximum(a, 0.01)
    eq = mus.equilibrium(l_mt, a)
    l = eq["l_ce"]
    x = np.sqrt(l * l - mus.height ** 2)
    f_t = winters_tendon_force((l_mt - x) / mus.l_slack - 1)
    res = np.abs(f_t - a * ng_force_length(l / mus.l_opt, mus.width) * x / l)
    assert res.max() < 1e-9
    np.testing.assert_allclose(eq["force"], mus.f_max * f_t, rtol=1e-12)
    np.testing.assert_allclose(mus.contraction_rate(l, l_mt, a) / mus.l_opt, 0.0, atol=1e-7)
    rows = np.array([mus.equilibrium(l_mt[k], a[k])["l_ce"] for k in range(30)])
    np.testing.assert_allclose(rows, l[:30], rtol=0, atol=1e-12)
    # with the velocity share; shortening within what the fiber can do (a >= 0.3:
    # unloaded shortening speed B f_isom / A >= 4 l_opt/s at f_isom >= 0.3)
    a_d = 0.3 + 0.7 * a[:500]
    v_d = np.random.default_rng(5).uniform(-2, 2, a_d.shape) * mus.l_opt
    eq_d = mus.equilibrium(l_mt[:500], a_d, v_d)
    l = eq_d["l_ce"]
    x = np.sqrt(l * l - mus.height ** 2)
    f_t = winters_tendon_force((l_mt[:500] - x) / mus.l_slack - 1)
    fi = ng_force_length(l / mus.l_opt, mus.width)
    res = np.abs(f_t - ng_fiber_force(eq_d["v_ce"] / mus.l_opt, a_d, fi) * x / l)
    assert res.max() < 1e-9
    assert np.all(eq_d["v_ce"] * v_d >= 0)


def test_bad_inputs():
    mus = gait()
    l_mt, v_mt, a = states(mus, 6)
    v_mt[2, 1] = np.inf
    with pytest.raises(TrialError, match=r"v_mt is inf for muscle 1 \('Vas'\) at frame 2"):
        mus.force_limits(l_mt, v_mt)
    with pytest.raises(TrialError, match=r"a is nan for muscle 0 \('Gl'\)"):
        mus.equilibrium(l_mt[0], [math.nan, 0.2, 0.3])
