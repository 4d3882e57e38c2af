"""Kinematically driven identification of foot contact parameters (thesis Sec. 4.1.2, Eq. 4.1-4.2).

The foot2d model is driven by the measured foot (channels ``ankle_x``, ``ankle_y``,
``foot_angle``; for the CSU data :func:`pinmsk.io.cleveland_gait.read_csu` derives them from the heel
and 5th-metatarsal markers, so the heel sphere follows the measured heel).  The toe
angle is the 11-term Fourier series of Eq. 4.1 over the analysed window (period =
window length).  By default (``toe="kinematic"``, the thesis procedure) its
coefficients are identified beforehand from the kinematics
(:func:`toe_from_kinematics`) and held fixed; ``toe="fit"`` fits them with the
contact parameters (Eq. 4.1 as written: toe and contact identified together), each within ``+-toe_range`` of the
kinematic estimate so the toe cannot act as a free force generator.  The objective is
Eq. 4.2 sampled uniformly,

    J = 1/N sum_t [ (f_n^m - f_n^e)/max|f_n^e| ]^2 + [ (f_f^m - f_f^e)/max|f_f^e| ]^2
                 + [ (X^m - X^e)/max|X^e| ]^2

with the COP term over the frames where the measured vertical force exceeds
``cop_threshold`` x its maximum (the measured COP is undefined elsewhere).  Every
contact model minimises the same terms (default all three, ``terms=`` picks a
subset), so their J are comparable; parameters no minimised term depends on (the
friction pair ``mu_f, v_s`` when friction is not tracked) are held at their initial values.

Solver.  Bounded trust-region least squares (``scipy.optimize.least_squares``,
'trf'; stiffness, damping and friction-speed parameters in log space) with the exact
Jacobian of the residual: the same contact-law code runs on
:class:`~pinmsk.contact.dual.Dual` numbers (forward mode), so there is one
implementation of every law and no finite differences (``jacobian="2-point"``
restores them, for comparison).  Multi-start: the initial guess (the thesis optimum
of Tables 4.2-4.4), then -- ``nested=True`` -- the optimum of each simpler model the
fitted one contains, mapped into its parameters (:func:`map_values`), then random
draws around the initial guess.  The linear volumetric sphere is the hyper-volumetric
one with ``H = 1``, ``k_h = k_V``, ``a_h = k_V a_V`` exactly, and the relaxed spheres
contain the fixed ones at ``dx = dy = 0``, so a model never ends worse than one it
contains exactly.  The point contact is contained only in its elastic part (``V ~ pi R
d^2`` for small penetration, so ``k_h V^H ~ k_s d^n`` with ``n = 2H``): its
Hunt-Crossley damping ``k_s a_s d^n v`` scales with the elastic force, Eq. 4.15's
``a_h V v`` with ``d^2``, so a point fit that leans on damping at a low exponent can end
below the hyper-volumetric one (it does on the CSU trial).  Each start stops when a step
lowers J by less than ``ftol`` (relative).  BLAS is limited to one thread
(``threadpoolctl``): the problem is ~360 x 20, where OpenBLAS's threaded gesdd took 40 ms
per SVD against 0.5 ms.

Channels: ``ground_force_vx`` (friction, N), ``ground_force_vy`` (normal, N),
``ground_force_px`` (COP x, m; NaN allowed where the vertical force is small).
The ground moves at ``ground_speed`` (m/s, x) -- ``trial.meta["ground_speed"]``
when the reader set it (a treadmill belt, see :mod:`pinmsk.io.cleveland_gait`).
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
from ..fitting import FitStatistics, Fitter, Result, format_report
from ..io.cleveland_gait import read_csu
from ..io.tables import read_trial
from ..model import load_model
from ..signals.filtering import CONTACT_CUTOFF, differentiate
from .dual import Dual
from .foot import KINDS, SITES, Foot2dGeometry, foot2d_site_kinematics, foot_contacts, ground_reaction
from .sphere import SiteKinematics, cap_volume

DRIVE = ("ankle_x", "ankle_y", "foot_angle")
GRF = ("ground_force_vy", "ground_force_vx", "ground_force_px")
#: the Eq. 4.2 terms, in the order of the residual blocks
ALL_TERMS = ("normal_force", "friction_force", "cop")
N_FOURIER = 11
TOE_MODES = ("kinematic", "fit", "flat", "channel")
JACOBIANS = ("exact", "2-point")
#: swing frames (toes off the ground) for :func:`toe_from_kinematics`: measured f_n below this x its peak
SWING = 0.02
#: parameters sampled log-uniformly in the multi-start (scale-like, >= 0)
_LOG_PARAMS = {"k_s", "a_s", "k_v", "a_v", "k_h", "a_h", "v_s"}
#: the simpler models each contact model contains (for the nested starts), closest first
CONTAINS = {"point": (), "volumetric": ("point",), "hypervolumetric": ("volumetric", "point")}
#: the friction parameters (only the friction term of Eq. 4.2 depends on them)
FRICTION = ("mu_f", "v_s")
THESIS_TABLE = {"point": "4.2", "volumetric": "4.3", "hypervolumetric": "4.4"}

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
    """Everything parameter-independent of one identification (shared by the nested fits)."""

    t: np.ndarray
    q: np.ndarray          # (N, 4); the mtp column holds the fixed toe angle unless it is fitted
    v: np.ndarray
    B: np.ndarray
    dB: np.ndarray
    geom: Foot2dGeometry
    meas: np.ndarray       # (3, N): fn, ff, cop
    cop_mask: np.ndarray
    scale: np.ndarray      # (3,) Eq. 4.2 normalisers
    weights: np.ndarray    # (3,) 1 or 0 per term in the minimised objective
    window_source: str = "given"
    fourier0: np.ndarray | None = None   # toe coefficients from the kinematics
    kin: dict | None = None              # site kinematics, when the toe angle is not fitted


class _Residual:
    """The Eq. 4.2 residual of one identification as a function of the scaled free parameters
    ``x`` (``p = x * typ``), and its exact Jacobian.

    ``slots`` lists the free parameters as (sphere index, name); with ``fit_toe`` the 11 toe
    coefficients follow them.  The three spheres (one class, one set of options) are evaluated
    in one call of their law on the frames of all three stacked (3N "frames", per-frame
    parameter arrays), which costs a third of three calls.  :meth:`jacobian` runs the same code
    on :class:`~pinmsk.contact.dual.Dual` parameters.  A sphere's outputs depend on its own
    parameters only, so the spheres share derivative columns (column compression: column ``k``
    is "the sphere's own k-th free parameter", plus the toe coefficients, which move the toe
    sphere only); the columns are spread out to the full Jacobian before :func:`ground_reaction`
    adds the spheres up.
    """

    def __init__(self, prob: _Problem, contacts, *, fit_toe: bool, toe_range: float):
        first = contacts[0]
        if any(type(c) is not type(first) or c.ground_speed != first.ground_speed or c.smoothing != first.smoothing
               or c.center != first.center for c in contacts):
            raise ModelError("ContactFit: the spheres of one fit must share their class and options")
        self.prob = prob
        self.contacts = contacts
        self.fit_toe = fit_toe
        params = [c.params for c in contacts]
        self.slots = [(i, n) for i, P in enumerate(params) for n, p in P.items() if p.vary]
        self.nfree = len(self.slots)
        par = [params[i][n] for i, n in self.slots]
        p0 = np.array([p.value for p in par])
        lo = np.array([p.min for p in par])
        hi = np.array([p.max for p in par])
        typ = np.array([_typical(p) for p in par])
        if fit_toe:
            f0 = prob.fourier0
            p0, lo, hi = (np.concatenate([p0, f0]), np.concatenate([lo, f0 - toe_range]),
                          np.concatenate([hi, f0 + toe_range]))
            typ = np.concatenate([typ, np.full(N_FOURIER, 0.1)])
        self.p0, self.lo, self.hi, self.typ = p0, lo, hi, typ
        # scale-like parameters (stiffness, damping, friction speed) are solved for in log space
        self.log = np.array([n in _LOG_PARAMS for _, n in self.slots] + [False] * (p0.size - self.nfree))
        self.lo_x = np.where(self.log, np.log(np.maximum(lo, 1e-9 * typ) / typ), lo / typ)
        self.hi_x = np.where(self.log, np.log(np.maximum(hi, 1e-9 * typ) / typ), hi / typ)
        self.base = [dict(c.values) for c in contacts]
        self.w = np.repeat(np.sqrt(prob.weights), prob.t.size)
        n, k = prob.t.size, len(contacts)
        # compressed derivative columns: one per free parameter name, then the toe coefficients
        self.local = {}
        for _, name in self.slots:
            self.local.setdefault(name, len(self.local))
        self.n_local = len(self.local) + (N_FOURIER if fit_toe else 0)
        self._seed = {name: np.zeros((k * n, self.n_local)) for name in self.local}
        self._spread = [[] for _ in contacts]   # per sphere: (column in x, compressed column)
        for j, (i, name) in enumerate(self.slots):
            self._seed[name][i * n:(i + 1) * n, self.local[name]] = 1.0
            self._spread[i].append((j, self.local[name]))
        if fit_toe:
            self._spread[SITES.index("toe")] += [(self.nfree + m, len(self.local) + m) for m in range(N_FOURIER)]
            self._toe_seed = np.zeros((N_FOURIER, self.n_local))
            self._toe_seed[:, len(self.local):] = np.eye(N_FOURIER)
        self._spread = [tuple(np.array(c, dtype=int).reshape(-1, 2).T) for c in self._spread]
        # the site kinematics that do not depend on the fitted toe angle (all of them unless it is fitted)
        if prob.kin is not None:
            fixed = prob.kin
        else:
            q = prob.q.copy()
            q[:, 3] = prob.B @ prob.fourier0
            fixed = foot2d_site_kinematics(prob.geom, q, prob.v)
        self._kin_fixed = fixed
        self._kin_stacked = _stack_kinematics([fixed[s] for s in SITES])

    # -- parameters ----------------------------------------------------------
    def unpack(self, p):
        """``(values per sphere, toe coefficients or None)`` from unscaled ``p``."""
        vals = [dict(b) for b in self.base]
        for j, (i, n) in enumerate(self.slots):
            vals[i][n] = p[j]
        return vals, (p[self.nfree:] if self.fit_toe else None)

    def start(self, values, fourier=None) -> np.ndarray:
        """The unscaled parameter vector of ``values`` ({name: value} per sphere; missing names keep
        the initial guess), clipped into the bounds."""
        p = np.array([values[i].get(n, self.base[i][n]) for i, n in self.slots], dtype=float)
        if self.fit_toe:
            p = np.concatenate([p, self.p0[self.nfree:] if fourier is None else np.asarray(fourier, float)])
        return np.clip(p, self.lo, self.hi)

    # -- evaluation ----------------------------------------------------------
    def _stacked(self, vals, four):
        """The spheres' ContactForces on their stacked frames (one law call), parameters per frame."""
        n = self.prob.t.size
        params = {name: np.repeat([float(v[name]) for v in vals], n) for name in vals[0]}
        kin = self._kin_stacked
        if four is not None:
            prob = self.prob
            q, v = prob.q, prob.v
            toe = foot2d_site_kinematics(prob.geom, [q[:, 0], q[:, 1], q[:, 2], prob.B @ four],
                                         [v[:, 0], v[:, 1], v[:, 2], prob.dB @ four])["toe"]
            kin = _stack_kinematics([self._kin_fixed["heel"], self._kin_fixed["metatarsal"], toe])
        return params, kin

    _FIELDS = ("normal", "friction", "force", "point", "penetration", "volume", "slip")

    def _split(self, o, n_x=None, fields=_FIELDS):
        """Per-sphere ContactForces from the stacked ones; Dual fields are spread to ``n_x``
        columns, and only ``fields`` are kept (the others None)."""
        n = self.prob.t.size
        out = []
        for i in range(len(self.contacts)):
            rows = slice(i * n, (i + 1) * n)
            kept = dict.fromkeys(self._FIELDS)
            for name in fields:
                a = getattr(o, name)[rows]
                if isinstance(a, Dual):
                    jx, jl = self._spread[i]
                    der = np.zeros(a.shape + (n_x,))
                    der[..., jx] = a.der[..., jl]
                    a = Dual._new(a.val, der)
                kept[name] = a
            out.append(type(o)(**kept))
        return out

    def reaction(self, vals, four):
        """``(per-sphere ContactForces, GroundReaction)`` for ``vals`` and toe coefficients ``four``."""
        params, kin = self._stacked(vals, four)
        outs = self._split(self.contacts[0].evaluate_kinematics(kin, params))
        return outs, ground_reaction(outs)

    def terms(self, gr):
        """The (3, N) Eq. 4.2 residual blocks (normal force, friction force, COP) of a GroundReaction."""
        prob = self.prob
        r = (np.stack([gr.normal, gr.friction, gr.cop[:, 0]]) - prob.meas) / prob.scale[:, None]
        r[2] = np.where(prob.cop_mask, r[2], 0.0)
        return r * (1.0 / math.sqrt(prob.t.size))

    def to_p(self, x) -> np.ndarray:
        """Parameters from solver variables: ``typ * exp(x)`` (log-scaled ones), else ``typ * x``."""
        x = np.asarray(x, dtype=float)
        return self.typ * np.where(self.log, np.exp(np.where(self.log, x, 0.0)), x)

    def to_x(self, p) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        return np.where(self.log, np.log(np.maximum(p, 1e-9 * self.typ) / self.typ), p / self.typ)

    def __call__(self, x) -> np.ndarray:
        vals, four = self.unpack(self.to_p(x))
        return self.terms(self.reaction(vals, four)[1]).ravel() * self.w

    def jacobian(self, x) -> np.ndarray:
        """``d residual / d x`` (exact, forward mode), (3N, n_x)."""
        x = np.asarray(x, dtype=float)
        p = self.to_p(x)
        vals, four = self.unpack(p)
        if four is not None:
            four = Dual._new(np.asarray(four, dtype=float), self._toe_seed)
        params, kin = self._stacked(vals, four)
        for name, seed in self._seed.items():
            params[name] = Dual._new(params[name], seed)
        outs = self._split(self.contacts[0].evaluate_kinematics(kin, params), x.size, ("normal", "force", "point"))
        r = self.terms(ground_reaction(outs)).ravel() * self.w
        dp_dx = np.where(self.log, p, self.typ)
        return r.der * dp_dx if isinstance(r, Dual) else np.zeros((r.size, x.size))


