"""Static optimization (SO): one muscle-redundancy problem per frame (thesis Sec. 2.2.2, 3.4).

At each frame ``k`` of a motion, with moment arms ``R_k`` (m, nv) and the
actuator moments ``tau_k`` of inverse dynamics, SO finds muscle forces

    minimise    J_k = sum_i (F_i / N_i)^P            (Eq. 2.11, 2.12, 3.13)
    subject to  sum_i R_k[i, j] F_i = tau_k[j]       for the balanced dofs j (Eq. 3.14)
                0 <= F_i <= F_max,i                  (force mode)

or, in activation mode (as OpenSim's static optimization),
``F_i = a_i F_active,i + F_passive,i`` with ``F_active = F_max f_L f_V cos(alpha)``
at the trial's muscle lengths and velocities, ``0 <= a_i <= 1`` and cost
``sum_i S_i a_i^P`` (Eq. 2.14).  ``N_i`` / ``S_i`` is 1, ``F_max``, PCSA or the
muscle volume (``weights=``).  P = 1 is an LP, P = 2 a QP, P > 2 is solved by
sequential QP or the dual Newton method (see :mod:`pinmsk.solvers.qp`), and
``minmax=True`` minimises ``max_i F_i / N_i`` (Eq. 2.13, an epigraph LP).

The problem is scaled before solving: the variables are ``x = F / F_max``
(force mode) or ``x = a``, each dof's equation is divided by that dof's
moment capacity ``s_j = max_k sum_i |R_k[i, j]| F_max,i`` (force mode) or the
active capacity (activation mode), and the cost weights are divided by their
largest value.  ``tol`` is then the largest accepted moment residual as a
fraction of ``s_j`` and proxsuite's absolute tolerance.

How frames are solved (``method="auto"``): 2 <= P <= 4 -- all frames at
once by the batched dual Newton method (every 8th frame first, the others
from multipliers interpolated in time), each frame's optimality verified by
its residual, proxsuite for the few that fail; P = 1 and min/max -- proxsuite
on a frame, then the basis of its vertex tried on the following unsolved
frames at once (kept where primal feasible, so optimal), repeated until every
frame is solved; P > 4 -- proxsuite SQP frame by frame, starting from the
P = 2 solution of the frame.  ``method="proxsuite"`` solves every frame with
proxsuite (the reference path).  See :mod:`pinmsk.solvers.qp`.

Infeasible frames (muscles too weak for the moment) raise
:class:`~pinmsk.errors.InfeasibleError` listing frames, dof and moment deficit,
unless ``reserves=True``: then each balanced dof gets an ideal actuator
``r_j`` (N m) with the exact-penalty cost
``reserve_weight * sum_j (|r_j| / s_j + (r_j / s_j)^2)`` in the scaled
problem, where a muscle at full force costs at most 1.  With the default
``reserve_weight = 1000`` reserves stay at zero wherever the muscles can
produce the moment at a marginal cost below 1000 fully-active muscles per
unit of capacity, i.e. in practice only where they cannot.

Ideal actuators (:mod:`pinmsk.actuators`: the model's, and ``actuators=`` -- an
OpenSim force set file of reserve and residual actuators) are further variables,
as in OpenSim's StaticOptimization: a control ``min_control <= u <= max_control``
whose generalized force is ``u F_opt B(q)``, costing ``|u|^P`` (times the largest
muscle coefficient); a control that may take both signs is split into two
non-negative variables, so every solver below is unchanged.  ``convention="opensim"``
takes OpenSim's muscle model (``F = a F_opt``, no passive force, activations
within the muscles' controls).  For an exact OpenSim import (dependent joints,
:func:`pinmsk.kinematics.coordinate_map`) the equations are OpenSim's coordinates'
(:func:`pinmsk.solvers.moments.balance_space`): moment arms, actuator columns and
moments all map by ``J^T``.

Fitters follow scikit-learn's habits: the constructor only stores arguments,
``fit`` returns ``self``, learned values end in ``_``, :meth:`report` prints
the objective, iterations, convergence and constraint violation.
"""
from __future__ import annotations

import time as _time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..actuators import IdealActuator, actuator_columns
from ..components import Motion
from ..dynamics import inverse_dynamics_array
from ..effects._base import SignalEffect
from ..errors import ConvergenceError, InfeasibleError, ModelError, ResidualWarning, SolverError
from ..fitting import FitStatistics, Fitter, Result, format_report
from ..kinematics import DEFAULT_CUTOFF, as_motion, prepare
from ..opensim.actuators import read_actuators
from ..opensim.muscle_import import muscle_control_bounds
from ..opensim.muscles import opensim_static_optimization_capacity
from ..residuals import floating_base_residuals
from ..trial import Trial
from . import qp as _qp
from .moments import balance_space, plan_moments, required_moments, without_actuators

MODES = ("force", "activation")
WEIGHTS = ("none", "fmax", "pcsa", "volume")
METHODS = ("auto", "proxsuite")

#: Per-frame ``status`` codes in results.
STATUS = {
    0: "optimal, KKT verified in the batched solve (dual Newton residual or LP basis)",
    1: "optimal, proxsuite",
    2: "optimal with reserve actuators in use",
}

#: Largest exponent solved by the batched dual Newton method; above it the
#: dual becomes too steep near zero forces (x ~ s^(1/(P-1))) and SQP is used.
DUAL_MAX_EXPONENT = 4.0

#: The batched dual Newton method first solves every COARSE-th frame, then the
#: others from multipliers interpolated in time (a warm start that vectorises).
COARSE = 8

#: LP basis guesses are verified on this many following unsolved frames; after
#: a guess that helps no other frame, the next LP_SKIP frames go straight to
#: proxsuite (doubling after each further failure, back to LP_SKIP on success).
LP_WINDOW = 64
LP_SKIP = 8


# ---------------------------------------------------------------------------
# The scaled problem
# ---------------------------------------------------------------------------

@dataclass
class SOProblem:
    """The scaled SO problem of a whole motion (see the module notes).

    The variables ``x`` (N, m + ns) are the muscles' (m) then the actuators' (ns
    columns: an actuator whose control may take both signs has two, ``u = x+ - x-``,
    both >= 0, so every solver sees non-negative variables with the cost
    ``x+^P + x-^P = |u|^P``).  Muscle forces are ``F = c * x + d``; actuator
    controls ``u = x[:, m:] @ S`` (:meth:`controls`); cost ``sum_i k_i x_i^P``
    (physical units) or ``max_i u_i x_i`` (min/max); the solvers see
    ``w = k / max(k)`` and ``u / max(u)``.  ``A x = b`` are the balanced dofs'
    equations divided by ``scale`` (N m).
    """

    time: np.ndarray          # (N,)
    muscles: tuple            # (m,) names
    dofs: tuple               # (nd,) balanced coordinate names
    dof_index: np.ndarray     # (nd,) columns in the balanced coordinates (q / v without a coordinate map)
    mode: str
    A: np.ndarray             # (N, nd, m + ns)
    b: np.ndarray             # (N, nd)
    lo: np.ndarray            # (N, m + ns)
    hi: np.ndarray            # (N, m + ns)
    c: np.ndarray             # (N, m)  N per unit x
    d: np.ndarray             # (N, m)  N
    R: np.ndarray             # (N, m, nd) moment arms of the balanced dofs
    tau: np.ndarray           # (N, nd) moments to balance (N m)
    scale: np.ndarray         # (nd,) N m per scaled unit
    k: np.ndarray             # (m + ns,) physical cost coefficients of x^P
    u: np.ndarray             # (m + ns,) physical min/max coefficients
    f_max: np.ndarray         # (m,)
    exponent: float
    actuators: tuple = ()                 # (na,) names
    C: np.ndarray | None = None           # (N, na, nd) generalized force per unit control (N m or N)
    split: np.ndarray | None = None       # (ns,) the actuator of each actuator variable
    sign: np.ndarray | None = None        # (ns,) +1 / -1: u = sum sign x
    optimal_force: np.ndarray | None = None   # (na,)
    stand_in: np.ndarray | None = None    # (ns,) the finite stand-in hi of an infinite bound (NaN: a real bound)

    @property
    def n_frames(self) -> int:
        return self.A.shape[0]

    @property
    def n_var(self) -> int:
        return self.A.shape[2]

    @property
    def w(self) -> np.ndarray:
        return self.k / np.max(self.k)

    @property
    def w_minmax(self) -> np.ndarray:
        return self.u / np.max(self.u)

    def forces(self, x) -> np.ndarray:
        """Muscle forces (N, m) of the variables ``x`` (N, m + ns)."""
        return self.c * x[:, :len(self.muscles)] + self.d

    def moments(self, F) -> np.ndarray:
        """The muscles' moments (N, nd) of muscle forces ``F``."""
        return np.einsum("nm,nmj->nj", F, self.R)

    def controls(self, x) -> np.ndarray:
        """Actuator controls (N, na) of the variables ``x``."""
        return _controls(self, x)

    def actuator_moments(self, u) -> np.ndarray:
        """The actuators' generalized forces (N, nd) of controls ``u`` (zero without actuators)."""
        if not self.actuators:
            return np.zeros((np.shape(u)[0], len(self.dofs)))
        return np.einsum("na,naj->nj", u, self.C)

    def cost(self, x, minmax: bool) -> np.ndarray:
        x = np.asarray(x)
        if x.shape[0] > CHUNK_FRAMES:      # a long motion's temporaries a chunk of frames at a time
            return np.concatenate([self.cost(x[k:k + CHUNK_FRAMES], minmax)
                                   for k in range(0, x.shape[0], CHUNK_FRAMES)])
        x = np.maximum(x, 0.0)
        if minmax:
            return np.max(self.u * x, axis=1)
        if self.exponent == 2.0:
            np.multiply(x, x, out=x)
        else:
            np.power(x, self.exponent, out=x)
        x *= self.k
        return np.sum(x, axis=1)


