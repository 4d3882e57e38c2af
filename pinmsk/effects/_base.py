"""Shared machinery of the effect families.

* :class:`JointEffect` -- an effect acting on one coordinate through a closed
  form ``Q_i(q_i, v_i)``; subclasses implement :meth:`JointEffect._force`
  and, where they can, the analytic derivatives used by the fitters and the
  conformance tests.
* :class:`SignalEffect` -- a muscle-level effect: it transforms the measured
  excitation/EMG signals on their way to muscle activation (activation
  dynamics, electromechanical delay) and applies no generalized force of its
  own.
* batch kinematics shared by the frame- and body-targeted effects
  (frame Jacobians and classical accelerations, the joint torque regressor),
  cached in the :class:`pinmsk.model.Data` the caller passes (``prepare(model,
  motion, data=...)``), so that several candidates prepared on the same motion
  do not repeat the Pinocchio calls; without a Data they are computed afresh.
"""
from __future__ import annotations

import re
from typing import Any, Mapping

import numpy as np
import pinocchio as pin

from ..components import Component, Motion, motion_cached, state_vector
from ..errors import ModelError
from ..skeleton import skeleton_constant

__all__ = ["JointEffect", "ScaledBasisEffect", "SignalEffect", "signal_parts", "frame_point_kinematics",
           "torque_regressor", "unactuated_coordinates", "moving_bodies", "hand_like_frames", "joint_range",
           "bounded_to_range"]


