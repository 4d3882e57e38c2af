"""Modified static optimization (MSO): SO with activation dynamics between frames (thesis Sec. 2.2.3).

MSO solves the activation-mode SO problem frame by frame, but the
activations of frame ``k`` may only be those the Winters-Stark activation
dynamics (thesis Eq. A.2-A.4) can reach from frame ``k-1`` with an
excitation ``0 <= u <= 1``.  For an excitation held over the step
``dt = t_k - t_{k-1}`` the dynamics solve exactly; because the activation
rate grows with ``u``, the reachable set is the interval between the answers
for ``u = 0`` and ``u = 1``:

    a_k >= a_{k-1} exp(-dt / tau_fall)                    (u = 0: adot = -a t2)
    a_k <= 1 - (1 - a_{k-1}) exp(-dt / tau_rise)          (u = 1: adot = (1 - a)(t1 + t2))

Both bounds are linear in ``(a_{k-1}, a_k)``, which is what lets
:mod:`pinmsk.solvers.eid` put them into one sparse QP.  The excitation that
moves ``a_{k-1}`` to ``a_k`` over the step (constant within it) is recovered
exactly: in closed form when falling, by bisection of the monotone rise
solution otherwise; ``<muscle>_excitation`` channels report it at frame ``k``
(frame 0: ``u = a``, steady state).

Frame 0 is plain SO (``0 <= a <= 1``), unless ``a0`` is given.  Each frame is
one proxsuite QP (:class:`pinmsk.solvers.qp.FrameQP`, warm started).

The time constants and any electromechanical delay are the model's
(:func:`pinmsk.effects.activation.excitation_path`): its
:class:`~pinmsk.effects.ActivationDynamics` (or delay-and-activation
component) where it has one, else its muscle model's constants.  With a
delay the reported ``<muscle>_excitation`` is what a recording would show,
``u(t + delay)``: it leads the activation, and its last ``delay`` seconds are
NaN (recorded after the trial ends).  The law is :mod:`pinmsk.muscles.activation`.
"""
from __future__ import annotations

import time as _time

import numpy as np

from ..effects.activation import ExcitationPath, excitation_path
from ..errors import InfeasibleError, SolverError
from ..fitting import FitStatistics, Fitter, Result, format_report
from ..kinematics import DEFAULT_CUTOFF, as_motion
from ..muscles.activation import TAU_FALL, TAU_RISE, held_step_excitation, reachable_activation
from ..trial import Trial
from . import qp as _qp
from .static import WEIGHTS, build_problem, diagnose_infeasible, infeasible_message

__all__ = ["ModifiedStaticOptimization", "activation_bounds", "step_excitation", "excitations",
           "TAU_RISE", "TAU_FALL"]


def activation_bounds(a_prev, dt, *, tau_rise=TAU_RISE, tau_fall=TAU_FALL):
    """Reachable ``(lo, hi)`` activations after ``dt`` from ``a_prev`` (Winters-Stark, exact):
    :func:`pinmsk.muscles.activation.reachable_activation`."""
    return reachable_activation(a_prev, dt, tau_rise=tau_rise, tau_fall=tau_fall)


def step_excitation(a_prev, a_next, dt, *, tau_rise=TAU_RISE, tau_fall=TAU_FALL):
    """Constant excitation over ``dt`` that takes ``a_prev`` to ``a_next`` (Eq. A.2 solved exactly):
    :func:`pinmsk.muscles.activation.held_step_excitation`."""
    return held_step_excitation(a_prev, a_next, dt, tau_rise=tau_rise, tau_fall=tau_fall)


def excitations(time, a, *, tau_rise=TAU_RISE, tau_fall=TAU_FALL):
    """Step excitations (N, m) for activations (N, m) at ``time``; ``u_0 = a_0``.

    ``tau_rise``, ``tau_fall``: scalars or (m,) per muscle."""
    a = np.asarray(a, dtype=float)
    u = np.empty_like(a)
    u[0] = np.clip(a[0], 0.0, 1.0)
    if a.shape[0] > 1:
        dt = np.diff(np.asarray(time, dtype=float))[:, None]
        u[1:] = held_step_excitation(a[:-1], a[1:], dt, tau_rise=tau_rise, tau_fall=tau_fall)
    return u


def model_path(est, model) -> ExcitationPath:
    """The model's excitation path for MSO or EID ``est`` (refusing the old time-constant arguments)."""
    given = [k for k in ("tau_rise", "tau_fall") if getattr(est, k, None) is not None]
    if given:
        raise SolverError(
            f"{type(est).__name__}({', '.join(f'{k}=...' for k in given)}): the activation time constants "
            "are the model's activation component; add it to the model instead: "
            "model.with_effect(ActivationDynamics('muscles', tau_rise=..., tau_fall=...))")
    if model.muscles is None:
        raise SolverError(f"model '{model.name}' has no muscles; {type(est).__name__} needs a model with muscles")
    return excitation_path(model)


