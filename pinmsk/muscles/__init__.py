"""The muscle layer: Hill-type muscle-tendon models, forward and inverse (thesis App. A, Ch. 5).

Pure vectorised numpy functions over time-first ``(N, m)`` arrays (frames x
muscles) with per-muscle ``(m,)`` parameters, plus two small immutable model
objects that bind the parameters:

- :class:`Thelen2003` -- Thelen tendon, parallel element, Eq. A.6-A.9;
- :class:`NaganoGerritsen` -- Winters tendon, Eq. A.10-A.14, no parallel element.

Modules: :mod:`.activation` (A.1-A.5), :mod:`.tendon` (A.6, A.10-A.11),
:mod:`.thelen2003` (A.7-A.9), :mod:`.nagano_gerritsen` (A.12-A.14),
:mod:`.pennation` (constant-thickness geometry), :mod:`.inverse` (Fig. 5.6,
Eq. 5.2-5.4), :mod:`.models` (the objects).  SI units; fiber velocity is
negative when shortening.
"""
from .activation import (TAU_FALL, TAU_RISE, activation_from_excitation, activation_rate,
                         excitation_from_activation, he_activation_rate)
from .inverse import inverse_muscle, inverse_nagano_gerritsen, inverse_thelen2003
from .models import NaganoGerritsen, Thelen2003
from .nagano_gerritsen import (ng_activation_from_force, ng_activation_hat, ng_contraction_rate,
                               ng_equilibrium, ng_fiber_force, ng_fiber_force_partials, ng_fiber_velocity,
                               ng_force_length, ng_force_length_derivative)
from .pennation import fiber_length, pennation_angle, pennation_height, rigid_tendon_kinematics
from .tendon import (TENDON_STRAIN0, thelen_tendon_force, thelen_tendon_stiffness,
                     thelen_tendon_stiffness_derivative, thelen_tendon_strain, winters_tendon_force,
                     winters_tendon_stiffness, winters_tendon_stiffness_derivative, winters_tendon_strain)
from .thelen2003 import (thelen_activation_from_force, thelen_active_force_length,
                         thelen_active_force_length_derivative, thelen_contraction_rate, thelen_equilibrium,
                         thelen_fiber_force, thelen_fiber_force_partials, thelen_fiber_velocity,
                         thelen_force_velocity, thelen_force_velocity_derivative,
                         thelen_force_velocity_inverse, thelen_passive_force_length,
                         thelen_passive_force_length_derivative)

__all__ = [
    "NaganoGerritsen", "Thelen2003",
    "TAU_FALL", "TAU_RISE", "TENDON_STRAIN0",
    "activation_from_excitation", "activation_rate", "excitation_from_activation",
    "he_activation_rate",
    "inverse_muscle", "inverse_nagano_gerritsen", "inverse_thelen2003",
    "ng_activation_from_force", "ng_activation_hat", "ng_contraction_rate", "ng_equilibrium",
    "ng_fiber_force", "ng_fiber_force_partials", "ng_fiber_velocity", "ng_force_length",
    "ng_force_length_derivative",
    "fiber_length", "pennation_angle", "pennation_height", "rigid_tendon_kinematics",
    "thelen_tendon_force", "thelen_tendon_stiffness", "thelen_tendon_stiffness_derivative",
    "thelen_tendon_strain", "winters_tendon_force", "winters_tendon_stiffness",
    "winters_tendon_stiffness_derivative", "winters_tendon_strain",
    "thelen_activation_from_force", "thelen_active_force_length",
    "thelen_active_force_length_derivative", "thelen_contraction_rate", "thelen_equilibrium",
    "thelen_fiber_force", "thelen_fiber_force_partials", "thelen_fiber_velocity",
    "thelen_force_velocity", "thelen_force_velocity_derivative", "thelen_force_velocity_inverse",
    "thelen_passive_force_length", "thelen_passive_force_length_derivative",
]
