"""The diagnosis on hard cases: joint refits, identifiable candidates, the statistical stopping rule,
residuals outside the catalog, and whole-body versus per-side masses on gait2d.

Every trial is synthetic (:func:`pinmsk.diagnose.make_trial`) with known hidden effects, and each test
checks the recovery against that truth.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import compare, diagnose, make_trial, run
from pinmsk.diagnose.fit import JointProblem
from pinmsk.diagnose.ranking import held_out_test
from pinmsk.diagnose.scoring import cycle_edges
from pinmsk.effects import JointDamping, MassScale, PassiveElastic, Payload, SensorGain, SensorOffset
from pinmsk.errors import ModelError

#: force-plate and motion-capture noise of a good gait lab (0.2 mm, 0.1 deg, 0.3 % of the peak force)
LAB = {"translation": 0.0002, "angle": np.deg2rad(0.1), "grf": 0.003}
_MODELS: dict = {}


def model(name):
    if name not in _MODELS:
        _MODELS[name] = pinmsk.load_model(name)
    return _MODELS[name]


class Loop:
    """The loop as a user runs it: add the suggested effect until nothing is suggested (one ``--add`` per
    step, each diagnosis reused as the next step's start)."""

    def __init__(self, m, trial, steps=4):
        self.adds, self.refits = [], []
        r = run(m, trial)
        while r.final.best is not None and len(self.adds) < steps:
            self.adds.append(r.final.best.label)
            r = run(m, trial, add=[self.adds[-1]], first=r.final)
            self.refits += r.refits
        self.final = r.final
        self.verdict, self.model, self.ratio = r.verdict, r.model, r.ratio


def follow(m, trial, steps=4):
    loop = Loop(m, trial, steps)
    return loop.adds, loop


# -- joint refit ----------------------------------------------------------------------------------

def test_damping_and_coulomb_of_similar_size_refit_jointly(tmp_path):
    """Damping (0.47 N m RMS) and friction (0.5 N m): the first effect absorbs the second, and gives it
    back when the second is fitted jointly with it."""
    m = model("forearm")
    trial = make_trial(m, ["joint_damping:elbow_flexion:c=0.3", "coulomb_friction:elbow_flexion:F_c=0.5"], seed=3)
    first = diagnose(m, trial)
    assert first.best.label == "joint_damping:elbow_flexion"
    assert first.best.params["c"] > 0.45                      # alone, it takes the friction too
    # the pair, fitted jointly, is significantly better than damping alone
    pair = first.best_pair
    assert pair is not None and set(pair["effects"]) == {"joint_damping:elbow_flexion",
                                                         "coulomb_friction:elbow_flexion"}
    r = run(m, trial, add=["joint_damping", "coulomb_friction"])
    assert r.verdict == "at_noise_floor"
    final = {c.label: c.values for c in r.model.components}
    assert final["joint_damping:elbow_flexion"]["c"] == pytest.approx(0.3, rel=0.05)
    assert final["coulomb_friction:elbow_flexion"]["F_c"] == pytest.approx(0.5, rel=0.06)
    assert r.steps[1].best.label == "coulomb_friction:elbow_flexion"        # the loop suggested both
    adds = [a.effect.label for a in r.added]
    # what the second add did to the first: recorded, printed, and in the JSON
    moved = r.refits[1]["effects"][0]["params"]["c"]
    assert moved["before"] > 0.45 and moved["after"] == pytest.approx(0.3, rel=0.05)
    assert moved["stderr"] is not None and moved["stderr"] < 0.02
    assert any("joint_damping:elbow_flexion.c" in k and "coulomb_friction" in k
               for k in r.refits[1]["correlations"])
    text = r.summary_text()
    assert "refitted jointly with it:" in text and "joint_damping:elbow_flexion.c:" in text
    r.write_json(tmp_path / "d.json")
    js = json.loads((tmp_path / "d.json").read_text())
    assert [e["added"] for e in js["refit"]] == adds
    assert js["added"][0]["params"]["c"] == pytest.approx(0.3, rel=0.05)       # final values, after the refit
    assert js["added"][0]["stderr"]["c"] is not None


def test_payload_and_spring_refit_jointly():
    m = model("forearm")
    trial = make_trial(m, ["payload:hand:mass=0.5", "joint_spring:elbow_flexion:k=3,q0=1.0"], seed=3)
    adds, r = follow(m, trial)
    assert set(adds) == {"joint_spring:elbow_flexion", "payload:hand"} and r.verdict == "at_noise_floor"
    final = {c.label: c.values for c in r.model.components}
    assert final["payload:hand"]["mass"] == pytest.approx(0.5, rel=0.03)
    assert final["joint_spring:elbow_flexion"]["k"] == pytest.approx(3.0, rel=0.05)
    assert final["joint_spring:elbow_flexion"]["q0"] == pytest.approx(1.0, rel=0.05)
    # the spring found first (0.24 rad rest angle, biased by the load) moved to the truth
    assert adds[0] == "joint_spring:elbow_flexion"
    assert r.refits[1]["effects"][0]["params"]["q0"]["before"] < 0.5


def test_a_third_effect_is_found():
    m = model("forearm")
    trial = make_trial(m, ["payload:hand:mass=0.5", "joint_damping:elbow_flexion:c=0.2",
                           "coulomb_friction:elbow_flexion:F_c=0.3"], seed=3)
    adds, r = follow(m, trial)
    assert adds == ["payload:hand", "joint_damping:elbow_flexion", "coulomb_friction:elbow_flexion"]
    assert r.verdict == "at_noise_floor" and r.ratio < 1.2
    final = {c.label: c.values for c in r.model.components}
    assert final["payload:hand"]["mass"] == pytest.approx(0.5, rel=0.02)
    # damping and friction correlate (both oppose the motion): each within its 2-sigma band
    assert final["joint_damping:elbow_flexion"]["c"] == pytest.approx(0.2, rel=0.1)
    assert final["coulomb_friction:elbow_flexion"]["F_c"] == pytest.approx(0.3, rel=0.15)


def test_joint_problem_is_exact_for_linear_effects():
    """Linear effects: the joint fit is the least-squares solution of the stacked regressors, and an
    effect already in the model moves relative to its value there."""
    m = model("forearm")
    trial = make_trial(m, ["payload:hand:mass=0.5", "joint_damping:elbow_flexion:c=0.2"], seed=12)
    c = compare(m, trial)
    jp = JointProblem(c.eq, c.eq_noise.sigma, [Payload("hand", mass=0.1), JointDamping("elbow_flexion", c=0.1)])
    assert jp.linear
    x, ok, msg = jp.solve()
    B, off = jp.basis()
    A = (B / jp.sigma[None, :, None]).reshape(-1, 2)
    ref = np.linalg.lstsq(A, -(jp.e / jp.sigma).ravel(), rcond=None)[0]
    np.testing.assert_allclose(x, ref, rtol=1e-10)
    assert ok and msg == "linear least squares" and x == pytest.approx([0.5, 0.2], rel=0.05)
    # the same with the payload in the model at 0.3 kg: the joint fit still lands on the same values
    m2 = m + Payload("hand", mass=0.3)
    c2 = c.with_model(m2)
    jp2 = JointProblem(c2.eq, c2.eq_noise.sigma, [m2.component("payload:hand"), JointDamping("elbow_flexion")])
    np.testing.assert_allclose(jp2.delta(jp2.x_start), np.c_[JointDamping("elbow_flexion").generalized_force(
        m, c.eq.motion_rows)[:, 0]], atol=1e-12)       # at its model value the payload changes nothing
    np.testing.assert_allclose(jp2.solve()[0], x, rtol=1e-8)


def test_refit_names_effects_of_the_model():
    m = model("forearm")
    trial = make_trial(m, ["joint_damping:elbow_flexion:c=0.3"], duration=6.0, seed=5)
    with pytest.raises(ModelError, match="refit names 'payload:hand', which model 'forearm' does not have"):
        diagnose(m, trial, refit=["payload:hand"])
    with pytest.raises(ModelError, match="alpha is a significance level"):
        diagnose(m, trial, alpha=2.0)


# -- identifiable candidates ---------------------------------------------------------------------

def test_sensor_offset_is_not_a_passive_moment():
    m = model("forearm")
    trial = make_trial(m, ["sensor_offset:elbow_flexion:offset=0.5"], seed=3)
    d = diagnose(m, trial)
    assert d.best.label == "sensor_offset:elbow_flexion"
    assert d.best.params["offset"] == pytest.approx(0.5, rel=0.03)
    # passive_elastic cannot be a constant any more (rest angle within the range, k >= 1/rad) ...
    pe = d.score("passive_elastic")
    assert not pe.significant and pe.params["theta_0"] >= 0.0
    # ... and the spring, whose rest angle would run off to absorb it, is flagged at its bound
    spring = d.score("joint_spring")
    assert not spring.identifiable and any("q0" in f and "bound" in f for f in spring.flags)
    after = diagnose(d.with_effect(), trial)
    assert after.verdict == "at_noise_floor"
    js = d.to_dict()
    entry = next(e for e in js["ranking"] if e["effect"] == "sensor_offset")
    assert entry["identifiability"]["identifiable"] is True and entry["identifiability"]["rank"] == 1
    assert entry["identifiability"]["intervals"]["offset"]["low"] < 0.5 < entry["identifiability"]["intervals"]["offset"]["high"]


def test_gain_error_is_sensor_gain():
    """A dynamometer reading 8 % high, with the held 1 kg dumbbell in the model: a sensor gain, not a mass."""
    m = model("forearm") + Payload("hand", mass=1.0)
    trial = make_trial(m, [SensorGain("elbow_flexion", gain=1.08)], seed=3)
    d = diagnose(m, trial)
    assert d.best.label == "sensor_gain:elbow_flexion"
    assert d.best.params["gain"] == pytest.approx(1.08, rel=0.005)
    after = diagnose(d.with_effect(), trial, refit=["sensor_gain:elbow_flexion"])
    assert after.verdict == "at_noise_floor" and not after.score("segment_mass").significant
    # the model's reading: the recording of the true moment through the sensor
    tau = np.linspace(-3.0, 5.0, 7)
    np.testing.assert_allclose(SensorGain("elbow_flexion", gain=1.08).measure(tau), 1.08 * tau)
    np.testing.assert_allclose(SensorOffset("elbow_flexion", offset=0.2).unmeasure(tau + 0.2), tau)
    # on the one-body forearm a gain and the segment's mass change the reading alike: aliases
    plain = model("forearm")
    d1 = diagnose(plain, make_trial(plain, ["sensor_gain:elbow_flexion:gain=1.08"], seed=3))
    assert {d1.best.label, *[a for a, _ in d1.best.aliases]} >= {"sensor_gain:elbow_flexion",
                                                                "segment_mass:forearm_hand"}
    assert "indistinguishable on this trial" in d1.verdict_line()


def test_a_diverging_passive_elastic_fit_is_flagged_not_suggested():
    """The candidate that scored a held-out RMSE of 242 N m after payload and damping were added (a
    wall of tiny amplitude and rate 100/rad extrapolated into the held-out block): its moment is now
    bounded by its amplitude over the range, and the fit that has nothing to explain is flagged."""
    from pinmsk.io.shared_data import shipped_trial
    m = model("forearm")
    r = run(m, pinmsk.read_trial(shipped_trial("forearm_payload_damping.csv")), add=["payload:hand", "joint_damping"])
    for d in r.steps:
        pe = d.score("passive_elastic")
        assert not pe.identifiable and not pe.significant and pe.flags
        assert d.best is None or d.best.family != "passive_elastic"
    pe = r.final.score("passive_elastic")
    assert pe.rmse_after["total"] < 1.2 * r.final.rmse["total"]                # no divergence held out
    assert r.verdict == "at_noise_floor"
    entry = next(e for e in r.to_dict()["ranking"] if e["effect"] == "passive_elastic")
    assert entry["identifiability"]["identifiable"] is False and entry["identifiability"]["flags"]
    assert "never suggested" in r.final.summary_text()


def test_flagged_candidate_in_the_model_does_not_end_at_the_floor():
    """passive_elastic added by hand where a sensor offset is missing: it takes part of the offset with
    a branch at its bounds, its parameters are not determined, and the verdict says so instead of
    at_noise_floor (the undetermined effect is held at its values, not refitted with the candidates)."""
    m = model("forearm")
    trial = make_trial(m, ["sensor_offset:elbow_flexion:offset=0.5"], duration=6.0, seed=4)
    r = run(m, trial, add=["passive_elastic:elbow_flexion"])
    first = r.steps[0]
    assert first.best.label == "sensor_offset:elbow_flexion"               # what was suggested instead
    assert not first.score("passive_elastic").significant
    d = r.final
    assert d.verdict == "missing_effect"
    assert d.stopping["not_identifiable_in_model"] == ["passive_elastic:elbow_flexion"]
    assert "remove it and diagnose again" in d.verdict_line()


def test_identifiability_reports_rank_condition_and_profile_intervals():
    m = model("forearm")
    trial = make_trial(m, ["joint_spring:elbow_flexion:k=2,q0=1.0"], seed=7)
    d = diagnose(m, trial)
    s = d.best
    assert s.label == "joint_spring:elbow_flexion"
    ident = s.identifiability
    assert ident["rank"] == 2 and 1.0 <= ident["condition_number"] < 1e3
    for name, truth in (("k", 2.0), ("q0", 1.0)):
        iv = ident["intervals"][name]
        assert iv["method"] == "profile" and not iv["open"]
        assert iv["low"] < truth < iv["high"] and iv["low"] < s.params[name] < iv["high"]
        # the profile interval is close to Wald's for this nearly quadratic problem
        assert (iv["high"] - iv["low"]) == pytest.approx(2 * 1.96 * ident["stderr"][name], rel=0.3)


# -- the stopping rule -------------------------------------------------------------------------------

def test_effect_below_the_old_floor_rule_is_suggested():
    """Damping at 0.75x the noise floor (the error 1.25x the floor, below the old 1.5x 'nothing to add')."""
    m = model("forearm")
    trial = make_trial(m, ["joint_damping:elbow_flexion:c=0.047"], seed=1)
    d = diagnose(m, trial)
    assert d.ratio < 1.5
    assert d.best is not None and d.best.label == "joint_damping:elbow_flexion"
    assert d.best.params["c"] == pytest.approx(0.047, rel=0.25)
    assert d.verdict == "missing_effect" and "--add joint_damping:elbow_flexion" in d.verdict_line()
    assert d.best.test["z"] > d.best.test["critical_z"]


# slow: test_effect_below_the_old_floor_rule_is_suggested covers the same code on one seed
@pytest.mark.slow
@pytest.mark.parametrize("family,target,values", [
    ("joint_damping", "elbow_flexion", {"c": 0.047}),              # 0.75x the floor
    ("coulomb_friction", "elbow_flexion", {"F_c": 0.078}),         # 0.75x
    ("sensor_offset", "elbow_flexion", {"offset": 0.078}),          # 0.75x
    ("joint_spring", "elbow_flexion", {"k": 0.13, "q0": 1.0}),     # 0.75x
])
def test_effects_below_the_floor_are_found_in_most_seeds(family, target, values):
    m = model("forearm")
    label = f"{family}:{target}"
    found = 0
    for seed in range(10):
        d = diagnose(m, make_trial(m, [f"{label}:" + ",".join(f"{k}={v}" for k, v in values.items())], seed=seed))
        found += d.best is not None and d.best.label == label
    assert found >= 9


def test_held_out_test_under_the_null_and_with_an_effect():
    rng = np.random.default_rng(5)
    n = 1000

    def coloured():           # white noise through a moving average, as the filtered kinematics' noise
        return np.convolve(rng.standard_normal(n + 19), np.ones(20) / np.sqrt(20), mode="valid")[:, None]

    # a change fitted to other noise, tested on this noise: z is about N(-d^2 / se, 1), so its level holds
    zs = []
    for _ in range(300):
        noise, other = coloured(), coloured()
        fitted = 0.1 * np.convolve(other[:, 0], np.ones(50) / 50, mode="same")[:, None]
        zs.append(held_out_test(noise, noise - fitted)["z"])
    zs = np.array(zs)
    assert np.mean(zs) < 0 and np.mean(zs > 2.326) <= 0.03 and 0.6 < np.std(zs) < 1.4
    noise = coloured()
    effect = np.sin(np.linspace(0, 40, n))[:, None]          # RMS 0.71 of the noise
    real = held_out_test(noise + effect, noise)          # explained
    assert real["improvement"] == pytest.approx(np.mean(effect ** 2) + 2 * np.mean(noise * effect), rel=1e-9)
    assert real["z"] > 3.0 and real["bandwidth"] >= 10


# -- outside the catalog -------------------------------------------------------------------------------

def test_an_unstructured_disturbance_is_outside_the_catalog(tmp_path):
    """A random smooth torque (0.05-2 Hz, 3x the floor), unrelated to the state: no catalog effect."""
    m = model("forearm")
    trial = make_trial(m, [], seed=4)
    rng = np.random.default_rng(1004)
    t = trial.time
    f = np.fft.rfftfreq(t.size, t[1] - t[0])
    spec = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) * ((f > 0.05) & (f < 2.0))
    dist = np.fft.irfft(spec, t.size)
    floor = diagnose(m, trial).noise_floor["total"]
    chans = {n: trial[n] for n in trial.names}
    chans["elbow_flexion_moment"] = chans["elbow_flexion_moment"] + 3 * floor * dist / np.std(dist)
    d = diagnose(m, pinmsk.Trial(t, chans))
    assert d.verdict == "missing_effect" and d.best is None and d.best_pair is None
    out = d.outside_catalog
    assert out is not None and out["held_out_ratio"] > out["consistent_limit"]
    info = out["channels"]["elbow_flexion_moment"]
    assert 0.05 <= info["dominant_frequency_hz"] <= 2.0 and info["summary"]
    assert "outside the catalog" in d.verdict_line()
    json.dumps(d.to_dict())


