"""Nagano & Gerritsen contractile element with the Winters tendon (thesis App. A.4-A.5).

Pure, elementwise functions; :class:`pinmsk.muscles.NaganoGerritsen` binds the
per-muscle parameters.  :func:`ng_force_length`, :func:`ng_activation_hat` and
:func:`ng_fiber_force` also take CasADi values (:mod:`pinmsk.backend`).  The model has no parallel elastic element (thesis
Sec. 5.1: passive joint moments take its place).  Conventions:

- lengths normalized by ``l_opt``; velocity normalized by ``l_opt`` too
  (``v_norm = v_ce / l_opt`` in 1/s), as Eq. A.12 is written;
- forces normalized by ``F_max``; ``a_hat = min(1, 10 a / 3)``.

Force-velocity, Eq. A.12 with ``q = f_ce / (a F_max)``.  Concentric
(``v <= 0``): ``v = -a_hat l_opt [(f_isom + A_rel) B_rel/(q + A_rel) - B_rel]``,
solved for the force: ``q = (f_isom B_rel + A_rel w)/(B_rel - w)`` with
``w = v_norm / a_hat``.  Eccentric (``v > 0``, Eq. A.14 coefficients):
``v_norm = -[c1/(q + c2) - c3]``; with ``K = B_rel f_isom (f_hat - 1)/(f_isom + A_rel Gamma)``
(so that ``c3 = -a_hat K`` and ``c1 = a_hat K f_isom (f_hat - 1)``) this is
``q = f_isom [1 + (f_hat - 1) v_norm/(a_hat K + v_norm)]``.  With Gamma = 1 the
slopes of the two branches match at v = 0 (the curve is C1 there).

The force-length parabola (Eq. A.13) is negative for ``|l_norm - 1| > width``;
it is clipped to zero there (no fiber pushes).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..backend import backend_of

from ._common import check_active
from ._solve import compliant_equilibrium
from .pennation import check_along_positive, pennation_height
from .tendon import TENDON_STRAIN0, winters_tendon_force, winters_tendon_stiffness, winters_tendon_strain

__all__ = [
    "A_REL", "B_REL", "F_HAT", "GAMMA_SLOPE",
    "ng_activation_hat", "ng_force_length", "ng_force_length_derivative",
    "ng_fiber_velocity", "ng_fiber_force", "ng_fiber_force_partials",
    "ng_activation_from_force", "ng_equilibrium", "ng_contraction_rate",
]

A_REL = 0.41        # Hill constant a/F_max (thesis A.5, from [5, 14])
B_REL = 5.2         # Hill constant b/l_opt (1/s)
F_HAT = 1.4         # asymptotic eccentric force (from Thelen [3])
GAMMA_SLOPE = 1.0   # Gamma: eccentric/concentric slope ratio at v = 0 (thesis: 1, not 2)
A_HAT_KNEE = 0.3    # a_hat = min(1, a / 0.3)


def ng_activation_hat(a):
    """``a_hat = min(1, 10 a / 3)``: the activation scaling of the shortening velocity (Eq. A.12)."""
    xp = backend_of(a)
    return xp.minimum(1.0, xp.asarray(a) / A_HAT_KNEE)


def ng_force_length(l_norm, width):
    """Nagano-Gerritsen force-length, thesis Eq. A.13: ``c l^2 - 2 c l + c + 1``, ``c = -1/width^2``.

    Equals ``1 - (l - 1)^2 / width^2``: 1 at ``l_opt``, 0 at ``l_opt (1 +- width)``,
    clipped at 0 beyond.
    """
    xp = backend_of(l_norm)
    d = (xp.asarray(l_norm) - 1.0) / width
    return xp.maximum(1.0 - d * d, 0.0)


def ng_force_length_derivative(l_norm, width):
    """d f_isom / d l_norm of Eq. A.13 (zero where the parabola is clipped)."""
    d = (np.asarray(l_norm, dtype=float) - 1.0) / width
    return np.where(d * d < 1.0, -2.0 * d / width, 0.0)


def _k(f_isom, b_rel, f_hat, a_rel, gamma):
    return b_rel * f_isom * (f_hat - 1.0) / (f_isom + a_rel * gamma)


def ng_fiber_force(v_norm, a, f_isom, *, a_rel=A_REL, b_rel=B_REL, f_hat=F_HAT,
                   gamma=GAMMA_SLOPE):
    """CE force ``f_ce / F_max`` from fiber velocity: the exact inverse of Eq. A.12.

    ``a q`` with the concentric hyperbola ``q = (f_isom B + A w)/(B - w)``,
    ``w = v_norm / a_hat``, or the eccentric ``q = f_isom [1 + (f_hat - 1) v/(a_hat K + v)]``.
    """
    xp = backend_of(v_norm, a, f_isom)
    v = xp.asarray(v_norm)
    a = xp.asarray(a)
    ah = ng_activation_hat(a)
    vc = xp.minimum(v, 0.0)
    ve = xp.maximum(v, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = vc / ah
        q_con = (f_isom * b_rel + a_rel * w) / (b_rel - w)
        q_ecc = f_isom * (1.0 + (f_hat - 1.0) * ve / (ah * _k(f_isom, b_rel, f_hat, a_rel, gamma) + ve))
    f = a * xp.where(v <= 0.0, q_con, q_ecc)
    if xp.symbolic:     # a symbolic activation must be kept > 0 by its bounds (a = 0 is a 0/0 here)
        return f
    # a = 0 makes a_hat = 0 and q a 0/0 (w = v / 0); the force there is its limit a -> 0+, zero
    return np.where(a == 0.0, 0.0, f) if np.any(a == 0.0) else f


def ng_fiber_velocity(f_ce, a, f_isom, *, a_rel=A_REL, b_rel=B_REL, f_hat=F_HAT,
                      gamma=GAMMA_SLOPE):
    """Fiber velocity (in l_opt/s) from CE force ``f_ce / F_max``, thesis Eq. A.12.

    ``q = f_ce/a``; concentric (``q <= f_isom``): ``a_hat B (q - f_isom)/(q + A)``;
    eccentric: ``a_hat K (q - f_isom)/(f_isom f_hat - q)``.  Defined for
    ``-A < q < f_isom f_hat`` (``+inf`` at or beyond the eccentric asymptote).
    """
    f_ce = np.asarray(f_ce, dtype=float)
    a = np.asarray(a, dtype=float)
    ah = ng_activation_hat(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = f_ce / a
        dq = q - f_isom
        v_con = ah * b_rel * dq / (q + a_rel)
        gap = f_isom * f_hat - q
        v_ecc = np.where(gap > 0, ah * _k(f_isom, b_rel, f_hat, a_rel, gamma) * dq / gap, np.inf)
    return np.where(dq <= 0.0, v_con, v_ecc)


def ng_fiber_force_partials(v_norm, a, f_isom, *, a_rel=A_REL, b_rel=B_REL, f_hat=F_HAT,
                            gamma=GAMMA_SLOPE):
    """``(f, df/dv_norm, df/da, df/df_isom)`` of the CE force ``f = a q(v, a_hat, f_isom)``.

    Analytic partials for the inverse model's activation rate (thesis Eq. 5.4).
    ``d a_hat/d a = 10/3`` below ``a = 0.3`` and 0 from 0.3 on (the derivative
    jumps at 0.3; exactly there the right-hand value, 0, is used).
    """
    v = np.asarray(v_norm, dtype=float)
    a = np.asarray(a, dtype=float)
    f_isom = np.asarray(f_isom, dtype=float)
    ah = ng_activation_hat(a)
    dah = np.where(a < A_HAT_KNEE, 1.0 / A_HAT_KNEE, 0.0)
    concentric = v <= 0.0
    vc = np.minimum(v, 0.0)
    ve = np.maximum(v, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        # concentric: q = (fi B + A w)/(B - w), w = v / a_hat
        w = vc / ah
        den = b_rel - w
        q_c = (f_isom * b_rel + a_rel * w) / den
        dq_dw = (a_rel + f_isom) * b_rel / (den * den)
        dqv_c = dq_dw / ah
        dqa_c = -dq_dw * w / ah
        dqf_c = b_rel / den
        # eccentric: q = fi + fi (f_hat - 1) v / D, D = a_hat K + v
        k = _k(f_isom, b_rel, f_hat, a_rel, gamma)
        dk = b_rel * (f_hat - 1.0) * a_rel * gamma / (f_isom + a_rel * gamma) ** 2
        d = ah * k + ve
        g = (f_hat - 1.0) / (d * d)
        q_e = f_isom + f_isom * (f_hat - 1.0) * ve / d
        dqv_e = f_isom * g * ah * k
        dqa_e = -f_isom * g * ve * k
        dqf_e = 1.0 + g * ve * (d - f_isom * ah * dk)
    q = np.where(concentric, q_c, q_e)
    dq_dv = np.where(concentric, dqv_c, dqv_e)
    dq_dah = np.where(concentric, dqa_c, dqa_e)
    dq_df = np.where(concentric, dqf_c, dqf_e)
    # a = 0 (a_hat = 0): q is a 0/0 there; use the limits a -> 0+: f = 0 and its v and f_isom
    # slopes vanish, df/da = lim q (-A_rel shortening, f_isom isometric, f_hat f_isom lengthening)
    off = a == 0.0
    if np.any(off):
        q0 = np.where(v < 0.0, -a_rel, np.where(v > 0.0, f_hat * f_isom, f_isom))
        return (np.where(off, 0.0, a * q), np.where(off, 0.0, a * dq_dv),
                np.where(off, q0, q + a * dq_dah * dah), np.where(off, 0.0, a * dq_df))
    return a * q, a * dq_dv, q + a * dq_dah * dah, a * dq_df


def _positive_root(p, b, c):
    """Positive root of ``p x^2 + b x + c`` with ``p > 0, c <= 0`` (cancellation-free)."""
    sq = np.sqrt(b * b - 4.0 * p * c)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b >= 0.0, np.where(sq + b > 0, -2.0 * c / (b + sq), 0.0),
                        (sq - b) / (2.0 * p))


def ng_activation_from_force(f_ce, f_isom, v_norm, *, a_rel=A_REL, b_rel=B_REL, f_hat=F_HAT,
                             gamma=GAMMA_SLOPE):
    """Activation from CE force, fiber length and velocity -- closed form (thesis Eq. 5.2 for a).

    ``f = a q(v, a_hat, f_isom)`` is increasing in ``a``.  For ``a >= 0.3``
    (``a_hat = 1``) it is linear: ``a = f / q(v, 1)``.  Below, ``a_hat = 10a/3``
    makes it a quadratic in ``a`` with exactly one positive root:
    concentric ``f_isom B a^2 + (A k - B f) a + k f = 0`` with ``k = 0.3 v_norm``,
    eccentric ``(K f_isom / 0.3) a^2 + (f_isom f_hat v - K f / 0.3) a - f v = 0``.
    ``a = 0`` where ``f <= 0``; ``inf`` where ``f_isom = 0`` and ``f > 0``.
    """
    f = np.asarray(f_ce, dtype=float)
    fi = np.asarray(f_isom, dtype=float)
    v = np.asarray(v_norm, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        q1 = ng_fiber_force(v, 1.0, fi, a_rel=a_rel, b_rel=b_rel, f_hat=f_hat, gamma=gamma)
        a_lin = f / q1
        kc = A_HAT_KNEE * np.minimum(v, 0.0)
        a_con = _positive_root(fi * b_rel, a_rel * kc - b_rel * f, kc * f)
        kk = _k(fi, b_rel, f_hat, a_rel, gamma) / A_HAT_KNEE
        ve = np.maximum(v, 0.0)
        a_ecc = _positive_root(kk * fi, fi * f_hat * ve - kk * f, -f * ve)
        # f_isom = 0: no activation suffices (a = inf); the quadratics degenerate.
        a_low = np.where(fi > 0, np.where(v <= 0.0, a_con, a_ecc), np.inf)
        a = np.where(a_lin >= A_HAT_KNEE, a_lin, a_low)
    return np.where(f > 0, a, 0.0)


# --------------------------------------------------------------------------- muscle-tendon unit
def _fiber_closure(a, width, *, a_rel=A_REL, b_rel=B_REL, f_hat=F_HAT, gamma=GAMMA_SLOPE):
    a = np.asarray(a, dtype=float)

    def fiber(l_norm, v_norm):
        fi = ng_force_length(l_norm, width)
        dfi = ng_force_length_derivative(l_norm, width)
        if v_norm is None:
            return a * fi, a * dfi
        f, _, _, df_dfi = ng_fiber_force_partials(v_norm, a, fi, a_rel=a_rel, b_rel=b_rel,
                                                  f_hat=f_hat, gamma=gamma)
        return f, df_dfi * dfi

    return fiber


def ng_equilibrium(l_mt, a, *, l_opt, l_slack, pennation, width, v_mt=None,
                   tendon_strain0: float = TENDON_STRAIN0, tol: float = 1e-10,
                   max_iter: int = 100, names: Sequence[str] | None = None):
    """Compliant (Winters) tendon fiber equilibrium ``F_t = F_ce cos(alpha)`` for the NG muscle.

    As :func:`pinmsk.muscles.thelen2003.thelen_equilibrium`, without a parallel
    element.  Returns ``(l_ce, v_ce, f_t)``, ``f_t`` normalized by F_max.
    """
    l_opt = np.asarray(l_opt, dtype=float)
    a = np.asarray(a, dtype=float)
    l, v, f_t, _ = compliant_equilibrium(
        l_mt, l_opt=l_opt, l_slack=l_slack, height=pennation_height(l_opt, pennation),
        tendon=lambda e: (winters_tendon_force(e, strain0=tendon_strain0),
                          winters_tendon_stiffness(e, strain0=tendon_strain0)),
        tendon_strain=lambda f: winters_tendon_strain(f, strain0=tendon_strain0),
        fiber=_fiber_closure(a, np.asarray(width, dtype=float)), v_mt=v_mt, v_scale=l_opt,
        tol=tol, max_iter=max_iter, names=names, inputs={"l_mt": l_mt, "a": a})
    return l, v, f_t


def ng_contraction_rate(l_ce, l_mt, a, *, l_opt, l_slack, pennation, width,
                        tendon_strain0: float = TENDON_STRAIN0,
                        names: Sequence[str] | None = None):
    """Contraction dynamics ``l_ce' = f_CD(l_ce, l_mt, a)`` (m/s) with the Winters tendon (Eq. 3.9).

    The tendon force (Eq. A.10) over ``cos(alpha)`` is the CE force; Eq. A.12
    gives the velocity.  Needs ``a > 0``.
    """
    l_ce = np.asarray(l_ce, dtype=float)
    a = np.asarray(a, dtype=float)
    l_opt = np.asarray(l_opt, dtype=float)
    check_active(a, l_ce, names)
    h = pennation_height(l_opt, pennation)
    x = np.sqrt(np.maximum(l_ce * l_ce - h * h, 0.0))
    check_along_positive(x, l_mt, names, what="contraction dynamics")
    cos = x / l_ce
    f_t = winters_tendon_force((np.asarray(l_mt, dtype=float) - x) / l_slack - 1.0,
                               strain0=tendon_strain0)
    fi = ng_force_length(l_ce / l_opt, width)
    return l_opt * ng_fiber_velocity(f_t / cos, a, fi)
