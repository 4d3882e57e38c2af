"""OpenSim's SmoothSphereHalfSpaceForce: a smooth Hunt-Crossley sphere against a half space."""
from __future__ import annotations

from ..backend import backend_of
from ..components import Parameter
from .dual import asarray, value
from .half_space import HALF_SPACE_PARAMETERS, HalfSpaceContact, hertz_coefficient
from .hunt_crossley import hunt_crossley_normal


def smooth_step(x):
    """``(1 + tanh(x)) / 2``: Serrancoli et al.'s smooth switch from 0 to 1 around ``x = 0``."""
    return 0.5 + 0.5 * backend_of(x).tanh(x)


class SmoothSphereHalfSpaceForce(HalfSpaceContact):
    """OpenSim's ``SmoothSphereHalfSpaceForce`` (Serrancoli, Falisse et al. 2019, IEEE TNSRE 27(9),
    doi:10.1109/tnsre.2019.2924536), as Simbody's ``SmoothSphereHalfSpaceForceImpl::calcForce``
    computes it: the contact of Moco's 2-D walking model, designed for gradient-based optimal control.

    With the indentation ``delta`` and compression rate ``v_n`` of
    :class:`~pinmsk.contact.half_space.HalfSpaceContact` (same geometry as OpenSim's), ``cf`` =
    ``constant_contact_force``, ``b_d`` = ``hertz_smoothing``, ``b_v`` = ``hunt_crossley_smoothing``:

        f_H  = 4/3 k sqrt(R k) (sqrt(delta^2 + cf))^(3/2) (1 + tanh(b_d delta)) / 2,   k = E^(2/3) / 2
        f_n  = f_H (1 + 3/2 c v_n) (1 + tanh(b_v (v_n + 2 / (3 c)))) / 2

    and :func:`~pinmsk.contact.friction.hollars_friction` with the slip speed
    ``sqrt(|v_t|^2 + cf)``.  The force is C-infinity except at the friction's transition velocity
    (Simbody's ``min(v / v_t, 1)``, a kink in the first derivative).  It never vanishes: out of
    contact ``f_H`` decays like ``exp(2 b_d delta)`` (about 1e-26 of the scale at 10 cm), and the
    second switch lets the ground pull only at rates near ``-2 / (3 c)`` where the first factor
    is already negative.  ``dissipation = 0`` takes the switch's limit 1 (Simbody divides by c:
    the same limit).  Parameters: OpenSim's names, defaults and units.
    """

    family = "smooth_sphere_half_space"
    parameters = HALF_SPACE_PARAMETERS + (
        Parameter("constant_contact_force", 1e-5, 0.0, 1.0, "m^2",
                  "cf: added to delta^2 (m^2) and to the squared slip speed (m^2/s^2) so that the force and "
                  "its derivatives never vanish (OpenSim's doc says N)", vary=False),
        Parameter("hertz_smoothing", 300.0, 0.0, 1e6, "1/m",
                  "b_d: steepness of the tanh switching the Hertz force on around delta = 0", vary=False),
        Parameter("hunt_crossley_smoothing", 50.0, 0.0, 1e6, "s/m",
                  "b_v: steepness of the tanh switching the damped force off at v_n = -2 / (3 c)", vary=False),
    )

    def normal_law(self, depth, rate, p):
        cf = p["constant_contact_force"]
        c = asarray(p["dissipation"])
        fh_scale = hertz_coefficient(p["stiffness"], p["radius"]) * smooth_step(p["hertz_smoothing"] * depth)
        xp = backend_of(depth, rate, c)
        f = hunt_crossley_normal(xp.sqrt(depth * depth + cf), rate, fh_scale, 1.5, 1.5 * c)
        damped = value(c) > 0.0
        c_safe = xp.where(damped, c, 1.0)
        switch = xp.where(damped, smooth_step(p["hunt_crossley_smoothing"] * (rate + 2.0 / (3.0 * c_safe))), 1.0)
        return f * switch

    def slip_smoothing(self, p):
        return p["constant_contact_force"]
