"""Floating-base residuals: what inverse dynamics leaves at the unactuated coordinates.

On a model with a floating base (``gait2d``'s ``torso_x, torso_y,
torso_angle``) nothing drives the root, so the generalized forces inverse
dynamics finds there are *residuals*: they vanish only when the motion, the
external loads and the model's mass distribution agree.  OpenSim's RRA
guidance (OpenSim documentation, "Getting Started with RRA", Table of
thresholds) judges them against the trial's peak external force ``F_ext``:

* residual **forces**: peak ``<= 5 %`` of ``F_ext`` (RMS ``<= 3 %``);
* residual **moments**: peak ``<= 1 %`` of ``COM height x F_ext``
  (RMS ``<= 0.75 %``).

OpenSim's checklist for evaluating a simulation ("Simulation with OpenSim -
Best Practices", *Evaluating your simulation*, RRA:
https://simtk-confluence.stanford.edu:8443/display/OpenSim/Simulation+with+OpenSim+-+Best+Practices)
gives absolute limits as well (:data:`OPENSIM_RESIDUAL_LIMITS`): peak
residual forces below 10-25 N and RMS below 5-15 N; peak residual moments
below 75 N m and RMS below 50 N m.

:func:`floating_base_residuals` returns a :class:`ResidualReport` with each
residual over time, its peak and RMS, the thresholds, and the frames that
fail.  Without any external load the residuals carry the whole body weight;
:meth:`ResidualReport.warning` says so by name.  :func:`residual_table` gives
each residual's mean, RMS and peak in N (N m) and in percent of body weight
(moments: of body weight x height) with the checklist's verdict, the per-dof
table of the diagnosis' residual report.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects._base import is_prismatic, unactuated_coordinates
from .trial import Trial

__all__ = ["ResidualReport", "floating_base_residuals", "residual_table", "residual_table_lines",
           "com_height", "height_from_com", "PEAK_FORCE_FRACTION", "PEAK_MOMENT_FRACTION", "OPENSIM_RESIDUAL_LIMITS",
           "STATURE_PER_COM_HEIGHT"]

#: OpenSim RRA guidance: peak residual force / peak external force.
PEAK_FORCE_FRACTION = 0.05
#: OpenSim RRA guidance: peak residual moment / (COM height x peak external force).
PEAK_MOMENT_FRACTION = 0.01
#: OpenSim's checklist for RRA results (module docstring): ``{unit: {"peak" | "rms": (good, acceptable)}}``
#: in N and N m; a residual is ``ok`` within the first limit of both, ``marginal`` within the second.
OPENSIM_RESIDUAL_LIMITS = {"N": {"peak": (10.0, 25.0), "rms": (5.0, 15.0)},
                           "N*m": {"peak": (75.0, 75.0), "rms": (50.0, 50.0)}}
#: Stature over the height of the standing body's centre of mass: the whole-body centre of mass of an
#: adult stands at about 55 % of stature, so ``height ~= COM height / 0.55``.  Used when a model gives no
#: stature, for percentages of ``body weight x height``.
STATURE_PER_COM_HEIGHT = 1.0 / 0.55


@dataclass(frozen=True)
class ResidualReport:
    """Residuals at the unactuated coordinates over time and against OpenSim's thresholds."""

    time: np.ndarray
    coordinates: tuple[str, ...]
    units: tuple[str, ...]             # "N" or "N*m" per coordinate
    values: np.ndarray                 # (N, k)
    peak_external_force: float         # N
    com_height: float                  # m
    body_weight: float                 # N
    thresholds: np.ndarray             # (k,) peak thresholds in the coordinate's unit

    @property
    def mean(self) -> np.ndarray:
        return np.mean(self.values, axis=0)

    @property
    def peak(self) -> np.ndarray:
        return np.max(np.abs(self.values), axis=0)

    @property
    def rms(self) -> np.ndarray:
        return np.sqrt(np.mean(self.values ** 2, axis=0))

    @property
    def failing(self) -> np.ndarray:
        """(N, k) frames where a residual exceeds its threshold."""
        return np.abs(self.values) > self.thresholds[None, :]

    @property
    def ok(self) -> bool:
        return not bool(self.failing.any())

    def to_trial(self) -> Trial:
        ch = {f"{c}_residual": self.values[:, j] for j, c in enumerate(self.coordinates)}
        units = {f"{c}_residual": u for c, u in zip(self.coordinates, self.units)}
        return Trial(self.time, ch, units=units, meta={"analysis": "floating_base_residuals"})

    def warning(self) -> str | None:
        """One line when the trial has no external load on a floating-base model."""
        if self.peak_external_force > 0 or not self.coordinates:
            return None
        j = int(np.argmax(self.peak / np.where(np.array(self.units) == "N", self.body_weight,
                                                self.body_weight * max(self.com_height, 1e-3))))
        c, u, pk = self.coordinates[j], self.units[j], self.peak[j]
        bw = pk / self.body_weight if u == "N" else pk / (self.body_weight * max(self.com_height, 1e-3))
        per = "body weight" if u == "N" else "body weight x COM height"
        return (f"no ground reaction forces: the floating base ({', '.join(self.coordinates)}) has nothing "
                f"holding it up, so its residuals carry the whole external load ({c} peak {pk:.4g} {u}, "
                f"{bw:.2f} x {per}); give the trial's GRF (--grf FILE or --external-loads XML)")

    def to_dict(self) -> dict:
        """Peak, RMS, threshold and failing frames per coordinate, as a JSON-ready dict."""
        out = {"peak_external_force_N": self.peak_external_force, "com_height_m": self.com_height,
               "ok": self.ok, "coordinates": {}}
        fail = self.failing
        for j, c in enumerate(self.coordinates):
            out["coordinates"][c] = {"unit": self.units[j], "mean": float(self.mean[j]),
                                     "peak": float(self.peak[j]), "rms": float(self.rms[j]),
                                     "threshold_peak": float(self.thresholds[j]),
                                     "frames_failing": int(fail[:, j].sum())}
        return out

    def table(self, *, height: float | None = None) -> dict:
        """:func:`residual_table` of these residuals (``height`` default: :func:`height_from_com`)."""
        return residual_table(self.values, self.coordinates, self.units, body_weight=self.body_weight,
                              height=height_from_com(self.com_height) if height is None else height,
                              peak_external_force=self.peak_external_force, com_height=self.com_height)

    def lines(self) -> list[str]:
        """A table for reports: one line per coordinate, then the failing frames."""
        if not self.coordinates:
            return []
        head = (f"floating-base residuals (OpenSim RRA guidance: force <= {100 * PEAK_FORCE_FRACTION:g} % of "
                f"peak external force {self.peak_external_force:.4g} N; moment <= {100 * PEAK_MOMENT_FRACTION:g} % "
                f"of COM height {self.com_height:.3g} m x that force)")
        out = [head]
        fail = self.failing
        for j, c in enumerate(self.coordinates):
            u = self.units[j]
            n_bad = int(fail[:, j].sum())
            verdict = "ok" if n_bad == 0 else f"FAILS at {n_bad} of {fail.shape[0]} frames"
            out.append(f"  {c:<14} mean {self.mean[j]:10.4g} {u:<4} peak {self.peak[j]:10.4g} {u:<4} "
                       f"rms {self.rms[j]:10.4g} {u:<4} threshold {self.thresholds[j]:.4g} {u}: {verdict}")
        bad = np.flatnonzero(fail.any(axis=1))
        if bad.size:
            spans = _spans(self.time, bad)
            out.append(f"  failing frames: {spans}")
        w = self.warning()
        if w:
            out.append(f"  {w}")
        return out