def _stack_kinematics(kins):
    """One SiteKinematics holding the frames of ``kins`` one after the other (plain or Dual fields)."""
    return SiteKinematics(*(np.concatenate([getattr(k, f) for k in kins])
                            for f in ("position", "rotation", "velocity", "omega")))


class ContactFit(Fitter):
    """Identify the contact parameters of foot2d from a trial (thesis Eq. 4.2).

    Keyword arguments (stored only; :meth:`fit` does the work).  These defaults are the
    settings of ``pinmsk contact fit`` and of ``examples/05_contact_identification.py``:

    contact        ``point`` | ``volumetric`` | ``hypervolumetric`` (default)
    relax          free the sphere centres' dx, dy (Sec. 4.1.4) within +-``relax_range`` m
                   (default 0.02: Table 4.4 allows 0-20 mm, Sec. 4.1.4 says +-15 mm)
    window         ``"cycle"`` (default: one gait cycle from the first toe-off to the next,
                   :func:`stance_cycle`, when the trial holds two; else the whole trial),
                   ``None`` (the whole trial) or ``(t0, t1)`` in s
    cutoff         low-pass (Hz) of the driving kinematics before differentiation (default
                   :data:`pinmsk.signals.filtering.CONTACT_CUTOFF` = 12 Hz, for marker data; None:
                   none, for noise-free synthetic kinematics).
                   The GRF is not filtered.
    terms          the Eq. 4.2 terms minimised, a non-empty subset of ``ALL_TERMS`` =
                   ``("normal_force", "friction_force", "cop")``; default all three, for every
                   contact model.  ``("normal_force",)`` tracks the vertical force only (the
                   thesis's point contact); ``mu_f, v_s`` are then held fixed
    toe            toe angle (the 11-term series of Eq. 4.1 in every mode but ``"channel"``):
                   ``"kinematic"`` (default; the thesis procedure: the toe angle is
                   identified beforehand from the kinematics, :func:`toe_from_kinematics`,
                   and held fixed during the contact fit), ``"fit"`` (the series is fitted
                   with the contact parameters, as Eq. 4.1 is written, each coefficient
                   bounded to +-``toe_range`` rad around the kinematic estimate so the toe
                   cannot act as a free force generator), ``"flat"`` (legacy: the series of
                   ``mtp = -max(foot_angle, 0)``), or ``"channel"`` (the trial's ``mtp``)
    toe_range      +- bound (rad) of each toe coefficient around its kinematic value (``toe="fit"``)
    n_starts       number of starting points (default 4): the initial guess, then (``nested``)
                   the optimum of each contained simpler model mapped into this one's
                   parameters (hyper-volumetric: volumetric, point; volumetric: point;
                   relaxed: the same model with fixed centres), then random draws around the
                   initial guess (``seed``).  1 = the initial guess only
    nested         fit the contained models first (with these settings) for those starts (default True)
    initial        ``{site: {param: value}}`` overriding the thesis initial values
    bounds         ``{site: {param: (lo, hi)}}`` overriding the bounds
    fixed          names of parameters to hold at their initial value (all sites)
    ground_speed   ground x-velocity (m/s); default ``trial.meta["ground_speed"]`` or 0
    cop_threshold  COP term only where f_n^e > cop_threshold * max f_n^e (default 0.05)
    jacobian       ``"exact"`` (default, forward-mode :class:`~pinmsk.contact.dual.Dual`) or
                   ``"2-point"`` (finite differences, for comparison)
    n_jobs         processes for the starts (fork; default 1 = serial: a start takes ~0.1 s,
                   less than starting a process pool costs)
    seed           of the random starts (default 0)
    max_nfev       residual evaluations per start (default 400)
    ftol           a start stops when a step lowers J by less than this fraction (default 1e-6:
                   on the CSU trial J agrees with ftol = 1e-10 to 1e-4, at a tenth of the evaluations)

    Learned attributes end in ``_``: ``contacts_`` (fitted components),
    ``fourier_`` (11 toe coefficients used; ``toe_kinematic_`` the kinematic estimate,
    ``toe_deviation_`` the largest |difference| of the two toe angles, rad), ``objective_`` (the minimised Eq. 4.2
    value), ``objective_full_`` (all three terms), ``terms_``, ``rmse_``,
    ``starts_`` (objective reached from every start, ``start_labels_`` where each began),
    ``nested_`` (``{kind: ContactFit}`` of the contained models; ``nested_skipped_`` those that
    could not be fitted, with the reason), ``seconds_`` (including
    the nested fits), ``nfev_`` (residual evaluations, nested fits included), ``aic_``,
    ``bic_``, ``reaction_`` (the model's GroundReaction), ``outputs_`` (per-sphere
    ContactForces), ``residual_`` (the residual function, with ``.jacobian``), ``window_``,
    ``result_`` (a :class:`~pinmsk.fitting.Result`: the fitted model's ``ground_force_vy``,
    ``ground_force_vx``, ``ground_force_px`` over the window, and the statistics of the
    minimised Eq. 4.2 residuals -- ``n`` of them, ``k = n_free_``, ``sse`` their sum of
    squares, AIC/BIC with the variance estimated, the best start's convergence).
    :meth:`to_dict` is the JSON summary ``pinmsk contact fit --json`` writes.
    """

    def __init__(self, *, contact: str = "hypervolumetric", relax: bool = False, window="cycle",
                 cutoff: float | None = CONTACT_CUTOFF, terms=ALL_TERMS, toe: str = "kinematic", n_starts: int = 4,
                 nested: bool = True, initial=None, bounds=None, fixed=(), ground_speed: float | None = None,
                 cop_threshold: float = 0.05, seed: int = 0, max_nfev: int = 400, ftol: float = 1e-6,
                 relax_range: float = 0.02, n_jobs: int = 1, toe_range: float = 0.02,
                 jacobian: str = "exact"):
        self.contact = contact
        self.relax = relax
        self.window = window
        self.cutoff = cutoff
        self.terms = terms
        self.toe = toe
        self.n_starts = n_starts
        self.nested = nested
        self.initial = initial
        self.bounds = bounds
        self.fixed = fixed
        self.ground_speed = ground_speed
        self.cop_threshold = cop_threshold
        self.seed = seed
        self.max_nfev = max_nfev
        self.ftol = ftol
        self.relax_range = relax_range
        self.n_jobs = n_jobs
        self.toe_range = toe_range
        self.jacobian = jacobian

    # -- setup ------------------------------------------------------------
    def _terms(self) -> tuple:
        terms = ALL_TERMS if self.terms is None else tuple(self.terms)
        bad = [x for x in terms if x not in ALL_TERMS]
        if bad or not terms:
            raise ModelError(f"ContactFit: terms must be a non-empty subset of {ALL_TERMS}, got {self.terms!r}")
        return terms

    def _validate(self):
        if self.contact not in KINDS:
            raise ModelError(f"unknown contact model '{self.contact}'; choose one of {', '.join(KINDS)}")
        if self.toe not in TOE_MODES:
            raise ModelError(f"ContactFit: toe must be one of {', '.join(map(repr, TOE_MODES))}, got {self.toe!r}")
        if not self.toe_range > 0:
            raise ModelError(f"ContactFit: toe_range must be > 0 rad (the +- bound of the toe coefficients), "
                             f"got {self.toe_range}; use toe='kinematic' to hold the toe angle fixed")
        if self.jacobian not in JACOBIANS:
            raise ModelError(f"ContactFit: jacobian must be one of {', '.join(map(repr, JACOBIANS))}, "
                             f"got {self.jacobian!r}")
        if isinstance(self.n_starts, bool) or not isinstance(self.n_starts, (int, np.integer)) or self.n_starts < 1:
            raise ModelError(f"ContactFit: n_starts must be an integer >= 1, got {self.n_starts!r}")
        if isinstance(self.window, str) and self.window != "cycle":
            raise ModelError(f"ContactFit: window must be 'cycle', None or (t0, t1) in s, got {self.window!r}")
        self._terms()

    def _contacts(self, model, ground_speed):
        cs = foot_contacts(model, self.contact, relax=self.relax, ground_speed=ground_speed)
        init = self.initial or {}
        bnds = self.bounds or {}
        for site in list(init) + list(bnds):
            if site not in SITES:
                raise ModelError(f"ContactFit: unknown site '{site}' (sites: {', '.join(SITES)})")
        known = {p.name for p in KINDS[self.contact].parameters}
        for name in self.fixed:
            if name not in known:
                raise ModelError(f"ContactFit: fixed names '{name}', which the {self.contact} contact does not "
                                 f"have (it has {', '.join(sorted(known))})")
        no_friction = "friction_force" not in self._terms()
        out = []
        for site, c in zip(SITES, cs):
            params = c.params
            bounds = {n: (-self.relax_range, self.relax_range) for n in ("dx", "dy")} if self.relax else {}
            values = {}
            for what, given, into in (("bounds", bnds, bounds), ("initial", init, values)):
                for name, x in given.get(site, {}).items():
                    if name not in params:
                        raise ModelError(f"ContactFit: {c.label} has no parameter '{name}' ({sorted(params)})")
                    into[name] = (float(x[0]), float(x[1])) if what == "bounds" else float(x)
            for name, p in params.items():
                lo, hi = bounds.get(name, (p.min, p.max))
                value = values.get(name, p.value)
                if not (lo <= value <= hi):
                    raise SolverError(
                        f"ContactFit: the initial guess {site}.{name} = {value:g} {p.unit} is outside its "
                        f"bounds [{lo:g}, {hi:g}]; widen bounds= or pass initial= inside them")
            # nothing minimised depends on the friction pair when friction is not tracked
            fixed = [n for n in params if n in self.fixed or (no_friction and n in FRICTION)]
            out.append(c.with_params(values, bounds=bounds, vary={n: False for n in fixed}))
        return out

    def _resolve_window(self, trial):
        if isinstance(self.window, str):   # "cycle"
            try:
                return stance_cycle(trial), "one cycle, toe-off to toe-off"
            except TrialError:
                return None, "whole trial (it holds fewer than two toe-offs)"
        if self.window is None:
            return None, "whole trial"
        return tuple(float(x) for x in self.window), "given"

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
        window, source = self._resolve_window(trial)
        if window is None:
            sel = np.ones(t_all.size, dtype=bool)
        else:
            t0, t1 = window
            sel = (t_all >= t0 - 1e-9) & (t_all <= t1 + 1e-9)
            if sel.sum() < 12:
                raise TrialError(f"window {window} holds {int(sel.sum())} frames; need at least 12")
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
        terms = self._terms()
        weights = np.array([1.0 if x in terms else 0.0 for x in ALL_TERMS])
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
        geom = Foot2dGeometry.from_model(model)
        prob = _Problem(t, q, v, B, dB, geom, meas, cop_mask, scale, weights, window_source=source)
        # toe angle from the kinematics (held fixed for "kinematic", the centre of the bounds for "fit")
        if self.toe != "channel":
            if self.toe == "flat":
                mtp = -np.maximum(q[:, 2], 0.0)
            else:
                mtp = toe_from_kinematics(geom, q, swing=meas[0] < SWING * scale[0])
            prob.fourier0 = np.linalg.lstsq(B, mtp, rcond=None)[0]
            if self.toe != "fit":
                q[:, 3], v[:, 3] = B @ prob.fourier0, dB @ prob.fourier0
        if self.toe != "fit":
            prob.kin = foot2d_site_kinematics(geom, q, v)
        return prob

    @property
    def _fit_toe(self) -> bool:
        return self.toe == "fit"

    # -- evaluation ---------------------------------------------------------
    def _simulate(self, prob: _Problem, contacts, fourier):
        res = _Residual(prob, contacts, fit_toe=self._fit_toe, toe_range=self.toe_range)
        return res.reaction([c.values for c in contacts], fourier if self._fit_toe else None)

    # -- fit ----------------------------------------------------------------
    def fit(self, model, trial, *, _cache=None) -> "ContactFit":
        """Identify the parameters (``model`` None: the built-in foot2d); returns self."""
        t_start = time.perf_counter()
        self._validate()
        if model is None:
            model = load_foot2d()
        if _cache is None or "problem" not in _cache:
            gs, self.ground_speed_source_ = self.ground_speed, "given"
            if gs is None:
                meta = getattr(trial, "meta", {})
                gs = float(meta.get("ground_speed", 0.0))
                self.ground_speed_source_ = ("the trial's" if "ground_speed" in meta
                                             else "none given: overground (give ground_speed for a treadmill)")
            prob = self._problem(model, trial, gs)
            if _cache is not None:
                _cache["problem"] = (prob, gs, self.ground_speed_source_)
        else:
            prob, gs, self.ground_speed_source_ = _cache["problem"]
        self.placement_ = foot_placement(trial)
        self._fit_problem(model, prob, gs, {} if _cache is None else _cache, t_start=t_start)
        return self

    def _sub(self, kind: str, relax: bool) -> "ContactFit":
        """These settings for a contained model (its own thesis initial values and bounds)."""
        names = {p.name for p in KINDS[kind].parameters}
        return self.clone().set_params(contact=kind, relax=relax, initial=None, bounds=None,
                                       fixed=[f for f in self.fixed if f in names])

    def _contained(self) -> list:
        if self.relax:
            return [(self.contact, False)]
        return [(kind, False) for kind in CONTAINS[self.contact]]

    def _fit_problem(self, model, prob: _Problem, gs: float, cache: dict, *, t_start: float | None = None):
        """Fit on a prepared problem; ``cache`` holds the nested fits already done, by (kind, relax);
        ``seconds_`` counts from ``t_start`` (default: now)."""
        t_start = time.perf_counter() if t_start is None else t_start
        self.ground_speed_ = gs
        contacts = self._contacts(model, gs)
        self._check_contact(prob, contacts)
        res = _Residual(prob, contacts, fit_toe=self._fit_toe, toe_range=self.toe_range)
        starts = [res.p0]
        labels = ["initial guess" if self.initial else f"initial guess (thesis Table {THESIS_TABLE[self.contact]})"]
        self.nested_ = {}
        self.nested_skipped_ = {}
        nested_nfev = 0
        if self.nested:
            for kind, relax in self._contained():
                if len(starts) >= self.n_starts:
                    break
                key = (kind, relax)
                name = f"{kind}{' relaxed' if relax else ''}"
                if key not in cache:
                    sub = self._sub(kind, relax)
                    sub.placement_ = getattr(self, "placement_", None)
                    try:
                        sub._fit_problem(model, prob, gs, cache)
                    except (ModelError, SolverError) as exc:   # e.g. its spheres cannot reach the ground
                        sub = exc
                    else:
                        nested_nfev += sub.nfev_
                    cache[key] = sub
                sub = cache[key]
                if isinstance(sub, Exception):
                    self.nested_skipped_[name] = str(sub)
                    continue
                self.nested_[name] = sub
                starts.append(res.start(map_values(sub, self.contact), sub.fourier_))
                how = _MAPPING[(kind, self.contact)] if kind != self.contact else "dx = dy = 0"
                labels.append(f"{name} optimum ({how})")
        rng = np.random.default_rng(self.seed)
        p0, lo, hi = res.p0, res.lo, res.hi
        n_fixed = len(starts)
        while len(starts) < self.n_starts:
            s = p0.copy()
            for j, (i, n) in enumerate(res.slots):
                if n in ("dx", "dy"):
                    s[j] = rng.uniform(lo[j], hi[j])
                elif n in _LOG_PARAMS and p0[j] > 0:
                    s[j] = p0[j] * math.exp(rng.uniform(-math.log(3), math.log(3)))
                else:
                    span = 0.25 * (abs(p0[j]) if p0[j] != 0 else res.typ[j])
                    s[j] = p0[j] + rng.uniform(-span, span)
            starts.append(np.clip(s, lo + 1e-12 * np.abs(lo), hi - 1e-12 * np.abs(hi)))
            labels.append(f"random {len(starts) - n_fixed} (seed {self.seed})")
        jac = res.jacobian if self.jacobian == "exact" else "2-point"

        def solve(p):
            try:
                return least_squares(res, np.clip(res.to_x(p), res.lo_x, res.hi_x), jac=jac,
                                     bounds=(res.lo_x, res.hi_x), method="trf",
                                     x_scale=1.0, ftol=self.ftol, xtol=1e-10, gtol=1e-10,
                                     max_nfev=self.max_nfev, diff_step=1e-6)
            except ValueError as exc:
                raise SolverError(f"ContactFit: least_squares failed: {exc}") from None

        # The linear algebra is tiny (~360 x 20): threaded BLAS only adds overhead (OpenBLAS's
        # threaded gesdd, used by 'trf', measured 40 ms per SVD vs 0.46 ms on one thread), and
        # with forked multi-start workers it oversubscribes the cores.  Forked workers inherit the limit.
        with threadpool_limits(limits=1):
            results = _map_starts(solve, starts, self.n_jobs)
        self.starts_ = [float(2 * r.cost) for r in results]
        self.start_nfev_ = [int(r.nfev) for r in results]
        self.start_labels_ = labels
        ib = int(np.argmin([r.cost if np.isfinite(r.cost) else np.inf for r in results]))
        best = results[ib]
        if not np.all(np.isfinite(best.x)) or not np.isfinite(best.cost):
            raise SolverError("ContactFit: no start produced a finite solution")
        vals, four = res.unpack(np.clip(res.to_p(best.x), res.lo, res.hi))   # rounding at a bound
        self.contacts_ = [c.with_params(v) for c, v in zip(contacts, vals)]
        self.fourier_ = four if four is not None else prob.fourier0
        self.toe_kinematic_ = prob.fourier0
        self.toe_deviation_ = (float(np.max(np.abs(prob.B @ (self.fourier_ - prob.fourier0))))
                               if self._fit_toe else 0.0)
        self.best_start_ = ib
        self.nfev_ = sum(int(r.nfev) for r in results) + nested_nfev
        self.njev_ = sum(int(r.njev or 0) for r in results)
        self.n_free_ = best.x.size
        self.problem_ = prob
        self.residual_ = res
        self.window_ = (float(prob.t[0]), float(prob.t[-1]))
        stats = self._finish(prob, best)
        self.aic_, self.bic_ = stats.aic, stats.bic
        self.seconds_ = time.perf_counter() - t_start
        gr = self.reaction_
        self.result_ = Result(prob.t, {GRF[0]: gr.normal, GRF[1]: gr.friction, GRF[2]: gr.cop[:, 0]},
                              units={GRF[0]: "N", GRF[1]: "N", GRF[2]: "m"},
                              meta={"analysis": "contact_fit", "contact": self.contact, "relax": str(bool(self.relax))},
                              stats=stats, report=self._report_text(stats))
        return self

    def _check_contact(self, prob, contacts):
        """Refuse spheres that cannot touch the ground anywhere in the window, even at their largest size."""
        kin = prob.kin
        if kin is None:
            q = prob.q.copy()
            q[:, 3] = prob.B @ prob.fourier0
            kin = foot2d_site_kinematics(prob.geom, q, prob.v)
        msgs = []
        for s, c in zip(SITES, contacts):
            P = c.params
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

    def _finish(self, prob, best) -> FitStatistics:
        """Reaction, terms, objective and RMSE of the fitted spheres; returns the fit's statistics."""
        outs, gr = self.residual_.reaction([c.values for c in self.contacts_],
                                           self.fourier_ if self._fit_toe else None)
        self.outputs_ = outs
        self.reaction_ = gr
        r = self.residual_.terms(gr)
        terms = np.sum(r ** 2, axis=1)
        self.terms_ = {name: float(x) for name, x in zip(ALL_TERMS, terms)}
        self.objective_ = float(np.dot(terms, prob.weights))
        self.objective_full_ = float(terms.sum())
        diff_n = gr.normal - prob.meas[0]
        diff_f = gr.friction - prob.meas[1]
        diff_c = (gr.cop[:, 0] - prob.meas[2])[prob.cop_mask]
        self.rmse_ = {"normal_force": float(np.sqrt(np.mean(diff_n ** 2))),
                      "friction_force": float(np.sqrt(np.mean(diff_f ** 2))),
                      "cop": float(np.sqrt(np.mean(diff_c ** 2))) if diff_c.size else float("nan")}
        # information criteria on the minimised residuals, Gaussian errors of unknown variance:
        # n ln(RSS/n) + 2k / + k ln n (pinmsk.stats; RSS floored at 1e-300 there)
        return FitStatistics(n=int(prob.t.size * np.count_nonzero(prob.weights)), k=int(self.n_free_),
                             sse=self.objective_ * prob.t.size, variance="estimated", converged=best.status > 0,
                             message=str(best.message), iterations=self.nfev_, objective=self.objective_)

    # -- results ------------------------------------------------------------
    def params_(self) -> dict:
        """``{site: {param: value}}`` of the fitted spheres."""
        return {s: dict(c.values) for s, c in zip(SITES, self.contacts_)}

    def to_dict(self) -> dict:
        """The fit as a JSON-ready dict (what ``pinmsk contact fit --json`` writes)."""
        self._check_fitted()
        return {"contact": self.contact, "relax": bool(self.relax), "toe": self.toe,
                "objective": self.objective_, "objective_full": self.objective_full_,
                "terms": self.terms_, "params": self.params_(),
                "toe_fourier": None if self.fourier_ is None else [float(x) for x in self.fourier_],
                "toe_max_deviation": self.toe_deviation_, "load_shares": self.load_shares(),
                "rmse": self.rmse_, "seconds": self.seconds_, "n_free": int(self.n_free_),
                "aic": self.aic_, "bic": self.bic_, "converged": self.result_.stats.converged,
                "nfev": int(self.nfev_), "starts": self.starts_, "start_labels": self.start_labels_,
                "best_start": self.best_start_,
                "nested": {name: f.objective_ for name, f in self.nested_.items()},
                "ground_speed": self.ground_speed_, "window": list(self.window_), "settings": self.settings_()}

    def settings_(self) -> dict:
        """The settings this fit used (what ``pinmsk contact fit`` prints): model, terms, window,
        filter, toe, foot placement, free and fixed parameters, starts."""
        free, fixed = {}, {}
        for s, c in zip(SITES, self.contacts_):
            for name, p in c.params.items():
                if p.vary:
                    free.setdefault(name, []).append(s)
                else:
                    fixed.setdefault(name, []).append(f"{s} {p.value:.4g}")
        prob = self.problem_
        return {"contact": self.contact, "relax": bool(self.relax),
                "terms": [t for t, w in zip(ALL_TERMS, prob.weights) if w],
                "window": list(self.window_), "window_source": prob.window_source, "frames": int(prob.t.size),
                "cutoff_hz": self.cutoff, "grf_filter": None, "toe": self.toe,
                "toe_fitted": self._fit_toe, "foot_placement": self.placement_,
                "ground_speed": self.ground_speed_, "ground_speed_source": self.ground_speed_source_,
                "cop_threshold": self.cop_threshold,
                "free": free, "fixed": fixed, "n_free": int(self.n_free_) + 0,
                "starts": list(self.start_labels_), "seed": self.seed, "nested": bool(self.nested),
                "jacobian": self.jacobian, "n_jobs": self.n_jobs, "max_nfev": self.max_nfev}

    def _report_text(self, stats: FitStatistics) -> str:
        rows = [("objective", f"J (Eq. 4.2) = {self.objective_:.5f} (all terms {self.objective_full_:.5f})"),
                ("rmse", f"normal {self.rmse_['normal_force']:.1f} N, friction "
                         f"{self.rmse_['friction_force']:.1f} N, COP {1000 * self.rmse_['cop']:.1f} mm"),
                ("starts", "; ".join(f"{lab} -> J {j:.5f}" for lab, j in zip(self.start_labels_, self.starts_))
                 + ("" if stats.converged else " (the best start hit max_nfev)"))]
        rows += [(s, ", ".join(f"{k}={v:.4g}" for k, v in c.values.items())) for s, c in zip(SITES, self.contacts_)]
        rows.append(("time", f"{self.seconds_:.2f} s"))
        rows += stats.rows()
        return format_report(f"Contact fit ({self.contact}{', relaxed' if self.relax else ''}) of the foot "
                             f"over {self.window_[0]:.3f}-{self.window_[1]:.3f} s", rows)

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


