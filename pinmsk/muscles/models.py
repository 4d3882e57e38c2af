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
- ``activation_rate(u, a)``, ``excitation(a, adot)``, ``activation(t, u, a0=None)`` (App. A.2)

Inputs are time-first ``(N, m)`` arrays (or ``(m,)`` for one frame) in SI
units; parameters are ``(m,)``.  The objects are immutable: constructors copy
the parameter arrays and mark them read-only, and attributes cannot be set.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError, TrialError
from ._common import check_finite, locate, muscle_parameter, n_muscles, where_first
from .activation import (TAU_FALL, TAU_RISE, activation_from_excitation, activation_rate,
                         excitation_from_activation)
from .inverse import inverse_nagano_gerritsen, inverse_thelen2003
from .nagano_gerritsen import ng_contraction_rate, ng_equilibrium, ng_fiber_force, ng_force_length
from .pennation import check_along_positive, pennation_height
from .tendon import TENDON_STRAIN0, thelen_tendon_force, winters_tendon_force
from .thelen2003 import (GAMMA, K_PE, PASSIVE_STRAIN0, thelen_contraction_rate, thelen_equilibrium,
                         thelen_fiber_force, thelen_force_velocity)

__all__ = ["MUSCLE_PARAMETERS", "MuscleParameter", "NaganoGerritsen", "Thelen2003"]

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
    MuscleParameter("v_max", "m/s", "maximum shortening velocity (Thelen 2003; default 10 l_opt)"),
    MuscleParameter("width", "", "force-length half-width in units of l_opt (Nagano & Gerritsen)"),
    MuscleParameter("fast_fraction", "", "fraction of fast-twitch fibers (energy models)", 0.0, 1.0,
                    low_open=False),
    MuscleParameter("volume", "m^3", "muscle volume (energy models, PCSA weights)"),
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
        if not (tendon_strain0 > 0):
            raise ModelError(f"tendon_strain0 = {tendon_strain0} must be > 0")
        if not (0 < tau_rise and 0 < tau_fall):
            raise ModelError(f"activation time constants must be > 0 (tau_rise={tau_rise}, "
                             f"tau_fall={tau_fall})")
        put(self, "tendon_strain0", float(tendon_strain0))
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
    def activation_rate(self, u, a):
        """Winters & Stark activation rate (thesis Eq. A.2) with this model's time constants."""
        return activation_rate(u, a, tau_rise=self.tau_rise, tau_fall=self.tau_fall)

    def excitation(self, a, adot):
        """Excitation from activation and its rate, inverse activation dynamics (Eq. A.5)."""
        return excitation_from_activation(a, adot, tau_rise=self.tau_rise, tau_fall=self.tau_fall)

    def activation(self, t, u, a0=None):
        """Activation over time from sampled excitation ``u`` (N, m) (Eq. A.2, see
        :func:`pinmsk.muscles.activation.activation_from_excitation`)."""
        return activation_from_excitation(t, u, a0, tau_rise=self.tau_rise, tau_fall=self.tau_fall)

    # -- kinematics ------------------------------------------------------------
    def _rigid(self, l_mt, v_mt):
        """``(l_ce, v_ce, cos_alpha)`` with an inextensible tendon."""
        l_mt = np.asarray(l_mt, dtype=float)
        x = l_mt - self.l_slack
        check_along_positive(x, l_mt, self.names, what=f"{type(self).__name__} rigid tendon")
        l_ce = np.sqrt(x * x + self.height * self.height)
        cos = x / l_ce
        return l_ce, np.asarray(v_mt, dtype=float) * cos, cos

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

    def _rigid_force(self, a, l_mt, v_mt):
        l_ce, v_ce, cos = self._rigid(l_mt, v_mt)
        d = l_ce / self.l_opt - 1.0
        f = thelen_fiber_force(v_ce, a, np.exp(d * d * (-1.0 / GAMMA)), v_max=self.v_max)
        f += np.expm1((K_PE / PASSIVE_STRAIN0) * np.maximum(d, 0.0)) / np.expm1(K_PE)
        return self.f_max * f * cos

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
        d = l_ce / self.l_opt - 1.0
        fmc = self.f_max * cos
        f_act = np.exp(d * d * (-1.0 / GAMMA))
        f_act *= thelen_force_velocity(v_ce / self.v_max)
        f_act *= fmc
        np.maximum(d, 0.0, out=d)
        d *= K_PE / PASSIVE_STRAIN0
        f_pas = np.expm1(d, out=d)
        f_pas *= fmc / np.expm1(K_PE)
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

    def _rigid_force(self, a, l_mt, v_mt):
        l_ce, v_ce, cos = self._rigid(l_mt, v_mt)
        fi = ng_force_length(l_ce / self.l_opt, self.width)
        return self.f_max * ng_fiber_force(v_ce / self.l_opt, a, fi) * cos

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
