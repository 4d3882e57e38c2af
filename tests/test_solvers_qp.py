"""The shared QP layer: proxsuite frame QPs, the batched dual Newton method, LP basis checks.

Small hand-built problems with known answers, the three paths against each
other, and proxsuite's warm starts (segfaults were seen with some settings)
exercised in a subprocess that must exit cleanly.
"""
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from pinmsk.errors import SolverError
from pinmsk.solvers import qp


def _random_problem(seed=0, n=40, nd=3, m=9, load=0.25):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, nd, m))
    A /= np.abs(A).sum(axis=2, keepdims=True)
    x_true = rng.uniform(0, load, size=(n, m))
    b = np.einsum("njm,nm->nj", A, x_true)
    w = rng.uniform(0.3, 1.0, size=m)
    return A, b, w


def _kkt_residual(A, b, x, w, P, lo=0.0, hi=1.0):
    """Max violation of the KKT conditions of min sum w x^P, A x = b, lo <= x <= hi."""
    grad = w * P * np.maximum(x, 0) ** (P - 1)
    lam, *_ = np.linalg.lstsq(A[:, (x > lo + 1e-7) & (x < hi - 1e-7)].T,
                              grad[(x > lo + 1e-7) & (x < hi - 1e-7)], rcond=None)
    z = grad - A.T @ lam
    viol = [np.max(np.abs(A @ x - b))]
    viol.append(np.max(np.abs(z[(x > lo + 1e-7) & (x < hi - 1e-7)]), initial=0))
    viol.append(max(0.0, -np.min(z[x <= lo + 1e-7], initial=0)))
    viol.append(max(0.0, np.max(z[x >= hi - 1e-7], initial=0)))
    return max(viol)


def test_single_dof_closed_form():
    # min x1^2 + x2^2 s.t. 2 x1 + x2 = 1 -> x = (0.4, 0.2)
    fq = qp.FrameQP(m=2, nd=1, weights=[1.0, 1.0], exponent=2)
    sol = fq.solve([[2.0, 1.0]], [1.0], 0.0, 1.0)
    assert sol.solved
    np.testing.assert_allclose(sol.x, [0.4, 0.2], atol=1e-10)
    bs = qp.dual_newton(np.array([[[2.0, 1.0]]]), np.array([[1.0]]), [1.0, 1.0], 2, 0.0, 1.0)
    np.testing.assert_allclose(bs.x[0], [0.4, 0.2], atol=1e-12)
    assert bs.converged.all()


def test_bound_active_and_antagonist():
    # an antagonist (negative arm) stays at zero; a saturated muscle sits at its bound
    A = np.array([[1.0, 0.5, -1.0]])
    fq = qp.FrameQP(m=3, nd=1, weights=[1.0, 1.0, 1.0], exponent=2)
    sol = fq.solve(A, [1.2], 0.0, [0.8, 1.0, 1.0])
    # x1 saturates at 0.8; x2 = 0.4/0.5 = 0.8 would then be needed
    np.testing.assert_allclose(sol.x, [0.8, 0.8, 0.0], atol=1e-9)
    bs = qp.dual_newton(A[None], np.array([[1.2]]), [1.0, 1.0, 1.0], 2, 0.0, np.array([0.8, 1.0, 1.0]))
    np.testing.assert_allclose(bs.x[0], [0.8, 0.8, 0.0], atol=1e-12)


@pytest.mark.parametrize("P", [2.0, 3.0, 4.0])
def test_dual_newton_matches_proxsuite(P):
    A, b, w = _random_problem(seed=int(P))
    bs = qp.dual_newton(A, b, w, P, 0.0, 1.0, tol=1e-10)
    assert bs.converged.mean() > 0.9
    fq = qp.FrameQP(m=A.shape[2], nd=A.shape[1], weights=w, exponent=P, eps=1e-13)
    for k in np.flatnonzero(bs.converged)[:15]:
        sol = fq.solve(A[k], b[k], 0.0, 1.0)
        assert sol.solved
        cost_b = np.sum(w * bs.x[k] ** P)
        cost_p = np.sum(w * np.maximum(sol.x, 0) ** P)
        assert cost_b <= cost_p * (1 + 1e-7) + 1e-15
        assert _kkt_residual(A[k], b[k], bs.x[k], w, P) < 1e-8


def test_sqp_large_exponent_kkt():
    A, b, w = _random_problem(seed=7, n=6, nd=2, m=6)
    fq = qp.FrameQP(m=6, nd=2, weights=w, exponent=10)
    for k in range(6):
        sol = fq.solve(A[k], b[k], 0.0, 1.0)
        assert sol.solved
        assert np.max(np.abs(A[k] @ sol.x - b[k])) < 1e-9


