"""Candidates for lab residuals: one-sided end stops, centre-of-mass offsets, segment masses within
anthropometric ranges, payload sites, force-plate corrections -- each against an independent
computation (OpenSim's law written out, inverse dynamics of the richer model, loads corrected by
hand) and recovered from synthetic data that hides it."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import pinmsk
from pinmsk.components import Motion
from pinmsk.diagnose import diagnose, run, synth
from pinmsk.dynamics import inverse_dynamics_array, skeleton_with_inertias
from pinmsk.effects import (ComOffset, EndStopLower, EndStopUpper, Payload, PlateCopOffset, PlateGain,
                            PlateLag, PlateOffset, PlateTilt, SegmentMass)
from pinmsk.effects.anthropometry import ALLOWANCE, DE_LEVA_1996, body_mass, mass_range
from pinmsk.effects.payload import AxisPayload, PointPayload, payload_sites, trunk_bodies
from pinmsk.errors import ModelError
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.kinematics import prepare
from pinmsk.skeleton import ExternalForce, cross3, world_wrench
from pinmsk.trial import Trial



def shared_file(relative: str):
    root = shared_data_dir()
    if root is None or not (root / relative).is_file():
        pytest.skip(f"shared data file {relative} not available (set PINMSK_SHARED_DATA)")
    return root / relative


@pytest.fixture(scope="module")
def gait2d():
    return pinmsk.load_model("gait2d")


def _motion(model, n=60, seed=1, lo=0.2, hi=2.4):
    rng = np.random.default_rng(seed)
    q = rng.uniform(lo, hi, (n, model.nv))
    return Motion(np.linspace(0, 1, n), q, rng.normal(0, 2, (n, model.nv)), rng.normal(0, 10, (n, model.nv)))


def _id_change(model, effect, motion, external=()):
    """``Q`` from inverse dynamics: the model's ID less the ID with ``effect`` folded into the skeleton."""
    base = inverse_dynamics_array(model, motion, external=external, actuated=False, components=False)
    rich = skeleton_with_inertias(model.with_effect(effect))
    q, v, a = motion.q, motion.v, motion.a
    import pinocchio as pin
    pd = rich.createData()
    tau = np.array([pin.rnea(rich, pd, q[k], v[k], a[k]) for k in range(q.shape[0])])
    return base - tau


# -- end stops: OpenSim's CoordinateLimitForce, one side ---------------------------------------------

def _opensim_limit_force(q, qdot, *, K_up, q_up, K_lo, q_lo, damping, transition):
    """``CoordinateLimitForce::calcLimitForce`` written out (SI: stiffness N m/rad, angles rad)."""
    def step(x0, y0, x1, y1, x):         # SimTK::Function::Step
        u = np.clip((x - x0) / (x1 - x0), 0, 1)
        return y0 + (y1 - y0) * u ** 3 * (10 - 15 * u + 6 * u * u)
    k_up = step(q_up, 0.0, q_up + transition, K_up, q)
    k_lo = step(q_lo - transition, K_lo, q_lo, 0.0, q)
    f_damp = -damping * ((k_up / K_up if K_up else 0) + (k_lo / K_lo if K_lo else 0)) * qdot
    return -k_up * (q - q_up) + k_lo * (q_lo - q) + f_damp


