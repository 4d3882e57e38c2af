"""Thelen 2003 muscle (thesis App. A.3): curve values, inverses, derivatives, equilibrium, model object."""
import math
import pickle

import numpy as np
import pytest

from pinmsk.errors import ConvergenceError, ModelError, TrialError
from pinmsk.muscles import (Thelen2003, pennation_angle, thelen_activation_from_force,
                            thelen_active_force_length, thelen_active_force_length_derivative,
                            thelen_fiber_force, thelen_fiber_force_partials, thelen_fiber_velocity,
                            thelen_force_velocity, thelen_force_velocity_derivative,
                            thelen_force_velocity_inverse, thelen_passive_force_length,
                            thelen_passive_force_length_derivative, thelen_tendon_force,
                            thelen_tendon_stiffness, thelen_tendon_stiffness_derivative,
                            thelen_tendon_strain)

EPS_TOE = 0.609 * 0.04


def fd(f, x, h=1e-6):
    return (f(x + h) - f(x - h)) / (2 * h)


# ----------------------------------------------------------------------------- tendon (A.6)
def test_tendon_value_at_reference_strain():
    # With the printed constants Eq. A.6 gives 1.712/0.04 * (0.04 - 0.609*0.04) + 0.33
    # = 42.8 * 0.01564 + 0.33 = 0.999392, within 1e-3 of the nominal 1.
    assert thelen_tendon_force(0.04) == pytest.approx(0.999392, abs=1e-12)
    assert abs(thelen_tendon_force(0.04) - 1.0) < 1e-3


def test_tendon_toe_continuity():
    left = thelen_tendon_force(EPS_TOE - 1e-13)
    right = thelen_tendon_force(EPS_TOE + 1e-13)
    assert thelen_tendon_force(EPS_TOE) == pytest.approx(0.33, abs=1e-14)     # C0 exactly
    assert abs(left - right) < 1e-11
    # C1 only approximately with the rounded constants: the exponential's slope
    # at the toe is 3*0.33 e^3/((e^3 - 1) 0.02436) = 42.7698 vs k_lin = 42.8.
    k_left = thelen_tendon_stiffness(EPS_TOE - 1e-12)
    k_right = thelen_tendon_stiffness(EPS_TOE + 1e-12)
    assert k_left == pytest.approx(3 * 0.33 * math.e ** 3 / (math.expm1(3) * EPS_TOE), rel=1e-9)
    assert k_left == pytest.approx(42.76978, abs=1e-5)
    assert k_right == 42.8
    assert abs(k_right - k_left) / k_right < 1e-3


def test_tendon_slack_and_round_trip():
    assert thelen_tendon_force(0.0) == 0.0
    assert thelen_tendon_force(-0.02) == 0.0
    eps = np.linspace(0, 0.12, 2001)
    np.testing.assert_allclose(thelen_tendon_strain(thelen_tendon_force(eps)), eps, rtol=0,
                               atol=1e-14)
    f = np.linspace(0, 3, 1001)
    np.testing.assert_allclose(thelen_tendon_force(thelen_tendon_strain(f)), f, rtol=1e-13,
                               atol=1e-15)
    assert thelen_tendon_strain(-0.5) == 0.0


def test_tendon_derivatives_fd():
    eps = np.concatenate([np.linspace(1e-4, EPS_TOE - 1e-4, 50), np.linspace(EPS_TOE + 1e-4, 0.1, 50)])
    np.testing.assert_allclose(thelen_tendon_stiffness(eps), fd(thelen_tendon_force, eps),
                               rtol=1e-7)
    np.testing.assert_allclose(thelen_tendon_stiffness_derivative(eps),
                               fd(thelen_tendon_stiffness, eps), rtol=1e-6, atol=1e-6)