def test_reserves_cover_a_deficit_and_stay_off_otherwise():
    A = np.array([[0.5, 0.25]])
    fq = qp.FrameQP(m=2, nd=1, weights=[1.0, 1.0], exponent=2, reserve_weight=1000.0)
    sol = fq.solve(A, [1.0], 0.0, 1.0)                 # capacity 0.75: deficit 0.25
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(sol.rho, [0.25], atol=1e-9)
    sol = fq.solve(A, [0.3], 0.0, 1.0)
    assert abs(sol.rho[0]) < 1e-12
    bs = qp.dual_newton(np.array([A, A]), np.array([[1.0], [0.3]]), [1.0, 1.0], 2, 0.0, 1.0,
                        reserve_weight=1000.0)
    np.testing.assert_allclose(bs.rho[:, 0], [0.25, 0.0], atol=1e-9)


def test_infeasible_frame_reported_not_solved():
    fq = qp.FrameQP(m=2, nd=1, weights=[1.0, 1.0], exponent=2)
    assert fq.solve([[0.5, 0.25]], [0.3], 0.0, 1.0).solved
    bad = fq.solve([[0.5, 0.25]], [2.0], 0.0, 1.0)
    assert not bad.solved
    # and the next (feasible) frame after a failure still solves correctly
    sol = fq.solve([[0.5, 0.25]], [0.3], 0.0, 1.0)
    assert sol.solved and abs(0.5 * sol.x[0] + 0.25 * sol.x[1] - 0.3) < 1e-10
    bs = qp.dual_newton(np.array([[[0.5, 0.25]]]), np.array([[2.0]]), [1.0, 1.0], 2, 0.0, 1.0)
    assert not bs.converged[0]


def test_minmax_epigraph():
    # max(x) minimal with x1 + x2 + x3 = 1.5 -> all 0.5
    fq = qp.FrameQP(m=3, nd=1, weights=[1.0, 1.0, 1.0], minmax=True)
    sol = fq.solve([[1.0, 1.0, 1.0]], [1.5], 0.0, 1.0)
    np.testing.assert_allclose(sol.x, [0.5, 0.5, 0.5], atol=1e-9)


def test_lp_verify_recovers_vertex():
    # min x1 + 2 x2 s.t. x1 + x2 = b, 0 <= x <= 1: x1 first, then x2
    E = np.array([[[1.0, 1.0]]] * 3)
    f = np.array([[0.5], [0.9], [1.5]])
    ok, z, _ = qp.lp_verify(E, f, np.array([1.0, 2.0]), np.zeros((3, 2)), np.ones((3, 2)), [0])
    assert ok.tolist() == [True, True, False]          # basis {x1} fails once x1 saturates
    np.testing.assert_allclose(z[:2], [[0.5, 0.0], [0.9, 0.0]])
    ok, z, _ = qp.lp_verify(E, f, np.array([1.0, 2.0]), np.zeros((3, 2)), np.ones((3, 2)), [1])
    assert ok.tolist() == [False, False, True]
    np.testing.assert_allclose(z[2], [1.0, 0.5])


def test_bad_exponent():
    with pytest.raises(SolverError, match="P = 1"):
        qp.check_exponent(1.5)
    with pytest.raises(SolverError, match="number"):
        qp.check_exponent("two")


def test_proxsuite_warm_starts_never_crash():
    """Many warm-started solves, infeasible ones and size changes between objects, in a subprocess."""
    code = textwrap.dedent("""
        import numpy as np
        from pinmsk.solvers import qp
        rng = np.random.default_rng(3)
        for m, nd, P, minmax, W in [(7, 1, 2, False, None), (7, 1, 1, False, None), (7, 1, 3, False, None),
                                    (5, 2, 2, False, 1e3), (7, 1, 1, True, None), (4, 2, 10, False, None)]:
            fq = qp.FrameQP(m=m, nd=nd, weights=rng.uniform(0.2, 1, m), exponent=P, minmax=minmax,
                            reserve_weight=W, max_iter=200)
            A = rng.normal(size=(nd, m)); A /= np.abs(A).sum(1, keepdims=True)
            for k in range(150):
                b = rng.normal(size=nd) * (0.3 if k % 7 else 5.0)    # every 7th frame infeasible
                sol = fq.solve(A + 0.01 * rng.normal(size=A.shape), b, 0.0, 1.0)
                assert np.all(np.isfinite(sol.x))
        print("ok")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "ok" in res.stdout
