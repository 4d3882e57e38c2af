"""One conformance suite over every kind of Component pinmsk has.

Cases (``CASES``):

* every registered effect family (built-in or user-registered while the tests run), on the
  first built-in model with a target for it (forearm, then gait2d);
* every contact kind (point / Hunt-Crossley, volumetric, hyper-volumetric) at the heel,
  metatarsal and toe of foot2d (centres at the sites) and of gait2d (``center="sole"``), as
  :func:`pinmsk.contact.foot_contacts` builds them, and one sphere from a sidecar
  ``[[contacts]]`` entry (:func:`pinmsk.contact.from_spec`, an explicit ``center = [x, y]``);
* OpenSim's SmoothSphereHalfSpaceForce and HuntCrossleyForce on gait2d's sole frames, offset
  spheres against Moco's floor (a half space turned by -90 degrees about z) and against a ramp
  (:data:`OPENSIM_CONTACTS`);
* the muscle set (``model.muscles``) of forearm (Thelen 2003) and gait2d (Nagano & Gerritsen).

Each is checked on what applies to it: declarations (family, label, target, parameters with
units and bounds, listed in ``model.parameters``), ``generalized_force`` (shape, finiteness,
cache and per-frame equivalence), the parameter values that switch the physics off, parameter
Jacobians and state derivatives against finite differences (the effects' ``param_jacobian`` /
``state_derivatives``; the contacts' forward-mode :class:`~pinmsk.contact.dual.Dual` numbers
through ``evaluate_kinematics``; the muscle paths' moment arms), pickling and equality (equal
components give identical forces, unequal options give unequal components), ``with_params`` /
``fix`` / ``free`` copies, and immutability.  A skip says which check does not apply and why.
"""
from __future__ import annotations

import functools
import pickle
from dataclasses import dataclass

import numpy as np
import pytest

import pinmsk
from pinmsk.components import Component, Motion
from pinmsk.contact import (CONTACT_TYPES, HalfSpaceContact, HuntCrossley, HuntCrossleyForce, HyperVolumetric,
                            SiteKinematics, SmoothSphereHalfSpaceForce, Volumetric, foot_contacts, from_spec,
                            wrench_generalized_force)
from pinmsk.contact.dual import Dual
from pinmsk.contact.foot import KINDS, SITES, Foot2dGeometry, foot2d_site_kinematics
from pinmsk.diagnose.catalog import CatalogContext, catalog
from pinmsk.effects import MeasurementEffect, SignalEffect, families, get
from pinmsk.errors import ModelError
from pinmsk.muscles.muscle_set import MUSCLE_PREFIX, MuscleSet
from pinmsk.muscles.paths import MomentArmPath


@functools.lru_cache(maxsize=None)
def _model(name):
    return pinmsk.load_model(name)


def _uniform_q(model, rng, n, lo_frac, hi_frac):
    """``n`` configurations in ``[lo_frac, hi_frac]`` of each coordinate's range (clipped to [-1, 1.5])."""
    lo = np.clip(model.pin.lowerPositionLimit, -1.0, 1.5)
    hi = np.clip(model.pin.upperPositionLimit, -1.0, 1.5)
    return lo + (hi - lo) * (lo_frac + (hi_frac - lo_frac) * rng.random((n, model.nv)))


# -- the cases ------------------------------------------------------------------------

@dataclass(frozen=True)
class Case:
    """A component, the model it acts on and a motion that exercises it."""

    comp: Component
    model: pinmsk.Model
    motion: Motion

    @property
    def host(self) -> pinmsk.Model:
        """A model holding the component (the muscle set is already the model's)."""
        return self.model if self.comp.kind == "muscle" else self.model.with_effect(self.comp)

    def in_host(self, model) -> Component:
        return model.muscles if self.comp.kind == "muscle" else model.component(self.comp.label)

    def prefixed(self, name: str) -> str:
        """The parameter's name in ``model.parameters``."""
        return f"{MUSCLE_PREFIX}:{name}" if self.comp.kind == "muscle" else f"{self.comp.label}.{name}"

    def force(self, comp=None, params=None, cache=None) -> np.ndarray:
        return (comp or self.comp).generalized_force(self.model, self.motion, params, cache)


def _effect_motion(model, n=40, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 0.39, n)
    q = _uniform_q(model, rng, n, 0.3, 0.7)
    sig = {f"{m}_excitation": 0.2 + 0.3 * (1 + np.sin(20 * t + rng.random() * 6)) for m in model.muscle_names}
    return Motion(t, q, rng.normal(0, 1.5, (n, model.nv)), rng.normal(0, 5.0, (n, model.nv)), sig)


