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
* if the heel (``RHEE``) and 5th-metatarsal (``RMT5``) markers are present, the
  foot2d driving coordinates ``foot_angle`` (rad, + = toes down: the heel->MT5
  marker line's angle below the horizontal, minus its value with the foot flat,
  the median over frames with F_y > 50 % of its maximum and |d angle/dt| < 0.5
  rad/s) and ``ankle_x``, ``ankle_y``, placed by ``anchor``:

  ``"heel"`` (default) -- the foot segment is located by its markers: the heel
      sphere's site H of foot2d (Table 4.1) is a point fixed in the marker-defined
      foot frame, ``H = RHEE + Rot(foot_angle) o``, and ``ankle_x, ankle_y`` is the
      foot2d ankle A that puts H there (``A = H - Rot h_AH``).  The constant offset
      ``o`` (m, foot frame) is ``heel_offset`` if given, else calibrated: its height
      puts H (and P, level with it) at ``heel_height`` above the belt in foot flat
      (default 0.045 m: the thesis radii of Tables 4.2-4.4, H 50, P 49, T 44 mm,
      then give 5, 4 and ~0 mm of static penetration, inside the radius bounds;
      the vertical datum is otherwise nearly interchangeable with the fitted
      radii -- 40, 45 and 50 mm gave J = 0.110, 0.113, 0.108 in one-start fits) and its x puts H above the measured COP during
      heel-only loading (frames within 0.1 s of each force onset with F_y >=
      ``min_force`` while the toes are still up, foot_angle < -0.02 rad: there the
      contact point is straight below the heel sphere's centre).  The result is in
      ``meta["heel_offset"]``, the implied (mean) offset of the foot2d ankle from the
      lateral malleolus marker in ``meta["ankle_from_marker"]`` (foot frame, m).
  ``"ankle"`` -- ``ankle_x, ankle_y`` = the lateral malleolus marker (``RLM``), the
      Table 4.1 foot hanging from it (the marker is not the ankle joint centre, so
      this puts the heel site where the heel marker is, ~4 cm behind the heel's
      contact point in this trial).

All heights are shifted by ``-belt_height`` so the belt surface is ``y = 0``,
the ground plane of :mod:`pinmsk.contact`.  ``meta["ground_speed"]`` is the belt
velocity along x (m/s, negative: moving backwards) estimated as the median x
velocity of the heel and MT5 markers' midpoint over the same foot-flat frames; the contact fit uses it
as the ground's tangential velocity.  ``meta["body_mass"]`` is ``body_mass`` if given.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import TrialError
from ..trial import Trial


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


def _anchor_heel(t, hx, hy, theta, fy, cop, flat, *, min_force, heel_offset, heel_height, heel_site, path):
    """Foot-model ankle ``(ax, ay)`` that puts the heel site H at ``RHEE + Rot(theta) o`` (see read_csu)."""
    h = np.asarray(heel_site, dtype=float).reshape(-1)[:2]
    c, s = np.cos(theta), np.sin(theta)
    info = {}
    if heel_offset is None:
        # heel-only loading: from each force onset, up to 0.1 s, while the toes are still up
        on = fy >= min_force
        onsets = np.flatnonzero(on[1:] & ~on[:-1]) + 1
        hs = np.zeros_like(on)
        for i0 in onsets:
            k = i0
            while k < t.size and on[k] and theta[k] < -0.02 and t[k] - t[i0] <= 0.1:
                hs[k] = True
                k += 1
        if hs.sum() < 2:
            raise TrialError(f"{path}: cannot calibrate the heel offset: no heel-only loading frames (force "
                             f"onset with the toes up, foot_angle < -0.02 rad); pass heel_offset=(ox, oy) in m "
                             "(heel marker -> heel sphere centre, foot frame) or anchor='ankle'")
        # unknowns o = (ox, oy):  mean over flat of  hy - s ox + c oy = heel_height
        #                         mean over hs   of  hx + c ox + s oy = cop_x
        A = np.array([[np.mean(-s[flat]), np.mean(c[flat])], [np.mean(c[hs]), np.mean(s[hs])]])
        b = np.array([heel_height - np.mean(hy[flat]), np.mean(cop[hs] - hx[hs])])
        o = np.linalg.solve(A, b)
        info["heel_calibration_frames"] = int(hs.sum())
    else:
        o = np.asarray(heel_offset, dtype=float).reshape(2)
    Hx = hx + c * o[0] + s * o[1]
    Hy = hy - s * o[0] + c * o[1]
    ax = Hx - (c * h[0] + s * h[1])
    ay = Hy - (-s * h[0] + c * h[1])
    info["heel_offset"] = [float(o[0]), float(o[1])]
    return ax, ay, info


def read_csu(path, *, plate: str = "FP2", belt_height: float = 0.0, min_force: float = 20.0,
             max_gap: int = 5, ankle: str = "RLM", heel: str = "RHEE", toe: str = "RMT5",
             body_mass: float | None = None, anchor: str = "heel", heel_offset=None,
             heel_height: float = 0.045, heel_site=None) -> Trial:
    """Read a CSU leg2d text file (see the module docstring) into a Trial.

    ``heel_site`` is the foot model's heel site H relative to its ankle A, in the
    foot frame (m, ``(x, y)``); ``anchor="heel"`` needs it to place the ankle.
    :func:`pinmsk.contact.foot.read_csu_foot2d` reads a file for the foot2d model.
    """
    path = Path(path)
    if anchor not in ("heel", "ankle"):
        raise TrialError(f"read_csu: anchor must be 'heel' (locate the foot from the heel and MT5 markers) "
                         f"or 'ankle' (hang the foot from the {ankle} marker), got {anchor!r}")
    if anchor == "heel" and heel_site is None:
        raise TrialError("read_csu: anchor='heel' places the foot model by its heel site: pass heel_site=(x, y) "
                         "(m, foot frame), or read with pinmsk.contact.foot.read_csu_foot2d(path), "
                         "or use anchor='ankle'")
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
    needed = (heel, toe) + ((ankle,) if anchor == "ankle" else ())
    if all(f"{m}_x" in channels for m in needed):
        ang = np.arctan2(channels[f"{toe}_y"] - channels[f"{heel}_y"], channels[f"{toe}_x"] - channels[f"{heel}_x"])
        dang = np.gradient(ang, t)
        flat = (fy > 0.5 * fy.max()) & (np.abs(dang) < 0.5)
        if flat.sum() < 3:
            raise TrialError(f"{path}: cannot find foot-flat frames (F_y > 50 % max, still foot) "
                             "to calibrate foot_angle")
        theta = -(ang - np.median(ang[flat]))
        channels["foot_angle"] = theta
        meta["foot_angle_offset"] = float(np.median(ang[flat]))
        meta["anchor"] = anchor
        if anchor == "ankle":
            ax, ay = channels[f"{ankle}_x"], channels[f"{ankle}_y"]
        else:
            try:
                ax, ay, info = _anchor_heel(t, channels[f"{heel}_x"], channels[f"{heel}_y"], theta, fy, cop, flat,
                                            min_force=min_force, heel_offset=heel_offset,
                                            heel_height=heel_height, heel_site=heel_site, path=path)
            except TrialError as exc:
                if f"{ankle}_x" not in channels:
                    raise
                # readers of the markers only (IK pipelines) must not fail on the foot2d channels
                warnings.warn(f"{exc}; ankle_x/ankle_y fall back to the {ankle} marker (anchor='ankle')",
                              stacklevel=2)
                ax, ay, info = channels[f"{ankle}_x"], channels[f"{ankle}_y"], {"anchor": "ankle"}
            meta.update(info)
            if f"{ankle}_x" in channels:
                c, s_ = np.cos(theta), np.sin(theta)
                dx, dy = ax - channels[f"{ankle}_x"], ay - channels[f"{ankle}_y"]
                # world -> foot frame: l = Rot^T d with Rot = [[c, s], [-s, c]]
                meta["ankle_from_marker"] = [float(np.mean(c * dx - s_ * dy)), float(np.mean(s_ * dx + c * dy))]
        channels["ankle_x"] = ax
        channels["ankle_y"] = ay
        # belt speed: the foot markers' x velocity in foot flat (the shank marker RLM is biased by
        # the shank's rotation: -0.94 vs -0.98 m/s in the CSU file)
        vx = np.gradient(0.5 * (channels[f"{heel}_x"] + channels[f"{toe}_x"]), t)
        meta["ground_speed"] = float(np.median(vx[flat]))
    units = {k: ("N" if k.startswith("ground_force_v") else "N*m" if "moment" in k else
                 "rad" if k == "foot_angle" else "m") for k in channels}
    return Trial(t, channels, units=units, meta=meta)
