"""A point mass held at a frame (a dumbbell in the hand, a backpack, a sensor).

Physics: a point mass ``m`` rigidly attached at the origin of frame
``target`` (e.g. ``hand``, the hand's centre of mass).  Its contribution to the
equations of motion is ``m J_p^T (a_p - g)``, so the generalized force it
applies to the rest of the system is::

    Q = -m J_p(q)^T (a_p - g),     a_p = J_p a + Jdot_p v

with ``J_p`` the frame origin's world-aligned linear Jacobian, ``a_p`` its
classical (not spatial) acceleration and ``g`` the model's gravity vector
(both from Pinocchio: ``computeFrameJacobian`` and
``getFrameClassicalAcceleration`` in ``LOCAL_WORLD_ALIGNED``).  ``Q`` is
linear in ``m``; ``prepare`` computes ``J_p^T (a_p - g)`` once per motion.
The payload is *inertial*: forward dynamics folds it into the parent joint's
inertia (:meth:`Payload.apply_inertia`) instead of calling
:meth:`generalized_force`, which needs the acceleration.

Sites.  ``target`` is a frame (a hand frame, a marker: an imported model's markers are frames of
their bodies), ``<body>@com``, the centre of mass of the body's joint inertia, or ``<body>@end``,
the body's far end estimated as twice its centre of mass from its joint (exact for a uniform rod;
0.86 of a limb's length for a COM at 43 %), or ``<body>@axis``, a point on the line from its joint
through its centre of mass at a fitted distance (:class:`AxisPayload`).  For a point
that is not a frame the same force comes from the joint torque regressor ``Y_j`` of the joint
carrying it (``computeJointTorqueRegressor``, ``rnea = Y pi``): a point mass ``m`` at ``p`` adds
the dynamic parameters ``m pi_1(p)`` (unit mass, first moment ``p``, no rotational inertia), so
``Q = -m Y_j(q, v, a) pi_1(p)``, which equals ``-m J_p^T (a_p - g)``.

Without user-named frames the diagnosis offers (:meth:`Payload.candidates`) the model's hand-like
frames (a frame named hand, palm, fingertip, tool, ...), else on a floating-base model the centres
of mass of its hand bodies, and on a fixed-base model :func:`payload_sites`: on each
distal body (a moving body without moving children: the forearm-and-hand of an arm model), its
centre of mass, its axis and the markers on it, and its joint's origin, the distal end of the
segment it hangs from.  A payload at a centre of mass and ``segment_mass`` of that body differ only by the
rotational inertia: the diagnosis reports them as aliases when the trial cannot tell them apart.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..components import Parameter
from ..errors import ModelError
from ._base import (_HAND_RE, ScaledBasisEffect, add_dynamic_parameters, frame_point_kinematics, hand_like_frames,
                    moving_bodies, torque_regressor, unactuated_coordinates, visible_directions)
from .registry import register

__all__ = ["Payload", "AxisPayload", "PointPayload", "payload_sites", "COM_SITE", "END_SITE", "AXIS_SITE",
           "POINT_SITE"]

#: suffix of a target at a body's centre of mass (``r_ulna_radius_hand@com``)
COM_SITE = "@com"
#: suffix of a target at a distal body's far end, twice its centre of mass from its joint (``rod2@end``)
END_SITE = "@end"
#: suffix of a target on a body's long axis, the line from its joint through its centre of mass, at a
#: fitted distance (``rod2@axis``: :class:`AxisPayload`)
AXIS_SITE = "@axis"
#: suffix of a target at a fitted point in a body's frame (``torso@point``: :class:`PointPayload`)
POINT_SITE = "@point"


@register
class Payload(ScaledBasisEffect):
    """Point mass ``m`` at the origin of frame ``target`` (or at the centre of mass of ``<body>@com``)."""

    family = "payload"
    level = "joint"
    target_kind = "frame"
    inertial = True
    parameters = (
        Parameter("mass", 1.0, 0.0, 200.0, "kg", "mass held at the frame origin"),
    )
    zero_params = {"mass": 0.0}

    def __new__(cls, target=None, **values):
        # a payload on a body's axis has a second parameter, its distance: its own class, one family
        if cls is Payload and isinstance(target, str):
            cls = AxisPayload if target.endswith(AXIS_SITE) else PointPayload if target.endswith(POINT_SITE) else cls
        return super().__new__(cls)

    @classmethod
    def parameters_for(cls, target) -> tuple:
        """The parameters of a payload at ``target`` (an ``@axis`` site adds its distance, a ``@point``
        site its coordinates)."""
        if isinstance(target, str) and target.endswith(AXIS_SITE):
            return AxisPayload.parameters
        if isinstance(target, str) and target.endswith(POINT_SITE):
            return PointPayload.parameters
        return cls.parameters

    @classmethod
    def candidates(cls, model, context) -> list:
        """The frames the user names; else the model's hand-like frames; else, on a fixed-base model,
        :func:`payload_sites`, and on a floating-base one the centres of mass of its hand bodies (an
        object carried while walking) and, in a torque-level comparison, a fitted point on its trunk
        (:func:`trunk_bodies`, a backpack: :class:`PointPayload`)."""
        sites = list(context.frames) or hand_like_frames(model)
        trunk = []
        if not sites:
            floating = bool(context.unactuated or unactuated_coordinates(model))
            sites = [b + COM_SITE for b in moving_bodies(model) if _HAND_RE.search(b)] if floating \
                else payload_sites(model)
            if floating and context.mode == "torque":
                trunk = [PointPayload.on_body(model, b) for b in trunk_bodies(model)]
        return [AxisPayload.on_body(model, f[:-len(AXIS_SITE)]) if f.endswith(AXIS_SITE) else cls(f)
                for f in sites] + trunk

    def _body_site(self) -> tuple[str, str] | None:
        """``(body, "@com" | "@end")`` for a target at a body's centre of mass or distal end, else None."""
        for suffix in (COM_SITE, END_SITE, AXIS_SITE, POINT_SITE):
            if self.target.endswith(suffix):
                return self.target[:-len(suffix)], suffix
        return None

    def site(self, model) -> tuple[int, np.ndarray]:
        """``(joint, point)``: the joint carrying the payload and its position in that joint's frame."""
        pm = model.pin
        at = self._body_site()
        if at is not None:
            body, suffix = at
            j = pm.frames[model.frame_id(body)].parentJoint
            if j == 0 or pm.inertias[j].mass <= 0:
                raise ModelError(f"payload: body '{body}' of model '{model.name}' does not move or has no mass, so "
                                 f"'{self.target}' is no site; bodies with mass: {', '.join(moving_bodies(model))}")
            c = np.array(pm.inertias[j].lever)
            if suffix == AXIS_SITE:
                n = np.linalg.norm(c)
                if n <= 1e-9:
                    raise ModelError(f"payload: the centre of mass of body '{body}' of model '{model.name}' is at "
                                     f"its joint, so '{self.target}' has no axis; use '{body}@com' or a frame")
                return j, self.values["distance"] * c / n
            if suffix == POINT_SITE:
                f = pm.frames[model.frame_id(body)]
                return j, np.asarray(f.placement.act(np.array([self.values[k] for k in _XYZ])), dtype=float)
            return j, (c if suffix == COM_SITE else 2.0 * c)
        f = pm.frames[model.frame_id(self.target)]
        return f.parentJoint, np.array(f.placement.translation)

    def check_target(self, model) -> None:
        self.site(model)

    def prepare(self, model, motion, data=None):
        """``J_p^T (a_p - g)`` over frames, ``(N, nv)`` (at a non-frame site: ``Y_j pi_1(p)``)."""
        if self._body_site() is not None:
            j, p = self.site(model)
            Y = torque_regressor(model, motion, data)[:, :, 10 * (j - 1):10 * j]
            return Y @ pin.Inertia(1.0, p, np.zeros((3, 3))).toDynamicParameters()
        J, acc = frame_point_kinematics(model, motion, self.target, data)
        return np.einsum("nkv,nk->nv", J, acc - model.gravity[None, :])

    def apply_inertia(self, model, pin_model) -> None:
        m = self.values["mass"]
        if m == 0.0:
            return
        j, p = self.site(model)
        point = pin.Inertia(m, p, np.zeros((3, 3)))
        add_dynamic_parameters(pin_model, j, point.toDynamicParameters())


