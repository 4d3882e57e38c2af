"""What a comparison of a model with a measurement is: the noise floor and the Comparison.

The types every level of the diagnosis shares (torque, motion, muscle and
contact comparisons make a :class:`Comparison`; the ranking reads it).  The
comparisons themselves are :mod:`pinmsk.diagnose.compare` and
:mod:`pinmsk.diagnose.contact`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from ..kinematics import TrialInputs
from ..trial import Trial

__all__ = ["NoiseFloor", "Comparison", "white_noise_sigma"]


@dataclass(frozen=True)
class NoiseFloor:
    """Per-channel noise floor ``sigma`` (same units as the channel) and how it was estimated.

    ``white`` is the part from the directly measured channels (moments, GRF,
    EMG), ``propagated`` the part from the angles; ``models`` the noise models
    used (:class:`pinmsk.signals.noise.NoiseModel` per source group, see
    :mod:`pinmsk.diagnose.noise`), ``fits`` those fitted to the trial before
    any correction (reused for another model of the same trial), ``info`` the
    JSON-ready description (:meth:`to_json`).
    """

    channels: tuple[str, ...]
    sigma: np.ndarray
    white: np.ndarray
    propagated: np.ndarray
    method: str
    models: Mapping = field(default_factory=dict, repr=False, compare=False)
    fits: Mapping | None = field(default=None, repr=False, compare=False)
    info: Mapping | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict[str, float]:
        """``{channel: sigma, ..., "total": RMS of the sigmas}``, JSON-ready."""
        out = {c: float(s) for c, s in zip(self.channels, self.sigma)}
        out["total"] = float(np.sqrt(np.mean(self.sigma ** 2)))
        return out

    def to_json(self) -> dict:
        """How the floor was made, JSON-ready (the diagnosis JSON's ``noise_model``): ``method`` (text),
        and for propagated floors ``band_start_hz``, ``realisations``, the ``sources`` with their fitted
        spectra, the per-channel ``kinematic`` and ``direct`` parts and any ``band_correction``."""
        out = {"description": self.method}
        out.update(self.info or {"method": "white noise and propagated angle noise",
                                 "direct": {c: float(v) for c, v in zip(self.channels, self.white)},
                                 "kinematic": {c: float(v) for c, v in zip(self.channels, self.propagated)}})
        return out


def white_noise_sigma(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """White-noise standard deviation of ``x`` from third differences (robust to steps and spikes)."""
    x = np.asarray(x, dtype=float)
    d = np.diff(x, n=3, axis=axis) / np.sqrt(20.0)
    med = np.median(d, axis=axis, keepdims=True)
    mad = 1.4826 * np.median(np.abs(d - med), axis=axis, keepdims=True)
    keep = np.abs(d - med) <= 5.0 * np.maximum(mad, 1e-300)
    ss = np.sum(np.where(keep, d * d, 0.0), axis=axis)
    n = np.maximum(np.sum(keep, axis=axis), 1)
    return np.sqrt(ss / n)


@dataclass
class Comparison:
    """Model against measurement on named channels, over the analysed frames.

    ``measured``, ``modelled`` and ``residual = measured - modelled`` are
    ``(n, C)`` over ``time`` (the analysed frames); ``noise`` the per-channel
    noise floor; ``eq`` the equation error effects are fitted to.
    """

    mode: str
    model: object
    trial: Trial
    cutoff: float | None
    time: np.ndarray
    channels: tuple[str, ...]
    coordinates: tuple[str, ...]
    measured: np.ndarray
    modelled: np.ndarray
    noise: NoiseFloor
    eq: object                              # the equation error effects are fitted to
    states: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    eq_noise: NoiseFloor | None = None
    mask: np.ndarray | None = None          # (n, C) frames where a channel is defined (contact: the COP)
    inputs: TrialInputs | None = None        # the filtered motion and loads (what was applied)
    #: ``remake(comparison, model)``: the same comparison for another model (set by its maker)
    remake: Callable | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if self.eq_noise is None:
            self.eq_noise = self.noise

    @property
    def residual(self) -> np.ndarray:
        return self.measured - self.modelled

    def _channel_rms(self) -> np.ndarray:
        if self.mask is None:
            return np.sqrt(np.mean(self.residual ** 2, axis=0))
        r2 = np.where(self.mask, self.residual ** 2, 0.0)
        return np.sqrt(np.sum(r2, axis=0) / np.maximum(self.mask.sum(axis=0), 1))

    def rmse(self) -> dict[str, float]:
        r = self._channel_rms()
        out = {c: float(v) for c, v in zip(self.channels, r)}
        out["total"] = float(np.sqrt(np.mean(r ** 2)))
        return out

    def ratio(self) -> float:
        """RMS over channels of ``rmse / noise floor`` (1 = at the floor)."""
        r = self._channel_rms()
        return float(np.sqrt(np.mean((r / self.noise.sigma) ** 2)))

    def with_model(self, model) -> "Comparison":
        """The same comparison (frames, noise floor) for another model, e.g. with an effect added."""
        return self.remake(self, model)