def test_a_clean_trial_is_at_the_floor_by_the_statistics():
    m = model("forearm")
    d = diagnose(m, make_trial(m, [], seed=21))
    assert d.verdict == "at_noise_floor" and d.outside_catalog is None
    st = d.stopping
    assert st["consistent_with_noise"] and st["held_out_ratio"] <= st["consistent_limit"]
    assert max(s.test["z"] for s in d.ranking) < st["critical_z"]
    assert st["critical_z"] == pytest.approx(3.09, abs=0.1)          # alpha 0.01 over 10 candidates


# -- gait2d: whole body and both sides ------------------------------------------------------------------

def test_gait2d_whole_body_mass_is_a_scale_not_one_segment():
    g = model("gait2d")
    trial = make_trial(g, [MassScale(delta=0.1)], duration=6.0, seed=2, motion="walk", noise=LAB)
    d = diagnose(g, trial)
    assert d.best.label == "scale" and d.best.params["delta"] == pytest.approx(0.1, rel=0.03)
    assert "scale the model" in d.verdict_line()
    # held out over whole strides (the walk is cyclic)
    assert "whole cycles (period 1 s)" in d.settings["blocks"]
    # a heavier trunk alone is still the trunk
    hat = diagnose(g, make_trial(g, ["segment_mass:hat:delta=0.1"], duration=6.0, seed=2, motion="walk", noise=LAB))
    assert hat.best.label == "segment_mass:hat" and hat.best.params["delta"] == pytest.approx(0.1, rel=0.05)


