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
  rates) or of the excitations' rate, which regularizes the collocation solution;
- :class:`ControlEffort`, :class:`StateTracking`, :class:`ContactTracking` -- OpenSim Moco's
  ``MocoControlGoal``, ``MocoStateTrackingGoal`` (as ``MocoTrack`` configures it) and
  ``MocoContactTrackingGoal``, with Moco's integrands and normalisations (plain integrals, no
  ``1/T``), so that an objective is in Moco's units.
"""
from __future__ import annotations

import numpy as np

from ...errors import ModelError
from ._values import ValueEq

__all__ = ["Cost", "CostSum", "Effort", "ActuatorEffort", "MetabolicEnergy", "TrackCoordinates", "TrackSignals",
           "Smoothness", "FinalTime", "ControlEffort", "StateTracking", "ContactTracking"]


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

    def _covered(self, times) -> np.ndarray:
        """``times`` as an array, refused by name when they leave the reference's ``self.time``."""
        t = np.asarray(times, dtype=float)
        if t.min() < self.time[0] - 1e-9 or t.max() > self.time[-1] + 1e-9:
            raise ModelError(f"cost '{self.name}': the reference covers {self.time[0]:g}-{self.time[-1]:g} s, "
                             f"the horizon {t.min():g}-{t.max():g} s")
        return t

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
        t = self._covered(times)
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


# ---------------------------------------------------------------------------------------------
# OpenSim Moco's goals, as Moco defines them (opensim-core OpenSim/Moco/MocoGoal/*.cpp, read there):
# a goal's value is the plain time integral of its integrand (no 1/T), optionally divided by the
# displacement and / or the duration (MocoGoal::calcGoal), times its weight.

def _moco_divisor(per, glob, j):
    """MocoGoal's ``divide_by_displacement`` / ``divide_by_duration`` of an integral."""
    if per == "distance":
        return glob["xN"][j] - glob["x0"][j]
    if per == "time":
        return glob["T"]
    return 1.0


class ControlEffort(Cost):
    """Moco's ``MocoControlGoal``: ``int sum_k w_k |u_k|^p dt`` over ALL the model's controls.

    The controls are the muscles' excitations and the CoordinateActuators' controls (Moco's
    ``createControlNamesFromModel``), each weighted by ``weights`` (name -> weight, muscle names
    or actuator names; default 1; a weight of 0 drops the control, as Moco does).  ``exponent``:
    an integer >= 2 (Moco refuses less; 2 is ``u*u``, otherwise ``|u|^p``).  ``per``: None (Moco's
    default: the integral itself), ``"distance"`` (``divide_by_displacement``) or ``"time"``
    (``divide_by_duration``).  Moco divides by the norm of the centre of mass's displacement
    (``MocoGoal::calcSystemDisplacement``); here it is the forward coordinate's displacement
    (``coordinate``, default the problem's forward coordinate), which equals it in a half gait
    cycle with left/right symmetry (every other coordinate ends mirrored, so the centre of mass
    moves as the pelvis does) and in any motion whose posture at the end is the start's.
    """

    name = "control_effort"

    def __init__(self, exponent: int = 2, *, per: str | None = None, weights: dict | None = None,
                 coordinate: str | None = None, weight: float = 1.0, name: str | None = None):
        super().__init__(weight=weight, name=name)
        if int(exponent) != exponent or exponent < 2:
            raise ModelError(f"ControlEffort exponent must be an integer >= 2 (as Moco's), got {exponent}")
        if per not in (None, "distance", "time"):
            raise ModelError(f"ControlEffort per must be None, 'distance' or 'time', not {per!r}")
        self.exponent, self.per, self.coordinate = int(exponent), per, coordinate
        self.weights = dict(weights or {})

    def check(self, problem) -> None:
        muscles = list(problem.model.muscle_names) if problem.model.muscles is not None else []
        acts = [a.name for a in problem._pm.actuators]
        if not muscles and not acts:
            raise ModelError(f"cost '{self.name}': model '{problem.model.name}' has no controls")
        unknown = sorted(set(self.weights) - set(muscles) - set(acts))
        if unknown:
            raise ModelError(f"cost '{self.name}': weights name no control of the model: {', '.join(unknown)} "
                             f"(controls: {', '.join(muscles + acts)})")
        self._wm = np.array([float(self.weights.get(n, 1.0)) for n in muscles])
        self._wa = np.array([float(self.weights.get(n, 1.0)) for n in acts])
        if self.per == "distance":
            self._j = problem.model.coordinate_index(self.coordinate or problem.forward_coordinate())
        else:
            self._j = None

    def _power(self, x):
        import casadi as ca
        return x * x if self.exponent == 2 else ca.fabs(x) ** self.exponent

    def integrand(self, pt, ref=None):
        import casadi as ca
        out = 0.0
        if self._wm.size:
            out = out + ca.dot(ca.DM(self._wm), self._power(pt["e"]))
        if self._wa.size:
            out = out + ca.dot(ca.DM(self._wa), self._power(pt["act"]))
        return out

    def finish(self, integral, glob):
        return integral / _moco_divisor(self.per, glob, self._j)

    def linear_finish(self, glob):
        if self.per is None:
            return 1.0
        if self.per == "time" and isinstance(glob["T"], (int, float)):
            return 1.0 / glob["T"]
        return None


