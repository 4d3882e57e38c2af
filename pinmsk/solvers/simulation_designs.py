"""Simulation designs of the dynamic optimization (thesis Sec. 5.1), batched over parameter sets.

``simulate_ff`` (fully forward): excitation -> activation dynamics (Eq. A.2) ->
Thelen 2003 muscle (rigid tendon, or compliant tendon with the contraction
dynamics of Eq. 3.9 / A.6-A.9) -> skeleton (Pinocchio ABA).  Rigid: classical
RK4.  Compliant: the fiber-tendon equation is stiff (see :func:`simulate_ff`),
so it is integrated implicitly inside an IMEX Runge-Kutta scheme.
``simulate_skeleton`` (IFM/IFT): the skeleton alone under muscle forces or
joint torques.  ``muscle_inverse``: the inverse muscle model (Fig. 5.6,
Eq. 5.2-5.4) that recovers activations and excitations from the forces and
their exact time derivatives.

Every function takes and returns time-first arrays ``(N, B, ...)`` where ``B``
is a batch of parameter sets (all perturbations of a finite-difference
gradient are one batch).
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..effects.activation import excitation_path
from ..errors import ModelError
from ..muscles.tendon import thelen_tendon_force
from ..muscles.thelen2003 import (GAMMA, K_PE, PASSIVE_STRAIN0, thelen_contraction_rate,
                                  thelen_passive_force_length)

__all__ = ["BatchSkeleton", "BatchMuscles", "simulate_ff", "simulate_skeleton", "muscle_inverse",
           "A_MIN", "U_MARGIN"]

A_MIN = 0.01   # activation floor of the compliant contraction dynamics
U_MARGIN = 0.2  # FF simulations clip excitations to [-0.2, 1.2]: smooth near the bounds


# =============================================================================== skeleton
class BatchSkeleton:
    """Forward dynamics ``a = ABA(q, v, tau)`` over a batch ``(B, nv)`` of states."""

    def __init__(self, model):
        self.pm = model.pin if hasattr(model, "pin") else model
        self.nv = self.pm.nv
        self.data = self.pm.createData()
        self.closed_form = False
        pm, pd = self.pm, self.data
        if self.nv == 1 and pm.njoints == 2 and pm.nq == 1:
            qa = np.array([0.0])
            qb = np.array([np.pi / 2])
            M = float(pin.crba(pm, pd, qa)[0, 0])
            c1 = float(pin.computeGeneralizedGravity(pm, pd, qa)[0])
            c2 = float(pin.computeGeneralizedGravity(pm, pd, qb)[0])
            ok = True
            for qq, vv, tt in ((0.7, 3.0, 0.2), (-1.9, -5.0, -1.0), (2.6, 0.5, 0.0)):
                ref = pin.aba(pm, pd, np.array([qq]), np.array([vv]), np.array([tt]))[0]
                mine = (tt - c1 * np.cos(qq) - c2 * np.sin(qq)) / M
                ok &= abs(ref - mine) <= 1e-9 * (1.0 + abs(ref))
            if ok:
                self.closed_form = True
                self.M, self.c1, self.c2 = M, c1, c2

    def accel(self, q, v, tau):
        if self.closed_form:
            return (tau - self.c1 * np.cos(q) - self.c2 * np.sin(q)) / self.M
        out = np.empty_like(tau)
        for b in range(q.shape[0]):
            out[b] = pin.aba(self.pm, self.data, q[b], v[b], tau[b])
        return out


# =============================================================================== muscles
from ..muscles.tendon import _thelen_constants as _tendon_consts
from ..muscles.thelen2003 import _C as _FV_C
from ..muscles.thelen2003 import _K_CON, _K_ECC, _W_THR
from ..muscles.thelen2003 import A_F as _A_F
from ..muscles.thelen2003 import F_HAT as _F_HAT
from ..muscles.thelen2003 import FV_EXTRAPOLATION as _FV_EXTRA

_FV_ECC = _FV_C * (_F_HAT - 1.0)
_mx, _mn = np.maximum, np.minimum


def _fv(w):
    """:func:`thelen_force_velocity` with bare ufuncs (same four pieces, tested equal)."""
    w1 = _mn(_mx(w, -1.0), 0.0)
    w2 = _mn(_mx(w, 0.0), _W_THR)
    return ((1.0 + w1) / (1.0 - w1 / _A_F) + _FV_ECC * w2 / (1.0 + _FV_C * w2)
            + _K_CON * _mn(w + 1.0, 0.0) + _K_ECC * _mx(w - _W_THR, 0.0))


_P_THR = _FV_EXTRA * _F_HAT
_TOE = _tendon_consts(0.04)


def _fv_inv(p):
    """``(w, dw/dp)``: :func:`thelen_force_velocity_inverse` and its slope, with bare ufuncs."""
    p1 = _mn(_mx(p, 0.0), 1.0)
    p2 = _mn(_mx(p, 1.0), _P_THR)
    e1 = 1.0 / (1.0 + p1 / _A_F)
    e2 = 1.0 / (_F_HAT - p2)
    w = ((p1 - 1.0) * e1 + ((p2 - 1.0) / _FV_C) * e2
         + _mn(p, 0.0) / _K_CON + _mx(p - _P_THR, 0.0) / _K_ECC)
    # Each slope formula at its clipped argument already equals the slope of the adjoining
    # linear tail (the tails are C1), so one select gives all four pieces; at p = 1 the left
    # (concentric) slope, as the force-velocity derivative.
    dw = np.where(p <= 1.0, (1.0 + 1.0 / _A_F) * e1 * e1, ((_F_HAT - 1.0) / _FV_C) * e2 * e2)
    return w, dw


def _tendon_f(eps, strain0):
    """``(f_t, df_t/d eps)`` of Eq. A.6 (:func:`thelen_tendon_force` and stiffness) in one pass."""
    eps_toe, k_lin, scale, rate = _TOE if strain0 == 0.04 else _tendon_consts(strain0)
    ex = np.exp(rate * _mn(_mx(eps, 0.0), eps_toe))
    f = scale * (ex - 1.0) + k_lin * _mx(eps - eps_toe, 0.0)
    k = np.where(eps > eps_toe, k_lin, (eps >= 0.0) * (rate * scale) * ex)
    return f, k


class BatchMuscles:
    """Thelen 2003 muscle layer bound to a model's MuscleSet, batched over ``(B, m)``."""

    def __init__(self, model):
        ms = model.muscles
        if ms is None:
            raise ModelError(f"model '{model.name}' has no muscles; dynamic optimization of "
                             "muscle controls needs a model with [[muscles]]")
        if ms.model_type != "thelen2003":
            raise ModelError(f"dynamic optimization supports Thelen 2003 muscles only; model "
                             f"'{model.name}' uses {ms.model_type}")
        self.ms = ms
        self.path = ms.path
        mtu = ms.mtu
        self.mtu = mtu
        self.f_max = np.asarray(mtu.f_max, dtype=float)
        self.l_opt = np.asarray(mtu.l_opt, dtype=float)
        self.l_slack = np.asarray(mtu.l_slack, dtype=float)
        self.pennation = np.asarray(mtu.pennation, dtype=float)
        self.h2 = np.asarray(mtu.height, dtype=float) ** 2
        self.v_max = np.asarray(mtu.v_max, dtype=float)
        self.strain0 = float(mtu.tendon_strain0)
        # the model's activation component (its muscle model's constants without one), per muscle
        path = excitation_path(model)
        self.tau_rise = path.tau_rise
        self.tau_fall = path.tau_fall
        self.m = ms.n
        self.no_pennation = bool(np.all(self.h2 == 0))
        self._x_min = 1e-6 * self.l_opt
        self._inv_lopt = 1.0 / self.l_opt
        self._kpe = K_PE / PASSIVE_STRAIN0
        self._pe_scale = 1.0 / np.expm1(K_PE)
        t2 = 1.0 / self.tau_fall
        self._t1, self._t2 = 1.0 / self.tau_rise - t2, t2
        self.constant_arms = self.path.degree == 0
        if self.constant_arms:
            self.R = np.asarray(self.path.moment_arms(np.zeros(model.nv)), dtype=float)  # (m, nv)
            self.l0 = np.asarray(self.path.lengths(np.zeros(model.nv)), dtype=float)

    # -- paths, batched -------------------------------------------------------
    def lengths(self, q):
        if self.constant_arms:
            return self.l0 - q @ self.R.T
        return self.path.lengths(q)

    def velocities(self, q, v):
        if self.constant_arms:
            return -(v @ self.R.T)
        return self.path.velocities(q, v)

    def moments(self, q, F):
        if self.constant_arms:
            return F @ self.R
        return np.einsum("bm,bmj->bj", F, self.path.moment_arms(q))

    # -- rigid tendon ---------------------------------------------------------
    def rigid(self, a, l_mt, v_mt):
        """``(F, l_ce, v_ce, f_ce, f_isom)``; F, f_ce in N (Eq. A.7-A.9, inextensible tendon).

        Written with bare ufuncs (it runs 4 times per RK4 step); equal to
        ``Thelen2003.force`` with ``tendon="rigid"`` (tested)."""
        x = np.maximum(l_mt - self.l_slack, self._x_min)
        if self.no_pennation:
            l_ce, cos, v_ce = x, 1.0, v_mt
        else:
            l_ce = np.sqrt(x * x + self.h2)
            cos = x / l_ce
            v_ce = v_mt * cos
        d = l_ce * self._inv_lopt - 1.0
        fl = np.exp(d * d * (-1.0 / GAMMA))
        fv = _fv(v_ce / ((0.25 + 0.75 * a) * self.v_max))
        f_act = a * fl * fv
        f_pe = np.expm1(self._kpe * np.maximum(d, 0.0)) * self._pe_scale
        F = self.f_max * (f_act + f_pe) * cos
        return F, l_ce, v_ce, self.f_max * f_act, fl

    # -- compliant tendon -----------------------------------------------------
    def compliant(self, a, l_mt, l_ce):
        """``(F, v_ce, f_ce, f_isom)`` from the fiber-length state (Eq. 3.9)."""
        a = np.maximum(a, A_MIN)
        l_ce = np.maximum(l_ce, self._fiber_bounds())
        x = np.sqrt(np.maximum(l_ce * l_ce - self.h2, 0.0))
        F = self.f_max * thelen_tendon_force((l_mt - x) / self.l_slack - 1.0, strain0=self.strain0)
        v_ce = thelen_contraction_rate(l_ce, np.maximum(l_mt, x + 1e-9), a, l_opt=self.l_opt,
                                       l_slack=self.l_slack, pennation=self.pennation,
                                       v_max=self.v_max, tendon_strain0=self.strain0)
        d = l_ce / self.l_opt - 1.0
        fl = np.exp(d * d * (-1.0 / GAMMA))
        f_ce = F * l_ce / x - self.f_max * thelen_passive_force_length(l_ce / self.l_opt)
        return F, v_ce, np.maximum(f_ce, 0.0), fl

    def _fiber_bounds(self):
        return 1.0001 * np.sqrt(self.h2) + 1e-6 * self.l_opt

    def tendon_force(self, l_mt, l_ce):
        """Tendon force (N), Eq. A.6 at ``l_t = l_mt - l_ce cos(alpha)``: ``compliant()[0]``."""
        l_ce = np.maximum(l_ce, self._fiber_bounds())
        x = np.sqrt(np.maximum(l_ce * l_ce - self.h2, 0.0))
        return self.f_max * _tendon_f((l_mt - x) / self.l_slack - 1.0, self.strain0)[0]

    def fiber_rate(self, a, l_mt, l_ce):
        """``(v_ce, d v_ce / d l_ce)`` of the contraction dynamics (Eq. 3.9) with bare ufuncs.

        ``v_ce`` equals ``compliant()[1]`` (tested); the partial derivative at
        fixed ``l_mt`` and ``a`` is the Newton slope of the implicit fiber
        stages in :func:`simulate_ff` -- analytic, so one evaluation per
        iteration, and exact so that the iteration converges quadratically.
        """
        a = np.maximum(a, A_MIN)
        l = np.maximum(l_ce, self._fiber_bounds())
        if self.no_pennation:
            x, sec, dsec = l, 1.0, 0.0
        else:
            x = np.sqrt(np.maximum(l * l - self.h2, 0.0))
            sec = l / x                                # 1/cos(alpha)
            dsec = -self.h2 / (x * x * x)              # d sec / d l_ce
        ft, kt = _tendon_f((np.maximum(l_mt, x + 1e-9) - x) / self.l_slack - 1.0, self.strain0)
        dft = -kt * sec / self.l_slack                 # dx/dl = sec
        d = l * self._inv_lopt - 1.0
        fl = np.exp(d * d * (-1.0 / GAMMA))
        dfl = (-2.0 / GAMMA) * d * fl * self._inv_lopt
        e = np.exp(self._kpe * np.maximum(d, 0.0))
        fpe = (e - 1.0) * self._pe_scale
        dfpe = (self._kpe * self._pe_scale * self._inv_lopt) * e * (d >= 0.0)
        f_ce = ft * sec - fpe                           # active fiber force / F_max (Eq. A.9 input)
        df_ce = dft * sec + ft * dsec - dfpe
        afl = a * fl
        p = f_ce / afl
        dp = (df_ce - p * a * dfl) / afl
        g, dg = _fv_inv(p)
        sv = (0.25 + 0.75 * a) * self.v_max
        return sv * g, sv * dg * dp


