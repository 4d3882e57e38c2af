"""The forces between two frames (bushings, springs) imported from OpenSim, on the optimal-control
engine's CasADi skeleton: the same numbers as the batched numpy law, and CasADi Jacobians equal to
finite differences of it.  Apart from tests/test_osim_forces.py because casadi and opensim cannot
share a process (tests/conftest.py); the states are that module's stored ones.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from pinmsk.components import Motion
from pinmsk.model import import_osim
from pinmsk.opensim.contacts import contact_hook
from pinmsk.opensim.forces import force_hook

from conftest import require_casadi, shared_folder
from test_osim_forces import _motion, cases


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    d = shared_folder("osim-zoo", "zoo_models.tar.xz")
    paths = cases.extract(d / "zoo_models.tar.xz", ["ToyLanding", "BouncingBlock"], tmp_path_factory.mktemp("zoo"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {n: import_osim(p, hooks=(force_hook, contact_hook)) for n, p in paths.items()}


def test_pair_forces_on_the_optimal_control_skeleton(imported):
    """The bushing and the spring at one state on the optimal-control engine's CasADi skeleton: the
    batched numpy values, and a CasADi Jacobian equal to finite differences of the numpy law."""
    ca = require_casadi()
    from pinmsk.solvers.ocp.skeleton import SymbolicSkeleton
    for name, label in (("ToyLanding", "bushing:tibia_r_offset"), ("BouncingBlock", "point_to_point_spring:block"),
                        ("BouncingBlock", "bushing:block")):
        model, _ = imported[name]
        mo, *_ = _motion(model, name)
        comp = model.component(label)
        sk = SymbolicSkeleton(model)
        qs, vs = ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nv)
        Q = comp.generalized_force_on(sk, qs, vs)
        F = ca.Function("Q", [qs, vs], [Q, ca.jacobian(Q, ca.vertcat(qs, vs))])
        k = 5
        val, jac = (np.array(ca.DM(x), dtype=float) for x in F(mo.q[k], mo.v[k]))
        np.testing.assert_allclose(val[:, 0], comp.generalized_force(model, mo)[k], rtol=1e-9, atol=1e-9)
        x0, h, cols = np.concatenate([mo.q[k], mo.v[k]]), 1e-6, []
        for j in range(x0.size):
            e = np.zeros_like(x0)
            e[j] = h
            f = [comp.generalized_force(model, Motion(np.zeros(1), (x0 + s * e)[None, :model.nq],
                                                      (x0 + s * e)[None, model.nq:], np.zeros((1, model.nv))))[0]
                 for s in (1, -1)]
            cols.append((f[0] - f[1]) / (2 * h))
        np.testing.assert_allclose(jac, np.stack(cols, axis=1), rtol=1e-5, atol=1e-5 * max(1.0, np.abs(val).max()))


def test_expression_force_at_one_state_on_casadi():
    """OpenSim's ExpressionBasedCoordinateForce as CasADi at one state: the numpy value, and CasADi's
    derivatives equal to the exact (forward-mode) state derivatives of the batched law."""
    ca = require_casadi()
    from pinmsk import load_model
    from pinmsk.effects import CoordinateExpressionForce
    model = load_model("forearm")
    c = model.coordinates[-1]
    eff = CoordinateExpressionForce(c, expression=cases.DERIVED["WalkerExpression"][1].split("<expression>")[1]
                                    .split("</expression>")[0], scale=1.5)
    qs, vs = ca.SX.sym("q", model.nv), ca.SX.sym("v", model.nv)
    Q = eff.generalized_force_at(model, qs, vs)
    F = ca.Function("Q", [qs, vs], [Q, ca.jacobian(Q, qs), ca.jacobian(Q, vs)])
    q, v = np.full(model.nv, 0.4), np.full(model.nv, -0.7)
    mo = Motion(np.zeros(1), q[None], v[None], np.zeros((1, model.nv)))
    val, dq, dv = (np.array(ca.DM(x), dtype=float) for x in F(q, v))
    i = model.coordinate_index(c)
    np.testing.assert_allclose(val[:, 0], eff.generalized_force(model, mo)[0], rtol=1e-12)
    a, b = eff.state_derivatives(model, mo)
    np.testing.assert_allclose(dq[i, i], a[0, i, i], rtol=1e-12)
    np.testing.assert_allclose(dv[i, i], b[0, i, i], rtol=1e-12)
