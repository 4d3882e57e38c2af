"""Inverse dynamics and forward simulation of a Model over a Trial.

Array-level batch calls live in :mod:`pinmsk.skeleton`; this module adds the
model's components and speaks in Trials:

* :func:`inverse_dynamics` -- actuator moments ``tau = M a + h - J^T f_ext - sum_k Q_k``
  as ``<coord>_moment`` channels;
* :func:`component_forces` -- each component's generalized force over time
  (the per-effect breakdown users plot beside a residual);
* :func:`simulate` -- forward dynamics driven by ``<coord>_moment`` channels
  (or a function), with RK4 or ``solve_ivp``.

Inertial components (a held payload, a segment-mass correction) enter forward
dynamics by changing the skeleton's inertias (their generalized force depends
on the acceleration), and inverse dynamics through their generalized force.
"""
from __future__ import annotations

import threading
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from . import skeleton
from .components import Motion
from .effects.sensor import apply_sensors
from .errors import ResidualWarning, TrialError
from .kinematics import (DEFAULT_CUTOFF, TrialInputs, actuated_forces, lowpass_external, prepare,
                         require_independent_joints, source_coordinates)
from .residuals import ResidualReport, floating_base_residuals
from .signals.sampling import median_step
from .trial import Trial, moment_channels


def component_forces(model, motion: Motion, *, data=None, loads=None) -> dict[str, np.ndarray]:
    """Generalized force ``(N, nv)`` of each of the model's effects and contacts, by label.

    ``data`` (``model.create_data()``, default a new one) is the workspace the components
    share their kinematics in; pass the same one to reuse it for later work on ``motion``.
    ``loads`` (the external loads of the motion) go to the components that correct them
    (``needs_loads``: a force plate's offset, tilt, ...)."""
    data = model.create_data() if data is None else data

    def prep(c):
        extra = {"loads": loads} if getattr(c, "needs_loads", False) else {}
        return c.prepare(model, motion, data=data, **extra)

    return {c.label: np.asarray(c.generalized_force(model, motion, cache=prep(c))) for c in model.components}


def inverse_dynamics_array(model, motion: Motion, *, external: Sequence[skeleton.ExternalForce] = (),
                           components: bool = True, progress=None, data=None, actuated: bool = True) -> np.ndarray:
    """Actuator generalized forces ``(N, nv)`` for a Motion (see :func:`inverse_dynamics`);
    ``data`` as for :func:`component_forces`.  On a model with dependent joints (an exact OpenSim
    import) they are OpenSim's coordinates' forces at their joints and 0 at the dependent joints
    (:func:`pinmsk.kinematics.actuated_forces`); ``actuated=False`` gives Pinocchio's ``tau`` of every joint.
    A contact on a body that ``external`` loads (a measured GRF on a foot that has contact spheres) is
    refused: the ground would act twice."""
    if components and external and model.contacts:
        _ground_acts_once(model, external)
    tau = skeleton.rnea(model, motion.q, motion.v, motion.a, external=external,
                        progress=progress, data=None if data is None else data.pin)
    if components and model.components:
        for f in component_forces(model, motion, data=data, loads=external).values():
            tau -= f
    return actuated_forces(model, motion, tau) if actuated else tau


def _ground_acts_once(model, external) -> None:
    pm = model.pin
    loaded = {pm.frames[model.frame_id(e.frame)].parentJoint: e.frame for e in external}
    both = [f"{c.label} on {loaded[j]}" for c in model.contacts
            if (j := pm.frames[model.frame_id(c.target)].parentJoint) in loaded]
    if both:
        raise TrialError(f"model '{model.name}' has contacts on the bodies the trial's ground reaction forces load "
                         f"({', '.join(both)}): the ground would act twice; leave the measured GRF out "
                         "(ground_reaction='ignore', CLI --no-grf) or the contacts (model.without(label))")


@dataclass(frozen=True)
class InverseDynamicsResult:
    """Inverse dynamics of a trial: the moments, the inputs used and the floating-base residuals."""

    trial: Trial
    inputs: TrialInputs
    residuals: ResidualReport

    def report(self) -> str:
        lines = [f"Inverse dynamics of model '{self.trial.meta.get('model', '?')}': "
                 f"{self.trial.n_frames} frames ({self.trial.time[0]:.4g}-{self.trial.time[-1]:.4g} s)"]
        lines += [f"  {ln}" for ln in self.inputs.describe()]
        lines += [f"  {ln}" for ln in self.residuals.lines()]
        return "\n".join(lines)


