"""Hunt-Crossley point contact (thesis Eq. 4.4)."""
from __future__ import annotations

import numpy as np

from ..components import Parameter
from .sphere import FRICTION_PARAMETERS, OFFSET_PARAMETERS, SphereContact


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
        fn = p["k_s"] * np.power(delta_s, p["n_s"]) * (1.0 + p["a_s"] * rate)
        zbar = p["L0"] - delta_s  # from the site down to the ground
        return fn, np.zeros_like(delta_s), zbar
