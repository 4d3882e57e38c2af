"""Batch rigid-body dynamics over whole trials, wrapping Pinocchio.

Arrays are time-first, ``(N, nq)`` / ``(N, nv)``; Pinocchio is called in a
tight loop writing into preallocated output, with one ``pin.Data`` workspace
per call (or the one passed in), so the Python layer adds little to a bare
``pin.rnea`` loop (see ``benchmarks/``).

External forces cross the API as world-frame wrenches applied at a point on a
body (:class:`ExternalForce`) and are converted here to Pinocchio's joint-local
``fext``: the world wrench at the world origin is ``(f, p x f + tau)``, which
``oMi.actInv`` expresses in the joint frame.
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from .errors import ModelError, SolverError


def _pin(model) -> pin.Model:
    return model.pin if hasattr(model, "pin") else model


def _frames(x: np.ndarray, n: int, what: str) -> np.ndarray:
    """``x`` as a C-contiguous float (N, n) array; a single (n,) row becomes (1, n)."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2 or x.shape[1] != n:
        raise ModelError(f"{what} must have shape (N, {n}) (time-first); got {np.shape(x)}")
    return np.ascontiguousarray(x)


@dataclass(frozen=True)
class ExternalForce:
    """A world-frame force (and optional free torque) applied at a world point on a body.

    ``frame`` names a Pinocchio frame (or joint) of the body that receives the
    load; ``force``, ``point`` and ``torque`` are ``(N, 3)`` in N, m, N m.
    """

    frame: str
    force: np.ndarray
    point: np.ndarray
    torque: np.ndarray | None = None



def _frame_joint(pmodel: pin.Model, name: str) -> int:
    if pmodel.existFrame(name):
        return pmodel.frames[pmodel.getFrameId(name)].parentJoint
    if pmodel.existJointName(name):
        return pmodel.getJointId(name)
    names = [f.name for f in pmodel.frames]
    close = difflib.get_close_matches(name, names, n=3)
    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
    raise ModelError(f"model has no frame or body '{name}'{hint}")


def world_wrench(ext: ExternalForce, n: int) -> np.ndarray:
    """(N, 6) spatial force ``[f, p x f + tau]`` of an :class:`ExternalForce` about the world origin."""
    f = _frames(ext.force, 3, f"external force on '{ext.frame}'")
    p = _frames(ext.point, 3, f"application point on '{ext.frame}'")
    if f.shape[0] != n or p.shape[0] != n:
        raise ModelError(
            f"external force on '{ext.frame}' has {f.shape[0]} frames and its point {p.shape[0]}; "
            f"the motion has {n}"
        )
    m = np.cross(p, f)
    if ext.torque is not None:
        tq = _frames(ext.torque, 3, f"external torque on '{ext.frame}'")
        m = m + tq
    return np.hstack([f, m])


#: Frames between two ``progress.update`` calls of the long loops here.
PROGRESS_CHUNK = 4096


def rnea(model, q, v, a, *, external: Sequence[ExternalForce] = (),
                     data: pin.Data | None = None, progress=None) -> np.ndarray:
    """Joint generalized forces ``tau = M(q) a + h(q, v) - J^T f_ext`` over frames (RNEA).

    Returns ``(N, nv)``.  ``external`` lists world-frame wrenches at points.
    ``progress``: an object with ``update(n)``, called every
    :data:`PROGRESS_CHUNK` frames (e.g. :class:`pinmsk.presentation.progress.Progress`).
    """
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    a = _frames(a, pm.nv, "a")
    n = q.shape[0]
    if v.shape[0] != n or a.shape[0] != n:
        raise ModelError(f"q, v, a have {n}, {v.shape[0]}, {a.shape[0]} frames; they must match")
    pd = data if data is not None else pm.createData()
    out = np.empty((n, pm.nv))
    rnea = pin.rnea
    if not external:
        for start in range(0, n, PROGRESS_CHUNK):
            for i in range(start, min(start + PROGRESS_CHUNK, n)):
                out[i] = rnea(pm, pd, q[i], v[i], a[i])
            if progress is not None:
                progress.update(min(PROGRESS_CHUNK, n - start))
        return out
    joints = [_frame_joint(pm, e.frame) for e in external]
    wrenches = [world_wrench(e, n) for e in external]
    # tau = rnea(q, v, a) - sum_j J_j(q)^T W_j, with W_j the world wrench about the origin and J_j the
    # joint's Jacobian in the world frame (WORLD: the motion subspaces of its supporting joints, at the
    # origin, as computeJointJacobians leaves them in data.J): two Pinocchio calls a frame, the products
    # batched over frames, instead of a Force built, moved and summed per load and frame
    loaded = sorted(set(joints))
    W = {j: sum(w for jj, w in zip(joints, wrenches) if jj == j) for j in loaded}
    cols = {j: [pm.joints[s].idx_v + k for s in pm.supports[j][1:] for k in range(pm.joints[s].nv)] for j in loaded}
    used = sorted({c for cs in cols.values() for c in cs})
    J = np.empty((n, 6, len(used)))
    for start in range(0, n, PROGRESS_CHUNK):
        for i in range(start, min(start + PROGRESS_CHUNK, n)):
            out[i] = rnea(pm, pd, q[i], v[i], a[i])
            # eigenpy hands a 6 x 1 matrix back as a vector (a one-dof model): keep it 6 x nv
            J[i] = np.reshape(pin.computeJointJacobians(pm, pd, q[i]), (6, pm.nv))[:, used]
        if progress is not None:
            progress.update(min(PROGRESS_CHUNK, n - start))
    where = {c: k for k, c in enumerate(used)}
    for j in loaded:
        k = [where[c] for c in cols[j]]
        out[:, cols[j]] -= np.einsum("nrc,nr->nc", J[:, :, k], W[j])
    return out


