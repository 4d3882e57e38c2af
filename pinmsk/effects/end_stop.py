"""One-sided passive end stops: OpenSim's ``CoordinateLimitForce`` acting at one limit of a coordinate.

OpenSim's ``CoordinateLimitForce`` (``OpenSim/Simulation/Model/CoordinateLimitForce.cpp``,
``calcLimitForce``) applies, beyond an upper limit ``q_up`` and below a lower limit ``q_lo``, a
spring whose stiffness rises from zero to ``K`` over a ``transition`` through Simbody's smooth
step ``S(x) = 10 x^3 - 15 x^4 + 6 x^5`` (``x`` clamped to [0, 1]), with a damping switched on by
the same step::

    upper:  Q = -K S((q - q_up) / d) (q - q_up) - c S((q - q_up) / d) qdot
    lower:  Q = -K S((q_lo - q) / d) (q - q_lo) - c S((q_lo - q) / d) qdot

(OpenSim writes the lower one ``K_low (q_lo - q)``; the damping term is
``-damping (K_up/K_up_max + K_low/K_low_max) qdot``, the sum of the two steps.)  Its
usual use is one stop at one end of the range (a hyper-extension stop at the elbow or the
knee), so the diagnosis offers the two sides as separate candidates:
:class:`EndStopUpper` (``end_stop_upper``) and :class:`EndStopLower` (``end_stop_lower``),
each with the parameters of one side only -- no unused branch that a fit leaves at a bound.

Parameters (SI inside; OpenSim's file gives stiffness in N m/deg, limit and transition in deg
and damping in N m s/deg for a rotational coordinate, :meth:`EndStop.from_opensim` converts):

* ``stiffness`` ``K`` (N m/rad, >= 0; 0 = no stop);
* ``limit`` (rad): where the stop begins, bounded to the joint's range of motion when the
  diagnosis builds the candidate (:meth:`EndStop.for_model`); a fitted stop that presses on
  nearly every frame is a linear spring, not a stop, and is flagged (:meth:`EndStop.plausibility`);
* ``transition`` ``d`` (rad, > 0): over which the stiffness rises; held at its value by the fit
  (``vary=False``) -- beyond the transition the moment is the linear spring ``-K (q - limit)``,
  which the data determine, while the shape inside it is barely seen;
* ``damping`` ``c`` (N m s/rad, >= 0): held at 0 by the fit (``vary=False``), since a
  damping acting only inside the stop is rarely resolved on top of ``joint_damping``.

The moment is linear in ``K`` (and ``c``) for a given limit, so the fit starts from a grid
over the limit with ``K`` solved by non-negative least squares (:meth:`EndStop.initial_guess`).
"""
from __future__ import annotations

import numpy as np

from ..backend import backend_of
from ..components import Parameter
from ._base import JointEffect, bounded_to_range, coordinate_target
from .registry import register

__all__ = ["EndStop", "EndStopLower", "EndStopUpper", "smooth_step", "FREE_SHARE"]

#: least share of the frames a fitted stop must leave free (else it is a spring over the whole motion)
FREE_SHARE = 0.05


def smooth_step(x):
    """Simbody's ``stepUp``: ``10 x^3 - 15 x^4 + 6 x^5`` for ``x`` clamped to [0, 1] (numpy or CasADi)."""
    xp = backend_of(x)
    xc = xp.clip(x, 0.0, 1.0)
    return xc * xc * xc * (10.0 - 15.0 * xc + 6.0 * xc * xc)


def _dstep(x):
    """``dS/dx = 30 x^2 (1 - x)^2`` inside (0, 1), zero outside (numpy)."""
    inside = (x > 0.0) & (x < 1.0)
    return np.where(inside, 30.0 * x * x * (1.0 - x) ** 2, 0.0)


