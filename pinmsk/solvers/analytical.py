"""Closed-form muscle force sharing for one dof (thesis Sec. 2.2.6 and 3.5).

For one dof with moment arms ``r_i`` (flexors > 0, extensors < 0) and net
muscle moment ``T``, the problem

    minimise  sum_i (F_i / N_i)^P   subject to  sum_i r_i F_i = T,  0 <= F_i <= U_i

has an explicit solution; the KKT conditions pick the branch:

* the **antagonists** (``r_i T < 0``) are off: their multiplier
  ``mu_i = -lambda r_i`` is then non-negative (Eq. 3.30-3.34 and the remark
  after Eq. 3.34: no co-contraction for single-dof problems);
* the **agonists** share ``|T|`` as ``F_j = Gamma_j T`` with
  ``F_j proportional to (|r_j| N_j^P)^(1/(P-1))`` (Eq. 2.21-2.24, 3.31, 3.37,
  3.40), ``Gamma_j = (|r_j| N_j^P)^(1/(P-1)) / sum_i (|r_i| N_i)^(P/(P-1))``;
* with **upper bounds** ``U_i`` (``F_max``), a muscle whose share exceeds its
  bound saturates at it and the others share the rest with the same ratios:
  ``F_j = min(U_j, c e_j)``, ``e_j = (|r_j| N_j^P)^(1/(P-1))``, with the one
  ``c`` for which ``sum_j |r_j| F_j = |T|`` (piecewise linear in ``c``, solved
  exactly from the sorted breakpoints ``U_j / e_j``).  This is the
  generalisation Sec. 3.5.3 says grows to 2^n branches if enumerated.
* ``P = 1`` (an LP): agonists are recruited in decreasing order of
  ``|r_i| N_i`` (moment per unit cost), each up to ``U_i`` (Fig. 2.6);
* min/max (Eq. 2.13): ``F_j = min(U_j, t N_j)`` with the smallest ``t`` that
  balances, i.e. the same water filling with ``e_j = N_j`` (the P -> infinity
  limit of ``e_j``).

Activation mode maps onto the same form: with ``F = a F_active + F_passive``
and cost ``sum S_i a_i^P``, use ``r_i F_active,i`` as the moment arm,
``T - sum r_i F_passive,i`` as the moment, ``N_i = S_i^(-1/P)`` and ``U_i = 1``
(:func:`one_dof_activations`).

:func:`gaussian_elbow_motion` generates the reference motion of Fig. 3.13.
"""
from __future__ import annotations

import numpy as np

from ..components import Motion
from ..errors import InfeasibleError, SolverError
from ..trial import Trial

# ---------------------------------------------------------------------------
# the thesis's formulas, as printed
# ---------------------------------------------------------------------------

def eq_2_22(r, T, *, exponent: float, n=None) -> np.ndarray:
    """Unbounded optimum of Eq. 2.15 (Eq. 2.22; Eq. 2.24 / 3.40 when ``n`` is None).

    ``F_j = (r_j N_j^P)^(1/(P-1)) / sum_i (r_i N_i)^(P/(P-1)) T`` for muscles
    that all act in the direction of ``T`` (``r`` > 0 for ``T`` > 0); the
    moment arms are taken by magnitude and the muscles must all be agonists.
    """
    r = np.asarray(r, dtype=float)
    P = float(exponent)
    if P <= 1:
        raise SolverError("Eq. 2.22 needs P > 1")
    N = np.ones_like(r) if n is None else np.asarray(n, dtype=float)
    a = np.abs(r)
    num = (a * N ** P) ** (1.0 / (P - 1.0))
    den = np.sum((a * N) ** (P / (P - 1.0)))
    return num / den * abs(float(T))


def two_muscles_p2(r1: float, r2: float, T: float) -> tuple[float, float]:
    """Two muscles, P = 2, N = 1, ``F >= 0``: the KKT branches of Eq. 3.29-3.34."""
    return _two_muscles(r1, r2, T, 2.0)


def two_muscles_p3(r1: float, r2: float, T: float) -> tuple[float, float]:
    """Two muscles, P = 3, N = 1, ``F >= 0``: the KKT branches of Eq. 3.35-3.39."""
    return _two_muscles(r1, r2, T, 3.0)


