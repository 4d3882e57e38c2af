"""Ground reaction forces: from force-plate signals to wrenches on the model's feet.

* :func:`cop_from_plate` -- centre of pressure and free moment from a plate's
  force and its moment about a reference point, on the plate surface
  ``y = surface_height`` (y up).  From ``M = (p - o) x F + T`` with ``T`` along y:
  ``r_x = (M_z + r_y F_x) / F_y``, ``r_z = (r_y F_z - M_x) / F_y`` and
  ``T_y = M_y - (r_z F_x - r_x F_z)`` with ``r = p - o``, ``r_y = h - o_y``.
  For the CSU file (moment about the global origin, belt at height h) this is
  ``x = (M_z + h F_x) / F_y``.
* :func:`check_vertical_force` -- the load *on the foot* points up during stance; a
  vertical force that is mostly negative when loaded means the plate's sign (or
  axis) is flipped: :class:`~pinmsk.errors.TrialError` naming the channel.
* :func:`external_forces` -- per-foot :class:`pinmsk.ExternalForce` lists from a
  Trial with ``[side_]ground_force_v[xyz]``, ``..._p[xyz]``, ``ground_torque_[xyz]``
  channels (OpenSim's ``ground_force_r_vy`` spellings too).  Unloaded samples
  (vertical force below ``min_force``) get zero force, so the meaningless COP of
  an unloaded plate never enters.  ``planar=True`` drops the out-of-plane force
  and the in-plane free-moment components (2-D models).
* :func:`transfer_cop` -- move a measured COP from the subject's foot to the
  model's foot (same offset from a reference point, e.g. the ankle), for a model
  whose segment lengths differ from the subject's.
* :func:`torso_residuals` -- the generalized forces inverse dynamics leaves at
  the unactuated root coordinates (for gait2d ``torso_x``, ``torso_y`` (N) and
  ``torso_angle`` (N m)), per frame, with RMS and peaks also as % of body weight
  (and body weight x height for the moment).  Large values mean the motion,
  the forces and the model's mass distribution disagree.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from .errors import TrialError
from .skeleton import ExternalForce
from .trial import Trial, parse_ground_reaction

__all__ = ["cop_from_plate", "check_vertical_force", "external_forces", "grf_channels",
           "transfer_cop", "torso_residuals", "stance_mask", "FOOT_FRAMES"]

#: Default body receiving each side's ground reaction (first present in the model).
FOOT_FRAMES = ("foot_{s}", "calcn_{s}", "heel_{s}", "{s}_foot")


def cop_from_plate(force, moment, *, surface_height: float = 0.0, origin=(0.0, 0.0, 0.0),
                   min_force: float = 20.0):
    """COP ``(N, 3)`` and free moment ``(N, 3)`` (only y non-zero) from a plate.

    ``force`` (N, 3) is the load on the foot (N), ``moment`` (N, 3) its moment (N m) about
    ``origin`` (a world point, m); 2-D data may pass ``moment`` as (N,) ``M_z``.  The COP
    lies on ``y = surface_height``; where ``F_y < min_force`` it is NaN.
    """
    F = np.atleast_2d(np.asarray(force, dtype=float))
    M = np.asarray(moment, dtype=float)
    if M.ndim == 1:
        M = np.column_stack([np.zeros_like(M), np.zeros_like(M), M])
    if F.shape != M.shape or F.shape[1] != 3:
        raise TrialError(f"force and moment must both be (N, 3) (or moment (N,) = M_z); got {F.shape}, {M.shape}")
    o = np.asarray(origin, dtype=float)
    ry = surface_height - o[1]
    fx, fy, fz = F.T
    mx, my, mz = M.T
    ok = fy >= min_force
    cop = np.full_like(F, np.nan)
    free = np.zeros_like(F)
    with np.errstate(divide="ignore", invalid="ignore"):
        rx = (mz + ry * fx) / fy
        rz = (ry * fz - mx) / fy
    cop[ok, 0] = o[0] + rx[ok]
    cop[ok, 1] = surface_height
    cop[ok, 2] = o[2] + rz[ok]
    free[ok, 1] = my[ok] - (rz[ok] * fx[ok] - rx[ok] * fz[ok])
    return cop, free


def _sides(trial: Trial) -> dict:
    groups: dict = {}
    for name in trial.names:
        p = parse_ground_reaction(name)
        if p is None:
            continue
        key = (p.quantity, p.axis)
        g = groups.setdefault(p.side, {})
        if key in g:
            raise TrialError(f"ground reaction of side {p.side!r}: both {g[key]!r} and {name!r} "
                             f"give the {p.quantity} {p.axis}; drop one")
        g[key] = name
    return groups


def grf_channels(trial: Trial) -> dict:
    """``{side: {(quantity, axis): channel}}`` of the trial's ground reaction channels."""
    return _sides(trial)


