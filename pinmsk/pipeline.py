"""Batch processing: IK -> ID -> SO -> report over many trials from one config file.

``pinmsk batch CONFIG`` calls :func:`batch_cli`.  The config is TOML::

    [batch]
    model = "gait2d"            # built-in name or a sidecar path
    out = "results"             # relative to the config file
    jobs = 2                    # local worker processes (default: all cores)

    [defaults]                  # any trial key, applied to every trial
    cutoff = 6.0                # Hz, low-pass of the coordinates and the GRF (the default; 0 = off)
    so = { mode = "activation", exponent = 2, reserves = true }

    [[trials]]
    name = "csu_subject7"
    kind = "csu"                # CSU leg2d text: markers + one force plate (right foot)
    path = "../shared/data/real/csu-treadmill-leg2d/rawdata.txt"
    markers = "csu"             # set in urdf/markers_gait2d.toml (or a path to a marker TOML)
    body_mass = 67.2

    [[trials]]
    name = "rajagopal_walk"
    kind = "opensim"            # OpenSim coordinates mapped onto gait2d, GRF .mot
    coordinates = ".../coordinates.sto"
    grf = ".../grf_walk.mot"
    trc = ".../markers_walk.trc"          # optional: ankle markers to transfer the COP
    cop_reference = { r = "R.Ankle", l = "L.Ankle" }

    [[trials]]
    name = "lab_trial"
    kind = "trc"                # TRC markers (+ optional GRF .mot), IK with a marker set
    trc = "walk.trc"
    markers = "csu"
    marker_map = { RSHO = "R.Shoulder" }  # model marker -> measured name
    grf = "walk_grf.mot"

Each trial is processed by :func:`run_trial` (a plain top-level function of
picklable arguments, so any ``concurrent.futures``-style executor can run it):
one folder ``<out>/<name>/`` with ``kinematics.sto``, ``inverse_dynamics.sto``,
``residuals.sto``, ``activations.sto`` (if the model has muscles), ``summary.json`` and
``moments.png`` / ``residuals.png`` (``plots = false`` in a trial or ``[defaults]`` skips them)
and last ``done.json``; :func:`batch` writes ``<out>/summary.csv`` (one row per trial) and
``<out>/report.html`` (:mod:`pinmsk.presentation.batch_report`).
A rerun skips the trials whose ``done.json`` matches :func:`trial_key` (options, model, input
file contents); ``force=True`` reruns them; ``shard=(i, n)`` runs every n-th trial
(:func:`shard_indices`), for job arrays.
OpenSim ``.sto``/``.mot`` inputs are read leniently (``strict=False``); the repairs made
are listed under ``info.read_repairs`` in ``summary.json``.

Parallelism: local trials go to a :class:`concurrent.futures.ProcessPoolExecutor`
with ``jobs`` workers and a progress bar (:class:`pinmsk.presentation.progress.Progress`).  With
``scheduler="tcp://host:8786"`` the same function is submitted through
``distributed.Client(scheduler).get_executor()`` (the Dask ``concurrent.futures``
interface): ``pip install distributed`` on the client and the workers, and pinmsk
plus the data paths must be visible to the workers.  Dask is not a dependency.
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib
import csv
import hashlib
import json
import os
import shutil
import tempfile
import time as _time
import traceback
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .contact.identify import ContactFit, load_contact_model, read_contact_trial, read_csu_foot2d
from .dynamics import inverse_dynamics
from .errors import PinmskError, TrialError
from .fitting import Result
from .grf import external_forces, grf_channels, torso_residuals, transfer_cop
from .ik import InverseKinematics
from .io.channel_map import RAJAGOPAL_HIP_OFFSET, apply_channel_map, opensim_gait2d_map
from .io.output_files import atomic_write, output_folder, write_json
from .io.tables import read_trial, write_trial
from .io.toml_files import read_toml
from .io.trc import read_trc
from .kinematics import DEFAULT_CUTOFF, cutoff_value, trial_coordinates
from .markers import load_marker_set
from .model import load_model
from .presentation import plots
from .presentation.plots import contact_fit_figures
from .presentation.progress import Progress
from .solvers.ocp.tasks import build_from_task, load_task
from .solvers.static import StaticOptimization
from .trial import Trial, moment_channel

__all__ = ["opensim_to_gait2d", "frame_positions", "transferred_cops", "run_trial", "batch",
           "batch_cli", "trial_key", "done_row", "parse_shard", "shard_indices", "DONE", "load_config",
           "RAJAGOPAL_HIP_OFFSET", "KINDS", "contact_fit_task", "optimize_task"]

KINDS = ("csu", "opensim", "trc")


# ---------------------------------------------------------------------------
# OpenSim coordinates -> gait2d
# ---------------------------------------------------------------------------

def opensim_to_gait2d(coords: Trial, model, *, hip_offset=RAJAGOPAL_HIP_OFFSET,
                      knee_sign: str | int = "auto") -> Trial:
    """gait2d coordinates from an OpenSim full-body model's coordinates (sagittal plane).

    The built-in column map :func:`pinmsk.io.channel_map.opensim_gait2d_map` (signs, the
    ``knee_sign="auto"`` rule and the hip placement are documented in
    :mod:`pinmsk.io.channel_map`) applied to ``coords``, keeping only the model's coordinates
    in ``model.coordinate_order``.  ``hip_offset``: the OpenSim hip centre in the pelvis
    frame (default the unscaled Rajagopal model's); ``knee_sign``: ``"auto"``, ``+1``
    (Rajagopal, + = flexion) or ``-1`` (gait2392, Gait10dof18musc).
    Out-of-plane coordinates (list, rotation, adduction, pelvis_tz, arms) are dropped.
    """
    cmap = opensim_gait2d_map(knee_sign=knee_sign, hip_offset=hip_offset)
    kin = apply_channel_map(coords, cmap, model=model)
    return Trial(coords.time, {c: kin[c] for c in model.coordinate_order},
                 meta={"source": coords.meta.get("source"), "mapping": "opensim_to_gait2d",
                       "hip_offset": tuple(hip_offset), "map_notes": kin.meta["channel_map"]["notes"]})


def frame_positions(model, q: np.ndarray, frames: Sequence[str]) -> dict:
    """World positions ``{frame: (N, 3)}`` of model frames over ``q`` ((N, nq), Pinocchio order)."""
    import pinocchio as pin

    pm = model.pin
    pd = pm.createData()
    ids = [model.frame_id(f) for f in frames]
    out = {f: np.empty((q.shape[0], 3)) for f in frames}
    for k in range(q.shape[0]):
        pin.forwardKinematics(pm, pd, q[k])
        for f, fid in zip(frames, ids):
            out[f][k] = pin.updateFramePlacement(pm, pd, fid).translation
    return out


def transferred_cops(model, kin: Trial, grf: Trial, markers: Trial, reference: Mapping[str, str], *,
                     model_frames: Mapping[str, str] | None = None) -> dict:
    """Per side, the COP moved from the subject's reference marker to the model's ankle.

    ``reference`` maps a side to a measured marker (e.g. ``{"r": "R.Ankle"}``); the marker
    trial is interpolated (cubic) onto ``kin.time``; ``model_frames`` maps a side to the model
    frame standing for that marker (default ``foot_<side>``, the ankle joint centre).
    See :func:`pinmsk.grf.transfer_cop`.
    """
    q = kin.get(model.coordinates)
    frames = {s: (model_frames or {}).get(s, f"foot_{s}") for s in reference}
    pos = frame_positions(model, q, list(frames.values()))
    mk = markers.resample(kin.time, method="cubic")
    groups = grf_channels(grf)
    out = {}
    for s, mname in reference.items():
        ch = groups.get(s)
        if ch is None:
            raise TrialError(f"the GRF trial has no side {s!r} (sides: {sorted(map(str, groups))})")
        meas = np.column_stack([mk[f"{mname}_{a}"] for a in "xyz"])
        P = np.column_stack([grf[ch[("point", a)]] for a in "xyz"])
        out[s] = transfer_cop(P, meas, pos[frames[s]])
    return out


# ---------------------------------------------------------------------------
# one trial
# ---------------------------------------------------------------------------

def _path(base: Path, p) -> Path:
    p = Path(os.path.expandvars(str(p))).expanduser()
    return p if p.is_absolute() else (base / p)


def _load_model(spec):
    return load_model(spec)


def _kinematics(model, spec: dict, base: Path):
    """(kinematics Trial, GRF Trial or None, info dict) for one trial spec."""
    kind = spec.get("kind")
    info: dict = {}
    ext = []
    if kind == "csu":
        raw = read_csu_foot2d(_path(base, spec["path"]), body_mass=spec.get("body_mass"),
                       belt_height=float(spec.get("belt_height", 0.0)))
        mset = load_marker_set(spec.get("marker_file", "gait2d")).subset(spec.get("markers", "csu"))
        ik = InverseKinematics(markers=mset, axes="xy", q0={"torso_y": 1.0}).fit(model, raw)
        kin = ik.result_
        info["ik_marker_rms_mm"] = {k: 1000 * v for k, v in ik.marker_rms_.items()}
        info["ik_mean_iterations"] = float(ik.iterations_.mean())
        side = spec.get("side", "r")
        ext = external_forces(model, raw, frames={None: f"foot_{side}"}, planar=True,
                              min_force=float(spec.get("min_force", 20.0)))
        info["body_mass"] = spec.get("body_mass")
    elif kind == "opensim":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            coords = read_trial(_path(base, spec["coordinates"]), strict=False)
            grf = read_trial(_path(base, spec["grf"]), strict=False)
        info["read_repairs"] = [*coords.meta["read_notes"], *grf.meta["read_notes"]]
        kin = opensim_to_gait2d(coords, model, hip_offset=tuple(spec.get("hip_offset", RAJAGOPAL_HIP_OFFSET)))
        if "t0" in spec or "t1" in spec:
            kin = kin.slice_time(spec.get("t0"), spec.get("t1"))
        grf = grf.resample(kin.time, method="linear", antialias=True)
        cops = None
        if spec.get("trc"):
            mk = read_trc(_path(base, spec["trc"]), warn=False)
            cops = transferred_cops(model, kin, grf, mk, spec.get("cop_reference", {"r": "R.Ankle", "l": "L.Ankle"}))
        ext = external_forces(model, grf, planar=True, cop=cops, min_force=float(spec.get("min_force", 20.0)))
        fy = sum(np.asarray(grf[n]) for n in grf.names if n.endswith("_vy") or n == "ground_force_vy")
        info["body_mass"] = spec.get("body_mass", float(np.mean(fy) / 9.81))
        info["body_mass_source"] = "config" if "body_mass" in spec else "mean vertical GRF / g"
    elif kind == "trc":
        mk = read_trc(_path(base, spec["trc"]), max_gap=int(spec.get("max_gap", 10)), warn=False)
        mset = load_marker_set(spec.get("marker_file", "gait2d")).subset(spec.get("markers", "csu"))
        if spec.get("marker_map"):
            mset = mset.renamed(dict(spec["marker_map"]))
        ik = InverseKinematics(markers=mset, axes=spec.get("axes", "xy"), q0={"torso_y": 1.0}).fit(model, mk)
        kin = ik.result_
        info["ik_marker_rms_mm"] = {k: 1000 * v for k, v in ik.marker_rms_.items()}
        if spec.get("grf"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                grf = read_trial(_path(base, spec["grf"]), strict=False)
            info["read_repairs"] = list(grf.meta["read_notes"])
            grf = grf.resample(kin.time, method="linear", antialias=True)
            ext = external_forces(model, grf, planar=True)
        info["body_mass"] = spec.get("body_mass")
    else:
        raise TrialError(f"trial {spec.get('name')!r}: kind must be one of {', '.join(KINDS)}, got {kind!r}")
    return kin, ext, info


def run_trial(spec: dict, *, model="gait2d", out_dir=None, base_dir=".", key: str | None = None) -> dict:
    """IK (or coordinate mapping) -> ID -> SO for one trial spec; writes ``out_dir`` if given.

    Returns a summary row (JSON-serialisable).  Never raises on a bad trial: the row gets
    ``status = "failed: <message>"`` instead, so one bad file does not stop a batch.
    The last file written in ``out_dir`` is ``done.json`` (:data:`DONE`: ``key``, see
    :func:`trial_key`, the row and the files), inside the folder that is renamed into
    place whole, so a folder with a matching ``done.json`` is a complete trial.
    """
    t0 = _time.perf_counter()
    name = spec.get("name", "trial")
    row: dict = {"name": name, "kind": spec.get("kind")}
    try:
        m = _load_model(model) if not hasattr(model, "pin") else model
        base = Path(base_dir)
        kin, ext, info = _kinematics(m, spec, base)
        t1 = _time.perf_counter()
        # inverse_dynamics low-passes the GRF wrenches like the kinematics (pinmsk.kinematics)
        cutoff = cutoff_value(spec.get("cutoff", DEFAULT_CUTOFF))
        idt = inverse_dynamics(m, kin, cutoff=cutoff, external=ext)
        row["lowpass_cutoff_hz"] = cutoff or 0.0
        row["ground_reaction"] = ", ".join(f"{e.frame}" for e in ext) or "none"
        t2 = _time.perf_counter()
        bm = info.get("body_mass")
        res, rsum = torso_residuals(m, idt, body_mass=bm)
        row.update({"frames": kin.n_frames, "duration_s": float(kin.time[-1] - kin.time[0]),
                    "body_mass_kg": bm})
        for k, v in info.items():
            if k.startswith("ik_") and isinstance(v, dict):
                row["ik_rms_mm_max"] = max(v.values())
        norm = bm if bm else 1.0
        for c in trial_coordinates(m):          # OpenSim's coordinates of a model with dependent joints
            if c.startswith(("hip", "knee", "ankle")):
                row[f"{c}_peak_abs_nm_per_kg" if bm else f"{c}_peak_abs_nm"] = float(
                    np.max(np.abs(idt[moment_channel(c)])) / norm)
        for c, s in rsum.items():                   # the unit in the name: N (translations) or N m
            row[f"{c}_residual_rms_{'nm' if s['unit'] == 'N*m' else 'n'}"] = s["rms"]
        act = None
        if m.n_muscles and spec.get("so", True) is not False:
            opts = dict(spec.get("so") or {}) if isinstance(spec.get("so"), dict) else {}
            opts.setdefault("mode", "activation")
            opts.setdefault("reserves", True)
            so = StaticOptimization(**opts).fit(m, kin, moments=idt, cutoff=cutoff)
            act = so.result_
            row["so_max_activation"] = float(np.max(so.activations_))
            row["so_reserve_frames"] = int(np.sum(so.status_ == 2))
        t3 = _time.perf_counter()
        row.update({"time_kinematics_s": t1 - t0, "time_id_s": t2 - t1, "time_so_s": t3 - t2,
                    "status": "ok"})
        if out_dir is not None:
            with _trial_folder(out_dir) as d:
                write_trial(kin, d / "kinematics.sto")
                write_trial(idt, d / "inverse_dynamics.sto")
                write_trial(res, d / "residuals.sto")
                if act is not None:
                    write_trial(act, d / "activations.sto")
                if spec.get("plots", True):
                    row["figures"] = _figures(m, d, idt, res)
                write_json(d / "summary.json", {"row": row, "info": info, "residuals": rsum}, default=str)
                row["time_total_s"] = _time.perf_counter() - t0
                files = sorted(p.name for p in d.iterdir())
                write_json(d / DONE, {"key": key, "row": row, "files": files}, default=str)
    except PinmskError as exc:
        row["status"] = f"failed: {exc}"
    except Exception as exc:  # noqa: BLE001 - a batch reports, it does not stop
        row["status"] = f"failed: {type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=5)
    row.setdefault("time_total_s", _time.perf_counter() - t0)    # (set before done.json when written)
    return row


_PARTIAL = ".partial-"

#: The marker file of a complete trial folder (see :func:`run_trial` and :func:`done_row`).
DONE = "done.json"

#: Trial keys whose string values may name input files (hashed by :func:`trial_key`).
_INPUT_KEYS = ("path", "coordinates", "grf", "trc", "markers", "marker_file")


def trial_key(spec: Mapping, *, model="gait2d", base_dir=".") -> str:
    """SHA-256 of what a trial's results depend on: its options, the model and its input files.

    The options are the trial spec (``[defaults]`` merged in) as canonical JSON, with the
    model (a name, or a sidecar path's content) and pinmsk's version; each input file
    (the string values of :data:`_INPUT_KEYS` that name an existing file, and the model
    file) enters by its content, so an edited or replaced file changes the key and a
    moved-but-identical one does not.
    """
    from . import __version__
    h = hashlib.sha256()
    model_name = getattr(model, "name", None) if hasattr(model, "pin") else str(model)
    h.update(json.dumps({"spec": spec, "model": model_name, "pinmsk": __version__},
                        sort_keys=True, default=str).encode())
    base = Path(base_dir)
    files = [(k, spec[k]) for k in _INPUT_KEYS if isinstance(spec.get(k), str)]
    if isinstance(model, (str, Path)):
        files.append(("model", str(model)))
    for k, v in files:
        p = _path(base, v)
        if p.is_file():
            h.update(f"\0{k}\0".encode())
            with open(p, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    h.update(chunk)
    return h.hexdigest()


def done_row(out_dir, key: str) -> dict | None:
    """The stored row of the trial folder ``out_dir`` if it is complete for ``key``, else None.

    Complete: its :data:`DONE` marker exists, parses, holds ``key`` and every file it lists
    is still there.
    """
    marker = Path(out_dir) / DONE
    try:
        done = json.loads(marker.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(done, dict) or done.get("key") != key or not isinstance(done.get("row"), dict):
        return None
    if not all((Path(out_dir) / f).is_file() for f in done.get("files", [])):
        return None
    return done["row"]


def parse_shard(text) -> tuple[int, int]:
    """``"i/n"`` -> ``(i, n)`` with ``1 <= i <= n`` (a Slurm array's ``$SLURM_ARRAY_TASK_ID/n``)."""
    try:
        i, n = (int(x) for x in str(text).split("/"))
    except ValueError:
        raise TrialError(f"--shard {text!r}: expected I/N, two whole numbers such as 1/4") from None
    if n < 1 or not 1 <= i <= n:
        raise TrialError(f"--shard {text!r}: I must be between 1 and N (N >= 1), e.g. 1/{max(n, 1)} "
                         f"to {max(n, 1)}/{max(n, 1)}")
    return i, n


def shard_indices(count: int, shard) -> list[int]:
    """The trial indices (0-based, config order) shard ``(i, n)`` runs: those with ``k % n == i - 1``."""
    if shard is None:
        return list(range(count))
    i, n = parse_shard(shard) if isinstance(shard, str) else parse_shard(f"{shard[0]}/{shard[1]}")
    return [k for k in range(count) if k % n == i - 1]


@contextlib.contextmanager
def _trial_folder(out_dir):
    """A temporary folder next to ``out_dir`` that becomes ``out_dir`` when the block completes.

    So a trial folder is complete or absent: on any exception (``KeyboardInterrupt``
    included) the temporary folder is removed; an existing ``out_dir`` is replaced
    only once the new one is complete.
    """
    target = Path(out_dir)
    output_folder(target.parent)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}{_PARTIAL}", dir=target.parent))
    try:
        umask = os.umask(0)
        os.umask(umask)
        tmp.chmod(0o777 & ~umask)          # mkdtemp makes it private; results are ordinary folders
        yield tmp
        old = None
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=target.parent))
            os.replace(target, old / target.name)
        os.replace(tmp, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _remove_partial_folders(out: Path, names) -> None:
    """Remove what interrupted trials left (their temporary folders) in ``out``."""
    for name in names:
        for d in out.glob(f".{name}{_PARTIAL}*"):
            shutil.rmtree(d, ignore_errors=True)


def _figures(model, d: Path, idt: Trial, res: Trial) -> int:
    """Per-trial PNGs (joint moments, torso residuals) via :mod:`pinmsk.presentation.plots`; returns how many."""
    joints = [moment_channel(c) for c in trial_coordinates(model) if c.startswith(("hip", "knee", "ankle"))]
    n = len(plots.save_channels(idt, joints, d, stem="moments", ylabel="N m"))
    n += len(plots.save_channels(res, list(res.names), d, stem="residuals"))
    return n


# ---------------------------------------------------------------------------
# many trials
# ---------------------------------------------------------------------------

def load_config(path) -> dict:
    """Parse and check a batch config (see the module docstring)."""
    path = Path(path)
    cfg = read_toml(path, what="batch config", error=TrialError)
    trials = cfg.get("trials")
    if not trials:
        raise TrialError(f"{path}: no [[trials]] entries")
    defaults = cfg.get("defaults", {})
    names = set()
    out = []
    for k, t in enumerate(trials):
        spec = {**defaults, **t}
        spec.setdefault("name", f"trial{k + 1:03d}")
        if spec["name"] in names:
            raise TrialError(f"{path}: two trials are named {spec['name']!r}; names must be unique "
                             "(they are the output folders)")
        names.add(spec["name"])
        if spec.get("kind") not in KINDS:
            raise TrialError(f"{path}: trial {spec['name']!r} has kind {spec.get('kind')!r}; "
                             f"use one of {', '.join(KINDS)}")
        out.append(spec)
    cfg["trials"] = out
    cfg.setdefault("batch", {})
    return cfg


def _executor(scheduler, jobs):
    if scheduler:
        try:
            from distributed import Client
        except ImportError as exc:
            raise ImportError("--scheduler needs Dask distributed: pip install distributed "
                              "(on this machine and on the workers)") from exc
        client = Client(scheduler)
        return client.get_executor(), client
    return cf.ProcessPoolExecutor(max_workers=jobs), None


def _finished_line(k: int, n: int, row: dict) -> str:
    """``[k/n] name: done in X s`` / ``skipped (done)`` / ``FAILED: reason``."""
    status = str(row.get("status", "failed"))
    if row.get("skipped"):
        what = "skipped (done)"
    elif status.startswith("ok"):
        what = f"done in {row.get('time_total_s', 0.0):.1f} s"
    else:
        what = f"FAILED: {status.removeprefix('failed: ')}"
    return f"[{k}/{n}] {row.get('name')}: {what}"


def _suffix(shard) -> str:
    if shard is None:
        return ""
    i, n = parse_shard(shard) if isinstance(shard, str) else shard
    return f"-{i}-of-{n}"


def batch(trials: Sequence[dict], *, model="gait2d", out=None, base_dir=".", jobs: int | None = None,
          scheduler: str | None = None, progress: bool | None = None, force: bool = False,
          shard=None, log: bool = False, report: bool = True) -> list[dict]:
    """Run :func:`run_trial` over ``trials`` in parallel; write ``<out>/summary.csv`` and
    ``<out>/report.html``; return the rows.

    ``jobs=1`` runs in this process (no pool).  Rows keep the order of ``trials``.
    Each trial's folder is written under a temporary name and renamed when
    complete, so an interrupted batch (Ctrl-C) leaves complete trial folders or
    none; the temporary folders of interrupted trials are removed.

    Resume: a trial whose folder holds a ``done.json`` with the same :func:`trial_key`
    (same options, model and input file contents) and all its files is not run again;
    its stored row comes back with ``skipped = True`` (every row has ``skipped``).
    ``force=True`` runs every trial.  ``shard=(i, n)`` (or ``"i/n"``) runs only the
    trials with index ``k % n == i - 1`` (:func:`shard_indices`) and names its table
    and report ``summary-i-of-n.csv`` / ``report-i-of-n.html``; a later unsharded run
    finds them all done and writes the whole table.  ``log=True`` prints one line per
    finished trial (:func:`_finished_line`) through :meth:`Progress.note`.
    ``report=False`` skips the HTML report (:mod:`pinmsk.presentation.batch_report`).
    """
    out = None if out is None else Path(out)
    jobs = jobs or os.cpu_count() or 1
    picked = shard_indices(len(trials), shard)
    trials = [trials[k] for k in picked]
    n = len(trials)
    rows: list = [None] * n
    keys = [trial_key(t, model=model, base_dir=base_dir) if out is not None else None for t in trials]
    args = [dict(model=model, out_dir=None if out is None else str(out / t["name"]), base_dir=str(base_dir),
                 key=keys[i]) for i, t in enumerate(trials)]
    if out is not None:
        output_folder(out)
    todo = []
    finished = 0
    with Progress(n, "batch", unit="trials", force=progress) as bar:
        def finish(i, row):
            nonlocal finished
            finished += 1
            rows[i] = row
            if log:
                bar.note(_finished_line(finished, n, row))
            bar.update(1)

        for i, t in enumerate(trials):
            stored = None if (out is None or force) else done_row(out / t["name"], keys[i])
            if stored is not None:
                finish(i, {**stored, "skipped": True})
            else:
                todo.append(i)
        try:
            if todo and jobs == 1 and not scheduler:
                for i in todo:
                    finish(i, {**run_trial(trials[i], **args[i]), "skipped": False})
            elif todo:
                ex, client = _executor(scheduler, jobs)
                try:
                    futs = {ex.submit(run_trial, trials[i], **args[i]): i for i in todo}
                    for f in cf.as_completed(futs):
                        finish(futs[f], {**f.result(), "skipped": False})
                except BaseException:
                    ex.shutdown(wait=True, cancel_futures=True)
                    raise
                finally:
                    ex.shutdown(wait=True)
                    if client is not None:
                        client.close()
        except BaseException:
            if out is not None:   # a worker stopped mid-trial may not have cleaned up
                _remove_partial_folders(out, [trials[i]["name"] for i in todo])
            raise
    if out is not None:
        cols: list = ["name", "status"] if not rows else []
        for r in rows:
            cols += [k for k in r if k not in cols and k != "traceback"]

        def write(fh):
            w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
            w.writeheader()
            for r in rows:
                w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})

        atomic_write(out / f"summary{_suffix(shard)}.csv", write)
        if report:
            from .presentation.batch_report import write_batch_report
            write_batch_report(out / f"report{_suffix(shard)}.html", rows, out,
                               model=getattr(model, "name", model),
                               title=f"pinmsk batch{'' if shard is None else ' shard ' + _suffix(shard)[1:]}")
    return rows