class ModifiedStaticOptimization(Fitter):
    """MSO: activation-mode SO whose activations obey activation dynamics between frames.

    Parameters (keyword-only): ``exponent``, ``weights`` (``S_i`` of Eq. 2.14),
    ``a0`` (activations before the first frame, (m,) or scalar; None: frame 0
    is free), ``reserves``, ``reserve_weight``, ``tol``, ``dofs`` as
    :class:`~pinmsk.solvers.static.StaticOptimization`.  The activation time
    constants are the model's (see the module notes); ``tau_rise`` and
    ``tau_fall`` are refused by name (they moved to the model's
    :class:`~pinmsk.effects.ActivationDynamics`).  ``result_`` as
    StaticOptimization's, with ``<muscle>_excitation`` channels;
    ``excitation_path_`` the :class:`~pinmsk.effects.activation.ExcitationPath` used.
    """

    def __init__(self, *, exponent: float = 2, weights: str = "none", tau_rise=None,
                 tau_fall=None, a0=None, reserves: bool = False,
                 reserve_weight: float = 1000.0, tol: float = 1e-9, dofs=None):
        self.exponent = exponent
        self.weights = weights
        self.tau_rise = tau_rise
        self.tau_fall = tau_fall
        self.a0 = a0
        self.reserves = reserves
        self.reserve_weight = reserve_weight
        self.tol = tol
        self.dofs = dofs

    def fit(self, model, trial, *, moments=None, cutoff=DEFAULT_CUTOFF, progress=None):
        """Solve frame after frame; returns ``self`` (results as StaticOptimization's, plus excitations)."""
        t0 = _time.perf_counter()
        path = model_path(self, model)
        P, prob = activation_problem(self, model, trial, moments=moments, cutoff=cutoff)
        N, nd, m = prob.A.shape
        tr, tf = path.tau_rise, path.tau_fall
        self.excitation_path_ = path
        tol = float(self.tol)
        W = float(self.reserve_weight) if self.reserves else None
        fq = _qp.FrameQP(m=m, nd=nd, weights=prob.w, exponent=P, reserve_weight=W, eps=tol * 1e-4,
                         sqp_tol=max(tol * 1e-2, 1e-13))
        x = np.zeros((N, m))
        rho = np.zeros((N, nd))
        lo_all = np.zeros((N, m))
        hi_all = np.ones((N, m))
        iters = nqp = 0
        prev = None if self.a0 is None else np.broadcast_to(np.asarray(self.a0, dtype=float), (m,))
        dts = np.diff(prob.time)
        for k in range(N):
            if prev is None:
                lo, hi = np.zeros(m), np.ones(m)
            else:
                dt = dts[k - 1] if k > 0 else (dts[0] if dts.size else 0.01)
                lo, hi = reachable_activation(prev, dt, tau_rise=tr, tau_fall=tf)
                lo = np.clip(lo, 0.0, 1.0)
                hi = np.clip(hi, lo, 1.0)
            lo_all[k], hi_all[k] = lo, hi
            sol = fq.solve(prob.A[k], prob.b[k], lo, hi)
            iters += sol.iterations
            nqp += sol.qp_solves
            if not sol.solved:
                prob_k = _bounded(prob, k, lo, hi)
                deficit = diagnose_infeasible(prob_k, [k], minmax=False, tol=tol)
                note = ("In MSO the activation dynamics limit how fast activations change: at this "
                        f"frame a_i must lie in [{', '.join(f'{v:.3g}' for v in lo)}] .. "
                        f"[{', '.join(f'{v:.3g}' for v in hi)}] ({path.describe()}).")
                raise InfeasibleError("MSO: " + infeasible_message(prob, np.array([k]), deficit, note=note))
            x[k] = np.clip(sol.x, lo, hi)      # proxsuite's answer is inside to ~1e-16
            rho[k] = sol.rho
            prev = x[k]
            if progress is not None:
                progress.update(1)
        self.bounds_ = (lo_all, hi_all)
        self.n_iter_ = iters
        self.n_qp_ = nqp
        channels = set_results(self, model, prob, x, rho, t0=t0, analysis="modified_static_optimization")
        self.result_ = result_of(self, prob, channels, objective=float(np.sum(self.cost_)),
                                 report=self._report_text())
        return self

    def _report_text(self) -> str:
        prob = self.problem_
        lo, hi = self.bounds_
        at_bound = np.sum((self.activations_ <= lo + 1e-9) & (lo > 1e-9)) + np.sum(
            (self.activations_ >= hi - 1e-9) & (hi < 1 - 1e-9))
        return format_report(
            f"Modified static optimization (activation dynamics between frames) of model '{self.model_name_}'", [
                ("criterion", f"sum_i S_i a_i^{float(self.exponent):g} (Eq. 2.14), S = {self.weights}"),
                ("dynamics", self.excitation_path_.describe()),
                ("frames", f"{prob.n_frames}, muscles {len(prob.muscles)}, dofs {', '.join(prob.dofs)}"),
                ("objective", f"sum over frames {np.sum(self.cost_):.6g}"),
                ("rate limits", f"active at {at_bound} muscle-frames"),
                ("solver", f"{self.n_qp_} proxsuite QPs, {self.n_iter_} iterations"),
                ("violation", f"max {np.max(self.violation_):.3g} N m"),
                ("time", f"{self.time_ * 1e3:.1f} ms"),
            ])