class StateTracking(Cost):
    """Moco's ``MocoStateTrackingGoal`` as ``MocoTrack`` sets it up: ``int sum_i w_i (y_i - r_i(t))^2 dt``.

    ``time`` (N,) and ``q`` (name -> (N,) coordinate values, model units) are the reference;
    ``v`` (name -> (N,)) optional speed references.  ``lowpass``: cut-off (Hz) of a zero-lag
    low-pass of the positions first (MocoTrack's ``TabOpLowPassFilter``; OpenSim's
    ``Signal::LowpassIIR`` is a third-order Butterworth run forwards and backwards, here
    :func:`pinmsk.signals.filtering.lowpass` of order 3).  ``position_derivatives``: also track
    the positions' time derivatives as the speeds (``track_reference_position_derivatives``).
    The references are splined (a quintic interpolating spline; Moco's ``GCVSplineSet`` is a
    quintic GCV-smoothing spline, which on these smooth data interpolates too) and evaluated at
    the collocation points; the speeds are the spline's derivative.  ``weights``: name -> weight
    (``"<coord>"`` for the value, ``"<coord>_speed"`` for the speed; default 1);
    ``scale_weights_with_range``: divide each weight by its reference's range (Moco's option,
    off by default).  The value is the integral itself (``MocoStateTrackingGoal::calcGoalImpl``).
    """

    name = "state_tracking"

    def __init__(self, time, q: dict, v: dict | None = None, *, lowpass: float | None = None,
                 position_derivatives: bool = False, weights: dict | None = None,
                 scale_weights_with_range: bool = False, weight: float = 1.0, name: str | None = None):
        super().__init__(weight=weight, name=name)
        t = np.asarray(time, dtype=float)
        if t.ndim != 1 or t.size < 6 or np.any(np.diff(t) <= 0):
            raise ModelError(f"cost '{self.name}': the reference time must increase, with >= 6 samples")
        qs = {k: np.asarray(x, dtype=float) for k, x in q.items()}
        for k, x in list(qs.items()) + list((v or {}).items()):
            if np.shape(x) != t.shape or not np.all(np.isfinite(x)):
                raise ModelError(f"cost '{self.name}': reference '{k}' needs {t.size} finite samples, "
                                 f"got shape {np.shape(x)}")
        if lowpass is not None and qs:
            from ...signals.filtering import lowpass as _lp
            rate = (t.size - 1) / (t[-1] - t[0])
            Y = _lp(np.column_stack(list(qs.values())), rate=rate, cutoff=float(lowpass), order=3)
            qs = {k: Y[:, i] for i, k in enumerate(qs)}
        from scipy.interpolate import make_interp_spline
        self.time = t
        self._splines = {("q", k): make_interp_spline(t, x, k=5) for k, x in qs.items()}
        if position_derivatives:
            for k in qs:
                if k not in (v or {}):
                    self._splines[("v", k)] = self._splines[("q", k)].derivative()
        for k, x in (v or {}).items():
            self._splines[("v", k)] = make_interp_spline(t, np.asarray(x, dtype=float), k=5)
        self.weights, self.scale_weights_with_range = dict(weights or {}), bool(scale_weights_with_range)
        self.q = qs

    def reference(self, times) -> dict:
        """The splined references at ``times``: ``{"<coord>": ..., "<coord>_speed": ...}``."""
        t = np.asarray(times, dtype=float)
        return {(k if g == "q" else f"{k}_speed"): sp(t) for (g, k), sp in self._splines.items()}

    def check(self, problem) -> None:
        m = problem.model
        keys = list(self._splines)
        self._rows = [(g, m.coordinate_index(k)) for g, k in keys]
        w = []
        for g, k in keys:
            label = k if g == "q" else f"{k}_speed"
            wi = float(self.weights.get(label, 1.0))
            if self.scale_weights_with_range:
                y = self._splines[(g, k)](self.time)
                wi /= abs(float(np.max(y) - np.min(y)))
            w.append(wi)
        unknown = sorted(set(self.weights) - {k if g == "q" else f"{k}_speed" for g, k in keys})
        if unknown:
            raise ModelError(f"cost '{self.name}': weights name no tracked state: {', '.join(unknown)}")
        self._w = np.array(w)

    def references(self, problem, times) -> np.ndarray:
        t = self._covered(times)
        return np.vstack([self._splines[key](t) for key in self._splines])

    def integrand(self, pt, ref=None):
        import casadi as ca
        y = ca.vertcat(*[pt[g][j] for g, j in self._rows])
        e = y - ref
        return ca.dot(ca.DM(self._w), e * e)

    def finish(self, integral, glob):
        return integral

    def linear_finish(self, glob):
        return 1.0


