"""Dynamic optimization with globally parametrized controls (thesis Sec. 3.1-3.3, 5.1).

The optimal control problem is turned into a parameter optimization: the
controls are ``s(t) = B(t) P`` for a :mod:`~pinmsk.solvers.parametrization`
(polynomial Eq. 3.2, Fourier series Eq. 3.4, or local splines) and a gradient
based optimizer (SciPy SLSQP) searches the coefficients ``P``.

Simulation designs (Sec. 5.1)
-----------------------------
``"ff"`` (fully forward)
    the signals are muscle excitations ``u``; the state ``[q, v, a(, l_ce)]``
    is integrated: activation dynamics (Eq. A.2) -> muscle force (Thelen 2003,
    rigid tendon, or compliant tendon with the contraction dynamics of
    Eq. 3.9 / A.6-A.9 and fiber lengths as states) -> skeleton (Pinocchio ABA).
``"ifm"`` (inverse-forward from muscle forces)
    the signals are muscle-tendon forces ``F`` (Eq. 5.5); only the skeleton is
    integrated (``tau = R(q)^T F``), then activations, activation rates and
    excitations come from the inverse muscle model (Fig. 5.6, Eq. 5.2-5.4,
    compliant tendon) fed with the *analytic* ``F, F', F''`` of the
    parametrization and ``l_mt, l_mt', l_mt''`` of the simulated kinematics.
    The contractile force the fiber must supply is constrained to at least
    ``F_CE_MIN`` (0.2 % of F_max) on the grid of the excitation bounds: below
    zero the inverse model switches to ``a = 0``, a kink no gradient method
    crosses.
``"ift"`` (inverse-forward from joint torques)
    the signals are joint torques; only the skeleton is integrated; muscle
    forces are the passive floor plus the torque above it shared among the
    agonists in the minimum ``sum (F_i/F_max,i)^2`` ratios, blended across zero
    torque by a softplus so that ``F, F', F''`` are exact and smooth
    (:meth:`DynamicOptimization._ift_forces`; 1-dof models, moment arms
    constant or angle-dependent with a fixed sign), then the inverse muscle
    model as in IFM.  The sharing is
    fixed, so the excitation bounds can be infeasible where IFM meets them
    (the optimizer then reports the violated bound, never a solution).

In IFM and IFT the recovered excitation contains ``df/dv`` (Eq. 5.4), and
Thelen's force-velocity slope jumps at zero velocity (5 concentric, 10
eccentric): the excitation would jump at every fiber reversal and the bound
constraints with it.  These designs therefore use the force-velocity curve
blended over ``|v/v_max| < fv_smooth`` (C2, within 1.2 % of Eq. A.9 in the
band; :func:`~pinmsk.muscles.thelen2003.thelen_force_velocity`), in the
optimization and in the reported result alike.

Integration is classical RK4 on a fixed grid of step ``step`` (excitations
and forces are evaluated analytically at the grid points and midpoints), with
all muscles -- and all parameter perturbations of a finite-difference
gradient -- vectorised in one batch.  For a fixed-base skeleton with a single
revolute joint (finger, forearm) the ABA is evaluated in closed form
``a = (tau - c1 cos q - c2 sin q) / M``, with ``M, c1, c2`` identified from
Pinocchio and verified against ``pin.aba`` at construction; any other
skeleton calls ``pin.aba`` per sample.

Excitations are clipped to [-0.2, 1.2] inside the FF simulation only to keep
infeasible iterates finite: the bounds themselves are constraints (Eq. 3.8),
and clipping exactly at 0 would make the problem non-smooth where
excitations rest on their lower bound and the compliant contraction dynamics
use ``max(a, 0.01)`` (the fiber velocity is undetermined at zero activation).

Objectives (``objective=``)
---------------------------
``{"kind": "effort", "exponent": P, "weights": "none"|"volume", "normalize": True}``
    ``J = 1/sum S_i 1/tau sum_i S_i int a_i^P dt`` (Eq. 3.5; ``normalize=False``
    drops ``1/sum S_i``, which is the ``J_1`` of Eq. 3.3).
``{"kind": "metabolic", "model": "umberger2003"|"bhargava2004"}``
    ``J = 1/sum max(E_i') 1/tau sum_i int E_i' dt`` (Eq. 3.6).  The normalizer
    ``sum_i max_t E_i'`` is taken (exact model) from the first start's initial
    guess and then held fixed, so that ``J`` stays proportional to the energy
    (the thesis's self-normalizing form would reward spikes).  The heat-rate
    models switch on ``u > a``, the sign of ``v_ce``, ``l_ce > l_opt``, ... and
    SLSQP stalls on those kinks (line-search failures), so the optimizer sees
    their C1 versions of width ``smooth`` (default 0.01; :mod:`pinmsk.energy`);
    the result reports the exact piecewise value as ``objective`` and the
    smoothed one as ``terms["J_optimized"]``.
``tracking_weight = 1 - mu`` (Eq. 3.3) adds
    ``(1 - mu) 1/(tau max theta_d^2) int (theta_s - theta_d)^2 dt`` and scales the
    physiological term by ``mu``; ``tracking_tolerance = eps`` instead imposes
    ``|theta_s - theta_d| <= eps`` on the grid (Eq. 3.7).
Excitation bounds ``0 <= u <= 1`` (Eq. 3.8) are imposed on a dense grid of
``bound_points`` times (linear constraints in FF, where they are exact).

Derivatives: central finite differences of the whole batched simulation, one
batch of ``2 n`` simulations per gradient (every parameter perturbed at
once), which costs about as much as three single simulations.  In IFM and IFT,
SLSQP works in variables preconditioned by the Gauss-Newton Hessian of the
tracking term at the start (:meth:`DynamicOptimization._preconditioner`): its
quasi-Newton Hessian starts as the identity, and without that its first steps
throw the open-loop skeleton far off the target.

An optimizer that stops without converging, or converges to a point that
violates the constraints by more than ``constraint_tol``, is flagged in the
result (``converged=False``, ``status``) and on stderr; its numbers are
never reported as a solution.

The result (``result_``) is a :class:`~pinmsk.fitting.Result`: the Trial of
``<coord>``, ``<coord>_speed``, ``<coord>_desired`` and ``<muscle>_excitation``,
``_activation``, ``_force`` on the RK4 grid; its statistics (``converged``,
``objective``, ``k`` the decision variables, ``iterations``, ``violation`` the
largest excitation-bound violation) and details (``status``, ``terms``,
``max_bound_violation``, ``max_tracking_error``, ``coeffs``,
``parametrization``, ``design``, ``q``, ``v``, ``a``, ``u``, ``force``,
``target`` as (N, .) arrays, ``seconds``, ``nit``, ``nfev``, ``starts``,
``coordinates``, ``muscles``, ``x``) are attributes of it.
:meth:`DynamicOptimization.to_dict` is the JSON summary ``pinmsk optimize`` writes.
"""
from __future__ import annotations

import json
import sys
import time as _time
from pathlib import Path

import numpy as np
import pinocchio as pin

from .. import energy
from ..effects.activation import ActivationDynamics
from ..errors import ConvergenceError, ModelError, SolverError, TrialError
from ..fitting import FitStatistics, Fitter, Result, format_report
from ..io.tables import read_trial
from ..io.toml_files import check_keys, read_toml
from ..model import Model, load_model
from ..muscles.activation import excitation_from_activation
from ..muscles.thelen2003 import GAMMA, K_PE, PASSIVE_STRAIN0, thelen_passive_force_length
from ..skeleton import rnea
from .parametrization import Fourier, Parametrization, Polynomial, Spline
from .simulation_designs import BatchMuscles, BatchSkeleton, muscle_inverse, simulate_ff, simulate_skeleton

__all__ = ["BatchSkeleton", "simulate_ff", "simulate_skeleton", "muscle_inverse",
           "DynamicOptimization", "Target",
           "load_task", "TASK_SCHEMA"]

DESIGNS = ("ff", "ifm", "ift")
FLOOR = 0.005   # IFT: muscle forces stay this fraction of F_max above the passive floor
F_CE_MIN = 0.002  # IFM: least contractile force (/ F_max), keeps the inverse model active
U_STEP = 0.1      # IFM/IFT preconditioning: excitation change (RMS) of a unit step


class _Unsimulable(SolverError):
    """A gradient was asked at a point whose own simulation fails (``x``): SLSQP accepted a
    step into such a region after its line search ran out of backtracks."""

    def __init__(self, message: str, x):
        super().__init__(message)
        self.x = x