def _two_muscles(r1, r2, T, P):
    if T == 0:                      # branch four: the trivial solution
        return 0.0, 0.0
    ag1, ag2 = r1 * T > 0, r2 * T > 0
    if ag1 and ag2:                 # branch one: both act (Eq. 3.31 / 3.37)
        if P == 2.0:
            d = r1 * r1 + r2 * r2
            return T * r1 / d, T * r2 / d
        a1, a2 = abs(r1), abs(r2)
        d = a1 ** 1.5 + a2 ** 1.5
        return a1 ** 0.5 * abs(T) / d, a2 ** 0.5 * abs(T) / d
    if ag1:                         # muscle 2 is an antagonist (Eq. 3.33 / 3.39)
        return T / r1, 0.0
    if ag2:                         # muscle 1 is an antagonist (Eq. 3.34 / 3.38)
        return 0.0, T / r2
    raise InfeasibleError(f"no muscle can produce T = {T:g} (moment arms {r1:g}, {r2:g})")


# ---------------------------------------------------------------------------
# the general one-dof solution with bounds
# ---------------------------------------------------------------------------

def _water_fill(a, e, U, target):
    """``F_j = min(U_j, c e_j)`` with ``sum a_j F_j = target`` (a, e > 0; U may be inf)."""
    if target <= 0:
        return np.zeros_like(a)
    with np.errstate(divide="ignore"):
        brk = np.where(e > 0, U / e, np.inf)
    order = np.argsort(brk)
    slope0 = float(np.sum(a * e))
    slope = slope0                        # d(moment)/dc while nothing more saturates
    base = 0.0                            # moment of the saturated muscles
    c_prev = 0.0
    n_sat = 0
    for j in order:
        c_j = brk[j]
        if not np.isfinite(c_j):
            break
        if base + slope * c_j >= target:  # the solution lies before this breakpoint
            break
        base += a[j] * U[j]
        slope -= a[j] * e[j]
        c_prev = c_j
        n_sat += 1
    if n_sat == a.size or slope <= 1e-12 * slope0:
        if abs(base - target) <= 1e-12 * max(1.0, abs(target)):
            c = c_prev
        else:
            raise InfeasibleError(f"the muscles cannot produce the moment {target:g} "
                                  f"(capacity {np.sum(a * U):g})")
    else:
        c = (target - base) / slope
    return np.minimum(U, c * e)


def one_dof_forces(r, T, *, exponent: float = 2.0, n=None, upper=None, minmax: bool = False) -> np.ndarray:
    """Optimal forces of the 1-dof problem with ``0 <= F <= upper`` (module notes).

    ``r`` (m,) or (N, m) moment arms; ``T`` scalar or (N,) net muscle moments;
    ``n`` the ``N_i`` (default 1); ``upper`` the bounds (default none).
    Returns (m,) or (N, m).  Raises InfeasibleError when ``|T|`` exceeds the
    agonists' capacity.
    """
    r = np.asarray(r, dtype=float)
    T = np.asarray(T, dtype=float)
    single = r.ndim == 1 and T.ndim == 0
    R = np.atleast_2d(r)
    Ts = np.atleast_1d(T)
    nfr = max(R.shape[0], Ts.shape[0])
    R = np.broadcast_to(R, (nfr, R.shape[1]))
    Ts = np.broadcast_to(Ts, (nfr,))
    m = R.shape[1]
    N = np.ones(m) if n is None else np.broadcast_to(np.asarray(n, dtype=float), (m,))
    U = np.full(m, np.inf) if upper is None else np.asarray(upper, dtype=float)
    U = np.broadcast_to(U, (nfr, m))
    P = float(exponent)
    out = np.zeros((nfr, m))
    for k in range(nfr):
        t = Ts[k]
        if t == 0:
            continue
        ag = R[k] * t > 0
        if not ag.any():
            raise InfeasibleError(f"frame {k}: no muscle acts in the direction of T = {t:g}")
        a = np.abs(R[k, ag])
        Uk = U[k, ag]
        Nk = N[ag]
        if minmax:
            e = Nk
        elif P == 1.0:
            # LP: recruit by moment per unit cost |r| N, best first (Fig. 2.6)
            F = np.zeros(a.size)
            need = abs(t)
            for j in np.argsort(-(a * Nk), kind="stable"):
                f = min(Uk[j], need / a[j])
                F[j] = f
                need -= a[j] * f
                if need <= 1e-15 * abs(t):
                    break
            if need > 1e-12 * abs(t):
                raise InfeasibleError(f"frame {k}: the muscles cannot produce T = {t:g} "
                                      f"(capacity {np.sum(a * Uk):g})")
            out[k, ag] = F
            continue
        else:
            if P <= 1.0:
                raise SolverError("exponent must be 1 or > 1")
            # e = (a N^P)^(1/(P-1)), in logs and normalised (only ratios matter; P = 200 overflows)
            le = (np.log(a) + P * np.log(Nk)) / (P - 1.0)
            e = np.exp(le - np.max(le))
        out[k, ag] = _water_fill(a, e, Uk, abs(t))
    return out[0] if single else out


