"""First-order activation dynamics between measured excitation and muscle activation (thesis Eq. A.2).

Physics: the calcium kinetics between neural excitation ``u`` (or the
normalised EMG envelope standing in for it) and muscle activation ``a``,
Winters & Stark (thesis App. A.2, Eq. A.2-A.4)::

    adot = (u - a)(t1 u + t2)   if u >= a   (activation)
    adot = (u - a) t2           if u <  a   (deactivation)
    t2 = 1 / tau_fall,  t1 = 1 / tau_rise - t2

A model without this effect takes the measured signal as the activation
(``a = u``).  Both time constants are fitted (the thesis uses 11 ms and
68 ms).  ``t1 u + t2 = u / tau_rise + (1 - u) / tau_fall > 0`` for ``0 <= u <= 1``,
so any positive pair is admissible.  Integration: on each sample interval the
excitation is replaced by the mean of its two samples and Eq. A.2 is solved
exactly for it (an exponential step; the scheme of
:func:`pinmsk.muscles.activation.activation_from_excitation`), second-order
accurate and unconditionally stable; ``a(t_0) = u(t_0)``.  The recurrence is
vectorised over muscles and over parameter sets, so a fitter evaluates a
whole finite-difference stencil in one pass.

The effect applies no generalized force to the skeleton: it acts through the
muscle forces ``F = a F_active + F_passive`` wherever those are computed from
measured excitations.
"""
from __future__ import annotations

import numpy as np

from ..components import Parameter
from ._base import SignalEffect
from .registry import register


@register
class ActivationDynamics(SignalEffect):
    """Winters & Stark first-order activation dynamics with fitted ``tau_rise``, ``tau_fall``."""

    family = "activation_dynamics"
    order = 10
    parameters = (
        Parameter("tau_rise", 0.011, 0.001, 0.3, "s", "activation time constant"),
        Parameter("tau_fall", 0.068, 0.002, 0.6, "s", "deactivation time constant"),
    )
    zero_params = None     # there is no parameter value that removes the lag

    def transform_batch(self, t, u, params, mask=None):
        """Activations for P parameter sets; ``u`` is (N, m), or (P, N, m) for one signal per set."""
        t = np.asarray(t, dtype=float)
        u = np.asarray(u, dtype=float)
        (tr, tf), ub, cols, out = self.broadcast_batch(u, mask, params["tau_rise"], params["tau_fall"])
        n = ub.shape[1]
        if n < 2 or cols.size == 0:
            return out
        us = np.ascontiguousarray(np.moveaxis(ub[:, :, cols], 1, 0))         # (N, P, k)
        t2 = (1.0 / tf)[:, None]
        t1 = (1.0 / tr)[:, None] - t2
        h = np.diff(t)[:, None, None]
        um = 0.5 * (us[1:] + us[:-1])                                          # (N-1, P, k)
        e_rise = np.exp(-(t1 * um + t2) * h)
        e_fall = np.exp(-t2 * h) * np.ones_like(um)
        a = np.empty_like(us)
        prev = us[0].copy()
        a[0] = prev
        d = np.empty_like(prev)
        for k in range(n - 1):
            np.subtract(um[k], prev, out=d)
            prev = um[k] - d * np.where(d >= 0.0, e_rise[k], e_fall[k])
            a[k + 1] = prev
        out[:, :, cols] = np.moveaxis(a, 0, 1)
        return out
