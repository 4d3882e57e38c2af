"""Fully forward simulation (thesis Sec. 5.1) with a compliant tendon: the IMEX integrator.

The contraction dynamics (Eq. 3.9) are stiff at low activation; ``simulate_ff`` integrates the
tendon length implicitly (ARS(4,4,3)).  Checked here against a stiff reference solver of the
same continuous ODE, for order, for smoothness in the inputs (the optimizer's finite
differences), and that the rigid-tendon path is unchanged.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import pinmsk
from pinmsk.solvers.simulation_designs import A_MIN, U_MARGIN, BatchMuscles, BatchSkeleton, _rk4, simulate_ff

# (model, period T in s, q0 in rad): the optimizer's cases, 200 steps per period.  The finger's
# excitations start at 0 and 1 (phase -pi/2): within one 1/6 s period its activations would
# not otherwise fall low enough (tau_fall) to reach the stiff regime.
CASES = {"finger": (1 / 6, 0.0), "forearm": (1.9, 0.3)}
PHASE0 = {"finger": -np.pi / 2, "forearm": 0.0}


@pytest.fixture(scope="module")
def models():
    return {name: pinmsk.load_model(name) for name in CASES}


def excitation(t, T, m, amp=0.5, spread=np.pi, phase0=0.0):
    """``u_i = 0.5 + amp sin(2 pi t/T + phase0 + i spread)`` clipped to [0, 1] (0 once amp >= 0.5)."""
    ph = phase0 + np.arange(m) * spread
    return np.clip(0.5 + amp * np.sin(2 * np.pi * np.atleast_1d(t)[:, None] / T + ph), 0.0, 1.0)


def ff(model, T, q0, n, **kw):
    t = np.linspace(0.0, T, n + 1)
    tm = 0.5 * (t[1:] + t[:-1])
    m = model.n_muscles
    return simulate_ff(model, t, excitation(t, T, m, **kw), excitation(tm, T, m, **kw), [q0], [0.0],
                       tendon="compliant")


def reference(model, T, q0, n_eval, **kw):
    """A stiff solve (BDF) of the continuous ODE (q, v, a, l_ce) from the public pieces, on n_eval + 1 points."""
    mu, sk = BatchMuscles(model), BatchSkeleton(model)
    m, nv = mu.m, model.nv
    t1, t2 = mu._t1, mu._t2

    def rhs(t, x):
        q, v = x[None, :nv], x[None, nv:2 * nv]
        a, l_ce = x[None, 2 * nv:2 * nv + m], x[None, 2 * nv + m:]
        w = np.clip(excitation(t, T, m, **kw), -U_MARGIN, 1.0 + U_MARGIN)
        F, v_ce, _, _ = mu.compliant(a, mu.lengths(q), l_ce)
        d = w - a
        adot = d * (t2 + t1 * w * (d >= 0))                                 # Eq. A.2
        return np.concatenate([v[0], sk.accel(q, v, mu.moments(q, F))[0], adot[0], v_ce[0]])

    a0 = excitation(0.0, T, m, **kw)[0]
    l_mt0 = mu.lengths(np.array([[q0]]))
    l_ce0 = mu.mtu.equilibrium(l_mt0, np.maximum(a0, A_MIN)[None])["l_ce"][0]
    tg = np.linspace(0.0, T, n_eval + 1)
    # BDF rather than Radau: within 3e-8 rad (and 1e-3 N) of Radau at the same tolerances, 700x
    # below the smallest error compared with it (2.2e-5 rad at 800 steps), in half the time
    sol = solve_ivp(rhs, (0.0, T), np.concatenate([[q0], [0.0], a0, l_ce0]), method="BDF",
                    rtol=1e-9, atol=1e-12, t_eval=tg)
    assert sol.success
    X = sol.y.T
    F = mu.compliant(X[:, 2 * nv:2 * nv + m], mu.lengths(X[:, :nv]), X[:, 2 * nv + m:])[0]
    return X[:, :nv], F


class _References(dict):
    """``refs[name]``: the reference solve of case ``name`` (a CASES key, or ``"forearm-fast"``: all
    seven muscles out of phase, a fast 0.3 -> 2.9 rad swing, the hardest case here), computed when
    first asked for (the slow-only cases' solves stay out of the default suite)."""

    def __init__(self, models):
        super().__init__()
        self.models = models

    def __missing__(self, name):
        model = name.split("-")[0]
        T, q0 = CASES[model]
        kw = {"spread": 2 * np.pi / 7} if name == "forearm-fast" else {"phase0": PHASE0[name]}
        self[name] = reference(self.models[model], T, q0, 800, **kw)
        return self[name]


@pytest.fixture(scope="module")
def refs(models):
    return _References(models)


@pytest.fixture(scope="module")
def fast_swing(models):
    """``{n: simulate_ff result}`` of the fast forearm swing, computed once for each step count asked for."""
    T, q0 = CASES["forearm"]
    cache = {}

    def sim(n):
        if n not in cache:
            cache[n] = ff(models["forearm"], T, q0, n, spread=2 * np.pi / 7)
        return cache[n]
    return sim


def errors(sim, ref, n):
    qr, Fr = ref
    k = (qr.shape[0] - 1) // n
    return np.abs(sim["q"][:, 0] - qr[::k, 0]).max(), np.abs(sim["force"] - Fr[::k]).max()


# --------------------------------------------------------------------------- stiffness
def test_explicit_rk4_of_the_compliant_fiber_ode_fails_at_the_optimizer_step(models):
    """Why an implicit fiber: classical RK4 of Eq. 3.9 on the forearm at h = 9.5 ms diverges
    (time constants of the fiber-tendon pair are ~0.1-2 ms), while simulate_ff stays accurate."""
    model = models["forearm"]
    mu, sk = BatchMuscles(model), BatchSkeleton(model)
    T, q0 = CASES["forearm"]
    t = np.linspace(0.0, T, 201)
    tm = 0.5 * (t[1:] + t[:-1])
    u, um = excitation(t, T, 7)[:, None], excitation(tm, T, 7)[:, None]
    a0 = u[0]
    l_ce0 = mu.mtu.equilibrium(mu.lengths(np.array([[q0]])), np.maximum(a0, A_MIN))["l_ce"]

    def deriv(x, w):
        q, v, a, l = x[:, :1], x[:, 1:2], x[:, 2:9], x[:, 9:]
        F, v_ce, _, _ = mu.compliant(a, mu.lengths(q), l)
        d = w - a
        adot = d * (mu._t2 + mu._t1 * w * (d >= 0))                        # Eq. A.2
        return np.concatenate([v, sk.accel(q, v, mu.moments(q, F)), adot, v_ce], axis=1)

    with np.errstate(all="ignore"):
        X = _rk4(deriv, np.concatenate([[[q0, 0.0]], a0, l_ce0], axis=1), t, u, um)
    q_rk4 = X[:, 0, 0]
    q_imex = ff(model, T, q0, 200)["q"][:, 0]
    assert not (np.all(np.isfinite(q_rk4)) and np.abs(q_rk4 - q_imex).max() < 0.1)
    assert np.abs(q_imex).max() < 1.0          # the motion stays in 0.3 - 0.74 rad


# --------------------------------------------------------------------------- accuracy
# the forearm case is slow: the finger covers the stiff regime (activations to 0), the fast swing the forearm
@pytest.mark.parametrize("name, q_tol, f_tol", [("finger", 5e-4, 5e-4),
                                                pytest.param("forearm", 3e-4, 2e-3, marks=pytest.mark.slow)])
def test_compliant_ff_matches_stiff_reference_at_200_steps(models, refs, name, q_tol, f_tol):
    """200 steps per period (finger h = 0.83 ms, forearm h = 9.5 ms), activations down to
    0 (finger) and 0.004 (forearm): q within q_tol rad of the reference (measured 1.8e-4 finger,
    9.1e-5 forearm, over motion ranges 3.6 and 0.43 rad), force within f_tol of the peak
    force (measured 0.017 N of 93 N, 0.83 N of 975 N)."""
    T, q0 = CASES[name]
    sim = ff(models[name], T, q0, 200, phase0=PHASE0[name])
    assert np.all(np.isfinite(sim["q"]))
    e_q, e_f = errors(sim, refs[name], 200)
    assert e_q < q_tol
    assert e_f < f_tol * refs[name][1].max()
    assert sim["a"].min() < 0.05                 # the stiff, low-activation regime was visited


def test_compliant_ff_fast_forearm_swing(fast_swing, refs):
    """All seven excitations out of phase drive a 2.6 rad swing at up to ~15 rad/s: the
    hardest case; still 1.2e-3 rad (4e-4 of the range) at h = 9.5 ms and 1.6e-4 at 4.75 ms."""
    e200 = errors(fast_swing(200), refs["forearm-fast"], 200)
    assert e200[0] < 2e-3 and e200[1] < 5.0           # N, of a 835 N peak
    assert np.ptp(refs["forearm-fast"][0]) > 2.5


# slow: the 200-step finger reference and the fast swing check the accuracy by default
@pytest.mark.slow
def test_compliant_ff_converges_at_third_order(fast_swing, refs):
    """ARS(4,4,3) is 3rd order: halving h cuts the q error ~7x (measured 1.23e-3 -> 1.64e-4
    -> 2.2e-5 on the fast forearm swing; 2^3 = 8)."""
    e = [errors(fast_swing(n), refs["forearm-fast"], n)[0] for n in (200, 400, 800)]
    ratios = np.array(e[:-1]) / np.array(e[1:])
    assert np.all(ratios > 5.0), ratios                # observed order > 2.3
    assert np.all(ratios < 12.0), ratios


# --------------------------------------------------------------------------- smoothness
@pytest.mark.parametrize("name", ["finger", "forearm"])
def test_compliant_ff_is_smooth_in_the_inputs(models, name):
    """Fixed Newton iterations, no data-dependent exits: finite differences of the final
    angle w.r.t. an excitation amplitude with steps 1e-5 and 1e-6 agree to ~5 digits
    (forward) and ~8 digits (central), as for a smooth function."""
    T, q0 = CASES[name]
    model = models[name]
    m = model.n_muscles
    t = np.linspace(0.0, T, 201)
    tm = 0.5 * (t[1:] + t[:-1])
    amps = 0.48 + np.array([0.0, 1e-5, -1e-5, 1e-6, -1e-6])
    U = np.stack([excitation(t, T, m, A, phase0=PHASE0[name]) for A in amps], axis=1)
    Um = np.stack([excitation(tm, T, m, A, phase0=PHASE0[name]) for A in amps], axis=1)
    q = simulate_ff(model, t, U, Um, [q0], [0.0], tendon="compliant")["q"][-1, :, 0]
    fwd5, fwd6 = (q[1] - q[0]) / 1e-5, (q[3] - q[0]) / 1e-6
    cen5, cen6 = (q[1] - q[2]) / 2e-5, (q[3] - q[4]) / 2e-6
    assert abs(cen6) > 0.1
    assert abs(fwd5 - fwd6) < 1e-4 * abs(cen6)
    assert abs(cen5 - cen6) < 1e-6 * abs(cen6)


# --------------------------------------------------------------------------- pieces
@pytest.mark.parametrize("name", ["finger", "forearm"])
def test_fiber_rate_equals_contraction_dynamics_and_its_slope(models, name):
    mu = BatchMuscles(models[name])
    rng = np.random.default_rng(3)
    q = rng.uniform(-0.5, 2.0, (500, 1))
    a = rng.uniform(0.0, 1.0, (500, mu.m))
    l_mt = mu.lengths(q)
    l_ce = mu.l_opt * rng.uniform(0.5, 1.5, (500, mu.m))
    F, v_ce, _, _ = mu.compliant(a, l_mt, l_ce)
    v, dv = mu.fiber_rate(a, l_mt, l_ce)
    assert np.allclose(v, v_ce, rtol=1e-12, atol=1e-10)
    assert np.allclose(mu.tendon_force(l_mt, l_ce), F, rtol=1e-13, atol=1e-10)
    dl = 1e-7 * mu.l_opt
    fd = (mu.fiber_rate(a, l_mt, l_ce + dl)[0] - mu.fiber_rate(a, l_mt, l_ce - dl)[0]) / (2 * dl)
    assert np.allclose(dv, fd, rtol=1e-5, atol=1e-6 * np.abs(dv).max())


# --------------------------------------------------------------------------- rigid unchanged
# q at steps 50, 100, 200 and the final forces of the rigid FF, computed with the
# implementation before the compliant integrator was replaced (same inputs as here).
RIGID_BEFORE = {
    "finger": ([0.1466978745834872, 0.7775261817250406, 0.5627653685773786],
               [52.89943983252454, 52.23465495892873]),
    "forearm": ([0.3261524102120016, 0.32739348255862105, 0.5228290365421683],
                [46.66398743869867, 231.6931340830158, 208.03179706478443, 493.79931581683644,
                 303.36606333959276, 578.4926446089795, 219.97070921231176]),
}


@pytest.mark.parametrize("name", ["finger", "forearm"])
def test_rigid_ff_is_unchanged(models, name):
    T, q0 = CASES[name]
    model = models[name]
    m = model.n_muscles
    t = np.linspace(0.0, T, 201)
    tm = 0.5 * (t[1:] + t[:-1])
    sim = simulate_ff(model, t, excitation(t, T, m), excitation(tm, T, m), [q0], [0.0])
    q_ref, f_ref = RIGID_BEFORE[name]
    assert np.allclose(sim["q"][[50, 100, 200], 0], q_ref, rtol=1e-13, atol=0)
    assert np.allclose(sim["force"][200], f_ref, rtol=1e-13, atol=0)