class JointEffect(Component):
    """An effect applying a generalized force on one coordinate, ``Q_i = f(q_i, v_i; theta)``.

    Subclasses implement ``_force(q, v, p) -> (N,)`` (``q, v`` the target
    coordinate's columns, ``p`` a dict of parameter values) and optionally
    ``_dforce_dparams(q, v, p) -> (N, n_params)`` and ``_dforce_dstate(q, v, p)
    -> (dQ/dq, dQ/dv)``, both ``(N,)``.
    """

    kind = "effect"
    level = "joint"
    target_kind = "coordinate"

    def affected_coordinates(self) -> tuple[str, ...]:
        """The coordinates whose generalized force this effect can change."""
        return (self.target,)

    def for_model(self, model) -> "JointEffect":
        """This effect with bounds that depend on ``model`` (a rest angle within the joint's range);
        the diagnosis fits candidates in this form.  Default: unchanged."""
        return self

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        i = model.coordinate_index(self.target)
        out = np.zeros((motion.n_frames, model.nv))
        out[:, i] = self._force(motion.q[:, i], motion.v[:, i], self._p(params))
        return out

    def generalized_force_at(self, model, q, v):
        """``Q (nv,)`` at one state, numpy or CasADi (:meth:`Component.generalized_force_at`):
        :meth:`_force_at` on the target coordinate, zero elsewhere."""
        i = model.coordinate_index(self.target)
        return state_vector(model.nv, {i: self._force_at(model, q[i], v[i], self.values)}, like=q)

    def _force_at(self, model, q, v, p):
        """The force law on one coordinate's ``q, v`` (numpy or CasADi): :meth:`_force`, which
        subclasses write against :func:`pinmsk.backend.backend_of` (model-dependent laws override
        this instead)."""
        return self._force(q, v, p)

    def param_jacobian(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                       cache: Any = None) -> np.ndarray:
        """``dQ/dtheta`` over frames, ``(N, nv, n_params)`` in declaration order."""
        i = model.coordinate_index(self.target)
        out = np.zeros((motion.n_frames, model.nv, len(self.parameters)))
        out[:, i, :] = self._dforce_dparams(motion.q[:, i], motion.v[:, i], self._p(params))
        return out

    def state_derivatives(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """``(dQ/dq, dQ/dv)`` over frames, each ``(N, nv, nv)``."""
        i = model.coordinate_index(self.target)
        dq = np.zeros((motion.n_frames, model.nv, model.nv))
        dv = np.zeros_like(dq)
        a, b = self._dforce_dstate(motion.q[:, i], motion.v[:, i], self._p(params))
        dq[:, i, i] = a
        dv[:, i, i] = b
        return dq, dv

    def _force(self, q, v, p) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _dforce_dparams(self, q, v, p) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _dforce_dstate(self, q, v, p):  # pragma: no cover - abstract
        raise NotImplementedError


class ScaledBasisEffect(Component):
    """An effect ``Q = -theta * B(q, v, a)``: its one parameter times a parameter-free basis that
    :meth:`prepare` computes once per motion (a payload's ``J_p^T (a_p - g)``, a body's ``Y_j pi_j``, the
    skeleton's ``Y pi``).  Linear, so the diagnosis fits it exactly."""

    linear = True

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        basis = self.prepare(model, motion) if cache is None else cache
        return -self._p(params)[self.parameters[0].name] * basis

    def param_jacobian(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                       cache: Any = None) -> np.ndarray:
        basis = self.prepare(model, motion) if cache is None else cache
        return -basis[:, :, None]

    def generalized_force_at(self, model, q, v):
        """Refused by name: the basis needs the accelerations (a payload's ``a_p``, a body's ``Y_j``),
        so this is no closed form in ``(q, v)``; an inertial effect enters the optimal-control
        problem through the skeleton instead (:meth:`apply_inertia` on a copy of the Pinocchio model)."""
        how = ("; fold it into the skeleton's inertia (apply_inertia) instead" if self.inertial else "")
        raise ModelError(f"component {self.label} has no closed form the optimal-control engine can use: its "
                         f"generalized force depends on the accelerations{how}")


class SignalEffect(Component):
    """A muscle-level effect: a transform of the excitation signals ``u (N, m) -> (N, m)``.

    It acts through the muscles (force = a F_active + F_passive with the
    transformed activation), so its :meth:`generalized_force` on the skeleton
    is zero: it shows up where muscle forces are computed from measured
    excitations (the diagnosis' muscle-level comparison).  ``target`` is
    ``"muscles"`` (all muscles) or one muscle name.  ``order`` fixes where it
    sits in the chain from measured signal to activation (delay before
    activation dynamics).
    """

    kind = "effect"
    level = "muscle"
    target_kind = "muscle"
    order: int = 0

    def __init__(self, target: str | None = "muscles", **values: float):
        super().__init__("muscles" if target in (None, "", "all") else target, **values)

    def check_target(self, model) -> None:
        if model.muscles is None:
            raise ModelError(f"{self.label}: model '{model.name}' has no muscles")
        if self.target != "muscles":
            model.muscles.index(self.target)

    def parts(self) -> tuple["SignalEffect", ...]:
        """The elementary muscle-level effects this one is made of, in chain order (itself by default;
        a composite such as delay-then-activation-dynamics gives its two)."""
        return (self,)

    def muscle_mask(self, model) -> np.ndarray:
        """Boolean ``(m,)``: the muscles this effect applies to."""
        m = model.n_muscles
        if self.target == "muscles":
            return np.ones(m, dtype=bool)
        mask = np.zeros(m, dtype=bool)
        mask[model.muscles.index(self.target)] = True
        return mask

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        return np.zeros((motion.n_frames, model.nv))

    def generalized_force_at(self, model, q, v):
        """Zero ``(nv,)`` (numpy or CasADi, as ``q``): a muscle-level effect acts through the muscles."""
        return state_vector(model.nv, {}, like=q)

    def transform(self, t: np.ndarray, u: np.ndarray, params: Mapping[str, float] | None = None,
                  mask: np.ndarray | None = None) -> np.ndarray:
        """The transformed signals ``(N, m)`` (columns outside ``mask`` unchanged)."""
        return self.transform_batch(t, u, self._p(params), mask)[0]

    def transform_batch(self, t, u, params, mask=None) -> np.ndarray:
        """Transforms for P parameter sets at once: ``params`` maps names to (P,) arrays -> (P, N, m)."""
        raise NotImplementedError  # pragma: no cover

    @staticmethod
    def broadcast_batch(u: np.ndarray, mask, *values):
        """The common start of :meth:`transform_batch`: P parameter sets against the signals.

        ``u`` is (N, m), or (P, N, m) for one signal per set; ``values`` are the
        parameter values (scalars or (P,) arrays).  Returns ``(values, ub, cols,
        out)``: each value broadcast to (P,), ``u`` broadcast to (P, N, m), the
        columns of the muscles in ``mask`` (all without one), and a copy of
        ``ub`` for the result.
        """
        vals = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float)) for v in values))
        P = max(vals[0].size, u.shape[0] if u.ndim == 3 else 1)
        vals = [np.broadcast_to(v, (P,)) for v in vals]
        ub = np.broadcast_to(u, (P,) + u.shape[-2:])
        cols = np.arange(ub.shape[2]) if mask is None else np.flatnonzero(mask)
        return vals, ub, cols, ub.copy()


# -- model structure helpers ---------------------------------------------------

