"""Electromechanical delay: muscle force follows the measured EMG/excitation ``delay`` seconds late.

Physics: the 10-100 ms between the electrical activity recorded by EMG and
the rise of muscle force (propagation along the fibres, excitation-contraction
coupling, taking up slack in the series elastic element).  The measured
signal is shifted before it drives the muscle::

    u_muscle(t) = u_measured(t - delay)

by linear interpolation between samples (the first sample is held before the
start).  ``delay`` (s) is fitted.  In a chain with
:class:`~pinmsk.effects.activation.ActivationDynamics` the delay comes first.
Like every muscle-level effect it applies no generalized force of its own.
"""
from __future__ import annotations

import numpy as np

from ..components import Parameter
from ._base import SignalEffect
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

    def transform_batch(self, t, u, params, mask=None):
        t = np.asarray(t, dtype=float)
        u = np.asarray(u, dtype=float)
        d = np.atleast_1d(np.asarray(params["delay"], dtype=float))
        n, m = u.shape
        cols = np.arange(m) if mask is None else np.flatnonzero(mask)
        out = np.broadcast_to(u, (d.size, n, m)).copy()
        for p, dp in enumerate(d):
            tt = t - dp
            for c in cols:
                out[p, :, c] = np.interp(tt, t, u[:, c])
        return out
