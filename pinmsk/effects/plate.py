"""Force-plate errors: corrections of a trial's measured ground reaction loads.

A force plate's zero drifts, its centre of pressure (COP) is off, its axes are tilted against the
lab's, its calibration is off by a few per cent, or its clock runs behind the motion capture's.
Each changes the measured wrench ``w_meas = w_true + Delta(theta)`` of one plate, so inverse
dynamics with the true loads is ``tau_ID(w_meas - Delta) = tau_ID(w_meas) + J^T Delta`` and, as
a component (``tau_ID - Q``), the correction's generalized force is::

    Q = -J_b^T Delta(theta)

with ``J_b`` the world-frame spatial Jacobian of the loaded body (Pinocchio's ``getJointJacobian``
in ``WORLD``: ``[v_O; omega]``, so ``J_b^T [f; m_O]`` is the generalized force of a force ``f``
with moment ``m_O`` about the world origin; the same numbers as
:func:`pinmsk.skeleton.external_generalized_force`).  ``target`` is the body the plate loads
(``calcn_r``), as the trial's external loads name it.

The measured wrench about the world origin ``(F, M)`` gives the COP on the ground plane
``p = (u x M) / (u . F)`` and the free moment ``T = u . (M - p x F)``, ``u`` the world's vertical
``+y`` (OpenSim's ground frame; the ground plane through the origin: a plate surface ``h`` above it
moves ``p`` along the line of action, which changes the moments below by ``h F x theta``, far below
a millimetre's worth here).  The families, each on one plate, each linear in its parameters or a
one-parameter law:

* :class:`PlateOffset` (``plate_offset``): a zero offset ``b = (fx, fy, fz)`` of the force
  channels (N), acting at the COP: ``Delta = (b, p x b)``, on the loaded frames only (an unloaded
  plate's samples are zero in the trial: pinmsk.grf);
* :class:`PlateCopOffset` (``plate_cop_offset``): the COP read at ``p + d``, ``d = (dx, 0, dz)``
  (m): ``Delta = (0, d x F)``;
* :class:`PlateTilt` (``plate_tilt``): the plate's axes turned by a small rotation
  ``theta = (tilt_x, rot_y, tilt_z)`` (rad) about its COP: ``Delta = (theta x F, p x (theta x F) +
  theta x T u)``, the first-order rotation (a 0.5 deg tilt of a 700 N load gives 6.1 N of shear;
  the neglected second order is ``theta^2 / 2``, 4e-5 of the load there);
* :class:`PlateGain` (``plate_gain``): every channel read ``g`` times the true value (force and
  moments alike; the COP, their ratio, unchanged): ``Delta = (1 - 1/g) w_meas``;
* :class:`PlateLag` (``plate_lag``): the plate's samples ``lag`` s behind the kinematics,
  ``w_meas(t) = w_true(t - lag)``; to first order ``Delta = -lag dw_meas/dt``, the derivative by
  central differences over the analysed frames (one-sided at their ends) of the loads as the
  comparison filtered them.

They are trial corrections: the diagnosis offers them only when the trial has ground reaction
loads (``needs_loads``: the comparison passes its loads to :meth:`PlateEffect.prepare`, and
inverse dynamics passes its ``external`` loads), one candidate per loaded body and family, in
torque-level comparisons.  Without a load on its body a plate effect is refused by name.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import pinocchio as pin

from ..components import Component, Motion, Parameter, motion_cached
from ..errors import ModelError
from ..skeleton import cross3, world_wrench
from .registry import register

__all__ = ["PlateEffect", "PlateOffset", "PlateCopOffset", "PlateTilt", "PlateGain", "PlateLag",
           "body_jacobian_world", "VERTICAL"]

#: the world's vertical (OpenSim's ground frame is y-up; pinmsk.grf takes F_y as the vertical load)
VERTICAL = np.array([0.0, 1.0, 0.0])


def body_jacobian_world(model, motion: Motion, frame: str, data=None) -> np.ndarray:
    """World-frame spatial Jacobian ``(N, 6, nv)`` (``[v_O; omega]``) of the joint carrying ``frame``."""
    pm = model.pin
    j = pm.frames[model.frame_id(frame)].parentJoint

    def compute(pd):
        out = np.empty((motion.n_frames, 6, pm.nv))
        for k, q in enumerate(motion.q):
            pin.computeJointJacobians(pm, pd, q)
            out[k] = pin.getJointJacobian(pm, pd, j, pin.ReferenceFrame.WORLD)
        return out

    return motion_cached(data, model, ("world_joint_jacobian", j), motion, compute)


def _moves_in_plane(model, frame: str) -> bool:
    """Whether the body of ``frame`` can only move in the world's x-y plane (a planar model's)."""
    pm = model.pin
    j = pm.frames[model.frame_id(frame)].parentJoint
    if j == 0:
        return False
    pd = pm.createData()
    q = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
    pin.computeJointJacobians(pm, pd, q)
    J = pin.getJointJacobian(pm, pd, j, pin.ReferenceFrame.WORLD)
    return bool(np.max(np.abs(J[[2, 3, 4], :]), initial=0.0) < 1e-9)


class PlateEffect(Component):
    """A correction of the measured loads on body ``target`` (one plate): ``Q = -J_b^T Delta(theta)``.

    Subclasses implement :meth:`delta_basis` -> ``(N, 6, p)`` with ``Delta = basis theta`` (linear
    families) or override :meth:`delta` and :meth:`delta_jacobian`.
    """

    kind = "effect"
    level = "joint"
    target_kind = "plate"
    #: the comparison passes the trial's external loads to prepare (see the module notes)
    needs_loads = True
    linear = True

    @classmethod
    def candidates(cls, model, context) -> list:
        """One per body the trial's loads act on, in torque-level comparisons with loads."""
        if context.mode != "torque":
            return []
        return [cls(b) for b in getattr(context, "loads", ())]

    #: parameters a planar model (motion in the x-y plane) cannot see: held at 0 there (:meth:`for_model`)
    out_of_plane: tuple[str, ...] = ()

    def check_target(self, model) -> None:
        model.frame_id(self.target)

    def for_model(self, model) -> "PlateEffect":
        """This correction with the parameters a planar model cannot see held at 0 (``vary=False``): the
        loaded body moves in the x-y plane only (its world Jacobian's ``v_z, omega_x, omega_y`` rows vanish
        at a generic configuration)."""
        if not self.out_of_plane or not _moves_in_plane(model, self.target):
            return self
        return self.with_params({n: 0.0 for n in self.out_of_plane}, vary={n: False for n in self.out_of_plane})

    # -- the loads ----------------------------------------------------------------------
    def prepare(self, model, motion, data=None, *, loads=None) -> dict:
        """The body's Jacobian and the measured wrench's parts on the loaded frames: ``F, M, p, T``
        (``(N, 3)`` force, moment about the origin, COP, free moment ``T u``), ``on`` (N,), ``dw``
        (``(N, 6)`` time derivative of the wrench), ``w`` (``(N, 6)``) and ``J`` (``(N, 6, nv)``)."""
        mine = [e for e in (loads or ()) if e.frame == self.target]
        if not mine:
            have = sorted({e.frame for e in (loads or ())})
            raise ModelError(f"{self.label} corrects the measured ground reaction on '{self.target}', but the "
                             f"trial's loads act on {', '.join(have) if have else 'no body'}; it applies only to a "
                             "trial with a force plate under that body")
        n = motion.n_frames
        w = sum(world_wrench(e, n) for e in mine)
        F, M = w[:, :3], w[:, 3:]
        Fu = F @ VERTICAL
        on = np.abs(F).sum(axis=1) > 0
        safe = np.where(on & (np.abs(Fu) > 0), Fu, 1.0)
        p = np.where(on[:, None], cross3(np.broadcast_to(VERTICAL, M.shape), M) / safe[:, None], 0.0)
        T = ((M - cross3(p, F)) @ VERTICAL)[:, None] * VERTICAL[None, :]
        t = motion.t
        dw = np.gradient(w, t, axis=0) if n > 1 else np.zeros_like(w)
        J = body_jacobian_world(model, motion, self.target, data)
        return {"J": J, "F": F, "M": M, "p": p, "T": T, "on": on, "w": w, "dw": dw}

    def _cache(self, model, motion, cache):
        if cache is None:
            raise ModelError(f"{self.label} needs the trial's external loads: pass "
                             "cache=component.prepare(model, motion, loads=[...])")
        return cache

    # -- the law --------------------------------------------------------------------------
    def delta_basis(self, cache) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def delta(self, cache, params) -> np.ndarray:
        """``Delta`` ``(N, 6)`` of the measured wrench for the parameter values ``params``."""
        p = self._p(params)
        return self.delta_basis(cache) @ np.array([p[n] for n in p], dtype=float)

    def delta_jacobian(self, cache, params) -> np.ndarray:
        """``d Delta / d theta`` ``(N, 6, p)``."""
        return self.delta_basis(cache)

    def generalized_force(self, model, motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        c = self._cache(model, motion, cache)
        return -np.einsum("nkv,nk->nv", c["J"], self.delta(c, params))

    def param_jacobian(self, model, motion, params=None, cache=None) -> np.ndarray:
        c = self._cache(model, motion, cache)
        return -np.einsum("nkv,nkp->nvp", c["J"], self.delta_jacobian(c, params))

    #: what the correction means for the lab (completed by :meth:`describe_remedy`)
    remedy = "correct the plate's data"

    def describe_remedy(self, model) -> str:
        """What to do about a fitted plate error: correct the recording (or keep this effect for the trial)."""
        vals = ", ".join(f"{n} = {p.value:.4g} {p.unit}".rstrip() for n, p in self.params.items() if p.vary)
        return (f"the force plate under {self.target} reads off ({vals}): {self.remedy}, or keep this effect "
                "for this trial")

    def generalized_force_at(self, model, q, v):
        """Refused by name: a plate correction acts on a trial's measured loads, not on a state."""
        raise ModelError(f"component {self.label} corrects a trial's measured ground reaction; it has no closed "
                         "form in (q, v) the optimal-control engine can use")


def _unit_columns(vectors) -> np.ndarray:
    """``(N, 6, p)`` from a list of p ``(N, 6)`` columns."""
    return np.stack(vectors, axis=-1)


@register
class PlateOffset(PlateEffect):
    """Zero offset ``(fx, fy, fz)`` of a plate's force channels, acting at the measured COP."""

    family = "plate_offset"
    parameters = tuple(Parameter(n, 1.0, -200.0, 200.0, "N", f"offset of the plate's {n[1]} force channel "
                                                              "(reading - true)") for n in ("fx", "fy", "fz"))
    zero_params = {"fx": 0.0, "fy": 0.0, "fz": 0.0}
    out_of_plane = ("fz",)
    remedy = "re-zero the plate (subtract its unloaded reading)"

    def delta_basis(self, c):
        on = c["on"].astype(float)[:, None]
        cols = []
        for k in range(3):
            e = np.zeros_like(c["F"])
            e[:, k] = 1.0
            cols.append(np.hstack([e * on, cross3(c["p"], e) * on]))
        return _unit_columns(cols)


@register
class PlateCopOffset(PlateEffect):
    """Centre of pressure read ``(dx, dz)`` off in the ground plane (the moments it implies, ``d x F``)."""

    family = "plate_cop_offset"
    parameters = (Parameter("dx", 0.005, -0.05, 0.05, "m", "COP offset along x (reading - true)"),
                  Parameter("dz", 0.005, -0.05, 0.05, "m", "COP offset along z (reading - true)"))
    zero_params = {"dx": 0.0, "dz": 0.0}
    out_of_plane = ("dz",)
    remedy = "check the plate's origin against the lab's (its position in the capture volume)"

    def delta_basis(self, c):
        F = c["F"]
        cols = []
        for k in (0, 2):
            e = np.zeros_like(F)
            e[:, k] = 1.0
            cols.append(np.hstack([np.zeros_like(F), cross3(e, F)]))
        return _unit_columns(cols)


@register
class PlateTilt(PlateEffect):
    """The plate's axes turned by a small rotation ``(tilt_x, rot_y, tilt_z)`` (rad) about its COP."""

    family = "plate_tilt"
    parameters = (Parameter("tilt_x", 0.002, -0.0873, 0.0873, "rad", "tilt of the plate about x"),
                  Parameter("rot_y", 0.002, -0.0873, 0.0873, "rad", "rotation of the plate about the vertical"),
                  Parameter("tilt_z", 0.002, -0.0873, 0.0873, "rad", "tilt of the plate about z"))
    zero_params = {"tilt_x": 0.0, "rot_y": 0.0, "tilt_z": 0.0}
    out_of_plane = ("tilt_x", "rot_y")
    remedy = "check the plate's alignment with the lab's axes (level, orientation)"

    def delta_basis(self, c):
        F, p, T = c["F"], c["p"], c["T"]
        cols = []
        for k in range(3):
            e = np.zeros_like(F)
            e[:, k] = 1.0
            dF = cross3(e, F)
            cols.append(np.hstack([dF, cross3(p, dF) + cross3(e, T)]))
        return _unit_columns(cols)


@register
class PlateGain(PlateEffect):
    """Every channel of a plate read ``gain`` times the true value (a calibration error)."""

    family = "plate_gain"
    linear = False
    parameters = (Parameter("gain", 1.02, 0.8, 1.25, "", "reading / true value (1 = calibrated)"),)
    zero_params = {"gain": 1.0}
    remedy = "recalibrate the plate"

    def delta(self, c, params):
        g = self._p(params)["gain"]
        return (1.0 - 1.0 / g) * c["w"]

    def delta_jacobian(self, c, params):
        g = self._p(params)["gain"]
        return (c["w"] / g ** 2)[:, :, None]


@register
class PlateLag(PlateEffect):
    """A plate's samples ``lag`` s behind the kinematics (first order: ``Delta = -lag dw/dt``)."""

    family = "plate_lag"
    parameters = (Parameter("lag", 0.002, -0.05, 0.05, "s", "delay of the plate's samples behind the kinematics"),)
    zero_params = {"lag": 0.0}
    remedy = "synchronise the plates with the motion capture"

    def delta_basis(self, c):
        return -c["dw"][:, :, None]
