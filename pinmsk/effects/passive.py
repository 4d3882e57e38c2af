"""Passive elastic joint moments: a fitted double exponential per joint, and Riener & Edrich (1999).

:class:`PassiveElastic` (``passive_elastic``) -- the Riener & Edrich form
(thesis Eq. 5.11) for one joint, fitted::

    Q = M_ref exp(-k_lo (q - theta_lo)) - M_ref exp(k_hi (q - theta_hi))

The first term is the moment that resists motion below the lower end of the
range (it pushes towards +q), the second the one above the upper end.  The
general double exponential ``k1 exp(-k2 (q - theta1)) - k3 exp(-k4 (theta2 - q))``
is over-parametrised -- ``k1`` and ``theta1`` (likewise ``k3`` and ``theta2``)
only enter through ``k1 exp(k2 theta1)`` -- so the amplitudes are fixed at
``M_ref = 1 N m`` and the identifiable parameters are

* ``theta_lo``, ``theta_hi`` (rad): the angles at which each branch reaches 1 N m;
* ``k_lo``, ``k_hi`` (1/rad): how fast each branch stiffens (e-folding angle ``1/k``).

With ``k_lo = k_hi = 0`` both branches are 1 N m and cancel: zero moment.
Exponents are clipped at 50 to keep far extrapolation finite.  Eq. 5.11's
constant offsets are left out: a constant moment is indistinguishable from
an offset in the measured moment or a gravity error.  The fit starts from a
variable-projection grid over ``(k_lo, k_hi)`` with the two amplitudes solved
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
from scipy.optimize import nnls

from ..components import Parameter
from ..errors import ModelError
from ._base import JointEffect
from .registry import register

_EXP_CLIP = 50.0


def _exp(x):
    return np.exp(np.minimum(x, _EXP_CLIP))


@register
class PassiveElastic(JointEffect):
    """Double-exponential passive moment ``M_ref [exp(-k_lo (q - theta_lo)) - exp(k_hi (q - theta_hi))]``."""

    family = "passive_elastic"
    #: fixed amplitude of each branch (N m): theta_* is where that branch reaches M_ref
    moment_ref = 1.0
    parameters = (
        Parameter("theta_lo", 0.0, -2 * np.pi, 2 * np.pi, "rad", "angle where the lower-limit moment is 1 N m"),
        Parameter("k_lo", 5.0, 0.0, 100.0, "1/rad", "stiffening rate of the lower-limit branch"),
        Parameter("theta_hi", 2.0, -2 * np.pi, 2 * np.pi, "rad", "angle where the upper-limit moment is 1 N m"),
        Parameter("k_hi", 5.0, 0.0, 100.0, "1/rad", "stiffening rate of the upper-limit branch"),
    )
    zero_params = {"k_lo": 0.0, "k_hi": 0.0}

    def _branches(self, q, p):
        lo = self.moment_ref * _exp(-p["k_lo"] * (q - p["theta_lo"]))
        hi = self.moment_ref * _exp(p["k_hi"] * (q - p["theta_hi"]))
        return lo, hi

    def _force(self, q, v, p):
        lo, hi = self._branches(q, p)
        return lo - hi

    def _dforce_dparams(self, q, v, p):
        lo, hi = self._branches(q, p)
        return np.column_stack([
            lo * p["k_lo"],                  # d/dtheta_lo
            -lo * (q - p["theta_lo"]),       # d/dk_lo
            hi * p["k_hi"],                  # d/dtheta_hi
            -hi * (q - p["theta_hi"]),       # d/dk_hi
        ])

    def _dforce_dstate(self, q, v, p):
        lo, hi = self._branches(q, p)
        return -p["k_lo"] * lo - p["k_hi"] * hi, np.zeros_like(v)

    def initial_guess(self, model, motion, target, cache=None) -> list[dict]:
        """Variable projection: for each ``(k_lo, k_hi)`` on a grid, amplitudes by NNLS; best few."""
        i = model.coordinate_index(self.target)
        y = np.asarray(target)[:, i]
        ok = np.isfinite(y)
        q, y = motion.q[ok, i], y[ok]
        if q.size < 4:
            return []
        lo_b, hi_b = self.bounds()
        qc = 0.5 * (q.min() + q.max())
        ks = np.geomspace(1.0, 60.0, 14)
        fits = []
        for kl in np.concatenate([[0.0], ks]):
            e_lo = _exp(-kl * (q - qc))
            for kh in np.concatenate([[0.0], ks]):
                if kl == 0.0 and kh == 0.0:
                    continue
                e_hi = _exp(kh * (q - qc))
                cols = []
                if kl > 0:
                    cols.append(e_lo)
                if kh > 0:
                    cols.append(-e_hi)
                A = np.column_stack(cols)
                scale = np.linalg.norm(A, axis=0)
                coef, rn = nnls(A / scale, y)
                coef = coef / scale
                fits.append((rn, kl, kh, coef))
        fits.sort(key=lambda f: f[0])
        out = []
        for rn, kl, kh, coef in fits[:3]:
            j = 0
            guess = {"k_lo": kl, "k_hi": kh, "theta_lo": float(lo_b[0]), "theta_hi": float(hi_b[2])}
            if kl > 0:
                amp = coef[j]; j += 1
                # M_ref exp(-kl (q - theta)) = amp exp(-kl (q - qc))  =>  theta = qc - ln(amp / M_ref) / kl
                guess["theta_lo"] = qc - np.log(amp / self.moment_ref) / kl if amp > 0 else float(lo_b[0])
            else:
                guess["k_lo"] = 0.0
            if kh > 0:
                amp = coef[j]
                guess["theta_hi"] = qc + np.log(amp / self.moment_ref) / kh if amp > 0 else float(hi_b[2])
            guess["theta_lo"] = float(np.clip(guess["theta_lo"], lo_b[0], hi_b[0]))
            guess["theta_hi"] = float(np.clip(guess["theta_hi"], lo_b[2], hi_b[2]))
            out.append(guess)
        return out


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
        th = (np.exp(1.4655 - 0.0034 * phi_k + 0.0750 * phi_h)
              - np.exp(1.3403 - 0.0226 * phi_k - 0.0305 * phi_h) + 8.072)
        tk = (np.exp(1.800 - 0.0460 * phi_a - 0.0352 * phi_k - 0.0217 * phi_h)
              - np.exp(-3.971 - 0.0004 * phi_a + 0.0495 * phi_k + 0.0128 * phi_h)
              - 4.820 + np.exp(2.220 - 0.150 * phi_k))
        ta = (np.exp(2.1016 - 0.0843 * phi_a - 0.0176 * phi_k)
              - np.exp(-7.9763 + 0.1949 * phi_a + 0.0008 * phi_k) - 1.792)
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