def batch_cli(config_path, *, scheduler: str | None = None, jobs: int | None = None, force: bool = False,
              shard: str | None = None) -> dict:
    """``pinmsk batch CONFIG``: run the config's trials; returns ``{"rows", "table", "report", "failed",
    "reasons", "skipped", "shard"}``.

    ``failed`` lists the names of the trials that failed, ``reasons`` maps each to its status
    (``"failed: <message>"``), ``skipped`` names the trials found done (see :func:`batch`'s
    resume), ``shard`` is ``(i, n)`` or None.  One line per finished trial goes to stderr.
    """
    path = Path(config_path).resolve()
    sh = None if shard is None else parse_shard(shard)       # a bad shard is refused before any work
    cfg = load_config(path)
    b = cfg["batch"]
    out = _path(path.parent, b.get("out", "results"))
    rows = batch(cfg["trials"], model=b.get("model", "gait2d"), out=out, base_dir=path.parent,
                 jobs=jobs if jobs is not None else b.get("jobs"), scheduler=scheduler or b.get("scheduler"),
                 progress=None, force=force, shard=sh, log=True)
    failed = [r["name"] for r in rows if not str(r.get("status", "")).startswith("ok")]
    reasons = {r["name"]: str(r.get("status", "failed")) for r in rows if r["name"] in failed}
    return {"rows": rows, "table": str(out / f"summary{_suffix(sh)}.csv"),
            "report": str(out / f"report{_suffix(sh)}.html"), "failed": failed, "reasons": reasons,
            "skipped": [r["name"] for r in rows if r.get("skipped")], "shard": sh}


