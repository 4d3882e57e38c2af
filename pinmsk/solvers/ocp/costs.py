"""Named cost terms of the optimal-control engine, composed as weighted sums (crocoddyl's cost-sum habit).

A term is an object with a ``name`` and a ``weight``; ``w * term`` reweights it
and ``a + b`` makes a :class:`CostSum`, so an objective reads as it is written::

    cost = 0.1 * Effort(exponent=2, normalize=False) + 0.9 * TrackCoordinates(target)

Each term gives an *integrand* evaluated at every collocation point (inside the
engine's per-point CasADi function, with the same component code the numpy
analyses use) and a *finish* that turns its time integral into the term's
value (by default the mean over the horizon, ``1/T int ... dt``).  The engine
integrates with the transcription's own quadrature (trapezoid or Simpson) and
reports every term's unweighted value next to the weighted objective.

Terms (thesis equation in brackets):

- :class:`Effort` -- ``1/sum S_i 1/T int sum_i S_i a_i^P dt`` (Eq. 3.5; ``normalize=False`` is
  the ``J_1`` of Eq. 3.3);
- :class:`MetabolicEnergy` -- Umberger 2003 / Bhargava 2004 heat rates plus work (App. B,
  C1-smoothed switches for the gradients); per unit time (Eq. 3.6, divided by a fixed
  normalizer) or per distance and body mass (cost of transport, Eq. 5.6);
- :class:`TrackCoordinates` -- ``1/(T max q_d^2) int (q - q_d)^2 dt`` (the ``J_2`` of Eq. 3.3);
- :class:`TrackSignals` -- any per-point quantity (EMG envelopes against activations, ground
  reaction forces) against sampled references, mean squared error over scales;
- :class:`ActuatorEffort` -- the mean square of the model's actuator controls (reserves, residuals;
  the actuators' part of Moco's control effort);
- :class:`FinalTime` -- the duration itself (s), with a free final time (Moco's final-time goal);
- :class:`Smoothness` -- the mean square of the implicit controls (accelerations, tendon-force
  rates) or of the excitations' rate, which regularizes the collocation solution.
"""
from __future__ import annotations

import numpy as np

from ...errors import ModelError
from ._values import ValueEq

__all__ = ["Cost", "CostSum", "Effort", "ActuatorEffort", "MetabolicEnergy", "TrackCoordinates", "TrackSignals",
           "Smoothness", "FinalTime"]


class Cost(ValueEq):
    """A named cost term ``weight * value``; subclasses give ``integrand(pt)`` and may override ``finish``."""

    name = "cost"

    def __init__(self, *, weight: float = 1.0, name: str | None = None):
        w = float(weight)
        if not np.isfinite(w) or w < 0:
            raise ModelError(f"cost '{name or self.name}': weight must be finite and >= 0, got {weight}")
        self.weight = w
        if name is not None:
            self.name = str(name)

    # -- composition -------------------------------------------------------------
    def terms(self) -> list["Cost"]:
        return [self]

    def __add__(self, other: "Cost") -> "CostSum":
        if not isinstance(other, Cost):
            return NotImplemented
        return CostSum(self.terms() + other.terms())

    def __mul__(self, w: float) -> "Cost":
        import copy
        c = copy.copy(self)
        c.weight = self.weight * float(w)
        return c

    __rmul__ = __mul__

    # -- the engine's interface --------------------------------------------------
    def check(self, problem) -> None:
        """Refuse, by name, what this term cannot use in ``problem`` (called once at setup)."""

    def references(self, problem, times) -> np.ndarray | None:
        """Per-point numeric reference (n_ref, n_points) this term needs, or None."""
        return None

    def integrand(self, pt, ref=None):
        """The scalar integrand at one collocation point (``pt``: the point's quantities)."""
        raise NotImplementedError

    def finish(self, integral, glob):
        """This term's value from ``int integrand dt`` (``glob``: horizon quantities T, x0, xN)."""
        return integral / glob["T"]

    def linear_finish(self, glob) -> float | None:
        """``a`` if :meth:`finish` is ``a * integral`` with a constant ``a`` (a fixed duration), else None."""
        return 1.0 / glob["T"] if isinstance(glob["T"], (int, float)) else None

    def __repr__(self) -> str:
        return f"{self.weight:g} * {type(self).__name__}(name={self.name!r})"


class CostSum(Cost):
    """A weighted sum of named terms (the objective)."""

    name = "sum"

    def __init__(self, terms):
        super().__init__()
        self._terms = list(terms)
        names = [t.name for t in self._terms]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ModelError(f"cost terms need distinct names; repeated: {', '.join(dup)} "
                             "(pass name=... to one of them)")

    def terms(self) -> list[Cost]:
        return list(self._terms)

    def _public(self) -> dict:
        return {"terms": self._terms}

    def __mul__(self, w: float) -> "CostSum":
        return CostSum([t * w for t in self._terms])

    __rmul__ = __mul__

    def __repr__(self) -> str:
        return " + ".join(repr(t) for t in self._terms)