def test_end_stops_follow_coordinate_limit_force(forearm):
    mo = _motion(forearm)
    q, v = mo.q[:, 0], mo.v[:, 0]
    up = EndStopUpper("elbow_flexion", stiffness=40.0, limit=1.9, transition=0.1, damping=0.5)
    lo = EndStopLower("elbow_flexion", stiffness=25.0, limit=0.6, transition=0.05, damping=0.2)
    both = (up.generalized_force(forearm, mo) + lo.generalized_force(forearm, mo))[:, 0]
    # OpenSim's one force with both sides: its damping switches by each side's step, like the two here
    k_up = _opensim_limit_force(q, v, K_up=40.0, q_up=1.9, K_lo=0.0, q_lo=-10, damping=0.5, transition=0.1)
    k_lo = _opensim_limit_force(q, v, K_up=0.0, q_up=10, K_lo=25.0, q_lo=0.6, damping=0.2, transition=0.05)
    np.testing.assert_allclose(both, k_up + k_lo, rtol=1e-12, atol=1e-12)
    assert np.any(q > 2.0) and np.any(q < 0.55)            # both stops are pressed
    # nothing between the limits
    inside = (q > 0.6) & (q < 1.9)
    np.testing.assert_array_equal(both[inside], 0.0)
    # OpenSim's file units: N m/deg, deg
    s = EndStopUpper.from_opensim("elbow_flexion", stiffness=1.0, limit=110.0, transition=2.0, damping=0.01)
    assert s.values["stiffness"] == pytest.approx(180 / np.pi)
    assert s.values["limit"] == pytest.approx(np.deg2rad(110.0))
    assert s.values["transition"] == pytest.approx(np.deg2rad(2.0))
    assert s.values["damping"] == pytest.approx(0.01 * 180 / np.pi)
    # the fit sees stiffness and limit only; the limit within the joint's range, the stiffness >= 0
    c = EndStopLower("elbow_flexion").for_model(forearm)
    assert [n for n, p in c.params.items() if p.vary] == ["stiffness", "limit"]
    assert (c.params["limit"].min, c.params["limit"].max) == (0.0, 2.6) and c.params["stiffness"].min == 0.0
    # a "stop" pressed on every frame is a spring, and is flagged as no stop
    assert EndStopUpper("elbow_flexion", limit=0.1).plausibility(forearm, mo)
    assert not EndStopUpper("elbow_flexion", limit=1.9).plausibility(forearm, mo)


@pytest.mark.parametrize("cls, limit", [(EndStopUpper, 2.1), (EndStopLower, 0.8)])
def test_a_one_sided_stop_is_found_and_identifiable(forearm, cls, limit):
    hidden = cls("elbow_flexion", stiffness=30.0, limit=limit)
    tr = synth.make_trial(forearm, [hidden], duration=8, seed=2)
    d = diagnose(forearm, tr)
    assert d.best is not None and d.best.label == hidden.label, d.verdict_line()
    assert d.best.identifiable and not d.best.flags         # no other side left at a bound
    assert d.best.params["stiffness"] == pytest.approx(30.0, rel=0.05)
    assert d.best.params["limit"] == pytest.approx(limit, abs=0.02)
    assert d.best.explained_fraction > 0.9


# -- segment masses within de Leva's ranges ------------------------------------------------------------

def test_de_leva_table_accounts_for_the_whole_body():
    """Table 4's segments, trunk in three parts and limbs twice, sum to 100 % for either sex."""
    paired = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")
    for sex in (0, 1):
        total = sum(v[sex] * (2 if k in paired else 1) for k, v in DE_LEVA_1996.items())
        assert total == pytest.approx(100.0, abs=0.05)


def test_mass_ranges_by_body_name(gait2d, forearm):
    j = {b: j for b, j in pinmsk.effects._base.moving_bodies(gait2d).items()}
    lo, hi, what = mass_range(gait2d, j["thigh_r"])
    M = float(gait2d.mass)
    assert body_mass(gait2d) == M                       # a whole body: the model's mass
    assert (lo, hi) == pytest.approx(((1 - ALLOWANCE) * 14.16 / 100 * M, (1 + ALLOWANCE) * 14.78 / 100 * M))
    assert what == "thigh"
    # gait2d's HAT is head, arms and the whole trunk: everything but the legs
    lo, hi, what = mass_range(gait2d, j["hat"])
    parts = {"head": 1, "upper_trunk": 1, "middle_trunk": 1, "lower_trunk": 1, "upper_arm": 2, "forearm": 2, "hand": 2}
    assert lo == pytest.approx(sum(k * (1 - ALLOWANCE) * min(DE_LEVA_1996[s]) for s, k in parts.items()) / 100 * M)
    assert hi == pytest.approx(sum(k * (1 + ALLOWANCE) * max(DE_LEVA_1996[s]) for s, k in parts.items()) / 100 * M)
    assert "with both arms" in what
    # the foot and toes share the foot's range in proportion to their masses
    f, t = mass_range(gait2d, j["foot_r"]), mass_range(gait2d, j["toes_r"])
    assert f[1] / t[1] == pytest.approx(gait2d.pin.inertias[j["foot_r"]].mass / gait2d.pin.inertias[j["toes_r"]].mass)
    # a forearm alone: the body mass its segments imply (forearm + hand at their mean share)
    assert body_mass(forearm) == pytest.approx(1.76 / ((1.38 + 1.62 + 0.56 + 0.61) / 200))


