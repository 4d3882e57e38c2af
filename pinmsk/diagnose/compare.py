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
    seconds drift).  Fixed-base models with independent joints only.

On an exact OpenSim import (dependent joints that are functions of OpenSim's
coordinates, :func:`pinmsk.kinematics.coordinate_map`) the torque and muscle
levels compare OpenSim's independent coordinates
(:func:`pinmsk.kinematics.independent_coordinates`): every generalized force
of the joints is mapped to them by virtual work, ``J^T Q``
(:meth:`EquationError.project`), a coupled coordinate's folded into its
independent one.

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
from ..kinematics import (DEFAULT_CUTOFF, TrialInputs, coordinate_map, cutoff_value, independent_coordinates,
                          prepare, source_coordinate_gaps, source_positions)
from ..signals.filtering import differentiate
from ..skeleton import ExternalForce
from ..trial import Trial, close_matches, moment_channel, moment_channels, parse_ground_reaction
from . import contact as _contact
from .comparison import Comparison, NoiseFloor, white_noise_sigma
from .contact import compare_contact
from .noise import propagated_floor

__all__ = ["DEFAULT_CUTOFF", "MODES", "Comparison", "EquationError", "NoiseFloor", "compare", "opensim_force_names",
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


def _contacts_once(model, external) -> None:
    """TrialError naming the contacts on bodies the measured ground reaction forces load (the ground
    would act twice), with the flags that leave one of them out."""
    if not (external and model.contacts):
        return
    pm = model.pin
    loaded = {pm.frames[model.frame_id(e.frame)].parentJoint for e in external}
    both = [c.label for c in model.contacts if pm.frames[model.frame_id(c.target)].parentJoint in loaded]
    if both:
        raise TrialError(
            f"model '{model.name}' has contacts on the bodies the measured ground reaction forces load "
            f"({', '.join(both)}): the ground would act twice; leave the contacts out "
            f"({' '.join(f'--without {b}' for b in both)}; in Python model.without(label)) or the measured "
            "GRF (--no-grf)")


def _has_grf(trial) -> bool:
    return any(parse_ground_reaction(n) is not None for n in trial.names)


def _check_measured(model, trial) -> None:
    """Refuse measured channels the diagnosis compares with (moments, excitations/EMG, GRF)
    that are NaN, infinite or beyond :data:`MEASURED_LIMIT`, by channel, row and time.

    A centre of pressure may be NaN (undefined while its plate is unloaded), not infinite."""
    coords = list(model.coordinates)
    cmap = coordinate_map(model)
    if cmap is not None:
        coords += [c for c in cmap.osim_coordinates if c not in model.coordinates]
    names = [n for n in moment_channels(coords) if n in trial]
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
            shown = ", ".join(missing[:8]) + (f" and {len(missing) - 8} more" if len(missing) > 8 else "")
            raise TrialError(f"the trial has {kind} channels for some muscles ({sum(have)} of {len(names)}) but "
                             f"not {shown}; muscle-level comparison needs all {len(names)} (or none); the "
                             "torque level alone compares no excitation: mode='torque' (--mode torque)")
    return None, None


def _muscle_coordinates(model) -> list[str]:
    """The coordinates some muscle spans (a nonzero moment arm at the zero pose; at OpenSim's default
    pose, mapped to its coordinates by ``J^T``, on an exact import)."""
    cmap = coordinate_map(model)
    if cmap is None:
        R = model.muscles.moment_arms(np.zeros((1, model.nq)))[0]
        return [c for j, c in enumerate(model.coordinates) if np.any(np.abs(R[:, j]) > 0)]
    q_os = np.array([[cmap.welded.get(c, cmap.defaults[c]) for c in cmap.osim_coordinates]])
    J = cmap.jacobian(q_os, couplers=True)[0]                       # (nv, n_osim)
    R = model.muscles.moment_arms(cmap.expand(q_os)[0])[0] @ J     # (m, n_osim)
    return [c for j, c in enumerate(cmap.osim_coordinates) if np.any(np.abs(R[:, j]) > 0)]


# -- channel selection -------------------------------------------------------------

@dataclass(frozen=True)
class _Plan:
    mode: str
    coordinates: tuple[str, ...]       # coordinates compared (channel = <coord>_moment or <coord>)
    unactuated: tuple[str, ...]
    excitation_kind: str | None


def comparison_plan(model, trial, mode: str, *, has_grf: bool | None = None,
                    missing_coordinates: str = "refuse") -> _Plan:
    """Which level compares ``model`` with ``trial`` and on which coordinates (no dynamics computed).

    The coordinates are the model's independent ones
    (:func:`pinmsk.kinematics.independent_coordinates`): on an exact OpenSim import OpenSim's coordinates,
    never a dependent joint nor the dependent coordinate of a coupler; the OpenSim coordinates the trial
    leaves out are refused by name or, with ``missing_coordinates="default"``, held at their defaults
    (:func:`pinmsk.kinematics.source_coordinate_gaps`)."""
    if mode not in ("auto",) + MODES:
        raise ModelError(f"unknown comparison mode {mode!r}; use one of auto, {', '.join(MODES)}")
    if mode == "contact" or (mode == "auto" and _contact.applicable(model, trial)):
        why = _contact._why_not(model, trial)
        if why:
            raise TrialError(f"contact-level comparison impossible: {why}")
        return _Plan("contact", (), (), None)        # no coordinate is compared: joint effects do not apply
    cmap = coordinate_map(model)
    coordinates = independent_coordinates(model)
    unact = tuple(c for c in unactuated_coordinates(model) if c in coordinates)
    grf = _has_grf(trial) if has_grf is None else has_grf
    with_moment = [c for c in coordinates if moment_channel(c) in trial]
    actuated_moment = [c for c in with_moment if c not in unact]
    base_rows = [c for c in unact if grf or c in with_moment]
    # the torque level compares no excitation: EMG for only some muscles is no reason to refuse it
    kind = None if mode == "torque" else _excitations(model, trial)[0]
    if cmap is not None:
        source_coordinate_gaps(model, trial, missing_coordinates=missing_coordinates)   # refuses a gap by name
    missing_coords = [] if cmap is not None else [c for c in model.coordinates if c not in trial]
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
                f"measured generalized forces ({', '.join(f'{c}_moment' for c in coordinates[:4])}...), "
                "ground reaction forces (ground_force_v[xyz], ground_force_p[xyz]) for a floating base, "
                "or muscle excitations/EMG (<muscle>_excitation, <muscle>_emg)"
                + ("" if model.muscles is None else f" for {', '.join(model.muscle_names[:4])}...")
            )
    if mode == "torque":
        coords = tuple(c for c in coordinates if c in actuated_moment or c in base_rows)
        if not coords:
            raise TrialError(
                f"torque-level comparison needs <coord>_moment channels (none of "
                f"{', '.join(f'{c}_moment' for c in coordinates[:6])} is in the trial) or, for "
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
        coords = tuple(c for c in coordinates if c in mc or c in base_rows)
    else:  # motion
        if cmap is not None:
            deps = list(cmap.dependent)
            raise ModelError(
                f"motion-level comparison integrates the Pinocchio joints of model '{model.name}' forward, but "
                f"{len(deps)} of them ({', '.join(deps[:4])}{' ...' if len(deps) > 4 else ''}) are dependent "
                "joints, functions of OpenSim's coordinates (an exact import), which a forward simulation "
                "cannot hold; use mode='torque' or 'muscle' (no simulation, in OpenSim's coordinates), or "
                "load the .osim with nonlinear='fit' (--nonlinear fit)")
        if unact:
            raise TrialError(
                f"motion-level comparison simulates the model open loop; '{model.name}' has a floating "
                f"base ({', '.join(unact)}) whose ground contact the simulation does not model. "
                "Use mode='torque' (--mode torque) with ground reaction forces"
            )
        if not actuated_moment:
            raise TrialError("motion-level comparison is driven by measured <coord>_moment channels; "
                             f"the trial has none of {', '.join(f'{c}_moment' for c in model.coordinates[:6])}")
        coords = tuple(model.coordinates)
    return _Plan(mode, coords, tuple(unact), kind)


# -- the equation error (what effects are fitted to) ---------------------------------------

class EquationError:
    """Torque-level (or muscle-level) residual ``e`` over the analysed frames, and how effects change it.

    ``coordinates`` are the compared coordinates (C); ``measured_tau`` (N, C) their measured generalized
    forces (torque mode; zeros on unactuated rows).  Every generalized force of the model's joints (inverse
    dynamics, an effect's ``Q``, the muscles' moment arms) reaches them through :meth:`project`: a column
    selection, or, on a model with a coordinate map (an exact OpenSim import, whose dependent joints are
    functions of OpenSim's coordinates), ``J^T Q`` by virtual work with ``J = d q_joints / d q_osim`` at each
    frame, the couplers applied (:func:`pinmsk.kinematics.independent_coordinates`).
    ``kinematic_channels`` are the measured coordinates whose noise :meth:`perturbed_motion` propagates
    (default: the model's coordinates).
    """

    def __init__(self, *, model, motion: Motion, rows: np.ndarray, coordinates: Sequence[str],
                 mode: str, measured_tau: np.ndarray | None, external, excitation: np.ndarray | None,
                 kinematic_channels: Sequence[str] | None = None):
        self.model = model
        self.motion = motion
        self.rows = rows
        self.motion_rows = motion.subset(rows)
        self.coordinates = tuple(coordinates)
        # each compared coordinate's joint column (-1: no joint of the model, e.g. a coupled coordinate)
        self.columns = np.array([model.coordinate_index(c) if c in model.coordinates else -1
                                 for c in coordinates], dtype=int)
        self.kinematic_channels = tuple(model.coordinates if kinematic_channels is None else kinematic_channels)
        self.mode = "muscle" if mode == "muscle" else "torque"
        self.external = list(external)
        self.measured_tau = measured_tau          # (N, C) with zeros on unactuated rows (torque mode)
        self.excitation = excitation              # (N, m) measured signals (muscle mode)
        self._ext_rows = _subset_external(self.external, rows)
        self._init_projection()
        self.data = model.create_data()           # the candidates' kinematics, shared (one thread)
        tau_id = inverse_dynamics_array(model, self.motion_rows, external=self._ext_rows, data=self.data,
                                        actuated=False)
        # the actuators' generalized forces, and (torque level) what the model's sensors read of them
        self.tau_act = self.project(tau_id)
        self.sensors = sensors_of(model) if self.mode == "torque" else []
        self.tau_id = apply_sensors(model, self.coordinates, self.tau_act) if self.sensors else self.tau_act
        if self.mode == "muscle":
            self.chain = sorted([c for c in model.effects if isinstance(c, SignalEffect)],
                                key=lambda c: c.order)
            q, v = motion.q, motion.v
            self.f_active, self.f_passive = model.muscles.force_limits(q, v)
            self.moment_arms = self.project_arms(model.muscles.moment_arms(q))     # (N, m, C)
            self.activation = self._apply_chain(self.chain, excitation)
            self.tau_mus = self._muscle_moment(self.activation)[rows]
            self.actuation = self.tau_mus
        else:
            self.actuation = np.asarray(measured_tau, dtype=float)[rows]
        self.e = self.actuation - self.tau_id

    # -- the joints' generalized forces -> the compared coordinates' ----
    def _init_projection(self) -> None:
        """The sparse ``J`` of the compared coordinates.  A compared coordinate that is a joint has the
        unit row there (``q_joint = q_coordinate``): a plain gather.  The other (joint, coordinate) pairs
        ``J`` couples anywhere in the trial -- a dependent joint's slope on its coordinate, through a
        coupler's slope where one applies -- are few (a knee's translations and its patella): their
        coefficients per frame (``_coef_all``, (N, K)) and, per compared coordinate, which of them it sums
        (``_extra``)."""
        self._cmap = coordinate_map(self.model)
        if self._cmap is None:
            return
        self._osim_cols = np.array([self._cmap.osim_coordinates.index(c) for c in self.coordinates], dtype=int)
        J = self._jacobian(self.motion)                                  # (N, nv, C)
        jn, cn = np.nonzero(np.any(J != 0.0, axis=0))
        coef = J[:, jn, cn]
        own = (jn == self.columns[cn]) & np.all(coef == 1.0, axis=0)
        self._own = np.zeros(len(self.coordinates), dtype=bool)
        self._own[cn[own]] = True
        order = np.argsort(cn[~own], kind="stable")
        self._jx, self._cx = jn[~own][order], cn[~own][order]
        self._extra = {int(c): np.flatnonzero(self._cx == c) for c in np.unique(self._cx)}
        self._coef_all = coef[:, ~own][:, order]                         # (N, K)
        self._coef = self._coef_all[self.rows]

    def _jacobian(self, motion: Motion) -> np.ndarray:
        """``d q_joints / d q_compared`` (n, nv, C) along ``motion`` (the couplers applied)."""
        q = source_positions(self.model, motion)
        return self._cmap.jacobian(q, couplers=True)[:, :, self._osim_cols]

    def coefficients(self, motion: Motion) -> np.ndarray | None:
        """The projection's coefficients (n, K) along another motion (None without a coordinate map)."""
        if self._cmap is None:
            return None
        return self._jacobian(motion)[:, self._jx, self._cx]

    def project(self, Q: np.ndarray, which=None, *, coef: np.ndarray | None = None) -> np.ndarray:
        """Generalized forces ``Q`` (..., n, nv) of the model's joints as the compared coordinates'
        (..., n, C), or those at positions ``which`` of :attr:`coordinates`: ``Q[..., columns]``, or with a
        coordinate map ``J^T Q`` (virtual work; ``coef`` the coefficients of the ``n`` frames, default
        the analysed rows)."""
        Q = np.asarray(Q, dtype=float)
        if self._cmap is None:
            return Q[..., self.columns if which is None else self.columns[which]]
        sel = np.arange(len(self.coordinates)) if which is None else np.atleast_1d(np.asarray(which, dtype=int))
        coef = self._coef if coef is None else coef
        out = np.zeros(Q.shape[:-1] + (sel.size,))
        own = self._own[sel]
        out[..., own] = np.take(Q, self.columns[sel[own]], axis=-1)
        for k, c in enumerate(sel):
            seg = self._extra.get(int(c))
            if seg is not None:
                out[..., k] += np.einsum("...nk,nk->...n", np.take(Q, self._jx[seg], axis=-1), coef[:, seg])
        return out

    def project_arms(self, R: np.ndarray, *, coef: np.ndarray | None = None) -> np.ndarray:
        """Moment arms ``R`` (N, m, nv) over all frames of the motion (or those ``coef`` belongs to) as the
        compared coordinates' (N, m, C): the muscles' generalized forces per unit force, by :meth:`project`."""
        R = np.asarray(R, dtype=float)
        if self._cmap is None:
            return R[:, :, self.columns]
        c = self._coef_all if coef is None else coef
        return np.moveaxis(self.project(np.moveaxis(R, 1, 0), coef=c), 0, 1)

    def project_jacobian(self, J: np.ndarray, which=None) -> np.ndarray:
        """Parameter Jacobians ``dQ/dtheta`` (n, nv, p) on the analysed rows as (n, C, p) (:meth:`project`)."""
        return np.moveaxis(self.project(np.moveaxis(np.asarray(J, dtype=float), -1, 0), which), 0, -1)

    # -- kinematic noise through the measurement's path ----
    def perturbed_motion(self, dq: np.ndarray, dv: np.ndarray, da: np.ndarray) -> Motion:
        """The motion (all frames) when the measured coordinates :attr:`kinematic_channels` change by
        ``dq`` (N, k), their filtered derivatives by ``dv``, ``da``: added to the joints, or, with a
        coordinate map, to OpenSim's coordinates, which are mapped again (the dependent joints and the
        couplers follow, as in :func:`pinmsk.kinematics.motion`)."""
        m = self.motion
        if self._cmap is None:
            if self.kinematic_channels == tuple(self.model.coordinates):
                return Motion(m.t, m.q + dq, m.v + dv, m.a + da, m.signals)
            idx = [self.model.coordinate_index(c) for c in self.kinematic_channels]
            q, v, a = m.q.copy(), m.v.copy(), m.a.copy()
            q[:, idx] += dq
            v[:, idx] += dv
            a[:, idx] += da
            return Motion(m.t, q, v, a, m.signals)
        cmap = self._cmap
        Q, V, A = (x.copy() for x in self._source_kinematics())
        cols = [cmap.osim_coordinates.index(c) for c in self.kinematic_channels]
        Q[:, cols] += dq
        V[:, cols] += dv
        A[:, cols] += da
        q, v, a, Qm = cmap.expand(Q, V, A, with_source=True)
        sig = dict(m.signals)
        sig.update({c: Qm[:, i] for i, c in enumerate(cmap.osim_coordinates) if c not in self.model.coordinates})
        return Motion(m.t, q, v, a, sig)

    def _source_kinematics(self):
        """OpenSim's coordinates, speeds and accelerations (N, n_osim) of the motion: the joints' columns, and
        for a coordinate that is no joint the spline derivatives of its (filtered) values, as its first
        differentiation gave them (a coupler's dependent coordinate is set again by the coupler)."""
        if getattr(self, "_source_qva", None) is None:
            m, cmap = self.motion, self._cmap
            Q = source_positions(self.model, m)
            V, A = np.zeros_like(Q), np.zeros_like(Q)
            for i, c in enumerate(cmap.osim_coordinates):
                if c in self.model.coordinates:
                    k = self.model.coordinate_index(c)
                    V[:, i], A[:, i] = m.v[:, k], m.a[:, k]
                elif c in m.signals:
                    _, V[:, i], A[:, i] = differentiate(m.t, Q[:, i])
            self._source_qva = (Q, V, A)
        return self._source_qva

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
        same = motion is self.motion
        coef_all = None if same else self.coefficients(motion)
        coef = None if coef_all is None else coef_all[self.rows]
        tau_id = self.project(inverse_dynamics_array(self.model, mrows, external=ext, actuated=False), coef=coef)
        if self.mode == "muscle":
            if same:
                return self.tau_mus - tau_id
            fa, fp = self.model.muscles.force_limits(motion.q, motion.v)
            R = self.project_arms(self.model.muscles.moment_arms(motion.q), coef=coef_all)
            act = np.einsum("nm,nmc->nc", self.activation * fa + fp, R)[self.rows]
            return act - tau_id
        if self.sensors:
            tau_id = apply_sensors(self.model, self.coordinates, tau_id)
        return self.actuation - tau_id


# -- the comparison ------------------------------------------------------------------------


def opensim_force_names(model, trial: Trial) -> Trial:
    """``trial`` with OpenSim's inverse-dynamics names of measured generalized forces read as pinmsk's:
    OpenSim's ID tool writes ``<coord>_force`` for a translational coordinate (``pelvis_tx_force``) and
    ``<coord>_moment`` for a rotational one; both are the coordinate's generalized force, so a
    ``<coord>_force`` column of a model coordinate is its ``<coord>_moment`` (unless the trial has both)."""
    rename = {f"{c}_force": moment_channel(c) for c in independent_coordinates(model)
              if f"{c}_force" in trial and moment_channel(c) not in trial}
    if not rename:
        return trial
    return trial.drop(list(rename)).with_channels({new: trial[old] for old, new in rename.items()})


def compare(model, trial: Trial, *, mode: str = "auto", cutoff: float | None = DEFAULT_CUTOFF,
            grf_frames: Mapping[str, str] | None = None, grf=None, external_loads=None, noise=None,
            grf_cutoff="auto", sim_window: float = 0.5, noise_floor: NoiseFloor | None = None,
            missing_coordinates: str = "refuse", _inputs: TrialInputs | None = None,
            _fits: dict | None = None) -> Comparison:
    """Compare ``model`` with ``trial`` (see the module docstring for the modes and the noise floor).

    Kinematics and ground reaction forces (the trial's own, ``grf=`` at its own
    rate or an OpenSim ``external_loads=`` file; ``grf_frames`` overrides which
    body takes a plate) go through :func:`pinmsk.kinematics.prepare`, so the GRF
    is low-passed at the same ``cutoff`` as the kinematics.

    On an exact OpenSim import (dependent joints, :func:`pinmsk.kinematics.coordinate_map`) the torque and
    muscle levels compare OpenSim's independent coordinates: the trial's coordinates are mapped to the
    joints as for inverse dynamics, and every generalized force of the joints is mapped back by
    ``J^T`` (:meth:`EquationError.project`); a coordinate the trial leaves out is refused, or held at its
    default with ``missing_coordinates="default"``.  The motion level, a forward simulation of the joints,
    is refused on such a model.
    """
    if not isinstance(trial, Trial):
        raise TrialError(f"compare needs a Trial, got {type(trial).__name__}; read one with pinmsk.read_trial")
    cutoff = cutoff_value(cutoff)              # 0 and None: no filter
    trial = opensim_force_names(model, trial)
    _check_measured(model, trial)
    external_given = grf is not None or external_loads is not None
    plan = comparison_plan(model, trial, mode, has_grf=_has_grf(trial) or external_given,
                           missing_coordinates=missing_coordinates)
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
        grf_cutoff=grf_cutoff, missing_coordinates=missing_coordinates)
    motion = inputs.motion
    rows = _rows_for(t, cutoff)
    if rows.size < 30:
        edge = f"{1.5 / cutoff:.3g} s (filter edge effects at {cutoff:g} Hz)" if cutoff else "5 frames"
        raise TrialError(f"only {rows.size} samples remain after leaving out {edge} at each end; "
                         "the diagnosis needs at least 30: record a longer trial")
    external = list(inputs.external)
    _contacts_once(model, external)
    measured_tau = None
    excitation = None
    eq_coords = plan.coordinates
    if plan.mode == "motion":
        eq_coords = tuple(c for c in plan.coordinates if moment_channel(c) in trial)
    if plan.mode in ("torque", "motion"):
        measured_tau = _measured_moments(model, trial, motion, eq_coords)
    else:
        _, excitation = _excitations(model, trial)
    cmap = coordinate_map(model)
    kin_channels = None if cmap is None else tuple(c for c in independent_coordinates(model) if c in trial)
    eq = EquationError(model=model, motion=motion, rows=rows, coordinates=eq_coords, mode=plan.mode,
                       measured_tau=measured_tau, external=external, excitation=excitation,
                       kinematic_channels=kin_channels)
    options = {"grf_frames": grf_frames, "grf": grf, "external_loads": external_loads, "grf_cutoff": grf_cutoff,
               "sim_window": sim_window}
    if missing_coordinates != "refuse":
        options["missing_coordinates"] = missing_coordinates
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
    # a floor the records do not determine (processed data) stays the weights of the model as given
    unknown = (c.eq_noise.info or {}).get("estimable") is False
    given = c.noise if c.options.get("noise_given") or unknown else None
    fits = None if given is not None else (c.eq_noise.fits or None)
    opts = {k: v for k, v in c.options.items() if k != "noise_given"}
    return compare(model, c.trial, mode=c.mode, cutoff=c.cutoff, noise_floor=given, _inputs=c.inputs,
                   _fits=fits, **opts)


