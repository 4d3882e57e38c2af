"""The closed-form 1-dof solutions (thesis Eq. 2.22-2.24, 3.31-3.40) against each other and brute force."""
import itertools

import numpy as np
import pytest
from scipy.optimize import linprog

from pinmsk.errors import InfeasibleError
from pinmsk.solvers import analytical as an


def brute_force(r, T, P, n, U):
    """Enumerate the 3^m KKT branches (off / free / saturated) of the 1-dof problem."""
    r, n, U = map(np.asarray, (r, n, U))
    m = r.size
    best, best_cost = None, np.inf
    for branch in itertools.product((0, 1, 2), repeat=m):
        b = np.array(branch)
        F = np.where(b == 2, U, 0.0)
        free = b == 1
        rest = T - np.sum(r * F)
        if free.any():
            e = np.zeros(m)
            e[free] = (np.abs(r[free]) * n[free] ** P) ** (1.0 / (P - 1.0)) * np.sign(r[free])
            denom = np.sum(r[free] * e[free])
            if denom == 0:
                continue
            F = F + e * rest / denom
        elif abs(rest) > 1e-12:
            continue
        if np.any(F < -1e-12) or np.any(F > U + 1e-12) or abs(np.sum(r * F) - T) > 1e-9:
            continue
        cost = np.sum((F / n) ** P)
        if cost < best_cost - 1e-15:
            best, best_cost = F, cost
    return best


def test_two_muscles_p2_branches():
    # both flexors: Eq. 3.31
    np.testing.assert_allclose(an.two_muscles_p2(0.05, 0.03, 2.0), (2 * 0.05 / 0.0034, 2 * 0.03 / 0.0034))
    # flexor + extensor, T > 0: Eq. 3.33; T < 0: Eq. 3.34 (the extensor alone)
    assert an.two_muscles_p2(0.05, -0.03, 2.0) == (2.0 / 0.05, 0.0)
    assert an.two_muscles_p2(0.05, -0.03, -1.5) == (0.0, -1.5 / -0.03)
    assert an.two_muscles_p2(0.05, 0.03, 0.0) == (0.0, 0.0)                  # branch four
    with pytest.raises(InfeasibleError):
        an.two_muscles_p2(0.05, 0.03, -1.0)


def test_two_muscles_p3_is_eq_2_24():
    r1, r2, T = 0.054, 0.037, 3.0
    F = an.two_muscles_p3(r1, r2, T)
    np.testing.assert_allclose(F, an.eq_2_22([r1, r2], T, exponent=3), rtol=1e-14)
    # Eq. 3.37 written out
    np.testing.assert_allclose(F[0], r1 ** 0.5 * T / (r1 ** 1.5 + r2 ** 1.5), rtol=1e-14)
    assert an.two_muscles_p3(-0.02, 0.03, 1.0) == (0.0, 1.0 / 0.03)        # Eq. 3.38


@pytest.mark.parametrize("P", [2.0, 3.0, 10.0])
def test_eq_2_22_satisfies_kkt(P):
    r = np.array([0.054, 0.0273, 0.037, 0.021])
    n = np.array([1.0, 2.0, 0.5, 1.5])
    T = 2.5
    F = an.eq_2_22(r, T, exponent=P, n=n)
    assert abs(np.sum(r * F) - T) < 1e-12
    lam = P * F ** (P - 1) / (r * n ** P)       # Eq. 2.19: one multiplier for all muscles
    np.testing.assert_allclose(lam, lam[0], rtol=1e-10)
    # Eq. 2.21 ratios
    np.testing.assert_allclose(F[0] / F[1], (r[0] / r[1]) ** (1 / (P - 1)) * (n[0] / n[1]) ** (P / (P - 1)))


@pytest.mark.parametrize("P", [2.0, 3.0, 4.0])
@pytest.mark.parametrize("T", [0.5, 3.0, 5.5, -1.0, -2.0])
def test_water_filling_is_the_kkt_branch(P, T):
    r = np.array([0.054, 0.0273, 0.037, -0.02, -0.0258])
    U = np.array([40.0, 60.0, 50.0, 70.0, 30.0])
    n = np.array([1.0, 1.3, 0.7, 1.0, 1.1])
    F = an.one_dof_forces(r, T, exponent=P, n=n, upper=U)
    np.testing.assert_allclose(F, brute_force(r, T, P, n, U), atol=1e-9)


def test_lp_matches_linprog():
    r = np.array([0.054, 0.0273, 0.037, 0.021, -0.02])
    U = np.array([20.0, 60.0, 50.0, 100.0, 70.0])
    n = np.array([1.0, 2.0, 1.0, 3.0, 1.0])
    for T in (0.5, 2.0, 4.0, -1.0):
        F = an.one_dof_forces(r, T, exponent=1, n=n, upper=U)
        res = linprog(1 / n, A_eq=r[None], b_eq=[T], bounds=list(zip(np.zeros(5), U)), method="highs")
        np.testing.assert_allclose(F, res.x, atol=1e-9)


def test_minmax_is_the_large_p_limit():
    r = np.array([0.054, 0.0273, 0.037, 0.021])
    U = np.array([101.58, 392.91, 461.76, 853.9])
    mm = an.one_dof_forces(r, 3.0, upper=U, n=U, minmax=True)
    np.testing.assert_allclose(mm / U, (mm / U)[0])                      # all at the same fraction
    big = an.one_dof_forces(r, 3.0, exponent=200, upper=U, n=U)
    np.testing.assert_allclose(big, mm, rtol=2e-2)                       # Rasmussen et al.


def test_infeasible_moment():
    with pytest.raises(InfeasibleError, match="capacity"):
        an.one_dof_forces([0.05, 0.02], 10.0, upper=[100.0, 100.0])


def test_gaussian_motion():
    mo = an.gaussian_elbow_motion()
    assert mo.q.shape == (201, 1)
    assert abs(np.rad2deg(mo.q.max()) - 120.0) < 1e-9
    assert np.rad2deg(mo.q[0, 0]) < 0.05 and np.rad2deg(mo.q[-1, 0]) < 0.05
    # exact derivatives
    np.testing.assert_allclose(np.gradient(mo.q[:, 0], mo.t), mo.v[:, 0], atol=2e-2)
    np.testing.assert_allclose(np.gradient(mo.v[:, 0], mo.t), mo.a[:, 0], atol=0.5)
