"""Ranking candidates: one ranked entry, the order by BIC, and the worst windows of a residual.

Shared by the effect ranking (:mod:`pinmsk.diagnose.diagnosis`) and the contact
ranking (:mod:`pinmsk.diagnose.contact`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..components import Component
from ..errors import TrialError
from ..fitting import Result
from ..signals.sampling import median_step
from .fit import describe_fit

__all__ = ["EffectScore", "finite_or_none", "order_by_bic", "windows_of"]


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
        }


def finite_or_none(x):
    """``float(x)``, or None where it is not finite (JSON has no NaN)."""
    x = float(x)
    return x if np.isfinite(x) else None


def windows_of(t, res, channels, floor: dict, window: float, k: int = 5, mask=None) -> list:
    """The ``k`` (channel, time window) pairs with the largest RMS residual / noise floor."""
    dur = t[-1] - t[0]
    if dur / window < 3:
        window = dur / 5
    dt = median_step(t)
    if window / dt < 10:
        raise TrialError(
            f"windows of {window:.3g} s hold {window / dt:.1f} samples at {1 / dt:.4g} Hz; need at least 10 "
            "per window: pass a longer window= or a longer, denser trial"
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
