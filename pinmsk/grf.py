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

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from .errors import TrialError
from .skeleton import ExternalForce, cross3
from .trial import Trial, moment_channel, parse_ground_reaction

__all__ = ["cop_from_plate", "check_vertical_force", "external_forces", "grf_channels", "Plate", "plates",
           "plate_wrench", "BODY_ALIASES",
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
        # |F_y| at least every horizontal component on every loaded sample puts each order statistic of |F_y|,
        # its median too, at or above theirs: nothing to refuse, no medians needed (the common case)
        dominant = all(bool(np.all(np.abs(c[heavy]) <= np.abs(fy[heavy]))) for c in comps.values())
        if heavy.any() and not dominant:
            # the loaded medians of all components in one call (column by column: the same numbers)
            med = np.median(np.abs(np.column_stack([fy, *comps.values()])[heavy]), axis=0)
            med_y = float(med[0])
            meds = {a: float(m) for a, m in zip(comps, med[1:])}
            for a in sorted(meds, key=meds.get, reverse=True)[:1]:
                med = meds[a]
                if med > med_y:
                    raise TrialError(
                        f"ground reaction of side {side!r}: the force along {a} (median {med:.0f} N when loaded, "
                        f"channel {ch[('force', a)]!r}) exceeds the vertical {name!r} (median {med_y:.0f} N); "
                        f"the plate's axes are not the lab's (y up): remap them (e.g. pinmsk.io.c3d.remap_axes "
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


#: Side prefixes and the words models use for them in body names.
_SIDE_WORDS = {"r": ("r", "right"), "l": ("l", "left"), "right": ("r", "right"), "left": ("l", "left")}

#: OpenSim body names and the pinmsk body of the same segment (the calcaneus is the foot).
BODY_ALIASES = {"calcn_{s}": "foot_{s}", "foot_{s}": "calcn_{s}"}


@dataclass(frozen=True)
class Plate:
    """One source of ground reaction: its columns and the body it acts on (and why).

    ``columns`` maps ``(quantity, axis)`` (quantity ``force``, ``point`` or
    ``torque``) to the trial's channel; ``body`` is a frame of the model;
    ``reason`` says how the body was chosen, for reports.
    """

    name: str
    columns: Mapping
    body: str
    reason: str

    def describe(self) -> str:
        force = [self.columns[("force", a)] for a in "xyz" if ("force", a) in self.columns]
        stem = force[0][:-1] + "[xyz]" if force else "?"
        return f"{self.name} ({stem}) -> {self.body} ({self.reason})"


def _frame_for_side(model, side) -> str | None:
    words = _SIDE_WORDS.get(str(side).lower(), (side,)) if side is not None else ()
    for word in words:
        for pat in FOOT_FRAMES:
            cand = pat.format(s=word)
            if cand in model.frame_names:
                return cand
    return None


def _body_in_model(model, body: str) -> tuple[str, str] | None:
    """``(frame, note)`` for a body name, trying the OpenSim-to-pinmsk aliases."""
    if body in model.frame_names:
        return body, ""
    for src, dst in BODY_ALIASES.items():
        for word in ("r", "l"):
            if body == src.format(s=word) and dst.format(s=word) in model.frame_names:
                return dst.format(s=word), f", the model's body for OpenSim's {body!r}"
    return None


def _nearest_foot(model, q, plate_cols, trial, min_force) -> tuple[str, str]:
    """The foot nearest to a plate's COP during its stance (whole-plate assignment)."""
    import pinocchio as pin
    feet = [f for f in (_frame_for_side(model, s) for s in ("r", "l")) if f is not None]
    if not feet:
        raise TrialError("the model has no foot body (foot_r, calcn_r, ...) to receive the ground reaction")
    fy = np.asarray(trial[plate_cols[("force", "y")]])
    loaded = np.flatnonzero(fy >= min_force)
    if q is None or loaded.size == 0 or ("point", "x") not in plate_cols:
        raise TrialError(f"cannot tell which foot the plate {plate_cols[('force', 'y')]!r} acts on; name the "
                         "side in the columns (r_ground_force_vy) or pass an ExternalLoads .xml / frames=")
    rows = loaded[:: max(1, loaded.size // 50)]
    cop = np.column_stack([np.asarray(trial[plate_cols[("point", a)]])[rows] if ("point", a) in plate_cols
                           else np.zeros(rows.size) for a in "xyz"])
    pm = model.pin
    pd = pm.createData()
    dist = np.zeros((rows.size, len(feet)))
    ids = [pm.getFrameId(f) for f in feet]
    for i, k in enumerate(rows):
        pin.framesForwardKinematics(pm, pd, q[k])
        for j, fid in enumerate(ids):
            d = pd.oMf[fid].translation - cop[i]
            dist[i, j] = np.hypot(d[0], d[2])
    votes = np.bincount(np.argmin(dist, axis=1), minlength=len(feet))
    j = int(np.argmax(votes))
    share = votes[j] / rows.size
    return feet[j], f"nearest foot to the COP in {100 * share:.0f} % of its loaded frames"


def plates(model, trial: Trial, *, external_loads=None, frames: Mapping | None = None, q=None,
           min_force: float = 20.0) -> list[Plate]:
    """The ground-reaction sources of ``trial`` and the body each acts on.

    Bodies are chosen, in order: ``frames[side]``; the ExternalLoads entry's
    ``applied_to_body`` (``calcn_r`` is taken as ``foot_r`` on a model that
    has no calcn); the side prefix (``r_ground_force_vy`` -> ``foot_r``,
    ``calcn_r``, ``right_foot``, ...); else the foot nearest to the plate's COP
    during its stance (``q``, the trial's coordinates, needed).  A body the
    model lacks is an error naming it.
    """
    out = []
    if external_loads is not None:
        for spec in external_loads.loads:
            cols = {}
            for kind in ("force", "point", "torque"):
                names = spec.columns(kind)
                if names is None:
                    continue
                present = [n for n in names if n in trial]
                if kind == "force" and len(present) < 3:
                    missing = [n for n in names if n not in trial]
                    raise TrialError(f"{external_loads.path}: ExternalForce {spec.name!r} needs the columns "
                                     f"{', '.join(missing)}, which the GRF data lacks (it has "
                                     f"{', '.join(n for n in trial.names if 'ground' in n) or 'no ground columns'})")
                cols.update({(kind, n[-1]): n for n in present})
            if frames and spec.name in frames:
                body, reason = frames[spec.name], "given"
                model.frame_id(body)
            else:
                found = _body_in_model(model, spec.body)
                if found is None:
                    raise TrialError(f"{external_loads.path}: ExternalForce {spec.name!r} acts on body "
                                     f"{spec.body!r}, which model '{model.name}' lacks; pass frames="
                                     f"{{{spec.name!r}: '<body>'}} (bodies: {', '.join(model.frame_names[:12])} ...)")
                body, note = found
                reason = f"ExternalLoads applied_to_body{note}"
            out.append(Plate(spec.name, cols, body, reason))
        return out
    for side, cols in sorted(_sides(trial).items(), key=lambda kv: str(kv[0])):
        if ("force", "y") not in cols:
            raise TrialError(f"ground reaction of side {side!r} has no vertical force ..._vy channel")
        name = f"side {side!r}" if side is not None else "plate"
        if frames and side in frames:
            model.frame_id(frames[side])
            out.append(Plate(name, cols, frames[side], "given"))
            continue
        body = _frame_for_side(model, side) if side is not None else None
        if body is not None:
            out.append(Plate(name, cols, body, "by the side in the column names"))
            continue
        if str(side).lower() in _SIDE_WORDS:
            tried = ", ".join(p.format(s=w) for w in _SIDE_WORDS[str(side).lower()] for p in FOOT_FRAMES)
            raise TrialError(f"ground reaction {name} ({cols[('force', 'y')]}): model '{model.name}' has no body "
                             f"to receive it (tried {tried}); pass frames={{{side!r}: '<body>'}}, or leave "
                             "the GRF out on purpose (ground_reaction='ignore', CLI --no-grf)")
        body, reason = _nearest_foot(model, q, cols, trial, min_force)
        out.append(Plate(name, cols, body, reason))
    return out


def plate_wrench(trial: Trial, plate: Plate, *, min_force: float = 20.0, planar: bool = False,
                 cop: np.ndarray | None = None, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World wrench of one plate about the world origin: force ``(N, 3)`` and moment ``(N, 3)``.

    ``M = p x F + T`` with ``p`` the COP and ``T`` the free moment.  Samples with
    vertical force below ``min_force`` N are zero (an unloaded plate's COP means
    nothing).  ``planar`` (models in the x-y plane) keeps F_x, F_y and M_z.
    ``rows`` (sorted frame indices) converts only those frames (``cop`` then has one row each).
    This is the one conversion of plate data to loads on the model.
    """
    ch = plate.columns
    need = [("force", "x"), ("force", "y")] + ([] if planar else [("force", "z")])
    if cop is None:
        need += [("point", "x")] + ([] if planar else [("point", "z")])
    missing = [f"{q}_{a}" for q, a in need if (q, a) not in ch]
    if missing:
        raise TrialError(f"ground reaction {plate.name} lacks {', '.join(missing)} channels "
                         "(need ground_force_v[xyz] and ground_force_p[xyz])")
    # force, point and torque as one (N, 9) block read in one call; absent components are zero
    kinds = ("force", "torque") if cop is not None else ("force", "point", "torque")
    keys = [(k, a) for k in kinds for a in "xyz"]
    have = [i for i, key in enumerate(keys) if key in ch]
    block = trial.get([ch[keys[i]] for i in have], rows=rows)
    X = np.zeros((block.shape[0], len(keys)))
    X[:, have] = block
    on = X[:, 1] >= min_force
    if cop is None and np.isfinite(block).all():
        # the usual case, every sample finite: the unloaded frames zeroed in one pass (the same numbers)
        X = np.where(on[:, None], X, 0.0)
        F, P, T = X[:, 0:3], X[:, 3:6], X[:, 6:9]
    else:
        F = X[:, 0:3]
        P = np.asarray(cop, dtype=float) if cop is not None else X[:, 3:6]
        T = X[:, -3:]
        bad = on & ~(np.isfinite(F).all(axis=1) & np.isfinite(T).all(axis=1))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            k = k if rows is None else int(rows[k])
            raise TrialError(f"ground reaction {plate.name} is not finite at frame {k} (t = {trial.time[k]:.6g} s)")
        F = np.where(on[:, None], F, 0.0)
        P = np.where(on[:, None] & np.isfinite(P), P, 0.0)
        T = np.where(on[:, None], T, 0.0)
    if planar:
        F[:, 2] = 0.0
        P[:, 2] = 0.0
        T[:, :2] = 0.0
    return F, cross3(P, F) + T


def external_forces(model, trial: Trial, *, frames: Mapping[str, str] | None = None,
                    min_force: float = 20.0, planar: bool = False, check_sign: bool = True,
                    cop: Mapping[str, np.ndarray] | None = None) -> list[ExternalForce]:
    """Per-plate world-frame wrenches of the trial's ground reaction channels (unfiltered).

    ``frames`` maps a side (``"r"``) to the receiving body (default ``foot_<side>``,
    ``calcn_<side>``, ...; see :func:`plates`).  Samples with vertical force below
    ``min_force`` N get a zero wrench.  ``planar`` keeps only F_x, F_y and the moment
    about z (2-D models in the x-y plane).  ``cop`` overrides a side's COP ``(N, 3)``
    (e.g. from :func:`transfer_cop`).  The trial must be on the motion's time base.
    Analyses use :func:`pinmsk.kinematics.prepare`, which also filters.
    """
    if check_sign:
        check_vertical_force(trial, min_force=min_force)
    out = []
    for plate, side in zip(plates(model, trial, frames=frames, min_force=min_force),
                           sorted(_sides(trial), key=str)):
        c = None if cop is None else cop.get(side)
        F, M = plate_wrench(trial, plate, min_force=min_force, planar=planar, cop=c)
        out.append(ExternalForce(plate.body, F, np.zeros_like(F), M))
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
        name = moment_channel(c)
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
