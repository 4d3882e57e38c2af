"""The one stage from a measured trial to what analyses use: q, v, a and the external loads.

Every analysis (inverse dynamics, SO, FSO, diagnosis, batch) goes through
:func:`prepare`, so they all apply the same filter to the same inputs:

* **Kinematics** are low-passed by a zero-lag 4th-order Butterworth filter at
  :data:`DEFAULT_CUTOFF` = 6 Hz unless told otherwise (the usual choice for
  gait and most movements; Winter, *Biomechanics and Motor Control of Human
  Movement*, Ch. 2), then differentiated by quintic spline
  (:func:`pinmsk.signals.filtering.differentiate`).  ``cutoff=0`` (or ``None``) turns
  filtering off explicitly, which is right for noise-free synthetic data.
* **Ground reaction forces** are used whenever the trial (or ``grf=``, or an
  OpenSim ExternalLoads file) has them: each plate goes to a body of the model
  (:func:`pinmsk.grf.plates` says which and why), becomes a world wrench about
  the origin (:func:`pinmsk.grf.plate_wrench`), and is low-passed at the
  **same** cut-off as the kinematics: a mismatch makes artificial residual
  peaks at heel strike (Kristianslund, Krosshaug & van den Bogert 2012,
  *J Biomech* 45:666-671).  Filtering the wrench rather than the COP keeps the
  filter linear and the unloaded frames meaningful.  A GRF file at its own
  rate is filtered at that rate, then interpolated onto the kinematics' times.
* A trial that has ground reaction channels but a model with no body to take
  them is an error, never a silent drop (``ground_reaction="ignore"`` says so
  explicitly).  A floating-base model without any GRF gets a warning from
  the residual report (:mod:`pinmsk.residuals`).

The result, :class:`TrialInputs`, carries what was applied
(:meth:`TrialInputs.meta`, :meth:`TrialInputs.describe`) for every output's
metadata and every report.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from . import grf as _grf
from .components import Motion
from .errors import ModelError, TrialError
from .io.channel_map import map_hint
from .io.external_loads import read_external_loads
from .io.tables import read_trial
from .signals.filtering import DEFAULT_CUTOFF, FILTER_ORDER, lowpass
from .signals.sampling import measured_rate
from .skeleton import ExternalForce, skeleton_constant, world_wrench
from .trial import Trial, parse_ground_reaction

__all__ = ["DEFAULT_CUTOFF", "FILTER_ORDER", "Filtering", "TrialInputs", "motion", "as_motion", "prepare",
           "cutoff_value", "coordinate_map", "source_coordinates", "source_positions", "independent_coordinates",
           "trial_coordinates", "actuated_forces",
           "require_independent_joints", "check_coordinate_columns",
           "is_planar", "has_ground_reaction", "lowpass_external"]

#: Vertical force (N) below which a plate counts as unloaded.
MIN_FORCE = 20.0

GROUND_REACTION_MODES = ("auto", "ignore")
#: What :func:`motion` does with an OpenSim coordinate the trial leaves out that is neither locked nor set by a
#: coupler: ``"refuse"`` (a TrialError naming it) or ``"default"`` (held at its default value, noted, as
#: OpenSim's InverseDynamicsTool does).
MISSING_COORDINATE_MODES = ("refuse", "default")


def cutoff_value(cutoff) -> float | None:
    """``cutoff`` as Hz, or None for no filter (``0`` and ``None`` both mean off)."""
    if cutoff is None:
        return None
    try:
        c = float(cutoff)
    except (TypeError, ValueError):
        raise TrialError(f"cutoff must be a number of Hz (0 = no filter); got {cutoff!r}") from None
    if not np.isfinite(c) or c < 0:
        raise TrialError(f"cutoff must be >= 0 Hz (0 = no filter); got {cutoff!r}")
    return c or None


@dataclass(frozen=True)
class Filtering:
    """What low-pass was applied: to the coordinates (``cutoff``) and to the GRF (``grf_cutoff``)."""

    cutoff: float | None
    order: int = FILTER_ORDER
    grf_cutoff: float | None = None
    has_grf: bool = False
    #: why the GRF got its filter: "" (asked or the kinematics' own), or the convention that chose it
    grf_convention: str = ""
    #: the coordinates' low-pass: "butterworth" (pinmsk's, ``order``) or "opensim" (its ID tool's)
    method: str = "butterworth"

    @property
    def applied_to(self) -> tuple[str, ...]:
        out = ("coordinates",) if self.cutoff is not None else ()
        if self.has_grf and self.grf_cutoff is not None:
            out += ("ground reaction",)
        return out

    def describe(self) -> str:
        def one(c):
            return "none" if c is None else f"{c:g} Hz"
        head = f"zero-lag Butterworth low-pass, order {self.order} (x2 forwards-backwards): "
        if self.method == "opensim":
            head = ("OpenSim's ID-tool filter (the trial padded by half its length at each end, third-order "
                    "Butterworth IIR forwards and backwards, quintic spline through the padded samples): ")
        if not self.has_grf:
            return head + f"coordinates {one(self.cutoff)}" + (" (cutoff 0)" if self.cutoff is None else "")
        why = f" ({self.grf_convention})" if self.grf_convention else ""
        if self.cutoff == self.grf_cutoff:
            return head + f"coordinates and ground reaction {one(self.cutoff)}{why}"
        return head + f"coordinates {one(self.cutoff)}, ground reaction {one(self.grf_cutoff)}{why}"

    def meta(self) -> dict:
        out = {"lowpass_cutoff_hz": 0.0 if self.cutoff is None else float(self.cutoff),
               "lowpass_order": 3 if self.method == "opensim" else self.order, "lowpass_method": self.method}
        if self.has_grf:
            out["grf_lowpass_cutoff_hz"] = 0.0 if self.grf_cutoff is None else float(self.grf_cutoff)
            if self.grf_convention:
                out["grf_convention"] = self.grf_convention
        return out


@dataclass(frozen=True)
class TrialInputs:
    """A trial made ready for analysis: the motion, the external loads and how they were made."""

    motion: Motion
    external: tuple[ExternalForce, ...]
    plates: tuple = ()
    filtering: Filtering = field(default_factory=lambda: Filtering(None))
    notes: tuple[str, ...] = ()
    grf_source: str | None = None

    @property
    def has_external(self) -> bool:
        return bool(self.external)

    def describe(self) -> list[str]:
        """Lines for reports: the filter, each plate and its body, and notes."""
        lines = [f"filter: {self.filtering.describe()}"]
        if self.plates:
            src = f" from {self.grf_source}" if self.grf_source else ""
            lines.append(f"ground reaction{src}: " + "; ".join(p.describe() for p in self.plates))
        else:
            lines.append("ground reaction: none")
        lines.extend(self.notes)
        return lines

    def meta(self) -> dict:
        """Flat metadata for written outputs (strings and numbers only)."""
        out = dict(self.filtering.meta())
        out["ground_reaction"] = "; ".join(p.describe() for p in self.plates) if self.plates else "none"
        if self.grf_source:
            out["ground_reaction_source"] = self.grf_source
        if self.notes:
            out["notes"] = " | ".join(self.notes)
        return out


def has_ground_reaction(trial: Trial) -> bool:
    """Whether the trial has any ground-reaction channel."""
    return any(parse_ground_reaction(n) is not None for n in trial.names)


#: is_planar's answers by skeleton (its Data costs ms to create on a large model, each ID asks): a few
#: skeletons, kept alive with their answers so that their ids stay theirs.
def is_planar(model) -> bool:
    """Whether every joint moves in the x-y plane (translations in x, y; rotations about z)."""
    return skeleton_constant(model.pin, "is_planar", _is_planar)


def _is_planar(pm) -> bool:
    import pinocchio as pin
    if pm.nv == 0:
        return False
    pd = pm.createData()
    # a generic configuration: no joint axis aligned with z by accident of the pose
    q = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
    J = np.asarray(pin.computeJointJacobians(pm, pd, q)).reshape(6, pm.nv)
    return bool(np.max(np.abs(J[[2, 3, 4], :]), initial=0.0) < 1e-9)


def lowpass_wrenches(W: np.ndarray, *, rate: float, cutoff: float | None) -> np.ndarray:
    """World wrenches ``(N, 6k)`` low-passed like the kinematics (no-op for ``cutoff=None``)."""
    if cutoff is None or W.size == 0:
        return W
    if cutoff >= 0.5 * rate:
        raise TrialError(f"cutoff {cutoff:g} Hz is not below the GRF's Nyquist frequency "
                         f"{0.5 * rate:g} Hz (GRF at {rate:g} Hz)")
    return lowpass(W, rate=rate, cutoff=cutoff, order=FILTER_ORDER)


def lowpass_external(external, *, rate: float, cutoff) -> tuple[ExternalForce, ...]:
    """:class:`ExternalForce` s with their wrenches (about the origin) low-passed at ``cutoff`` Hz."""
    c = cutoff_value(cutoff)
    out = []
    for e in external:
        W = lowpass_wrenches(world_wrench(e, np.shape(e.force)[0]), rate=rate, cutoff=c)
        out.append(ExternalForce(e.frame, W[:, :3].copy(), np.zeros((W.shape[0], 3)), W[:, 3:].copy()))
    return tuple(out)


def _bracket(t: np.ndarray, tg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For ``np.interp(t, tg, .)``: each ``t``'s piece ``j`` (``tg[j] <= t < tg[j + 1]``, clipped to the
    pieces) and ``t`` clamped to ``tg``'s span (np.interp holds the end values outside it)."""
    j = np.clip(np.searchsorted(tg, t, side="right") - 1, 0, tg.size - 2)
    return j, np.clip(t, tg[0], tg[-1])


