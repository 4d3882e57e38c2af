"""Extended inverse dynamics (EID): the whole trial as one sparse QP (thesis Sec. 2.2.4, Ackermann).

Unknowns: the activations ``a_k`` of every frame (and, with reserves, the
reserve moments).  The problem

    minimise    sum_k dt_k sum_i S_i a_ik^P                  (time integral, trapezoid weights dt_k)
    subject to  R_k^T (a_k F_active,k + F_passive,k) = tau_k     each frame (rigid tendon)
                a_{k-1} exp(-dt/tau_fall) <= a_k <= 1 - (1 - a_{k-1}) exp(-dt/tau_rise)
                0 <= a <= 1

couples the frames through activation dynamics (Winters-Stark, thesis
Eq. A.2; see :mod:`pinmsk.solvers.mso` for why the reachable set of a
step with a held excitation is exactly this interval, so no linearisation is
needed).  Contraction dynamics enter through the rigid-tendon force
capacity ``F_active = F_max f_L f_V cos(alpha)`` at the measured muscle
lengths and velocities (the inverse of contraction dynamics for a rigid
tendon); a compliant tendon would add the tendon-length states (not done).

P = 2 is a QP and P = 1 an LP, both solved at once with proxsuite's sparse
solver (``proxsuite.proxqp.sparse``); for P > 2 the same sparse problem is
solved by sequential QP (Newton steps with an Armijo line search).
Excitations are recovered exactly from consecutive activations
(:func:`pinmsk.solvers.mso.excitations`).
"""
from __future__ import annotations

import time as _time

import numpy as np
import scipy.sparse as sp

from ..errors import ConvergenceError, InfeasibleError, SolverError
from ..fitting import Fitter, format_report
from ..kinematics import DEFAULT_CUTOFF
from . import qp as _qp
from .mso import activation_problem, model_path, result_of, set_results

#: P = 1: proxsuite's sparse solver reported feasible whole-trial LPs as
#: infeasible; a proximal term ``LP_REGULARISATION * w a^2`` (activations are
#: at most 1, so the objective moves by at most this fraction) makes the
#: problem strictly convex and the solution unique.
LP_REGULARISATION = 1e-6


