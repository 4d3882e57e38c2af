"""Validation of one simulated gait stride on ``gait2d`` against measured walking (thesis Sec. 5.2).

:func:`validate_gait` takes a Result or Trial holding ONE full stride (gait2d coordinate channels in rad:
``hip_r``, ``knee_r``, ``ankle_r``, ... and optionally ``torso_x``; ``<muscle>_activation``; ground
reactions named as in trials, ``r_ground_force_vx``, ``r_ground_force_vy``, ``l_ground_force_vx``,
``l_ground_force_vy`` in N) and returns a :class:`GaitValidation`: the numbers (JSON-ready) and the
curves over 0-100 % of the stride that the figures draw (:mod:`pinmsk.presentation.gait_report`).

References (read from ``../shared/data/real``, ``$PINMSK_SHARED_DATA``; nothing is copied):

* **Winter** (:func:`winter_cycle`): Table A.1 of Winter (2009), *Biomechanics and Motor Control of
  Human Movement*, 4th ed., Appendix A (via BMClab/BMC, CC BY 4.0): raw sagittal markers of one
  subject's right side, scaled uniformly to gait2d (no joint angle changes) and solved by
  :class:`~pinmsk.ik.InverseKinematics` with gait2d's ``winter`` marker set; the stride is right heel
  contact at frame 28 to the next at frame 97 (the events other users of the data give; the
  ``winter-gait-bmc`` SOURCE.md asks for a check against the book, not done here).
* **The measured walk** (:func:`measured_walk_cycle`): ``opensim-moco-walk-emg`` (Rajagopal et al. 2016
  subject, Moco example3DWalking): ``coordinates.sto`` (IK + RRA) mapped onto gait2d by
  :func:`pinmsk.pipeline.opensim_to_gait2d`; ``grf_walk.mot``; the EMG envelopes of
  ``electromyography.sto`` (each scaled to max 1 by Moco; taken as the right leg).  The right stride
  runs from right heel strike (vertical GRF rising through 20 N) at 0.267 s to 1.4115 s, but the
  coordinates start at 0.45 s, so the joint-angle curve of the walk is the mean of the right leg
  (16-100 % of its stride) and the left leg from its own heel strike (0.836 s; 0-84 %), each over
  the phases it covers.  Body weight = the mean total vertical GRF over the left stride (the
  impulse balance of a steady stride; the one stride whose every foot contact is on a plate); speed = the slope of ``pelvis_tx``.

Definitions (the same for the simulation and the references):

* % stride: time from the side's heel strike (vertical GRF of that side rising through
  ``threshold`` N, default 20 N; without GRF channels the stride starts at a right heel strike and
  the left one is half a stride later) divided by the stride time; the stride is treated as periodic
  (a mirrored full cycle), so curves are interpolated periodically.  A stride whose last sample
  repeats the first (every coordinate but ``torso_x`` within 1e-3) is closed: stride time =
  ``time[-1] - time[0]``; otherwise one more median step is added.
* Joint-angle RMS (deg) and Pearson correlation over 0, 1, ..., 99 % (the 100 % point of a periodic
  stride repeats the 0 % one; the figures draw 0-100 %), per joint and side (the references' right leg);
  gait2d conventions (hip + extension, knee + flexion, ankle + plantarflexion; see
  :mod:`pinmsk.io.channel_map`).
* Vertical GRF double hump (:func:`double_hump`): on a 0.1 % grid of the side's stance, the first peak =
  the maximum over the first half of stance, the second = over the second half, the valley = the
  minimum between them; values in % body weight, timings in % stride.
* Stride length = speed x stride time, cadence = 2 steps per stride (steps/min), cost of transport
  (J/kg/m) from the caller or the result's ``cost_of_transport`` (meta or info; never estimated here).
* GRF RMS (% body weight) against the measured walk, per side and component, over 0-99 %.
* Activation vs EMG: Pearson correlation (0-99 %) per gait2d muscle group (:data:`EMG_GROUPS`; EMG columns of
  one group averaged), right muscles on the right stride, left muscles on the left stride.
"""
from __future__ import annotations

