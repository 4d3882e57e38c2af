"""Compare a model with measurements: residuals, noise floor, where it fails.

Three comparison modes (:func:`compare`, ``mode=``):

``"torque"``
    Inverse dynamics of the measured kinematics against the measured
    generalized forces ``<coord>_moment`` (dynamometer, exoskeleton, another
    pipeline).  Unactuated coordinates (a floating base such as gait2d's
    ``torso_x, torso_y, torso_angle``) are compared against zero when the trial
    has ground reaction forces, which enter as world-frame wrenches at the
    feet: their rows of inverse dynamics vanish when model and forces agree.
``"muscle"``
    Net joint moments of the muscles driven by measured excitations or EMG
    (``<muscle>_excitation`` / ``<muscle>_emg``, normalised to [0, 1]):
    ``tau_mus = R(q)^T (a F_active(q, qdot) + F_passive(q))`` with ``a`` the
    signal after the model's muscle-level effects (``a = u`` without any),
    against inverse dynamics.
``"contact"``
    A kinematically driven foot's ground reaction force (normal, friction,
    COP) from its contact spheres against the measured GRF; chosen by
    ``"auto"`` for a foot2d-like model and a trial with GRF but no
    ``<coord>_moment`` channels.  Noise floor, candidates and scoring (BIC, a
    single stance being too short for blocked cross-validation) in
    :mod:`pinmsk.diagnose.contact`.
``"motion"``
    Forward simulation driven by the measured ``<coord>_moment`` against the
    measured coordinates, restarted from the measured state at the start of
    each ``sim_window`` (multiple shooting: open-loop simulations of a few
    seconds drift).  Fixed-base models only.

Every mode has the same *residual* ``measured - model`` per channel.  For
fitting effects, torque and motion modes use the torque-level equation error
``e = tau_measured - tau_ID`` (fast and linear in most effects); the muscle
mode uses ``e = tau_mus - tau_ID``.  An effect with generalized force ``Q``
changes ``e`` by ``+Q`` (inverse dynamics of the richer model is ``tau_ID - Q``);
a muscle-level effect changes it by the change of ``tau_mus``.

Kinematics are low-passed (zero-lag Butterworth, ``cutoff`` Hz, default 6)
and differentiated by quintic spline; frames within ``1.5 / cutoff`` s of
either end (filter and spline end effects) are left out of every statistic.

Noise floor (:class:`NoiseFloor`), estimated from the data, per channel
(:mod:`pinmsk.diagnose.noise`)::

    sigma^2 = sigma_direct^2 + sigma_kinematic^2

Each measured input -- raw coordinates, measured moments, ground reaction
channels, excitations/EMG -- gets a noise model fitted to its own spectrum
above the movement's band (white, or low-passed white noise: filtered angles,
EMG envelopes; :mod:`pinmsk.signals.noise`); seeded realisations of the models
are pushed through the same path as the measurement (low-pass, spline
derivatives, inverse dynamics, GRF filter, the model's muscle-level chain and
muscle moments), and the RMS change of the residual is the floor: angles give
``sigma_kinematic``, the other channels ``sigma_direct``.  The propagation runs
through the model compared, so a model with an added effect gets its own
floor (:meth:`Comparison.with_model` reuses the fitted noise models, not the
floor).  ``noise=`` states noise levels of measured inputs (``{channel or group:
sigma}``, SI units) in place of the fitted ones.  Motion mode: the angle noise combined with the spread of the
simulated angles when the driving moments get their white noise and the
initial states their filtered-kinematics noise (two Monte-Carlo runs).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..components import Motion
from ..dynamics import inverse_dynamics_array, simulate
from ..effects._base import SignalEffect, unactuated_coordinates
from ..effects.sensor import apply_sensors, sensors_of
from ..errors import ModelError, TrialError
from ..grf import external_forces
from ..kinematics import DEFAULT_CUTOFF, TrialInputs, cutoff_value, prepare, require_independent_joints
from ..signals.filtering import differentiate
from ..skeleton import ExternalForce
from ..trial import Trial, close_matches, moment_channel, moment_channels, parse_ground_reaction
from . import contact as _contact
from .comparison import Comparison, NoiseFloor, white_noise_sigma
from .contact import compare_contact
from .noise import propagated_floor

__all__ = ["DEFAULT_CUTOFF", "MODES", "Comparison", "EquationError", "NoiseFloor", "compare",
           "comparison_plan", "external_forces_from_trial", "white_noise_sigma"]

MODES = ("torque", "motion", "muscle", "contact")
#: Largest |value| accepted in a measured channel (SI: N m, N, m, or excitation): far above any
#: human moment or ground force, so a larger finite value is a fill value or a unit error.
MEASURED_LIMIT = 1e6


# -- small numerical helpers ---------------------------------------------------


def _rows_for(t: np.ndarray, cutoff: float | None) -> np.ndarray:
    """Frames analysed: all but ``1.5 / cutoff`` s at each end (5 frames without a filter)."""
    if cutoff:
        trim = 1.5 / cutoff
        return np.flatnonzero((t >= t[0] + trim) & (t <= t[-1] - trim))
    return np.arange(5, t.size - 5)


# -- ground reaction forces -----------------------------------------------------

def external_forces_from_trial(model, trial: Trial, *, grf_frames: Mapping[str, str] | None = None
                               ) -> list[ExternalForce]:
    """Ground reaction wrenches of the trial as :class:`ExternalForce` s on the model's feet.

    Channels ``[<side>_]ground_force_v[xyz]`` (N), ``..._p[xyz]`` (centre of
    pressure, m) and optionally ``..._torque_[xyz]`` (free moment, N m), via
    :func:`pinmsk.grf.external_forces` (side ``s`` to the body of ``foot_s``,
    ``calcn_s``, ``heel_s``, ... or ``grf_frames[s]``; unloaded samples get no
    force).
    """
    return external_forces(model, trial, frames=grf_frames)


def _subset_external(external, rows):
    return [ExternalForce(e.frame, np.asarray(e.force)[rows], np.asarray(e.point)[rows],
                          None if e.torque is None else np.asarray(e.torque)[rows]) for e in external]


def _has_grf(trial) -> bool:
    return any(parse_ground_reaction(n) is not None for n in trial.names)


def _check_measured(model, trial) -> None:
    """Refuse measured channels the diagnosis compares with (moments, excitations/EMG, GRF)
    that are NaN, infinite or beyond :data:`MEASURED_LIMIT`, by channel, row and time.

    A centre of pressure may be NaN (undefined while its plate is unloaded), not infinite."""
    names = [n for n in moment_channels(model.coordinates) if n in trial]
    names += [f"{m}_{kind}" for m in model.muscle_names for kind in ("excitation", "emg")
              if f"{m}_{kind}" in trial]
    grf = {n: parse_ground_reaction(n) for n in trial.names}
    names += [n for n, g in grf.items() if g is not None and g.quantity != "point"]
    what = "before the diagnosis, which compares the model with them"
    trial.check_finite(names, limit=MEASURED_LIMIT, what=what)
    trial.check_finite([n for n, g in grf.items() if g is not None and g.quantity == "point"],
                       limit=MEASURED_LIMIT, nan_ok=True, what=what)


def _excitations(model, trial):
    """``(kind, (N, m))`` of measured excitation (preferred) or EMG, or ``(None, None)``."""
    if model.muscles is None:
        return None, None
    for kind in ("excitation", "emg"):
        names = [f"{m}_{kind}" for m in model.muscle_names]
        have = [n in trial for n in names]
        if all(have):
            return kind, np.column_stack([trial[n] for n in names])
        if any(have):
            missing = [n for n, h in zip(names, have) if not h]
            raise TrialError(f"the trial has {kind} channels for some muscles but not {', '.join(missing)}; "
                             f"muscle-level comparison needs all {len(names)} (or none)")
    return None, None


def _muscle_coordinates(model) -> list[str]:
    R = model.muscles.moment_arms(np.zeros((1, model.nq)))[0]
    return [c for j, c in enumerate(model.coordinates) if np.any(np.abs(R[:, j]) > 0)]


# -- channel selection -------------------------------------------------------------

@dataclass(frozen=True)
class _Plan:
    mode: str
    coordinates: tuple[str, ...]       # coordinates compared (channel = <coord>_moment or <coord>)
    unactuated: tuple[str, ...]
    excitation_kind: str | None


def comparison_plan(model, trial, mode: str, *, has_grf: bool | None = None) -> _Plan:
    """Which level compares ``model`` with ``trial`` and on which coordinates (no dynamics computed)."""
    if mode not in ("auto",) + MODES:
        raise ModelError(f"unknown comparison mode {mode!r}; use one of auto, {', '.join(MODES)}")
    if mode == "contact" or (mode == "auto" and _contact.applicable(model, trial)):
        why = _contact._why_not(model, trial)
        if why:
            raise TrialError(f"contact-level comparison impossible: {why}")
        return _Plan("contact", (), (), None)        # no coordinate is compared: joint effects do not apply
    unact = unactuated_coordinates(model)
    grf = _has_grf(trial) if has_grf is None else has_grf
    with_moment = [c for c in model.coordinates if moment_channel(c) in trial]
    actuated_moment = [c for c in with_moment if c not in unact]
    base_rows = [c for c in unact if grf or c in with_moment]
    kind, _ = _excitations(model, trial)
    missing_coords = [c for c in model.coordinates if c not in trial]
    if missing_coords:
        hints = {c: close_matches(c, trial.names) for c in missing_coords[:3]}
        hint = "; ".join(f"{c}: did you mean {', '.join(map(repr, h))}?" for c, h in hints.items() if h)
        raise TrialError(
            f"the trial has no channel for coordinate(s) {', '.join(missing_coords)} of model "
            f"'{model.name}', so the model cannot be compared on it"
            + (f" ({hint})" if hint else "") + f". Trial channels: {', '.join(trial.names[:15])}"
        )
    if mode == "auto":
        if actuated_moment or base_rows:
            mode = "torque"
        elif kind is not None:
            mode = "muscle"
        else:
            raise TrialError(
                f"the trial has no channel model '{model.name}' can be compared on: it needs "
                f"measured generalized forces ({', '.join(f'{c}_moment' for c in model.coordinates[:4])}...), "
                "ground reaction forces (ground_force_v[xyz], ground_force_p[xyz]) for a floating base, "
                "or muscle excitations/EMG (<muscle>_excitation, <muscle>_emg)"
                + ("" if model.muscles is None else f" for {', '.join(model.muscle_names[:4])}...")
            )
    if mode == "torque":
        coords = tuple(c for c in model.coordinates if c in actuated_moment or c in base_rows)
        if not coords:
            raise TrialError(
                f"torque-level comparison needs <coord>_moment channels (none of "
                f"{', '.join(f'{c}_moment' for c in model.coordinates[:6])} is in the trial) or, for "
                "a floating base, ground reaction force channels"
            )
    elif mode == "muscle":
        if model.muscles is None:
            raise TrialError(f"muscle-level comparison needs a model with muscles; '{model.name}' has none")
        if kind is None:
            raise TrialError(
                "muscle-level comparison needs excitation or EMG channels: "
                + ", ".join(f"{m}_excitation" for m in model.muscle_names[:4]) + ", ..."
            )
        mc = _muscle_coordinates(model)
        coords = tuple(c for c in model.coordinates if c in mc or c in base_rows)
    else:  # motion
        if unact:
            raise TrialError(
                f"motion-level comparison simulates the model open loop; '{model.name}' has a floating "
                f"base ({', '.join(unact)}) whose ground contact the simulation does not model. "
                "Use mode='torque' with ground reaction forces"
            )
        if not actuated_moment:
            raise TrialError("motion-level comparison is driven by measured <coord>_moment channels; "
                             f"the trial has none of {', '.join(f'{c}_moment' for c in model.coordinates[:6])}")
        coords = tuple(model.coordinates)
    return _Plan(mode, coords, tuple(unact), kind)


# -- the equation error (what effects are fitted to) ---------------------------------------

class EquationError:
    """Torque-level (or muscle-level) residual ``e`` over the analysed frames, and how effects change it."""

    def __init__(self, *, model, motion: Motion, rows: np.ndarray, coordinates: Sequence[str],
                 mode: str, measured_tau: np.ndarray | None, external, excitation: np.ndarray | None):
        self.model = model
        self.motion = motion
        self.rows = rows
        self.motion_rows = motion.subset(rows)
        self.coordinates = tuple(coordinates)
        self.columns = np.array([model.coordinate_index(c) for c in coordinates], dtype=int)
        self.mode = "muscle" if mode == "muscle" else "torque"
        self.external = list(external)
        self.measured_tau = measured_tau          # (N, nv) with zeros on unactuated rows (torque mode)
        self.excitation = excitation              # (N, m) measured signals (muscle mode)
        self._ext_rows = _subset_external(self.external, rows)
        self.data = model.create_data()           # the candidates' kinematics, shared (one thread)
        tau_id = inverse_dynamics_array(model, self.motion_rows, external=self._ext_rows, data=self.data)
        # the actuators' generalized forces, and (torque level) what the model's sensors read of them
        self.tau_act = tau_id[:, self.columns]
        self.sensors = sensors_of(model) if self.mode == "torque" else []
        self.tau_id = apply_sensors(model, self.coordinates, self.tau_act) if self.sensors else self.tau_act
        if self.mode == "muscle":
            self.chain = sorted([c for c in model.effects if isinstance(c, SignalEffect)],
                                key=lambda c: c.order)
            q, v = motion.q, motion.v
            self.f_active, self.f_passive = model.muscles.force_limits(q, v)
            self.moment_arms = model.muscles.moment_arms(q)[:, :, self.columns]     # (N, m, C)
            self.activation = self._apply_chain(self.chain, excitation)
            self.tau_mus = self._muscle_moment(self.activation)[rows]
            self.actuation = self.tau_mus
        else:
            self.actuation = measured_tau[rows][:, self.columns]
        self.e = self.actuation - self.tau_id

    def sensor_input(self, component) -> np.ndarray:
        """What the measurement effect ``component`` reads on its channel (n_rows,): the actuator's
        generalized force through the model's sensors that come before it (not itself)."""
        x = self.tau_act[:, self.coordinates.index(component.target)].copy()
        for s in self.sensors:
            if s.target == component.target and s.label != component.label and s.order < component.order:
                x = s.measure(x)
        return x

    # -- muscle level ----
    def _apply_chain(self, chain, u):
        t = self.motion.t
        a = u
        for c in chain:
            a = c.transform(t, a, mask=c.muscle_mask(self.model))
        return a

    def _muscle_moment(self, a):
        """(..., N, C) net moments of activations a (..., N, m)."""
        force = a * self.f_active + self.f_passive
        return np.einsum("...nm,nmc->...nc", force, self.moment_arms)

    def signal_delta(self, component: SignalEffect, params_batch: Mapping[str, np.ndarray]) -> np.ndarray:
        """Change of ``e`` (P, n_rows, C) when ``component`` joins the model's muscle-level chain
        (or replaces the entry of the same label)."""
        return self.chain_delta([(component, params_batch)])

    def chain_delta(self, changes) -> np.ndarray:
        """Change of ``e`` (P, n_rows, C) when each ``(component, params_batch)`` of ``changes`` joins the
        muscle-level chain or replaces its entry of the same label (a joint fit of several)."""
        t = self.motion.t
        labels = {c.label for c, _ in changes}
        entries = [(c, None) for c in self.chain if c.label not in labels] + list(changes)
        entries.sort(key=lambda x: x[0].order)           # stable: the model's own entries first on ties
        first = next(i for i, (_, b) in enumerate(entries) if b is not None)
        a = self._apply_chain([c for c, _ in entries[:first]], self.excitation)
        P = max(np.size(next(iter(b.values()))) if b else 1 for _, b in changes)
        for c, b in entries[first:]:          # the rest of the chain, all parameter sets in one pass
            batch = b if b is not None else {k: np.full(P, v) for k, v in c.values.items()}
            a = c.transform_batch(t, a, batch, c.muscle_mask(self.model))
        dtau = np.einsum("pnm,nmc->pnc", (a - self.activation[None]) * self.f_active[None],
                         self.moment_arms)
        return dtau[:, self.rows]

    # -- EMG noise through the muscle-level chain ----
    def set_excitation_noise(self, realisations) -> None:
        """The excitations' noise realisations (list of (N, m)) :meth:`emg_noise` propagates
        (set by the noise floor, :mod:`pinmsk.diagnose.noise`); None: no excitation noise."""
        self._u_noise = None if realisations is None else [np.asarray(x, dtype=float) for x in realisations]

    def excitation_response(self, xi: np.ndarray, chain=None, base=None) -> np.ndarray:
        """Change (n_rows, C) of the muscle moments when the measured signals change by ``xi`` (N, m)."""
        chain = self.chain if chain is None else chain
        base = self.activation if base is None else base
        a = self._apply_chain(chain, self.excitation + xi)
        return np.einsum("nm,nmc->nc", (a - base) * self.f_active, self.moment_arms)[self.rows]

    def emg_noise(self, extra=None) -> np.ndarray:
        """RMS (C,) of the muscle moments' response to the measured signals' noise.

        The noise realisations are those of the excitations' own noise model
        (multiplicative, coloured by the envelope's low-pass; see
        :mod:`pinmsk.diagnose.noise`), passed through the model's muscle-level
        chain (plus ``extra``, a fitted candidate or a list of them, each
        replacing the chain's entry of the same label) and the muscle moments.
        """
        if self.mode != "muscle" or not getattr(self, "_u_noise", None):
            return np.zeros(self.columns.size)
        if extra is not None and not isinstance(extra, (list, tuple)):
            extra = [extra]
        labels = {c.label for c in extra or ()}
        chain = self.chain if not extra else sorted(
            [c for c in self.chain if c.label not in labels] + list(extra), key=lambda c: c.order)
        base = self._apply_chain(chain, self.excitation) if extra is not None else self.activation
        acc = np.zeros(self.columns.size)
        for xi in self._u_noise:
            acc += np.mean(self.excitation_response(xi, chain, base) ** 2, axis=0)
        return np.sqrt(acc / len(self._u_noise))

    # -- residual with perturbed kinematics or loads (noise propagation) ----
    def residual_for(self, motion: Motion, *, external=None) -> np.ndarray:
        """``e`` for another motion (same frames) and, optionally, other external loads."""
        mrows = motion.subset(self.rows)
        ext = self._ext_rows if external is None else _subset_external(external, self.rows)
        tau_id = inverse_dynamics_array(self.model, mrows, external=ext)[:, self.columns]
        if self.mode == "muscle":
            if motion is self.motion:
                return self.tau_mus - tau_id
            fa, fp = self.model.muscles.force_limits(motion.q, motion.v)
            R = self.model.muscles.moment_arms(motion.q)[:, :, self.columns]
            act = np.einsum("nm,nmc->nc", self.activation * fa + fp, R)[self.rows]
            return act - tau_id
        if self.sensors:
            tau_id = apply_sensors(self.model, self.coordinates, tau_id)
        return self.actuation - tau_id


