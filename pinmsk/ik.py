"""Inverse kinematics from markers: weighted least squares per frame.

For each frame k, the coordinates minimise

    sum_m  w_m || P_a (x_m(q) - y_m[k]) ||^2

where ``x_m(q)`` is model marker m (a point fixed in a body, from a
:class:`pinmsk.markers.MarkerSet`), ``y_m[k]`` the measured position, ``P_a``
keeps the measured axes (``"xy"`` for sagittal data, ``"xyz"`` for 3-D) and
``w_m`` the marker weight.  A marker that is NaN in a frame has zero weight
there (gaps that :func:`pinmsk.signals.gaps.fill_gaps` did not fill).

The solver is Levenberg-Marquardt on the Gauss-Newton normal equations.  On a tree of
one-dof joints (every model pinmsk builds or imports) all frames take their steps at once
(:class:`BatchKinematics`: forward kinematics and marker Jacobians as numpy over frames, each
frame with its own damping, acceptance and end), coarse to fine in time: key frames every
``key_stride`` frames start from ``q0`` (as OpenSim assembles its first frame from the default
pose), every quarter of that from the cubic interpolation of their solutions, down to every
frame.  A frame ends when its step, or the error left estimated from the linear rate of
Gauss-Newton on a nonzero residual (``step * rho / (1 - rho)``, ``rho`` the ratio of the last
two steps), is below ``tol``, or when a step lowers its objective by less than 1e-9 of it (a direction
the markers hardly see, such as a forearm's pronation, then moves no further: the fit is the same to
that part).  ``method="frames"`` solves frame after frame instead, warm-started
from the previous one, with Pinocchio frame Jacobians (``LOCAL_WORLD_ALIGNED``), for any joints.
Coordinates that no marker moves (and no coordinate task names) are held at ``q0``.
Coordinate tasks (``coordinate_tasks``, OpenSim's IKCoordinateTask) and bounds (``bounds``,
OpenSim's clamped ranges) add to the batched problem.

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

__all__ = ["InverseKinematics", "BatchKinematics", "inverse_kinematics", "model_marker_positions", "add_marker_frames"]


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
        Largest change of any coordinate in one iteration (rad or m; a trust region); the batched
        solver bounds the rotations' steps only.
    strict : bool
        Raise :class:`~pinmsk.errors.ConvergenceError` at the first frame that does not
        converge in ``max_iter`` iterations (default: keep it, flagged in ``converged_``).
    coordinate_tasks : dict, optional
        ``{coordinate: (weight, target)}``, target a number or one per frame (rad or m): adds
        ``weight * W_k * (q - target)^2`` to frame k's objective, ``W_k`` the frame's total marker
        weight, as OpenSim's IKCoordinateTask (Simbody's Assembler divides the marker goal by
        ``W_k``).  Each such coordinate is solved even if no marker moves it.
    bounds : dict, optional
        ``{coordinate: (lower, upper)}``: the coordinate stays in the range (projected steps), as
        OpenSim's IK keeps clamped coordinates in theirs.
    method : str
        ``"batch"``: all frames' steps at once (:class:`BatchKinematics`; one-dof joints), coarse to
        fine in time: key frames every ``key_stride`` frames (default 4) from ``q0``, then every
        quarter of that from their cubic interpolation, down to every frame; ``"frames"``: frame
        after frame with Pinocchio's Jacobians (any joints); ``"auto"`` (default): batch when the
        model allows it.

    ``result_.stats``: ``n`` the measured marker coordinates used, ``k`` the free
    coordinates times the frames, ``sse`` the weighted sum of squared marker errors (m^2),
    AIC/BIC with the variance estimated, ``converged`` when every frame converged.
    """

    def __init__(self, *, markers, coordinates: Sequence[str] | None = None, axes: str | None = None,
                 weights: dict | None = None, q0=None, max_iter: int = 50, tol: float = 1e-10,
                 max_step: float = 0.5, strict: bool = False, coordinate_tasks: dict | None = None,
                 bounds: dict | None = None, method: str = "auto", key_stride: int | None = None):
        self.markers = markers
        self.coordinates = coordinates
        self.axes = axes
        self.weights = weights
        self.q0 = q0
        self.max_iter = max_iter
        self.tol = tol
        self.max_step = max_step
        self.strict = strict
        self.coordinate_tasks = coordinate_tasks
        self.bounds = bounds
        self.method = method
        self.key_stride = key_stride

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

        use_batch = self.method == "batch" or (self.method == "auto" and BatchKinematics.supports(model.pin))
        all_axes = ax == [0, 1, 2]
        if use_batch:
            kin = _batch_kinematics(model.pin, mset)
            mapping = _fast_map(cmap) if cmap is not None else None

            def batch_eval(Qs, cols, jacobian=True):
                """Marker positions (n, M, A) and Jacobians (n, M, A, len(cols)) in the solved coordinates."""
                if mapping is not None:
                    qp, slopes = mapping(Qs, jacobian)
                    pos = np.full(nq, -1)
                    pos[cols] = np.arange(len(cols))
                    columns = {}
                    for jq, ic in zip(*mapping.same):
                        if pos[ic] >= 0:
                            columns[jq] = [(pos[ic], None)]
                    for js, ic, D1 in slopes:
                        if pos[ic] >= 0:
                            for g, jq in enumerate(js):
                                columns.setdefault(jq, []).append((pos[ic], D1[g]))
                    X, Jp = kin(qp, jacobian, columns, len(cols))
                    Jm = None
                else:
                    if cmap is None:
                        qp, Jm = Qs, None
                    else:
                        qp, Jm = cmap.expand(Qs)[0], (cmap.jacobian(Qs) if jacobian else None)
                    X, Jp = kin(qp, jacobian)
                    if jacobian:
                        if Jm is None:
                            Jp = Jp[..., cols]
                        else:
                            Jp = (Jp.reshape(len(Qs), -1, Jp.shape[-1]) @ Jm[:, :, cols]).reshape(
                                Jp.shape[:3] + (len(cols),))
                if not all_axes:
                    X = X[:, :, ax]
                if not jacobian:
                    return X, None
                if not all_axes:
                    Jp = Jp[:, :, ax, :]
                return X, Jp

            J0 = batch_eval(q[None], np.arange(nq))[1][0]
        else:
            pm, fids = add_marker_frames(model, mset)
            pd = pm.createData()

            def evaluate(qk, x, Jall):
                """Marker positions and Jacobians (solved coordinates) at qk into x (nm, na), Jall (nm, na, nq)."""
                qp = qk if cmap is None else cmap.expand(qk[None])[0][0]
                Jm = None if cmap is None else cmap.jacobian(qk[None])[0]
                pin.computeJointJacobians(pm, pd, qp)      # also runs forward kinematics
                pin.updateFramePlacements(pm, pd)
                for j, fid in enumerate(fids):
                    x[j] = pd.oMf[fid].translation[ax]
                    Jp = pin.getFrameJacobian(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED)[ax]
                    Jall[j] = Jp if Jm is None else Jp @ Jm

            x0, J0 = np.empty((nm, na)), np.empty((nm, na, nq))
            evaluate(q, x0, J0)
        # free coordinates: those that move a marker
        moves = np.abs(J0).sum(axis=(0, 1)) > 0
        if self.coordinates is None:
            free = np.flatnonzero(moves)
        else:
            free = np.array([column(c) for c in self.coordinates])
        if free.size == 0:
            raise ModelError("inverse kinematics: no coordinate moves any measured marker")
        if nm * na < free.size:
            raise TrialError(f"inverse kinematics: {nm} markers x {na} axes = {nm * na} measurements "
                             f"cannot determine {free.size} coordinates; add markers or fix coordinates")
        nf = free.size
        lo = np.full(nq, -np.inf)
        hi = np.full(nq, np.inf)
        for c, (a, b) in (self.bounds or {}).items():
            lo[column(c)], hi[column(c)] = a, b
        tasks = dict(self.coordinate_tasks or {})
        if tasks:
            task_cols = np.array([column(c) for c in tasks], dtype=int)
            task_w = np.array([float(v[0]) for v in tasks.values()])
            bad = [c for c, x in zip(tasks, task_w) if not (np.isfinite(x) and x >= 0)]
            if bad:
                raise ModelError(f"inverse kinematics: coordinate task weights must be finite and >= 0; "
                                 f"'{bad[0]}' has {tasks[bad[0]][0]!r}")
            task_y = np.column_stack([np.broadcast_to(np.asarray(v[1], dtype=float), (n,)) for v in tasks.values()])
            free = np.union1d(free, task_cols)
            nf = free.size
        if not use_batch and (tasks or self.bounds):
            raise ModelError(f"inverse kinematics: coordinate tasks and bounds need the batched solver "
                             f"(one-dof joints); model '{model.name}' has other joints")
        if use_batch:
            def solve_eval(Qs, jacobian=True):
                return batch_eval(Qs, free, jacobian)

            ok_all = np.isfinite(Y).all(axis=2)
            W = np.where(ok_all, w[None, :], 0.0)
            Y0 = np.where(ok_all[..., None], Y, 0.0)
            few = np.flatnonzero(np.count_nonzero(W, axis=1) * na < nf)
            if few.size:
                k = int(few[0])
                raise TrialError(f"inverse kinematics: frame {k} (t = {trial.time[k]:.6g} s) has only "
                                 f"{int(np.count_nonzero(W[k]))} measured marker(s) for {nf} coordinates; "
                                 "fill the gaps (read_trc max_gap=...) or cut the frames")
            if not tasks:
                task_cols, task_w, task_y = np.zeros(0, dtype=int), np.zeros(0), np.zeros((n, 0))
            rotational = set(model.rotational_coordinates)
            turning = np.array([names[i] in rotational or (cmap is not None and names[i] not in model.coordinates)
                                for i in free])
            Q, iters, conv = self._solve_batch(solve_eval, Y0, W, q, free, task_cols, task_w, task_y, lo, hi,
                                               progress, turning)
            X, _ = solve_eval(Q, jacobian=False)
            err = np.where(ok_all, np.linalg.norm(X - Y0, axis=2), np.nan)
            rot = np.array([index[c] for c in model.rotational_coordinates if c in index], dtype=int)
            Q[:, rot] = np.angle(np.exp(1j * Q[:, rot]))        # revolute coordinates in (-pi, pi]
        else:
            Q, err, iters, conv = self._solve_frames(evaluate, Y, w, q, free, nm, na, nq, n, trial,
                                                     model, index, progress)

        if self.strict and not conv.all():
            k = int(np.flatnonzero(~conv)[0])
            raise ConvergenceError(f"inverse kinematics did not converge at frame {k} "
                                   f"(t = {trial.time[k]:.6g} s) in {self.max_iter} iterations")
        with np.errstate(invalid="ignore"):
            rms = np.sqrt(np.nanmean(err ** 2, axis=0))
            self.marker_rms_ = {m: float(rms[j]) for j, m in enumerate(mset.names)}
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

    def _solve_frames(self, evaluate, Y, w, q, free, nm, na, nq, n, trial, model, index, progress):
        """Frame after frame, each warm-started from the previous one (any Pinocchio joints)."""
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
            cost = float(np.sum(r * r))
            it = 0
            done = False
            while it < self.max_iter:
                it += 1
                J = (Jk[:, :, free] * sw[:, :, None]).reshape(nm * na, nf)
                g = J.T @ r.ravel()
                H = J.T @ J
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
                    cn = float(np.sum(rn * rn))
                    if cn <= cost or np.max(np.abs(dq)) < self.tol:
                        break
                    lam *= 10.0
                    if lam > 1e10:
                        break
                if cn <= cost:          # accept: the trial point's positions and Jacobians become current
                    q, cost, r = qn, cn, rn
                    xk, xn = xn, xk
                    Jk, Jn = Jn, Jk
                    lam = max(lam / 10.0, 1e-12)
                step = float(np.max(np.abs(dq)))
                if step < self.tol or lam > 1e10:
                    Jw = (Jk[:, :, free] * sw[:, :, None]).reshape(nm * na, nf)
                    done = step < self.tol or np.max(np.abs(Jw.T @ r.ravel())) < 1e-12
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
        return Q, err, iters, conv

    def _solve_batch(self, evaluate, Y, W, q, free, task_cols, task_w, task_y, lo, hi, progress, turning=None):
        """Coarse to fine in time, every level's frames at once: the key frames every ``key_stride``
        (default 4) frames start from ``q`` (the default pose, as OpenSim assembles its first frame), each finer level
        from the cubic interpolation of the coarser one's solutions, each level solving its new
        frames to ``tol``; each level's stride is a quarter of the one before (4, 1; 16, 4, 1)."""
        n = Y.shape[0]
        top = max(int(self.key_stride if self.key_stride is not None else 4), 1)
        strides = [top]
        while strides[-1] > 1:
            strides.append(max(strides[-1] // 4, 1))
        strides = [x for x in strides if x == 1 or 2 * x <= n - 1]
        Q = np.empty((n, q.size))
        iters = np.zeros(n, dtype=int)
        conv = np.zeros(n, dtype=bool)
        solved = np.zeros(0, dtype=int)
        with np.errstate(invalid="ignore"):
            span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
            one = np.isfinite(lo) | np.isfinite(hi)
            margin = np.where(np.isfinite(lo) & np.isfinite(hi), 0.01 * span, np.where(one, 1e-3, 0.0))
            mid = np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (lo + hi), np.where(np.isfinite(lo), lo, hi))
            mid = np.where(np.isfinite(mid), mid, 0.0)
        for stride in strides:
            frames = np.unique(np.r_[np.arange(0, n, stride), n - 1])
            new = np.setdiff1d(frames, solved)
            if new.size == 0:
                continue
            Qs = np.repeat(q[None], new.size, axis=0) if solved.size == 0 else _interpolate(solved, Q[solved], new)
            # seeds strictly inside the bounds (a default pose on a range's end would hold that coordinate there
            # from the first step on: descent pushes it out, so the active set keeps it)
            Qs = np.clip(Qs, np.minimum(lo + margin, mid), np.maximum(hi - margin, mid))
            it, cv = _lm_frames(evaluate, Y[new], W[new], Qs, free, task_cols, task_w, task_y[new], lo, hi,
                                max_iter=self.max_iter, tol=self.tol, max_step=self.max_step, turning=turning,
                                progress=progress)
            Q[new], iters[new], conv[new] = Qs, it, cv
            solved = np.union1d(solved, new)
        return Q, iters, conv

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


# ---------------------------------------------------------------------------------------------
# the batched solver: every frame's Gauss-Newton step at once
# ---------------------------------------------------------------------------------------------

#: Pinocchio joints the batched kinematics handles (one degree of freedom, ``nq = nv = 1``).
_ONE_DOF = frozenset({"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned",
                      "JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"})


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over the last axis (broadcast), without :func:`numpy.cross`'s per-call set-up."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


class BatchKinematics:
    """World positions of points fixed in the bodies of a tree of one-dof joints, and their Jacobians,
    for N configurations at once (numpy over frames; the same numbers as Pinocchio's
    ``framesForwardKinematics`` and ``LOCAL_WORLD_ALIGNED`` frame Jacobians, to rounding).

    Each joint's pose is ``oMi = oMparent * placement * exp(axis q)`` (a rotation about, or a
    translation along, the joint's axis, read from its motion subspace).  A point ``x`` fixed
    below a revolute joint with world axis ``a`` through ``o`` moves by ``a x (x - o)`` per radian;
    below a prismatic joint by ``a`` per metre.  ``bodies`` are Pinocchio frame names, ``points``
    (M, 3) the points in those frames.
    """

    def __init__(self, pm: pin.Model, bodies: Sequence[str], points: np.ndarray):
        if not self.supports(pm):
            raise ModelError("batched kinematics needs one-dof joints only")
        pd = pm.createData()
        pin.forwardKinematics(pm, pd, pin.neutral(pm))
        self.nq = pm.nq
        self.njoints = pm.njoints
        self.joints = []
        for j in range(1, pm.njoints):
            S = np.array(pd.joints[j].S).ravel()
            rev = pm.joints[j].shortname().startswith("JointModelR")
            axis = S[3:] if rev else S[:3]
            axis = axis / np.linalg.norm(axis)
            K = _skew(axis)
            pl = pm.jointPlacements[j]
            Rpl, tpl = pl.rotation.copy(), pl.translation.copy()
            # one product with the parent's rotation gives all of these: [Rpl | Rpl K | Rpl K^2 | Rpl a | t]
            C = np.column_stack([Rpl, Rpl @ K, Rpl @ K @ K, Rpl @ axis, tpl])
            self.joints.append((j, pm.parents[j], C, rev, pm.idx_qs[j]))
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        mj, loc = [], []
        for b, x in zip(bodies, points):
            f = pm.frames[pm.getFrameId(b)]
            mj.append(f.parentJoint)
            loc.append(f.placement.act(np.asarray(x, dtype=float)))
        self.marker_joint = np.array(mj, dtype=int)
        self.marker_point = np.array(loc).reshape(-1, 3)
        # the markers each joint moves (those on it or below it)
        below = {j: [] for j in range(pm.njoints)}
        for m, jm in enumerate(mj):
            for s in pm.supports[jm]:
                below[s].append(m)
        self.moved = {j: np.array(v, dtype=int) for j, v in below.items()}
        self.n_markers = len(mj)
        # the markers of each joint, with their points as columns (3, k)
        self.groups = [(j, np.flatnonzero(self.marker_joint == j), self.marker_point[self.marker_joint == j].T.copy())
                       for j in sorted(set(mj))]

    @staticmethod
    def supports(pm: pin.Model) -> bool:
        return all(pm.joints[j].shortname() in _ONE_DOF for j in range(1, pm.njoints))

    def __call__(self, q: np.ndarray, jacobian: bool = True, columns: dict | None = None, width: int | None = None):
        """Positions (N, M, 3) and, with ``jacobian``, d position / d q (N, M, 3, nq) at ``q`` (N, nq).

        ``columns`` (with ``width``) folds the Jacobian into other coordinates as it is built:
        ``{q index: [(column, scale), ...]}``, each joint's column added to those columns of a
        (N, M, 3, width) result, times ``scale`` ((N,) or None for 1): the chain rule of a coordinate
        map, ``d x / d q_osim = sum_j d x / d q_j  d q_j / d q_osim``, without the dense product."""
        q = np.atleast_2d(q)
        n = q.shape[0]
        # one (n, 3, 3) / (n, 3) array per joint; the constants of a joint meet its parent's rotation in one
        # 2-D product of the (3n, 3) stack
        R = [np.broadcast_to(np.eye(3), (n, 3, 3))] + [None] * (self.njoints - 1)     # the universe: markers on
        p = [np.zeros((n, 3))] + [None] * (self.njoints - 1)                           # ground stay put
        axes = [None] * self.njoints
        s, c = np.sin(q), 1.0 - np.cos(q)
        for j, parent, C, rev, iq in self.joints:
            if parent == 0:
                M = np.broadcast_to(C, (n, 3, 11))
                pb = C[:, 10]
            else:
                M = (R[parent].reshape(3 * n, 3) @ C).reshape(n, 3, 11)
                pb = p[parent] + M[:, :, 10]
            aw = M[:, :, 9]
            axes[j] = aw
            if rev:
                # Rodrigues: R exp(K x) = R + sin(x) R K + (1 - cos(x)) R K^2
                Rj = M[:, :, 3:6] * s[:, iq, None, None]
                Rj += M[:, :, 6:9] * c[:, iq, None, None]
                Rj += M[:, :, 0:3]
                R[j] = Rj
                p[j] = pb if parent else np.broadcast_to(pb, (n, 3))
            else:
                R[j] = np.ascontiguousarray(M[:, :, 0:3])
                p[j] = pb + aw * q[:, iq, None]
        X = np.empty((n, self.n_markers, 3))
        for j, ms, pts in self.groups:
            X[:, ms] = (R[j].reshape(3 * n, 3) @ pts).reshape(n, 3, -1).transpose(0, 2, 1) + p[j][:, None, :]
        if not jacobian:
            return X, None
        J = np.zeros((n, self.n_markers, 3, self.nq if columns is None else width))
        for j, parent, C, rev, iq in self.joints:
            ms = self.moved[j]
            targets = [(iq, None)] if columns is None else columns.get(iq, ())
            if ms.size == 0 or not targets:
                continue
            every = ms.size == self.n_markers          # a joint above every marker: no gather, no scatter
            if rev:
                d = _cross(axes[j][:, None, :], (X if every else X[:, ms]) - p[j][:, None, :])
            else:
                d = axes[j][:, None, :]                  # the same for every marker below
            for oc, scale in targets:
                col = J[..., oc]
                if every:
                    col += d if scale is None else d * scale[:, None, None]
                else:
                    col[:, ms] += d if scale is None else d * scale[:, None, None]
        return X, J


#: BatchKinematics of (Pinocchio model, marker set) pairs lately used (the model kept with it, so an id
#: is never taken for another model's).
_KINEMATICS: dict = {}


def _batch_kinematics(pm: pin.Model, mset: MarkerSet) -> "BatchKinematics":
    key = (id(pm), tuple((m.body, tuple(m.position)) for m in mset.markers))
    hit = _KINEMATICS.get(key)
    if hit is not None and hit[0] is pm:
        return hit[1]
    kin = BatchKinematics(pm, [m.body for m in mset.markers], [m.position for m in mset.markers])
    if len(_KINEMATICS) >= 16:
        _KINEMATICS.pop(next(iter(_KINEMATICS)))
    _KINEMATICS[key] = (pm, kin)
    return kin


def _fast_map(cmap):
    """``(q_pinocchio, slopes)`` of a coordinate map in one pass, when it has no couplers and each
    dependent joint is a one-argument function in one of its banks (an imported knee): the banks' values
    and slopes from one evaluation (``mapping.same``: the joints that are OpenSim coordinates, and
    their columns).  None when the map needs its general path."""
    if cmap.couplers or not getattr(cmap, "_all_banked", False):
        return None
    same_j, same_i, banks = cmap._same_j, cmap._same_i, cmap._banks
    nj = len(cmap.joints)

    def mapping(Q, jacobian=True):
        """Pinocchio's q (n, nj) and the banks' slopes [(joints, OpenSim column, (size, n) slopes)]."""
        n = Q.shape[0]
        qp = np.empty((n, nj))
        qp[:, same_j] = Q[:, same_i]
        slopes = []
        for col, js, bank in banks:
            F, D1 = _bank_values(bank, Q[:, col])
            qp[:, js] = F.T
            slopes.append((js, col, D1))
        return qp, slopes
    mapping.same = (same_j, same_i)
    return mapping


def _bank_values(bank, x):
    """A :class:`~pinmsk.opensim.functions.FunctionBank`'s values and slopes (size, N): its splines'
    pieces looked up directly when the bank holds splines only and ``x`` is inside their knots (a
    spline is C1, so at a knot either piece gives the same value and slope); else the bank's own
    evaluation."""
    knots = getattr(bank, "_knots", None)
    if bank._poly is None and not bank._other and knots and np.isfinite(x).all():
        F = np.empty((bank.size, x.size))
        D1 = np.empty((bank.size, x.size))
        for idx, first, coef in knots:
            kx = first.x
            if not (x.min() > kx[0] and x.max() < kx[-1]):
                break
            k = np.searchsorted(kx, x, side="right") - 1
            t = x - kx[k]
            y, b, c, d = coef[:, k].reshape(4, idx.size, x.size)
            F[idx] = y + t * (b + t * (c + t * d))
            D1[idx] = b + t * (2.0 * c + 3.0 * t * d)
        else:
            return F, D1
    F, D1, _ = bank.evaluate(x)
    return F, D1


def _interpolate(t, Q, at):
    """``Q`` (k, nq) at the frames ``t`` interpolated at ``at``: a cubic spline through four or more
    frames (the ends not-a-knot), else linear."""
    if t.size >= 4:
        from scipy.interpolate import CubicSpline
        return CubicSpline(t, Q, axis=0)(at)
    return np.column_stack([np.interp(at, t, Q[:, c]) for c in range(Q.shape[1])])


def _lm_frames(evaluate, Y, W, Q, free, task_cols, task_w, task_y, lo, hi, *, max_iter, tol, max_step,
               turning=None, progress=None):
    """Levenberg-Marquardt on every frame at once (each frame its own damping, acceptance and end).

    ``evaluate(Q)`` -> marker positions (n, M, A) and their Jacobians (n, M, A, nf) in the free
    coordinates ``free`` (column indices of ``Q``); ``Y`` (n, M, A) measured (0 where missing), ``W`` (n, M)
    weights (0 where missing);
    ``Q`` (n, nq) the start, solved in place.  Coordinate tasks add rows ``sqrt(wc Wk) (q_c - y_c)``
    with ``Wk`` the frame's total marker weight (Simbody's Assembler divides the marker goal by it).
    ``lo``/``hi`` (nq,) bound the coordinates (projected steps); ``turning`` (nf,) marks the rotations,
    whose largest step is at most ``max_step``.  Returns (iterations, converged).
    """
    n, nm, na = Y.shape
    nf = free.size
    its = np.zeros(n, dtype=int)
    conv = np.zeros(n, dtype=bool)
    sw = np.sqrt(W)[:, :, None]                                    # (n, M, 1)
    tw = np.sqrt(task_w[None, :] * W.sum(axis=1)[:, None]) if task_cols.size else None   # (n, T)
    tpos = np.array([int(np.flatnonzero(free == c)[0]) for c in task_cols], dtype=int)

    def residual(idx, Qs, Ya, swa):
        """Weighted residuals and Jacobian rows of the frames ``idx`` (their measurements ``Ya``, ``swa``)."""
        X, J = evaluate(Qs)
        r = ((X - Ya) * swa).reshape(len(idx), nm * na)
        Jf = (J * swa[..., None]).reshape(len(idx), nm * na, nf)
        if tw is not None:
            rt = tw[idx] * (Qs[:, task_cols] - task_y[idx])
            Jt = np.zeros((len(idx), task_cols.size, nf))
            Jt[:, np.arange(task_cols.size), tpos] = tw[idx]
            r = np.concatenate([r, rt], axis=1)
            Jf = np.concatenate([Jf, Jt], axis=1)
        return r, Jf

    act = np.arange(n)
    Ya, swa = Y, sw                       # the active frames' measurements, kept in step with ``act``
    r, J = residual(act, Q, Ya, swa)
    cost = np.einsum("ni,ni->n", r, r)
    lam = np.full(n, 1e-6)
    prev = np.full(n, np.inf)
    turning = np.ones(nf, dtype=bool) if turning is None else np.asarray(turning, dtype=bool)
    eye = np.eye(nf)
    bounded = np.isfinite(lo[free]).any() or np.isfinite(hi[free]).any()
    for _ in range(max_iter):
        if act.size == 0:
            break
        Jt = J.transpose(0, 2, 1)
        H = Jt @ J
        g = (Jt @ r[..., None])[..., 0]
        d = np.einsum("nii->ni", H).copy()
        d[d <= 0] = 1.0
        A = H + lam[act, None, None] * d[:, :, None] * eye
        if bounded:
            # the active set: a coordinate at a bound that descent would push through it stays there this
            # step (its row and column out of the system), the others step on the bound's face
            qf = Q[act][:, free]
            held = ((qf <= lo[free] + 1e-12) & (g > 0)) | ((qf >= hi[free] - 1e-12) & (g < 0))
            if held.any():
                g = np.where(held, 0.0, g)
                keep = ~held
                A = A * (keep[:, :, None] & keep[:, None, :]) + held[:, :, None] * eye
        dq = -np.linalg.solve(A, g[..., None])[..., 0]
        # a trust region on the rotations (no jumps by whole turns); a translation enters the markers
        # nearly linearly, so its Gauss-Newton step is kept whole
        big = np.abs(dq[:, turning]).max(axis=1) if turning.any() else np.abs(dq).max(axis=1)
        cut = big > max_step
        dq[cut] *= (max_step / big[cut])[:, None]
        Qn = Q[act].copy()
        Qn[:, free] += dq
        if bounded:
            Qn[:, free] = np.clip(Qn[:, free], lo[free], hi[free])
        step = np.abs(Qn[:, free] - Q[act][:, free]).max(axis=1)
        # Gauss-Newton on a residual that is not zero converges linearly: with the rate rho = step / the
        # step before, the error left after this step is about step * rho / (1 - rho)
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = np.where(np.isfinite(prev[act]), step / prev[act], np.inf)
            left = np.where(rho < 0.5, step * rho / (1.0 - rho), np.inf)
        rn, Jn = residual(act, Qn, Ya, swa)
        cn = np.einsum("ni,ni->n", rn, rn)
        ok = cn <= cost[act]
        its[act] += 1
        a_ok = act[ok]
        Q[a_ok] = Qn[ok]
        # done: a small step, a small error left, or a near Gauss-Newton step (not one damped after
        # rejections) that hardly lowers the objective
        flat = ok & (lam[act] <= 1e-4) & (cost[act] - cn <= 1e-9 * cost[act])
        small = (step < tol) | (ok & (left < tol)) | flat
        prev[act] = np.where(ok, step, prev[act])
        cost[a_ok] = cn[ok]
        if ok.all():
            r, J = rn, Jn
        else:
            r[ok] = rn[ok]
            J[ok] = Jn[ok]
        lam[a_ok] = np.maximum(lam[a_ok] / 10.0, 1e-12)
        lam[act[~ok]] *= 10.0
        stuck = lam[act] > 1e10
        done = small | stuck
        conv[act[small]] = True
        if stuck.any():                                            # no descent left: converged if the gradient is nil
            gmax = np.abs(g[stuck]).max(axis=1)
            conv[act[stuck]] |= gmax < 1e-12
        if progress is not None and done.any():
            progress.update(int(done.sum()))
        if done.any():
            keep = ~done
            act, r, J, Ya, swa = act[keep], r[keep], J[keep], Ya[keep], swa[keep]
    if progress is not None and act.size:
        progress.update(int(act.size))
    return its, conv