def one_dof_activations(r, T, f_active, f_passive=0.0, *, exponent: float = 2.0, s=None,
                        minmax: bool = False) -> np.ndarray:
    """Optimal activations of the 1-dof activation-mode problem (``sum S a^P``, ``0 <= a <= 1``).

    ``F = a f_active + f_passive``; returns ``a`` (N, m) (or (m,)).
    """
    r = np.atleast_2d(np.asarray(r, dtype=float))
    fa = np.atleast_2d(np.asarray(f_active, dtype=float))
    fp = np.broadcast_to(np.asarray(f_passive, dtype=float), fa.shape)
    T = np.atleast_1d(np.asarray(T, dtype=float))
    m = fa.shape[1]
    S = np.ones(m) if s is None else np.broadcast_to(np.asarray(s, dtype=float), (m,))
    P = float(exponent)
    reff = r * fa
    Teff = T - np.sum(r * fp, axis=1)
    if minmax:
        n = 1.0 / S                     # max S a = max a / (1/S)
    else:
        n = S ** (-1.0 / P)             # S a^P = (a / S^(-1/P))^P
    return one_dof_forces(reff, Teff, exponent=P, n=n, upper=np.ones(m), minmax=minmax)


# ---------------------------------------------------------------------------
# the reference motion of Fig. 3.13
# ---------------------------------------------------------------------------

def gaussian_elbow_motion(*, n_frames: int = 201, duration: float = 2.0, peak_deg: float = 120.0,
                          sigma: float = 0.25, times=None) -> Motion:
    """The Gaussian 0 -> peak -> 0 elbow flexion of thesis Fig. 3.13, with exact derivatives.

    ``q(t) = peak exp(-(t - T/2)^2 / (2 sigma^2))`` over ``[0, T]``; with the
    default ``sigma = 0.25 s`` and ``T = 2 s`` the motion starts and ends at
    ``120 deg * exp(-8) = 0.04 deg`` (the thesis does not give sigma; this
    choice makes the curve start and end at rest as in the figure).  Returns a
    :class:`Motion` with ``q, v, a`` (N, 1) in rad, rad/s, rad/s^2, at ``n_frames``
    uniform samples or at the given ``times``.
    """
    t = np.linspace(0.0, duration, int(n_frames)) if times is None else np.asarray(times, dtype=float)
    A = np.deg2rad(peak_deg)
    c = duration / 2.0
    g = np.exp(-(t - c) ** 2 / (2 * sigma ** 2))
    q = A * g
    v = -A * (t - c) / sigma ** 2 * g
    a = A * ((t - c) ** 2 / sigma ** 4 - 1.0 / sigma ** 2) * g
    return Motion(t, q[:, None], v[:, None], a[:, None])


def gaussian_elbow_trial(*, coordinate: str = "elbow_flexion", **kw) -> Trial:
    """:func:`gaussian_elbow_motion` as a Trial with channels ``<coordinate>`` and ``<coordinate>_speed``."""
    mo = gaussian_elbow_motion(**kw)
    return Trial(mo.t, {coordinate: mo.q[:, 0], f"{coordinate}_speed": mo.v[:, 0]},
                 meta={"source": "gaussian_elbow_motion (thesis Fig. 3.13)"})