def external_generalized_force(model, q, external: Sequence[ExternalForce]) -> np.ndarray:
    """``J^T f_ext`` over frames, ``(N, nv)``: the generalized force of external wrenches."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    z = np.zeros((q.shape[0], pm.nv))
    return rnea(pm, q, z, z, external=()) - rnea(pm, q, z, z, external=external)


def forward_dynamics(model, q, v, tau, *, data: pin.Data | None = None) -> np.ndarray:
    """Accelerations ``a = M^-1 (tau - h)`` over frames (ABA); returns ``(N, nv)``."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    tau = _frames(tau, pm.nv, "tau")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv))
    aba = pin.aba
    for i in range(q.shape[0]):
        out[i] = aba(pm, pd, q[i], v[i], tau[i])
    return out


def mass_matrix(model, q, *, data: pin.Data | None = None) -> np.ndarray:
    """Joint-space inertia ``M(q)`` over frames, ``(N, nv, nv)``, symmetric (CRBA)."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv, pm.nv))
    for i in range(q.shape[0]):
        M = pin.crba(pm, pd, q[i])
        out[i] = np.triu(M) + np.triu(M, 1).T
    return out


def gravity_torque(model, q, *, data: pin.Data | None = None) -> np.ndarray:
    """Generalized gravity ``g(q)`` over frames (the torque that holds the pose), ``(N, nv)``."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv))
    for i in range(q.shape[0]):
        out[i] = pin.computeGeneralizedGravity(pm, pd, q[i])
    return out


def nonlinear_effects(model, q, v, *, data: pin.Data | None = None) -> np.ndarray:
    """Coriolis, centrifugal and gravity terms ``h(q, v)`` over frames, ``(N, nv)``."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    pd = data if data is not None else pm.createData()
    out = np.empty((q.shape[0], pm.nv))
    for i in range(q.shape[0]):
        out[i] = pin.nonLinearEffects(pm, pd, q[i], v[i])
    return out


def _derivatives(fn, model, q, v, x, x_name, data):
    """Run a Pinocchio derivative routine over frames; the third output is symmetrised."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    x = _frames(x, pm.nv, x_name)
    pd = data if data is not None else pm.createData()
    n = q.shape[0]
    d1 = np.empty((n, pm.nv, pm.nv))
    d2 = np.empty_like(d1)
    d3 = np.empty_like(d1)
    for i in range(n):
        r = fn(pm, pd, q[i], v[i], x[i])
        d1[i], d2[i] = r[0], r[1]
        # Pinocchio fills only the upper triangle of M / M^-1
        d3[i] = np.triu(r[2]) + np.triu(r[2], 1).T
    return d1, d2, d3


def rnea_derivatives(model, q, v, a, *, data: pin.Data | None = None):
    """``(dtau/dq, dtau/dv, M)`` over frames, each ``(N, nv, nv)`` (Pinocchio RNEA derivatives)."""
    return _derivatives(pin.computeRNEADerivatives, model, q, v, a, "a", data)