def test_an_implausible_segment_mass_is_flagged_never_suggested(forearm):
    assert SegmentMass("forearm_hand", delta=0.2).plausibility(forearm) == []
    flags = SegmentMass("forearm_hand", delta=0.6).plausibility(forearm)
    assert len(flags) == 1 and "de Leva 1996" in flags[0] and "2.816 kg" in flags[0]
    tr = synth.make_trial(forearm, ["segment_mass:forearm_hand:delta=0.6"], duration=6, seed=1)
    d = diagnose(forearm, tr)
    s = d.score("segment_mass")
    assert s.params["delta"] == pytest.approx(0.6, abs=0.02)       # the fit is what the data say ...
    assert not s.significant and s.identifiability["plausible"] is False and "de Leva" in s.note
    assert d.best is None or d.best.family != "segment_mass"        # ... and it is never suggested


# -- centre-of-mass offsets ---------------------------------------------------------------------------

def test_com_offset_is_inverse_dynamics_of_the_moved_com(gait2d):
    mo = _motion(gait2d, lo=-0.5, hi=0.5)
    c = ComOffset("hat", dx=0.03, dy=-0.02, dz=0.01)
    Q = c.generalized_force(gait2d, mo)
    np.testing.assert_allclose(Q, _id_change(gait2d, c, mo), rtol=1e-9, atol=1e-9)
    # the mass is kept, the COM moved: mass and rotational inertia about the new COM unchanged
    rich = skeleton_with_inertias(gait2d.with_effect(c))
    j = gait2d.pin.frames[gait2d.frame_id("hat")].parentJoint
    a, b = gait2d.pin.inertias[j], rich.inertias[j]
    assert b.mass == pytest.approx(a.mass)
    np.testing.assert_allclose(b.lever - a.lever, [0.03, -0.02, 0.01], atol=1e-12)
    np.testing.assert_allclose(b.inertia, a.inertia, atol=1e-9)
    # bounded to a fifth of the segment, the planar model's out-of-plane axis held
    f = ComOffset("hat").for_model(gait2d)
    assert f.params["dz"].vary is False and f.params["dx"].vary
    assert 0.02 <= f.params["dx"].max <= 0.1


def test_trunk_com_offset_is_recovered(gait2d):
    tr = synth.make_trial(gait2d, [ComOffset("hat", dx=0.03, dy=0.0, dz=0.0)], duration=8, seed=1)
    d = diagnose(gait2d, tr, candidates=["com_offset", "segment_mass:hat", "scale"])
    assert d.best is not None and d.best.label == "com_offset:hat", d.verdict_line()
    assert abs(d.best.params["dx"] - 0.03) < 3 * d.best.stderr["dx"] and d.best.stderr["dx"] < 0.01


# -- payload sites ------------------------------------------------------------------------------------

def test_payload_at_a_body_com_is_inverse_dynamics_of_the_point_mass(forearm):
    mo = _motion(forearm)
    for target in ("hand", "forearm_hand@com", "forearm_hand@end"):
        p = Payload(target, mass=1.3)
        np.testing.assert_allclose(p.generalized_force(forearm, mo), _id_change(forearm, p, mo), rtol=1e-9,
                                   atol=1e-9)
    with pytest.raises(ModelError, match="no_body"):
        Payload("no_body@com").check_target(forearm)
    c = np.array(forearm.pin.inertias[1].lever)
    np.testing.assert_allclose(Payload("forearm_hand@com").site(forearm)[1], c)
    np.testing.assert_allclose(Payload("forearm_hand@end").site(forearm)[1], 2 * c)     # a uniform rod's tip


def test_axis_payload_is_the_point_mass_at_its_distance_with_exact_derivatives(forearm):
    mo = _motion(forearm)
    c = np.array(forearm.pin.inertias[1].lever)
    p = AxisPayload.on_body(forearm, "forearm_hand", mass=1.3, distance=1.7 * np.linalg.norm(c))
    assert isinstance(Payload("forearm_hand@axis"), AxisPayload) and p.family == "payload"
    np.testing.assert_allclose(p.site(forearm)[1], 1.7 * c)
    np.testing.assert_allclose(p.generalized_force(forearm, mo), _id_change(forearm, p, mo), rtol=1e-9, atol=1e-9)
    assert p.params["distance"].max == pytest.approx(4 * np.linalg.norm(c))
    J = p.param_jacobian(forearm, mo)
    for k, name in enumerate(("mass", "distance")):
        h = 1e-6
        up = p.generalized_force(forearm, mo, {name: p.values[name] + h})
        dn = p.generalized_force(forearm, mo, {name: p.values[name] - h})
        np.testing.assert_allclose(J[..., k], (up - dn) / (2 * h), rtol=1e-6, atol=1e-7)
    with pytest.raises(ModelError, match="unknown parameter"):
        Payload("hand", distance=0.2)