def _interp_rows(t: np.ndarray, tg: np.ndarray, j: np.ndarray, y0: np.ndarray, y1: np.ndarray) -> np.ndarray:
    """``np.interp`` of every column at once from the bracketing rows ``y0 = y[j]``, ``y1 = y[j + 1]``
    (:func:`_bracket`), with its formula ``slope (t - tg[j]) + y[j]`` and its end values (the same numbers
    for finite ``y``)."""
    x0, x1 = tg[j], tg[j + 1]
    out = ((y1 - y0) / (x1 - x0)[:, None]) * (t - x0)[:, None] + y0
    at_end = t >= tg[-1]
    if at_end.any():
        out[at_end] = y1[at_end]
    at_start = t <= tg[0]
    if at_start.any():
        out[at_start] = y0[at_start]
    return out


def _plate_loads(model, grf: Trial, motion: Motion, *, cutoff, external_loads, frames, planar,
                 q_on_grf_time, same_time: bool):
    _grf.check_vertical_force(grf, min_force=MIN_FORCE)
    plist = _grf.plates(model, grf, external_loads=external_loads, frames=frames, q=q_on_grf_time,
                        min_force=MIN_FORCE)
    # an OpenSim ExternalLoads file says which columns load which body, and OpenSim applies them at every
    # frame (its GRF files carry a processed COP); only plates found by pinmsk drop their unloaded frames
    wrench_min = -np.inf if external_loads is not None else MIN_FORCE
    rows = None
    if not same_time:
        tg = np.asarray(grf.time, dtype=float)
        t = motion.t
        if t[0] < tg[0] - 1e-9 or t[-1] > tg[-1] + 1e-9:
            raise TrialError(f"the GRF covers {tg[0]:.4g}-{tg[-1]:.4g} s but the kinematics "
                             f"{t[0]:.4g}-{t[-1]:.4g} s; cut the trial to the GRF's time span")
        j, tc = _bracket(t, tg)
        if cutoff is None:
            # unfiltered, the interpolation reads only the GRF frames bracketing the motion's times: the
            # wrenches are made at those alone (a GRF file is sampled 5-10x faster than the kinematics)
            used = np.zeros(tg.size, dtype=bool)
            used[j] = used[j + 1] = True
            rows = np.flatnonzero(used)
    wrenches = [_grf.plate_wrench(grf, p, min_force=wrench_min, planar=planar, rows=rows) for p in plist]
    n_w = grf.n_frames if rows is None else rows.size
    W = np.concatenate([np.hstack([F, M]) for F, M in wrenches], axis=1) if wrenches else np.zeros((n_w, 0))
    if cutoff is not None:
        W = lowpass_wrenches(W, rate=measured_rate(grf), cutoff=cutoff)
    if not same_time:
        if not W.size:
            W = np.zeros((t.size, 0))
        else:
            k = j if rows is None else np.searchsorted(rows, j)     # j + 1 is the next row of ``rows``
            W = _interp_rows(tc, tg, j, W[k], W[k + 1])
    ext = []
    for i, p in enumerate(plist):
        F = np.ascontiguousarray(W[:, 6 * i: 6 * i + 3])
        M = np.ascontiguousarray(W[:, 6 * i + 3: 6 * i + 6])
        ext.append(ExternalForce(p.body, F, np.zeros_like(F), M))
    return tuple(plist), tuple(ext)


