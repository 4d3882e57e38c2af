"""Metabolic energy rates (thesis App. B) against hand computations at stated states.

Every expected value below is worked out from the printed equations with
``math`` only (not with pinmsk), so a slip in the implementation shows.
"""
import math

import numpy as np
import pytest

from pinmsk.energy import (bhargava2004, metabolic_rate, muscle_mass, stimulation_time,
                           umberger2003)
from pinmsk.errors import ModelError


def test_mass_eq_b3():
    # m = rho l_opt F_max / sigma = 1059.7 * 0.1 * 500 / 0.25e6
    assert muscle_mass(0.1, 500.0) == pytest.approx(1059.7 * 0.1 * 500 / 0.25e6, rel=1e-14)
    assert muscle_mass(0.1, 500.0) == pytest.approx(0.21194, rel=1e-12)


def test_umberger_shortening_short_fiber():
    # State: u = 0.6 > a = 0.4 -> beta = u = 0.6 (B.17); l_ce = 0.09 <= l_opt = 0.1 (B.15);
    # v_ce = -0.2 m/s -> v~ = -2 /s; f_fast = 0.4; F_max = 500 N; F_ce = 200 N; xi = 1.
    m = 1059.7 * 0.1 * 500 / 0.25e6
    h_am = 128 * 0.4 + 25                               # B.18 = 76.2
    a_st, a_ft = 100 / 4, 153 / 10                       # B.19, B.20
    maint = h_am * 0.6 ** 0.6                            # 56.0849...
    sl = -(-2.0) * 0.6 ** 0.2 * (a_st * 0.6 + a_ft * 0.4)  # slow term 30 < 100 W/kg: no cap
    h = maint + sl
    assert h == pytest.approx(94.2226, abs=1e-3)
    out = umberger2003(u=0.6, a=0.4, l_ce=0.09, v_ce=-0.2, f_ce=200.0, f_isom=0.95, l_opt=0.1,
                       f_max=500.0, fast_fraction=0.4)
    assert out["specific_heat"] == pytest.approx(h, rel=1e-12)
    assert out["heat"] == pytest.approx(m * h, rel=1e-12)
    assert out["work"] == pytest.approx(40.0, rel=1e-12)           # -F_ce v_ce, B.2
    assert out["total"] == pytest.approx(m * h + 40.0, rel=1e-12)  # B.1
    assert out["total"] == pytest.approx(59.9698, abs=1e-3)


def test_umberger_lengthening_long_fiber():
    # u = 0.2 <= a = 0.5 -> beta = 0.35; l_ce = 0.12 > l_opt (B.16) with f_isom = 0.7;
    # v_ce = +0.3 m/s -> v~ = 3 /s; f_fast = 0.5; F_max = 1000 N; F_ce = 600 N.
    m = 1059.7 * 0.1 * 1000 / 0.25e6
    beta = 0.35
    maint = (128 * 0.5 + 25) * beta ** 0.6 * (0.4 + 0.6 * 0.7)
    length = (4 * 100 / 4) * 0.7 * 3.0 * beta           # alpha_L f_isom v~ beta xi = 73.5
    assert length == pytest.approx(73.5)
    h = maint + length
    out = umberger2003(u=0.2, a=0.5, l_ce=0.12, v_ce=0.3, f_ce=600.0, f_isom=0.7, l_opt=0.1,
                       f_max=1000.0, fast_fraction=0.5)
    assert out["specific_heat"] == pytest.approx(h, rel=1e-12)
    assert out["total"] == pytest.approx(m * h - 180.0, rel=1e-12)


def test_umberger_cap_and_floor():
    # all slow fibers, v~ = -10 /s: -alpha_S(ST) f_slow v~ = 250 W/kg is capped at 100 W/kg.
    beta = 1.0
    h = (128 * 0 + 25) * beta ** 0.6 + 100.0 * beta ** 0.2
    out = umberger2003(u=1.0, a=1.0, l_ce=0.1, v_ce=-1.0, f_ce=0.0, f_isom=1.0, l_opt=0.1,
                       f_max=100.0, fast_fraction=0.0)
    assert out["specific_heat"] == pytest.approx(h, rel=1e-12)
    # resting muscle: u = a = 0, isometric -> h' floored at 1.0 W/kg
    out = umberger2003(u=0.0, a=0.0, l_ce=0.1, v_ce=0.0, f_ce=0.0, f_isom=1.0, l_opt=0.1,
                       f_max=100.0, fast_fraction=0.5)
    assert out["specific_heat"] == pytest.approx(1.0)
    assert out["total"] == pytest.approx(1059.7 * 0.1 * 100 / 0.25e6)


