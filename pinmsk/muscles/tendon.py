"""Tendon force-strain curves, their derivatives and inverses (thesis App. A.3.1 and A.4).

Forces are normalized to the muscle's maximum isometric force ``F_max``;
strain is engineering strain ``(l_t - l_slack) / l_slack``.  All functions are
elementwise over broadcastable arrays; the curves and their inverses (not the second
derivatives) also take CasADi values (:mod:`pinmsk.backend`).

A slack tendon carries no compression: both curves are zero for strain <= 0.
The thesis writes Eq. A.6 without that lower bound (read literally the
exponential would give a small *negative* force below slack length); we clip,
as OpenSim's Thelen2003Muscle does.  Derivatives at the kinks (strain 0, and
the toe of the Thelen curve) are the one-sided values from the loaded side,
so that an inverse model at zero force still has a finite compliance.

Thelen 2003 with the thesis constants (k_toe = 3, f_toe = 0.33, strain0 = 0.04,
strain_toe = 0.609 strain0, k_lin = 1.712/strain0) gives a force of
**0.999392** (not exactly 1) at strain 0.04, and the slope of the exponential
at the toe is 42.770 against k_lin = 42.8: the curve is C0 at the toe but its
slope jumps by 0.07 % (the published constants are rounded; OpenSim's exact
ones are ``strain_toe = 99 e^3 strain0 / (166 e^3 - 67)``).  We use the thesis
values as printed; ``exact_toe=True`` gives OpenSim's (for imported OpenSim models).
"""
from __future__ import annotations

import math

import numpy as np

from ..backend import backend_of

__all__ = ["TENDON_STRAIN0",
           "thelen_tendon_force", "thelen_tendon_stiffness", "thelen_tendon_stiffness_derivative",
           "thelen_tendon_strain",
           "winters_tendon_force", "winters_tendon_stiffness",
           "winters_tendon_stiffness_derivative", "winters_tendon_strain"]

TENDON_STRAIN0 = 0.04  # tendon strain at F_max (thesis A.3.1 and A.4)
K_TOE = 3.0
F_TOE = 0.33


#: OpenSim's exact toe strain of the Thelen tendon, as a fraction of strain0 (the thesis rounds it to 0.609)
EXACT_TOE_FRACTION = 99.0 * math.exp(3.0) / (166.0 * math.exp(3.0) - 67.0)


def _thelen_constants(strain0, exact_toe: bool = False):
    """``(strain_toe, k_lin, scale, rate)`` of Eq. A.6: the thesis' rounded toe constants, or
    OpenSim's exact ones (``exact_toe``: the curve is C1 at the toe and 1 at strain0)."""
    if exact_toe:
        strain_toe = EXACT_TOE_FRACTION * strain0
        k_lin = (1.0 - F_TOE) / (strain0 - strain_toe)
    else:
        strain_toe = 0.609 * strain0
        k_lin = 1.712 / strain0
    scale = F_TOE / math.expm1(K_TOE)          # f_toe / (e^k_toe - 1)
    return strain_toe, k_lin, scale, K_TOE / strain_toe


def thelen_tendon_force(strain, *, strain0=TENDON_STRAIN0, exact_toe: bool = False):
    """Thelen 2003 normalized tendon force from strain, thesis Eq. A.6.

    Exponential toe ``f_toe/(e^k_toe - 1) (exp(k_toe eps/eps_toe) - 1)`` up to
    ``eps_toe = 0.609 strain0``, then linear ``k_lin (eps - eps_toe) + f_toe``
    with ``k_lin = 1.712/strain0``; zero for eps <= 0 (slack).
    """
    eps_toe, k_lin, scale, rate = _thelen_constants(strain0, exact_toe)
    xp = backend_of(strain)
    eps = xp.asarray(strain)
    # clipping to [0, eps_toe] evaluates both pieces branch-free: the toe term
    # saturates at f_toe and the linear term is zero below the toe.
    toe = scale * xp.expm1(rate * xp.clip(eps, 0.0, eps_toe))
    return toe + k_lin * xp.maximum(eps - eps_toe, 0.0)


def thelen_tendon_stiffness(strain, *, strain0=TENDON_STRAIN0, exact_toe: bool = False):
    """d(normalized tendon force)/d(strain) of Eq. A.6 (right derivative at 0 and at the toe)."""
    eps_toe, k_lin, scale, rate = _thelen_constants(strain0, exact_toe)
    xp = backend_of(strain)
    eps = xp.asarray(strain)
    toe = rate * scale * xp.exp(rate * xp.clip(eps, 0.0, eps_toe))
    # (eps >= 0) & (eps <= eps_toe) -> toe; above the toe k_lin; slack 0 (nested: CasADi has no &)
    return xp.where(eps > eps_toe, k_lin, xp.where(eps >= 0.0, toe, 0.0))


def thelen_tendon_stiffness_derivative(strain, *, strain0: float = TENDON_STRAIN0):
    """Second derivative d^2 f/d strain^2 of Eq. A.6 (zero on the linear part and when slack)."""
    eps_toe, _, scale, rate = _thelen_constants(strain0)
    eps = np.asarray(strain, dtype=float)
    in_toe = (eps >= 0.0) & (eps <= eps_toe)
    return np.where(in_toe, rate * rate * scale * np.exp(rate * np.clip(eps, 0.0, eps_toe)), 0.0)


def thelen_tendon_strain(force, *, strain0=TENDON_STRAIN0, exact_toe: bool = False):
    """Inverse of Eq. A.6: tendon strain from normalized tendon force (0 for force <= 0)."""
    eps_toe, k_lin, scale, rate = _thelen_constants(strain0, exact_toe)
    xp = backend_of(force)
    f = xp.asarray(force)
    toe = xp.log1p(xp.clip(f, 0.0, F_TOE) / scale) / rate
    return toe + xp.maximum(f - F_TOE, 0.0) / k_lin


def winters_tendon_force(strain, *, strain0: float = TENDON_STRAIN0):
    """Winters quadratic tendon, thesis Eq. A.10-A.11, normalized: ``(eps/strain0)^2`` for eps >= 0.

    With ``k_t = F_max/(strain0 l_slack)^2``, ``F = k_t (l_t - l_slack)^2`` is
    ``F_max (eps/strain0)^2``: the tendon carries F_max at ``strain0`` (4 %).
    """
    xp = backend_of(strain)
    e = xp.maximum(xp.asarray(strain), 0.0) / strain0
    return e * e


def winters_tendon_stiffness(strain, *, strain0: float = TENDON_STRAIN0):
    """d(normalized force)/d(strain) of Eq. A.10: ``2 eps / strain0^2`` (0 when slack)."""
    xp = backend_of(strain)
    return 2.0 * xp.maximum(xp.asarray(strain), 0.0) / (strain0 * strain0)


def winters_tendon_stiffness_derivative(strain, *, strain0: float = TENDON_STRAIN0):
    """Second derivative of Eq. A.10: ``2/strain0^2`` when taut (right value at 0), else 0."""
    eps = np.asarray(strain, dtype=float)
    return np.where(eps >= 0.0, 2.0 / (strain0 * strain0), 0.0)


def winters_tendon_strain(force, *, strain0: float = TENDON_STRAIN0):
    """Inverse of Eq. A.10: strain ``strain0 sqrt(f)`` (0 for force <= 0)."""
    xp = backend_of(force)
    return strain0 * xp.sqrt(xp.maximum(xp.asarray(force), 0.0))