# =============================================================================== integration
def _rk4(deriv, x0, t, inputs, inputs_mid):
    """Fixed-step RK4 of ``x' = deriv(x, w)`` with inputs given at grid points and midpoints.

    ``x0`` (B, nx); ``inputs`` (N, B, ...) and ``inputs_mid`` (N-1, B, ...).  Returns (N, B, nx).
    """
    n = t.size
    X = np.empty((n,) + x0.shape)
    X[0] = x = x0
    for i in range(n - 1):
        h = t[i + 1] - t[i]
        k1 = deriv(x, inputs[i])
        k2 = deriv(x + 0.5 * h * k1, inputs_mid[i])
        k3 = deriv(x + 0.5 * h * k2, inputs_mid[i])
        k4 = deriv(x + h * k3, inputs[i + 1])
        x = x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
        X[i + 1] = x
    return X


# ARS(4,4,3) of Ascher, Ruuth & Spiteri (1997): an IMEX pair, 3rd order, whose implicit half is
# an L-stable, stiffly accurate SDIRK (gamma = 1/2) and whose explicit half shares the stage
# times.  Stage 0 is x_n itself (first same as last), so a step costs 4 explicit evaluations
# and 4 scalar implicit solves.
_ARS_AE = ((), (1 / 2,), (11 / 18, 1 / 18), (5 / 6, -5 / 6, 1 / 2), (1 / 4, 7 / 4, 3 / 4, -7 / 4))
_ARS_AI = ((), (0.0, 1 / 2), (0.0, 1 / 6, 1 / 2), (0.0, -1 / 2, 1 / 2, 1 / 2),
           (0.0, 3 / 2, -3 / 2, 1 / 2, 1 / 2))
