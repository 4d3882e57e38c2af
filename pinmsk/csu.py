"""Reader for the CSU (Cleveland State University HMC lab) 2-D gait text files.

The format of GaitAnalysisToolKit's ``leg2d`` test data (``rawdata.txt``): one
``%`` header line of tab-separated column names, then one row per sample:
``TimeStamp`` (s), sagittal marker coordinates ``<MARKER>.PosX/.PosY`` (m, X
forward, Y up) and force-plate channels ``FP<k>.ForX``, ``FP<k>.ForY`` (N, the
load on the foot) and ``FP<k>.MomZ`` (N m) -- the moment of that load about
the **global origin**, not about the centre of pressure.

:func:`read_csu` returns a :class:`pinmsk.Trial` with

* every marker as ``<MARKER>_x``, ``<MARKER>_y`` (m; NaN gaps of up to
  ``max_gap`` samples filled linearly, listed in ``meta["filled"]``);
* ``ground_force_vx``, ``ground_force_vy`` (N) and ``ground_moment_origin_z`` (N m);
* ``ground_force_px`` -- the COP on the belt surface ``y = belt_height``,
  ``x = (M_z + belt_height * F_x) / F_y`` (from ``M_z = x F_y - y F_x``), and
  ``ground_force_py`` (= 0 after the shift below).  Where ``F_y < min_force``
  the COP is undefined and set to **NaN**: mask it (``ground_force_vy >=
  min_force``) before use;
* if the ankle (``RLM``), heel (``RHEE``) and 5th-metatarsal (``RMT5``) markers are
  present, the foot2d driving coordinates ``ankle_x``, ``ankle_y`` (the lateral
  malleolus) and ``foot_angle`` (rad, + = toes down): the heel->MT5 marker line's
  angle below the horizontal, minus its value with the foot flat (median over
  frames with F_y > 50 % of its maximum and |d angle/dt| < 0.5 rad/s).

All heights are shifted by ``-belt_height`` so the belt surface is ``y = 0``,
the ground plane of :mod:`pinmsk.contact`.  ``meta["ground_speed"]`` is the belt
velocity along x (m/s, negative: moving backwards) estimated as the median
ankle-marker x velocity over the same foot-flat frames; the contact fit uses it
as the ground's tangential velocity.  ``meta["body_mass"]`` is ``body_mass`` if given.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import TrialError
from .trial import Trial


def _fill_gaps(x: np.ndarray, max_gap: int, name: str, path) -> tuple[np.ndarray, int]:
    bad = ~np.isfinite(x)
    if not bad.any():
        return x, 0
    if bad.all():
        raise TrialError(f"{path}: column {name!r} has no finite value")
    idx = np.flatnonzero(bad)
    # run lengths
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    for r in runs:
        if len(r) > max_gap or r[0] == 0 or r[-1] == len(x) - 1:
            raise TrialError(
                f"{path}: column {name!r} has a gap of {len(r)} sample(s) at rows {r[0] + 2}-{r[-1] + 2}"
                f"{' at the edge of the file' if r[0] == 0 or r[-1] == len(x) - 1 else ''}; "
                f"at most {max_gap} interior samples are filled (pass max_gap=... to fill longer gaps)"
            )
    good = ~bad
    out = x.copy()
    out[bad] = np.interp(np.flatnonzero(bad), np.flatnonzero(good), x[good])
    return out, int(bad.sum())


def read_csu(path, *, plate: str = "FP2", belt_height: float = 0.0, min_force: float = 20.0,
             max_gap: int = 5, ankle: str = "RLM", heel: str = "RHEE", toe: str = "RMT5",
             body_mass: float | None = None) -> Trial:
    """Read a CSU leg2d text file (see the module docstring) into a Trial."""
    path = Path(path)
    if not path.exists():
        raise TrialError(f"CSU file not found: {path}")
    lines = path.read_text().splitlines()
    if not lines or not lines[0].lstrip().startswith("%"):
        raise TrialError(f"{path}: expected a first header line starting with '%' (CSU leg2d format)")
    names = lines[0].lstrip()[1:].strip().split("\t")
    names = [n.strip() for n in names]
    if names[0] != "TimeStamp":
        raise TrialError(f"{path}: the first column must be 'TimeStamp', got {names[0]!r}")
    rows = []
    for k, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = line.split("\t")
        if len(cells) != len(names):
            raise TrialError(f"{path}: row {k} has {len(cells)} cells, the header has {len(names)} columns")
        try:
            rows.append([float(c) for c in cells])
        except ValueError as exc:
            raise TrialError(f"{path}: row {k}: {exc}") from None
    data = np.array(rows, dtype=float)
    col = {n: data[:, i] for i, n in enumerate(names)}
    t = col["TimeStamp"]
    for ch in ("ForX", "ForY", "MomZ"):
        if f"{plate}.{ch}" not in col:
            raise TrialError(f"{path}: no column '{plate}.{ch}' (columns: {', '.join(names)})")
    channels: dict[str, np.ndarray] = {}
    filled = {}
    for n in names[1:]:
        if n.endswith(".PosX") or n.endswith(".PosY"):
            mk, ax = n[:-5], n[-1].lower()
            x, nfill = _fill_gaps(col[n], max_gap, n, path)
            if nfill:
                filled[n] = nfill
            if ax == "y":
                x = x - belt_height
            channels[f"{mk}_{ax}"] = x
    fx, fy, mz = (col[f"{plate}.{c}"] for c in ("ForX", "ForY", "MomZ"))
    for c, arr in (("ForX", fx), ("ForY", fy), ("MomZ", mz)):
        if not np.all(np.isfinite(arr)):
            row = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise TrialError(f"{path}: column '{plate}.{c}' is not finite at row {row + 2} (t = {t[row]:g} s)")
    channels["ground_force_vx"] = fx
    channels["ground_force_vy"] = fy
    channels["ground_moment_origin_z"] = mz
    cop = np.full_like(fy, np.nan)
    ok = fy >= min_force
    cop[ok] = (mz[ok] + belt_height * fx[ok]) / fy[ok]
    channels["ground_force_px"] = cop
    channels["ground_force_py"] = np.zeros_like(fy)
    meta = {"source": str(path), "format": "csu", "plate": plate, "belt_height": belt_height,
            "min_force": min_force, "filled": filled}
    if body_mass is not None:
        meta["body_mass"] = float(body_mass)
    if all(f"{m}_x" in channels for m in (ankle, heel, toe)):
        ang = np.arctan2(channels[f"{toe}_y"] - channels[f"{heel}_y"], channels[f"{toe}_x"] - channels[f"{heel}_x"])
        dang = np.gradient(ang, t)
        flat = (fy > 0.5 * fy.max()) & (np.abs(dang) < 0.5)
        if flat.sum() < 3:
            raise TrialError(f"{path}: cannot find foot-flat frames (F_y > 50 % max, still foot) "
                             "to calibrate foot_angle")
        channels["ankle_x"] = channels[f"{ankle}_x"]
        channels["ankle_y"] = channels[f"{ankle}_y"]
        channels["foot_angle"] = -(ang - np.median(ang[flat]))
        vx = np.gradient(channels[f"{ankle}_x"], t)
        meta["ground_speed"] = float(np.median(vx[flat]))
        meta["foot_angle_offset"] = float(np.median(ang[flat]))
    units = {k: ("N" if k.startswith("ground_force_v") else "N*m" if "moment" in k else
                 "rad" if k == "foot_angle" else "m") for k in channels}
    return Trial(t, channels, units=units, meta=meta)
