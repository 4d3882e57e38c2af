"""Muscle-tendon model objects: per-muscle parameters bound to the pure muscle functions.

:class:`Thelen2003` (thesis App. A.3: Thelen tendon, parallel element,
Eq. A.6-A.9) and :class:`NaganoGerritsen` (App. A.4-A.5: Winters tendon,
Eq. A.10-A.14, no parallel element) share one interface:

- ``fiber_kinematics_rigid(l_mt, v_mt) -> (l_ce, v_ce)``
- ``equilibrium(l_mt, a, v_mt=None) -> {"l_ce", "v_ce", "force"}`` (compliant tendon)
- ``force(a, l_mt, v_mt, tendon="rigid"|"compliant") -> F`` (N)
- ``force_limits(l_mt, v_mt) -> (F_active, F_passive)`` (rigid tendon; ``F = a F_active + F_passive``)
- ``contraction_rate(l_ce, l_mt, a) -> v_ce`` (compliant-tendon ODE, thesis Eq. 3.9)
- ``inverse(F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=0.0) -> dict`` (thesis Fig. 5.6)
- ``activation_rate(u, a, smooth=0)``, ``excitation(a, adot)``, ``activation(t, u, a0=None)`` (App. A.2)

and the laws of the optimal-control engine, written once for numpy and CasADi
(:mod:`pinmsk.backend`; no input checks, the checked methods above call the same math):

- ``rigid_force(a, l_mt, v_mt) -> F`` (N), ``fiber_rigid(l_mt, v_mt) -> (l_ce, v_ce, cos_alpha)``;
- De Groote et al. (2016)'s implicit compliant tendon, state ``f_t = F_T/F_max`` and control
  ``df_t``: ``fiber_from_tendon(f_t, df_t, l_mt, v_mt) -> (l_ce, v_ce, cos_alpha)``,
  ``implicit_residual(a, f_t, df_t, l_mt, v_mt)`` (zero at the Hill equilibrium),
  ``tendon_force_bounds() -> (lo, hi)``, ``equilibrium_tendon_force(a, l_mt, v_mt=None)`` (numpy);
- ``fiber_forces(a, l_ce, v_ce) -> {"f_isom", "f_v", "f_pe", "f_damping", "f_active", "f_fiber"}``.

Millard2012's quintic Bezier curves are numpy only: it refuses these by name.

:class:`DeGroote2016` and :class:`Millard2012` (OpenSim's DeGrooteFregly2016Muscle
and Millard2012EquilibriumMuscle curves, with fiber damping) share the
rigid-tendon part of it (``fiber_kinematics_rigid``, ``force``,
``force_limits``), ``equilibrium`` and ``tendon_force``; they have no
contraction dynamics or inverse model (those raise ModelError by name).

Inputs are time-first ``(N, m)`` arrays (or ``(m,)`` for one frame) in SI
units; parameters are ``(m,)``.  The objects are immutable: constructors copy
the parameter arrays and mark them read-only, and attributes cannot be set.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..backend import backend_of
from ..errors import ModelError, TrialError
from . import millard2012 as _millard
from ._common import check_finite, locate, muscle_parameter, n_muscles, where_first
from ._solve import compliant_equilibrium
from .activation import (TAU_FALL, TAU_RISE, activation_from_excitation, activation_rate,
                         excitation_from_activation)
from .degroote2016 import (degroote_active_force_length, degroote_active_force_length_derivative,
                           degroote_force_velocity, degroote_passive_force_length,
                           degroote_passive_force_length_derivative, degroote_tendon_force,
                           degroote_tendon_force_derivative, degroote_tendon_length)
from .inverse import inverse_nagano_gerritsen, inverse_thelen2003
from .nagano_gerritsen import ng_contraction_rate, ng_equilibrium, ng_fiber_force, ng_force_length
from .pennation import check_along_positive, pennation_height
from .tendon import (TENDON_STRAIN0, thelen_tendon_force, thelen_tendon_stiffness, thelen_tendon_strain,
                     winters_tendon_force, winters_tendon_stiffness, winters_tendon_strain)
from .thelen2003 import (_speed_scale, thelen_active_force_length, thelen_active_force_length_derivative,
                         thelen_contraction_rate, thelen_equilibrium, thelen_fiber_force, thelen_force_velocity,
                         thelen_passive_force_length, thelen_passive_force_length_derivative)

__all__ = ["MUSCLE_MODELS", "MUSCLE_PARAMETERS", "DeGroote2016", "Millard2012", "MuscleParameter",
           "NaganoGerritsen", "Thelen2003", "Thelen2003OpenSim"]

_TENDONS = ("rigid", "compliant")


@dataclass(frozen=True)
class MuscleParameter:
    """The declaration of one per-muscle parameter: unit, meaning and valid range.

    ``low``/``high`` bound it (``low_open``/``high_open``: the bound itself is
    excluded); :meth:`check` is the one validation of muscle parameters (the
    muscle models run it on construction).
    """

    name: str
    unit: str
    doc: str
    low: float = 0.0
    high: float = math.inf
    low_open: bool = True
    high_open: bool = False

    def check(self, value, m: int, names=None) -> np.ndarray:
        """``value`` as a read-only (m,) array, or ModelError naming the first bad muscle."""
        return muscle_parameter(value, self.name, m, names=names, positive=self.low == 0.0 and self.low_open,
                                low=None if self.low == 0.0 and self.low_open else self.low,
                                high=None if math.isinf(self.high) else self.high, high_open=self.high_open)


#: Every per-muscle parameter of the muscle-tendon models, by name (SI units).
MUSCLE_PARAMETERS = {p.name: p for p in (
    MuscleParameter("f_max", "N", "maximum isometric force"),
    MuscleParameter("l_opt", "m", "optimal fiber length"),
    MuscleParameter("l_slack", "m", "tendon slack length"),
    MuscleParameter("pennation", "rad", "pennation angle at optimal fiber length", 0.0, math.pi / 2,
                    low_open=False, high_open=True),
    MuscleParameter("v_max", "m/s", "maximum shortening velocity (default 10 l_opt)"),
    MuscleParameter("width", "", "force-length half-width in units of l_opt (Nagano & Gerritsen)"),
    MuscleParameter("fast_fraction", "", "fraction of fast-twitch fibers (energy models)", 0.0, 1.0,
                    low_open=False),
    MuscleParameter("volume", "m^3", "muscle volume (energy models, PCSA weights)"),
    # -- DeGroote 2016 and Millard 2012 (OpenSim property in brackets) ----------
    MuscleParameter("damping", "", "fiber damping: damping force = damping F_max v_ce / v_max "
                    "[fiber_damping]", 0.0, low_open=False),
    MuscleParameter("tendon_strain", "", "tendon strain at one normalized force "
                    "[tendon_strain_at_one_norm_force; TendonForceLengthCurve strain_at_one_norm_force]"),
    MuscleParameter("passive_strain", "", "fiber strain (from l_opt) at one normalized passive force "
                    "[passive_fiber_strain_at_one_norm_force; FiberForceLengthCurve "
                    "strain_at_one_norm_force]"),
    MuscleParameter("width_scale", "", "active force-length width scale (De Groote) "
                    "[active_force_width_scale]", 1.0, low_open=False),
    MuscleParameter("passive_scale", "", "passive fiber force factor, 0 = ignore_passive_fiber_force "
                    "(De Groote)", 0.0, 1.0, low_open=False),
    MuscleParameter("max_pennation", "rad", "maximum pennation angle: the fiber-length floor (Millard) "
                    "[maximum_pennation_angle]", 0.0, math.pi / 2, low_open=False),
    MuscleParameter("min_norm_active_fiber_length", "", "Millard active force-length: start of the "
                    "steep ascending limb, in l_opt [ActiveForceLengthCurve]", 0.0, low_open=False),
    MuscleParameter("transition_norm_fiber_length", "", "Millard active force-length: start of the "
                    "shallow ascending limb, in l_opt [ActiveForceLengthCurve]", 0.0, 1.0, high_open=True),
    MuscleParameter("max_norm_active_fiber_length", "", "Millard active force-length: end of the "
                    "descending limb, in l_opt [ActiveForceLengthCurve]", 1.0, low_open=False),
    MuscleParameter("shallow_ascending_slope", "", "Millard active force-length: slope of the shallow "
                    "ascending limb [ActiveForceLengthCurve]", 0.0, low_open=False),
    MuscleParameter("active_minimum_value", "", "Millard active force-length: value outside the "
                    "active range [ActiveForceLengthCurve minimum_value]", 0.0, 1.0, low_open=False,
                    high_open=True),
    MuscleParameter("passive_strain_at_zero_force", "", "Millard passive force-length: fiber strain "
                    "where the passive force starts [FiberForceLengthCurve strain_at_zero_force]",
                    -1.0, low_open=True),
    MuscleParameter("passive_stiffness_at_low_force", "", "Millard passive force-length: slope at low "
                    "force [FiberForceLengthCurve stiffness_at_low_force]"),
    MuscleParameter("passive_stiffness", "", "Millard passive force-length: slope at one normalized "
                    "force [FiberForceLengthCurve stiffness_at_one_norm_force]"),
    MuscleParameter("passive_curviness", "", "Millard passive force-length: curviness "
                    "[FiberForceLengthCurve curviness]", 0.0, 1.0, low_open=False),
    MuscleParameter("concentric_slope_at_vmax", "", "Millard force-velocity: slope at v = -v_max "
                    "[ForceVelocityCurve]", 0.0, 1.0, low_open=False, high_open=True),
    MuscleParameter("concentric_slope_near_vmax", "", "Millard force-velocity: slope near v = -v_max "
                    "[ForceVelocityCurve]", 0.0, 1.0),
    MuscleParameter("isometric_slope", "", "Millard force-velocity: slope at v = 0 [ForceVelocityCurve]",
                    1.0, low_open=True),
    MuscleParameter("eccentric_slope_at_vmax", "", "Millard force-velocity: slope at v = +v_max "
                    "[ForceVelocityCurve]", 0.0, low_open=False),
    MuscleParameter("eccentric_slope_near_vmax", "", "Millard force-velocity: slope near v = +v_max "
                    "[ForceVelocityCurve]", 0.0, low_open=False),
    MuscleParameter("max_eccentric_velocity_force_multiplier", "", "Millard force-velocity: value at "
                    "v = +v_max [ForceVelocityCurve]", 1.0, low_open=True),
    MuscleParameter("concentric_curviness", "", "Millard force-velocity: concentric curviness "
                    "[ForceVelocityCurve]", 0.0, 1.0, low_open=False),
    MuscleParameter("eccentric_curviness", "", "Millard force-velocity: eccentric curviness "
                    "[ForceVelocityCurve]", 0.0, 1.0, low_open=False),
    MuscleParameter("tendon_stiffness", "", "Millard tendon: slope at one normalized force "
                    "[TendonForceLengthCurve stiffness_at_one_norm_force]"),
    MuscleParameter("tendon_toe_force", "", "Millard tendon: normalized force at the end of the toe "
                    "[TendonForceLengthCurve norm_force_at_toe_end]", 0.0, 1.0, high_open=True),
    MuscleParameter("tendon_curviness", "", "Millard tendon: curviness [TendonForceLengthCurve curviness]",
                    0.0, 1.0, low_open=False),
    # -- Thelen 2003 with OpenSim's per-muscle curve constants ------------------
    MuscleParameter("active_shape", "", "Thelen active force-length shape factor gamma [KshapeActive]"),
    MuscleParameter("passive_shape", "", "Thelen passive force-length shape factor k_PE [KshapePassive]"),
    MuscleParameter("fv_shape", "", "Thelen force-velocity shape factor A_f [Af]"),
    MuscleParameter("eccentric_force", "", "Thelen maximum eccentric force multiplier f_hat [Flen]",
                    1.0, low_open=True),
    MuscleParameter("fv_extrapolation", "", "Thelen force-velocity: fraction of f_hat where the linear "
                    "tail starts [fv_linear_extrap_threshold]", 0.0, 1.0, high_open=True),
)}


class _MuscleModel:
    """Shared machinery: parameter validation, immutability, input checks, rigid kinematics."""

    #: the per-muscle parameters of the model's mechanics (what ``pinmsk.Model.parameters`` lists)
    mechanical_parameters: tuple[str, ...] = ("f_max", "l_opt", "l_slack", "pennation")

    def _setup(self, *, names, f_max, l_opt, l_slack, pennation, fast_fraction, volume,
               tendon_strain0, tau_rise, tau_fall, **extra) -> None:
        m = n_muscles(f_max, l_opt, l_slack, pennation, fast_fraction, volume, *extra.values())
        if names is not None:
            names = tuple(str(n) for n in names)
            if len(names) != m and m != 1:
                raise ModelError(f"{len(names)} names for {m} muscles")
            m = len(names)
        put = object.__setattr__
        put(self, "names", names)
        put(self, "n", m)
        given = dict(f_max=f_max, l_opt=l_opt, l_slack=l_slack, pennation=pennation, **extra,
                     fast_fraction=fast_fraction, volume=volume)
        for key, value in given.items():
            optional = key in ("fast_fraction", "volume")
            put(self, key, None if optional and value is None else MUSCLE_PARAMETERS[key].check(value, m, names))
        # models with a per-muscle tendon_strain parameter pass tendon_strain0=None
        if tendon_strain0 is not None and not (tendon_strain0 > 0):
            raise ModelError(f"tendon_strain0 = {tendon_strain0} must be > 0")
        if not (0 < tau_rise and 0 < tau_fall):
            raise ModelError(f"activation time constants must be > 0 (tau_rise={tau_rise}, "
                             f"tau_fall={tau_fall})")
        put(self, "tendon_strain0", None if tendon_strain0 is None else float(tendon_strain0))
        put(self, "tau_rise", float(tau_rise))
        put(self, "tau_fall", float(tau_fall))
        h = pennation_height(self.l_opt, self.pennation)
        h.flags.writeable = False
        put(self, "height", h)

    # -- immutability / copying ------------------------------------------------
    def __setattr__(self, key, value):
        raise AttributeError(f"{type(self).__name__} is immutable; build a new one with "
                             f"replace({key}=...)")

    def __delattr__(self, key):
        raise AttributeError(f"{type(self).__name__} is immutable")

    def _kwargs(self) -> dict:
        raise NotImplementedError

    def replace(self, **changes):
        """A new model with some constructor arguments changed."""
        kw = self._kwargs()
        unknown = set(changes) - set(kw)
        if unknown:
            raise ModelError(f"unknown {type(self).__name__} parameter(s) {sorted(unknown)}; "
                             f"known: {sorted(kw)}")
        kw.update(changes)
        return type(self)(**kw)

    def __reduce__(self):
        return (_rebuild, (type(self), self._kwargs()))

    def __eq__(self, other):
        if type(other) is not type(self):
            return NotImplemented
        a, b = self._kwargs(), other._kwargs()
        return all(np.array_equal(a[k], b[k]) if isinstance(a[k], np.ndarray) else a[k] == b[k]
                   for k in a)

    __hash__ = None

    def __repr__(self) -> str:
        label = ", ".join(self.names) if self.names else f"{self.n} muscles"
        return f"{type(self).__name__}({label})"

    # -- checks ------------------------------------------------------------------
    def _check(self, **arrays):
        check_finite(self.names, **arrays)

    def _taut(self, l_mt):
        """``(l_mt', slack)``: frames where the unit is not longer than its tendon are
        slack (a rigid tendon cannot transmit force there); ``l_mt'`` moves them just
        past the slack length so the fiber geometry stays defined."""
        l_mt = np.asarray(l_mt, dtype=float)
        slack = l_mt - self.l_slack <= 1e-9 * self.l_opt
        if slack.any():
            l_mt = np.where(slack, self.l_slack + 1e-6 * self.l_opt, l_mt)
        return l_mt, slack

    def _check_activation(self, a):
        a = np.asarray(a, dtype=float)
        if not (a >= 0).all():
            frame, muscle = where_first(~(a >= 0))
            raise TrialError(f"activation must be >= 0; got {a.min():.6g} at "
                             f"{locate(frame, muscle, self.names)}")
        return a

    # -- activation dynamics (thesis App. A.2) -----------------------------------
    def activation_rate(self, u, a, *, smooth: float = 0.0):
        """Winters & Stark activation rate (thesis Eq. A.2) with this model's time constants.

        Any backend (numpy or CasADi); ``smooth > 0`` blends the rise/fall switch with a
        tanh of that width (De Groote et al. 2016, Eq. 1-2), see
        :func:`pinmsk.muscles.activation.activation_rate`.
        """
        return activation_rate(u, a, tau_rise=self.tau_rise, tau_fall=self.tau_fall, smooth=smooth)

    def excitation(self, a, adot):
        """Excitation from activation and its rate, inverse activation dynamics (Eq. A.5)."""
        return excitation_from_activation(a, adot, tau_rise=self.tau_rise, tau_fall=self.tau_fall)

    def activation(self, t, u, a0=None):
        """Activation over time from sampled excitation ``u`` (N, m) (Eq. A.2, see
        :func:`pinmsk.muscles.activation.activation_from_excitation`)."""
        return activation_from_excitation(t, u, a0, tau_rise=self.tau_rise, tau_fall=self.tau_fall)

    # -- kinematics ------------------------------------------------------------
    def fiber_rigid(self, l_mt, v_mt):
        """``(l_ce, v_ce, cos_alpha)`` with an inextensible tendon; any backend, no input checks.

        ``x = l_mt - l_slack``, ``l_ce = sqrt(x^2 + h^2)`` (constant-thickness pennation),
        ``v_ce = v_mt cos(alpha)``; needs ``x > 0`` (checked by the numpy wrappers).
        """
        xp = backend_of(l_mt, v_mt)
        return self._fiber_from_along(xp, xp.asarray(l_mt) - self.l_slack, xp.asarray(v_mt))

    def _fiber_from_along(self, xp, x, x_rate):
        """``(l_ce, v_ce, cos_alpha)`` from the fiber's projection ``x`` on the line of action and
        its rate: ``l_ce = sqrt(x^2 + h^2)``, ``v_ce = x x'/l_ce = x' cos(alpha)`` (constant thickness)."""
        l_ce = xp.sqrt(x * x + self.height * self.height)
        cos = x / l_ce
        return l_ce, x_rate * cos, cos

    def _rigid(self, l_mt, v_mt):
        """``(l_ce, v_ce, cos_alpha)`` with an inextensible tendon (checked: the fiber must fit)."""
        l_mt = np.asarray(l_mt, dtype=float)
        check_along_positive(l_mt - self.l_slack, l_mt, self.names,
                             what=f"{type(self).__name__} rigid tendon")
        return self.fiber_rigid(l_mt, v_mt)

    def _rigid_force(self, a, l_mt, v_mt):
        """:meth:`rigid_force` with the fiber-fits check of the numpy path."""
        l_mt = np.asarray(l_mt, dtype=float)
        check_along_positive(l_mt - self.l_slack, l_mt, self.names,
                             what=f"{type(self).__name__} rigid tendon")
        return self.rigid_force(a, l_mt, v_mt)

    def rigid_force(self, a, l_mt, v_mt):
        """Muscle-tendon force (N) with a rigid tendon at activation ``a``; any backend, no checks."""
        raise NotImplementedError

    # -- compliant tendon, implicit form (De Groote et al. 2016) ------------------
    #: ``(lo, hi)`` of the normalized tendon force state ``f_t`` (see :meth:`tendon_force_bounds`)
    _TENDON_FORCE_BOUNDS = (0.0, 5.0)

    def _tendon_curve(self, strain):
        """``(f_T, df_T/dstrain)`` at the tendon strain (any backend)."""
        raise NotImplementedError

    def _tendon_strain(self, force):
        """Tendon strain at a normalized tendon force (the inverse of :meth:`_tendon_curve`)."""
        raise NotImplementedError

    def _fiber_parts(self, a, l_ce, v_ce):
        """``(f_L, f_V, f_PE, f_D)``: normalized force-length, force-velocity (at activation ``a``),
        passive and damping forces of the fiber (any backend)."""
        raise NotImplementedError

    def _fiber_total(self, a, l_ce, v_ce):
        """Normalized fiber force ``a f_L f_V + f_PE + f_D`` (any backend)."""
        fl, fv, fpe, fd = self._fiber_parts(a, l_ce, v_ce)
        return a * fl * fv + fpe + fd

    def fiber_forces(self, a, l_ce, v_ce):
        """The fiber's forces as the metabolic models need them; any backend, no checks.

        Returns ``{"f_isom", "f_v", "f_pe", "f_damping", "f_active", "f_fiber"}``: the normalized
        active force-length factor ``f_L``, force-velocity factor ``f_V`` (at activation ``a``),
        passive and damping forces, then the active (contractile) fiber force
        ``F_max a f_L f_V`` and the total fiber force (N).
        """
        fl, fv, fpe, fd = self._fiber_parts(a, l_ce, v_ce)
        act = a * fl * fv
        return {"f_isom": fl, "f_v": fv, "f_pe": fpe, "f_damping": fd,
                "f_active": self.f_max * act, "f_fiber": self.f_max * (act + fpe + fd)}

    def tendon_force_bounds(self):
        """``(lo, hi)``: bounds of the normalized tendon force state ``f_t`` (``F_T / F_max``)."""
        return self._TENDON_FORCE_BOUNDS

    def fiber_from_tendon(self, f_t, df_t, l_mt, v_mt):
        """``(l_ce, v_ce, cos_alpha)`` from the normalized tendon force ``f_t`` and its rate ``df_t`` (1/s).

        De Groote et al. (2016)'s implicit compliant tendon: the tendon length from the
        inverse tendon curve, ``l_t = l_slack (1 + strain(f_t))``; the fiber from the
        constant-thickness pennation geometry, ``x = l_mt - l_t``, ``l_ce = sqrt(x^2 + h^2)``;
        its velocity from d/dt of the same geometry, ``v_ce = (v_mt - v_t) cos(alpha)`` with the
        tendon velocity ``v_t = l_slack df_t / (df_T/dstrain)``.  Any backend, no checks.
        """
        xp = backend_of(f_t, df_t, l_mt, v_mt)
        strain = self._tendon_strain(xp.asarray(f_t))
        stiffness = self._tendon_curve(strain)[1]
        v_t = self.l_slack * xp.asarray(df_t) / stiffness
        return self._fiber_from_along(xp, xp.asarray(l_mt) - self.l_slack * (1.0 + strain),
                                      xp.asarray(v_mt) - v_t)

    def implicit_residual(self, a, f_t, df_t, l_mt, v_mt):
        """Hill equilibrium residual ``(a f_L f_V + f_PE + f_D) cos(alpha) - f_t`` (dimensionless).

        The fiber state from :meth:`fiber_from_tendon`; zero when the fiber and the tendon
        carry the same force (De Groote et al. 2016's implicit contraction dynamics, with
        ``f_t`` a state and ``df_t`` a control).  Any backend, no checks.
        """
        l_ce, v_ce, cos = self.fiber_from_tendon(f_t, df_t, l_mt, v_mt)
        return self._fiber_total(a, l_ce, v_ce) * cos - f_t

    def equilibrium_tendon_force(self, a, l_mt, v_mt=None, *, tol: float = 1e-10):
        """Normalized tendon force ``f_t`` at the compliant equilibrium (numpy; for initial guesses).

        :meth:`equilibrium` divided by ``F_max`` (isometric fiber unless ``v_mt`` is given).
        """
        return self.equilibrium(l_mt, a, v_mt, tol=tol)["force"] / self.f_max

    def fiber_kinematics_rigid(self, l_mt, v_mt):
        """Fiber length and velocity ``(l_ce, v_ce)`` (m, m/s) for an inextensible tendon.

        ``x = l_mt - l_slack``, ``l_ce = sqrt(x^2 + h^2)`` (constant-thickness
        pennation), ``v_ce = v_mt cos(alpha)``.
        """
        self._check(l_mt=l_mt, v_mt=v_mt)
        l_ce, v_ce, _ = self._rigid(l_mt, v_mt)
        return l_ce, v_ce

    def force(self, a, l_mt, v_mt, tendon: str = "rigid"):
        """Muscle-tendon force (N) at activation ``a``.

        ``tendon="rigid"``: the fiber follows the unit (``fiber_kinematics_rigid``);
        ``"compliant"``: the fiber length from :meth:`equilibrium` (with the
        quasi-static velocity share of ``v_mt``).
        """
        if tendon not in _TENDONS:
            raise ModelError(f"tendon must be one of {_TENDONS}, not {tendon!r}")
        if tendon == "compliant":
            return self.equilibrium(l_mt, a, v_mt)["force"]
        if v_mt is None:
            raise TrialError("the rigid-tendon force needs the muscle-tendon velocity v_mt "
                             "(pass 0.0 for an isometric fiber)")
        self._check(a=a, l_mt=l_mt, v_mt=v_mt)
        a = self._check_activation(a)
        return self._rigid_force(a, l_mt, v_mt)


def _rebuild(cls, kwargs):
    return cls(**kwargs)


class Thelen2003(_MuscleModel):
    """Thelen 2003 muscle-tendon units (thesis App. A.3, Eq. A.6-A.9), vectorised over muscles.

    Parameters (keyword-only; scalars or ``(m,)`` arrays): ``f_max`` (N),
    ``l_opt`` (m), ``l_slack`` (m), ``pennation`` at optimal length (rad),
    ``v_max`` (m/s, default ``10 l_opt``); optional ``names``, ``fast_fraction``
    and ``volume`` (m^3) for the energy models; ``tendon_strain0`` (0.04) and the
    activation time constants (0.011 s, 0.068 s).

    Curve constants are the thesis values: k_pe = 5, passive strain 0.6,
    gamma = 0.45, A_f = 0.25, f_hat = 1.4 (young adults).
    """

    model_type = "thelen2003"

    mechanical_parameters = ("f_max", "l_opt", "l_slack", "pennation", "v_max")

    def __init__(self, *, f_max, l_opt, l_slack, pennation=0.0, v_max=None, names=None,
                 fast_fraction=None, volume=None, tendon_strain0: float = TENDON_STRAIN0,
                 tau_rise: float = TAU_RISE, tau_fall: float = TAU_FALL):
        l_opt_arr = np.asarray(l_opt, dtype=float)
        self._setup(names=names, f_max=f_max, l_opt=l_opt, l_slack=l_slack, pennation=pennation,
                    fast_fraction=fast_fraction, volume=volume, tendon_strain0=tendon_strain0,
                    tau_rise=tau_rise, tau_fall=tau_fall,
                    v_max=10.0 * l_opt_arr if v_max is None else v_max)
        object.__setattr__(self, "_v_max_given", v_max is not None)

    def _kwargs(self) -> dict:
        return dict(f_max=self.f_max, l_opt=self.l_opt, l_slack=self.l_slack,
                    pennation=self.pennation, v_max=self.v_max if self._v_max_given else None,
                    names=self.names, fast_fraction=self.fast_fraction, volume=self.volume,
                    tendon_strain0=self.tendon_strain0, tau_rise=self.tau_rise,
                    tau_fall=self.tau_fall)

    def rigid_force(self, a, l_mt, v_mt):
        """Muscle-tendon force (N), rigid tendon (Eq. A.7-A.9); any backend, no input checks."""
        l_ce, v_ce, cos = self.fiber_rigid(l_mt, v_mt)
        l_norm = l_ce / self.l_opt
        f = thelen_fiber_force(v_ce, a, thelen_active_force_length(l_norm), v_max=self.v_max)
        f = f + thelen_passive_force_length(l_norm)
        return self.f_max * f * cos

    def _tendon_curve(self, strain):
        return (thelen_tendon_force(strain, strain0=self.tendon_strain0),
                thelen_tendon_stiffness(strain, strain0=self.tendon_strain0))

    def _tendon_strain(self, force):
        return thelen_tendon_strain(force, strain0=self.tendon_strain0)

    def _fiber_parts(self, a, l_ce, v_ce):
        l_norm = l_ce / self.l_opt
        fl = thelen_active_force_length(l_norm)
        # Eq. A.9: activation scales the maximum shortening velocity (as thelen_fiber_force)
        fv = thelen_force_velocity(v_ce / (_speed_scale(a) * self.v_max))
        fpe = thelen_passive_force_length(l_norm)
        return fl, fv, fpe, 0.0 * fl

    def force_limits(self, l_mt, v_mt):
        """Rigid-tendon force capacity ``(F_active, F_passive)`` (N), each shaped like ``l_mt``.

        ``F_active = F_max f_L(l_ce) f_V(v_ce / v_max) cos(alpha)`` (Eq. A.8 and the
        a = 1 force-velocity curve of Eq. A.9) and ``F_passive = F_max f_pe cos(alpha)``
        (Eq. A.7), so that "activation mode" static optimization uses
        ``F = a F_active + F_passive`` with ``0 <= a <= 1``.  This is exact at
        a = 1 and a = 0; in between it ignores the activation scaling
        ``0.25 + 0.75 a`` of the maximum shortening velocity (the usual
        linear-in-activation approximation).
        """
        self._check(l_mt=l_mt, v_mt=v_mt)
        l_mt, slack = self._taut(l_mt)
        l_ce, v_ce, cos = self._rigid(l_mt, v_mt)
        l_norm = l_ce / self.l_opt
        fmc = self.f_max * cos
        f_act = thelen_active_force_length(l_norm)
        f_act *= thelen_force_velocity(v_ce / self.v_max)
        f_act *= fmc
        f_pas = thelen_passive_force_length(l_norm)
        f_pas *= fmc
        if slack.any():  # a slack unit cannot pull
            f_act = np.where(slack, 0.0, f_act)
            f_pas = np.where(slack, 0.0, f_pas)
        return f_act, f_pas

    def equilibrium(self, l_mt, a, v_mt=None, *, tol: float = 1e-10, max_iter: int = 100):
        """Compliant-tendon fiber equilibrium ``F_t = (F_ce + F_pe) cos(alpha)`` (App. A.3).

        Isometric fiber (``v_ce = 0``) unless ``v_mt`` is given, in which case the
        fiber takes the series-stiffness share of ``v_mt`` (an initial-state
        heuristic).  Returns ``{"l_ce", "v_ce", "force"}`` (m, m/s, N).
        Raises :class:`pinmsk.errors.ConvergenceError` naming muscle and frame.
        """
        self._check(l_mt=l_mt, a=a, v_mt=v_mt)
        a = self._check_activation(a)
        l_ce, v_ce, f_t = thelen_equilibrium(
            l_mt, a, l_opt=self.l_opt, l_slack=self.l_slack, pennation=self.pennation,
            v_max=self.v_max, v_mt=v_mt, tendon_strain0=self.tendon_strain0, tol=tol,
            max_iter=max_iter, names=self.names)
        return {"l_ce": l_ce, "v_ce": v_ce, "force": self.f_max * f_t}

    def tendon_force(self, l_t):
        """Tendon force (N) at tendon length ``l_t`` (Eq. A.6)."""
        return self.f_max * thelen_tendon_force(np.asarray(l_t, dtype=float) / self.l_slack - 1.0,
                                                strain0=self.tendon_strain0)

    def contraction_rate(self, l_ce, l_mt, a):
        """Fiber velocity ``l_ce' = f_CD(l_ce, l_mt, a)`` (m/s), compliant tendon (thesis Eq. 3.9)."""
        self._check(l_ce=l_ce, l_mt=l_mt, a=a)
        return thelen_contraction_rate(l_ce, l_mt, a, l_opt=self.l_opt, l_slack=self.l_slack,
                                       pennation=self.pennation, v_max=self.v_max,
                                       tendon_strain0=self.tendon_strain0, names=self.names)

    def inverse(self, F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=0.0, *, fv_smooth: float = 0.0,
                fiber_floor=None):
        """Activation, its rate and excitation from muscle-tendon force (thesis Fig. 5.6, Eq. 5.2-5.4).

        ``ddF_mt`` (the force's second derivative) enters the fiber acceleration;
        the default 0 neglects it (see :mod:`pinmsk.muscles.inverse`).  ``fv_smooth`` and
        ``fiber_floor``: see :func:`~pinmsk.muscles.inverse.inverse_thelen2003`.
        Returns ``{"a", "adot", "u", "l_ce", "v_ce", "dv_ce", "l_t"}``.
        """
        return inverse_thelen2003(F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=ddF_mt,
                                  f_max=self.f_max, l_opt=self.l_opt, l_slack=self.l_slack,
                                  pennation=self.pennation, v_max=self.v_max,
                                  tendon_strain0=self.tendon_strain0, tau_rise=self.tau_rise,
                                  tau_fall=self.tau_fall, names=self.names, fv_smooth=fv_smooth,
                                  fiber_floor=fiber_floor)


class NaganoGerritsen(_MuscleModel):
    """Nagano & Gerritsen muscles with the Winters tendon (thesis App. A.4-A.5), no parallel element.

    Parameters (keyword-only; scalars or ``(m,)``): ``f_max`` (N), ``l_opt`` (m),
    ``l_slack`` (m), ``pennation`` (rad), ``width`` (force-length half-width in
    units of l_opt, thesis Table 5.3); optional ``names``, ``fast_fraction``,
    ``volume``; ``tendon_strain0`` (0.04) and activation time constants.
    Constants: A_rel = 0.41, B_rel = 5.2 /s, f_hat = 1.4, Gamma = 1.
    """

    model_type = "nagano_gerritsen"

    mechanical_parameters = ("f_max", "l_opt", "l_slack", "pennation", "width")

    def __init__(self, *, f_max, l_opt, l_slack, pennation=0.0, width, names=None,
                 fast_fraction=None, volume=None, tendon_strain0: float = TENDON_STRAIN0,
                 tau_rise: float = TAU_RISE, tau_fall: float = TAU_FALL):
        self._setup(names=names, f_max=f_max, l_opt=l_opt, l_slack=l_slack, pennation=pennation,
                    fast_fraction=fast_fraction, volume=volume, tendon_strain0=tendon_strain0,
                    tau_rise=tau_rise, tau_fall=tau_fall, width=width)

    def _kwargs(self) -> dict:
        return dict(f_max=self.f_max, l_opt=self.l_opt, l_slack=self.l_slack,
                    pennation=self.pennation, width=self.width, names=self.names,
                    fast_fraction=self.fast_fraction, volume=self.volume,
                    tendon_strain0=self.tendon_strain0, tau_rise=self.tau_rise,
                    tau_fall=self.tau_fall)

    #: the Winters tendon's stiffness vanishes at zero force (its inverse has an infinite slope
    #: there), so the implicit tendon-force state is kept just above it
    _TENDON_FORCE_BOUNDS = (1e-3, 5.0)

    def rigid_force(self, a, l_mt, v_mt):
        """Muscle-tendon force (N), rigid tendon (Eq. A.12-A.13); any backend, no input checks."""
        l_ce, v_ce, cos = self.fiber_rigid(l_mt, v_mt)
        fi = ng_force_length(l_ce / self.l_opt, self.width)
        return self.f_max * ng_fiber_force(v_ce / self.l_opt, a, fi) * cos

    def _tendon_curve(self, strain):
        return (winters_tendon_force(strain, strain0=self.tendon_strain0),
                winters_tendon_stiffness(strain, strain0=self.tendon_strain0))

    def _tendon_strain(self, force):
        return winters_tendon_strain(force, strain0=self.tendon_strain0)

    def _fiber_total(self, a, l_ce, v_ce):
        return ng_fiber_force(v_ce / self.l_opt, a, ng_force_length(l_ce / self.l_opt, self.width))

    def _fiber_parts(self, a, l_ce, v_ce):
        # Eq. A.12 is not separable: f_V is the CE force over a f_isom (1 where f_isom = 0)
        xp = backend_of(a, l_ce, v_ce)
        fi = ng_force_length(l_ce / self.l_opt, self.width)
        f = ng_fiber_force(v_ce / self.l_opt, a, fi)
        fv = xp.where(fi * a > 0, f / xp.maximum(fi * a, 1e-300), 1.0)
        return fi, fv, 0.0 * fi, 0.0 * fi

    def force_limits(self, l_mt, v_mt):
        """Rigid-tendon force capacity ``(F_active, F_passive)`` (N).

        ``F_active = F_max q(v_ce, a_hat = 1, f_isom) cos(alpha)`` (Eq. A.12-A.13 at
        full activation) and ``F_passive = 0`` (no parallel element).
        ``a F_active`` is exact for ``a >= 0.3``; below, the activation scaling
        of the velocity (``a_hat``) is ignored.
        """
        self._check(l_mt=l_mt, v_mt=v_mt)
        l_mt, slack = self._taut(l_mt)
        l_ce, v_ce, cos = self._rigid(l_mt, v_mt)
        fi = ng_force_length(l_ce / self.l_opt, self.width)
        f_act = ng_fiber_force(v_ce / self.l_opt, 1.0, fi)
        f_act *= self.f_max * cos
        if slack.any():  # a slack unit cannot pull
            f_act = np.where(slack, 0.0, f_act)
        return f_act, np.zeros_like(f_act)

    def equilibrium(self, l_mt, a, v_mt=None, *, tol: float = 1e-10, max_iter: int = 100):
        """Compliant (Winters) tendon fiber equilibrium ``F_t = F_ce cos(alpha)``.

        Returns ``{"l_ce", "v_ce", "force"}``; see :meth:`Thelen2003.equilibrium`.
        """
        self._check(l_mt=l_mt, a=a, v_mt=v_mt)
        a = self._check_activation(a)
        l_ce, v_ce, f_t = ng_equilibrium(
            l_mt, a, l_opt=self.l_opt, l_slack=self.l_slack, pennation=self.pennation,
            width=self.width, v_mt=v_mt, tendon_strain0=self.tendon_strain0, tol=tol,
            max_iter=max_iter, names=self.names)
        return {"l_ce": l_ce, "v_ce": v_ce, "force": self.f_max * f_t}

    def tendon_force(self, l_t):
        """Tendon force (N) at tendon length ``l_t`` (Eq. A.10-A.11)."""
        return self.f_max * winters_tendon_force(np.asarray(l_t, dtype=float) / self.l_slack - 1.0,
                                                 strain0=self.tendon_strain0)

    def contraction_rate(self, l_ce, l_mt, a):
        """Fiber velocity ``l_ce' = f_CD(l_ce, l_mt, a)`` (m/s), Winters tendon (thesis Eq. 3.9)."""
        self._check(l_ce=l_ce, l_mt=l_mt, a=a)
        return ng_contraction_rate(l_ce, l_mt, a, l_opt=self.l_opt, l_slack=self.l_slack,
                                   pennation=self.pennation, width=self.width,
                                   tendon_strain0=self.tendon_strain0, names=self.names)

    def inverse(self, F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=0.0):
        """Activation, its rate and excitation from muscle-tendon force (thesis Fig. 5.6, Eq. 5.2-5.4).

        Returns ``{"a", "adot", "u", "l_ce", "v_ce", "dv_ce", "l_t"}``; see
        :meth:`Thelen2003.inverse`.
        """
        return inverse_nagano_gerritsen(F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=ddF_mt,
                                        f_max=self.f_max, l_opt=self.l_opt,
                                        l_slack=self.l_slack, pennation=self.pennation,
                                        width=self.width, tendon_strain0=self.tendon_strain0,
                                        tau_rise=self.tau_rise, tau_fall=self.tau_fall,
                                        names=self.names)


class _CurveMuscle(_MuscleModel):
    """OpenSim-style separable Hill muscles: fiber force ``F_max (a f_L f_V + f_PE + damping v)``.

    ``v = v_ce / v_max`` is the normalized fiber velocity (negative when
    shortening) and the curves are functions of ``l_ce / l_opt`` and ``v``;
    the tendon curve is a function of the tendon strain.  Subclasses supply
    the curves (:meth:`_length_curves`, :meth:`_velocity_curve`,
    :meth:`_tendon_curve`, :meth:`_tendon_strain`) and may floor or clamp the
    rigid-tendon force as their OpenSim counterpart does (:meth:`_rigid_fiber`).
    """

    mechanical_parameters = ("f_max", "l_opt", "l_slack", "pennation", "v_max", "damping")

    def _curve_setup(self, kwargs, v_max) -> None:
        l_opt = np.asarray(kwargs["l_opt"], dtype=float)
        kwargs["v_max"] = 10.0 * l_opt if v_max is None else v_max
        self._setup(tendon_strain0=None, **kwargs)
        object.__setattr__(self, "_v_max_given", v_max is not None)

    # -- hooks -------------------------------------------------------------------
    def _length_curves(self, l_norm):
        """``(f_L, df_L/dl, f_PE, df_PE/dl)`` at the normalized fiber length."""
        raise NotImplementedError

    def _velocity_curve(self, v_norm):
        """``f_V`` at the normalized fiber velocity (the a = 1 curve)."""
        raise NotImplementedError

    def _tendon_curve(self, strain):
        """``(f_T, df_T/dstrain)`` at the tendon strain."""
        raise NotImplementedError

    def _tendon_strain(self, force):
        """Tendon strain at a normalized tendon force (the inverse of :meth:`_tendon_curve`)."""
        raise NotImplementedError

    def _rigid_fiber(self, l_ce, v_norm, f_total):
        """The rigid-tendon normalized fiber force (and a mask of muscle-frames that carry none)."""
        return f_total, None

    def _active_velocity_factor(self, a, v_norm):
        """The force-velocity factor at activation ``a`` (the a = 1 curve unless activation scales it)."""
        return self._velocity_curve(v_norm)

    # -- forces ------------------------------------------------------------------
    def rigid_force(self, a, l_mt, v_mt):
        """Muscle-tendon force (N), rigid tendon, as OpenSim; any backend, no input checks."""
        l_ce, v_ce, cos = self.fiber_rigid(l_mt, v_mt)
        v = v_ce / self.v_max
        fl, _, fpe, _ = self._length_curves(l_ce / self.l_opt)
        fv = self._active_velocity_factor(a, v)
        f, off = self._rigid_fiber(l_ce, v, a * fl * fv + fpe + self.damping * v)
        if off is not None:
            f = backend_of(f, off).where(off, 0.0, f)
        return self.f_max * f * cos

    def _fiber_parts(self, a, l_ce, v_ce):
        v = v_ce / self.v_max
        fl, _, fpe, _ = self._length_curves(l_ce / self.l_opt)
        return fl, self._active_velocity_factor(a, v), fpe, self.damping * v

    def force_limits(self, l_mt, v_mt):
        """Rigid-tendon force capacity ``(F_active, F_passive)`` (N), each shaped like ``l_mt``.

        ``F_active = F_max f_L f_V cos(alpha)`` (``f_V`` at full activation) and
        ``F_passive = F_max (f_PE + damping v) cos(alpha)``, so that
        ``F = a F_active + F_passive`` is the rigid-tendon force at activation ``a``:
        exactly for De Groote and Millard (activation does not scale their
        velocity), at a = 0 and a = 1 for Thelen (as :meth:`Thelen2003.force_limits`).
        The damping term is negative while the fiber shortens; Millard 2012 floors
        the total fiber force at 0, which a linear function of ``a`` cannot
        (:meth:`force` applies it).  A slack unit gives 0 and 0.
        """
        slack, l_ce, v, cos, fl, fpe, fv = self.rigid_curves(l_mt, v_mt)
        fmc = self.f_max * cos
        f_act = fl * fv * fmc
        f_pas = (fpe + self.damping * v) * fmc
        _, off = self._rigid_fiber(l_ce, v, f_pas)
        off = slack if off is None else (off | slack)
        if off.any():
            f_act = np.where(off, 0.0, f_act)
            f_pas = np.where(off, 0.0, f_pas)
        return f_act, f_pas

    def rigid_curves(self, l_mt, v_mt):
        """``(slack, l_ce, v, cos_alpha, f_L, f_PE, f_V)`` of the rigid-tendon fiber.

        ``slack``: muscle-frames where the unit is not longer than its tendon (their
        fiber is placed just taut); ``v = v_ce / v_max``; ``f_V`` at full activation.
        """
        self._check(l_mt=l_mt, v_mt=v_mt)
        l_mt, slack = self._taut(l_mt)
        l_ce, v_ce, cos = self._rigid(l_mt, v_mt)
        v = v_ce / self.v_max
        fl, _, fpe, _ = self._length_curves(l_ce / self.l_opt)
        return slack, l_ce, v, cos, fl, fpe, self._velocity_curve(v)

    def _fiber_closure(self, a):
        damping = self.damping

        def fiber(l_norm, v_norm):
            fl, dfl, fpe, dfpe = self._length_curves(l_norm)
            if v_norm is None:
                return a * fl + fpe, a * dfl + dfpe
            fv = self._active_velocity_factor(a, v_norm)
            return a * fl * fv + fpe + damping * v_norm, a * dfl * fv + dfpe

        return fiber

    def equilibrium(self, l_mt, a, v_mt=None, *, tol: float = 1e-10, max_iter: int = 100):
        """Compliant-tendon fiber equilibrium ``F_t = (a f_L f_V + f_PE + damping v) F_max cos(alpha)``.

        Isometric fiber (``v_ce = 0``) unless ``v_mt`` is given (then the fiber
        takes the series-stiffness share of ``v_mt``, see
        :func:`pinmsk.muscles._solve.compliant_equilibrium`).  Returns
        ``{"l_ce", "v_ce", "force"}`` (m, m/s, N); raises
        :class:`pinmsk.errors.ConvergenceError` naming muscle and frame.
        """
        self._check(l_mt=l_mt, a=a, v_mt=v_mt)
        a = self._check_activation(a)
        l_ce, v_ce, f_t, _ = compliant_equilibrium(
            l_mt, l_opt=self.l_opt, l_slack=self.l_slack, height=self.height,
            tendon=self._tendon_curve, tendon_strain=self._tendon_strain,
            fiber=self._fiber_closure(a), v_mt=v_mt, v_scale=self.v_max, tol=tol,
            max_iter=max_iter, names=self.names, inputs={"l_mt": l_mt, "a": a})
        return {"l_ce": l_ce, "v_ce": v_ce, "force": self.f_max * f_t}

    def tendon_force(self, l_t):
        """Tendon force (N) at tendon length ``l_t`` (m)."""
        return self.f_max * self._tendon_curve(np.asarray(l_t, dtype=float) / self.l_slack - 1.0)[0]

    def contraction_rate(self, l_ce, l_mt, a):
        """Not available: pinmsk has no contraction dynamics for this model (use Thelen2003)."""
        raise ModelError(f"{type(self).__name__} has no contraction dynamics in pinmsk; forward "
                         "simulation and dynamic optimization need Thelen2003 muscles")

    def inverse(self, F_mt, dF_mt, l_mt, dl_mt, ddl_mt, ddF_mt=0.0, **_):
        """Not available: pinmsk has no inverse muscle model for this model (use Thelen2003)."""
        raise ModelError(f"{type(self).__name__} has no inverse muscle model in pinmsk (excitations "
                         "from forces need Thelen2003 or NaganoGerritsen muscles)")

    def _curve_kwargs(self, names) -> dict:
        return {k: getattr(self, k) for k in names}

    def _common_kwargs(self) -> dict:
        return dict(f_max=self.f_max, l_opt=self.l_opt, l_slack=self.l_slack, pennation=self.pennation,
                    v_max=self.v_max if self._v_max_given else None, damping=self.damping,
                    names=self.names, fast_fraction=self.fast_fraction, volume=self.volume,
                    tau_rise=self.tau_rise, tau_fall=self.tau_fall)


class DeGroote2016(_CurveMuscle):
    """De Groote et al. 2016 muscle-tendon units as OpenSim's DeGrooteFregly2016Muscle, vectorised.

    Curves: :mod:`pinmsk.muscles.degroote2016` (three-Gaussian active
    force-length, exponential passive, asinh force-velocity, exponential
    tendon).  Parameters (keyword-only; scalars or ``(m,)``): ``f_max`` (N),
    ``l_opt`` (m), ``l_slack`` (m), ``pennation`` (rad), ``v_max`` (m/s,
    default ``10 l_opt``), ``damping`` (0), ``width_scale`` (1),
    ``passive_strain`` (0.6), ``passive_scale`` (1; 0 = no passive force),
    ``tendon_strain`` (0.049), activation time constants (0.015 s, 0.060 s);
    optional ``names``, ``fast_fraction`` and ``volume``.  As in OpenSim the
    rigid-tendon force is not floored: the passive curve is negative below
    0.2 l_opt and the damping term while shortening.
    """

    model_type = "degroote2016"

    _CURVE_PARAMETERS = ("width_scale", "passive_strain", "passive_scale", "tendon_strain")

    def __init__(self, *, f_max, l_opt, l_slack, pennation=0.0, v_max=None, damping=0.0,
                 width_scale=1.0, passive_strain=0.6, passive_scale=1.0, tendon_strain=0.049,
                 names=None, fast_fraction=None, volume=None, tau_rise: float = 0.015,
                 tau_fall: float = 0.060):
        self._curve_setup(dict(names=names, f_max=f_max, l_opt=l_opt, l_slack=l_slack,
                               pennation=pennation, fast_fraction=fast_fraction, volume=volume,
                               tau_rise=tau_rise, tau_fall=tau_fall, damping=damping,
                               width_scale=width_scale, passive_strain=passive_strain,
                               passive_scale=passive_scale, tendon_strain=tendon_strain), v_max)

    def _kwargs(self) -> dict:
        return {**self._common_kwargs(), **self._curve_kwargs(self._CURVE_PARAMETERS)}

    def _length_curves(self, l_norm):
        fpe = degroote_passive_force_length(l_norm, strain=self.passive_strain)
        dfpe = degroote_passive_force_length_derivative(l_norm, strain=self.passive_strain)
        return (degroote_active_force_length(l_norm, width_scale=self.width_scale),
                degroote_active_force_length_derivative(l_norm, width_scale=self.width_scale),
                self.passive_scale * fpe, self.passive_scale * dfpe)

    def _velocity_curve(self, v_norm):
        return degroote_force_velocity(v_norm)

    def _tendon_curve(self, strain):
        l_t = 1.0 + backend_of(strain).asarray(strain)
        return (degroote_tendon_force(l_t, strain=self.tendon_strain),
                degroote_tendon_force_derivative(l_t, strain=self.tendon_strain))

    def _tendon_strain(self, force):
        xp = backend_of(force)
        return degroote_tendon_length(xp.maximum(force, 0.0), strain=self.tendon_strain) - 1.0


#: Millard 2012 curve parameters: ``(parameter, default)``; ``None`` = OpenSim's fitted default
_MILLARD_CURVES = (
    ("min_norm_active_fiber_length", 0.47 - 0.0259), ("transition_norm_fiber_length", 0.73),
    ("max_norm_active_fiber_length", 1.8123), ("shallow_ascending_slope", 0.8616),
    ("active_minimum_value", 0.0),
    ("passive_strain_at_zero_force", 0.0), ("passive_strain", 0.7),
    ("passive_stiffness_at_low_force", None), ("passive_stiffness", None), ("passive_curviness", None),
    ("concentric_slope_at_vmax", 0.0), ("concentric_slope_near_vmax", 0.25), ("isometric_slope", 5.0),
    ("eccentric_slope_at_vmax", 0.0), ("eccentric_slope_near_vmax", 0.15),
    ("max_eccentric_velocity_force_multiplier", 1.4), ("concentric_curviness", 0.6),
    ("eccentric_curviness", 0.9),
    ("tendon_strain", 0.049), ("tendon_stiffness", None), ("tendon_toe_force", None),
    ("tendon_curviness", None),
)


class Millard2012(_CurveMuscle):
    """Millard et al. 2013 muscle-tendon units as OpenSim's Millard2012EquilibriumMuscle, vectorised.

    The curves are OpenSim's quintic Bezier chains, evaluated exactly
    (:mod:`pinmsk.muscles.millard2012`), built per muscle from the curve
    parameters (names in :data:`MUSCLE_PARAMETERS`; OpenSim's curve property
    in brackets there).  Parameters (keyword-only; scalars or ``(m,)``):
    ``f_max``, ``l_opt``, ``l_slack``, ``pennation``, ``v_max`` (default
    ``10 l_opt``), ``damping`` (0.1), ``max_pennation`` (acos 0.1), the curve
    parameters (defaults: OpenSim's curve defaults as its damped model uses
    them, i.e. ``active_minimum_value`` 0; the passive and tendon stiffness and
    curviness default to OpenSim's fitted values from the strains: 0.2,
    ``2/(e1 - e0)``, 0.75 and ``1.375/e_T``, 2/3, 0.5), activation time constants
    (0.010 s, 0.040 s); optional ``names``, ``fast_fraction`` and ``volume``.

    Rigid tendon as in OpenSim: the fiber length has the floor
    ``max(min_norm_active_fiber_length l_opt, h / sin(max_pennation))``; a
    fiber at the floor (shortening) or below carries no force, and the total
    fiber force is floored at 0.  Use :meth:`Millard2012EquilibriumMuscle.model_parameters`
    (via :mod:`pinmsk.opensim.muscles`) to get OpenSim's effective curve settings.
    """

    model_type = "millard2012"

    def __init__(self, *, f_max, l_opt, l_slack, pennation=0.0, v_max=None, damping=0.1,
                 max_pennation=math.acos(0.1), names=None, fast_fraction=None, volume=None,
                 tau_rise: float = 0.010, tau_fall: float = 0.040, **curves):
        known = dict(_MILLARD_CURVES)
        unknown = set(curves) - set(known)
        if unknown:
            raise ModelError(f"Millard2012: unknown parameter(s) {sorted(unknown)}; curve parameters "
                             f"are {sorted(known)}")
        given = {k: curves[k] for k in known if curves.get(k) is not None}
        m = n_muscles(f_max, l_opt, l_slack, pennation, *given.values())
        if names is not None:
            m = len(names)
        # OpenSim's fitted defaults of the optional passive and tendon settings
        e0 = np.broadcast_to(np.asarray(given.get("passive_strain_at_zero_force", 0.0), float), (m,))
        e1 = np.broadcast_to(np.asarray(given.get("passive_strain", 0.7), float), (m,))
        et = np.broadcast_to(np.asarray(given.get("tendon_strain", 0.049), float), (m,))
        fitted = {"passive_stiffness_at_low_force": 0.2, "passive_curviness": 0.75,
                  "tendon_toe_force": 2.0 / 3.0, "tendon_curviness": 0.5}
        with np.errstate(divide="ignore", invalid="ignore"):
            fitted["passive_stiffness"] = 2.0 / (e1 - e0)
            fitted["tendon_stiffness"] = 1.375 / et
        values = {k: given.get(k, known[k] if known[k] is not None else fitted[k]) for k in known}
        self._curve_setup(dict(names=names, f_max=f_max, l_opt=l_opt, l_slack=l_slack,
                               pennation=pennation, fast_fraction=fast_fraction, volume=volume,
                               tau_rise=tau_rise, tau_fall=tau_fall, damping=damping,
                               max_pennation=max_pennation, **values), v_max)
        object.__setattr__(self, "_given", frozenset(given))
        self._build_curves()

    def _build_curves(self) -> None:
        """One stacked Bezier chain per curve (a single chain when all muscles share the settings)."""
        p = {k: getattr(self, k) for k, _ in _MILLARD_CURVES}
        rows = []
        for i in range(self.n):
            v = {k: float(a[i]) for k, a in p.items()}
            try:
                rows.append((
                    _millard.ActiveForceLengthCurve(
                        v["min_norm_active_fiber_length"], v["transition_norm_fiber_length"],
                        v["max_norm_active_fiber_length"], v["shallow_ascending_slope"],
                        v["active_minimum_value"]),
                    _millard.FiberForceLengthCurve(
                        v["passive_strain_at_zero_force"], v["passive_strain"],
                        v["passive_stiffness_at_low_force"], v["passive_stiffness"], v["passive_curviness"]),
                    _millard.ForceVelocityCurve(
                        v["concentric_slope_at_vmax"], v["concentric_slope_near_vmax"], v["isometric_slope"],
                        v["eccentric_slope_at_vmax"], v["eccentric_slope_near_vmax"],
                        v["max_eccentric_velocity_force_multiplier"], v["concentric_curviness"],
                        v["eccentric_curviness"]),
                    _millard.TendonForceLengthCurve(
                        v["tendon_strain"], v["tendon_stiffness"], v["tendon_toe_force"],
                        v["tendon_curviness"])))
            except ModelError as exc:
                raise ModelError(f"Millard2012 {locate(None, i, self.names)}: {exc}") from None
        if all(r == rows[0] for r in rows):
            rows = rows[:1]
        curves = [_millard.QuinticBezierCurve.stack([_millard._cached(r[j]) for r in rows])
                  for j in range(4)]
        put = object.__setattr__
        put(self, "_afl", curves[0])
        put(self, "_fpe", curves[1])
        put(self, "_fv", curves[2])
        put(self, "_tfl", curves[3])
        h_min = np.where(self.max_pennation > 1e-14,
                         self.height / np.sin(np.maximum(self.max_pennation, 1e-300)), 0.01 * self.l_opt)
        l_min = np.maximum(np.maximum(self.min_norm_active_fiber_length * self.l_opt, h_min), 1e-14)
        l_min.flags.writeable = False
        put(self, "l_min", l_min)

    def _kwargs(self) -> dict:
        curves = {k: (getattr(self, k) if k in self._given else None) for k, _ in _MILLARD_CURVES}
        return {**self._common_kwargs(), "max_pennation": self.max_pennation, **curves}

    def _length_curves(self, l_norm):
        fl, dfl = self._afl.evaluate(l_norm, (0, 1))
        fpe, dfpe = self._fpe.evaluate(l_norm, (0, 1))
        return fl, dfl, fpe, dfpe

    def _velocity_curve(self, v_norm):
        return self._fv.value(v_norm)

    def _tendon_curve(self, strain):
        return tuple(self._tfl.evaluate(1.0 + np.asarray(strain, dtype=float), (0, 1)))

    def _tendon_strain(self, force):
        return self._tfl.inverse(force) - 1.0

    def _numpy_only(self, what):
        raise ModelError(f"Millard2012 has no {what} for the optimal-control engine: its curves are "
                         "quintic Bezier splines evaluated in numpy only; use DeGroote2016 muscles "
                         "(closed-form curves, OpenSim's DeGrooteFregly2016Muscle)")

    def rigid_force(self, a, l_mt, v_mt):
        """Not available: Millard2012 curves are numpy only (use DeGroote2016); :meth:`force` works."""
        self._numpy_only("rigid_force")

    def fiber_from_tendon(self, f_t, df_t, l_mt, v_mt):
        """Not available: Millard2012 curves are numpy only (use DeGroote2016)."""
        self._numpy_only("fiber_from_tendon")

    def implicit_residual(self, a, f_t, df_t, l_mt, v_mt):
        """Not available: Millard2012 curves are numpy only (use DeGroote2016)."""
        self._numpy_only("implicit_residual")

    def fiber_forces(self, a, l_ce, v_ce):
        """Not available: Millard2012 curves are numpy only (use DeGroote2016)."""
        self._numpy_only("fiber_forces")

    def tendon_force_bounds(self):
        """Not available: Millard2012 curves are numpy only (use DeGroote2016)."""
        self._numpy_only("tendon_force_bounds")

    def equilibrium_tendon_force(self, a, l_mt, v_mt=None, *, tol: float = 1e-10):
        """Not available: Millard2012 curves are numpy only (use DeGroote2016)."""
        self._numpy_only("equilibrium_tendon_force")

    def _rigid_force(self, a, l_mt, v_mt):
        # the numpy path of force(): the generic CurveMuscle math on numpy arrays
        l_mt = np.asarray(l_mt, dtype=float)
        check_along_positive(l_mt - self.l_slack, l_mt, self.names, what="Millard2012 rigid tendon")
        return _CurveMuscle.rigid_force(self, a, l_mt, v_mt)

    def _rigid_fiber(self, l_ce, v_norm, f_total):
        # OpenSim: a fiber at its length floor that shortens (or below it) is clamped and carries no
        # force; with a rigid tendon the damping force saturates so the fiber never pushes.
        off = (l_ce < self.l_min) | ((l_ce <= self.l_min) & (v_norm <= 0.0))
        return np.maximum(f_total, 0.0), off


#: Thelen2003OpenSim curve constants: ``(parameter, OpenSim property, default)``
_THELEN_CURVES = (("tendon_strain", "FmaxTendonStrain", 0.04), ("passive_strain", "FmaxMuscleStrain", 0.6),
                  ("active_shape", "KshapeActive", 0.45), ("passive_shape", "KshapePassive", 5.0),
                  ("fv_shape", "Af", 0.25), ("eccentric_force", "Flen", 1.4),
                  ("fv_extrapolation", "fv_linear_extrap_threshold", 0.95))


class Thelen2003OpenSim(_CurveMuscle):
    """Thelen 2003 muscles with OpenSim's per-muscle curve constants (Thelen2003Muscle), vectorised.

    The curves of :class:`Thelen2003` (thesis Eq. A.6-A.9) with the constants
    as parameters -- ``tendon_strain`` (FmaxTendonStrain, 0.04),
    ``passive_strain`` (FmaxMuscleStrain, 0.6), ``active_shape`` (KshapeActive,
    0.45), ``passive_shape`` (KshapePassive, 5), ``fv_shape`` (Af, 0.25),
    ``eccentric_force`` (Flen, 1.4), ``fv_extrapolation``
    (fv_linear_extrap_threshold, 0.95) -- and OpenSim's exact tendon toe
    (:data:`pinmsk.muscles.tendon.EXACT_TOE_FRACTION`).  Also ``f_max``, ``l_opt``,
    ``l_slack``, ``pennation``, ``v_max`` (default ``10 l_opt``), ``max_pennation``
    (acos 0.1), activation time constants (0.015 s, 0.050 s), ``names``,
    ``fast_fraction``, ``volume``.

    As OpenSim: the force-velocity factor at activation ``a`` is the curve at
    ``v / (0.25 + 0.75 a)``, floored at 0; a fiber at or below OpenSim's length
    floor (``h / sin(max_pennation)``, or 1 % of l_opt unpennated) carries no
    force.  Rigid-tendon forces, force limits, isometric equilibrium and tendon
    forces; no contraction dynamics or inverse model (use :class:`Thelen2003`,
    which has the thesis constants, for those).
    """

    model_type = "thelen2003_opensim"

    mechanical_parameters = ("f_max", "l_opt", "l_slack", "pennation", "v_max")

    def __init__(self, *, f_max, l_opt, l_slack, pennation=0.0, v_max=None, tendon_strain=0.04,
                 passive_strain=0.6, active_shape=0.45, passive_shape=5.0, fv_shape=0.25,
                 eccentric_force=1.4, fv_extrapolation=0.95, max_pennation=math.acos(0.1),
                 names=None, fast_fraction=None, volume=None, tau_rise: float = 0.015,
                 tau_fall: float = 0.050):
        self._curve_setup(dict(names=names, f_max=f_max, l_opt=l_opt, l_slack=l_slack,
                               pennation=pennation, fast_fraction=fast_fraction, volume=volume,
                               tau_rise=tau_rise, tau_fall=tau_fall, damping=0.0,
                               max_pennation=max_pennation, tendon_strain=tendon_strain,
                               passive_strain=passive_strain, active_shape=active_shape,
                               passive_shape=passive_shape, fv_shape=fv_shape,
                               eccentric_force=eccentric_force, fv_extrapolation=fv_extrapolation), v_max)
        bad = ~(self.fv_extrapolation > 1.0 / self.eccentric_force)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ModelError(f"fv_extrapolation = {self.fv_extrapolation[i]:g} for "
                             f"{locate(None, i, self.names)}; it must exceed 1/eccentric_force = "
                             f"{1.0 / self.eccentric_force[i]:g}")
        h_min = np.where(self.max_pennation > 1e-14,
                         self.height / np.sin(np.maximum(self.max_pennation, 1e-300)), 0.01 * self.l_opt)
        h_min.flags.writeable = False
        object.__setattr__(self, "l_min", h_min)

    def _kwargs(self) -> dict:
        kw = self._common_kwargs()
        del kw["damping"]
        return {**kw, "max_pennation": self.max_pennation,
                **{k: getattr(self, k) for k, _, _ in _THELEN_CURVES}}

    def _length_curves(self, l_norm):
        xp = backend_of(l_norm)
        l_norm = xp.asarray(l_norm)
        passive = {"k_pe": self.passive_shape, "strain0": self.passive_strain}
        # OpenSim's passive curve has slope 0 at l_norm = 1 exactly (the left one), Eq. A.7's is the right one
        return (thelen_active_force_length(l_norm, gamma=self.active_shape),
                thelen_active_force_length_derivative(l_norm, gamma=self.active_shape),
                thelen_passive_force_length(l_norm, **passive),
                xp.where(l_norm > 1.0, thelen_passive_force_length_derivative(l_norm, **passive), 0.0))

    def _velocity_curve(self, v_norm):
        xp = backend_of(v_norm)
        return xp.maximum(thelen_force_velocity(v_norm, a_f=self.fv_shape, f_hat=self.eccentric_force,
                                                extrapolation=self.fv_extrapolation), 0.0)

    def _active_velocity_factor(self, a, v_norm):
        xp = backend_of(a, v_norm)
        scale = 0.25 + 0.75 * xp.asarray(a)       # activation scales the speed (Eq. A.9)
        return self._velocity_curve(xp.asarray(v_norm) / scale)

    def _tendon_curve(self, strain):
        return (thelen_tendon_force(strain, strain0=self.tendon_strain, exact_toe=True),
                thelen_tendon_stiffness(strain, strain0=self.tendon_strain, exact_toe=True))

    def _tendon_strain(self, force):
        return thelen_tendon_strain(force, strain0=self.tendon_strain, exact_toe=True)

    def _rigid_fiber(self, l_ce, v_norm, f_total):
        # OpenSim's calcActiveFiberForceAlongTendon: no force at or below the fiber-length floor
        return f_total, l_ce <= self.l_min


#: The muscle-tendon model classes by their ``model_type`` (the MuscleSet / sidecar type name).
MUSCLE_MODELS = {cls.model_type: cls for cls in (Thelen2003, NaganoGerritsen, DeGroote2016, Millard2012,
                                                  Thelen2003OpenSim)}
