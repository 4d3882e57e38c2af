"""Scoring candidates: joint refits, the held-out test, identifiability, pairs, and what is left.

:class:`Scorer` scores every candidate of a diagnosis against the model as it
is, with the effects added at earlier steps (``refit``) *refitted jointly* with
the candidate (:class:`~pinmsk.diagnose.fit.JointProblem`, warm-started from
their current values and the candidate's own fit; linear effects solved
exactly):

* the reference is the earlier effects alone, cross-validated on the same
  blocks (refitted on each training set), so candidate and reference are held
  out alike; with no earlier effect it is the equation error itself;
* each candidate's held-out residual comes from the joint fit on each training
  set; :func:`~pinmsk.diagnose.ranking.held_out_test` compares the two
  (``z``), and the in-sample BIC of the joint fit against the reference's
  must fall;
* identifiability (:func:`identifiability`): the joint sensitivity matrix's
  rank and condition number (columns scaled to unit norm), which parameters
  sit at a bound, and a 95 % profile-likelihood interval of each of the
  candidate's parameters (Wald's for linear ones, where the two agree);
* pairs (:meth:`Scorer.pairs`): when the best single candidate leaves a
  residual the noise does not explain, the pairs of the leading candidates are
  fitted jointly and tested against that best single;
* backward elimination (:meth:`Scorer.elimination`): each earlier effect left
  out, the others refitted jointly, tested by the same held-out test against
  the model with it, and named an alias of another whose sensitivity spans the
  same direction.

:func:`residual_character` is what a residual outside the catalog follows.
"""
from __future__ import annotations

import itertools

import numpy as np
from scipy.stats import norm

from ..effects._base import SignalEffect
from ..errors import PinmskError
from ..fitting import FitStatistics, Result, format_report
from ..stats import bic_change
from ..trial import moment_channel
from .fit import EffectFit, JointProblem, _describe, cv_blocks
from .ranking import EffectScore, held_out_test

__all__ = ["Scorer", "identifiability", "model_with_components", "motion_rmse_after", "cycle_edges", "residual_character", "consistent_with_noise",
           "critical_z", "hac_mean", "mean_test", "systematic_residual", "describe_systematic", "PROFILE_LEVEL", "COND_MAX",
           "ALIAS_PARAMETER"]

#: chi-square(1) quantile of the profile-likelihood intervals (95 %)
PROFILE_LEVEL = 3.841
#: an interval side that runs into a bound is "flat" -- the data do not bound the parameter -- when the
#: profile there has risen by less than this share of the 95 % threshold (a quadratic profile: the bound
#: within one standard error); a larger rise is an imprecise but informative parameter, cut at the bound
FLAT = 0.25
#: condition number (unit-norm columns) beyond which parameters are taken as not identifiable together
COND_MAX = 1e6
#: candidates whose fitted changes correlate beyond this, and whose held-out errors the test cannot tell
#: apart, are reported as aliases of each other
ALIAS_CORRELATION = 0.9
#: an effect in the model whose sensitivity and a later effect's share a direction beyond this canonical
#: correlation (their parameter estimates correlate near +-1) is named an alias of it
ALIAS_PARAMETER = 0.99
#: leading candidates combined into pairs
PAIR_POOL = 4


def critical_z(alpha: float, m: int) -> float:
    """One-sided critical value of the held-out test at family-wise level ``alpha`` over ``m`` candidates
    (Bonferroni)."""
    return float(norm.isf(alpha / max(int(m), 1)))


def cycle_edges(t: np.ndarray, q: np.ndarray, folds: int, *, min_corr: float = 0.8):
    """Block edges (row indices) at whole cycles when the motion is cyclic, else None.

    The period is the first peak of the autocorrelation of the compared coordinates (each without its
    linear trend, standardised, summed) after its first zero crossing, taken when the peak exceeds ``min_corr`` and the trial holds
    at least ``folds`` cycles; each block is then a whole number of cycles.  Returns ``(edges, period_s)``.
    """
    n = q.shape[0]
    if n < 4 * folds:
        return None
    s = np.linspace(-1.0, 1.0, n)[:, None]
    x = q - q.mean(axis=0)
    x = x - s * (np.sum(s * x, axis=0) / np.sum(s * s))      # without the trend (a walk's forward travel)
    sd = x.std(axis=0)
    moving = sd > 1e-6 * (np.abs(q).max(axis=0) + 1e-9)     # what is left of a pure ramp is round-off
    x = x[:, moving] / sd[moving]
    if x.shape[1] == 0:
        return None
    m = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(x, m, axis=0)
    ac = np.fft.irfft(np.sum(f * np.conj(f), axis=1), m)[:n]
    ac = ac / ac[0] * n / (n - np.arange(n))          # unbiased
    half = n // 2
    below = np.flatnonzero(ac[:half] < 0)
    if below.size == 0:
        return None
    start = below[0]
    k = start + int(np.argmax(ac[start:half])) if half > start else None
    if k is None or ac[k] < min_corr:
        return None
    cycles = n // k
    if cycles < folds:
        return None
    edges = [int(round(i * cycles / folds)) * k for i in range(1, folds)]
    if len(set(edges)) < folds - 1:
        return None
    dt = float(np.median(np.diff(t)))
    return edges, k * dt


def consistent_with_noise(residual: np.ndarray, sigma: np.ndarray, allowance: float, z: float = 2.326):
    """Whether a residual ``(n, C)`` is consistent with the noise floor ``sigma``: over all channels and per
    channel, ``rms / sigma <= allowance * sqrt(1 + z sqrt(2 / n_eff))`` (the chi-square spread of a mean
    square of ``n_eff`` effectively independent frames, AR(1), times an allowance for the uncertainty of
    the floor estimate itself), ``z`` at its one-sided level over all channels and, per channel, at that
    level over the ``C`` channels (Bonferroni: ten channels are not ten chances for a false alarm).
    Returns ``(consistent, ratio, limit, ratios per channel)``."""
    r = residual / sigma
    n, C = r.shape
    rho = np.array([float(np.clip(np.dot(c[1:], c[:-1]) / max(np.dot(c, c), 1e-300), 0.0, 0.99)) for c in r.T])
    n_eff = np.maximum(n * (1 - rho) / (1 + rho), 2.0)
    ratios = np.sqrt(np.mean(r ** 2, axis=0))
    z_channel = float(norm.isf(norm.sf(z) / max(C, 1)))
    limits = allowance * np.sqrt(1 + z_channel * np.sqrt(2 / n_eff))
    total = float(np.sqrt(np.mean(ratios ** 2)))
    limit_total = allowance * float(np.sqrt(1 + z * np.sqrt(2 / np.sum(n_eff))))
    ok = bool(total <= limit_total and np.all(ratios <= limits))
    return ok, total, limit_total, ratios