def _spans(t: np.ndarray, idx: np.ndarray, most: int = 6) -> str:
    """Frame indices as 'k0-k1 (t0-t1 s)' runs."""
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    parts = [f"{r[0]}-{r[-1]} ({t[r[0]]:.3f}-{t[r[-1]]:.3f} s)" if r.size > 1 else f"{r[0]} ({t[r[0]]:.3f} s)"
             for r in runs[:most]]
    if len(runs) > most:
        parts.append(f"... {len(runs) - most} more runs")
    return ", ".join(parts)


def floating_base_residuals(model, motion, tau: np.ndarray, external=(), *, data=None) -> ResidualReport:
    """Residuals of ``tau`` (N, nv, inverse dynamics) at the model's unactuated coordinates.

    ``external`` are the :class:`pinmsk.skeleton.ExternalForce` s used in that
    inverse dynamics; their summed force gives the peak external force.  The COM
    height is the mean height of the model's centre of mass along ``-g`` above the world origin (the lab
    floor of OpenSim's and pinmsk's data) over a dozen frames spread over the trial: a typical lever arm
    for the moment threshold.  ``data``: a Pinocchio Data of the model to work in (default a new one).
    """
    coords = tuple(unactuated_coordinates(model))
    t = np.asarray(motion.t, dtype=float)
    idx = [model.coordinate_index(c) for c in coords]
    vals = np.asarray(tau, dtype=float)[:, idx] if idx else np.zeros((t.size, 0))
    units = tuple("N" if is_prismatic(model, c) else "N*m" for c in coords)
    body_weight = model.mass * float(np.linalg.norm(model.gravity))
    if external:
        total = sum(np.asarray(e.force, dtype=float) for e in external)
        f_peak = float(np.max(np.linalg.norm(total, axis=1)))
    else:
        f_peak = 0.0
    com_h = com_height(model, motion.q, data=data)
    thr = np.array([PEAK_FORCE_FRACTION * f_peak if u == "N" else PEAK_MOMENT_FRACTION * com_h * f_peak
                    for u in units])
    return ResidualReport(t, coords, units, vals, f_peak, com_h, body_weight, thr)


