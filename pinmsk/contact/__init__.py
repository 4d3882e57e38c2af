"""Foot-ground contact (thesis Ch. 4): sphere elements, friction, feet and identification.

Components (``kind = "contact"``, target = a body frame), vectorised over frames, C1-smooth:

* :class:`HuntCrossley` -- point contact, Eq. 4.4;
* :class:`Volumetric` -- linear volumetric sphere, Eq. 4.5-4.8;
* :class:`HyperVolumetric` -- hyper-volumetric sphere, Eq. 4.9-4.15;
* friction of all three: regularized Coulomb, Eq. 4.16-4.17 (:func:`regularized_coulomb`);

and OpenSim's two sphere-half-space forces, Simbody's laws exactly (geometry:
:mod:`pinmsk.contact.half_space`, a sphere on a body against a ground-fixed half space of any
orientation; friction :func:`hollars_friction`):

* :class:`SmoothSphereHalfSpaceForce` -- Serrancoli et al. 2019, smooth (Moco's 2-D walking model);
* :class:`HuntCrossleyForce` -- Hertz contact with Hunt-Crossley damping (not smooth).

:data:`CONTACT_TYPES` lists every contact component class.

Each reports normal force, friction force and point of application
(:class:`ContactForces`); :func:`ground_reaction` gives one foot's GRF, COP and
free moment, :func:`contact_ground_reactions` and :func:`ground_reaction_trial` each side's of a
model's own contacts over a motion.  Their ``generalized_force`` is ``J^T`` of the world wrench.

Feet and fitting: :func:`load_foot2d`, :func:`foot_contacts`, :class:`ContactFit`
(Eq. 4.2 identification, exact Jacobians through :class:`~pinmsk.contact.dual.Dual`
numbers), :func:`fit_contact_models` (several models on one trial, each starting from the
ones it contains), :func:`load_contact_model`,
:func:`read_contact_trial` (CSU text or .csv/.sto/.mot), :func:`synthetic_foot_trial`,
:func:`from_spec` (a sidecar ``[[contacts]]`` entry -> component, see
:mod:`pinmsk.contact.spec`).  The CSU reader is :func:`pinmsk.io.cleveland_gait.read_csu`.  The
contact models as diagnosis candidates (``contact_candidates``) are in :mod:`pinmsk.diagnose.contact`.

Layers: the physics (spheres, laws, feet, sidecar entries) is imported with the package and
imports no model; the identification and the synthetic trial use models
(:func:`pinmsk.load_model`, which builds contacts from this package), so their names are
imported on first use (PEP 562), as :mod:`pinmsk` does.
"""
from .._lazy import lazy_attributes
from .foot import (KINDS, SITES, GroundReaction, contact_ground_reactions, contact_side, foot_contacts,
                   ground_reaction, ground_reaction_trial, site_frames)
from .friction import friction_coefficient, hollars_friction, regularized_coulomb
from .half_space import HalfSpaceContact, hertz_coefficient
from .hunt_crossley import HuntCrossley, HuntCrossleyForce, hunt_crossley_normal
from .smooth_sphere import SmoothSphereHalfSpaceForce
from .spec import from_spec
from .sphere import (ContactForces, SiteKinematics, SphereContact, cap_centroid_depth, cap_volume,
                     site_kinematics, smooth_positive, wrench_generalized_force)
from .volumetric import HyperVolumetric, Volumetric

#: Every contact component class: the thesis's spheres (``KINDS``) and OpenSim's.
CONTACT_TYPES = (HuntCrossley, Volumetric, HyperVolumetric, SmoothSphereHalfSpaceForce, HuntCrossleyForce)

#: Names of the model-level submodules, imported when first used.
_LAZY = {
    "ContactFit": "identify", "load_contact_model": "identify", "fit_contact_models": "identify",
    "fourier_basis": "identify", "load_foot2d": "identify", "read_contact_trial": "identify",
    "read_csu_foot2d": "identify",
    "stance_cycle": "identify", "toe_from_kinematics": "identify",
    "synthetic_foot_trial": "synthetic",
}


__all__ = [
    "CONTACT_TYPES", "ContactFit", "ContactForces", "GroundReaction", "HalfSpaceContact", "HuntCrossley",
    "HuntCrossleyForce", "HyperVolumetric", "KINDS", "SmoothSphereHalfSpaceForce",
    "contact_ground_reactions", "contact_side", "ground_reaction_trial", "hertz_coefficient",
    "hollars_friction", "hunt_crossley_normal",
    "SITES", "SiteKinematics", "SphereContact", "Volumetric", "cap_centroid_depth", "cap_volume",
    "fit_contact_models", "load_contact_model", "from_spec", "foot_contacts", "fourier_basis",
    "friction_coefficient", "ground_reaction", "load_foot2d", "read_contact_trial", "read_csu_foot2d",
    "regularized_coulomb", "site_frames",
    "site_kinematics", "smooth_positive", "stance_cycle", "synthetic_foot_trial", "toe_from_kinematics",
    "wrench_generalized_force",
]

__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, __all__)
