"""Measurement effects: a recorded generalized-force channel that is biased or mis-scaled.

A dynamometer, an instrumented orthosis or an inverse-dynamics pipeline of
another lab records ``<coord>_moment``; its zero drifts (an offset) and its
calibration is off by a few per cent (a gain).  In real data these are as
common as missing physics, and a flexible physical candidate absorbs them when
the catalog lacks them (a constant moment is not a passive elastic moment).

With ``tau`` the actuator's true generalized force and ``m`` the recording,
the sensor reads ``m = g tau + b``:

* :class:`SensorGain` (``sensor_gain``): ``m = g tau`` (``g = 1``: calibrated);
* :class:`SensorOffset` (``sensor_offset``): ``m = tau + b`` (``b = 0``: zeroed);

applied in that order (:attr:`MeasurementEffect.order`), so a gain and an
offset on one channel are ``g tau + b`` and enter a fit additively.

A measurement effect is no force on the skeleton (its ``generalized_force``
is zero, as a muscle-level :class:`~pinmsk.effects.SignalEffect`'s is): it is
the model of the sensor.  Inverse dynamics still gives the actuator's ``tau``;
the diagnosis compares the recording with the model's *reading*
``measure(tau_ID)`` -- the model side, so the recording's noise keeps its
level and a gain cannot win by shrinking it, as dividing the noisy
recording by ``g`` would -- and forward dynamics driven by a recording
(:func:`pinmsk.dynamics.simulate` with a moments Trial) takes the true drive
``unmeasure(m) = (m - b) / g``.

On a model of one rigid body (``forearm``, ``finger``) a gain error and a
``segment_mass`` error change the modelled reading identically (both scale
the whole inverse dynamics): the diagnosis reports them as aliases, which no
recording of that channel can tell apart.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ..components import Component, Motion, Parameter, state_vector
from ..trial import moment_channel
from .registry import register

__all__ = ["MeasurementEffect", "SensorGain", "SensorOffset"]


class MeasurementEffect(Component):
    """The model of the sensor recording ``<target>_moment``: true value -> reading.

    Subclasses implement :meth:`measure`, :meth:`unmeasure` (reading -> true
    value) and :meth:`measure_jacobian` (``d reading / d theta``).  ``order`` is
    the place in the sensor's chain on one channel (gain before offset).
    """

    kind = "effect"
    level = "sensor"
    target_kind = "coordinate"
    order: int = 0

    @property
    def channel(self) -> str:
        """The recorded channel this effect describes."""
        return moment_channel(self.target)

    def affected_coordinates(self) -> tuple[str, ...]:
        """The coordinate whose recorded generalized force this effect changes."""
        return (self.target,)

    @classmethod
    def candidates(cls, model, context) -> list:
        """One per compared, actuated coordinate whose recorded ``<coord>_moment`` the comparison uses."""
        if context.mode not in ("torque", "motion"):
            return []
        return [cls(c) for c in context.coordinates if c not in context.unactuated]

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        return np.zeros((motion.n_frames, model.nv))

    def generalized_force_at(self, model, q, v):
        """Zero ``(nv,)`` (numpy or CasADi, as ``q``): a measurement effect is no force on the skeleton."""
        return state_vector(model.nv, {}, like=q)

    def state_derivatives(self, model, motion: Motion, params=None, cache=None):
        """Zero: no force, so no dependence on the state."""
        dq = np.zeros((motion.n_frames, model.nv, model.nv))
        return dq, dq.copy()

    def measure(self, actual, params=None) -> np.ndarray:  # pragma: no cover - abstract
        """The reading ``(N,)`` of the sensor for the true values ``actual`` ``(N,)``."""
        raise NotImplementedError

    def unmeasure(self, reading, params=None) -> np.ndarray:  # pragma: no cover - abstract
        """The true values ``(N,)`` behind the reading ``reading`` ``(N,)``."""
        raise NotImplementedError

    def measure_jacobian(self, actual, params=None) -> np.ndarray:  # pragma: no cover - abstract
        """``d measure / d theta`` ``(N, n_params)`` in declaration order."""
        raise NotImplementedError


@register
class SensorGain(MeasurementEffect):
    """Gain ``g`` of the recorded ``<target>_moment``: the reading is ``g tau``."""

    family = "sensor_gain"
    order = 0
    parameters = (
        Parameter("gain", 1.05, 0.5, 2.0, "", "reading / true value (1 = calibrated)"),
    )
    zero_params = {"gain": 1.0}

    def measure(self, actual, params=None):
        return self._p(params)["gain"] * np.asarray(actual, dtype=float)

    def unmeasure(self, reading, params=None):
        return np.asarray(reading, dtype=float) / self._p(params)["gain"]

    def measure_jacobian(self, actual, params=None):
        return np.asarray(actual, dtype=float)[:, None]


@register
class SensorOffset(MeasurementEffect):
    """Constant bias ``b`` of the recorded ``<target>_moment``: the reading is ``tau + b``."""

    family = "sensor_offset"
    order = 1
    linear = True
    parameters = (
        Parameter("offset", 0.1, -1.0e3, 1.0e3, "N m", "bias of the recorded channel (reading - true)"),
    )
    zero_params = {"offset": 0.0}

    def measure(self, actual, params=None):
        return np.asarray(actual, dtype=float) + self._p(params)["offset"]

    def unmeasure(self, reading, params=None):
        return np.asarray(reading, dtype=float) - self._p(params)["offset"]

    def measure_jacobian(self, actual, params=None):
        return np.ones((np.size(actual), 1))


def sensors_of(model) -> list:
    """The model's measurement effects, in chain order."""
    return sorted([c for c in model.components if isinstance(c, MeasurementEffect)], key=lambda c: c.order)


def apply_sensors(model, coordinates, tau: np.ndarray, *, inverse: bool = False) -> np.ndarray:
    """``tau`` ``(N, len(coordinates))`` as the model's sensors read it (``inverse``: the true values behind
    a reading); columns without a sensor unchanged."""
    sensors = sensors_of(model)
    if not sensors:
        return tau
    out = np.array(tau, dtype=float, copy=True)
    index = {c: j for j, c in enumerate(coordinates)}
    for s in (reversed(sensors) if inverse else sensors):
        j = index.get(s.target)
        if j is not None:
            out[:, j] = s.unmeasure(out[:, j]) if inverse else s.measure(out[:, j])
    return out
