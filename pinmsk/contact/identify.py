"""Kinematically driven identification of foot contact parameters (thesis Sec. 4.1.2, Eq. 4.1-4.2).

The foot2d model is driven by the measured foot (channels ``ankle_x``, ``ankle_y``,
``foot_angle``; for the CSU data :func:`pinmsk.csu.read_csu` derives them from the heel
and 5th-metatarsal markers, so the heel sphere follows the measured heel).  The toe
angle is the 11-term Fourier series of Eq. 4.1 over the analysed window (period =
window length).  By default (``toe="kinematic"``, the thesis procedure) its
coefficients are identified beforehand from the kinematics
(:func:`toe_from_kinematics`) and held fixed; ``toe="fit"`` fits them with the
contact parameters (the issue's Eq. 4.1 setting), each within ``+-toe_range`` of the
kinematic estimate so the toe cannot act as a free force generator.  The objective is
Eq. 4.2 sampled uniformly,

    J = 1/N sum_t [ (f_n^m - f_n^e)/max|f_n^e| ]^2 + [ (f_f^m - f_f^e)/max|f_f^e| ]^2
                 + [ (X^m - X^e)/max|X^e| ]^2

with the COP term over the frames where the measured vertical force exceeds
``cop_threshold`` x its maximum (the measured COP is undefined elsewhere).  As in
the thesis the point-contact model tracks the vertical force only (``terms=`` changes
that).  Solved by bounded trust-region least squares (``scipy.optimize.least_squares``,
'trf', finite-difference Jacobian on the vectorised residual) from ``n_starts``
starting points (the thesis optimum of Tables 4.2-4.4 plus random draws), with BLAS
limited to one thread (``threadpoolctl``): the problem is ~360 x 30, where OpenBLAS's
threaded gesdd took 40 ms per SVD against 0.5 ms on one thread.

Channels: ``ground_force_vx`` (friction, N), ``ground_force_vy`` (normal, N),
``ground_force_px`` (COP x, m; NaN allowed where the vertical force is small).
The ground moves at ``ground_speed`` (m/s, x) -- ``trial.meta["ground_speed"]``
when the reader set it (a treadmill belt, see :mod:`pinmsk.csu`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from ..errors import ModelError, SolverError, TrialError
from ..filtering import differentiate
from .foot import (KINDS, SITES, Foot2dGeometry, foot2d_site_kinematics, foot_contacts,
                   ground_reaction, load_foot2d)

DRIVE = ("ankle_x", "ankle_y", "foot_angle")
GRF = ("ground_force_vy", "ground_force_vx", "ground_force_px")
N_FOURIER = 11
TOE_MODES = ("kinematic", "fit", "flat", "channel")
#: swing frames (toes off the ground) for :func:`toe_from_kinematics`: measured f_n below this x its peak
SWING = 0.02
#: parameters sampled log-uniformly in the multi-start (scale-like, >= 0)
_LOG_PARAMS = {"k_s", "a_s", "k_v", "a_v", "k_h", "a_h", "v_s"}


def fourier_basis(t: np.ndarray, period: float):
    """Eq. 4.1 basis ``[1, sin(2 pi k t / tau), cos(2 pi k t / tau)]_k=1..5`` and its time derivative, (N, 11)."""
    t = np.asarray(t, dtype=float)
    B = np.empty((t.size, N_FOURIER))
    dB = np.empty_like(B)
    B[:, 0], dB[:, 0] = 1.0, 0.0
    for k in range(1, 6):
        w = 2 * math.pi * k / period
        B[:, 2 * k - 1], dB[:, 2 * k - 1] = np.sin(w * t), w * np.cos(w * t)
        B[:, 2 * k], dB[:, 2 * k] = np.cos(w * t), -w * np.sin(w * t)
    return B, dB


def toe_from_kinematics(geom: Foot2dGeometry, q: np.ndarray, *, swing=None, clearance: float = 0.05,
                        max_extension: float = 1.2) -> np.ndarray:
    """Toe angle (rad, (N,)) from the driving kinematics ``q[:, :3]``: the toes are rigid and
    extend only as much as keeps the toe site T from sinking below a floor height.

    With the toes in line with the foot (mtp = 0), T is ``PT sin(theta)`` below the MTP joint
    P (theta = foot angle, + = toes down).  The floor is ``h0`` in stance -- the 5th percentile
    of P's height over the stance frames (where the foot rolls over its forefoot) -- and
    ``max(h0, clearance)`` in the ``swing`` frames (bool mask, e.g. the measured vertical force
    below 2 % of its peak; default: no swing frames): swing means the toes are off the ground.
    Where T would go below the floor the toes turn up to put it there,
    ``mtp = arcsin((h_P - floor) / PT) - theta``; elsewhere (heel strike, foot flat, late swing)
    ``mtp = 0``.  Clipped at ``-max_extension``.  No toe marker is needed: this is the "toe angle
    identified beforehand" of the thesis procedure for data with heel and metatarsal markers only.
    """
    q0 = np.zeros((q.shape[0], 4))
    q0[:, :3] = q[:, :3]
    kin = foot2d_site_kinematics(geom, q0, np.zeros_like(q0))
    h_p = kin["metatarsal"].position[:, 1] + (geom.mtp - geom.metatarsal)[1]
    swing = np.zeros(q.shape[0], dtype=bool) if swing is None else np.asarray(swing, dtype=bool)
    h0 = float(np.percentile(h_p[~swing] if (~swing).sum() >= 3 else h_p, 5))
    floor = np.where(swing, max(h0, clearance), h0)
    pt = float(np.hypot(geom.toe[0], geom.toe[1]))
    phi = np.arcsin(np.clip((h_p - floor) / pt, -1.0, 1.0))
    return np.clip(np.minimum(0.0, phi - q[:, 2]), -max_extension, 0.0)


def stance_cycle(trial, *, threshold: float = 20.0) -> tuple[float, float]:
    """``(t0, t1)`` from the first toe-off to the next one (vertical force falling below ``threshold``)."""
    fy = np.asarray(trial["ground_force_vy"], dtype=float)
    on = np.nan_to_num(fy, nan=0.0) > threshold
    off = np.flatnonzero(on[:-1] & ~on[1:]) + 1
    if off.size < 2:
        raise TrialError(f"stance_cycle: need two toe-offs (vertical force falling below {threshold} N); "
                         f"found {off.size}")
    t = trial.time
    return float(t[off[0]]), float(t[off[1]])


@dataclass
class _Problem:
    """Everything parameter-independent of one identification."""

    t: np.ndarray
    q: np.ndarray          # (N, 4), mtp column filled per evaluation
    v: np.ndarray
    B: np.ndarray
    dB: np.ndarray
    geom: Foot2dGeometry
    meas: np.ndarray       # (3, N): fn, ff, cop
    cop_mask: np.ndarray
    scale: np.ndarray      # (3,) Eq. 4.2 normalisers
    weights: np.ndarray    # (3,) 1 or 0 per term in the minimised objective


class ContactFit:
    """Identify the contact parameters of foot2d from a trial (thesis Eq. 4.2).

    Keyword arguments (stored only; :meth:`fit` does the work):

    contact        ``point`` | ``volumetric`` | ``hypervolumetric``
    relax          free the sphere centres' dx, dy (Sec. 4.1.4) within +-``relax_range`` m
                   (default 0.02: Table 4.4 allows 0-20 mm, Sec. 4.1.4 says +-15 mm)
    window         ``(t0, t1)`` in s (default: the whole trial)
    cutoff         low-pass (Hz) of the driving kinematics before differentiation (None: none)
    n_starts       number of starting points (the first is the initial guess)
    initial        ``{site: {param: value}}`` overriding the thesis initial values
    bounds         ``{site: {param: (lo, hi)}}`` overriding the bounds
    fixed          names of parameters to hold at their initial value (all sites)
    toe            toe angle (the 11-term series of Eq. 4.1 in every mode but ``"channel"``):
                   ``"kinematic"`` (default; the thesis procedure: the toe angle is
                   identified beforehand from the kinematics, :func:`toe_from_kinematics`,
                   and held fixed during the contact fit), ``"fit"`` (the series is fitted
                   with the contact parameters, the issue's Eq. 4.1 setting, each coefficient
                   bounded to +-``toe_range`` rad around the kinematic estimate so the toe
                   cannot act as a free force generator), ``"flat"`` (legacy: the series of
                   ``mtp = -max(foot_angle, 0)``), or ``"channel"`` (the trial's ``mtp``)
    toe_range      +- bound (rad) of each toe coefficient around its kinematic value (``toe="fit"``)
    terms          the Eq. 4.2 terms minimised, a subset of ``("normal_force", "friction_force",
                   "cop")``; default ``None``: all three, except the point contact, which as in
                   the thesis tracks the vertical force only (pass all three to compare on equal terms)
    ground_speed   ground x-velocity (m/s); default ``trial.meta["ground_speed"]`` or 0
    cop_threshold  COP term only where f_n^e > cop_threshold * max f_n^e
    n_jobs         processes for the multi-start (fork; 1 = serial)
    seed, max_nfev, ftol

    Learned attributes end in ``_``: ``contacts_`` (fitted components),
    ``fourier_`` (11 toe coefficients used; ``toe_kinematic_`` the kinematic estimate,
    ``toe_deviation_`` the largest |difference| of the two toe angles, rad), ``objective_`` (the minimised Eq. 4.2
    value), ``objective_full_`` (all three terms), ``terms_``, ``rmse_``,
    ``starts_`` (objective of every start), ``seconds_``, ``nfev_``, ``aic_``, ``bic_``,
    ``reaction_`` (the model's GroundReaction), ``outputs_`` (per-sphere ContactForces).
    """

    def __init__(self, *, contact: str = "hypervolumetric", relax: bool = False, window=None,
                 cutoff: float | None = 12.0, n_starts: int = 6, initial=None, bounds=None,
                 fixed=(), toe: str = "kinematic", ground_speed: float | None = None,
                 cop_threshold: float = 0.05, seed: int = 0, max_nfev: int = 400, ftol: float = 1e-10,
                 relax_range: float = 0.02, n_jobs: int = 1, toe_range: float = 0.02, terms=None):
        self.contact = contact
        self.relax = relax
        self.window = window
        self.cutoff = cutoff
        self.n_starts = n_starts
        self.initial = initial
        self.bounds = bounds
        self.fixed = tuple(fixed)
        self.toe = toe
        self.ground_speed = ground_speed
        self.cop_threshold = cop_threshold
        self.seed = seed
        self.max_nfev = max_nfev
        self.ftol = ftol
        self.relax_range = relax_range
        self.n_jobs = n_jobs
        self.toe_range = toe_range
        self.terms = terms

    # -- setup ------------------------------------------------------------
    def _contacts(self, model, ground_speed):
        if self.contact not in KINDS:
            raise ModelError(f"unknown contact model '{self.contact}'; choose one of {', '.join(KINDS)}")
        cs = foot_contacts(model, self.contact, relax=self.relax, ground_speed=ground_speed)
        init = self.initial or {}
        bnds = self.bounds or {}
        for site in list(init) + list(bnds):
            if site not in SITES:
                raise ModelError(f"ContactFit: unknown site '{site}' (sites: {', '.join(SITES)})")
        from .sphere import _replace
        out = []
        for site, c in zip(SITES, cs):
            params = dict(c._params)
            if self.relax:
                for name in ("dx", "dy"):
                    params[name] = _replace(params[name], min=-self.relax_range, max=self.relax_range)
            for name, (lo, hi) in bnds.get(site, {}).items():
                if name not in params:
                    raise ModelError(f"ContactFit: {c.label} has no parameter '{name}' ({sorted(params)})")
                params[name] = _replace(params[name], min=float(lo), max=float(hi))
            for name, val in init.get(site, {}).items():
                if name not in params:
                    raise ModelError(f"ContactFit: {c.label} has no parameter '{name}' ({sorted(params)})")
                params[name] = _replace(params[name], value=float(val))
            for name, p in params.items():
                if (self.contact == "point" and name in ("mu_f", "v_s")
                        and (self.terms is None or "friction_force" not in self.terms)):
                    params[name] = p = _replace(p, vary=False)
                if name in self.fixed:
                    params[name] = p = _replace(p, vary=False)
                if not (p.min <= p.value <= p.max):
                    raise SolverError(
                        f"ContactFit: the initial guess {site}.{name} = {p.value:g} {p.unit} is outside its "
                        f"bounds [{p.min:g}, {p.max:g}]; widen bounds= or pass initial= inside them")
            c = c.with_params()  # copy
            c._params = params
            out.append(c)
        return out

    def _problem(self, model, trial, ground_speed) -> _Problem:
        trial.require(DRIVE + GRF)
        t_all = np.asarray(trial.time, dtype=float)
        X = np.column_stack([np.asarray(trial[c], dtype=float) for c in DRIVE])
        for j, c in enumerate(DRIVE):
            bad = ~np.isfinite(X[:, j])
            if bad.any():
                r = int(np.flatnonzero(bad)[0])
                raise TrialError(f"channel '{c}' is not finite at row {r} (t = {t_all[r]:g} s); "
                                 "fill the gap (e.g. interpolate) before the contact fit")
        qs, vs, _ = differentiate(t_all, X, cutoff=self.cutoff)
        if self.window is None:
            sel = np.ones(t_all.size, dtype=bool)
        else:
            t0, t1 = self.window
            sel = (t_all >= t0 - 1e-9) & (t_all <= t1 + 1e-9)
            if sel.sum() < 12:
                raise TrialError(f"window {self.window} holds {int(sel.sum())} frames; need at least 12")
        t = t_all[sel]
        meas = np.vstack([np.asarray(trial[c], dtype=float)[sel] for c in GRF])
        for j, c in enumerate(GRF[:2]):
            bad = ~np.isfinite(meas[j])
            if bad.any():
                r = int(np.flatnonzero(bad)[0])
                raise TrialError(
                    f"channel '{c}' is NaN/inf at t = {t[r]:g} s (and {int(bad.sum()) - 1} more frames in the "
                    "window); ground reaction forces must be finite everywhere, also in swing: set them to 0 "
                    "where the foot is off the plate")
        fmax = np.max(np.abs(meas[0]))
        if not fmax > 0:
            raise TrialError("the measured vertical force is zero throughout the window: nothing to fit")
        cop_mask = meas[0] > self.cop_threshold * fmax
        bad = cop_mask & ~np.isfinite(meas[2])
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise TrialError(f"'ground_force_px' (COP) is undefined at t = {t[r]:g} s although the vertical "
                             f"force there is {meas[0][r]:.1f} N; lower cop_threshold or fix the COP channel")
        meas[2] = np.where(cop_mask, meas[2], 0.0)
        scale = np.array([fmax, max(np.max(np.abs(meas[1])), 1e-9),
                          max(np.max(np.abs(meas[2][cop_mask])), 1e-9)])
        names = ("normal_force", "friction_force", "cop")
        if self.terms is None:
            weights = np.array([1.0, 0.0, 0.0]) if self.contact == "point" else np.ones(3)
        else:
            bad = [x for x in self.terms if x not in names]
            if bad or not self.terms:
                raise ModelError(f"ContactFit: terms must be a non-empty subset of {names}, got {self.terms!r}")
            weights = np.array([1.0 if x in self.terms else 0.0 for x in names])
        period = t[-1] - t[0]
        B, dB = fourier_basis(t - t[0], period)
        q = np.zeros((t.size, 4))
        v = np.zeros((t.size, 4))
        q[:, :3], v[:, :3] = qs[sel], vs[sel]
        if self.toe == "channel":
            if "mtp" not in trial:
                raise TrialError("toe='channel' needs an 'mtp' channel (toe angle, rad)")
            m, dm, _ = differentiate(t_all, np.asarray(trial["mtp"], dtype=float), cutoff=self.cutoff)
            q[:, 3], v[:, 3] = m[sel], dm[sel]
        return _Problem(t, q, v, B, dB, Foot2dGeometry.from_model(model), meas, cop_mask, scale, weights)

    @property
    def _fit_toe(self) -> bool:
        return self.toe == "fit"

    # -- evaluation ---------------------------------------------------------
    def _simulate(self, prob: _Problem, contacts, fourier):
        q, v = prob.q, prob.v
        if self._fit_toe:
            q = q.copy()
            v = v.copy()
            q[:, 3] = prob.B @ fourier
            v[:, 3] = prob.dB @ fourier
        kin = foot2d_site_kinematics(prob.geom, q, v)
        outs = [c.evaluate_kinematics(kin[s]) for s, c in zip(SITES, contacts)]
        return outs, ground_reaction(outs)

    def _residual_terms(self, prob, gr):
        model = np.vstack([gr.normal, gr.friction, gr.cop[:, 0]])
        r = (model - prob.meas) / prob.scale[:, None]
        r[2] = np.where(prob.cop_mask, r[2], 0.0)
        return r / math.sqrt(prob.t.size)

    # -- fit ----------------------------------------------------------------
    def fit(self, model, trial) -> "ContactFit":
        """Identify the parameters; returns self."""
        t_start = time.perf_counter()
        if self.toe not in TOE_MODES:
            raise ModelError(f"ContactFit: toe must be one of {', '.join(map(repr, TOE_MODES))}, got {self.toe!r}")
        if not self.toe_range > 0:
            raise ModelError(f"ContactFit: toe_range must be > 0 rad (the +- bound of the toe coefficients), "
                             f"got {self.toe_range}; use toe='kinematic' to hold the toe angle fixed")
        if model is None:
            model = load_foot2d()
        gs = self.ground_speed
        if gs is None:
            gs = float(trial.meta.get("ground_speed", 0.0)) if hasattr(trial, "meta") else 0.0
        self.ground_speed_ = gs
        contacts = self._contacts(model, gs)
        prob = self._problem(model, trial, gs)
        # toe angle from the kinematics (held fixed for "kinematic", the centre of the bounds for "fit")
        if self.toe == "flat":
            mtp_kin = -np.maximum(prob.q[:, 2], 0.0)
        else:
            mtp_kin = toe_from_kinematics(prob.geom, prob.q, swing=prob.meas[0] < SWING * prob.scale[0])
        fourier0 = np.linalg.lstsq(prob.B, mtp_kin, rcond=None)[0]
        self.toe_kinematic_ = fourier0
        if self.toe in ("flat", "kinematic"):
            prob.q[:, 3], prob.v[:, 3] = prob.B @ fourier0, prob.dB @ fourier0
        self._check_contact(prob, contacts, fourier0)

        # free-parameter vector
        slots = []  # (sphere index, name)
        for i, c in enumerate(contacts):
            for name, p in c._params.items():
                if p.vary:
                    slots.append((i, name))
        nfree = len(slots)
        p0 = np.array([contacts[i]._params[n].value for i, n in slots])
        lo = np.array([contacts[i]._params[n].min for i, n in slots])
        hi = np.array([contacts[i]._params[n].max for i, n in slots])
        typ = np.array([_typical(contacts[i], n) for i, n in slots])
        if self._fit_toe:
            # regularised: each coefficient within +-toe_range of its kinematic value
            p0 = np.concatenate([p0, fourier0])
            lo = np.concatenate([lo, fourier0 - self.toe_range])
            hi = np.concatenate([hi, fourier0 + self.toe_range])
            typ = np.concatenate([typ, np.full(N_FOURIER, 0.1)])
        w = np.repeat(np.sqrt(prob.weights), prob.t.size)

        def unpack(x):
            p = x * typ
            vals = [dict(c.values) for c in contacts]
            for (i, n), val in zip(slots, p[:nfree]):
                vals[i][n] = val
            four = p[nfree:] if self._fit_toe else None
            return vals, four

        def fun(x):
            vals, four = unpack(x)
            gr = self._simulate_vals(prob, contacts, vals, four)
            return self._residual_terms(prob, gr).ravel() * w

        rng = np.random.default_rng(self.seed)
        starts = [p0]
        for _ in range(max(self.n_starts, 1) - 1):
            s = p0.copy()
            for j, (i, n) in enumerate(slots):
                if n in ("dx", "dy"):
                    s[j] = rng.uniform(lo[j], hi[j])
                elif n in _LOG_PARAMS and p0[j] > 0:
                    s[j] = p0[j] * math.exp(rng.uniform(-math.log(3), math.log(3)))
                else:
                    span = 0.25 * (abs(p0[j]) if p0[j] != 0 else typ[j])
                    s[j] = p0[j] + rng.uniform(-span, span)
            starts.append(np.clip(s, lo + 1e-12 * np.abs(lo), hi - 1e-12 * np.abs(hi)))
        def solve(s):
            try:
                res = least_squares(fun, s / typ, bounds=(lo / typ, hi / typ), method="trf",
                                    x_scale=1.0, ftol=self.ftol, xtol=1e-10, gtol=1e-10,
                                    max_nfev=self.max_nfev, diff_step=1e-6)
            except ValueError as exc:
                raise SolverError(f"ContactFit: least_squares failed: {exc}") from None
            return res

        # The linear algebra is tiny (~300 x 35): threaded BLAS only adds overhead (OpenBLAS's
        # threaded gesdd, used by 'trf', measured 40 ms per SVD vs 0.46 ms on one thread), and
        # with forked multi-start workers it oversubscribes the cores.  Forked workers inherit the limit.
        with threadpool_limits(limits=1):
            results = _map_starts(solve, starts, self.n_jobs)
        self.starts_ = [float(2 * r.cost) for r in results]
        nfev = sum(int(r.nfev) for r in results)
        best = min(results, key=lambda r: r.cost if np.isfinite(r.cost) else np.inf)
        if best is None or not np.all(np.isfinite(best.x)):
            raise SolverError("ContactFit: no start produced a finite solution")
        vals, four = unpack(best.x)
        self.contacts_ = [c.with_params(v) for c, v in zip(contacts, vals)]
        self.fourier_ = four if four is not None else (None if self.toe == "channel" else fourier0)
        self.toe_deviation_ = (float(np.max(np.abs(prob.B @ (self.fourier_ - fourier0))))
                               if self.fourier_ is not None else 0.0)
        self.result_ = best
        self.nfev_ = nfev
        self.n_free_ = best.x.size
        self.problem_ = prob
        self._finish(prob)
        self.seconds_ = time.perf_counter() - t_start
        return self

    def _simulate_vals(self, prob, contacts, vals, four):
        q, v = prob.q, prob.v
        if four is not None:
            q = q.copy()
            v = v.copy()
            q[:, 3] = prob.B @ four
            v[:, 3] = prob.dB @ four
        kin = foot2d_site_kinematics(prob.geom, q, v)
        outs = [c.evaluate_kinematics(kin[s], vals[i]) for i, (s, c) in enumerate(zip(SITES, contacts))]
        return ground_reaction(outs)

    def _check_contact(self, prob, contacts, fourier0):
        """Refuse spheres that cannot touch the ground anywhere in the window, even at their largest size."""
        q = prob.q.copy()
        if self._fit_toe:
            q[:, 3] = prob.B @ fourier0
        kin = foot2d_site_kinematics(prob.geom, q, prob.v)
        msgs = []
        for s, c in zip(SITES, contacts):
            P = c._params
            rmax = P[c.radius_name].max
            reach = rmax + max(abs(P["dy"].min), abs(P["dy"].max)) * P["dy"].vary + abs(P["dy"].value)
            hmin = float(kin[s].position[:, 1].min())
            if hmin > reach:
                tmin = prob.t[int(np.argmin(kin[s].position[:, 1]))]
                msgs.append(f"'{c.target}' (lowest centre {hmin * 1000:.1f} mm above y = 0 at t = {tmin:g} s, "
                            f"largest {c.radius_name} {rmax * 1000:.1f} mm)")
        if msgs:
            raise ModelError(
                "contact sphere(s) never touch the ground in the fitted window: " + "; ".join(msgs)
                + ". Check that ankle_y is in m with the ground (belt surface) at y = 0, and the window covers stance")

    def _finish(self, prob):
        outs, gr = self._simulate(prob, self.contacts_, self.fourier_)
        self.outputs_ = outs
        self.reaction_ = gr
        r = self._residual_terms(prob, gr)
        terms = np.sum(r ** 2, axis=1)
        self.terms_ = {"normal_force": float(terms[0]), "friction_force": float(terms[1]), "cop": float(terms[2])}
        self.objective_ = float(np.dot(terms, prob.weights))
        self.objective_full_ = float(terms.sum())
        # information criteria on the minimised residuals (Gaussian errors): n ln(RSS/n) + 2k / + k ln n
        n_res = int(prob.t.size * np.count_nonzero(prob.weights))
        rss = max(self.objective_ * prob.t.size, 1e-300)
        k = int(self.n_free_)
        self.aic_ = float(n_res * math.log(rss / n_res) + 2 * k)
        self.bic_ = float(n_res * math.log(rss / n_res) + k * math.log(n_res))
        diff_n = gr.normal - prob.meas[0]
        diff_f = gr.friction - prob.meas[1]
        diff_c = (gr.cop[:, 0] - prob.meas[2])[prob.cop_mask]
        self.rmse_ = {"normal_force": float(np.sqrt(np.mean(diff_n ** 2))),
                      "friction_force": float(np.sqrt(np.mean(diff_f ** 2))),
                      "cop": float(np.sqrt(np.mean(diff_c ** 2))) if diff_c.size else float("nan")}

    # -- results ------------------------------------------------------------
    def params_(self) -> dict:
        """``{site: {param: value}}`` of the fitted spheres."""
        return {s: dict(c.values) for s, c in zip(SITES, self.contacts_)}

    def to_dict(self) -> dict:
        return {"contact": self.contact, "relax": bool(self.relax), "toe": self.toe,
                "objective": self.objective_, "objective_full": self.objective_full_,
                "terms": self.terms_, "params": self.params_(),
                "toe_fourier": None if self.fourier_ is None else [float(x) for x in self.fourier_],
                "toe_max_deviation": self.toe_deviation_, "load_shares": self.load_shares(),
                "rmse": self.rmse_, "seconds": self.seconds_, "n_free": int(self.n_free_),
                "aic": self.aic_, "bic": self.bic_, "converged": bool(self.result_.status > 0),
                "nfev": int(self.nfev_), "starts": self.starts_, "ground_speed": self.ground_speed_,
                "window": [float(self.problem_.t[0]), float(self.problem_.t[-1])]}

    def report(self) -> str:
        lines = [f"contact fit ({self.contact}{', relaxed' if self.relax else ''}): "
                 f"J (Eq. 4.2) = {self.objective_:.5f} (all terms {self.objective_full_:.5f}), "
                 f"{self.n_free_} free parameters, {self.nfev_} evaluations, {self.seconds_:.2f} s, "
                 f"AIC {self.aic_:.1f}, BIC {self.bic_:.1f}"
                 f"{'' if self.result_.status > 0 else ' (best start hit max_nfev)'}",
                 f"  RMSE: normal {self.rmse_['normal_force']:.1f} N, friction "
                 f"{self.rmse_['friction_force']:.1f} N, COP {1000 * self.rmse_['cop']:.1f} mm"]
        for s, c in zip(SITES, self.contacts_):
            lines.append(f"  {s:<10} " + ", ".join(f"{k}={v:.4g}" for k, v in c.values.items()))
        return "\n".join(lines)

    def sensitivity(self, *, factor: float = 1.1) -> dict:
        """Fig. 4.11: % change of the peak total normal force when each sphere's stiffness is scaled by ``factor``."""
        prob = self.problem_
        base = self.reaction_.normal
        out = {}
        for i, s in enumerate(SITES):
            cs = list(self.contacts_)
            c = cs[i]
            k = c.stiffness_name
            cs[i] = c.with_params({k: c.values[k] * factor})
            _, gr = self._simulate(prob, cs, self.fourier_)
            out[s] = {"peak_percent": float(100 * (gr.normal.max() / base.max() - 1)),
                      "mean_percent": float(100 * (gr.normal.sum() / base.sum() - 1))}
        return out

    def load_shares(self) -> dict:
        """``{site: fraction}`` of the model's normal impulse over the window carried by each sphere."""
        tot = float(np.sum(self.reaction_.normal))
        return {s: float(np.sum(o.normal) / tot) if tot > 0 else float("nan")
                for s, o in zip(SITES, self.outputs_)}

    def double_hump(self) -> dict:
        """The vertical GRF's double hump, measured vs model, at the measured events.

        Peaks: the largest measured f_n in the first and second half of the loaded frames;
        valley: the smallest between them.  ``depth`` = 1 - valley / mean(peaks) (0 = no
        hump), for the measurement and for the model sampled at the same three frames, plus
        the model's own depth (its peaks/valley searched in the same halves).
        """
        prob = self.problem_
        fm, fe = prob.meas[0], self.reaction_.normal
        idx = np.flatnonzero(fm > 0.5 * fm.max())
        if idx.size < 5:
            raise SolverError("double_hump: fewer than 5 frames above half the peak vertical force")
        mid = (idx[0] + idx[-1]) // 2
        a, b = np.arange(idx[0], mid + 1), np.arange(mid, idx[-1] + 1)

        def depth(f, i1, i2, iv):
            return float(1 - f[iv] / (0.5 * (f[i1] + f[i2])))

        i1, i2 = a[np.argmax(fm[a])], b[np.argmax(fm[b])]
        iv = i1 + int(np.argmin(fm[i1:i2 + 1]))
        j1, j2 = a[np.argmax(fe[a])], b[np.argmax(fe[b])]
        jv = j1 + int(np.argmin(fe[j1:j2 + 1])) if j2 > j1 else j1
        t = prob.t
        return {"measured_depth": depth(fm, i1, i2, iv), "model_depth_at_measured_events": depth(fe, i1, i2, iv),
                "model_depth": depth(fe, j1, j2, jv) if j2 > j1 else 0.0,
                "measured_events_s": [float(t[i1]), float(t[iv]), float(t[i2])],
                "model_events_s": [float(t[j1]), float(t[jv]), float(t[j2])]}

    def plot(self, out_dir) -> list[Path]:
        """GRF (vertical, horizontal) and COP vs measured, as PNGs in ``out_dir``."""
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ..plots import save_figure

        out_dir = Path(out_dir)
        prob, gr = self.problem_, self.reaction_
        t = prob.t
        title = f"{self.contact}{' relaxed' if self.relax else ''}"
        fig, ax = plt.subplots(2, 1, figsize=(6, 5.5), sharex=True)
        ax[0].plot(t, prob.meas[0], "k", label="measured")
        ax[0].plot(t, gr.normal, "C3", label="model")
        for o, s in zip(self.outputs_, SITES):
            ax[0].plot(t, o.normal, lw=0.8, ls="--", label=s)
        ax[0].set_ylabel("vertical GRF (N)")
        ax[0].legend(fontsize=7)
        ax[0].set_title(f"{title}: J = {self.objective_:.4f}")
        ax[1].plot(t, prob.meas[1], "k", label="measured")
        ax[1].plot(t, gr.friction, "C3", label="model")
        ax[1].set_ylabel("horizontal GRF (N)")
        ax[1].set_xlabel("time (s)")
        fig.tight_layout()
        p1 = out_dir / f"grf_{self.contact}{'_relaxed' if self.relax else ''}.png"
        save_figure(fig, p1, dpi=110)
        plt.close(fig)
        fig, ax = plt.subplots(figsize=(6, 3.2))
        m = prob.cop_mask
        ax.plot(t[m], prob.meas[2][m], "k.", ms=3, label="measured")
        ax.plot(t[m], gr.cop[m, 0], "C3", label="model")
        ax.set_ylabel("COP x (m)")
        ax.set_xlabel("time (s)")
        ax.set_title(title)
        ax.legend(fontsize=7)
        fig.tight_layout()
        p2 = out_dir / f"cop_{self.contact}{'_relaxed' if self.relax else ''}.png"
        save_figure(fig, p2, dpi=110)
        plt.close(fig)
        return [p1, p2]


_JOB = None


def _run_job(i):
    fn, starts = _JOB
    return fn(starts[i])


def _map_starts(fn, starts, n_jobs: int):
    """``[fn(s) for s in starts]``, in ``n_jobs`` forked processes when > 1 (serial where fork is absent)."""
    global _JOB
    if n_jobs <= 1 or len(starts) < 2:
        return [fn(s) for s in starts]
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    try:
        ctx = mp.get_context("fork")
    except ValueError:  # pragma: no cover - no fork on this platform
        return [fn(s) for s in starts]
    _JOB = (fn, starts)
    try:
        with ProcessPoolExecutor(max_workers=n_jobs, mp_context=ctx) as ex:
            return list(ex.map(_run_job, range(len(starts))))
    finally:
        _JOB = None


def _typical(c, name: str) -> float:
    p = c._params[name]
    if name in ("dx", "dy"):
        return 0.01
    return abs(p.value) if p.value != 0 else 1.0


def read_contact_trial(path):
    """A Trial from ``path``: a CSU leg2d text file (first line ``% TimeStamp ...``) or any file
    :func:`pinmsk.read_trial` reads (.csv/.sto/.mot)."""
    path = Path(path)
    if not path.exists():
        raise TrialError(f"trial file not found: {path}")
    with open(path, "r", errors="replace") as fh:
        first = fh.readline()
    if first.lstrip().startswith("%") and "TimeStamp" in first:
        from ..csu import read_csu
        return read_csu(path)
    from ..io import read_trial
    return read_trial(path)


def _load_model_arg(model):
    if model is None or str(model) == "foot2d" or Path(str(model)).name in ("foot2d.toml", "foot2d.urdf"):
        return load_foot2d()
    from ..model import load_model
    return load_model(model)


def fit_cli_run(model, trial, *, contact: str = "hypervolumetric", relax: bool = False,
                json_path=None, plot_dir=None, window=None, n_starts: int = 6, **options) -> dict:
    """What ``pinmsk contact fit MODEL TRIAL --contact ... [--relax] [--json] [--plot]`` runs.

    ``model`` is a Model, a model name/path, or None (foot2d); ``trial`` a Trial or a
    file (CSU leg2d text, .csv, .sto, .mot; see :func:`read_contact_trial`) with
    ankle_x, ankle_y, foot_angle and ground_force_vx/vy/px.  ``window`` defaults
    to one cycle from toe-off to toe-off if the trial holds two, else the whole
    trial.  Returns (and writes to ``json_path``) a dict with ``objective``
    (Eq. 4.2), ``params`` ({site: {name: value}}), ``rmse`` (``normal_force``,
    ``friction_force`` in N, ``cop`` in m) and ``seconds``; ``plot_dir`` gets the
    GRF and COP figures (their paths under ``figures``).
    """
    if model is None or isinstance(model, (str, Path)):
        model = _load_model_arg(model)
    if isinstance(trial, (str, Path)):
        trial = read_contact_trial(trial)
    if window is None:
        try:
            window = stance_cycle(trial)
        except TrialError:
            window = None
    fit = ContactFit(contact=contact, relax=relax, window=window, n_starts=n_starts, **options).fit(model, trial)
    out = fit.to_dict()
    if plot_dir is not None:
        out["figures"] = [str(p) for p in fit.plot(plot_dir)]
    if json_path is not None:
        from ..io import write_json
        write_json(json_path, out, parents=True)
    return out
