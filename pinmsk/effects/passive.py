"""Passive elastic joint moments: a fitted double exponential per joint, and Riener & Edrich (1999).

:class:`PassiveElastic` (``passive_elastic``) -- the Riener & Edrich form
(thesis Eq. 5.11) for one joint, written as an amplitude times a restoring
shape about the joint's rest angle ``theta_0``::

    Q = A [exp(-k_lo (q - theta_0)) - exp(k_hi (q - theta_0))] / Z,
    Z = exp(k_lo (theta_0 - q_lo)) + exp(k_hi (q_hi - theta_0))

with ``[q_lo, q_hi]`` the joint's range of motion (the model's position
limits; ``theta_0 -+ 1 rad`` for a joint without them).  The first term is the
moment that resists motion towards the lower end of the range (it pushes
towards +q), the second the one towards the upper end.  ``Z`` normalises the
shape by its two branches' values at the ends of the range, so the moment
there is at most ``A``, whatever the stiffening rates: the ends' moments add up
to ``A`` up to the small share of the opposite branch.

Why this form.  The general double exponential ``k1 exp(-k2 (q - theta1)) -
k3 exp(-k4 (theta2 - q))`` is over-parametrised -- ``k1`` and ``theta1``
(likewise ``k3`` and ``theta2``) only enter through ``k1 exp(k2 theta1)`` -- and
its one-branch limits are degenerate: with ``k4 -> 0`` a branch becomes a
constant offset, which a sensor bias or a gravity error produces as well, and
with a large rate at a tiny amplitude it becomes a wall far outside the data
that a fit on part of the range extrapolates into kilonewton-metres.  Here
every member of the family is a *restoring* moment (``dQ/dq < 0``) that
vanishes at the rest angle and stays within ``A`` over the range:

* ``amplitude`` ``A`` (N m, >= 0; 0 = no moment): the scale of the moments at
  the ends of the range;
* ``theta_0`` (rad): the rest angle, bounded to the joint's range of motion
  when the diagnosis builds the candidate (:meth:`PassiveElastic.for_model`);
* ``k_lo``, ``k_hi`` (1/rad, >= 1): how fast each branch stiffens (e-folding
  angle ``1/k`` at most 57 deg, the physiological range: Riener & Edrich's
  exponents are 1.2-11 /rad).  Below 1/rad the shape would be a near-linear
  spring, which :class:`~pinmsk.effects.spring.JointSpring` describes with two
  parameters.

No member of the family is a constant offset (that is ``sensor_offset``).
The published form with ``theta_lo``, ``theta_hi`` (the angles where each branch
is ``M_ref``) maps onto this one exactly (:meth:`PassiveElastic.from_limits`).
The exponents are evaluated as ``exp(a - log Z)`` (no overflow within the
range) and clipped at 50 beyond it.  ``A`` enters linearly, so the fit starts
from a variable-projection grid over ``(theta_0, k_lo, k_hi)`` with ``A`` solved
by non-negative least squares (:meth:`PassiveElastic.initial_guess`).

:class:`RienerEdrich1999PassiveMoment` (``riener_edrich_1999``) -- thesis
Eq. 5.11 as published for the hip, knee and ankle of one leg (angles in
degrees inside the formula, moments in N m), with a single ``scale``
parameter (1 = as published, 0 = off).  Mapping to pinmsk coordinates
(``gait2d``: hip + = extension, knee + = flexion, ankle + = plantarflexion,
0 = standing with the foot perpendicular to the shank)::

    phi_H = hip_s,  phi_K = knee_s,  phi_A = ankle_s   (in degrees; phi_A = 0 is neutral)
    Q_hip = -T^H,   Q_knee = +T^K,   Q_ankle = +T^A

``T^H`` is flexion-positive while ``hip`` is extension-positive, hence the
sign.  Each moment is restoring (``dQ_i/dq_i < 0``) over the range of gait;
the equilibria at the standing posture's neighbours are hip ~27 deg flexion,
knee ~15 deg flexion and ankle ~18 deg plantarflexion, as for a relaxed leg.
(Note: ``phi_A`` here is the *neutral-zero* ankle angle.  Eq. 5.12's
``phi_A - pi/2`` belongs to the muscle-length model; evaluating Eq. 5.11 at
``phi_A = 90 deg`` gives a 14 kN m ankle moment.)
"""
from __future__ import annotations

import numpy as np