class AxisPayload(Payload):
    """Point mass ``m`` on a body's long axis (target ``<body>@axis``): at distance ``s`` from the body's
    joint along the unit vector ``u`` through its centre of mass, ``p = s u``.

    Where a held object sits along a limb is rarely known (a dumbbell in the palm, a weight at the
    ankle), and the segment's far end is only estimated (``@end``); so ``s`` is fitted with the mass.
    The dynamic parameters of a unit point mass at ``s u`` are quadratic in ``s``,
    ``pi_1(s u) = pi_0 + s pi_u + s^2 pi_uu`` (unit mass; first moment ``s u``; rotational inertia
    about the joint ``s^2 (I - u u^T)``), so with ``B_k = Y_j pi_k`` the generalized force is::

        Q = -m (B_0 + s B_1 + s^2 B_2),   dQ/dm = -(B_0 + s B_1 + s^2 B_2),   dQ/ds = -m (B_1 + 2 s B_2)

    exact derivatives from three bases :meth:`prepare` computes once per motion.  The mass and the
    distance are both identifiable: the joint carrying the payload sees its first moment ``m s`` (its
    weight's lever) and its second ``m s^2`` (its inertia), the joints above it its mass."""

    linear = False
    frame_cache = True
    parameters = (
        Parameter("mass", 1.0, 0.0, 200.0, "kg", "mass held on the body's axis"),
        Parameter("distance", 0.3, 0.0, 3.0, "m", "its distance from the body's joint along the axis"),
    )
    zero_params = {"mass": 0.0}

    @classmethod
    def on_body(cls, model, body: str, **values) -> "AxisPayload":
        """``<body>@axis`` with the distance bounded to four times the body's centre of mass from its
        joint (twice a uniform segment's length) and started at its far end (twice the centre of mass)."""
        eff = cls(body + AXIS_SITE, **values)
        j = model.pin.frames[model.frame_id(body)].parentJoint
        c = float(np.linalg.norm(model.pin.inertias[j].lever))
        start = values.get("distance", 2.0 * c)
        return eff.with_params({"distance": min(start, 4.0 * c)}, bounds={"distance": (0.0, 4.0 * c)})

    def for_model(self, model) -> "AxisPayload":
        """This payload with :meth:`on_body`'s bounds for ``model``."""
        return type(self).on_body(model, self.target[:-len(AXIS_SITE)], **self.values)

    def _bases(self, model, motion, data=None) -> np.ndarray:
        j, _ = self.site(model)
        u = np.array(model.pin.inertias[j].lever)
        u = u / np.linalg.norm(u)
        pi0 = pin.Inertia(1.0, np.zeros(3), np.zeros((3, 3))).toDynamicParameters()
        pi1 = pin.Inertia(1.0, u, np.zeros((3, 3))).toDynamicParameters()
        pi2 = pin.Inertia(1.0, 2.0 * u, np.zeros((3, 3))).toDynamicParameters()
        # quadratic in s: pi(s) = pi0 + s a + s^2 b, from its values at s = 1 and s = 2
        b = (pi2 - 2.0 * pi1 + pi0) / 2.0
        a = pi1 - pi0 - b
        Y = torque_regressor(model, motion, data)[:, :, 10 * (j - 1):10 * j]
        return np.stack([Y @ pi0, Y @ a, Y @ b], axis=-1)           # (N, nv, 3)

    def prepare(self, model, motion, data=None):
        """The bases ``B_0, B_1, B_2`` over frames, ``(N, nv, 3)``."""
        return self._bases(model, motion, data)

    def generalized_force(self, model, motion, params=None, cache=None) -> np.ndarray:
        B = self.prepare(model, motion) if cache is None else cache
        p = self._p(params)
        s = p["distance"]
        return -p["mass"] * (B[..., 0] + s * B[..., 1] + s * s * B[..., 2])

    def param_jacobian(self, model, motion, params=None, cache=None) -> np.ndarray:
        """``dQ/d(mass, distance)`` over frames, ``(N, nv, 2)``."""
        B = self.prepare(model, motion) if cache is None else cache
        p = self._p(params)
        m, s = p["mass"], p["distance"]
        return np.stack([-(B[..., 0] + s * B[..., 1] + s * s * B[..., 2]), -m * (B[..., 1] + 2.0 * s * B[..., 2])],
                        axis=-1)

    def initial_guess(self, model, motion, target, cache=None) -> list[dict]:
        """Variable projection: on a grid of distances within the bounds, the mass by non-negative
        least squares against the generalized force the effect should supply; the best few."""
        B = self.prepare(model, motion) if cache is None else cache
        y = np.asarray(target, dtype=float)
        ok = np.isfinite(y)
        if ok.sum() < 4:
            return []
        d = self.params["distance"]
        grid = np.linspace(d.min, d.max, 41)
        # Q = -m b(s): per unit mass the force is -b(s); best m = <-b, y> / <b, b>
        b = B[None, ..., 0] + grid[:, None, None] * B[None, ..., 1] + grid[:, None, None] ** 2 * B[None, ..., 2]
        b = np.where(ok[None], b, 0.0)
        yy = np.where(ok, y, 0.0)
        ss = np.einsum("gnv,gnv->g", b, b)
        sy = -np.einsum("gnv,nv->g", b, yy)
        m = np.clip(sy / np.maximum(ss, 1e-300), 0.0, self.params["mass"].max)
        rn = np.sum(yy ** 2) - 2 * m * sy + m ** 2 * ss
        return [{"mass": float(m[g]), "distance": float(grid[g])} for g in np.argsort(rn)[:3] if m[g] > 0]