def test_diagnosis_finds_a_payload_beyond_the_segment_end_on_its_axis(forearm):
    """Neither a marker nor the segment's estimated end is at the load: its distance is fitted."""
    c = np.array(forearm.pin.inertias[1].lever)
    true = AxisPayload.on_body(forearm, "forearm_hand", mass=1.0, distance=2.6 * np.linalg.norm(c))
    tr = synth.make_trial(forearm, [true], duration=8, seed=3)
    d = diagnose(forearm, tr, candidates=["payload:forearm_hand@axis", "payload:forearm_hand@com"])
    assert d.best is not None and d.best.label == "payload:forearm_hand@axis", d.verdict_line()
    for name in ("mass", "distance"):
        assert abs(d.best.params[name] - true.values[name]) < 3 * d.best.stderr[name], (name, d.best.params)


def test_point_payload_is_the_point_mass_with_exact_derivatives(gait2d):
    mo = _motion(gait2d)
    p = PointPayload.on_body(gait2d, "hat", mass=4.0, x=-0.12, y=0.3)
    assert isinstance(Payload("hat@point"), PointPayload) and trunk_bodies(gait2d) == ["hat"]
    assert p.params["z"].vary is False and p.params["x"].vary and p.params["y"].vary   # planar: z unseen
    np.testing.assert_allclose(p.generalized_force(gait2d, mo), _id_change(gait2d, p, mo), rtol=1e-9, atol=1e-8)
    J = p.param_jacobian(gait2d, mo)
    for k, name in enumerate(("mass", "x", "y", "z")):
        h = 1e-6
        up = p.generalized_force(gait2d, mo, {name: p.values[name] + h})
        dn = p.generalized_force(gait2d, mo, {name: p.values[name] - h})
        np.testing.assert_allclose(J[..., k], (up - dn) / (2 * h), rtol=1e-6, atol=1e-6)


def test_diagnosis_finds_a_backpack_and_where_it_sits(gait2d):
    """A 5 kg load 12 cm behind and 30 cm up the trunk: mass and place, not a heavier trunk."""
    true = PointPayload.on_body(gait2d, "hat", mass=5.0, x=-0.12, y=0.3)
    tr = synth.make_trial(gait2d, [true], duration=8, seed=2)
    d = diagnose(gait2d, tr, candidates=["payload:hat@point", "segment_mass:hat", "com_offset:hat"])
    assert d.best is not None and d.best.label == "payload:hat@point", d.verdict_line()
    for name in ("mass", "x", "y"):
        assert abs(d.best.params[name] - true.values[name]) < 3 * d.best.stderr[name], (name, d.best.params)
    assert d.best.stderr["mass"] < 0.5


def test_imported_arm_offers_its_wrist_marker_and_finds_the_held_mass():
    path = shared_file("opensim-models/Arm26/arm26.osim")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arm = pinmsk.load_model(path)
    sites = payload_sites(arm)
    assert sites == ["r_ulna_radius_hand@com", "r_ulna_radius_hand@axis", "r_radius_styloid", "r_ulna_radius_hand"]
    tr = synth.make_trial(arm, [Payload("r_radius_styloid", mass=1.5)], duration=8, seed=1)
    d = diagnose(arm, tr)
    assert d.best is not None and d.best.label == "payload:r_radius_styloid", d.verdict_line()
    assert d.best.params["mass"] == pytest.approx(1.5, rel=0.02)


# -- force plates ---------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def walk(gait2d):
    """gait2d's synthetic squat with ground reactions, its motion and measured loads as the comparison uses."""
    tr = synth.make_trial(gait2d, [], duration=6, seed=1, noise=None)
    inputs = prepare(gait2d, tr)
    return tr, inputs.motion, list(inputs.external)