def test_bhargava_shortening():
    # u = 0.5, a = 0.45, l_ce = 0.11 (l~ = 1.1 -> psi = -2 * 1.1 + 3 = 0.8, B.9), v = -0.1 m/s,
    # F_ce = 300 N, f_isom = 0.9, F_max = 800 N, f_fast = 0.3, t_stim = 0.02 s.
    m = 1059.7 * 0.1 * 800 / 0.25e6
    uf = 1 - math.cos(math.pi / 2 * 0.5)                 # B.6
    us = math.sin(math.pi / 2 * 0.5)
    phi = 0.06 + math.exp(-0.02 * 0.5 / 0.045)           # B.7
    A = phi * m * (0.3 * 133 * uf + 0.7 * 40 * us)       # B.5
    M = 0.8 * m * (0.3 * 111 * uf + 0.7 * 74 * us)       # B.8
    F_iso = 0.45 * 0.9 * 800                             # active isometric force, 324 N
    S = -(0.16 * F_iso + 0.18 * 300) * (-0.1)            # B.10-B.11 = 10.584 W
    B = 0.0225 * m                                       # B.12
    W = -300 * (-0.1)                                    # B.2
    out = bhargava2004(u=0.5, a=0.45, l_ce=0.11, v_ce=-0.1, f_ce=300.0, f_isom=0.9, l_opt=0.1,
                       f_max=800.0, fast_fraction=0.3, t_stim=0.02)
    assert S == pytest.approx(10.584)
    for key, val in (("activation", A), ("maintenance", M), ("shortening", S), ("basal", B),
                     ("work", W)):
        assert out[key] == pytest.approx(val, rel=1e-12), key
    assert out["total"] == pytest.approx(A + M + S + B + W, rel=1e-12)
    # A = 9.18995, M = 12.58252, S = 10.584, B = 0.00763, W = 30 (W)
    assert out["total"] == pytest.approx(62.3641, abs=1e-3)


def test_bhargava_lengthening_and_psi_pieces():
    out = bhargava2004(u=0.5, a=0.45, l_ce=0.11, v_ce=0.2, f_ce=300.0, f_isom=0.9, l_opt=0.1,
                       f_max=800.0, fast_fraction=0.3, t_stim=0.0)
    assert out["shortening"] == pytest.approx(-0.157 * 300 * 0.2)
    m = 1059.7 * 0.1 * 800 / 0.25e6
    uf, us = 1 - math.cos(math.pi / 4), math.sin(math.pi / 4)
    base = m * (0.3 * 111 * uf + 0.7 * 74 * us)
    for l_ce, psi in ((0.04, 0.2), (0.07, 0.7), (0.16, 0.0)):
        o = bhargava2004(u=0.5, a=0.45, l_ce=l_ce, v_ce=0.0, f_ce=0.0, f_isom=0.9, l_opt=0.1,
                         f_max=800.0, fast_fraction=0.3, t_stim=0.0)
        assert o["maintenance"] == pytest.approx(psi * base, rel=1e-12, abs=1e-15)


def test_stimulation_time_and_dispatch():
    t = np.linspace(0, 1, 11)
    u = np.where(t >= 0.5, 0.5, 0.0)[:, None]
    ts = stimulation_time(t, u)
    assert ts[-1, 0] == pytest.approx(0.05 + 0.5)
    assert ts[4, 0] == 0.0
    with pytest.raises(ModelError, match="umberger2003, bhargava2004"):
        metabolic_rate("margaria", u=0.1)


# -- C1 versions of the switches used inside optimizations (smooth=w > 0) -------------------

def _thelen_fl(l_ce, l_opt=0.1):
    return np.exp(-((np.asarray(l_ce) / l_opt - 1.0) ** 2) / 0.45)


def _states(n=4000, seed=3):
    rng = np.random.default_rng(seed)
    l_ce = rng.uniform(0.03, 0.17, n)
    return dict(u=rng.uniform(0, 1, n), a=rng.uniform(0, 1, n), l_ce=l_ce,
                v_ce=rng.uniform(-1.2, 1.2, n), f_ce=rng.uniform(0, 500, n), f_isom=_thelen_fl(l_ce),
                l_opt=0.1, f_max=500.0, fast_fraction=0.4)


@pytest.mark.parametrize("name", ["umberger2003", "bhargava2004"])
def test_smooth_converges_to_exact(name):
    s = _states()
    if name == "bhargava2004":
        s["t_stim"] = np.full_like(s["u"], 0.05)
    # stay 1e-3 away from the switch points, where a blend of width w < 1e-4 is exact
    ln, vt = s["l_ce"] / 0.1, s["v_ce"] / 0.1
    far = (np.abs(ln - 1.0) > 1e-3) & (np.abs(vt) > 1e-3) & (np.abs(s["u"] - s["a"]) > 1e-3)
    far &= np.abs(ln - 0.5) > 1e-3
    exact = metabolic_rate(name, **s)["total"]
    errs = []
    for w in (1e-2, 1e-3, 1e-4, 1e-5):
        smooth = metabolic_rate(name, **s, smooth=w)["total"]
        errs.append(np.max(np.abs(smooth - exact)[far]))
    scale = np.max(np.abs(exact))
    assert errs[0] < 0.05 * scale                      # w = 0.01: a few per cent at most
    assert all(e2 <= e1 + 1e-12 for e1, e2 in zip(errs, errs[1:]))
    assert errs[-1] < 1e-4 * scale
    assert np.array_equal(metabolic_rate(name, **s, smooth=0.0)["total"], exact)


