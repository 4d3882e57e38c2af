"""Shared conformance check over the whole effect registry.

For every registered family (built-in or user-registered while the tests
run): shapes, zero parameters giving zero force where that is the physics,
parameter and state derivatives against finite differences, pickling, and
``with_params`` returning a modified copy.
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest

import pinmsk
from pinmsk.components import Motion
from pinmsk.effects import SignalEffect, families, get
from pinmsk.diagnose.catalog import catalog
from pinmsk.diagnose.catalog import CatalogContext
from pinmsk.errors import ModelError

_MODELS: dict = {}


def _model(name):
    if name not in _MODELS:
        _MODELS[name] = pinmsk.load_model(name)
    return _MODELS[name]


def _motion(model, n=40, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 0.39, n)
    lo = np.where(np.isfinite(model.pin.lowerPositionLimit), model.pin.lowerPositionLimit, -1.0)
    hi = np.where(np.isfinite(model.pin.upperPositionLimit), model.pin.upperPositionLimit, 1.0)
    lo, hi = np.maximum(lo, -1.0), np.minimum(hi, 1.5)
    q = lo + (hi - lo) * (0.3 + 0.4 * rng.random((n, model.nv)))
    v = rng.normal(0, 1.5, (n, model.nv))
    a = rng.normal(0, 5.0, (n, model.nv))
    sig = {}
    for m in model.muscle_names:
        sig[f"{m}_excitation"] = 0.2 + 0.3 * (1 + np.sin(20 * t + rng.random() * 6))
    return Motion(t, q, v, a, sig)


def _instance(family):
    """(component, model) for a family: the first applicable target on forearm, then gait2d."""
    cls = get(family)
    for name in ("forearm", "gait2d"):
        model = _model(name)
        for c in model.components:
            model = model.without(c.label)
        ctx = CatalogContext("muscle", tuple(model.coordinates), (), ())
        found = catalog(model, None, families=[family], context=ctx)
        if not found and getattr(cls, "target_kind", "") == "frame":
            found = [cls(model.frame_names[-1])]
        if found:
            return found[0], model
    pytest.skip(f"no built-in model has a target for '{family}'")


FAMILIES = families()


@pytest.fixture(params=FAMILIES)
def effect(request):
    return _instance(request.param)


def test_registry_has_the_catalog_families():
    assert {"joint_damping", "coulomb_friction", "joint_spring", "passive_elastic", "payload",
            "segment_mass", "activation_dynamics", "electromechanical_delay",
            "riener_edrich_1999"} <= set(FAMILIES)


def test_declarations(effect):
    comp, model = effect
    assert comp.family in families()
    assert comp.label == f"{comp.family}:{comp.target}"
    names = [p.name for p in comp.parameters]
    assert len(set(names)) == len(names)
    for p in comp.parameters:
        assert p.min <= p.value <= p.max, p
        assert p.unit is not None and p.doc, f"{comp.family}.{p.name} needs a unit string and a doc"
    assert comp.__doc__ and type(comp).__module__ != "__main__"
    comp.check_target(model)


def test_shapes_and_finite(effect):
    comp, model = effect
    mo = _motion(model)
    cache = comp.prepare(model, mo)
    Q = comp.generalized_force(model, mo, cache=cache)
    assert Q.shape == (mo.n_frames, model.nv)
    assert np.all(np.isfinite(Q))
    # without the cache it must give the same (prepare is an optimisation only)
    np.testing.assert_allclose(comp.generalized_force(model, mo), Q, rtol=1e-12, atol=1e-12)
    # vectorised over frames == frame by frame
    one = np.vstack([comp.generalized_force(model, mo.subset(slice(k, k + 1))) for k in range(5)])
    np.testing.assert_allclose(one, Q[:5], rtol=1e-10, atol=1e-12)


def test_zero_parameters_zero_force(effect):
    comp, model = effect
    mo = _motion(model)
    zero = getattr(comp, "zero_params", None)
    if isinstance(comp, SignalEffect):
        assert np.all(comp.generalized_force(model, mo) == 0.0)   # acts through the muscles only
        if zero is not None:
            u = np.column_stack([mo.signals[f"{m}_excitation"] for m in model.muscle_names])
            np.testing.assert_allclose(comp.transform(mo.t, u, zero), u, atol=1e-12)
        return
    if zero is None:
        pytest.skip(f"{comp.family} has no parameter values that switch it off")
    Q = comp.with_params(zero).generalized_force(model, mo)
    np.testing.assert_allclose(Q, 0.0, atol=1e-12)


def test_parameter_jacobian_matches_finite_differences(effect):
    comp, model = effect
    if not hasattr(comp, "param_jacobian"):
        pytest.skip(f"{comp.family} has no analytic parameter Jacobian")
    mo = _motion(model)
    cache = comp.prepare(model, mo)
    J = comp.param_jacobian(model, mo, cache=cache)
    assert J.shape == (mo.n_frames, model.nv, len(comp.parameters))
    base = comp.values
    for k, name in enumerate(base):
        h = 1e-6 * max(abs(base[name]), 1.0)
        up = comp.generalized_force(model, mo, {name: base[name] + h}, cache)
        dn = comp.generalized_force(model, mo, {name: base[name] - h}, cache)
        fd = (up - dn) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-5, atol=1e-7 * max(1.0, np.abs(fd).max()))


def test_state_derivatives_match_finite_differences(effect):
    comp, model = effect
    if not hasattr(comp, "state_derivatives"):
        pytest.skip(f"{comp.family} has no state derivatives")
    mo = _motion(model)
    dq, dv = comp.state_derivatives(model, mo)
    for j in range(model.nv):
        for which, D in (("q", dq), ("v", dv)):
            h = 1e-6
            e = np.zeros(model.nv)
            e[j] = h
            if which == "q":
                up = Motion(mo.t, mo.q + e, mo.v, mo.a, mo.signals)
                dn = Motion(mo.t, mo.q - e, mo.v, mo.a, mo.signals)
            else:
                up = Motion(mo.t, mo.q, mo.v + e, mo.a, mo.signals)
                dn = Motion(mo.t, mo.q, mo.v - e, mo.a, mo.signals)
            fd = (comp.generalized_force(model, up) - comp.generalized_force(model, dn)) / (2 * h)
            np.testing.assert_allclose(D[:, :, j], fd, rtol=1e-5, atol=1e-6 * max(1.0, np.abs(fd).max()))


def test_pickle_roundtrip(effect):
    comp, model = effect
    mo = _motion(model)
    back = pickle.loads(pickle.dumps(comp))
    assert back == comp and hash(back) == hash(comp)
    np.testing.assert_array_equal(back.generalized_force(model, mo), comp.generalized_force(model, mo))
    # and inside a model
    m2 = pickle.loads(pickle.dumps(model.with_effect(comp)))
    assert comp.label in [c.label for c in m2.components]


def test_with_params_copies(effect):
    comp, model = effect
    name = comp.parameters[0].name
    p = comp.params[name]
    new_value = p.value + 0.5 * (min(p.max, p.value + 1.0) - p.value) if p.max > p.value else \
        p.value - 0.5 * (p.value - max(p.min, p.value - 1.0))
    other = comp.with_params({name: new_value}, stderr={name: 0.01})
    assert other is not comp and type(other) is type(comp) and other.target == comp.target
    assert other.values[name] == pytest.approx(new_value)
    assert comp.values[name] == p.value                       # the original is unchanged
    assert other.params[name].stderr == 0.01 and comp.params[name].stderr is None
    with pytest.raises(ModelError, match="outside its bounds"):
        comp.with_params({name: p.max + 1.0 if np.isfinite(p.max) else p.min - 1.0})
    with pytest.raises(ModelError, match="no parameter"):
        comp.with_params({"no_such_parameter": 1.0})