_ARS_GAMMA = 0.5
# The stage times are 0, 1/2, 2/3, 1/2, 1 (of the step): inputs exist at 0, 1/2 and 1 only, so
# t + 2h/3 takes the quadratic through the three, exact to O(h^3) like the scheme itself.
_ARS_W = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (-1 / 9, 8 / 9, 2 / 9), (0.0, 1.0, 0.0),
          (0.0, 0.0, 1.0))
NEWTON_ITERS = 4   # fixed: the trajectory must stay a smooth function of the inputs


def _imex_ars443(f_exp, fiber, y0, l0, t, inputs, inputs_mid, *, dl_max, n_newton=None):
    """IMEX ARS(4,4,3) of ``y' = f_exp(y, l, w)`` (explicit) and ``l' = f(l; y)`` (implicit).

    ``fiber(y)`` returns ``l -> (f, df/dl)`` at the stage's ``y`` (paths evaluated once),
    elementwise in ``l`` (B, m): each implicit stage
    ``l = L + h/2 f(l; y_i)`` is a scalar equation per (batch, muscle), solved by a fixed
    number of Newton steps warm-started from an explicit predictor.  Steps are capped
    smoothly at ``dl_max`` (inactive near the root).  Returns ``(Y, L)`` (N, B, .).
    """
    n_newton = NEWTON_ITERS if n_newton is None else n_newton
    n = t.size
    Y = np.empty((n,) + y0.shape)
    Lc = np.empty((n,) + l0.shape)
    Y[0], Lc[0] = y, l = y0, l0
    kI_prev = fiber(y)(l)[0]
    kE_next = f_exp(y, l, inputs[0])
    kE = [None] * 4
    for i in range(n - 1):
        h = t[i + 1] - t[i]
        hg = h * _ARS_GAMMA
        w3 = (inputs[i], inputs_mid[i], inputs[i + 1])
        kE[0] = kE_next                     # first same as last: f_exp at x_n
        kI = [None] * 5
        for s in range(1, 5):
            ys = y + h * sum(c * kE[j] for j, c in enumerate(_ARS_AE[s]))
            base = l + h * sum(c * kI[j] for j, c in enumerate(_ARS_AI[s][:-1]) if j > 0)
            ls = base + hg * kI_prev
            rate = fiber(ys)
            for _ in range(n_newton):
                f, df = rate(ls)
                step = (base + hg * f - ls) / np.maximum(1.0 - hg * df, 0.5)
                ls = ls + step / np.sqrt(1.0 + (step / dl_max) ** 2)
            kI[s] = kI_prev = (ls - base) / hg
            ws = sum(c * w for c, w in zip(_ARS_W[s], w3) if c)
            if s < 4:
                kE[s] = f_exp(ys, ls, ws)
            else:
                kE_next = f_exp(ys, ls, ws)
        y, l = ys, ls
        Y[i + 1], Lc[i + 1] = y, l
    return Y, Lc


