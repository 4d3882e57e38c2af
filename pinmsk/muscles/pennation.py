"""Constant-thickness pennation geometry and rigid-tendon fiber kinematics.

The fibers keep a constant height ``h = l_opt sin(alpha_opt)``:
``l_ce sin(alpha) = l_opt sin(alpha_opt)`` (thesis Fig. 5.6, as in OpenSim's
fixed-width pennation model).  With ``x = l_ce cos(alpha)`` the fiber length
projected on the line of action, ``l_ce^2 = x^2 + h^2`` and ``l_mt = l_t + x``.
Differentiating ``l_ce^2 = x^2 + h^2`` once and twice gives the fiber velocity
and acceleration used by the inverse model:

    l_ce v_ce = x x',      v_ce^2 + l_ce a_ce = x'^2 + x x''.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import TrialError
from ._common import locate, where_first

__all__ = ["pennation_height", "pennation_angle", "fiber_length", "fiber_velocity_from_along",
           "fiber_acceleration_from_along", "rigid_tendon_kinematics", "check_along_positive"]


def pennation_height(l_opt, pennation):
    """Constant fiber height ``l_opt sin(alpha_opt)`` (m)."""
    return np.asarray(l_opt, dtype=float) * np.sin(np.asarray(pennation, dtype=float))


def pennation_angle(l_ce, height):
    """Pennation angle ``alpha = arcsin(h / l_ce)`` (rad) of the constant-thickness model."""
    return np.arcsin(np.asarray(height, dtype=float) / np.asarray(l_ce, dtype=float))


def fiber_length(along, height):
    """Fiber length ``sqrt(x^2 + h^2)`` from its projection ``x`` on the line of action."""
    x = np.asarray(along, dtype=float)
    return np.sqrt(x * x + np.asarray(height, dtype=float) ** 2)


def fiber_velocity_from_along(along, along_rate, l_ce):
    """Fiber velocity ``v_ce = x x' / l_ce`` (= x' cos(alpha))."""
    return along * along_rate / l_ce


def fiber_acceleration_from_along(along, along_rate, along_acc, l_ce, v_ce):
    """Fiber acceleration ``a_ce = (x'^2 + x x'' - v_ce^2) / l_ce`` (second derivative of the geometry)."""
    return (along_rate * along_rate + along * along_acc - v_ce * v_ce) / l_ce


def check_along_positive(along, l_mt, names: Sequence[str] | None = None, *, what: str) -> None:
    """Raise if the fiber's projection on the line of action is not positive.

    ``x <= 0`` means the muscle-tendon unit is shorter than the tendon
    (pennation angle 90 degrees or more); no fiber state exists there.
    """
    bad = ~(np.asarray(along) > 0)
    if bad.any():
        frame, muscle = where_first(bad)
        raise TrialError(
            f"{what}: the muscle-tendon length leaves no room for the fiber at "
            f"{locate(frame, muscle, names)} (l_mt = {float(np.broadcast_to(l_mt, bad.shape)[bad][0]):.6g} m "
            f"is not longer than the tendon; {int(bad.sum())} muscle-frame(s) affected). "
            "Check the path lengths and l_slack of this muscle")


def rigid_tendon_kinematics(l_mt, v_mt, *, l_slack, l_opt, pennation,
                            names: Sequence[str] | None = None):
    """Fiber length, velocity and ``cos(alpha)`` for an inextensible tendon.

    ``x = l_mt - l_slack``, ``l_ce = sqrt(x^2 + h^2)``, ``v_ce = v_mt x / l_ce``
    (the fiber shortens by ``cos(alpha)`` of the unit's shortening).
    Returns ``(l_ce, v_ce, cos_alpha)`` broadcast to the inputs' shape.
    """
    l_mt = np.asarray(l_mt, dtype=float)
    x = l_mt - l_slack
    check_along_positive(x, l_mt, names, what="rigid-tendon kinematics")
    h = pennation_height(l_opt, pennation)
    l_ce = np.sqrt(x * x + h * h)
    cos_alpha = x / l_ce
    return l_ce, np.asarray(v_mt, dtype=float) * cos_alpha, cos_alpha
