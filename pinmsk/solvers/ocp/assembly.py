"""Exact sparse derivatives of a collocation NLP, assembled from its local pieces.

A collocation NLP is a sum of *local* pieces: each interval's defects, residuals
and path rows depend only on the variables of that interval (its two nodes, its
midpoint controls, and the duration if free).  :class:`LocalBlock` holds one
such piece as a small CasADi ``SX`` function of its local variables ``z`` and
constants ``p``, with the index matrix that gathers ``z`` from the NLP vector
``w`` for every instance.  :func:`assemble` differentiates each piece once,
symbolically (its Jacobian and the upper triangle of its Lagrangian Hessian),
maps the derivative functions over the instances, and scatters their nonzeros
into the NLP's sparse Jacobian and Hessian with one constant sparse matrix each
(which also sums the entries that neighbouring intervals share).

Why: handing CasADi the whole NLP instead costs either seconds of symbolic
differentiation of the expanded graph (every interval's Hessian built anew) or,
unexpanded, tens of seeded sweeps of the whole graph per evaluation; here the
Hessian of one interval is built once and evaluated in one mapped call.

The rest of the NLP (the objective, linear links such as a global
parametrization's ``S = B P``, boundary rows) is small and is differentiated by
CasADi directly.  Integrals enter through one variable per cost term
(``I_c - sum_k c_k(z_k) = 0``), so the objective is a function of a few
variables whatever the cost's finish (a mean, a cost of transport ...).
"""
from __future__ import annotations

import numpy as np

__all__ = ["LocalBlock", "assemble"]


class LocalBlock:
    """``K`` instances of ``fn(z, p) -> (rows, integrals)`` with ``z = w[idx[:, k]]``, ``p = params[:, k]``.

    ``rows`` become consecutive rows of the NLP's ``g`` (instance after instance);
    ``integrals`` (one per cost term) are summed over the instances.
    """

    def __init__(self, name: str, fn, idx: np.ndarray, params: np.ndarray):
        self.name, self.fn = name, fn
        self.idx = np.asarray(idx, dtype=np.int64)
        self.params = np.asarray(params, dtype=float)
        self.K = self.idx.shape[1]
        self.n_rows = fn.size1_out(0)
        self.n_int = fn.size1_out(1)