def inverse_dynamics_result(model, trial, *, cutoff=DEFAULT_CUTOFF, grf=None, external_loads=None,
                            frames=None, ground_reaction: str = "auto", grf_cutoff="auto",
                            external: Sequence[skeleton.ExternalForce] = (),
                            components: bool = True, progress=None,
                            missing_coordinates: str = "refuse", convention: str = "pinmsk") -> InverseDynamicsResult:
    """Inverse dynamics with its inputs and residual report (see :func:`inverse_dynamics`).

    ``convention='opensim'`` reproduces OpenSim's InverseDynamicsTool on an imported model's FreeJoints and
    BallJoints: the tool hands the motion's Euler-angle rates ``q'`` and ``q''`` to Simbody's Free/Ball
    mobilizer as its speeds ``u`` (the angular velocity ``w`` of the child in the parent frame) and their
    rates, so it computes the dynamics of the motion with ``w = q'``, ``w' = q''`` and reports the
    mobilizer's generalized forces (the joint moment in the parent frame).  Here that motion's angle rates
    are ``E^-1 w`` and ``E^-1 (w' - E' E^-1 w)`` (``w = E(q) q'`` of body-fixed X-Y-Z angles) and the moments
    ``E^-T tau`` (virtual work: ``tau . q' = M . w``).  The default ``'pinmsk'`` differentiates the angles:
    the physically consistent result, which OpenSim's own solver gives with consistent speeds."""
    inputs = prepare(model, trial, cutoff=cutoff, grf=grf, external_loads=external_loads, frames=frames,
                     ground_reaction=ground_reaction, grf_cutoff=grf_cutoff,
                     missing_coordinates=missing_coordinates)
    if external and inputs.external:
        raise TrialError("external= was given and the trial has its own ground reaction forces; "
                         "pass one source of external loads")
    ext = inputs.external
    if external:
        # explicit wrenches on the motion's time base get the same low-pass as the kinematics
        gc = inputs.filtering.grf_cutoff
        ext = lowpass_external(external, rate=1.0 / median_step(inputs.motion.t), cutoff=gc)
        inputs = replace(inputs, external=ext, filtering=replace(inputs.filtering, has_grf=True),
                         notes=inputs.notes + ("external wrenches given by the caller on "
                                               + ", ".join(e.frame for e in ext),))
    if convention not in ("pinmsk", "opensim"):
        raise TrialError(f"convention={convention!r}: use 'pinmsk' or 'opensim'")
    motion = inputs.motion
    tool = _opensim_tool_rotations(model) if convention == "opensim" else []
    if tool:
        motion = _as_opensim_tool_reads(motion, tool)
    with _workspace(model) as data:     # one workspace for the whole analysis
        tau = inverse_dynamics_array(model, motion, external=ext, components=components, progress=progress,
                                     data=data, actuated=False)
        residuals = floating_base_residuals(model, motion, tau, ext, data=data.pin)
    if tool:
        tau = _as_opensim_tool_forces(motion, tau, tool)
    names, q_out, tau_out = source_coordinates(model, motion, tau)
    meta = {"analysis": "inverse_dynamics", "model": model.name, **inputs.meta()}
    if external:
        meta["ground_reaction"] = "given by the caller: " + ", ".join(e.frame for e in ext)
    euler = model.meta.get("euler_rate_convention")     # an imported model's FreeJoints and BallJoints
    if euler:
        meta["euler_rate_convention"] = ("convention 'opensim' (the tool's numbers): " if tool else
                                         "convention 'pinmsk' (the angles differentiated): ") + euler
        if not tool:
            warnings.warn(f"model '{model.name}', {euler}", UserWarning, stacklevel=3)
    if residuals.coordinates:
        meta["residuals"] = "; ".join(
            f"{c} peak {p:.4g} {u} (threshold {th:.4g})" for c, p, u, th in
            zip(residuals.coordinates, residuals.peak, residuals.units, residuals.thresholds))
    # the channels as one (N, 2n) array: no per-channel columns split and stacked again
    out = Trial.from_array(motion.t, tuple(names) + tuple(moment_channels(names)), np.hstack([q_out, tau_out]),
                           meta=meta)
    if residuals.warning():
        warnings.warn(residuals.warning(), ResidualWarning, stacklevel=3)
    return InverseDynamicsResult(out, inputs, residuals)