def _weights(problem, weights):
    """Per-muscle weights S_i of Eq. 3.5: 'none' (1), 'volume' (muscle volume) or an array."""
    ms = problem.model.muscles
    if isinstance(weights, str):
        if weights == "none":
            return np.ones(ms.n)
        if weights == "volume":
            return np.asarray(ms.volume, dtype=float)
        raise ModelError(f"Effort weights must be 'none', 'volume' or an array, not {weights!r}")
    S = np.asarray(weights, dtype=float)
    if S.shape != (ms.n,):
        raise ModelError(f"Effort weights: {ms.n} values needed (one per muscle), got shape {S.shape}")
    return S


class Effort(Cost):
    """Muscle effort ``1/sum S_i 1/T int sum_i S_i x_i^P dt`` (thesis Eq. 3.5).

    ``of="activation"`` (default) or ``"excitation"``; ``weights`` ``"none"`` (S_i = 1),
    ``"volume"`` (S_i = V_i) or an array; ``normalize=False`` drops ``1/sum S_i``
    (the ``J_1`` of Eq. 3.3).  Also the "small effort term" of predictive gait.
    """

    name = "effort"

    def __init__(self, exponent: float = 2.0, *, weights="none", normalize: bool = True,
                 of: str = "activation", weight: float = 1.0, name: str | None = None):
        super().__init__(weight=weight, name=name)
        if of not in ("activation", "excitation"):
            raise ModelError(f"Effort of must be 'activation' or 'excitation', not {of!r}")
        if not float(exponent) > 0:
            raise ModelError(f"Effort exponent must be > 0, got {exponent}")
        self.exponent, self.weights, self.normalize, self.of = float(exponent), weights, bool(normalize), of

    def check(self, problem) -> None:
        if problem.model.muscles is None:
            raise ModelError(f"cost '{self.name}': model '{problem.model.name}' has no muscles")
        S = _weights(problem, self.weights)
        self._S = S / S.sum() if self.normalize else S

    def integrand(self, pt, ref=None):
        import casadi as ca
        x = pt["a"] if self.of == "activation" else pt["e"]
        # a^P of a slightly negative iterate is NaN for non-integer P: IPOPT stays within the
        # bounds, but the Hermite-Simpson midpoint activation is an interpolant, not a variable
        xs = ca.fmax(x, 0.0) if self.exponent != int(self.exponent) else x
        return ca.dot(ca.DM(self._S), xs ** self.exponent)


class ActuatorEffort(Cost):
    """``1/T int mean_k u_k^2 dt`` over the model's CoordinateActuators' controls (reserves and
    residuals: a large weight keeps them for what the muscles cannot do)."""

    name = "actuator_effort"

    def check(self, problem) -> None:
        if not problem._pm.actuators:
            raise ModelError(f"cost '{self.name}': model '{problem.model.name}' has no actuators")

    def integrand(self, pt, ref=None):
        import casadi as ca
        return ca.sumsqr(pt["act"]) / pt["act"].numel()


class MetabolicEnergy(Cost):
    """Metabolic energy of the muscles (thesis App. B), ``model`` ``"umberger2003"`` or ``"bhargava2004"``.

    ``per="time"``: ``1/E_norm 1/T int sum_i E_i' dt`` (Eq. 3.6), ``E_norm`` a fixed
    normalizer (W; default 1, the mean metabolic power itself); ``per="distance"``:
    ``1/(m d) int sum_i E_i' dt`` in J/(kg m) with ``d`` the distance travelled by
    ``coordinate`` (the cost of transport, Eq. 5.6; ``m`` the model's mass).  The heat
    rates' switches (``u > a``, shortening, ``l > l_opt``) are C1-smoothed with width
    ``smooth`` (:mod:`pinmsk.energy`), which the gradients need.
    """

    name = "metabolic"

    def __init__(self, model: str = "umberger2003", *, per: str = "time", coordinate: str | None = None,
                 normalizer: float = 1.0, smooth: float = 0.01, weight: float = 1.0, name: str | None = None):
        super().__init__(weight=weight, name=name)
        if model not in ("umberger2003", "bhargava2004"):
            raise ModelError(f"metabolic model must be umberger2003 or bhargava2004, not {model!r}")
        if per not in ("time", "distance"):
            raise ModelError(f"MetabolicEnergy per must be 'time' or 'distance', not {per!r}")
        if not normalizer > 0:
            raise ModelError(f"MetabolicEnergy normalizer must be > 0, got {normalizer}")
        self.model, self.per, self.coordinate = model, per, coordinate
        self.normalizer, self.smooth = float(normalizer), float(smooth)

    def check(self, problem) -> None:
        if problem.model.muscles is None:
            raise ModelError(f"cost '{self.name}': model '{problem.model.name}' has no muscles")
        if self.model == "bhargava2004":
            raise ModelError("MetabolicEnergy('bhargava2004') needs each muscle's stimulation time (a "
                             "history, not a point quantity); the optimal-control engine uses "
                             "umberger2003, or bhargava2004 with the stimulation-time factor at 1")
        if self.per == "distance":
            c = self.coordinate or problem.forward_coordinate()
            problem.model.coordinate_index(c)
            self._j = problem.model.coordinate_index(c)
        problem.need("metabolic", smooth=self.smooth)

    def integrand(self, pt, ref=None):
        import casadi as ca
        return ca.sum1(pt["metabolic_rate"])

    def linear_finish(self, glob):
        a = super().linear_finish(glob)
        return None if (a is None or self.per == "distance") else a / self.normalizer

    def finish(self, integral, glob):
        if self.per == "time":
            return integral / glob["T"] / self.normalizer
        d = glob["xN"][self._j] - glob["x0"][self._j]
        return integral / (glob["mass"] * d)


