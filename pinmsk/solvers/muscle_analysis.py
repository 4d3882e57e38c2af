"""Muscle analysis over a trial, as OpenSim's MuscleAnalysis reports it: :func:`muscle_analysis`.

Channels (SI): ``<muscle>_length`` (muscle-tendon length from the model's path),
``<muscle>_fiber_length`` (the fiber length with an inextensible tendon, from the
muscle model's rigid-tendon fiber kinematics: OpenSim's value for muscles with
``ignore_tendon_compliance``; for compliant tendons OpenSim's equilibrium fiber
depends on activation, which a kinematic analysis does not have) and
``<muscle>_moment_arm_<coord>`` for each coordinate the muscle's path depends on
(the others are zero and not written).

A muscle whose muscle-tendon length is not longer than its tendon slack length at
some frames has no rigid-tendon fiber state there (``x = l_mt - l_slack <= 0``):
its fiber length is NaN at those frames, the rest of the analysis is kept, and
one :class:`FiberRoomWarning` line names the muscles and their frame counts.

On a model imported from an ``.osim`` the lengths and moment arms are those of
the geometric paths (OpenSim's algorithm, exact), not of the fitted polynomials
the solvers use; ``paths="model"`` takes the model's own paths.
"""
from __future__ import annotations

import warnings

import numpy as np

from ..errors import ModelError
from ..kinematics import prepare
from ..opensim.muscle_import import geometric_paths
from ..signals.filtering import DEFAULT_CUTOFF
from ..trial import Trial

__all__ = ["muscle_analysis", "FiberRoomWarning"]


class FiberRoomWarning(UserWarning):
    """Some muscles' muscle-tendon length leaves no room for a rigid-tendon fiber at some frames."""


def muscle_analysis(model, trial, *, cutoff=DEFAULT_CUTOFF, grf=None, external_loads=None,
                    ground_reaction: str = "auto", grf_cutoff="auto", paths: str = "auto",
                    missing_coordinates: str = "refuse") -> Trial:
    """Muscle-tendon lengths, rigid-tendon fiber lengths and moment arms of ``model``'s muscles over
    ``trial`` (the coordinates low-passed at ``cutoff`` Hz as every analysis does; see the module
    docstring for the channels).  The load options are accepted as every analysis takes them and
    do not change the result."""
    if paths not in ("auto", "model"):
        raise ModelError(f"paths must be 'auto' or 'model', got {paths!r}")
    if model.muscles is None or model.n_muscles == 0:
        raise ModelError(f"model '{model.name}' has no muscles to analyse")
    inputs = prepare(model, trial, cutoff=cutoff, grf=grf, external_loads=external_loads,
                     ground_reaction=ground_reaction, grf_cutoff=grf_cutoff,
                     missing_coordinates=missing_coordinates)
    motion = inputs.motion
    ms = model.muscles
    gp = geometric_paths(model.meta.get("import_report")) if paths == "auto" else None
    if gp is not None and tuple(gp.muscles) == tuple(ms.names):
        l_mt, arms = _geometric(model, gp, motion)
        source = "geometric paths (OpenSim's path algorithm)"
    else:
        l_mt, arms = ms.lengths(motion.q), ms.moment_arms(motion.q)     # (N, m), (N, m, nv)
        source = f"the model's paths ({type(ms.path).__name__})"
    v_mt = np.einsum("nmj,nj->nm", -arms, motion.v)
    l_ce = _fiber_lengths(ms, l_mt, v_mt)
    crossed = np.any(np.abs(arms) > 0.0, axis=0)                       # (m, nv)
    if hasattr(ms.path, "terms"):      # a polynomial path names the coordinates each muscle crosses
        crossed = np.zeros_like(crossed)
        for i, t in enumerate(ms.path.terms):
            crossed[i, [model.coordinate_index(c) for c in t["coordinates"]]] = True
    chans, units = {}, {}
    for i, muscle in enumerate(ms.names):
        chans[f"{muscle}_length"] = l_mt[:, i]
        chans[f"{muscle}_fiber_length"] = l_ce[:, i]
        units[f"{muscle}_length"] = units[f"{muscle}_fiber_length"] = "m"
    for i, muscle in enumerate(ms.names):
        for c in model.coordinate_order:
            j = model.coordinate_index(c)
            if crossed[i, j]:
                chans[f"{muscle}_moment_arm_{c}"] = arms[:, i, j]
                units[f"{muscle}_moment_arm_{c}"] = "m"
    meta = {"analysis": "muscle_analysis", "model": model.name, "fiber_length": "rigid tendon", "paths": source,
            **inputs.meta()}
    return Trial(motion.t, chans, units=units, meta=meta)


def _geometric(model, gp, motion):
    """Exact lengths (N, m) and moment arms (N, m, nv) of an imported model's geometric paths (OpenSim
    coordinates that drive only dependent joints ride along in the motion's signals)."""
    q = motion.q
    cols = [c for c in gp.coordinates if c in model.coordinate_order]
    qg = np.zeros((q.shape[0], len(gp.coordinates)))
    for c in cols:
        qg[:, gp.coordinates.index(c)] = q[:, model.coordinate_index(c)]
    for c in gp.coordinates:
        if c not in model.coordinate_order and c in motion.signals:
            qg[:, gp.coordinates.index(c)] = motion.signals[c]
    crossed = sorted({c for t in model.muscles.path.terms for c in t["coordinates"]}
                     if hasattr(model.muscles.path, "terms") else cols, key=gp.coordinates.index)
    lengths, a = gp.lengths_and_moment_arms(qg, coordinates=crossed)
    arms = np.zeros((q.shape[0], lengths.shape[1], model.nv))
    for k, c in enumerate(crossed):
        arms[:, :, model.coordinate_index(c)] = a[:, :, k]
    return lengths, arms


def _fiber_lengths(ms, l_mt, v_mt):
    """Rigid-tendon fiber lengths (N, m); NaN where ``l_mt <= l_slack`` (no fiber state), named in one
    :class:`FiberRoomWarning` line."""
    l_slack = np.broadcast_to(np.asarray(ms.mtu.l_slack, dtype=float), l_mt.shape[1:])
    room = l_mt - l_slack > 0.0
    if room.all():
        return ms.mtu.fiber_kinematics_rigid(l_mt, v_mt)[0]
    # the fiber kinematics of the frames without room are evaluated at a placeholder length, then masked
    placeholder = np.where(room, l_mt, l_slack + 1e-3)
    l_ce = np.where(room, ms.mtu.fiber_kinematics_rigid(placeholder, np.where(room, v_mt, 0.0))[0], np.nan)
    bad = np.flatnonzero(~room.all(axis=0))
    named = ", ".join(f"{ms.names[i]} ({int((~room[:, i]).sum())} of {room.shape[0]} frames, first at frame "
                      f"{int(np.argmax(~room[:, i]))})" for i in bad)
    warnings.warn(f"muscle analysis: no room for the rigid-tendon fiber (l_mt <= tendon slack length) of "
                  f"{named}; fiber length NaN there", FiberRoomWarning, stacklevel=3)
    return l_ce