def _opensim_tool_rotations(model) -> list[list[int]]:
    """The q/v columns of each FreeJoint's and BallJoint's X-Y-Z rotation coordinates of an imported model."""
    out = []
    for names in model.meta.get("euler_rotation_coordinates") or ():
        try:
            out.append([model.coordinate_index(c) for c in names])
        except Exception:        # a locked or folded rotation: no Euler-rate reading to reproduce
            continue
    return out if model.pin.nq == model.pin.nv else []


def _euler_columns(q3):
    """Columns (N, 3, 3) of ``E`` in ``w = E q'`` for body-fixed X-Y-Z angles (w in the parent frame):
    ``e_x``, ``R_x e_y``, ``R_x R_y e_z``."""
    a, b = q3[:, 0], q3[:, 1]
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    n = len(a)
    c1 = np.tile([1.0, 0.0, 0.0], (n, 1))
    c2 = np.stack([np.zeros(n), ca, sa], 1)
    c3 = np.stack([sb, -sa * cb, ca * cb], 1)
    return c1, c2, c3


def _as_opensim_tool_reads(motion, tool):
    """The motion OpenSim's ID tool computes when it reads Euler-angle rates as angular velocity."""
    v, a = np.array(motion.v), np.array(motion.a)
    for cols in tool:
        c1, c2, c3 = _euler_columns(motion.q[:, cols])
        E = np.stack([c1, c2, c3], axis=2)                          # (N, 3, 3)
        w, wd = v[:, cols], a[:, cols]                              # what the tool takes as w and w'
        qd = np.linalg.solve(E, w[..., None])[..., 0]
        # E' q' = a' b' (e_x x c2) + c' (a' e_x + b' c2) x c3
        edq = (qd[:, :1] * qd[:, 1:2] * np.cross(c1, c2)
               + qd[:, 2:3] * np.cross(qd[:, :1] * c1 + qd[:, 1:2] * c2, c3))
        v[:, cols] = qd
        a[:, cols] = np.linalg.solve(E, (wd - edq)[..., None])[..., 0]
    return replace(motion, v=v, a=a)


def _as_opensim_tool_forces(motion, tau, tool):
    """The tool's generalized forces of the rotations: ``E^-T tau`` (the moment in the parent frame)."""
    tau = np.array(tau)
    for cols in tool:
        E = np.stack(_euler_columns(motion.q[:, cols]), axis=2)
        tau[:, cols] = np.linalg.solve(np.transpose(E, (0, 2, 1)), tau[:, cols][..., None])[..., 0]
    return tau


_WORKSPACES = threading.local()


@contextmanager
def _workspace(model):
    """A :class:`pinmsk.model.Data` of ``model`` for one analysis, kept per thread between analyses (a
    Data costs milliseconds on a large model, as much as a short trial's dynamics): emptied of cached
    kinematics before each use (no motion outlives its analysis in it), lent to one analysis at a time
    (a nested analysis of the same model gets a fresh one)."""
    pool = getattr(_WORKSPACES, "pool", None)
    if pool is None:
        pool = _WORKSPACES.pool = {}
    hit = pool.get(id(model))
    if hit is None or hit[0] is not model or hit[2]:
        if hit is not None and hit[0] is model:          # lent already: a nested analysis
            yield model.create_data()
            return
        if len(pool) >= 8:
            pool.pop(next(iter(pool)))
        hit = pool[id(model)] = [model, model.create_data(), False]
    hit[1].clear()
    hit[2] = True
    try:
        yield hit[1]
    finally:
        hit[2] = False
        hit[1].clear()


