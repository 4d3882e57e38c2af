"""Volumetric sphere contact: linear (Eq. 4.5-4.8) and hyper-volumetric (Eq. 4.9-4.15)."""
from __future__ import annotations

from ..backend import backend_of
from ..components import Parameter
from .sphere import FRICTION_PARAMETERS, OFFSET_PARAMETERS, SphereContact, cap_centroid_depth, cap_volume


class Volumetric(SphereContact):
    """Linear volumetric sphere (elastic foundation, Boos & McPhee), Eq. 4.5-4.8.

    ``f_n = k_V V (1 + a_V v_cn)`` with ``V`` the closed-form volume of the
    spherical cap below the ground (:func:`cap_volume`), ``v_cn`` the
    compression speed of the cap's centroid, acting at that centroid.  Friction
    Eq. 4.16-4.17 uses the tangential velocity of the body point at the centroid.
    Defaults and bounds: Table 4.3 (heel).
    """

    family = "volumetric"
    radius_name = "R"
    stiffness_name = "k_v"
    parameters = (
        Parameter("k_v", 2.21e6, 0.0, 1e12, "N/m^3", "foundation stiffness k_V of Eq. 4.8"),
        Parameter("a_v", 1.2, 0.0, 1e3, "s/m", "pseudo-damping a_V of Eq. 4.8"),
        Parameter("R", 0.051, 0.001, 0.055, "m", "sphere radius R_V"),
    ) + FRICTION_PARAMETERS + OFFSET_PARAMETERS

    def normal_law(self, delta_s, rate, p):
        R = p["R"]
        V = cap_volume(delta_s, R)
        fn = p["k_v"] * V * (1.0 + p["a_v"] * rate)
        return fn, V, cap_centroid_depth(delta_s, R)


class HyperVolumetric(SphereContact):
    """Hyper-volumetric sphere (hyper-elastic foundation), Eq. 4.9-4.15.

    ``f_n = k_h V^H + a_h V v_cn`` (Eq. 4.15): nonlinear stiffness through the
    hypervolume ``V_h = c_v(V) V = e^{a0} V^H`` (Eq. 4.10-4.13) and a linear
    damping term, at the centroid of the penetrating cap.  Units: ``k_h`` in
    N/m^(3H), ``a_h`` in N s/m^4.  Defaults and bounds: Table 4.4 (heel).
    """

    family = "hypervolumetric"
    radius_name = "R"
    stiffness_name = "k_h"
    parameters = (
        Parameter("k_h", 8.0e5, 0.0, 1e12, "N/m^(3H)", "hyper-volumetric pseudo-stiffness k_h, Eq. 4.13"),
        Parameter("a_h", 5.0e6, 0.0, 1e10, "N s/m^4", "damping a_h = k_V a_V, Eq. 4.15"),
        Parameter("R", 0.050, 0.001, 0.055, "m", "sphere radius R_V"),
        Parameter("H", 0.74, 0.1, 10.0, "", "hypervolume exponent H = 1 + a_1, Eq. 4.13"),
    ) + FRICTION_PARAMETERS + OFFSET_PARAMETERS

    def normal_law(self, delta_s, rate, p):
        R = p["R"]
        V = cap_volume(delta_s, R)
        xp = backend_of(V, rate, p["H"])
        Vp = xp.maximum(V, 1e-300)
        fn = p["k_h"] * xp.exp(p["H"] * xp.log(Vp)) + p["a_h"] * V * rate
        return fn, V, cap_centroid_depth(delta_s, R)
