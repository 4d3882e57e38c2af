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

:func:`floating_base_residuals` returns a :class:`ResidualReport` with each
residual over time, its peak and RMS, the thresholds, and the frames that
fail.  Without any external load the residuals carry the whole body weight;
:meth:`ResidualReport.warning` says so by name.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects._base import is_prismatic, unactuated_coordinates
from .trial import Trial

__all__ = ["ResidualReport", "floating_base_residuals", "PEAK_FORCE_FRACTION", "PEAK_MOMENT_FRACTION"]

#: OpenSim RRA guidance: peak residual force / peak external force.
PEAK_FORCE_FRACTION = 0.05
#: OpenSim RRA guidance: peak residual moment / (COM height x peak external force).
PEAK_MOMENT_FRACTION = 0.01


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
            out["coordinates"][c] = {"unit": self.units[j], "peak": float(self.peak[j]), "rms": float(self.rms[j]),
                                     "threshold_peak": float(self.thresholds[j]),
                                     "frames_failing": int(fail[:, j].sum())}
        return out

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
            out.append(f"  {c:<14} peak {self.peak[j]:10.4g} {u:<4} rms {self.rms[j]:10.4g} {u:<4} "
                       f"threshold {self.thresholds[j]:.4g} {u}: {verdict}")
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
    import pinocchio as pin

    coords = tuple(unactuated_coordinates(model))
    t = np.asarray(motion.t, dtype=float)
    idx = [model.coordinate_index(c) for c in coords]
    vals = np.asarray(tau, dtype=float)[:, idx] if idx else np.zeros((t.size, 0))
    units = tuple("N" if is_prismatic(model, c) else "N*m" for c in coords)
    g = np.asarray(model.gravity, dtype=float)
    gn = float(np.linalg.norm(g))
    up = -g / gn if gn > 0 else np.array([0.0, 1.0, 0.0])
    body_weight = model.mass * gn
    if external:
        total = sum(np.asarray(e.force, dtype=float) for e in external)
        f_peak = float(np.max(np.linalg.norm(total, axis=1)))
    else:
        f_peak = 0.0
    pm = model.pin
    pd = pm.createData() if data is None else data
    # a typical height for the threshold: a dozen frames spread over the trial (each a Pinocchio call)
    rows = np.unique(np.linspace(0, t.size - 1, min(t.size, 12)).astype(int))
    heights = [float(pin.centerOfMass(pm, pd, motion.q[k]) @ up) for k in rows]
    com_h = float(np.mean(heights))
    thr = np.array([PEAK_FORCE_FRACTION * f_peak if u == "N" else PEAK_MOMENT_FRACTION * com_h * f_peak
                    for u in units])
    return ResidualReport(t, coords, units, vals, f_peak, com_h, body_weight, thr)
