"""Desired motions ``q_d(t)`` with analytic derivatives, numpy or CasADi (the tracked coordinates).

Moved here from the replaced single-shooting engine; the closed forms are written
against :mod:`pinmsk.backend`, so a free final time (a symbolic ``t``) works too.
"""
from __future__ import annotations

import numpy as np

from ...backend import backend_of
from ...errors import ModelError
from ._values import ValueEq

__all__ = ["Target"]


class Target(ValueEq):
    """A desired motion ``q_d(t)`` with analytic time derivatives.

    ``kind="sine"``: ``offset + amplitude sin(2 pi frequency t + phase)`` (thesis Eq. 3.1);
    ``kind="cycle"``: ``offset + amplitude (1 - cos(2 pi t / period)) / 2`` (a
    flexion-extension cycle starting and ending at ``offset``, Sec. 3.3.2);
    ``kind="samples"``: a quintic spline through ``(time, values)`` (numeric times only).
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
            if tt.size < 6:
                raise ModelError(f"a sampled target needs at least 6 samples, got {tt.size}")
            self._spl = make_interp_spline(tt - tt[0], np.asarray(values, dtype=float), k=5)
            self.period = float(tt[-1] - tt[0])
            self.frequency = 1.0 / self.period
        else:
            raise ModelError(f"unknown motion kind '{kind}'; valid: sine, cycle, samples")

    def __call__(self, t, deriv: int = 0):
        xp = backend_of(t)
        if self.kind == "samples":
            if xp.symbolic:
                raise ModelError("a sampled target needs fixed times (no free final time)")
            return self._spl(np.asarray(t, dtype=float), nu=deriv)
        t = xp.asarray(t)
        if self.kind == "sine":
            w = 2 * np.pi * self.frequency
            y = self.amplitude * w ** deriv * xp.sin(w * t + self.phase + deriv * np.pi / 2)
            return y + (self.offset if deriv == 0 else 0.0)
        w = 2 * np.pi / self.period
        if deriv == 0:
            return self.offset + 0.5 * self.amplitude * (1 - xp.cos(w * t))
        return -0.5 * self.amplitude * w ** deriv * xp.cos(w * t + deriv * np.pi / 2)

    def peak_square(self, t) -> float:
        """``max q_d^2`` over the numeric times ``t`` (the normalizer of the tracking term, Eq. 3.3)."""
        return float(np.max(np.asarray(self(np.asarray(t, dtype=float))) ** 2))

    def describe(self) -> dict:
        d = {"kind": self.kind, "period": self.period}
        if self.kind != "samples":
            d.update(amplitude=self.amplitude, offset=self.offset, phase=self.phase)
        return d