def _typical(p) -> float:
    """The scale of parameter ``p`` in the solver's variables (``x = value / typical``)."""
    if p.name in ("dx", "dy"):
        return 0.01
    return abs(p.value) if p.value != 0 else 1.0


#: how each contained model's optimum becomes a start of the containing model (for the labels)
_MAPPING = {("volumetric", "hypervolumetric"): "exact: H = 1, k_h = k_V, a_h = k_V a_V",
            ("point", "hypervolumetric"): "small-penetration limit",
            ("point", "volumetric"): "small-penetration limit"}


def _loaded_penetration(out) -> float:
    """The normal-force-weighted mean penetration of one sphere (m; 1 mm if it carries no load)."""
    f = np.maximum(out.normal, 0.0)
    d = np.maximum(out.penetration, 0.0)
    return float(np.sum(f * d) / np.sum(f)) if np.sum(f) > 0 and np.sum(f * d) > 0 else 1e-3


def map_values(src: "ContactFit", kind: str) -> list:
    """The fitted parameters of ``src`` expressed in contact model ``kind`` (a list of
    ``{name: value}`` per site), for starting ``kind``'s fit where ``src`` ended.

    Same model: copied (a relaxed fit starts from the fixed-centre optimum, dx = dy = 0).
    Linear volumetric -> hyper-volumetric: exact, ``f = k_V V + k_V a_V V v`` is Eq. 4.15
    with ``H = 1``, ``k_h = k_V``, ``a_h = k_V a_V``.  Point (``k_s d^n (1 + a_s v)``) ->
    sphere of radius ``R = L0``: for small penetration ``V ~ pi R d^2``, so the law is the
    point's with ``n = 2 H``; stiffness, exponent and damping are matched in value and
    log-slope at the sphere's load-weighted penetration ``d*`` (``H = n (3R - d*) / (6R - 3 d*)``,
    ``k_h = k_s d*^n / V(d*)^H``, ``a_h = k_s a_s d*^n / V(d*)``; volumetric: ``k_V = k_s d*^n / V(d*)``,
    ``a_V = a_s``).  Friction (mu_f, v_s) and the centre offsets carry over unchanged.
    """
    out = []
    for c, o in zip(src.contacts_, src.outputs_):
        v = dict(c.values)
        common = {k: v[k] for k in ("mu_f", "v_s", "dx", "dy")}
        if src.contact == kind:
            out.append(v)
        elif src.contact == "volumetric" and kind == "hypervolumetric":
            out.append({**common, "R": v["R"], "H": 1.0, "k_h": v["k_v"], "a_h": v["k_v"] * v["a_v"]})
        elif src.contact == "point" and kind in ("volumetric", "hypervolumetric"):
            R, n = v["L0"], v["n_s"]
            d = min(_loaded_penetration(o), R)
            V = float(cap_volume(d, R))
            elastic = v["k_s"] * d ** n
            if kind == "volumetric":
                out.append({**common, "R": R, "k_v": elastic / V, "a_v": v["a_s"]})
            else:
                H = n * (3 * R - d) / (6 * R - 3 * d)
                out.append({**common, "R": R, "H": H, "k_h": elastic / V ** H, "a_h": elastic * v["a_s"] / V})
        else:
            raise ModelError(f"map_values: no mapping from the {src.contact} contact to {kind}")
    return out