def _effect_case(family):
    """The family on the first applicable target of forearm, then gait2d (other components removed)."""
    cls = get(family)
    for name in ("forearm", "gait2d"):
        model = _model(name)
        for c in model.components:
            model = model.without(c.label)
        found = []
        for mode in ("muscle", "torque"):      # muscle-level effects, then measurement effects of a torque comparison
            ctx = CatalogContext(mode, tuple(model.coordinates), (), ())
            found = found or catalog(model, None, families=[family], context=ctx)
        if not found and getattr(cls, "target_kind", "") == "frame":
            found = [cls(model.frame_names[-1])]
        if found:
            return Case(found[0], model, _effect_motion(model))
    pytest.skip(f"no built-in model has a target for '{family}'")


#: the coordinate that moves a foot up and down
VERTICAL = {"foot2d": "ankle_y", "gait2d": "torso_y"}


def _contact_motion(model, comp, n=12, seed=1):
    """Frames with the sphere 2-8 mm into the ground, slipping at ~0.1 m/s, and compressed or
    released at rates that keep the damping factor ``1 + a v_n`` of Eq. 4.4 / 4.8 in [0.7, 2]
    (OpenSim's ``1 + 3/2 c v_n`` in [0.02, 2], where the smooth sphere's second switch acts):
    the vertical coordinate and its speed are shifted to give that penetration and rate."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    q = _uniform_q(model, rng, n, 0.4, 0.6)
    v = rng.normal(0.0, 0.1, (n, model.nv))
    j = model.coordinate_index(VERTICAL[model.name])
    e = np.zeros(model.nv)
    e[j] = 1.0

    def penetration(q):
        return comp.evaluate(model, Motion(t, q, v, np.zeros_like(q))).penetration

    eps = 1e-6
    # the penetration is linear in the vertical coordinate (-1 on level ground, -cos on a ramp)
    slope = (penetration(q + eps * e) - penetration(q - eps * e)) / (2 * eps)
    q[:, j] += (rng.uniform(0.002, 0.008, n) - penetration(q)) / slope
    rate = (penetration(q + eps * v) - penetration(q - eps * v)) / (2 * eps)
    if isinstance(comp, HalfSpaceContact):
        target = (rng.uniform(0.02, 2.0, n) - 1.0) / (1.5 * max(comp.values["dissipation"], 0.1))
    else:
        target = rng.uniform(-0.3, 1.0, n) / max(comp.values.get("a_s", comp.values.get("a_v", 10.0)), 10.0)
    v[:, j] += (target - rate) / slope
    return Motion(t, q, v, np.zeros_like(q))


def _floor_normal(orientation_z: float) -> tuple:
    """The outward normal of an OpenSim ContactHalfSpace on the ground turned by ``orientation_z``
    about z (``-x`` of its frame): Moco's floor (-pi/2) has +y, up to rounding."""
    return (-np.cos(orientation_z), -np.sin(orientation_z), 0.0)


#: Moco's 2-D walking contact parameters (2D_gait.osim)
MOCO = dict(stiffness=3067776.0, dissipation=2.0, static_friction=0.8, dynamic_friction=0.8,
            viscous_friction=0.5, transition_velocity=0.2)
#: OpenSim's contacts: offset spheres on gait2d's sole frames, on Moco's floor and on a ramp
RAMP = dict(plane_normal=(-np.sin(0.1), np.cos(0.1), 0.05), plane_point=(0.1, 0.02, -0.03))
OPENSIM_CONTACTS = {
    "smooth_sphere_half_space:heel_r": lambda: SmoothSphereHalfSpaceForce(
        "heel_r", location=(0.03, 0.035, 0.0), plane_normal=_floor_normal(-np.pi / 2), radius=0.035, **MOCO),
    "smooth_sphere_half_space:toe_r": lambda: SmoothSphereHalfSpaceForce(
        "toe_r", location=(0.0, 0.015, 0.005), radius=0.015, **{**MOCO, "dissipation": 1.0,
                                                               "static_friction": 0.9}, **RAMP),
    "hunt_crossley_force:metatarsal_r": lambda: HuntCrossleyForce(
        "metatarsal_r", location=(0.01, 0.02, -0.004), radius=0.02, stiffness=1e6, dissipation=1.5,
        static_friction=0.9, dynamic_friction=0.5, viscous_friction=0.3, transition_velocity=0.2, **RAMP),
}


#: a sidecar [[contacts]] entry: the alias type name, a fixed centre in the site frame, a fixed parameter
SIDECAR_CONTACT = {"type": "hunt_crossley", "frame": "toe_r", "center": [0.01, 0.03], "k_s": 5e4,
                   "fixed": ["mu_f"]}


def _contact_case(model_name, kind, site):
    model = _model(model_name)
    if f"{kind}:{site}" in OPENSIM_CONTACTS:
        comp = OPENSIM_CONTACTS[f"{kind}:{site}"]()
    elif kind == "sidecar":
        comp = from_spec(SIDECAR_CONTACT, where="conformance [[contacts]] #1")
    else:
        comp = foot_contacts(model, kind, side=None if model_name == "foot2d" else "r")[SITES.index(site)]
    return Case(comp, model, _contact_motion(model, comp))