def passive_floor(mu: BatchMuscles, l_mt, dl_mt=None, ddl_mt=None):
    """Smooth upper bound of a muscle-tendon unit's passive force, with its time derivatives.

    ``F_max (FLOOR + exp(K_PE (l - 1)/eps0) / (exp(K_PE) - 1))`` at the rigid-tendon fiber
    length ``l = sqrt((l_mt - l_slack)^2 + h^2) / l_opt``.  It exceeds the Thelen
    passive force (Eq. A.7) everywhere, because the compliant fiber is never longer
    than the rigid one and ``cos(alpha) <= 1``, and unlike Eq. A.7 it is C-infinity.
    A force above it leaves a positive contractile force, so the inverse muscle model
    (Fig. 5.6) returns ``a > 0`` and no switch to ``a = 0`` (a kink the optimizer of
    the IFM/IFT designs cannot cross).  Returns ``(F, F', F'')`` (the derivatives
    need ``dl_mt``, ``ddl_mt``; None otherwise).
    """
    x = l_mt - mu.l_slack
    l = np.sqrt(x * x + mu.h2)
    k = K_PE / PASSIVE_STRAIN0 / mu.l_opt            # d exponent / d l (1/m)
    e = mu.f_max * np.exp(K_PE / PASSIVE_STRAIN0 * (l / mu.l_opt - 1.0)) / np.expm1(K_PE)
    F = mu.f_max * FLOOR + e
    if dl_mt is None:
        return F, None, None
    dl = x * dl_mt / l
    ddl = (dl_mt * dl_mt + x * ddl_mt - dl * dl) / l
    return F, e * k * dl, e * k * (ddl + k * dl * dl)


# =============================================================================== target
class Target:
    """A desired motion ``q_d(t)`` with analytic derivatives (the tracked coordinate(s)).

    ``kind="sine"``: ``offset + amplitude sin(2 pi frequency t + phase)`` (Eq. 3.1);
    ``kind="cycle"``: ``offset + amplitude (1 - cos(2 pi t / period)) / 2``
    (a flexion-extension cycle starting and ending at ``offset``);
    ``kind="samples"``: a quintic spline through ``(time, values)``.
    """

    def __init__(self, kind: str, *, amplitude: float = 0.0, frequency: float | None = None,
                 period: float | None = None, offset: float = 0.0, phase: float = 0.0,
                 time=None, values=None):
        self.kind = kind
        self.amplitude, self.offset, self.phase = float(amplitude), float(offset), float(phase)
        if kind == "sine":
            if not (frequency and frequency > 0):
                raise ModelError("sine motion needs frequency > 0 (Hz)")
            self.frequency = float(frequency)
            self.period = 1.0 / self.frequency
        elif kind == "cycle":
            if not (period and period > 0):
                raise ModelError("cycle motion needs period > 0 (s)")
            self.period = float(period)
            self.frequency = 1.0 / self.period
        elif kind == "samples":
            from scipy.interpolate import make_interp_spline
            tt = np.asarray(time, dtype=float)
            self._spl = make_interp_spline(tt, np.asarray(values, dtype=float), k=5)
            self.period = float(tt[-1] - tt[0])
            self.frequency = 1.0 / self.period
        else:
            raise ModelError(f"unknown motion kind '{kind}'; valid: sine, cycle, samples")

    def __call__(self, t, deriv: int = 0):
        t = np.asarray(t, dtype=float)
        if self.kind == "sine":
            w = 2 * np.pi * self.frequency
            y = self.amplitude * w ** deriv * np.sin(w * t + self.phase + deriv * np.pi / 2)
            return y + (self.offset if deriv == 0 else 0.0)
        if self.kind == "cycle":
            w = 2 * np.pi / self.period
            if deriv == 0:
                return self.offset + 0.5 * self.amplitude * (1 - np.cos(w * t))
            return -0.5 * self.amplitude * w ** deriv * np.cos(w * t + deriv * np.pi / 2)
        return self._spl(t, nu=deriv)

    def peak_square(self, t):
        return float(np.max(self(t) ** 2))


# =============================================================================== problem
_OBJ_KEYS = {"kind", "exponent", "weights", "normalize", "model"}