def aba_derivatives(model, q, v, tau, *, data: pin.Data | None = None):
    """``(da/dq, da/dv, da/dtau = M^-1)`` over frames, each ``(N, nv, nv)`` (Pinocchio ABA derivatives)."""
    return _derivatives(pin.computeABADerivatives, model, q, v, tau, "tau", data)


def mechanical_energy(model, q, v, *, data: pin.Data | None = None) -> np.ndarray:
    """Kinetic + potential energy over frames, ``(N,)`` in J (potential relative to the origin)."""
    pm = _pin(model)
    q = _frames(q, pm.nq, "q")
    v = _frames(v, pm.nv, "v")
    pd = data if data is not None else pm.createData()
    out = np.empty(q.shape[0])
    for i in range(q.shape[0]):
        out[i] = pin.computeKineticEnergy(pm, pd, q[i], v[i]) + pin.computePotentialEnergy(pm, pd, q[i])
    return out


# -- forward simulation ---------------------------------------------------

#: ``tau_fn(t, q, v) -> (nv,)``: generalized force applied at time t and state (q, v).
TorqueFn = Callable[[float, np.ndarray, np.ndarray], np.ndarray]


def integrate(model, q0, v0, t, tau_fn: TorqueFn | None = None, *, method: str = "rk4",
              rtol: float = 1e-8, atol: float = 1e-10, data: pin.Data | None = None,
              progress=None):
    """Integrate ``M a + h = tau_fn(t, q, v)`` from ``(q0, v0)`` and return ``(q, v, a)`` at ``t``.

    ``method="rk4"`` takes fixed classical Runge-Kutta steps between the
    samples of ``t``; any other value (``"RK45"``, ``"DOP853"``, ``"Radau"``, ...)
    is passed to :func:`scipy.integrate.solve_ivp` with ``t_eval=t``.
    Requires ``nq == nv`` (models of 1-dof joints).
    """
    pm = _pin(model)
    if pm.nq != pm.nv:
        raise ModelError("integrate: models with multi-dof joints (nq != nv) are not supported yet")
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
        raise ModelError("integrate: t must be a strictly increasing 1-D array of at least 2 times")
    nv = pm.nv
    pd = data if data is not None else pm.createData()
    zero = np.zeros(nv)
    aba = pin.aba

    def accel(ti, q, v):
        tau = zero if tau_fn is None else np.asarray(tau_fn(ti, q, v), dtype=float)
        return aba(pm, pd, q, v, tau)

    n = t.size
    Q = np.empty((n, nv))
    V = np.empty((n, nv))
    A = np.empty((n, nv))
    q = np.array(q0, dtype=float).reshape(nv)
    v = np.array(v0, dtype=float).reshape(nv)
    if method.lower() == "rk4":
        Q[0], V[0] = q, v
        for i in range(n - 1):
            h = t[i + 1] - t[i]
            ti = t[i]
            k1q, k1v = v, accel(ti, q, v)
            A[i] = k1v
            k2q, k2v = v + 0.5 * h * k1v, accel(ti + 0.5 * h, q + 0.5 * h * k1q, v + 0.5 * h * k1v)
            k3q, k3v = v + 0.5 * h * k2v, accel(ti + 0.5 * h, q + 0.5 * h * k2q, v + 0.5 * h * k2v)
            k4q, k4v = v + h * k3v, accel(ti + h, q + h * k3q, v + h * k3v)
            q = q + h / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q)
            v = v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
                raise SolverError(f"integrate: the state became non-finite at t = {t[i + 1]:.6g} s "
                                  f"(step {i + 1}); reduce the step or check the applied forces")
            Q[i + 1], V[i + 1] = q, v
            if progress is not None:
                progress.update(1)
        A[-1] = accel(t[-1], q, v)
        return Q, V, A
    from scipy.integrate import solve_ivp

    def rhs(ti, x):
        return np.concatenate([x[nv:], accel(ti, x[:nv], x[nv:])])

    sol = solve_ivp(rhs, (t[0], t[-1]), np.concatenate([q, v]), method=method, t_eval=t,
                    rtol=rtol, atol=atol)
    if not sol.success:
        raise SolverError(f"integrate: solve_ivp ({method}) failed at t = {sol.t[-1]:.6g} s: {sol.message}")
    Q[:] = sol.y[:nv].T
    V[:] = sol.y[nv:].T
    for i in range(n):
        A[i] = accel(t[i], Q[i], V[i])
    return Q, V, A