def com_height(model, q: np.ndarray, *, data=None) -> float:
    """Mean height of ``model``'s centre of mass along ``-g`` above the world origin over a dozen frames of
    ``q`` (N, nq) spread evenly (each a Pinocchio call): a typical lever arm for the moment limits."""
    import pinocchio as pin
    g = np.asarray(model.gravity, dtype=float)
    gn = float(np.linalg.norm(g))
    up = -g / gn if gn > 0 else np.array([0.0, 1.0, 0.0])
    pm = model.pin
    pd = pm.createData() if data is None else data
    q = np.asarray(q, dtype=float)
    rows = np.unique(np.linspace(0, q.shape[0] - 1, min(q.shape[0], 12)).astype(int))
    return float(np.mean([pin.centerOfMass(pm, pd, q[k]) @ up for k in rows]))


def height_from_com(com_height: float) -> float:
    """Stature estimated from the centre of mass height: ``COM height x`` :data:`STATURE_PER_COM_HEIGHT`."""
    return float(com_height) * STATURE_PER_COM_HEIGHT


def _status(unit: str, peak: float, rms: float) -> str:
    """OpenSim's checklist verdict on one residual: ``ok``, ``marginal`` or ``exceeds``."""
    lim = OPENSIM_RESIDUAL_LIMITS[unit]
    if peak <= lim["peak"][0] and rms <= lim["rms"][0]:
        return "ok"
    if peak <= lim["peak"][1] and rms <= lim["rms"][1]:
        return "marginal"
    return "exceeds"