def _muscle_motion(model, n=12, seed=2):
    """A motion whose ``<muscle>_force`` signals are ``a F_active + F_passive`` at random activations."""
    rng = np.random.default_rng(seed)
    q = _uniform_q(model, rng, n, 0.3, 0.7)
    v = rng.normal(0.0, 1.0, (n, model.nv))
    f_act, f_pas = model.muscles.force_limits(q, v)
    F = rng.uniform(0.05, 1.0, f_act.shape) * f_act + f_pas
    sig = {f"{m}_force": F[:, i] for i, m in enumerate(model.muscle_names)}
    return Motion(np.arange(n) * 0.01, q, v, rng.normal(0.0, 5.0, (n, model.nv)), sig)


def _muscle_case(model_name):
    model = _model(model_name)
    return Case(model.muscles, model, _muscle_motion(model))


CASES = ([f"effect:{f}" for f in families()]
         + [f"contact:{m}:{k}:{s}" for m in ("foot2d", "gait2d") for k in KINDS for s in SITES]
         + [f"contact:gait2d:sidecar:{SIDECAR_CONTACT['frame']}"]
         + [f"contact:gait2d:{key}" for key in OPENSIM_CONTACTS]
         + ["muscles:forearm", "muscles:gait2d"])


@functools.lru_cache(maxsize=None)
def _build(case_id) -> Case:
    kind, *rest = case_id.split(":")
    return {"effect": _effect_case, "contact": _contact_case, "muscles": _muscle_case}[kind](*rest)


@pytest.fixture(params=CASES)
def case(request) -> Case:
    return _build(request.param)


def test_the_suite_covers_every_kind_of_component():
    assert {"joint_damping", "coulomb_friction", "joint_spring", "passive_elastic", "payload",
            "segment_mass", "activation_dynamics", "electromechanical_delay",
            "riener_edrich_1999"} <= set(families())
    kinds = {type(_build(c).comp) for c in CASES if c.startswith("contact:")}
    assert kinds == set(CONTACT_TYPES) == set(KINDS.values()) | {SmoothSphereHalfSpaceForce, HuntCrossleyForce}
    assert {_build(c).comp.mtu.__class__.__name__ for c in CASES if c.startswith("muscles:")} == \
        {"Thelen2003", "NaganoGerritsen"}
    # every contact motion loads its sphere (else the contact checks below could not fail)
    for c in CASES:
        if c.startswith("contact:"):
            cs = _build(c)
            assert np.mean(cs.comp.evaluate(cs.model, cs.motion).normal > 0.01) > 0.5, c


# -- declarations -------------------------------------------------------------------------

def test_declarations(case):
    comp, model = case.comp, case.model
    assert comp.__doc__ and type(comp).__module__ != "__main__"
    assert comp.kind in ("effect", "contact", "muscle")
    if comp.kind == "effect":
        assert get(comp.family) is type(comp)
    elif comp.kind == "contact":
        assert type(comp) in CONTACT_TYPES
    else:
        assert isinstance(comp, MuscleSet) and comp.family == "muscles"
    assert comp.label == (f"{comp.family}:{comp.target}" if comp.target else comp.family)
    # the target exists, and a component aimed at a missing one is refused, naming it
    if comp.target_kind == "coordinate":
        assert comp.target in model.coordinates
    elif comp.target_kind == "side":
        assert comp.target in ("r", "l")
    elif comp.target_kind in ("frame", "body"):
        model.frame_id(comp.target)
    elif comp.target_kind == "muscle":
        assert comp.target == "muscles" or comp.target in model.muscle_names
    else:
        assert comp.target_kind == "model" and comp.target is None
    comp.check_target(model)
    if comp.kind != "muscle":
        with pytest.raises(ModelError, match="no_such_target"):
            model.with_effect(type(comp)("no_such_target"))
    # parameters: named, bounded, with a unit string and a meaning
    params = comp.params
    assert params and list(params) == list(comp.values)
    for name, p in params.items():
        assert p.name == name and np.isfinite(p.value) and p.min <= p.value <= p.max, p
        assert isinstance(p.unit, str) and p.doc, f"{comp.label}.{name} needs a unit string and a doc"
        assert isinstance(p.vary, bool)
    # ... and the model's one parameter table lists each of them, prefixed
    table = case.host.parameters
    for name, p in params.items():
        row = table[case.prefixed(name)]
        assert (row.value, row.min, row.max, row.unit, row.vary) == (p.value, p.min, p.max, p.unit, p.vary)
    sep = ":" if comp.kind == "muscle" else "."     # muscle:BRD.f_max, joint_damping:elbow_flexion.c
    assert comp.parameter_table(prefix="x").valuesdict() == {f"x{sep}{k}": v for k, v in comp.values.items()}


def test_sidecar_contact_keeps_its_entry():
    comp = _build(f"contact:gait2d:sidecar:{SIDECAR_CONTACT['frame']}").comp
    assert isinstance(comp, HuntCrossley) and comp.center == (0.01, 0.03)
    assert comp.values["k_s"] == 5e4 and not comp.params["mu_f"].vary and comp.params["k_s"].vary