def inverse_dynamics(model, trial, *, cutoff=DEFAULT_CUTOFF, grf=None, external_loads=None, frames=None,
                     ground_reaction: str = "auto", grf_cutoff="auto",
                     external: Sequence[skeleton.ExternalForce] = (), components: bool = True,
                     progress=None, missing_coordinates: str = "refuse") -> Trial:
    """Inverse dynamics of a trial: the actuator moments ``<coord>_moment`` (N m or N).

    ``tau = M(q) a + h(q, v) - J^T f_ext - sum_k Q_k(q, v, a)``: what muscles
    (or motors) must supply once the external loads and the model's effects
    and contacts are accounted for.  The trial goes through
    :func:`pinmsk.kinematics.prepare`: its coordinates and its ground reaction
    forces (its own channels, ``grf=`` at their own rate, or an OpenSim
    ``external_loads=`` file) are low-passed at ``cutoff`` Hz (default 6;
    0 = off; ``grf_cutoff`` sets the GRF's apart) and the GRF enter as world
    wrenches on the feet.  ``external`` gives explicit
    :class:`~pinmsk.skeleton.ExternalForce` s on the trial's time base instead
    (low-passed like the GRF).  The
    output's metadata says which filter and loads were applied; the residuals
    at a floating base are in :func:`inverse_dynamics_result`.  ``progress``
    (an object with ``update(n)``) is told the frames done, a chunk at a time.
    """
    return inverse_dynamics_result(model, trial, cutoff=cutoff, grf=grf, external_loads=external_loads,
                                   frames=frames, ground_reaction=ground_reaction, grf_cutoff=grf_cutoff,
                                   external=external, components=components, progress=progress,
                                   missing_coordinates=missing_coordinates).trial


def skeleton_with_inertias(model) -> pin.Model:
    """A copy of the Pinocchio model with inertial components (payload, segment mass) folded in."""
    inertial = [c for c in model.components if getattr(c, "inertial", False)]
    if not inertial:
        return model.pin
    pm = pin.Model(model.pin)
    for c in inertial:
        c.apply_inertia(model, pm)
    return pm


def simulate(model, *, t, q0, v0, moments=None, method: str = "rk4", rtol: float = 1e-8,
             atol: float = 1e-10) -> Trial:
    """Forward dynamics of the model from ``(q0, v0)`` over times ``t``.

    ``moments`` drives the coordinates: ``None`` (unactuated), a Trial with
    ``<coord>_moment`` channels (linearly interpolated; absent coordinates get
    zero), or a function ``f(t, q, v) -> (nv,)``.  Non-inertial components add
    their generalized force at each evaluation.  Returns a Trial with the
    coordinates and ``<coord>_speed`` channels.
    """
    require_independent_joints(model, "simulate (forward dynamics)")
    t = np.asarray(t, dtype=float)
    tau_fn = _torque_function(model, moments)
    comps = [c for c in model.components if not getattr(c, "inertial", False)]
    pm = skeleton_with_inertias(model)
    nv = model.nv
    if comps:
        base = tau_fn

        def tau_fn(ti, q, v):  # noqa: F811 - wraps the drive with the components
            m = Motion(np.array([ti]), q[None, :], v[None, :], np.zeros((1, nv)))
            total = np.zeros(nv) if base is None else np.array(base(ti, q, v), dtype=float)
            for c in comps:
                total += c.generalized_force(model, m, cache=c.prepare(model, m))[0]
            return total

    Q, V, _ = skeleton.integrate(pm, q0, v0, t, tau_fn, method=method, rtol=rtol, atol=atol)
    idx = [model.coordinate_index(c) for c in model.coordinate_order]
    chans = {c: Q[:, i] for c, i in zip(model.coordinate_order, idx)}
    chans.update({f"{c}_speed": V[:, i] for c, i in zip(model.coordinate_order, idx)})
    return Trial(t, chans, meta={"analysis": "simulate", "model": model.name, "method": method})


def _torque_function(model, moments) -> Callable | None:
    if moments is None or callable(moments):
        return moments
    if not isinstance(moments, Trial):
        raise TrialError(f"moments must be None, a Trial or a function; got {type(moments).__name__}")
    cols = list(moment_channels(model.coordinates))
    present = [i for i, c in enumerate(cols) if c in moments]
    if not present:
        raise TrialError(
            f"the driving trial has none of the channels {', '.join(cols)}; name them <coordinate>_moment"
        )
    tt = np.asarray(moments.time, dtype=float)
    vals = np.column_stack([moments[cols[i]] for i in present])
    # a recording through a modelled sensor (gain, offset): the true drive behind the reading
    vals = apply_sensors(model, [model.coordinates[i] for i in present], vals, inverse=True)
    nv = model.nv
    idx = np.array(present)

    def fn(ti, q, v):
        out = np.zeros(nv)
        k = np.searchsorted(tt, ti) - 1
        k = min(max(k, 0), tt.size - 2)
        w = (ti - tt[k]) / (tt[k + 1] - tt[k])
        w = min(max(w, 0.0), 1.0)
        out[idx] = (1 - w) * vals[k] + w * vals[k + 1]
        return out

    return fn
