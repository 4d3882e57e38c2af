"""Fitting one effect's parameters to the equation error, in and out of sample.

The one entry point is :class:`EffectFit`:
``EffectFit(effect).fit(comparison).result_`` is a :class:`~pinmsk.fitting.Result`
-- the change of the compared channels the fitted effect makes, with the
fit's statistics and the details ``effect`` (the fitted component),
``params`` and ``stderr`` -- the same type as every ranked candidate's
``EffectScore.fit`` in :mod:`pinmsk.diagnose.diagnosis`.

An effect with parameters ``theta`` changes the equation error ``e`` (see
:mod:`pinmsk.diagnose.compare`) by ``d(theta)``; the fit minimises the
noise-whitened sum of squares ``sum_c sum_k ((e_kc + d_kc(theta)) / sigma_c)^2``
within the parameters' bounds:

* ``linear`` components (``d = B theta``): linear least squares, bounded by
  :func:`scipy.optimize.lsq_linear` when the unconstrained solution leaves the
  bounds -- exact and fast;
* others: :func:`scipy.optimize.least_squares` (trust-region reflective,
  bounds), with the component's analytic ``param_jacobian`` when it has one
  and forward differences evaluated in one batched call otherwise; started
  from the best of the component's ``initial_guess`` values (if it has the
  hook), its current values and, for muscle-level effects, a grid over the
  bounds evaluated in one batch.

Uncertainties: ``cov = s^2 (J^T J)^-1`` with ``J`` the whitened Jacobian at
the optimum and ``s^2`` the residual variance, inflated by
``(1 + rho) / (1 - rho)`` with ``rho`` the residual's lag-1 autocorrelation (an
AR(1) effective-sample-size correction, :func:`ar1_inflation`; the
filtered-kinematics and EMG-envelope parts of the noise are not white).  It
overstates the correction for band-limited noise, whose autocorrelation falls
off faster than ``rho^j``, which keeps the reported errors conservative; the
identifiability checks (:mod:`pinmsk.diagnose.scoring`), which ask whether the
likelihood is flat, use the integrated autocorrelation instead
(:func:`inflation`: the Newey-West long-run variance over the variance).

Blocked cross-validation (:meth:`EffectFit.cross_validate`): the frames
are cut into ``folds`` contiguous blocks; each block is predicted by the fit
on the others, leaving out a guard of ``guard`` frames on either side of the
held-out block (the low-pass filter correlates neighbouring frames).

Several effects at once (:class:`JointProblem`): the earlier effects of a
diagnosis loop and a candidate, fitted together -- linear ones exactly, the
others by trust-region least squares from warm starts -- with the covariance of
all their parameters (a pseudo-inverse on the identifiable subspace), the rank
and condition number of the sensitivity matrix, and profile-likelihood
intervals (:meth:`JointProblem.profile_interval`).  Measurement effects
(``sensor_gain``, ``sensor_offset``) change the model's reading of their
channel, ``tau - measure(tau)``, where ``tau`` is what reaches that sensor.
"""
from __future__ import annotations

import itertools

import numpy as np
from scipy.optimize import least_squares, lsq_linear

from ..components import Component
from ..effects._base import SignalEffect
from ..errors import ConvergenceError, ModelError
from ..fitting import FitStatistics, Fitter, Result, format_report
from ..stats import weighted_sse
from ..trial import moment_channel

__all__ = ["EffectFit", "EffectProblem", "JointProblem", "cv_blocks", "describe_fit"]



def _informative(se, span):
    """Standard errors with those over a million times the parameter's whole range (``span``) set to
    inf (not determined): such an error comes from a curvature or a condition number at rounding
    level, and whether it is finite or not would flip with the last bits of the data."""
    return np.where(se > 1e6 * np.where(np.isfinite(span), span, np.inf), np.inf, se)