# -- generalized force ------------------------------------------------------------------------

def test_generalized_force_shape_and_finite(case):
    comp, model, mo = case.comp, case.model, case.motion
    Q = case.force()
    assert Q.shape == (mo.n_frames, model.nv) and np.all(np.isfinite(Q))
    # prepare is an optimisation only: with or without it, or through a Data, the same numbers
    np.testing.assert_allclose(case.force(cache=comp.prepare(model, mo)), Q, rtol=1e-12, atol=1e-12)
    cache = comp.prepare(model, mo, data=model.create_data())
    np.testing.assert_allclose(case.force(cache=cache), Q, rtol=1e-12, atol=1e-12)
    # vectorised over frames == frame by frame
    one = np.vstack([comp.generalized_force(model, mo.subset(slice(k, k + 1))) for k in range(5)])
    np.testing.assert_allclose(one, Q[:5], rtol=1e-10, atol=1e-12)
    if isinstance(comp, (SignalEffect, MeasurementEffect)):
        assert np.all(Q == 0.0)          # acts through the muscles, or is the model of a sensor
    else:
        assert np.abs(Q).max() > 0.0     # the motion exercises the component


# -- zero parameters: no physics ------------------------------------------------------------

def _effect_zero(case):
    comp, model, mo = case.comp, case.model, case.motion
    zero = getattr(comp, "zero_params", None)
    if isinstance(comp, SignalEffect):
        if zero is not None:
            u = np.column_stack([mo.signals[f"{m}_excitation"] for m in model.muscle_names])
            np.testing.assert_allclose(comp.transform(mo.t, u, zero), u, atol=1e-12)
            assert np.abs(comp.transform(mo.t, u) - u).max() > 1e-3      # ... and it does act otherwise
            return
        pytest.skip(f"{comp.family} has no parameter values that switch it off")
    if isinstance(comp, MeasurementEffect):
        tau = mo.a[:, 0] * 3.0 + 1.0
        np.testing.assert_allclose(comp.measure(tau, zero), tau, atol=1e-12)      # a calibrated sensor
        assert np.abs(comp.measure(tau) - tau).max() > 1e-3                          # ... this one is not
        np.testing.assert_allclose(comp.unmeasure(comp.measure(tau)), tau, rtol=1e-12, atol=1e-12)
        return
    if zero is None:
        pytest.skip(f"{comp.family} has no parameter values that switch it off")
    np.testing.assert_allclose(case.force(comp.with_params(zero)), 0.0, atol=1e-12)


#: the parameters whose zero switches a sphere off: the stiffness, and for the hyper-volumetric
#: law also its damping, a_h V v_n (Eq. 4.15), which does not scale with k_h
CONTACT_OFF = {HuntCrossley: ("k_s",), Volumetric: ("k_v",), HyperVolumetric: ("k_h", "a_h"),
               SmoothSphereHalfSpaceForce: ("stiffness",), HuntCrossleyForce: ("stiffness",)}


def _contact_zero(case):
    comp, model, mo = case.comp, case.model, case.motion
    off = CONTACT_OFF[type(comp)]
    zero = comp.with_params({n: 0.0 for n in off})
    np.testing.assert_array_equal(case.force(zero), 0.0)
    out = zero.evaluate(model, mo)
    np.testing.assert_array_equal(out.force, 0.0)      # normal and friction (mu_f f_n) both
    np.testing.assert_array_equal(out.penetration, comp.evaluate(model, mo).penetration)   # same geometry
    if len(off) > 1:
        assert np.abs(case.force(comp.with_params({off[0]: 0.0}))).max() > 0.0


