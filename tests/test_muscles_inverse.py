"""Inverse muscle model (thesis Fig. 5.6, Eq. 5.2-5.4) against forward simulations.

A forward compliant-tendon muscle is simulated with a smooth excitation by
integrating the activation (Eq. A.2) and contraction (Eq. 3.9) ODEs with
``solve_ivp``.  At sample times the states ``(a, l_ce)`` give, analytically,
the muscle-tendon force and its first two time derivatives; these together
with ``l_mt`` and its derivatives go into the inverse model, which must return
the state's activation and the excitation that was applied.

Tolerances.  The inverse evaluates the *same* algebraic relations as the
forward model at each sample, so the comparison is pointwise and does not
depend on the integrator's accuracy: ``a``, ``l_ce`` and ``v_ce`` come back to
roundoff (1e-12).  The excitation also depends on ``F_mt''``, which here needs
the fiber acceleration, i.e. the time derivative of the contraction ODE's
right-hand side along the trajectory.  That one is taken by a central
difference with a 1e-6 s step (truncation ~1e-12, roundoff ~1e-10 relative);
the measured excitation errors are ~5e-9 (Thelen) and ~7e-10 (NG), asserted
below 1e-7.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pinmsk.errors import TrialError
from pinmsk.muscles import (NaganoGerritsen, Thelen2003, inverse_thelen2003,
                            thelen_tendon_force, thelen_tendon_stiffness,
                            thelen_tendon_stiffness_derivative, winters_tendon_force,
                            winters_tendon_stiffness, winters_tendon_stiffness_derivative)

PHASE = np.array([0.0, 1.0, 2.0])


def thelen_forearm():
    """Thesis Table 3.2: BRD, BICLH, BRA."""
    return Thelen2003(f_max=[101.58, 392.91, 853.90], l_opt=[0.2703, 0.1536, 0.1028],
                      l_slack=[0.0604, 0.2293, 0.0175], pennation=np.deg2rad([5.0, 10.0, 15.0]),
                      names=["BRD", "BICLH", "BRA"])


def ng_leg():
    """Thesis Table 5.3: Gl, Vas, Sol."""
    return NaganoGerritsen(f_max=[1705.0, 7403.0, 3883.0], l_opt=[0.200, 0.093, 0.055],
                           l_slack=[0.157, 0.223, 0.245], pennation=np.deg2rad([3.0, 4.4, 23.6]),
                           width=[0.625, 0.627, 1.039], names=["Gl", "Vas", "Sol"])


def path(mus, stretch, amp, freq):
    """Muscle-tendon length, velocity and acceleration: a smooth oscillation."""
    w = 2 * np.pi * freq
    base = mus.l_slack * stretch + mus.l_opt * np.cos(mus.pennation)
    amp = amp * mus.l_opt

    def lmt(t):
        t = np.asarray(t, dtype=float)[..., None]
        s, c = np.sin(w * t + PHASE), np.cos(w * t + PHASE)
        return base + amp * s, amp * w * c, -amp * w * w * s
    return lmt


def simulate(mus, lmt, u_of, t_end=1.5, n=400):
    """Integrate (a, l_ce); return samples after the initial transient."""
    m = mus.n

    def rhs(t, y):
        a, l = y[:m], y[m:]
        return np.concatenate([mus.activation_rate(u_of(t), a),
                               mus.contraction_rate(l, lmt(t)[0], a)])

    a0 = u_of(0.0)
    l0 = mus.equilibrium(lmt(0.0)[0], a0)["l_ce"]
    # the comparison is pointwise (module doc), so the integrator needs no more accuracy than
    # a faithful trajectory: rtol 1e-8 instead of 1e-10 takes 40 % of the time
    sol = solve_ivp(rhs, (0, t_end), np.concatenate([a0, l0]), method="Radau", rtol=1e-8,
                    atol=1e-10, dense_output=True)
    assert sol.status == 0
    t = np.linspace(0.2, t_end, n)
    y = sol.sol(t).T
    return t, y[:, :m], y[:, m:]


def forces_from_states(mus, lmt, u_of, t, a, l, tendon_force, stiffness, curvature, dt=1e-6):
    """F_mt, dF_mt, ddF_mt from the states, by the chain rule through the tendon curve."""
    L, V, A = lmt(t)
    x = np.sqrt(l * l - mus.height ** 2)
    eps = (L - x) / mus.l_slack - 1
    v = mus.contraction_rate(l, L, a)
    adot = mus.activation_rate(u_of(t), a)
    # fiber acceleration: d/dt of the contraction ODE along (v_ce, v_mt, adot)
    acc = (mus.contraction_rate(l + dt * v, lmt(t + dt)[0], a + dt * adot)
           - mus.contraction_rate(l - dt * v, lmt(t - dt)[0], a - dt * adot)) / (2 * dt)
    dx = l * v / x
    ddx = (v * v + l * acc - dx * dx) / x
    deps = (V - dx) / mus.l_slack
    ddeps = (A - ddx) / mus.l_slack
    F = mus.f_max * tendon_force(eps)
    dF = mus.f_max * stiffness(eps) * deps
    ddF = mus.f_max * (curvature(eps) * deps * deps + stiffness(eps) * ddeps)
    return dict(F=F, dF=dF, ddF=ddF, L=L, V=V, A=A, v=v, acc=acc, adot=adot, eps=eps)


@pytest.fixture(scope="module")
def thelen_run():
    mus = thelen_forearm()
    lmt = path(mus, 1.03, 0.12, 1.2)

    def u_of(t):
        return 0.35 + 0.3 * np.sin(2 * np.pi * 1.7 * np.asarray(t)[..., None] + PHASE) ** 3

    t, a, l = simulate(mus, lmt, u_of)
    s = forces_from_states(mus, lmt, u_of, t, a, l, thelen_tendon_force, thelen_tendon_stiffness,
                           thelen_tendon_stiffness_derivative)
    return mus, u_of(t), a, l, s


@pytest.fixture(scope="module")
def ng_run():
    mus = ng_leg()
    lmt = path(mus, 1.02, 0.10, 1.0)

    def u_of(t):
        return 0.3 + 0.25 * np.sin(2 * np.pi * 1.3 * np.asarray(t)[..., None] + PHASE)

    t, a, l = simulate(mus, lmt, u_of)
    s = forces_from_states(mus, lmt, u_of, t, a, l, winters_tendon_force,
                           winters_tendon_stiffness, winters_tendon_stiffness_derivative)
    return mus, u_of(t), a, l, s


def test_thelen_inverse_recovers_activation_and_excitation(thelen_run):
    mus, u, a, l, s = thelen_run
    # the run exercises both contraction directions and the tendon's toe and linear parts
    assert s["v"].min() < 0 < s["v"].max()
    assert s["eps"].min() < 0.609 * 0.04 < s["eps"].max()
    assert (u > a).any() and (u < a).any()
    out = mus.inverse(s["F"], s["dF"], s["L"], s["V"], s["A"], ddF_mt=s["ddF"])
    np.testing.assert_allclose(out["l_ce"], l, rtol=1e-12)
    np.testing.assert_allclose(out["v_ce"], s["v"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["dv_ce"], s["acc"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["a"], a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["adot"], s["adot"], rtol=0, atol=1e-5)  # |adot| up to ~10 /s
    np.testing.assert_allclose(out["u"], u, rtol=0, atol=1e-7)
    x = np.sqrt(l * l - mus.height ** 2)
    np.testing.assert_allclose(out["l_t"], s["L"] - x, rtol=1e-12)


def test_nagano_gerritsen_inverse_recovers_activation_and_excitation(ng_run):
    mus, u, a, l, s = ng_run
    assert s["v"].min() < 0 < s["v"].max()
    assert (a < 0.3).any() and (a > 0.3).any()       # both a_hat branches
    out = mus.inverse(s["F"], s["dF"], s["L"], s["V"], s["A"], ddF_mt=s["ddF"])
    np.testing.assert_allclose(out["l_ce"], l, rtol=1e-12)
    np.testing.assert_allclose(out["v_ce"], s["v"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["a"], a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out["adot"], s["adot"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(out["u"], u, rtol=0, atol=1e-7)


def test_second_force_derivative_matters(thelen_run):
    # Without F_mt'' the tendon's part of the fiber acceleration is lost:
    # a and l_ce are unchanged but the excitation is off by ~0.15 in this run.
    mus, u, a, l, s = thelen_run
    out = mus.inverse(s["F"], s["dF"], s["L"], s["V"], s["A"])
    np.testing.assert_allclose(out["a"], a, rtol=0, atol=1e-12)
    assert np.abs(out["u"] - u).max() > 1e-2


def test_pure_function_matches_object_and_loops(thelen_run):
    mus, u, a, l, s = thelen_run
    kw = dict(f_max=mus.f_max, l_opt=mus.l_opt, l_slack=mus.l_slack, pennation=mus.pennation)
    full = inverse_thelen2003(s["F"], s["dF"], s["L"], s["V"], s["A"], ddF_mt=s["ddF"], **kw)
    obj = mus.inverse(s["F"], s["dF"], s["L"], s["V"], s["A"], ddF_mt=s["ddF"])
    for key in ("a", "adot", "u", "l_ce", "v_ce"):
        np.testing.assert_array_equal(full[key], obj[key])
    for k in (0, 57, 399):           # one frame at a time, (m,) arrays
        row = mus.inverse(s["F"][k], s["dF"][k], s["L"][k], s["V"][k], s["A"][k],
                          ddF_mt=s["ddF"][k])
        np.testing.assert_allclose(row["u"], obj["u"][k], rtol=0, atol=1e-13)
    i, k = 1, 123                    # one muscle, scalars
    one = inverse_thelen2003(s["F"][k, i], s["dF"][k, i], s["L"][k, i], s["V"][k, i],
                             s["A"][k, i], ddF_mt=s["ddF"][k, i],
                             **{key: val[i] for key, val in kw.items()})
    assert np.ndim(one["u"]) == 0
    assert float(one["u"]) == pytest.approx(obj["u"][k, i], abs=1e-13)


def test_force_below_passive_gives_zero_activation():
    mus = Thelen2003(f_max=1000.0, l_opt=0.1, l_slack=0.2, pennation=0.0)
    # fiber at 1.4 l_opt carries f_pe = (e^(5*0.4/0.6) - 1)/(e^5 - 1) = 0.184 F_max passively
    F_pe = 1000 * np.expm1(5 * 0.4 / 0.6) / np.expm1(5)
    from pinmsk.muscles import thelen_tendon_strain
    for F, expect_zero in ((0.5 * F_pe, True), (2 * F_pe, False)):
        l_t = 0.2 * (1 + thelen_tendon_strain(F / 1000))
        out = mus.inverse(F, 0.0, l_t + 0.14, 0.0, 0.0)
        assert out["l_ce"] == pytest.approx(0.14, rel=1e-12)
        if expect_zero:
            assert out["a"] == 0 and out["adot"] == 0 and out["u"] == 0
        else:
            # isometric: a = (F - F_pe)/(F_max f_L(1.4))
            assert out["a"] == pytest.approx(F_pe / (1000 * np.exp(-0.16 / 0.45)), rel=1e-12)
            assert out["u"] == pytest.approx(out["a"], rel=1e-12)   # steady: adot = 0


def test_bad_inputs():
    mus = ng_leg()
    F = np.full((4, 3), 500.0)
    F[2, 1] = np.nan
    L = mus.l_slack * 1.02 + mus.l_opt
    with pytest.raises(TrialError, match=r"F_mt is nan for muscle 1 \('Vas'\) at frame 2"):
        mus.inverse(F, 0.0, L, 0.0, 0.0)
    with pytest.raises(TrialError, match=r"no room for the fiber at muscle 0 \('Gl'\)"):
        mus.inverse(np.full(3, 500.0), 0.0, mus.l_slack * 0.9, 0.0, 0.0)


def test_fiber_floor_keeps_wild_states_finite_and_normal_ones_exact():
    """``fiber_floor`` (for optimizers): a unit shorter than its tendon gives a finite,
    grossly infeasible state instead of an error; a normal state is unchanged."""
    mus = Thelen2003(f_max=1000.0, l_opt=0.1, l_slack=0.2, pennation=0.1)
    t = np.linspace(0, 1, 51)
    l_mt = 0.29 + 0.01 * np.sin(2 * np.pi * t)
    dl, ddl = 0.02 * np.pi * np.cos(2 * np.pi * t), -0.04 * np.pi ** 2 * np.sin(2 * np.pi * t)
    F, dF, ddF = 300 + 50 * np.sin(2 * np.pi * t), 100 * np.pi * np.cos(2 * np.pi * t), 0 * t
    a = mus.inverse(F, dF, l_mt, dl, ddl, ddF)
    b = mus.inverse(F, dF, l_mt, dl, ddl, ddF, fiber_floor=1e-3 * 0.1)
    for k in ("a", "adot", "u", "l_ce", "v_ce"):
        np.testing.assert_array_equal(a[k], b[k])
    from pinmsk.muscles import thelen_tendon_strain
    F = np.full_like(t, 300.0)
    short = 0.2 * (1 + thelen_tendon_strain(0.3)) - 2e-4 + 0 * t    # 0.2 mm shorter than the tendon
    with pytest.raises(TrialError, match="no room for the fiber"):
        mus.inverse(F, 0 * t, short, 0 * t, 0 * t, ddF)
    wild = mus.inverse(F, 0 * t, short, 0 * t, 0 * t, ddF, fiber_floor=1e-4)
    assert all(np.all(np.isfinite(wild[k])) for k in ("a", "adot", "u"))
    assert np.min(wild["u"]) > 100          # far outside the bounds 0 <= u <= 1