def simulate_ff(model, t, u, u_mid, q0, v0, *, a0=None, l_ce0=None, tendon: str = "rigid",
                skeleton: BatchSkeleton | None = None, muscles: BatchMuscles | None = None) -> dict:
    """Fully forward simulation (Sec. 5.1 design 1) of excitations on the grid ``t``.

    ``u`` (N, B, m) at the grid points and ``u_mid`` (N-1, B, m) at the interval
    midpoints (B parameter sets at once; (N, m) for one).  ``q0, v0`` (nv,) or
    (B, nv); ``a0`` defaults to the clipped ``u[0]`` (steady state); with
    ``tendon="compliant"`` the fibers start in isometric equilibrium unless
    ``l_ce0`` is given.  Returns time-first arrays (N, B, ...): ``q, v, acc, a,
    u, force, l_ce, v_ce, f_ce, f_isom``.  Non-finite values mean the run diverged.

    Rigid tendon: classical RK4 of ``(q, v, a)``, 4th order.

    Compliant tendon: the contraction dynamics (Eq. 3.9; tendon Eq. A.6, fiber
    Eq. A.7-A.9) are stiff -- the force-velocity damping of the fiber scales
    with activation and sits in series with a stiff tendon, so their time
    constant falls to ~0.1 ms (forearm) at a = 0.01, far below the optimizer's
    steps (0.83 ms finger, 9.5 ms forearm), where RK4 diverges.  They are
    integrated with the IMEX Runge-Kutta pair ARS(4,4,3) (Ascher, Ruuth &
    Spiteri 1997; 3rd order, implicit half L-stable and stiffly accurate):
    ``(q, v, a)`` -- skeleton (ABA) and activation dynamics (Eq. A.2) -- are
    explicit, the tendon lengths ``l_t = l_mt - l_ce cos(alpha)`` implicit,
    ``l_t' = v_mt - v_ce(l_t; q, v, a) / cos(alpha)``.  The tendon length (not
    the fiber length) is the implicit unknown because the tendon force is
    then a function of it alone: the explicit stages see the fiber's damping,
    as with a rigid tendon, instead of a tendon spring stretched by ``q`` at
    frozen ``l_ce`` (stiff again).  Each implicit stage is a scalar equation
    per (batch, muscle), solved by ``NEWTON_ITERS`` Newton steps with the
    analytic slope, warm-started; the iteration count is fixed and the step
    limiter smooth, so the trajectory is a smooth function of the inputs
    (finite-difference gradients).  The input at the stage time t + 2h/3 is
    the quadratic through ``u``, ``u_mid`` and the next ``u``.  Measured
    against Radau (rtol 1e-9) at 200 steps per period with activations down
    to 0: q within 1.8e-4 rad (finger) and 9e-5 to 1.2e-3 rad (forearm);
    error ratio ~7.4 per halving of h (tests/test_designs.py).  Cost ~7x a
    rigid run (implicit Newton iterations).
    """
    if tendon not in ("rigid", "compliant"):
        raise ModelError(f"tendon must be 'rigid' or 'compliant', not {tendon!r}")
    sk = skeleton or BatchSkeleton(model)
    mu = muscles or BatchMuscles(model)
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    single = u.ndim == 2
    if single:
        u = u[:, None, :]
        u_mid = np.asarray(u_mid, dtype=float)[:, None, :]
    n, B, m = u.shape
    nv = sk.nv
    uc = np.clip(u, -U_MARGIN, 1.0 + U_MARGIN)
    ucm = np.clip(u_mid, -U_MARGIN, 1.0 + U_MARGIN)
    q0 = np.broadcast_to(np.asarray(q0, dtype=float), (B, nv))
    v0 = np.broadcast_to(np.asarray(v0, dtype=float), (B, nv))
    a0 = np.clip(uc[0], 0.0, 1.0) if a0 is None else np.broadcast_to(np.asarray(a0, dtype=float), (B, m))
    t1, t2 = mu._t1, mu._t2
    compliant = tendon == "compliant"
    parts = [q0, v0, a0]
    if compliant:
        if l_ce0 is None:
            l_mt0 = mu.lengths(q0)
            l_ce0 = mu.mtu.equilibrium(l_mt0, np.maximum(a0, A_MIN))["l_ce"]
        parts.append(np.broadcast_to(np.asarray(l_ce0, dtype=float), (B, m)))
    x0 = np.concatenate(parts, axis=1)
    iq, iv, ia, il = slice(0, nv), slice(nv, 2 * nv), slice(2 * nv, 2 * nv + m), \
        slice(2 * nv + m, 2 * nv + 2 * m)

    def deriv(x, w):
        q, v, a = x[:, iq], x[:, iv], x[:, ia]
        l_mt = mu.lengths(q)
        out = np.empty_like(x)
        out[:, iq] = v
        d = w - a
        out[:, ia] = d * (t2 + t1 * w * (d >= 0))        # Eq. A.2
        F = mu.rigid(a, l_mt, mu.velocities(q, v))[0]
        out[:, iv] = sk.accel(q, v, mu.moments(q, F))
        return out

    # The implicit unknown is the tendon length l_t = l_mt - l_ce cos(alpha), not l_ce: the
    # tendon force is then a function of the implicit state alone, so the explicit (q, v)
    # stages see the fiber's force-velocity damping (as with a rigid tendon) rather than a
    # stiff tendon spring stretched by q at frozen l_ce -- which the explicit half could not
    # integrate at the optimizer's steps.
    l_floor = mu._fiber_bounds()
    x_floor = np.sqrt(np.maximum(l_floor * l_floor - mu.h2, 0.0)) + 1e-9

    def deriv_exp(y, l_t, w):
        q, v, a = y[:, iq], y[:, iv], y[:, ia]
        out = np.empty_like(y)
        out[:, iq] = v
        d = w - a
        out[:, ia] = d * (t2 + t1 * w * (d >= 0))        # Eq. A.2
        F = mu.f_max * _tendon_f(l_t / mu.l_slack - 1.0, mu.strain0)[0]   # Eq. A.6
        out[:, iv] = sk.accel(q, v, mu.moments(q, F))
        return out

    def fiber(y):
        # l_t' = v_mt - v_ce / cos(alpha) (Eq. 3.9 through x = l_ce cos(alpha) = l_mt - l_t)
        q, a = y[:, iq], y[:, ia]
        l_mt = mu.lengths(q)
        v_mt = mu.velocities(q, y[:, iv])

        def rate(l_t):
            x = np.maximum(l_mt - l_t, x_floor)
            if mu.no_pennation:
                v_ce, dv = mu.fiber_rate(a, l_mt, x)
                return v_mt - v_ce, dv
            l_ce = np.sqrt(x * x + mu.h2)
            v_ce, dv = mu.fiber_rate(a, l_mt, l_ce)
            # d(v_ce sec)/d l_t = -(dv sec + v_ce dsec/dl) dl/dx; dl/dx = 1/sec, dsec/dl = -h^2/x^3
            return v_mt - v_ce * l_ce / x, dv - v_ce * mu.h2 / (x * x * l_ce)
        return rate

    if compliant:
        l_ce0 = x0[:, il]
        lt0 = mu.lengths(q0) - np.sqrt(np.maximum(l_ce0 * l_ce0 - mu.h2, 0.0))
        with np.errstate(all="ignore"):   # a diverging run ends non-finite; the caller checks
            Y, Lt = _imex_ars443(deriv_exp, fiber, x0[:, :il.start], lt0, t, uc, ucm,
                                 dl_max=0.1 * mu.l_slack)
        x = mu.lengths(Y[..., iq].reshape(n * B, nv)).reshape(n, B, m) - Lt
        X = np.concatenate([Y, np.sqrt(x * x + mu.h2)], axis=2)
    else:
        X = _rk4(deriv, x0, t, uc, ucm)
    flat = X.reshape(n * B, -1)
    q, v, a = flat[:, iq], flat[:, iv], flat[:, ia]
    l_mt = mu.lengths(q)
    if compliant:
        l_ce = flat[:, il]
        F, v_ce, f_ce, fl = mu.compliant(a, l_mt, l_ce)
    else:
        F, l_ce, v_ce, f_ce, fl = mu.rigid(a, l_mt, mu.velocities(q, v))
    acc = sk.accel(q, v, mu.moments(q, F))
    out = {"q": q, "v": v, "acc": acc, "a": a, "u": uc.reshape(n * B, m), "force": F,
           "l_ce": l_ce, "v_ce": v_ce, "f_ce": f_ce, "f_isom": fl}
    shp = (n, B) if not single else (n,)
    return {k: val.reshape(shp + val.shape[1:]) for k, val in out.items()}


