"""OpenSim Moco's goals on the optimal-control engine (pinmsk.solvers.ocp.costs: ControlEffort,
StateTracking, ContactTracking): each term's value at a collocated motion equals an independent numpy
evaluation of Moco's definition (opensim-core MocoControlGoal.cpp, MocoStateTrackingGoal.cpp,
MocoContactTrackingGoal.cpp, MocoGoal::calcGoal) on the same motion, integrated by the same rule."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import LazyCasadi

ca = LazyCasadi()   # imported inside the tests (tests/conftest.py)

import pinmsk  # noqa: E402
from pinmsk.actuators import CoordinateActuator  # noqa: E402
from pinmsk.errors import ModelError  # noqa: E402
from pinmsk.solvers import ocp  # noqa: E402
from pinmsk.solvers.ocp import gait  # noqa: E402

T, N = 0.4, 4
W = 2 * np.pi / T


def _model():
    return gait.gait_model("gait2d", contact="smooth_sphere") + CoordinateActuator(
        "trunk_reserve", "hip_r", optimal_force=10.0, min_control=-1.0, max_control=1.0)


def _ref_q(t):          # analytical references: the spline must reproduce them
    return {"hip_r": 0.2 * np.sin(W * t), "knee_r": -0.3 + 0.1 * np.cos(W * t)}


def _ref_v(t):
    return {"hip_r": 0.2 * W * np.cos(W * t), "knee_r": -0.1 * W * np.sin(W * t)}


def _ref_f(t):
    return {"right": np.column_stack([50 * np.sin(W * t), 600 * np.sin(np.pi * t / T) ** 2, 5 + 0 * t]),
            "left": np.column_stack([-20 * np.cos(W * t), 300 + 100 * np.cos(W * t), 0 * t])}


GROUPS = {"right": ("heel_r", "metatarsal_r", "toe_r"), "left": ("heel_l", "metatarsal_l", "toe_l")}


@pytest.fixture(scope="module")
def solved():
    """A 4-interval trapezoidal half cycle whose objective holds every Moco goal, evaluated at its start
    (IPOPT with 0 iterations and no bound push: the guess's motion, with every term's integral
    variable consistent with it; the definitions, not an optimum, are under test)."""
    model = _model()
    ts = np.linspace(0, T, 81)
    q, fr = _ref_q(ts), _ref_f(ts)
    cost = (2.0 * ocp.ControlEffort(3, per="distance", weights={"glutei_r": 2.0, "trunk_reserve": 0.5})
            + ocp.ControlEffort(2, per="time", name="effort_time")
            + ocp.ControlEffort(2, name="effort_plain")
            + ocp.StateTracking(ts, q, position_derivatives=True, weights={"knee_r_speed": 0.3})
            + ocp.StateTracking(ts, q, scale_weights_with_range=True, name="range_tracking")
            + 3.0 * ocp.ContactTracking({g: (GROUPS[g], fr[g]) for g in GROUPS}, ts, projection="plane",
                                        vector=(0, 0, 1))
            + ocp.ContactTracking({g: (GROUPS[g], fr[g]) for g in GROUPS}, ts, projection="vector",
                                  vector=(0, 2, 0), normalize_tracking_error=False, name="vertical")
            + ocp.ContactTracking({"right": (GROUPS["right"], fr["right"])}, ts, normalize_tracking_error=True,
                                  name="normalized"))
    tg = np.linspace(0, T, 11)
    guess = pinmsk.Trial(tg, {"torso_x": 1.2 * tg, "torso_y": np.full(tg.size, 0.93), **_ref_q(tg)})
    fit = ocp.Collocation(model, cost=cost, duration=T, intervals=N, scheme="trapezoidal", guess=guess,
                          solver={"max_iter": 0, "bound_push": 1e-12, "hessian": "limited-memory"}, verbose=False).fit()
    return model, fit.result_


def _trapz(y, t):
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def test_control_effort_is_mocos_integral_over_all_controls(solved):
    model, r = solved
    t = np.asarray(r.time)
    e = np.column_stack([r[f"{m}_excitation"] for m in model.muscle_names])
    u = np.asarray(r["trunk_reserve_control"])
    w = np.array([2.0 if m == "glutei_r" else 1.0 for m in model.muscle_names])
    cube = _trapz(np.abs(e) ** 3 @ w + 0.5 * np.abs(u) ** 3, t)
    d = float(r["torso_x"][-1] - r["torso_x"][0])
    assert abs(d) > 0.1
    assert r.terms["control_effort"] == pytest.approx(cube / d, rel=1e-9)
    square = _trapz(np.sum(e ** 2, axis=1) + u ** 2, t)
    assert r.terms["effort_plain"] == pytest.approx(square, rel=1e-9)          # no 1/T: Moco's default
    assert r.terms["effort_time"] == pytest.approx(square / T, rel=1e-9)


def test_state_tracking_is_mocos_weighted_squared_error_of_values_and_speeds(solved):
    model, r = solved
    t = np.asarray(r.time)
    qd, vd = _ref_q(t), _ref_v(t)
    err = sum((np.asarray(r[c]) - qd[c]) ** 2 for c in qd)
    err = err + (np.asarray(r["hip_r_speed"]) - vd["hip_r"]) ** 2
    err = err + 0.3 * (np.asarray(r["knee_r_speed"]) - vd["knee_r"]) ** 2
    assert r.terms["state_tracking"] == pytest.approx(_trapz(err, t), rel=1e-6)
    rng = {"hip_r": 0.4, "knee_r": 0.2}            # max - min of the analytical references
    err = sum((np.asarray(r[c]) - qd[c]) ** 2 / rng[c] for c in qd)
    assert r.terms["range_tracking"] == pytest.approx(_trapz(err, t), rel=1e-5)


def test_contact_tracking_is_mocos_projected_error_over_body_weight(solved):
    model, r = solved
    t = np.asarray(r.time)
    fr = _ref_f(t)
    mg = sum(I.mass for I in model.pin.inertias) * 9.81
    F = {g: sum(np.column_stack([r[f"smooth_sphere_half_space:{c}_force_{a}"] for a in "xyz"]) for c in GROUPS[g])
         for g in GROUPS}
    assert np.max(F["right"][:, 1]) > 1.0                       # the feet are loaded: a real test
    plane = sum(np.sum((F[g] - fr[g])[:, :2] ** 2, axis=1) for g in GROUPS)
    assert r.terms["contact_tracking"] == pytest.approx(_trapz(plane, t) / mg, rel=1e-6)
    vert = sum((F[g] - fr[g])[:, 1] ** 2 for g in GROUPS)
    assert r.terms["vertical"] == pytest.approx(_trapz(vert, t) / mg, rel=1e-6)
    peak = np.array([50.0, 600.0, 5.0])
    norm = np.sum(((F["right"] - fr["right"]) / peak) ** 2, axis=1)
    assert r.terms["normalized"] == pytest.approx(_trapz(norm, t) / mg, rel=1e-4)
    w = {"control_effort": 2.0, "contact_tracking": 3.0}
    assert r.objective == pytest.approx(sum(w.get(k, 1.0) * v for k, v in r.terms.items()), rel=1e-9)


def test_state_tracking_lowpass_keeps_slow_motion_and_removes_fast():
    t = np.linspace(0, 1, 201)
    slow, fast = 0.3 * np.sin(2 * np.pi * t), 0.05 * np.sin(2 * np.pi * 40 * t)
    st = ocp.StateTracking(t, {"hip_r": slow + fast}, lowpass=6.0, position_derivatives=True)
    ref = st.reference(t[20:-20])
    assert np.max(np.abs(ref["hip_r"] - slow[20:-20])) < 3e-3
    assert np.max(np.abs(ref["hip_r_speed"] - 0.6 * np.pi * np.cos(2 * np.pi * t[20:-20]))) < 0.05


@pytest.mark.parametrize("make, match", [
    (lambda: ocp.ControlEffort(1), "integer >= 2"),
    (lambda: ocp.ControlEffort(2.5), "integer >= 2"),
    (lambda: ocp.ControlEffort(2, per="mass"), "per must be"),
    (lambda: ocp.StateTracking([0, 1, 2], {"hip_r": [0, 1, 2]}), ">= 6 samples"),
    (lambda: ocp.StateTracking(np.arange(8.0), {"hip_r": np.zeros(7)}), "reference 'hip_r' needs 8"),
    (lambda: ocp.ContactTracking({"r": (("heel_r",), np.zeros((8, 3)))}, np.arange(8.0), projection="plane"),
     "needs its vector"),
    (lambda: ocp.ContactTracking({"r": (("heel_r",), np.zeros((8, 2)))}, np.arange(8.0)), r"shape \(8, 3\)"),
    (lambda: ocp.ContactTracking({"r": (("heel_r",), np.ones((8, 3)))}, np.arange(8.0), projection="cone",
                                 vector=(0, 0, 1)), "projection must be"),
    (lambda: ocp.ContactTracking({"r": (("heel_r",), np.zeros((8, 3)))}, np.arange(8.0),
                                 normalize_tracking_error=True), "zero along x"),
])
def test_bad_goal_arguments_are_named(make, match):
    with pytest.raises(ModelError, match=match):
        make()


@pytest.mark.parametrize("cost, match", [
    (lambda: ocp.ControlEffort(2, weights={"nope": 1.0}), "weights name no control of the model: nope"),
    (lambda: ocp.StateTracking(np.linspace(0, T, 9), {"nope": np.zeros(9)}), "nope"),
    (lambda: ocp.StateTracking(np.linspace(0, T, 9), {"hip_r": np.zeros(9)}, weights={"hip_l": 2.0}),
     "no tracked state: hip_l"),
    (lambda: ocp.ContactTracking({"r": (("heel_x",), np.ones((9, 3)))}, np.linspace(0, T, 9)),
     "unknown contacts heel_x"),
])
def test_goals_refuse_names_the_model_lacks(cost, match):
    with pytest.raises(ModelError, match=match):
        ocp.Collocation(_model(), cost=cost(), duration=T, intervals=N, scheme="trapezoidal", verbose=False).fit()
