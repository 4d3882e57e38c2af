"""Direct collocation of a musculoskeletal optimal-control problem, solved by IPOPT (thesis Ch. 3, 5).

:class:`Collocation` is the engine: a fitter in scikit-learn's habit (the
constructor stores, :meth:`Collocation.fit` solves and returns ``self``,
``result_`` is a :class:`~pinmsk.fitting.Result`).  The problem is

    minimize   sum_k w_k J_k                              (named cost terms, costs.py)
    subject to x' = f(x, u, s)                            (collocation defects)
               rnea(q, v, qdd) = R^T F + Q_effects + J^T f_contacts   (implicit skeleton)
               Hill equilibrium (compliant tendons)       (implicit muscle, De Groote 2016)
               path and boundary constraints              (constraints.py)
               bounds from the model's components

with states ``x = [q, v, a (, f_t)]``, point controls ``[qdd (, df_t) ...]`` and
the control *signal* ``s`` (excitations, muscle forces or torques, by
formulation; physics.py) either at every collocation point or as a global
parametrization (controls.py).

Transcription (``scheme``):

- ``"trapezoidal"``: ``x_{k+1} - x_k = h/2 (f_k + f_{k+1})``; the trapezoid rule integrates the costs;
- ``"hermite-simpson"`` (compressed form): the midpoint state
  ``x_m = (x_k + x_{k+1})/2 + h/8 (f_k - f_{k+1})``, the defect
  ``x_{k+1} - x_k = h/6 (f_k + 4 f_m + f_{k+1})``, Simpson's rule for the costs;
  path constraints and the implicit dynamics hold at nodes and midpoints.

Derivatives: the per-point model is one CasADi ``SX`` function (the same
component code as the numpy analyses, :mod:`pinmsk.backend`), mapped over the
points; the NLP is expanded to ``SX`` and IPOPT gets the exact sparse Jacobian
and Hessian of the Lagrangian by algorithmic differentiation.  No finite
differences anywhere.

Scaling: every variable group is divided by a nominal size (rad, rad/s, the
guess's accelerations, ...) and every residual by its own (the guess's joint
moments for the skeleton, 1 for the normalized muscle rows), so IPOPT sees
O(1) numbers.

Convergence: IPOPT's return status is reported as it is.  A problem that did
not reach ``Solve_Succeeded`` (or the acceptable level with its constraints
met to ``constraint_tol``) has ``converged = False`` and its status names the
most violated constraint, where and by how much; it is never reported as a
solution.
"""
from __future__ import annotations

import contextlib
import sys
import time as _time

import numpy as np

from ...errors import ModelError
from ...fitting import FitStatistics, Fitter, Result, format_report
from .constraints import Bounds, Constraint, ExcitationBounds, TrackingTolerance
from .controls import GlobalControls, NodeControls
from .costs import Cost, TrackCoordinates
from .physics import PointModel

__all__ = ["Collocation", "SCHEMES"]

SCHEMES = ("trapezoidal", "hermite-simpson")
_SOLVER_KEYS = {"tol", "max_iter", "constraint_tol", "print_level", "hessian", "linear_solver",
                "acceptable_tol", "mu_strategy", "nlp_scaling_method", "bound_push", "acceptable_iter",
                "acceptable_constr_viol_tol"}


def _time_derivative(t, y):
    """``dy/dt`` (N, k) at the collocation points ``t``, which are not in time order (nodes, then
    Hermite-Simpson midpoints): finite differences in time order, put back in the points' order."""
    order = np.argsort(t)
    out = np.empty_like(np.asarray(y, dtype=float))
    out[order] = np.gradient(np.asarray(y, dtype=float)[order], t[order], axis=0) if t.size > 1 else 0.0
    return out


class _Blocks:
    """Labels, bounds and physical scales of the NLP's constraint rows, in the order of ``g``.

    A block is ``K`` instances of the same rows (an interval's defects, residuals and path
    rows, one instance per interval), stored instance after instance.
    """

    def __init__(self):
        self.meta, self.lo, self.hi = [], [], []

    def add(self, rows, where, lo, hi, scale):
        """Rows labelled ``rows`` (each with its bounds and scale), repeated for each of ``where``."""
        n, K = len(rows), len(where)
        self.meta.append((list(rows), list(where), np.asarray(scale, dtype=float)))
        self.lo.append(np.tile(np.asarray(lo, dtype=float), K))
        self.hi.append(np.tile(np.asarray(hi, dtype=float), K))
        assert self.lo[-1].size == n * K

    def add_grid(self, label, rows, where, lo, hi, scale):
        """One row per signal and point, stored row-fastest (a column-major signal matrix)."""
        sc = np.broadcast_to(np.asarray(scale, dtype=float), (len(rows),))
        self.add([f"{label} {r}" for r in rows], where, np.full(len(rows), lo), np.full(len(rows), hi), sc)

    def vector(self):
        return (np.concatenate(self.lo) if self.lo else np.zeros(0),
                np.concatenate(self.hi) if self.hi else np.zeros(0))

    def worst(self, g, lo, hi):
        """``(violation in physical units, description)`` of the most violated row (scaled measure)."""
        v = np.maximum(np.maximum(lo - g, g - hi), 0.0)
        if v.size == 0 or not np.any(v > 0):
            return 0.0, ""
        i = int(np.argmax(v))
        k = 0
        for rows, where, sc in self.meta:
            n = len(rows) * len(where)
            if i < k + n:
                j = i - k
                r, c = j % len(rows), j // len(rows)
                side = "below its lower bound" if g[i] < lo[i] else "above its upper bound"
                at = f" {where[c]}" if where[c] else ""
                return float(v[i] * sc[r]), f"{rows[r]}{at}: {side} by {v[i] * sc[r]:.3g}"
            k += n
        return float(v[i]), f"row {i}"

    @staticmethod
    def max_violation(g, lo, hi) -> float:
        v = np.maximum(np.maximum(lo - g, g - hi), 0.0)
        return float(v.max()) if v.size else 0.0


def _iteration_callback_class():
    """:class:`_IterationCallback`'s base is ``casadi.Callback``, imported when first used."""
    import casadi as ca

    class IterationCallback(ca.Callback):
        """CasADi's ``iteration_callback`` of ``nlpsol``: at every IPOPT iteration it gets the
        iterate (``nlpsol_out``: x, f, g, ...) and tells ``monitor.iteration(k, f, inf_pr)``,
        ``inf_pr`` being ``max(lbg - g, g - ubg, 0)`` (IPOPT keeps x inside its bounds)."""

        def __init__(self, monitor, nx, lbg, ubg):
            ca.Callback.__init__(self)
            self.monitor, self.nx = monitor, int(nx)
            self.lbg, self.ubg = np.asarray(lbg, dtype=float), np.asarray(ubg, dtype=float)
            self.count = 0
            self.interrupted = False
            self.construct("pinmsk_iteration", {})

        def reset(self):
            self.count = 0
            self.interrupted = False

        def get_n_in(self):
            return ca.nlpsol_n_out()

        def get_n_out(self):
            return 1

        def get_name_in(self, i):
            return ca.nlpsol_out(i)

        def get_name_out(self, i):
            return "ret"

        def get_sparsity_in(self, i):
            n = {"x": self.nx, "lam_x": self.nx, "g": self.lbg.size, "lam_g": self.lbg.size, "f": 1}.get(ca.nlpsol_out(i), 0)
            return ca.Sparsity.dense(n) if n else ca.Sparsity(0, 0)

        def eval(self, arg):
            if self.interrupted:  # non-zero: IPOPT stops (User_Requested_Stop)
                return [1]
            if self.monitor is not None:
                g = np.asarray(arg[2], dtype=float).ravel()
                viol = np.maximum(np.maximum(self.lbg - g, g - self.ubg), 0.0)
                self.monitor.iteration(self.count, float(arg[1]), float(viol.max()) if viol.size else 0.0)
            self.count += 1       # IPOPT calls it at iteration 0 (the start) too
            return [0]

    return IterationCallback


