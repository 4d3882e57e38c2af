"""The optimal-control engine (pinmsk.solvers.ocp): the thesis problems, exact derivatives, the model's
components in the dynamics, formulations, constraints, convergence reporting, task files."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from conftest import REPO, LazyCasadi

ca = LazyCasadi()   # imported inside the tests (tests/conftest.py)

import pinmsk  # noqa: E402
from pinmsk.errors import ConvergenceError, ModelError  # noqa: E402
from pinmsk.solvers import ocp  # noqa: E402
from pinmsk.solvers.parametrization import Fourier, Polynomial  # noqa: E402

GOLDEN = json.loads((REPO / "tests" / "golden" / "replaced_engine_optima.json").read_text())
CYCLE = ocp.Target("cycle", amplitude=1.6, period=1.9, offset=0.3)
START = ocp.InitialState(q={"elbow_flexion": 0.3}, v={"elbow_flexion": 0.0})
OBJECTIVES = {"J1": lambda: ocp.Effort(2), "J2": lambda: ocp.Effort(3), "J3": lambda: ocp.Effort(2, weights="volume"),
              "J4": lambda: ocp.Effort(3, weights="volume")}


def _forearm(cost, *, model=None, controls=None, constraints=(), intervals=50, **kw):
    model = model or pinmsk.load_model("forearm", moment_arms="angle")
    return ocp.Collocation(model, cost=cost, constraints=[ocp.TrackingTolerance(CYCLE, 0.1), START, *constraints],
                           duration=1.9, intervals=intervals,
                           controls=controls if controls is not None else ocp.GlobalControls(Fourier(5, period=1.9)),
                           verbose=False, **kw)


def _finger(f, **kw):
    target = ocp.Target("sine", amplitude=0.21, frequency=f)
    return ocp.Collocation(pinmsk.load_model("finger"),
                           cost=0.1 * ocp.Effort(2, normalize=False) + 0.9 * ocp.TrackCoordinates(target),
                           constraints=[ocp.InitialState(q={"mcp_flexion": 0.0}, v={"mcp_flexion": float(target(0.0, 1))})],
                           duration=1.0 / f, intervals=50,
                           controls=ocp.GlobalControls(Polynomial(6, duration=1.0 / f)), verbose=False, **kw)


# -- the thesis problems give the replaced engine's optima (J within 1 %) -------------------------------
@pytest.mark.parametrize("name", sorted(OBJECTIVES))
def test_forearm_effort_optima_match_the_replaced_engine(name):
    """Sec. 3.3.2, J1-J4 with 11-term Fourier series: the SLSQP single-shooting engine's optima
    (RK4, 100 steps, recorded at commit 806da15) within 1 % -- in fact within 0.01 %."""
    r = _forearm(OBJECTIVES[name]()).fit().result_
    assert r.converged, r.status
    ref = GOLDEN["forearm"][f"{name}_fourier"]["J"]
    assert r.objective == pytest.approx(ref, rel=0.01)
    assert r.objective == pytest.approx(ref, rel=2e-4)
    assert r.max_tracking_error <= 0.1 + 1e-6          # Eq. 3.7 holds on the whole grid


def test_forearm_polynomial_j1_matches_the_replaced_engine():
    r = _forearm(OBJECTIVES["J1"](), controls=ocp.GlobalControls(Polynomial(10, duration=1.9))).fit().result_
    assert r.converged, r.status
    assert r.objective == pytest.approx(GOLDEN["forearm"]["J1_polynomial"]["J"], rel=0.01)


@pytest.mark.slow   # ~20 s (190 IPOPT iterations); the default suite covers the metabolic cost in test_metabolic_rate_is_the_umberger_model
def test_forearm_metabolic_optimum_matches_the_replaced_engine():
    """J5 (Umberger 2003): the same mean metabolic power as the replaced engine (its J times its
    normalizer), within 1 %; the optimizer sees the C1-smoothed heat rates in both."""
    r = _forearm(ocp.MetabolicEnergy("umberger2003")).fit().result_
    ref = GOLDEN["forearm"]["J5_fourier"]
    assert r.converged, r.status
    assert r.objective == pytest.approx(ref["J"] * ref["terms"]["E_norm"], rel=0.01)


@pytest.mark.parametrize("f", [2, 4, 5, 6, 7])
def test_finger_tapping_optima_are_the_replaced_engines_or_lower(f):
    """Sec. 3.2.2 with 6th-order polynomial excitations, J = 0.1 J1 + 0.9 J2 (Eq. 3.3).  The same
    problem, solved to IPOPT's tolerance: never above the replaced SLSQP engine's optimum, and below it
    where SLSQP stopped early (its ``ftol`` 1e-6 stop; 2 Hz: 10 % lower, 4-7 Hz: 1-3 %)."""
    r = _finger(f).fit().result_
    assert r.converged, r.status
    ref = GOLDEN["finger"][str(f)]
    assert r.objective <= ref["J"] * 1.001
    assert r.objective >= ref["J"] * 0.85


# -- exact derivatives ---------------------------------------------------------------------------
def _check_derivatives(fit, seed=0):
    fit._setup()
    t = fit._frac * fit._T0
    nlp = fit._build(fit._guess_from_trial(fit.guess, t) if fit.guess is not None else fit._auto_guess(t, 0))
    w, g, J = nlp["w"], nlp["g"], nlp["J"]
    rng = np.random.default_rng(seed)
    lo, hi = nlp["lbx"] + 1e-3, nlp["ubx"] - 1e-3     # a random point inside the bounds (the laws' domain)
    x = np.clip(nlp["w0"] + 0.05 * rng.standard_normal(nlp["w0"].size), lo, hi)
    lam = rng.standard_normal(g.numel())
    lf, lg = ca.MX.sym("lf"), ca.MX.sym("lg", g.numel())
    J_ref = ca.Function("j", [w], [ca.jacobian(g, w)])(x)
    H_ref = ca.Function("h", [w, lf, lg], [ca.triu(ca.hessian(lf * J + ca.dot(lg, g), w)[0])])(x, 0.7, lam)
    g_a, J_a = nlp["jac_g"](x, [])
    H_a = nlp["hess_lag"](x, [], 0.7, lam)
    g_ref = ca.Function("g", [w], [g])(x)
    assert float(ca.norm_inf(g_a - g_ref)) == 0.0
    assert float(ca.norm_inf(ca.densify(J_a) - ca.densify(J_ref))) <= 1e-10 * (1 + float(ca.norm_inf(J_ref)))
    assert float(ca.norm_inf(ca.densify(H_a) - ca.densify(H_ref))) <= 1e-10 * (1 + float(ca.norm_inf(H_ref)))
    # and the gradient of the whole Lagrangian against central differences of g and f
    fg = ca.Function("fg", [w], [J, g])
    d = rng.standard_normal(x.size) * 1e-6
    fp, gp = fg(x + d)
    fm, gm = fg(x - d)
    dg = np.asarray(gp - gm).ravel() / 2
    assert np.allclose(np.asarray(ca.mtimes(J_a, ca.DM(d))).ravel(), dg, atol=1e-7 * (1 + np.abs(dg).max()))


def test_assembled_derivatives_are_casadis_own_hermite_simpson_global_free_period():
    fit = _forearm(ocp.Effort(3, weights="volume") + 0.5 * ocp.TrackCoordinates(CYCLE), intervals=5,
                   controls=ocp.GlobalControls(Fourier(2, period=1.9), free_period=True))
    _check_derivatives(fit)


def test_assembled_derivatives_are_casadis_own_trapezoidal_compliant_free_time_metabolic():
    model = pinmsk.load_model("forearm", moment_arms="angle")
    fit = ocp.Collocation(model, cost=ocp.MetabolicEnergy() + ocp.Smoothness("df_t", scale=10.0),
                          constraints=[ocp.CoordinateBounds("elbow_flexion", 0.2, 2.0), START,
                                       ocp.FinalState(q={"elbow_flexion": 1.5})],
                          duration=(0.5, 1.5), intervals=6, scheme="trapezoidal", tendon="compliant", verbose=False)
    _check_derivatives(fit, seed=1)


def test_assembled_derivatives_with_effects_contacts_and_a_floating_base():
    """gait2d with its passive moments (Eq. 5.11), foot contact spheres and the planar floating base."""
    model = pinmsk.load_model("gait2d")
    t = np.linspace(0, 0.5, 11)
    standing = pinmsk.Trial(t, {"torso_y": np.full(t.size, 0.95), "hip_r": 0.2 * np.sin(2 * np.pi * t)})
    fit = ocp.Collocation(model, cost=ocp.Effort(2) + ocp.Smoothness("qdd", scale=100.0),
                          constraints=[ocp.Periodic(exclude=("torso_x",))], duration=0.5, intervals=3,
                          scheme="trapezoidal", guess=standing, verbose=False)
    _check_derivatives(fit, seed=2)


# -- the dynamics are the model's (round trips through numpy analyses) ----------------------------
def test_collocated_motion_is_a_forward_simulation_of_its_excitations():
    """The optimum's excitations (a Fourier series, exact in t) integrated forward with scipy's RK45,
    numpy muscle laws and ``pin.aba``, reproduce the collocated motion (Hermite-Simpson, 50 intervals)."""
    from scipy.integrate import solve_ivp
    from pinmsk.muscles.activation import activation_rate
    model = pinmsk.load_model("forearm", moment_arms="angle")
    r = _forearm(ocp.Effort(3, weights="volume"), model=model).fit().result_
    par, P = r.parametrization, r.coeffs
    ms, mtu = model.muscles, model.muscles.mtu
    data = model.pin.createData()

    def rhs(t, y):
        q, v, a = y[:1], y[1:2], y[2:]
        e = (par.basis(np.array([t])) @ P)[0]
        F = mtu.rigid_force(a, ms.lengths(q[None])[0], ms.velocities(q[None], v[None])[0])
        tau = ms.moment_arms(q[None])[0].T @ F
        qdd = pin.aba(model.pin, data, q, v, tau)
        return np.concatenate([v, qdd, activation_rate(e, a, tau_rise=mtu.tau_rise, tau_fall=mtu.tau_fall)])

    a0 = (par.basis(np.array([0.0])) @ P)[0]
    sol = solve_ivp(rhs, (0.0, 1.9), np.concatenate([[0.3, 0.0], a0]), t_eval=r.time, rtol=1e-9, atol=1e-10)
    assert sol.success
    err = np.max(np.abs(sol.y[0] - r["elbow_flexion"]))
    assert err < 2e-3, err
    assert np.max(np.abs(sol.y[2:].T - np.column_stack([r[f"{n}_activation"] for n in ms.names]))) < 2e-3


def test_effects_enter_the_skeleton_dynamics():
    """A joint-damping effect of the model is in the optimizer's dynamics: at every point of the result
    ``rnea(q, v, qdd) = R^T F + Q_damping`` (numpy analyses' own code), and the optimum differs."""
    from pinmsk import effects
    base = pinmsk.load_model("forearm", moment_arms="angle")
    model = base + effects.JointDamping("elbow_flexion", c=0.5)
    r = _forearm(ocp.Effort(2), model=model, controls=ocp.NodeControls(), intervals=20).fit().result_
    assert r.converged, r.status
    q, v, a = (np.asarray(r[c])[:, None] for c in ("elbow_flexion", "elbow_flexion_speed", "elbow_flexion_acceleration"))
    F = np.column_stack([r[f"{n}_force"] for n in model.muscle_names])
    tau = np.array([pin.rnea(model.pin, model.pin.createData(), q[k], v[k], a[k]) for k in range(q.shape[0])])
    from pinmsk.components import Motion
    mo = Motion(t=np.asarray(r.time), q=q, v=v, a=a)
    Q = sum(c.generalized_force(model, mo) for c in model.effects)
    resid = tau - model.muscles.joint_moments(q, F) - Q
    assert np.max(np.abs(resid)) < 1e-6
    r0 = _forearm(ocp.Effort(2), model=base, controls=ocp.NodeControls(), intervals=20).fit().result_
    assert abs(r.objective / r0.objective - 1) > 0.01


def test_formulations_have_one_optimum_with_node_controls():
    """FF, IFM and IFT (Sec. 5.1) tie the same variables by equalities: with node-wise controls the
    three have the same optimum."""
    Js = {}
    for form in ("ff", "ifm", "ift"):
        r = _forearm(ocp.Effort(2), controls=ocp.NodeControls(), intervals=15, formulation=form).fit().result_
        assert r.converged, (form, r.status)
        Js[form] = r.objective
    assert Js["ifm"] == pytest.approx(Js["ff"], rel=1e-5)
    assert Js["ift"] == pytest.approx(Js["ff"], rel=1e-5)


def test_electromechanical_delay_shifts_the_excitation():
    """With an electromechanical delay of 40 ms in the model, activation follows the excitation 40 ms
    earlier: integrating Eq. A.2 with u(t - d) reproduces the result's activations."""
    from pinmsk.effects import ElectromechanicalDelay
    from pinmsk.muscles.activation import activation_from_excitation
    model = pinmsk.load_model("forearm", moment_arms="angle") + ElectromechanicalDelay("muscles", delay=0.04)
    # 30 intervals: 18 iterations, 0.5 s (50: 91 iterations, 7 s, the same agreement to 5e-5 / 1.7e-4)
    r = _forearm(ocp.Effort(3, weights="volume"), model=model, intervals=30).fit().result_
    assert r.converged, r.status
    t = np.asarray(r.time)
    tf = np.linspace(0, 1.9, 3801)
    par, P = r.parametrization, r.coeffs
    u = par.basis(np.maximum(tf - 0.04, 0.0)) @ P
    mtu = model.muscles.mtu
    a0 = np.array([r[f"{n}_activation"][0] for n in model.muscle_names])
    a = activation_from_excitation(tf, u, a0, tau_rise=mtu.tau_rise, tau_fall=mtu.tau_fall)
    for i, n in enumerate(model.muscle_names):
        assert np.max(np.abs(np.interp(t, tf, a[:, i]) - r[f"{n}_activation"])) < 1e-3


# -- problem features ---------------------------------------------------------------------------
def test_periodicity_holds_at_the_solution():
    r = _forearm(ocp.Effort(3, weights="volume"), constraints=[ocp.Periodic(("q", "v", "a"))], intervals=30).fit().result_
    assert r.converged, r.status
    for ch in ["elbow_flexion", "elbow_flexion_speed"] + [f"{n}_activation" for n in r.muscles]:
        assert r[ch][-1] == pytest.approx(r[ch][0], abs=1e-7)


def test_free_final_time_is_optimal_within_its_bounds():
    """Reach 1.5 rad from rest at 0.3 rad, trading mean effort against duration (``FinalTime``), the
    duration free in [0.3, 3] s: it ends inside its bounds, and fixing it 10 % away on either side gives a
    higher cost."""
    model = pinmsk.load_model("forearm", moment_arms="angle")

    def solve(duration):
        return ocp.Collocation(model, cost=ocp.Effort(2) + 1e-3 * ocp.FinalTime(),
                               constraints=[START, ocp.FinalState(q={"elbow_flexion": 1.5}, v={"elbow_flexion": 0.0})],
                               duration=duration, intervals=20, verbose=False).fit().result_
    r = solve((0.3, 3.0))
    assert r.converged, r.status
    T = r.horizon
    assert 0.35 < T < 2.9
    assert r.terms["final_time"] == pytest.approx(T)
    for s_ in (0.9, 1.1):
        other = solve(T * s_)
        assert other.converged and other.objective > r.objective


def test_hermite_simpson_is_more_accurate_than_trapezoidal():
    """Finger tapping at 4 Hz: the error of J against a 160-interval Hermite-Simpson reference falls like
    h^2 with the trapezoidal rule (20 -> 40 intervals: 4.5x), and Hermite-Simpson with 20 intervals is
    more accurate than the trapezoidal rule with 40 (6e-7 against 5e-6)."""
    def J(n, scheme):
        fit = _finger(4)
        fit.intervals, fit.scheme = n, scheme
        return fit.fit().result_.objective
    ref = J(160, "hermite-simpson")
    trap = [abs(J(n, "trapezoidal") - ref) for n in (20, 40)]
    hs = abs(J(20, "hermite-simpson") - ref)
    assert trap[0] / trap[1] > 3.0
    assert hs < trap[1]


# -- convergence and bad input --------------------------------------------------------------------
def test_infeasible_problem_names_the_violated_constraint():
    """Muscles capped at 1 % excitation cannot hold the forearm on its path: IPOPT stops, the result is
    flagged, and the status names the most violated constraint, where and by how much."""
    r = _forearm(ocp.Effort(2), constraints=[ocp.ExcitationBounds(0.0, 0.01)], intervals=10,
                 solver={"max_iter": 200}).fit().result_
    assert not r.converged
    assert "largest violation:" in r.status and " by " in r.status
    assert any(k in r.status for k in ("skeleton dynamics", "tracking error", "collocation defect", "initial"))
    assert "NOT CONVERGED" in r.report()


def test_unconverged_task_writes_nothing_and_exits_2(tmp_path):
    task = tmp_path / "bad.toml"
    task.write_text((REPO / "data/tasks/finger_tapping_6hz.toml").read_text()
                    .replace("n_starts = 2", "n_starts = 1\nmaxiter = 3"))
    from pinmsk.presentation.cli import main
    out = tmp_path / "out.sto"
    assert main(["optimize", str(task), "-o", str(out)]) == 2
    assert not out.exists() and not (tmp_path / "out.sto.json").exists()
    from pinmsk.pipeline import optimize_task
    with pytest.raises(ConvergenceError, match="did not converge"):
        optimize_task(task, out)


@pytest.mark.parametrize("kw, match", [
    (dict(scheme="euler"), "unknown scheme"), (dict(intervals=1), "intervals must be"),
    (dict(duration=-1.0), "duration must be > 0"), (dict(duration=(2.0, 1.0)), "free final time bounds"),
    (dict(solver={"tolerance": 1}), "unknown solver setting"), (dict(formulation="x"), "unknown formulation"),
    (dict(n_starts=0), "n_starts must be"), (dict(cost="effort"), "cost must be a Cost"),
    (dict(n_starts=2, guess=pinmsk.Trial(np.linspace(0, 1, 5), {"mcp_flexion": np.zeros(5)})), "with a guess given"),
    (dict(cost=ocp.TrackSignals("emg", [0], [0.0, 1.0], [[0.0], [1.0]])), "unknown quantity 'emg'"),
])
def test_bad_problem_arguments_are_named(kw, match):
    args = dict(cost=ocp.Effort(2), duration=1.0, intervals=5)
    args.update(kw)
    with pytest.raises(ModelError, match=match):
        ocp.Collocation(pinmsk.load_model("finger"), verbose=False, **args).fit()


def test_cost_terms_compose_and_need_distinct_names():
    c = 0.1 * ocp.Effort(2) + 0.9 * ocp.TrackCoordinates(CYCLE)
    assert [t.name for t in c.terms()] == ["effort", "tracking"]
    assert [t.weight for t in (2 * c).terms()] == pytest.approx([0.2, 1.8])
    with pytest.raises(ModelError, match="distinct names"):
        ocp.Effort(2) + ocp.Effort(3)
    with pytest.raises(ModelError, match="weight must be"):
        ocp.Effort(2, weight=-1)


# -- task files ------------------------------------------------------------------------------------
def test_finger_task_file_runs_and_writes_its_contract(tmp_path):
    from pinmsk.pipeline import optimize_task
    out = tmp_path / "finger.sto"
    res = optimize_task(REPO / "data/tasks/finger_tapping_6hz.toml", out)
    summary = json.loads((tmp_path / "finger.sto.json").read_text())
    for key in ("converged", "status", "objective", "seconds"):
        assert key in summary
    assert summary["converged"] is True and summary["objective"] == pytest.approx(res.objective)
    assert summary["objective"] == pytest.approx(GOLDEN["finger"]["6"]["J"], rel=0.03)
    assert pinmsk.read_trial(out)["mcp_flexion"].size == res.time.size


@pytest.mark.parametrize("task", sorted(p.name for p in (REPO / "data/tasks").glob("*.toml")))
def test_every_shipped_task_file_builds(task):
    from pinmsk.io.shared_data import shared_data_dir
    from pinmsk.solvers.ocp.tasks import build_from_task, load_task
    text = (REPO / "data/tasks" / task).read_text()
    if shared_data_dir() is None and re.search(r"""["'](real|opensim-models|osim-zoo)/""", text):
        pytest.skip(f"{task} reads measured data from ../shared/data, which is absent")
    fit = build_from_task(load_task(REPO / "data/tasks" / task), base_dir=REPO / "data/tasks")
    assert isinstance(fit, ocp.Collocation)


def test_unknown_task_keys_are_rejected_by_name(tmp_path):
    from pinmsk.solvers.ocp.tasks import load_task
    task = tmp_path / "t.toml"
    task.write_text((REPO / "data/tasks/finger_tapping_6hz.toml").read_text().replace("n_starts = 2", "n_strats = 2"))
    with pytest.raises(ModelError, match="n_strats"):
        load_task(task)


def test_metabolic_rate_is_the_umberger_model():
    """The metabolic cost's per-muscle rate at the solution is pinmsk.energy.umberger2003 (numpy) on the
    result's own fiber states: the optimizer's heat rates are the analyses' heat rates."""
    from pinmsk import energy
    model = pinmsk.load_model("forearm", moment_arms="angle")
    r = _forearm(ocp.MetabolicEnergy(smooth=0.01), model=model, controls=ocp.NodeControls(), intervals=10,
                 solver={"max_iter": 300}).fit().result_
    ms, mtu = model.muscles, model.muscles.mtu
    q = np.asarray(r["elbow_flexion"])[:, None]
    v = np.asarray(r["elbow_flexion_speed"])[:, None]
    a = np.column_stack([r[f"{n}_activation"] for n in ms.names])
    u = np.column_stack([r[f"{n}_excitation"] for n in ms.names])
    l_ce, v_ce, _ = mtu.fiber_rigid(ms.lengths(q), ms.velocities(q, v))
    ff = mtu.fiber_forces(a, l_ce, v_ce)
    w = 0.01
    E = energy.umberger2003(u=energy.smooth_clip(u, 0, 1, w), a=energy.smooth_clip(a, 0, 1, w), l_ce=l_ce, v_ce=v_ce,
                            f_ce=ff["f_active"], f_isom=ff["f_isom"], l_opt=mtu.l_opt, f_max=mtu.f_max,
                            fast_fraction=ms.fast_fraction, smooth=w)["total"]
    got = np.column_stack([r[f"{n}_metabolic_rate"] for n in ms.names])
    assert np.allclose(got, E, rtol=1e-9, atol=1e-9)
    Et = E.sum(axis=1)          # nodes and midpoints alternate on the result's grid: Simpson's rule
    T = float(r.time[-1])
    assert r.objective == pytest.approx(float(np.sum(Et[:-1:2] + 4 * Et[1::2] + Et[2::2])) / 6 * (T / 10) / T, rel=1e-9)


def test_coordinate_actuators_are_controls_that_enter_the_dynamics():
    """A reserve actuator on the elbow (CoordinateActuator, 10 N m, controls in [-1, 1]) makes the
    too-weak problem of test_infeasible_problem_names_the_violated_constraint feasible: at every point
    ``rnea = R^T F + 10 u`` (numpy's own code), and the controls stay in their bounds."""
    from pinmsk.actuators import CoordinateActuator
    model = pinmsk.load_model("forearm", moment_arms="angle") + CoordinateActuator(
        "elbow_reserve", "elbow_flexion", optimal_force=10.0, min_control=-1.0, max_control=1.0)
    r = _forearm(ocp.Effort(2) + 10.0 * ocp.ActuatorEffort(), model=model, controls=ocp.NodeControls(),
                 constraints=[ocp.ExcitationBounds(0.0, 0.01)], intervals=10).fit().result_
    assert r.converged, r.status
    u = np.asarray(r["elbow_reserve_control"])
    assert np.all(np.abs(u) <= 1.0 + 1e-9) and np.max(np.abs(u)) > 0.05
    q, v, a = (np.asarray(r[c])[:, None] for c in ("elbow_flexion", "elbow_flexion_speed", "elbow_flexion_acceleration"))
    F = np.column_stack([r[f"{n}_force"] for n in model.muscle_names])
    tau = np.array([pin.rnea(model.pin, model.pin.createData(), q[k], v[k], a[k]) for k in range(q.shape[0])])
    assert np.max(np.abs(tau[:, 0] - model.muscles.joint_moments(q, F)[:, 0] - 10.0 * u)) < 1e-6
    with pytest.raises(ModelError, match="has no actuators"):
        _forearm(ocp.ActuatorEffort(), intervals=5).fit()
