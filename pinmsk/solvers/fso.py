"""Forward static optimization (FSO): static optimization inside a forward simulation (thesis Sec. 3.4).

The model is integrated forward from the reference motion's initial state.
At each of ``control_points`` instants ``t_k`` a QP chooses the muscle forces
(held constant until ``t_{k+1}``) that minimise Eq. 3.15,

    J_k = sum_i k_i x_i^P  +  mu * kappa * || a(F) - a*_k ||^2,

where the acceleration the forces produce, ``a(F) = M(q)^-1 (R(q)^T F + Q_c - h(q, v))``,
is linear in ``F``, so the tracking term of Eq. 3.16-3.19 is a quadratic in
the forces.  The desired acceleration ``a*`` and the weight ``kappa`` come from
the tracking form (``h = t_{k+1} - t_k``, ``e_q = q_d(t+h) - q - h v``,
``e_v = v_d(t+h) - v``):

``"q"`` (Eq. 3.16)
    ``(q_{k+1} - q_d)^2`` with the one-step prediction ``q_{k+1} = q + h v + h^2 a / 2``:
    ``a* = 2 e_q / h^2``, ``kappa = h^4 / 4``;
``"qv"`` (Eq. 3.17)
    adds ``(v_{k+1} - v_d)^2``, ``v_{k+1} = v + h a``: ``a* = (h^2 e_q / 2 + h e_v) / kappa``,
    ``kappa = h^4 / 4 + h^2``;
``"qva"`` (Eq. 3.18)
    adds ``(a - a_d(t+h))^2``: ``a* = (h^2 e_q / 2 + h e_v + a_d) / kappa``, ``kappa = h^4/4 + h^2 + 1``;
``"pid"`` (Eq. 3.19)
    ``psi'' + alpha psi' + beta psi + gamma int psi = 0`` with ``psi = q - q_d``:
    ``a* = a_d(t + h/2) + alpha (v_d - v) + beta (q_d - q) + gamma int (q_d - q) dt``
    (feed-forward at the middle of the hold interval, where a held force acts on average),
    ``kappa = 1``; default gains put a triple pole at ``-omega``
    (``alpha = 3 omega``, ``beta = 3 omega^2``, ``gamma = omega^3``, ``omega = 20 rad/s``).

The forces are held over each control interval ``h``, so the PID loop is a
sampled one: for the error dynamics (a double integrator under a zero-order
hold) it is stable only while ``omega h`` stays below about 0.67 with the
default gains (:func:`pid_spectral_radius`).  The default number of control
points is therefore chosen from the duration, ``omega h <= 0.5`` and at least
100; a count that makes the loop unstable is refused before simulating.  A
tracking error above ``max_tracking_error`` (default 1 deg; the same number in
m for translations) stops the run with a :class:`~pinmsk.errors.ConvergenceError`
naming the time and coordinate, unless ``allow_divergence=True``, which keeps
the result but flags it (``diverged`` channel and meta entry, a warning).

``enforce="constraint"`` imposes ``a(F) = a*`` exactly (equivalently
``R^T F = M a* + h - Q_c``, an SO problem at the simulated state);
``enforce="cost"`` keeps the tracking term in the cost; ``tracking_weight``
is ``mu = mu_2 kappa``, the weight of the squared acceleration error, with
the error measured as a fraction of each dof's capacity acceleration
``s_j / M_jj`` (its muscles all fully active) and the muscle cost scaled so a
fully active muscle of the highest weight costs 1.  The default 1e6 keeps
the acceleration error near 1e-6 of capacity (about 1e-3 rad/s^2 for the
forearm) while the QP stays well conditioned.

The held forces drive Pinocchio's ABA (inertial components such as a held
payload folded into the skeleton, other components added) with fixed-step
RK4 (``integrator="rk4"``, ``substeps`` per control interval) or
``scipy.integrate.solve_ivp`` (``"RK45"``, ``"DOP853"``, ...).  In force mode
the forces are held and the moment ``R(q)^T F`` follows the moment arms; in
activation mode the activations are held and the forces follow the muscles'
force-length-velocity state.  Every QP goes through proxsuite
(:class:`pinmsk.solvers.qp.FrameQP`, reused and warm started).

Muscle-level components of the model are honoured in activation mode: with
activation dynamics (:class:`~pinmsk.effects.ActivationDynamics`, or the
delay-and-activation component) the activations a control point may choose
are those the dynamics reach from the previous one with ``0 <= u <= 1`` held
(:func:`pinmsk.muscles.activation.reachable_activation`, as MSO), and the
result has ``<muscle>_excitation`` channels (held-step excitations; with an
electromechanical delay, what a recording shows, ``u(t + delay)``, NaN in the
last ``delay`` s).  Force mode holds forces, not activations, and refuses a
model with muscle-level components by name.
"""
from __future__ import annotations

