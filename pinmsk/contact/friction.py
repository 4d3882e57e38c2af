"""Regularized Coulomb friction of the contact elements (thesis Eq. 4.16-4.17)."""
from __future__ import annotations

import numpy as np

from .dual import asarray


def regularized_coulomb(slip: np.ndarray, normal: np.ndarray, mu_f, v_s) -> np.ndarray:
    """Regularized Coulomb friction, Eq. 4.16-4.17: ``f_f = -mu_f arctan(|v_t| / v_s) f_n v_t/|v_t|``.

    ``slip`` (N, 3) tangential velocity, ``normal`` (N,) normal force.  As in the
    thesis the arctan is *not* normalised, so the dry-friction limit
    (v_s -> 0, or |v_t| >> v_s) is ``(pi / 2) mu_f f_n``.  Written with
    ``arctan(s / v_s) / s`` (an even, smooth function of s, equal to 1 / v_s at 0)
    so the force is smooth through zero slip.
    """
    s2 = np.einsum("ni,ni->n", slip, slip)
    s = np.sqrt(s2)
    v_s = asarray(v_s)
    tiny = s < 1e-9 * np.maximum(v_s, 1e-300)
    s_safe = np.where(tiny, 1.0, s)
    # near zero slip the series 1/v_s (1 - s^2 / (3 v_s^2)) in s^2 (sqrt has no derivative at 0)
    g = np.where(tiny, 1.0 / v_s * (1.0 - s2 / (3.0 * v_s * v_s)), np.arctan(s_safe / v_s) / s_safe)
    return -(mu_f * normal * g)[:, None] * slip


def friction_coefficient(speed, mu_f, v_s):
    """``mu(v) = mu_f arctan(v / v_s)``, Eq. 4.17 (tends to (pi/2) mu_f for v >> v_s)."""
    return mu_f * np.arctan(np.asarray(speed, dtype=float) / v_s)