def assemble(w, blocks, other_g, *, n_int_vars: int = 0, int_weights=None, f_extra=0):
    """The NLP's ``g``, ``f`` and custom ``jac_g``, ``hess_lag`` (and ``grad_f`` with direct integrals, else
    None) Functions (CasADi ``nlpsol`` options).

    ``w`` (MX symbol, n_w): the decision vector; ``blocks``: :class:`LocalBlock` s;
    ``other_g`` (MX of ``w``): the remaining rows.  The integrals enter the objective
    either through variables -- the LAST ``n_int_vars`` entries of ``w``, with rows
    ``I - sum integrals = 0`` -- or, when every cost is linear in its integral,
    directly: ``f = int_weights . sum integrals + f_extra``.  ``f_extra`` (MX of ``w``):
    the rest of the objective.  ``g = [rows of each block, (I - sum integrals), other_g]``.
    """
    import casadi as ca
    n_w = int(w.numel())
    lam_f = ca.MX.sym("lam_f")
    direct = n_int_vars == 0
    g_parts, jac_trip, jac_vals, hess_trip, hess_vals = [], [], [], [], []
    grad_trip, grad_vals = [], []
    row0 = 0
    n_rows_local = sum(b.n_rows * b.K for b in blocks)
    i_row0 = n_rows_local                       # first integral row
    n_g_other = int(other_g.numel())
    n_g = n_rows_local + n_int_vars + n_g_other
    lam_g = ca.MX.sym("lam_g", n_g)
    integ_sum = 0
    # the weights of the integrals in the Lagrangian: -mu (rows I - sum c) or lam_f * int_weights
    mu = (-lam_f * ca.DM(np.asarray(int_weights, dtype=float)) if direct and int_weights is not None and len(int_weights)
          else lam_g[i_row0: i_row0 + n_int_vars])
    for b in blocks:
        z = ca.SX.sym("z", b.idx.shape[0])
        p = ca.SX.sym("p", b.params.shape[0])
        r, c = b.fn(z, p)
        lr = ca.SX.sym("lr", b.n_rows)
        lc = ca.SX.sym("lc", b.n_int)
        if mu.numel() != b.n_int:
            mu = ca.MX.zeros(b.n_int)
        Jr = ca.jacobian(r, z)
        Jc = ca.jacobian(c, z)
        # the integral rows are I - sum c: their multipliers weigh -c
        H = ca.triu(ca.hessian(ca.dot(lr, r) - ca.dot(lc, c), z)[0])
        # values, Jacobian, gradient and Hessian are separate mapped functions, so that evaluating
        # g or f never computes derivatives
        Fj = ca.Function(f"{b.name}_jacobian", [z, p], [_nonzeros(Jr), _nonzeros(Jc)])
        Fh = ca.Function(f"{b.name}_hessian", [z, p, lr, lc], [_nonzeros(H)])
        Zk = ca.reshape(w[b.idx.ravel(order="F").tolist()], b.idx.shape[0], b.K)
        Pk = ca.DM(b.params)
        Lr = ca.reshape(lam_g[row0: row0 + b.n_rows * b.K], b.n_rows, b.K)
        Rk, Ck = b.fn.map(b.K)(Zk, Pk)
        JRk, JCk = Fj.map(b.K)(Zk, Pk)
        HKk = Fh.map(b.K)(Zk, Pk, Lr, ca.repmat(mu, 1, b.K))
        if direct and int_weights is not None and len(int_weights):
            Fg = ca.Function(f"{b.name}_gradient", [z, p], [ca.gradient(ca.dot(ca.DM(np.asarray(int_weights, float)), c), z)])
            grad_trip.append(b.idx.ravel(order="F"))
            grad_vals.append(ca.vec(Fg.map(b.K)(Zk, Pk)))
        g_parts.append(ca.vec(Rk))
        integ_sum = integ_sum + ca.sum2(Ck)
        # Jacobian triplets: local rows are distinct NLP rows; integral rows sum over instances
        jr_r, jr_c = Jr.sparsity().get_triplet()
        jc_r, jc_c = Jc.sparsity().get_triplet()
        jr_r, jr_c, jc_r, jc_c = map(np.asarray, (jr_r, jr_c, jc_r, jc_c))
        k = np.arange(b.K)
        if jr_r.size:
            jac_trip.append((row0 + (k[None, :] * b.n_rows + jr_r[:, None]).ravel(order="F"),
                             b.idx[jr_c][:, k].ravel(order="F")))
            jac_vals.append(ca.vec(JRk))
        if jc_r.size and not direct:
            jac_trip.append(((i_row0 + jc_r)[:, None].repeat(b.K, 1).ravel(order="F"),
                             b.idx[jc_c][:, k].ravel(order="F")))
            jac_vals.append(-ca.vec(JCk))
        h_r, h_c = map(np.asarray, H.sparsity().get_triplet())
        if h_r.size:
            gi, gj = b.idx[h_r][:, k], b.idx[h_c][:, k]
            hess_trip.append((np.minimum(gi, gj).ravel(order="F"), np.maximum(gi, gj).ravel(order="F")))
            hess_vals.append(ca.vec(HKk))
        row0 += b.n_rows * b.K
    if direct:
        g_int = ca.MX.zeros(0)
        f = f_extra + (ca.dot(ca.DM(np.asarray(int_weights, dtype=float)), integ_sum)
                       if int_weights is not None and len(int_weights) else 0)
    else:
        g_int = w[n_w - n_int_vars:] - integ_sum
        f = f_extra
    g = ca.vertcat(*g_parts, g_int, other_g)
    # integral rows: +1 on their own variable
    if n_int_vars:
        jac_trip.append((i_row0 + np.arange(n_int_vars), n_w - n_int_vars + np.arange(n_int_vars)))
        jac_vals.append(ca.MX.ones(n_int_vars))
    # the rest: CasADi's own derivatives (small support)
    if n_g_other:
        Jo = ca.jacobian(other_g, w)
        so = Jo.sparsity()
        r_o, c_o = map(np.asarray, so.get_triplet())
        jac_trip.append((i_row0 + n_int_vars + r_o, c_o))
        jac_vals.append(_nonzeros(Jo))
    lam_o = lam_g[i_row0 + n_int_vars:]
    Lo = lam_f * f_extra + (ca.dot(lam_o, other_g) if n_g_other else 0)
    Ho = ca.triu(ca.hessian(Lo, w)[0])
    ho_r, ho_c = map(np.asarray, Ho.sparsity().get_triplet())
    if ho_r.size:
        hess_trip.append((ho_r, ho_c))
        hess_vals.append(_nonzeros(Ho))
    J = _scatter(n_g, n_w, jac_trip, jac_vals)
    H = _scatter(n_w, n_w, hess_trip, hess_vals)
    p = ca.MX.sym("p", 0)
    jac_g = ca.Function("nlp_jac_g", [w, p], [g, J], ["x", "p"], ["g", "jac_g_x"])
    grad_f = None
    if grad_trip:           # direct integrals: the gradient is the local gradients summed
        Gf = _scatter(n_w, 1, [(np.concatenate(grad_trip), np.zeros(sum(t.size for t in grad_trip), dtype=np.int64))],
                      [ca.vertcat(*grad_vals)])
        if not (isinstance(f_extra, (int, float)) and f_extra == 0):
            Gf = Gf + ca.gradient(f_extra, w)
        grad_f = ca.Function("nlp_grad_f", [w, p], [f, ca.densify(Gf)], ["x", "p"], ["f", "grad_f_x"])
    hess_lag = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"],
                           ["triu_hess_gamma_x_x"])
    return g, f, jac_g, hess_lag, grad_f


def _nonzeros(M):
    """The nonzeros of a sparse SX/MX expression, in its sparsity's (column-major) order."""
    import casadi as ca
    if M.nnz() == 0:
        return type(M).zeros(0)
    return ca.vec(M.nz[:])


def _scatter(nrow, ncol, trips, vals):
    """A sparse MX matrix from triplet blocks and their value vectors, duplicates summed."""
    import casadi as ca
    if not trips:
        return ca.MX(nrow, ncol)
    rows = np.concatenate([np.asarray(t[0], dtype=np.int64) for t in trips])
    cols = np.concatenate([np.asarray(t[1], dtype=np.int64) for t in trips])
    sp, mapping = ca.Sparsity.triplet(nrow, ncol, rows.tolist(), cols.tolist(), True)
    mapping = np.asarray(mapping, dtype=np.int64)
    A = ca.DM(ca.Sparsity.triplet(sp.nnz(), rows.size, mapping.tolist(), list(range(rows.size))), 1.0)
    nz = ca.mtimes(A, ca.vertcat(*vals))
    return ca.MX(sp, nz)
