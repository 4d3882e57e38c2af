"""Conformance of the muscle, activation and metabolic laws under CasADi.

Each law is written once against :mod:`pinmsk.backend`; here the CasADi
expression of it must give the numpy numbers (rel 1e-12) at random valid
points, its exact Jacobian (``casadi.jacobian``) must match central finite
differences of the numpy law (~1e-6), and the implicit compliant-tendon
residual must vanish at the numpy compliant equilibrium.
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import LazyCasadi  # noqa: E402

ca = LazyCasadi()   # imported inside the tests (tests/conftest.py)

from pinmsk import energy  # noqa: E402
from pinmsk.errors import ModelError  # noqa: E402
from pinmsk.muscles import (DeGroote2016, Millard2012, NaganoGerritsen, Thelen2003,  # noqa: E402
                            Thelen2003OpenSim)
from pinmsk.muscles.activation import activation_rate  # noqa: E402

M = 4
F_MAX = np.array([500.0, 1000.0, 1500.0, 2500.0])
L_OPT = np.array([0.10, 0.08, 0.12, 0.05])
L_SLACK = np.array([0.20, 0.25, 0.15, 0.30])
PENNATION = np.array([0.0, 0.2, 0.3, 0.1])
COMMON = dict(f_max=F_MAX, l_opt=L_OPT, l_slack=L_SLACK, pennation=PENNATION)

MODELS = {
    "Thelen2003": Thelen2003(**COMMON),
    "NaganoGerritsen": NaganoGerritsen(**COMMON, width=np.array([0.5, 0.6, 0.56, 0.45])),
    "DeGroote2016": DeGroote2016(**COMMON, damping=np.array([0.0, 0.01, 0.1, 0.05]),
                                 tendon_strain=np.array([0.049, 0.04, 0.06, 0.049])),
    "Thelen2003OpenSim": Thelen2003OpenSim(**COMMON, tendon_strain=np.array([0.04, 0.05, 0.033, 0.04]),
                                           fv_shape=0.3, eccentric_force=1.6),
}


def _rng(seed):
    return np.random.default_rng(seed)


def _outputs(out):
    if isinstance(out, dict):
        return [out[k] for k in sorted(out)]
    if isinstance(out, tuple):
        return list(out)
    return [out]


def _as_sx(o, m):
    if isinstance(o, (ca.SX, ca.MX)):
        return o
    return ca.SX(ca.DM(np.broadcast_to(np.asarray(o, float), (m,)).reshape(m, 1)))


def conform(law, *args, h_rel: float = 1e-6, fd_tol: float = 1e-6):
    """``law(*args)`` (elementwise over (m,) inputs): CasADi value == numpy value, CasADi Jacobian == FD."""
    args = [np.asarray(x, dtype=float) for x in args]
    m = args[0].size
    xs = [ca.SX.sym(f"x{i}", m) for i in range(len(args))]
    outs = [_as_sx(o, m) for o in _outputs(law(*xs))]
    x_all = ca.vertcat(*xs)
    fun = ca.Function("law", xs, outs + [ca.jacobian(o, x_all) for o in outs])
    res = fun(*args)
    n = len(outs)
    expected = [np.broadcast_to(np.asarray(o, float), (m,)) for o in _outputs(law(*args))]
    assert len(expected) == n
    for k in range(n):
        got = np.asarray(res[k]).ravel()
        scale = max(np.abs(expected[k]).max(), 1e-300)
        np.testing.assert_allclose(got, expected[k], rtol=1e-12, atol=1e-12 * scale)
    # central finite differences of the numpy law, one input at a time (the laws are elementwise)
    for i, x in enumerate(args):
        h = h_rel * np.maximum(1.0, np.abs(x))
        up = [a.copy() for a in args]
        dn = [a.copy() for a in args]
        up[i] = x + h
        dn[i] = x - h
        f_up, f_dn = _outputs(law(*up)), _outputs(law(*dn))
        for k in range(n):
            jac = np.asarray(res[n + k])[:, i * m:(i + 1) * m]
            fd = np.diag((np.broadcast_to(f_up[k], (m,)) - np.broadcast_to(f_dn[k], (m,))) / (2.0 * h))
            scale = max(np.abs(fd).max(), np.abs(jac).max(), 1.0)
            np.testing.assert_allclose(jac, fd, rtol=fd_tol, atol=fd_tol * scale,
                                       err_msg=f"output {k}, input {i}")


def _rigid_point(model, rng):
    a = rng.uniform(0.05, 1.0, M)
    l_mt = model.l_slack + model.l_opt * rng.uniform(0.6, 1.3, M)
    v_mt = 10.0 * model.l_opt * rng.uniform(-0.3, 0.3, M)
    return a, l_mt, v_mt


def _tendon_point(model, rng):
    a = rng.uniform(0.05, 1.0, M)
    f_t = rng.uniform(0.05, 1.5, M)
    df_t = rng.uniform(-5.0, 5.0, M)
    l_mt = model.l_slack * 1.2 + model.l_opt * rng.uniform(0.6, 1.2, M)
    v_mt = 10.0 * model.l_opt * rng.uniform(-0.3, 0.3, M)
    return a, f_t, df_t, l_mt, v_mt


@pytest.mark.parametrize("name", sorted(MODELS))
def test_model_laws_conform(name):
    model = MODELS[name]
    rng = _rng(1)
    a, l_mt, v_mt = _rigid_point(model, rng)
    conform(model.rigid_force, a, l_mt, v_mt)
    conform(model.fiber_rigid, l_mt, v_mt)
    a, f_t, df_t, l_mt, v_mt = _tendon_point(model, rng)
    conform(model.fiber_from_tendon, f_t, df_t, l_mt, v_mt)
    conform(model.implicit_residual, a, f_t, df_t, l_mt, v_mt)
    l_ce = model.l_opt * rng.uniform(0.6, 1.4, M)
    v_ce = 10.0 * model.l_opt * rng.uniform(-0.3, 0.3, M)
    conform(model.fiber_forces, a, l_ce, v_ce)
    conform(lambda u, a: model.activation_rate(u, a, smooth=0.05), rng.uniform(0, 1, M), a)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_rigid_force_is_the_checked_force(name):
    model = MODELS[name]
    a, l_mt, v_mt = _rigid_point(model, _rng(2))
    np.testing.assert_array_equal(model.rigid_force(a, l_mt, v_mt), model.force(a, l_mt, v_mt, tendon="rigid"))
    l_ce, v_ce, _ = model.fiber_rigid(l_mt, v_mt)
    np.testing.assert_array_equal(np.stack([l_ce, v_ce]), np.stack(model.fiber_kinematics_rigid(l_mt, v_mt)))


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("moving", [False, True])
def test_implicit_residual_vanishes_at_equilibrium(name, moving):
    model = MODELS[name]
    rng = _rng(3)
    a = rng.uniform(0.2, 1.0, M)
    l_mt = model.l_slack * 1.02 + model.l_opt * rng.uniform(0.8, 1.1, M)
    v_mt = 10.0 * model.l_opt * rng.uniform(-0.05, 0.05, M) if moving else None
    eq = model.equilibrium(l_mt, a, v_mt, tol=1e-13)
    f_t = model.equilibrium_tendon_force(a, l_mt, v_mt, tol=1e-13)
    np.testing.assert_allclose(f_t * model.f_max, eq["force"], rtol=1e-15)
    lo, hi = model.tendon_force_bounds()
    assert np.all((lo < f_t) & (f_t < hi))
    if moving:
        # the tendon velocity the equilibrium implies, as a tendon-force rate
        x = np.sqrt(eq["l_ce"] ** 2 - model.height ** 2)
        v_t = v_mt - eq["v_ce"] * eq["l_ce"] / x
        df_t = model._tendon_curve(model._tendon_strain(f_t))[1] * v_t / model.l_slack
    else:
        v_mt, df_t = np.zeros(M), np.zeros(M)
    l_ce, v_ce, _ = model.fiber_from_tendon(f_t, df_t, l_mt, v_mt)
    np.testing.assert_allclose(l_ce, eq["l_ce"], rtol=1e-9)
    np.testing.assert_allclose(v_ce / model.l_opt, eq["v_ce"] / model.l_opt, atol=1e-9)
    np.testing.assert_allclose(model.implicit_residual(a, f_t, df_t, l_mt, v_mt), 0.0, atol=1e-9)


def test_activation_rate_conforms():
    rng = _rng(4)
    u, a = rng.uniform(0, 1, M), rng.uniform(0, 1, M)
    tau = dict(tau_rise=np.array([0.01, 0.015, 0.011, 0.02]), tau_fall=np.array([0.04, 0.06, 0.068, 0.05]))
    conform(lambda u, a: activation_rate(u, a, **tau), u, a)
    conform(lambda u, a: activation_rate(u, a, **tau, smooth=0.1), u, a)
    # the tanh blend tends to the exact law away from u = a, and keeps u = a a rest point
    np.testing.assert_allclose(activation_rate(u, a, smooth=1e-6), activation_rate(u, a), rtol=1e-12)
    assert np.all(activation_rate(u, u, smooth=0.1) == 0.0)


def _energy_point(rng):
    return dict(u=rng.uniform(0.05, 1.0, M), a=rng.uniform(0.05, 1.0, M),
                l_ce=L_OPT * rng.uniform(0.6, 1.6, M), v_ce=L_OPT * rng.uniform(-5.0, 5.0, M),
                f_ce=F_MAX * rng.uniform(0.0, 1.0, M), f_isom=rng.uniform(0.1, 1.0, M))


@pytest.mark.parametrize("smooth", [0.0, 0.01])
def test_metabolic_models_conform(smooth):
    rng = _rng(5)
    p = dict(l_opt=L_OPT, f_max=F_MAX, fast_fraction=np.array([0.3, 0.5, 0.6, 0.4]), smooth=smooth)
    x = _energy_point(rng)
    keys = ("u", "a", "l_ce", "v_ce", "f_ce", "f_isom")
    conform(lambda *v: energy.umberger2003(**dict(zip(keys, v)), **p), *(x[k] for k in keys))
    t_stim = rng.uniform(0.0, 0.5, M)
    conform(lambda *v: energy.bhargava2004(**dict(zip(keys, v[:-1])), t_stim=v[-1], **p),
            *(x[k] for k in keys), t_stim)


def test_smooth_helpers_conform():
    rng = _rng(6)
    w = 0.01
    conform(lambda x: energy.smooth_step(x, w), rng.uniform(-0.05, 0.05, M))
    conform(lambda x: energy.smooth_relu(x, w), rng.uniform(-0.05, 0.05, M))
    conform(lambda x: energy.smooth_clip(x, 0.0, 1.0, w), np.array([-0.2, 0.003, 0.5, 1.004]))
    conform(lambda x: energy.smooth_power(x, 0.6, w), np.array([-0.004, 0.003, 0.02, 0.5]))
    conform(lambda x: energy.smooth_relu(x, 0.0), np.array([-0.3, 0.2, 0.5, -1.0]))


def test_millard_refuses_the_generic_laws_by_name():
    model = Millard2012(f_max=1000.0, l_opt=0.1, l_slack=0.2)
    for call in (lambda: model.rigid_force(0.5, 0.3, 0.0), lambda: model.implicit_residual(0.5, 0.5, 0.0, 0.3, 0.0),
                 lambda: model.fiber_from_tendon(0.5, 0.0, 0.3, 0.0), lambda: model.fiber_forces(0.5, 0.1, 0.0),
                 model.tendon_force_bounds, lambda: model.equilibrium_tendon_force(0.5, 0.3)):
        with pytest.raises(ModelError, match="Millard2012.*DeGroote2016"):
            call()
    # its checked numpy force is unchanged
    assert np.isfinite(model.force(0.5, 0.3, 0.0))