def foot_placement(trial) -> str:
    """Where the driving foot kinematics come from, in words (for the printed settings)."""
    meta = getattr(trial, "meta", None) or {}
    anchor = meta.get("anchor")
    if anchor == "heel":
        ox, oy = meta.get("heel_offset", (float("nan"), float("nan")))
        return (f"heel and 5th-metatarsal markers (pinmsk.io.cleveland_gait.read_csu, anchor='heel'): foot angle from the "
                f"marker line, heel site at ({1000 * ox:.1f}, {1000 * oy:.1f}) mm from the heel marker")
    if anchor == "ankle":
        return "lateral malleolus marker as the ankle (pinmsk.io.cleveland_gait.read_csu, anchor='ankle')"
    return "the trial's ankle_x, ankle_y, foot_angle channels"


def settings_lines(settings: dict) -> list[str]:
    """:meth:`ContactFit.settings_` as printable lines."""
    s = settings
    w = s["window"]
    cut = "none" if not s["cutoff_hz"] else f"{s['cutoff_hz']:g} Hz low-pass"
    toe = {"kinematic": "identified from the kinematics beforehand, held fixed",
           "fit": "Eq. 4.1 series fitted within +- toe_range of the kinematic estimate",
           "flat": "legacy: toes flat while the heel is up", "channel": "the trial's mtp channel"}[s["toe"]]

    def group(d, fmt):
        return "; ".join(fmt(k, v) for k, v in d.items()) or "none"

    free = group(s["free"], lambda k, v: k if len(v) == len(SITES) else f"{k} ({', '.join(v)})")
    fixed = group(s["fixed"], lambda k, v: f"{k} = " + ", ".join(v))
    return [f"settings: {s['contact']} contact{' (relaxed centres)' if s['relax'] else ''}, "
            f"Eq. 4.2 terms: {' + '.join(s['terms'])}",
            f"  window {w[0]:.3f}-{w[1]:.3f} s ({s['frames']} frames; {s['window_source']}); kinematics: "
            f"{cut} (GRF unfiltered); ground speed {s['ground_speed']:.3f} m/s"
            + (f" ({s['ground_speed_source']})" if s.get("ground_speed_source") else ""),
            f"  foot placement: {s['foot_placement']}",
            f"  toe angle: {toe}",
            f"  free ({s['n_free']}): {free}",
            f"  fixed: {fixed}",
            f"  starts ({len(s['starts'])}): {'; '.join(s['starts'])}; jacobian {s['jacobian']}, "
            f"{s['n_jobs']} process(es), max_nfev {s['max_nfev']}"]