class DynamicOptimization(Fitter):
    """Parametrized dynamic optimization of a musculoskeletal model (thesis Ch. 3).

    Arguments (stored only; :meth:`fit` solves), the model first and the rest keyword-only:

    - ``design``: ``"ff"``, ``"ifm"`` or ``"ift"`` (Sec. 5.1);
    - ``parametrization``: a :class:`Parametrization` (one per signal, shared basis);
    - ``target``: :class:`Target` for coordinate ``coordinate`` (default: the first);
    - ``duration`` (s; default: the target's period), ``step`` (RK4 step, s);
    - ``objective``: dict, see the module docstring;
    - ``tracking_weight`` (``1 - mu`` of Eq. 3.3) or ``tracking_tolerance`` (Eq. 3.7, rad);
    - ``excitation_bounds`` (0, 1), ``bound_points`` (dense constraint grid);
    - ``tendon``: ``"rigid"``/``"compliant"`` for FF (IFM/IFT always compliant);
    - ``maxiter``, ``tol`` (SLSQP ``ftol`` on the objective scaled by its value at
      the first start), ``constraint_tol``, ``n_starts``, ``n_jobs`` (parallel
      starts; once one converges the others get ``budget_factor`` times its run
      time more, then stop and count as unconverged starts), ``restarts`` (SLSQP
      restarts after a line-search failure), ``fd``
      (``"central"`` or ``"forward"``), ``fd_step`` (relative), ``smooth`` (width
      of the C1 switches of the metabolic models inside the optimization, see
      :mod:`pinmsk.energy`; 0 = exact), ``free_period`` (Fourier only: the
      period tau is one more decision variable, for non-periodic motions, Sec.
      3.3.6; the last entry of ``x`` is ``tau / tau_0``, kept within
      ``period_bounds`` times the parametrization's ``tau_0``), ``fv_smooth``
      (IFM/IFT: width of the force-velocity blend at zero velocity, in
      ``v/v_max``; see the module docstring), ``precondition`` (SLSQP in the
      variables of :meth:`_preconditioner`; default: IFM and IFT, whose open-loop
      skeleton makes the tracking error stiff in the coefficients, not FF,
      where the muscles' force-length-velocity damps it), ``progress``
      (object with ``update(n)``), ``verbose``.
    """

    def __init__(self, model, *, parametrization: Parametrization, target: Target,
                 design: str = "ff", coordinate: str | None = None, duration: float | None = None,
                 step: float = 1e-3, objective: dict | None = None,
                 tracking_weight: float | None = None, tracking_tolerance: float | None = None,
                 excitation_bounds=(0.0, 1.0), bound_points: int = 200,
                 tracking_points: int = 200, tendon: str = "rigid", maxiter: int = 200, tol: float = 1e-7,
                 constraint_tol: float = 1e-5, n_starts: int = 3, fd_step: float = 1e-6,
                 fd: str = "central", n_jobs: int = 1, restarts: int = 3,
                 budget_factor: float = 2.0, smooth: float = 0.01,
                 free_period: bool = False, period_bounds=(0.5, 2.0), fv_smooth: float = 0.02,
                 precondition: bool | None = None,
                 progress=None, verbose: bool = False):
        from ..kinematics import require_independent_joints
        require_independent_joints(model, "dynamic optimization")
        self.model = model
        self.parametrization = parametrization
        self.target = target
        self.design = design
        self.coordinate = coordinate
        self.duration = duration
        self.step = step
        self.objective = objective
        self.tracking_weight = tracking_weight
        self.tracking_tolerance = tracking_tolerance
        self.excitation_bounds = excitation_bounds
        self.bound_points = bound_points
        self.tracking_points = tracking_points
        self.tendon = tendon
        self.maxiter = maxiter
        self.tol = tol
        self.constraint_tol = constraint_tol
        self.n_starts = n_starts
        self.fd_step = fd_step
        self.fd = fd
        self.n_jobs = n_jobs
        self.restarts = restarts
        self.budget_factor = budget_factor
        self.smooth = smooth
        self.free_period = free_period
        self.period_bounds = period_bounds
        self.fv_smooth = fv_smooth
        self.precondition = precondition
        self.progress = progress
        self.verbose = verbose

    # -- setup -----------------------------------------------------------------
    def _setup(self):
        model = self.model
        if self.design not in DESIGNS:
            raise ModelError(f"unknown design '{self.design}'; valid: {', '.join(DESIGNS)}")
        other = [c.label for c in model.components if type(c) is not ActivationDynamics]
        if other:
            raise ModelError(f"model '{model.name}' has components ({', '.join(other)}); dynamic "
                             "optimization does not include effects, delays or contacts yet (it honours "
                             "activation_dynamics: its time constants drive the excitation-activation step)")
        self._mu = BatchMuscles(model)
        self._sk = BatchSkeleton(model)
        nv, m = model.nv, self._mu.m
        self._jc = model.coordinate_index(self.coordinate or model.coordinates[0])
        T = float(self.duration or self.target.period)
        n = max(int(np.ceil(T / self.step)), 4)
        self._t = np.linspace(0.0, T, n + 1)
        tm = 0.5 * (self._t[1:] + self._t[:-1])
        par = self.parametrization
        self._B = par.basis(self._t)
        self._Bm = par.basis(tm)
        self._qd = self.target(self._t)
        q0 = np.zeros(nv)
        v0 = np.zeros(nv)
        q0[self._jc] = self.target(0.0)
        v0[self._jc] = self.target(0.0, 1)
        self._q0, self._v0 = q0, v0
        obj = dict(self.objective or {"kind": "effort", "exponent": 2, "weights": "none",
                                      "normalize": True})
        bad = set(obj) - _OBJ_KEYS
        if bad:
            raise ModelError(f"unknown objective key(s) {sorted(bad)}; valid: {sorted(_OBJ_KEYS)}")
        kind = obj.get("kind", "effort")
        if kind not in ("effort", "metabolic"):
            raise ModelError(f"unknown objective kind '{kind}'; valid: effort, metabolic")
        if kind == "effort":
            w = obj.get("weights", "none")
            if w not in ("none", "volume"):
                raise ModelError(f"objective weights must be 'none' or 'volume', not {w!r}")
            S = np.ones(m) if w == "none" else np.asarray(self._mu.ms.volume, dtype=float)
            self._S = S / S.sum() if obj.get("normalize", True) else S
            self._P = float(obj.get("exponent", 2))
        else:
            mm = obj.get("model", "umberger2003")
            if mm not in ("umberger2003", "bhargava2004"):
                raise ModelError(f"metabolic model must be umberger2003 or bhargava2004, not {mm!r}")
            self._metab = mm
            self._E_norm = None
        self._kind = kind
        if self.tracking_weight is None and self.tracking_tolerance is None:
            raise ModelError("give tracking_weight (1 - mu, Eq. 3.3) or tracking_tolerance "
                             "(rad, Eq. 3.7): the motion must be tracked")
        if self.tracking_weight is not None and not 0 <= self.tracking_weight <= 1:
            raise ModelError(f"tracking_weight must be in [0, 1], got {self.tracking_weight}")
        lo, hi = map(float, self.excitation_bounds)
        if not lo < hi:
            raise ModelError(f"excitation bounds {self.excitation_bounds} are empty: lower must be "
                             "below upper (the problem would be infeasible)")
        self._lo, self._hi = lo, hi
        nb = min(self.bound_points, self._t.size)
        self._ib = np.unique(np.linspace(0, self._t.size - 1, nb).round().astype(int))
        self._ibt = np.unique(np.linspace(0, self._t.size - 1, min(self.tracking_points, self._t.size)).round().astype(int))
        if self.tracking_tolerance is not None and not self.tracking_tolerance > 0:
            raise ModelError(f"tracking_tolerance must be > 0 rad, got {self.tracking_tolerance} "
                             "(the problem would be infeasible)")
        # signal scaling: decision variables are O(1) at the scale of what the motion needs
        # (the inverse dynamics of the target), not of what the muscles could give
        self._tau_target = self._target_torque()
        tau_peak = float(np.max(np.abs(self._tau_target[:, self._jc])))
        if self.design == "ff":
            self._n_sig, self._scale = m, np.ones(m)
        elif self.design == "ifm":
            r_max = float(np.max(np.abs(self._mu.path.moment_arms(self._q0[None])[0])))
            self._floor = self._force_floor(self._t)          # (N, m), also the starts' base
            self._n_sig, self._scale = m, self._floor.max(axis=0) + tau_peak / max(r_max, 1e-9)
        else:
            if nv != 1:
                raise ModelError(f"design 'ift' shares one joint torque among the muscles: it "
                                 f"needs a 1-dof model ('{model.name}' has {nv}); use 'ifm'")
            self._ift_arms()
            tau_cap = float(np.sum(self._r_max * self._mu.f_max))
            self._n_sig, self._scale = 1, np.array([max(tau_peak, 1e-3 * tau_cap)])
            self._soft = 0.01 * tau_cap       # softplus width of the agonist sharing (N m)
        self._npar = par.n_params * self._n_sig
        self._nx = self._npar
        if self.free_period:
            if not isinstance(par, Fourier):
                raise ModelError(f"free_period needs a Fourier parametrization, not {par!r}")
            plo, phi = map(float, self.period_bounds)
            if not 0 < plo <= 1 <= phi:
                raise ModelError(f"period_bounds {self.period_bounds} must satisfy "
                                 "0 < lower <= 1 <= upper (factors on the nominal period)")
            self._nx = self._npar + 1
        self._rows_period = None
        self._cache = {}
        self._gcache = {}
        self._c_size = None
        self.n_sim_ = 0

    # -- evaluation ------------------------------------------------------------
    def _coeffs(self, X):
        """(B, npar) decision vectors -> (B, n_params, n_sig) coefficients."""
        X = np.atleast_2d(X)[:, : self._npar]
        return X.reshape(X.shape[0], self.parametrization.n_params, self._n_sig) * self._scale

    def _periods(self, X):
        """(B,) Fourier periods of the decision vectors with ``free_period``, else None."""
        if not self.free_period:
            return None
        plo, phi = map(float, self.period_bounds)
        # SLSQP may step outside the (linear) period bounds: keep such iterates finite
        f = np.clip(np.atleast_2d(X)[:, self._npar], 0.5 * plo, 2.0 * phi)
        return f * self.parametrization.period

    def _signals(self, C, deriv=0, where="grid", t=None):
        periods = self._rows_period
        if t is None:
            t = self._t if where == "grid" else 0.5 * (self._t[1:] + self._t[:-1])
            if deriv == 0 and periods is None:
                return np.einsum("np,bps->nbs", {"grid": self._B, "mid": self._Bm}[where], C)
        if periods is None:
            return np.einsum("np,bps->nbs", self.parametrization.basis(t, deriv), C)
        # free period: one basis per distinct period (a gradient batch has at most three)
        out = np.empty((t.size, C.shape[0], C.shape[2]))
        for tau in np.unique(periods):
            rows = periods == tau
            Bt = self.parametrization.with_period(float(tau)).basis(t, deriv)
            out[:, rows] = np.einsum("np,bps->nbs", Bt, C[rows])
        return out

    def simulate(self, X) -> dict:
        """Batched simulation of decision vectors ``X`` (B, npar): dict of (N, B, ...) arrays."""
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return self._simulate(X)

    def _simulate(self, X) -> dict:
        C = self._coeffs(X)
        self._rows_period = self._periods(X)
        self.n_sim_ += C.shape[0]
        if self.design == "ff":
            sim = simulate_ff(self.model, self._t, self._signals(C), self._signals(C, where="mid"),
                              self._q0, self._v0, tendon=self.tendon, skeleton=self._sk,
                              muscles=self._mu)
            sim["u_raw"] = self._signals(C)
            return sim
        n, B = self._t.size, C.shape[0]
        if self.design == "ifm":
            F, Fm = self._signals(C), self._signals(C, where="mid")
            q, v, acc = simulate_skeleton(self.model, self._t, None, None, self._q0, self._v0,
                                          skeleton=self._sk, muscles=self._mu,
                                          forces=F, forces_mid=Fm)
            dF, ddF = self._signals(C, 1), self._signals(C, 2)
        else:
            tau, taum = self._signals(C), self._signals(C, where="mid")
            q, v, acc = simulate_skeleton(self.model, self._t, tau, taum, self._q0, self._v0,
                                          skeleton=self._sk)
            F, dF, ddF = self._ift_forces(q, v, acc, tau, self._signals(C, 1),
                                          self._signals(C, 2))
        flat = lambda x: x.reshape(n * B, -1)   # noqa: E731
        mu = self._mu
        inv = muscle_inverse(self.model, flat(q), flat(v), flat(acc), flat(F), flat(dF), flat(ddF),
                             muscles=mu, fv_smooth=self.fv_smooth, fiber_floor=1e-3 * mu.l_opt)
        sim = {"q": q, "v": v, "acc": acc, "force": F}
        for k in ("a", "u", "l_ce", "v_ce"):
            sim[k] = inv[k].reshape(n, B, -1)
        sim["u_raw"] = sim["u"]
        d = sim["l_ce"] / mu.l_opt - 1.0
        sim["f_isom"] = np.exp(d * d * (-1.0 / GAMMA))
        x = np.sqrt(np.maximum(sim["l_ce"] ** 2 - mu.h2, 1e-12))
        # normalized contractile force demanded of the fiber (Fig. 5.6 step 3), unclipped
        sim["f_ce_raw"] = (F * sim["l_ce"] / x) / mu.f_max \
            - thelen_passive_force_length(sim["l_ce"] / mu.l_opt)
        sim["f_ce"] = mu.f_max * np.maximum(sim["f_ce_raw"], 0.0)
        return sim

    def _ift_arms(self):
        """Agonist groups of IFT: each muscle's moment-arm sign, which must hold over the
        reachable angles (target +- 0.5 rad), and its largest arm there (m)."""
        qd = self.target(self._t)
        Q = np.tile(self._q0, (qd.size * 3, 1))
        Q[:, self._jc] = np.concatenate([qd - 0.5, qd, qd + 0.5])
        r = self._mu.path.moment_arms(Q)[:, :, 0]
        sign = np.sign(r[qd.size])                        # at the start of the motion
        flips = np.any(np.sign(r) != sign, axis=0) | (sign == 0)
        if np.any(flips):
            bad = ", ".join(n for n, f in zip(self.model.muscle_names, flips) if f)
            raise ModelError(f"design 'ift': the moment arm of {bad} changes sign (or is 0) within "
                             "0.5 rad of the motion, so no fixed agonist sharing exists; use 'ifm'")
        if not (np.any(sign > 0) and np.any(sign < 0)):
            raise ModelError("design 'ift' needs agonists on both sides of the joint (moment "
                             "arms of both signs); use 'ifm'")
        self._pos = sign > 0
        self._r_max = np.max(np.abs(r), axis=0)

    def _ift_share(self, q, v, acc):
        """Sharing ratios ``S(q) = w r / sum_agonists w r^2`` (``w = F_max^2``: minimum
        ``sum (F/F_max)^2``), for both agonist groups in one array, with ``dS/dt`` and
        ``d2S/dt2`` along the motion; also ``r, dr/dt, d2r/dt2``.  Inputs (K,) angles etc."""
        path, w = self._mu.path, self._mu.f_max ** 2
        Q = q[:, None]
        r = path.moment_arms(Q)[:, :, 0]
        r1 = path.moment_arm_derivative(Q, 1)[:, :, 0]
        r2 = path.moment_arm_derivative(Q, 2)[:, :, 0]
        g = self._pos[None, :]

        def group_sum(x):   # each muscle gets the sum over its own agonist group
            return np.where(g, np.sum(np.where(g, x, 0.0), axis=1, keepdims=True),
                            np.sum(np.where(g, 0.0, x), axis=1, keepdims=True))

        D = group_sum(w * r * r)
        D1 = group_sum(2.0 * w * r * r1)
        D2 = group_sum(2.0 * w * (r1 * r1 + r * r2))
        S = w * r / D
        Sq = w * (r1 * D - r * D1) / D ** 2
        Sqq = w * ((r2 * D - r * D2) / D ** 2 - 2.0 * (r1 * D - r * D1) * D1 / D ** 3)
        vv, aa = v[:, None], acc[:, None]
        return (S, Sq * vv, Sqq * vv * vv + Sq * aa,
                r, r1 * vv, r2 * vv * vv + r1 * aa)

    def _ift_forces(self, q, v, acc, tau, dtau, ddtau):
        """IFT muscle forces ``F, F', F''`` (N, B, m) from the joint torque and its exact derivatives.

        ``F = F_floor + S+ phi(tau') + S- (tau' - phi(tau'))`` with ``tau' = tau - r.F_floor``
        and ``phi(x) = c log(1 + exp(x/c))``: the torque above the passive floor
        (:func:`passive_floor`) goes to the agonists in the minimum ``sum (F_i/F_max,i)^2``
        ratios ``S+(q)`` (flexion) or ``S-(q)`` (extension), blended by the softplus ``phi``
        of width ``c`` (a co-contraction of ``c log 2`` at zero torque) so that ``F`` is
        C-infinity in ``tau``; ``r(q).F = tau`` exactly.  1-dof; the moment arms may depend
        on the angle (their derivatives enter ``F'`` and ``F''`` through ``q', q''``).
        """
        mu, c, m = self._mu, self._soft, self._mu.m
        shp = q.shape[:2]
        qf, vf, af = (x[..., 0].reshape(-1) for x in (q, v, acc))
        Fl, dFl, ddFl = passive_floor(mu, mu.lengths(qf[:, None]), mu.velocities(qf[:, None], vf[:, None]),
                                      mu.path.accelerations(qf[:, None], vf[:, None], af[:, None]))
        S, dS, ddS, r, dr, ddr = self._ift_share(qf, vf, af)
        pos = self._pos
        Sp, Sn = np.where(pos, S, 0.0), np.where(pos, 0.0, S)
        dSp, dSn = np.where(pos, dS, 0.0), np.where(pos, 0.0, dS)
        ddSp, ddSn = np.where(pos, ddS, 0.0), np.where(pos, 0.0, ddS)
        t0, t1, t2 = (x.reshape(-1) for x in (tau[..., 0], dtau[..., 0], ddtau[..., 0]))
        x = (t0 - np.sum(r * Fl, axis=1)) / c
        dx = (t1 - np.sum(dr * Fl + r * dFl, axis=1)) / c
        ddx = (t2 - np.sum(ddr * Fl + 2.0 * dr * dFl + r * ddFl, axis=1)) / c
        sig = (0.5 * (1.0 + np.tanh(0.5 * x)))[:, None]   # phi'(x c) = sigmoid(x)
        phi = (c * np.logaddexp(0.0, x))[:, None]
        psi = c * x[:, None] - phi
        x, dx, ddx = x[:, None], dx[:, None], ddx[:, None]
        d2 = sig * (1.0 - sig) * dx * dx
        F = Fl + Sp * phi + Sn * psi
        dF = dFl + dSp * phi + dSn * psi + c * (Sp * sig + Sn * (1.0 - sig)) * dx
        ddF = (ddFl + ddSp * phi + ddSn * psi
               + 2.0 * c * (dSp * sig + dSn * (1.0 - sig)) * dx
               + c * (Sp * sig + Sn * (1.0 - sig)) * ddx + c * (Sp - Sn) * d2)
        return tuple(y.reshape(shp + (m,)) for y in (F, dF, ddF))

    def _force_floor(self, t):
        """IFM starting forces (N, m): :func:`passive_floor` at the worst angle within the
        tracking band ``q_d(t) +- tolerance`` (0.1 rad with a tracking weight), so that the
        starts lie in the active region of the inverse model."""
        band = self.tracking_tolerance if self.tracking_tolerance is not None else 0.1
        qd = self.target(np.clip(t, self._t[0], self._t[-1]))
        out = None
        for dq in np.linspace(-band, band, 5):
            Q = np.tile(self._q0, (t.size, 1))
            Q[:, self._jc] = qd + dq
            F = passive_floor(self._mu, self._mu.lengths(Q))[0]
            out = F if out is None else np.maximum(out, F)
        return out

    def _integral(self, y):
        """(1/tau) int y dt over the grid, y (N, B, ...) -> (B, ...)."""
        T = self._t[-1] - self._t[0]
        return np.trapezoid(y, self._t, axis=0) / T

    def _terms(self, sim, exact: bool = False) -> dict:
        a = sim["a"]
        if self._kind == "effort":
            phys = self._integral(np.maximum(a, 0.0) ** self._P) @ self._S
        else:
            E = self._energy(sim, 0.0 if exact else float(self.smooth))   # (N, B, m)
            if self._E_norm is None:   # from the exact model, so J does not depend on `smooth`
                E0 = E if exact else self._energy(sim, 0.0)
                self._E_norm = float(np.sum(np.max(E0[:, 0, :], axis=0)))
            phys = self._integral(E).sum(axis=-1) / self._E_norm
        err = sim["q"][:, :, self._jc] - self._qd[:, None]
        track = self._integral(err ** 2) / self.target.peak_square(self._t)
        return {"physiological": phys, "tracking": track, "max_error": np.max(np.abs(err), axis=0)}

    def _energy(self, sim, w: float = 0.0):
        """Metabolic rates (N, B, m): exact (``w = 0``, reported) or with the C1 switches
        of width ``w`` (optimized; :mod:`pinmsk.energy`), u and a clipped to [0, 1] alike."""
        mu = self._mu
        kw = dict(u=energy.smooth_clip(sim["u"], 0.0, 1.0, w),
                  a=energy.smooth_clip(sim["a"], 0.0, 1.0, w), l_ce=sim["l_ce"],
                  v_ce=sim["v_ce"], f_ce=sim["f_ce"], f_isom=sim["f_isom"], l_opt=mu.l_opt,
                  f_max=mu.f_max, fast_fraction=mu.ms.fast_fraction, smooth=w)
        if self._metab == "bhargava2004":
            n, B, m = sim["u"].shape
            ts = energy.stimulation_time(self._t, sim["u"].reshape(n, B * m),
                                         smooth=w).reshape(n, B, m)
            return energy.bhargava2004(**kw, t_stim=ts)["total"]
        return energy.umberger2003(**kw)["total"]

    def _objective_of(self, terms):
        if self.tracking_weight is not None:
            w = self.tracking_weight
            return (1.0 - w) * terms["physiological"] + w * terms["tracking"]
        return terms["physiological"]

    def _constraints_of(self, sim):
        """Nonlinear inequality constraints g >= 0, (B, nc)."""
        cons = []
        if self.design != "ff":   # bounds on the recovered excitation
            u = sim["u"][self._ib]                           # (nb, B, m)
            cons += [np.moveaxis(u - self._lo, 1, 0).reshape(u.shape[1], -1),
                     np.moveaxis(self._hi - u, 1, 0).reshape(u.shape[1], -1)]
        if self.design == "ifm":  # active region of the inverse model: f_ce >= F_CE_MIN (smooth)
            f = sim["f_ce_raw"][self._ib] - F_CE_MIN
            cons.append(np.moveaxis(10.0 * f, 1, 0).reshape(f.shape[1], -1))
        if self.tracking_tolerance is not None:
            err = sim["q"][self._ibt, :, self._jc] - self._qd[self._ibt, None]
            eps = self.tracking_tolerance        # scaled to O(1): 1 - |err|/eps >= 0
            cons += [(1.0 - err / eps).T, (1.0 + err / eps).T]
        if not cons:
            return None
        return np.concatenate(cons, axis=1)

    def _value(self, x):
        """``(f, c)`` at one decision vector (one simulation), cached."""
        key = x.tobytes()
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        try:
            sim = self.simulate(x[None, :])
        except (TrialError, ConvergenceError) as exc:
            # e.g. the inverse muscle model has no fiber state at a wild iterate: a
            # large objective and violated constraints make the line search back off.
            if self._c_size is None:
                raise
            self._last_failure = str(exc)
            return (1e6 * getattr(self, "_f_ref", 1.0),
                    None if self._c_size == 0 else -np.ones(self._c_size))
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # blow-ups are caught below
            f = float(self._objective_of(self._terms(sim))[0])
            c = self._constraints_of(sim)
        if not np.isfinite(f) or (c is not None and not np.all(np.isfinite(c))):
            # the simulation blew up (state went non-finite): penalize like a failure
            if self._c_size is None:
                raise SolverError("the simulation of the initial guess is not finite; "
                                  "reduce the step or change the start")
            self._last_failure = "the state went non-finite"
            return (1e6 * getattr(self, "_f_ref", 1.0),
                    None if self._c_size == 0 else -np.ones(self._c_size))
        self._c_size = 0 if c is None else c.shape[1]
        out = (f, None if c is None else c[0])
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[key] = out
        return out

    def _rows(self, X):
        """Objective and constraints ``(f (B,), c (B, nc) or None)`` of decision vectors ``X``,
        one batch; non-finite where a simulation failed or blew up (then row by row, so that
        one bad perturbation does not spoil the others)."""
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            try:
                sim = self.simulate(X)
                return self._objective_of(self._terms(sim)), self._constraints_of(sim)
            except (TrialError, ConvergenceError):
                pass
            f = np.full(X.shape[0], np.nan)
            c = None if not self._c_size else np.full((X.shape[0], self._c_size), np.nan)
            for b in range(X.shape[0]):
                try:
                    sim = self.simulate(X[b:b + 1])
                except (TrialError, ConvergenceError):
                    continue
                f[b] = self._objective_of(self._terms(sim))[0]
                if c is not None:
                    c[b] = self._constraints_of(sim)[0]
            return f, c

    def _gradient(self, x):
        """``(df/dx, dc/dx)`` by finite differences, all perturbations in one batch.

        Central differences; where one side of a perturbation fails (the inverse muscle
        model has no fiber state there, or the simulation blows up) the other side is
        used one-sided, so an iterate near such a region keeps a usable gradient."""
        key = x.tobytes()
        hit = self._gcache.get(key)
        if hit is not None:
            return hit
        f0, c0 = self._value(x)
        if key not in self._cache:
            # _value caches successes only: x itself did not simulate, and f0, c0 are the
            # penalty, not values to difference against
            raise _Unsimulable("the simulation fails at the current point ("
                               f"{self._last_failure})", x)
        h = self.fd_step * np.maximum(1.0, np.abs(x))
        n = x.size
        central = self.fd == "central"
        X = np.vstack([x + np.diag(h), x - np.diag(h)]) if central else x + np.diag(h)
        f, c = self._rows(X)
        fp, fm = f[:n], (f[n:] if central else np.full(n, np.nan))
        cp = None if c is None else c[:n]
        cm = None if c is None else (c[n:] if central else np.full_like(cp, np.nan))

        def ok(fv, cv):
            good = np.isfinite(fv)
            return good if cv is None else good & np.all(np.isfinite(cv), axis=1)

        okp, okm = ok(fp, cp), ok(fm, cm)
        if not np.all(okp | okm):
            raise SolverError("a finite-difference simulation failed on both sides of the "
                              "current point (non-finite state or no fiber state); reduce "
                              "the step or change the start")
        both = okp & okm
        w = np.where(both, 2.0 * h, h)                    # (f+ - f-)/2h, (f+ - f0)/h, (f0 - f-)/h
        hi = np.where(okp, fp, f0)
        lo = np.where(both | ~okp, np.where(okm, fm, f0), f0)
        g = (hi - lo) / w
        dc = None
        if c is not None:
            chi = np.where(okp[:, None], cp, c0[None, :])
            clo = np.where((both | ~okp)[:, None], np.where(okm[:, None], cm, c0[None, :]), c0[None, :])
            dc = ((chi - clo) / w[:, None]).T
        self._gcache.clear()
        self._gcache[key] = (g, dc)
        if self.progress is not None:
            self.progress.update(1)
        return g, dc

    # -- initial guesses (Sec. 3.5.3) -------------------------------------------
    def _target_states(self):
        """``(q, v, a)`` (N, nv) of the target motion on the grid (other coordinates at rest)."""
        t, nv = self._t, self.model.nv
        q = np.tile(self._q0, (t.size, 1))
        v, acc = np.zeros((t.size, nv)), np.zeros((t.size, nv))
        q[:, self._jc] = self._qd
        v[:, self._jc] = self.target(t, 1)
        acc[:, self._jc] = self.target(t, 2)
        return q, v, acc

    def _target_torque(self):
        """Inverse dynamics (N, nv) of the target motion: what the muscles must supply."""
        return rnea(self.model, *self._target_states())

    def initial_guesses(self) -> list[np.ndarray]:
        """Cheap starts: inverse dynamics of the target, minimum-effort sharing, inverse
        activation dynamics with analytic derivatives -> least-squares fits of the parametrization."""
        par, mu, t = self.parametrization, self._mu, self._t
        tau = self._tau_target
        q, v = self._target_states()[:2]
        guesses = []
        if self.design == "ift":
            # one start: the torque is fixed by the motion, only the fit error is left
            return [(par.fit(t, tau) / self._scale).ravel()]
        # minimum sum (a/.)^2 sharing among agonists with a rigid tendon (closed form, 1 dof)
        l_mt = mu.lengths(q)
        v_mt = mu.velocities(q, v)
        F1, *_ = mu.rigid(np.ones_like(l_mt), l_mt, v_mt)
        F0, *_ = mu.rigid(np.zeros_like(l_mt) + 1e-9, l_mt, v_mt)
        Fa = np.maximum(F1 - F0, 1e-6)
        R = mu.R if mu.constant_arms else mu.path.moment_arms(q)[:, :, 0]
        R = np.broadcast_to(R[:, 0] if R.ndim == 2 and R.shape[0] == mu.m else R, l_mt.shape)
        need = tau[:, [0]] - np.sum(R * F0, axis=1, keepdims=True)
        S = np.ones(mu.m) if self._kind != "effort" else np.maximum(self._S, 1e-12) / self._S.max()
        g = R * Fa / S                                     # a_i = lam * g_i for agonists
        ag = np.sign(R) == np.sign(need)
        lam = need[:, 0] / np.maximum(np.sum(np.where(ag, R * Fa * g, 0.0), axis=1), 1e-12)
        act = np.clip(np.where(ag, lam[:, None] * g, 0.0), 0.0, 1.0)
        if self.design == "ifm":
            # forces above the passive floor (the active region of the inverse model), the
            # agonists' share of the rest of the moment, then 0, 2 and 5 % co-contraction
            # of zero net moment: every start tracks the target equally well
            Fl = self._floor
            need = tau[:, [0]] - np.sum(R * Fl, axis=1, keepdims=True)
            ag = np.sign(R) == np.sign(need)
            lam = need[:, 0] / np.maximum(np.sum(np.where(ag, R * Fa * g, 0.0), axis=1), 1e-12)
            Fg = Fl + np.where(ag, lam[:, None] * g, 0.0) * Fa
            tr = R * mu.f_max
            pos = np.where(R > 0, mu.f_max / np.sum(np.where(R > 0, tr, 0.0), axis=1, keepdims=True), 0.0)
            neg = np.where(R < 0, mu.f_max / np.sum(np.where(R < 0, -tr, 0.0), axis=1, keepdims=True), 0.0)
            cap = np.sum(np.abs(tr), axis=1, keepdims=True)
            return [(par.fit(t, Fg + gam * cap * (pos + neg)) / self._scale).ravel()
                    for gam in (0.0, 0.02, 0.05)][: self.n_starts]
        ca = par.fit(t, act)
        a_fit = par.evaluate(ca, t)
        adot = par.evaluate(ca, t, 1)
        u = excitation_from_activation(np.clip(a_fit, 0, 1), adot, tau_rise=mu.tau_rise,
                                       tau_fall=mu.tau_fall)
        lo, hi = self._lo, self._hi
        span = hi - lo
        u1 = np.clip(u, lo + 0.02 * span, hi - 0.02 * span)
        guesses.append(par.fit(t, u1).ravel())
        guesses.append(par.constant(lo + 0.05 * span, mu.m).ravel())
        guesses.append(par.fit(t, np.clip(act, lo + 0.02 * span, hi - 0.02 * span)).ravel())
        return guesses[: self.n_starts]

    # -- solve -------------------------------------------------------------------
    def fit(self, x0=None):
        """Solve from ``x0`` -- a decision vector, or (k, n) for k starts (e.g. the ``x`` of
        another result as a warm start) -- or from the multi-start guesses; returns ``self``.

        With ``n_jobs > 1`` the starts run in parallel worker processes (fork).  BLAS runs
        on one thread: its products here are small (a few hundred rows), where threads only
        add overhead -- and oversubscribe the cores when the starts run in parallel -- and
        one thread makes the result the same on every machine."""
        from threadpoolctl import threadpool_limits
        with threadpool_limits(limits=1):
            return self._fit(x0)

    def _fit(self, x0):
        t0 = _time.perf_counter()
        self._setup()
        if x0 is None:
            starts = self.initial_guesses()
            if self.free_period:   # start at the nominal period
                starts = [np.append(xs, 1.0) for xs in starts]
        else:
            x0 = np.asarray(x0, dtype=float)
            starts = [x0.ravel()] if x0.ndim == 1 else [row for row in x0]
            if any(xs.size != self._nx for xs in starts):
                raise ModelError(f"x0 must hold {self._nx} values per start (n_params x "
                                 f"n_signals{', + 1 period factor' if self.free_period else ''}); "
                                 f"got shape {x0.shape}")
        self._A_lin = None
        if True:
            # Linear constraints on the signals over a dense grid: FF 0 <= u <= 1 (Eq. 3.8);
            # IFM 0 <= F <= 1.5 F_max (a pulling muscle below the eccentric plateau; keeps
            # the inverse model's tendon within its range at wild iterates); IFT the
            # torque range those forces span.
            nb = self.bound_points
            if self.free_period:
                # the grid of times moves with the period: bound the signals over all the
                # phases of one period instead (linear and period-independent; conservative
                # when the motion lasts less than a period)
                Bd = self.parametrization.basis(np.linspace(0.0, self.parametrization.period, nb))
            else:
                Bd = self.parametrization.basis(np.linspace(self._t[0], self._t[-1], nb))
            self._A_lin = np.kron(Bd, np.eye(self._n_sig))  # rows (time, signal); x is (p, s) row-major
            if self.design == "ff":
                self._lin_lo = np.full(self._A_lin.shape[0], self._lo)
                self._lin_hi = np.full(self._A_lin.shape[0], self._hi)
            elif self.design == "ifm":
                self._lin_lo = np.zeros(self._A_lin.shape[0])
                self._lin_hi = np.tile(1.5 * self._mu.f_max / self._scale, nb)
            else:   # IFT: the torque the muscles can give, 1.5 F_max each at their largest arm
                cap = 1.5 * self._mu.f_max * self._r_max
                self._lin_lo = np.full(nb, -cap[~self._pos].sum() / self._scale[0])
                self._lin_hi = np.full(nb, cap[self._pos].sum() / self._scale[0])
            if self.free_period:   # one more column (the period factor) and its bounds
                A = self._A_lin
                self._A_lin = np.vstack([np.hstack([A, np.zeros((A.shape[0], 1))]),
                                         np.eye(1, A.shape[1] + 1, A.shape[1])])
                plo, phi = map(float, self.period_bounds)
                self._lin_lo = np.append(self._lin_lo, plo)
                self._lin_hi = np.append(self._lin_hi, phi)
        # Objective scaled by its value at the first start (SLSQP's ftol is absolute).
        self._f_ref = max(abs(self._value(starts[0])[0]), 1e-6)
        if self.n_jobs > 1 and len(starts) > 1 and sys.platform != "win32":
            import multiprocessing as mp
            global _ACTIVE
            _ACTIVE = self
            ctx = mp.get_context("fork")
            # Shared wall-clock deadline: when a start converges, the others get at most
            # ``budget_factor`` times its run time more (their SLSQP callback stops them).
            self._deadline = ctx.Value("d", float("inf"))
            prog, self.progress = self.progress, None
            try:
                with ctx.Pool(min(self.n_jobs, len(starts))) as pool:
                    outs = pool.map(_run_start, list(enumerate(starts)))
            finally:
                _ACTIVE = None
                self.progress = prog
                self._deadline = None
        else:
            outs = [self._solve_start(k, xs) for k, xs in enumerate(starts)]
        best = None
        records = []
        for x, rec in outs:
            records.append(rec)
            if self.verbose:
                print(f"  start {rec['start']}: {rec}", file=sys.stderr)
            if x is None:
                continue
            ok = rec["ok"]
            key = (0 if ok else 1, rec["objective"] if ok else rec["violation"] + rec["objective"])
            if best is None or key < best[0]:
                best = (key, x, rec)
        if best is None:
            raise SolverError("every start of the dynamic optimization failed: "
                              + "; ".join(r["message"] for r in records))
        _, x, rec = best
        self.result_ = self._result(x, rec, records, _time.perf_counter() - t0)
        if not self.result_.stats.converged:
            print(f"pinmsk: WARNING dynamic optimization did not converge ({self.result_.status}); "
                  "the result is not a solution", file=sys.stderr)
        return self

    def _preconditioner(self, xs):
        """``M`` with ``x = xs + M y``: SLSQP works on ``y``.

        SLSQP's quasi-Newton Hessian starts as the identity, but the tracking error of
        an open-loop simulation is far more sensitive to some coefficient directions
        than to others (torques and forces are integrated twice in IFT/IFM), so its
        first steps throw the motion off the target.  ``M = L^-T`` with
        ``L L^T = I + H_t``, ``H_t`` the Gauss-Newton Hessian of the tracking term at
        the start (scaled like the objective with a tracking weight; with a tracking
        tolerance ``eps``, scaled so that a unit step moves the RMS error by ``eps``),
        makes that Hessian the identity; directions the tracking ignores keep their
        scale."""
        n = xs.size
        h = self.fd_step * np.maximum(1.0, np.abs(xs))
        try:
            sim = self.simulate(np.vstack([xs + np.diag(h), xs - np.diag(h)]))
        except (TrialError, ConvergenceError):
            return np.eye(n)
        q = sim["q"][self._ibt, :, self._jc]                    # (nt, 2n)
        J = (q[:, :n] - q[:, n:]) / (2.0 * h)
        if not np.all(np.isfinite(J)):
            return np.eye(n)
        if self.tracking_weight is not None:
            peak = self.target.peak_square(self._t)
            Ht = (self.tracking_weight * 2.0 / (peak * self._f_ref * J.shape[0])) * (J.T @ J)
        else:
            Ht = (J.T @ J) / (J.shape[0] * self.tracking_tolerance ** 2)
        if self.design != "ff":
            # the recovered excitations contain F'' (Eq. 5.4): as stiff in the coefficients
            # as the tracking, so a unit step should move them by U_STEP RMS at most
            u = sim["u"][self._ib].reshape(self._ib.size, 2 * n, -1)
            Ju = np.moveaxis((u[:, :n] - u[:, n:]) / (2.0 * h[:, None]), 1, 2).reshape(-1, n)
            if np.all(np.isfinite(Ju)):
                Ht = Ht + (Ju.T @ Ju) / (Ju.shape[0] * U_STEP ** 2)
        L = np.linalg.cholesky(np.eye(n) + Ht)
        return np.linalg.inv(L).T

    def _solve_start(self, k, xs):
        """SLSQP in preconditioned variables (:meth:`_preconditioner`) from ``xs``: ``(x, record)``.

        After a line-search failure (status 8; also a step SLSQP accepted into a region
        where the simulation fails, see :class:`_Unsimulable`) or incompatible linearized
        constraints (4) SLSQP restarts -- with a fresh quasi-Newton Hessian, from the best
        point seen (feasible and lowest, else least infeasible) -- while that still improves
        it, at most ``restarts`` times; when the failed run had wandered off (ended worse
        than that best point) the restart takes steps a third as large."""
        from scipy.optimize import minimize
        fs = 1.0 / self._f_ref
        pre = self.design != "ff" if self.precondition is None else self.precondition
        A = self._A_lin
        opts = {"maxiter": self.maxiter, "ftol": self.tol}
        ts = _time.perf_counter()
        deadline = getattr(self, "_deadline", None)
        stopped = []
        best = {"key": (True, np.inf), "x": xs}

        def rank(x):
            f = self._value(x)[0]
            viol = self._violation(x, A)
            bad = not viol <= self.constraint_tol
            return (bad, viol if bad else f)

        def callback(yk):
            if deadline is not None and _time.time() > deadline.value:
                stopped.append(True)
                raise StopIteration

        def run(xc, M):
            def X(y):
                return xc + M @ y

            cons = []
            if A is not None:
                lo, hi = self._lin_lo, self._lin_hi
                AM = A @ M
                AMM = np.vstack([AM, -AM])
                Ax = A @ xc
                cons.append({"type": "ineq", "fun": lambda y: np.concatenate([Ax + AM @ y - lo,
                                                                              hi - Ax - AM @ y]),
                             "jac": lambda y: AMM})
            if self.tracking_tolerance is not None or self.design != "ff":
                cons.append({"type": "ineq", "fun": lambda y: self._value(X(y))[1],
                             "jac": lambda y: self._gradient(X(y))[1] @ M})

            count = {"nit": 0, "nfev": 0}   # SLSQP's own, for a run cut short below

            def fun(y):
                count["nfev"] += 1
                x = X(y)
                key = rank(x)
                if key < best["key"]:
                    best["key"], best["x"] = key, x
                return fs * self._value(x)[0]

            def jac(y):
                return fs * (self._gradient(X(y))[0] @ M)

            def iterate(yk):
                count["nit"] += 1
                callback(yk)

            try:
                res = minimize(fun, np.zeros(xc.size), jac=jac, method="SLSQP",
                               constraints=cons, options=opts, callback=iterate)
            except _Unsimulable as exc:
                if np.array_equal(exc.x, xc):
                    raise           # the start itself does not simulate
                # SLSQP's line search gives up after 10 backtracks and accepts the step:
                # here into a region that does not simulate.  End this run as a
                # line-search failure; the restarts below go back to the best point.
                from scipy.optimize import OptimizeResult
                return OptimizeResult(success=False, status=8, message=str(exc), **count), exc.x
            return res, X(res.x)

        try:
            M = self._preconditioner(xs) if pre else np.eye(xs.size)
            res, x = run(xs, M)
            nit, nfev = res.nit, res.nfev
            for _ in range(self.restarts):
                if res.success or res.status not in (4, 8) or stopped:
                    break
                before = best["key"]
                if rank(x) > before:         # wandered off: restart nearer, with shorter steps
                    M = M / 3.0
                res, x = run(best["x"], M)
                nit, nfev = nit + res.nit, nfev + res.nfev
                if not res.success and not best["key"] < before:
                    break
            if not res.success and best["key"] < rank(x):
                x = best["x"]
        except (SolverError, FloatingPointError, ValueError) as exc:
            return None, {"start": k, "ok": False, "success": False, "message": f"failed: {exc}",
                          "objective": float("nan"), "violation": float("inf"), "nit": 0,
                          "nfev": 0, "seconds": _time.perf_counter() - ts}
        viol = self._violation(x, A)
        f = float(self._value(x)[0])
        success = bool(res.success) and not stopped
        message = (f"stopped after {nit} iterations: another start converged first and this one "
                   f"ran past {self.budget_factor:g}x its time" if stopped else str(res.message))
        ok = success and viol <= self.constraint_tol and bool(np.isfinite(f))
        if ok and deadline is not None:
            with deadline.get_lock():
                elapsed = _time.perf_counter() - ts
                deadline.value = min(deadline.value, _time.time() + self.budget_factor * elapsed)
        return x, {"start": k, "ok": ok, "success": success, "message": message,
                   "objective": f, "violation": viol, "nit": int(nit), "nfev": int(nfev),
                   "seconds": _time.perf_counter() - ts}

    def _parametrization_at(self, x):
        """The parametrization with the period of ``x`` when the period is free."""
        if not self.free_period:
            return self.parametrization
        return self.parametrization.with_period(float(self._periods(x[None, :])[0]))

    def _integration_error(self, x, sim) -> float:
        """Max |q| difference (rad) against a simulation on a grid twice as fine (a check)."""
        t_f = np.linspace(self._t[0], self._t[-1], 2 * self._t.size - 1)
        tm_f = 0.5 * (t_f[1:] + t_f[:-1])
        C = self._coeffs(x[None, :])
        par = self._parametrization_at(x)
        sig = np.einsum("np,bps->nbs", par.basis(t_f), C)
        sig_m = np.einsum("np,bps->nbs", par.basis(tm_f), C)
        if self.design == "ff":
            q = simulate_ff(self.model, t_f, sig, sig_m, self._q0, self._v0, tendon=self.tendon,
                            skeleton=self._sk, muscles=self._mu)["q"]
        elif self.design == "ifm":
            q = simulate_skeleton(self.model, t_f, None, None, self._q0, self._v0, skeleton=self._sk,
                                  muscles=self._mu, forces=sig, forces_mid=sig_m)[0]
        else:
            q = simulate_skeleton(self.model, t_f, sig, sig_m, self._q0, self._v0,
                                  skeleton=self._sk)[0]
        return float(np.max(np.abs(q[::2, 0] - sim["q"][:, 0])))

    def _violation(self, x, A_lin):
        viol = 0.0
        if A_lin is not None:
            ub = A_lin @ x
            viol = max(viol, float(np.max(np.maximum(self._lin_lo - ub, 0))),
                       float(np.max(np.maximum(ub - self._lin_hi, 0))))
        c = self._value(x)[1]
        if c is not None:
            viol = max(viol, float(np.max(np.maximum(-c, 0.0))))
        return viol

    def _worst_violation(self, sim, u, err) -> str:
        """The most violated constraint of a simulated result, in words (or '')."""
        t, names = self._t, self.model.muscle_names
        cands = []
        lo, hi = self._lo - u, u - self._hi
        for d, side in ((lo, f"below its lower bound {self._lo:g}"), (hi, f"above its upper bound {self._hi:g}")):
            i, j = np.unravel_index(np.argmax(d), d.shape)
            cands.append((float(d[i, j]), f"the excitation of '{names[j]}' is {side} by "
                                          f"{d[i, j]:.3g} at t = {t[i]:.4g} s"))
        if self.tracking_tolerance is not None:
            cands.append((float(err - self.tracking_tolerance) / self.tracking_tolerance,
                          f"the tracking error reaches {err:.4g} rad (tolerance "
                          f"{self.tracking_tolerance:g} rad)"))
        if self.design == "ifm":
            f = F_CE_MIN - sim["f_ce_raw"][:, 0]
            i, j = np.unravel_index(np.argmax(f), f.shape)
            cands.append((float(f[i, j]), f"'{names[j]}' must supply {-f[i, j] + F_CE_MIN:.3g} F_max of "
                                          f"contractile force at t = {t[i]:.4g} s (least {F_CE_MIN:g})"))
        v, what = max(cands)
        return what if v > 0 else ""

    def _result(self, x, rec, records, seconds):
        A_lin = self._A_lin
        ok = rec["ok"]
        sim = self.simulate(x[None, :])
        terms = self._terms(sim, exact=True)      # reported with the exact (piecewise) models
        f = float(self._objective_of(terms)[0])
        f_opt = float(self._objective_of(self._terms(sim))[0])
        u = sim["u_raw"][:, 0]
        bound_viol = float(max(np.max(np.maximum(self._lo - u, 0)), np.max(np.maximum(u - self._hi, 0))))
        if A_lin is not None and self.design == "ff":
            ub = A_lin @ x
            ub = ub[:-1] if self.free_period else ub      # the last row bounds the period
            bound_viol = max(bound_viol, float(np.max(np.maximum(self._lo - ub, 0))),
                             float(np.max(np.maximum(ub - self._hi, 0))))
        err = float(terms["max_error"][0])
        status = rec["message"]
        if ok and self.tracking_tolerance is not None and err > self.tracking_tolerance + 1e-3:
            ok, status = False, f"tracking error {err:.4g} rad exceeds the tolerance on the full grid"
        if not ok and rec["success"]:
            status = f"constraints violated by {self._violation(x, A_lin):.3g} ({status})"
        if not ok:
            worst = self._worst_violation(sim, u, err)
            if worst:
                status = f"{status}; worst: {worst}"
        ierr = self._integration_error(x, sim)
        nq = self.model.nv
        qd = np.zeros((self._t.size, nq))
        qd[:, self._jc] = self._qd
        tn = {"J": f, "physiological": float(terms["physiological"][0]),
              "tracking": float(terms["tracking"][0]), "integration_error": ierr,
              "J_optimized": f_opt}
        info = dict(status=status, terms=tn, max_bound_violation=bound_viol, max_tracking_error=err,
                    coeffs=self._coeffs(x)[0], parametrization=self._parametrization_at(x), design=self.design,
                    q=sim["q"][:, 0], v=sim["v"][:, 0], a=sim["a"][:, 0], u=u, force=sim["force"][:, 0],
                    target=qd, seconds=seconds, nit=int(rec["nit"]), nfev=int(rec["nfev"]), starts=records,
                    x=np.array(x), coordinates=self.model.coordinates, muscles=self.model.muscle_names)
        stats = FitStatistics(k=np.size(x), converged=bool(ok), message=status, iterations=int(rec["nit"]),
                              violation=bound_viol, objective=f)
        ch = {}
        for j, c in enumerate(info["coordinates"]):
            ch[c] = info["q"][:, j]
            ch[f"{c}_speed"] = info["v"][:, j]
            ch[f"{c}_desired"] = qd[:, j]
        for i, n in enumerate(info["muscles"]):
            ch[f"{n}_excitation"] = u[:, i]
            ch[f"{n}_activation"] = info["a"][:, i]
            ch[f"{n}_force"] = info["force"][:, i]
        return Result(self._t.copy(), ch, stats=stats, info=info, report=self._report_text(stats, info))

    def _report_text(self, stats: FitStatistics, info: dict) -> str:
        flag = "CONVERGED" if stats.converged else "NOT CONVERGED (not a solution)"
        terms = info["terms"]
        return format_report(
            f"Dynamic optimization ({info['design']} design, {info['parametrization']!r}) of model "
            f"'{self.model.name}': {flag}", [
                ("status", info["status"]),
                ("objective", f"{stats.objective:.6g} (" + ", ".join(f"{k} {v:.6g}" for k, v in terms.items()) + ")"),
                ("violation", f"max excitation-bound violation {info['max_bound_violation']:.3g}"),
                ("tracking", f"max error {info['max_tracking_error']:.4g} rad, integration check "
                             f"{terms.get('integration_error', float('nan')):.2g} rad"),
                ("solver", f"SLSQP, {info['nit']} iterations, {info['nfev']} batched evaluations, "
                           f"{np.size(info['x'])} decision variables"),
                ("time", f"{info['seconds']:.2f} s"),
            ])

    def to_dict(self) -> dict:
        """The fit as a JSON-ready dict (what ``pinmsk optimize`` writes to ``<out>.json``)."""
        self._check_fitted()
        r = self.result_
        return {"converged": bool(r.converged), "status": r.status,
                "objective": float(r.objective),
                "terms": {k: float(v) for k, v in r.terms.items()},
                "max_bound_violation": float(r.max_bound_violation),
                "max_tracking_error": float(r.max_tracking_error),
                "seconds": float(r.seconds), "nit": int(r.nit), "nfev": int(r.nfev),
                "design": r.design, "parametrization": r.parametrization.describe(),
                "coefficients": np.asarray(r.coeffs).tolist(),
                "starts": r.starts}


