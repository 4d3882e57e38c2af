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

from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from . import skeleton
from .components import Motion
from .errors import TrialError
from .trial import Trial


def _as_motion(model, data, cutoff) -> Motion:
    if isinstance(data, Motion):
        return data
    if isinstance(data, Trial):
        return model.motion(data, cutoff=cutoff)
    raise TrialError(f"expected a Trial or a Motion, got {type(data).__name__}")


def component_forces(model, motion: Motion) -> dict[str, np.ndarray]:
    """Generalized force ``(N, nv)`` of each of the model's effects and contacts, by label."""
    return {c.label: np.asarray(c.generalized_force(model, motion, cache=c.prepare(model, motion)))
            for c in model.components}


def inverse_dynamics_array(model, motion: Motion, *, external: Sequence[skeleton.ExternalForce] = (),
                           components: bool = True, progress=None) -> np.ndarray:
    """Actuator generalized forces ``(N, nv)`` for a Motion (see :func:`inverse_dynamics`)."""
    tau = skeleton.inverse_dynamics(model, motion.q, motion.v, motion.a, external=external,
                                    progress=progress)
    if components:
        for f in component_forces(model, motion).values():
            tau -= f
    return tau


def inverse_dynamics(model, trial, *, cutoff: float | None = None,
                     external: Sequence[skeleton.ExternalForce] = (), components: bool = True,
                     progress=None) -> Trial:
    """Inverse dynamics of a trial: the actuator moments ``<coord>_moment`` (N m or N).

    ``tau = M(q) a + h(q, v) - J^T f_ext - sum_k Q_k(q, v, a)``: what muscles
    (or motors) must supply once the model's effects and contacts are
    accounted for.  Velocities and accelerations come from the trial's
    coordinates (``cutoff`` Hz zero-lag low-pass first, if given).  ``progress``
    (an object with ``update(n)``) is told the frames done, a chunk at a time.
    """
    motion = _as_motion(model, trial, cutoff)
    tau = inverse_dynamics_array(model, motion, external=external, components=components,
                                 progress=progress)
    idx = [model.coordinate_index(c) for c in model.coordinate_order]
    chans = {c: motion.q[:, i] for c, i in zip(model.coordinate_order, idx)}
    chans.update({f"{c}_moment": tau[:, i] for c, i in zip(model.coordinate_order, idx)})
    return Trial(motion.t, chans, meta={"analysis": "inverse_dynamics", "model": model.name})


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
    cols = [f"{c}_moment" for c in model.coordinates]
    present = [i for i, c in enumerate(cols) if c in moments]
    if not present:
        raise TrialError(
            f"the driving trial has none of the channels {', '.join(cols)}; name them <coordinate>_moment"
        )
    tt = np.asarray(moments.time, dtype=float)
    vals = np.column_stack([moments[cols[i]] for i in present])
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