class EffectProblem:
    """One effect on one :class:`~pinmsk.diagnose.compare.EquationError`, prepared for fitting.

    Built once per effect (the component's caches, the channels it changes);
    :meth:`solve` finds the parameters on any subset of the frames, which is
    what the cross-validation repeats.  :class:`EffectFit` is the fitter
    around it.
    """

    def __init__(self, eq, sigma: np.ndarray, component: Component):
        self.eq = eq
        self.component = component
        self.model = eq.model
        self.signal = isinstance(component, SignalEffect)
        # a measurement effect changes the modelled reading of its channel, not the skeleton
        self.sensor = getattr(component, "level", None) == "sensor"
        # Fit on the channels the effect can change (a joint effect: its coordinate's); the others
        # only add a constant to the sum of squares.
        affected = getattr(component, "affected_coordinates", None)
        if affected is not None and not self.signal:
            names = set(affected())
            act = np.array([j for j, c in enumerate(eq.coordinates) if c in names], dtype=int)
            if act.size == 0:
                raise ModelError(f"{component.label} acts on {', '.join(sorted(names))}, which this comparison "
                                 f"does not include (compared: {', '.join(eq.coordinates)})")
        else:
            act = np.arange(len(eq.coordinates))
        self.act = act
        self.e = eq.e[:, act]
        self.sigma_full = np.asarray(sigma, dtype=float)
        self.sigma = self.sigma_full[act]
        self.columns = eq.columns[act]
        rest = np.setdiff1d(np.arange(len(eq.coordinates)), act)
        self._rest_sq = weighted_sse(eq.e[:, rest], self.sigma_full[rest], axis=1)   # per frame
        if getattr(component, "level", "joint") == "muscle" and eq.mode != "muscle":
            raise ModelError(f"{component.label} acts through muscle excitations; it can only be fitted "
                             "in a muscle-level comparison (a trial with <muscle>_excitation or _emg channels)")
        decl = component.params
        self.all_names = list(decl)
        self.names = [n for n, p in decl.items() if p.vary]
        self.fixed = {n: p.value for n, p in decl.items() if not p.vary}
        self.lo = np.array([decl[n].min for n in self.names], dtype=float)
        self.hi = np.array([decl[n].max for n in self.names], dtype=float)
        self.x_default = np.array([decl[n].value for n in self.names], dtype=float)
        # a correction of the measured loads (a force plate's) gets the comparison's loads
        loads = {"loads": eq._ext_rows} if getattr(component, "needs_loads", False) else {}
        self.cache = None if self.signal or self.sensor else component.prepare(self.model, eq.motion_rows,
                                                                              data=eq.data, **loads)
        if self.sensor:
            if eq.mode != "torque":
                raise ModelError(f"{component.label} models the sensor of a recorded {component.channel}; "
                                 "it applies to torque- and motion-level comparisons only")
            self.reading = eq.sensor_input(component)
        self._basis = None
        self._memo = None
        self.nfev = 0

    # -- predictions of the change of e -------------------------------------------------
    def _params(self, x) -> dict:
        out = dict(self.fixed)
        out.update(zip(self.names, np.asarray(x, dtype=float)))
        return out

    @property
    def linear(self) -> bool:
        return bool(getattr(self.component, "linear", False)) and not self.fixed

    def basis(self) -> np.ndarray:
        """``B`` with ``d = B theta`` for linear components, ``(n, C, p)``."""
        if self._basis is None:
            self._basis = self.jacobian(self.x_default)
        return self._basis

    def predict(self, X) -> np.ndarray:
        """Change of ``e`` for parameter sets ``X`` (P, p) -> (P, n, C)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if X.shape[0] == 1 and self._memo is not None and np.array_equal(self._memo[0], X[0]):
            return self._memo[1][None]
        out = self._predict(X)
        self._memo = (X[0].copy(), out[0])
        return out

    def _predict(self, X) -> np.ndarray:
        self.nfev += X.shape[0]
        if self.signal:
            batch = {n: np.full(X.shape[0], v) for n, v in self.fixed.items()}
            batch.update({n: X[:, k] for k, n in enumerate(self.names)})
            return self.eq.signal_delta(self.component, batch)[:, :, self.act]
        if self.linear:
            return np.einsum("ncp,Pp->Pnc", self.basis(), X)
        if self.sensor:      # the model reads measure(tau) instead of tau: e falls by the difference
            return np.stack([(self.reading - self.component.measure(self.reading, self._params(x)))[:, None]
                             for x in X])
        out = np.empty((X.shape[0], self.eq.rows.size, self.act.size))
        for k, x in enumerate(X):
            Q = self.component.generalized_force(self.model, self.eq.motion_rows, self._params(x), self.cache)
            out[k] = self.eq.project(Q, self.act)
        return out

    def jacobian(self, x) -> np.ndarray:
        """``d(change of e)/d theta`` at ``x``, ``(n, C, p)``."""
        comp = self.component
        if self.sensor:
            idx = [self.all_names.index(n) for n in self.names]
            return -comp.measure_jacobian(self.reading, self._params(x))[:, None, idx]
        if not self.signal and hasattr(comp, "param_jacobian"):
            J = comp.param_jacobian(self.model, self.eq.motion_rows, self._params(x), self.cache)
            idx = [self.all_names.index(n) for n in self.names]
            return self.eq.project_jacobian(J, self.act)[:, :, idx]
        x = np.asarray(x, dtype=float)
        span = np.where(np.isfinite(self.hi - self.lo), self.hi - self.lo, 1.0)
        h = 1e-6 * np.maximum(np.abs(x), 1e-3 * span) + 1e-12
        step = np.where(x + h <= self.hi, h, -h)
        X = np.vstack([x, x + np.diag(step)])
        D = self.predict(X)
        return np.moveaxis((D[1:] - D[0]) / step[:, None, None], 0, -1)

    # -- objective ---------------------------------------------------------------------
    def _whiten(self, d, mask):
        r = (self.e + d) / self.sigma
        return r[mask].ravel()

    def sse(self, X, mask=None) -> np.ndarray:
        """Whitened SSE of ``e + d(x)`` on the ``mask`` rows for each parameter set (P,)."""
        mask = slice(None) if mask is None else mask
        D = self.predict(X)
        return weighted_sse((self.e[None] + D)[:, mask], self.sigma, axis=(1, 2))

    # -- fitting ------------------------------------------------------------------------
    def starts(self, mask) -> list[np.ndarray]:
        out = [np.clip(self.x_default, self.lo, self.hi)]
        comp = self.component
        if hasattr(comp, "initial_guess") and not self.signal and not self.sensor:
            rows_motion = self.eq.motion_rows.subset(np.flatnonzero(mask))
            # the hook's target is per joint: the compared coordinates' (on an exact import, the joints that
            # are OpenSim coordinates; a start value only, the fit itself uses the projection)
            target = np.full((rows_motion.n_frames, self.model.nv), np.nan)
            joint = self.columns >= 0
            target[:, self.columns[joint]] = -self.e[mask][:, joint]
            # a cache indexed by frame (``frame_cache``) is the masked rows' own: not recomputed for the guess
            by_frame = getattr(comp, "frame_cache", False) and self.cache is not None
            cache = self.cache[np.flatnonzero(mask)] if by_frame else None
            try:
                guesses = comp.initial_guess(self.model, rows_motion, target, cache) or []
            except Exception:           # a bad guess hook must not stop the fit
                guesses = []
            for g in guesses:
                x = np.array([g.get(n, v) for n, v in zip(self.names, self.x_default)], dtype=float)
                out.append(np.clip(x, self.lo, self.hi))
        if self.signal:
            grids = []
            for lo, hi in zip(self.lo, self.hi):
                if lo > 0 and hi / lo > 10:
                    grids.append(np.geomspace(lo * 1.5, hi / 1.5, 7))
                else:
                    grids.append(np.linspace(lo, hi, 9)[1:-1] if lo < hi else np.array([lo]))
            X = np.array(list(itertools.product(*grids)), dtype=float)
            s = self.sse(X, mask)
            out.extend(X[np.argsort(s)[:2]])
        return out

    def solve(self, mask=None, x0=None, *, max_nfev: int = 100) -> tuple[np.ndarray, bool, str]:
        """Best parameters on the ``mask`` rows: ``(x, converged, message)``."""
        n = self.eq.rows.size
        mask = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if not self.names:
            return np.zeros(0), True, "no free parameters"
        if self.linear:
            B = self.basis()[mask] / self.sigma[None, :, None]
            A = B.reshape(-1, B.shape[-1])
            b = -(self.e[mask] / self.sigma).ravel()
            x, *_ = np.linalg.lstsq(A, b, rcond=None)
            if np.all(x >= self.lo) and np.all(x <= self.hi):
                return x, True, "linear least squares"
            res = lsq_linear(A, b, bounds=(self.lo, self.hi))
            return res.x, bool(res.success), f"bounded linear least squares: {res.message}"
        if len(self.names) == 1:
            return self._fit_scalar(mask)
        candidates = [x0] if x0 is not None else self.starts(mask)
        if len(candidates) > 1:
            s = self.sse(np.array(candidates), mask)
            order = np.argsort(s)
            candidates = [candidates[i] for i in order[:2]]
        best = None
        for start in candidates:
            res = self._least_squares(start, mask, max_nfev)
            if best is None or res.cost < best.cost:
                best = res
        return best.x, bool(best.status > 0), str(best.message)

    def _grid(self):
        """Predictions on a 1-D grid over the bounds, computed once in one batch (``(G,), (G, n, C)``)."""
        if getattr(self, "_grid_cache", None) is None:
            lo, hi = float(self.lo[0]), float(self.hi[0])
            if not np.isfinite(lo) or not np.isfinite(hi):
                c = float(self.x_default[0])
                w = max(abs(c), 1.0)
                lo, hi = (max(lo, c - 10 * w), min(hi, c + 10 * w))
            g = np.geomspace(lo, hi, 33) if lo > 0 and hi / lo > 10 else np.linspace(lo, hi, 33)
            self._grid_cache = (g, self.predict(g[:, None]))
        return self._grid_cache

    def _fit_scalar(self, mask):
        """One free parameter: grid, then bounded Brent on the bracket around the best grid point.

        Least squares (Gauss-Newton) steps are poor here when the prediction
        carries measured noise that moves with the parameter (a delayed noisy
        EMG): ``J^T J`` then far exceeds the curvature of the sum of squares.
        """
        from scipy.optimize import minimize_scalar

        g, D = self._grid()
        sse = weighted_sse((self.e[None] + D)[:, mask], self.sigma, axis=(1, 2))
        if not np.all(np.isfinite(sse)):
            bad = g[~np.isfinite(sse)]
            raise ConvergenceError(
                f"fitting {self.component.label}: the model gave non-finite values for "
                f"{self.names[0]} = {bad[0]:.6g} (and {bad.size - 1} more grid values); tighten its bounds"
            )
        i = int(np.argmin(sse))
        a, b = g[max(i - 1, 0)], g[min(i + 1, g.size - 1)]
        if a == b:
            return np.array([a]), True, "grid"

        def f(x):
            return float(self.sse(np.array([[x]]), mask)[0])

        res = minimize_scalar(f, bounds=(a, b), method="bounded",
                              options={"xatol": 1e-7 * max(abs(b - a), 1e-12), "maxiter": 100})
        x = res.x if res.fun <= sse[i] else g[i]
        return np.array([x]), bool(res.success), f"grid + bounded Brent: {res.message}"

    def _least_squares(self, x0, mask, max_nfev):
        span = self.hi - self.lo
        eps = np.where(np.isfinite(span), 1e-9 * span, 1e-9)
        x0 = np.clip(np.asarray(x0, dtype=float), self.lo + eps, self.hi - eps)

        def fun(x):
            d = self.predict(x[None])[0]
            r = self._whiten(d, mask)
            if not np.all(np.isfinite(r)):
                raise ConvergenceError(
                    f"fitting {self.component.label}: the model gave non-finite values at "
                    f"{dict(zip(self.names, np.round(x, 6)))}; tighten the parameter bounds"
                )
            return r

        def jac(x):
            J = self.jacobian(x)[mask] / self.sigma[None, :, None]
            return J.reshape(-1, J.shape[-1])

        return least_squares(fun, x0, jac=jac, bounds=(self.lo, self.hi), method="trf",
                             x_scale="jac", max_nfev=max_nfev, xtol=1e-8, ftol=1e-9)

    def result(self, x, converged: bool, message: str, mask=None) -> Result:
        """The :class:`~pinmsk.fitting.Result` of the parameters ``x`` (fit on ``mask``), with uncertainties."""
        n_rows = self.eq.rows.size
        mask = np.ones(n_rows, dtype=bool) if mask is None else mask
        d = self.predict(x[None])[0] if self.names else np.zeros_like(self.e)
        r = ((self.e + d) / self.sigma)[mask]
        rest = float(np.sum(self._rest_sq[mask]))
        sse = weighted_sse((self.e + d)[mask], self.sigma) + rest      # over all channels
        sse0 = weighted_sse(self.e[mask], self.sigma) + rest
        n_all = int(np.sum(mask)) * self.eq.e.shape[1]
        n = int(r.size)
        p = len(self.names)
        stderr = {}
        if p:
            s2 = (sse - rest) / max(n - p, 1)
            J3 = self.jacobian(x)[mask] / self.sigma[None, :, None]            # (n, C, p)
            if p == 1 and not self.linear:
                # curvature of the sum of squares itself (see _fit_scalar): cov = 2 s^2 / SSE''
                span = (self.hi - self.lo)[0] if np.isfinite(self.hi - self.lo)[0] else max(abs(x[0]), 1.0)
                h = 1e-3 * span
                xs = np.clip(np.array([[x[0] - h], [x[0]], [x[0] + h]]), self.lo, self.hi)
                S = self.sse(xs, mask)
                hh = 0.5 * (xs[2, 0] - xs[0, 0])
                curv = (S[0] - 2 * S[1] + S[2]) / hh ** 2 if hh > 0 else 0.0
                JtJ = np.array([[0.5 * curv]]) if curv > 0 else np.zeros((1, 1))
            else:
                J = J3.reshape(-1, p)
                JtJ = J.T @ J
            try:
                if not np.all(np.isfinite(JtJ)) or np.linalg.cond(JtJ) > 1e12:
                    raise np.linalg.LinAlgError("singular")      # parameters not identifiable here
                with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                    A_inv = np.linalg.inv(JtJ)
                    G = channel_inflation(J3, r)
                    cov = A_inv * s2 * G[0, 0] if p == 1 else A_inv @ G @ A_inv * s2
                    se = np.sqrt(np.clip(np.diag(cov), 0, None))
                se = np.where(np.isfinite(se), se, np.inf)
            except np.linalg.LinAlgError:
                se = np.full(p, np.inf)
            span = self.hi - self.lo
            se = _informative(se, span)
            tol = np.where(np.isfinite(span), 1e-8 * span, 1e-9)
            at_bound = (x <= self.lo + tol) | (x >= self.hi - tol)
            se = np.where(at_bound, np.nan, se)          # no curvature-based error at a bound
            stderr = dict(zip(self.names, map(float, se)))
        values = self._params(x)
        clipped = {k: float(np.clip(v, self.component.params[k].min, self.component.params[k].max))
                   for k, v in values.items()}
        effect = self.component.with_params(clipped, stderr=stderr)
        full = np.zeros_like(self.eq.e)
        full[:, self.act] = d
        stats = FitStatistics(n=n_all, k=p, sse=sse, sse_before=sse0, variance="estimated", converged=converged,
                              message=message, iterations=self.nfev, objective=sse)
        info = {"effect": effect, "params": {k: clipped[k] for k in self.all_names}, "stderr": stderr,
                "delta": full}
        channels = {moment_channel(c): full[:, j] for j, c in enumerate(self.eq.coordinates)}
        title = f"{effect.label}: {_describe(effect, info['params'], stderr)}"
        return Result(self.eq.motion.t[self.eq.rows], channels, stats=stats, info=info,
                      meta={"analysis": "effect_fit", "effect": effect.label},
                      report=format_report(title, stats.rows()))

    def cross_validate(self, folds: int, guard: int, x_full=None) -> tuple[np.ndarray, bool]:
        """Held-out predictions: ``e`` plus each block's change predicted by the fit on the others."""
        n = self.eq.rows.size
        blocks = np.array_split(np.arange(n), folds)
        e_cv = self.eq.e.copy()
        ok = True
        for blk in blocks:
            train = np.ones(n, dtype=bool)
            train[max(blk[0] - guard, 0):min(blk[-1] + guard + 1, n)] = False
            if not self.names:
                x = np.zeros(0)
            elif self.linear or x_full is None:
                x, conv, _ = self.solve(train)
                ok &= conv
            else:
                x, conv, _ = self.solve(train, x0=x_full, max_nfev=30)
            d = self.predict(x[None])[0] if self.names else 0.0
            e_cv[np.ix_(blk, self.act)] = (self.e + d)[blk]
        return e_cv, ok


