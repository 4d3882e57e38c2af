"""First-order activation dynamics between measured excitation and muscle activation (thesis Eq. A.2).

Physics: the calcium kinetics between neural excitation ``u`` (or the
normalised EMG envelope standing in for it) and muscle activation ``a``,
Winters & Stark (thesis App. A.2, Eq. A.2-A.4)::

    adot = (u - a)(t1 u + t2)   if u >= a   (activation)
    adot = (u - a) t2           if u <  a   (deactivation)
    t2 = 1 / tau_fall,  t1 = 1 / tau_rise - t2

The law itself is :mod:`pinmsk.muscles.activation` (the one implementation:
this effect, MSO, EID and FSO call it); this module holds the components and
:func:`excitation_path`, the one place an analysis reads a model's activation
time constants and delays from.

* :class:`ActivationDynamics` -- both time constants fitted (defaults: the
  Winters & Stark values, 11 ms and 68 ms).  ``t1 u + t2 = u / tau_rise +
  (1 - u) / tau_fall > 0`` for ``0 <= u <= 1``, so any positive pair is
  admissible.  Integration: held steps at the mean of each interval's two
  samples (:func:`pinmsk.muscles.activation.activation_from_excitation`),
  second-order accurate and unconditionally stable; ``a(t_0) = u(t_0)``;
  vectorised over muscles and parameter sets.
* :class:`DelayedActivationDynamics` -- an electromechanical delay followed
  by activation dynamics, the two fitted together (three parameters): the
  diagnosis ranks it beside each alone, so a pure delay, pure activation
  dynamics and both are told apart by their held-out score.

Without an activation component a model's activation follows its muscle
model's constants in the analyses that need activation dynamics (MSO, EID),
and equals the measured signal in the muscle-level diagnosis (``a = u``).
Like every muscle-level effect these apply no generalized force of their own:
they act through the muscle forces ``F = a F_active + F_passive``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..components import Parameter
from ..errors import ModelError
from ..muscles.activation import TAU_FALL, TAU_RISE, activation_from_excitation
from ._base import SignalEffect, signal_parts
from .delay import ElectromechanicalDelay
from .registry import register

__all__ = ["ActivationDynamics", "DelayedActivationDynamics", "ExcitationPath", "excitation_path"]

_TAU_RISE = Parameter("tau_rise", TAU_RISE, 0.001, 0.3, "s", "activation time constant")
_TAU_FALL = Parameter("tau_fall", TAU_FALL, 0.002, 0.6, "s", "deactivation time constant")


def _muscle_candidates(cls, model, context, kinds):
    """One candidate for all muscles in a muscle-level comparison, unless the model already has a
    part of one of ``kinds`` (classes) on some muscle (a second one would double it)."""
    if context.mode != "muscle" or model.muscles is None:
        return []
    if any(isinstance(p, kinds) for p in signal_parts(model)):
        return []
    return [cls("muscles")]


@register
class ActivationDynamics(SignalEffect):
    """Winters & Stark first-order activation dynamics with fitted ``tau_rise``, ``tau_fall``."""

    family = "activation_dynamics"
    order = 10
    parameters = (_TAU_RISE, _TAU_FALL)
    zero_params = None     # there is no parameter value that removes the lag

    @classmethod
    def candidates(cls, model, context):
        return _muscle_candidates(cls, model, context, (ActivationDynamics,))

    def transform_batch(self, t, u, params, mask=None):
        """Activations for P parameter sets; ``u`` is (N, m), or (P, N, m) for one signal per set."""
        (tr, tf), ub, cols, out = self.broadcast_batch(u, mask, params["tau_rise"], params["tau_fall"])
        if ub.shape[1] < 2 or cols.size == 0:
            return out
        us = np.moveaxis(ub[:, :, cols], 1, 0)                                   # (N, P, k)
        a = activation_from_excitation(np.asarray(t, dtype=float), us, tau_rise=tr[:, None], tau_fall=tf[:, None])
        out[:, :, cols] = np.moveaxis(a, 0, 1)
        return out


@register
class DelayedActivationDynamics(SignalEffect):
    """Electromechanical delay, then Winters & Stark activation dynamics: ``a = A(u(t - delay))``."""

    family = "delayed_activation_dynamics"
    order = 10
    parameters = (ElectromechanicalDelay.parameters[0], _TAU_RISE, _TAU_FALL)
    zero_params = None

    @classmethod
    def candidates(cls, model, context):
        return _muscle_candidates(cls, model, context, (ActivationDynamics, ElectromechanicalDelay))

    def parts(self) -> tuple[SignalEffect, ...]:
        v = self.values
        return (ElectromechanicalDelay(self.target, delay=v["delay"]),
                ActivationDynamics(self.target, tau_rise=v["tau_rise"], tau_fall=v["tau_fall"]))

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("_shift", None)
        return state

    def transform_batch(self, t, u, params, mask=None):
        """Delayed, then activated signals for P parameter sets (see :meth:`SignalEffect.transform_batch`)."""
        shift = self.__dict__.get("_shift")
        if shift is None:             # one delay part kept: it memoises the signal's spectrum
            shift = self.__dict__.setdefault("_shift", ElectromechanicalDelay(self.target))
        d = shift.transform_batch(t, u, {"delay": params["delay"]}, mask)
        return ActivationDynamics(self.target).transform_batch(
            t, d, {"tau_rise": params["tau_rise"], "tau_fall": params["tau_fall"]}, mask)


@dataclass(frozen=True)
class ExcitationPath:
    """What lies between each muscle's recorded excitation and its activation in a model.

    ``tau_rise``, ``tau_fall`` (m,) s: the activation time constants (the
    model's activation component where it declares one -- ``declared`` (m,) --
    else its muscle model's); ``delay`` (m,) s: the electromechanical delay
    (0 without one); ``sources``: labels of the muscle-level components read;
    ``default``: where undeclared constants come from.
    """

    muscles: tuple[str, ...]
    tau_rise: np.ndarray
    tau_fall: np.ndarray
    delay: np.ndarray
    declared: np.ndarray
    sources: tuple[str, ...]
    default: str

    @property
    def has_delay(self) -> bool:
        return bool(np.any(self.delay > 0))

    def describe(self) -> str:
        """One line: the time constants and delays used, and where they come from."""
        def span(x, scale=1e3):
            lo, hi = float(np.min(x)) * scale, float(np.max(x)) * scale
            return f"{lo:g}" if np.isclose(lo, hi) else f"{lo:g}-{hi:g}"
        src = (", ".join(self.sources) if np.all(self.declared) else
               (f"{', '.join(self.sources)}; others {self.default}" if self.sources else self.default))
        out = (f"Winters-Stark, tau_rise {span(self.tau_rise)} ms, tau_fall {span(self.tau_fall)} ms "
               f"({src})")
        if self.has_delay:
            out += f"; electromechanical delay {span(self.delay)} ms"
        return out

    def recorded(self, t, u) -> np.ndarray:
        """The excitations a recording would show, ``u(t + delay)`` (N, m), for the muscles' ``u`` (N, m).

        The shift is :class:`ElectromechanicalDelay`'s own (band-limited) with the
        delay negated; frames whose ``t + delay`` lies past the end are NaN (the
        recording would have been made after the trial).
        """
        u = np.asarray(u, dtype=float)
        if not self.has_delay:
            return u.copy()
        t = np.asarray(t, dtype=float)
        out = u.copy()
        for d in np.unique(self.delay[self.delay > 0]):
            mask = self.delay == d
            shifted = ElectromechanicalDelay("muscles", delay=float(d)).transform_batch(
                t, u, {"delay": np.array([-float(d)])}, mask)[0]
            out[:, mask] = shifted[:, mask]
            late = t > t[-1] - d + 1e-12
            out[np.ix_(late, mask)] = np.nan
        return out


def excitation_path(model) -> ExcitationPath:
    """The :class:`ExcitationPath` of ``model``: its muscle-level components read in chain order.

    A component is understood through its parts (``parts()``, default itself):
    :class:`ActivationDynamics` sets the time constants of the muscles it
    targets, :class:`~pinmsk.effects.delay.ElectromechanicalDelay` adds its
    delay.  Raises :class:`~pinmsk.errors.ModelError` naming any other
    muscle-level component, or two activation dynamics on one muscle (a
    second-order path no analysis here represents).
    """
    ms = model.muscles
    if ms is None:
        raise ModelError(f"model '{model.name}' has no muscles: it has no excitation path")
    m = ms.n
    mtu = ms.mtu
    tr = np.full(m, float(mtu.tau_rise))
    tf = np.full(m, float(mtu.tau_fall))
    delay = np.zeros(m)
    declared = np.zeros(m, dtype=bool)
    owner = [None] * m
    sources = []
    chain = sorted([c for c in model.effects if isinstance(c, SignalEffect)], key=lambda c: c.order)
    for comp in chain:
        for part in comp.parts():
            mask = part.muscle_mask(model)
            if isinstance(part, ActivationDynamics):
                twice = [ms.names[i] for i in np.flatnonzero(mask & declared)]
                if twice:
                    raise ModelError(
                        f"model '{model.name}' has two activation dynamics on {', '.join(twice[:4])} "
                        f"({owner[int(np.flatnonzero(mask & declared)[0])]} and {comp.label}); an analysis "
                        "takes one first-order activation per muscle: remove one (model.without(label))")
                v = part.values
                tr[mask], tf[mask] = v["tau_rise"], v["tau_fall"]
                declared |= mask
                for i in np.flatnonzero(mask):
                    owner[i] = comp.label
            elif isinstance(part, ElectromechanicalDelay):
                delay[mask] += part.values["delay"]
            else:
                raise ModelError(
                    f"{comp.label} is a muscle-level component the analyses cannot represent (they know "
                    "activation_dynamics and electromechanical_delay): remove it (model.without"
                    f"('{comp.label}')) or give it parts() made of those")
        sources.append(comp.label)
    default = f"the {ms.model_type} muscle model's"
    return ExcitationPath(tuple(ms.names), tr, tf, delay, declared, tuple(sources), default)
