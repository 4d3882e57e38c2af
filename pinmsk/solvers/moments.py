"""The moments a muscle-redundancy solver balances, and the coordinates muscles cannot reach.

SO and FSO share this step (:func:`plan_moments`):

* **Which moments.** ``moments="id"`` (default): inverse dynamics of the
  prepared trial (:func:`pinmsk.kinematics.prepare`: filtered coordinates, the
  trial's ground reaction forces on the feet, the model's effects).
  ``moments="measured"``: the trial's own ``<coord>_moment`` channels (from a
  dynamometer or another pipeline), low-passed at the same cut-off as the
  kinematics.  A Trial or an array: those values.  A trial that carries
  measured moments while inverse-dynamics moments are balanced gets a note
  saying so, never a silent choice.
* **Which coordinates.** The equations are those of the model's *source*
  coordinates (:func:`balance_space`): the model's own, or, for an exact OpenSim
  import with dependent joints, OpenSim's independent coordinates (generalized
  forces mapped by virtual work, ``tau = J^T tau_pin``; coupled coordinates
  follow their independent ones, as OpenSim's static optimization balances the
  unconstrained coordinates only).  The default balances the coordinates at least one
  muscle (or one of the actuators given) spans.  Every other coordinate (a floating base, a joint without
  muscles) is *unspanned*: the force it needs is reported.  If any of them
  needs a force (above a round-off tolerance) and the solver has no reserves,
  that is an :class:`~pinmsk.errors.InfeasibleError` naming each coordinate
  and its peak; with reserves, the needed force *is* the reserve (no muscle
  can share it), reported as a table.  Passing ``dofs=`` explicitly balances
  those coordinates only; the rest are reported as left out by request.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..components import Motion
from ..dynamics import inverse_dynamics_array
from ..errors import InfeasibleError, TrialError
from ..kinematics import TrialInputs, coordinate_map, first_non_finite
from ..signals.filtering import lowpass
from ..signals.sampling import median_step
from ..trial import Trial, moment_channels

__all__ = ["MomentPlan", "BalanceSpace", "balance_space", "plan_moments", "required_moments", "spanned_coordinates",
           "MOMENT_SOURCES", "without_actuators"]

MOMENT_SOURCES = ("id", "measured")
#: An unspanned coordinate needing less than this (N or N m) needs nothing (round-off).
ZERO_FORCE = 1e-6


def spanned_coordinates(muscles, q: np.ndarray, *, chunk: int = 20000, space=None) -> np.ndarray:
    """(nv,) bool: coordinates with a non-zero moment arm of some muscle at some frame (``(ns,)`` of the
    coordinates of ``space``, a :class:`BalanceSpace`, when given)."""
    q = np.asarray(q, dtype=float)
    out = None
    for k in range(0, max(q.shape[0], 1), chunk):
        R = np.asarray(muscles.moment_arms(q[k:k + chunk]), dtype=float)
        if space is not None:
            R = space.arms(R, slice(k, k + chunk))
        s = np.any(np.abs(R) > 0, axis=(0, 1))
        out = s if out is None else (out | s)
    return out


#: Frames of a coordinate map's Jacobian built at a time (:meth:`BalanceSpace.forces`, :meth:`BalanceSpace.arms`).
ROWS = 20000


class BalanceSpace:
    """The coordinates whose equations a solver balances, and the map to them from the model's.

    ``names`` (ns,); ``model_columns`` (ns,) each one's column in the model's ``q`` (-1 if it is no
    joint of the model); without a coordinate map the model's own coordinates (identity).  With one
    (:func:`pinmsk.kinematics.coordinate_map`), generalized forces map by ``J^T`` with ``J = d q_model /
    d q_source`` (N, nv, ns), computed per rows of the motion (:meth:`jacobian`).
    """

    def __init__(self, names, model_columns, rotational, *, cmap=None, q_source=None):
        self.names = tuple(names)
        self.model_columns = np.asarray(model_columns, dtype=int)
        self.rotational = tuple(rotational)
        self._cmap = cmap
        self._q = q_source       # {source coordinate: (N,)}
        self._cols = None if cmap is None else [cmap.osim_coordinates.index(c) for c in self.names]

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def identity(self) -> bool:
        return self._cmap is None

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            import difflib
            close = difflib.get_close_matches(str(name), self.names, n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise TrialError(f"no coordinate '{name}' to balance{hint} (coordinates: {', '.join(self.names)})") \
                from None

    def jacobian(self, rows=slice(None)) -> np.ndarray | None:
        """``d q_model / d q_space`` (n, nv, ns) of the frames ``rows``; None for the identity."""
        if self._cmap is None:
            return None
        J = self._cmap.jacobian({c: np.asarray(v)[rows] for c, v in self._q.items()}, couplers=True)
        return J[:, :, self._cols]

    def forces(self, tau: np.ndarray, rows=slice(None)) -> np.ndarray:
        """Generalized forces (n, nv) of the model -> (n, ns) of the space (``J^T tau``)."""
        if self._cmap is None:
            return np.asarray(tau)
        return self._mapped(tau, rows, "njs,nj->ns")

    def arms(self, R: np.ndarray, rows=slice(None)) -> np.ndarray:
        """Columns (n, k, nv) of generalized force per unit (moment arms, actuator columns) -> (n, k, ns)."""
        if self._cmap is None:
            return np.asarray(R)
        return self._mapped(R, rows, "njs,nkj->nks")

    def _mapped(self, X: np.ndarray, rows, spec: str) -> np.ndarray:
        """``einsum(spec, J, X)`` of the frames ``rows``, the Jacobian built :data:`ROWS` frames at a time
        (it is ``nv * ns`` numbers a frame: a long motion's whole would dwarf the result)."""
        X = np.asarray(X)
        if not isinstance(rows, slice) or X.shape[0] <= ROWS:
            return np.einsum(spec, self.jacobian(rows), X)
        frames = np.arange(self._n_frames())[rows]
        out = None
        for k in range(0, frames.size, ROWS):
            part = frames[k:k + ROWS]
            y = np.einsum(spec, self.jacobian(slice(int(part[0]), int(part[-1]) + 1, rows.step)), X[k:k + ROWS])
            if out is None:
                out = np.empty((frames.size,) + y.shape[1:])
            out[k:k + ROWS] = y
        return out

    def _n_frames(self) -> int:
        return next(iter(np.shape(v)[0] for v in self._q.values()))


def without_actuators(model):
    """``model`` without its actuator components (kind ``"actuator"``): the skeleton whose inverse dynamics
    the actuators (and muscles) balance."""
    for c in model.components:
        if c.kind == "actuator":
            model = model.without(c.label)
    return model


def balance_space(model, motion: Motion) -> BalanceSpace:
    """The :class:`BalanceSpace` of ``model`` on ``motion``: its own coordinates, or, with dependent joints
    (an exact OpenSim import), OpenSim's coordinates other than the dependent ones of enforced couplers."""
    cmap = coordinate_map(model)
    rot = model.rotational_coordinates
    if cmap is None:
        return BalanceSpace(model.coordinates, np.arange(model.nv), rot)
    coupled = {dep for dep, *_ in cmap.couplers}
    names = [c for c in cmap.osim_coordinates if c not in coupled and c not in cmap.welded]
    q = {}
    for c in cmap.osim_coordinates:
        if c in model.coordinates:
            q[c] = motion.q[:, model.coordinate_index(c)]
        elif c in motion.signals:
            q[c] = motion.signals[c]
    motion_types = (model.meta.get("osim_motion_types") or {})
    rot = tuple(c for c in names if (c in rot) or motion_types.get(c) == "Rotational")
    cols = [model.coordinate_index(c) if c in model.coordinates else -1 for c in names]
    return BalanceSpace(names, cols, rot, cmap=cmap, q_source=q)


@dataclass(frozen=True)
class MomentPlan:
    """What a solver balances: the dofs, their moments, and what is left at the other coordinates."""

    source: str                        # "inverse dynamics ..." / "measured <coord>_moment channels" / "given"
    dofs: tuple[str, ...]              # balanced coordinates
    tau: np.ndarray                    # (N, nd) moments to balance
    unspanned: tuple[str, ...]         # coordinates no muscle spans (not balanced)
    unspanned_tau: np.ndarray          # (N, nu) force they need (NaN where unknown)
    by_request: bool                   # dofs= given: the others are left out on purpose
    tau_full: np.ndarray | None        # (N, nv) inverse dynamics, when computed
    notes: tuple[str, ...] = ()

    def needing(self) -> list[tuple[str, float, int]]:
        """``(coordinate, peak, frame of the peak)`` of unspanned coordinates that need a force."""
        out = []
        for j, c in enumerate(self.unspanned):
            x = np.abs(self.unspanned_tau[:, j])
            if np.isfinite(x).any() and np.nanmax(x) > ZERO_FORCE:
                k = int(np.nanargmax(x))
                out.append((c, float(x[k]), k))
        return out

    def table_lines(self, time, rotational) -> list[str]:
        """Lines: each unspanned coordinate, the force it needs (peak, RMS) and where."""
        lines = []
        for j, c in enumerate(self.unspanned):
            x = self.unspanned_tau[:, j]
            unit = "N*m" if c in rotational else "N"
            if not np.isfinite(x).any():
                lines.append(f"  {c:<14} not known (no measured {c}_moment)")
                continue
            k = int(np.nanargmax(np.abs(x)))
            rms = float(np.sqrt(np.nanmean(x ** 2)))
            lines.append(f"  {c:<14} peak {abs(x[k]):10.4g} {unit:<4} (t = {time[k]:.4g} s)  rms {rms:10.4g} {unit}")
        return lines


def _measured(model, trial: Trial, motion: Motion, coords, cutoff) -> np.ndarray:
    cols = moment_channels(coords)
    missing = [c for c in cols if c not in trial]
    if missing:
        raise TrialError(f"moments='measured' needs the trial's {', '.join(missing)} channel(s); it has "
                         f"{', '.join(n for n in trial.names if n.endswith('_moment')) or 'no _moment channels'}")
    tau = np.column_stack([np.asarray(trial[c], dtype=float) for c in cols])
    where = first_non_finite(tau)
    if where is not None:
        k, j = where
        raise TrialError(f"measured moment {cols[j]!r} is {tau[k, j]!r} at row {k} (t = {motion.t[k]:.6g} s)")
    if cutoff is not None:
        tau = lowpass(tau, rate=1.0 / median_step(motion.t), cutoff=cutoff)
    return tau


def plan_moments(model, trial, inputs: TrialInputs, *, moments=None, dofs=None, reserves: bool = False,
                 what: str = "static optimization", space: BalanceSpace | None = None,
                 actuator_arms: np.ndarray | None = None) -> MomentPlan:
    """Decide the balanced dofs and their moments (see the module docstring).

    ``space``: the :class:`BalanceSpace` (default the model's own coordinates); ``actuator_arms``
    (N, na, ns): the generalized-force columns of the actuators in it, whose coordinates count as
    spanned (a residual actuator on the pelvis lets the pelvis be balanced)."""
    motion = inputs.motion
    space = BalanceSpace(model.coordinates, np.arange(model.nv), model.rotational_coordinates) \
        if space is None else space
    spanned = spanned_coordinates(model.muscles, motion.q, space=space)
    if actuator_arms is not None and actuator_arms.size:
        spanned = spanned | np.any(np.abs(actuator_arms) > 0, axis=(0, 1))
    coords = space.names
    if dofs is None:
        idx = np.flatnonzero(spanned)
        by_request = False
    else:
        names = [dofs] if isinstance(dofs, str) else list(dofs)
        idx = np.array([space.index(d) for d in names], dtype=int)
        if len(set(idx.tolist())) != idx.size:
            raise TrialError(f"dofs lists a coordinate twice: {names}")
        by_request = True
    rest = np.array([j for j in range(space.n) if j not in set(idx.tolist())], dtype=int)
    notes = []
    tau_full = None
    src = moments if moments is not None else "id"
    if isinstance(src, str):
        if src not in MOMENT_SOURCES:
            raise TrialError(f"moments must be one of {', '.join(MOMENT_SOURCES)}, a Trial or an array; got {src!r}")
        if src == "measured":
            if not isinstance(trial, Trial):
                raise TrialError("moments='measured' needs a Trial with <coord>_moment channels")
            tau = _measured(model, trial, motion, [coords[j] for j in idx], inputs.filtering.cutoff)
            have = [j for j in rest if moment_channels([coords[j]])[0] in trial]
            un = np.full((motion.n_frames, rest.size), np.nan)
            if have:
                vals = _measured(model, trial, motion, [coords[j] for j in have], inputs.filtering.cutoff)
                for col, j in enumerate(have):
                    un[:, list(rest).index(j)] = vals[:, col]
            source = "measured <coord>_moment channels of the trial" + (
                f", low-passed at {inputs.filtering.cutoff:g} Hz" if inputs.filtering.cutoff else "")
        else:
            # the actuators are what the moments are for: none of their force is taken out first
            # Pinocchio's tau of every joint: the balance space maps it to the coordinates (J^T tau) itself
            tau_full = inverse_dynamics_array(without_actuators(model), motion, external=inputs.external,
                                              actuated=False)
            tau_space = space.forces(tau_full)
            tau = tau_space[:, idx]
            un = tau_space[:, rest]
            loads = "with the trial's ground reaction forces" if inputs.external else "without external loads"
            comps = [c.label for c in model.components if c.kind != "actuator"]
            source = f"inverse dynamics {loads}" + (
                f" and the model's components ({', '.join(comps)})" if comps else "")
            if not space.identity:
                source += " (OpenSim's coordinates: tau = J^T tau of the dependent joints)"
            if isinstance(trial, Trial):
                measured = [n for n in trial.names if n.endswith("_moment")]
                if measured:
                    notes.append(f"the trial's measured {', '.join(measured[:4])}{' ...' if len(measured) > 4 else ''} "
                                 "were not balanced (inverse dynamics was); pass moments='measured' "
                                 "(CLI --moments measured) to balance them")
    else:
        dof_names = tuple(coords[j] for j in idx)
        tau = required_moments(model, motion, moments, idx, dof_names, width=space.n)
        # what the given moments ask of the unspanned coordinates, where they say it
        un = np.full((motion.n_frames, rest.size), np.nan)
        if isinstance(moments, Trial):
            for col, j in enumerate(rest):
                name = moment_channels([coords[j]])[0]
                if name in moments and moments.n_frames == motion.n_frames:
                    un[:, col] = np.asarray(moments[name], dtype=float)
        elif np.ndim(moments) == 2 and np.shape(moments)[1] == space.n and space.n != idx.size:
            un = np.asarray(moments, dtype=float)[:, rest]
        source = "given by the caller"
    plan = MomentPlan(source, tuple(coords[j] for j in idx), np.ascontiguousarray(tau),
                      tuple(coords[j] for j in rest), un, by_request, tau_full, tuple(notes))
    need = plan.needing()
    if need and not reserves and not by_request:
        parts = ", ".join(f"{c} (peak {pk:.4g} {'N*m' if c in space.rotational else 'N'} at "
                          f"t = {motion.t[k]:.4g} s)" for c, pk, k in need)
        raise InfeasibleError(
            f"no muscle{' or actuator' if actuator_arms is not None and actuator_arms.shape[1] else ''} spans "
            f"{', '.join(c for c, _, _ in need)}, but the motion needs a force there: {parts}. "
            f"{what.capitalize()} cannot balance them; pass reserves=True (CLI --reserves) to give them ideal "
            "actuators (their use is reported), actuators= (CLI --actuators FILE.xml: OpenSim's residual and "
            "reserve actuators), or dofs=[...] to balance only the muscle-spanned coordinates"
            + ("" if inputs.external else "; a floating base without ground reaction forces is in free fall: "
               "give the trial's GRF"))
    return plan


def required_moments(model, motion: Motion, moments, idx, dofs, *, width: int | None = None) -> np.ndarray:
    """Moments (N, nd) to balance: given (Trial or array) or by inverse dynamics.  ``width``: the number
    of coordinates a full array has (default the model's ``nv``)."""
    n = motion.n_frames
    nv = model.nv if width is None else int(width)
    if moments is None:
        tau = inverse_dynamics_array(model, motion)[:, idx]
    elif isinstance(moments, Trial):
        if moments.n_frames != n:
            raise TrialError(f"the moments trial has {moments.n_frames} frames; the motion has {n}")
        cols = list(moment_channels(dofs))
        missing = [c for c in cols if c not in moments]
        if missing:
            raise TrialError(f"the moments trial lacks {', '.join(missing)} "
                             f"(it has {', '.join(moments.names)})")
        tau = np.column_stack([np.asarray(moments[c], dtype=float) for c in cols])
    else:
        tau = np.asarray(moments, dtype=float)
        if tau.ndim == 1 and len(idx) == 1:
            tau = tau[:, None]
        if tau.ndim != 2 or tau.shape[0] != n:
            raise TrialError(f"moments must be (N, nv) or (N, n_dofs) with N = {n}; got {tau.shape}")
        if tau.shape[1] == nv and tau.shape[1] != len(idx):
            tau = tau[:, idx]
        elif tau.shape[1] != len(idx):
            raise TrialError(f"moments has {tau.shape[1]} columns; expected {nv} (all "
                             f"coordinates) or {len(idx)} (the dofs {', '.join(dofs)})")
    where = first_non_finite(tau)
    if where is not None:
        k, j = where
        raise TrialError(f"the moment of '{dofs[j]}' is not finite at frame {k} "
                         f"(t = {motion.t[k]:.6g} s); check the trial and its inverse dynamics")
    return tau