@pytest.mark.slow          # the per-side refit of gait2d is also in the hat-mass golden and the loop tests
def test_gait2d_segment_masses_per_side_both_reported():
    g = model("gait2d")
    trial = make_trial(g, ["segment_mass:thigh_r:delta=0.4", "segment_mass:thigh_l:delta=0.15"], duration=6.0,
                       seed=2, motion="walk", noise=LAB)
    adds, r = follow(g, trial)
    assert adds == ["segment_mass:thigh_r", "segment_mass:thigh_l"] and r.verdict == "at_noise_floor"
    final = {c.label: c.values["delta"] for c in r.model.components if c.family == "segment_mass"}
    assert final["segment_mass:thigh_r"] == pytest.approx(0.4, rel=0.05)
    assert final["segment_mass:thigh_l"] == pytest.approx(0.15, rel=0.1)
    # alone, the right thigh had taken the left one's share too; the joint refit gave it back
    assert r.refits[1]["effects"][0]["params"]["delta"]["before"] > 0.5


def test_cycle_edges():
    t = np.arange(1000) * 0.01
    q = np.c_[np.sin(2 * np.pi * t) + 0.1 * np.sin(6 * np.pi * t)]
    edges, period = cycle_edges(t, q, 5)
    assert period == pytest.approx(1.0, abs=0.011) and edges == [200, 400, 600, 800]
    assert cycle_edges(t, np.c_[np.sin(2 * np.pi * 0.37 * t) + np.sin(2 * np.pi * 1.13 * t)], 5) is None