def source_coordinate_gaps(model, trial, *, missing_coordinates: str = "refuse") -> tuple[dict, tuple[str, ...]]:
    """The values of the OpenSim coordinates an exact import's trial leaves out, and a note on each.

    Moco's and OpenSim's states and coordinates files often leave coordinates out (RajagopalWalk's
    ``coordinates.sto`` has no ``mtp_angle_*``).  A locked coordinate (or one welded at import) is held at
    its value, as the model says; the dependent coordinate of an enforced CoordinateCouplerConstraint is
    set by its coupler in :func:`motion` whether the trial has it or not (``fill`` holds a placeholder
    for it; :func:`prepare` notes trial values the coupler replaced); any other coordinate is refused
    by name, or, with ``missing_coordinates="default"``, held at its default value as OpenSim's
    InverseDynamicsTool does.  Returns ``({coordinate: value}, notes)``; ``({}, ())`` for a model without
    a coordinate map."""
    if missing_coordinates not in MISSING_COORDINATE_MODES:
        raise TrialError(f"missing_coordinates must be one of {', '.join(MISSING_COORDINATE_MODES)}; "
                         f"got {missing_coordinates!r}")
    cmap = coordinate_map(model)
    if cmap is None:
        return {}, ()
    coupled = {dep: indep for dep, indep, _, _ in cmap.couplers}
    locked = {**(model.meta.get("locked_coordinates") or {}), **cmap.welded}
    fill, notes, free = {}, [], []
    for c in cmap.osim_coordinates:
        if c in coupled:
            # a placeholder, in the trial or not: the coupler sets it (motion), so the trial's own values
            # (Moco's files carry patella angles that are not the coupling's) are neither checked nor used
            fill[c] = cmap.defaults[c]
            if c not in trial:
                notes.append(f"{c}: not in the trial; set from {', '.join(coupled[c])} by its "
                             "CoordinateCouplerConstraint")
        elif c in trial:
            continue
        elif c in locked:
            fill[c] = float(locked[c])
            notes.append(f"{c}: not in the trial; locked at {float(locked[c]):.6g}")
        else:
            free.append(c)
    if free and missing_coordinates == "refuse":
        try:
            trial.require(free)
        except TrialError as exc:
            raise TrialError(f"{exc}; {map_hint(trial, [c for c in free if c not in trial])}; or, to hold a "
                             "coordinate the file leaves out at its default value, as OpenSim's ID tool does, pass "
                             "--missing-coordinates default (missing_coordinates='default')") from None
    for c in free:
        fill[c] = cmap.defaults[c]
        notes.append(f"{c}: not in the trial; held at its default value {cmap.defaults[c]:.6g} "
                     "(missing_coordinates='default', as OpenSim's ID tool does)")
    return fill, tuple(notes)