def _muscle_zero(case):
    """Activation 0 and no passive stretch: no force.  ``F = a F_active + F_passive`` (the
    rigid-tendon force capacity) is exact at a = 0 and at a = 1."""
    ms, mo = case.comp, case.motion
    q, v = mo.q, mo.v
    l, lv = ms.lengths(q), ms.velocities(q, v)
    f_act, f_pas = ms.force_limits(q, v)
    zero = np.zeros_like(l)
    rigid = ms.mtu.force(zero, l, lv)
    np.testing.assert_allclose(rigid, f_pas, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(ms.mtu.force(np.ones_like(l), l, lv), f_act + f_pas, rtol=1e-12, atol=1e-9)
    unstretched = f_pas == 0.0
    assert unstretched.any()
    compliant = ms.mtu.force(zero, l, lv, tendon="compliant")
    assert np.all(np.isfinite(compliant))
    assert np.all(rigid[unstretched] == 0.0)
    np.testing.assert_allclose(compliant[unstretched], 0.0, atol=1e-6)
    # the tendon gives a little under passive load: less fibre stretch, no more force than rigid
    assert np.all(compliant[~unstretched] > 0.0) and np.all(compliant <= rigid * (1 + 1e-9) + 1e-9)
    # and through the skeleton: the generalized force of these forces is that of the passive ones
    Q0 = ms.joint_moments(q, rigid)
    np.testing.assert_allclose(Q0, ms.joint_moments(q, f_pas), rtol=1e-12, atol=1e-9)
    if unstretched.all():
        np.testing.assert_array_equal(Q0, 0.0)


def test_zero_parameters_zero_force(case):
    {"effect": _effect_zero, "contact": _contact_zero, "muscle": _muscle_zero}[case.comp.kind](case)


# -- parameter Jacobians ----------------------------------------------------------------------

def _effect_param_jacobian(case):
    comp, model, mo = case.comp, case.model, case.motion
    if isinstance(comp, MeasurementEffect):      # d reading / d theta, of the sensor model
        tau = mo.a[:, 0] * 3.0 + 1.0
        J = comp.measure_jacobian(tau)
        assert J.shape == (mo.n_frames, len(comp.parameters))
        for k, (name, v) in enumerate(comp.values.items()):
            h = 1e-6 * max(abs(v), 1.0)
            fd = (comp.measure(tau, {name: v + h}) - comp.measure(tau, {name: v - h})) / (2 * h)
            np.testing.assert_allclose(J[:, k], fd, rtol=1e-6, atol=1e-9)
        return
    if not hasattr(comp, "param_jacobian"):
        pytest.skip(f"{comp.family} has no analytic parameter Jacobian")
    cache = comp.prepare(model, mo)
    J = comp.param_jacobian(model, mo, cache=cache)
    assert J.shape == (mo.n_frames, model.nv, len(comp.parameters))
    base = comp.values
    for k, name in enumerate(base):
        h = 1e-6 * max(abs(base[name]), 1.0)
        fd = (case.force(params={name: base[name] + h}, cache=cache)
              - case.force(params={name: base[name] - h}, cache=cache)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-5, atol=1e-7 * max(1.0, np.abs(fd).max()))


def _contact_param_jacobian(case):
    """The exact Jacobian: every parameter a :class:`Dual` seed through ``evaluate_kinematics``
    and the wrench's ``J^T`` (the code ContactFit differentiates)."""
    comp, model, mo = case.comp, case.model, case.motion
    kin = comp.prepare(model, mo)
    base = comp.values
    P = len(base)
    seeded = {name: Dual(value, np.eye(P)[k]) for k, (name, value) in enumerate(base.items())}
    out = comp.evaluate_kinematics(kin, seeded)
    Q = wrench_generalized_force(kin, out.force, out.point)
    np.testing.assert_allclose(Q.val, case.force(cache=kin), rtol=1e-13, atol=1e-12)
    assert Q.der.shape == (mo.n_frames, model.nv, P)
    for k, name in enumerate(base):
        h = 1e-6 * max(abs(base[name]), 1e-3)
        fd = (case.force(params={name: base[name] + h}, cache=kin)
              - case.force(params={name: base[name] - h}, cache=kin)) / (2 * h)
        assert np.abs(fd).max() > 0.0, name     # every parameter acts on a loaded, slipping sphere
        np.testing.assert_allclose(Q.der[:, :, k], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max(), err_msg=name)


def _muscle_param_jacobian(case):
    """The muscle set exposes no parameter Jacobian; the one derivative known in closed form is
    that of the force capacity in ``f_max`` (Eq. A.7-A.8 are proportional to it), taken through
    ``with_params`` by central differences.  The generalized force R^T F of the measured forces
    does not depend on the parameters."""
    ms, mo = case.comp, case.motion
    f_act, f_pas = ms.force_limits(mo.q, mo.v)
    for i in (0, ms.n - 1):
        key = f"{ms.names[i]}.f_max"
        f = ms.values[key]
        h = 1e-6 * f
        up = ms.with_params({key: f + h}).force_limits(mo.q, mo.v)
        dn = ms.with_params({key: f - h}).force_limits(mo.q, mo.v)
        for which, F in ((0, f_act), (1, f_pas)):
            fd = (up[which] - dn[which]) / (2 * h)
            expected = np.zeros_like(F)
            expected[:, i] = F[:, i] / f
            np.testing.assert_allclose(fd, expected, rtol=1e-6, atol=1e-9)
        np.testing.assert_array_equal(case.force(ms.with_params({key: 2 * f})), case.force())
    assert np.abs(f_act).max() > 0.0


def test_parameter_jacobian_matches_finite_differences(case):
    {"effect": _effect_param_jacobian, "contact": _contact_param_jacobian,
     "muscle": _muscle_param_jacobian}[case.comp.kind](case)


# -- state derivatives -------------------------------------------------------------------------

def _shifted(mo, which, j, h):
    e = np.zeros(mo.q.shape[1])
    e[j] = h
    if which == "q":
        return Motion(mo.t, mo.q + e, mo.v, mo.a, mo.signals)
    return Motion(mo.t, mo.q, mo.v + e, mo.a, mo.signals)


def _effect_state_derivatives(case):
    comp, model, mo = case.comp, case.model, case.motion
    if not hasattr(comp, "state_derivatives"):
        pytest.skip(f"{comp.family} has no state derivatives")
    dq, dv = comp.state_derivatives(model, mo)
    h = 1e-6
    for j in range(model.nv):
        for which, D in (("q", dq), ("v", dv)):
            fd = (comp.generalized_force(model, _shifted(mo, which, j, h))
                  - comp.generalized_force(model, _shifted(mo, which, j, -h))) / (2 * h)
            np.testing.assert_allclose(D[:, :, j], fd, rtol=1e-5, atol=1e-6 * max(1.0, np.abs(fd).max()))


KIN_FIELDS = ("position", "velocity", "omega")


def _contact_state_derivatives(case):
    """The forces and their point of application, d/d(site position, velocity, angular velocity)
    through :class:`Dual` kinematics; on foot2d also d/d(q, v) through its planar kinematics
    (Dual coordinates) against Pinocchio's by finite differences."""
    comp, model, mo = case.comp, case.model, case.motion
    kin = comp.prepare(model, mo)
    n = mo.n_frames
    seeded = {}
    for k, f in enumerate(KIN_FIELDS):
        der = np.zeros((n, 3, 9))
        der[:, :, 3 * k:3 * k + 3] = np.eye(3)
        seeded[f] = Dual(getattr(kin, f), der)
    out = comp.evaluate_kinematics(SiteKinematics(seeded["position"], kin.rotation, seeded["velocity"],
                                                  seeded["omega"]))
    h = 1e-7
    for k, f in enumerate(KIN_FIELDS):
        for i in range(3):
            def moved(s, f=f, i=i):
                arrays = {g: np.array(getattr(kin, g)) for g in KIN_FIELDS}
                arrays[f][:, i] += s
                return comp.evaluate_kinematics(SiteKinematics(arrays["position"], kin.rotation,
                                                               arrays["velocity"], arrays["omega"]))
            up, dn = moved(h), moved(-h)
            for name in ("force", "point"):
                fd = (getattr(up, name) - getattr(dn, name)) / (2 * h)
                np.testing.assert_allclose(getattr(out, name).der[..., 3 * k + i], fd, rtol=1e-4,
                                           atol=1e-5 * max(np.abs(fd).max(), 1.0), err_msg=f"{name}/{f}[{i}]")
    assert np.abs(out.force.der[:, 1, 1]).max() > 0.0      # the normal force stiffens with depth
    if model.name != "foot2d":
        return
    geom = Foot2dGeometry.from_model(model)
    eye = np.eye(2 * model.nv)
    qd = [Dual(mo.q[:, j], np.tile(eye[j], (n, 1))) for j in range(model.nv)]
    vd = [Dual(mo.v[:, j], np.tile(eye[model.nv + j], (n, 1))) for j in range(model.nv)]
    out = comp.evaluate_kinematics(foot2d_site_kinematics(geom, qd, vd)[comp.target])
    for j in range(2 * model.nv):
        which, col = ("q", j) if j < model.nv else ("v", j - model.nv)
        up = comp.evaluate(model, _shifted(mo, which, col, h))
        dn = comp.evaluate(model, _shifted(mo, which, col, -h))
        for name in ("force", "point"):
            fd = (getattr(up, name) - getattr(dn, name)) / (2 * h)
            np.testing.assert_allclose(getattr(out, name).der[..., j], fd, rtol=1e-4,
                                       atol=1e-5 * max(np.abs(fd).max(), 1.0), err_msg=f"{name}/{which}{col}")


def _muscle_state_derivatives(case):
    """The muscle set's state derivatives are its paths': moment arms r = -dl/dq, dr/dq, the
    lengthening velocity and acceleration along the motion; and the generalized force of the
    muscle forces does their work, Q . v = -F . dl/dt (virtual power)."""
    ms, model, mo = case.comp, case.model, case.motion
    q, v, a = mo.q, mo.v, mo.a
    R = ms.moment_arms(q)
    dR = ms.path.moment_arm_derivative(q)
    h = 1e-6
    for j in range(model.nv):
        e = np.zeros(model.nv)
        e[j] = h
        np.testing.assert_allclose(-(ms.lengths(q + e) - ms.lengths(q - e)) / (2 * h), R[:, :, j],
                                   rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose((ms.moment_arms(q + e) - ms.moment_arms(q - e))[:, :, j] / (2 * h),
                                   dR[:, :, j], rtol=1e-5, atol=1e-8)
    l_dot = (ms.lengths(q + h * v) - ms.lengths(q - h * v)) / (2 * h)
    np.testing.assert_allclose(ms.velocities(q, v), l_dot, rtol=1e-6, atol=1e-9)
    s = 1e-4
    path = [ms.lengths(q + t * v + 0.5 * t * t * a) for t in (-s, 0.0, s)]
    np.testing.assert_allclose(ms.path.accelerations(q, v, a), (path[0] - 2 * path[1] + path[2]) / s ** 2,
                               rtol=1e-4, atol=1e-5)
    F = np.column_stack([mo.signal(f"{m}_force") for m in ms.names])
    power = np.einsum("nj,nj->n", case.force(), v)
    np.testing.assert_allclose(power, -np.einsum("nm,nm->n", F, l_dot), rtol=1e-6, atol=1e-6)
    assert np.abs(R).max() > 0.0 and np.abs(power).max() > 0.0


def test_state_derivatives_match_finite_differences(case):
    {"effect": _effect_state_derivatives, "contact": _contact_state_derivatives,
     "muscle": _muscle_state_derivatives}[case.comp.kind](case)


# -- pickling and equality ------------------------------------------------------------------------

def _outputs(case, comp):
    """Everything the component computes on the case's motion (forces and, per kind, more)."""
    mo = case.motion
    out = [case.force(comp)]
    if comp.kind == "contact":
        o = comp.evaluate(case.model, mo)
        out += [o.normal, o.friction, o.force, o.point, o.penetration, o.volume, o.slip]
    elif comp.kind == "muscle":
        out += list(comp.force_limits(mo.q, mo.v)) + [comp.moment_arms(mo.q)]
    elif isinstance(comp, SignalEffect):
        u = np.column_stack([mo.signals[f"{m}_excitation"] for m in case.model.muscle_names])
        out.append(comp.transform(mo.t, u))
    elif isinstance(comp, MeasurementEffect):
        out.append(comp.measure(mo.a[:, 0] * 3.0 + 1.0))
    return out


def test_pickle_roundtrip(case):
    comp = case.comp
    back = pickle.loads(pickle.dumps(comp))
    assert back is not comp and back == comp and hash(back) == hash(comp)
    for a, b in zip(_outputs(case, back), _outputs(case, comp)):
        np.testing.assert_array_equal(a, b)
    # and inside a model
    host = pickle.loads(pickle.dumps(case.host))
    inside = case.in_host(host)
    assert inside == comp
    np.testing.assert_array_equal(inside.generalized_force(host, case.motion), case.force())
    assert host.parameters == case.host.parameters


def _contact_options(comp) -> tuple[str, ...]:
    """The settings of a contact that are not parameters (equality compares them too)."""
    if isinstance(comp, HalfSpaceContact):
        return ("location", "plane_normal", "plane_point")
    return ("center", "ground_speed", "smoothing")


def _rebuilt(comp, **options):
    """A fresh sphere with the parameters (values, bounds, vary) and options of ``comp``, some replaced."""
    kw = {o: getattr(comp, o) for o in _contact_options(comp)}
    kw.update(options)
    p = comp.params
    fresh = type(comp)(comp.target, bounds={k: (x.min, x.max) for k, x in p.items()}, **kw, **comp.values)
    return fresh.with_params(vary={k: x.vary for k, x in p.items()})


def _variants(comp):
    """``(what, same, others)``: a component built afresh equal to ``comp``, and ones that differ
    from it in something that changes what it computes."""
    if isinstance(comp, HalfSpaceContact):
        loc = np.array(comp.location)
        return _rebuilt(comp), [_rebuilt(comp, location=loc + (0.0, 0.002, 0.0)),
                                _rebuilt(comp, plane_normal=(0.1, 1.0, 0.0)),
                                _rebuilt(comp, plane_point=np.array(comp.plane_point) + (0.0, 0.001, 0.0))]
    if comp.kind == "contact":
        centers = [c for c in (None, "sole", (0.0, 0.01)) if c != comp.center]
        return _rebuilt(comp), [_rebuilt(comp, center=c) for c in centers] + [
            _rebuilt(comp, ground_speed=-1.0), _rebuilt(comp, smoothing=1e-3)]
    if comp.kind == "muscle":
        path = comp.path

        def with_path(coeffs):
            return MuscleSet(names=comp.names, model_type=comp.model_type, mtu=comp.mtu, tendon=comp.tendon,
                             path=MomentArmPath(muscles=path.muscles, coordinates=path.coordinates,
                                                l0=path.l0, coeffs=coeffs))
        return with_path(np.array(path.coeffs)), [with_path(1.1 * path.coeffs)]
    name, p = next(iter(comp.params.items()))
    other = p.value + 0.5 if p.value + 0.5 <= p.max else p.value - 0.5 * (p.value - p.min)
    return type(comp)(comp.target, **comp.values), [comp.with_params({name: other})]


def test_equal_components_compute_the_same(case):
    comp = case.comp
    same, others = _variants(comp)
    assert same is not comp and same == comp and hash(same) == hash(comp)
    for a, b in zip(_outputs(case, same), _outputs(case, comp)):
        np.testing.assert_array_equal(a, b)
    for other in others:
        assert other != comp, other
        assert any(not np.array_equal(a, b) for a, b in zip(_outputs(case, other), _outputs(case, comp)))


# -- with_params, fix, free: copies -------------------------------------------------------------

def _key_parameter(comp) -> str:
    if comp.kind == "contact":
        return comp.stiffness_name
    if comp.kind == "muscle":
        return f"{comp.names[0]}.f_max"
    return next(iter(comp.params))


def test_with_params_copies(case):
    comp = case.comp
    name = _key_parameter(comp)
    p = comp.params[name]
    before, values = _outputs(case, comp), comp.values
    new_value = p.value + 0.5 * (min(p.max, p.value + 1.0) - p.value) if p.max > p.value else \
        p.value - 0.5 * (p.value - max(p.min, p.value - 1.0))
    other = comp.with_params({name: new_value})
    assert other is not comp and type(other) is type(comp) and other.target == comp.target
    assert other.values == {**values, name: pytest.approx(new_value)}
    assert any(not np.array_equal(a, b) for a, b in zip(_outputs(case, other), before))   # it acts
    assert comp.values == values                                  # the original is unchanged
    for a, b in zip(_outputs(case, comp), before):
        np.testing.assert_array_equal(a, b)
    if comp.kind == "contact":                                    # the copy keeps the options
        options = _contact_options(comp)
        assert [getattr(other, o) for o in options] == [getattr(comp, o) for o in options]
        for a, b in zip(_outputs(case, other), _outputs(case, _rebuilt(other))):
            np.testing.assert_array_equal(a, b)
    if comp.kind == "muscle":
        with pytest.raises(ModelError, match="not stored"):
            comp.with_params({name: new_value}, stderr={name: 0.01})
    else:
        err = comp.with_params({name: new_value}, stderr={name: 0.01})
        assert err.params[name].stderr == 0.01 and comp.params[name].stderr is None
    short = name.rsplit(".", 1)[-1]
    with pytest.raises(ModelError, match=short):
        comp.with_params({name: p.max + 1.0 if np.isfinite(p.max) else p.min - 1.0})
    with pytest.raises(ModelError, match="outside its bounds"):
        comp.with_params({name: p.value}, bounds={name: (p.value + 1.0, p.value + 2.0)})
    with pytest.raises(ModelError, match="no parameter"):
        comp.with_params({"no_such_parameter": 1.0})
    # bounds= returns a copy too
    wider = comp.with_params(bounds={name: (p.min, p.max + 1.0)})
    assert wider.params[name].max == p.max + 1.0 and comp.params[name].max == p.max


def test_fix_and_free_return_copies(case):
    comp = case.comp
    names = list(comp.params)
    vary = {k: p.vary for k, p in comp.params.items()}
    for name in dict.fromkeys((names[0], names[len(names) // 2], names[-1])):
        fixed, freed = comp.fix(name), comp.free(name)
        assert fixed is not comp and freed is not comp
        assert fixed.params[name].vary is False and freed.params[name].vary is True
        assert comp.with_params(vary={name: False}).params == fixed.params
        for copy_ in (fixed, freed):
            assert {k: p.vary for k, p in copy_.params.items() if k != name} == \
                {k: f for k, f in vary.items() if k != name}
            assert copy_.values == comp.values
    assert {k: p.vary for k, p in comp.params.items()} == vary      # the original is unchanged
    all_fixed = comp.fix(*names)
    assert not any(p.vary for p in all_fixed.params.values())
    assert all(p.vary for p in comp.free(*names).params.values())
    np.testing.assert_array_equal(case.force(all_fixed), case.force())   # vary is for fits only
    with pytest.raises(ModelError, match="no_such_parameter"):
        comp.fix("no_such_parameter")
    # the same through the model's parameter table
    host = case.host
    full = case.prefixed(names[0])
    m_fixed, m_freed = host.fix(full), host.free(full)
    assert m_fixed.parameters[full].vary is False and m_freed.parameters[full].vary is True
    assert case.in_host(m_freed).params[names[0]].vary is True
    assert case.in_host(m_fixed).params[names[0]].vary is False
    assert host.parameters[full].vary is vary[names[0]]
    with pytest.raises(ModelError, match="no parameter"):
        host.fix(case.prefixed("no_such_parameter"))


# -- immutability ------------------------------------------------------------------------------

OPTIONS = {"effect": (), "contact": ("center", "ground_speed", "smoothing", "location", "plane_normal", "plane_point"),
           "muscle": ("names", "mtu", "path", "tendon", "model_type")}


def test_frozen(case):
    comp = case.comp
    for attr in ("target", "_params", "brand_new_attribute") + OPTIONS[comp.kind]:
        with pytest.raises(AttributeError, match="immutable"):
            setattr(comp, attr, getattr(comp, attr, 1.0))      # even re-assigning the same value
    with pytest.raises(AttributeError, match="immutable"):
        del comp.target
    # what it hands out are copies, or read-only
    name = _key_parameter(comp)
    comp.params.clear()
    comp.values[name] = -1.0
    assert comp.params and comp.values[name] == comp.params[name].value != -1.0
    if comp.kind == "muscle":
        with pytest.raises(ValueError, match="read-only"):
            comp.f_max[0] = 1.0
        with pytest.raises(TypeError):
            comp.display_points["x"] = ()