_XYZ = ("x", "y", "z")


class PointPayload(Payload):
    """Point mass ``m`` at a fitted point ``p = (x, y, z)`` in a body's frame (target ``<body>@point``):
    a backpack, a load carried on the trunk, whose place on the body no marker marks.

    With ``pi_1(p)`` the dynamic parameters of a unit point mass at ``p`` (unit mass, first moment
    ``p``, rotational inertia about the joint ``|p|^2 I - p p^T``; quadratic in ``p``), ``Q = -m Y_j
    pi_1(p)``, so ``dQ/dm = -Y_j pi_1(p)`` and ``dQ/dp = -m Y_j dpi_1/dp`` (central differences, exact
    for the quadratic).  Its mass is seen by the vertical force on the base, its first moment by the
    moments; a coordinate the dynamics cannot see (the normal of a planar model) is held at 0
    (:meth:`on_body`).  Unlike ``segment_mass`` with ``com_offset`` it adds no rotational inertia of
    its own: a small, dense load."""

    linear = False
    frame_cache = True
    parameters = (
        Parameter("mass", 1.0, 0.0, 200.0, "kg", "mass held at the point"),
        *(Parameter(k, 0.0, -1.0, 1.0, "m", f"the point's {k} in the body's frame") for k in _XYZ),
    )
    zero_params = {"mass": 0.0}

    @classmethod
    def on_body(cls, model, body: str, **values) -> "PointPayload":
        """``<body>@point`` bounded to the body's reach (its segment length from its joint, at least 0.6
        m) and with the coordinates the skeleton's dynamics cannot see held at 0."""
        eff = cls(body + POINT_SITE, **values)
        j, _ = eff.site(model)
        pm = model.pin
        kids = [float(np.linalg.norm(pm.jointPlacements[k].translation)) for k in range(1, pm.njoints)
                if pm.parents[k] == j]
        reach = max([0.6, 2.0 * float(np.linalg.norm(pm.inertias[j].lever)), *kids])
        seen = visible_directions(model, j, eff._dpi_dp(model, np.zeros(3))[:, 1:])
        vals = {k: (float(np.clip(eff.values[k], -reach, reach)) if ok else 0.0) for k, ok in zip(_XYZ, seen)}
        return eff.with_params(vals, bounds={k: (-reach, reach) for k in _XYZ},
                               vary={k: bool(ok) for k, ok in zip(_XYZ, seen)})

    def for_model(self, model) -> "PointPayload":
        """This payload with :meth:`on_body`'s bounds and held coordinates for ``model``."""
        return type(self).on_body(model, self.target[:-len(POINT_SITE)], **self.values)

    def _pi(self, model, p) -> np.ndarray:
        """``m pi_1`` columns: the unit point mass's dynamic parameters at body-frame ``p`` (10,)."""
        body = self.target[:-len(POINT_SITE)]
        f = model.pin.frames[model.frame_id(body)]
        return pin.Inertia(1.0, np.asarray(f.placement.act(np.asarray(p, dtype=float))),
                           np.zeros((3, 3))).toDynamicParameters()

    def _dpi_dp(self, model, p) -> np.ndarray:
        """``[pi_1(p), dpi_1/dp]`` (10, 4): central differences, exact for the quadratic ``pi_1``."""
        e = np.eye(3)
        cols = [self._pi(model, p)]
        cols += [(self._pi(model, p + e[k]) - self._pi(model, p - e[k])) / 2.0 for k in range(3)]
        return np.column_stack(cols)

    def _xyz(self, params) -> np.ndarray:
        p = self._p(params)
        return np.array([p[k] for k in _XYZ], dtype=float)

    def prepare(self, model, motion, data=None):
        """``Y_j`` over frames, ``(N, nv, 10)``: the body's joint's columns of the torque regressor."""
        j, _ = self.site(model)
        return np.ascontiguousarray(torque_regressor(model, motion, data)[:, :, 10 * (j - 1):10 * j])

    def generalized_force(self, model, motion, params=None, cache=None) -> np.ndarray:
        Yj = self.prepare(model, motion) if cache is None else cache
        return -self._p(params)["mass"] * (Yj @ self._pi(model, self._xyz(params)))

    def param_jacobian(self, model, motion, params=None, cache=None) -> np.ndarray:
        """``dQ/d(mass, x, y, z)`` over frames, ``(N, nv, 4)``."""
        Yj = self.prepare(model, motion) if cache is None else cache
        D = self._dpi_dp(model, self._xyz(params))
        D[:, 1:] *= self._p(params)["mass"]
        return -(Yj @ D)

    def initial_guess(self, model, motion, target, cache=None) -> list[dict]:
        """The mass and first moment ``m p`` by linear least squares (the point's own inertia dropped),
        ``p = (m p) / m``, clipped to the bounds."""
        Yj = self.prepare(model, motion) if cache is None else cache
        D = self._dpi_dp(model, np.zeros(3))          # at p = 0: [unit mass, d first moment / dp, 0]
        names = ["mass", *_XYZ]
        free = [0] + [1 + k for k, n in enumerate(_XYZ) if self.params[n].vary]
        B = -(Yj @ D[:, free])
        y = np.asarray(target)
        ok = np.isfinite(y)
        sol, *_ = np.linalg.lstsq(B[ok], y[ok], rcond=None)
        m = float(sol[0])
        if m <= 0:
            return []
        out = {"mass": m}
        for i, col in enumerate(free[1:], start=1):
            n = names[col]
            out[n] = float(np.clip(sol[i] / m, self.params[n].min, self.params[n].max))
        return [out]