# -- the comparison ------------------------------------------------------------------------


def compare(model, trial: Trial, *, mode: str = "auto", cutoff: float | None = DEFAULT_CUTOFF,
            grf_frames: Mapping[str, str] | None = None, grf=None, external_loads=None, noise=None,
            grf_cutoff="same", sim_window: float = 0.5, noise_floor: NoiseFloor | None = None,
            _inputs: TrialInputs | None = None, _fits: dict | None = None) -> Comparison:
    """Compare ``model`` with ``trial`` (see the module docstring for the modes and the noise floor).

    Kinematics and ground reaction forces (the trial's own, ``grf=`` at its own
    rate or an OpenSim ``external_loads=`` file; ``grf_frames`` overrides which
    body takes a plate) go through :func:`pinmsk.kinematics.prepare`, so the GRF
    is low-passed at the same ``cutoff`` as the kinematics.
    """
    if not isinstance(trial, Trial):
        raise TrialError(f"compare needs a Trial, got {type(trial).__name__}; read one with pinmsk.read_trial")
    # the candidate effects' generalized forces and the motion-level simulation are in the Pinocchio joints
    require_independent_joints(model, "the diagnosis")
    cutoff = cutoff_value(cutoff)              # 0 and None: no filter
    _check_measured(model, trial)
    external_given = grf is not None or external_loads is not None
    plan = comparison_plan(model, trial, mode, has_grf=_has_grf(trial) or external_given)
    if plan.mode == "contact":
        _no_stated_noise(noise, plan.mode)
        return compare_contact(model, trial, cutoff=cutoff, noise_floor=noise_floor,
                               options={"grf_frames": grf_frames, "sim_window": sim_window})
    t = np.asarray(trial.time, dtype=float)
    if plan.mode == "motion":
        _no_stated_noise(noise, plan.mode)
    if t.size < 30:
        raise TrialError(f"the trial has {t.size} samples; the diagnosis needs at least 30 "
                         "(and several seconds for cross-validation)")
    inputs = _inputs if _inputs is not None else prepare(
        model, trial, cutoff=cutoff, grf=grf, external_loads=external_loads, frames=grf_frames,
        grf_cutoff=grf_cutoff)
    motion = inputs.motion
    rows = _rows_for(t, cutoff)
    if rows.size < 30:
        edge = f"{1.5 / cutoff:.3g} s (filter edge effects at {cutoff:g} Hz)" if cutoff else "5 frames"
        raise TrialError(f"only {rows.size} samples remain after leaving out {edge} at each end; "
                         "the diagnosis needs at least 30: record a longer trial")
    external = list(inputs.external)
    measured_tau = None
    excitation = None
    if plan.mode in ("torque", "motion"):
        measured_tau = np.zeros((t.size, model.nv))
        for c in plan.coordinates:
            if moment_channel(c) in trial:
                measured_tau[:, model.coordinate_index(c)] = trial[moment_channel(c)]
    else:
        _, excitation = _excitations(model, trial)
    eq_coords = plan.coordinates
    if plan.mode == "motion":
        eq_coords = tuple(c for c in plan.coordinates if moment_channel(c) in trial)
    eq = EquationError(model=model, motion=motion, rows=rows, coordinates=eq_coords, mode=plan.mode,
                       measured_tau=measured_tau, external=external, excitation=excitation)
    options = {"grf_frames": grf_frames, "grf": grf, "external_loads": external_loads, "grf_cutoff": grf_cutoff,
               "sim_window": sim_window}
    channels = moment_channels(eq_coords)
    floor = noise_floor if noise_floor is not None and plan.mode != "motion" else propagated_floor(
        eq, trial, mode=plan.mode, excitation_kind=plan.excitation_kind, cutoff=cutoff, options=options,
        channels=channels, grf_in_trial=_has_grf(trial) and not external_given, fits=_fits, noise=noise)
    if noise_floor is not None:
        options["noise_given"] = True
    if noise:
        options["noise"] = noise                 # stated noise levels (the remade comparisons keep them)
    states = _states(model, trial, motion, rows, eq_coords, excitation, plan.excitation_kind, external)
    if plan.mode == "motion":
        eq_floor = floor
        meas, mod, floor = _motion_level(model, trial, motion, rows, sim_window, eq,
                                         None if noise_floor is None else noise_floor, cutoff)
        return Comparison("motion", model, trial, cutoff, t[rows], tuple(plan.coordinates), tuple(plan.coordinates),
                          meas, mod, floor, eq, states, options, eq_floor, inputs=inputs, remake=_remake)
    return Comparison(plan.mode, model, trial, cutoff, t[rows], channels, eq_coords, eq.actuation.copy(),
                      eq.tau_id.copy(), floor, eq, states, options, inputs=inputs, remake=_remake)