def motion(model, trial, *, cutoff=DEFAULT_CUTOFF, signals: Iterable[str] | None = None,
           missing_coordinates: str = "refuse") -> Motion:
    """The model's :class:`Motion` (q, v, a in coordinate order) from a Trial.

    Velocities and accelerations come from the trial's coordinates
    (:meth:`pinmsk.Trial.kinematics`): zero-lag low-pass at ``cutoff`` Hz (default
    :data:`DEFAULT_CUTOFF` = 6 Hz; 0 or None: none), then quintic-spline derivatives.
    All other channels (or those named in ``signals``) are passed as signals.  On an exact OpenSim
    import, the coordinates the trial leaves out are filled as :func:`source_coordinate_gaps` says
    (``missing_coordinates``).  Analyses use :func:`prepare`, which adds the external loads.
    """
    return _motion(model, trial, cutoff=cutoff, signals=signals, missing_coordinates=missing_coordinates)[0]


def _motion(model, trial, *, cutoff, signals=None, missing_coordinates="refuse",
            method: str = "butterworth") -> tuple[Motion, tuple[str, ...]]:
    """:func:`motion` and the notes on the OpenSim coordinates it filled or replaced (for :func:`prepare`)."""
    cmap = coordinate_map(model)
    check_coordinate_columns(model, trial)
    notes: tuple[str, ...] = ()
    if cmap is None:
        missing = [c for c in model.coordinates if c not in trial]
        if missing:
            try:
                trial.require(model.coordinates)
            except TrialError as exc:
                raise TrialError(f"{exc}; {map_hint(trial, missing)}") from None
        q, v, a = trial.kinematics(model.coordinates, cutoff=cutoff_value(cutoff), method=method)
        measured = model.coordinates
    else:
        # dependent joints (an exact OpenSim import): the trial holds OpenSim's coordinates, which are
        # filtered and differentiated, then mapped: q_pin = f(q), v_pin = J v, a_pin = J a + dJ v
        measured = cmap.osim_coordinates
        fill, notes = source_coordinate_gaps(model, trial, missing_coordinates=missing_coordinates)
        source = trial.with_channels({c: np.full(trial.n_frames, x) for c, x in fill.items()}) if fill else trial
        q, v, a, q_os = _expand_rows(cmap, *source.kinematics(measured, cutoff=cutoff_value(cutoff), method=method))
        notes = _coupler_notes(cmap, trial, q_os) + notes
    names = [n for n in trial.names if n not in measured] if signals is None else list(signals)
    sig = {n: trial[n] for n in names}
    if cmap is not None:
        # OpenSim coordinates that drive only dependent joints are no column of q: they ride along as
        # (filtered) signals, with the couplers applied (the angles the joints were mapped at), so
        # moments map back at the same coordinates (source_coordinates)
        sig.update({c: q_os[:, i] for i, c in enumerate(measured) if c not in model.coordinates})
    return Motion(np.asarray(trial.time, dtype=float), q, v, a, sig), notes


