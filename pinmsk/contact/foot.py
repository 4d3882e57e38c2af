"""Feet: the foot2d model, the three-sphere contact sets of thesis Ch. 4, and per-foot totals.

* the 4-dof kinematically driven foot is the built-in model ``foot2d``
  (``load_model("foot2d")``, or :func:`pinmsk.contact.load_foot2d`).
* :func:`foot_contacts` -- spheres at the heel H, first metatarsal P and toe T
  with the bounds of Tables 4.2-4.4 (``kind`` = ``point``, ``volumetric`` or
  ``hypervolumetric``).  Works for any model with those frames: foot2d's
  ``heel, metatarsal, toe`` or gait2d's ``heel_r, metatarsal_r, toe_r`` (``side="r"``).
* :func:`ground_reaction` -- total ground reaction force, centre of pressure and
  free moment of a set of contact outputs (one foot);
* :func:`contact_ground_reactions` / :func:`ground_reaction_trial` -- the same for each side of
  a model's own contacts over a motion (e.g. the four spheres of an imported Moco 2-D model), the
  latter as trial channels ``r_ground_force_vy`` ...

COP regularisation.  The COP of the model is the normal-force-weighted mean of
the application points,

    x_cop = (sum_i w_i x_i + eps * x_ref) / (sum_i w_i + eps),
    w_i = smooth_positive(f_n,i, 1e-3 N),  x_ref = mean_i x_i,

with ``eps = cop_eps`` (default 1 N).  It equals the exact COP within
``eps / F`` relative weight (0.1 % of the position at 1 kN), is C-infinity, and
tends to the mean of the sphere positions (not NaN or inf) as the vertical force
vanishes.  ``ground_reaction`` also returns ``loaded`` (F_y > ``cop_eps``), a mask
of the frames where the COP means something physically.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cached_property
from typing import Sequence

import numpy as np

from ..errors import ModelError
from ..trial import Trial
from .dual import vector
from .hunt_crossley import HuntCrossley
from .sphere import ContactForces, SiteKinematics, cross, smooth_positive
from .volumetric import HyperVolumetric, Volumetric

#: contact model names (CLI ``--contact``) -> classes
KINDS = {"point": HuntCrossley, "volumetric": Volumetric, "hypervolumetric": HyperVolumetric}
SITES = ("heel", "metatarsal", "toe")

#: Upper bound of the radius / rest length per site, Tables 4.2-4.4 (m)
RADIUS_UPPER = {"heel": 0.055, "metatarsal": 0.050, "toe": 0.045}
#: Table 4.2-4.4 optimal values, the defaults of the spheres at each site
THESIS_VALUES = {
    "point": {
        "heel": dict(k_s=1.2e4, a_s=64.6, L0=0.052, n_s=0.95),
        "metatarsal": dict(k_s=1.9e3, a_s=1.4e3, L0=0.048, n_s=0.96),
        "toe": dict(k_s=6.4e4, a_s=3e-3, L0=0.043, n_s=0.96),
    },
    "volumetric": {
        "heel": dict(k_v=2.21e6, a_v=1.2, R=0.051),
        "metatarsal": dict(k_v=1.87e6, a_v=0.45, R=0.049),
        "toe": dict(k_v=2.51e5, a_v=0.1, R=0.044),
    },
    "hypervolumetric": {
        "heel": dict(k_h=8.0e5, a_h=52.3e6, R=0.050, H=0.74, mu_f=0.20, v_s=0.005),
        "metatarsal": dict(k_h=1.4e6, a_h=1.2e5, R=0.049, H=0.80, mu_f=0.22, v_s=0.050),
        "toe": dict(k_h=7.5e5, a_h=13e6, R=0.044, H=0.79, mu_f=0.34, v_s=0.034),
    },
}


def site_frames(model, side: str | None = None) -> dict[str, str]:
    """``{site: frame name}`` for heel, metatarsal, toe (``side`` appends ``_r``/``_l``)."""
    out = {}
    for s in SITES:
        name = s if not side else f"{s}_{side}"
        model.frame_id(name)  # ModelError with suggestions if absent
        out[s] = name
    return out


def foot_contacts(model, kind: str = "hypervolumetric", *, side: str | None = None,
                  relax: bool = False, ground_speed: float = 0.0, values=None,
                  smoothing: float = 1e-4, center="auto") -> list:
    """Three contact elements of type ``kind`` at the heel, metatarsal and toe of ``model``.

    Defaults are the thesis optima (Tables 4.2-4.4), radius/rest-length bounds
    per site as in the tables, friction (mu_f, v_s) of Table 4.4 where given.
    ``relax=True`` frees the centre offsets dx, dy (Sec. 4.1.4, +-20 mm).
    ``values`` optionally maps site -> {parameter: value}.
    ``center`` (see :class:`SphereContact`): ``"auto"`` (default) is ``None`` for
    foot2d (``side=None``: the thesis places the centres at H, P, T, and the
    driving kinematics put them a radius above the belt) and ``"sole"`` for a
    sided model such as gait2d, whose ``heel_r, metatarsal_r, toe_r`` lie on the
    sole (on the ground when standing), so each centre sits one radius above its site.
    """
    if kind not in KINDS:
        raise ModelError(f"unknown contact model '{kind}'; choose one of {', '.join(KINDS)}")
    cls = KINDS[kind]
    frames = site_frames(model, side)
    if isinstance(center, str) and center == "auto":
        center = "sole" if side else None
    out = []
    for site, frame in frames.items():
        vals = dict(THESIS_VALUES[kind][site])
        vals.update((values or {}).get(site, {}))
        c = cls(frame, ground_speed=ground_speed, smoothing=smoothing, center=center,
                bounds={cls.radius_name: (0.001, RADIUS_UPPER[site])}, **vals)
        out.append(c.free("dx", "dy") if relax else c)
    return out


@dataclass(frozen=True)
class GroundReaction:
    """Totals of one foot over N frames: ``force`` (N, 3), ``moment`` (N, 3) about the world
    origin, ``cop`` (N, 3) on the ground plane (regularised, see module doc), ``free_moment``
    (N,) about the vertical at the COP, and ``loaded`` (N,) where F_y > cop_eps.

    ``moment`` and ``free_moment`` are computed on first use from ``outputs`` (the contact
    outputs summed), so a fit that needs only the force and COP does not pay for them."""

    force: np.ndarray
    cop: np.ndarray
    loaded: np.ndarray
    outputs: tuple = field(repr=False, default=())

    @cached_property
    def moment(self) -> np.ndarray:
        return sum(cross(o.point, o.force) for o in self.outputs)

    @cached_property
    def free_moment(self) -> np.ndarray:
        # about the vertical through the COP: M = cop x F + T y  =>  T = M_y - (cop x F)_y
        return self.moment[:, 1] - cross(self.cop, self.force)[:, 1]

    @property
    def normal(self) -> np.ndarray:
        return self.force[:, 1]

    @property
    def friction(self) -> np.ndarray:
        return self.force[:, 0]


def ground_reaction(outputs: Sequence[ContactForces], *, cop_eps: float = 1.0) -> GroundReaction:
    """Total force, moment about the origin, COP and free moment of the contacts of one foot."""
    if not outputs:
        raise ModelError("ground_reaction: no contact outputs given")
    outputs = tuple(outputs)
    F = sum(o.force for o in outputs)
    w = [smooth_positive(o.normal, 1e-3) for o in outputs]
    W = sum(w)
    ref = sum(o.point for o in outputs) * (1.0 / len(outputs))
    num = sum(wi[:, None] * o.point for wi, o in zip(w, outputs))
    cop = (num + cop_eps * ref) / (W + cop_eps)[:, None]
    cop[:, 1] = 0.0
    return GroundReaction(F, cop, F[:, 1] > cop_eps, outputs)


_SIDE = re.compile(r"_(r|l)$")


def contact_side(model, contact) -> str:
    """``"r"``, ``"l"`` or ``""``: the side of a contact, from its frame's name (``heel_r``) or, failing
    that, its body's (``calcn_l``)."""
    m = _SIDE.search(contact.target)
    if m is None:
        pm = model.pin
        f = pm.frames[model.frame_id(contact.target)]
        m = _SIDE.search(pm.frames[f.parentFrame].name)
    return m.group(1) if m else ""