def _muscle_property(muscles, which: str) -> np.ndarray:
    if which == "none":
        return np.ones(muscles.n)
    if which == "fmax":
        return np.asarray(muscles.f_max, dtype=float)
    if which == "pcsa":
        return np.asarray(muscles.pcsa, dtype=float)
    if which == "volume":
        return np.asarray(muscles.volume, dtype=float)
    raise SolverError(f"weights must be one of {', '.join(WEIGHTS)}; got {which!r}")


def check_model(model):
    """The model's MuscleSet, or ModelError saying what is missing."""
    muscles = getattr(model, "muscles", None)
    if muscles is None or getattr(muscles, "n", 0) == 0:
        raise ModelError(f"model '{getattr(model, 'name', '?')}' has no muscles; static optimization "
                         "needs a model with muscles (e.g. load_model('forearm'))")
    f_max = np.asarray(muscles.f_max, dtype=float)
    bad = np.flatnonzero(~(f_max > 0) | ~np.isfinite(f_max))
    if bad.size:
        i = int(bad[0])
        raise ModelError(f"muscle '{muscles.names[i]}' has F_max = {f_max[i]}; it must be a finite "
                         "value > 0 (fix the model's sidecar)")
    return muscles


def resolve_dofs(model, R_all: np.ndarray, dofs, *, allow_unspanned: bool = False, names=None):
    """Names and columns of the balanced dofs; default: those spanned by at least one muscle (or actuator:
    ``R_all`` holds their columns too).  ``names``: the coordinates of ``R_all``'s last axis (default the
    model's)."""
    coords = tuple(model.coordinates if names is None else names)
    spanned = np.any(np.abs(R_all) > 0, axis=(0, 1))
    if dofs is None:
        idx = np.flatnonzero(spanned)
        if idx.size == 0:
            raise ModelError(f"no coordinate of model '{model.name}' is spanned by a muscle "
                             "(all moment arms are zero over the trial)")
    else:
        if isinstance(dofs, str):
            dofs = [dofs]
        idx = np.array([_coordinate_column(model, coords, d) for d in dofs], dtype=int)
        if len(set(idx.tolist())) != idx.size:
            raise ModelError(f"dofs lists a coordinate twice: {list(dofs)}")
        lonely = [coords[j] for j in idx if not spanned[j]]
        if lonely and not allow_unspanned:
            raise ModelError(
                f"no muscle spans {', '.join(lonely)} over this trial, so static optimization "
                "cannot balance it; leave it out of dofs (the default balances the "
                "coordinates spanned by muscles) or pass reserves=True")
    return tuple(coords[j] for j in idx), idx


def _coordinate_column(model, coords, name) -> int:
    if tuple(coords) == tuple(model.coordinates):
        return model.coordinate_index(name)
    if name not in coords:
        import difflib
        close = difflib.get_close_matches(str(name), coords, n=3)
        hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
        raise ModelError(f"no coordinate '{name}' to balance{hint} (coordinates: {', '.join(coords)})")
    return list(coords).index(name)


#: Frames per chunk in which :class:`StaticOptimization` builds and solves a long motion:
#: the per-frame arrays of one chunk only are in memory, and the batched solve's
#: working set stays in the CPU cache (``StaticOptimization(chunk_size=...)``).
CHUNK_FRAMES = 2500

#: An actuator without a bound gets a finite stand-in for the solvers (proxsuite needs finite boxes):
#: this many times the control that alone would give the largest scaled moment of the problem.  A
#: solution at a stand-in is refused (:class:`~pinmsk.errors.SolverError`), never returned.
STAND_IN_FACTOR = 1e4

#: Muscle models whose choices OpenSim's static optimization reproduces (``convention=``).
CONVENTIONS = ("pinmsk", "opensim")


