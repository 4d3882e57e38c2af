"""De Groote et al. (2016) muscle curves as OpenSim's DeGrooteFregly2016Muscle defines them.

Pure, elementwise functions over broadcastable arrays (per-muscle settings
broadcast against time-first ``(N, m)`` inputs; the curve arguments may be CasADi
values, see :mod:`pinmsk.backend`), their analytic derivatives,
and :class:`DeGrooteFregly2016Muscle`, the OpenSim muscle's properties with
their OpenSim names, defaults and bounds.  The vectorised muscle-tendon model
is :class:`pinmsk.muscles.DeGroote2016`.

The constants are OpenSim's (opensim-core ``DeGrooteFregly2016Muscle.h``),
which differ slightly from the paper's supplement so that the curves pass
through their key points:

- active force-length: the sum of three Gaussian-like terms
  ``b1 exp(-(x - b2)^2 / (2 (b3 + b4 x)^2))``, with ``b11`` chosen so that
  ``f_L(1) = 1``; ``active_force_width_scale`` w widens it about the peak,
  ``x = (l - 1)/w + 1``;
- passive force-length: ``(exp(k_PE (l - 1)/e0) - o)/(exp(k_PE) - o)`` with
  ``k_PE = 4`` and ``o = exp(k_PE (0.2 - 1)/e0)``, so that it is 0 at
  ``l = 0.2`` (not at ``l = 1``: there is a small passive force at l_opt) and
  1 at ``l = 1 + e0``;
- force-velocity: ``d1 asinh(d2 v + d3) + d4`` (the paper's log form), with
  ``d1, d4`` chosen so that ``f_V(-1) = 0`` and ``f_V(0) = 1``; ``v`` is the
  fiber velocity in units of the maximum contraction velocity (negative when
  shortening); it is defined for all ``v`` (no clipping, as in OpenSim);
- tendon: ``c1 exp(k_T (l_T - c2)) - c3`` of the normalised tendon length
  ``l_T = l_t / l_slack`` with ``c1 = c3 = 0.2``, ``c2 = 1`` (0 at slack length,
  negative -- down to -0.2 -- below it, as in OpenSim) and ``k_T`` from the
  tendon strain at one normalised force:
  ``k_T = ln((1 + c3)/c1) / (1 + e_T - c2)``.

Fiber damping (an addition of OpenSim's, not in the paper) adds
``fiber_damping * v`` (normalised) to the fiber force.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..backend import backend_of

from ._common import OpenSimMuscleProperties

__all__ = [
    "ACTIVE_B", "K_PE", "TENDON_C1", "TENDON_C2", "TENDON_C3", "FV_D1", "FV_D2", "FV_D3", "FV_D4",
    "MIN_NORM_FIBER_LENGTH", "MAX_NORM_FIBER_LENGTH",
    "DeGrooteFregly2016Muscle",
    "degroote_active_force_length", "degroote_active_force_length_derivative",
    "degroote_passive_force_length", "degroote_passive_force_length_derivative",
    "degroote_force_velocity", "degroote_force_velocity_derivative",
    "degroote_force_velocity_inverse",
    "degroote_tendon_stiffness_parameter", "degroote_tendon_force",
    "degroote_tendon_force_derivative", "degroote_tendon_length",
]

#: (b1, b2, b3, b4) of the three Gaussian-like terms of the active force-length curve
ACTIVE_B = ((0.8150671134243542, 1.055033428970575, 0.162384573599574, 0.063303448465465),
            (0.433004984392647, 0.716775413397760, -0.029947116970696, 0.200356847296188),
            (0.1, 1.0, 0.353553390593274, 0.0))
K_PE = 4.0                      # passive exponential shape factor
TENDON_C1 = 0.2
TENDON_C2 = 1.0
TENDON_C3 = 0.2
FV_D1 = -0.3211346127989808
FV_D2 = -8.149
FV_D3 = -0.374
FV_D4 = 0.8825327733249912
MIN_NORM_FIBER_LENGTH = 0.2     # where the passive curve is 0 (and OpenSim's fiber-length bounds)
MAX_NORM_FIBER_LENGTH = 1.8


# --------------------------------------------------------------------------- fiber curves
def _width_x(l_norm, width_scale):
    return (backend_of(l_norm).asarray(l_norm) - 1.0) / width_scale + 1.0


def degroote_active_force_length(l_norm, *, width_scale=1.0):
    """Active force-length multiplier ``f_L(l_norm)``: the sum of three Gaussian-like terms.

    ``width_scale`` (>= 1, OpenSim's ``active_force_width_scale``) stretches the
    curve about its peak at ``l_norm = 1``.
    """
    xp = backend_of(l_norm)
    x = _width_x(l_norm, width_scale)
    out = 0.0 * x if xp.symbolic else np.zeros(np.shape(x))
    for b1, b2, b3, b4 in ACTIVE_B:
        s = b3 + b4 * x
        d = x - b2
        out = out + b1 * xp.exp(-0.5 * d * d / (s * s))
    return out


def degroote_active_force_length_derivative(l_norm, *, width_scale=1.0):
    """``d f_L / d l_norm``: ``sum b1 e(x) (b2 - x)(b3 + b2 b4)/(b3 + b4 x)^3`` over ``width_scale``."""
    xp = backend_of(l_norm)
    x = _width_x(l_norm, width_scale)
    out = 0.0 * x if xp.symbolic else np.zeros(np.shape(x))
    for b1, b2, b3, b4 in ACTIVE_B:
        s = b3 + b4 * x
        d = x - b2
        out = out + b1 * xp.exp(-0.5 * d * d / (s * s)) * (-d) * (b3 + b2 * b4) / (s * s * s)
    return out / np.asarray(width_scale, dtype=float)


def _passive_offset(strain):
    strain = np.asarray(strain, dtype=float)
    offset = np.exp(K_PE * (MIN_NORM_FIBER_LENGTH - 1.0) / strain)
    return offset, math.exp(K_PE) - offset


def degroote_passive_force_length(l_norm, *, strain=0.6):
    """Passive fiber force multiplier: 0 at ``l_norm = 0.2``, 1 at ``1 + strain`` (negative below 0.2).

    ``strain`` is OpenSim's ``passive_fiber_strain_at_one_norm_force``.
    """
    xp = backend_of(l_norm)
    offset, denom = _passive_offset(strain)
    return (xp.exp(K_PE * (xp.asarray(l_norm) - 1.0) / strain) - offset) / denom


def degroote_passive_force_length_derivative(l_norm, *, strain=0.6):
    """``d f_PE / d l_norm = k_PE exp(k_PE (l - 1)/e0) / (e0 (exp(k_PE) - o))``."""
    xp = backend_of(l_norm)
    _, denom = _passive_offset(strain)
    e = xp.exp(K_PE * (xp.asarray(l_norm) - 1.0) / strain)
    return K_PE * e / (np.asarray(strain, dtype=float) * denom)


def degroote_force_velocity(v_norm):
    """Force-velocity multiplier ``d1 asinh(d2 v + d3) + d4``: 0 at ``v = -1``, 1 at 0, ~1.794 at +1."""
    xp = backend_of(v_norm)
    return FV_D1 * xp.arcsinh(FV_D2 * xp.asarray(v_norm) + FV_D3) + FV_D4


def degroote_force_velocity_derivative(v_norm):
    """``d f_V / d v = d1 d2 / sqrt((d2 v + d3)^2 + 1)`` (positive: the curve is increasing)."""
    t = FV_D2 * np.asarray(v_norm, dtype=float) + FV_D3
    return FV_D1 * FV_D2 / np.sqrt(t * t + 1.0)


def degroote_force_velocity_inverse(f_v):
    """Normalised fiber velocity from the multiplier: ``(sinh((f - d4)/d1) - d3)/d2`` (exact inverse)."""
    return (np.sinh((np.asarray(f_v, dtype=float) - FV_D4) / FV_D1) - FV_D3) / FV_D2


# --------------------------------------------------------------------------- tendon
def degroote_tendon_stiffness_parameter(strain=0.049):
    """``k_T = ln((1 + c3)/c1) / (1 + strain - c2)``, so that the tendon force is 1 at ``1 + strain``."""
    return math.log((1.0 + TENDON_C3) / TENDON_C1) / (1.0 + np.asarray(strain, dtype=float) - TENDON_C2)


def degroote_tendon_force(l_norm, *, strain=0.049):
    """Normalised tendon force ``c1 exp(k_T (l_T - c2)) - c3`` of the normalised tendon length.

    0 at ``l_T = 1``, 1 at ``1 + strain``; negative (to -0.2) below slack length, as in OpenSim.
    """
    xp = backend_of(l_norm)
    k = degroote_tendon_stiffness_parameter(strain)
    return TENDON_C1 * xp.exp(k * (xp.asarray(l_norm) - TENDON_C2)) - TENDON_C3


def degroote_tendon_force_derivative(l_norm, *, strain=0.049):
    """``d f_T / d l_T = c1 k_T exp(k_T (l_T - c2))``."""
    xp = backend_of(l_norm)
    k = degroote_tendon_stiffness_parameter(strain)
    return TENDON_C1 * k * xp.exp(k * (xp.asarray(l_norm) - TENDON_C2))


def degroote_tendon_length(force, *, strain=0.049):
    """Normalised tendon length from normalised tendon force (the exact inverse; needs force > -0.2)."""
    xp = backend_of(force)
    k = degroote_tendon_stiffness_parameter(strain)
    with np.errstate(divide="ignore", invalid="ignore"):
        return xp.log((xp.asarray(force) + TENDON_C3) / TENDON_C1) / k + TENDON_C2


# --------------------------------------------------------------------------- OpenSim properties
@dataclass(frozen=True)
class DeGrooteFregly2016Muscle(OpenSimMuscleProperties):
    """The properties of one OpenSim ``DeGrooteFregly2016Muscle``, with OpenSim's names and defaults.

    Values are in OpenSim's units (metres, newtons, radians; ``max_contraction_velocity``
    in optimal fiber lengths per second).  Construction checks OpenSim's
    property bounds and raises :class:`~pinmsk.errors.ModelError` naming the
    property.  The curve methods are OpenSim's ``calc...`` functions, vectorised;
    :meth:`model_parameters` gives the keyword arguments of
    :class:`pinmsk.muscles.DeGroote2016`.
    """

    activation_time_constant: float = 0.015
    deactivation_time_constant: float = 0.060
    default_activation: float = 0.5
    default_normalized_tendon_force: float = 0.5
    active_force_width_scale: float = 1.0
    fiber_damping: float = 0.0
    ignore_passive_fiber_force: bool = False
    passive_fiber_strain_at_one_norm_force: float = 0.6
    tendon_strain_at_one_norm_force: float = 0.049
    tendon_compliance_dynamics_mode: str = "explicit"
    activation_dynamics_smoothing: float = 0.1

    def __post_init__(self):
        self._check_properties("activation_time_constant", "deactivation_time_constant",
                               "activation_dynamics_smoothing", "passive_fiber_strain_at_one_norm_force",
                               "tendon_strain_at_one_norm_force", "default_activation")
        need = self._require
        need(self.active_force_width_scale >= 1.0, "active_force_width_scale", ">= 1")
        need(self.fiber_damping >= 0.0, "fiber_damping", ">= 0")
        need(0.0 <= self.default_normalized_tendon_force <= 5.0, "default_normalized_tendon_force",
             "in [0, 5]")
        need(self.tendon_compliance_dynamics_mode in ("explicit", "implicit"),
             "tendon_compliance_dynamics_mode", "'explicit' or 'implicit'")

    # -- OpenSim's curve functions ------------------------------------------------
    def active_force_length_multiplier(self, l_norm):
        """OpenSim ``calcActiveForceLengthMultiplier``."""
        return degroote_active_force_length(l_norm, width_scale=self.active_force_width_scale)

    def active_force_length_multiplier_derivative(self, l_norm):
        """OpenSim ``calcActiveForceLengthMultiplierDerivative``."""
        return degroote_active_force_length_derivative(l_norm, width_scale=self.active_force_width_scale)

    def passive_force_multiplier(self, l_norm):
        """OpenSim ``calcPassiveForceMultiplier`` (0 with ``ignore_passive_fiber_force``)."""
        if self.ignore_passive_fiber_force:
            return np.zeros(np.shape(l_norm))
        return degroote_passive_force_length(l_norm, strain=self.passive_fiber_strain_at_one_norm_force)

    def passive_force_multiplier_derivative(self, l_norm):
        """OpenSim ``calcPassiveForceMultiplierDerivative``."""
        if self.ignore_passive_fiber_force:
            return np.zeros(np.shape(l_norm))
        return degroote_passive_force_length_derivative(
            l_norm, strain=self.passive_fiber_strain_at_one_norm_force)

    @staticmethod
    def force_velocity_multiplier(v_norm):
        """OpenSim ``calcForceVelocityMultiplier``."""
        return degroote_force_velocity(v_norm)

    @staticmethod
    def force_velocity_multiplier_derivative(v_norm):
        """The derivative of :meth:`force_velocity_multiplier`."""
        return degroote_force_velocity_derivative(v_norm)

    @staticmethod
    def force_velocity_inverse(f_v):
        """OpenSim ``calcForceVelocityInverseCurve``."""
        return degroote_force_velocity_inverse(f_v)

    def tendon_force_multiplier(self, l_norm):
        """OpenSim ``calcTendonForceMultiplier`` of the normalised tendon length."""
        return degroote_tendon_force(l_norm, strain=self.tendon_strain_at_one_norm_force)

    def tendon_force_multiplier_derivative(self, l_norm):
        """OpenSim ``calcTendonForceMultiplierDerivative``."""
        return degroote_tendon_force_derivative(l_norm, strain=self.tendon_strain_at_one_norm_force)

    def tendon_force_length_inverse(self, force):
        """OpenSim ``calcTendonForceLengthInverseCurve``: normalised tendon length from force."""
        return degroote_tendon_length(force, strain=self.tendon_strain_at_one_norm_force)

    # -- pinmsk ------------------------------------------------------------------
    def properties(self) -> dict:
        """All properties by their OpenSim names."""
        return asdict(self)

    def model_parameters(self) -> dict:
        """Keyword arguments of :class:`pinmsk.muscles.DeGroote2016` for this muscle (SI units)."""
        return dict(f_max=float(self.max_isometric_force), l_opt=float(self.optimal_fiber_length),
                    l_slack=float(self.tendon_slack_length),
                    pennation=float(self.pennation_angle_at_optimal),
                    v_max=float(self.max_contraction_velocity * self.optimal_fiber_length),
                    damping=float(self.fiber_damping),
                    width_scale=float(self.active_force_width_scale),
                    passive_strain=float(self.passive_fiber_strain_at_one_norm_force),
                    passive_scale=0.0 if self.ignore_passive_fiber_force else 1.0,
                    tendon_strain=float(self.tendon_strain_at_one_norm_force),
                    tau_rise=float(self.activation_time_constant),
                    tau_fall=float(self.deactivation_time_constant))
