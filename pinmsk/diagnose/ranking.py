"""Ranking candidates: one ranked entry, the held-out test, the order by BIC, and the worst windows.

Shared by the effect ranking (:mod:`pinmsk.diagnose.diagnosis`) and the contact
ranking (:mod:`pinmsk.diagnose.contact`).

:func:`held_out_test` is the significance test of the effect ranking, a test
of equal predictive accuracy on held-out data in the manner of Diebold &
Mariano (1995).  With ``r0`` and ``r1`` the noise-whitened held-out residuals
without and with the candidate and ``d = r0 - r1`` the change the
candidate's out-of-sample fit makes, the per-frame loss differential is
``r0^2 - r1^2 = d^2 + 2 r1 d``: ``D``, its mean, is the held-out improvement
per frame (in noise variances).  Given the fitted change ``d``, the noise
enters only through ``2 r1 d``; its variance is that of the noise projected on
``d``, ``4 sum_j w_j sum_cc' Gamma_cc'(j) A_cc'(j)``, with ``Gamma`` the
auto- and cross-covariances of the held-out residual ``r1`` (the noise, when the
candidate explains the rest), ``A_cc'(j) = sum_k d_kc d_(k+j)c'`` and Bartlett
weights ``w_j = 1 - |j| / (L + 1)`` up to the bandwidth of Andrews (1991) for
an AR(1) plug-in (``L = 1.1447 (a n)^(1/3)``, ``a = 4 rho^2 / ((1 - rho)^2 (1 +
rho)^2)``, ``rho`` the lag-1 autocorrelation of ``r1``): the residuals of
filtered kinematics and slow disturbances are strongly autocorrelated, and a
test that took the frames as independent would find structure in every slow
wiggle.  ``z = D / se``.  The plain Diebold-Mariano test takes the variance of
the whole differential instead, which counts the effect's own envelope
(``d^2``, large near the ends of the range for a passive moment) as noise and
misses effects that act in a few excursions; a residual ``r1`` that still holds
a slow disturbance has a long bandwidth and a large variance, so a chance fit to
it is not significant.  Under the null the out-of-sample change is fitted
noise, independent of the held-out noise, and ``E[D] = -E[d^2] < 0``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..components import Component
from ..errors import TrialError
from ..fitting import Result
from ..signals.sampling import median_step
from .fit import describe_fit

__all__ = ["EffectScore", "finite_or_none", "held_out_test", "order_by_bic", "windows_of"]


@dataclass
class EffectScore:
    """One ranked candidate: its fit (a :class:`~pinmsk.fitting.Result`, as
    :class:`~pinmsk.diagnose.fit.EffectFit` gives) and how much it explains out of sample."""

    fit: Result
    rmse_after: dict
    explained_fraction: float
    improvement: float
    significant: bool
    converged: bool
    note: str = ""
    #: the held-out test (:func:`held_out_test`) against the model as it is (earlier effects refitted)
    test: dict = field(default_factory=dict)
    #: rank and condition number of the sensitivity matrix, profile intervals, flags
    identifiability: dict = field(default_factory=dict)
    #: how the earlier effects' parameters move when this candidate joins them (None at the first step)
    refit: dict | None = None
    #: every component of the joint fit (earlier effects refitted, this candidate last)
    components: list = field(default_factory=list)
    #: candidates that explain the same on this trial (label, correlation of the fitted changes)
    aliases: list = field(default_factory=list)
    #: the held-out equation error (n, C) with this candidate, and the joint fit's stacked parameters
    heldout: np.ndarray | None = field(default=None, repr=False, compare=False)
    x: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def identifiable(self) -> bool:
        """False when a parameter sits at a bound or the data do not determine it (never suggested)."""
        return bool(self.identifiability.get("identifiable", True))

    @property
    def flags(self) -> list:
        return list(self.identifiability.get("flags", []))

    @property
    def effect(self) -> Component:
        """The fitted component (add it with ``model.with_effect(score.effect)``)."""
        return self.fit.effect

    @property
    def family(self) -> str:
        return self.effect.family

    @property
    def target(self) -> str | None:
        return self.effect.target

    @property
    def label(self) -> str:
        return self.effect.label

    @property
    def params(self) -> dict:
        return dict(self.fit.params)

    @property
    def stderr(self) -> dict:
        return dict(self.fit.stderr)

    def describe_params(self) -> str:
        """``name = value ± stderr unit, ...`` of the fitted parameters."""
        return describe_fit(self.fit)

    def to_dict(self) -> dict:
        """The entry as a JSON-ready dict (one element of the diagnosis JSON's ``ranking``)."""
        return {
            "effect": self.family, "target": self.target,
            "params": {k: float(v) for k, v in self.params.items()},
            "rmse_after": {k: float(v) for k, v in self.rmse_after.items()},
            "explained_fraction": float(self.explained_fraction),
            "significant": bool(self.significant),
            "stderr": {k: finite_or_none(v) for k, v in self.stderr.items()},
            **({"bic_change": float(self.fit.stats.bic_change), "n_params": int(self.fit.stats.k),
                "worst_windows": [dict(w) for w in getattr(self, "worst_windows", [])]}
               if getattr(self.effect, "kind", None) == "contact" else {}),
            **({"held_out_test": _json(self.test)} if self.test else {}),
            **({"identifiability": _json(self.identifiability)} if self.identifiability else {}),
            **({"refit": _json(self.refit)} if self.refit else {}),
            **({"aliases": [{"effect": a, "correlation": finite_or_none(r)} for a, r in self.aliases]}
               if self.aliases else {}),
        }


def finite_or_none(x):
    """``float(x)``, or None where it is not finite (JSON has no NaN)."""
    x = float(x)
    return x if np.isfinite(x) else None


def _json(x):
    """``x`` with numpy scalars as Python numbers and non-finite floats as None (JSON-ready)."""
    if isinstance(x, dict):
        return {str(k): _json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return finite_or_none(x)
    return x


def held_out_test(r0: np.ndarray, r1: np.ndarray, *, offset: float = 0.0) -> dict:
    """Held-out accuracy of ``r1`` against ``r0`` (whitened residuals ``(n, C)``, each predicted out of
    sample; see the module notes).

    ``offset`` (noise variances per channel and frame) is subtracted from the improvement: the part of the
    fall that is no physics (a muscle-level effect also filters the noise).  Returns ``{"improvement": D,
    "stderr": se(D), "z": D / se, "bandwidth": L, "frames": n}``.
    """
    r0 = np.asarray(r0, dtype=float).reshape(len(r0), -1)
    r1 = np.asarray(r1, dtype=float).reshape(len(r1), -1)
    n, C = r0.shape
    mean = float(np.mean(r0 ** 2 - r1 ** 2)) - offset
    d = r0 - r1
    # only the channels the candidate changes carry its noise term (a joint effect: one channel)
    act = np.flatnonzero(np.any(d != 0.0, axis=0))
    if act.size == 0:
        return {"improvement": mean, "stderr": 0.0, "z": 0.0 if mean <= 0 else float("inf"), "bandwidth": 0,
                "frames": n}
    d = d[:, act]
    res = r1[:, act] - r1[:, act].mean(axis=0)
    g0 = float(np.sum(res * res))
    rho = float(np.clip(np.sum(res[1:] * res[:-1]) / g0, 0.0, 0.995)) if g0 > 0 else 0.0
    a = 4 * rho ** 2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    L = int(min(max(np.ceil(1.1447 * (a * n) ** (1 / 3)), 1), n // 4)) if n >= 4 else 0
    m = 1 << int(np.ceil(np.log2(2 * max(n, 1))))
    fr = np.fft.rfft(res, m, axis=0)                       # (F, C)
    fd = np.fft.rfft(d, m, axis=0)
    # lags -L..L of Gamma_cc'(j) = sum_k r_kc r_(k+j)c' / n and A_cc'(j) = sum_k d_kc d_(k+j)c'
    G = np.fft.irfft(np.conj(fr)[:, :, None] * fr[:, None, :], m, axis=0) / n
    A = np.fft.irfft(np.conj(fd)[:, :, None] * fd[:, None, :], m, axis=0)
    lags = np.r_[0:L + 1, m - L:m] if L > 0 else np.array([0])
    w = 1.0 - np.abs(np.r_[0:L + 1, -L:0] if L > 0 else np.array([0])) / (L + 1)
    var = 4.0 * float(np.sum(w[:, None, None] * G[lags] * A[lags]))
    var = max(var, 4.0 * float(np.sum(G[0] * A[0])) / max(n, 1), 0.0)
    se = float(np.sqrt(var)) / (n * C) if n else 0.0
    if se <= 0:
        return {"improvement": mean, "stderr": 0.0, "z": float("inf") if mean > 0 else 0.0, "bandwidth": L,
                "frames": n}
    return {"improvement": mean, "stderr": se, "z": mean / se, "bandwidth": L, "frames": n}


def windows_of(t, res, channels, floor: dict, window: float, k: int = 5, mask=None) -> list:
    """The ``k`` (channel, time window) pairs with the largest RMS residual / noise floor."""
    dur = t[-1] - t[0]
    dt = median_step(t)
    if dur / window < 3:
        window = max(dur / 5, 10 * dt)       # a short trial: five windows, each of 10 samples at least
    if window / dt < 10:
        raise TrialError(
            f"windows of {window:.3g} s hold {window / dt:.1f} samples at {1 / dt:.4g} Hz; need at least 10 "
            "per window: pass a longer window (--window S; window= in Python) or a longer, denser trial"
        )
    out = []
    starts = np.arange(t[0], t[-1] - 0.5 * window, window)
    for a in starts:
        sel = (t >= a) & (t < a + window)
        if sel.sum() < 5:
            continue
        if mask is None:
            r = np.sqrt(np.mean(res[sel] ** 2, axis=0))
        else:
            m = mask[sel]
            r = np.sqrt(np.sum(np.where(m, res[sel] ** 2, 0.0), axis=0) / np.maximum(m.sum(axis=0), 1))
            r = np.where(m.sum(axis=0) >= 3, r, 0.0)
        for ch, v in zip(channels, r):
            out.append({"channel": ch, "start": float(a), "end": float(min(a + window, t[-1])),
                        "rmse": float(v)})
    out.sort(key=lambda w: -w["rmse"] / floor[w["channel"]])
    return out[:k]


def order_by_bic(ranking: list) -> list:
    """Converged first, then lowest BIC (largest fall of BIC against the model as given)."""
    return sorted(ranking, key=lambda s: (not s.converged, s.fit.stats.bic_change))