def contact_ground_reactions(model, motion, *, data=None, cop_eps: float = 1.0) -> dict[str, GroundReaction]:
    """``{side: GroundReaction}`` of ``model.contacts`` over ``motion`` (a
    :class:`~pinmsk.components.Motion`), the contacts grouped by :func:`contact_side` (``""`` for
    those of no side).  ``data`` (``model.create_data()``) shares the frames' kinematics with other
    work on the same motion.  The COP lies on ``y = 0`` (see :func:`ground_reaction`)."""
    if not model.contacts:
        raise ModelError(f"model '{model.name}' has no contacts (model.contacts is empty)")
    sides: dict[str, list] = {}
    for c in model.contacts:
        out = c.evaluate(model, motion, cache=c.prepare(model, motion, data=data))
        sides.setdefault(contact_side(model, c), []).append(out)
    return {side: ground_reaction(outs, cop_eps=cop_eps) for side, outs in sides.items()}


def ground_reaction_trial(model, motion, *, data=None, cop_eps: float = 1.0) -> Trial:
    """The ground reaction of the model's contacts as a :class:`~pinmsk.trial.Trial` named as
    trials are: per side ``r_ground_force_v[xyz]`` (N), ``r_ground_force_p[xyz]`` (the COP, m) and
    ``r_ground_torque_[xyz]`` (the free moment about the vertical at the COP, N m), no prefix for
    contacts of no side (:func:`contact_ground_reactions`)."""
    channels, units = {}, {}
    for side, gr in contact_ground_reactions(model, motion, data=data, cop_eps=cop_eps).items():
        pre = f"{side}_" if side else ""
        torque = np.zeros_like(gr.force)
        torque[:, 1] = gr.free_moment
        for what, arr, unit in (("ground_force_v", gr.force, "N"), ("ground_force_p", gr.cop, "m"),
                                ("ground_torque_", torque, "N*m")):
            for k, a in enumerate("xyz"):
                channels[f"{pre}{what}{a}"], units[f"{pre}{what}{a}"] = np.asarray(arr[:, k], dtype=float), unit
    return Trial(motion.t, channels, units=units,
                 meta={"analysis": "contact ground reaction", "model": model.name,
                       "contacts": ", ".join(c.label for c in model.contacts)})