def _bounded(prob, k, lo, hi):
    import copy
    p2 = copy.copy(prob)
    p2.lo = prob.lo.copy()
    p2.hi = prob.hi.copy()
    p2.lo[k] = lo
    p2.hi[k] = hi
    return p2


def activation_problem(est, model, trial, *, moments, cutoff):
    """``(P, prob)``: the activation-mode SO problem of ``trial`` for MSO or EID ``est``, options checked."""
    if est.weights not in WEIGHTS:
        raise SolverError(f"weights must be one of {', '.join(WEIGHTS)}; got {est.weights!r}")
    P = _qp.check_exponent(est.exponent)
    motion = as_motion(model, trial, cutoff)
    prob = build_problem(model, motion, mode="activation", weights=est.weights, exponent=P,
                         dofs=est.dofs, moments=moments, reserves=est.reserves)
    return P, prob


def set_results(est, model, prob, a, rho, *, t0: float, analysis: str) -> Trial:
    """Store the activations ``a`` (N, m) and scaled reserves ``rho`` (N, nd) of MSO or EID ``est``.

    Sets ``problem_``, ``activations_``, ``forces_``, ``excitations_``,
    ``reserves_`` (None without reserves), ``violation_``, ``cost_``,
    ``time_`` (since ``t0``) and ``model_name_``; returns the result's channels
    (:func:`result_of` makes ``result_`` of them once the fitter is done).
    """
    est.problem_ = prob
    F = prob.forces(a)
    est.activations_ = a
    est.forces_ = F
    path = est.excitation_path_                  # prob.muscles are the model's, in its order
    u = excitations(prob.time, a, tau_rise=path.tau_rise, tau_fall=path.tau_fall)
    est.excitations_ = path.recorded(prob.time, u)
    est.reserves_ = rho * prob.scale if est.reserves else None
    moment = prob.moments(F) + (est.reserves_ if est.reserves else 0.0)
    est.violation_ = np.max(np.abs(moment - prob.tau), axis=1)
    est.cost_ = prob.cost(a, False)
    est.time_ = _time.perf_counter() - t0
    est.model_name_ = model.name
    return result_trial(prob, F, a, est.excitations_, est.reserves_, est.cost_, est.violation_,
                        meta={"analysis": analysis, **{k: str(v) for k, v in est.get_params(deep=False).items()}})


def result_of(est, prob, channels: Trial, *, objective: float, report: str) -> Result:
    """``result_`` of MSO or EID ``est`` after :func:`set_results`: its channels, statistics and report."""
    N, m = est.activations_.shape
    nd = len(prob.dofs)
    stats = FitStatistics(k=N * (m + (nd if est.reserves else 0)), converged=True,
                          message=f"all {N} frames solved to tol {float(est.tol):g}", iterations=est.n_iter_,
                          violation=float(np.max(est.violation_)), objective=objective)
    return Result.from_trial(channels, stats=stats, report=report)


def result_trial(prob, F, a, u, reserves, cost, violation, *, meta) -> Trial:
    """The result Trial shared by MSO and EID."""
    ch = {}
    for i, n in enumerate(prob.muscles):
        ch[f"{n}_force"] = F[:, i]
    for i, n in enumerate(prob.muscles):
        ch[f"{n}_activation"] = a[:, i]
    for i, n in enumerate(prob.muscles):
        ch[f"{n}_excitation"] = u[:, i]
    if reserves is not None:
        for j, d in enumerate(prob.dofs):
            ch[f"{d}_reserve"] = reserves[:, j]
    ch["cost"] = cost
    ch["violation"] = violation
    return Trial(prob.time, ch, meta=meta)