#: Frames a coordinate map expands at a time (its intermediate arrays are several times the result's).
EXPAND_ROWS = 20000


def _expand_rows(cmap, q_os, v_os, a_os):
    """``cmap.expand(q_os, v_os, a_os, with_source=True)`` (the map is per frame), :data:`EXPAND_ROWS`
    frames at a time into arrays of the whole motion, made read-only (a Motion keeps them uncopied)."""
    n = q_os.shape[0]
    if n <= EXPAND_ROWS:
        out = cmap.expand(q_os, v_os, a_os, with_source=True)
    else:
        out = None
        for k in range(0, n, EXPAND_ROWS):
            part = cmap.expand(q_os[k:k + EXPAND_ROWS], v_os[k:k + EXPAND_ROWS], a_os[k:k + EXPAND_ROWS],
                               with_source=True)
            if out is None:
                out = tuple(np.empty((n,) + np.shape(p)[1:]) for p in part)
            for o, p in zip(out, part):
                o[k:k + EXPAND_ROWS] = p
    out = tuple(np.require(x, dtype=float, requirements="CO") for x in out)
    for x in out:
        x.flags.writeable = False
    return out


def _coupler_notes(cmap, trial, q_os: np.ndarray) -> tuple[str, ...]:
    """A note for each coupled coordinate whose values in the trial the coupler replaced (by > 1e-6);
    ``q_os`` the OpenSim coordinates as mapped."""
    out = []
    for dep, indep, _, _ in cmap.couplers:
        if dep in trial:
            mapped = q_os[:, cmap.osim_coordinates.index(dep)]
            dev = float(np.max(np.abs(np.asarray(trial[dep], dtype=float) - mapped), initial=0.0))
            if dev > 1e-6:
                out.append(f"{dep}: the trial's values replaced by its CoordinateCouplerConstraint's on "
                           f"{', '.join(indep)} (they differed by up to {dev:.3g})")
    return tuple(out)


def coordinate_map(model):
    """The model's map from its source's coordinates to its joints (``model.meta['coordinate_map']``,
    a :class:`pinmsk.opensim.skeleton.CoordinateMap`), or None when every joint is a coordinate."""
    cmap = model.meta.get("coordinate_map")
    return None if cmap is None or cmap.identity else cmap


def source_coordinates(model, motion: Motion, tau: np.ndarray) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """``(names, q, tau)`` per coordinate of the model's source (OpenSim's coordinates of an exact import:
    ``tau = J^T tau_pin`` by virtual work), or the model's own coordinates and arrays without a map.

    Coupled coordinates keep their own generalized force (``couplers=False``), as OpenSim's ID reports
    them (it ignores constraints)."""
    cmap = coordinate_map(model)
    if cmap is None:
        idx = [model.coordinate_index(c) for c in model.coordinate_order]
        return model.coordinate_order, motion.q[:, idx], tau[:, idx]
    q = source_positions(model, motion)
    return cmap.osim_coordinates, q, cmap.generalized_forces(q, tau, couplers=False)


def source_positions(model, motion: Motion) -> np.ndarray:
    """OpenSim's coordinates ``(N, n_osim)`` (:attr:`CoordinateMap.osim_coordinates` order) of a motion of a model
    with a coordinate map: the joints that are coordinates from ``q``, the others from the motion's signals
    (:func:`motion` keeps them there, couplers applied) or their welded or default values."""
    cmap = coordinate_map(model)
    # the coordinates that are joints in one gather; the others from the motion's signals or their values
    q = np.empty((motion.n_frames, len(cmap.osim_coordinates)))
    joints = [(i, model.coordinate_index(c)) for i, c in enumerate(cmap.osim_coordinates) if c in model.coordinates]
    if joints:
        q[:, [i for i, _ in joints]] = motion.q[:, [k for _, k in joints]]
    for i, c in enumerate(cmap.osim_coordinates):
        if c not in model.coordinates:
            q[:, i] = motion.signals[c] if c in motion.signals else cmap.welded.get(c, cmap.defaults[c])
    return q