def stance_mask(fy: np.ndarray, *, min_force: float = 20.0) -> np.ndarray:
    """Frames where the (correctly signed) vertical force is at least ``min_force`` N."""
    return np.asarray(fy) >= min_force


def check_vertical_force(trial: Trial, *, min_force: float = 20.0, body_mass: float | None = None) -> None:
    """Raise TrialError if a vertical ground force is negative during stance (wrong sign/axis).

    Wrong axis: when the plate is loaded, a horizontal component larger than the vertical
    one (median magnitudes) means y is not the plate's vertical axis (a z-up lab).
    Loaded samples are those with ``|F_y| >= min_force``; if most of them are
    negative (or the most negative exceeds the largest positive), the plate's
    sign convention is the reaction *on the plate*, or y is not vertical.
    With ``body_mass``, a total vertical force whose loaded median is below 20 %
    of body weight also suggests the wrong axis.
    """
    groups = _sides(trial)
    if not groups:
        raise TrialError("no ground reaction channels (ground_force_v[xyz] ...) in the trial")
    for side, ch in groups.items():
        name = ch.get(("force", "y"))
        if name is None:
            raise TrialError(f"ground reaction of side {side!r} has no vertical force ..._vy channel")
        fy = np.asarray(trial[name])
        comps = {a: np.asarray(trial[ch[("force", a)]]) for a in "xz" if ("force", a) in ch}
        norm = np.sqrt(fy ** 2 + sum(c ** 2 for c in comps.values()))
        heavy = norm >= min_force
        if heavy.any():
            med_y = float(np.median(np.abs(fy[heavy])))
            meds = {a: float(np.median(np.abs(c[heavy]))) for a, c in comps.items()}
            for a in sorted(meds, key=meds.get, reverse=True)[:1]:
                med = meds[a]
                if med > med_y:
                    raise TrialError(
                        f"ground reaction of side {side!r}: the force along {a} (median {med:.0f} N when loaded, "
                        f"channel {ch[('force', a)]!r}) exceeds the vertical {name!r} (median {med_y:.0f} N); "
                        f"the plate's axes are not the lab's (y up): remap them (e.g. pinmsk.c3d.remap_axes "
                        f"for a z-up lab)")
        loaded = np.abs(fy) >= min_force
        if not loaded.any():
            continue
        neg = np.mean(fy[loaded] < 0)
        if neg > 0.5 or -fy.min() > fy.max():
            k = int(np.argmin(fy))
            raise TrialError(
                f"channel {name!r}: the vertical ground force is negative during stance "
                f"({100 * neg:.0f} % of the loaded samples; minimum {fy.min():.1f} N at t = "
                f"{trial.time[k]:.4g} s, maximum {fy.max():.1f} N). The plate gives the force on the plate, "
                "not on the foot, or y is not the vertical axis: flip the sign of the force (and moment) "
                "channels, or map the plate axes onto the lab frame (y up)")
        if body_mass is not None:
            med = float(np.median(fy[loaded]))
            if med < 0.2 * body_mass * 9.81:
                raise TrialError(
                    f"channel {name!r}: the loaded vertical force (median {med:.0f} N) is below 20 % of body "
                    f"weight ({body_mass * 9.81:.0f} N); check the axis mapping (y up) and the units")


def _foot_frame(model, side, frames: Mapping | None) -> str:
    if frames and side in frames:
        model.frame_id(frames[side])
        return frames[side]
    if side is not None:
        for pat in FOOT_FRAMES:
            cand = pat.format(s=side)
            if cand in model.frame_names:
                return cand
    raise TrialError(f"cannot tell which body receives the ground reaction of side {side!r}; pass "
                     f"frames={{{side!r}: '<frame>'}}")