class EndStop(JointEffect):
    """A passive stop at one limit of coordinate ``target`` (OpenSim's CoordinateLimitForce, one side).

    ``side`` is ``+1`` for a stop beyond the upper limit, ``-1`` below the lower one.
    """

    side: int = 1
    parameters = (
        Parameter("stiffness", 10.0, 0.0, 1.0e5, "N m/rad", "stiffness of the stop beyond the transition"),
        Parameter("limit", 0.5, -2 * np.pi, 2 * np.pi, "rad", "where the stop begins; bounded to the joint's range"),
        Parameter("transition", np.deg2rad(2.0), 1.0e-4, 0.5, "rad",
                  "angle over which the stiffness rises from 0 to its value (held by the fit)", vary=False),
        Parameter("damping", 0.0, 0.0, 1.0e3, "N m s/rad", "damping inside the stop (held by the fit)",
                  vary=False),
    )
    zero_params = {"stiffness": 0.0, "damping": 0.0}
    #: parameters bounded to the target coordinate's range of motion (see :meth:`for_model`)
    range_parameters = ("limit",)

    @classmethod
    def from_opensim(cls, coordinate: str, *, stiffness: float, limit: float, transition: float,
                     damping: float = 0.0, rotational: bool = True) -> "EndStop":
        """From one side of a CoordinateLimitForce as OpenSim's file writes it (N m/deg, deg, deg,
        N m s/deg for a rotational coordinate; SI for a translational one)."""
        w = np.pi / 180.0 if rotational else 1.0
        return cls(coordinate, stiffness=stiffness / w, limit=limit * w, transition=transition * w,
                   damping=damping / w)

    def for_model(self, model) -> "EndStop":
        """The end stop with its limit bounded to the target coordinate's range of motion."""
        return bounded_to_range(self, model, self.range_parameters)

    def plausibility(self, model, motion=None) -> list[str]:
        """Why this fitted stop is no stop (empty when it is one): on ``motion`` it presses on (nearly)
        every frame -- fewer than :data:`FREE_SHARE` of them on its free side -- so it is a linear spring
        over the whole motion, which ``joint_spring`` (with ``sensor_offset`` for the constant)
        describes without a limit to determine."""
        if motion is None or not self.values["stiffness"] > 0:
            return []
        q = motion.q[:, model.coordinate_index(self.target)]
        free = float(np.mean(self._x(q, self.values) <= 0.0))
        if free >= FREE_SHARE:
            return []
        return [f"{self.label} presses on {100 * (1 - free):.0f} % of the frames (limit {self.values['limit']:.4g} "
                f"rad beyond the motion's other end): a linear spring here, not a stop"]

    # -- the law ---------------------------------------------------------------------
    def _x(self, q, p):
        return self.side * (q - p["limit"]) / p["transition"]

    def _force(self, q, v, p):
        s = smooth_step(self._x(q, p))
        return -s * (p["stiffness"] * (q - p["limit"]) + p["damping"] * v)

    def _dforce_dparams(self, q, v, p):
        x = self._x(q, p)
        s, ds = smooth_step(x), _dstep(x)
        d, k, c = p["transition"], p["stiffness"], p["damping"]
        spring = k * (q - p["limit"]) + c * v
        return np.column_stack([
            -s * (q - p["limit"]),                                      # d/d stiffness
            k * (ds * x + s) + c * ds * self.side * v / d,              # d/d limit
            spring * ds * x / d,                                        # d/d transition
            -s * v,                                                     # d/d damping
        ])

    def _dforce_dstate(self, q, v, p):
        x = self._x(q, p)
        s, ds = smooth_step(x), _dstep(x)
        k, c, d = p["stiffness"], p["damping"], p["transition"]
        return -k * (ds * x + s) - c * ds * self.side * v / d, -c * s

    def initial_guess(self, model, motion, target, cache=None) -> list[dict]:
        """Variable projection: on a grid of limits within the bounds and the data, the stiffness
        (and the damping, when it is free) by non-negative least squares; the best few."""
        q, y = coordinate_target(model, motion, target, self.target)
        if q.size < 4:
            return []
        decl = self.params
        lo, hi = decl["limit"].min, decl["limit"].max
        lo, hi = max(lo, q.min() - decl["transition"].value), min(hi, q.max())
        if self.side < 0:
            lo, hi = max(decl["limit"].min, q.min()), min(decl["limit"].max, q.max() + decl["transition"].value)
        if not lo < hi:
            return []
        limits = np.linspace(lo, hi, 25)
        p = self.values
        x = self.side * (q[None, :] - limits[:, None]) / p["transition"]
        s = smooth_step(x)
        basis = -s * (q[None, :] - limits[:, None])                      # Q per unit stiffness
        ss = np.einsum("gn,gn->g", basis, basis)
        sy = basis @ y
        k = np.clip(sy / np.maximum(ss, 1e-300), 0.0, decl["stiffness"].max)
        rn = np.sum(y ** 2) - 2 * k * sy + k ** 2 * ss
        out = []
        for g in np.argsort(rn)[:3]:
            if k[g] > 0:
                out.append({"stiffness": float(k[g]), "limit": float(limits[g])})
        return out


@register
class EndStopUpper(EndStop):
    """A passive stop beyond the upper limit of coordinate ``target`` (pushes towards -q)."""

    family = "end_stop_upper"
    side = 1


@register
class EndStopLower(EndStop):
    """A passive stop below the lower limit of coordinate ``target`` (pushes towards +q)."""

    family = "end_stop_lower"
    side = -1