class ContactTracking(Cost):
    """Moco's ``MocoContactTrackingGoal``: ``1/(m g) int sum_groups |P (f_group - f_ref(t)) / n|^2 dt``.

    ``groups``: external-force name -> ``(contacts, force)``: the contact components whose forces
    on their bodies add up to the group's force (labels such as ``"smooth_sphere_half_space:heel_r"``,
    the part after ``:`` or the contact's frame), and the reference force (N, 3) in the ground frame
    sampled at ``time`` (splined like Moco's GCVSplineSet, quintic).  ``projection``: ``"none"``,
    ``"plane"`` (remove the error's component along ``vector``: the plane's normal) or ``"vector"``
    (keep only it).  ``normalize_tracking_error``: divide each axis's error by the reference's peak
    magnitude on that axis, over all groups' own data (``n``; Moco's default False: ``n = 1``).  ``m g``:
    the model's weight (total mass times the gravity's norm), Moco's denominator.
    """

    name = "contact_tracking"

    def __init__(self, groups: dict, time, *, projection: str = "none", vector=None,
                 normalize_tracking_error: bool = False, weight: float = 1.0, name: str | None = None):
        super().__init__(weight=weight, name=name)
        if projection not in ("none", "plane", "vector"):
            raise ModelError(f"cost '{self.name}': projection must be 'none', 'plane' or 'vector', "
                             f"not {projection!r}")
        if projection != "none":
            if vector is None:
                raise ModelError(f"cost '{self.name}': projection '{projection}' needs its vector")
            n = np.asarray(vector, dtype=float).reshape(3)
            if not np.linalg.norm(n) > 0:
                raise ModelError(f"cost '{self.name}': the projection vector must not be zero")
            self.vector = n / np.linalg.norm(n)
        else:
            self.vector = None
        t = np.asarray(time, dtype=float)
        from scipy.interpolate import make_interp_spline
        self.time, self.projection = t, projection
        self.groups, self._splines, self._norm = {}, {}, {}
        for g, (contacts, force) in groups.items():
            F = np.asarray(force, dtype=float)
            if F.shape != (t.size, 3) or not np.all(np.isfinite(F)):
                raise ModelError(f"cost '{self.name}': group '{g}' needs a finite force of shape ({t.size}, 3), "
                                 f"got {F.shape}")
            self.groups[g] = (tuple(contacts), F)
            self._splines[g] = make_interp_spline(t, F, k=5)
            if normalize_tracking_error:
                peak = np.max(np.abs(F), axis=0)
                if np.any(peak < 1e-12):
                    raise ModelError(f"cost '{self.name}': normalize_tracking_error needs a nonzero reference "
                                     f"force on every axis; group '{g}' is zero along "
                                     f"{'xyz'[int(np.argmin(peak))]}")
                self._norm[g] = peak
            else:
                self._norm[g] = np.ones(3)

    def check(self, problem) -> None:
        contacts = list(problem._pm.contacts)
        if not contacts:
            raise ModelError(f"cost '{self.name}': model '{problem.model.name}' has no contacts")
        keys = {}
        for i, c in enumerate(contacts):
            for k in (c.label, c.label.split(":")[-1], getattr(c, "target", None)):
                if k:
                    keys.setdefault(k, i)
        self._idx = {}
        for g, (names, _) in self.groups.items():
            bad = [n for n in names if n not in keys]
            if bad:
                raise ModelError(f"cost '{self.name}': group '{g}' names unknown contacts {', '.join(bad)} "
                                 f"(has: {', '.join(c.label for c in contacts)})")
            self._idx[g] = [keys[n] for n in names]
        g = np.asarray(problem.model.pin.gravity.linear, dtype=float)
        self._den = problem._pm.mass * (float(np.linalg.norm(g)) or 1.0)

    def references(self, problem, times) -> np.ndarray:
        t = self._covered(times)
        return np.vstack([self._splines[g](t).T for g in self.groups])

    def integrand(self, pt, ref=None):
        import casadi as ca
        cf = pt["contact_forces"]
        out = 0.0
        for k, g in enumerate(self.groups):
            f = sum((cf[3 * i: 3 * i + 3] for i in self._idx[g]), ca.SX.zeros(3))
            e = (f - ref[3 * k: 3 * k + 3]) / ca.DM(self._norm[g])
            if self.projection != "none":
                n = ca.DM(self.vector)
                along = ca.dot(e, n) * n
                e = along if self.projection == "vector" else e - along
            out = out + ca.sumsqr(e)
        return out

    def finish(self, integral, glob):
        return integral / self._den

    def linear_finish(self, glob):
        return 1.0 / self._den