def independent_coordinates(model) -> tuple[str, ...]:
    """The coordinates whose generalized forces are the model's independent equations of motion: its own
    coordinates, or, with a coordinate map (an exact OpenSim import), OpenSim's coordinates that are neither
    welded nor set by an enforced CoordinateCouplerConstraint.  A coupled coordinate is no degree of freedom:
    by virtual work its generalized force reaches its independent coordinates through the coupler's slope
    (``J^T`` with the couplers applied, the equations static optimization balances), which is what an
    actuator there (a dynamometer, the muscles) has to supply."""
    cmap = coordinate_map(model)
    if cmap is None:
        return tuple(model.coordinates)
    coupled = {dep for dep, *_ in cmap.couplers}
    return tuple(c for c in cmap.osim_coordinates if c not in cmap.welded and c not in coupled)


def trial_coordinates(model) -> tuple[str, ...]:
    """The coordinates a trial of ``model`` gives: OpenSim's (not welded) for a model with a coordinate map,
    else the model's own (:attr:`~pinmsk.Model.coordinate_order`)."""
    cmap = coordinate_map(model)
    if cmap is None:
        return tuple(model.coordinate_order)
    return tuple(c for c in cmap.osim_coordinates if c not in cmap.welded)


def actuated_forces(model, motion: Motion, tau: np.ndarray) -> np.ndarray:
    """The generalized forces ``(N, nv)`` actuators supply for Pinocchio's ``tau`` (N, nv), in the model's joint
    columns: ``tau`` itself without a coordinate map; with one (an exact OpenSim import), each OpenSim
    coordinate's force ``J^T tau`` (:func:`source_coordinates`) at its joint and 0 at the dependent joints,
    which no actuator drives (their share of the load reaches the coordinates by virtual work).  What muscles
    and reserves balance (static optimization) is this.  A map whose coordinates drive only dependent joints
    (Rajagopal's patella angle ``knee_angle_r_beta``) has no column for their force: ModelError naming them."""
    cmap = coordinate_map(model)
    if cmap is None:
        return tau
    names, _, tau_os = source_coordinates(model, motion, tau)
    lost = [c for c in names if c not in model.coordinates and c not in cmap.welded]
    if lost:
        raise ModelError(f"model '{model.name}': coordinate(s) {', '.join(lost)} drive only dependent joints, so "
                         "their generalized force has no joint column here; this analysis cannot balance "
                         "them (inverse_dynamics reports them; or import the model with nonlinear='fit')")
    out = np.zeros_like(np.asarray(tau, dtype=float))
    for i, c in enumerate(names):
        if c in model.coordinates:
            out[:, model.coordinate_index(c)] = tau_os[:, i]
    return out


def require_independent_joints(model, what: str) -> None:
    """ModelError if ``model`` has dependent joints (a coordinate map): ``what`` (an analysis that integrates
    or moves the Pinocchio joints independently) cannot hold them."""
    cmap = coordinate_map(model)
    if cmap is None:
        return
    deps = list(cmap.dependent)
    raise ModelError(
        f"{what} moves the Pinocchio joints of model '{model.name}' independently, but {len(deps)} of them "
        f"({', '.join(deps[:4])}{' ...' if len(deps) > 4 else ''}) are dependent joints, functions of OpenSim's "
        "coordinates (an exact import of nonlinear joint axes), which it cannot hold; load the .osim with "
        "nonlinear='fit' (command line: --nonlinear fit; the fitted joints' errors are in the import report)")


def check_coordinate_columns(model, trial) -> None:
    """TrialError naming each column of a coordinates file (OpenSim's ``Coordinates`` tables: IK output) that
    is not a coordinate of ``model``, with the closest model coordinates (a coordinate the model lacks is an
    input that would otherwise be dropped).  Speeds and accelerations of the model's coordinates, and trials
    a channel map made (which chose their columns), are not checked."""
    meta = getattr(trial, "meta", {}) or {}
    if meta.get("name") != "Coordinates" or meta.get("channel_map"):
        return
    from .trial import close_matches
    offered = trial_coordinates(model)
    full = model.meta.get("coordinate_map")        # an OpenSim import's: welded coordinates are known too
    have = set(offered) | set(getattr(full, "osim_coordinates", ())) | set(model.coordinates)
    unknown = []
    for n in trial.names:
        base = n.split("/")[-2] if n.startswith("/") and n.count("/") >= 3 else n
        if base in have or _DERIVATIVE.sub("", base) in have:
            continue
        unknown.append((n, close_matches(base, offered)))
    if unknown:
        parts = [f"'{n}'" + (f" (did you mean {' or '.join(map(repr, hint))}?)" if hint else "")
                 for n, hint in unknown]
        src = meta.get("source", "the trial")
        raise TrialError(f"{src}: column(s) {', '.join(parts)} of the coordinates file are not coordinates of "
                         f"model '{model.name}' ({', '.join(offered)}); rename them (--map) or "
                         "drop them (Trial.drop) if the model does not have them")


