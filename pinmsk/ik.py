"""Inverse kinematics from markers: weighted least squares per frame.

For each frame k, the coordinates minimise

    sum_m  w_m || P_a (x_m(q) - y_m[k]) ||^2

where ``x_m(q)`` is model marker m (a point fixed in a body, from a
:class:`pinmsk.markers.MarkerSet`), ``y_m[k]`` the measured position, ``P_a``
keeps the measured axes (``"xy"`` for sagittal data, ``"xyz"`` for 3-D) and
``w_m`` the marker weight.  A marker that is NaN in a frame has zero weight
there (gaps that :func:`pinmsk.signals.gaps.fill_gaps` did not fill).

The solver is Levenberg-Marquardt on the Gauss-Newton normal equations with
Pinocchio frame Jacobians (``LOCAL_WORLD_ALIGNED``: the linear rows are the
marker point's world velocity Jacobian), warm-started from the previous
frame's solution, so after the first frame it typically converges in 2-3
iterations.  Coordinates that no marker moves are held at ``q0``.

:class:`InverseKinematics` is a :class:`~pinmsk.fitting.Fitter`: ``fit(model, markers)``
returns self; ``result_`` (a :class:`~pinmsk.fitting.Result`: the Trial of coordinates
in ``model.coordinate_order`` and the statistics of the weighted marker residuals),
``marker_rms_`` (per-marker RMS error over frames, m), ``frame_rms_`` (per-frame RMS
over markers, m), ``iterations_`` and ``converged_`` (per frame).

A model with dependent joints (an exact OpenSim import, ``pinmsk.kinematics.coordinate_map``)
is solved in OpenSim's coordinates: the joints follow by the map and the marker Jacobians by
its chain rule; coupled coordinates take their couplers' values, as OpenSim's IK enforces
them.  The result's channels are then OpenSim's coordinates (``q_`` stays Pinocchio's).
"""
from __future__ import annotations

import difflib
from typing import Sequence

import numpy as np
import pinocchio as pin

from .errors import ConvergenceError, ModelError, TrialError
from .fitting import FitStatistics, Fitter, Result, format_report
from .kinematics import coordinate_map, trial_coordinates
from .markers import MarkerSet, load_marker_set
from .trial import Trial, marker_array, marker_names

__all__ = ["InverseKinematics", "inverse_kinematics", "model_marker_positions", "add_marker_frames"]


def add_marker_frames(model, markers: MarkerSet) -> tuple[pin.Model, list[int]]:
    """A copy of the Pinocchio model with one OP_FRAME per marker; returns (model, frame ids)."""
    pm = pin.Model(model.pin if hasattr(model, "pin") else model)
    ids = []
    for m in markers.markers:
        if not pm.existFrame(m.body):
            close = difflib.get_close_matches(m.body, [f.name for f in pm.frames], n=3)
            raise ModelError(f"marker {m.name!r}: the model has no body/frame {m.body!r}"
                             + (f"; did you mean {', '.join(map(repr, close))}?" if close else ""))
        parent_id = pm.getFrameId(m.body)
        parent = pm.frames[parent_id]
        placement = parent.placement * pin.SE3(np.eye(3), np.asarray(m.position, dtype=float))
        name = f"__marker__{m.name}"
        ids.append(pm.addFrame(pin.Frame(name, parent.parentJoint, parent_id, placement, pin.FrameType.OP_FRAME)))
    return pm, ids


def model_marker_positions(model, markers: MarkerSet, q: np.ndarray) -> np.ndarray:
    """World positions ``(N, M, 3)`` of the model markers at ``q`` ((N, nq), Pinocchio order)."""
    markers = load_marker_set(markers) if not isinstance(markers, MarkerSet) else markers
    pm, ids = add_marker_frames(model, markers)
    pd = pm.createData()
    q = np.atleast_2d(np.asarray(q, dtype=float))
    out = np.empty((q.shape[0], len(ids), 3))
    for k in range(q.shape[0]):
        pin.framesForwardKinematics(pm, pd, q[k])
        for j, fid in enumerate(ids):
            out[k, j] = pd.oMf[fid].translation
    return out


def markers_trial(model, markers: MarkerSet, time, q: np.ndarray, *, axes: str = "xyz") -> Trial:
    """Synthetic marker Trial (``<marker>_<axis>``, m) of the model moving through ``q``."""
    xyz = model_marker_positions(model, markers, q)
    chans = {}
    for j, m in enumerate(markers.names):
        for a in axes:
            chans[f"{m}_{a}"] = xyz[:, j, "xyz".index(a)]
    return Trial(time, chans, meta={"markers": markers.names, "format": "synthetic"})