def _frame_capacity(R: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(n, nd) moment capacity ``sum_i |R_kij| c_ki`` of each frame and dof."""
    return np.einsum("nmj,nm->nj", np.abs(R), c)


def _controls(prob, x) -> np.ndarray:
    na = len(prob.actuators)
    if not na:
        return np.zeros((np.shape(x)[0], 0))
    S = np.zeros((prob.split.size, na))
    S[np.arange(prob.split.size), prob.split] = prob.sign
    return np.asarray(x)[:, len(prob.muscles):] @ S


def _split_bounds(lo: np.ndarray, hi: np.ndarray):
    """The non-negative variables of controls ``lo <= u <= hi``: ``(actuator, sign, lo, hi)`` arrays,
    ``u = x`` where ``lo >= 0``, ``u = -x`` where ``hi <= 0``, both (``u = x+ - x-``) otherwise."""
    split, sign, vlo, vhi = [], [], [], []
    for i, (a, b) in enumerate(zip(lo, hi)):
        if b > 0.0:
            split.append(i), sign.append(1.0), vlo.append(max(a, 0.0)), vhi.append(b)
        if a < 0.0:
            split.append(i), sign.append(-1.0), vlo.append(max(-b, 0.0)), vhi.append(-a)
        if a == b == 0.0:
            split.append(i), sign.append(1.0), vlo.append(0.0), vhi.append(0.0)
    return (np.array(split, dtype=int), np.array(sign), np.array(vlo, dtype=float), np.array(vhi, dtype=float))


class ChunkedSOProblem:
    """The scaled SO problem of a long motion, its per-frame arrays built a chunk at a time.

    It has the whole-motion parts of :class:`SOProblem` (``time``, ``muscles``,
    ``dofs``, ``dof_index``, ``mode``, ``tau``, ``scale``, ``k``, ``u``,
    ``f_max``, ``exponent``, the actuators'; the scale from every frame, so each chunk is the
    same problem as in one piece) and builds the per-frame ones (``A``, ``b``,
    ``lo``, ``hi``, ``c``, ``d``, ``R``, ``C``) for frames ``[start, stop)`` on demand
    with :meth:`frames`.  :func:`solve_frames` solves it chunk by chunk.  Reading
    one of the per-frame arrays builds it for the whole motion (cached).

    ``space`` (:class:`~pinmsk.solvers.moments.BalanceSpace`, default the model's coordinates): the
    coordinates whose equations are balanced.  ``actuators``: ideal actuators
    (:mod:`pinmsk.actuators`), extra variables with their control bounds and cost ``|u|^P``.
    ``convention="opensim"``: the muscle model of OpenSim's StaticOptimization (see
    :class:`StaticOptimization`); ``muscle_bounds``: (lo, hi) arrays (m,) of the muscle variables.
    """

    _PER_FRAME = ("A", "b", "lo", "hi", "c", "d", "R", "C")

    def __init__(self, model, motion: Motion, *, mode: str, weights: str, exponent: float, dofs,
                 moments, reserves: bool, chunk_size: int, actuators=(), space=None, convention: str = "pinmsk",
                 muscle_bounds=None, data=None):
        if mode not in MODES:
            raise SolverError(f"mode must be one of {', '.join(MODES)}; got {mode!r}")
        if convention not in CONVENTIONS:
            raise SolverError(f"convention must be one of {', '.join(CONVENTIONS)}; got {convention!r}")
        P = _qp.check_exponent(exponent)
        muscles = check_model(model)
        n, m = motion.n_frames, muscles.n
        self.time = np.asarray(motion.t, dtype=float)
        self.chunk_size = max(int(chunk_size), 1)
        self._muscle_set = muscles
        self._q, self._v = motion.q, motion.v
        self.mode = mode
        self.convention = convention
        self._space = space
        nv = model.nv if space is None else space.n
        coord_names = model.coordinates if space is None else space.names
        f_max = np.asarray(muscles.f_max, dtype=float)
        # the actuators: their columns over the whole motion (Pinocchio kinematics once), in the space
        acts = tuple(actuators)
        self.actuators = tuple(a.name for a in acts)
        na = len(acts)
        if na:
            C = actuator_columns(model, motion, acts, data=data)
            self._C_all = C if space is None else space.arms(C)
            a_lo = np.array([a.min_control for a in acts])
            a_hi = np.array([a.max_control for a in acts])
            self.optimal_force = np.array([a.values["optimal_force"] for a in acts])
        else:
            self._C_all = np.zeros((n, 0, nv))
            a_lo = a_hi = self.optimal_force = np.zeros(0)
        self.split, self.sign, self._v_lo, self._v_hi = _split_bounds(a_lo, a_hi)
        lo_m, hi_m = (np.zeros(m), np.ones(m)) if muscle_bounds is None else \
            (np.asarray(muscle_bounds[0], dtype=float), np.asarray(muscle_bounds[1], dtype=float))
        self._m_lo, self._m_hi = lo_m, hi_m
        # whole-motion statistics a chunk at a time: which coordinates the muscles
        # span (max |R|) and each coordinate's moment capacity (the scale)
        arm_max = np.zeros((m, nv))
        cap_max = np.zeros(nv)
        self._whole = None
        for start, stop in self.chunks(n):
            R, c, d = self._arms_and_forces(slice(start, stop))
            if R.shape != (stop - start, m, nv):
                raise ModelError(f"moment arms have shape {(n,) + R.shape[1:]}; expected {(n, m, nv)}")
            np.maximum(arm_max, np.max(np.abs(R), axis=0, initial=0.0), out=arm_max)
            np.maximum(cap_max, np.max(_frame_capacity(R, c * np.maximum(np.abs(hi_m), np.abs(lo_m))), axis=0,
                                       initial=0.0), out=cap_max)
            if stop - start == n:
                self._whole = (R, c, d)       # one chunk: keep it rather than build it again
        act_max = np.max(np.abs(self._C_all), axis=0, initial=0.0) if na else np.zeros((0, nv))
        spans = np.concatenate([self._whole[0] if self._whole else arm_max[None],
                                np.broadcast_to(act_max, (1,) + act_max.shape) if self._whole is None
                                else self._C_all], axis=1)
        names, idx = resolve_dofs(model, spans, dofs, allow_unspanned=reserves, names=coord_names)
        if moments is None and space is not None and not space.identity:
            moments = space.forces(inverse_dynamics_array(without_actuators(model), motion, actuated=False))
        tau = required_moments(model, motion, moments, idx, names, width=nv)
        if convention == "opensim":
            if weights != "none":
                raise SolverError(f"convention='opensim' costs the activations as OpenSim does (sum a^P, "
                                  f"a = F / F_max in force mode); weights={weights!r} is not OpenSim's: leave "
                                  "weights at 'none'")
            prop = f_max.copy() if mode == "force" else np.ones(m)
        else:
            prop = _muscle_property(muscles, weights)
        if np.any(~(prop > 0)):
            i = int(np.flatnonzero(~(prop > 0))[0])
            raise ModelError(f"muscle '{muscles.names[i]}' has {weights} = {prop[i]}; weights need "
                             "positive values")
        scale = cap_max[idx].copy()
        for j in np.flatnonzero(~(scale > 0)):
            scale[j] = max(float(np.max(np.abs(tau[:, j]))), 1.0)
        self.muscles = tuple(muscles.names)
        self.dofs = names
        self.dof_index = idx
        self.tau = tau
        self.scale = scale
        k_m = (f_max / prop) ** P if mode == "force" else prop.copy()
        u_m = f_max / prop if mode == "force" else prop.copy()
        # an actuator's control u costs |u|^P times the largest muscle coefficient: u = 1 costs what the
        # most expensive fully active muscle costs (OpenSim's sum of |u|^P over all its actuators when
        # the muscle coefficients are 1: activation mode, or force mode with F_max weights)
        self.k = np.concatenate([k_m, np.full(self.split.size, np.max(k_m))])
        self.u = np.concatenate([u_m, np.full(self.split.size, np.max(u_m))])
        self.f_max = f_max
        self.exponent = P
        # finite stand-ins for infinite control bounds (see STAND_IN_FACTOR)
        infinite = ~np.isfinite(self._v_hi)
        self.stand_in = np.full(self.split.size, np.nan)
        if infinite.any():
            cols = np.abs(self._C_all[:, self.split, :][:, :, idx]) / scale       # (N, ns, nd)
            col_max = np.max(cols, axis=(0, 2), initial=0.0)
            b_max = (float(np.max(np.abs(tau) / scale, initial=0.0))
                     + float(m) * float(np.max(np.abs(hi_m), initial=1.0)))
            need = np.where(col_max > 0, (1.0 + b_max) / np.where(col_max > 0, col_max, 1.0), 1.0)
            self._v_hi = np.where(infinite, STAND_IN_FACTOR * need, self._v_hi)
            self.stand_in = np.where(infinite, self._v_hi, np.nan)
        self._full = None

    def _arms_and_forces(self, rows):
        """Moment arms (n, m, ns) and ``F = c x + d`` coefficients (n, m) of frames ``rows`` (a slice or indices)."""
        muscles, q, v = self._muscle_set, self._q[rows], self._v[rows]
        n = q.shape[0]
        if self.mode == "force":
            R = np.asarray(muscles.moment_arms(q), dtype=float)
        else:           # the paths evaluated once for the arms, lengths and velocities
            lengths, speeds, R = muscles.path_kinematics(q, v)
            R = np.asarray(R, dtype=float)
        if self._space is not None:
            R = self._space.arms(R, rows)
        if self.mode == "force":
            f_max = np.asarray(muscles.f_max, dtype=float)
            return R, np.broadcast_to(f_max, (n, f_max.size)).copy(), np.zeros((n, f_max.size))
        if self.convention == "opensim":
            c = opensim_static_optimization_capacity(muscles.mtu, lengths, speeds)
            c = np.asarray(c, dtype=float)
            d = np.zeros_like(c)
        else:
            fa, fp = muscles.force_limits_from(lengths, speeds)
            c = np.maximum(np.asarray(fa, dtype=float), 0.0)
            d = np.asarray(fp, dtype=float)
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(d))):
            k0, i0 = np.argwhere(~np.isfinite(c + d))[0]
            k = int(np.arange(self.time.size)[rows][k0])
            raise SolverError(f"muscle '{muscles.names[i0]}' force capacity is not finite at frame "
                              f"{k} (t = {self.time[k]:.6g} s)")
        return R, c, d

    @property
    def n_frames(self) -> int:
        return self._q.shape[0]

    @property
    def n_var(self) -> int:
        return len(self.muscles) + self.split.size

    @property
    def is_chunked(self) -> bool:
        return self.n_frames > self.chunk_size

    def chunks(self, n: int | None = None):
        """``(start, stop)`` of each chunk of frames."""
        n = self.n_frames if n is None else n
        return [(s, min(s + self.chunk_size, n)) for s in range(0, n, self.chunk_size)]

    def frames(self, start: int, stop: int) -> SOProblem:
        """The :class:`SOProblem` of frames ``[start, stop)`` (scaled as the whole motion)."""
        if self._whole is not None and (start, stop) == (0, self.n_frames):
            return self._build(slice(start, stop), self._whole)
        return self._build(slice(start, stop))

    def frames_at(self, rows) -> SOProblem:
        """The :class:`SOProblem` of the frames ``rows`` (indices), each as in :meth:`frames`."""
        return self._build(np.asarray(rows, dtype=int))

    def _build(self, rows, arrays=None) -> SOProblem:
        R_all, c, d = self._arms_and_forces(rows) if arrays is None else arrays
        R = np.ascontiguousarray(R_all[:, :, self.dof_index])
        tau = self.tau[rows]
        A = np.einsum("nmj,nm->njm", R, c)
        C = np.ascontiguousarray(self._C_all[rows][:, :, self.dof_index])
        if self.split.size:
            A_act = np.swapaxes(C[:, self.split, :] * self.sign[None, :, None], 1, 2)
            A = np.concatenate([A, A_act], axis=2)
        A /= self.scale[None, :, None]
        b = (tau - np.einsum("nmj,nm->nj", R, d)) / self.scale
        n, m = R.shape[0], len(self.muscles)
        lo = np.concatenate([np.broadcast_to(self._m_lo, (n, m)), np.broadcast_to(self._v_lo, (n, self.split.size))],
                            axis=1)
        hi = np.concatenate([np.broadcast_to(self._m_hi, (n, m)), np.broadcast_to(self._v_hi, (n, self.split.size))],
                            axis=1)
        return SOProblem(time=self.time[rows], muscles=self.muscles, dofs=self.dofs,
                         dof_index=self.dof_index, mode=self.mode, A=A, b=b, lo=lo, hi=hi, c=c, d=d, R=R, tau=tau,
                         scale=self.scale, k=self.k, u=self.u, f_max=self.f_max, exponent=self.exponent,
                         actuators=self.actuators, C=C, split=self.split, sign=self.sign,
                         optimal_force=self.optimal_force, stand_in=self.stand_in)

    def __getattr__(self, name):
        if name in ChunkedSOProblem._PER_FRAME:
            if self.__dict__.get("_full") is None:
                self._full = self.frames(0, self.n_frames)
            return getattr(self._full, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    w = SOProblem.w
    w_minmax = SOProblem.w_minmax
    cost = SOProblem.cost
    controls = SOProblem.controls

    def forces(self, x) -> np.ndarray:
        return np.concatenate([self.frames(s, e).forces(x[s:e]) for s, e in self.chunks()])

    def moments(self, F) -> np.ndarray:
        return np.concatenate([self.frames(s, e).moments(F[s:e]) for s, e in self.chunks()])

    def actuator_moments(self, u) -> np.ndarray:
        if not self.actuators:
            return np.zeros((np.shape(u)[0], len(self.dofs)))
        return np.einsum("na,naj->nj", u, self._C_all[:, :, self.dof_index])

    def __repr__(self) -> str:
        return (f"ChunkedSOProblem({self.n_frames} frames in chunks of {self.chunk_size}, "
                f"{len(self.muscles)} muscles, {len(self.actuators)} actuators, dofs {', '.join(self.dofs)})")


def build_problem(model, motion: Motion, *, mode: str = "force", weights: str = "none",
                  exponent: float = 2.0, dofs=None, moments=None, reserves: bool = False,
                  chunk_size: int | None = None, actuators=(), space=None, convention: str = "pinmsk",
                  muscle_bounds=None, data=None):
    """The scaled SO problem of ``motion`` (moments by inverse dynamics unless given).

    An :class:`SOProblem`; with ``chunk_size`` and a motion of more frames, a
    :class:`ChunkedSOProblem` that builds its per-frame arrays a chunk at a time.
    ``actuators``, ``space``, ``convention``, ``muscle_bounds``: see :class:`ChunkedSOProblem`.
    """
    prob = ChunkedSOProblem(model, motion, mode=mode, weights=weights, exponent=exponent, dofs=dofs,
                            moments=moments, reserves=reserves,
                            chunk_size=motion.n_frames if chunk_size is None else chunk_size,
                            actuators=actuators, space=space, convention=convention,
                            muscle_bounds=muscle_bounds, data=data)
    return prob if prob.is_chunked else prob.frames(0, prob.n_frames)


# ---------------------------------------------------------------------------
# Solving all frames
# ---------------------------------------------------------------------------

@dataclass
class FramesResult:
    """Scaled solution of all frames with bookkeeping."""

    x: np.ndarray            # (N, m + ns) muscles then actuator variables
    rho: np.ndarray          # (N, nd) scaled reserves
    solved: np.ndarray       # (N,) bool
    path: np.ndarray         # (N,) 0 batched, 1 proxsuite
    iterations: int          # Newton + proxsuite iterations
    qp_solves: int           # proxsuite QPs
    batched_frames: int
    forces: np.ndarray | None = None    # (N, m) N, when solved chunk by chunk
    moments: np.ndarray | None = None   # (N, nd) N m of the muscles and actuators, in one piece
    violation: np.ndarray | None = None  # (N,) largest |moments (+ reserves) - tau|, when solved by chunks


def _frame_qp(prob: SOProblem, *, exponent, minmax, reserve_weight, tol) -> _qp.FrameQP:
    m, nd = prob.n_var, len(prob.dofs)
    return _qp.FrameQP(m=m, nd=nd, weights=prob.w_minmax if minmax else prob.w, exponent=exponent,
                       minmax=minmax, reserve_weight=reserve_weight, eps=tol * 1e-4,
                       sqp_tol=max(tol * 1e-2, 1e-13))


def solve_frames(prob: SOProblem, *, minmax: bool = False, reserve_weight: float | None = None,
                 tol: float = 1e-9, method: str = "auto", progress=None,
                 frames: np.ndarray | None = None) -> FramesResult:
    """Solve the frames of a scaled problem (all, or ``frames``); see the module notes.

    A :class:`ChunkedSOProblem` is built and solved a chunk at a time, with the
    same steps on the same frames as in one piece: the batched solve is per
    frame, its warm starts come from multipliers interpolated over the whole
    motion, and one proxsuite QP is carried across chunks, so the result is
    the same (only LP basis guesses, P = 1 and min/max, stop at a chunk's
    end).  Its result also holds the forces and the muscles' moments.
    """
    if method not in METHODS:
        raise SolverError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    chunked = isinstance(prob, ChunkedSOProblem)
    P = prob.exponent
    N, nd, m = prob.n_frames, len(prob.dofs), prob.n_var
    spans = prob.chunks() if chunked else [(0, N)]
    sel = np.arange(N) if frames is None else np.asarray(frames, dtype=int)
    x = np.full((N, m), np.nan)
    rho = np.zeros((N, nd))
    solved = np.zeros(N, dtype=bool)
    path = np.full(N, -1, dtype=int)
    forces = np.full((N, len(prob.muscles)), np.nan) if chunked else None
    violation = np.zeros(N) if chunked else None
    iters = 0
    nqp = 0
    batched = 0
    dual = method == "auto" and not minmax and 2.0 <= P <= DUAL_MAX_EXPONENT
    batched_ok = np.zeros(N, dtype=bool)

    def batch(rows_of, ip, lam0):
        """dual_newton on the frames ``sel[ip]``; ``rows_of(frames)`` gives their (A, b, lo, hi)."""
        nonlocal iters
        fr = sel[ip]
        A, b, lo, hi = rows_of(fr)
        bs = _qp.dual_newton(A, b, prob.w, P, lo, hi, reserve_weight=reserve_weight, tol=tol, lam0=lam0)
        ok = bs.converged
        batched_ok[fr[ok]] = True
        x[fr[ok]] = bs.x[ok]
        rho[fr[ok]] = bs.rho[ok]
        iters += int(bs.iterations.sum())
        return ok, bs.lam

    def rows(p, offset=0):
        return lambda fr: (p.A[fr - offset], p.b[fr - offset], p.lo[fr - offset], p.hi[fr - offset])

    second = lam0_all = None
    if dual:
        second = np.arange(sel.size)
        if sel.size > 4 * COARSE:
            # two passes: every COARSE-th frame from scratch, then the others starting from
            # the multipliers interpolated in time between their solved neighbours
            first = np.arange(0, sel.size, COARSE)
            second = np.setdiff1d(np.arange(sel.size), first)
            lam_known = np.full((first.size, nd), np.nan)       # the multipliers of the first pass' frames
            for start, stop in spans:
                inside = (sel[first] >= start) & (sel[first] < stop)
                ip = first[inside]
                if ip.size:
                    if chunked:   # build the rows of these frames alone
                        part = prob.frames_at(sel[ip])
                        got = lambda fr, p=part: (p.A, p.b, p.lo, p.hi)
                    else:
                        got = rows(prob)
                    ok, lam = batch(got, ip, None)
                    lam_known[np.flatnonzero(inside)[ok]] = lam[ok]
            good = np.flatnonzero(~np.isnan(lam_known[:, 0])) if nd else np.zeros(0, int)
            if good.size >= 2:
                # interpolated a chunk at a time, where they are used
                lam0_all = (first[good], lam_known[good])
    fq = _frame_qp(prob, exponent=P, minmax=minmax, reserve_weight=reserve_weight, tol=tol)
    use_lp = (method == "auto" and (minmax or P == 1.0) and reserve_weight is None)
    remaining = np.zeros(N, dtype=bool)
    skip = 0
    skip_next = LP_SKIP
    for start, stop in spans:
        here = sel[(sel >= start) & (sel < stop)]
        if here.size == 0:
            continue
        sub, off = (prob.frames(start, stop), start) if chunked else (prob, 0)
        if dual:
            inside = (sel[second] >= start) & (sel[second] < stop)
            if inside.any():
                lam0 = None
                if lam0_all is not None:
                    at, known = lam0_all
                    lam0 = np.column_stack([np.interp(second[inside], at, known[:, j]) for j in range(nd)])
                batch(rows(sub, off), second[inside], lam0)
            done = here[batched_ok[here]]
            solved[done] = True
            path[done] = 0
            batched += done.size
            if progress is not None:
                progress.update(int(done.size))
            todo = here[~batched_ok[here]]
        else:
            todo = here
        if use_lp:
            E, f, cvec, lo_a, hi_a, ne = _lp_standard_form(sub, minmax)
        remaining[todo] = True
        for k in todo:
            if not remaining[k]:
                continue
            remaining[k] = False
            kl = k - off
            sol = fq.solve(sub.A[kl], sub.b[kl], sub.lo[kl], sub.hi[kl])
            iters += sol.iterations
            nqp += sol.qp_solves
            done_now = 1
            if sol.solved:
                x[k], rho[k], solved[k], path[k] = sol.x, sol.rho, True, 1
                if use_lp and skip > 0:
                    skip -= 1
                elif use_lp:
                    # try this frame's basis on the next LP_WINDOW unsolved frames at once
                    zk = _lp_point(sub, kl, sol.x, minmax)
                    basis = _qp.lp_basis_from(zk, lo_a[kl], hi_a[kl], ne)
                    rest = np.flatnonzero(remaining[start:stop])[:LP_WINDOW]
                    cand = np.concatenate([[kl], rest])
                    okv, zv, _ = _qp.lp_verify(E[cand], f[cand], cvec, lo_a[cand], hi_a[cand], basis,
                                               tol=tol)
                    if okv[0]:
                        x[k] = zv[0, :m]
                        path[k] = 0
                    acc = cand[1:][okv[1:]] + off
                    x[acc] = zv[1:][okv[1:], :m]
                    solved[acc] = True
                    path[acc] = 0
                    remaining[acc] = False
                    batched += int(acc.size) + int(okv[0])
                    done_now += int(acc.size)
                    if acc.size == 0:          # degenerate or changing bases: stop guessing for a
                        skip = skip_next        # while, twice as long after each failure (min/max
                        skip_next = min(2 * skip_next, 512)   # with several dofs is rarely a vertex)
                    else:
                        skip_next = LP_SKIP
            if progress is not None:
                progress.update(done_now)
        xs = x[start:stop]
        x[start:stop] = np.where(np.isfinite(xs), np.clip(xs, sub.lo, sub.hi), xs)   # proxsuite: inside to ~1e-16
        if chunked:
            forces[start:stop] = sub.forces(x[start:stop])
            # the balance each frame reaches, a chunk at a time (the whole motion's moments are not kept)
            bal = sub.moments(forces[start:stop]) + sub.actuator_moments(sub.controls(x[start:stop]))
            if reserve_weight is not None:
                bal += rho[start:stop] * prob.scale
            bal -= sub.tau
            violation[start:stop] = np.max(np.abs(bal), axis=1, initial=0.0)
    return FramesResult(x=x, rho=rho, solved=solved, path=path, iterations=iters, qp_solves=nqp,
                        batched_frames=batched, forces=forces, violation=violation)


def _by_chunk(prob, frames):
    """``(problem, local frame, position in frames)`` for each of ``frames``, one build per chunk."""
    frames = np.asarray(frames, dtype=int)
    if not isinstance(prob, ChunkedSOProblem):
        for i, k in enumerate(frames):
            yield prob, int(k), i
        return
    for start, stop in prob.chunks():
        here = np.flatnonzero((frames >= start) & (frames < stop))
        if here.size:
            sub = prob.frames(start, stop)
            for i in here:
                yield sub, int(frames[i]) - start, int(i)


def _lp_standard_form(prob: SOProblem, minmax: bool):
    """``min c'z, E z = f, lo <= z <= hi`` of P = 1 (z = x) or min/max (z = [x, t, sigma])."""
    N, nd, m = prob.A.shape
    if not minmax:
        return prob.A, prob.b, prob.w.copy(), prob.lo, prob.hi, nd
    u = prob.w_minmax
    n = 2 * m + 1
    E = np.zeros((N, nd + m, n))
    E[:, :nd, :m] = prob.A
    E[:, nd:, :m] = np.diag(u)
    E[:, nd:, m] = -1.0
    E[:, nd:, m + 1:] = np.eye(m)
    f = np.zeros((N, nd + m))
    f[:, :nd] = prob.b
    c = np.zeros(n)
    c[m] = 1.0
    lo = np.zeros((N, n))
    lo[:, :m] = prob.lo
    hi = np.full((N, n), _qp.BIG)
    hi[:, :m] = prob.hi
    return E, f, c, lo, hi, nd + m


def _lp_point(prob: SOProblem, k: int, x, minmax: bool):
    if not minmax:
        return np.asarray(x, dtype=float)
    u = prob.w_minmax
    t = float(np.max(u * x))
    return np.concatenate([x, [t], t - u * x])


def diagnose_infeasible(prob: SOProblem, frames, *, minmax: bool, tol: float):
    """Moment deficits (frames, nd) in N m of frames that have no solution, via strong reserves."""
    frames = np.asarray(frames, dtype=int)
    fq = _frame_qp(prob, exponent=min(prob.exponent, 2.0) if not minmax else 1.0, minmax=minmax,
                   reserve_weight=1e4, tol=tol)
    out = np.full((frames.size, len(prob.dofs)), np.nan)
    for sub, k, i in _by_chunk(prob, frames):
        sol = fq.solve(sub.A[k], sub.b[k], sub.lo[k], sub.hi[k])
        if sol.solved:
            out[i] = sol.rho * prob.scale
    return out


def infeasible_message(prob: SOProblem, frames, deficits, *, limit: int = 8, note: str = "") -> str:
    lines = []
    for i, k in enumerate(frames[:limit]):
        parts = []
        for j, dof in enumerate(prob.dofs):
            dj = deficits[i, j]
            if np.isfinite(dj) and abs(dj) > 1e-6 * prob.scale[j]:
                parts.append(f"{dof} short by {dj:+.4g} N m (needs {prob.tau[k, j]:+.4g})")
        if not parts:
            parts.append("no solution found (deficit not quantified)")
        lines.append(f"  frame {k} (t = {prob.time[k]:.4g} s): " + "; ".join(parts))
    more = f"\n  ... and {len(frames) - limit} more frames" if len(frames) > limit else ""
    return (f"the muscles cannot produce the required moments at {len(frames)} of "
            f"{prob.n_frames} frames:\n" + "\n".join(lines) + more + (f"\n{note}" if note else "") +
            "\nPass reserves=True (CLI --reserves) to add ideal actuators with a high cost and see "
            "their use per dof and frame, or check the model's strength and the inverse dynamics.")


# ---------------------------------------------------------------------------
# The fitter
# ---------------------------------------------------------------------------

class StaticOptimization(Fitter):
    """Static optimization of muscle forces over a whole trial (thesis Eq. 2.11-2.14, 3.13-3.14).

    Parameters (keyword-only)
    -------------------------
    mode : "force" | "activation"
        Unknown forces ``0 <= F <= F_max``, or activations ``0 <= a <= 1`` with
        ``F = a F_active + F_passive`` at the trial's muscle lengths and velocities.
    exponent : float
        P of the cost ``sum (F/N)^P`` (or ``sum S a^P``): 1 (LP), 2 (QP), >= 2.
    weights : "none" | "fmax" | "pcsa" | "volume"
        ``N_i`` (force mode) or ``S_i`` (activation mode).
    minmax : bool
        Minimise ``max_i F_i / N_i`` (``max S_i a_i``) instead, Eq. 2.13.
    reserves : bool
        Add one ideal actuator per balanced dof with cost ``reserve_weight``
        (see the module notes) instead of raising InfeasibleError.
    reserve_weight : float
        Cost of a reserve using one dof's full muscle capacity, in units of one
        fully active muscle of the highest weight (default 1000).
    tol : float
        Scaled tolerance: the moment residual as a fraction of each dof's
        capacity and proxsuite's eps_abs (default 1e-9).
    dofs : sequence of str or None
        Coordinates whose moments the muscles must balance; default the
        coordinates spanned by at least one muscle (so a floating base's
        unactuated coordinates and muscle-free joints are left out).
    method : "auto" | "proxsuite"
        "auto" uses the batched paths with proxsuite as fallback;
        "proxsuite" solves every frame with proxsuite.
    chunk_size : int
        Frames built and solved at a time (default :data:`CHUNK_FRAMES`): a
        long motion's per-frame problem arrays are never all in memory.  It
        changes memory and speed only, not the result (so not recorded in the result's meta).
    actuators : path, sequence of actuators, or None
        Ideal actuators (:mod:`pinmsk.actuators`: OpenSim's reserve and residual
        CoordinateActuator, PointActuator, TorqueActuator) sharing the moments
        with the muscles: the model's own actuator components always, plus an
        OpenSim force set file (``*_Reserve_Actuators.xml``) or components given
        here.  Each is a variable ``min_control <= u <= max_control`` with the
        cost ``|u|^P`` times the largest muscle coefficient (a control of 1
        costs what the most expensive fully active muscle costs: OpenSim's
        ``sum |u|^P`` over all actuators when the muscles' coefficients are 1,
        as in activation mode or with ``convention="opensim"``); its channels
        are ``<name>_control`` and ``<name>_force``.
        The coordinates they span count as spanned (the pelvis of a gait model
        with residual actuators is balanced).  Not the same as ``reserves``
        (pinmsk's unnamed, heavily penalised actuator per dof).
    convention : "pinmsk" | "opensim"
        The muscle model.  ``"pinmsk"`` (default): the physical one above
        (passive forces included, activations in [0, 1]).  ``"opensim"``:
        OpenSim's StaticOptimization, for like-for-like comparisons --
        activation mode as ``use_muscle_physiology`` (``F = a F_opt`` with
        OpenSim's ``calcInextensibleTendonActiveFiberForce`` at the
        rigid-tendon fiber length and velocity and *no* passive force,
        :func:`pinmsk.opensim.muscles.opensim_static_optimization_capacity`),
        force mode as without it (``F = a F_max``, cost ``sum a^P``); the
        activations bounded by the muscles' ``min_control``/``max_control``
        (OpenSim's defaults 0.01..1 for Thelen and Millard muscles; 0..1 for a
        model not imported from an .osim).  Not the default: OpenSim's SO leaves
        the passive fiber forces unbalanced and, for Millard 2012 and De Groote
        2016 muscles, takes a capacity that is not the force along the tendon.

    Attributes (after ``fit``)
    --------------------------
    forces_ (N, m) N; activations_ (N, m) -- in force mode ``F / F_max`` (the
    activation the force needs at optimal length and zero velocity);
    reserves_ (N, nd) N m or None; status_ (N,) codes of :data:`STATUS`;
    cost_ (N,) the criterion per frame in physical units (Eq. 2.11 / 2.14, or
    ``max F/N`` for min/max); violation_ (N,) ``max_j |R^T F + r - tau|`` in
    N m; dofs_, muscles_; n_iter_, n_qp_, n_batched_; timing_; problem_ (the
    scaled :class:`SOProblem`, or :class:`ChunkedSOProblem` for motions longer
    than ``chunk_size``); result_ (a :class:`~pinmsk.fitting.Result`: the
    Trial of ``<muscle>_force``, ``<muscle>_activation``, ``<coord>_reserve``
    with reserves, ``status``, ``cost``, ``violation`` -- write it with
    :func:`pinmsk.write_trial` -- and its statistics: ``k`` the free
    variables, ``objective`` the summed criterion, ``violation`` the largest
    moment residual in N m; an effort minimisation has no AIC/BIC).
    """

    #: parameters that change speed or memory only, left out of the result's meta
    _NOT_RECORDED = ("chunk_size",)

    def __init__(self, *, mode: str = "force", exponent: float = 2, weights: str = "none",
                 minmax: bool = False, reserves: bool = False, reserve_weight: float = 1000.0,
                 tol: float = 1e-9, dofs=None, method: str = "auto", chunk_size: int = CHUNK_FRAMES,
                 actuators=None, convention: str = "pinmsk"):
        self.mode = mode
        self.exponent = exponent
        self.weights = weights
        self.minmax = minmax
        self.reserves = reserves
        self.reserve_weight = reserve_weight
        self.tol = tol
        self.dofs = dofs
        self.method = method
        self.chunk_size = chunk_size
        self.actuators = actuators
        self.convention = convention

    def _check_params(self):
        if self.mode not in MODES:
            raise SolverError(f"mode must be one of {', '.join(MODES)}; got {self.mode!r}")
        if self.weights not in WEIGHTS:
            raise SolverError(f"weights must be one of {', '.join(WEIGHTS)}; got {self.weights!r}")
        if self.method not in METHODS:
            raise SolverError(f"method must be one of {', '.join(METHODS)}; got {self.method!r}")
        if self.convention not in CONVENTIONS:
            raise SolverError(f"convention must be one of {', '.join(CONVENTIONS)}; got {self.convention!r}")
        _qp.check_exponent(self.exponent)
        if not (float(self.tol) > 0):
            raise SolverError(f"tol must be > 0; got {self.tol!r}")
        if self.reserves and not (float(self.reserve_weight) > 0):
            raise SolverError(f"reserve_weight must be > 0; got {self.reserve_weight!r}")
        if isinstance(self.chunk_size, bool) or not isinstance(self.chunk_size, (int, np.integer)) \
                or self.chunk_size < 1:
            raise SolverError(f"chunk_size must be a whole number of frames >= 1; got {self.chunk_size!r}")

    # -- fitting -----------------------------------------------------------
    def fit(self, model, trial, *, moments=None, cutoff=DEFAULT_CUTOFF, grf=None, external_loads=None,
            frames=None, ground_reaction: str = "auto", grf_cutoff="auto", progress=None,
            missing_coordinates: str = "refuse"):
        """Solve every frame of ``trial`` (a Trial or a Motion); returns ``self``.

        The trial goes through :func:`pinmsk.kinematics.prepare` (coordinates and
        GRF low-passed at ``cutoff`` Hz, default 6, 0 = off; the GRF -- the
        trial's own, ``grf=`` or ``external_loads=`` -- on the feet).
        ``moments``: ``"id"`` (default, inverse dynamics), ``"measured"`` (the
        trial's ``<coord>_moment`` channels), a Trial or an (N, nv) / (N, n_dofs)
        array.  Coordinates no muscle spans are handled by
        :func:`pinmsk.solvers.moments.plan_moments`: an error without reserves
        where they need a force, a reported reserve with them.
        ``progress``: an object with ``update(n)`` (e.g. pinmsk.presentation.progress.Progress).
        """
        self._check_params()
        t0 = _time.perf_counter()
        check_model(model)
        inputs = prepare(model, trial, cutoff=cutoff, grf=grf, external_loads=external_loads, frames=frames,
                         ground_reaction=ground_reaction, grf_cutoff=grf_cutoff,
                         missing_coordinates=missing_coordinates)
        motion = as_motion(model, inputs.motion)
        acts = self._actuators(model)
        space = balance_space(model, motion)
        data = model.create_data()
        arms = space.arms(actuator_columns(model, motion, acts, data=data)) if acts else None
        plan = plan_moments(model, trial, inputs, moments=moments, dofs=self.dofs, reserves=self.reserves,
                            space=space, actuator_arms=arms)
        prob = build_problem(model, motion, mode=self.mode, weights=self.weights,
                             exponent=self.exponent, dofs=plan.dofs, moments=plan.tau,
                             reserves=self.reserves, chunk_size=self.chunk_size, actuators=acts, space=space,
                             convention=self.convention, muscle_bounds=self._muscle_bounds(model), data=data)
        t1 = _time.perf_counter()
        self.actuators_ = acts
        self._actuator_units = {a.name: a.actuation_unit(model) for a in acts}
        self.inputs_ = inputs
        self.plan_ = plan
        self.residuals_ = (floating_base_residuals(model, motion, plan.tau_full, inputs.external)
                           if plan.tau_full is not None else None)
        if self.residuals_ is not None and self.residuals_.warning():
            warnings.warn(self.residuals_.warning(), ResidualWarning, stacklevel=2)
        self._model_rot = tuple(model.rotational_coordinates)
        self._solve(prob, progress=progress)
        t2 = _time.perf_counter()
        self.timing_ = {"setup_s": t1 - t0, "solve_s": t2 - t1, "total_s": t2 - t0}
        self.model_name_ = getattr(model, "name", "?")
        self._signal_effects = tuple(c for c in model.effects if isinstance(c, SignalEffect))
        self.result_ = self._result(prob)
        return self

    def _actuators(self, model) -> tuple:
        """The model's actuator components and those of ``actuators=`` (a force set file or components)."""
        own = [c for c in model.components if c.kind == "actuator"]
        given = self.actuators
        if given is None:
            extra = []
        elif isinstance(given, (str, Path)):
            extra = list(read_actuators(given, model)[0])
        else:
            extra = list(given)
            for a in extra:
                if not isinstance(a, IdealActuator):
                    raise SolverError(f"actuators= takes a force set file or pinmsk.actuators components, not "
                                      f"{type(a).__name__}")
                a.check_target(model)
        names = [a.name for a in own + extra]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            where = " (the model has them already)" if any(n in [a.name for a in own] for n in dup) else ""
            raise SolverError(f"actuator(s) {dup} appear twice{where}; give each actuator once")
        return tuple(own + extra)

    def _muscle_bounds(self, model):
        """The muscles' activation bounds: [0, 1], or with ``convention="opensim"`` their min/max controls."""
        if self.convention != "opensim":
            return None
        cb = muscle_control_bounds(model.meta.get("import_report")) or {}
        names = model.muscles.names
        lo = np.array([cb.get(n, (0.0, 1.0))[0] for n in names], dtype=float)
        hi = np.array([cb.get(n, (0.0, 1.0))[1] for n in names], dtype=float)
        bad = np.flatnonzero(~(lo <= hi) | (lo < 0))
        if bad.size:
            i = int(bad[0])
            raise ModelError(f"muscle '{names[i]}' has control bounds [{lo[i]:g}, {hi[i]:g}]; static optimization "
                             "needs 0 <= min_control <= max_control")
        return lo, hi

    def fit_problem(self, prob: SOProblem, progress=None):
        """Solve an already built :class:`SOProblem` (used by benchmarks and FSO)."""
        self._check_params()
        self.plan_ = self.inputs_ = self.residuals_ = None
        t0 = _time.perf_counter()
        self._model_rot = ()
        self.actuators_ = ()
        self._actuator_units = {}
        self._solve(prob, progress=progress)
        self.timing_ = {"setup_s": 0.0, "solve_s": _time.perf_counter() - t0,
                        "total_s": _time.perf_counter() - t0}
        self.model_name_ = "?"
        self.result_ = self._result(prob)
        return self

    def _solve(self, prob: SOProblem, progress=None):
        tol = float(self.tol)
        W = float(self.reserve_weight) if self.reserves else None
        fr = solve_frames(prob, minmax=bool(self.minmax), reserve_weight=W, tol=tol,
                          method=self.method, progress=progress)
        failed = np.flatnonzero(~fr.solved)
        if failed.size:
            if W is None:
                deficits = diagnose_infeasible(prob, failed, minmax=bool(self.minmax), tol=tol)
                quantified = np.isfinite(deficits).all(axis=1)
                real = quantified & (np.max(np.abs(deficits) / prob.scale, axis=1, initial=0.0) > 10 * tol)
                if real.any() or not quantified.all():
                    bad = failed[real | ~quantified]
                    raise InfeasibleError(infeasible_message(prob, bad, deficits[real | ~quantified]))
            raise ConvergenceError(
                f"static optimization did not converge at {failed.size} frame(s) "
                f"{failed[:10].tolist()}{' ...' if failed.size > 10 else ''} (tol = {tol:g}); "
                "loosen tol, or report the trial and settings")
        self.problem_ = prob
        x = fr.x
        m = len(prob.muscles)
        stand_in = getattr(prob, "stand_in", None)
        if stand_in is not None and np.isfinite(stand_in).any():
            cols = np.flatnonzero(np.isfinite(stand_in))
            at = x[:, m + cols] >= 0.999 * stand_in[cols]
            if at.any():
                k, j = np.argwhere(at)[0]
                name = prob.actuators[int(prob.split[cols[j]])]
                raise SolverError(f"actuator '{name}' (no control bound) reached the solver's stand-in bound "
                                  f"{stand_in[cols[j]]:.4g} at frame {k} (t = {prob.time[k]:.4g} s): give it "
                                  "min_control / max_control, or a larger optimal_force")
        # the per-frame arrays of a long motion are reused in place where their values are no longer needed
        F = prob.forces(x) if fr.forces is None else fr.forces
        u = prob.controls(x)
        used = np.any(np.abs(fr.rho) > 1e-6, axis=1) if W is not None else None
        reserves = fr.rho
        reserves *= prob.scale
        violation = fr.violation
        moment = None
        if violation is None:
            moment = prob.moments(F)
            moment += prob.actuator_moments(u)
            if W is not None:
                moment += reserves
        status = fr.path
        if W is not None:
            status[used] = 2
        self.n_iter_ = fr.iterations
        self.n_qp_ = fr.qp_solves
        self.n_batched_ = fr.batched_frames
        fr = None
        self.forces_ = F
        self.controls_ = u
        self.actuator_forces_ = u * (prob.optimal_force if prob.actuators else np.zeros(0))
        self.cost_ = prob.cost(x, bool(self.minmax))
        if prob.mode == "activation":
            self.activations_ = x[:, :m]
        else:                                   # x is spent: its muscle columns take the activations
            self.activations_ = np.divide(F, prob.f_max, out=x[:, :m])
        x = None
        self.reserves_ = reserves if W is not None else None
        if violation is None:
            moment -= prob.tau
            np.abs(moment, out=moment)
            violation = np.max(moment, axis=1, initial=0.0)
            moment = None
        self.violation_ = violation
        self.status_ = status
        self.dofs_ = prob.dofs
        self.muscles_ = prob.muscles
        return self

    def _recorded_params(self) -> dict:
        """The parameters written into the result's meta (as strings)."""
        out = {k: str(v) for k, v in self.get_params(deep=False).items() if k not in self._NOT_RECORDED}
        if self.actuators is not None and not isinstance(self.actuators, (str, Path)):
            out["actuators"] = ", ".join(a.label for a in self.actuators) or "none"
        return out

    def _result(self, prob: SOProblem) -> Result:
        """The result: the channels of :meth:`_channels`, the statistics and the report."""
        N, m = self.forces_.shape
        nd = len(prob.dofs)
        stats = FitStatistics(
            k=N * (m + len(prob.actuators) + (nd if self.reserves_ is not None else 0)), converged=True,
            message=f"all {N} frames optimal to tol {float(self.tol):g}", iterations=self.n_iter_,
            violation=float(np.max(self.violation_)), objective=float(np.sum(self.cost_)))
        return Result.from_trial(self._channels(prob), stats=stats, report=self._report_text())

    def _channels(self, prob: SOProblem) -> Trial:
        ch = {}
        for i, name in enumerate(prob.muscles):
            ch[f"{name}_force"] = self.forces_[:, i]
        for i, name in enumerate(prob.muscles):
            ch[f"{name}_activation"] = self.activations_[:, i]
        if self.reserves_ is not None:
            for j, dof in enumerate(prob.dofs):
                ch[f"{dof}_reserve"] = self.reserves_[:, j]
        plan = getattr(self, "plan_", None)
        units = {f"{n}_force": "N" for n in prob.muscles}
        for i, name in enumerate(prob.actuators):
            ch[f"{name}_control"] = self.controls_[:, i]
            ch[f"{name}_force"] = self.actuator_forces_[:, i]
            units[f"{name}_force"] = self._actuator_units.get(name, "")
        if self.reserves_ is not None:
            units.update({f"{d}_reserve": "N*m" for d in prob.dofs})
        if plan is not None:
            # what no muscle can supply: a reserve with reserves, else the left-over (residual) force
            kind = "reserve" if self.reserves else "residual"
            for j, c in enumerate(plan.unspanned):
                if np.isfinite(plan.unspanned_tau[:, j]).all():
                    ch[f"{c}_{kind}"] = plan.unspanned_tau[:, j]
                    units[f"{c}_{kind}"] = "N*m" if c in self._model_rot else "N"
        ch["status"] = self.status_.astype(float)
        ch["cost"] = self.cost_
        ch["violation"] = self.violation_
        meta = {"analysis": "static_optimization", **self._recorded_params()}
        if prob.actuators:
            meta["actuator_names"] = ", ".join(prob.actuators)
        if plan is not None:
            meta.update(self.inputs_.meta())
            meta["balanced_moments"] = plan.source
            meta["balanced_dofs"] = ", ".join(plan.dofs)
        units["violation"] = "N*m"
        return self._columns(prob, ch, units, meta)

    def _columns(self, prob, ch: dict, units, meta) -> Trial:
        """The Trial of the channels ``ch``: one column-major (N, C) array filled channel by channel, the
        fitted arrays re-bound to their columns as soon as these are filled (read-only views of the
        result's: a long motion's forces and activations are held once, not twice)."""
        names = list(ch)
        pos = {n: i for i, n in enumerate(names)}
        values = np.empty((len(names), prob.time.size), dtype=float).T
        blocks = {}
        for attr, fmt, items in (("forces_", "{}_force", prob.muscles), ("activations_", "{}_activation", prob.muscles),
                                 ("reserves_", "{}_reserve", prob.dofs), ("cost_", "{}", ("cost",)),
                                 ("violation_", "{}", ("violation",))):
            cols = [pos.get(fmt.format(x)) for x in items]
            if (items and getattr(self, attr, None) is not None and None not in cols
                    and cols == list(range(cols[0], cols[0] + len(cols)))):
                blocks.setdefault(cols[-1], []).append((attr, cols[0], len(cols) == 1 and attr in ("cost_", "violation_")))
        for i, n in enumerate(names):
            values[:, i] = ch[n]
            ch[n] = None                       # the column's source goes once it is copied
            for attr, first, single in blocks.get(i, ()):
                view = values[:, i] if single else values[:, first:i + 1]
                setattr(self, attr, view)
        out = Trial._adopt(prob.time, names, values, units=units, meta=meta)
        return out

    # -- reporting -----------------------------------------------------------
    def criterion(self) -> str:
        if self.minmax:
            what = "max_i F_i/N_i" if self.mode == "force" else "max_i S_i a_i"
            return f"min/max {what} (Eq. 2.13)"
        p = float(self.exponent)
        ps = f"{p:g}"
        acts = f" + max(weight) sum_k |u_k|^{ps} (actuator controls)" if getattr(self, "actuators_", ()) else ""
        if self.mode == "force":
            n = {"none": "", "fmax": "/F_max", "pcsa": "/PCSA", "volume": "/V"}[self.weights]
            if self.convention == "opensim":
                n = "/F_max"
            return f"sum_i (F_i{n})^{ps} (Eq. 2.11){acts}"
        s = {"none": "", "fmax": "F_max ", "pcsa": "PCSA ", "volume": "V "}[self.weights]
        return f"sum_i {s}a_i^{ps} (Eq. 2.14){acts}"

    def _report_text(self) -> str:
        """Objective, iterations, convergence and constraint violation, in the one report format."""
        prob = self.problem_
        N, m = self.forces_.shape
        na = len(prob.actuators)
        rows = [
            ("criterion", self.criterion()),
            ("frames", f"{N} ({prob.time[0]:.4g}-{prob.time[-1]:.4g} s), muscles {m}"
                       + (f", actuators {na}" if na else "") + f", balanced dofs {', '.join(prob.dofs)}"),
            ("free variables", f"{N * (m + na)} ({m + na} per frame)"),
            ("objective", f"sum over frames {np.sum(self.cost_):.6g}, per frame "
                          f"min {np.min(self.cost_):.6g} max {np.max(self.cost_):.6g}"),
            ("solver", f"{self.n_batched_} frames verified in the batched solve, "
                       f"{N - self.n_batched_} by proxsuite ({self.n_qp_} QPs); {self.n_iter_} iterations in all"),
            ("convergence", f"all {N} frames optimal to tol {float(self.tol):g} (moment residual / dof capacity)"),
            ("violation", f"max |R^T F - tau| = {np.max(self.violation_):.3g} N m "
                          f"(capacity {', '.join(f'{d} {s:.4g}' for d, s in zip(prob.dofs, prob.scale))} N m)"),
        ]
        plan = self.plan_
        if plan is not None:
            rows.append(("moments", plan.source))
            rows += list(self.inputs_.describe())
            rows += [("note", n) for n in plan.notes]
            signal = [c.label for c in self._signal_effects]
            if signal:
                # said, not ignored: a frame's activations do not depend on excitation-to-activation dynamics
                rows.append(("note", f"the model's {', '.join(signal)} act between excitation and activation; "
                             "static optimization solves each frame's activations, which they do not change "
                             "(MSO and EID use them to bound and report the excitations)"))
            if plan.unspanned:
                how = ("left out by request (dofs=)" if plan.by_request else
                       "ideal reserves (no muscle can share them)" if self.reserves else "need no force")
                rows.append(f"not spanned by any muscle: {', '.join(plan.unspanned)} -- {how}; force needed:")
                rows += plan.table_lines(prob.time, self._model_rot)
            if self.residuals_ is not None and self.residuals_.coordinates:
                rows += list(self.residuals_.lines())
        if self.reserves_ is not None:
            used = np.abs(self.reserves_) > 1e-6 * prob.scale
            parts = []
            for j, d in enumerate(prob.dofs):
                if used[:, j].any():
                    parts.append(f"{d}: {used[:, j].sum()} frames, max {np.max(np.abs(self.reserves_[:, j])):.4g} N m")
            rows.append(("reserves", ("; ".join(parts) if parts else "not used")
                         + (" (N for translational dofs)" if parts else "")))
        if self.convention == "opensim":
            rows.append(("muscle model", "OpenSim's StaticOptimization (convention='opensim'): "
                         + ("F = a F_opt, no passive force" if prob.mode == "activation" else "F = a F_max")
                         + ", activations within the muscles' min/max controls"))
        if na:
            for i, name in enumerate(prob.actuators):
                u = self.controls_[:, i]
                k = int(np.argmax(np.abs(u)))
                unit = self._actuator_units.get(name, "")
                rows.append(f"  actuator {name:<24} control max |u| {abs(u[k]):9.4g} (t = {prob.time[k]:.4g} s), "
                            f"force max {abs(self.actuator_forces_[k, i]):9.4g} {unit}, rms "
                            f"{float(np.sqrt(np.mean(self.actuator_forces_[:, i] ** 2))):.4g} {unit}")
        t = self.timing_
        rows.append(("time", f"{t['total_s'] * 1e3:.1f} ms (setup {t['setup_s'] * 1e3:.1f} ms, "
                             f"solve {t['solve_s'] * 1e3:.1f} ms, {t['solve_s'] / N * 1e6:.1f} us/frame)"))
        return format_report(f"Static optimization ({prob.mode} mode) of model '{self.model_name_}'", rows)


# ---------------------------------------------------------------------------
# An independent reference: scipy's SLSQP, frame by frame
# ---------------------------------------------------------------------------

def solve_frame_slsqp(prob: SOProblem, k: int, *, minmax: bool = False, ftol: float = 1e-14,
                      maxiter: int = 1000, x0=None) -> np.ndarray:
    """Frame ``k`` of the scaled problem solved by ``scipy.optimize.minimize(method="SLSQP")``.

    The second computation path of tests and benchmarks (no proxsuite, no
    batching): returns ``x`` (m,), raises SolverError if SLSQP fails.
    """
    from scipy.optimize import minimize

    A, b, lo, hi = prob.A[k], prob.b[k], prob.lo[k], prob.hi[k]
    m = A.shape[1]
    P = prob.exponent
    if minmax:
        u = prob.w_minmax
        z0 = np.concatenate([np.clip(np.full(m, 0.5) if x0 is None else x0, lo, hi), [1.0]])
        res = minimize(lambda z: z[-1], z0, jac=lambda z: np.r_[np.zeros(m), 1.0], method="SLSQP",
                       bounds=list(zip(lo, hi)) + [(0.0, None)],
                       constraints=[{"type": "eq", "fun": lambda z: A @ z[:m] - b,
                                     "jac": lambda z: np.hstack([A, np.zeros((A.shape[0], 1))])},
                                    {"type": "ineq", "fun": lambda z: z[-1] - u * z[:m],
                                     "jac": lambda z: np.hstack([-np.diag(u), np.ones((m, 1))])}],
                       options={"ftol": ftol, "maxiter": maxiter})
        x = res.x[:m]
    else:
        w = prob.w
        # SLSQP's ftol is absolute: scale the cost to O(1) at the start point
        xs = np.clip(np.full(m, 0.1) if x0 is None else x0, lo, hi)
        c = 1.0 / max(float(np.sum(w * np.maximum(xs, 1e-3) ** P)), 1e-300)
        res = minimize(lambda x: c * float(np.sum(w * np.maximum(x, 0.0) ** P)), xs,
                       jac=lambda x: c * w * P * np.maximum(x, 0.0) ** (P - 1.0), method="SLSQP",
                       bounds=list(zip(lo, hi)),
                       constraints=[{"type": "eq", "fun": lambda x: A @ x - b, "jac": lambda x: A}],
                       options={"ftol": ftol, "maxiter": maxiter})
        x = res.x
    if not res.success:
        raise SolverError(f"SLSQP failed at frame {k}: {res.message}")
    return np.clip(x, lo, hi)