# -- single tasks the CLI runs: an analysis, then its files -----------------------------------

def contact_fit_task(model, trial, *, json_path=None, plot_dir=None, **options) -> dict:
    """What ``pinmsk contact fit MODEL TRIAL [--contact ...] [--json] [--plot]`` runs.

    ``model`` is a Model, a model name/path, or None (foot2d); ``trial`` a Trial or a
    file (CSU leg2d text, .csv, .sto, .mot; see :func:`read_contact_trial`) with
    ankle_x, ankle_y, foot_angle and ground_force_vx/vy/px.  ``options`` are
    :class:`ContactFit`'s keywords, with its defaults (the CLI passes only what the
    user gave).  Returns (and writes to ``json_path``) :meth:`ContactFit.to_dict`:
    ``objective`` (Eq. 4.2), ``params`` ({site: {name: value}}), ``rmse``
    (``normal_force``, ``friction_force`` in N, ``cop`` in m), ``seconds`` and
    ``settings`` (:meth:`ContactFit.settings_`); ``plot_dir`` gets the GRF and COP
    figures (their paths under ``figures``).
    """
    if model is None or isinstance(model, (str, Path)):
        model = load_contact_model(model)
    if isinstance(trial, (str, Path)):
        trial = read_contact_trial(trial)
    fit = ContactFit(**options).fit(model, trial)
    out = fit.to_dict()
    if plot_dir is not None:
        out["figures"] = [str(p) for p in contact_fit_figures(fit, plot_dir)]
    if json_path is not None:
        write_json(json_path, out, parents=True)
    return out