# -- muscle level: several effects of the chain at once ----------------------------------------------

def test_joint_chain_of_muscle_level_effects():
    """Two muscle-level effects in one joint fit: the change of e is that of the whole chain (delay, then
    activation dynamics) against the model's, not the sum of each alone."""
    from pinmsk.effects import ActivationDynamics, ElectromechanicalDelay
    m = model("forearm")
    trial = make_trial(m, [], duration=3.0, seed=3, measure=("excitations",))
    c = compare(m, trial)
    delay, act = ElectromechanicalDelay("muscles", delay=0.05), ActivationDynamics("muscles")
    jp = JointProblem(c.eq, c.eq_noise.sigma, [delay, act])
    both = jp.delta(jp.x_start)
    eq = c.eq
    u = eq.excitation
    a = act.transform(eq.motion.t, delay.transform(eq.motion.t, u))
    expected = eq._muscle_moment(a)[eq.rows] - eq.tau_mus
    np.testing.assert_allclose(both, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    alone = JointProblem(c.eq, c.eq_noise.sigma, [delay]).delta([0.05]) + \
        JointProblem(c.eq, c.eq_noise.sigma, [act]).delta(act.param_vector())
    assert np.abs(alone - both).max() > 0.05 * np.abs(both).max()          # they do not add up


# slow (9 s): test_joint_chain_of_muscle_level_effects covers the joint chain, test_damping_and_coulomb_...
# the loop's refit
@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="after the true delay and activation dynamics are added, "
                   "end_stop_upper:elbow_flexion is called significant (held-out z 4.0, BIC -92, stiffness "
                   "9 +- 13 N m/rad) while the error is 0.73x the noise floor: the verdict is missing_effect")