import functools
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import TrialError
from .io.shared_data import shared_data_dir
from .trial import Trial

__all__ = ["GaitCycle", "GaitValidation", "validate_gait", "gait_cycle", "read_stride", "winter_cycle",
           "measured_walk_cycle", "double_hump", "heel_strikes", "curve_rms", "curve_correlation",
           "read_table_a1", "scale_to_model", "PUBLISHED", "EMG_GROUPS", "JOINTS", "G"]

G = 9.80665
JOINTS = ("hip", "knee", "ankle")
PERCENT = np.linspace(0.0, 100.0, 101)
FINE = np.linspace(0.0, 100.0, 1001)
THRESHOLD = 20.0            # N: a foot is loaded above this vertical force
CLOSED_TOL = 1e-3           # rad/m: a stride whose last sample repeats its first

#: Winter Table A.1 marker names (x, y columns in cm)
TABLE_A1_MARKERS = ("RIB_CAGE", "RIGHT_HIP", "RIGHT_KNEE", "RIGHT_FIBULA", "RIGHT_ANKLE", "RIGHT_HEEL",
                    "RIGHT_MT5", "RIGHT_TOE")
WINTER_STRIDE = (27, 96)    # 0-based frames: right heel contact (frame 28) .. the next (frame 97)
MEASURED_WALK = "real/opensim-moco-walk-emg"
WINTER_FILE = "real/winter-gait-bmc/WinterTableA1.txt"

#: gait2d muscle group -> the ``electromyography.sto`` columns averaged for it
EMG_GROUPS = {
    "soleus": ("soleus",),
    "gastrocnemius": ("gastrocnemius",),
    "tibialis_anterior": ("tibialis_anterior",),
    "hamstrings": ("medial_hamstrings", "biceps_femoris"),
    "vasti": ("vastus_lateralis", "vastus_medius"),
    "rectus_femoris": ("rectus_femoris",),
    "glutei": ("gluteus_maximus", "gluteus_medius"),
}

#: Published values of healthy adult walking at a natural speed: (low, high) and the source.  The
#: numbers are those commonly quoted from these sources; they were not re-read in the originals here.
PUBLISHED = {
    "cadence_steps_per_min": {
        "range": (94.0, 116.6), "mean": 105.3,
        "source": "Winter DA (1991) The Biomechanics and Motor Control of Human Gait: Normal, Elderly and "
                  "Pathological, 2nd ed., University of Waterloo Press: natural cadence of young adults "
                  "105.3 +/- 11.3 steps/min (range = mean +/- 1 SD)"},
    "stride_length_m": {
        "range": (1.27, 1.55), "mean": 1.41,
        "source": "Winter (1991), same table: natural stride length 1.41 +/- 0.14 m"},
    "speed_m_per_s": {
        "range": (1.1, 1.5), "mean": 1.3,
        "source": "Winter (1991): natural walking speed about 1.2-1.4 m/s (cadence x stride length / 120)"},
    "cost_of_transport_j_per_kg_m": {
        "range": (2.5, 3.6), "mean": 3.0,
        "source": "Waters RL, Mulroy S (1999) The energy expenditure of normal and pathologic gait. Gait "
                  "Posture 9:207-231: gross O2 cost about 0.15 mL O2/kg/m at comfortable speed, i.e. about "
                  "3.0 J/kg/m at 20.1 J/mL O2 (range: +/- ~20 %, the spread across ages; gross, i.e. "
                  "including resting metabolism: a model's muscle-only (net) energy is lower)"},
}


# ---------------------------------------------------------------------------
# small measures

