"""Simulation designs of the dynamic optimization (thesis Sec. 5.1), batched over parameter sets.

``simulate_ff`` (fully forward): excitation -> activation dynamics (Eq. A.2) ->
Thelen 2003 muscle (rigid tendon, or compliant tendon with the contraction
dynamics of Eq. 3.9 / A.6-A.9) -> skeleton (Pinocchio ABA).
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
from ..muscles.thelen2003 import A_F as _A_F, F_HAT as _F_HAT, _C as _FV_C, _K_CON, _K_ECC, _W_THR

_FV_ECC = _FV_C * (_F_HAT - 1.0)
_mx, _mn = np.maximum, np.minimum


def _fv(w):
    """:func:`thelen_force_velocity` with bare ufuncs (same four pieces, tested equal)."""
    w1 = _mn(_mx(w, -1.0), 0.0)
    w2 = _mn(_mx(w, 0.0), _W_THR)
    return ((1.0 + w1) / (1.0 - w1 / _A_F) + _FV_ECC * w2 / (1.0 + _FV_C * w2)
            + _K_CON * _mn(w + 1.0, 0.0) + _K_ECC * _mx(w - _W_THR, 0.0))


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
        self.tau_rise = float(mtu.tau_rise)
        self.tau_fall = float(mtu.tau_fall)
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
        """``(F, v_ce, f_ce, f_isom)`` from the fibre-length state (Eq. 3.9)."""
        a = np.maximum(a, A_MIN)
        l_ce = np.maximum(l_ce, 1.0001 * np.sqrt(self.h2) + 1e-6 * self.l_opt)
        x = np.sqrt(np.maximum(l_ce * l_ce - self.h2, 0.0))
        F = self.f_max * thelen_tendon_force((l_mt - x) / self.l_slack - 1.0, strain0=self.strain0)
        v_ce = thelen_contraction_rate(l_ce, np.maximum(l_mt, x + 1e-9), a, l_opt=self.l_opt,
                                       l_slack=self.l_slack, pennation=self.pennation,
                                       v_max=self.v_max, tendon_strain0=self.strain0)
        d = l_ce / self.l_opt - 1.0
        fl = np.exp(d * d * (-1.0 / GAMMA))
        f_ce = F * l_ce / x - self.f_max * thelen_passive_force_length(l_ce / self.l_opt)
        return F, v_ce, np.maximum(f_ce, 0.0), fl


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


def _batch3(x, b):
    x = np.asarray(x, dtype=float)
    if x.ndim == 2:
        x = np.broadcast_to(x[:, None, :], (x.shape[0], b, x.shape[1]))
    return x


def simulate_ff(model, t, u, u_mid, q0, v0, *, a0=None, l_ce0=None, tendon: str = "rigid",
                skeleton: BatchSkeleton | None = None, muscles: BatchMuscles | None = None) -> dict:
    """Fully forward simulation (Sec. 5.1 design 1) of excitations on the grid ``t``.

    ``u`` (N, B, m) at the grid points and ``u_mid`` (N-1, B, m) at the interval
    midpoints (B parameter sets at once; (N, m) for one).  ``q0, v0`` (nv,) or
    (B, nv); ``a0`` defaults to the clipped ``u[0]`` (steady state); with
    ``tendon="compliant"`` the fibres start in isometric equilibrium unless
    ``l_ce0`` is given.  Returns time-first arrays (N, B, ...): ``q, v, acc, a,
    u, force, l_ce, v_ce, f_ce, f_isom``.
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
        if compliant:
            F, v_ce, _, _ = mu.compliant(a, l_mt, x[:, il])
            out[:, il] = v_ce
        else:
            F = mu.rigid(a, l_mt, mu.velocities(q, v))[0]
        out[:, iv] = sk.accel(q, v, mu.moments(q, F))
        return out

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


def muscle_inverse(model, q, v, acc, F, dF, ddF, *, muscles=None) -> dict:
    """Inverse muscle model (Fig. 5.6, Eq. 5.2-5.4) over frames: ``a, adot, u, l_ce, v_ce``.

    ``q, v, acc`` (N, nv) kinematics; ``F, dF, ddF`` (N, m) muscle-tendon force and its
    exact time derivatives.  Compliant Thelen tendon.
    """
    mu = muscles or BatchMuscles(model)
    l_mt = mu.lengths(q)
    dl = mu.velocities(q, v)
    ddl = mu.path.accelerations(q, v, acc)
    return mu.mtu.inverse(F, dF, l_mt, dl, ddl, ddF)