class InverseKinematics(Fitter):
    """Marker-based inverse kinematics (weighted least squares, LM, warm-started).

    Parameters (keyword-only)
    ----------
    markers : MarkerSet or path
        Model markers; those absent from the measured trial are ignored (the
        fit needs at least as many measured coordinates as free coordinates).
    coordinates : sequence of str, optional
        Coordinates to solve for; default: every coordinate that moves some marker.
    axes : str
        Measured axes used, ``"xy"`` (sagittal) or ``"xyz"``; default: ``"xyz"`` if the
        trial has ``_z`` channels for all used markers, else ``"xy"``.
    weights : dict, optional
        Per-marker weights overriding the marker set's.
    q0 : dict or (nq,) array, optional
        Initial pose (Pinocchio order) for the first frame and for the held coordinates.
    max_iter, tol : int, float
        Per-frame iteration limit and step tolerance (rad or m).
    max_step : float
        Largest change of any coordinate in one iteration (rad or m; a trust region).
    strict : bool
        Raise :class:`~pinmsk.errors.ConvergenceError` at the first frame that does not
        converge in ``max_iter`` iterations (default: keep it, flagged in ``converged_``).
    coordinate_targets : dict, optional
        ``{coordinate: (value, weight)}``: OpenSim's coordinate tasks, each adding
        ``weight * (q_c - value)^2`` to every frame's objective (rad or m); the coordinate
        is solved for even when no marker moves it.

    ``result_.stats``: ``n`` the measured marker coordinates used, ``k`` the free
    coordinates times the frames, ``sse`` the weighted sum of squared marker errors (m^2),
    AIC/BIC with the variance estimated, ``converged`` when every frame converged.
    """

    def __init__(self, *, markers, coordinates: Sequence[str] | None = None, axes: str | None = None,
                 weights: dict | None = None, q0=None, max_iter: int = 50, tol: float = 1e-10,
                 max_step: float = 0.5, strict: bool = False, coordinate_targets: dict | None = None):
        self.markers = markers
        self.coordinates = coordinates
        self.axes = axes
        self.weights = weights
        self.q0 = q0
        self.max_iter = max_iter
        self.tol = tol
        self.max_step = max_step
        self.strict = strict
        self.coordinate_targets = coordinate_targets

    def fit(self, model, trial: Trial, *, progress=None) -> "InverseKinematics":
        """Solve every frame of the marker ``trial``; returns self."""
        mset = self.markers if isinstance(self.markers, MarkerSet) else load_marker_set(self.markers)
        measured = set(marker_names(trial))
        used = [m for m in mset.markers if m.name in measured]
        if not used:
            raise TrialError(f"none of the model markers ({', '.join(mset.names)}) is in the trial "
                             f"(markers: {', '.join(sorted(measured))}); rename with MarkerSet.renamed")
        mset = MarkerSet(tuple(used), {}, mset.model, mset.source)
        axes = self.axes
        if axes is None:
            axes = "xyz" if all(f"{m.name}_z" in trial for m in used) else "xy"
        ax = ["xyz".index(a) for a in axes]
        Y = marker_array(trial, mset.names, axes=axes)              # (N, M, A)
        n, nm, na = Y.shape
        w = np.array([(self.weights or {}).get(m.name, m.weight) for m in used], dtype=float)
        pm, fids = add_marker_frames(model, mset)
        pd = pm.createData()
        # the solved coordinates: the model's joints, or OpenSim's coordinates of a model with dependent
        # joints (an exact import), whose joints follow by the map (marker Jacobians J_pin dq_pin/dq)
        cmap = coordinate_map(model)
        names = model.coordinates if cmap is None else tuple(cmap.osim_coordinates)
        index = {c: i for i, c in enumerate(names)}
        nq = len(names)

        def column(c):
            if cmap is None or c in index:
                return index[c] if c in index else model.coordinate_index(c)
            hint = difflib.get_close_matches(str(c), names, n=3)
            raise ModelError(f"inverse kinematics: model '{model.name}' solves OpenSim's coordinates; '{c}' is not "
                             f"one{'; did you mean ' + ', '.join(map(repr, hint)) + '?' if hint else ''} "
                             f"(coordinates: {', '.join(names)})")

        # initial pose
        q = np.zeros(nq) if cmap is None else np.array([cmap.welded.get(c, 0.0) for c in names])
        if self.q0 is not None:
            if isinstance(self.q0, dict):
                for c, v in self.q0.items():
                    q[column(c)] = v
            else:
                q[:] = np.asarray(self.q0, dtype=float)

        def evaluate(qk, x, Jall):
            """Marker positions (and Jacobians in the solved coordinates) at qk into x (nm, na), Jall (nm, na, nq)."""
            qp = qk if cmap is None else cmap.expand(qk[None])[0][0]
            Jm = None if cmap is None else cmap.jacobian(qk[None])[0]
            pin.computeJointJacobians(pm, pd, qp)      # also runs forward kinematics
            pin.updateFramePlacements(pm, pd)
            for j, fid in enumerate(fids):
                x[j] = pd.oMf[fid].translation[ax]
                Jp = pin.getFrameJacobian(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED)[ax]
                Jall[j] = Jp if Jm is None else Jp @ Jm

        # free coordinates: those that move a marker
        x0, J0 = np.empty((nm, na)), np.empty((nm, na, nq))
        evaluate(q, x0, J0)
        moves = np.abs(J0).sum(axis=(0, 1)) > 0
        targets = dict(self.coordinate_targets or {})
        tcols = np.array([column(c) for c in targets], dtype=int)
        tval = np.array([float(v) for v, _ in targets.values()])
        tw = np.array([float(w) for _, w in targets.values()])
        if np.any(~np.isfinite(tw)) or np.any(tw < 0):
            bad = [c for c, (_, w) in targets.items() if not (np.isfinite(float(w)) and float(w) >= 0)]
            raise ModelError(f"inverse kinematics: coordinate target weights must be finite and >= 0 ({', '.join(bad)})")
        tw = np.sqrt(tw)
        if self.coordinates is None:
            free = np.flatnonzero(moves | np.isin(np.arange(nq), tcols[tw > 0]))
        else:
            free = np.array([column(c) for c in self.coordinates])
        fpos = {int(c): i for i, c in enumerate(free)}
        trow = np.array([fpos.get(int(c), -1) for c in tcols], dtype=int)

        def target_residual(qk):
            return tw * (qk[tcols] - tval) if tcols.size else np.zeros(0)

        def target_jacobian():
            Jt = np.zeros((tcols.size, free.size))
            for i, r in enumerate(trow):
                if r >= 0:
                    Jt[i, r] = tw[i]
            return Jt
        if free.size == 0:
            raise ModelError("inverse kinematics: no coordinate moves any measured marker")
        if nm * na < free.size:
            raise TrialError(f"inverse kinematics: {nm} markers x {na} axes = {nm * na} measurements "
                             f"cannot determine {free.size} coordinates; add markers or fix coordinates")
        Q = np.empty((n, nq))
        err = np.full((n, nm), np.nan)
        iters = np.zeros(n, dtype=int)
        conv = np.zeros(n, dtype=bool)
        nf = free.size
        rot = np.array([index[c] for c in model.rotational_coordinates if c in index], dtype=int)

        xk, Jk = np.empty((nm, na)), np.empty((nm, na, nq))
        xn, Jn = np.empty((nm, na)), np.empty((nm, na, nq))
        for k in range(n):
            y = Y[k]
            ok = np.isfinite(y).all(axis=1)
            wk = np.where(ok, w, 0.0)
            yk = np.where(ok[:, None], y, 0.0)
            if np.count_nonzero(wk) * na < nf:
                raise TrialError(f"inverse kinematics: frame {k} (t = {trial.time[k]:.6g} s) has only "
                                 f"{int(np.count_nonzero(wk))} measured marker(s) for {nf} coordinates; "
                                 "fill the gaps (read_trc max_gap=...) or cut the frames")
            sw = np.sqrt(wk)[:, None]
            lam = 1e-6
            evaluate(q, xk, Jk)
            r = (xk - yk) * sw
            rt = target_residual(q)
            Jt = target_jacobian()
            cost = float(np.sum(r * r) + np.sum(rt * rt))
            it = 0
            done = False
            while it < self.max_iter:
                it += 1
                J = (Jk[:, :, free] * sw[:, :, None]).reshape(nm * na, nf)
                g = J.T @ r.ravel() + Jt.T @ rt
                H = J.T @ J + Jt.T @ Jt
                scale = np.diag(H).copy()
                scale[scale <= 0] = 1.0
                while True:
                    dq = -np.linalg.solve(H + lam * np.diag(scale), g)
                    big = np.max(np.abs(dq))
                    if big > self.max_step:  # trust region: no jumps by whole turns
                        dq *= self.max_step / big
                    qn = q.copy()
                    qn[free] += dq
                    evaluate(qn, xn, Jn)
                    rn = (xn - yk) * sw
                    rtn = target_residual(qn)
                    cn = float(np.sum(rn * rn) + np.sum(rtn * rtn))
                    if cn <= cost or np.max(np.abs(dq)) < self.tol:
                        break
                    lam *= 10.0
                    if lam > 1e10:
                        break
                if cn <= cost:          # accept: the trial point's positions and Jacobians become current
                    q, cost, r, rt = qn, cn, rn, rtn
                    xk, xn = xn, xk
                    Jk, Jn = Jn, Jk
                    lam = max(lam / 10.0, 1e-12)
                step = float(np.max(np.abs(dq)))
                if step < self.tol or lam > 1e10:
                    Jw = (Jk[:, :, free] * sw[:, :, None]).reshape(nm * na, nf)
                    done = step < self.tol or np.max(np.abs(Jw.T @ r.ravel() + Jt.T @ rt)) < 1e-12
                    break
            # final residual per marker (unweighted, only measured)
            d = np.linalg.norm(xk - yk, axis=1)
            err[k] = np.where(ok, d, np.nan)
            q[rot] = np.angle(np.exp(1j * q[rot]))  # revolute coordinates in (-pi, pi]
            Q[k] = q
            iters[k] = it
            conv[k] = done
            if progress is not None:
                progress.update(1)
        if self.strict and not conv.all():
            k = int(np.flatnonzero(~conv)[0])
            raise ConvergenceError(f"inverse kinematics did not converge at frame {k} "
                                   f"(t = {trial.time[k]:.6g} s) in {self.max_iter} iterations")
        with np.errstate(invalid="ignore"):
            self.marker_rms_ = {m: float(np.sqrt(np.nanmean(err[:, j] ** 2))) for j, m in enumerate(mset.names)}
            self.frame_rms_ = np.sqrt(np.nanmean(err ** 2, axis=1))
        self.marker_error_ = err
        self.iterations_ = iters
        self.converged_ = conv
        self.free_coordinates_ = tuple(names[i] for i in free)
        self.axes_ = axes
        if cmap is None:
            self.q_ = Q
            chans = {c: Q[:, model.coordinate_index(c)] for c in model.coordinate_order}
        else:
            # coupled coordinates take their couplers' values (OpenSim's IK enforces them); q_ is Pinocchio's
            for dep, indep, f, scale in cmap.couplers:
                x = Q[:, index[indep[0]]] if len(indep) == 1 else Q[:, [index[c] for c in indep]]
                Q[:, index[dep]] = scale * f.value(x)
            self.q_ = cmap.expand(Q)[0]
            chans = {c: Q[:, index[c]] for c in trial_coordinates(model)}
        used_k = np.isfinite(err)                        # (n, nm) markers measured in each frame
        stats = FitStatistics(
            n=int(used_k.sum()) * na, k=n * nf, sse=float(np.sum(np.where(used_k, w * err ** 2, 0.0))),
            variance="estimated", converged=bool(conv.all()),
            message=f"{int(conv.sum())}/{n} frames converged", iterations=int(iters.sum()),
            objective=float(np.sum(np.where(used_k, w * err ** 2, 0.0))))
        self.result_ = Result(trial.time, chans,
                              meta={"analysis": "inverse_kinematics", "model": model.name,
                                    "markers": mset.names, "axes": axes,
                                    "marker_rms": self.marker_rms_},
                              stats=stats, report=self._report_text(model, stats))
        return self

    def _report_text(self, model, stats: FitStatistics) -> str:
        return format_report(f"Inverse kinematics of model '{model.name}' from markers", [
            ("frames", f"{len(self.frame_rms_)}, axes {self.axes_}, free {', '.join(self.free_coordinates_)}"),
            ("solver", f"Levenberg-Marquardt, converged {int(self.converged_.sum())}/{len(self.converged_)} "
                       f"frames; mean iterations {self.iterations_.mean():.2f}"),
            ("marker rms", ", ".join(f"{m} {1000 * v:.1f} mm" for m, v in self.marker_rms_.items())),
            *stats.rows()])


def inverse_kinematics(model, trial: Trial, *, markers, **options) -> Trial:
    """Shortcut: ``InverseKinematics(markers=markers, **options).fit(model, trial).result_``."""
    return InverseKinematics(markers=markers, **options).fit(model, trial).result_