def curve_rms(a, b) -> float:
    """RMS of ``a - b`` over the samples where both are finite."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.sqrt(np.mean((a[ok] - b[ok]) ** 2))) if ok.any() else float("nan")


def curve_correlation(a, b) -> float:
    """Pearson correlation of ``a`` and ``b`` over the samples where both are finite (NaN if one is flat)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.ptp(a[ok]) == 0 or np.ptp(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def heel_strikes(time, fy, *, threshold: float = THRESHOLD) -> np.ndarray:
    """Times where ``fy`` rises through ``threshold`` (linear interpolation between samples)."""
    t, f = np.asarray(time, dtype=float), np.asarray(fy, dtype=float) - threshold
    k = np.flatnonzero((f[:-1] < 0) & (f[1:] >= 0))
    return t[k] - f[k] * (t[k + 1] - t[k]) / (f[k + 1] - f[k])


def _periodic(time, x, start: float, duration: float, percent=PERCENT) -> np.ndarray:
    """``x`` at ``percent`` of a periodic stride starting at ``start`` lasting ``duration``."""
    ph = 100.0 * np.mod(np.asarray(time, dtype=float) - start, duration) / duration
    return np.interp(percent, ph, np.asarray(x, dtype=float), period=100.0)


def _window(time, x, start: float, duration: float, percent=PERCENT) -> np.ndarray:
    """``x`` at ``percent`` of the stride [start, start + duration] of a non-periodic record (NaN outside it)."""
    t = start + np.asarray(percent) / 100.0 * duration
    out = np.interp(t, np.asarray(time, dtype=float), np.asarray(x, dtype=float))
    out[(t < time[0] - 1e-9) | (t > time[-1] + 1e-9)] = np.nan
    return out


def double_hump(percent, fy_bw) -> dict:
    """First and second peak and the valley between them of a vertical GRF over one stance.

    ``percent``: % stride (increasing), ``fy_bw``: the vertical force in % body weight (NaN allowed
    outside the record).  Stance = the longest run above 5 % BW; the first peak is the maximum over its
    first half, the second over its second half, the valley the minimum between the two peaks.
    """
    p, f = np.asarray(percent, dtype=float), np.asarray(fy_bw, dtype=float)
    on = np.nan_to_num(f, nan=0.0) > 5.0
    edges = np.diff(np.concatenate([[0], on.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if starts.size == 0:
        raise TrialError("double_hump: the vertical GRF never exceeds 5 % of body weight (no stance)")
    j = int(np.argmax(ends - starts))
    a, b = starts[j], ends[j]
    mid = (a + b) // 2
    i1 = a + int(np.argmax(f[a:mid]))
    i2 = mid + int(np.argmax(f[mid:b]))
    iv = i1 + int(np.argmin(f[i1:i2 + 1]))
    return {"first_peak_bw_pct": float(f[i1]), "first_peak_at_pct": float(p[i1]),
            "valley_bw_pct": float(f[iv]), "valley_at_pct": float(p[iv]),
            "second_peak_bw_pct": float(f[i2]), "second_peak_at_pct": float(p[i2]),
            "stance_pct": float(p[b - 1] - p[a])}


# ---------------------------------------------------------------------------
# one stride over % stride

@dataclass
class GaitCycle:
    """One stride over 0-100 % (:data:`PERCENT`, 101 points); NaN where a source does not cover a phase.

    ``angles``: ``{"hip_r": deg, ...}`` (gait2d conventions); ``grf``: ``{"r_vy": % BW, ...}`` on the
    same side's stride; ``grf_fine``: the same on a 0.1 % grid (for the double hump); ``muscles``:
    ``{"soleus_r": activation or EMG envelope}``; scalars in SI (s, m/s, m, N).
    """
    label: str
    angles: dict = field(default_factory=dict)
    grf: dict = field(default_factory=dict)
    grf_fine: dict = field(default_factory=dict)
    muscles: dict = field(default_factory=dict)
    stride_time: float = float("nan")
    speed: float = float("nan")
    body_weight: float = float("nan")
    notes: list = field(default_factory=list)

    @property
    def percent(self) -> np.ndarray:
        return PERCENT

    @property
    def stride_length(self) -> float:
        return self.speed * self.stride_time

    @property
    def cadence(self) -> float:
        """Steps per minute (two steps per stride)."""
        return 120.0 / self.stride_time


def _grf_name(trial: Trial, side: str, axis: str) -> str | None:
    for n in (f"{side}_ground_force_v{axis}", f"ground_force_{side}_v{axis}"):
        if n in trial:
            return n
    return None


def _meta_value(trial, key):
    for src in (getattr(trial, "info", None), trial.meta):
        if src is not None and key in src and src[key] is not None:
            return float(src[key])
    return None


def gait_cycle(trial: Trial, *, label: str = "simulation", body_weight: float | None = None,
               speed: float | None = None, threshold: float = THRESHOLD) -> GaitCycle:
    """The :class:`GaitCycle` of a simulated full stride (a Result or Trial; see the module docstring).

    ``body_weight`` (N) defaults to the result's ``body_weight`` (meta or info), else the mean total
    vertical GRF over the stride; ``speed`` (m/s) to the result's ``speed``, else the ``torso_x``
    displacement over the stride.
    """
    if not isinstance(trial, Trial):
        raise TypeError(f"gait_cycle needs a Trial or Result, got {type(trial).__name__}")
    t = np.asarray(trial.time, dtype=float)
    if t.size < 4:
        raise TrialError(f"gait_cycle: {trial.n_frames} frames are too few for a stride")
    missing = [f"{j}_{s}" for j in JOINTS for s in "rl" if f"{j}_{s}" not in trial]
    if missing:
        raise TrialError(f"gait_cycle: the stride has no channel(s) {', '.join(missing)} (gait2d coordinates, rad)")
    coords = [n for n in trial.names if n in {f"{j}_{s}" for j in JOINTS for s in "rl"}
              | {"torso_y", "torso_angle", "mtp_r", "mtp_l"}]
    closed = bool(np.all(np.abs(trial.get(coords)[-1] - trial.get(coords)[0]) < CLOSED_TOL))
    dt = float(np.median(np.diff(t)))
    T = float(t[-1] - t[0]) + (0.0 if closed else dt)
    x, y = (t[:-1], slice(0, -1)) if closed else (t, slice(None))
    notes = [f"stride {'closed (last sample = first)' if closed else 'open (one median step added)'}: "
             f"{T:.4f} s"]
    fy = {s: _grf_name(trial, s, "y") for s in "rl"}
    starts = {}
    for s in "rl":
        hs = heel_strikes(x, np.asarray(trial[fy[s]])[y], threshold=threshold) if fy[s] else np.array([])
        if hs.size == 0 and fy[s] and np.asarray(trial[fy[s]])[0] >= threshold:
            # loaded at the first sample, never rising inside: periodically, the strike is at the wrap
            hs = heel_strikes(np.concatenate([x - T, x]), np.tile(np.asarray(trial[fy[s]])[y], 2),
                              threshold=threshold)
        starts[s] = float(hs[0]) if hs.size else None
    if starts["r"] is None:
        starts["r"] = float(t[0]) if starts["l"] is None else starts["l"] - T / 2
        notes.append("no right heel strike in the GRF: the stride is taken to start at one")
    if starts["l"] is None:
        starts["l"] = starts["r"] + T / 2
        notes.append("no left heel strike in the GRF: taken half a stride after the right one")
    cyc = GaitCycle(label=label, stride_time=T, notes=notes)
    for j in JOINTS:
        for s in "rl":
            cyc.angles[f"{j}_{s}"] = np.degrees(_periodic(x, np.asarray(trial[f"{j}_{s}"])[y], starts[s], T))
    if body_weight is None:
        body_weight = _meta_value(trial, "body_weight")
    if body_weight is None and fy["r"] and fy["l"]:
        body_weight = float(np.mean(np.asarray(trial[fy["r"]])[y] + np.asarray(trial[fy["l"]])[y]))
        notes.append("body weight = mean total vertical GRF over the stride")
    cyc.body_weight = float("nan") if body_weight is None else float(body_weight)
    for s in "rl":
        for a in "xy":
            n = _grf_name(trial, s, a)
            if n:
                v = 100.0 * np.asarray(trial[n])[y] / cyc.body_weight
                cyc.grf[f"{s}_v{a}"] = _periodic(x, v, starts[s], T)
                cyc.grf_fine[f"{s}_v{a}"] = _periodic(x, v, starts[s], T, FINE)
    for n in trial.names:
        if n.endswith("_activation") and n[-12] in "rl" and n[-13] == "_":
            m = n[: -len("_activation")]
            cyc.muscles[m] = _periodic(x, np.asarray(trial[n])[y], starts[m[-1]], T)
    if speed is None:
        speed = _meta_value(trial, "speed")
    if speed is None and "torso_x" in trial:
        tx = np.asarray(trial["torso_x"])
        speed = float((tx[-1] - tx[0]) / (t[-1] - t[0])) if closed else float(np.polyfit(t, tx, 1)[0])
    cyc.speed = float("nan") if speed is None else float(speed)
    return cyc


# ---------------------------------------------------------------------------
# references

def _data(folder, relative: str) -> Path | None:
    if folder is not None:
        return Path(folder)
    d = shared_data_dir()
    return None if d is None else Path(d) / relative


def read_table_a1(path) -> Trial:
    """Winter's Table A.1 as a marker Trial (m); the 3-decimal time column is rebuilt from its end time."""
    path = Path(path)
    d = np.loadtxt(path, skiprows=2)
    if d.ndim != 2 or d.shape[1] != 2 + 2 * len(TABLE_A1_MARKERS):
        raise TrialError(f"{path}: expected {2 + 2 * len(TABLE_A1_MARKERS)} columns, got "
                         f"{d.shape[1] if d.ndim == 2 else d.size}")
    n = d.shape[0]
    t = np.arange(n) * (d[-1, 1] - d[0, 1]) / (n - 1)
    ch = {}
    for j, m in enumerate(TABLE_A1_MARKERS):
        ch[f"{m}_x"] = d[:, 2 + 2 * j] / 100.0
        ch[f"{m}_y"] = d[:, 3 + 2 * j] / 100.0
    return Trial(t, ch, meta={"source": str(path), "markers": TABLE_A1_MARKERS, "units": "cm"})


def scale_to_model(mk: Trial, mset) -> tuple[Trial, float]:
    """Table A.1 markers scaled uniformly to gait2d's trochanter-knee-malleolus length; (trial, factor)."""
    def dist(a, b):
        return np.hypot(mk[f"{a}_x"] - mk[f"{b}_x"], mk[f"{a}_y"] - mk[f"{b}_y"])

    measured = np.median(dist("RIGHT_HIP", "RIGHT_KNEE") + dist("RIGHT_KNEE", "RIGHT_ANKLE"))
    p = {m.name: np.asarray(m.position) for m in mset.markers}
    # hip and knee markers on the thigh, ankle marker on the shank (0.41552 m below the knee centre)
    model = np.linalg.norm(p["RIGHT_HIP"] - p["RIGHT_KNEE"]) + np.linalg.norm(
        p["RIGHT_ANKLE"] - (p["RIGHT_KNEE"] - np.array([0.0, -0.41552, 0.0])))
    s = float(model / measured)
    d = mk.to_dict()
    d.pop("time")
    return Trial(mk.time, {k: s * v for k, v in d.items()}, meta={**dict(mk.meta), "scale": s}), s


@functools.lru_cache(maxsize=4)
def _winter_cached(path: str) -> GaitCycle:
    from .ik import InverseKinematics
    from .markers import load_marker_set
    from .model import load_model

    model = load_model("gait2d")
    mset = load_marker_set("gait2d").subset("winter")
    raw = read_table_a1(path)
    mk, scale = scale_to_model(raw, mset)
    kin = InverseKinematics(markers=mset, axes="xy", q0={"torso_y": 1.0}).fit(model, mk).result_
    a, b = WINTER_STRIDE
    t = np.asarray(kin.time)
    T = float(t[b] - t[a])
    cyc = GaitCycle(label="Winter (2009) Table A.1", stride_time=T,
                    notes=[f"IK on Table A.1 (markers scaled x{scale:.3f}); stride = frames {a + 1}-{b + 1} "
                           "(right heel contacts as given by other users of the data; not checked against the book)"])
    for j in JOINTS:
        cyc.angles[f"{j}_r"] = np.degrees(_window(t, kin[f"{j}_r"], t[a], T))
    # the subject's own speed: the unscaled hip marker's forward slope over the stride
    cyc.speed = float(np.polyfit(raw.time[a:b + 1], raw["RIGHT_HIP_x"][a:b + 1], 1)[0])
    return cyc


def winter_cycle(path=None) -> GaitCycle | None:
    """Winter's stride (right joint angles, stride time, speed), or None without the shared data."""
    p = _data(path, WINTER_FILE)
    if p is None or not p.exists():
        return None
    return _winter_cached(str(p.resolve()))


def _read_moco(path: Path) -> Trial:
    from .io.tables import read_trial
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")            # the Moco files' headers are sloppy (nColumns)
        return read_trial(path, strict=False)


@functools.lru_cache(maxsize=4)
def _measured_cached(folder: str) -> GaitCycle:
    from .model import load_model
    from .pipeline import opensim_to_gait2d

    folder = Path(folder)
    model = load_model("gait2d")
    coords = _read_moco(folder / "coordinates.sto")
    grf = _read_moco(folder / "grf_walk.mot")
    emg = _read_moco(folder / "electromyography.sto")
    kin = opensim_to_gait2d(coords, model)
    tg = np.asarray(grf.time)
    hs = {s: heel_strikes(tg, grf[f"ground_force_{s}_vy"]) for s in "rl"}
    if hs["r"].size < 2 or hs["l"].size < 1:
        raise TrialError(f"{folder / 'grf_walk.mot'}: expected two right and one left heel strike, "
                         f"got {hs['r'].size} and {hs['l'].size}")
    start = {"r": float(hs["r"][0]), "l": float(hs["l"][0])}
    T = float(hs["r"][1] - hs["r"][0])
    # the left stride is the one whose every foot contact is on a plate (the left stance before 0.836 s
    # was not), so its mean total vertical force is the body weight (impulse balance of a steady stride)
    win = (tg >= start["l"]) & (tg <= start["l"] + T)
    if start["l"] + T > tg[-1]:
        raise TrialError(f"{folder / 'grf_walk.mot'}: the left stride ends after the record ({tg[-1]:.3f} s)")
    bw = float(np.mean(np.asarray(grf["ground_force_r_vy"])[win] + np.asarray(grf["ground_force_l_vy"])[win]))
    tk = np.asarray(kin.time)
    pelvis = next(n for n in coords.names if n.endswith("pelvis_tx/value") or n == "pelvis_tx")
    cyc = GaitCycle(label="measured walk (Rajagopal 2016 subject)", stride_time=T, body_weight=bw,
                    speed=float(np.polyfit(coords.time, coords[pelvis], 1)[0]),
                    notes=[f"right stride {start['r']:.4f}-{start['r'] + T:.4f} s; angles = mean of the right leg "
                           f"and the left leg (from {start['l']:.4f} s) over the phases each covers "
                           f"(coordinates {tk[0]:.3f}-{tk[-1]:.3f} s)",
                           f"body weight = mean total vertical GRF over the left stride = {bw:.1f} N "
                           f"({bw / G:.1f} kg)", "EMG envelopes taken as the right leg (not stated in the data)"])
    for j in JOINTS:
        both = np.vstack([np.degrees(_window(tk, kin[f"{j}_{s}"], start[s], T)) for s in "rl"])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")        # all-NaN phases stay NaN
            cyc.angles[f"{j}_r"] = np.nanmean(both, axis=0)
    for s in "rl":
        for a in "xy":
            v = 100.0 * np.asarray(grf[f"ground_force_{s}_v{a}"]) / bw
            cyc.grf[f"{s}_v{a}"] = _window(tg, v, start[s], T)
            cyc.grf_fine[f"{s}_v{a}"] = _window(tg, v, start[s], T, FINE)
    te = np.asarray(emg.time)
    for g, cols in EMG_GROUPS.items():
        e = np.mean([np.asarray(emg[c]) for c in cols], axis=0)
        cyc.muscles[f"{g}_r"] = _window(te, e, start["r"], T)
    return cyc


def measured_walk_cycle(folder=None) -> GaitCycle | None:
    """The measured walk's stride (angles, GRF in % BW, EMG envelopes), or None without the shared data."""
    p = _data(folder, MEASURED_WALK)
    if p is None or not all((p / f).exists() for f in ("coordinates.sto", "grf_walk.mot", "electromyography.sto")):
        return None
    return _measured_cached(str(p.resolve()))


# ---------------------------------------------------------------------------
# the comparison

def compare_angles(sim: GaitCycle, ref: GaitCycle) -> dict:
    """``{joint_side: {"rms_deg", "correlation"}}`` of ``sim`` against ``ref``'s curve of the same joint."""
    out = {}
    for name, a in sim.angles.items():
        r = ref.angles.get(name) if name in ref.angles else ref.angles.get(name[:-1] + "r")
        if r is None:
            continue
        out[name] = {"rms_deg": curve_rms(a[:-1], r[:-1]), "correlation": curve_correlation(a[:-1], r[:-1])}
    return out


def _band(value, ref) -> dict:
    lo, hi = ref["range"]
    ok = None if value is None or not np.isfinite(value) else bool(lo <= value <= hi)
    return {"value": value, "published_range": [lo, hi], "published_mean": ref["mean"], "within": ok,
            "source": ref["source"]}


def _finite(x):
    """``x`` with every non-finite float replaced by None and numpy scalars made plain (strict JSON)."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


#: keys of the ``OUT.sto.json`` beside a ``pinmsk optimize`` stride that the validation reads
SIDECAR_KEYS = ("speed", "stride_length", "cost_of_transport", "body_weight")


def read_stride(path) -> Trial:
    """A stride written by ``pinmsk optimize`` (``OUT.sto``), with ``OUT.sto.json``'s speed, stride
    length, cost of transport and body weight (when present) in its meta."""
    from .io.tables import read_trial

    path = Path(path)
    tr = read_trial(path)
    side = path.with_name(path.name + ".json")
    if not side.exists():
        return tr
    try:
        info = json.loads(side.read_text())
    except json.JSONDecodeError as exc:
        raise TrialError(f"{side}: line {exc.lineno}, column {exc.colno}: not JSON ({exc.msg})") from None
    if not isinstance(info, dict):
        raise TrialError(f"{side}: expected a JSON object, got {type(info).__name__}")
    extra = {k: info[k] for k in SIDECAR_KEYS if info.get(k) is not None}
    return tr.with_meta(**extra, sidecar=str(side))


@dataclass
class GaitValidation:
    """The numbers (``numbers``, JSON-ready) and the cycles compared (``simulation``, ``references``)."""
    numbers: dict
    simulation: GaitCycle
    references: dict

    def to_json(self, path=None) -> str:
        """The numbers as JSON (NaN -> null), also written to ``path`` (atomically) if given."""
        text = json.dumps(_finite(self.numbers), indent=2, allow_nan=False)
        if path is not None:
            from .io.output_files import atomic_write
            atomic_write(path, lambda fh: fh.write(text), parents=True)
        return text

    def write_report(self, path, *, figures_dir=None, title: str | None = None) -> Path:
        """The HTML report (:func:`pinmsk.presentation.gait_report.write_gait_report`)."""
        from .presentation.gait_report import write_gait_report
        return write_gait_report(self, path, figures_dir=figures_dir, title=title)


def validate_gait(result: Trial, *, winter: GaitCycle | None | bool = True,
                  measured: GaitCycle | None | bool = True, cost_of_transport: float | None = None,
                  body_weight: float | None = None, speed: float | None = None,
                  label: str = "simulation") -> GaitValidation:
    """Validate one simulated full stride on gait2d (see the module docstring for every definition).

    ``result``: a Result or Trial, a path of a ``pinmsk optimize`` stride (:func:`read_stride`), or a
    :class:`GaitCycle`.  ``winter`` / ``measured``: True = read from the shared data (skipped, with a
    note, when absent), a :class:`GaitCycle` to use instead, or False/None to leave that reference out.
    """
    if isinstance(result, (str, Path)):
        result = read_stride(result)
    sim = result if isinstance(result, GaitCycle) else gait_cycle(result, label=label,
                                                                   body_weight=body_weight, speed=speed)
    refs = {}
    notes = list(sim.notes)
    for key, given, loader in (("winter", winter, winter_cycle), ("measured_walk", measured, measured_walk_cycle)):
        cyc = loader() if given is True else (given or None)
        if cyc is None and given is True:
            notes.append(f"reference {key}: shared data absent, not compared")
        if cyc is not None:
            refs[key] = cyc
    if cost_of_transport is None and isinstance(result, Trial):
        cost_of_transport = _meta_value(result, "cost_of_transport")
    nums = {"label": sim.label, "stride_time_s": sim.stride_time, "speed_m_per_s": sim.speed,
            "body_weight_n": sim.body_weight, "notes": notes}
    nums["joint_angles"] = {k: compare_angles(sim, c) for k, c in refs.items()}
    nums["grf"] = {}
    for side in "rl":
        if f"{side}_vy" in sim.grf_fine:
            nums["grf"].setdefault("simulation", {})[side] = double_hump(FINE, sim.grf_fine[f"{side}_vy"])
    if "measured_walk" in refs:
        m = refs["measured_walk"]
        nums["grf"]["measured_walk"] = {s: double_hump(FINE, m.grf_fine[f"{s}_vy"]) for s in "rl"}
        nums["grf"]["rms_bw_pct"] = {f"{s}_v{a}": curve_rms(sim.grf[f"{s}_v{a}"][:-1], m.grf[f"{s}_v{a}"][:-1])
                                     for s in "rl" for a in "xy" if f"{s}_v{a}" in sim.grf}
        nums["emg"] = {}
        for g in EMG_GROUPS:
            e = m.muscles[f"{g}_r"]
            row = {f"correlation_{s}": curve_correlation(sim.muscles[f"{g}_{s}"][:-1], e[:-1])
                   for s in "rl" if f"{g}_{s}" in sim.muscles}
            if row:
                nums["emg"][g] = row
    nums["spatiotemporal"] = {
        "cadence_steps_per_min": _band(sim.cadence, PUBLISHED["cadence_steps_per_min"]),
        "stride_length_m": _band(sim.stride_length if np.isfinite(sim.speed) else None,
                                 PUBLISHED["stride_length_m"]),
        "speed_m_per_s": _band(sim.speed if np.isfinite(sim.speed) else None, PUBLISHED["speed_m_per_s"]),
        "cost_of_transport_j_per_kg_m": _band(cost_of_transport, PUBLISHED["cost_of_transport_j_per_kg_m"]),
    }
    nums["references"] = {k: {"label": c.label, "stride_time_s": c.stride_time, "cadence_steps_per_min": c.cadence,
                              "speed_m_per_s": c.speed, "stride_length_m": c.stride_length,
                              "body_weight_n": c.body_weight, "notes": c.notes} for k, c in refs.items()}
    return GaitValidation(numbers=nums, simulation=sim, references=refs)


def measured_walk_as_stride(folder=None, *, rate: float = 100.0) -> Trial | None:
    """The measured walk's stride rebuilt as a simulation-like full stride (an open stride sampled at
    ``rate``): right angles = the walk's angle curves, left = the same half a stride later, GRF = each
    side's measured curve (left from 50 %), ``torso_x`` = speed x time; None without the shared data.
    For checks (the walk validated against itself) and demos, not a measurement of the left leg.
    """
    cyc = measured_walk_cycle(folder)
    if cyc is None:
        return None
    T = cyc.stride_time
    n = int(round(T * rate))
    t = np.arange(n) * T / n
    pct = 100.0 * t / T
    left = np.mod(pct - 50.0, 100.0)
    ch = {}
    for j in JOINTS:
        ch[f"{j}_r"] = np.radians(np.interp(pct, PERCENT, cyc.angles[f"{j}_r"]))
        ch[f"{j}_l"] = np.radians(np.interp(left, PERCENT, cyc.angles[f"{j}_r"]))
    for s, ph in (("r", pct), ("l", left)):
        for a in "xy":
            ch[f"{s}_ground_force_v{a}"] = np.interp(ph, FINE, cyc.grf_fine[f"{s}_v{a}"]) * cyc.body_weight / 100.0
    ch["torso_x"] = cyc.speed * t
    return Trial(t, ch, meta={"source": "measured walk (stride rebuilt)", "body_weight": cyc.body_weight})