from ..backend import backend_of
from ..components import Parameter, state_vector
from ..errors import ModelError
from ._base import JointEffect, bounded_to_range, coordinate_target, joint_range
from .registry import register

_EXP_CLIP = 50.0


def _exp(x):
    xp = backend_of(x)
    return xp.exp(xp.minimum(x, _EXP_CLIP))


@register
class PassiveElastic(JointEffect):
    """Restoring double exponential about the rest angle, normalised at the ends of the joint's range."""

    family = "passive_elastic"
    parameters = (
        Parameter("amplitude", 1.0, 0.0, 1.0e3, "N m", "scale of the moments at the ends of the range"),
        Parameter("theta_0", 0.0, -np.pi, np.pi, "rad", "rest angle (zero moment); bounded to the joint's range"),
        Parameter("k_lo", 5.0, 1.0, 100.0, "1/rad", "stiffening rate of the lower-limit branch"),
        Parameter("k_hi", 5.0, 1.0, 100.0, "1/rad", "stiffening rate of the upper-limit branch"),
    )
    zero_params = {"amplitude": 0.0}
    #: parameters bounded to the target coordinate's range of motion (see :meth:`for_model`)
    range_parameters = ("theta_0",)

    @classmethod
    def from_limits(cls, target, model, *, theta_lo: float, k_lo: float, theta_hi: float, k_hi: float,
                    moment_ref: float = 1.0) -> "PassiveElastic":
        """The published parametrisation ``M_ref [exp(-k_lo (q - theta_lo)) - exp(k_hi (q - theta_hi))]``
        on ``model``'s range of ``target``."""
        theta_0 = (k_lo * theta_lo + k_hi * theta_hi) / (k_lo + k_hi)
        lo, hi = _range(model, target, theta_0)
        log_z = np.logaddexp(k_lo * (theta_0 - lo), k_hi * (hi - theta_0))
        amp = moment_ref * float(np.exp(-k_lo * (theta_0 - theta_lo) + log_z))
        return cls(target, amplitude=amp, theta_0=theta_0, k_lo=k_lo, k_hi=k_hi)

    def for_model(self, model) -> "PassiveElastic":
        """This effect with ``theta_0`` bounded to the target coordinate's range of motion."""
        return bounded_to_range(self, model, self.range_parameters)

    # -- the law, on the model's range -----------------------------------------------
    def _terms(self, model, q, p):
        t0, kl, kh = p["theta_0"], p["k_lo"], p["k_hi"]
        lo, hi = _range(model, self.target, t0)
        d = q - t0
        e_l, e_h = kl * (t0 - lo), kh * (hi - t0)
        log_z = np.logaddexp(e_l, e_h)
        u = _exp(-kl * d - log_z)
        w = _exp(kh * d - log_z)
        s_l, s_h = np.exp(e_l - log_z), np.exp(e_h - log_z)      # softmax shares, s_l + s_h = 1
        dz = {"theta_0": s_l * kl - s_h * kh, "k_lo": s_l * (t0 - lo), "k_hi": s_h * (hi - t0)}
        return u, w, d, dz

    def generalized_force(self, model, motion, params=None, cache=None):
        i = model.coordinate_index(self.target)
        p = self._p(params)
        u, w, _, _ = self._terms(model, motion.q[:, i], p)
        out = np.zeros((motion.n_frames, model.nv))
        out[:, i] = p["amplitude"] * (u - w)
        return out

    def _force_at(self, model, q, v, p):
        u, w, _, _ = self._terms(model, q, p)
        return p["amplitude"] * (u - w)

    def param_jacobian(self, model, motion, params=None, cache=None):
        i = model.coordinate_index(self.target)
        p = self._p(params)
        u, w, d, dz = self._terms(model, motion.q[:, i], p)
        a = p["amplitude"]
        out = np.zeros((motion.n_frames, model.nv, 4))
        out[:, i, 0] = u - w                                                    # d/dA
        out[:, i, 1] = a * (u * (p["k_lo"] - dz["theta_0"]) + w * (p["k_hi"] + dz["theta_0"]))
        out[:, i, 2] = a * (-u * d - (u - w) * dz["k_lo"])
        out[:, i, 3] = a * (-w * d - (u - w) * dz["k_hi"])
        return out

    def state_derivatives(self, model, motion, params=None, cache=None):
        i = model.coordinate_index(self.target)
        p = self._p(params)
        u, w, _, _ = self._terms(model, motion.q[:, i], p)
        dq = np.zeros((motion.n_frames, model.nv, model.nv))
        dq[:, i, i] = -p["amplitude"] * (p["k_lo"] * u + p["k_hi"] * w)
        return dq, np.zeros_like(dq)

    def initial_guess(self, model, motion, target, cache=None) -> list[dict]:
        """Variable projection: on a grid of ``(theta_0, k_lo, k_hi)`` within the bounds, ``A`` by
        non-negative least squares; the best few."""
        q, y = coordinate_target(model, motion, target, self.target)
        if q.size < 4:
            return []
        decl = self.params
        t_lo, t_hi = decl["theta_0"].min, decl["theta_0"].max
        t_lo, t_hi = max(t_lo, q.min() - 0.5), min(t_hi, q.max() + 0.5)
        if not t_lo < t_hi:
            t_lo = t_hi = float(np.clip(np.median(q), decl["theta_0"].min, decl["theta_0"].max))
        thetas = np.linspace(t_lo, t_hi, 13)
        ks = np.geomspace(max(decl["k_lo"].min, 1e-3), min(decl["k_lo"].max, 60.0), 8)
        kh = np.geomspace(max(decl["k_hi"].min, 1e-3), min(decl["k_hi"].max, 60.0), 8)
        # the shapes on the whole grid at once: axes (k_lo, k_hi, theta_0, frame)
        grid = {"k_lo": ks[:, None, None, None], "k_hi": kh[None, :, None, None],
                "theta_0": thetas[None, None, :, None]}
        u, w, _, _ = self._terms(model, q[None, None, None, :], grid)
        S = u - w
        ss = np.einsum("abtn,abtn->abt", S, S)
        sy = np.einsum("abtn,n->abt", S, y)
        amp = np.clip(sy / np.maximum(ss, 1e-300), 0.0, decl["amplitude"].max)
        rn = np.sum(y ** 2) - 2 * amp * sy + amp ** 2 * ss
        order = np.argsort(rn, axis=None)[:3]
        out = []
        for flat in order:
            a, b, t = np.unravel_index(flat, rn.shape)
            out.append({"amplitude": float(amp[a, b, t]), "theta_0": float(thetas[t]),
                        "k_lo": float(ks[a]), "k_hi": float(kh[b])})
        return out


