"""Synthetic trials with hidden effects: the ground truth the diagnosis is tested on.

:func:`make_trial` builds a smooth motion for a model, computes what the
*true* model -- the model plus the hidden ``effects`` -- needs to produce it,
and returns the measurements a lab would record, with noise:

* fixed-base models (``forearm``, ``finger``): a multi-sine of each
  coordinate over 8-92 % of its joint range (0.2-1.3 Hz, seeded phases),
  exact derivatives; measured ``<coord>`` and ``<coord>_moment`` (the true
  inverse dynamics: what a dynamometer sees), and with muscle-level hidden
  effects (or ``measure=("excitations",)``) the excitations
  ``<muscle>_excitation`` instead of the moments:
  activations share the moment by a smooth minimum-norm split over flexors
  and extensors on top of 5 % co-activation; with hidden
  ``activation_dynamics`` the excitation is the exact inverse (thesis Eq. A.5)
  of those activations; with a hidden ``electromechanical_delay`` the
  recorded excitation leads the muscle's by ``delay``; hidden measurement
  effects (``sensor_offset``, ``sensor_gain``) turn the true moment into the
  reading of a biased or mis-scaled sensor (their ``measure``);
* floating-base models (``gait2d``): a squat-and-sway with the right foot flat
  on the ground at a fixed place (the torso coordinates follow from the
  closure), the left leg slightly out of phase; measured coordinates and
  ground reaction forces per foot (``r_ground_force_v[xyz]``, ``..._p[xyz]``,
  ``..._torque_[xyz]``) whose wrench makes the torso rows of the true
  inverse dynamics vanish: the vertical load split 50 +- 15 % between the
  feet, both centres of pressure under the feet, shifted together to carry
  the moment.

Noise (``noise="realistic"``, seeded): white on angles 0.2 deg, translations
0.5 mm; moments 2 % of the channel's peak; ground reaction forces 1 % of the
peak vertical force, centres of pressure 2 mm.  Excitations are measured as
EMG envelopes are made: raw EMG at 1 kHz is the excitation times a Gaussian
carrier band-limited to 20-450 Hz, plus an amplifier floor of
``excitation_floor`` (0.005) times another; it is rectified and low-passed at
``emg_lowpass`` Hz (6, zero-lag, order 4: :func:`pinmsk.signals.emg.envelope`)
over a record 1 s longer at each end, scaled by the carrier's rectified mean
and sampled at the trial's times.  Its noise is multiplicative and coloured:
about 8 % of the envelope, flat up to the low-pass and nothing above it (what
third differences cannot see); ``trial.meta["emg_lowpass"]`` and
``["emg_rate"]`` record the low-pass and the rate it ran at, as
:func:`pinmsk.signals.emg.envelopes` does.  ``emg_lowpass=0``
gives the white model instead, ``u (1 + excitation xi) + excitation_floor xi'``
with ``excitation`` = 0.05, clipped at 0.  ``noise=None`` gives exact data; a
dict overrides single levels (keys ``angle``, ``translation``, ``moment``,
``grf``, ``cop``, ``excitation``, ``excitation_floor``, ``emg_lowpass``).

The CLI's ``pinmsk synth MODEL --effect FAMILY:TARGET:param=value ...`` maps
onto :func:`make_trial` with effect strings in the same syntax
(:func:`pinmsk.diagnose.parse_effect`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.interpolate import make_interp_spline

from ..components import Component, Motion
from ..dynamics import inverse_dynamics_array
from ..effects import registry
from ..effects._base import SignalEffect, unactuated_coordinates
from ..errors import ModelError
from ..grf import external_forces
from ..kinematics import require_independent_joints
from ..model import load_model
from ..muscles.activation import excitation_from_activation
from ..skeleton import ExternalForce, external_generalized_force
from ..trial import Trial, moment_channel, parse_ground_reaction
from .diagnosis import parse_effect

__all__ = ["make_trial", "NOISE", "WALK", "effect_from_text", "walking_motion", "write_compact"]

#: realistic noise levels (see the module docstring)
NOISE = {"angle": np.deg2rad(0.2), "translation": 0.0005, "moment": 0.02, "grf": 0.01, "cop": 0.002,
         "excitation": 0.05, "excitation_floor": 0.005, "emg_lowpass": 6.0}
#: Sampling rate (Hz) of the raw EMG behind synthetic envelopes, and its band (Hz).
EMG_RATE = 1000.0
EMG_BAND = (20.0, 450.0)


def effect_from_text(text: str) -> Component:
    """``"family:target:p=v,p=v"`` -> a Component (all parameters not given keep their defaults)."""
    family, target, values = parse_effect(text)
    cls = registry.get(family)
    if target is None and getattr(cls, "level", "joint") != "muscle":
        raise ModelError(f"effect {text!r} needs a target: write {family}:TARGET[:PARAM=VALUE,...]")
    return cls(target, **values) if target is not None else cls(**values)


def _load(model):
    if isinstance(model, (str, Path)):
        return load_model(model)
    return model


def _walk_coordinates(model, tt, period: float, speed: float) -> np.ndarray:
    """The closed-form gait2d walk of :func:`walking_motion` at times ``tt``."""
    w = 2 * np.pi / period
    q = np.zeros((tt.size, model.nv))
    ix = model.coordinate_index
    q[:, ix("torso_x")] = speed * tt
    q[:, ix("torso_y")] = 1.0 + 0.02 * np.cos(2 * w * tt)
    q[:, ix("torso_angle")] = 0.05 + 0.02 * np.sin(2 * w * tt)
    for side, ph in (("r", 0.0), ("l", np.pi)):
        q[:, ix(f"hip_{side}")] = -0.1 + 0.35 * np.sin(w * tt + ph)
        q[:, ix(f"knee_{side}")] = 0.6 + 0.5 * np.sin(w * tt + ph - 1.2)
        q[:, ix(f"ankle_{side}")] = 0.05 + 0.2 * np.sin(w * tt + ph + 0.5)
    return q


def _central(f, t, h: float = 1e-5):
    """``(f(t), f'(t), f''(t))`` of a smooth closed form by central differences (step ``h``)."""
    q = f(t)
    return q, (f(t + h) - f(t - h)) / (2 * h), (f(t + h) - 2 * q + f(t - h)) / h ** 2


def walking_motion(model, *, n_frames: int = 200, duration: float = 1.0, period: float = 1.0,
                   speed: float = 1.2) -> Motion:
    """A walking-like gait2d motion with exact derivatives (no data, no noise): the SO test and benchmark motion.

    The torso moves forward at ``speed`` (m/s) and bobs at twice the stride
    frequency; hips, knees and ankles swing sinusoidally with period ``period``
    (s), the left leg half a period behind the right.  ``n_frames`` uniform
    samples over ``[0, duration]``; velocities and accelerations by central
    differences (step 1e-5 s) of the closed-form coordinates.
    """
    t = np.linspace(0.0, duration, n_frames)
    return Motion(t, *_central(lambda tt: _walk_coordinates(model, tt, period, speed), t))


#: The synthetic walk (``make_trial(..., motion="walk")``): stride period (s), speed (m/s), the foot
#: loads' hand-over (s, double support) and the heel-strike bounce (m, s).
WALK = {"period": 1.0, "speed": 1.2, "double_support": 0.06, "impact": 0.001, "impact_time": 0.015}


def _heel_strikes(side: str, tt) -> np.ndarray:
    """Time since the last heel strike of ``side`` (right at 0, 1, 2 ... s; left half a period later)."""
    P = WALK["period"]
    off = 0.0 if side == "r" else 0.5 * P
    return np.mod(tt - off, P)


def _walk(model, t):
    """``(q, v, a, share_r)`` of the synthetic walk: :func:`walking_motion`'s coordinates plus a heel-strike
    bounce of the trunk, ``-A (s / T)^3 exp(3 - s / T) / 27`` for ``s`` seconds after each heel strike (C2,
    content up to ~1 / (2 pi T) = 10 Hz, above the 6-Hz low-pass: what makes GRF and kinematics need the
    same filter), and the right foot's share of the load: 1 in right single stance, 0 in left, a quintic
    smoothstep over the double support after each heel strike (zero load is exactly zero)."""
    need = ["torso_x", "torso_y", "torso_angle", "hip_r", "knee_r", "ankle_r", "hip_l", "knee_l", "ankle_l"]
    missing = [c for c in need if c not in model.coordinates]
    if missing or "heel_r" not in model.frame_names:
        raise ModelError(f"the synthetic walk needs a planar leg model with {', '.join(need)}; '{model.name}' "
                         f"lacks {', '.join(missing) or 'heel_r'}")
    A, T = WALK["impact"], WALK["impact_time"]
    iy = model.coordinate_index("torso_y")

    def coords(tt):
        q = _walk_coordinates(model, tt, WALK["period"], WALK["speed"])
        for side in ("r", "l"):
            x = _heel_strikes(side, tt) / T
            q[:, iy] -= A * x ** 3 * np.exp(3.0 - x) / 27.0
        return q

    q, v, a = _central(coords, t)
    x = np.clip(_heel_strikes("r", t) / WALK["double_support"], 0, 1)
    y = np.clip(_heel_strikes("l", t) / WALK["double_support"], 0, 1)
    rise = x ** 3 * (10 - 15 * x + 6 * x ** 2)                  # right takes the load after its heel strike
    fall = y ** 3 * (10 - 15 * y + 6 * y ** 2)                  # and gives it up after the left's
    half = _heel_strikes("r", t) < 0.5 * WALK["period"]
    share = np.where(half, rise, 1.0 - fall)
    return q, v, a, share


def make_trial(model, effects: Sequence = (), *, duration: float = 10.0, rate: float = 100.0,
               noise="realistic", seed: int = 0, measure: Sequence[str] | None = None,
               amplitude: float = 1.0, motion: str = "auto") -> Trial:
    """A synthetic trial of ``model`` with hidden ``effects`` (Components or effect strings).

    ``measure`` picks the recorded channel groups among ``"moments"``,
    ``"excitations"``, ``"grf"`` (default: moments for fixed-base models,
    excitations when a muscle-level effect is hidden, ground reaction forces
    for a floating base).  ``amplitude`` scales the motion (1 = the default
    range).  ``motion``: ``"auto"`` (the multi-sine, or the squat-and-sway for
    a floating base) or ``"walk"`` (gait2d: :func:`walking_motion` with
    heel-strike bounces and the load handed from foot to foot, :data:`WALK`).
    Returns a :class:`~pinmsk.trial.Trial` whose ``meta`` records the hidden
    effects and noise levels.
    """
    model = _load(model)
    # the synthetic motion drives every joint on its own: dependent joints (an exact import) cannot follow
    require_independent_joints(model, "make_trial (pinmsk synth)")
    effs = [effect_from_text(e) if isinstance(e, str) else e for e in effects]
    for e in effs:
        if not isinstance(e, Component):
            raise ModelError(f"hidden effects are Components or 'family:target:p=v' strings, got {e!r}")
    if duration <= 0 or rate <= 0:
        raise ModelError(f"duration and rate must be positive, got {duration} s at {rate} Hz")
    levels = _levels(noise)
    rng = np.random.default_rng(seed)
    sensors = [e for e in effs if getattr(e, "level", "joint") == "sensor"]
    joint = [e for e in effs if not isinstance(e, SignalEffect) and e not in sensors]
    signal = sorted([e for e in effs if isinstance(e, SignalEffect)], key=lambda e: e.order)
    truth = model.with_effect(*joint) if joint else model
    for e in signal:
        e.check_target(model)
    unact = unactuated_coordinates(model)
    if measure is None:
        measure = ("grf",) if unact else (("excitations",) if signal else ("moments",))
    measure = tuple(measure)
    bad = [m for m in measure if m not in ("moments", "excitations", "grf")]
    if bad:
        raise ModelError(f"measure entries are 'moments', 'excitations' or 'grf', got {bad}")
    if signal and "excitations" not in measure:
        raise ModelError("muscle-level hidden effects only show in excitation channels; "
                         "include 'excitations' in measure")
    if sensors and "moments" not in measure:
        raise ModelError(f"hidden {sensors[0].label} describes a recorded moment: include 'moments' in measure")
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    lead = 0.3 if signal else 0.0            # extra time so a delayed signal exists at the end
    if motion not in ("auto", "walk"):
        raise ModelError(f"motion must be 'auto' or 'walk', got {motion!r}")
    share = None
    if motion == "walk":
        if not unact:
            raise ModelError(f"the synthetic walk is for a floating-base leg model; '{model.name}' is fixed")
        q, v, a, share = _walk(model, t)
    elif unact:
        q, v, a = _squat(model, t, rng, amplitude)
    else:
        q, v, a = _multisine(model, np.arange(int(round((duration + lead) * rate)) + 1) / rate,
                             rng, amplitude)
    motion = Motion(t, q[:n], v[:n], a[:n])
    chans: dict[str, np.ndarray] = {}
    for i, c in enumerate(model.coordinates):
        chans[c] = q[:n, i].copy()
    if "grf" in measure:
        if not unact:
            raise ModelError(f"model '{model.name}' is fixed to the world: it has no ground reaction forces")
        chans.update(_grf(truth, motion, unact, t, share))
    if "moments" in measure or "excitations" in measure:
        full = Motion(np.arange(q.shape[0]) / rate, q, v, a)
        external = []
        if "grf" in measure:                     # the legs carry what the ground pushes
            external = external_forces(model, Trial(t, {k: x for k, x in chans.items() if "ground" in k}))
        tau = inverse_dynamics_array(truth, full, external=external)
        if "moments" in measure:
            for i, c in enumerate(model.coordinates):
                if c not in unact:
                    chans[moment_channel(c)] = tau[:n, i].copy()
            for e in sorted(sensors, key=lambda x: x.order):   # the recording of a biased or mis-scaled sensor
                e.check_target(model)
                if e.channel not in chans:
                    raise ModelError(f"hidden {e.label}: the synthetic trial records no {e.channel}")
                chans[e.channel] = e.measure(chans[e.channel])
        if "excitations" in measure:
            u = _excitations(model, full, tau, signal)
            for j, m in enumerate(model.muscle_names):
                chans[f"{m}_excitation"] = u[:n, j]
    trial = Trial(t, chans, meta={"source": f"synth:{model.name}", "hidden_effects": [repr(e) for e in effs],
                                  "noise": {k: float(v) for k, v in levels.items()}, "seed": seed})
    return _add_noise(trial, model, levels, rng) if levels else trial


def _levels(noise) -> dict:
    if noise is None or noise is False or noise == "none":
        return {}
    if noise == "realistic" or noise is True:
        return dict(NOISE)
    if isinstance(noise, dict):
        unknown = set(noise) - set(NOISE)
        if unknown:
            raise ModelError(f"unknown noise keys {sorted(unknown)}; known: {sorted(NOISE)}")
        out = {**NOISE, **noise}
        if "excitation" in noise and out["emg_lowpass"] > 0:
            raise ModelError("noise key 'excitation' sets the white excitation model, but emg_lowpass = "
                             f"{out['emg_lowpass']:g} Hz makes envelope noise (its level follows from the EMG "
                             "process); pass emg_lowpass=0 with it")
        if not 0 <= out["emg_lowpass"] < 0.5 * EMG_RATE:
            raise ModelError(f"noise emg_lowpass must be 0 (white model) or a low-pass in Hz below "
                             f"{0.5 * EMG_RATE:g}; got {out['emg_lowpass']!r}")
        return out
    raise ModelError(f"noise must be 'realistic', None or a dict of levels, got {noise!r}")


# -- motions -------------------------------------------------------------------------------

_FREQS = np.array([0.21, 0.37, 0.59, 0.83, 1.13, 1.31])


def _multisine(model, t, rng, amplitude):
    pm = model.pin
    nv = model.nv
    q = np.empty((t.size, nv))
    v = np.empty_like(q)
    a = np.empty_like(q)
    for i in range(nv):
        lo, hi = float(pm.lowerPositionLimit[i]), float(pm.upperPositionLimit[i])
        if not (np.isfinite(lo) and np.isfinite(hi)) or hi - lo > 20:
            lo, hi = -1.0, 1.0
        mid, half = 0.5 * (lo + hi), 0.42 * (hi - lo) * amplitude
        ph = rng.uniform(0, 2 * np.pi, _FREQS.size)
        amp = 1.0 / (1.0 + np.arange(_FREQS.size) * 0.35)
        w = 2 * np.pi * _FREQS
        s = np.sin(np.outer(t, w) + ph) @ amp
        ds = (np.cos(np.outer(t, w) + ph) * w) @ amp
        dds = (-np.sin(np.outer(t, w) + ph) * w ** 2) @ amp
        k = half / np.max(np.abs(s))
        q[:, i], v[:, i], a[:, i] = mid + k * s, k * ds, k * dds
    return q, v, a


def _squat(model, t, rng, amplitude, fine: int = 10):
    """Squat-and-sway of a planar floating-base leg model: right foot flat and fixed on the ground."""
    import pinocchio as pin

    pm = model.pin
    idx = {c: model.coordinate_index(c) for c in model.coordinates}
    need = ["hip_r", "knee_r", "ankle_r", "hip_l", "knee_l", "ankle_l", "torso_angle", "torso_x", "torso_y"]
    missing = [c for c in need if c not in idx]
    if missing or "heel_r" not in model.frame_names:
        raise ModelError(f"the synthetic squat needs a planar leg model with {', '.join(need)} and a heel_r "
                         f"frame; '{model.name}' lacks {', '.join(missing) or 'heel_r'}")
    tf = np.linspace(t[0], t[-1], (t.size - 1) * fine + 1)
    ph = rng.uniform(0, 2 * np.pi, 4)
    s = amplitude
    w = 2 * np.pi
    knee = s * (0.45 - 0.35 * np.cos(w * 0.25 * tf + ph[0]) + 0.08 * np.sin(w * 0.61 * tf + ph[1]))
    hip = -0.8 * knee * 0.7 + s * 0.06 * np.sin(w * 0.43 * tf + ph[2])
    lean = s * (0.10 * np.sin(w * 0.17 * tf + ph[3]) + 0.05 * np.sin(w * 0.71 * tf))
    lag = 0.15
    knee_l = np.interp(tf - lag, tf, knee) * 0.92
    hip_l = np.interp(tf - lag, tf, hip) * 0.92
    Q = np.zeros((tf.size, model.nq))
    Q[:, idx["knee_r"]], Q[:, idx["hip_r"]], Q[:, idx["torso_angle"]] = knee, hip, lean
    Q[:, idx["knee_l"]], Q[:, idx["hip_l"]] = knee_l, hip_l
    for side, ph_m in (("r", 0.0), ("l", 1.0)):
        if f"mtp_{side}" in idx:
            Q[:, idx[f"mtp_{side}"]] = 0.05 * s * np.sin(w * 0.9 * tf + ph_m)
    data = pm.createData()
    # foot world angle is affine in the joint angles (parallel axes): find the coefficients numerically
    fid = {sd: pm.getFrameId(f"heel_{sd}") for sd in ("r", "l")}

    def foot_angle(qq, sd):
        pin.framesForwardKinematics(pm, data, qq)
        R = data.oMf[fid[sd]].rotation
        return np.arctan2(R[1, 0], R[0, 0])

    q0 = np.zeros(model.nq)
    coef = {}
    for sd in ("r", "l"):
        base = foot_angle(q0, sd)
        coef[sd] = {}
        for c in ("torso_angle", f"hip_{sd}", f"knee_{sd}", f"ankle_{sd}"):
            qq = q0.copy()
            qq[idx[c]] = 0.1
            coef[sd][c] = (foot_angle(qq, sd) - base) / 0.1
    for sd in ("r", "l"):
        cc = coef[sd]
        rest = (cc["torso_angle"] * Q[:, idx["torso_angle"]] + cc[f"hip_{sd}"] * Q[:, idx[f"hip_{sd}"]]
                + cc[f"knee_{sd}"] * Q[:, idx[f"knee_{sd}"]])
        Q[:, idx[f"ankle_{sd}"]] = -rest / cc[f"ankle_{sd}"]
    heel = np.empty((tf.size, 3))
    for k in range(tf.size):
        pin.framesForwardKinematics(pm, data, Q[k])
        heel[k] = data.oMf[fid["r"]].translation
    Q[:, idx["torso_x"]] = -heel[:, 0]
    Q[:, idx["torso_y"]] = -heel[:, 1]
    spline = make_interp_spline(tf, Q, k=5, axis=0)
    return spline(t), spline.derivative(1)(t), spline.derivative(2)(t)


# -- measurements --------------------------------------------------------------------------

def _excitations(model, motion, tau, signal):
    """Excitations that make the muscles produce ``tau`` (after the hidden muscle-level effects)."""
    ms = model.muscles
    if ms is None:
        raise ModelError(f"model '{model.name}' has no muscles: it cannot have excitation channels")
    fa, fp = ms.force_limits(motion.q, motion.v)
    R = ms.moment_arms(motion.q)                               # (N, m, nv)
    crossing = np.any(np.abs(R) > 0, axis=0).sum(axis=1)       # coordinates each muscle crosses
    if np.any(crossing > 1):
        multi = [n for n, k in zip(model.muscle_names, crossing) if k > 1]
        raise ModelError(
            f"synthetic excitations share each joint's moment among the muscles crossing it, which needs "
            f"muscles that cross one coordinate; model '{model.name}' has multi-joint muscles "
            f"({', '.join(multi[:4])}{', ...' if len(multi) > 4 else ''})"
        )
    base = 0.05
    act = np.full(fa.shape, base)
    for j in range(model.nv):
        d = fa * R[:, :, j]                                    # moment per unit activation
        need = tau[:, j] - np.einsum("nm,nm->n", act * fa + fp, R[:, :, j])
        if not np.any(np.abs(R[:, :, j]) > 0):
            continue
        eps = 0.02 * np.max(np.abs(need)) + 1e-9
        pos = 0.5 * (need + np.sqrt(need ** 2 + eps ** 2))
        neg = pos - need
        dp = np.where(d > 0, d, 0.0)
        dn = np.where(d < 0, -d, 0.0)
        act = act + pos[:, None] * dp / np.maximum(np.sum(dp ** 2, axis=1), 1e-300)[:, None] \
                  + neg[:, None] * dn / np.maximum(np.sum(dn ** 2, axis=1), 1e-300)[:, None]
    if np.max(act) > 1.0:
        raise ModelError(f"the synthetic motion needs activation {np.max(act):.2f} > 1 for model "
                         f"'{model.name}'; lower the amplitude")
    u = act
    t = motion.t
    parts = [(e, p) for e in signal for p in e.parts()]
    for e, p in reversed(parts):                               # undo the chain, last part first
        mask = p.muscle_mask(model)
        if p.family == "activation_dynamics":
            v = p.values
            spline = make_interp_spline(t, u, k=5, axis=0)
            adot = spline.derivative(1)(t)
            inv = excitation_from_activation(u, adot, tau_rise=v["tau_rise"], tau_fall=v["tau_fall"])
            u = np.where(mask[None, :], inv, u)
        elif p.family == "electromechanical_delay":
            d = p.values["delay"]
            shifted = np.column_stack([np.interp(t + d, t, u[:, j]) for j in range(u.shape[1])])
            u = np.where(mask[None, :], shifted, u)
        else:
            raise ModelError(f"the synthesiser cannot invert the muscle-level effect {e.label}")
    if np.min(u) < 0 or np.max(u) > 1:
        u = np.clip(u, 0.0, 1.0)
    return u


def _grf(truth, motion: Motion, unact, t, share=None) -> dict:
    """Per-foot ground reaction forces making the torso rows of the true inverse dynamics vanish
    (``share``: the right foot's part of the load; default 50 +- 15 %)."""
    import pinocchio as pin

    model = truth
    tau = inverse_dynamics_array(truth, motion)
    base = [model.coordinate_index(c) for c in unact]
    b = tau[:, base]                                            # J_base^T f must equal this
    n = t.size
    pm = model.pin
    data = pm.createData()
    mid = {}
    zside = {}
    for sd in ("r", "l"):
        h = pm.getFrameId(f"heel_{sd}")
        mname = f"metatarsal_{sd}" if f"metatarsal_{sd}" in model.frame_names else f"toe_{sd}"
        mf = pm.getFrameId(mname)
        pts = np.empty((n, 3))
        for k in range(n):
            pin.framesForwardKinematics(pm, data, motion.q[k])
            pts[k] = 0.5 * (data.oMf[h].translation + data.oMf[mf].translation)
        mid[sd] = pts
        zside[sd] = pts[:, 2]
    share = 0.5 + 0.15 * np.sin(2 * np.pi * 0.3 * t) if share is None else np.asarray(share, dtype=float)
    ex, ey = np.tile([1.0, 0, 0], (n, 1)), np.tile([0, 1.0, 0], (n, 1))

    def gen(sd, unit, dx):
        p = mid[sd].copy()
        p[:, 1] = 0.0
        p[:, 0] += dx
        return external_generalized_force(model, motion.q, [ExternalForce(f"heel_{sd}", unit, p)])[:, base]

    # generalized force of the two feet carrying F = (Fx, Fy) with shares w, 1-w, CoP shift dx
    A = {}
    for dx in (0.0, 1.0):
        cols = []
        for unit in (ex, ey):
            cols.append(share[:, None] * gen("r", unit, dx) + (1 - share)[:, None] * gen("l", unit, dx))
        A[dx] = np.stack(cols, axis=2)                          # (N, nbase, 2)
    F = np.empty((n, 2))
    delta = np.empty(n)
    for k in range(n):
        A0, A1 = A[0.0][k], A[1.0][k]
        # Solve (A0 + delta (A1 - A0)) F = b: the translation rows fix F, the rest fixes delta.
        F[k] = np.linalg.lstsq(A0[:2], b[k, :2], rcond=None)[0]
        g0, g1 = A0 @ F[k], (A1 - A0) @ F[k]
        delta[k] = np.dot(g1[2:], b[k, 2:] - g0[2:]) / max(np.dot(g1[2:], g1[2:]), 1e-300)
    out = {}
    for sd, w in (("r", share), ("l", 1 - share)):
        f = np.column_stack([w * F[:, 0], w * F[:, 1], np.zeros(n)])
        p = np.column_stack([mid[sd][:, 0] + delta, np.zeros(n), zside[sd]])
        for ax, j in zip("xyz", range(3)):
            out[f"{sd}_ground_force_v{ax}"] = f[:, j]
        for ax, j in zip("xyz", range(3)):
            out[f"{sd}_ground_force_p{ax}"] = p[:, j]
        for ax in "xyz":
            out[f"{sd}_ground_torque_{ax}"] = np.zeros(n)
    return out


def _envelope_noise(t, u, lv: dict, rng) -> np.ndarray:
    """Envelopes ``(N, m)`` of simulated raw EMG for excitations ``u`` (N, m) at times ``t`` (see the module notes)."""
    from ..signals.emg import envelope
    from ..signals.filtering import bandpass

    pad = 1.0
    tf = np.arange(t[0] - pad, t[-1] + pad + 0.5 / EMG_RATE, 1.0 / EMG_RATE)
    uf = make_interp_spline(t, u, k=3, axis=0)(np.clip(tf, t[0], t[-1]))
    carrier = bandpass(rng.standard_normal((2,) + uf.shape), rate=EMG_RATE, band=EMG_BAND, order=4, axis=1)
    carrier /= np.mean(np.abs(carrier), axis=1, keepdims=True)       # unit rectified mean
    raw = uf * carrier[0] + lv["excitation_floor"] * carrier[1]
    env = envelope(raw, rate=EMG_RATE, band=None, cutoff=lv["emg_lowpass"])
    return np.column_stack([np.interp(t, tf, env[:, j]) for j in range(u.shape[1])])


def _add_noise(trial: Trial, model, lv: dict, rng) -> Trial:
    new = {}
    meta = dict(trial.meta)
    n = trial.n_frames
    exc = [c for c in trial.names if c.endswith("_excitation")]
    if exc and lv["emg_lowpass"] > 0:
        env = _envelope_noise(np.asarray(trial.time), np.column_stack([trial[c] for c in exc]), lv, rng)
        new.update({c: env[:, j] for j, c in enumerate(exc)})
        meta["emg_lowpass"] = float(lv["emg_lowpass"])
        meta["emg_rate"] = EMG_RATE
    peak_fy = max([np.max(np.abs(trial[c])) for c in trial.names if c.endswith("ground_force_vy")] or [0.0])
    for c in trial.names:
        x = np.array(trial[c], dtype=float)
        if c in model.coordinates:
            prismatic = _is_prismatic(model, c)
            x = x + rng.standard_normal(n) * (lv["translation"] if prismatic else lv["angle"])
        elif c.endswith("_moment"):
            x = x + rng.standard_normal(n) * lv["moment"] * np.max(np.abs(x))
        elif c.endswith("_excitation"):
            if c in new:
                continue
            x = x * (1 + lv["excitation"] * rng.standard_normal(n)) + lv["excitation_floor"] * rng.standard_normal(n)
            x = np.maximum(x, 0.0)
        else:
            g = parse_ground_reaction(c)
            if g is not None and g.quantity == "force":
                x = x + rng.standard_normal(n) * lv["grf"] * peak_fy
            elif g is not None and g.quantity == "point" and g.axis != "z":
                x = x + rng.standard_normal(n) * lv["cop"]
        new[c] = x
    return Trial(trial.time, {c: new[c] for c in trial.names}, meta=meta)


def _is_prismatic(model, coord: str) -> bool:
    pm = model.pin
    j = pm.getJointId(coord)
    return pm.joints[j].shortname().startswith("JointModelP")


def write_compact(trial: Trial, path, *, digits: int = 8) -> Path:
    """Write a trial as CSV with ``digits`` significant digits (small files for ``data/``)."""
    path = Path(path)
    header = ",".join(("time",) + tuple(trial.names))
    table = np.column_stack([trial.time, trial.values])
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt=f"%.{digits}g")
    return path