def simulate_skeleton(model, t, tau, tau_mid, q0, v0, *, skeleton=None, muscles=None,
                      forces=None, forces_mid=None):
    """Integrate the skeleton alone under joint torques ``tau`` (N, B, nv) -- or muscle forces.

    With ``forces`` (N, B, m) / ``forces_mid`` the torque is ``R(q)^T F`` (IFM).
    Returns ``(q, v, acc)`` each (N, B, nv).
    """
    sk = skeleton or BatchSkeleton(model)
    nv = sk.nv
    t = np.asarray(t, dtype=float)
    if forces is not None:
        mu = muscles or BatchMuscles(model)
        w, wm = np.asarray(forces, dtype=float), np.asarray(forces_mid, dtype=float)

        def torque(q, f):
            return mu.moments(q, f)
    else:
        w, wm = np.asarray(tau, dtype=float), np.asarray(tau_mid, dtype=float)

        def torque(q, f):
            return f
    B = w.shape[1]
    x0 = np.concatenate([np.broadcast_to(np.asarray(q0, dtype=float), (B, nv)),
                         np.broadcast_to(np.asarray(v0, dtype=float), (B, nv))], axis=1)

    def deriv(x, f):
        q, v = x[:, :nv], x[:, nv:]
        return np.concatenate([v, sk.accel(q, v, torque(q, f))], axis=1)

    X = _rk4(deriv, x0, t, w, wm)
    n = t.size
    flat = X.reshape(n * B, 2 * nv)
    q, v = flat[:, :nv], flat[:, nv:]
    acc = sk.accel(q, v, torque(q, w.reshape(n * B, -1)))
    return (q.reshape(n, B, nv), v.reshape(n, B, nv), acc.reshape(n, B, nv))


def muscle_inverse(model, q, v, acc, F, dF, ddF, *, muscles=None, fv_smooth: float = 0.0,
                   fiber_floor=None) -> dict:
    """Inverse muscle model (Fig. 5.6, Eq. 5.2-5.4) over frames: ``a, adot, u, l_ce, v_ce``.

    ``q, v, acc`` (N, nv) kinematics; ``F, dF, ddF`` (N, m) muscle-tendon force and its
    exact time derivatives.  Compliant Thelen tendon.  ``fv_smooth`` and ``fiber_floor``:
    see :func:`~pinmsk.muscles.inverse.inverse_thelen2003`.
    """
    mu = muscles or BatchMuscles(model)
    l_mt = mu.lengths(q)
    dl = mu.velocities(q, v)
    ddl = mu.path.accelerations(q, v, acc)
    return mu.mtu.inverse(F, dF, l_mt, dl, ddl, ddF, fv_smooth=fv_smooth, fiber_floor=fiber_floor)