def hac_mean(x: np.ndarray) -> tuple:
    """Mean ``(C,)`` of ``x`` (n, C) per column and its Newey-West standard error: the long-run variance
    ``gamma_0 + 2 sum_j (1 - j / (L + 1)) gamma_j`` (Bartlett weights, Newey & West 1987) up to the
    bandwidth of Andrews (1991) for an AR(1) plug-in, ``L = 1.1447 (a n)^(1/3)``, ``a = 4 rho^2 /
    ((1 - rho)^2 (1 + rho)^2)``, as the held-out test (:func:`~pinmsk.diagnose.ranking.held_out_test`),
    and never below the AR(1) long-run variance ``gamma_0 (1 + rho) / (1 - rho)`` (Bartlett weights
    truncated at ``L`` under-count a strongly autocorrelated residual's).  Returns ``(mean, se,
    bandwidth)``."""
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    n = x.shape[0]
    mean = x.mean(axis=0)
    r = x - mean
    se = np.zeros(x.shape[1])
    bw = np.zeros(x.shape[1], dtype=int)
    m = 1 << int(np.ceil(np.log2(2 * max(n, 1))))
    f = np.fft.rfft(r, m, axis=0)
    acov = np.fft.irfft(np.abs(f) ** 2, m, axis=0)[:n] / n            # gamma_j, j = 0..n-1
    for k in range(x.shape[1]):
        g0 = acov[0, k]
        if g0 <= 0:
            continue
        rho = float(np.clip(acov[1, k] / g0, 0.0, 0.995)) if n > 1 else 0.0
        a = 4 * rho ** 2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
        L = int(min(max(np.ceil(1.1447 * (a * n) ** (1 / 3)), 1), max(n // 4, 1)))
        j = np.arange(1, L + 1)
        lrv = g0 + 2.0 * float(np.sum((1 - j / (L + 1)) * acov[1:L + 1, k]))
        lrv = max(lrv, g0 * (1 + rho) / (1 - rho))
        se[k] = np.sqrt(lrv / n)
        bw[k] = L
    return mean, se, bw


def systematic_residual(c, residual: np.ndarray, *, alpha: float, bins: int = 16, channels=None) -> dict:
    """What of the residual ``(n, C)`` is systematic, not noise, per channel.

    * ``mean``: its mean over the trial against the Newey-West standard error (:func:`hac_mean`):
      ``mean_z = mean / se``;
    * ``phase``: the share of its variance that bin means over ``bins`` quantile bins of the movement's
      phase explain (the phase of the analytic signal of the coordinate that moves most, as
      :func:`residual_character`), against chance: ``share * n_eff`` is chi-square with ``bins - 1``
      degrees of freedom for noise, ``n_eff = n (1 - rho) / (1 + rho)`` its effectively independent
      frames (AR(1)).

    Each is tested at ``alpha`` over the channels and the two tests (Bonferroni, the mean two-sided).
    ``channels`` names the residual's columns (default ``c.channels``).
    Returns ``{"alpha", "critical_z", "channels": {channel: {"mean", "mean_stderr", "mean_z",
    "phase_share", "phase_critical_share", "systematic_mean", "phase_locked"}}, "systematic": [channels]}``.
    """
    from scipy.stats import chi2

    r = np.asarray(residual, dtype=float).reshape(len(residual), -1)
    n, C = r.shape
    tests = 2 * max(C, 1)
    zc = float(norm.isf(alpha / (2 * tests)))
    mean, se, bw = hac_mean(r)
    phase = _movement_phase(c)
    out, flagged = {}, []
    for jc, ch in enumerate(list(channels if channels is not None else c.channels)[:C]):
        info = {"mean": float(mean[jc]), "mean_stderr": float(se[jc]), "newey_west_lags": int(bw[jc])}
        z = float(mean[jc] / se[jc]) if se[jc] > 0 else 0.0
        info["mean_z"] = z
        info["systematic_mean"] = bool(abs(z) > zc)
        x = r[:, jc] - mean[jc]
        info["phase_locked"] = False
        if phase is not None and np.dot(x, x) > 0:
            rho = float(np.clip(np.dot(x[1:], x[:-1]) / np.dot(x, x), 0.0, 0.99))
            n_eff = max(n * (1 - rho) / (1 + rho), 2.0)
            share = _binned_share(phase, x, bins, np.inf)
            crit = float(chi2.isf(alpha / tests, bins - 1)) / n_eff
            info["phase_share"] = share
            info["phase_critical_share"] = crit
            info["phase_locked"] = bool(share > crit)
        out[ch] = info
        if info["systematic_mean"] or info["phase_locked"]:
            flagged.append(ch)
    return {"alpha": float(alpha), "critical_z": zc, "channels": out, "systematic": flagged}


def mean_test(r0: np.ndarray, r1: np.ndarray, *, alpha: float) -> dict:
    """Held-out test of a residual's systematic mean: does ``r1`` (whitened, ``(n, C)``, held out) leave
    less of the mean over the trial that ``r0`` has?

    It applies when ``r0``'s mean is systematic on some channel (``|mean / se| > z_c``, the Newey-West
    error of :func:`hac_mean` and the critical value of :func:`systematic_residual` at ``alpha``).  The
    statistic is the fall of the Wald chi-square of the means over every channel, each mean in units of
    ``r0``'s standard error: ``D = sum_c (m0_c / se_c)^2 - (m1_c / se_c)^2``, reported as ``z = sign(D)
    sqrt(|D|)`` (the likelihood ratio of a mean that the candidate's held-out prediction takes away, one
    degree of freedom).  A candidate that moves the mean onto another channel gains nothing.

    Squared-error tests (:func:`~.ranking.held_out_test`) give a constant shift that explains the mean
    ``m`` the power ``m / (2 se)``: half that of the mean itself, and on a real walk the gait-locked
    part of the residual that no candidate explains widens their error further.  Returns ``{"applies",
    "systematic": [channel indices], "chi2_before", "chi2_after", "z", "mean_before", "mean_after",
    "stderr"}``.
    """
    r0 = np.asarray(r0, dtype=float).reshape(len(r0), -1)
    r1 = np.asarray(r1, dtype=float).reshape(len(r1), -1)
    C = r0.shape[1]
    m0, se, _ = hac_mean(r0)
    m1 = r1.mean(axis=0)
    ok = se > 0
    z0 = np.where(ok, m0 / np.where(ok, se, 1.0), 0.0)
    z1 = np.where(ok, m1 / np.where(ok, se, 1.0), 0.0)
    zc = float(norm.isf(alpha / (4 * max(C, 1))))
    sys_ch = np.flatnonzero(np.abs(z0) > zc)
    d = float(np.sum(z0 ** 2) - np.sum(z1 ** 2))
    return {"applies": bool(sys_ch.size), "systematic": [int(k) for k in sys_ch], "critical_z_mean": zc,
            "chi2_before": float(np.sum(z0 ** 2)), "chi2_after": float(np.sum(z1 ** 2)),
            "z": float(np.sign(d) * np.sqrt(abs(d))) if sys_ch.size else 0.0,
            "mean_before": m0.tolist(), "mean_after": m1.tolist(), "stderr": se.tolist()}


def describe_systematic(info: dict, unit: str = "") -> str:
    """One phrase on a channel's systematic part (from :func:`systematic_residual`), or ''."""
    parts = []
    if info.get("systematic_mean"):
        parts.append(f"its mean over the trial is {info['mean']:+.3g}{unit} ± {info['mean_stderr']:.2g} "
                     f"(z {info['mean_z']:+.1f}, Newey-West)")
    if info.get("phase_locked"):
        parts.append(f"{100 * info['phase_share']:.0f} % of its variance is locked to the phase of the "
                     f"movement (chance {100 * info['phase_critical_share']:.0f} %)")
    return "; ".join(parts)


def _movement_phase(c):
    """The phase (rad) of the analytic signal of the compared coordinate that moves most, or None."""
    states = c.states
    coords = [k for k in c.coordinates if k in states]
    if not coords:
        return None
    from scipy.signal import hilbert
    q = np.column_stack([np.asarray(states[k], dtype=float) for k in coords])
    j = int(np.argmax(q.std(axis=0)))
    x = q[:, j] - q[:, j].mean()
    return np.angle(hilbert(x))


# -- identifiability ---------------------------------------------------------------------

def identifiability(jp: JointProblem, x: np.ndarray, which: int = -1, *, profile: bool = True,
                    base: tuple | None = None) -> dict:
    """Identifiability of component ``which`` of a joint fit at its optimum ``x``.

    ``rank`` and ``condition_number`` of the whole joint sensitivity matrix (the whitened Jacobian with
    unit-norm columns: a candidate collinear with an earlier effect is not identifiable beside it);
    ``intervals``: the 95 % profile-likelihood interval of each of the component's free parameters, the
    others re-minimised (linear components: Wald's, which is the profile there), ``[low, high]`` with
    ``open`` naming the sides that reach a bound before the likelihood falls that far; ``flags``: why
    the component is not identifiable (empty when it is).  ``base`` is ``(rank, condition number)`` of the
    joint fit without the component: a rank or conditioning that the earlier effects already lack is not
    held against it.  A parameter whose interval reaches the value
    that switches the effect off (``zero_params``) is consistent with no effect, which the held-out test
    judges: that is no flag.
    """
    which = which % len(jp.components)
    comp = jp.components[which]
    prob = jp.problems[which]
    sl = jp.slices[which]
    cov = jp.covariance(x)
    se, corr = jp.stderr_corr(cov["cov"])
    names = prob.names
    zero = getattr(comp, "zero_params", None) or {}
    flags, intervals, off = [], {}, []
    p_all = jp.p
    base_rank, base_cond = base if base is not None else (0, 1.0)
    if cov["rank"] < base_rank + len(names):
        flags.append(f"the sensitivity matrix has rank {cov['rank']} < {p_all} parameters")
    elif cov["cond"] > COND_MAX and cov["cond"] > 10 * base_cond:
        flags.append(f"the sensitivity matrix is ill-conditioned (condition number {cov['cond']:.3g})")
    # whether the likelihood is flat: the integrated autocorrelation, not the (conservative) AR(1) factor
    threshold = PROFILE_LEVEL * cov["s2"] * cov["integrated_inflation"]
    se_id = se * np.sqrt(cov["integrated_inflation"] / cov["inflation"])      # the errors on that footing
    linear = jp.linear or prob.linear
    for k, name in zip(range(sl.start, sl.stop), names):
        lo_b, hi_b = jp.lo[k], jp.hi[k]
        if cov["at_bound"][k]:
            at = "lower" if x[k] <= lo_b + 1e-8 * max(hi_b - lo_b, 1e-12) else "upper"
            b = lo_b if at == "lower" else hi_b
            if name in zero and np.isclose(b, zero[name]):
                flags.append(f"{name} = {b:.4g} at its bound: the fit switches the effect off")
                off.append(name)
            else:
                flags.append(f"{name} = {b:.4g} at its {at} bound")
            intervals[name] = {"low": None, "high": None, "open": [at]}
            continue
        if not np.isfinite(se[k]):
            flags.append(f"{name} is not identifiable (no finite standard error)")
            intervals[name] = {"low": None, "high": None, "open": ["lower", "upper"]}
            continue
        if linear or not profile:
            h = np.sqrt(PROFILE_LEVEL) * se_id[k]
            a, b = max(x[k] - h, lo_b), min(x[k] + h, hi_b)
            ca, cb = x[k] - h > lo_b, x[k] + h < hi_b
            # the quadratic profile's rise at a bound inside the Wald interval
            ra, rb = (threshold * ((x[k] - lo_b) / h) ** 2, threshold * ((hi_b - x[k]) / h) ** 2)
            method = "wald"
        else:
            a, b, ca, cb, ra, rb = jp.profile_interval(x, k, se_id[k], threshold)
            method = "profile"
        opened = [side for side, closed in (("lower", ca), ("upper", cb)) if not closed]
        intervals[name] = {"low": float(a), "high": float(b), "open": opened, "method": method}
        for side, rise in (("lower", ra), ("upper", rb)):
            if side not in opened:
                continue
            bound = lo_b if side == "lower" else hi_b
            if name in zero and np.isclose(bound, zero[name]):
                continue                         # consistent with no effect: the held-out test decides
            if rise < FLAT * threshold:
                flags.append(f"{name}: the profile is flat up to its {side} bound {bound:.4g} (not identifiable)")
            else:                                # informative, only imprecise: the interval is cut at the bound
                intervals[name].setdefault("cut", []).append(side)
    corr_out = {}
    for k in range(sl.start, sl.stop):
        for m in range(p_all):
            if m != k and np.isfinite(corr[k, m]) and abs(corr[k, m]) >= 0.5:
                corr_out[f"{jp.names[k]}~{jp.names[m]}"] = float(corr[k, m])
    return {"identifiable": not flags, "flags": flags, "determined": len(flags) == len(off),
            "rank": cov["rank"], "n_params": p_all,
            "condition_number": cov["cond"], "intervals": intervals, "level": 0.95,
            "correlations": corr_out, "stderr": {n: float(se[k]) for n, k in zip(names, range(sl.start, sl.stop))}}


# -- the scorer ------------------------------------------------------------------------------

class Scorer:
    """Scores candidates against the comparison ``c`` with the earlier effects ``refit`` refitted jointly."""

    def __init__(self, c, settings: dict, refit=()):
        self.c = c
        self.eq = c.eq
        self.settings = settings
        self.sigma = c.eq_noise.sigma
        n = self.eq.rows.size
        self.blocks = cv_blocks(n, settings["folds"], settings.get("block_edges"))
        self.guard = settings["guard"]
        self.refit = list(refit)
        self.given = list(refit)          # as in the model, before any is held (backward elimination)
        self.problems: dict = {}
        self.base = None
        self.base_x = np.zeros(0)
        self.base_info = None
        if self.refit:
            self._fit_base()
            self.base_ident = [identifiability(self.base, self.base_x, k, profile=False)
                               for k in range(len(self.refit))]
            # an earlier effect the data do not determine is held at its value in the model: refitting it
            # with every candidate would only let it wander (and take the candidates with it)
            held = [k for k, info in enumerate(self.base_ident) if not info["determined"]]
            if held:
                self.refit = [c.fix(*[n for n, p in c.params.items() if p.vary]) if k in held else c
                              for k, c in enumerate(self.refit)]
                for k in held:
                    self.problems.pop(self.refit[k].label, None)
                self._fit_base()
        else:
            self.base_cv = self.eq.e
            self.base_sse = float(np.sum((self.eq.e / self.sigma) ** 2))
            self.base_ident = []
            self.base_rank_cond = (0, 1.0)
        self.r0 = self.base_cv / self.sigma
        self.mse0 = float(np.mean(self.r0 ** 2))

    def _fit_base(self):
        """The earlier effects alone: fitted on all rows and cross-validated on the blocks."""
        settings = self.settings
        self.base = JointProblem(self.eq, self.sigma, self.refit, problems=self.problems)
        self.problems.update({c.label: p for c, p in zip(self.refit, self.base.problems)})
        x, conv, msg = self.base.solve(x0=self.base.x_start, max_nfev=100)
        self.base_x, self.base_converged, self.base_message = x, conv, msg
        self.base_cv, _ = self.base.cross_validate(self.blocks, self.guard, x, max_nfev=settings["cv_nfev"])
        self.base_sse = self.base.sse(x)
        cov = self.base.covariance(x)
        self.base_rank_cond = (cov["rank"], cov["cond"])
        self.base_se, self.base_corr = self.base.stderr_corr(cov["cov"])

    # -- one candidate --------------------------------------------------------------
    def score(self, comp) -> EffectScore:
        c, eq, settings = self.c, self.eq, self.settings
        est = EffectFit(comp, strict=False).fit(c)
        self.problems[comp.label] = est.problem_
        single = est.result_
        refit_info = None
        if self.refit:
            jp = JointProblem(eq, self.sigma, self.refit + [est.effect_], problems=self.problems)
            x0 = np.concatenate([self.base_x, est.theta_])
            x, conv, msg = jp.solve(x0=x0, max_nfev=settings["joint_nfev"])
            if jp.sse(x) > jp.sse(x0):
                x = x0
            e_cv, cv_ok = jp.cross_validate(self.blocks, self.guard, x, max_nfev=settings["cv_nfev"])
            conv = bool(conv or jp.linear) and est.converged_
            fit = _joint_result(jp, x, conv, msg, self.base_sse, eq)
            refit_info = _moves(jp, x, fit.info["joint_stderr"], fit.info["joint_corr"], len(self.refit))
        else:
            jp = JointProblem(eq, self.sigma, [est.effect_], problems=self.problems)
            x = est.theta_
            e_cv, cv_ok = est.cross_validate(folds=settings["folds"], guard=settings["guard"]) \
                if settings.get("block_edges") is None else jp.cross_validate(
                    self.blocks, self.guard, x, max_nfev=settings["cv_nfev"])
            conv = est.converged_
            fit = single
        floor_change = self._floor_change(jp, x) if c.mode == "muscle" else 0.0
        test = held_out_test(self.r0, e_cv / self.sigma, offset=floor_change)
        improvement = test["improvement"]
        explained = max(improvement / self.mse0, -1.0) if self.mse0 > 0 else 0.0
        if c.mode == "motion":
            rmse_after = motion_rmse_after(c, jp.components_at(x))
        else:
            r = np.sqrt(np.mean(e_cv ** 2, axis=0))
            rmse_after = {ch: float(v) for ch, v in zip(c.channels, r)}
            rmse_after["total"] = float(np.sqrt(np.mean(r ** 2)))
        test["critical_z"] = settings["z_critical"]
        test["bic_change"] = float(fit.stats.bic_change)
        # a residual whose mean over the trial is systematic: a candidate that takes the mean away out of
        # sample passes too (mean_test), when it also lowers the held-out error and the in-sample BIC
        mt = mean_test(self.r0, e_cv / self.sigma, alpha=settings["alpha"]) if c.mode != "motion" else None
        test["mean"] = mt
        admissible = bool(conv and improvement > settings["threshold"] and fit.stats.bic_change < 0)
        by_error = admissible and test["z"] >= settings["z_critical"]
        by_mean = admissible and mt is not None and mt["applies"] and mt["z"] >= settings["z_critical"]
        passes = bool(by_error or by_mean)
        test["passes"] = passes
        test["passes_by"] = "held_out" if by_error else ("mean" if by_mean else None)
        # profile-likelihood intervals where they decide something (a candidate the test passes); Wald's
        # elsewhere, which is the profile for linear effects
        try:
            ident = identifiability(jp, x, -1, profile=settings.get("profile", True) and passes,
                                    base=self.base_rank_cond)
        except PinmskError as exc:            # a profile refit that fails: the candidate is not identifiable
            ident = {"identifiable": False, "flags": [f"profile likelihood failed: {exc}"]}
        # a fit outside the physically plausible range (a segment mass beyond the anthropometric table)
        # ... of the candidate and of every earlier effect as the joint refit moved it (a candidate that
        # only fits by pushing an earlier one out of its range is no explanation)
        comps = jp.components_at(x)
        implausible = _plausibility(comps[-1], c.model, eq.motion_rows)
        if len(comps) > 1:
            before = self._earlier_flags()
            for earlier in comps[:-1]:
                implausible += [f"with it, {flag}" for flag in _plausibility(earlier, c.model, eq.motion_rows)
                                if not before.get(earlier.label)]
        if implausible:
            ident = dict(ident, identifiable=False, plausible=False,
                         flags=list(ident.get("flags", [])) + implausible)
        note = "" if conv else f"fit did not converge: {fit.stats.message}"
        # the held-out errors rest on one fit per fold: a fold that stopped short is said, never hidden
        test["folds_converged"] = bool(cv_ok)
        if not cv_ok:
            note = (note + "; " if note else "") + ("a cross-validation fold's fit did not converge (its "
                                                    "held-out error is that of its last iterate)")
        if not ident.get("identifiable", True):
            note = (note + "; " if note else "") + "not identifiable: " + "; ".join(ident["flags"]) + \
                " (shown, never suggested)"
        significant = passes and ident.get("identifiable", True)
        return EffectScore(fit, rmse_after, explained, improvement, significant, bool(conv), note,
                           test=test, identifiability=ident, refit=refit_info,
                           components=jp.components_at(x, fit.info.get("joint_stderr")), heldout=e_cv, x=x)

    def _earlier_flags(self) -> dict:
        """The plausibility flags of the earlier effects at their own fitted values (an effect the user
        added out of range is not held against every candidate)."""
        if getattr(self, "_earlier", None) is None:
            comps = self.base.components_at(self.base_x) if self.refit else []
            self._earlier = {e.label: _plausibility(e, self.c.model, self.c.eq.motion_rows) for e in comps}
        return self._earlier

    def _floor_change(self, jp: JointProblem, x) -> float:
        """Muscle level: the fall of the noise-whitened mean square that the joint fit ``x`` makes by
        filtering the measured signals' noise (no physics), in noise variances per channel and frame.

        The muscle-level chain of the joint fit (the candidate *and* the earlier effects at their jointly
        refitted values: an earlier delay that goes to zero while activation dynamics joins changes the
        filtering too) against the reference's (the earlier effects alone, as refitted), each through the
        excitations' noise realisations (:meth:`~pinmsk.diagnose.compare.EquationError.emg_noise`)."""
        after = [comp for comp in jp.components_at(x) if isinstance(comp, SignalEffect)]
        if not after:
            return 0.0
        if self.base is not None:
            before = [comp for comp in self.base.components_at(self.base_x) if isinstance(comp, SignalEffect)]
        else:
            before = []
        emg_before = self.eq.emg_noise(before or None)
        emg_after = self.eq.emg_noise(after)
        return float(np.mean((emg_before ** 2 - emg_after ** 2) / self.sigma ** 2))

    # -- pairs ---------------------------------------------------------------------------
    def pairs(self, ranking: list, best=None) -> list:
        """Pairs of the leading significant candidates fitted jointly (with the earlier effects) and tested
        against the best single candidate (``best``, default the first significant); sorted by held-out
        improvement."""
        sig = [s for s in ranking if s.significant]
        best = best if best is not None else (sig[0] if sig else None)
        pool = ([best] + [s for s in sig if s is not best])[:PAIR_POOL] if best is not None else []
        if len(pool) < 2:
            return []
        r_best = best.heldout / self.sigma
        out = []
        for a, b in itertools.combinations(pool, 2):
            if a.family == b.family and a.target == b.target:
                continue
            try:
                jp = JointProblem(self.eq, self.sigma, self.refit + [a.effect, b.effect], problems=self.problems)
                x0 = np.concatenate([self.base_x, _own(a), _own(b)])
                x, conv, msg = jp.solve(x0=x0, max_nfev=self.settings["joint_nfev"])
                e_cv, _ = jp.cross_validate(self.blocks, self.guard, x, max_nfev=self.settings["cv_nfev"])
                cov = jp.covariance(x)
            except PinmskError:
                continue
            se, _ = jp.stderr_corr(cov["cov"])
            test = held_out_test(r_best, e_cv / self.sigma)
            k_pair = len(jp.problems[-2].names) + len(jp.problems[-1].names) - best.fit.stats.k
            dbic = bic_change(jp.sse(x), best.fit.stats.sse, n=self.eq.e.size, k=k_pair, variance="estimated")
            flags = []
            if cov["rank"] < jp.p:
                flags.append(f"the sensitivity matrix has rank {cov['rank']} < {jp.p}")
            for k in range(jp.slices[-2].start, jp.p):
                if cov["at_bound"][k]:
                    flags.append(f"{jp.names[k]} at a bound")
                elif not np.isfinite(se[k]):
                    flags.append(f"{jp.names[k]} not identifiable")
            comps = jp.components_at(x, se)
            sig = bool(conv or jp.linear) and test["z"] >= self.settings["z_critical"] and dbic < 0 and not flags
            out.append({"effects": [a.label, b.label], "components": comps[-2:], "refit": comps[:-2],
                        "improvement_over_best": test["improvement"], "z": test["z"],
                        "bic_change_over_best": float(dbic), "flags": flags, "significant": bool(sig),
                        "rmse_after": float(np.sqrt(np.mean(e_cv ** 2)))})
        out.sort(key=lambda d: -d["improvement_over_best"])
        return out

    # -- backward elimination -------------------------------------------------------------
    def elimination(self, z_critical: float) -> list:
        """Each earlier effect tested by leaving it out: is it still significant beside the others?

        The model as it is (every earlier effect, refitted jointly, cross-validated: the
        reference of the candidates) is tested against the model *without* the effect, the
        others refitted jointly on the same blocks, by the held-out test of the candidates
        (:func:`~.ranking.held_out_test`; ``z`` against ``z_critical``, the Bonferroni value over
        the effects tested) and the in-sample BIC.  "Without" is the effect switched off (its
        ``zero_params``) where a value does that, else the effect taken out of the model (its
        noise floor propagated again: a muscle-level effect also filters the signals' noise).
        ``alias_of``: the other effect whose sensitivity (whitened Jacobian columns) spans the
        same direction, canonical correlation ``>= ALIAS_PARAMETER`` (the correlation of the
        parameter estimates near +-1; 1 when the joint sensitivity is rank deficient).  One
        effect at most has ``suggest_remove``: the least significant of those that are not
        (the earlier on a tie), as backward elimination drops one effect per refit.  Returns one
        dict per effect; ``components`` are the others as refitted without it (what
        ``--remove`` puts in the model).
        """
        if not self.given:
            return []
        held = {c.label for c, info in zip(self.given, self.base_ident) if not info.get("determined", True)}
        r_with = self.base_cv / self.sigma
        canon = _canonical_correlations(self)
        out = []
        for k, comp in enumerate(self.given):
            try:
                e_cv, sse, comps, offset, how = self._without(k, held)
            except PinmskError as exc:
                out.append({"label": comp.label, "effect": comp.family, "target": comp.target,
                            "significant": None, "improvement": None, "z": None, "z_mean": None,
                            "critical_z": z_critical,
                            "bic_change": None, "alias_of": None, "alias_correlation": None,
                            "determined": comp.label not in held, "suggest_remove": False,
                            "without": f"could not be fitted without it: {exc}", "components": None})
                continue
            test = held_out_test(e_cv / self.sigma, r_with, offset=offset)
            mt = mean_test(e_cv / self.sigma, r_with, alpha=self.settings["alpha"]) \
                if self.c.mode != "motion" else None
            n_free = sum(1 for p in comp.params.values() if p.vary)
            dbic = bic_change(self.base_sse, sse, n=self.eq.e.size, k=n_free, variance="estimated")
            # kept when the model without it is worse out of sample: in its error, or in a systematic mean
            # that comes back (the candidates' two tests)
            z_mean = mt["z"] if mt is not None and mt["applies"] else None
            sig = bool(comp.label not in held and (test["z"] >= z_critical or
                                                   (z_mean is not None and z_mean >= z_critical))
                       and test["improvement"] > 0 and dbic < 0)
            alias, r = None, 0.0
            for j, other in enumerate(self.given):
                if j != k and canon[k, j] > r:
                    alias, r = other.label, float(canon[k, j])
            out.append({"label": comp.label, "effect": comp.family, "target": comp.target, "significant": sig,
                        "improvement": test["improvement"], "z": test["z"], "z_mean": z_mean,
                        "critical_z": z_critical,
                        "bic_change": float(dbic), "alias_of": alias if r >= ALIAS_PARAMETER else None,
                        "alias_correlation": r if r >= ALIAS_PARAMETER else None,
                        "determined": comp.label not in held, "suggest_remove": False, "without": how,
                        "components": comps})
        drop = [e for e in out if e["significant"] is False]
        if drop:
            worst = min(drop, key=lambda e: (round(e["z"], 6), out.index(e)))
            worst["suggest_remove"] = True
        return out

    def _without(self, k: int, held: set):
        """The earlier effects without ``given[k]``, refitted jointly and cross-validated: ``(held-out
        equation error, in-sample whitened SSE, the others as refitted, floor offset, how it was left out)``."""
        comp = self.given[k]
        zero = getattr(comp, "zero_params", None) or {}
        # a muscle-level effect filters the measured signals' noise too: leaving it out changes the floor
        signal = isinstance(comp, SignalEffect) and self.c.mode == "muscle"
        if zero and all(n in comp.params for n in zero) and not signal:
            comps = [comp if j == k else c for j, c in enumerate(self.refit)]
            probs = {lab: p for lab, p in self.problems.items() if lab != comp.label}
            jp = JointProblem(self.eq, self.sigma, comps, problems=probs)
            x0 = jp.x_start.copy()
            if self.base is not None:
                for j, c in enumerate(comps):
                    if j != k and jp.slices[j].stop - jp.slices[j].start == \
                            self.base.slices[j].stop - self.base.slices[j].start:
                        x0[jp.slices[j]] = self.base_x[self.base.slices[j]]
            names = jp.problems[k].names
            fixed = {jp.slices[k].start + i: float(zero.get(n, comp.values[n])) for i, n in enumerate(names)}
            x, _, _ = jp.solve(x0=x0, fixed=fixed, max_nfev=100)
            e_cv = _cross_validate_fixed(jp, self.blocks, self.guard, x, fixed, self.settings["cv_nfev"])
            others = [c for j, c in enumerate(jp.components_at(x)) if j != k]
            off = ", ".join(f"{n} = {zero[n]:g}" for n in zero)
            return e_cv, jp.sse(x), others, 0.0, f"switched off ({off})"
        # no value switches it off, or it filters the measured signals' noise: the model without it
        c2 = self.c.with_model(self.c.model.without(comp.label))
        if c2.eq.e.shape != self.eq.e.shape:
            raise PinmskError(f"the comparison without {comp.label} covers other rows or channels")
        sigma2 = c2.eq_noise.sigma
        offset = float(np.mean((sigma2 ** 2 - self.sigma ** 2) / self.sigma ** 2))
        rest = [c for j, c in enumerate(self.refit) if j != k]
        if not rest:
            return c2.eq.e, float(np.sum((c2.eq.e / self.sigma) ** 2)), [], offset, "taken out of the model"
        jp = JointProblem(c2.eq, self.sigma, rest)
        x, _, _ = jp.solve(x0=jp.x_start, max_nfev=100)
        e_cv, _ = jp.cross_validate(self.blocks, self.guard, x, max_nfev=self.settings["cv_nfev"])
        return e_cv, jp.sse(x), jp.components_at(x), offset, "taken out of the model"

    # -- the loop's record of a refit -----------------------------------------------------
    def base_moves(self) -> dict:
        """The earlier effects as the reference fit leaves them (values, errors, correlations)."""
        if not self.refit:
            return {}
        return _moves(self.base, self.base_x, self.base_se, self.base_corr, len(self.refit), every=True)


def _cross_validate_fixed(jp: JointProblem, blocks, guard: int, x_full, fixed: dict, max_nfev: int) -> np.ndarray:
    """:meth:`JointProblem.cross_validate` with the parameters ``fixed`` (index -> value) held."""
    e_cv = jp.eq.e.copy()
    for blk in blocks:
        train = np.ones(jp.n, dtype=bool)
        train[max(blk[0] - guard, 0):min(blk[-1] + guard + 1, jp.n)] = False
        x, _, _ = jp.solve(train, x0=x_full, max_nfev=max_nfev, fixed=fixed)
        e_cv[np.ix_(blk, jp.cols)] = (jp.e + jp.delta(x))[blk]
    return e_cv


def _canonical_correlations(sc) -> np.ndarray:
    """``(m, m)``: for the earlier effects of scorer ``sc``, the largest canonical correlation between the
    column spaces of their whitened sensitivities (the joint Jacobian at the current fit), every parameter
    free: 1 when one effect's change is one of the other's (rank deficiency)."""
    m = len(sc.given)
    out = np.zeros((m, m))
    if m < 2:
        return out
    try:
        probs = {lab: p for lab, p in sc.problems.items() if lab not in
                 {c.label for c, g in zip(sc.refit, sc.given) if c is not g}}
        jp = JointProblem(sc.eq, sc.sigma, sc.given, problems=probs)
        x = jp.x_start.copy()
        if sc.base is not None:
            for j in range(m):
                a, b = jp.slices[j], sc.base.slices[j]
                if a.stop - a.start == b.stop - b.start:
                    x[a] = sc.base_x[b]
        J = (jp.jacobian(x) / jp.sigma[None, :, None]).reshape(-1, jp.p)
    except PinmskError:
        return out
    bases = []
    for sl in jp.slices:
        A = J[:, sl]
        if A.size == 0 or not np.any(A):
            bases.append(None)
            continue
        u, s, _ = np.linalg.svd(A, full_matrices=False)
        bases.append(u[:, s > s[0] * 1e-10])
    for i in range(m):
        for j in range(m):
            if i != j and bases[i] is not None and bases[j] is not None:
                out[i, j] = float(np.clip(np.linalg.svd(bases[i].T @ bases[j], compute_uv=False)[0], 0.0, 1.0))
    return out


def model_with_components(model, components):
    """``model`` with each component: replacing the one of the same label (new values, errors, bounds),
    else added."""
    have = {c.label for c in model.components}
    for comp in components:
        if comp.label in have:
            table = {f"{comp.label}.{n}": p.value for n, p in comp.params.items()}
            errs = {f"{comp.label}.{n}": p.stderr for n, p in comp.params.items() if p.stderr is not None}
            bounds = {f"{comp.label}.{n}": (p.min, p.max) for n, p in comp.params.items()}
            model = model.with_parameters(table, bounds=bounds, stderr=errs or None)
        else:
            model = model.with_effect(comp)
    return model


def motion_rmse_after(c, components) -> dict:
    """Motion level: the RMSE of the multiple-shooting simulation with ``components`` in the model."""
    from .compare import simulate_windows
    model = model_with_components(c.model, components)
    eq = c.eq
    qs = simulate_windows(model, c.trial, eq.motion, eq.rows, c.options["sim_window"])
    r = np.sqrt(np.mean((c.measured - qs) ** 2, axis=0))
    out = {ch: float(v) for ch, v in zip(c.channels, r)}
    out["total"] = float(np.sqrt(np.mean(r ** 2)))
    return out


def _plausibility(comp, model, motion) -> list:
    """The flags of a fitted component's own plausibility check (``plausibility(model, motion)``: a segment
    mass beyond the anthropometric range, a stop pressed on every frame), if it has one."""
    check = getattr(comp, "plausibility", None)
    return list(check(model, motion)) if check is not None else []


def _own(score) -> np.ndarray:
    """The free parameter values of a scored candidate itself."""
    comp = score.effect
    return np.array([comp.values[n] for n, p in comp.params.items() if p.vary], dtype=float)


def _joint_result(jp: JointProblem, x, conv, msg, base_sse, eq) -> Result:
    """The candidate's :class:`~pinmsk.fitting.Result` from a joint fit (its parameters, their errors from
    the joint covariance, the statistics against the earlier effects alone)."""
    cov = jp.covariance(x)
    se, corr = jp.stderr_corr(cov["cov"])
    se = np.where(cov["at_bound"], np.nan, se)
    comps = jp.components_at(x, se)
    effect = comps[-1]
    sl = jp.slices[-1]
    names = jp.problems[-1].names
    stderr = {n: float(s) for n, s in zip(names, se[sl])}
    params = dict(effect.values)
    delta = jp.delta_full(x)
    sse = jp.sse(x)
    k = len(names)
    stats = FitStatistics(n=eq.e.size, k=k, sse=sse, sse_before=base_sse, variance="estimated",
                          converged=conv, message=f"joint refit: {msg}", iterations=jp.nfev, objective=sse)
    info = {"effect": effect, "params": params, "stderr": stderr, "delta": delta,
            "joint_stderr": se, "joint_corr": corr, "joint_names": list(jp.names)}
    channels = {moment_channel(cn): delta[:, j] for j, cn in enumerate(eq.coordinates)}
    title = f"{effect.label} (refitted with {', '.join(c.label for c in comps[:-1])}): " \
            f"{_describe(effect, params, stderr)}"
    return Result(eq.motion.t[eq.rows], channels, stats=stats, info=info,
                  meta={"analysis": "effect_fit", "effect": effect.label},
                  report=format_report(title, stats.rows()))


def _moves(jp: JointProblem, x, se, corr, n_earlier: int, *, every: bool = False) -> dict:
    """How the earlier effects' parameters move in a joint fit: before (their values in the model), after,
    standard error, and their correlations with the other parameters (|r| >= 0.3)."""
    effects = []
    for i in range(n_earlier):
        comp, prob, sl = jp.components[i], jp.problems[i], jp.slices[i]
        params = {}
        for n, k in zip(prob.names, range(sl.start, sl.stop)):
            before = float(comp.values[n])
            after = float(x[k])
            e = float(se[k]) if np.isfinite(se[k]) else None
            params[n] = {"before": before, "after": after, "change": after - before, "stderr": e}
        effects.append({"effect": comp.family, "target": comp.target, "label": comp.label, "params": params})
    pairs = {}
    for k, m in itertools.combinations(range(jp.p), 2):
        if not every and k >= jp.slices[n_earlier - 1].stop and m >= jp.slices[n_earlier - 1].stop:
            continue
        if np.isfinite(corr[k, m]) and abs(corr[k, m]) >= 0.3:
            pairs[f"{jp.names[k]}~{jp.names[m]}"] = float(corr[k, m])
    return {"effects": effects, "correlations": pairs}


# -- what a residual outside the catalog follows ---------------------------------------------------

def residual_character(c, residual: np.ndarray, *, bins: int = 16) -> dict:
    """What the residual ``(n, C)`` follows, per channel: the states it correlates with (q, qd, ...), time
    (a drift), its dominant frequency and that peak's share of the power, the share of its variance a
    smooth function of each compared coordinate and speed explains (bin means over ``bins`` quantile
    bins, less the share ``bins / n_eff`` chance gives), and the share the phase of the movement explains
    (the phase of the analytic signal of the coordinate that moves most)."""
    t = c.time
    n = t.size
    dt = float(np.median(np.diff(t)))
    out = {}
    states = {k: np.asarray(v, dtype=float) for k, v in c.states.items()}
    coords = [k for k in c.coordinates if k in states]
    phase = None
    if coords:
        q = np.column_stack([states[k] for k in coords])
        j = int(np.argmax(q.std(axis=0)))
        x = q[:, j] - q[:, j].mean()
        from scipy.signal import hilbert
        phase = np.angle(hilbert(x))
    for jc, ch in enumerate(c.channels):
        r = residual[:, jc] - residual[:, jc].mean()
        var = float(np.mean(r ** 2))
        info = {"rms": float(np.sqrt(np.mean(residual[:, jc] ** 2)))}
        if var <= 0:
            out[ch] = info
            continue
        rho = float(np.clip(np.dot(r[1:], r[:-1]) / max(np.dot(r, r), 1e-300), 0.0, 0.99))
        n_eff = max(n * (1 - rho) / (1 + rho), bins + 1.0)
        cors = []
        for name, s in states.items():
            sc = s - s.mean()
            den = np.sqrt(np.sum(r ** 2) * np.sum(sc ** 2))
            if den > 0:
                cors.append((name, float(np.sum(r * sc) / den)))
        cors.sort(key=lambda kv: -abs(kv[1]))
        info["correlations"] = [{"state": k, "r": v} for k, v in cors[:4]]
        tc = t - t.mean()
        info["time_correlation"] = float(np.sum(r * tc) / np.sqrt(np.sum(r ** 2) * np.sum(tc ** 2)))
        spec = np.abs(np.fft.rfft(r * np.hanning(n))) ** 2
        freqs = np.fft.rfftfreq(n, dt)
        k = int(np.argmax(spec[1:])) + 1
        band = slice(max(k - 2, 1), k + 3)
        info["dominant_frequency_hz"] = float(freqs[k])
        info["dominant_share"] = float(np.sum(spec[band]) / max(np.sum(spec[1:]), 1e-300))
        shares = {}
        for name in [x for k2 in coords for x in (k2, f"{k2}_speed")]:
            if name in states:
                shares[name] = _binned_share(states[name], r, bins, n_eff)
        info["explained_by_state"] = shares
        if phase is not None:
            info["explained_by_phase"] = _binned_share(phase, r, bins, n_eff)
        out[ch] = info
    return out


def _binned_share(s, r, bins, n_eff) -> float:
    """Share of ``var(r)`` explained by bin means of ``r`` over quantile bins of ``s``, less chance."""
    edges = np.quantile(s, np.linspace(0, 1, bins + 1))
    idx = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, bins - 1)
    cnt = np.bincount(idx, minlength=bins)
    sums = np.bincount(idx, weights=r, minlength=bins)
    means = np.where(cnt > 0, sums / np.maximum(cnt, 1), 0.0)
    explained = float(np.sum(cnt * means ** 2) / max(np.sum(r ** 2), 1e-300))
    return float(max(explained - bins / n_eff, 0.0))


def describe_character(info: dict, coordinates) -> str:
    """One line on what a channel's residual follows (from :func:`residual_character`)."""
    parts = []
    shares = info.get("explained_by_state", {})
    if shares:
        name, share = max(shares.items(), key=lambda kv: kv[1])
        if share >= 0.2:
            parts.append(f"{100 * share:.0f} % of it is a function of {name}")
    if info.get("explained_by_phase", 0.0) >= 0.2:
        parts.append(f"{100 * info['explained_by_phase']:.0f} % follows the phase of the movement")
    if abs(info.get("time_correlation", 0.0)) >= 0.3:
        parts.append(f"it drifts with time (r = {info['time_correlation']:+.2f})")
    if info.get("dominant_share", 0.0) >= 0.3:
        parts.append(f"{100 * info['dominant_share']:.0f} % of its power near {info['dominant_frequency_hz']:.2g} Hz")
    cors = info.get("correlations") or []
    if cors and abs(cors[0]["r"]) >= 0.3:
        parts.append(f"correlates with {cors[0]['state']} (r = {cors[0]['r']:+.2f})")
    if not parts:
        parts.append("no state, time, frequency or phase explains it: an unstructured, time-varying disturbance")
    return "; ".join(parts)