def external_forces(model, trial: Trial, *, frames: Mapping[str, str] | None = None,
                    min_force: float = 20.0, planar: bool = False, check_sign: bool = True,
                    cop: Mapping[str, np.ndarray] | None = None) -> list[ExternalForce]:
    """Per-foot world-frame wrenches of the trial's ground reaction channels.

    ``frames`` maps a side (``"r"``) to the receiving body (default ``foot_<side>``,
    ``calcn_<side>``, ...).  Samples with vertical force below ``min_force`` N get a
    zero wrench.  ``planar`` keeps only F_x, F_y and the free moment about z (2-D
    models in the x-y plane).  ``cop`` overrides a side's COP ``(N, 3)`` (e.g. from
    :func:`transfer_cop`).  The trial must be on the motion's time base (see
    :mod:`pinmsk.resample`).
    """
    if check_sign:
        check_vertical_force(trial, min_force=min_force)
    groups = _sides(trial)
    out = []
    for side, ch in sorted(groups.items(), key=lambda kv: str(kv[0])):
        need = [("force", "x"), ("force", "y")] + ([] if planar else [("force", "z")])
        if not (cop is not None and side in cop):
            need += [("point", "x")] + ([] if planar else [("point", "z")])
        missing = [f"{q}_{a}" for q, a in need if (q, a) not in ch]
        if missing:
            raise TrialError(f"ground reaction of side {side!r} lacks {', '.join(missing)} channels "
                             "(need ground_force_v[xyz] and ground_force_p[xyz])")
        n = trial.n_frames
        zero = np.zeros(n)
        F = np.column_stack([trial[ch[("force", a)]] if ("force", a) in ch else zero for a in "xyz"])
        if cop is not None and side in cop:
            P = np.asarray(cop[side], dtype=float)
        else:
            P = np.column_stack([trial[ch[("point", a)]] if ("point", a) in ch else zero for a in "xyz"])
        T = np.column_stack([trial[ch[("torque", a)]] if ("torque", a) in ch else zero for a in "xyz"])
        on = F[:, 1] >= min_force
        F = np.where(on[:, None], F, 0.0)
        P = np.where(on[:, None] & np.isfinite(P), P, 0.0)
        T = np.where(on[:, None], T, 0.0)
        if planar:
            F[:, 2] = 0.0
            T[:, :2] = 0.0
            P[:, 2] = 0.0
        bad = on & ~np.isfinite(F).all(axis=1)
        if bad.any():
            raise TrialError(f"ground reaction of side {side!r} is not finite at frame {int(np.flatnonzero(bad)[0])}")
        out.append(ExternalForce(_foot_frame(model, side, frames), F, P, T))
    return out


def transfer_cop(cop, measured_reference, model_reference):
    """COP relative to a measured reference point (e.g. the ankle marker), re-attached to the model's.

    ``cop - measured_reference + model_reference`` for the x (and z) coordinates; the height
    (y) is kept, so the COP stays on the ground.  All ``(N, 3)`` in m.
    """
    cop = np.array(cop, dtype=float)
    d = np.asarray(model_reference, dtype=float) - np.asarray(measured_reference, dtype=float)
    cop[:, 0] += d[:, 0]
    cop[:, 2] += d[:, 2]
    return cop


def torso_residuals(model, id_trial: Trial, *, coordinates: Sequence[str] | None = None,
                    body_mass: float | None = None, height: float | None = None) -> tuple[Trial, dict]:
    """Residual generalized forces at the unactuated root coordinates, per frame, and a summary.

    ``coordinates`` default: the model's prismatic coordinates and the first revolute
    coordinate before any leg (gait2d: ``torso_x``, ``torso_y``, ``torso_angle``).  Returns
    ``(trial of <coord>_residual, summary)``; the summary has per coordinate RMS and peak
    (N or N m) and, with ``body_mass`` (and ``height`` for moments), RMS as % of body
    weight (x height).
    """
    if coordinates is None:
        coordinates = [c for c in model.coordinate_order if c.startswith(("torso_", "pelvis_"))]
        if not coordinates:
            raise TrialError("cannot tell the model's unactuated coordinates; pass coordinates=[...]")
    ch = {}
    summary = {}
    bw = None if body_mass is None else body_mass * 9.81
    for c in coordinates:
        name = f"{c}_moment"
        if name not in id_trial:
            raise TrialError(f"the inverse-dynamics trial has no {name!r}")
        r = np.asarray(id_trial[name])
        ch[f"{c}_residual"] = r
        rms = float(np.sqrt(np.mean(r ** 2)))
        s = {"rms": rms, "peak": float(np.max(np.abs(r))), "mean": float(np.mean(r)),
             "unit": "N*m" if c in model.rotational_coordinates else "N"}
        if bw is not None:
            if s["unit"] == "N":
                s["rms_percent_bw"] = 100 * rms / bw
            elif height is not None:
                s["rms_percent_bw_height"] = 100 * rms / (bw * height)
        summary[c] = s
    return Trial(id_trial.time, ch, meta={"analysis": "torso_residuals"}), summary