def _range(model, coordinate, theta_0):
    """The normalising range ``(q_lo, q_hi)``: the joint's range of motion, else ``theta_0 -+ 1 rad``
    (``theta_0`` may be an array of rest angles)."""
    rng = joint_range(model, coordinate)
    return rng if rng is not None else (np.asarray(theta_0) - 1.0, np.asarray(theta_0) + 1.0)


@register
class RienerEdrich1999PassiveMoment(JointEffect):
    """Passive hip, knee and ankle moments of one leg, Riener & Edrich (1999), thesis Eq. 5.11.

    ``RienerEdrich1999PassiveMoment("r")`` (or ``side="r"``, as the gait2d
    sidecar writes it) acts on ``hip_r``, ``knee_r`` and ``ankle_r``.
    """

    family = "riener_edrich_1999"
    linear = True
    target_kind = "side"
    parameters = (
        Parameter("scale", 1.0, 0.0, 5.0, "", "multiplier of the published moments (1 = Eq. 5.11)"),
    )
    zero_params = {"scale": 0.0}

    def __init__(self, target: str | None = None, *, side: str | None = None, **values: float):
        side = _side(target, side)
        super().__init__(side, **values)

    @property
    def side(self) -> str:
        return self.target

    def coordinates(self) -> tuple[str, str, str]:
        s = self.target
        return f"hip_{s}", f"knee_{s}", f"ankle_{s}"

    def affected_coordinates(self) -> tuple[str, ...]:
        return self.coordinates()

    def check_target(self, model) -> None:
        for c in self.coordinates():
            model.coordinate_index(c)

    @staticmethod
    def moments_deg(phi_h, phi_k, phi_a):
        """``(T^H, T^K, T^A)`` of Eq. 5.11 in N m for angles in degrees (thesis conventions)."""
        exp = backend_of(phi_h, phi_k, phi_a).exp
        th = (exp(1.4655 - 0.0034 * phi_k + 0.0750 * phi_h)
              - exp(1.3403 - 0.0226 * phi_k - 0.0305 * phi_h) + 8.072)
        tk = (exp(1.800 - 0.0460 * phi_a - 0.0352 * phi_k - 0.0217 * phi_h)
              - exp(-3.971 - 0.0004 * phi_a + 0.0495 * phi_k + 0.0128 * phi_h)
              - 4.820 + exp(2.220 - 0.150 * phi_k))
        ta = (exp(2.1016 - 0.0843 * phi_a - 0.0176 * phi_k)
              - exp(-7.9763 + 0.1949 * phi_a + 0.0008 * phi_k) - 1.792)
        return th, tk, ta

    def _unit(self, q_hip, q_knee, q_ankle):
        d = 180.0 / np.pi
        th, tk, ta = self.moments_deg(q_hip * d, q_knee * d, q_ankle * d)
        return -th, tk, ta

    def generalized_force(self, model, motion, params=None, cache=None):
        idx = [model.coordinate_index(c) for c in self.coordinates()]
        s = self._p(params)["scale"]
        out = np.zeros((motion.n_frames, model.nv))
        qh, qk, qa = (motion.q[:, i] for i in idx)
        for i, m in zip(idx, self._unit(qh, qk, qa)):
            out[:, i] = s * m
        return out

    def generalized_force_at(self, model, q, v):
        """Eq. 5.11 at one state (numpy or CasADi), the same :meth:`moments_deg` as the batched form."""
        idx = [model.coordinate_index(c) for c in self.coordinates()]
        s = self.values["scale"]
        return state_vector(model.nv, {i: s * m for i, m in zip(idx, self._unit(*(q[i] for i in idx)))}, like=q)

    def param_jacobian(self, model, motion, params=None, cache=None):
        return self.generalized_force(model, motion, {"scale": 1.0})[:, :, None]

    def state_derivatives(self, model, motion, params=None, cache=None):
        """Analytic ``dQ/dq`` (3 x 3 block of the side's coordinates); ``dQ/dv = 0``."""
        idx = [model.coordinate_index(c) for c in self.coordinates()]
        s = self._p(params)["scale"]
        d = 180.0 / np.pi
        ph, pk, pa = (motion.q[:, i] * d for i in idx)
        n = motion.n_frames
        # dT/dphi (per degree), rows T^H, T^K, T^A; columns phi_H, phi_K, phi_A
        e1 = np.exp(1.4655 - 0.0034 * pk + 0.0750 * ph)
        e2 = np.exp(1.3403 - 0.0226 * pk - 0.0305 * ph)
        e3 = np.exp(1.800 - 0.0460 * pa - 0.0352 * pk - 0.0217 * ph)
        e4 = np.exp(-3.971 - 0.0004 * pa + 0.0495 * pk + 0.0128 * ph)
        e5 = np.exp(2.220 - 0.150 * pk)
        e6 = np.exp(2.1016 - 0.0843 * pa - 0.0176 * pk)
        e7 = np.exp(-7.9763 + 0.1949 * pa + 0.0008 * pk)
        dT = np.zeros((n, 3, 3))
        dT[:, 0, 0] = 0.0750 * e1 + 0.0305 * e2
        dT[:, 0, 1] = -0.0034 * e1 + 0.0226 * e2
        dT[:, 1, 0] = -0.0217 * e3 - 0.0128 * e4
        dT[:, 1, 1] = -0.0352 * e3 - 0.0495 * e4 - 0.150 * e5
        dT[:, 1, 2] = -0.0460 * e3 + 0.0004 * e4
        dT[:, 2, 1] = -0.0176 * e6 - 0.0008 * e7
        dT[:, 2, 2] = -0.0843 * e6 - 0.1949 * e7
        dT[:, 0, :] *= -1.0                      # Q_hip = -T^H
        dT *= s * d                              # per radian
        dq = np.zeros((n, model.nv, model.nv))
        for r, i in enumerate(idx):
            for c, j in enumerate(idx):
                dq[:, i, j] = dT[:, r, c]
        return dq, np.zeros_like(dq)


def _side(target, side) -> str:
    if side is not None and target is not None and _norm_side(target) != _norm_side(side):
        raise ModelError(f"riener_edrich_1999: target {target!r} and side {side!r} disagree")
    s = _norm_side(side if side is not None else target)
    if s not in ("r", "l"):
        raise ModelError(
            f"riener_edrich_1999 needs side 'r' or 'l' (or a coordinate such as 'knee_r'), got {target or side!r}"
        )
    return s


def _norm_side(x) -> str | None:
    if x is None:
        return None
    x = str(x).strip().lower()
    if x in ("r", "right"):
        return "r"
    if x in ("l", "left"):
        return "l"
    if x.endswith("_r"):
        return "r"
    if x.endswith("_l"):
        return "l"
    return x