def signal_parts(model) -> list:
    """The elementary parts of the model's muscle-level effects, in chain order."""
    chain = sorted([c for c in model.effects if isinstance(c, SignalEffect)], key=lambda c: c.order)
    return [p for c in chain for p in c.parts()]


def unactuated_coordinates(model) -> tuple[str, ...]:
    """Coordinates no actuator drives: the model's floating base.

    ``model.meta["unactuated"]`` if the sidecar declares it; otherwise the
    root chain of joints (each an ancestor of every other joint) when that
    chain contains a prismatic joint -- the sliders-plus-hinge floating base of
    planar models such as ``gait2d`` (``torso_x, torso_y, torso_angle``).
    Fixed-base models (``forearm``, ``finger``) have none.
    """
    declared = model.meta.get("unactuated") if hasattr(model, "meta") else None
    if declared is not None:
        return tuple(declared)
    return skeleton_constant(model.pin, "unactuated_root_chain", _root_chain)


def _root_chain(pm) -> tuple[str, ...]:
    """The joints of the root chain when it holds a prismatic joint (a planar floating base), else ()."""
    children = {j: [k for k in range(1, pm.njoints) if pm.parents[k] == j] for j in range(pm.njoints)}
    root, j = [], 0
    while len(children[j]) == 1:
        j = children[j][0]
        root.append(j)
    if not children[j] or not root:      # a serial chain (or nothing): a fixed-base model
        return ()
    if not any(pm.joints[k].shortname().startswith("JointModelP") for k in root):
        return ()
    return tuple(pm.names[k] for k in root)


def coordinate_target(model, motion: Motion, target, coordinate: str) -> tuple[np.ndarray, np.ndarray]:
    """``(q, y)`` of ``coordinate`` on the frames where an ``initial_guess`` target (N, nv; NaN where not
    compared) is finite: the angle and the generalized force an effect there should supply."""
    i = model.coordinate_index(coordinate)
    y = np.asarray(target)[:, i]
    ok = np.isfinite(y)
    return motion.q[ok, i], y[ok]


def is_prismatic(model, coordinate: str) -> bool:
    """Whether ``coordinate`` is a translation (its generalized force is in N, not N m)."""
    pm = model.pin
    return pm.joints[pm.getJointId(coordinate)].shortname().startswith("JointModelP")


def moving_bodies(model) -> dict[str, int]:
    """Body (link) name -> joint id, one per joint that carries mass (the joint's first body)."""
    pm = model.pin
    out = {}
    for j in range(1, pm.njoints):
        if pm.inertias[j].mass <= 0:
            continue
        bodies = [f.name for f in pm.frames if f.type == pin.FrameType.BODY and f.parentJoint == j]
        if not bodies:
            continue
        # an imported joint's moving link between it and the source's child body is named
        # '<source joint>_<coordinate>' (pinmsk.opensim.skeleton); the body a user knows comes after it
        named = [b for b in bodies if not b.endswith(f"_{pm.names[j]}")]
        out[(named or bodies)[0]] = j
    return out


_HAND_RE = re.compile(r"(^|_)(hand|palm|wrist|fingertip|tip|tool|grip|end_effector)($|_)", re.I)


def hand_like_frames(model) -> list[str]:
    """Frames where a held payload is plausible: named hand/palm/fingertip/tool... and off the joint axis."""
    pm = model.pin
    out, seen = [], []
    for f in pm.frames:
        if f.parentJoint == 0 or not _HAND_RE.search(f.name):
            continue
        if f.type not in (pin.FrameType.BODY, pin.FrameType.OP_FRAME):
            continue      # joint frames duplicate the body frame they carry
        pos = np.array(f.placement.translation)
        if np.linalg.norm(pos) < 1e-9:
            continue      # at its joint's origin: a point mass there has no lever arm
        if any(j == f.parentJoint and np.allclose(pos, p) for j, p in seen):
            continue
        seen.append((f.parentJoint, pos))
        out.append(f.name)
    return out


def joint_range(model, coordinate: str) -> tuple[float, float] | None:
    """The range of motion of ``coordinate`` (the model's position limits), or None without finite limits
    (a free translation such as ``torso_x``, or limits wider than 20 rad / m: none in practice)."""
    pm = model.pin
    i = model.coordinate_index(coordinate)
    lo, hi = float(pm.lowerPositionLimit[i]), float(pm.upperPositionLimit[i])
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi - lo > 20 or not lo < hi:
        return None
    return lo, hi


