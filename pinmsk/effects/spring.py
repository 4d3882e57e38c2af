"""Linear joint spring with a rest angle: ``Q = -k (q - q0)``.

Physics: the linear approximation of the passive elastic moment about a rest
angle (an orthosis spring, ligament stiffness near mid-range).  ``k`` in
N m/rad, ``q0`` in rad.  The rest angle is where the spring is relaxed, so it
lies within the joint's range of motion: the diagnosis bounds it there
(:meth:`JointSpring.for_model`).  Unbounded, a weak spring with its rest angle
far outside the range (``q0 -> +-2 pi``) is a constant moment plus a small
slope -- what a sensor offset does -- and its parameters mean nothing.  ``Q``
is linear in ``(k, k q0)``; the diagnosis starts its bounded nonlinear fit of
``(k, q0)`` from that linear solution (:meth:`JointSpring.initial_guess`), so
the fit needs one or two iterations.
"""
from __future__ import annotations

import numpy as np

from ..components import Parameter
from ._base import JointEffect, bounded_to_range
from .registry import register


@register
class JointSpring(JointEffect):
    """Linear spring ``Q_i = -k (q_i - q0)`` at coordinate ``target``."""

    family = "joint_spring"
    parameters = (
        Parameter("k", 1.0, 0.0, 1.0e4, "N m/rad", "stiffness"),
        Parameter("q0", 0.0, -2 * np.pi, 2 * np.pi, "rad", "rest angle (zero force); bounded to the joint's range"),
    )
    zero_params = {"k": 0.0}
    #: parameters bounded to the target coordinate's range of motion (see :meth:`for_model`)
    range_parameters = ("q0",)

    def for_model(self, model) -> "JointSpring":
        """This spring with its rest angle ``q0`` bounded to the target coordinate's range of motion."""
        return bounded_to_range(self, model, self.range_parameters)

    def _force(self, q, v, p):
        return -p["k"] * (q - p["q0"])

    def _dforce_dparams(self, q, v, p):
        return np.column_stack([-(q - p["q0"]), np.full_like(q, p["k"])])

    def _dforce_dstate(self, q, v, p):
        return np.full_like(q, -p["k"]), np.zeros_like(v)

    def initial_guess(self, model, motion, target, cache=None) -> list[dict]:
        """Start from linear least squares of ``target ~ -k q + b`` (``b = k q0``)."""
        i = model.coordinate_index(self.target)
        y = np.asarray(target)[:, i]
        ok = np.isfinite(y)
        q = motion.q[ok, i]
        A = np.column_stack([-q, np.ones_like(q)])
        (k, b), *_ = np.linalg.lstsq(A, y[ok], rcond=None)
        lo, hi = self.bounds()
        k = float(np.clip(k, max(lo[0], 1e-9), hi[0]))
        q0 = float(np.clip(b / k, lo[1], hi[1]))
        return [{"k": k, "q0": q0}]