def _no_stated_noise(noise, mode: str) -> None:
    """Refuse stated noise levels where they would not be used (the contact and motion levels)."""
    if noise:
        raise ModelError(f"noise= (stated noise levels) sets the torque- and muscle-level noise floors; the "
                         f"{mode}-level comparison estimates its own: leave noise out or pick mode='torque'")


def _remake(c: Comparison, model) -> Comparison:
    """``c`` again for another model: the same frames, inputs and options; the noise floor is
    propagated again through the new model (the trial's noise models are reused), unless it was given."""
    given = c.noise if c.options.get("noise_given") else None
    fits = None if given is not None else (c.eq_noise.fits or None)
    opts = {k: v for k, v in c.options.items() if k != "noise_given"}
    return compare(model, c.trial, mode=c.mode, cutoff=c.cutoff, noise_floor=given, _inputs=c.inputs,
                   _fits=fits, **opts)


def _states(model, trial, motion, rows, coords, excitation, kind, external) -> dict:
    """Candidate explanatory signals over the analysed rows, for residual correlations."""
    out = {}
    for c in coords:
        i = model.coordinate_index(c)
        out[c] = motion.q[rows, i]
        out[f"{c}_speed"] = motion.v[rows, i]
        out[f"{c}_acceleration"] = motion.a[rows, i]
        out[f"sign({c}_speed)"] = np.sign(motion.v[rows, i])
    if excitation is not None:
        for j, m in enumerate(model.muscle_names):
            out[f"{m}_{kind}"] = excitation[rows, j]
    for e in external:
        out[f"{e.frame}_contact_force_y"] = np.asarray(e.force)[rows, 1]
    return out