def bounded_to_range(effect, model, names):
    """``effect`` with the parameters ``names`` bounded to its target coordinate's range of motion
    (intersected with their declared bounds; values clipped into it)."""
    rng = joint_range(model, effect.target)
    if rng is None:
        return effect
    bounds, values = {}, {}
    for n in names:
        p = effect.params[n]
        lo, hi = max(p.min, rng[0]), min(p.max, rng[1])
        if not lo < hi:
            continue
        bounds[n] = (lo, hi)
        values[n] = float(np.clip(p.value, lo, hi))
    return effect.with_params(values, bounds=bounds) if bounds else effect


# -- batch kinematics (cached in a caller's Data) ---------------------------------

def frame_point_kinematics(model, motion: Motion, frame: str, data=None):
    """``(J_p, a_p)`` of a frame's origin over frames: world-aligned linear Jacobian ``(N, 3, nv)``
    and classical linear acceleration ``(N, 3)`` (``J_p a + Jdot_p v``).

    ``data`` (a :class:`pinmsk.model.Data`) caches the result for this motion."""
    pm = model.pin
    fid = model.frame_id(frame)

    def compute(pd):
        n = motion.n_frames
        J = np.empty((n, 3, pm.nv))
        acc = np.empty((n, 3))
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        q, v, a = motion.q, motion.v, motion.a
        for k in range(n):
            pin.forwardKinematics(pm, pd, q[k], v[k], a[k])
            pin.updateFramePlacement(pm, pd, fid)
            acc[k] = pin.getFrameClassicalAcceleration(pm, pd, fid, lwa).linear
            J[k] = np.reshape(pin.computeFrameJacobian(pm, pd, q[k], fid, lwa), (6, pm.nv))[:3]
        return J, acc

    return motion_cached(data, model, ("frame_point", fid), motion, compute)


def torque_regressor(model, motion: Motion, data=None) -> np.ndarray:
    """Pinocchio's joint torque regressor over frames, ``(N, nv, 10 (njoints - 1))``.

    ``rnea(q, v, a) = Y(q, v, a) pi`` with ``pi`` the stacked dynamic
    parameters ``[m, m c, I_origin]`` of each joint's inertia (gravity included).
    ``data`` (a :class:`pinmsk.model.Data`) caches the result for this motion.
    """
    pm = model.pin

    def compute(pd):
        n = motion.n_frames
        Y = np.empty((n, pm.nv, 10 * (pm.njoints - 1)))
        q, v, a = motion.q, motion.v, motion.a
        for k in range(n):
            Y[k] = np.reshape(pin.computeJointTorqueRegressor(pm, pd, q[k], v[k], a[k]), Y.shape[1:])
        return Y

    return motion_cached(data, model, "torque_regressor", motion, compute)


def visible_directions(model, joint: int, D: np.ndarray, samples: int = 6) -> np.ndarray:
    """Boolean (k,): which columns of ``D`` (10, k), changes of joint ``joint``'s dynamic parameters,
    change some generalized force, from the joint torque regressor at ``samples`` seeded random states
    (a planar model's dynamics are blind to a shift normal to its plane)."""
    pm = model.pin
    rng = np.random.default_rng(0)
    pd = pm.createData()
    lo = np.where(np.isfinite(pm.lowerPositionLimit), pm.lowerPositionLimit, -1.0).clip(-1.0, 1.0)
    hi = np.where(np.isfinite(pm.upperPositionLimit), pm.upperPositionLimit, 1.0).clip(-1.0, 1.0)
    B = []
    for _ in range(samples):
        q = pin.randomConfiguration(pm, lo, hi) if pm.nq == pm.nv else pin.neutral(pm)
        v, a = rng.normal(size=pm.nv), rng.normal(size=pm.nv)
        Y = np.asarray(pin.computeJointTorqueRegressor(pm, pd, q, v, a))[:, 10 * (joint - 1):10 * joint]
        B.append(Y @ D)
    norms = np.linalg.norm(np.vstack(B), axis=0)
    return norms > 1e-9 * max(norms.max(), 1e-300)


def add_dynamic_parameters(pin_model, joint: int, dpi: np.ndarray) -> None:
    """``pin_model.inertias[joint] += dpi`` in dynamic-parameter space (exact, any sign)."""
    pi = pin_model.inertias[joint].toDynamicParameters() + np.asarray(dpi, dtype=float)
    if pi[0] <= 0:
        raise ModelError(f"joint '{pin_model.names[joint]}' would get mass {pi[0]:.4g} kg <= 0")
    pin_model.inertias[joint] = pin.Inertia.FromDynamicParameters(pi)