def test_plate_cop_and_free_moment_from_the_wrench(gait2d, walk):
    tr, mo, ext = walk
    r = next(e for e in ext if e.frame == "foot_r")
    c = PlateOffset("foot_r").prepare(gait2d, mo, loads=ext)
    on = c["on"]
    assert on.mean() > 0.9
    w = world_wrench(r, mo.n_frames)
    # p x F + T reproduces the moment about the origin; p on the ground plane, T about the vertical
    np.testing.assert_allclose(cross3(c["p"], c["F"]) + c["T"], w[:, 3:], atol=1e-9)
    assert np.all(c["p"][:, 1] == 0.0) and np.all(c["T"][:, [0, 2]] == 0.0)


def _corrected(ext, frame, fun):
    return [ExternalForce(e.frame, *fun(np.asarray(e.force), np.asarray(e.torque))) if e.frame == frame else e
            for e in ext]


def test_plate_corrections_are_inverse_dynamics_with_corrected_loads(gait2d, walk):
    tr, mo, ext = walk
    n = mo.n_frames
    base = inverse_dynamics_array(gait2d, mo, external=ext, actuated=False)

    def check(effect, fun, rtol=1e-9, atol=1e-9):
        Q = effect.generalized_force(gait2d, mo, cache=effect.prepare(gait2d, mo, loads=ext))
        rich = inverse_dynamics_array(gait2d, mo, external=_corrected(ext, "foot_r", fun), actuated=False)
        np.testing.assert_allclose(Q, base - rich, rtol=rtol, atol=atol * np.abs(Q).max())
        assert np.abs(Q).max() > 0.1
        return Q

    c = PlateOffset("foot_r").prepare(gait2d, mo, loads=ext)
    on, p = c["on"][:, None], c["p"]
    b = np.array([6.0, -4.0, 0.0])
    # the true loads: the offset taken off the force, and its moment at the COP off the moment
    check(PlateOffset("foot_r", fx=6.0, fy=-4.0, fz=0.0),
          lambda F, M: (F - b * on, np.zeros((n, 3)), M - cross3(p, np.broadcast_to(b, F.shape)) * on))
    d = np.array([0.01, 0.0, 0.0])
    check(PlateCopOffset("foot_r", dx=0.01, dz=0.0),
          lambda F, M: (F, np.zeros((n, 3)), M - cross3(np.broadcast_to(d, F.shape), F)))
    check(PlateGain("foot_r", gain=1.05), lambda F, M: (F / 1.05, np.zeros((n, 3)), M / 1.05))
    # a tilt: the exact rotation of force and free moment about the COP, to first order (theta = 1 deg)
    th = np.deg2rad(1.0)
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])

    def untilt(F, M):
        Ft = F @ R          # R^T F per row: the measured force turned back
        T = c["T"]
        return Ft, np.zeros((n, 3)), cross3(p, Ft) + T @ R
    Q = PlateTilt("foot_r", tilt_x=0.0, rot_y=0.0, tilt_z=th)
    check(Q, untilt, rtol=2e-2, atol=2e-2)
    # a lag: the loads sampled lag later, to first order
    lag = 0.004
    t = mo.t

    def shifted(F, M):
        return (np.column_stack([np.interp(t + lag, t, F[:, k]) for k in range(3)]), np.zeros((n, 3)),
                np.column_stack([np.interp(t + lag, t, M[:, k]) for k in range(3)]))
    Ql = PlateLag("foot_r", lag=lag)
    Qv = Ql.generalized_force(gait2d, mo, cache=Ql.prepare(gait2d, mo, loads=ext))
    rich = inverse_dynamics_array(gait2d, mo, external=_corrected(ext, "foot_r", shifted), actuated=False)
    inner = slice(5, -5)
    err = np.abs(Qv - (base - rich))[inner].max()
    assert err < 0.1 * np.abs(Qv[inner]).max()


def test_plate_correction_needs_loads_on_its_body(gait2d, walk):
    tr, mo, ext = walk
    with pytest.raises(ModelError, match="no_plate.*foot_l, foot_r"):
        PlateOffset("no_plate").prepare(gait2d, mo, loads=ext)
    with pytest.raises(ModelError, match="needs the trial's external loads"):
        PlateOffset("foot_r").generalized_force(gait2d, mo)