_ACTIVE = None


def _run_start(arg):  # worker of the multi-start pool (fork: inherits _ACTIVE)
    k, xs = arg
    return _ACTIVE._solve_start(k, xs)


# =============================================================================== task files
TASK_SCHEMA = {
    "model": {"name": "built-in model name or path of a .toml sidecar (required)",
              "moment_arms": "path variant, e.g. 'constant' or 'angle'",
              "tendon": "'rigid' or 'compliant' (FF muscle tendon)",
              "mass_scale": "scale factor on all segment masses and inertias (e.g. 0.5)"},
    "motion": {"kind": "'sine' | 'cycle' | 'file'", "coordinate": "tracked coordinate",
               "amplitude": "rad", "frequency": "Hz (sine)", "period": "s (cycle)",
               "offset": "rad", "phase": "rad (sine)", "duration": "s (default: one period)",
               "file": "trial file (.csv/.sto/.mot) holding the coordinate (kind = 'file')"},
    "parametrization": {"kind": "'polynomial' | 'fourier' | 'spline'",
                        "design": "'ff' | 'ifm' | 'ift'", "order": "polynomial order",
                        "n_harmonics": "Fourier K (2K + 1 terms)",
                        "period": "Fourier period tau (s; default the duration)",
                        "free_period": "true: tau is a decision variable (Sec. 3.3.6)",
                        "period_bounds": "[lower, upper] factors on tau with free_period",
                        "n_params": "spline coefficients"},
    "objective": {"kind": "'effort' | 'metabolic'", "exponent": "P of Eq. 3.5",
                  "weights": "'none' | 'volume'", "normalize": "divide by sum S_i (Eq. 3.5)",
                  "model": "'umberger2003' | 'bhargava2004'",
                  "tracking_weight": "1 - mu of Eq. 3.3"},
    "constraints": {"excitation_bounds": "[lower, upper] (Eq. 3.8)",
                    "tracking_tolerance": "rad (Eq. 3.7)",
                    "bound_points": "times at which the excitation bounds are imposed",
                    "tracking_points": "times at which the tracking tolerance is imposed"},
    "solver": {"step": "RK4 step (s)", "maxiter": "SLSQP iterations", "tol": "SLSQP ftol",
               "constraint_tol": "accepted constraint violation", "n_starts": "multi-start count",
               "fd_step": "relative finite-difference step",
               "n_jobs": "parallel worker processes for the starts",
               "smooth": "width of the C1 switches of the metabolic models (0 = exact)",
               "fv_smooth": "IFM/IFT: force-velocity blend width at zero velocity (v/v_max)"},
}


