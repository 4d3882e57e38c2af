"""Coulomb joint friction, smoothed: ``Q = -F_c tanh(qdot / v_s)``.

Physics: a velocity-independent friction moment opposing motion (dry
friction of an orthosis, a dynamometer bearing or a cable), made smooth by a
``tanh`` so that simulation and fitting stay differentiable.  ``v_s`` is *not*
fitted: it is fixed at :attr:`CoulombFriction.velocity_scale` = 0.01 rad/s
(m/s), small against the speeds of human movement (0.5-10 rad/s), so the
force reaches 96 % of ``F_c`` at 0.02 rad/s.  Fitting ``v_s`` as well would
trade it against noise in the estimated speed near reversals, where the data
carry almost no information about it.  Linear in ``F_c``.
"""
from __future__ import annotations

import numpy as np

from ..backend import backend_of
from ..components import Parameter
from ._base import JointEffect
from .registry import register


@register
class CoulombFriction(JointEffect):
    """Smoothed Coulomb friction ``Q_i = -F_c tanh(v_i / v_s)``, ``v_s = 0.01`` rad/s fixed."""

    family = "coulomb_friction"
    linear = True
    #: fixed smoothing speed v_s (rad/s or m/s)
    velocity_scale = 0.01
    parameters = (
        Parameter("F_c", 0.1, 0.0, 1.0e3, "N m", "Coulomb friction moment"),
    )
    zero_params = {"F_c": 0.0}

    def _force(self, q, v, p):
        return -p["F_c"] * backend_of(v).tanh(v / self.velocity_scale)

    def _dforce_dparams(self, q, v, p):
        return (-np.tanh(v / self.velocity_scale))[:, None]

    def _dforce_dstate(self, q, v, p):
        s = self.velocity_scale
        return np.zeros_like(q), -p["F_c"] / s / np.cosh(v / s) ** 2