def _measured_moments(model, trial, motion, coords) -> np.ndarray:
    """The measured generalized forces (N, C) of the compared ``coords``: ``<coord>_moment`` (0 where the
    trial has none: the unactuated rows).  On an exact import, a recorded moment of a coupled coordinate
    (OpenSim's ID reports ``knee_angle_r_beta_moment``) joins its independent coordinates through the
    coupler's slope, ``tau_ind += s f'(q_ind) tau_dep``, as the model's own generalized forces do
    (:func:`pinmsk.kinematics.independent_coordinates`)."""
    out = np.zeros((trial.n_frames, len(coords)))
    for j, c in enumerate(coords):
        if moment_channel(c) in trial:
            out[:, j] = trial[moment_channel(c)]
    cmap = coordinate_map(model)
    if cmap is None:
        return out
    q_os = None
    for dep, indep, f, scale in reversed(cmap.couplers):      # the adjoint of applying them in order
        if moment_channel(dep) not in trial or not any(c in coords for c in indep):
            continue
        q_os = source_positions(model, motion) if q_os is None else q_os
        arg = q_os[:, cmap.osim_coordinates.index(indep[0])] if len(indep) == 1 else \
            q_os[:, [cmap.osim_coordinates.index(c) for c in indep]]
        tau_dep = np.asarray(trial[moment_channel(dep)], dtype=float)
        for i, c in enumerate(indep):
            if c in coords:
                slope = f.derivative(arg, 1) if len(indep) == 1 else f.derivative(arg, 1, i)
                out[:, coords.index(c)] += scale * np.asarray(slope, dtype=float) * tau_dep
    return out


def _states(model, trial, motion, rows, coords, excitation, kind, external) -> dict:
    """Candidate explanatory signals over the analysed rows, for residual correlations."""
    out = {}
    for c in coords:
        if c not in model.coordinates:
            continue
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