# -- motion level --------------------------------------------------------------------------

def _windows(rows: np.ndarray, t: np.ndarray, length: float) -> list[np.ndarray]:
    """Consecutive groups of ``rows`` spanning ``length`` s each (a short tail joins the last group)."""
    tr = t[rows]
    k = np.floor((tr - tr[0]) / length + 1e-9).astype(int)
    groups = [rows[k == i] for i in range(k.max() + 1)]
    groups = [g for g in groups if g.size]
    if len(groups) > 1 and groups[-1].size < 3:
        tail = groups.pop()
        groups[-1] = np.concatenate([groups[-1], tail])
    return groups


def simulate_windows(model, trial, motion, rows, window, *, tau_noise=None, state_noise=None):
    """Multiple-shooting simulation: q (n_rows, nv) restarted from the measured state each ``window`` s."""
    t = motion.t
    out = np.full((rows.size, model.nv), np.nan)
    pos = {r: k for k, r in enumerate(rows)}
    cols = list(moment_channels(model.coordinates))
    drive_all = np.column_stack([trial[c] if c in trial else np.zeros(t.size) for c in cols])
    if tau_noise is not None:
        drive_all = drive_all + tau_noise
    for w in _windows(rows, t, window):
        drive = Trial(t[w], {c: drive_all[w, j] for j, c in enumerate(cols)})
        q0 = motion.q[w[0]].copy()
        v0 = motion.v[w[0]].copy()
        if state_noise is not None:
            q0 += state_noise[0][w[0]]
            v0 += state_noise[1][w[0]]
        sim = simulate(model, t=t[w], q0=q0, v0=v0, moments=drive)
        q = np.column_stack([sim[c] for c in model.coordinates])
        for k, r in enumerate(w):
            out[pos[r]] = q[k]
    return out