def residual_table(values, coordinates, units, *, body_weight: float, height: float,
                   peak_external_force: float | None = None, com_height: float | None = None) -> dict:
    """Mean, RMS and peak of each residual, in its unit and in percent, against OpenSim's limits.

    ``values`` (N, k) residuals over frames at ``coordinates`` (``units`` ``"N"`` or ``"N*m"``); forces
    in percent of ``body_weight`` (N), moments in percent of ``body_weight x height`` (N m).  Per
    coordinate: ``unit``, ``mean`` (signed), ``rms``, ``peak`` (largest magnitude) and ``peak_signed``
    (its value), ``mean_percent``, ``rms_percent``, ``peak_percent``, ``percent_of`` (the reference in
    words), ``limits`` (:data:`OPENSIM_RESIDUAL_LIMITS` for the unit: ``peak`` and ``rms``, each
    ``[good, acceptable]``), ``status`` (``ok`` within both good limits, ``marginal`` within both
    acceptable ones, ``exceeds`` otherwise) and, with ``peak_external_force`` and ``com_height``,
    ``threshold_peak`` (the RRA guidance: 5 % of the peak external force, moments 1 % of COM height times
    it) with ``relative_status`` (``ok`` or ``exceeds``).  Plus ``body_weight_N``, ``height_m``,
    ``frames`` and ``ok`` (every status ``ok``).
    """
    x = np.asarray(values, dtype=float)
    x = x.reshape(x.shape[0], -1) if x.ndim else x.reshape(1, 1)
    bw = float(body_weight)
    h = float(height)
    out = {"body_weight_N": bw, "height_m": h, "frames": int(x.shape[0]), "coordinates": {}}
    f_ext = None if peak_external_force is None else float(peak_external_force)
    if f_ext is not None:
        out["peak_external_force_N"] = f_ext
    if com_height is not None:
        out["com_height_m"] = float(com_height)
    for j, (c, u) in enumerate(zip(coordinates, units)):
        col = x[:, j]
        k = int(np.argmax(np.abs(col))) if col.size else 0
        mean, rms = float(np.mean(col)), float(np.sqrt(np.mean(col * col)))
        peak, signed = float(abs(col[k])), float(col[k])
        ref = bw if u == "N" else bw * h
        pct = (lambda v: 100.0 * v / ref) if ref > 0 else (lambda v: None)
        row = {"unit": u, "mean": mean, "rms": rms, "peak": peak, "peak_signed": signed,
               "mean_percent": pct(mean), "rms_percent": pct(rms), "peak_percent": pct(peak),
               "percent_of": "body weight" if u == "N" else "body weight x height",
               "limits": {k2: list(v) for k2, v in OPENSIM_RESIDUAL_LIMITS[u].items()},
               "status": _status(u, peak, rms)}
        if f_ext is not None and com_height is not None:
            thr = PEAK_FORCE_FRACTION * f_ext if u == "N" else PEAK_MOMENT_FRACTION * float(com_height) * f_ext
            row["threshold_peak"] = float(thr)
            row["relative_status"] = "ok" if peak <= thr else "exceeds"
        out["coordinates"][c] = row
    out["ok"] = all(r["status"] == "ok" for r in out["coordinates"].values())
    return out


def residual_table_lines(table: dict, *, indent: str = "  ") -> list[str]:
    """One line per coordinate of a :func:`residual_table`: mean, RMS and peak in units and percent, and
    the verdict of OpenSim's checklist (its limits are :data:`OPENSIM_RESIDUAL_LIMITS`)."""
    rows = table.get("coordinates", {})
    if not rows:
        return []
    w = max(len(c) for c in rows)
    out = []
    for c, r in rows.items():
        u = "N m" if r["unit"] == "N*m" else "N"
        p = "%BW" if r["unit"] == "N" else "%BWh"
        cells = []
        for what in ("mean", "rms", "peak"):
            pc = r[f"{what}_percent"]
            cells.append(f"{what} {r[what]:8.3g} {u:<3}" + (f" ({pc:6.2f} {p})" if pc is not None else ""))
        out.append(f"{indent}{c:<{w}}  " + "  ".join(cells) + f"  {r['status']}")
    return out
