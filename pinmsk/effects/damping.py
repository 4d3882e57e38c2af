"""Viscous joint damping: ``Q = -c qdot`` on one coordinate.

Physics: dissipative joint moment of soft tissue, synovial fluid and the
muscles' passive viscosity, linear in the joint velocity.  ``c`` is in
N m s/rad (N s/m for a prismatic coordinate).  The generalized force is
linear in ``c``, so the diagnosis fits it by linear least squares.
"""
from __future__ import annotations

import numpy as np

from ..components import Parameter
from ._base import JointEffect
from .registry import register


@register
class JointDamping(JointEffect):
    """Linear viscous damping ``Q_i = -c v_i`` at coordinate ``target``."""

    family = "joint_damping"
    linear = True
    parameters = (
        Parameter("c", 0.1, 0.0, 1.0e3, "N m s/rad", "viscous damping coefficient"),
    )
    #: parameter values that switch the effect off
    zero_params = {"c": 0.0}

    def _force(self, q, v, p):
        return -p["c"] * v

    def _dforce_dparams(self, q, v, p):
        return (-v)[:, None]

    def _dforce_dstate(self, q, v, p):
        return np.zeros_like(q), np.full_like(v, -p["c"])