def _IterationCallback(monitor, nx, lbg, ubg):
    return _iteration_callback_class()(monitor, nx, lbg, ubg)


@contextlib.contextmanager
def _interrupt_flag(callback):
    """During the block, SIGINT (Ctrl-C) sets ``callback.interrupted`` instead of raising inside
    IPOPT's callbacks, where CasADi would turn it into a failed solve (``NonIpopt_Exception_Thrown``)
    and a fit of several stages would go on to the next; the callback then stops IPOPT and the fit
    raises ``KeyboardInterrupt``.  Only Python's default handler in the main thread is replaced."""
    import signal
    import threading
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return

    def _flag(signum, frame):
        callback.interrupted = True
    signal.signal(signal.SIGINT, _flag)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


class Collocation(Fitter):
    """Direct-collocation optimal control of a musculoskeletal model (see the module docstring).

    Arguments (stored; :meth:`fit` solves), the model first, the rest keyword-only:

    - ``cost``: a :class:`~pinmsk.solvers.ocp.costs.Cost` or a weighted sum of them;
    - ``constraints``: sequence of :mod:`~pinmsk.solvers.ocp.constraints` objects
      (excitation bounds default to [0, 1]);
    - ``duration``: seconds, or ``(lower, upper)`` for a free final time;
    - ``intervals``: collocation intervals; ``scheme``: ``"trapezoidal"`` or ``"hermite-simpson"``;
    - ``controls``: :class:`NodeControls` (default) or :class:`GlobalControls`;
    - ``formulation``: ``"ff"`` (excitations), ``"ifm"`` (muscle forces), ``"ift"`` (joint torques);
    - ``tendon``: ``"rigid"`` or ``"compliant"`` (default: the model's muscle set);
    - ``guess``: None (automatic: the tracked motion and static optimization) or a Trial /
      Result whose channels (``<coord>``, ``<coord>_speed``, ``<muscle>_activation``, ...)
      start the solver (a warm start);
    - ``n_starts``: automatic guesses to try (the best converged one is the result);
    - ``solver``: IPOPT settings ``tol`` (1e-8), ``max_iter`` (1000), ``constraint_tol`` (1e-6,
      scaled), ``print_level`` (5: the level of IPOPT's log when ``verbose`` or in ``solver_log``),
      ``hessian`` (``"exact"`` or ``"limited-memory"``), ...;
    - ``verbose``: IPOPT's iteration table on stdout (default: when stdout is a terminal);
    - ``monitor``: an object told of each IPOPT solve (a *stage*: every start, and both grids of
      :class:`~pinmsk.solvers.ocp.gait.CoarseToFine`): ``start(label)``, then
      ``iteration(k, objective, violation)`` at every IPOPT iteration (``violation``: the largest
      constraint violation, IPOPT's ``inf_pr``), then ``end(record)`` with the stage's status,
      iterations, objective, violation and seconds (e.g.
      :class:`pinmsk.presentation.solve_progress.SolveProgress`);
    - ``solver_log``: a file IPOPT's own log (print level 5, or ``solver["print_level"]``) is
      appended to, each solve under a ``# pinmsk: ...`` header line.
    """

    def __init__(self, model, *, cost: Cost, constraints=(), duration=1.0, intervals: int = 50,
                 scheme: str = "hermite-simpson", controls=None, formulation: str = "ff",
                 tendon: str | None = None, guess=None, n_starts: int = 1, solver: dict | None = None,
                 verbose: bool | None = None, monitor=None, solver_log=None):
        self.model = model
        self.cost = cost
        self.constraints = constraints
        self.duration = duration
        self.intervals = intervals
        self.scheme = scheme
        self.controls = controls
        self.formulation = formulation
        self.tendon = tendon
        self.guess = guess
        self.n_starts = n_starts
        self.solver = solver
        self.verbose = verbose
        self.monitor = monitor
        self.solver_log = solver_log

    # ------------------------------------------------------------------ problem facts
    @property
    def compliant(self) -> bool:
        return self._pm.compliant

    def forward_coordinate(self) -> str:
        """The coordinate of progression: ``pelvis_tx`` if present, else the first x translation."""
        names = self.model.coordinates
        for c in ("pelvis_tx", "base_x", "root_x"):
            if c in names:
                return c
        for j, jm in enumerate(self.model.pin.joints[1:]):
            if jm.shortname() == "JointModelPX":
                return names[self.model.pin.joints[j + 1].idx_v]
        raise ModelError(f"model '{self.model.name}' has no forward translation; name the coordinate")

    def nominal_times(self) -> np.ndarray:
        """Collocation times at the nominal duration."""
        return self._frac * self._T0

    def need(self, what: str, **kw) -> None:
        """A cost asks the point model for a quantity (``"metabolic"``)."""
        self._needs[what] = kw

    # ------------------------------------------------------------------ setup
    def _setup(self):
        try:
            import casadi  # noqa: F401
        except ImportError as exc:   # an optional dependency: say how to get it
            raise ModelError("the optimal-control engine needs CasADi: pip install casadi") from exc
        if self.scheme not in SCHEMES:
            raise ModelError(f"unknown scheme '{self.scheme}'; valid: {', '.join(SCHEMES)}")
        N = int(self.intervals)
        if N != self.intervals or N < 2:
            raise ModelError(f"intervals must be an integer >= 2, got {self.intervals}")
        self._N = N
        d = self.duration
        if np.ndim(d) == 0:
            if not float(d) > 0:
                raise ModelError(f"duration must be > 0 s, got {d}")
            self._T0, self._Tb = float(d), None
        else:
            lo, hi = map(float, d)
            if not 0 < lo < hi:
                raise ModelError(f"free final time bounds {tuple(d)} must satisfy 0 < lower < upper")
            self._T0, self._Tb = 0.5 * (lo + hi), (lo, hi)
        nodes = np.arange(N + 1) / N
        self._frac = nodes if self.scheme == "trapezoidal" else np.concatenate([nodes, (np.arange(N) + 0.5) / N])
        self._controls = self.controls if self.controls is not None else NodeControls()
        if not isinstance(self._controls, (NodeControls, GlobalControls)):
            raise ModelError(f"controls must be NodeControls() or GlobalControls(...), not {self._controls!r}")
        if isinstance(self._controls, GlobalControls) and self._Tb is not None:
            raise ModelError("a global parametrization is defined on a fixed duration: give duration as "
                             "one number (a Fourier series can have a free period instead)")
        if not isinstance(self.cost, Cost):
            raise ModelError(f"cost must be a Cost (e.g. Effort(3) + TrackCoordinates(target)), not {self.cost!r}")
        self._costs = self.cost.terms()
        cons = list(self.constraints)
        for c in cons:
            if not isinstance(c, Constraint):
                raise ModelError(f"constraints must be Constraint objects, not {c!r}")
        self._cons = cons
        s = dict(self.solver or {})
        bad = set(s) - _SOLVER_KEYS
        if bad:
            raise ModelError(f"unknown solver setting(s) {sorted(bad)}; valid: {sorted(_SOLVER_KEYS)}")
        self._solver = s
        self._needs = {}
        tendon = self.tendon or (self.model.muscles.tendon if self.model.muscles is not None else "rigid")
        # costs first: they declare what the point model must provide
        self._pm = PointModel(self.model, tendon=tendon, formulation=self.formulation)
        for c in self._costs:
            c.check(self)
        for c in cons:
            c.check(self)
        met = self._needs.get("metabolic")
        if met is not None:
            self._pm.metabolic = float(met["smooth"])
        vb = [c for c in cons if isinstance(c, Bounds)]
        self._vbounds = {}
        for what in ("q", "v", "qdd"):
            lo, hi = np.full(self.model.nv, -np.inf), np.full(self.model.nv, np.inf)
            for c in vb:                   # several Bounds intersect
                a, b = c.arrays(self.model, what)
                lo, hi = np.maximum(lo, a), np.minimum(hi, b)
            bad = np.flatnonzero(~(lo < hi))
            if bad.size:
                raise ModelError(f"Bounds on {what} of {self.model.coordinates[bad[0]]} are empty "
                                 f"({lo[bad[0]]:g} to {hi[bad[0]]:g})")
            self._vbounds[what] = (lo, hi)
        lo, hi = -np.inf, np.inf
        for c in vb:
            if c.df_t is not None:
                lo, hi = max(lo, c.df_t[0]), min(hi, c.df_t[1])
        self._vbounds["df_t"] = (lo, hi)
        eb = [c for c in cons if isinstance(c, ExcitationBounds)]
        if len(eb) > 1:
            raise ModelError("give at most one ExcitationBounds")
        self._ebounds = (eb[0].lower, eb[0].upper) if eb else (0.0, 1.0)
        if np.any(self._pm.delay > 0) and self._Tb is not None:
            raise ModelError("an electromechanical delay needs a fixed duration (the delayed excitation is "
                             "an interpolation on a fixed time grid)")

    # ------------------------------------------------------------------ guess
    def _targets(self):
        """``{coordinate index: Target}`` of the tracked coordinates (costs and constraints)."""
        out = {}
        for c in list(self._costs) + list(self._cons):
            if isinstance(c, (TrackCoordinates, TrackingTolerance)):
                out.setdefault(c._j, c.target)
        return out

    def _auto_guess(self, t, start: int = 0) -> dict:
        """Point values (each (rows, n_points)) of the automatic guess on times ``t``.

        Coordinates follow the tracked targets (0 elsewhere), activations come from
        static optimization of the targets' inverse dynamics (start 0) or are constant
        (later starts), excitations from inverse activation dynamics (Eq. A.5).
        """
        model, pm = self.model, self._pm
        n, nv, m = t.size, model.nv, pm.m
        q, v, qdd = np.zeros((n, nv)), np.zeros((n, nv)), np.zeros((n, nv))
        for j, tg in self._targets().items():
            q[:, j], v[:, j], qdd[:, j] = tg(t), tg(t, 1), tg(t, 2)
        g = {"q": q.T, "v": v.T, "qdd": qdd.T}
        if not m:
            return g
        a = None
        if start == 0 and self._targets():
            a = self._so_activations(t, q, v, qdd)
        if a is None:
            a = np.full((n, m), 0.05 + 0.1 * start)
        return self._muscle_guess(g, t, q, v, a)

    def _muscle_guess(self, g, t, q, v, a):
        pm, mtu = self._pm, self._pm.ms.mtu
        lo, hi = self._ebounds
        adot = _time_derivative(t, a)
        from ...muscles.activation import excitation_from_activation
        e = np.clip(excitation_from_activation(a, adot, tau_rise=pm.tau_rise, tau_fall=pm.tau_fall), lo, hi)
        l_mt = pm.ms.lengths(q)
        v_mt = pm.ms.velocities(q, v)
        g.update(a=a.T, e=e.T)
        if pm.compliant:
            ft = mtu.equilibrium_tendon_force(a, l_mt)
            dft = _time_derivative(t, ft)
            g.update(f_t=ft.T, df_t=dft.T)
            F = mtu.f_max * ft
        else:
            F = mtu.rigid_force(a, l_mt, v_mt)
        g["F"] = np.asarray(F).T
        if pm.formulation == "ift":
            R = pm.ms.moment_arms(q)
            tau = np.einsum("nm,nmj->nj", np.asarray(F), R)
            g["tau"] = tau[:, pm.driven].T
        return g

    def _so_activations(self, t, q, v, qdd):
        """Static-optimization activations (N, m) of the motion (q, v, qdd), or None if SO fails."""
        from ...components import Motion
        from ...errors import PinmskError
        from ..static import StaticOptimization
        order = np.argsort(t)
        mo = Motion(t=t[order], q=q[order], v=v[order], a=qdd[order])
        try:
            so = StaticOptimization(mode="activation", exponent=2, reserves=True).fit(self.model, mo, cutoff=0)
        except PinmskError:
            return None
        res = so.result_
        a = np.column_stack([np.asarray(res[f"{n}_activation"]) for n in self.model.muscle_names])
        out = np.empty_like(a)
        out[order] = np.clip(a, 0.01, 1.0)
        return out

    def _guess_from_trial(self, trial, t) -> dict:
        """Point values from a Trial/Result's channels (a warm start), interpolated to ``t``."""
        model = self.model
        tt = np.asarray(trial.time, dtype=float) - float(trial.time[0])
        T = self._T0
        span = tt[-1] if tt[-1] > 0 else 1.0

        def ch(name, default):
            if name in trial.names:
                return np.interp(t * span / T, tt, np.asarray(trial[name], dtype=float))
            return default

        n = t.size
        q = np.column_stack([ch(c, np.zeros(n)) for c in model.coordinates])
        dq = _time_derivative(t, q)
        v = np.column_stack([ch(f"{c}_speed", dq[:, j]) for j, c in enumerate(model.coordinates)])
        qdd = np.column_stack([ch(f"{c}_acceleration", np.zeros(n)) for c in model.coordinates])
        g = {"q": q.T, "v": v.T, "qdd": qdd.T}
        if self._pm.m:
            a = np.column_stack([ch(f"{mu}_activation", np.full(n, 0.05)) for mu in model.muscle_names])
            g = self._muscle_guess(g, t, q, v, np.clip(a, 0.0, 1.0))
            e = np.column_stack([ch(f"{mu}_excitation", g["e"][i]) for i, mu in enumerate(model.muscle_names)])
            g["e"] = e.T
        return g

    # ------------------------------------------------------------------ NLP
    def _build(self, guess: dict):
        import casadi as ca
        pm, N = self._pm, self._N
        st, co = pm.layout()
        nx = sum(len(r) for r in st.values())
        nu = sum(len(r) for r in co.values())
        ns = pm.n_signal
        npt = self._frac.size
        nv, m = pm.nv, pm.m
        names = self.model.coordinates
        muscles = tuple(self.model.muscle_names) if m else ()

        # -- nominal scales (variables and residuals)
        def nominal(x, floor):
            return np.maximum(np.max(np.abs(np.atleast_2d(x)), axis=1), floor)
        def by_bounds(sc, what):   # a finite bound's half range is the variable's scale (Moco)
            lo, hi = self._vbounds[what]
            half = 0.5 * (hi - lo)
            return np.where(np.isfinite(half), np.maximum(sc, half), sc)
        sx = np.concatenate([nominal(guess["q"], 0.1), by_bounds(nominal(guess["v"], 1.0), "v")]
                            + ([np.ones(m)] if m else []) + ([np.ones(m)] if pm.compliant else []))
        su = [by_bounds(nominal(guess["qdd"], 1.0), "qdd")]
        if pm.compliant:
            lo, hi = self._vbounds["df_t"]
            su.append(np.maximum(nominal(guess["df_t"], 1.0), 0.5 * (hi - lo) if np.isfinite(hi - lo) else 1.0))
        if m and pm.formulation != "ff":
            su.append(np.ones(m))
        if pm.formulation == "ift":
            su.append(nominal(guess["F"], 1.0))
        if pm.actuators:
            su.append(np.ones(len(pm.actuators)))
        su = np.concatenate(su)
        if pm.formulation == "ff":
            ss = np.ones(ns)
        elif pm.formulation == "ifm":
            ss = nominal(guess["F"], 1.0)
        else:
            ss = nominal(guess["tau"], 0.1)
        tau_guess = self._guess_torques(guess)
        weight = 9.81 * pm.mass
        # the guess's inverse dynamics do not see contact forces, which are of the body weight's
        # size (a standing guess's horizontal rows are 0): with contacts the floor is 5 % of it
        floor = 0.05 * weight if pm.contacts else max(1e-3 * weight, 1e-2)
        s_tau = np.maximum(np.max(np.abs(tau_guess), axis=1), floor)

        # -- the per-point function (SX)
        xs, us = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
        sg, sd, ts = ca.SX.sym("s", ns), ca.SX.sym("sd", ns), ca.SX.sym("t")
        refs_np = [c.references(self, self._frac * self._T0) for c in self._costs]
        nref = [0 if r is None else r.shape[0] for r in refs_np]
        rs = ca.SX.sym("r", sum(nref))
        pt, res, xdot = pm.evaluate(xs, us, sg, sd, ts)
        res_rows, res_meta = [], []
        for label, expr, scale in res:
            expr = ca.vec(expr)
            if scale is None:   # joint-moment rows: N m per coordinate
                sc = s_tau if expr.numel() == nv else np.full(expr.numel(), float(np.max(s_tau)))
                rows = list(names) if expr.numel() == nv else [names[j] for j in pm.driven]
            else:
                sc = np.full(expr.numel(), float(scale))
                rows = list(muscles) if expr.numel() == m else [str(i) for i in range(expr.numel())]
            res_rows.append(expr / ca.DM(sc))
            res_meta.append((label, rows, sc))
        path_rows, path_meta = [], []
        for c in self._cons:
            for label, expr, lo, hi in c.path(pt):
                path_rows.append(ca.vec(expr))
                path_meta.append((label, lo, hi))
        integrands, k = [], 0
        for c, nr in zip(self._costs, nref):
            integrands.append(c.integrand(pt, rs[k: k + nr] if nr else None))
            k += nr
        report = {"F": pt.get("F", ca.SX.zeros(0)), "contact_forces": pt["contact_forces"],
                  "metabolic_rate": pt.get("metabolic_rate", ca.SX.zeros(0)),
                  "e": pt.get("e", ca.SX.zeros(0)) if pm.formulation != "ff" else ca.SX.zeros(0)}
        rep_keys = list(report)
        Fpt = ca.Function("point", [xs, us, sg, sd, ts, rs],
                          [xdot / ca.DM(sx), ca.vertcat(*res_rows) if res_rows else ca.SX.zeros(0),
                           ca.vertcat(*path_rows) if path_rows else ca.SX.zeros(0),
                           ca.vertcat(*integrands) if integrands else ca.SX.zeros(0)]
                          + [ca.vec(report[k_]) for k_ in rep_keys])

        R_all = np.vstack([r for r in refs_np if r is not None]) if any(nref) else np.zeros((0, npt))

        # -- decision variables (scaled); their order is the order of w
        ctl = self._controls
        glob_ctl = isinstance(ctl, GlobalControls)
        has_delay = pm.formulation == "ff" and bool(np.any(pm.delay > 0))
        ncost = len(self._costs)
        Z = {"X": ca.MX.sym("X", nx, N + 1), "U": ca.MX.sym("U", nu, npt), "S": ca.MX.sym("S", ns, npt)}
        if has_delay:
            Z["Sd"] = ca.MX.sym("Sd", ns, npt)
        if glob_ctl:
            Z["P"] = ca.MX.sym("P", ctl.n_params, ns)
            if ctl.free_period:
                Z["period"] = ca.MX.sym("period")
        if self._Tb is not None:
            Z["T"] = ca.MX.sym("T")
        Z["I"] = ca.MX.sym("I", ncost)           # the cost integrals (assembly.py)
        w = ca.vertcat(*[ca.vec(z) for z in Z.values()])
        off, k0 = {}, 0
        for key, z in Z.items():
            off[key] = k0
            k0 += int(z.numel())
        rep = lambda v, n: ca.repmat(ca.DM(v), 1, n)   # noqa: E731
        X, U, S = Z["X"] * rep(sx, N + 1), Z["U"] * rep(su, npt), Z["S"] * rep(ss, npt)
        Sd = Z["Sd"] * rep(ss, npt) if has_delay else S
        T = Z["T"] * self._T0 if "T" in Z else self._T0
        P = Z["P"] * ca.repmat(ca.DM(ss).T, ctl.n_params, 1) if glob_ctl else None
        period = Z["period"] * ctl.parametrization.period if "period" in Z else None

        # -- index matrices of the local variables
        def idx(key, rows, cols):
            n_r = Z[key].shape[0]
            return off[key] + np.asarray(cols)[None, :] * n_r + np.asarray(rows)[:, None]
        hs = self.scheme == "hermite-simpson"
        kk = np.arange(N)
        rx, ru, rs_ = np.arange(nx), np.arange(nu), np.arange(ns)
        parts = [idx("X", rx, kk), idx("X", rx, kk + 1), idx("U", ru, kk), idx("U", ru, kk + 1)]
        if hs:
            parts.append(idx("U", ru, N + 1 + kk))
        sig_key = "S"
        for key in ((sig_key, "Sd") if has_delay else (sig_key,)):
            parts += [idx(key, rs_, kk), idx(key, rs_, kk + 1)] + ([idx(key, rs_, N + 1 + kk)] if hs else [])
        if "T" in Z:
            parts.append(np.full((1, N), off["T"]))
        idx_int = np.vstack(parts)
        nref_ = R_all.shape[0]
        frac_a = self._frac[:N]
        if hs:
            par_int = np.vstack([frac_a[None, :], R_all[:, :N], R_all[:, 1:N + 1], R_all[:, N + 1:]])
        else:
            par_int = np.vstack([frac_a[None, :], R_all[:, :N], R_all[:, 1:N + 1]])
        fin = [idx("X", rx, [N]), idx("U", ru, [N]), idx("S", rs_, [N])] + ([idx("Sd", rs_, [N])] if has_delay else [])
        if "T" in Z:
            fin.append(np.full((1, 1), off["T"]))
        idx_fin = np.vstack(fin)
        par_fin = np.vstack([np.ones((1, 1)), R_all[:, N:N + 1]])

        # -- the local functions (SX): an interval, and the final node
        def unpack(z, sizes):
            out, k = [], 0
            for n_ in sizes:
                out.append(z[k: k + n_])
                k += n_
            return out
        zi = ca.SX.sym("z", idx_int.shape[0])
        pi = ca.SX.sym("p", par_int.shape[0])
        sizes = [nx, nx, nu, nu] + ([nu] if hs else []) + [ns] * ((3 if hs else 2) * (2 if has_delay else 1)) \
            + ([1] if "T" in Z else [])
        zz = unpack(zi, sizes)
        xa, xb, ua, ub = zz[0] * ca.DM(sx), zz[1] * ca.DM(sx), zz[2] * ca.DM(su), zz[3] * ca.DM(su)
        j = 4
        um = None
        if hs:
            um = zz[4] * ca.DM(su)
            j = 5
        nsig = 3 if hs else 2
        sig = [zz[j + i] * ca.DM(ss) for i in range(nsig)]
        j += nsig
        sdl = [zz[j + i] * ca.DM(ss) for i in range(nsig)] if has_delay else sig
        j += nsig if has_delay else 0
        Ti = zz[j] * self._T0 if "T" in Z else self._T0
        hi = Ti / N
        ta = pi[0] * Ti
        pr = unpack(pi[1:], [nref_] * (3 if hs else 2))
        oa = Fpt(xa, ua, sig[0], sdl[0], ta, pr[0])
        ob = Fpt(xb, ub, sig[1], sdl[1], ta + hi, pr[1])
        DX = ca.DM(sx)
        fa, fb = oa[0] * DX, ob[0] * DX
        if hs:
            xm = 0.5 * (xa + xb) + hi / 8 * (fa - fb)
            om = Fpt(xm, um, sig[2], sdl[2], ta + hi / 2, pr[2])
            defect = (xb - xa - hi / 6 * (fa + 4 * om[0] * DX + fb)) / DX
            integral = hi / 6 * (oa[3] + 4 * om[3] + ob[3])
            rows_int = ca.vertcat(defect, oa[1], oa[2], om[1], om[2])
            report_int = [xm] + list(oa[4:]) + list(om[4:])
        else:
            defect = (xb - xa - hi / 2 * (fa + fb)) / DX
            integral = hi / 2 * (oa[3] + ob[3])
            rows_int = ca.vertcat(defect, oa[1], oa[2])
            report_int = list(oa[4:])
        G_int = ca.Function("interval", [zi, pi], [rows_int, integral])
        R_int = ca.Function("interval_report", [zi, pi], report_int)
        zf = ca.SX.sym("z", idx_fin.shape[0])
        pf = ca.SX.sym("p", par_fin.shape[0])
        zz = unpack(zf, [nx, nu, ns] + ([ns] if has_delay else []) + ([1] if "T" in Z else []))
        Tf = zz[-1] * self._T0 if "T" in Z else self._T0
        sN = zz[2] * ca.DM(ss)
        oN = Fpt(zz[0] * DX, zz[1] * ca.DM(su), sN, zz[3] * ca.DM(ss) if has_delay else sN, pf[0] * Tf, pf[1:])
        G_fin = ca.Function("final_node", [zf, pf], [ca.vertcat(oN[1], oN[2]), ca.SX.zeros(ncost)])
        R_fin = ca.Function("final_report", [zf, pf], list(oN[4:]))

        # -- the other rows: links of the signal, boundary conditions
        blocks = _Blocks()
        t_int = [f"in interval {k_} ({k_ * self._T0 / N:.4g}-{(k_ + 1) * self._T0 / N:.4g} s)" for k_ in range(N)]
        state_labels = ([f"q {c}" for c in names] + [f"v {c}" for c in names]
                        + [f"a {n_}" for n_ in muscles] + ([f"f_t {n_}" for n_ in muscles] if pm.compliant else []))
        r_labels, r_lo, r_hi, r_sc = [], [], [], []

        def rows_meta(where_tag):
            for label, rows, sc in res_meta:
                r_labels.extend(f"{label} {r_} {where_tag}" for r_ in rows)
                r_lo.extend([0.0] * len(rows))
                r_hi.extend([0.0] * len(rows))
                r_sc.extend(sc)
            for label, lo, hi in path_meta:
                r_labels.append(f"{label} {where_tag}")
                r_lo.append(lo)
                r_hi.append(hi)
                r_sc.append(1.0)
        r_labels += [f"collocation defect of {s_}" for s_ in state_labels]
        r_lo += [0.0] * nx
        r_hi += [0.0] * nx
        r_sc += list(sx)
        rows_meta("at the interval's start")
        if hs:
            rows_meta("at the interval's midpoint")
        blocks.add(r_labels, t_int, r_lo, r_hi, r_sc)
        r_labels, r_lo, r_hi, r_sc = [], [], [], []
        rows_meta("")
        blocks.add(r_labels, [f"at the final node (t = {self._T0:.4g} s)"], r_lo, r_hi, r_sc)
        blocks.add([f"integral of cost '{c.name}'" for c in self._costs], [""], [0.0] * ncost, [0.0] * ncost,
                   [1.0] * ncost)
        ptimes = [f"at t = {t_:.4g} s" for t_ in self._frac * self._T0]
        sig_rows = list(muscles) if pm.formulation != "ift" else [names[j_] for j_ in pm.driven]
        other = []
        if glob_ctl:
            B = ctl.basis(self._frac * self._T0, period)
            link = (S - ca.mtimes(ca.MX(B) if not isinstance(B, ca.MX) else B, P).T) / rep(ss, npt)
            other.append(ca.vec(link))
            blocks.add_grid("global parametrization of the signal", sig_rows, ptimes, 0.0, 0.0, ss)
        if has_delay:
            other.append(ca.vec((Sd - self._delayed_signal(S, P, period)) / rep(ss, npt)))
            blocks.add_grid("electromechanical delay of the excitation", sig_rows, ptimes, 0.0, 0.0, ss)
        x0, xN = X[:, 0], X[:, N]
        glob = {"T": T, "x0": x0, "xN": xN, "layout": st, "coordinates": names, "muscles": muscles, "m": m,
                "mass": pm.mass, "e0": (S[:, 0] if pm.formulation == "ff" else U[co["e"][0]: co["e"][-1] + 1, 0])
                if m else None,
                # the actuators' controls at the first and last node (the points are the nodes first)
                "actuators": [a_.name for a_ in pm.actuators],
                "act0": U[co["act"][0]: co["act"][-1] + 1, 0] if pm.actuators else None,
                "actN": U[co["act"][0]: co["act"][-1] + 1, N] if pm.actuators else None}
        for c in self._cons:
            for label, expr, lo, hi in c.boundary(glob):
                other.append(ca.vec(expr))
                blocks.add([label], [""], [lo], [hi], [1.0])
        other_g = ca.vertcat(*other) if other else ca.MX.zeros(0)

        # -- objective: each term's finish of its integral; directly when every finish is linear in it
        lin = [c.linear_finish(glob) for c in self._costs]
        direct = all(a_ is not None for a_ in lin)
        if direct:
            del Z["I"]
            w = ca.vertcat(*[ca.vec(z) for z in Z.values()])
        from .assembly import LocalBlock, assemble
        lblocks = [LocalBlock("interval", G_int, idx_int, par_int), LocalBlock("final", G_fin, idx_fin, par_fin)]
        if direct:
            weights = np.array([c.weight * a_ for c, a_ in zip(self._costs, lin)])
            g, J, jac_g, hess_lag, grad_f = assemble(w, lblocks, other_g, int_weights=weights)
            integ = ca.sum2(G_int.map(N)(ca.reshape(w[idx_int.ravel(order="F").tolist()], idx_int.shape[0], N),
                                         ca.DM(par_int))[1])
            values = {c.name: integ[i] * a_ for i, (c, a_) in enumerate(zip(self._costs, lin))}
        else:
            values, J = {}, 0
            I = Z["I"]
            for i, c in enumerate(self._costs):
                values[c.name] = c.finish(I[i], glob)
                J = J + c.weight * values[c.name]
            g, J, jac_g, hess_lag, grad_f = assemble(w, lblocks, other_g, n_int_vars=ncost, f_extra=J)
        blocks.meta, blocks.lo, blocks.hi = (blocks.meta[:2] + blocks.meta[3:], blocks.lo[:2] + blocks.lo[3:],
                                             blocks.hi[:2] + blocks.hi[3:]) if direct else \
            (blocks.meta, blocks.lo, blocks.hi)
        lbg, ubg = blocks.vector()
        lbx, ubx, w0 = self._bounds_and_guess(Z, guess, sx, su, ss, st, co)
        if not direct:
            w0 = self._with_integrals(w0, G_int, G_fin, idx_int, par_int, idx_fin, par_fin, ncost)

        # -- what the result reports (evaluated once, numerically)
        Zi = ca.reshape(w[idx_int.ravel(order="F").tolist()], idx_int.shape[0], N)
        Zf = w[idx_fin.ravel(order="F").tolist()]
        RI = R_int.map(N)(Zi, ca.DM(par_int))
        RF = R_fin(Zf, ca.DM(par_fin))
        RI = RI if isinstance(RI, (list, tuple)) else [RI]
        RF = RF if isinstance(RF, (list, tuple)) else [RF]
        n_rep = len(rep_keys)
        outputs = {"X": X, "U": U, "S": S, "Sd": Sd, "J": J, "T": T,
                   **{f"cost:{k_}": v_ for k_, v_ in values.items()}}
        if hs:
            outputs["Xm"] = RI[0]
            for i_, k_ in enumerate(rep_keys):
                outputs[f"rep:{k_}"] = ca.horzcat(RI[1 + i_], RF[i_], RI[1 + n_rep + i_])
        else:
            for i_, k_ in enumerate(rep_keys):
                outputs[f"rep:{k_}"] = ca.horzcat(RI[i_], RF[i_])
        if glob_ctl:
            outputs["P"] = P
            if period is not None:
                outputs["period"] = period
        return dict(w=w, J=J, g=g, jac_g=jac_g, hess_lag=hess_lag, grad_f=grad_f, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx, w0=w0,
                    blocks=blocks, outputs=outputs, layout=(st, co), n_w=int(w.numel()), Z=Z,
                    scales=(sx, su, ss), local=(G_int, G_fin, idx_int, par_int, idx_fin, par_fin, ncost))

    def _with_integrals(self, w0, G_int, G_fin, idx_int, par_int, idx_fin, par_fin, ncost):
        """``w0`` with its integral variables set to the integrals of the guess (feasible rows)."""
        if not ncost:
            return w0
        w0 = np.array(w0, dtype=float)
        c = np.asarray(G_int.map(idx_int.shape[1])(w0[idx_int], par_int)[1]).sum(axis=1)
        w0[-ncost:] = c
        return w0

    def _guess_torques(self, guess):
        """Inverse-dynamics torques (nv, n_points) of the guess's motion (for scaling)."""
        from ...skeleton import rnea
        # frame by frame on the model's own skeleton (a bare pin.Model: not the batched RNEA on the skeleton
        # with its massless chains folded, which agrees to rounding): the constraint scaling takes these
        # numbers to the last bit, and IPOPT's path over thousands of iterations follows it (the folded
        # skeleton's rounding alone sent the default predictive gait to its iteration limit)
        return rnea(self.model.pin, guess["q"].T, guess["v"].T, guess["qdd"].T).T

    def _delayed_signal(self, S, P, period):
        """The signal through each muscle's electromechanical delay at the points (FF only)."""
        import casadi as ca
        pm = self._pm
        if pm.formulation != "ff" or not np.any(pm.delay > 0):
            return S
        t = self._frac * self._T0
        rows = []
        for i, d in enumerate(pm.delay):
            if d <= 0:
                rows.append(S[i, :])
                continue
            td = np.maximum(t - d, 0.0)   # before the start the excitation is held at its initial value
            if P is not None:
                Bd = self._controls.basis(td, period)
                rows.append(ca.mtimes(ca.MX(Bd) if not isinstance(Bd, ca.MX) else Bd, P[:, i]).T)
            else:
                order = np.argsort(t)
                L = np.zeros((t.size, t.size))
                ts = t[order]
                for k, tk in enumerate(td):
                    j = int(np.clip(np.searchsorted(ts, tk) - 1, 0, t.size - 2))
                    f = (tk - ts[j]) / (ts[j + 1] - ts[j])
                    L[k, order[j]], L[k, order[j + 1]] = 1.0 - f, f
                rows.append(ca.mtimes(S[i, :], ca.DM(L).T))
        return ca.vertcat(*rows)

    def _bounds_and_guess(self, Z, guess, sx, su, ss, st, co):
        model, pm, N = self.model, self._pm, self._N
        npt = self._frac.size
        m = pm.m
        lo_e, hi_e = self._ebounds
        pmod = model.pin
        qlo = np.where(np.isfinite(pmod.lowerPositionLimit) & (np.abs(pmod.lowerPositionLimit) < 1e6),
                       pmod.lowerPositionLimit, -np.inf)
        qhi = np.where(np.isfinite(pmod.upperPositionLimit) & (np.abs(pmod.upperPositionLimit) < 1e6),
                       pmod.upperPositionLimit, np.inf)
        qlo, qhi = np.maximum(qlo, self._vbounds["q"][0]), np.minimum(qhi, self._vbounds["q"][1])
        xlo = [qlo, self._vbounds["v"][0]]
        xhi = [qhi, self._vbounds["v"][1]]
        if m:
            a_min = 0.01 if pm.compliant else 0.0
            xlo.append(np.full(m, a_min))
            xhi.append(np.ones(m))
            if pm.compliant:
                flo, fhi = pm.ms.mtu.tendon_force_bounds()
                xlo.append(np.full(m, flo))
                xhi.append(np.full(m, fhi))
        xlo, xhi = np.concatenate(xlo), np.concatenate(xhi)
        ulo, uhi = [self._vbounds["qdd"][0]], [self._vbounds["qdd"][1]]
        if pm.compliant:
            ulo.append(np.full(m, self._vbounds["df_t"][0]))
            uhi.append(np.full(m, self._vbounds["df_t"][1]))
        if m and pm.formulation != "ff":
            ulo.append(np.full(m, lo_e))
            uhi.append(np.full(m, hi_e))
        if pm.formulation == "ift":
            ulo.append(np.zeros(m))
            uhi.append(np.full(m, np.inf))
        if pm.actuators:
            ulo.append(np.array([a.min_control for a in pm.actuators]))
            uhi.append(np.array([a.max_control for a in pm.actuators]))
        ulo, uhi = np.concatenate(ulo), np.concatenate(uhi)
        nodes = slice(0, N + 1)
        xg = np.vstack([guess["q"][:, nodes], guess["v"][:, nodes]]
                       + ([guess["a"][:, nodes]] if m else []) + ([guess["f_t"][:, nodes]] if pm.compliant else []))
        ug = [guess["qdd"]]
        if pm.compliant:
            ug.append(guess["df_t"])
        if m and pm.formulation != "ff":
            ug.append(guess["e"])
        if pm.formulation == "ift":
            ug.append(guess["F"])
        if pm.actuators:
            ug.append(guess.get("act", np.zeros((len(pm.actuators), npt))))
        ug = np.vstack(ug)
        sig = {"ff": "e", "ifm": "F", "ift": "tau"}[pm.formulation]
        parts = {}

        def put(key, lo, hi, w0, scale):
            sc = np.asarray(scale, dtype=float)
            parts[key] = ((lo / sc).ravel(order="F"), (hi / sc).ravel(order="F"),
                          (np.clip(w0, lo, hi) / sc).ravel(order="F"))

        put("X", np.repeat(xlo[:, None], N + 1, 1), np.repeat(xhi[:, None], N + 1, 1), xg, sx[:, None])
        put("U", np.repeat(ulo[:, None], npt, 1), np.repeat(uhi[:, None], npt, 1), ug, su[:, None])
        ctl = self._controls
        ns = pm.n_signal
        if pm.formulation == "ff":
            slo, shi = np.full(ns, lo_e), np.full(ns, hi_e)
        elif pm.formulation == "ifm":
            slo, shi = np.zeros(ns), np.full(ns, np.inf)
        else:
            slo, shi = np.full(ns, -np.inf), np.full(ns, np.inf)
        put("S", np.repeat(slo[:, None], npt, 1), np.repeat(shi[:, None], npt, 1), guess[sig], ss[:, None])
        t = self._frac * self._T0
        coef = None
        if isinstance(ctl, GlobalControls):
            coef = ctl.parametrization.fit(t, guess[sig].T)
            put("P", np.full(coef.shape, -np.inf), np.full(coef.shape, np.inf), coef, ss[None, :])
        if "period" in Z:
            p0 = ctl.parametrization.period
            lo, hi = ctl.period_bounds
            put("period", np.array([lo * p0]), np.array([hi * p0]), np.array([p0]), p0)
        if "Sd" in Z:
            sd0 = np.empty((ns, npt))
            for i, d in enumerate(pm.delay):
                td = np.maximum(t - d, 0.0)
                if coef is not None:
                    sd0[i] = ctl.basis(td) @ coef[:, i]
                else:
                    o = np.argsort(t)
                    sd0[i] = np.interp(td, t[o], guess[sig][i, o])
            put("Sd", np.full((ns, npt), -np.inf), np.full((ns, npt), np.inf), sd0, ss[:, None])
        if "T" in Z:
            lo, hi = self._Tb
            put("T", np.array([lo]), np.array([hi]), np.array([self._T0]), self._T0)
        if "I" in Z:      # the integrals: free; their start is set from the guess (_with_integrals)
            n_ = int(Z["I"].numel())
            parts["I"] = (np.full(n_, -np.inf), np.full(n_, np.inf), np.zeros(n_))
        return tuple(np.concatenate([parts[k][i] for k in Z]) for i in range(3))

    # ------------------------------------------------------------------ solve
    def _ipopt_options(self) -> dict:
        s = self._solver
        verbose = self.verbose if self.verbose is not None else sys.stdout.isatty()
        level = int(s.get("print_level", 5))
        opts = {"expand": False, "print_time": False,
                "ipopt.print_level": level if verbose else 0,
                "ipopt.sb": "yes", "ipopt.tol": float(s.get("tol", 1e-8)),
                "ipopt.max_iter": int(s.get("max_iter", 1000)),
                "ipopt.mu_strategy": s.get("mu_strategy", "adaptive"),
                "ipopt.linear_solver": s.get("linear_solver", "mumps"),
                "ipopt.hessian_approximation": s.get("hessian", "exact")}
        for k in ("acceptable_tol", "bound_push", "acceptable_constr_viol_tol"):
            if k in s:
                opts[f"ipopt.{k}"] = float(s[k])
        if "acceptable_iter" in s:
            opts["ipopt.acceptable_iter"] = int(s["acceptable_iter"])
        if "nlp_scaling_method" in s:
            opts["ipopt.nlp_scaling_method"] = str(s["nlp_scaling_method"])
        if self.solver_log is not None:       # appended: every solve of a fit (starts, stages) in one file
            opts.update({"ipopt.output_file": str(self.solver_log), "ipopt.file_print_level": level,
                         "ipopt.file_append": "yes"})
        return opts

    def fit(self):
        """Build the NLP, solve it from ``n_starts`` guesses with IPOPT, keep the best converged."""
        import casadi as ca
        t_start = _time.perf_counter()
        self._setup()
        t = self._frac * self._T0
        n_starts = int(self.n_starts)
        if n_starts < 1:
            raise ModelError(f"n_starts must be >= 1, got {self.n_starts}")
        if n_starts > 1 and self.guess is not None:
            raise ModelError(f"n_starts={n_starts} counts automatic guesses; with a guess given, one start "
                             "is solved: pass n_starts=1 (or no guess)")
        start = self.__dict__.get("_warm", self.guess)     # a subclass's warm start, else the argument
        guesses = ([self._guess_from_trial(start, t)] if start is not None
                   else [self._auto_guess(t, k) for k in range(n_starts)])
        nlp = self._build(guesses[0])
        from .threads import single_threaded
        single_threaded()
        opts = self._ipopt_options()
        opts.update(jac_g=nlp["jac_g"], hess_lag=nlp["hess_lag"])
        if nlp["grad_f"] is not None:
            opts["grad_f"] = nlp["grad_f"]
        # every iteration passes through it: the monitor's progress, and Ctrl-C ends the fit
        callback = _IterationCallback(self.monitor, nlp["w"].numel(), nlp["lbg"], nlp["ubg"])
        opts["iteration_callback"] = callback
        solver = ca.nlpsol("ocp", "ipopt", {"x": nlp["w"], "f": nlp["J"], "g": nlp["g"]}, opts)
        out_fn = ca.Function("outputs", [nlp["w"]], list(nlp["outputs"].values()))
        records, best = [], None
        ctol = float(self._solver.get("constraint_tol", 1e-6))
        for k, gs in enumerate(guesses):
            w0 = nlp["w0"] if k == 0 else self._build_guess_only(nlp, gs)
            label = f"{self._N} intervals" + (f", start {k + 1}/{len(guesses)}" if len(guesses) > 1 else "")
            if self.solver_log is not None:
                with open(self.solver_log, "a", encoding="utf-8") as fh:
                    fh.write(f"# pinmsk: IPOPT solve of model '{self.model.name}', {label}\n")
            callback.reset()
            if self.monitor is not None:
                self.monitor.start(label)
            t0 = _time.perf_counter()
            try:
                with _interrupt_flag(callback):
                    sol = solver(x0=w0, lbx=nlp["lbx"], ubx=nlp["ubx"], lbg=nlp["lbg"], ubg=nlp["ubg"])
                if callback.interrupted:      # Ctrl-C: IPOPT stopped at the callback's request
                    raise KeyboardInterrupt
            except BaseException:
                if self.monitor is not None:      # an interrupted solve closes its progress line
                    self.monitor.end(None)
                raise
            stats = solver.stats()
            wv = np.asarray(sol["x"]).ravel()
            gv = np.asarray(sol["g"]).ravel()
            viol = nlp["blocks"].max_violation(gv, nlp["lbg"], nlp["ubg"])
            status = str(stats.get("return_status", "unknown"))
            ok = (status == "Solve_Succeeded" or (status == "Solved_To_Acceptable_Level" and viol <= ctol)) \
                and np.all(np.isfinite(wv))
            msg = status
            if not ok:
                _, worst = nlp["blocks"].worst(gv, nlp["lbg"], nlp["ubg"])
                if worst:
                    msg = f"{status}; largest violation: {worst}"
            rec = {"start": k, "converged": bool(ok), "status": msg, "objective": float(sol["f"]),
                   "iterations": int(stats.get("iter_count", -1)), "seconds": _time.perf_counter() - t0,
                   "violation": viol}
            records.append(rec)
            if self.monitor is not None:
                self.monitor.end(rec)
            if best is None or (ok and (not best[0]["converged"] or rec["objective"] < best[0]["objective"])):
                best = (rec, wv)
        self._nlp = nlp
        self.result_ = self._result(nlp, out_fn, best, records, _time.perf_counter() - t_start)
        return self

    def _build_guess_only(self, nlp, guess):
        """The scaled start vector of another guess on the same NLP (the first guess's scales)."""
        return self._bounds_and_guess(nlp["Z"], guess, *nlp["scales"], *nlp["layout"])[2]

    # ------------------------------------------------------------------ result
    def _result(self, nlp, out_fn, best, records, seconds) -> Result:
        rec, wv = best
        vals = dict(zip(nlp["outputs"].keys(), [np.asarray(v) for v in out_fn(wv)]))
        pm, N = self._pm, self._N
        st, co = nlp["layout"]
        T = float(np.asarray(vals["T"]).ravel()[0]) if "T" in vals else self._T0
        X, U, S = vals["X"], vals["U"], vals["S"]
        Xall = np.hstack([X, vals["Xm"]]) if "Xm" in vals else X
        order = np.argsort(self._frac, kind="stable")
        t = (self._frac * T)[order]
        names, muscles = self.model.coordinates, tuple(self.model.muscle_names) if pm.m else ()
        ch = {}
        for j, c in enumerate(names):
            ch[c] = Xall[st["q"][j], order]
            ch[f"{c}_speed"] = Xall[st["v"][j], order]
            ch[f"{c}_acceleration"] = U[co["qdd"][j], order]
        for j, tg in self._targets().items():
            ch[f"{names[j]}_desired"] = np.asarray(tg(t), dtype=float)
        if pm.m:
            e = S if pm.formulation == "ff" else vals["rep:e"]
            F = vals["rep:F"]
            for i, n_ in enumerate(muscles):
                ch[f"{n_}_excitation"] = e[i, order]
                ch[f"{n_}_activation"] = Xall[st["a"][i], order]
                ch[f"{n_}_force"] = F[i, order]
                if pm.compliant:
                    ch[f"{n_}_tendon_force"] = Xall[st["f_t"][i], order] * pm.ms.mtu.f_max[i]
            if vals["rep:metabolic_rate"].size:
                for i, n_ in enumerate(muscles):
                    ch[f"{n_}_metabolic_rate"] = vals["rep:metabolic_rate"][i, order]
        if pm.formulation == "ift":
            for k, j in enumerate(pm.driven):
                ch[f"{names[j]}_torque_signal"] = S[k, order]
        for k, a_ in enumerate(pm.actuators):
            ch[f"{a_.name}_control"] = U[co["act"][k], order]
        cf = vals["rep:contact_forces"]
        for i, c in enumerate(pm.contacts):
            for k, ax in enumerate("xyz"):
                ch[f"{c.label}_force_{ax}"] = cf[3 * i + k, order]
        terms = {c.name: float(np.asarray(vals[f"cost:{c.name}"]).ravel()[0]) for c in self._costs}
        objective = float(np.asarray(vals["J"]).ravel()[0])
        err = 0.0
        for j, tg in self._targets().items():
            err = max(err, float(np.max(np.abs(ch[names[j]] - ch[f"{names[j]}_desired"]))))
        e_all = S if pm.formulation == "ff" else (vals["rep:e"] if pm.m else np.zeros((0, 1)))
        lo, hi = self._ebounds
        bviol = float(max(np.max(np.maximum(lo - e_all, 0), initial=0.0), np.max(np.maximum(e_all - hi, 0), initial=0.0)))
        ctl = self._controls
        info = dict(status=rec["status"], terms=terms, seconds=seconds,
                    nit=rec["iterations"], n_variables=nlp["n_w"],
                    n_constraints=int(nlp["lbg"].size), scheme=self.scheme, intervals=N,
                    design=pm.formulation, formulation=pm.formulation, tendon=pm.tendon,
                    controls=ctl.describe(), horizon=T, max_tracking_error=err, max_bound_violation=bviol,
                    starts=records, coordinates=names, muscles=muscles, x=wv)
        if "P" in vals:
            info["coeffs"] = vals["P"]
            par = ctl.parametrization
            if ctl.free_period:
                info["period"] = float(np.asarray(vals["period"]).ravel()[0])
                par = par.with_period(info["period"])
            info["parametrization"] = par
        stats = FitStatistics(k=nlp["n_w"], converged=bool(rec["converged"]), message=rec["status"],
                              iterations=int(rec["iterations"]), violation=float(rec["violation"]),
                              objective=objective)
        res = Result(t, ch, stats=stats, info=info, report=self._report_text(stats, info))
        if not rec["converged"] and self.monitor is None:      # a monitor has shown each stage's status
            print(f"pinmsk: optimal control did not converge: {rec['status']}", file=sys.stderr)
        return res

    def _report_text(self, stats, info) -> str:
        flag = "CONVERGED" if stats.converged else "NOT CONVERGED (not a solution)"
        terms = ", ".join(f"{k} {v:.6g}" for k, v in info["terms"].items())
        return format_report(
            f"Optimal control ({info['formulation']} formulation, {info['scheme']}, {info['intervals']} intervals, "
            f"{info['controls']['kind']} controls) of model '{self.model.name}': {flag}", [
                ("status", info["status"]),
                ("objective", f"{stats.objective:.6g} ({terms})"),
                ("tracking", f"max error {info['max_tracking_error']:.4g} rad"),
                ("solver", f"IPOPT, {info['nit']} iterations, {info['n_variables']} variables, "
                           f"{info['n_constraints']} constraints, exact derivatives (CasADi)"),
                ("time", f"{info['seconds']:.2f} s (horizon {info['horizon']:.4g} s)"),
            ])

    def to_dict(self) -> dict:
        """The fit as a JSON-ready dict (what ``pinmsk optimize`` writes to ``<out>.json``)."""
        self._check_fitted()
        r = self.result_
        out = {"converged": bool(r.converged), "status": r.status, "objective": float(r.objective),
               "seconds": float(r.seconds), "iterations": int(r.iterations),
               "terms": {k: float(v) for k, v in r.terms.items()},
               "max_bound_violation": float(r.max_bound_violation),
               "max_tracking_error": float(r.max_tracking_error),
               "design": r.design, "scheme": r.scheme, "intervals": int(r.intervals),
               "duration": float(r.horizon), "controls": r.controls,
               "n_variables": int(r.n_variables), "n_constraints": int(r.n_constraints),
               "starts": r.starts}
        if "coeffs" in r.info:
            out["coefficients"] = np.asarray(r.coeffs).tolist()
            out["parametrization"] = r.parametrization.describe()
        return out