def read_contact_trial(path):
    """A Trial from ``path``: a CSU leg2d text file (first line ``% TimeStamp ...``) or any file
    :func:`pinmsk.read_trial` reads (.csv/.sto/.mot)."""
    path = Path(path)
    if not path.exists():
        raise TrialError(f"trial file not found: {path}")
    with open(path, "r", errors="replace") as fh:
        first = fh.readline()
    if first.lstrip().startswith("%") and "TimeStamp" in first:
        return read_csu_foot2d(path)
    return read_trial(path)


def load_foot2d():
    """The foot2d :class:`pinmsk.Model` (4 dof: ankle_x, ankle_y, foot_angle, mtp; thesis Ch. 4):
    the built-in model ``foot2d`` (``urdf/foot2d.toml``, y up), by :func:`pinmsk.load_model`."""
    return load_model("foot2d")


def read_csu_foot2d(path, **options):
    """A CSU leg2d file (:func:`pinmsk.io.cleveland_gait.read_csu`) placed on the foot2d model.

    With ``anchor="heel"`` (the default) the foot2d ankle goes where foot2d's heel
    sphere site (Table 4.1) sits relative to the heel marker; ``options`` go to ``read_csu``.
    """
    if options.get("anchor", "heel") == "heel" and options.get("heel_site") is None:
        options["heel_site"] = Foot2dGeometry.from_model(load_foot2d()).heel[:2]
    return read_csu(path, **options)


def load_contact_model(model):
    """The model a contact fit runs on: foot2d for None or its name/files, else :func:`pinmsk.load_model`."""
    if model is None or str(model) == "foot2d" or Path(str(model)).name in ("foot2d.toml", "foot2d.urdf"):
        return load_foot2d()
    return load_model(model)


#: the contact model variants compared by the example and the diagnosis: (kind, relax)
VARIANTS = (("point", False), ("volumetric", False), ("hypervolumetric", False), ("hypervolumetric", True))


def fit_contact_models(model, trial, variants=VARIANTS, **options) -> dict:
    """``{(kind, relax): ContactFit}`` of several contact models on one trial with the same
    :class:`ContactFit` ``options``, sharing the kinematics and the nested fits: each model is
    fitted once, and serves as a start of the models that contain it (in ``variants``' order,
    simplest first, every variant after the models it contains)."""
    cache = {}
    out = {}
    for kind, relax in variants:
        if not isinstance(cache.get((kind, relax)), ContactFit):   # not fitted yet, or failed as a nested fit
            fit = ContactFit(contact=kind, relax=relax, **options).fit(model, trial, _cache=cache)
            cache[(kind, relax)] = fit
        out[(kind, relax)] = cache[(kind, relax)]
    return out