def _motion_level(model, trial, motion, rows, window, eq, floor, cutoff):
    raw_q = np.column_stack([trial[c] for c in model.coordinates])[rows]
    qs = simulate_windows(model, trial, motion, rows, window)
    if floor is None:
        sigma_q = white_noise_sigma(np.column_stack([trial[c] for c in model.coordinates]))
        cols = list(moment_channels(model.coordinates))
        tau = np.column_stack([trial[c] if c in trial else np.zeros(trial.n_frames) for c in cols])
        sigma_tau = white_noise_sigma(tau)
        rng = np.random.default_rng(54321)
        acc = np.zeros(model.nv)
        runs = 2
        for _ in range(runs):
            nt = rng.standard_normal(tau.shape) * sigma_tau
            nq = rng.standard_normal(tau.shape) * sigma_q
            dq, dv, _ = differentiate(motion.t, nq, cutoff=cutoff)
            qn = simulate_windows(model, trial, motion, rows, window, tau_noise=nt, state_noise=(dq, dv))
            acc += np.mean((qn - qs) ** 2, axis=0)
        prop = np.sqrt(acc / runs)
        sigma = np.sqrt(sigma_q ** 2 + prop ** 2)
        floor = NoiseFloor(
            tuple(model.coordinates), np.maximum(sigma, np.finfo(float).tiny), sigma_q, prop,
            "angle noise from third differences of the raw coordinates, plus the RMS spread of the "
            f"{window:g}-s simulations when the driving moments get their white noise (third differences) "
            "and the initial states their filtered-kinematics noise (2 Monte-Carlo runs)")
    return raw_q, qs, floor
