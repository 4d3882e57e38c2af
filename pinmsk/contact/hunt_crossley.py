"""Hunt-Crossley contact: the law (:func:`hunt_crossley_normal`), the thesis's point contact (Eq. 4.4)
and OpenSim's HuntCrossleyForce between a sphere and a half space."""
from __future__ import annotations

import numpy as np

from ..backend import backend_of
from ..components import Parameter
from .dual import asarray
from .half_space import HALF_SPACE_PARAMETERS, HalfSpaceContact, hertz_coefficient
from .sphere import FRICTION_PARAMETERS, OFFSET_PARAMETERS, SphereContact


def hunt_crossley_normal(depth, rate, stiffness, exponent, damping):
    """Hunt & Crossley (1975): ``k x^n (1 + a v)`` for the penetration ``x >= 0`` (m) and its rate
    ``v`` (m/s, + compressing): thesis Eq. 4.4 (``k_s, n_s, a_s``), and Simbody's Hertz contact
    (``n = 3/2``, ``k = 4/3 k_e sqrt(R k_e)``, ``a = 3/2 c``) in OpenSim's HuntCrossleyForce and
    SmoothSphereHalfSpaceForce."""
    return stiffness * backend_of(depth, exponent).power(asarray(depth), exponent) * (1.0 + damping * rate)


class HuntCrossley(SphereContact):
    """Nonlinear spring with Hunt-Crossley damping between a body site and the ground, Eq. 4.4.

    ``f_n = k_s |L - L0|^n_s (1 + a_s v_n)`` for ``L <= L0`` and 0 otherwise,
    where ``L`` is the site's height above the ground (the spring hangs
    vertically from the site), ``L0`` its rest length and ``v_n = -dL/dt`` the
    compression speed.  ``L0 - L`` enters through the smooth positive part
    (see :mod:`pinmsk.contact.sphere`), which keeps the law C1 even for
    ``n_s < 1``.  The force acts at the spring's foot on the ground, below the
    site.  Friction: Eq. 4.16-4.17 on the slip of that point.
    Defaults and bounds: Table 4.2 (heel); pass ``bounds={"L0": (lo, hi)}`` for other sites.
    """

    family = "hunt_crossley"
    radius_name = "L0"
    stiffness_name = "k_s"
    parameters = (
        Parameter("k_s", 1.2e4, 0.0, 1e9, "N/m^n", "stiffness k_s of Eq. 4.4"),
        Parameter("n_s", 0.95, 0.1, 10.0, "", "nonlinearity exponent n_s of Eq. 4.4"),
        Parameter("a_s", 64.6, 0.0, 1e5, "s/m", "pseudo-damping a_s of Eq. 4.4"),
        Parameter("L0", 0.052, 0.001, 0.055, "m", "rest length L_0 of Eq. 4.4"),
    ) + FRICTION_PARAMETERS + OFFSET_PARAMETERS

    def normal_law(self, delta_s, rate, p):
        fn = hunt_crossley_normal(delta_s, rate, p["k_s"], p["n_s"], p["a_s"])
        zbar = p["L0"] - delta_s  # from the site down to the ground
        return fn, (0.0 * delta_s if backend_of(delta_s).symbolic else np.zeros_like(delta_s)), zbar


class HuntCrossleyForce(HalfSpaceContact):
    """OpenSim's ``HuntCrossleyForce`` between a ContactSphere and a ContactHalfSpace, as Simbody's
    ``HuntCrossleyForce`` computes it (Hunt & Crossley 1975 on Hertz contact; friction of M. Hollars;
    Sherman, Seth & Delp 2011), for one sphere whose ContactParameters are the half space's too:

        f_n = max(0, 4/3 k sqrt(R k) x^(3/2) (1 + 3/2 c v_n)),   k = E^(2/3) / 2,

    ``x = max(0, delta)`` the indentation, ``v_n`` the compression rate, at the contact point
    midway through the overlap (geometry: :class:`~pinmsk.contact.half_space.HalfSpaceContact`), and
    :func:`~pinmsk.contact.friction.hollars_friction` on the unsmoothed slip.  Exactly Simbody's
    law, so not smooth: the force and its first derivative are continuous at first touch
    (``x^(3/2)``), the ``max`` leaves a kink where the damping factor turns negative (Simbody returns
    no force there), and the friction has one at the transition velocity.  For gradient-based
    optimisation use :class:`~pinmsk.contact.SmoothSphereHalfSpaceForce`.  Unlike thesis Eq. 4.4
    (:class:`HuntCrossley`, a vertical spring under a site), the law acts between a sphere and a
    half space of any orientation.  Parameters: OpenSim's ContactParameters (``stiffness``,
    ``dissipation``, the friction coefficients) and the force's ``transition_velocity``.
    """

    family = "hunt_crossley_force"
    parameters = HALF_SPACE_PARAMETERS

    def normal_law(self, depth, rate, p):
        xp = backend_of(depth, rate)
        x = xp.maximum(depth, 0.0)
        f = hunt_crossley_normal(x, rate, hertz_coefficient(p["stiffness"], p["radius"]), 1.5,
                                 1.5 * asarray(p["dissipation"]))
        return xp.maximum(f, 0.0)
