"""The QP layer shared by the muscle-redundancy solvers (SO, MSO, EID, FSO).

Every solver here works on the *scaled* per-frame problem

    minimise    sum_i w_i x_i^P  + reserve cost
    subject to  A x + rho = b          (nd balanced dofs; rho only with reserves)
                lo <= x <= hi          (x = F / F_max or x = a, so O(1))

with rows of ``A`` and ``b`` divided by a typical moment of each dof, so
``A`` entries are at most 1 and a unit residual is a whole dof's capacity.
The min/max criterion (thesis Eq. 2.13) replaces the cost by ``max_i u_i x_i``
(an epigraph LP in ``(x, t)``).  The reserve cost is the exact-penalty form
``W sum_j (|rho_j| + rho_j^2)``: zero reserve whenever the muscles can
balance the dof with multipliers below ``W``, strictly convex so the answer
is unique.  (FSO's tracking cost uses the same slot as a soft equality,
``W rho^2``.)

Three independent ways to solve it live here:

:class:`FrameQP`
    proxsuite's dense solver, one :class:`proxsuite.proxqp.dense.QP` of fixed
    dimensions reused frame after frame with ``update`` and
    ``WARM_START_WITH_PREVIOUS_RESULT``.  P = 1 and min/max are LPs, P = 2 a
    QP, P > 2 sequential QP (Newton steps on the convex objective with the
    linear constraints, each step a proxsuite QP, Armijo line search, stopped
    when the step is below ``sqp_tol`` or the predicted decrease below
    ``SQP_RTOL`` of the cost).  Each frame is rescaled (variables by its
    largest moment, objective to a unit gradient) before proxsuite sees it.
    Crashes seen with warm starts after failed solves are avoided by
    construction: dimensions never change, warm starts only follow a
    ``PROXQP_SOLVED`` of the same object, and after any other status the QP
    object is thrown away and the next solve starts cold on a fresh one.
    All bounds are finite (proxsuite misjudged feasibility with 1e20 ones).

:func:`dual_newton`
    For P >= 2 (any weights, reserves or not), all frames at once in numpy.
    The Lagrangian is separable, so for multipliers ``lam`` the minimiser
    over the box is explicit, ``x_i = clip((s_i / (P w_i))^(1/(P-1)), lo, hi)``
    with ``s = A' lam``; it satisfies stationarity, complementarity and the
    bounds exactly.  Semismooth Newton with an Armijo line search on the
    concave dual function drives the equality residual ``b - A x - rho`` to
    the tolerance (for P = 2 this is the primal-dual active-set method: it
    stops at the exact active set).  A frame counts as solved only when its
    residual is below the tolerance, which *is* the KKT verification; the
    others go to :class:`FrameQP`.  Used up to P = 4: beyond, ``x ~ s^(1/(P-1))``
    makes the dual too steep near zero forces.

:func:`lp_verify` / :func:`lp_basis_from`
    For LPs (P = 1, min/max): guess an optimal basis from another frame's
    solution, solve the basis system for all frames in one batched call and
    keep the frames whose vertex is primal feasible (dual feasibility holds by
    construction).  Along a smooth motion the basis repeats for many frames,
    so only a few frames need proxsuite.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SolverError

#: Stand-in for an infinite bound in proxsuite box constraints.
BIG = 1e20

#: SQP (P > 2) also stops when the predicted decrease of the cost is below this
#: fraction of the cost: for large P, muscles far below the most active one
#: change the cost by less (a muscle at 3 % of the top one weighs 3e-16 at P = 10)
#: and their exact value is numerically meaningless.
SQP_RTOL = 1e-10

#: proxsuite statuses that count as solved.
_SOLVED_NAMES = ("PROXQP_SOLVED",)


def _proxqp():
    try:
        from proxsuite import proxqp
    except ImportError as exc:  # pragma: no cover - proxsuite is a hard dependency
        raise SolverError("the muscle-redundancy solvers need proxsuite: pip install proxsuite") from exc
    return proxqp


def check_exponent(exponent) -> float:
    """The cost exponent as a float; P must be 1 (LP) or >= 2."""
    try:
        p = float(exponent)
    except (TypeError, ValueError):
        raise SolverError(f"exponent must be a number (1, 2, 3, 10, ...), got {exponent!r}") from None
    if not np.isfinite(p) or not (p == 1.0 or p >= 2.0):
        raise SolverError(f"exponent P = {exponent!r} is not supported: use P = 1 (LP) or P >= 2 "
                          "(thesis Eq. 2.11 uses 1, 2, 3 and 10)")
    return p


# ---------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------

@dataclass
class FrameSolution:
    """Solution of one frame by :class:`FrameQP` (scaled units)."""

    x: np.ndarray            # (m,)
    rho: np.ndarray          # (nd,) reserves (zeros without reserves)
    lam: np.ndarray          # (nd,) multipliers of A x + rho = b (cost gradient = A' lam)
    solved: bool
    status: str              # proxsuite status name of the last QP
    iterations: int          # proxsuite iterations, summed over SQP steps
    qp_solves: int           # number of proxsuite QPs (1, or the SQP steps)


@dataclass
class _QPOut:
    x: np.ndarray
    y: np.ndarray
    iter: int
    status: str


@dataclass
class BatchSolution:
    """Solution of many frames by :func:`dual_newton` (scaled units)."""

    x: np.ndarray            # (N, m)
    rho: np.ndarray          # (N, nd)
    lam: np.ndarray          # (N, nd)
    converged: np.ndarray    # (N,) bool: residual <= tol (KKT verified)
    iterations: np.ndarray   # (N,) Newton iterations
    residual: np.ndarray     # (N,) max |b - A x - rho|


# ---------------------------------------------------------------------------
# proxsuite, frame by frame
# ---------------------------------------------------------------------------

class FrameQP:
    """A proxsuite dense QP for one frame of the scaled problem, reused across frames.

    Parameters (keyword-only): ``m`` muscle variables, ``nd`` equality rows,
    ``weights`` ``w`` (m,) of ``sum w x^P`` (or ``u`` of ``max u x``),
    ``exponent`` P, ``minmax``, ``reserve_weight`` W or None (reserve cost
    ``W (|rho| + rho^2)``, or ``W rho^2`` with ``reserve_linear=False`` -- a
    soft equality, as FSO's tracking cost uses it), ``eps``
    proxsuite's absolute tolerance, ``max_iter`` its iteration limit,
    ``sqp_tol`` the step at which SQP stops, ``sqp_max_iter``.

    Internally the variables are ``y = sig * x`` with ``sig = (w / max w)^(1/P)``
    (``w / max w`` for P = 1 and min/max), so the cost is ``sum y^P`` or
    ``max y`` with unit weights: P = 10 with F_max weights spans 1e-11..1 in
    ``w`` but only 0.08..1 in ``sig``.  The min/max epigraph is written with
    slacks as equalities, ``y_i - t + s_i = 0, s_i >= 0`` (proxsuite wrongly
    reported some feasible frames as infeasible in the inequality form), and
    every bound is finite (``t, s <= max(hi) + 1``; a reserve never needs
    more than ``|b_j| + sum_i |A_ji| hi_i``).
    """

    def __init__(self, *, m: int, nd: int, weights, exponent: float = 2.0, minmax: bool = False,
                 reserve_weight: float | None = None, reserve_linear: bool = True,
                 eps: float = 1e-10, max_iter: int = 300, sqp_tol: float = 1e-9,
                 sqp_max_iter: int = 100):
        self.proxqp = _proxqp()
        self.m = m = int(m)
        self.nd = nd = int(nd)
        self.P = check_exponent(exponent)
        self.minmax = bool(minmax)
        w = np.asarray(weights, dtype=float).reshape(m)
        if np.any(~(w > 0)):
            raise SolverError(f"FrameQP: weights must be > 0, got {w}")
        w = w / np.max(w)
        self.sig = w if (self.minmax or self.P == 1.0) else w ** (1.0 / self.P)
        self.W = None if reserve_weight is None else float(reserve_weight)
        self.WL = self.W if (self.W is not None and reserve_linear) else 0.0
        self.eps = float(eps)
        self.max_iter = int(max_iter)
        self.sqp_tol = float(sqp_tol)
        self.sqp_max_iter = int(sqp_max_iter)
        # layout: [y (m) | t, s (m) if minmax | rho+ (nd), rho- (nd) if reserves]
        self.nt = (1 + m) if self.minmax else 0
        self.nr = 2 * nd if self.W is not None else 0
        self.r0 = m + self.nt
        self.n = m + self.nt + self.nr
        self.n_eq = nd + (m if self.minmax else 0)
        self._qp = None
        self._warm = False
        self._last_y = np.zeros(nd)
        Af = np.zeros((self.n_eq, self.n))
        if self.nr:
            Af[:nd, self.r0:self.r0 + nd] = np.eye(nd)
            Af[:nd, self.r0 + nd:] = -np.eye(nd)
        if self.minmax:
            Af[nd:, :m] = np.eye(m)
            Af[nd:, m] = -1.0
            Af[nd:, m + 1:m + 1 + m] = np.eye(m)
        self._Afull = Af
        self._bfull = np.zeros(self.n_eq)
        self.sqp = (not self.minmax) and self.P > 2.0

    # -- pieces of the QP -----------------------------------------------------
    def _objective(self, y_lin, Q, q, floor: float = 1e-4):
        """H, g of the QP in internal units; ``y_lin`` is the SQP linearisation point."""
        n, m = self.n, self.m
        H = np.zeros((n, n))
        g = np.zeros(n)
        diag = np.arange(m)
        if self.minmax:
            g[m] = 1.0
        elif self.P == 1.0:
            g[:m] = 1.0
        elif y_lin is None:  # P = 2, or the P = 2 start of SQP
            H[diag, diag] = 2.0
        else:
            P = self.P
            yf = np.maximum(y_lin, floor)
            h = P * (P - 1.0) * yf ** (P - 2.0)
            # keep the model strictly convex (its fixed point is the exact optimum
            # whatever positive curvature is used; flat directions stall proxsuite)
            h = np.maximum(h, 1e-5 * float(np.max(h)))
            grad = P * np.maximum(y_lin, 0.0) ** (P - 1.0)
            H[diag, diag] = h
            g[:m] = grad - h * y_lin
        if self.nr:
            idx = np.arange(self.r0, n)
            H[idx, idx] = 2.0 * self.W
            g[self.r0:] = self.WL
        if Q is not None:
            H[:m, :m] += Q
        if q is not None:
            g[:m] += q
        return H, g

    def _boxes(self, lo, hi, A, b):
        lb = np.zeros(self.n)
        ub = np.zeros(self.n)
        lb[:self.m] = lo
        ub[:self.m] = hi
        if self.minmax:
            ub[self.m:self.m + 1 + self.m] = max(float(np.max(hi)), 0.0) + 1.0
        if self.nr:
            cap = np.abs(b) + np.abs(A) @ np.abs(hi) + 1.0
            ub[self.r0:self.r0 + self.nd] = cap
            ub[self.r0 + self.nd:] = cap
        return lb, ub

    def _fresh(self):
        pq = self.proxqp
        qp = pq.dense.QP(self.n, self.n_eq, 0, True)
        qp.settings.eps_abs = self.eps
        qp.settings.eps_rel = 0.0
        qp.settings.max_iter = self.max_iter
        qp.settings.verbose = False
        qp.settings.initial_guess = pq.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        return qp

    def _qp_solve(self, H, g, A, b, lb, ub) -> "_QPOut":
        """One QP; warm start only from a successful solve of the same-size QP.

        The frame is rescaled first: variables by ``beta = max|b|`` (so a frame
        with tiny moments is not a tiny problem: proxsuite's absolute
        tolerances and infeasibility test would misjudge it) and the objective
        to a unit gradient (or Hessian).  Results come back in internal units.
        """
        pq = self.proxqp
        beta = max(float(np.max(np.abs(b))) if b.size else 1.0, 1e-9)
        Hs = H * (beta * beta)
        gs = g * beta
        # normalise by the muscle (and t) part only: the reserves' high cost must
        # not shrink the muscles' curvature below proxsuite's tolerances
        k = self.r0
        c = float(np.max(np.abs(gs[:k]))) if k else 0.0
        if not c > 1e-300:
            c = float(np.max(np.abs(Hs[:k, :k]))) if k else 0.0
        c = c if c > 1e-300 else 1.0
        Hs /= c
        gs /= c
        if self.nr:
            # a reserve cost above 1e6 muscle-gradients is an exact penalty already;
            # capping it keeps frames with tiny forces (P = 10: gradients ~1e-22) solvable
            idx = np.arange(k, self.n)
            Hs[idx, idx] = np.minimum(Hs[idx, idx], 1e6)
            gs[k:] = np.minimum(gs[k:], 1e6)
        lbs = lb / beta
        ubs = ub / beta
        Af = self._Afull
        Af[:self.nd, :self.m] = A
        bs = self._bfull
        bs[:self.nd] = b / beta
        attempts = ["warm", "cold"] if (self._qp is not None and self._warm) else ["cold"]
        attempts.append("loose")
        for how in attempts:
            if how == "warm":
                qp = self._qp
                qp.settings.initial_guess = pq.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
                qp.update(H=Hs, g=gs, A=Af, b=bs, l_box=lbs, u_box=ubs, update_preconditioner=False)
            else:
                qp = self._fresh()
                if how == "loose":
                    # last resort: a looser tolerance (still far below the SO tolerance in
                    # the default settings); badly scaled frames stall at the tight one
                    qp.settings.eps_abs = min(self.eps * 1e3, 1e-8)
                    qp.settings.max_iter = 5 * self.max_iter
                self._qp = qp
                qp.init(Hs, gs, Af, bs, None, None, None, lbs, ubs)
            qp.solve()
            res = qp.results
            ok = (res.info.status.name in _SOLVED_NAMES and np.all(np.isfinite(res.x))
                  and np.all(np.isfinite(res.y)))
            out = _QPOut(x=np.array(res.x) * beta, y=np.array(res.y)[:self.nd] * (c / beta),
                         iter=int(res.info.iter), status=res.info.status.name)
            if ok:
                self._warm = True
                self._last_y = out.y
                return out, True
            self._warm = False   # never warm start from a failed solve
            if how == "cold" and out.status == "PROXQP_PRIMAL_INFEASIBLE":
                break            # a cold verdict of infeasibility: do not insist
        return out, False

    def solve(self, A, b, lo, hi, *, Q=None, q=None, x0=None) -> FrameSolution:
        """Solve one frame: ``A`` (nd, m), ``b`` (nd,), bounds (m,); optional ``Q`` (m, m), ``q`` (m,).

        For P > 2, ``x0`` (m,) -- e.g. the previous frame's answer -- is the
        first linearisation point of SQP; without it SQP starts from the
        P = 2 solution.
        """
        sig = self.sig
        A = np.asarray(A, dtype=float).reshape(self.nd, self.m) / sig
        b = np.asarray(b, dtype=float).reshape(self.nd)
        lo = np.broadcast_to(np.asarray(lo, dtype=float), (self.m,)) * sig
        hi = np.broadcast_to(np.asarray(hi, dtype=float), (self.m,)) * sig
        if Q is not None:
            Q = np.asarray(Q, dtype=float) / np.outer(sig, sig)
        if q is not None:
            q = np.asarray(q, dtype=float) / sig
        lb, ub = self._boxes(lo, hi, A, b)
        iters = 0
        nsolve = 0
        status = "PROXQP_SOLVED"
        if self.sqp and x0 is not None and np.all(np.isfinite(x0)):
            z = np.zeros(self.n)
            z[:self.m] = np.clip(np.asarray(x0, dtype=float) * sig, lo, hi)
            feasible = False
        else:
            H, g = self._objective(None, Q, q)
            res, ok = self._qp_solve(H, g, A, b, lb, ub)
            iters += res.iter
            nsolve += 1
            z = res.x
            status = res.status
            feasible = True
            if not ok:
                return self._pack(z, False, status, iters, nsolve)
        ok = True
        if self.sqp:
            z, ok, it2, n2, status = self._sqp(z, A, b, lb, ub, Q, q, feasible=feasible)
            iters += it2
            nsolve += n2
        return self._pack(z, ok, status, iters, nsolve)

    def _pack(self, z, ok, status, iters, nsolve) -> FrameSolution:
        m, nd = self.m, self.nd
        x = np.array(z[:m]) / self.sig
        rho = (z[self.r0:self.r0 + nd] - z[self.r0 + nd:]) if self.nr else np.zeros(nd)
        lam = -self._last_y if ok else np.full(nd, np.nan)
        return FrameSolution(x=x, rho=np.array(rho), lam=lam, solved=bool(ok), status=status,
                             iterations=int(iters), qp_solves=int(nsolve))

    def _total(self, z, Q, q):
        m = self.m
        y = z[:m]
        c = float(np.sum(np.maximum(y, 0.0) ** self.P))
        if self.nr:
            r = z[self.r0:]
            c += float(np.sum(self.WL * r + self.W * r * r))
        if Q is not None:
            c += 0.5 * float(y @ Q @ y)
        if q is not None:
            c += float(q @ y)
        return c

    def _sqp(self, z, A, b, lb, ub, Q, q, *, feasible: bool):
        """Newton steps on sum y^P (+ reserves, + tracking) with the linear constraints.

        Each step is a proxsuite QP in ``y`` itself (so any linearisation
        point works); from a feasible point an Armijo line search on the cost
        keeps the iterates feasible and decreasing.  Stops when the step is
        below ``sqp_tol`` or the predicted decrease below SQP_RTOL of the cost.
        """
        m = self.m
        iters = 0
        nsolve = 0
        f0 = self._total(z, Q, q) if feasible else np.inf
        for it in range(self.sqp_max_iter):
            # curvature floor for near-zero forces (y^(P-2) vanishes there, which
            # would make them free torque sources in the model): 5 % of the
            # largest y at first, shrinking tenfold per step
            floor = max(0.05 * float(np.max(z[:m], initial=0.0)) * 0.1 ** it, 1e-6)
            H, g = self._objective(z[:m], Q, q, floor)
            res, ok = self._qp_solve(H, g, A, b, lb, ub)
            iters += res.iter
            nsolve += 1
            if not ok:
                return z, False, iters, nsolve, res.status
            znew = res.x
            if not feasible:          # first step from an outside guess: take it whole
                z, f0, feasible = znew, self._total(znew, Q, q), True
                continue
            d = znew - z
            step = float(np.max(np.abs(d[:m]))) if m else 0.0
            grad = self.P * np.maximum(z[:m], 0.0) ** (self.P - 1.0)
            if Q is not None:
                grad = grad + Q @ z[:m]
            if q is not None:
                grad = grad + q
            pred = -float(grad @ d[:m])
            if self.nr:
                r = z[self.r0:]
                pred -= float(np.sum((self.WL + 2.0 * self.W * r) * d[self.r0:]))
            if step <= self.sqp_tol or pred <= SQP_RTOL * abs(f0):
                return znew, True, iters, nsolve, "PROXQP_SOLVED"
            alpha = 1.0
            for _ls in range(40):
                zt = z + alpha * d
                ft = self._total(zt, Q, q)
                if ft <= f0 - 1e-4 * alpha * pred + 1e-15 * abs(f0):
                    break
                alpha *= 0.5
            else:
                return z, True, iters, nsolve, "PROXQP_SOLVED"   # no further decrease possible
            z, f0 = zt, ft
        return z, False, iters, nsolve, "SQP_MAX_ITER_REACHED"


# ---------------------------------------------------------------------------
# batched semismooth Newton on the dual (P >= 2)
# ---------------------------------------------------------------------------

def _primal_from_dual(A, lam, w, P, lo, hi, W):
    """Box minimiser of the Lagrangian for multipliers ``lam`` and its derivative.

    Returns ``x, D, rho, Drho, s`` where ``D = dx/ds`` (0 at the bounds).
    """
    s = np.matmul(lam[:, None, :], A)[:, 0, :]           # A' lam, batched
    if P == 2.0:
        xu = s / (2.0 * w)
        D = np.broadcast_to(1.0 / (2.0 * w), s.shape)
    else:
        sp = np.maximum(s, 0.0)
        xu = (sp / (P * w)) ** (1.0 / (P - 1.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            D = np.where(sp > 0.0, xu / ((P - 1.0) * np.where(sp > 0, s, 1.0)), 0.0)
    x = np.minimum(np.maximum(xu, lo), hi)
    free = (xu > lo) & (xu < hi)
    D = np.where(free, D, 0.0)
    if W is None:
        rho = np.zeros_like(lam)
        Drho = np.zeros_like(lam)
    else:
        mag = np.maximum(np.abs(lam) - W, 0.0)
        rho = np.sign(lam) * mag / (2.0 * W)
        Drho = np.where(mag > 0, 1.0 / (2.0 * W), 0.0)
    return x, D, rho, Drho, s


def _dual_value(x, s, rho, lam, b, w, P, W):
    th = np.sum(w * x ** P - s * x, axis=1) + np.sum(lam * b, axis=1)
    if W is not None:
        th = th + np.sum(W * (np.abs(rho) + rho * rho) - lam * rho, axis=1)
    return th


def dual_newton(A, b, w, P, lo, hi, *, reserve_weight=None, lam0=None, tol: float = 1e-10,
                max_iter: int = 60) -> BatchSolution:
    """Solve many frames of the scaled problem (P >= 2) at once; see the module notes.

    ``A`` (N, nd, m), ``b`` (N, nd), ``w`` (m,) or (N, m) positive, ``lo``/``hi``
    broadcastable to (N, m).  Frames whose residual stays above ``tol`` after
    ``max_iter`` Newton steps (or whose line search stalls) come back with
    ``converged = False``; their ``x`` is not optimal.
    """
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    N, nd, m = A.shape
    P = float(P)
    if P < 2.0:
        raise SolverError("dual_newton needs P >= 2 (P = 1 is an LP: use lp_verify or FrameQP)")
    w = np.broadcast_to(np.asarray(w, dtype=float), (N, m))
    lo = np.broadcast_to(np.asarray(lo, dtype=float), (N, m))
    hi = np.broadcast_to(np.asarray(hi, dtype=float), (N, m))
    W = None if reserve_weight is None else float(reserve_weight)
    eye = np.eye(nd)

    def hess(idx, D, Drho):
        Ai = A[idx]
        Hm = np.matmul(Ai * D[:, None, :], np.swapaxes(Ai, 1, 2))
        Hm[:, np.arange(nd), np.arange(nd)] += Drho
        return Hm

    if lam0 is None:
        # start from the problem without bounds at P = 2 ...
        D0 = 1.0 / (2.0 * w)
        H0 = np.matmul(A * D0[:, None, :], np.swapaxes(A, 1, 2)) + 1e-12 * eye
        if W is not None:   # a dof with reserves only: lam = W (1 + 2 b) at the optimum
            H0 = H0 + eye / (2.0 * W)
        lam = np.linalg.solve(H0, b[..., None])[..., 0]
        if P != 2.0:
            # ... and, for P > 2, match its activations in the KKT relation s = P w x^(P-1)
            x2 = np.clip(np.matmul(lam[:, None, :], A)[:, 0, :] * D0, lo, hi)
            x2 = np.maximum(x2, 1e-3)
            s_target = P * w * x2 ** (P - 1.0)
            G = np.matmul(A, np.swapaxes(A, 1, 2)) + 1e-12 * eye
            lam = np.linalg.solve(G, np.matmul(A, s_target[..., None]))[..., 0]
    else:
        lam = np.array(np.broadcast_to(lam0, (N, nd)), dtype=float)

    x, D, rho, Drho, s = _primal_from_dual(A, lam, w, P, lo, hi, W)
    res = b - np.matmul(A, x[..., None])[..., 0] - rho
    rnorm = np.max(np.abs(res), axis=1) if nd else np.zeros(N)
    iters = np.zeros(N, dtype=int)
    target = 1e-3 * tol      # iterate past the acceptance tolerance (Newton is cheap there)
    active = rnorm > target
    stalled = np.zeros(N, dtype=bool)
    for _ in range(max_iter):
        idx = np.flatnonzero(active & ~stalled)
        if idx.size == 0:
            break
        iters[idx] += 1
        g = res[idx]
        gn = rnorm[idx]
        Hm = hess(idx, D[idx], Drho[idx])
        # Levenberg-Marquardt term ~ |g|^2: harmless near the solution (keeps the
        # exact active-set step of P = 2), decisive where a dof has no free muscle
        reg = 1e-13 + (1e-12 + 1e-2 * np.minimum(gn, 1.0) ** 2) * np.maximum(
            np.trace(Hm, axis1=1, axis2=2) / max(nd, 1), 1e-6)
        Hm[:, np.arange(nd), np.arange(nd)] += reg[:, None]
        d = np.linalg.solve(Hm, g[..., None])[..., 0]
        # keep steps within a sane trust radius (a dof with no free muscle has a flat dual)
        dmax = np.max(np.abs(d), axis=1)
        cap = 10.0 * (1.0 + np.max(np.abs(lam[idx]), axis=1))
        d *= np.minimum(1.0, cap / np.maximum(dmax, 1e-300))[:, None]
        wi, loi, hii, bi = w[idx], lo[idx], hi[idx], b[idx]
        lam_i = lam[idx]
        th0 = _dual_value(x[idx], s[idx], rho[idx], lam_i, bi, wi, P, W)
        slope = np.sum(g * d, axis=1)
        alpha = np.ones(idx.size)
        todo = np.ones(idx.size, dtype=bool)
        new_lam = lam_i.copy()
        if P != 2.0:
            # for P > 2 first try the full step along the curve lam = phi(mu + dmu),
            # phi(mu) = sign(mu)|mu|^(P-1): x is linear in mu for one dof, so this
            # step is exact there and nearly so for several dofs.
            e = 1.0 / (P - 1.0)
            mu = np.sign(lam_i) * np.abs(lam_i) ** e
            dphi = (P - 1.0) * np.abs(mu) ** (P - 2.0)
            small = dphi < 1e-300
            dmu = np.where(small, 0.0, d / np.where(small, 1.0, dphi))
            mu_t = mu + dmu
            lam_c = np.where(small, lam_i + d, np.sign(mu_t) * np.abs(mu_t) ** (P - 1.0))
            xt, Dt, rt, Drt, st = _primal_from_dual(A[idx], lam_c, wi, P, loi, hii, W)
            tht = _dual_value(xt, st, rt, lam_c, bi, wi, P, W)
            ok = tht >= th0 + 1e-4 * slope - 1e-13 * (1.0 + np.abs(th0))
            new_lam[ok] = lam_c[ok]
            todo[ok] = False
        for _ls in range(40):
            t = np.flatnonzero(todo)
            if t.size == 0:
                break
            lam_t = lam_i[t] + alpha[t, None] * d[t]
            xt, Dt, rt, Drt, st = _primal_from_dual(A[idx[t]], lam_t, wi[t], P, loi[t], hii[t], W)
            tht = _dual_value(xt, st, rt, lam_t, bi[t], wi[t], P, W)
            ok = tht >= th0[t] + 1e-4 * alpha[t] * slope[t] - 1e-13 * (1.0 + np.abs(th0[t]))
            new_lam[t[ok]] = lam_t[ok]
            todo[t[ok]] = False
            alpha[t[~ok]] *= 0.5
        stalled[idx[todo]] = True
        lam[idx] = new_lam
        xi, Di, ri, Dri, si = _primal_from_dual(A[idx], new_lam, wi, P, loi, hii, W)
        x[idx], D[idx], rho[idx], Drho[idx], s[idx] = xi, Di, ri, Dri, si
        res[idx] = bi - np.matmul(A[idx], xi[..., None])[..., 0] - ri
        rnorm[idx] = np.max(np.abs(res[idx]), axis=1)
        active[idx] = rnorm[idx] > target
    converged = rnorm <= tol
    return BatchSolution(x=x, rho=rho, lam=lam, converged=converged, iterations=iters, residual=rnorm)


# ---------------------------------------------------------------------------
# batched basis verification for LPs (P = 1 and min/max)
# ---------------------------------------------------------------------------

def _solve_many(M, r):
    """Batched ``M x = r``; singular (or non-finite) systems give x = 0 and a True flag."""
    try:
        x = np.linalg.solve(M, r[..., None])[..., 0]
        bad = ~np.all(np.isfinite(x), axis=1)
        return np.where(bad[:, None], 0.0, x), bad
    except np.linalg.LinAlgError:
        x = np.zeros(r.shape)
        bad = np.zeros(r.shape[0], dtype=bool)
        for i in range(r.shape[0]):
            try:
                x[i] = np.linalg.solve(M[i], r[i])
                bad[i] = not np.all(np.isfinite(x[i]))
            except np.linalg.LinAlgError:
                bad[i] = True
        return x, bad


def lp_basis_from(z, lo, hi, ne: int) -> np.ndarray:
    """A guess of the optimal basis (``ne`` variable indices) from a solution ``z`` (n,).

    The variables farthest from their bounds (relative to the box width, or
    1 for unbounded ones) are taken as basic.
    """
    z = np.asarray(z, dtype=float)
    width = np.where(hi >= BIG / 10, 1.0, np.maximum(hi - lo, 1e-12))
    dist = np.minimum(z - lo, np.where(hi >= BIG / 10, np.inf, hi - z)) / width
    return np.sort(np.argsort(-dist, kind="stable")[:ne])


def lp_verify(E, f, c, lo, hi, basis, *, tol: float = 1e-9):
    """Vertex solutions of ``min c'z, E z = f, lo <= z <= hi`` for a guessed basis.

    ``E`` (N, ne, n), ``f`` (N, ne), ``c`` (n,), ``lo``/``hi`` (N, n), ``basis``
    (ne,) indices shared by all frames.  Non-basic variables sit at the bound
    their reduced cost asks for, so the vertex is dual feasible by
    construction; ``ok`` marks the frames where it is also primal feasible
    (basic variables within bounds, finite non-basic bounds), i.e. optimal.
    Returns ``ok (N,), z (N, n), y (N, ne)``.
    """
    E = np.asarray(E, dtype=float)
    N, ne, n = E.shape
    basis = np.asarray(basis, dtype=int)
    nb = np.setdiff1d(np.arange(n), basis)
    EB = E[:, :, basis]
    cB = c[basis]
    y, sing = _solve_many(np.swapaxes(EB, 1, 2), np.broadcast_to(cB, (N, ne)))
    ok = ~sing
    EN = E[:, :, nb]
    r = c[None, nb] - np.matmul(y[:, None, :], EN)[:, 0, :]
    loN, hiN = lo[:, nb], hi[:, nb]
    # r ~ 0 (a tie) may sit at either bound: take the lower one
    up = r < -1e-12
    zN = np.where(up, hiN, loN)
    ok &= ~np.any(up & (hiN >= BIG / 10), axis=1)
    ok &= ~np.any(~up & (loN <= -BIG / 10), axis=1)
    rhs = f - np.matmul(EN, zN[..., None])[..., 0]
    zB, sing = _solve_many(EB, rhs)
    ok &= ~sing
    ok &= np.all(zB >= lo[:, basis] - tol, axis=1) & np.all(zB <= hi[:, basis] + tol, axis=1)
    ok &= np.all(np.isfinite(zB), axis=1)
    z = np.empty((N, n))
    z[:, basis] = np.clip(zB, lo[:, basis], hi[:, basis])
    z[:, nb] = zN
    # the clip moved z by at most tol; keep the equality residual honest
    if ne:
        ok &= np.max(np.abs(np.matmul(E, z[..., None])[..., 0] - f), axis=1) <= 10 * tol
    return ok, z, y