_DERIVATIVE = re.compile(r"_(?:speed|u|acceleration|accel)$")


def first_non_finite(x: np.ndarray) -> tuple[int, int] | None:
    """``(frame, column)`` of the first NaN or infinity of a time-first ``(N, k)`` array, or None."""
    bad = ~np.isfinite(x)
    if not bad.any():
        return None
    k, j = np.argwhere(bad)[0]
    return int(k), int(j)


def as_motion(model, data, cutoff=DEFAULT_CUTOFF) -> Motion:
    """A :class:`Motion` of the model from a Trial (by :func:`motion`) or a Motion, checked:
    its width is the model's, it has frames, and q, v, a are finite (the frame and
    coordinate of the first bad value are named)."""
    if isinstance(data, Motion):
        mo = data
        if mo.q.shape[1] != model.nv:
            raise TrialError(f"the motion has {mo.q.shape[1]} coordinates; model "
                             f"'{model.name}' has {model.nv} ({', '.join(model.coordinates)})")
    elif isinstance(data, Trial):
        mo = motion(model, data, cutoff=cutoff)
    else:
        raise TrialError(f"expected a Trial or a Motion, got {type(data).__name__}")
    if mo.n_frames == 0:
        raise TrialError("the trial has no frames; an analysis needs at least one")
    for name in ("q", "v", "a"):
        where = first_non_finite(getattr(mo, name))
        if where is not None:
            k, j = where
            raise TrialError(f"the motion's {name} is not finite at frame {k} (t = {mo.t[k]:.6g} s), "
                             f"coordinate '{model.coordinates[j]}'; fill or cut the gaps first")
    return mo


GRF_CUTOFF_MODES = ("auto", "same")


def _grf_cutoff(grf_cutoff, cutoff, external_loads) -> tuple[float | None, str]:
    """The GRF low-pass of :func:`prepare` and the convention that chose it (see its ``grf_cutoff``)."""
    if isinstance(grf_cutoff, str):
        if grf_cutoff not in GRF_CUTOFF_MODES:
            raise TrialError(f"grf_cutoff must be a frequency in Hz or one of {', '.join(GRF_CUTOFF_MODES)}; "
                             f"got {grf_cutoff!r}")
        if grf_cutoff == "auto" and external_loads is not None:
            return None, ("OpenSim's ExternalLoads convention: coordinates filtered and loads applied "
                          "unfiltered, as its ID tool does; --grf-cutoff HZ to filter both with pinmsk's filter")
        return cutoff, ""
    return cutoff_value(grf_cutoff), ""


def coordinate_filter(grf_cutoff, external_loads) -> str:
    """The coordinates' low-pass of :func:`prepare`: OpenSim's ID tool's under OpenSim's ExternalLoads
    convention (``grf_cutoff="auto"`` with an ExternalLoads file), else pinmsk's Butterworth."""
    return "opensim" if (isinstance(grf_cutoff, str) and grf_cutoff == "auto" and external_loads is not None) \
        else "butterworth"


