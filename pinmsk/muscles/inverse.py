"""Inverse muscle model: activation and excitation from muscle-tendon force (thesis Fig. 5.6, Eq. 5.2-5.4).

Given the muscle-tendon force ``F_mt`` with its time derivatives and the
muscle-tendon length ``l_mt`` with its derivatives (from the multibody
kinematics), the flow of Fig. 5.6 is:

1. tendon: ``eps = f_t^-1(F_mt / F_max)``, ``l_t = l_slack (1 + eps)``;
   ``l_t' = l_slack F_mt' / (F_max f_t'(eps))`` and
   ``l_t'' = l_slack (F_mt''/F_max - f_t''(eps) eps'^2) / f_t'(eps)``;
2. pennation geometry: ``x = l_mt - l_t``, ``l_ce = sqrt(x^2 + h^2)``,
   ``v_ce = x x'/l_ce``, ``a_ce = (x'^2 + x x'' - v_ce^2)/l_ce``;
3. contractile force: ``f_ce = F_mt/(F_max cos(alpha)) - f_pe(l_ce)``, and its
   rate from ``d/dt (F_mt l_ce / x)`` and ``f_pe' v_ce``;
4. activation: solve ``f_ce = f(l_ce, v_ce, a)`` (Eq. 5.2) for ``a``;
5. activation rate, Eq. 5.4:
   ``a' = (f_ce' - df/dl_ce l_ce' - df/dv_ce l_ce'') / (df/da)`` with analytic partials;
6. excitation from ``(a, a')`` by inverse activation dynamics (Eq. A.5).

The fiber acceleration in step 5 needs the tendon acceleration, hence
``F_mt''`` (the thesis lists ``f_tm, f_tm', f_tm''`` as inputs).  ``ddF_mt``
defaults to 0, which neglects the tendon's share of the fiber acceleration;
pass the true value for exact activation rates and excitations.  ``a``,
``l_ce`` and ``v_ce`` do not depend on it.

Where the demanded contractile force is not positive (the tendon force is
below the passive force, or the tendon is slack) no activation produces it:
``a``, ``a'`` and ``u`` are set to 0 there.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ._common import check_finite
from .activation import TAU_FALL, TAU_RISE, excitation_from_activation
from .nagano_gerritsen import (ng_activation_from_force, ng_fiber_force_partials, ng_force_length,
                               ng_force_length_derivative)
from .pennation import check_along_positive, pennation_height
from .tendon import (TENDON_STRAIN0, thelen_tendon_stiffness, thelen_tendon_stiffness_derivative,
                     thelen_tendon_strain, winters_tendon_stiffness, winters_tendon_stiffness_derivative,
                     winters_tendon_strain)
from .thelen2003 import (thelen_activation_from_force, thelen_active_force_length,
                         thelen_active_force_length_derivative, thelen_fiber_force_partials,
                         thelen_passive_force_length, thelen_passive_force_length_derivative)

__all__ = ["inverse_muscle", "inverse_thelen2003", "inverse_nagano_gerritsen"]


def inverse_muscle(F_mt, dF_mt, l_mt, dl_mt, ddl_mt, *, ddF_mt=0.0, f_max, l_opt, l_slack,
                   height, v_scale,
                   tendon_strain: Callable, tendon_stiffness: Callable,
                   tendon_stiffness_derivative: Callable,
                   force_length: Callable, force_partials: Callable,
                   activation_from_force: Callable, passive: Callable | None = None,
                   tau_rise: float = TAU_RISE, tau_fall: float = TAU_FALL,
                   names: Sequence[str] | None = None, fiber_floor=None) -> dict:
    """Generic inverse Hill muscle of thesis Fig. 5.6 (see the module docstring).

    Model pieces (all normalized): ``tendon_strain(f)``, ``tendon_stiffness(eps)``
    and ``tendon_stiffness_derivative(eps)``; ``force_length(l_norm) -> (f_isom, df_isom)``;
    ``force_partials(v_norm, a, f_isom) -> (f, df/dv_norm, df/da, df/df_isom)``;
    ``activation_from_force(f_ce, f_isom, v_norm) -> a``;
    ``passive(l_norm) -> (f_pe, df_pe)`` or None.  ``v_norm = v_ce / v_scale``.
    ``fiber_floor`` (m, per muscle): where the unit is shorter than its tendon there is no
    fiber state and this raises, unless a floor is given: the fiber's projection ``x`` is
    then replaced by the smooth ``x_f (log(1 + exp(x / x_f)) + 1e-6 sigmoid(-x / x_f))``
    (``x`` itself where ``x > 30 x_f``), so that an optimizer's wild iterate yields a finite,
    grossly infeasible state instead of an exception.

    Returns a dict of ``(N, m)`` arrays: ``a, adot, u`` (activation, its rate,
    excitation), ``l_ce, v_ce, dv_ce`` (fiber length, velocity, acceleration)
    and ``l_t`` (tendon length).
    """
    check_finite(names, F_mt=F_mt, dF_mt=dF_mt, ddF_mt=ddF_mt, l_mt=l_mt, dl_mt=dl_mt,
                 ddl_mt=ddl_mt)
    F = np.asarray(F_mt, dtype=float)
    f_max = np.asarray(f_max, dtype=float)
    l_opt = np.asarray(l_opt, dtype=float)
    l_slack = np.asarray(l_slack, dtype=float)
    ft = F / f_max
    dft = np.asarray(dF_mt, dtype=float) / f_max
    ddft = np.asarray(ddF_mt, dtype=float) / f_max

    # 1. tendon (Eq. A.6 or A.10 inverted)
    eps = tendon_strain(ft)
    k1 = tendon_stiffness(eps)
    k2 = tendon_stiffness_derivative(eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        # A slack tendon (k1 = 0, zero force) has no defined rate; it stays at slack length.
        deps = np.where(k1 > 0, dft / k1, 0.0)
        ddeps = np.where(k1 > 0, (ddft - k2 * deps * deps) / k1, 0.0)
    l_t = l_slack * (1.0 + eps)

    # 2. pennation geometry, differentiated twice
    x = np.asarray(l_mt, dtype=float) - l_t
    dx = np.asarray(dl_mt, dtype=float) - l_slack * deps
    ddx = np.asarray(ddl_mt, dtype=float) - l_slack * ddeps
    if fiber_floor is not None:
        # x_f g(x / x_f), g(z) = softplus(z) + 1e-6 sigmoid(-z): smooth, never below
        # 1e-6 x_f, and x itself (to 1e-13 x_f) where z > 30, where x is taken as is
        z = x / fiber_floor
        sig = 0.5 * (1.0 + np.tanh(0.5 * z))
        s1 = sig * (1.0 - sig)
        g1 = sig - 1e-6 * s1
        g2 = s1 - 1e-6 * s1 * (1.0 - 2.0 * sig)
        far = z > 30.0
        x = np.where(far, x, fiber_floor * (np.logaddexp(0.0, z) + 1e-6 * (1.0 - sig)))
        ddx = np.where(far, ddx, g1 * ddx + g2 / fiber_floor * dx * dx)
        dx = np.where(far, dx, g1 * dx)
    check_along_positive(x, l_mt, names, what="inverse muscle model")
    h = np.asarray(height, dtype=float)
    l_ce = np.sqrt(x * x + h * h)
    v_ce = x * dx / l_ce
    dv_ce = (dx * dx + x * ddx - v_ce * v_ce) / l_ce

    # 3. contractile-element force and its rate: F/cos(alpha) = F l_ce / x
    l_norm = l_ce / l_opt
    sec = l_ce / x
    dsec = (v_ce * x - l_ce * dx) / (x * x)
    f_ce = ft * sec
    df_ce = dft * sec + ft * dsec
    if passive is not None:
        fpe, dfpe = passive(l_norm)
        f_ce = f_ce - fpe
        df_ce = df_ce - dfpe * (v_ce / l_opt)

    # 4. activation (Eq. 5.2 solved for a)
    v_norm = v_ce / v_scale
    fi, dfi = force_length(l_norm)
    a = activation_from_force(f_ce, fi, v_norm)

    # 5. activation rate (Eq. 5.4)
    _, df_dv, df_da, df_dfi = force_partials(v_norm, a, fi)
    df_dl = df_dfi * dfi
    active = a > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        adot = (df_ce - df_dl * (v_ce / l_opt) - df_dv * (dv_ce / v_scale)) / df_da
    adot = np.where(active, adot, 0.0)

    # 6. excitation (Eq. A.5)
    u = np.where(active, excitation_from_activation(a, adot, tau_rise=tau_rise,
                                                    tau_fall=tau_fall), 0.0)
    return {"a": a, "adot": adot, "u": u, "l_ce": l_ce, "v_ce": v_ce, "dv_ce": dv_ce,
            "l_t": l_t}


def inverse_thelen2003(F_mt, dF_mt, l_mt, dl_mt, ddl_mt, *, ddF_mt=0.0, f_max, l_opt, l_slack,
                       pennation, v_max=None, tendon_strain0: float = TENDON_STRAIN0,
                       tau_rise: float = TAU_RISE, tau_fall: float = TAU_FALL,
                       names: Sequence[str] | None = None, fv_smooth: float = 0.0,
                       fiber_floor=None) -> dict:
    """Inverse Thelen 2003 muscle (compliant Thelen tendon + parallel element), Fig. 5.6 / Eq. 5.2-5.4.

    Activation from Eq. A.9 by vectorised Newton (the activation scaling of
    v_max makes it nonlinear in ``a``).  See :func:`inverse_muscle`.  ``fv_smooth``
    blends the force-velocity slope jump at zero velocity (width in ``v/v_max``
    units, :func:`~pinmsk.muscles.thelen2003.thelen_fiber_force_partials`): without
    it the excitation jumps wherever a fiber reverses, because Eq. 5.4 contains
    ``df/dv``; dynamic optimization of the IFM/IFT designs needs it continuous.
    ``fiber_floor``: see :func:`inverse_muscle`.
    """
    l_opt = np.asarray(l_opt, dtype=float)
    v_max = 10.0 * l_opt if v_max is None else np.asarray(v_max, dtype=float)
    return inverse_muscle(
        F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=ddF_mt, f_max=f_max, l_opt=l_opt,
        l_slack=l_slack, height=pennation_height(l_opt, pennation), v_scale=v_max,
        tendon_strain=lambda f: thelen_tendon_strain(f, strain0=tendon_strain0),
        tendon_stiffness=lambda e: thelen_tendon_stiffness(e, strain0=tendon_strain0),
        tendon_stiffness_derivative=lambda e: thelen_tendon_stiffness_derivative(
            e, strain0=tendon_strain0),
        force_length=lambda l: (thelen_active_force_length(l),
                                thelen_active_force_length_derivative(l)),
        force_partials=lambda v, a, fi: thelen_fiber_force_partials(v, a, fi, smooth=fv_smooth),
        activation_from_force=lambda f, fi, v: thelen_activation_from_force(
            f, fi, v, names=names, smooth=fv_smooth),
        passive=lambda l: (thelen_passive_force_length(l),
                           thelen_passive_force_length_derivative(l)),
        tau_rise=tau_rise, tau_fall=tau_fall, names=names, fiber_floor=fiber_floor)


def inverse_nagano_gerritsen(F_mt, dF_mt, l_mt, dl_mt, ddl_mt, *, ddF_mt=0.0, f_max, l_opt,
                             l_slack, pennation, width, tendon_strain0: float = TENDON_STRAIN0,
                             tau_rise: float = TAU_RISE, tau_fall: float = TAU_FALL,
                             names: Sequence[str] | None = None) -> dict:
    """Inverse Nagano-Gerritsen muscle with the Winters tendon, no parallel element (thesis Sec. 5.1).

    Activation in closed form (linear above a = 0.3, a quadratic below).
    See :func:`inverse_muscle`.
    """
    l_opt = np.asarray(l_opt, dtype=float)
    width = np.asarray(width, dtype=float)
    return inverse_muscle(
        F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=ddF_mt, f_max=f_max, l_opt=l_opt,
        l_slack=l_slack, height=pennation_height(l_opt, pennation), v_scale=l_opt,
        tendon_strain=lambda f: winters_tendon_strain(f, strain0=tendon_strain0),
        tendon_stiffness=lambda e: winters_tendon_stiffness(e, strain0=tendon_strain0),
        tendon_stiffness_derivative=lambda e: winters_tendon_stiffness_derivative(
            e, strain0=tendon_strain0),
        force_length=lambda l: (ng_force_length(l, width), ng_force_length_derivative(l, width)),
        force_partials=ng_fiber_force_partials,
        activation_from_force=ng_activation_from_force,
        passive=None, tau_rise=tau_rise, tau_fall=tau_fall, names=names)