class TrackCoordinates(Cost):
    """Tracking ``1/(T max q_d^2) int (q_c - q_d)^2 dt`` of one coordinate (thesis Eq. 3.3, ``J_2``).

    ``target``: a :class:`~pinmsk.solvers.ocp.target.Target`; ``coordinate``: default the
    problem's tracked coordinate; ``normalize=False`` drops ``1/max q_d^2``.
    """

    name = "tracking"

    def __init__(self, target, *, coordinate: str | None = None, normalize: bool = True,
                 weight: float = 1.0, name: str | None = None):
        super().__init__(weight=weight, name=name)
        self.target, self.coordinate, self.normalize = target, coordinate, bool(normalize)

    def check(self, problem) -> None:
        self._j = problem.model.coordinate_index(self.coordinate or problem.model.coordinates[0])
        t = problem.nominal_times()
        self._scale = 1.0 / self.target.peak_square(t) if self.normalize else 1.0

    def integrand(self, pt, ref=None):
        e = pt["q"][self._j] - self.target(pt["t"])
        return self._scale * e * e


class TrackSignals(Cost):
    """Mean squared, scaled error of per-point quantities against sampled references.

    ``quantity``: a point quantity of the engine (``"a"`` activations, ``"e"`` excitations,
    ``"grf"`` ground reaction forces, ``"q"`` coordinates); ``index``: which of its rows;
    ``time``, ``values`` (N, len(index)) the reference, linearly interpolated to the
    collocation points; ``scale`` (one per row) divides the errors (e.g. body weight for
    GRF, the EMG envelope's peak for activations).
    """

    name = "track_signals"

    def __init__(self, quantity: str, index, time, values, *, scale=1.0, weight: float = 1.0,
                 name: str | None = None):
        super().__init__(weight=weight, name=name or f"track_{quantity}")
        self.quantity = quantity
        self.index = [int(i) for i in np.atleast_1d(index)]
        self.time = np.asarray(time, dtype=float)
        self.values = np.asarray(values, dtype=float).reshape(self.time.size, len(self.index))
        self.scale = np.broadcast_to(np.asarray(scale, dtype=float), (len(self.index),)).copy()

    QUANTITIES = ("q", "v", "qdd", "a", "e", "F", "contact_forces", "act")

    def check(self, problem) -> None:
        if self.quantity not in self.QUANTITIES:
            raise ModelError(f"cost '{self.name}': unknown quantity '{self.quantity}'; valid: "
                             f"{', '.join(self.QUANTITIES)}")

    def references(self, problem, times) -> np.ndarray:
        t = np.asarray(times, dtype=float)
        if t.min() < self.time[0] - 1e-9 or t.max() > self.time[-1] + 1e-9:
            raise ModelError(f"cost '{self.name}': the reference covers {self.time[0]:g}-{self.time[-1]:g} s, "
                             f"the horizon {t.min():g}-{t.max():g} s")
        return np.vstack([np.interp(t, self.time, self.values[:, j]) / self.scale[j]
                          for j in range(len(self.index))])

    def integrand(self, pt, ref=None):
        import casadi as ca
        x = ca.vertcat(*[pt[self.quantity][i] / self.scale[j] for j, i in enumerate(self.index)])
        return ca.sumsqr(x - ref) / len(self.index)


class Smoothness(Cost):
    """Mean square of the implicit controls (``of="qdd"`` accelerations, ``"df_t"`` tendon-force
    rates), scaled by ``scale`` (one number), a regularizer of the collocation solution."""

    name = "smoothness"

    def __init__(self, of: str = "qdd", *, scale: float = 1.0, weight: float = 1.0, name: str | None = None):
        super().__init__(weight=weight, name=name or f"smoothness_{of}")
        if of not in ("qdd", "df_t", "e"):
            raise ModelError(f"Smoothness of must be 'qdd', 'df_t' or 'e', not {of!r}")
        self.of, self.scale = of, float(scale)

    def check(self, problem) -> None:
        if self.of == "df_t" and not problem.compliant:
            raise ModelError(f"cost '{self.name}': tendon-force rates exist only with compliant tendons")

    def integrand(self, pt, ref=None):
        import casadi as ca
        return ca.sumsqr(pt[self.of] / self.scale) / pt[self.of].numel()


class FinalTime(Cost):
    """The duration ``T`` (s) as a cost (with a free final time; Moco's ``MocoFinalTimeGoal``)."""

    name = "final_time"

    def integrand(self, pt, ref=None):
        return 0.0 * pt["t"]

    def finish(self, integral, glob):
        return glob["T"]

    def linear_finish(self, glob):
        return None
