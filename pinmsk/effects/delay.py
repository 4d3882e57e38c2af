"""Electromechanical delay: muscle force follows the measured EMG/excitation ``delay`` seconds late.

Physics: the 10-100 ms between the electrical activity recorded by EMG and
the rise of muscle force (propagation along the fibers, excitation-contraction
coupling, taking up slack in the series elastic element).  The measured
signal is shifted before it drives the muscle::

    u_muscle(t) = u_measured(t - delay)

by band-limited (Fourier) interpolation: the shift is the all-pass filter
``exp(-i omega delay)`` applied by FFT, after bridging the two ends of the
record smoothly (a half-cosine over ``delay_max`` on each side) so that the
circular shift neither wraps nor rings; before the start the first sample is
held.  Unlike linear interpolation, which averages two samples and so halves
the variance of white noise at half-sample delays, the all-pass shift keeps
the noise level for every delay -- otherwise noisy EMG biases the fitted
delay towards half samples.  ``delay`` (s) is fitted.  In a chain with
:class:`~pinmsk.effects.activation.ActivationDynamics` the delay comes first.
Like every muscle-level effect it applies no generalized force of its own.
"""
from __future__ import annotations

import threading

import numpy as np

from ..components import Parameter
from ..signals.sampling import median_step
from ._base import SignalEffect, signal_parts
from .registry import register


@register
class ElectromechanicalDelay(SignalEffect):
    """Pure delay ``u(t - delay)`` of the measured excitations."""

    family = "electromechanical_delay"
    order = 0
    parameters = (
        Parameter("delay", 0.04, 0.0, 0.25, "s", "delay from EMG/excitation to muscle activation"),
    )
    zero_params = {"delay": 0.0}

    @classmethod
    def candidates(cls, model, context):
        """One candidate for all muscles in a muscle-level comparison, unless the model has a delay already."""
        if context.mode != "muscle" or model.muscles is None:
            return []
        return [] if any(isinstance(p, cls) for p in signal_parts(model)) else [cls("muscles")]

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("_spectrum", None)
        return state

    def _spectrum_memo(self) -> threading.local:
        """The last signal's spectrum, per thread (a memo, not state: the effect stays immutable)."""
        memo = self.__dict__.get("_spectrum")
        if memo is None:
            memo = self.__dict__.setdefault("_spectrum", threading.local())
        return memo

    def transform_batch(self, t, u, params, mask=None):
        """Delayed signals for P delays; ``u`` is (N, m), or (P, N, m) for one signal per delay."""
        t = np.asarray(t, dtype=float)
        u = np.asarray(u, dtype=float)
        (d,), ub, cols, out = self.broadcast_batch(u, mask, params["delay"])
        n = ub.shape[1]
        if n < 2 or cols.size == 0:
            return out
        dt = median_step(t)
        pad = int(np.ceil(self.params["delay"].max / dt)) + 8
        key = (id(u), u.shape, float(u.flat[0]), float(u.flat[-1]), pad, tuple(cols))
        memo = self._spectrum_memo()
        cached = getattr(memo, "value", None)
        if cached is not None and cached[0] == key:
            spec, L = cached[1:]                          # same signal, other delays: reuse its FFT
        else:
            x = (u if u.ndim == 3 else u[None])[:, :, cols]                  # (P or 1, N, k)
            s = (np.arange(1, 2 * pad + 1) / (2 * pad + 1))[None, :, None]
            bridge = x[:, -1:] + (x[:, :1] - x[:, -1:]) * 0.5 * (1 - np.cos(np.pi * s))
            ext = np.concatenate([x, bridge], axis=1)                        # circular: bridge also precedes x
            L = ext.shape[1]
            spec = np.fft.rfft(ext, axis=1)
            memo.value = (key, spec, L) if u.ndim == 2 else None
        omega = 2 * np.pi * np.fft.rfftfreq(L, dt)
        shift = np.exp(-1j * omega[None, :] * d[:, None])                   # (P, F)
        y = np.fft.irfft(spec * shift[:, :, None], n=L, axis=1)
        out[:, :, cols] = y[:, :n]
        return out