def _sweep_slopes(fun, x):
    f = fun(x)
    g = np.gradient(f, x)
    return np.max(np.abs(np.diff(g[1:-1]))), np.max(np.abs(g[1:-1]))


W = 0.01
UMB = dict(u=0.5, a=0.3, l_ce=0.09, v_ce=-0.1, f_ce=200.0, l_opt=0.1, f_max=500.0,
           fast_fraction=0.4)
BHA = dict(UMB, t_stim=0.05)
# (model, swept argument, centre of the sweep = the switch point, fixed overrides)
SWEEPS = [
    ("umberger2003", "u", 0.3, {}),                         # u > a (B.17)
    ("umberger2003", "v_ce", 0.0, {}),                      # shortening / lengthening (B.15)
    ("umberger2003", "l_ce", 0.1, {"v_ce": 0.05, "f_isom": 0.8}),   # l_ce <= l_opt (B.15/B.16)
    ("umberger2003", "v_ce", -100.0 / (25.0 * 0.6) * 0.1, {}),      # 100 W/kg cap
    ("umberger2003", "u", 0.0, {"a": 0.0, "v_ce": 0.0}),    # beta = 0, beta^p and 1 W/kg floor
    ("bhargava2004", "v_ce", 0.0, {}),                      # alpha switch (B.11)
    ("bhargava2004", "l_ce", 0.1, {}),                      # psi_H pieces (B.9)
    ("bhargava2004", "l_ce", 0.15, {}),
]


@pytest.mark.parametrize("name,arg,x0,over", SWEEPS)
def test_smooth_is_c1_by_finite_differences(name, arg, x0, over):
    """Finite-difference slopes across each switch: the exact model's slope jumps, the
    smooth one's changes by a small fraction of that on a grid much finer than w."""
    base = dict(UMB if name == "umberger2003" else BHA, **over)
    x = np.linspace(x0 - 5 * W * (0.1 if arg in ("l_ce", "v_ce") else 1.0),
                    x0 + 5 * W * (0.1 if arg in ("l_ce", "v_ce") else 1.0), 2001)

    def fun(xx, w):
        kw = dict(base, **{arg: xx})
        if "f_isom" not in over:
            kw["f_isom"] = _thelen_fl(kw["l_ce"])
        return metabolic_rate(name, **kw, smooth=w)["total"] * np.ones_like(xx)

    jump_s, slope_s = _sweep_slopes(lambda xx: fun(xx, W), x)
    jump_e, slope_e = _sweep_slopes(lambda xx: fun(xx, 0.0), x)
    assert np.all(np.isfinite([jump_s, slope_s]))
    assert jump_s < 0.05 * max(slope_s, slope_e)       # slope continuous on the fine grid
    assert jump_e > 5 * jump_s                          # ... where the exact one kinks


def test_smooth_helpers():
    from pinmsk.energy import smooth_clip, smooth_power, smooth_relu, smooth_step
    x = np.linspace(-1, 2, 3001)
    for w in (0.1, 0.01):
        assert np.max(np.abs(smooth_relu(x, w) - np.maximum(x, 0))) <= w / 8 + 1e-15
        assert np.max(np.abs(smooth_clip(x, 0, 1, w) - np.clip(x, 0, 1))) <= w / 2 + 1e-15
        inside = (x >= 0) & (x <= 1)
        assert np.array_equal(smooth_clip(x, 0, 1, w)[inside], x[inside])   # exact when feasible
        assert np.array_equal(smooth_power(x[x >= w], 0.2, w), x[x >= w] ** 0.2)
        assert smooth_power(0.0, 0.6, w) == 0.0
        for f in (lambda y: smooth_relu(y, w), lambda y: smooth_power(y, 0.2, w),
                  lambda y: smooth_step(y, w)):
            g = np.gradient(f(x), x)
            assert np.max(np.abs(np.diff(g))) < 0.1 * np.max(np.abs(g)) + 1e-12
    assert np.array_equal(smooth_step(x, 0.0), (x > 0).astype(float))
    t = np.linspace(0, 1, 11)
    u = np.linspace(0.01, 0.21, 11)[:, None]
    assert np.allclose(stimulation_time(t, u, smooth=1e-6), stimulation_time(t, u))
