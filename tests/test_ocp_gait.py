"""Gait on the optimal-control engine (pinmsk.solvers.ocp.gait, thesis Ch. 5): one stride from a half
cycle, variable bounds, the gait task files."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import REPO, LazyCasadi

ca = LazyCasadi()   # imported inside the tests (tests/conftest.py)

import pinmsk  # noqa: E402
from pinmsk.errors import ModelError  # noqa: E402
from pinmsk.fitting import FitStatistics, Result  # noqa: E402
from pinmsk.solvers import ocp  # noqa: E402
from pinmsk.solvers.ocp import gait  # noqa: E402


def _half_cycle(model, T=0.5, n=11, d=0.65):
    """A synthetic half cycle (Result) with every channel kind full_stride reads."""
    t = np.linspace(0.0, T, n)
    rng = np.random.default_rng(3)
    ch = {"torso_x": d * t / T, "torso_y": 0.9 + 0.01 * np.sin(2 * np.pi * t / T)}
    for c in model.coordinates[2:]:
        ch[c] = rng.normal(size=n)
    for m in model.muscle_names:
        ch[f"{m}_activation"] = rng.uniform(0.01, 1, n)
        ch[f"{m}_metabolic_rate"] = np.full(n, 10.0)
    for c in model.contacts:
        for ax in "xyz":
            ch[f"{c.label}_force_{ax}"] = rng.uniform(0, 100, n) if ax != "z" else np.zeros(n)
    return Result(t, ch, stats=FitStatistics(k=1, converged=True, message="", iterations=0, violation=0.0,
                                             objective=0.0))


def test_full_stride_mirrors_the_half_cycle_and_sums_each_sides_spheres():
    """The second half is the first with right and left swapped and the pelvis advanced by the half
    cycle's distance; each side's GRF is the sum of its three spheres; speed, stride length, cost of
    transport (16 muscles x 10 W over 0.5 s, per kg and m) and body weight from their definitions."""
    model = gait.gait_model()
    half = _half_cycle(model)
    stride, s = gait.full_stride(half, model=model)
    n = half.time.size
    assert stride.time.size == 2 * n - 1 and stride.time[-1] == pytest.approx(1.0)
    # the seam (index n - 1) is the half cycle's end, which symmetry makes its start mirrored
    np.testing.assert_array_equal(stride["hip_r"][n:], half["hip_l"][1:])
    np.testing.assert_array_equal(stride["knee_l"][n:], half["knee_r"][1:])
    np.testing.assert_array_equal(stride["soleus_r_activation"][n:], half["soleus_l_activation"][1:])
    np.testing.assert_allclose(stride["torso_x"][n:], half["torso_x"][1:] + 0.65)
    np.testing.assert_array_equal(stride["torso_y"][n:], half["torso_y"][1:])
    fy_r = sum(half[f"{c.label}_force_y"] for c in model.contacts if c.target.endswith("_r"))
    np.testing.assert_allclose(stride["r_ground_force_vy"][:n], fy_r)
    np.testing.assert_allclose(stride["l_ground_force_vy"][n:], fy_r[1:])
    mass = sum(I.mass for I in model.pin.inertias)
    assert s["speed"] == pytest.approx(1.3) and s["stride_length"] == pytest.approx(1.3)
    assert s["body_weight"] == pytest.approx(9.81 * mass)
    assert s["cost_of_transport"] == pytest.approx(16 * 10.0 * 0.5 / (mass * 0.65))
    # mirroring twice is the identity (a round trip)
    again, _ = gait.full_stride(Result(stride.time[n - 1:] - stride.time[n - 1],
                                       {k: stride[k][n - 1:] for k in half.names},
                                       stats=half.stats), model=model)
    np.testing.assert_allclose(again["hip_r"][n:], half["hip_r"][1:])
    np.testing.assert_allclose(again["torso_x"][n:], half["torso_x"][1:] + 2 * 0.65)


def test_bounds_hold_on_the_variables_and_bind_when_active():
    """A forearm reach in 1 s: its unbounded peak speed exceeds 2 rad/s; bounded to 2 rad/s the speed
    stays within it at every node, touches it, and the effort rises."""
    model = pinmsk.load_model("forearm", moment_arms="angle")
    cons = [ocp.InitialState(q={"elbow_flexion": 0.3}, v={"elbow_flexion": 0.0}),
            ocp.FinalState(q={"elbow_flexion": 1.5}, v={"elbow_flexion": 0.0})]

    def solve(extra):
        return ocp.Collocation(model, cost=ocp.Effort(2), constraints=cons + extra, duration=0.8, intervals=15,
                               scheme="trapezoidal", verbose=False).fit().result_
    free = solve([])
    assert free.converged and free["elbow_flexion_speed"].max() > 2.1
    r = solve([ocp.Bounds(v={"elbow_flexion": (-2.0, 2.0)})])
    assert r.converged, r.status
    assert r["elbow_flexion_speed"].max() <= 2.0 + 1e-9
    assert r["elbow_flexion_speed"].max() > 2.0 - 1e-4
    assert r.objective > free.objective


def test_bounds_refuse_empty_ranges_by_name():
    with pytest.raises(ModelError, match="Bounds v of knee_r"):
        ocp.Bounds(v={"knee_r": (1.0, -1.0)})
    model = pinmsk.load_model("forearm", moment_arms="angle")
    fit = ocp.Collocation(model, cost=ocp.Effort(2), constraints=[ocp.Bounds(q={"elbow_flexion": (0.1, 0.2)}),
                                                                  ocp.Bounds(q={"elbow_flexion": (0.3, 0.4)})],
                          duration=1.0, intervals=5, verbose=False)
    with pytest.raises(ModelError, match="Bounds on q of elbow_flexion are empty"):
        fit.fit()


def test_gait_task_files_build_the_half_cycle_problem():
    """data/tasks/gait2d_predictive.toml: the half-cycle constraints (symmetry, periodic forward speed,
    knee bounds, box bounds, 1.3 m/s), metabolic cost per distance plus effort; an unknown [gait] key
    is refused by name."""
    from pinmsk.solvers.ocp.tasks import build_from_task, load_task
    spec = load_task(REPO / "data/tasks/gait2d_predictive.toml")
    fit = build_from_task(spec, base_dir=REPO / "data/tasks")
    assert isinstance(fit, ocp.Collocation)
    kinds = [type(c).__name__ for c in fit.constraints]
    assert kinds.count("CoordinateBounds") == 2 and "Symmetric" in kinds and "Periodic" in kinds
    sp = [c for c in fit.constraints if isinstance(c, ocp.AverageSpeed)]
    assert len(sp) == 1 and sp[0].speed == 1.3
    assert [t.name for t in fit.cost.terms()] == ["metabolic", "effort"]
    # coarse-to-fine (15 then 25 intervals) from the walking guess, the trunk within +-0.15 rad
    assert isinstance(fit, gait.CoarseToFine) and fit.intervals == 25 and fit.coarse_intervals == 15
    assert len(fit.model.contacts) == 6 and isinstance(fit.guess, pinmsk.trial.Trial)
    b = [c for c in fit.constraints if isinstance(c, ocp.Bounds)][0]
    assert b.q["torso_angle"] == (-0.15, 0.15)
    # the toe springs (20 N m/rad, 0.5 N m s/rad) in the fine stage only; the rest of the model the same
    from pinmsk.effects.damping import JointDamping
    from pinmsk.effects.spring import JointSpring
    toes = {(type(e).__name__, e.target): dict(e.values) for e in fit.model.effects
            if isinstance(e, (JointSpring, JointDamping))}
    assert toes == {("JointSpring", "mtp_r"): {"k": 20.0, "q0": 0.0}, ("JointSpring", "mtp_l"): {"k": 20.0, "q0": 0.0},
                    ("JointDamping", "mtp_r"): {"c": 0.5}, ("JointDamping", "mtp_l"): {"c": 0.5}}
    assert len(fit.coarse_model.effects) == len(fit.model.effects) - 4
    assert fit.coarse_model.contacts == fit.model.contacts
    spec["gait"]["mtp_stiffness"] = "none"
    assert build_from_task(spec, base_dir=REPO / "data/tasks").coarse_model is None
    spec["gait"]["spead"] = 1.2
    with pytest.raises(ModelError, match="spead"):
        build_from_task(spec)


def test_walking_guess_is_symmetric_and_stands_on_the_lowest_sole_site():
    """The generic walking guess: the half cycle ends in its start mirrored (hip_r(T) = hip_l(0), the
    symmetry Eq. 5.8 asks of the solution), the hip amplitude is the angle of a step of speed x T on a
    leg of the standing height, and at every node the lowest of the six sole sites is `sink` below
    the ground (forward kinematics of the guess's own posture)."""
    import pinocchio as pin
    model = gait.gait_model()
    g = gait.walking_guess(model, 1.3, 0.55, n=11, sink=0.005)
    for j in ("hip", "knee", "ankle"):
        assert g[f"{j}_r"][-1] == pytest.approx(g[f"{j}_l"][0], abs=1e-12)
        assert g[f"{j}_l"][-1] == pytest.approx(g[f"{j}_r"][0], abs=1e-12)
    h0 = gait.standing_height(model)
    assert -g["hip_r"][0] == pytest.approx(1.3 * 0.55 / (2 * h0))
    np.testing.assert_allclose(g["torso_x"], 1.3 * g.time)
    assert g["knee_r"].min() >= 0.0 and g["knee_l"].min() >= 0.0      # Eq. 5.10 holds in the guess
    d = model.pin.createData()
    for k in range(g.time.size):
        q = np.array([g[c][k] if c in g.names else 0.0 for c in model.coordinates])
        pin.framesForwardKinematics(model.pin, d, q)
        low = min(d.oMf[model.frame_id(f"{s}_{side}")].translation[1]
                  for s in ("heel", "metatarsal", "toe") for side in "rl")
        assert low == pytest.approx(-0.005, abs=1e-9)


@pytest.mark.slow
def test_predictive_gait_converges_from_the_walking_guess_and_validates():
    """Slow (~140-160 s on the loaded 2 cores; test_gait_task_files_build_the_half_cycle_problem
    builds the same problem in the default suite).
    The default predictive half cycle (task file gait2d_predictive.toml: walking guess, 15 intervals
    without the toe springs then 25 with them, trapezoidal, 0.55 s, 1.3 m/s, trunk within +-0.15 rad;
    De Groote 2016 rigid-tendon muscles, limited-memory Hessian) reaches IPOPT's Optimal Solution Found
    in both stages (5203 iterations in all measured), with the prescribed speed, the stride length it
    implies (2 x 0.55 s x 1.3 m/s), a cost of transport equal to the metabolic term of the objective
    (1.98 J/kg/m measured), and joint angles close to measured walking (vs Winter's Table A.1: hip
    13.0, knee 7.2 (correlation 0.98), ankle 11.9 deg RMS measured; without the toe springs the knee
    was 18.4, 0.60)."""
    from pinmsk.gait_validation import validate_gait
    from pinmsk.solvers.ocp.tasks import build_from_task, load_task
    spec = load_task(REPO / "data/tasks/gait2d_predictive.toml")
    fit = build_from_task(spec, base_dir=REPO / "data/tasks").fit()
    r, numbers = gait.stride_result(fit)
    d = {**fit.to_dict(), **numbers}
    assert d["converged"] and d["status"] == "Solve_Succeeded", d["status"]
    stages = fit.result_.info["stages"]
    assert [s["intervals"] for s in stages] == [15, 25] and all(s["status"] == "Solve_Succeeded" for s in stages)
    assert d["iterations"] == sum(s["iterations"] for s in stages)
    assert d["speed"] == pytest.approx(1.3, abs=1e-6)
    assert d["stride_length"] == pytest.approx(2 * 0.55 * 1.3, abs=1e-6)
    assert d["cost_of_transport"] == pytest.approx(d["terms"]["metabolic"], rel=1e-6)
    assert d["cost_of_transport"] == pytest.approx(1.98, abs=0.15)
    # the knee hyper-extension bound (Eq. 5.10) and the trunk bound hold and the feet carry the body:
    # the mean vertical GRF over the stride is the body weight (periodic vertical motion)
    assert r["knee_r"].min() >= -1e-6 and np.abs(r["torso_angle"]).max() <= 0.15 + 1e-6
    fy = r["r_ground_force_vy"] + r["l_ground_force_vy"]
    assert np.trapezoid(fy, r.time) / r.time[-1] == pytest.approx(d["body_weight"], rel=0.05)
    v = validate_gait(r, measured=False).numbers["joint_angles"]
    if "winter" in v:      # the shared data present (else validate_gait notes the reference absent)
        w = v["winter"]
        assert w["hip_r"]["rms_deg"] < 15 and w["hip_r"]["correlation"] > 0.7
        assert w["knee_r"]["rms_deg"] < 10 and w["knee_r"]["correlation"] > 0.9 and w["ankle_r"]["rms_deg"] < 13


def test_tracking_gait_tracks_grf_in_newtons_or_in_body_weights():
    """tracking_gait's GRF reference: as measured (N, Moco's habit) by default; with subject_weight
    (N, or "grf": the mean total vertical force over the tracked span) scaled by the model's weight
    over the subject's, so that the model tracks the same multiples of its own weight."""
    model = gait.gait_model("gait2d", muscle_model="degroote2016", tendon="rigid")
    bw = sum(I.mass for I in model.pin.inertias) * 9.81
    t = np.linspace(0.0, 1.0, 101)
    kin = pinmsk.Trial(t, {"torso_x": 1.2 * t, "hip_r": 0.3 * np.sin(6 * t), "hip_l": -0.3 * np.sin(6 * t)})
    fy = {"r": 800.0 + 200.0 * np.sin(2 * np.pi * t), "l": 100.0 - 200.0 * np.sin(2 * np.pi * t)}   # sum 900 N
    grf = pinmsk.Trial(t, {"r_ground_force_vx": np.full(t.size, 30.0), "r_ground_force_vy": fy["r"],
                           "l_ground_force_vx": np.zeros(t.size), "l_ground_force_vy": fy["l"]})

    def ref(**kw):
        fit = gait.tracking_gait(model, kin, grf, start=0.0, duration=1.0, muscle_model=None, tendon=None, **kw)
        term = next(c for c in fit.cost.terms() if c.name == "track_grf")
        return term.values                      # columns r_vx, r_vy, l_vx, l_vy (N)

    np.testing.assert_allclose(ref()[:, 1], fy["r"], rtol=1e-12)
    np.testing.assert_allclose(ref(subject_weight=900.0)[:, 1], fy["r"] * bw / 900.0, rtol=1e-12)
    np.testing.assert_allclose(ref(subject_weight="grf"), ref(subject_weight=900.0), rtol=1e-12)
    np.testing.assert_allclose(ref(subject_weight="grf")[:, 0], 30.0 * bw / 900.0, rtol=1e-12)
    with pytest.raises(ModelError, match="subject_weight"):
        ref(subject_weight=-1.0)
    with pytest.raises(ModelError, match="subject_weight"):
        ref(subject_weight="kg")


def test_gait_task_guess_file_is_the_strides_first_half_cycle(tmp_path):
    """[gait] guess = "<stride file>" (a pinmsk optimize output): the guess is its first half cycle, in
    the file's own time from 0; foot_mass and coarse_intervals = 0 (one solve) are task keys; a
    missing guess file is named."""
    from pinmsk.solvers.ocp.tasks import build_from_task, load_task
    t = np.linspace(0.0, 1.1, 23)
    pinmsk.write_trial(pinmsk.Trial(t + 2.0, {"torso_x": 1.3 * t, "hip_r": np.sin(t)}), tmp_path / "walk.sto")
    spec = load_task(REPO / "data/tasks/gait2d_predictive.toml")
    spec["gait"].update(speed="free", guess="walk.sto", coarse_intervals=0, foot_mass=0.67)
    fit = build_from_task(spec, base_dir=tmp_path)
    assert type(fit) is ocp.Collocation                      # coarse_intervals = 0: one solve
    g = fit.guess
    np.testing.assert_allclose(g.time, t[:12], atol=1e-12)   # 0 .. 0.55 s of the 1.1 s stride
    np.testing.assert_allclose(g["hip_r"], np.sin(t[:12]), atol=1e-12)
    assert not [c for c in fit.constraints if isinstance(c, ocp.AverageSpeed)]
    assert fit.model.pin.inertias[fit.model.pin.frames[fit.model.frame_id("foot_r")].parentJoint].mass \
        == pytest.approx(0.67 * 1.2)
    spec["gait"]["guess"] = "nowhere.sto"
    with pytest.raises(ModelError, match="guess file 'nowhere.sto' not found"):
        build_from_task(spec, base_dir=tmp_path)


def test_symmetric_pairs_actuator_controls_like_mocos_control_pair():
    """Symmetric(controls=...): an unsided actuator's control ends where it starts (Moco's
    addControlPair of the lumbar actuator); without it the optimum's control does not; a name that is
    not an actuator is refused."""
    from pinmsk.actuators import CoordinateActuator
    model = pinmsk.load_model("forearm") + CoordinateActuator("reserve", "elbow_flexion", optimal_force=1.0,
                                                              min_control=-50.0, max_control=50.0)
    tg = ocp.Target("sine", amplitude=0.3, frequency=1.0)

    def ends(cons):
        fit = ocp.Collocation(model, cost=ocp.Effort(2) + 1e-3 * ocp.ActuatorEffort() + 10 * ocp.TrackCoordinates(tg),
                              constraints=cons, duration=1.0, intervals=20, scheme="trapezoidal",
                              solver={"max_iter": 300}, verbose=False).fit()
        assert fit.result_.converged
        u = np.asarray(fit.result_["reserve_control"])
        return u[0], u[-1]

    u0, uN = ends([])
    assert abs(uN - u0) > 0.1                              # measured: -0.49 -> -1.01
    u0, uN = ends([ocp.Symmetric({}, controls=("reserve",))])
    assert uN == pytest.approx(u0, abs=1e-8)
    with pytest.raises(ModelError, match="'lumbar' is not an actuator"):
        ocp.Collocation(model, cost=ocp.Effort(2), constraints=[ocp.Symmetric({}, controls=("lumbar",))],
                        duration=1.0, intervals=4, solver={"max_iter": 0}, verbose=False).fit()