def optimize_task(task_path, out_path=None, progress=None, *, precision: int | None = None,
                  monitor=None, verbose: bool | None = None, solver_log=None, max_iter: int | None = None,
                  keep_unconverged: bool = False) -> Result:
    """Run the task file ``task_path`` on the optimal-control engine (:mod:`pinmsk.solvers.ocp`);
    write the result trial to ``out_path`` (.sto/.csv/.mot, ``precision`` significant digits,
    default that of :func:`pinmsk.io.write_trial`) and the JSON summary
    (:meth:`~pinmsk.solvers.ocp.problem.Collocation.to_dict`, plus a gait's speed, stride length,
    cost of transport and body weight) next to it (``<out>.json``); the summary is also
    ``result.info["summary"]``.

    ``monitor``: told of every IPOPT solve and iteration (:class:`Collocation`'s ``monitor``,
    e.g. :class:`pinmsk.presentation.solve_progress.SolveProgress`); ``verbose``: IPOPT's own
    log on stdout (default: none); ``solver_log``: a file that gets IPOPT's log of this run
    (replaced); ``max_iter``: IPOPT's iteration limit of every stage (default: the task's
    ``[solver] maxiter``).

    A problem IPOPT did not solve raises :class:`~pinmsk.errors.ConvergenceError` naming its
    status and the most violated constraint; nothing is written then (it is not a solution),
    unless ``keep_unconverged``: then the last iterate is written, flagged ``"converged": false``
    in the JSON, and returned (``result.converged`` is False), e.g. to start the next try from.
    """
    from .errors import ConvergenceError, ModelError
    from .solvers.ocp.tasks import resolve_task
    task_path = resolve_task(task_path)          # a path, or a shipped task's name
    spec = load_task(task_path)
    if max_iter is not None:
        if int(max_iter) < 0:
            raise ModelError(f"max_iter must be >= 0, got {max_iter}")
        spec = dict(spec, solver=dict(spec.get("solver", {}), maxiter=int(max_iter)))
    prob = build_from_task(spec, base_dir=Path(task_path).parent, progress=progress)
    if solver_log is not None:
        Path(solver_log).write_text("", encoding="utf-8")     # this run's log only (IPOPT appends to it)
    prob.set_params(monitor=monitor, verbose=bool(verbose), solver_log=solver_log)
    res = prob.fit().result_
    if not res.converged and not keep_unconverged:
        raise ConvergenceError(f"{task_path}: the optimizer did not converge ({res.status}); "
                               "no result written (it is not a solution; --keep-unconverged writes "
                               "the last iterate)")
    summary = prob.to_dict()
    if "gait" in spec:      # a gait task writes one full stride and its gait numbers
        from .solvers.ocp.gait import stride_result
        res, gait_numbers = stride_result(prob, mirror=spec["gait"].get("kind", "predictive") == "predictive")
        summary.update(gait_numbers)
    # the report is the solve's (for a gait, of the half cycle the stride is made of)
    res = Result.from_trial(res, stats=res.stats, info=dict(res.info, summary=summary),
                            report=prob.result_.report())
    if out_path is not None:
        out = Path(out_path)
        write_json(out.with_suffix(out.suffix + ".json"), summary)
        write_trial(res, out, precision=precision)
    return res
