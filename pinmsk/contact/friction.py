"""Regularized Coulomb friction of the contact elements (thesis Eq. 4.16-4.17)."""
from __future__ import annotations

import numpy as np

from ..backend import backend_of, is_symbolic
from .dual import asarray, value


def regularized_coulomb(slip: np.ndarray, normal: np.ndarray, mu_f, v_s) -> np.ndarray:
    """Regularized Coulomb friction, Eq. 4.16-4.17: ``f_f = -mu_f arctan(|v_t| / v_s) f_n v_t/|v_t|``.

    ``slip`` (N, 3) tangential velocity, ``normal`` (N,) normal force.  As in the
    thesis the arctan is *not* normalised, so the dry-friction limit
    (v_s -> 0, or |v_t| >> v_s) is ``(pi / 2) mu_f f_n``.  Written with
    ``arctan(s / v_s) / s`` (an even, smooth function of s, equal to 1 / v_s at 0)
    so the force is smooth through zero slip.
    """
    xp = backend_of(slip, normal, mu_f, v_s)
    if xp.symbolic:                 # one frame under CasADi: slip a row (1, 3)
        s2 = slip[:, 0] * slip[:, 0] + slip[:, 1] * slip[:, 1] + slip[:, 2] * slip[:, 2]
    else:
        s2 = np.einsum("ni,ni->n", slip, slip)
    s = xp.sqrt(s2)
    v_s = asarray(v_s)
    tiny = s < 1e-9 * xp.maximum(v_s, 1e-300)
    s_safe = xp.where(tiny, 1.0, s)
    # near zero slip the series 1/v_s (1 - s^2 / (3 v_s^2)) in s^2 (sqrt has no derivative at 0)
    g = xp.where(tiny, 1.0 / v_s * (1.0 - s2 / (3.0 * v_s * v_s)), xp.arctan(s_safe / v_s) / s_safe)
    return -scale_rows(mu_f * normal * g, slip)


def scale_rows(s, vec):
    """``s[:, None] * vec``: each frame's vector ``vec`` (N, 3) times its scalar ``s`` (N,); under
    CasADi (one frame: ``s`` (1, 1), ``vec`` (1, 3)) the plain product."""
    if is_symbolic(s) or is_symbolic(vec):
        return s * vec
    return s[:, None] * vec


def friction_coefficient(speed, mu_f, v_s):
    """``mu(v) = mu_f arctan(v / v_s)``, Eq. 4.17 (tends to (pi/2) mu_f for v >> v_s)."""
    return mu_f * np.arctan(np.asarray(speed, dtype=float) / v_s)


def hollars_friction(slip, normal, *, static, dynamic, viscous, transition_velocity, slip_smoothing=0.0):
    """Simbody's friction law (M. Hollars), that of OpenSim's HuntCrossleyForce and
    SmoothSphereHalfSpaceForce: the force (N, 3) on the body slipping at ``slip`` (N, 3) m/s,

        f = -f_n [min(v/v_t, 1) (u_d + 2 (u_s - u_d) / (1 + (v/v_t)^2)) + u_v v] slip / v,

    ``v = sqrt(|slip|^2 + slip_smoothing)`` (SmoothSphereHalfSpaceForce adds its
    ``constant_contact_force`` there, in m^2/s^2; HuntCrossleyForce adds nothing), ``v_t`` =
    ``transition_velocity`` (m/s), ``u_s, u_d`` the static and dynamic coefficients, ``u_v`` the
    viscous one (s/m).  ``min(v/v_t, 1) / v`` is ``1 / v_t`` below the transition, so the force is
    smooth through zero slip (Simbody divides by v; the limit is the same); the ``min`` itself is
    Simbody's, so the law has a kink at ``v = v_t`` (C0 there; the derivative is one-sided).
    """
    v2 = slip[:, 0] * slip[:, 0] + slip[:, 1] * slip[:, 1] + slip[:, 2] * slip[:, 2] + slip_smoothing
    vt = asarray(transition_velocity)
    xp = backend_of(v2, vt, normal)
    below = value(v2) < value(vt) * value(vt)
    v = xp.sqrt(xp.where(below, value(vt) * value(vt), v2))   # only the branch v >= v_t divides by v
    g = xp.where(below, 1.0 / vt, 1.0 / v)
    mu = g * (dynamic + 2.0 * (static - dynamic) / (1.0 + v2 / (vt * vt))) + viscous
    return -scale_rows(normal * mu, slip)