def trunk_bodies(model) -> list[str]:
    """The trunk of a floating-base model, where a carried load (a backpack) sits: its heaviest moving
    body (the torso of an OpenSim gait model, the head-arms-trunk of a planar one)."""
    pm = model.pin
    best = [(pm.inertias[j].mass, b) for b, j in moving_bodies(model).items()]
    return [max(best)[1]] if best else []


def payload_sites(model) -> list[str]:
    """Where a held payload is plausible on a model without hand-like frames: on each distal body (a
    moving body with no moving child) its centre of mass (``<body>@com``), its axis (``<body>@axis``)
    and its markers (frames off the joint axis), and its body frame (its joint's origin: the distal
    end of the parent segment)."""
    pm = model.pin
    bodies = moving_bodies(model)
    parents = {int(pm.parents[k]) for k in range(1, pm.njoints) if pm.inertias[k].mass > 0}
    markers = set()
    for mk in (model.meta.get("markers") or ()) if hasattr(model, "meta") else ():
        name = mk.get("name") if hasattr(mk, "get") else getattr(mk, "name", None)
        if name:
            markers.add(name)
    out = []
    for body, j in bodies.items():
        if j in parents:
            continue                                   # not distal: another moving body hangs from it
        out.append(body + COM_SITE)
        if np.linalg.norm(pm.inertias[j].lever) > 1e-9:
            out.append(body + AXIS_SITE)
        seen = []
        for f in pm.frames:
            if f.parentJoint != j or f.name not in markers or f.type != pin.FrameType.OP_FRAME:
                continue
            pos = np.array(f.placement.translation)
            if np.linalg.norm(pos) < 1e-9 or any(np.allclose(pos, x) for x in seen):
                continue
            seen.append(pos)
            out.append(f.name)
        if pm.parents[j] != 0 and np.linalg.norm(pm.jointPlacements[j].translation) > 1e-9:
            out.append(body)                           # the joint's origin, off the parent's joint
    return out