# ----------------------------------------------------------------------------- fiber curves
def test_active_force_length_peak_and_shape():
    assert thelen_active_force_length(1.0) == 1.0
    l = np.linspace(0.3, 1.7, 14001)
    assert l[np.argmax(thelen_active_force_length(l))] == pytest.approx(1.0, abs=1e-12)
    # (l - 1)^2 = gamma gives e^-1 (Eq. A.8 with gamma = 0.45)
    assert thelen_active_force_length(1 + math.sqrt(0.45)) == pytest.approx(math.exp(-1), rel=1e-14)
    np.testing.assert_allclose(thelen_active_force_length_derivative(l),
                               fd(thelen_active_force_length, l), rtol=1e-7, atol=1e-9)


def test_passive_force_length():
    assert thelen_passive_force_length(1.0) == 0.0
    assert thelen_passive_force_length(0.7) == 0.0
    # passive strain 0.6 gives F_max: (e^5 - 1)/(e^5 - 1)
    assert thelen_passive_force_length(1.6) == pytest.approx(1.0, rel=1e-14)
    assert thelen_passive_force_length(1.3) == pytest.approx(math.expm1(2.5) / math.expm1(5), rel=1e-14)
    l = np.linspace(1.001, 1.8, 200)
    np.testing.assert_allclose(thelen_passive_force_length_derivative(l),
                               fd(thelen_passive_force_length, l), rtol=1e-7)


def test_force_velocity_curve_points():
    assert thelen_force_velocity(0.0) == 1.0
    assert thelen_force_velocity(-1.0) == 0.0
    # eccentric hyperbola (1 + c f_hat w)/(1 + c w), c = (2 + 2/A_f)/(f_hat - 1) = 25
    assert thelen_force_velocity(0.1) == pytest.approx(4.5 / 3.5, rel=1e-14)
    # concentric (1 + w)/(1 - w/A_f)
    assert thelen_force_velocity(-0.5) == pytest.approx(0.5 / 3.0, rel=1e-14)
    # linear tail starts at 0.95 f_hat = 1.33; below the asymptote 1.4 until then
    w_thr = 0.33 / (25 * 0.07)
    assert thelen_force_velocity(w_thr) == pytest.approx(1.33, rel=1e-13)
    w = np.linspace(-2, 3, 50001)
    fv = thelen_force_velocity(w)
    assert np.all(np.diff(fv) > 0)
    assert fv[(w > 0) & (w < w_thr)].max() < 1.4


def test_force_velocity_inverse_and_derivative():
    w = np.linspace(-2.5, 3, 20001)
    np.testing.assert_allclose(thelen_force_velocity_inverse(thelen_force_velocity(w)), w,
                               rtol=0, atol=1e-12)
    mask = np.abs(w) > 1e-5          # kink at 0: slopes 5 (concentric) and 10 (eccentric)
    np.testing.assert_allclose(thelen_force_velocity_derivative(w)[mask],
                               fd(thelen_force_velocity, w)[mask], rtol=1e-7)
    assert thelen_force_velocity_derivative(-1e-12) == pytest.approx(5.0)
    assert thelen_force_velocity_derivative(1e-12) == pytest.approx(10.0)


def test_fiber_velocity_is_printed_A9():
    rng = np.random.default_rng(3)
    a = rng.uniform(0.02, 1, 4000)
    fi = rng.uniform(0.05, 1, 4000)
    f = rng.uniform(0.0, 0.949 * 1.4, 4000) * a * fi           # inside the printed domain
    b = np.where(f <= a * fi, a * fi + f / 0.25, (2 + 2 / 0.25) * (a * fi * 1.4 - f) / 0.4)
    v_max = 1.3
    printed = (0.25 + 0.75 * a) * v_max * (f - a * fi) / b
    np.testing.assert_allclose(thelen_fiber_velocity(f, a, fi, v_max=v_max), printed,
                               rtol=1e-12, atol=1e-15)