import time as _time
import warnings

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from ..components import Motion
from ..dynamics import skeleton_with_inertias
from ..effects._base import SignalEffect
from ..effects.activation import excitation_path
from ..errors import ConvergenceError, InfeasibleError, ModelError, SolverError
from ..fitting import FitStatistics, Fitter, Result, format_report
from ..kinematics import DEFAULT_CUTOFF, as_motion, prepare, require_independent_joints
from ..muscles.activation import held_step_excitation, reachable_activation
from ..skeleton import (ExternalForce, external_generalized_force, integrate, mass_matrix, nonlinear_effects, rnea,
                        world_wrench)
from ..trial import Trial
from . import qp as _qp
from .static import MODES, WEIGHTS, _muscle_property, check_model

TRACKING = ("q", "qv", "qva", "pid")
ENFORCE = ("constraint", "cost")
#: ``omega h`` of the default number of PID control points (stable up to about 0.67).
PID_OMEGA_H = 0.5
#: Default ``max_tracking_error``: 1 degree (rad; the same number in m for translations).
MAX_TRACKING_ERROR = float(np.deg2rad(1.0))


def pid_spectral_radius(gains, h: float) -> float:
    """Spectral radius of the sampled PID tracking loop of Eq. 3.19 (below 1: stable).

    The tracking error ``e = q - q_d`` of a double integrator whose acceleration
    ``-(alpha e' + beta e + gamma int e)`` is held over each interval ``h``
    (the trapezoid rule for the integral, as :class:`ForwardStaticOptimization`).
    """
    alpha, beta, gamma = (float(g) for g in gains)
    A = np.array([[1.0, h, 0.0], [0.0, 1.0, 0.0], [h, h * h / 2.0, 1.0]])
    B = np.array([h * h / 2.0, h, h ** 3 / 4.0])
    K = np.array([-beta, -alpha, -gamma])
    return float(np.max(np.abs(np.linalg.eigvals(A + np.outer(B, K)))))


def _pid_bandwidth(gains) -> float:
    """``omega`` of the triple pole the gains would place (their largest equivalent)."""
    alpha, beta, gamma = (abs(float(g)) for g in gains)
    return max(alpha / 3.0, np.sqrt(beta / 3.0), np.cbrt(gamma), 1e-12)


def _external_drive(model, t, external):
    """``f(t, q) -> (nv,)``: the generalized force ``J(q)^T f_ext(t)`` of the measured loads, or None.

    The wrenches (world frame, about the origin) are interpolated linearly in
    time and applied at the simulated configuration, so the feet carry the
    measured ground reaction wherever the simulation puts them.
    """
    if not external:
        return None
    frames = [e.frame for e in external]
    W = [world_wrench(e, len(t)) for e in external]
    zero = np.zeros((1, 3))

    def drive(ti, q):
        loads = []
        for name, w in zip(frames, W):
            wi = np.array([np.interp(ti, t, w[:, j]) for j in range(6)])
            loads.append(ExternalForce(name, wi[None, :3], zero, wi[None, 3:]))
        return external_generalized_force(model, q[None, :], loads)[0]

    return drive