def long_run_variance(u: np.ndarray) -> tuple[float, int]:
    """Newey-West (Bartlett kernel) long-run variance of the series ``u`` (demeaned) with the bandwidth of
    Andrews (1991) for an AR(1) plug-in, ``L = 1.1447 (a n)^(1/3)``, ``a = 4 rho^2 / ((1 - rho)^2 (1 +
    rho)^2)``: ``(lrv, L)``."""
    u = np.asarray(u, dtype=float)
    n = u.size
    uc = u - np.mean(u) if n else u
    g0 = float(uc @ uc) / max(n, 1)
    if n < 3 or g0 <= 0:
        return g0, 0
    rho = float(np.clip(np.dot(uc[1:], uc[:-1]) / (n * g0), 0.0, 0.995))
    a = 4 * rho ** 2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    L = int(min(max(np.ceil(1.1447 * (a * n) ** (1 / 3)), 1), n // 4))
    m = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(uc, m)
    acov = np.fft.irfft(f * np.conj(f), m)[:L + 1] / n
    w = 1.0 - np.arange(1, L + 1) / (L + 1)
    return max(acov[0] + 2.0 * float(np.dot(w, acov[1:])), acov[0] / n), L


def ar1_inflation(r: np.ndarray) -> float:
    """``(1 + rho) / (1 - rho)``, ``rho`` the lag-1 autocorrelation of the residual ``r`` (clipped to
    [0, 0.98]): the AR(1) effective-sample-size factor of the reported standard errors (conservative for
    band-limited noise, whose autocorrelation falls off faster than ``rho^j``)."""
    r = np.asarray(r, dtype=float)
    if r.ndim == 1:
        r = r[:, None]
    den = np.sum(r * r)
    rho = float(np.clip(np.sum(r[1:] * r[:-1]) / den if den > 0 else 0.0, 0.0, 0.98))
    return (1 + rho) / (1 - rho)


def channel_inflation(J3: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The meat of the channel-wise sandwich covariance ``s^2 (J^T J)^-1 B (J^T J)^-1``: ``B = sum_c k_c
    J_c^T J_c`` ``(p, p)``, ``k_c`` the AR(1) inflation of channel ``c``'s residual
    (:func:`ar1_inflation`); for one parameter, ``B / (J^T J)``, the information-weighted mean
    inflation ``sum_c k_c |J_c|^2 / sum_c |J_c|^2`` (so a curvature-based ``J^T J`` can use it).
    ``J3`` (n, C, p) is the whitened Jacobian, ``r`` (n, C) the whitened residual.  A parameter one
    smooth channel determines gets that channel's inflation, not the pooled one of channels it barely
    sees."""
    n, C, p = J3.shape
    k = np.array([ar1_inflation(r[:, c]) for c in range(C)])
    B = np.einsum("c,ncp,ncq->pq", k, J3, J3)
    if p == 1:
        tot = float(np.sum(J3 ** 2))
        return np.array([[float(B[0, 0]) / tot if tot > 0 else float(np.max(k, initial=1.0))]])
    return B


def inflation(r: np.ndarray) -> float:
    """Variance inflation of a sum over the autocorrelated residual ``r`` (n,) or (n, C): its long-run
    variance over its variance (the integrated autocorrelation, Bartlett-weighted; 1 for white noise),
    the channels weighted by their variances."""
    r = np.asarray(r, dtype=float)
    if r.ndim == 1:
        r = r[:, None]
    num = den = 0.0
    for c in r.T:
        lrv, _ = long_run_variance(c)
        v = float(np.var(c))
        num += lrv
        den += v
    return float(max(num / den, 1.0)) if den > 0 else 1.0


def describe_fit(fit: Result) -> str:
    """``name = value ± stderr unit, ...`` of an effect fit (``(at bound)`` where it stopped at a bound)."""
    return _describe(fit.effect, fit.params, fit.stderr)


def _describe(effect, params: dict, stderr: dict) -> str:
    parts = []
    decl = effect.params
    for k, v in params.items():
        se = stderr.get(k)
        unit = decl[k].unit
        s = f"{k} = {v:.4g}"
        if se is not None and np.isfinite(se):
            s += f" ± {se:.2g}"
        s += f" {unit}" if unit else ""
        if se is not None and np.isnan(se):
            s += " (at bound)"
        elif se is not None and np.isinf(se):
            s += " (not identifiable)"
        parts.append(s)
    return ", ".join(parts)


class EffectFit(Fitter):
    """Fit one effect to a comparison's equation error on all its frames (the one way to fit an effect).

    ``EffectFit(effect, max_nfev=100).fit(comparison)`` returns the fitter
    with ``result_`` (a :class:`~pinmsk.fitting.Result`: channels
    ``<coord>_moment``, the change of the equation error the fitted effect
    makes over the compared frames; statistics ``n`` residuals, ``k`` free
    parameters, the noise-whitened ``sse`` and ``sse_before`` without the
    effect, AIC/BIC with the residual variance estimated; details ``effect``,
    ``params``, ``stderr`` and ``delta``, the channels as an array),
    ``effect_`` (the fitted component, parameter uncertainties in its
    Parameters' ``stderr``), ``params_``, ``stderr_``, ``sse_``,
    ``n_params_`` (free parameters), ``aic_change_``, ``bic_change_``,
    ``converged_``, ``theta_`` (the free parameter values) and ``problem_``
    (the :class:`EffectProblem`, for :meth:`cross_validate`).

    ``strict``: a fit that stops without converging (after ``max_nfev``
    evaluations) raises :class:`~pinmsk.errors.ConvergenceError`; with
    ``strict=False`` it is kept, flagged ``converged = False`` (the ranking
    does so).
    """

    def __init__(self, effect: Component, *, max_nfev: int = 100, strict: bool = True):
        self.effect = effect
        self.max_nfev = max_nfev
        self.strict = strict

    def fit(self, comparison) -> "EffectFit":
        """Fit ``effect`` to ``comparison`` (a :class:`~pinmsk.diagnose.compare.Comparison`); returns self."""
        problem = EffectProblem(comparison.eq, comparison.eq_noise.sigma, self.effect)
        x, conv, msg = problem.solve(max_nfev=self.max_nfev)
        if self.strict and not conv:
            raise ConvergenceError(
                f"the fit of {self.effect.label} did not converge after {problem.nfev} evaluations "
                f"({msg.rstrip('.')}); check the trial covers the effect (e.g. the joint range for "
                "passive_elastic), or fix some parameters (Parameter.vary=False; on the command line "
                "--add FAMILY:TARGET:NAME=VALUE) and fit again"
            )
        r = problem.result(x, conv, msg)
        self.problem_ = problem
        self.theta_ = x
        self.result_ = r
        self.effect_ = r.effect
        self.params_ = dict(r.params)
        self.stderr_ = dict(r.stderr)
        self.sse_ = r.stats.sse
        self.n_params_ = r.stats.k
        self.bic_change_ = r.stats.bic_change
        self.aic_change_ = r.stats.aic_change
        self.converged_ = r.stats.converged
        return self

    def cross_validate(self, *, folds: int, guard: int) -> tuple[np.ndarray, bool]:
        """Blocked cross-validation of the fitted effect: ``(e_cv, converged)``.

        ``e_cv`` is the equation error with each of ``folds`` contiguous blocks
        changed by the effect fitted on the other frames, leaving out
        ``guard`` frames on either side of the block (see the module notes).
        """
        self._check_fitted()
        p = self.problem_
        return p.cross_validate(folds, guard, x_full=None if p.linear else self.theta_)


# -- several effects at once: the joint refit ----------------------------------------------------

def cv_blocks(n: int, folds: int, edges=None) -> list[np.ndarray]:
    """The held-out blocks of blocked cross-validation: ``folds`` contiguous index arrays over ``n`` rows,
    cut at ``edges`` (row indices, e.g. cycle boundaries) when given, else of equal length."""
    if edges is None:
        return np.array_split(np.arange(n), folds)
    cuts = [0] + [int(e) for e in edges] + [n]
    return [np.arange(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]


class JointProblem:
    """Several effects fitted together to one equation error: lmfit's composite model.

    ``components`` are the effects in order; those whose label is a component
    of the comparison's model already (effects added at earlier steps) change
    the equation error *relative to their values in the model*, so the joint
    fit at their current values and the candidate's zero is the model as it
    is.  The change of ``e`` is the sum over the effects that act through
    generalized forces plus, for muscle-level effects, the change of the muscle
    moments when they all join (or replace their entries in) the model's
    muscle-level chain (:meth:`~pinmsk.diagnose.compare.EquationError.chain_delta`).

    When every effect is linear in its parameters (``d = B theta``) the fit is
    exact linear least squares (bounded by :func:`scipy.optimize.lsq_linear`
    when the solution leaves the bounds); otherwise trust-region reflective
    least squares with the effects' analytic Jacobians (finite differences of
    the chain for muscle-level effects), warm-started from ``x0`` (the earlier
    effects' values and the candidate's own fit), so a few iterations suffice.
    ``problems`` maps labels to :class:`EffectProblem` s already built (their
    caches are reused).
    """

    def __init__(self, eq, sigma, components, *, problems: dict | None = None):
        self.eq = eq
        self.sigma = np.asarray(sigma, dtype=float)
        self.components = list(components)
        labels = [c.label for c in self.components]
        if len(set(labels)) != len(labels):
            raise ModelError(f"a joint fit takes each effect once, got {', '.join(labels)}")
        have = {c.label for c in eq.model.components}
        self.in_model = [c.label in have for c in self.components]
        problems = problems or {}
        self.problems = []
        for c in self.components:
            p = problems.get(c.label)
            self.problems.append(p if p is not None and p.eq is eq else EffectProblem(eq, self.sigma, c))
        # the channels some effect can change; the others add a constant to the sum of squares
        sigma_full = self.sigma
        self.cols = np.unique(np.concatenate([p.act for p in self.problems])) if self.problems else \
            np.arange(eq.e.shape[1])
        pos = {int(c): k for k, c in enumerate(self.cols)}
        self.local = [np.array([pos[int(a)] for a in p.act], dtype=int) for p in self.problems]
        self.e = eq.e[:, self.cols]
        self.sigma = sigma_full[self.cols]
        rest = np.setdiff1d(np.arange(eq.e.shape[1]), self.cols)
        self.rest_sse = float(np.sum((eq.e[:, rest] / sigma_full[rest]) ** 2))
        self.n, self.C = self.e.shape
        self.slices, names, lo, hi, x0 = [], [], [], [], []
        k = 0
        for comp, p in zip(self.components, self.problems):
            vals = comp.values
            self.slices.append(slice(k, k + len(p.names)))
            k += len(p.names)
            names += [f"{comp.label}.{n}" for n in p.names]
            lo.append(p.lo)
            hi.append(p.hi)
            x0.append(np.array([vals[n] for n in p.names], dtype=float))
        self.names = names
        self.lo = np.concatenate(lo) if lo else np.zeros(0)
        self.hi = np.concatenate(hi) if hi else np.zeros(0)
        self.x_start = np.clip(np.concatenate(x0), self.lo, self.hi) if x0 else np.zeros(0)
        self.signal_idx = [i for i, p in enumerate(self.problems) if p.signal]
        self.force_idx = [i for i, p in enumerate(self.problems) if not p.signal]
        # earlier effects acting through forces: their change relative to the model's values
        self._base = {}
        for i in self.force_idx:
            if self.in_model[i] and self.problems[i].names:
                self._base[i] = self.problems[i].predict(self.x_start[self.slices[i]][None])[0]
        self.nfev = 0

    @property
    def linear(self) -> bool:
        return not self.signal_idx and all(self.problems[i].linear for i in self.force_idx)

    @property
    def p(self) -> int:
        return len(self.names)

    # -- predictions ------------------------------------------------------------------
    def delta(self, x) -> np.ndarray:
        """Change of ``e`` (n, C) for the stacked free parameters ``x``."""
        return self.delta_batch(np.asarray(x, dtype=float)[None])[0]

    def delta_batch(self, X) -> np.ndarray:
        """Change of ``e`` (P, n, C) for parameter sets ``X`` (P, p)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        self.nfev += X.shape[0]
        out = np.zeros((X.shape[0], self.n, self.C))
        for i in self.force_idx:
            p = self.problems[i]
            if not p.names:
                continue
            d = p.predict(X[:, self.slices[i]])
            if i in self._base:
                d = d - self._base[i][None]
            out[:, :, self.local[i]] += d
        if self.signal_idx:
            changes = []
            for i in self.signal_idx:
                p = self.problems[i]
                batch = {n: np.full(X.shape[0], v) for n, v in p.fixed.items()}
                batch.update({n: X[:, self.slices[i]][:, j] for j, n in enumerate(p.names)})
                changes.append((p.component, batch))
            out += self.eq.chain_delta(changes)[:, :, self.cols]
        return out

    def jacobian(self, x) -> np.ndarray:
        """``d delta / d x`` (n, C, p)."""
        x = np.asarray(x, dtype=float)
        J = np.zeros((self.n, self.C, self.p))
        for i in self.force_idx:
            p = self.problems[i]
            if p.names:
                J[:, self.local[i], self.slices[i]] = p.jacobian(x[self.slices[i]])
        if self.signal_idx:
            cols = np.concatenate([np.arange(self.p)[self.slices[i]] for i in self.signal_idx])
            span = np.where(np.isfinite(self.hi - self.lo), self.hi - self.lo, 1.0)[cols]
            h = 1e-6 * np.maximum(np.abs(x[cols]), 1e-3 * span) + 1e-12
            step = np.where(x[cols] + h <= self.hi[cols], h, -h)
            X = np.tile(x, (cols.size + 1, 1))
            X[1 + np.arange(cols.size), cols] += step
            # only the chain varies across the stencil: the forces' part cancels in the differences
            D = self.delta_batch(X)
            J[:, :, cols] = np.moveaxis((D[1:] - D[0]) / step[:, None, None], 0, -1)
        return J

    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """``(B, c)`` with ``delta = B x + c`` (linear problems): B (n, C, p), c (n, C)."""
        B = np.zeros((self.n, self.C, self.p))
        c = np.zeros((self.n, self.C))
        for i in self.force_idx:
            p = self.problems[i]
            if not p.names:
                continue
            b = p.basis()
            B[:, self.local[i], self.slices[i]] = b
            if i in self._base:
                c[:, self.local[i]] -= np.einsum("ncp,p->nc", b, self.x_start[self.slices[i]])
        return B, c

    # -- objective ----------------------------------------------------------------------
    def residual(self, x, mask=None) -> np.ndarray:
        r = (self.e + self.delta(x)) / self.sigma
        return (r if mask is None else r[mask]).ravel()

    def sse(self, x, mask=None) -> float:
        """Whitened SSE over all channels (the ones no effect changes as a constant; all rows only)."""
        return float(np.sum(self.residual(x, mask) ** 2)) + (self.rest_sse if mask is None else 0.0)

    def delta_full(self, x) -> np.ndarray:
        """Change of the whole equation error (n, all channels)."""
        out = np.zeros_like(self.eq.e)
        out[:, self.cols] = self.delta(x)
        return out

    def solve(self, mask=None, x0=None, *, max_nfev: int = 100, fixed: dict | None = None):
        """Best stacked parameters on the ``mask`` rows from ``x0``: ``(x, converged, message)``.

        ``fixed`` maps indices into ``x`` to values held during the fit (a profile)."""
        mask = np.ones(self.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        x0 = self.x_start if x0 is None else np.asarray(x0, dtype=float)
        free = np.ones(self.p, dtype=bool)
        x0 = x0.copy()
        for j, v in (fixed or {}).items():
            free[j] = False
            x0[j] = v
        if not np.any(free):
            return x0, True, "no free parameters"
        lo, hi = self.lo[free], self.hi[free]
        sig = self.sigma[None, :, None]
        if self.linear:
            B, c = self.basis()
            Bm = B[mask]
            rhs = -(self.e[mask] + c[mask] + np.einsum("ncp,p->nc", Bm[:, :, ~free], x0[~free]))
            A = (Bm[:, :, free] / sig).reshape(-1, int(free.sum()))
            b = (rhs / self.sigma).ravel()
            xs, *_ = np.linalg.lstsq(A, b, rcond=None)
            msg = "linear least squares"
            ok = True
            if not (np.all(xs >= lo) and np.all(xs <= hi)):
                res = lsq_linear(A, b, bounds=(lo, hi))
                xs, ok, msg = res.x, bool(res.success), f"bounded linear least squares: {res.message}"
            out = x0.copy()
            out[free] = xs
            return out, ok, msg
        span = hi - lo
        eps = np.where(np.isfinite(span), 1e-9 * span, 1e-9)
        start = np.clip(x0[free], lo + eps, hi - eps)

        def full(z):
            x = x0.copy()
            x[free] = z
            return x

        def fun(z):
            r = self.residual(full(z), mask)
            if not np.all(np.isfinite(r)):
                raise ConvergenceError(
                    f"joint fit of {', '.join(c.label for c in self.components)}: the model gave non-finite "
                    f"values at {dict(zip(np.array(self.names)[free], np.round(z, 6)))}; tighten the bounds")
            return r

        def jac(z):
            J = self.jacobian(full(z))[mask][:, :, free] / sig
            return J.reshape(-1, int(free.sum()))

        res = least_squares(fun, start, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac",
                            max_nfev=max_nfev, xtol=1e-8, ftol=1e-9)
        return full(res.x), bool(res.status > 0), str(res.message)

    def cross_validate(self, blocks, guard: int, x_full, *, max_nfev: int = 20) -> tuple[np.ndarray, bool]:
        """Held-out equation error (n, all channels): each block changed by the joint fit on the other rows (less a
        ``guard`` of rows either side), warm-started at ``x_full``."""
        e_cv = self.eq.e.copy()
        ok = True
        for blk in blocks:
            train = np.ones(self.n, dtype=bool)
            train[max(blk[0] - guard, 0):min(blk[-1] + guard + 1, self.n)] = False
            x, conv, _ = self.solve(train, x0=x_full, max_nfev=max_nfev)
            ok &= conv
            e_cv[np.ix_(blk, self.cols)] = (self.e + self.delta(x))[blk]
        return e_cv, ok

    # -- uncertainties and identifiability ----------------------------------------------
    def covariance(self, x, mask=None) -> dict:
        """Parameter covariance ``s^2 (J^T J)^-1`` (inflated as :class:`EffectFit`'s), the whitened
        Jacobian's rank and condition number (columns scaled to unit norm) and which parameters sit at a
        bound (left out of the inversion: their error is NaN)."""
        mask = np.ones(self.n, dtype=bool) if mask is None else mask
        r = ((self.e + self.delta(x)) / self.sigma)[mask]
        if self.p == 0:
            return {"cov": np.zeros((0, 0)), "rank": 0, "cond": 1.0, "at_bound": np.zeros(0, bool),
                    "s2": float(np.mean(r ** 2)) if r.size else 1.0, "inflation": 1.0, "integrated_inflation": 1.0,
                    "singular_values": np.zeros(0)}
        J3 = self.jacobian(x)[mask] / self.sigma[None, :, None]            # (n, C, p)
        J = J3.reshape(-1, self.p)
        span = self.hi - self.lo
        tol = np.where(np.isfinite(span), 1e-8 * span, 1e-9)
        at_bound = (x <= self.lo + tol) | (x >= self.hi - tol)
        norms = np.linalg.norm(J, axis=0)
        Jn = J / np.where(norms > 0, norms, 1.0)
        sv = np.linalg.svd(Jn, compute_uv=False) if self.p else np.zeros(0)
        rank = int(np.sum(sv > sv[0] * 1e-10)) if sv.size and sv[0] > 0 else 0
        cond = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else float("inf")
        n_res, p = r.size, self.p
        s2 = float(np.sum(r ** 2)) / max(n_res - p, 1)
        infl = ar1_inflation(r)
        cov = np.full((p, p), np.nan)
        inner = ~at_bound & (norms > 0)
        if np.any(inner):
            Ji = J[:, inner] / norms[inner]
            JtJ = Ji.T @ Ji
            if not np.all(np.isfinite(JtJ)):
                cov[np.ix_(inner, inner)] = np.inf
            else:
                # pseudo-inverse on the identifiable subspace; a parameter with a share in a null direction
                # (a combination the data do not see) has no finite error, the others keep theirs
                w, V = np.linalg.eigh(JtJ)
                keep = w > max(w.max(), 1e-300) * 1e-12
                # sandwich over the channels: each channel's information counted with its own residual's
                # AR(1) inflation (a parameter that one smooth channel determines gets that channel's,
                # not the pooled one of channels it barely sees)
                A_inv = (V[:, keep] / w[keep]) @ V[:, keep].T
                meat = channel_inflation(J3[:, :, inner] / norms[inner], r)
                if meat.shape == (1, 1):
                    meat = meat * float(np.sum((J3[:, :, inner] / norms[inner]) ** 2))
                sub = A_inv @ meat @ A_inv / np.outer(norms[inner], norms[inner])
                sub = sub * s2
                blind = np.any(np.abs(V[:, ~keep]) > 0.05, axis=1) if np.any(~keep) else np.zeros(sub.shape[0], bool)
                sub[blind, :] = np.inf
                sub[:, blind] = np.inf
                cov[np.ix_(inner, inner)] = sub
        return {"cov": cov, "rank": rank, "cond": cond, "at_bound": at_bound, "s2": s2, "inflation": infl,
                "integrated_inflation": inflation(r), "singular_values": sv}

    def stderr_corr(self, cov) -> tuple[np.ndarray, np.ndarray]:
        d = np.diag(cov)
        with np.errstate(invalid="ignore", divide="ignore"):
            se = np.sqrt(np.where(d >= 0, d, np.nan))
            corr = cov / np.outer(se, se)
        return _informative(se, self.hi - self.lo), corr

    def components_at(self, x, stderr=None) -> list:
        """The components with the stacked values ``x`` (and standard errors)."""
        out = []
        for comp, p, sl in zip(self.components, self.problems, self.slices):
            vals = {n: float(np.clip(v, comp.params[n].min, comp.params[n].max)) for n, v in zip(p.names, x[sl])}
            se = {} if stderr is None else {n: float(s) for n, s in zip(p.names, stderr[sl])}
            out.append(comp.with_params(vals, stderr=se) if vals else comp)
        return out

    def profile_interval(self, x, j: int, se_wald: float, threshold: float, *, max_nfev: int = 10,
                         evaluations: int = 3) -> tuple:
        """Profile-likelihood interval of parameter ``j``: where the SSE, re-minimised over all the other
        parameters, has risen by ``threshold`` (``3.84 s^2`` for 95 %).

        Returns ``(low, high, low_closed, high_closed, rise_low, rise_high)``: a side that reaches its bound
        before the SSE rises that far is open, and ``rise_*`` is how far the SSE has risen at that bound
        (NaN for a closed side): near zero, the data do not bound the parameter there at all.  Each side starts with a step
        of the Wald half-width and then takes secant steps on ``sqrt(delta SSE)``, which is linear in the
        step where the SSE is quadratic (``evaluations`` warm-started refits at most, ``max_nfev``
        evaluations each).
        """
        s0 = self.sse(x)
        lo, hi = self.lo[j], self.hi[j]
        span = hi - lo if np.isfinite(hi - lo) else max(abs(x[j]), 1.0) * 10
        out = []

        def rise_at(v, start):
            xk, _, _ = self.solve(None, x0=start, max_nfev=max_nfev, fixed={j: v})
            return self.sse(xk) - s0, xk

        for sign, bound in ((-1.0, lo), (1.0, hi)):
            room = abs(bound - x[j]) if np.isfinite(bound) else np.inf
            if room <= 1e-12 * max(span, 1e-12):
                out.append((x[j], False, 0.0))
                continue
            h = 1.96 * se_wald if np.isfinite(se_wald) and se_wald > 0 else 0.1 * span
            h = min(h, room)
            xk, opened, tried_room, rise = x.copy(), False, False, np.nan
            for _ in range(evaluations):
                rise, xk = rise_at(x[j] + sign * h, xk)
                tried_room = h >= room
                if rise < threshold and tried_room:
                    opened = True
                    break
                est = h * np.sqrt(threshold / rise) if rise > 0 else 2.0 * h
                h_new = min(est, room)
                done = abs(h_new - h) <= 0.02 * h
                h = h_new
                if done:
                    break
            if not opened and h >= room and not tried_room:
                rise, _ = rise_at(x[j] + sign * room, xk)     # the estimate lies beyond the bound: check it
                opened = rise < threshold
            out.append((x[j] + sign * min(h, room), not opened, float(rise) if opened else float("nan")))
        (a, ca, ra), (b, cb, rb) = out
        return float(a), float(b), bool(ca), bool(cb), ra, rb