def prepare(model, trial, *, cutoff=DEFAULT_CUTOFF, grf: Trial | str | Path | None = None,
            external_loads=None, frames=None, ground_reaction: str = "auto",
            grf_cutoff="auto", missing_coordinates: str = "refuse") -> TrialInputs:
    """A trial (or a Motion) made ready for analysis; see the module docstring.

    Parameters (keyword-only after ``trial``)
    -----------------------------------------
    cutoff : float or None
        Low-pass cut-off (Hz) of the coordinates and the GRF; 0 or None: no filter.
    grf : Trial or path, optional
        Ground reaction forces at their own rate (instead of the trial's own channels).
    external_loads : ExternalLoads or path, optional
        An OpenSim ExternalLoads ``.xml``: which columns act on which body; its
        ``datafile`` is read unless ``grf`` is given.
    frames : mapping, optional
        Side or ExternalForce name -> body, overriding the automatic choice.
    ground_reaction : "auto" | "ignore"
        "ignore" leaves all GRF out on purpose (recorded in the metadata).
    grf_cutoff : "auto", "same" or float
        Low-pass of the GRF.  "same": the kinematics' ``cutoff`` (the consistent choice for
        a plain trial).  "auto" (default): "same", except when the loads come from an OpenSim
        ExternalLoads file, which follows OpenSim's convention: its ID tool applies the loads
        unfiltered and filters the coordinates its own way (:func:`coordinate_filter`,
        :func:`~pinmsk.signals.filtering.lowpass_opensim`), so the plain command reproduces OpenSim's
        results; :class:`Filtering` says which convention ran.  0 leaves the GRF unfiltered.
    missing_coordinates : "refuse" | "default"
        An exact OpenSim import's coordinate the trial leaves out (not locked, not coupled):
        refused by name, or held at its default value as OpenSim's ID tool does
        (:func:`source_coordinate_gaps`; each filled coordinate is noted).
    """
    if ground_reaction not in GROUND_REACTION_MODES:
        raise TrialError(f"ground_reaction must be one of {', '.join(GROUND_REACTION_MODES)}; "
                         f"got {ground_reaction!r}")
    c = cutoff_value(cutoff)
    gc, convention = _grf_cutoff(grf_cutoff, c, external_loads)
    if isinstance(trial, TrialInputs):
        return trial
    if isinstance(trial, Motion):
        if grf is not None or external_loads is not None:
            raise TrialError("a Motion carries no time-aligned GRF source; pass a Trial with grf=/external_loads=")
        if trial.q.shape[1] != model.nv:
            raise TrialError(f"the motion has {trial.q.shape[1]} coordinates; model '{model.name}' has "
                             f"{model.nv} ({', '.join(model.coordinates)})")
        return TrialInputs(trial, (), (), Filtering(None), ("a Motion was given: no filter applied",))
    if not isinstance(trial, Trial):
        raise TrialError(f"expected a Trial or a Motion, got {type(trial).__name__}")
    method = coordinate_filter(grf_cutoff, external_loads)
    mo, gap_notes = _motion(model, trial, cutoff=c, missing_coordinates=missing_coordinates, method=method)
    if external_loads is not None and not hasattr(external_loads, "loads"):
        external_loads = read_external_loads(external_loads)
    own = has_ground_reaction(trial)
    source = None
    if ground_reaction == "ignore":
        notes = ("ground reaction: left out on request (ground_reaction='ignore')",) if (
            own or grf is not None or external_loads is not None) else ()
        return TrialInputs(mo, (), (), Filtering(c, grf_cutoff=gc, method=method), gap_notes + notes)
    if grf is None and external_loads is not None and external_loads.datafile is not None and not own:
        grf = external_loads.datafile
    if grf is not None and own:
        raise TrialError("the trial has ground reaction channels and a separate GRF source was given "
                         f"({grf if not isinstance(grf, Trial) else 'grf='}); pass only one")
    if isinstance(grf, (str, Path)):
        source = str(grf)
        grf = read_trial(grf)
    elif grf is not None:
        source = grf.meta.get("source", "grf trial")
    if grf is None and not own:
        return TrialInputs(mo, (), (), Filtering(c, grf_cutoff=gc, method=method), gap_notes)
    data = grf if grf is not None else trial
    planar = is_planar(model)
    if external_loads is not None or model.nq != model.nv:
        q_g = None          # an ExternalLoads file names each load's body: no foot search, no poses needed
    elif grf is not None:
        tg = np.asarray(grf.time, dtype=float)
        q_g = np.column_stack([np.interp(tg, mo.t, mo.q[:, j]) for j in range(model.nq)])
    else:
        q_g = mo.q
    try:
        plist, ext = _plate_loads(model, data, mo, cutoff=gc, external_loads=external_loads, frames=frames,
                                  planar=planar, q_on_grf_time=q_g, same_time=grf is None)
    except ModelError as exc:
        raise TrialError(f"ground reaction: {exc}") from None
    notes = list(gap_notes)
    if planar:
        dropped = [n for p in plist for (kind, a), n in p.columns.items()
                   if (kind in ("force", "point") and a == "z") or (kind == "torque" and a in "xy")]
        if dropped and any(np.any(np.abs(np.asarray(data[n])) > 0) for n in dropped):
            notes.append(f"planar model: out-of-plane GRF components ({', '.join(dropped)}) cannot act "
                         "on it and were left out")
    filtering = Filtering(c, grf_cutoff=gc, has_grf=True, grf_convention=convention, method=method)
    return TrialInputs(mo, ext, plist, filtering, tuple(notes), source)