# -- analytic planar kinematics of foot2d ----------------------------------------

@dataclass(frozen=True)
class Foot2dGeometry:
    """Site positions of foot2d in their body frames, read from the Pinocchio model."""

    heel: np.ndarray      # (3,) in the foot frame (origin A)
    metatarsal: np.ndarray
    mtp: np.ndarray       # MTP joint origin in the foot frame
    toe: np.ndarray       # (3,) in the toes frame (origin at the MTP joint)

    @classmethod
    def from_model(cls, model) -> "Foot2dGeometry":
        pm = model.pin
        for c in ("ankle_x", "ankle_y", "foot_angle", "mtp"):
            model.coordinate_index(c)

        def frame_local(name):
            return np.array(pm.frames[model.frame_id(name)].placement.translation)

        jm = pm.getJointId("mtp")
        return cls(frame_local("heel"), frame_local("metatarsal"),
                   np.array(pm.jointPlacements[jm].translation), frame_local("toe"))


def _rot(angle):
    """World rotation of a body turned by ``angle`` about (0, 0, -1): (N, 3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    z = np.zeros(np.shape(angle))
    return np.stack([vector(c, s, z), vector(-s, c, z), vector(z, z, z + 1.0)], axis=-2)


def _planar(x, y):
    """(N, 3) vectors ``(x, y, 0)``."""
    return vector(x, y, 0.0 * x)


def foot2d_site_kinematics(geom: Foot2dGeometry, q, v) -> dict:
    """``{site: SiteKinematics}`` of foot2d from ``q, v`` (N, 4), vectorised (no Pinocchio loop).

    Same numbers as :func:`pinmsk.contact.sphere.site_kinematics` (tested), without
    the Jacobians; used by the identification where the toe angle changes every iteration.
    ``q, v`` may also be sequences of the four (N,) columns, some of them
    :class:`~pinmsk.contact.dual.Dual` (the fitted toe angle): the kinematics then carry derivatives.
    """
    if not isinstance(q, (list, tuple)):
        q, v = np.asarray(q, dtype=float).T, np.asarray(v, dtype=float).T
    A, vA = _planar(q[0], q[1]), _planar(v[0], v[1])
    z = np.zeros(np.shape(q[0]))
    Rf = _rot(q[2])
    wf = vector(z, z, -v[2])
    Rt = _rot(q[2] + q[3])
    wt = vector(z, z, -(v[2] + v[3]))
    foot = SiteKinematics(A, Rf, vA, wf)
    out = {}
    for site in ("heel", "metatarsal"):
        p, vp = foot.point(getattr(geom, site))
        out[site] = SiteKinematics(p, Rf, vp, wf)
    pm, vpm = foot.point(geom.mtp)
    toes = SiteKinematics(pm, Rt, vpm, wt)
    p, vp = toes.point(geom.toe)
    out["toe"] = SiteKinematics(p, Rt, vp, wt)
    return out