def _check_keys(table: dict, section: str, where: str):
    check_keys(table, TASK_SCHEMA[section], where=where, section=f"[{section}]")


def load_task(task_path) -> dict:
    """Read and validate a task file (TOML or JSON); see :data:`TASK_SCHEMA`."""
    p = Path(task_path)
    if not p.exists():
        raise ModelError(f"task file not found: {p}")
    if p.suffix.lower() == ".json":
        spec = json.loads(p.read_text())
    else:
        spec = read_toml(p, what="task file")
    for k in spec:
        if k not in TASK_SCHEMA:
            raise ModelError(f"{p}: unknown section '{k}'; valid sections: {', '.join(TASK_SCHEMA)}")
    if "model" not in spec or "name" not in spec.get("model", {}):
        raise ModelError(f"{p}: missing model: add a [model] table with name = \"finger\" (a "
                         "built-in name) or the path of a model sidecar .toml")
    if "motion" not in spec:
        raise ModelError(f"{p}: missing [motion] table (the motion to track)")
    for k, v in spec.items():
        _check_keys(v, k, str(p))
    return spec


def build_from_task(spec: dict, *, base_dir=None, progress=None) -> DynamicOptimization:
    """A :class:`DynamicOptimization` from a validated task dict."""
    ms = spec["model"]
    name = ms["name"]
    if base_dir is not None and str(name).endswith((".toml", ".urdf")) and not Path(name).is_absolute():
        name = str(Path(base_dir) / name)
    model = load_model(name, moment_arms=ms.get("moment_arms"))
    scale = float(ms.get("mass_scale", 1.0))
    if scale != 1.0:
        model = scale_masses(model, scale)
    mo = spec["motion"]
    kind = mo.get("kind", "sine")
    coord = mo.get("coordinate", model.coordinates[0])
    model.coordinate_index(coord)
    if kind == "file":
        f = Path(mo["file"])
        if base_dir is not None and not f.is_absolute():
            f = Path(base_dir) / f
        tr = read_trial(f)
        target = Target("samples", time=tr.time - tr.time[0], values=tr[coord])
    elif kind in ("sine", "cycle"):
        target = Target(kind, amplitude=mo.get("amplitude", 0.0), frequency=mo.get("frequency"),
                        period=mo.get("period"), offset=mo.get("offset", 0.0),
                        phase=mo.get("phase", 0.0))
    else:
        raise ModelError(f"unknown motion kind '{kind}'; valid: sine, cycle, file")
    duration = float(mo.get("duration", target.period))
    pa = dict(spec.get("parametrization", {}))
    design = pa.pop("design", "ff")
    free_period = bool(pa.pop("free_period", False))
    period_bounds = tuple(pa.pop("period_bounds", (0.5, 2.0)))
    pk = pa.pop("kind", "fourier")
    if pk == "polynomial":
        par = Polynomial(pa.get("order", 6), duration=duration)
    elif pk == "fourier":
        par = Fourier(pa.get("n_harmonics", 5), period=pa.get("period", duration))
    elif pk == "spline":
        par = Spline(pa.get("n_params", 10), duration=duration)
    else:
        raise ModelError(f"unknown parametrization kind '{pk}'; valid: polynomial, fourier, spline")
    ob = dict(spec.get("objective", {}))
    tw = ob.pop("tracking_weight", None)
    co = spec.get("constraints", {})
    so = spec.get("solver", {})
    if tw is None and "tracking_tolerance" not in co:
        raise ModelError("task: give [objective] tracking_weight or [constraints] "
                         "tracking_tolerance (the motion must be tracked)")
    return DynamicOptimization(
        model, parametrization=par, target=target, design=design, coordinate=coord,
        duration=duration, step=so.get("step", 1e-3), objective=ob or None,
        tracking_weight=tw, tracking_tolerance=co.get("tracking_tolerance"),
        excitation_bounds=tuple(co.get("excitation_bounds", (0.0, 1.0))),
        bound_points=co.get("bound_points", 200), tracking_points=co.get("tracking_points", 200),
        tendon=ms.get("tendon", "rigid"),
        maxiter=so.get("maxiter", 200), tol=so.get("tol", 1e-7),
        constraint_tol=so.get("constraint_tol", 1e-5), n_starts=so.get("n_starts", 3),
        fd_step=so.get("fd_step", 1e-6), n_jobs=so.get("n_jobs", 1),
        smooth=so.get("smooth", 0.01), fv_smooth=so.get("fv_smooth", 0.02),
        free_period=free_period, period_bounds=period_bounds, progress=progress)


def scale_masses(model, factor: float):
    """A new model whose segment masses and inertias are scaled by ``factor``."""
    if not factor > 0:
        raise ModelError(f"mass_scale must be > 0, got {factor}")
    pm = pin.Model(model.pin)
    for j in range(1, pm.njoints):
        I = pm.inertias[j]
        pm.inertias[j] = pin.Inertia(I.mass * factor, I.lever, I.inertia * factor)
    return Model(name=model.name, pin_model=pm, muscles=model.muscles, effects=model.effects,
                 contacts=model.contacts, meta=model.meta)