def test_delay_refitted_when_activation_dynamics_joins():
    m = model("forearm")
    trial = make_trial(m, ["electromechanical_delay:muscles:delay=0.04",
                           "activation_dynamics:muscles:tau_rise=0.02,tau_fall=0.08"], duration=5.0, seed=3)
    r = run(m, trial, add=["electromechanical_delay", "activation_dynamics"])
    assert r.verdict == "at_noise_floor"
    final = {c.label: c.values for c in r.model.components}
    # each hidden value recovered within 3 standard errors of the joint fit, each standard error informative
    # (< 75 % of the value): delay and the time constants trade off (correlation -0.8 with tau_fall), so
    # where the optimizer stops inside that uncertainty is rounding on the machine's BLAS (tau_rise 0.031
    # +- 0.013 on one machine, within 10 % of 0.02 on another)
    delay_se = r.refits[1]["effects"][0]["params"]["delay"]["stderr"]
    act_se = r.added[1].stderr
    for value, se, truth in ((final["electromechanical_delay:muscles"]["delay"], delay_se, 0.04),
                             (final["activation_dynamics:muscles"]["tau_rise"], act_se["tau_rise"], 0.02),
                             (final["activation_dynamics:muscles"]["tau_fall"], act_se["tau_fall"], 0.08)):
        assert se < 0.75 * truth and abs(value - truth) <= 3.0 * se, (value, se, truth)
    assert r.refits[1]["effects"][0]["params"]["delay"]["before"] > 0.08     # alone it took the lag too