class ForwardStaticOptimization(Fitter):
    """Forward static optimization over a reference motion (thesis Sec. 3.4, Eq. 3.15-3.19).

    Parameters (keyword-only)
    -------------------------
    mode, exponent, weights : as :class:`~pinmsk.solvers.static.StaticOptimization`
        (cost Eq. 3.13 / 2.11 / 2.14).
    tracking : "q" | "qv" | "qva" | "pid"
        Tracking error, Eq. 3.16, 3.17, 3.18 or the PID form 3.19.
    enforce : "constraint" | "cost"
        Tracking as an equality constraint or as the cost term of Eq. 3.15.
    tracking_weight : float
        ``mu`` of Eq. 3.15 (cost mode).
    gains : (alpha, beta, gamma) or None
        PID gains of Eq. 3.19; default from ``omega`` (triple pole).
    omega : float
        Bandwidth (rad/s) of the default PID gains.
    control_points : int or None
        Number of uniformly spaced QP instants over the trial (thesis: 100).
        Default: 100, or for ``tracking="pid"`` more if needed for
        ``omega h <= 0.5`` (a stable sampled loop).
    max_tracking_error : float
        Largest accepted ``|q - q_d|`` at a control point (rad, or m for
        translations; default 1 deg).  Above it the run stops with a
        ConvergenceError naming the time and coordinate.
    allow_divergence : bool
        Keep going past ``max_tracking_error`` (and an unstable PID sampling):
        the result gets a ``diverged`` channel (1 where the error is above the
        tolerance) and ``meta["diverged"]``, and a warning is issued.
    integrator : "rk4" | "RK45" | any solve_ivp method
    substeps : int
        RK4 steps per control interval.
    reserves, reserve_weight, tol : as StaticOptimization; here every
        coordinate of the model must be balanced, so coordinates that no muscle
        spans need ``reserves=True``.
    rtol, atol : solve_ivp tolerances (integrators other than rk4).

    Attributes (after ``fit``, also available as ``run``)
    -----------------------------------------------------
    t_ (K,) control points; t_hold_ (K,) middles of the hold intervals; q_, v_
    (K, nv) simulated state; q_desired_, v_desired_; acc_desired_ ``a*``;
    tracking_error_ ``q_ - q_desired_``; diverged_ (bool) and divergence_
    (``{"time", "control_point", "coordinate", "error"}`` of the first
    tolerance violation, or None); forces_, activations_ (K, m) held
    from each control point; reserves_; cost_; trajectory_ (a Trial on the
    integration grid); n_qp_, n_iter_; time_ (s); result_ (a
    :class:`~pinmsk.fitting.Result`: the Trial of ``<coord>``,
    ``<coord>_speed``, ``<coord>_desired``, ``<coord>_error``,
    ``<muscle>_force``, ``<muscle>_activation``, ``cost``, and its statistics:
    ``converged`` False when the run diverged, ``violation`` how far the
    largest tracking error exceeds ``max_tracking_error``).
    """

    def __init__(self, *, mode: str = "force", exponent: float = 2, weights: str = "none",
                 tracking: str = "pid", enforce: str = "constraint", tracking_weight: float = 1e6,
                 gains=None, omega: float = 20.0, control_points: int | None = None,
                 integrator: str = "rk4", substeps: int = 4, reserves: bool = False,
                 reserve_weight: float = 1000.0, tol: float = 1e-9, rtol: float = 1e-6,
                 atol: float = 1e-8, max_tracking_error: float = MAX_TRACKING_ERROR,
                 allow_divergence: bool = False):
        self.mode = mode
        self.exponent = exponent
        self.weights = weights
        self.tracking = tracking
        self.enforce = enforce
        self.tracking_weight = tracking_weight
        self.gains = gains
        self.omega = omega
        self.control_points = control_points
        self.integrator = integrator
        self.substeps = substeps
        self.reserves = reserves
        self.reserve_weight = reserve_weight
        self.tol = tol
        self.rtol = rtol
        self.atol = atol
        self.max_tracking_error = max_tracking_error
        self.allow_divergence = allow_divergence

    def _check_params(self):
        if self.mode not in MODES:
            raise SolverError(f"mode must be one of {', '.join(MODES)}; got {self.mode!r}")
        if self.weights not in WEIGHTS:
            raise SolverError(f"weights must be one of {', '.join(WEIGHTS)}; got {self.weights!r}")
        if self.tracking not in TRACKING:
            raise SolverError(f"tracking must be one of {', '.join(TRACKING)} (Eq. 3.16, 3.17, 3.18, "
                              f"3.19); got {self.tracking!r}")
        if self.enforce not in ENFORCE:
            raise SolverError(f"enforce must be one of {', '.join(ENFORCE)}; got {self.enforce!r}")
        if self.control_points is not None and int(self.control_points) < 2:
            raise SolverError(f"control_points must be >= 2; got {self.control_points!r}")
        if not float(self.max_tracking_error) > 0:
            raise SolverError(f"max_tracking_error must be > 0 (rad, or m); got {self.max_tracking_error!r}")
        if int(self.substeps) < 1:
            raise SolverError(f"substeps must be >= 1; got {self.substeps!r}")
        _qp.check_exponent(self.exponent)
        if self.enforce == "cost" and not float(self.tracking_weight) > 0:
            raise SolverError(f"tracking_weight must be > 0; got {self.tracking_weight!r}")

    def _pid_gains(self):
        if self.gains is not None:
            g = tuple(float(x) for x in self.gains)
            if len(g) != 3:
                raise SolverError(f"gains must be (alpha, beta, gamma); got {self.gains!r}")
            return g
        w = float(self.omega)
        return 3.0 * w, 3.0 * w * w, w ** 3

    def _control_times(self, t0: float, t1: float) -> np.ndarray:
        """The control points over [t0, t1]; refuses a count that makes the PID loop unstable."""
        n = self.control_points
        if self.tracking != "pid":
            return np.linspace(t0, t1, 100 if n is None else int(n))
        gains = self._pid_gains()
        need = int(np.ceil((t1 - t0) * _pid_bandwidth(gains) / PID_OMEGA_H)) + 1
        n = max(100, need) if n is None else int(n)
        h = (t1 - t0) / (n - 1)
        rho = pid_spectral_radius(gains, h)
        if rho >= 1.0:
            msg = (f"FSO: {n} control points over {t1 - t0:.4g} s hold each force for h = {h:.4g} s, too long "
                   f"for the PID gains (alpha, beta, gamma) = {tuple(round(g, 4) for g in gains)}: the sampled "
                   f"tracking loop is unstable (spectral radius {rho:.3g} > 1; omega h = "
                   f"{_pid_bandwidth(gains) * h:.3g}, stable below about 0.67) and would diverge; use "
                   f"control_points >= {need} (--control-points), or lower omega / the gains")
            if not self.allow_divergence:
                raise ConvergenceError(msg)
            warnings.warn(msg + "; going on (allow_divergence)", stacklevel=3)
        return np.linspace(t0, t1, n)

    # -- running -------------------------------------------------------------
    def fit(self, model, trial, *, cutoff=DEFAULT_CUTOFF, grf=None, external_loads=None, frames=None,
            ground_reaction: str = "auto", grf_cutoff="auto", progress=None, missing_coordinates: str = "refuse"):
        """Simulate the model tracking ``trial`` (a Trial or a Motion); returns ``self``.

        The trial goes through :func:`pinmsk.kinematics.prepare` (coordinates and
        GRF low-passed at ``cutoff`` Hz, default 6, 0 = off); its ground reaction
        forces act on the simulated feet as world wrenches interpolated in time.
        """
        self._check_params()
        t_start = _time.perf_counter()
        require_independent_joints(model, "forward static optimization (FSO)")
        muscles = check_model(model)
        signal = [c.label for c in model.effects if isinstance(c, SignalEffect)]
        if signal and self.mode == "force":
            raise ModelError(f"FSO in force mode holds muscle forces, not activations, so it cannot honour the "
                             f"model's {', '.join(signal)}: use mode='activation' or model.without(...) them")
        path = excitation_path(model) if signal else None
        self.excitation_path_ = path
        inputs = prepare(model, trial, cutoff=cutoff, grf=grf, external_loads=external_loads, frames=frames,
                         ground_reaction=ground_reaction, grf_cutoff=grf_cutoff,
                         missing_coordinates=missing_coordinates)
        self.inputs_ = inputs
        ref = as_motion(model, inputs.motion)
        external_force = _external_drive(model, ref.t, inputs.external)
        if ref.n_frames < 2:
            raise SolverError("FSO needs a reference motion of at least 2 frames")
        nv, m = model.nv, muscles.n
        P = _qp.check_exponent(self.exponent)
        # which coordinates the muscles span; all must be driven
        R_ref = np.asarray(muscles.moment_arms(ref.q), dtype=float)
        spanned = np.any(np.abs(R_ref) > 0, axis=(0, 1))
        if not spanned.all() and not self.reserves:
            lonely = [model.coordinates[j] for j in np.flatnonzero(~spanned)]
            raise ModelError(f"FSO drives every coordinate, but no muscle spans {', '.join(lonely)}; "
                             "pass reserves=True to give them ideal actuators")
        # reference splines
        t_ref = ref.t
        q_s = CubicHermiteSpline(t_ref, ref.q, ref.v, axis=0)
        v_s = CubicHermiteSpline(t_ref, ref.v, ref.a, axis=0)
        a_s = v_s.derivative()
        tc = self._control_times(float(t_ref[0]), float(t_ref[-1]))
        if progress is not None and hasattr(progress, "total"):
            progress.total = tc.size
        # cost weights and force map
        f_max = np.asarray(muscles.f_max, dtype=float)
        prop = _muscle_property(muscles, self.weights)
        if self.mode == "force":
            k = (f_max / prop) ** P
        else:
            k = prop.copy()
        w = k / np.max(k)
        # dof scales: capacity over the reference (as SO)
        if self.mode == "force":
            cap_c = np.broadcast_to(f_max, (ref.n_frames, m))
        else:
            cap_c = np.maximum(np.asarray(muscles.force_limits(ref.q, ref.v)[0], dtype=float), 0.0)
        scale = np.max(np.einsum("nmj,nm->nj", np.abs(R_ref), cap_c), axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        W = float(self.reserve_weight) if self.reserves else None
        cost_mode = self.enforce == "cost"
        # cost mode: the tracking term mu ||B x - r||^2 is written as a soft equality
        # B x + e = r with cost mu e^2 (FrameQP's quadratic reserve), which keeps the
        # Hessian diagonal and the QP well conditioned for large mu
        fq = _qp.FrameQP(m=m, nd=nv, weights=w, exponent=P,
                         reserve_weight=float(self.tracking_weight) if cost_mode else W,
                         reserve_linear=not cost_mode, eps=float(self.tol) * 1e-4,
                         sqp_tol=max(float(self.tol) * 1e-2, 1e-13))
        if cost_mode and self.reserves:
            raise SolverError("reserves are for enforce='constraint'; in cost mode the tracking "
                              "term already absorbs what the muscles cannot do")
        # skeleton with inertial components, other components as forces
        pm = skeleton_with_inertias(model)
        pd = pm.createData()
        comps = [c for c in model.components if not getattr(c, "inertial", False)]

        def comp_force(ti, q, v):
            total = 0.0 if external_force is None else external_force(ti, q)
            if not comps:
                return total
            mo = Motion(np.array([ti]), q[None, :], v[None, :], np.zeros((1, nv)))
            return total + sum(c.generalized_force(model, mo, cache=c.prepare(model, mo))[0] for c in comps)

        alpha, beta, gamma = self._pid_gains()
        tol_err = float(self.max_tracking_error)
        rotational = set(model.rotational_coordinates)
        divergence = None
        q = ref.q[0].copy()
        v = ref.v[0].copy()
        integ = np.zeros(nv)
        n_c = tc.size
        Qc = np.empty((n_c, nv))
        Vc = np.empty((n_c, nv))
        Astar = np.empty((n_c, nv))
        X = np.empty((n_c, m))
        F_out = np.empty((n_c, m))
        RHO = np.zeros((n_c, nv))
        iters = 0
        n_qp = 0
        fine_t, fine_q, fine_v = [tc[0]], [q.copy()], [v.copy()]
        meth = str(self.integrator)
        for kk in range(n_c):
            ti = tc[kk]
            Qc[kk], Vc[kk] = q, v
            h = (tc[kk + 1] - ti) if kk + 1 < n_c else (tc[kk] - tc[kk - 1])
            tn = min(ti + h, t_ref[-1])
            qd, vd = q_s(ti), v_s(ti)
            qd1, vd1, ad1 = q_s(tn), v_s(tn), a_s(tn)
            e_q = qd1 - q - h * v
            e_v = vd1 - v
            if self.tracking == "q":
                kap = h ** 4 / 4.0
                a_star = 2.0 * e_q / h ** 2
            elif self.tracking == "qv":
                kap = h ** 4 / 4.0 + h ** 2
                a_star = (h ** 2 * e_q / 2.0 + h * e_v) / kap
            elif self.tracking == "qva":
                kap = h ** 4 / 4.0 + h ** 2 + 1.0
                a_star = (h ** 2 * e_q / 2.0 + h * e_v + ad1) / kap
            else:
                kap = 1.0
                # feed-forward at the middle of the hold interval: a force held over
                # [t_k, t_k + h] acts on average there (zero-order hold)
                a_star = a_s(ti + 0.5 * h) + alpha * (vd - v) + beta * (qd - q) + gamma * integ
            Astar[kk] = a_star
            # muscle state at the control point
            R = np.asarray(muscles.moment_arms(q[None, :]), dtype=float)[0]           # (m, nv)
            if self.mode == "force":
                c_now = f_max.copy()
                d_now = np.zeros(m)
            else:
                fa, fp = muscles.force_limits(q[None, :], v[None, :])
                c_now = np.maximum(np.asarray(fa, dtype=float)[0], 0.0)
                d_now = np.asarray(fp, dtype=float)[0]
            Qcomp = comp_force(ti, q, v)
            lo, hi = np.zeros(m), np.ones(m)
            if path is not None and kk > 0 and path.declared.any():
                # activation dynamics: only what the held excitations of the last interval can reach
                r_lo, r_hi = reachable_activation(X[kk - 1], ti - tc[kk - 1], tau_rise=path.tau_rise,
                                                  tau_fall=path.tau_fall)
                lo = np.where(path.declared, np.clip(r_lo, 0.0, 1.0), 0.0)
                hi = np.where(path.declared, np.clip(r_hi, lo, 1.0), 1.0)
            if not cost_mode:
                tau_star = rnea(pm, q, v, a_star, data=pd)[0] - Qcomp
                A = (R * c_now[:, None]).T / scale[:, None]
                b = (tau_star - R.T @ d_now) / scale
                sol = fq.solve(A, b, lo, hi)
                if not sol.solved:
                    raise InfeasibleError(
                        f"FSO: at t = {ti:.4g} s (control point {kk}) the muscles cannot produce the "
                        f"moments {np.round(tau_star, 4).tolist()} N m needed to track the motion "
                        f"({sol.status})" + (f" within the activations the model's activation dynamics reach "
                                            f"({path.describe()})" if path is not None and path.declared.any()
                                            else "") + "; pass reserves=True, use enforce='cost', or lower the gains")
                RHO[kk] = sol.rho * scale
            else:
                M = mass_matrix(pm, q, data=pd)[0]
                nle = nonlinear_effects(pm, q, v, data=pd)[0]
                Minv = np.linalg.inv(M)
                # accelerations in units of each dof's capacity acceleration s_j / M_jj
                a_ref = scale / np.diag(M)
                B = (Minv @ (R * c_now[:, None]).T) / a_ref[:, None]   # (nv, m): a = B x + a0
                a0 = Minv @ (R.T @ d_now + Qcomp - nle)
                r = (a_star - a0) / a_ref
                sol = fq.solve(B, r, lo, hi)      # + mu e^2, mu = mu_2 kappa of Eq. 3.15
                if not sol.solved:
                    raise SolverError(f"FSO: the QP at t = {ti:.4g} s failed ({sol.status})")
            iters += sol.iterations
            n_qp += sol.qp_solves
            X[kk] = sol.x
            F_out[kk] = c_now * sol.x + d_now
            if kk + 1 == n_c:
                break
            # integrate to the next control point with the forces (activations) held
            x_hold = sol.x.copy()
            F_hold = F_out[kk].copy()
            rho_hold = RHO[kk].copy()

            if self.mode == "force":
                def tau_fn(tt, qq, vv, F_hold=F_hold, rho_hold=rho_hold):
                    Rq = np.asarray(muscles.moment_arms(qq[None, :]), dtype=float)[0]
                    return Rq.T @ F_hold + rho_hold + comp_force(tt, qq, vv)
            else:
                def tau_fn(tt, qq, vv, x_hold=x_hold, rho_hold=rho_hold):
                    Rq = np.asarray(muscles.moment_arms(qq[None, :]), dtype=float)[0]
                    fa, fp = muscles.force_limits(qq[None, :], vv[None, :])
                    F = x_hold * np.maximum(np.asarray(fa, dtype=float)[0], 0.0) + np.asarray(fp, dtype=float)[0]
                    return Rq.T @ F + rho_hold + comp_force(tt, qq, vv)

            if meth.lower() == "rk4":
                grid = np.linspace(ti, tc[kk + 1], int(self.substeps) + 1)
            else:
                grid = np.array([ti, tc[kk + 1]])
            Qg, Vg, _ = integrate(pm, q, v, grid, tau_fn, method=meth, rtol=float(self.rtol),
                                  atol=float(self.atol), data=pd)
            # PID integral of (q_d - q), trapezoid over the substeps
            if self.tracking == "pid":
                err = q_s(grid) - Qg
                integ = integ + np.sum(0.5 * (err[1:] + err[:-1]) * np.diff(grid)[:, None], axis=0)
            q, v = Qg[-1].copy(), Vg[-1].copy()
            fine_t.extend(grid[1:].tolist())
            fine_q.extend(Qg[1:])
            fine_v.extend(Vg[1:])
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
                raise SolverError(f"FSO: the simulation diverged after t = {ti:.4g} s")
            if divergence is None:
                err = np.abs(q - q_s(tc[kk + 1]))
                if np.any(err > tol_err):
                    j = int(np.argmax(err > tol_err))
                    divergence = self._divergence(model, tc[kk + 1], kk + 1, j, err[j], rotational)
                    if not self.allow_divergence:
                        raise ConvergenceError(divergence["message"])
            if progress is not None:
                progress.update(1)
        if progress is not None:
            progress.update(1)
        t_end = _time.perf_counter()
        self.t_ = tc
        #: middle of each hold interval (the last control point holds nothing)
        self.t_hold_ = np.concatenate([0.5 * (tc[1:] + tc[:-1]), tc[-1:]])
        self.q_ = Qc
        self.v_ = Vc
        self.q_desired_ = q_s(tc)
        self.v_desired_ = v_s(tc)
        self.acc_desired_ = Astar
        self.forces_ = F_out
        self.activations_ = X if self.mode == "activation" else F_out / f_max
        self.reserves_ = RHO if self.reserves else None
        self.excitations_ = None
        if path is not None:
            u = X.copy()
            if n_c > 1:
                held = held_step_excitation(X[:-1], X[1:], np.diff(tc)[:, None], tau_rise=path.tau_rise,
                                            tau_fall=path.tau_fall)
                u[1:] = np.where(path.declared, held, X[1:])     # without dynamics a = u
            self.excitations_ = path.recorded(tc, u)
        self.tracking_error_ = self.q_ - self.q_desired_
        self.diverged_ = divergence is not None
        self.divergence_ = divergence
        if divergence is not None:
            warnings.warn(divergence["message"] + "; result kept and flagged (allow_divergence)", stacklevel=2)
        self.trajectory_ = Trial(np.asarray(fine_t), {
            **{c: np.asarray(fine_q)[:, j] for j, c in enumerate(model.coordinates)},
            **{f"{c}_speed": np.asarray(fine_v)[:, j] for j, c in enumerate(model.coordinates)}},
            meta={"analysis": "fso_trajectory", "model": model.name})
        self.n_iter_ = iters
        self.n_qp_ = n_qp
        self.time_ = t_end - t_start
        self.model_name_ = model.name
        self.coordinates_ = model.coordinates
        self.muscles_ = muscles.names
        cost = np.sum(k * np.maximum(X, 0.0) ** P, axis=1)
        self.cost_ = cost
        self.result_ = self._result()
        return self

    run = fit

    def _divergence(self, model, t, k, j, error, rotational) -> dict:
        """The first tracking-error violation, with the message of the ConvergenceError."""
        c = model.coordinates[j]
        tol = float(self.max_tracking_error)
        if c in rotational:
            size = f"{np.rad2deg(error):.3g} deg, above max_tracking_error = {np.rad2deg(tol):.3g} deg"
        else:
            size = f"{error:.3g} m, above max_tracking_error = {tol:.3g} m"
        why = ("the muscles (with reserves, if any) cannot follow the motion, or the control points "
               "are too sparse; try more control points, lower gains, or enforce='cost'")
        msg = (f"FSO: the tracking error of '{c}' reached {size} at t = {t:.4g} s (control point {k}): "
               f"the simulation does not follow the motion ({why}; allow_divergence=True, "
               "--allow-divergence, keeps such a result, flagged)")
        return {"time": float(t), "control_point": int(k), "coordinate": c, "error": float(error),
                "message": msg}

    def _result(self) -> Result:
        K, m = self.forces_.shape
        over = float(np.max(np.abs(self.tracking_error_))) - float(self.max_tracking_error)
        stats = FitStatistics(
            k=K * (m + (self.reserves_.shape[1] if self.reserves_ is not None else 0)),
            converged=not self.diverged_,
            message=self.divergence_["message"] if self.diverged_ else
            "tracked the motion within max_tracking_error", iterations=self.n_iter_,
            violation=max(over, 0.0), objective=float(np.sum(self.cost_)))
        return Result.from_trial(self._channels(), stats=stats, report=self._report_text())

    def _channels(self) -> Trial:
        ch = {}
        for j, c in enumerate(self.coordinates_):
            ch[c] = self.q_[:, j]
            ch[f"{c}_speed"] = self.v_[:, j]
            ch[f"{c}_desired"] = self.q_desired_[:, j]
            ch[f"{c}_error"] = self.tracking_error_[:, j]
        for i, n in enumerate(self.muscles_):
            ch[f"{n}_force"] = self.forces_[:, i]
        for i, n in enumerate(self.muscles_):
            ch[f"{n}_activation"] = self.activations_[:, i]
        if getattr(self, "excitations_", None) is not None:
            for i, n in enumerate(self.muscles_):
                ch[f"{n}_excitation"] = self.excitations_[:, i]
        if self.reserves_ is not None:
            for j, c in enumerate(self.coordinates_):
                ch[f"{c}_reserve"] = self.reserves_[:, j]
        ch["cost"] = self.cost_
        meta = {"analysis": "forward_static_optimization",
                **{k: str(v) for k, v in self.get_params(deep=False).items()}}
        if getattr(self, "inputs_", None) is not None:
            meta.update(self.inputs_.meta())
        if self.allow_divergence:
            ch["diverged"] = np.any(np.abs(self.tracking_error_) > float(self.max_tracking_error),
                                    axis=1).astype(float)
            meta["diverged"] = self.divergence_["message"] if self.diverged_ else "no"
        return Trial(self.t_, ch, meta=meta)

    def _report_text(self) -> str:
        err = np.abs(self.tracking_error_)
        rms = np.sqrt(np.mean(self.tracking_error_ ** 2, axis=0))
        form = {"q": "Eq. 3.16", "qv": "Eq. 3.17", "qva": "Eq. 3.18", "pid": "Eq. 3.19 (PID)"}[self.tracking]
        rk4 = str(self.integrator).lower() == "rk4"
        rows = [
            ("cost", f"sum (F/N)^{float(self.exponent):g} (Eq. 3.15) with tracking {form} as a {self.enforce}"),
            ("control points", f"{self.t_.size} over {self.t_[0]:.4g}-{self.t_[-1]:.4g} s, integrator "
                               f"{self.integrator}" + (f" ({self.substeps} steps per interval)" if rk4 else "")),
            ("tracking error", "max |q - q_d| = " + ", ".join(
                f"{c} {np.rad2deg(e):.3g} deg (rms {np.rad2deg(r):.3g})"
                for c, e, r in zip(self.coordinates_, err.max(axis=0), rms))),
            ("solver", f"{self.n_qp_} proxsuite QPs, {self.n_iter_} iterations"),
            ("time", f"{self.time_ * 1e3:.1f} ms"),
        ]
        if getattr(self, "inputs_", None) is not None:
            rows += list(self.inputs_.describe())
        if getattr(self, "excitation_path_", None) is not None:
            rows.append(("dynamics", self.excitation_path_.describe()))
        if self.reserves_ is not None:
            rows.append(("reserves", f"max {np.max(np.abs(self.reserves_)):.4g} N m"))
        if self.diverged_:
            rows.append(("DIVERGED", f"from t = {self.divergence_['time']:.4g} s "
                                     f"('{self.divergence_['coordinate']}'); the result does not track the motion"))
        return format_report(f"Forward static optimization ({self.mode} mode) of model '{self.model_name_}'", rows)


#: Short name used in the thesis and the CLI.
FSO = ForwardStaticOptimization