def test_force_velocity_round_trip_both_directions():
    rng = np.random.default_rng(4)
    a = rng.uniform(0.01, 1, 20000)
    fi = rng.uniform(0.05, 1, 20000)
    v = rng.uniform(-1.5, 2.0, 20000)           # covers both linear tails
    f = thelen_fiber_force(v, a, fi)
    np.testing.assert_allclose(thelen_fiber_velocity(f, a, fi), v, rtol=0, atol=1e-10)
    f2 = rng.uniform(-0.2, 1.6, 20000) * a * fi
    np.testing.assert_allclose(thelen_fiber_force(thelen_fiber_velocity(f2, a, fi), a, fi), f2,
                               rtol=0, atol=1e-12)
    # maximum shortening velocity scales with 0.25 + 0.75 a
    assert thelen_fiber_velocity(0.0, 0.2, 0.8, v_max=2.0) == pytest.approx(-(0.25 + 0.15) * 2.0)


def test_fiber_force_partials_fd():
    rng = np.random.default_rng(5)
    a = rng.uniform(0.05, 1, 3000)
    fi = rng.uniform(0.1, 1, 3000)
    v = rng.uniform(-1.2, 1.0, 3000)
    f, dv, da, dfi = thelen_fiber_force_partials(v, a, fi)
    np.testing.assert_allclose(f, thelen_fiber_force(v, a, fi), rtol=1e-15)
    ok = np.abs(v) > 1e-4
    np.testing.assert_allclose(dv[ok], fd(lambda x: thelen_fiber_force(x, a, fi), v)[ok],
                               rtol=1e-6, atol=1e-9)
    s = 0.25 + 0.75 * a
    ok = np.abs(v / s) > 1e-4
    np.testing.assert_allclose(da[ok], fd(lambda x: thelen_fiber_force(v, x, fi), a)[ok],
                               rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(dfi, fd(lambda x: thelen_fiber_force(v, a, x), fi), rtol=1e-8)


def test_activation_from_force_round_trip():
    rng = np.random.default_rng(6)
    a = rng.uniform(0.0, 1.2, (400, 5))
    fi = rng.uniform(0.05, 1, (400, 5))
    v = rng.uniform(-0.8, 1.0, (400, 5))
    f = thelen_fiber_force(v, a, fi)
    ok = f > 0
    a2 = thelen_activation_from_force(f, fi, v)
    np.testing.assert_allclose(a2[ok], a[ok], rtol=0, atol=1e-12)
    assert np.all(a2[~ok] == 0)
    # closed form at v = 0
    assert thelen_activation_from_force(0.3, 0.6, 0.0) == pytest.approx(0.5, abs=1e-15)


# ----------------------------------------------------------------------------- model object
def forearm():
    """Thesis Table 3.2 (BRD, BICLH, BRA, TRILH)."""
    return Thelen2003(f_max=[101.58, 392.91, 853.90, 692.21],
                      l_opt=[0.2703, 0.1536, 0.1028, 0.1524],
                      l_slack=[0.0604, 0.2293, 0.0175, 0.1905],
                      pennation=np.deg2rad([5.0, 10.0, 15.0, 15.0]),
                      names=["BRD", "BICLH", "BRA", "TRILH"],
                      volume=[83.19e-6, 182.92e-6, 256.96e-6, 290.67e-6])


def states(mus, n=2000, seed=0):
    rng = np.random.default_rng(seed)
    l_norm = rng.uniform(0.6, 1.5, (n, mus.n))
    x = np.sqrt((l_norm * mus.l_opt) ** 2 - mus.height ** 2)
    l_mt = mus.l_slack * (1 + rng.uniform(0.0, 0.05, (n, mus.n))) + x
    a = rng.uniform(0.0, 1.0, (n, mus.n))
    v_mt = rng.uniform(-0.5, 0.5, (n, mus.n))
    return l_mt, v_mt, a


def test_parameters_stored_and_defaults():
    mus = forearm()
    assert mus.n == 4 and mus.names == ("BRD", "BICLH", "BRA", "TRILH")
    np.testing.assert_array_equal(mus.v_max, 10 * mus.l_opt)
    np.testing.assert_allclose(mus.volume, [83.19e-6, 182.92e-6, 256.96e-6, 290.67e-6])
    assert mus.fast_fraction is None
    assert Thelen2003(f_max=1.0, l_opt=0.1, l_slack=0.2, fast_fraction=[0.3, 0.6]).n == 2


def test_immutable_copies_and_pickle():
    f_max = np.array([100.0, 200.0])
    mus = Thelen2003(f_max=f_max, l_opt=0.1, l_slack=0.2, pennation=0.1)
    f_max[0] = -1
    assert mus.f_max[0] == 100.0
    with pytest.raises(ValueError):
        mus.f_max[0] = 5.0
    with pytest.raises(AttributeError, match="immutable"):
        mus.f_max = np.ones(2)
    clone = pickle.loads(pickle.dumps(mus))
    assert clone == mus and not clone.f_max.flags.writeable
    assert mus.replace(l_opt=0.2).l_opt[1] == 0.2 and mus.l_opt[1] == 0.1
    with pytest.raises(TypeError):
        Thelen2003(100.0, 0.1, 0.2)


def test_bad_parameters_name_the_muscle():
    with pytest.raises(ModelError, match=r"f_max = -5.0 for muscle 1"):
        Thelen2003(f_max=[100.0, -5.0, 3.0], l_opt=0.1, l_slack=0.2)
    with pytest.raises(ModelError, match=r"l_opt = 0.0 for muscle 2 \('c'\)"):
        Thelen2003(f_max=1.0, l_opt=[0.1, 0.1, 0.0], l_slack=0.2, names=["a", "b", "c"])
    with pytest.raises(ModelError, match="pennation"):
        Thelen2003(f_max=1.0, l_opt=0.1, l_slack=0.2, pennation=[0.1, np.pi / 2])
    with pytest.raises(ModelError, match="l_slack = nan"):
        Thelen2003(f_max=1.0, l_opt=0.1, l_slack=[0.2, np.nan])


def test_bad_inputs_name_frame_and_muscle():
    mus = forearm()
    l_mt, v_mt, a = states(mus, 10)
    l_mt[7, 2] = np.nan
    with pytest.raises(TrialError, match=r"l_mt is nan for muscle 2 \('BRA'\) at frame 7"):
        mus.force_limits(l_mt, v_mt)
    with pytest.raises(TrialError, match=r"muscle 2 \('BRA'\) at frame 7"):
        mus.equilibrium(l_mt, a)
    l_mt, v_mt, a = states(mus, 10)
    l_mt[3, 1] = mus.l_slack[1] * 0.99
    with pytest.raises(TrialError, match=r"no room for the fiber at muscle 1 \('BICLH'\) at frame 3"):
        mus.fiber_kinematics_rigid(l_mt, v_mt)
    l_mt, v_mt, a = states(mus, 10)
    a[4, 0] = -0.1
    with pytest.raises(TrialError, match=r"activation must be >= 0.*muscle 0 \('BRD'\) at frame 4"):
        mus.equilibrium(l_mt, a)
    with pytest.raises(ModelError, match="tendon must be"):
        mus.force(a, l_mt, v_mt, tendon="elastic")


def test_pennation_and_rigid_kinematics():
    mus = forearm()
    l_mt = mus.l_slack + mus.l_opt * np.cos(mus.pennation)
    l_ce, v_ce = mus.fiber_kinematics_rigid(l_mt, -0.2)
    np.testing.assert_allclose(l_ce, mus.l_opt, rtol=1e-15)
    np.testing.assert_allclose(v_ce, -0.2 * np.cos(mus.pennation), rtol=1e-15)
    l_mt, v_mt, _ = states(mus, 100)
    l_ce, _ = mus.fiber_kinematics_rigid(l_mt, v_mt)
    # constant thickness: l_ce sin(alpha) = l_opt sin(alpha_opt)
    np.testing.assert_allclose(l_ce * np.sin(pennation_angle(l_ce, mus.height)),
                               mus.l_opt * np.sin(mus.pennation) + 0 * l_ce, rtol=1e-13)
    # v_ce is the time derivative of l_ce along l_mt
    h = 1e-7
    lp, _ = mus.fiber_kinematics_rigid(l_mt + h * v_mt, 0.0)
    lm, _ = mus.fiber_kinematics_rigid(l_mt - h * v_mt, 0.0)
    np.testing.assert_allclose(mus.fiber_kinematics_rigid(l_mt, v_mt)[1], (lp - lm) / (2 * h),
                               rtol=1e-6, atol=1e-10)


def test_force_limits():
    mus = Thelen2003(f_max=[1000.0, 500.0], l_opt=[0.1, 0.2], l_slack=[0.3, 0.2], pennation=0.0)
    Fa, Fp = mus.force_limits(mus.l_slack + mus.l_opt, 0.0)
    np.testing.assert_allclose(Fa, mus.f_max, rtol=1e-15)            # f_L(1) f_V(0) = 1
    np.testing.assert_allclose(Fp, 0.0, atol=1e-11)                 # roundoff in l_mt - l_slack
    Fa, Fp = mus.force_limits(mus.l_slack + 1.6 * mus.l_opt, 0.0)    # passive = F_max at 1.6 l_opt
    np.testing.assert_allclose(Fp, mus.f_max, rtol=1e-13)
    np.testing.assert_allclose(Fa, mus.f_max * math.exp(-0.36 / 0.45), rtol=1e-13)
    Fa, _ = mus.force_limits(mus.l_slack + mus.l_opt, -mus.v_max)     # max shortening: 0
    np.testing.assert_allclose(Fa, 0.0, atol=1e-12)

    fa = forearm()
    l_mt, v_mt, a = states(fa, 500)
    Fa, Fp = fa.force_limits(l_mt, v_mt)
    assert Fa.shape == Fp.shape == (500, 4)
    # exact at a = 1 and a = 0; for all a when the fiber is isometric
    np.testing.assert_allclose(Fa + Fp, fa.force(1.0, l_mt, v_mt), rtol=1e-13)
    np.testing.assert_allclose(Fp, fa.force(0.0, l_mt, v_mt), rtol=1e-13, atol=1e-12)
    Fa0, Fp0 = fa.force_limits(l_mt, 0.0)
    np.testing.assert_allclose(a * Fa0 + Fp0, fa.force(a, l_mt, 0.0), rtol=1e-13)


def equilibrium_residual(mus, l_mt, a, eq):
    """Normalized |F_t - (F_ce + F_pe) cos(alpha)| from the returned fiber length."""
    l = eq["l_ce"]
    x = np.sqrt(l * l - mus.height ** 2)
    f_t = thelen_tendon_force((l_mt - x) / mus.l_slack - 1)
    ln = l / mus.l_opt
    f_fib = thelen_fiber_force(eq["v_ce"], a, thelen_active_force_length(ln), v_max=mus.v_max) \
        + thelen_passive_force_length(ln)
    return np.abs(f_t - f_fib * x / l), f_t


def test_equilibrium_isometric():
    mus = forearm()
    l_mt, _, a = states(mus, 4000)
    eq = mus.equilibrium(l_mt, a)
    res, f_t = equilibrium_residual(mus, l_mt, a, eq)
    assert res.max() < 1e-9
    np.testing.assert_array_equal(eq["v_ce"], 0.0)
    np.testing.assert_allclose(eq["force"], mus.f_max * f_t, rtol=1e-9)
    # a fiber in equilibrium does not move: the contraction ODE returns ~0 there
    a_pos = np.maximum(a, 0.02)
    eq = mus.equilibrium(l_mt, a_pos)
    v = mus.contraction_rate(eq["l_ce"], l_mt, a_pos)
    assert np.abs(v / mus.v_max).max() < 1e-7
    # the tendon force law applied at the implied tendon length
    x = np.sqrt(eq["l_ce"] ** 2 - mus.height ** 2)
    np.testing.assert_allclose(mus.tendon_force(l_mt - x), eq["force"], rtol=1e-12)


def test_equilibrium_with_velocity_share():
    mus = forearm()
    l_mt, _, a = states(mus, 1000, seed=2)
    # within what the fibers can follow: |v_mt| <= 3 l_opt/s, a >= 0.2 (max shortening >= 4 l_opt/s)
    rng = np.random.default_rng(12)
    a = 0.2 + 0.8 * a
    v_mt = rng.uniform(-3, 3, a.shape) * mus.l_opt
    eq = mus.equilibrium(l_mt, a, v_mt)
    res, _ = equilibrium_residual(mus, l_mt, a, eq)
    assert res.max() < 1e-9
    # the fiber takes the series-stiffness share of v_mt: x' = k_t v_mt / (k_t + k_m),
    # k_t the tendon and k_m the isometric fiber stiffness along the line of action
    l = eq["l_ce"]
    x = np.sqrt(l * l - mus.height ** 2)
    k_t = thelen_tendon_stiffness((l_mt - x) / mus.l_slack - 1) / mus.l_slack

    def along(xx):
        ll = np.sqrt(xx * xx + mus.height ** 2)
        ln = ll / mus.l_opt
        return (a * thelen_active_force_length(ln) + thelen_passive_force_length(ln)) * xx / ll

    k_m = np.maximum(fd(along, x, 1e-8), 0.0)     # descending limb counted as 0
    np.testing.assert_allclose(eq["v_ce"], (x / l) * k_t * v_mt / (k_t + k_m), rtol=1e-5,
                               atol=1e-9)
    # faster shortening than a weakly active fiber can follow has no equilibrium
    with pytest.raises(ConvergenceError, match="shorten faster than the fiber can"):
        mus.equilibrium(l_mt[:5], 0.01, -2 * mus.v_max)


def test_equilibrium_vectorised_equals_loop():
    mus = forearm()
    l_mt, v_mt, a = states(mus, 40, seed=7)
    eq = mus.equilibrium(l_mt, a)
    rows = np.array([mus.equilibrium(l_mt[k], a[k])["l_ce"] for k in range(40)])
    np.testing.assert_allclose(eq["l_ce"], rows, rtol=0, atol=1e-12)
    for i in range(mus.n):                 # one muscle, scalar inputs, through the pure function
        single = Thelen2003(f_max=mus.f_max[i], l_opt=mus.l_opt[i], l_slack=mus.l_slack[i],
                            pennation=mus.pennation[i])
        got = single.equilibrium(float(l_mt[5, i]), float(a[5, i]))["l_ce"]
        assert np.ndim(got) == 0 or np.shape(got) == (1,)
        assert float(np.squeeze(got)) == pytest.approx(eq["l_ce"][5, i], abs=1e-12)
    Fa, Fp = mus.force_limits(l_mt, v_mt)
    rows = [mus.force_limits(l_mt[k], v_mt[k]) for k in range(40)]
    np.testing.assert_array_equal(Fa, np.array([r[0] for r in rows]))
    np.testing.assert_array_equal(Fp, np.array([r[1] for r in rows]))


def test_equilibrium_compliant_force_vs_rigid():
    mus = forearm()
    l_mt, v_mt, a = states(mus, 300, seed=9)
    # a stretched tendon shortens the fiber: compliant force is the force at a shorter fiber
    eq = mus.equilibrium(l_mt, a)
    l_rigid, _ = mus.fiber_kinematics_rigid(l_mt, 0.0)
    assert np.all(eq["l_ce"] <= l_rigid + 1e-15)
    np.testing.assert_allclose(mus.force(a, l_mt, None, tendon="compliant"), eq["force"])


def test_equilibrium_without_solution_raises_convergence_error():
    mus = Thelen2003(f_max=[500.0, 500.0], l_opt=0.1, l_slack=0.3, pennation=0.0, names=["x", "y"])
    l_mt = np.array([[0.42, 0.42], [0.42, 0.3003]])   # second muscle, frame 1: no room for force
    with pytest.raises(ConvergenceError, match=r"muscle 1 \('y'\) at frame 1 \(l_mt = 0.3003, a = 1\)"):
        mus.equilibrium(l_mt, 1.0)


def test_contraction_rate_requires_activation():
    mus = forearm()
    l_mt, _, a = states(mus, 5)
    a[2, 3] = 0.0
    with pytest.raises(TrialError, match=r"activation > 0.*muscle 3 \('TRILH'\) at frame 2"):
        mus.contraction_rate(mus.fiber_kinematics_rigid(l_mt, 0.0)[0], l_mt, a)


def test_force_velocity_smooth_blend_is_c2_and_local():
    """The C2 blend of the slope jump at w = 0 (5 concentric, 10 eccentric): identical
    outside |w| < width, continuous slope across 0, derivative = FD of the value,
    increasing, and within 1.2 % of Eq. A.9 inside the band."""
    width = 0.02
    w = np.linspace(-0.06, 0.06, 4801)
    exact = thelen_force_velocity(w)
    sm = thelen_force_velocity(w, smooth=width)
    dsm = thelen_force_velocity_derivative(w, smooth=width)
    out = np.abs(w) >= width
    assert np.array_equal(sm[out], exact[out])
    assert np.max(np.abs(sm - exact)) < 0.012
    assert np.all(np.diff(sm) > 0)
    np.testing.assert_allclose(dsm, fd(lambda x: thelen_force_velocity(x, smooth=width), w, 1e-7),
                               rtol=1e-5, atol=1e-6)
    # the slope is continuous (the exact curve jumps from 5 to 10 at 0)
    assert thelen_force_velocity_derivative(-1e-9) == pytest.approx(5.0)
    assert thelen_force_velocity_derivative(1e-9) == pytest.approx(10.0)
    assert np.max(np.abs(np.diff(dsm))) < 0.1
    # and the second derivative too (C2): FD of the slope has no jump at the band edges
    d2 = np.diff(dsm) / np.diff(w)
    assert np.max(np.abs(np.diff(d2))) < 0.02 * np.max(np.abs(d2))
    f, dv, da, _ = thelen_fiber_force_partials(0.004, 0.3, 0.8, smooth=width)
    s = 0.25 + 0.75 * 0.3
    assert f == pytest.approx(0.3 * 0.8 * thelen_force_velocity(0.004 / s, smooth=width))
    assert da == pytest.approx(fd(lambda x: thelen_fiber_force_partials(0.004, x, 0.8, smooth=width)[0],
                                  0.3), rel=1e-6)
    with pytest.raises(ValueError, match="smoothing width"):
        thelen_force_velocity(w, smooth=0.05)


def test_inverse_excitation_is_continuous_across_fiber_reversal_with_smoothing():
    """Eq. 5.4 contains df/dv: with the printed Thelen curve the recovered excitation jumps
    where the fiber velocity changes sign; with ``fv_smooth`` it is continuous."""
    from pinmsk.muscles.inverse import inverse_thelen2003
    t = np.linspace(0.0, 0.5, 20001)
    w = 2 * np.pi * 2.0
    l_mt = 0.20 + 0.004 * np.sin(w * t)              # m; the fiber reverses at the extremes
    dl, ddl = 0.004 * w * np.cos(w * t), -0.004 * w * w * np.sin(w * t)
    F = np.full_like(t, 300.0)
    kw = dict(f_max=1000.0, l_opt=0.08, l_slack=0.12, pennation=0.1, ddF_mt=np.zeros_like(t))
    exact = inverse_thelen2003(F, np.zeros_like(t), l_mt, dl, ddl, **kw)["u"]
    smooth = inverse_thelen2003(F, np.zeros_like(t), l_mt, dl, ddl, fv_smooth=0.02, **kw)["u"]
    assert np.max(np.abs(np.diff(exact))) > 0.01        # a jump of > 0.01 in one 25 us step
    assert np.max(np.abs(np.diff(smooth))) < 1e-3
    far = np.abs(dl) > 0.5 * np.max(np.abs(dl))         # away from reversals: the same model
    np.testing.assert_allclose(smooth[far], exact[far], rtol=1e-12)