def test_plate_offset_is_found_and_added(gait2d):
    tr = synth.make_trial(gait2d, [], duration=8, seed=1)
    ch = {k: np.asarray(tr[k]).copy() for k in tr.names}
    loaded = ch["r_ground_force_vy"] > 20
    ch["r_ground_force_vx"][loaded] += 8.0                   # the right plate's x channel drifted by 8 N
    drifted = Trial(tr.time, ch, meta=tr.meta)
    r = run(gait2d, drifted, add=["plate_offset:foot_r"],
            candidates=["plate_offset", "plate_tilt", "plate_gain", "com_offset", "scale"])
    first, last = r.steps
    assert first.best is not None and first.best.family == "plate_offset", first.verdict_line()
    fit = last.model.component("plate_offset:foot_r")
    assert fit.values["fx"] == pytest.approx(8.0, abs=3 * fit.params["fx"].stderr)
    assert last.verdict == "at_noise_floor" and last.ratio < first.ratio


# -- the loop on a case of three effects ------------------------------------------------------------------

def test_payload_damping_and_end_stop_are_all_found(forearm):
    """A payload, damping and an end stop, hidden together: diagnose and add until nothing is left."""
    hidden = ["payload:hand:mass=1.0", "joint_damping:elbow_flexion:c=0.3",
              "end_stop_upper:elbow_flexion:stiffness=30,limit=2.1"]
    tr = synth.make_trial(forearm, hidden, duration=8, seed=3)
    d = diagnose(forearm, tr)
    for _ in range(4):
        if d.best is None:
            break
        d = run(d.model, tr, add=[d.best.label], first=d).steps[-1]
    assert d.verdict == "at_noise_floor", d.verdict_line()
    got = {c.label: c.values for c in d.model.components}
    assert set(got) == {"payload:hand", "joint_damping:elbow_flexion", "end_stop_upper:elbow_flexion"}
    assert got["payload:hand"]["mass"] == pytest.approx(1.0, rel=0.03)
    assert got["joint_damping:elbow_flexion"]["c"] == pytest.approx(0.3, rel=0.1)
    assert got["end_stop_upper:elbow_flexion"]["stiffness"] == pytest.approx(30.0, rel=0.05)
    assert got["end_stop_upper:elbow_flexion"]["limit"] == pytest.approx(2.1, abs=0.02)


@pytest.mark.parametrize("cls", [PlateOffset, PlateCopOffset, PlateTilt, PlateGain, PlateLag])
def test_plate_corrections_conform(gait2d, walk, cls):
    """What the shared conformance suite checks, on loads it cannot supply: declarations, zero parameters,
    the parameter Jacobian against central differences, pickling and immutability."""
    import pickle

    tr, mo, ext = walk
    comp = cls("foot_r")
    assert comp.__doc__ and comp.label == f"{comp.family}:foot_r" and comp.needs_loads
    for name, p in comp.params.items():
        assert p.unit is not None and p.doc and p.min <= p.value <= p.max, name
    cache = comp.prepare(gait2d, mo, loads=ext)
    Q = comp.generalized_force(gait2d, mo, cache=cache)
    assert Q.shape == (mo.n_frames, gait2d.nv) and np.all(np.isfinite(Q)) and np.abs(Q).max() > 0
    np.testing.assert_array_equal(comp.generalized_force(gait2d, mo, comp.zero_params, cache), 0.0)
    J = comp.param_jacobian(gait2d, mo, cache=cache)
    assert J.shape == (mo.n_frames, gait2d.nv, len(comp.params))
    for k, (name, v) in enumerate(comp.values.items()):
        h = 1e-6 * max(abs(v), 1.0)
        fd = (comp.generalized_force(gait2d, mo, {name: v + h}, cache)
              - comp.generalized_force(gait2d, mo, {name: v - h}, cache)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-5, atol=1e-7 * max(1.0, np.abs(fd).max()))
    back = pickle.loads(pickle.dumps(comp))
    assert back == comp
    np.testing.assert_array_equal(back.generalized_force(gait2d, mo, cache=cache), Q)
    with pytest.raises(AttributeError):
        comp.target = "foot_l"
    # the model holding it: inverse dynamics passes it the loads
    with_it = inverse_dynamics_array(gait2d.with_effect(comp), mo, external=ext, actuated=False)
    np.testing.assert_allclose(with_it, inverse_dynamics_array(gait2d, mo, external=ext, actuated=False) - Q,
                               rtol=1e-10, atol=1e-8)