class ExtendedInverseDynamics(Fitter):
    """EID over a whole trial as one sparse proxsuite QP (see the module notes).

    Parameters (keyword-only): ``exponent`` (>= 1), ``weights`` (``S_i``),
    ``reserves``, ``reserve_weight``, ``tol``, ``dofs``, ``max_iter``
    (proxsuite iterations), ``sqp_max_iter``.  The activation time constants
    and any delay are the model's, as in
    :class:`~pinmsk.solvers.mso.ModifiedStaticOptimization` (``tau_rise`` and
    ``tau_fall`` are refused by name).
    ``result_`` as :class:`~pinmsk.solvers.mso.ModifiedStaticOptimization`'s;
    its ``objective`` is the time integral of the criterion.
    """

    def __init__(self, *, exponent: float = 2, weights: str = "none", tau_rise=None,
                 tau_fall=None, reserves: bool = False, reserve_weight: float = 1000.0,
                 tol: float = 1e-9, dofs=None, max_iter: int = 10000, sqp_max_iter: int = 50):
        self.exponent = exponent
        self.weights = weights
        self.tau_rise = tau_rise
        self.tau_fall = tau_fall
        self.reserves = reserves
        self.reserve_weight = reserve_weight
        self.tol = tol
        self.dofs = dofs
        self.max_iter = max_iter
        self.sqp_max_iter = sqp_max_iter

    def fit(self, model, trial, *, moments=None, cutoff=DEFAULT_CUTOFF, progress=None):
        """Solve the whole trial at once; returns ``self``."""
        t0 = _time.perf_counter()
        path = model_path(self, model)
        self.excitation_path_ = path
        P, prob = activation_problem(self, model, trial, moments=moments, cutoff=cutoff)
        N, nd, m = prob.A.shape
        if N < 2:
            raise SolverError("EID needs at least 2 frames (a single frame is static optimization)")
        W = float(self.reserve_weight) if self.reserves else None
        t = prob.time
        dt = np.diff(t)
        wt = np.zeros(N)                     # trapezoid weights of the time integral
        wt[:-1] += 0.5 * dt
        wt[1:] += 0.5 * dt
        wt /= np.mean(wt)
        na = N * m
        nr = 2 * N * nd if W is not None else 0
        n = na + nr
        # equalities: A_k a_k (+ rho+ - rho-) = b_k
        rows = np.repeat(np.arange(N * nd), m)
        cols = (np.arange(N)[:, None, None] * m + np.arange(m)[None, None, :]).repeat(nd, axis=1).ravel()
        Aeq = sp.csc_matrix((prob.A.ravel(), (rows, cols)), shape=(N * nd, n))
        if nr:
            I = sp.identity(N * nd, format="csc")
            Aeq = Aeq + sp.hstack([sp.csc_matrix((N * nd, na)), I, -I], format="csc")
        beq = prob.b.ravel()
        # activation dynamics: lo: a_k - ef a_{k-1} >= 0 ; hi: a_k - er a_{k-1} <= 1 - er
        ef = np.exp(-dt[:, None] / path.tau_fall[None, :]).ravel()      # (N-1) m, frame-major as cur
        er = np.exp(-dt[:, None] / path.tau_rise[None, :]).ravel()
        nk = (N - 1) * m
        r_idx = np.arange(nk)
        cur = (np.arange(1, N)[:, None] * m + np.arange(m)[None, :]).ravel()
        prv = cur - m
        Cd = sp.csc_matrix((np.concatenate([np.ones(nk), -ef]),
                            (np.concatenate([r_idx, r_idx]), np.concatenate([cur, prv]))), shape=(nk, n))
        Cu = sp.csc_matrix((np.concatenate([np.ones(nk), -er]),
                            (np.concatenate([r_idx, r_idx]), np.concatenate([cur, prv]))), shape=(nk, n))
        # box rows (the sparse API has no separate box constraints): 0 <= a <= 1 only at
        # frame 0 -- the dynamics rows keep later frames inside [0, 1] -- and the reserves
        box_idx = np.concatenate([np.arange(m), np.arange(na, n)])
        Cb = sp.csc_matrix((np.ones(box_idx.size), (np.arange(box_idx.size), box_idx)),
                           shape=(box_idx.size, n))
        ub_res = (np.abs(prob.b) + np.abs(prob.A).sum(axis=2) + 1.0).ravel() if nr else np.zeros(0)
        C = sp.vstack([Cd, Cu, Cb], format="csc")
        l = np.concatenate([np.zeros(nk), np.full(nk, -2.0), np.zeros(box_idx.size)])
        u = np.concatenate([np.full(nk, 2.0), 1.0 - er, np.ones(m),
                            np.concatenate([ub_res, ub_res]) if nr else np.zeros(0)])
        wcost = (np.repeat(wt, m) * np.tile(prob.w, N))
        wres = np.repeat(wt, nd)

        def objective(a_lin):
            """H (sparse diagonal), g in the variables [a, rho+, rho-]."""
            hd = np.zeros(n)
            g = np.zeros(n)
            if P == 1.0:
                g[:na] = wcost
                hd[:na] = LP_REGULARISATION * wcost   # see ExtendedInverseDynamics notes
            elif a_lin is None or P == 2.0:
                hd[:na] = 2.0 * wcost
            else:
                af = np.maximum(a_lin, 1e-6)
                h = wcost * P * (P - 1.0) * af ** (P - 2.0)
                h = np.maximum(h, 1e-5 * h.max())
                grad = wcost * P * np.maximum(a_lin, 0.0) ** (P - 1.0)
                hd[:na] = h
                g[:na] = grad - h * a_lin
            if nr:
                hd[na:] = 2.0 * W * np.tile(wres, 2)
                g[na:] = W * np.tile(wres, 2)
            return hd, g

        from proxsuite import proxqp

        def solve(hd, g):
            c = float(np.max(np.abs(g[:na]))) if P == 1.0 or np.any(g[:na]) else float(np.max(hd[:na]))
            c = c if c > 0 else 1.0
            H = sp.diags(hd / c, format="csc")
            qp = proxqp.sparse.QP(n, N * nd, C.shape[0])
            qp.settings.eps_abs = float(self.tol) * 1e-2
            qp.settings.eps_rel = 0.0
            qp.settings.max_iter = int(self.max_iter)
            qp.settings.verbose = False
            # the equality-constrained initial guess of a (nearly) linear problem is far
            # outside the inequalities and proxsuite then declared feasible LPs infeasible
            qp.settings.initial_guess = proxqp.InitialGuess.NO_INITIAL_GUESS
            qp.init(H, g / c, Aeq, beq, C, l, u)
            qp.solve()
            res = qp.results
            return np.array(res.x), res.info.status.name, int(res.info.iter)

        hd, g = objective(None)
        z, status, iters = solve(hd, g)
        nqp = 1
        if status != "PROXQP_SOLVED":
            self._fail(status, prob)
        if P > 2.0:
            def total(zz):
                c = float(np.sum(wcost * np.maximum(zz[:na], 0.0) ** P))
                if nr:
                    r = zz[na:]
                    c += float(W * np.sum(np.tile(wres, 2) * (r + r * r)))
                return c
            f0 = total(z)
            for _ in range(int(self.sqp_max_iter)):
                hd, g = objective(z[:na])
                zn, status, it = solve(hd, g)
                iters += it
                nqp += 1
                if status != "PROXQP_SOLVED":
                    self._fail(status, prob)
                d = zn - z
                pred = -float((wcost * P * np.maximum(z[:na], 0) ** (P - 1.0)) @ d[:na])
                if np.max(np.abs(d[:na])) <= 1e-10 or pred <= _qp.SQP_RTOL * f0:
                    z = zn
                    break
                alpha = 1.0
                for _ls in range(40):
                    ft = total(z + alpha * d)
                    if ft <= f0 - 1e-4 * alpha * pred:
                        break
                    alpha *= 0.5
                z = z + alpha * d
                f0 = total(z)
            else:
                raise ConvergenceError(f"EID: SQP did not converge in {self.sqp_max_iter} steps")
        a = np.clip(z[:na].reshape(N, m), 0.0, 1.0)
        rho = (z[na:na + N * nd] - z[na + N * nd:]).reshape(N, nd) if nr else np.zeros((N, nd))
        if progress is not None:
            progress.update(N)
        self.n_iter_ = iters
        self.n_qp_ = nqp
        self.n_variables_ = n
        self.n_constraints_ = (Aeq.shape[0], C.shape[0])
        channels = set_results(self, model, prob, a, rho, t0=t0, analysis="extended_inverse_dynamics")
        self.objective_ = float(np.sum(np.diff(t) * 0.5 * (self.cost_[1:] + self.cost_[:-1])))
        self.result_ = result_of(self, prob, channels, objective=self.objective_, report=self._report_text())
        return self

    def _fail(self, status, prob):
        if status == "PROXQP_PRIMAL_INFEASIBLE":
            raise InfeasibleError(
                "EID: no activations satisfy the moments and the activation dynamics over the whole "
                f"trial ({prob.n_frames} frames, dofs {', '.join(prob.dofs)}); run StaticOptimization "
                "to find frames where the muscles are too weak, or pass reserves=True")
        raise ConvergenceError(f"EID: proxsuite sparse stopped with {status}; raise max_iter or loosen tol")

    def _report_text(self) -> str:
        prob = self.problem_
        return format_report(
            f"Extended inverse dynamics (one sparse QP over the trial) of model '{self.model_name_}'", [
                ("criterion", f"integral sum_i S_i a_i^{float(self.exponent):g} dt, S = {self.weights}; "
                              f"value {self.objective_:.6g}"),
                ("dynamics", self.excitation_path_.describe()),
                ("size", f"{self.n_variables_} variables, {self.n_constraints_[0]} equalities, "
                         f"{self.n_constraints_[1]} inequalities ({prob.n_frames} frames)"),
                ("solver", f"proxsuite sparse, {self.n_qp_} QP(s), {self.n_iter_} iterations"),
                ("violation", f"max {np.max(self.violation_):.3g} N m"),
                ("time", f"{self.time_ * 1e3:.1f} ms"),
            ])


#: Short name used in the thesis.
EID = ExtendedInverseDynamics
