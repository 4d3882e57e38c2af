"""The diagnosis side by side with OpenSim's Residual Reduction Algorithm (RRA).

Two walks of OpenSim's examples, each with RRA's own outputs beside it:

* Gait10dof18musc ``subject01`` (planar, 2.5 s at 60 Hz).  RRA (``RRA/walk_Setup_RRA.xml``,
  ``adjust_com_to_reduce_residuals`` false) reaches average residuals FX -3.77 N, FY -2.85 N,
  MZ -3.38 N m (``reference_outputs/RRA/subject_adjusted_avgResiduals.txt``) by changing the kinematics
  (pelvis_tx by 9.8 mm RMS, pelvis_ty by 3.8 mm, the joint angles by 0.1-0.26 deg RMS against the 6-Hz
  low-passed IK).  pinmsk keeps the kinematics and fits a torso centre-of-mass offset.
* Gait2354 pipeline (3-D, one stride at 60 Hz).  RRA moved the torso's centre of mass from
  (-0.0324, 0.3455, 0) to (+0.0161, 0.3455, +0.0167) m in ``OutputReference/subject01_simbody_adjusted.osim``
  and changed nothing else in the model.

Every figure compared is a residual of inverse dynamics over the analysed frames of the diagnosis (the
trial less 0.25 s at each end), with the coordinates low-passed at 6 Hz by OpenSim's ID-tool filter and the loads of OpenSim's
ExternalLoads file applied unfiltered, as OpenSim's ID tool applies them (the default of both
``pinmsk diagnose`` and ``pinmsk id``).  Needs ``../shared/data``; skips without it.
"""
import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import run
from pinmsk.dynamics import inverse_dynamics_result
from pinmsk.effects import registry
from conftest import shared_folder
from pinmsk.model import import_osim
from pinmsk.opensim.export import write_model

GAIT10 = "opensim-models/Gait10dof18musc"
GAIT2354 = "opensim-models/Gait2354Pipeline"
#: RRA's average residuals on the subject01 walk (reference_outputs/RRA/subject_adjusted_avgResiduals.txt)
RRA_10DOF = {"pelvis_tx": -3.76711, "pelvis_ty": -2.84942, "pelvis_tilt": -3.37546}
#: RRA's torso centre of mass before and after, in the torso's frame (OutputReference/*.osim of Gait2354)
TORSO_COM_2354 = (np.array([-0.0323916, 0.34551, 0.0]), np.array([0.0161184, 0.34551, 0.0166874]))


_folder = shared_folder


@pytest.fixture(scope="module")
def gait10():
    d = _folder(GAIT10, "subject01.osim")
    model, _ = import_osim(d / "subject01.osim", nonlinear="exact", hooks=())
    return d, model, pinmsk.read_trial(d / "IK" / "subject01_walk_IK.mot"), \
        d / "ExperimentalData" / "subject01_walk_grf.xml"


@pytest.fixture(scope="module")
def gait2354():
    d = _folder(GAIT2354, "OutputReference/subject01_simbody.osim")
    out = d / "OutputReference"
    model, _ = import_osim(out / "subject01_simbody.osim", nonlinear="exact", hooks=())
    adjusted, _ = import_osim(out / "subject01_simbody_adjusted.osim", nonlinear="exact", hooks=())
    return d, model, adjusted, pinmsk.read_trial(out / "subject01_walk1_ik.mot"), d / "forces_grf.xml"


def _means(model, trial, xml, times, coords):
    res = inverse_dynamics_result(model, trial, external_loads=xml)
    rows = np.isin(np.round(res.trial.time, 9), np.round(times, 9))
    return {c: float(np.mean(res.trial[f"{c}_moment"][rows])) for c in coords}, res


def _report_means(r, step):
    return {c: row["mean"] for c, row in r.residual_report()["steps"][step]["coordinates"].items()}


# -- Gait2354: RRA's adjusted model is pinmsk's com_offset ------------------------------------------------

def test_rra_adjusted_torso_is_pinmsks_com_offset(gait2354):
    """The model RRA wrote (torso COM moved) and pinmsk's ``com_offset:torso`` with RRA's shift give the
    same inverse dynamics on every frame: the effect's body-frame axes are OpenSim's."""
    d, model, adjusted, trial, xml = gait2354
    dx, dy, dz = TORSO_COM_2354[1] - TORSO_COM_2354[0]
    shifted = model.with_effect(registry.get("com_offset")("torso", dx=dx, dy=dy, dz=dz))
    a = inverse_dynamics_result(adjusted, trial, external_loads=xml).trial
    b = inverse_dynamics_result(shifted, trial, external_loads=xml).trial
    names = [n for n in a.names if n.endswith("_moment")]
    assert len(names) == 23
    scale = max(float(np.max(np.abs(a[n]))) for n in names)
    assert max(float(np.max(np.abs(a[n] - b[n]))) for n in names) < 1e-12 * scale


def test_rra_torso_shift_answers_the_mean_moments_not_the_forces(gait2354):
    """Over RRA's window (0.75-1.25 s) with the IK kinematics unchanged, RRA's torso shift takes the mean
    pelvis-tilt moment from -15.3 to -0.4 N m and pelvis-list from 5.5 to 1.4 N m; the mean forces stay
    (pelvis_tx -5.4 -> -5.8 N): RRA's own FX -0.52 N comes from its kinematic changes."""
    d, model, adjusted, trial, xml = gait2354
    t = trial.time[(trial.time >= 0.75 - 1e-9) & (trial.time <= 1.25 + 1e-9)]
    coords = ("pelvis_tilt", "pelvis_list", "pelvis_tx")
    before, _ = _means(model, trial, xml, t, coords)
    after, _ = _means(adjusted, trial, xml, t, coords)
    assert before["pelvis_tilt"] == pytest.approx(-15.29, abs=0.05)
    assert after["pelvis_tilt"] == pytest.approx(-0.40, abs=0.05)
    assert abs(after["pelvis_tilt"]) < 1.42             # RRA's MZ -1.42 N m
    assert before["pelvis_list"] == pytest.approx(5.50, abs=0.05)
    assert after["pelvis_list"] == pytest.approx(1.43, abs=0.05)
    assert after["pelvis_tx"] == pytest.approx(-5.78, abs=0.05)


# -- Gait10dof18musc: the loop, and the torso offset RRA would make ------------------------------------

@pytest.fixture(scope="module")
def gait10_torso(gait10):
    """The diagnosis of the walk as given, then with the torso's centre of mass moved along the torso's
    x axis (dy held at 0, as RRA holds the vertical), as ``--add com_offset:torso:dy=0`` does."""
    d, model, trial, xml = gait10
    return run(model, trial, external_loads=xml, add=["com_offset:torso:dy=0"])


def test_subject01_walk_suggests_the_torso_offset_by_its_mean(gait10_torso):
    """The model as given: no candidate passes by its held-out error (the best z 2.8 against 3.30), but
    the mean pelvis-tilt moment (-9.5 N m, z 4.5 Newey-West) is systematic; ``com_offset:torso`` (across
    the trunk: dy, along it, held as RRA holds it) takes most of it away out of sample (mean test z 4.5)
    and is suggested; the plate and COP offsets that take less of it away are named beside it."""
    d0 = gait10_torso.steps[0]
    assert d0.verdict == "missing_effect" and d0.suggest_remove is None
    assert max(s.test["z"] for s in d0.ranking) < d0.ranking[0].test["critical_z"]
    best = d0.best
    assert best.label == "com_offset:torso" and best.test["passes_by"] == "mean"
    mt = best.test["mean"]
    assert [d0.comparison.channels[k] for k in mt["systematic"]] == ["pelvis_tilt_moment"]
    assert mt["z"] > best.test["critical_z"] and mt["chi2_after"] < 1.0
    assert best.identifiability.get("identifiable", True)
    assert not best.effect.params["dy"].vary and best.effect.values["dy"] == 0.0
    assert 0.015 < best.effect.values["dx"] < 0.035
    others = [s for s in d0.significant if s is not best]
    assert others and all(s.test["passes_by"] == "mean" and s.test["mean"]["z"] < mt["z"] for s in others)
    assert "takes the systematic mean of pelvis_tilt_moment away" in d0.verdict_line()
    # added, it is kept: without it the mean comes back (the elimination's mean test)
    elim = gait10_torso.steps[1].elimination
    assert [e["label"] for e in elim] == ["com_offset:torso"]
    assert elim[0]["significant"] and not elim[0]["suggest_remove"]
    assert elim[0]["z"] < elim[0]["critical_z"] < elim[0]["z_mean"]


def test_subject01_torso_offset_brings_the_means_to_rra_level(gait10_torso, gait10, tmp_path):
    """``com_offset:torso`` (dx = +2.6 cm: the torso COM from x -0.032 to -0.007 m) takes the mean
    pelvis-tilt moment from -9.52 to -1.56 N m, below RRA's -3.38, the forces' means stay below RRA's, and
    the kinematics stay as measured; the saved model's inverse dynamics gives the same means."""
    d, model, trial, xml = gait10
    r = gait10_torso
    fit = r.added[0].effect
    assert fit.label == "com_offset:torso"
    lo, hi = fit.params["dx"].min, fit.params["dx"].max
    assert 0.015 < fit.values["dx"] < 0.035 and lo < fit.values["dx"] < hi
    assert fit.values["dy"] == 0.0 and fit.values["dz"] == 0.0
    before, after = _report_means(r, 0), _report_means(r, 1)
    assert before["pelvis_tilt"] == pytest.approx(-9.52, abs=0.05)
    assert after["pelvis_tilt"] == pytest.approx(-1.56, abs=0.1)
    for c, rra in RRA_10DOF.items():
        assert abs(after[c]) <= abs(rra), c
    # the kinematics are the measured ones at both steps
    q0, q1 = r.steps[0].comparison.eq.motion_rows.q, r.steps[1].comparison.eq.motion_rows.q
    assert np.array_equal(q0, q1)
    # the saved model runs in `pinmsk id` and gives the same residuals over the analysed frames
    back = pinmsk.load_model(write_model(r.model, tmp_path / "subject01_torso.toml")["sidecar"])
    means, res = _means(back, trial, xml, r.steps[1].comparison.time, RRA_10DOF)
    for c in RRA_10DOF:
        assert means[c] == pytest.approx(after[c], abs=1e-6), c
    # both low-pass the coordinates at 6 Hz and, with OpenSim's ExternalLoads file, apply the loads
    # unfiltered, as OpenSim's ID tool (and RRA) applies them
    assert r.steps[0].comparison.cutoff == 6.0 and r.steps[0].comparison.options["grf_cutoff"] == "auto"
    assert r.steps[0].comparison.inputs.filtering.grf_cutoff is None
    assert res.trial.meta["lowpass_cutoff_hz"] == 6.0 and res.trial.meta["grf_lowpass_cutoff_hz"] == 0.0
    # over every frame the filter's ends (peaks of 124 N and 167 N at the last frame) pull the force means
    # past RRA's, as they do in OpenSim's own ID of this walk (reference_outputs/ID: -5.9 N, -3.7 N)
    full = {c: float(np.mean(res.trial[f"{c}_moment"])) for c in RRA_10DOF}
    assert full["pelvis_tx"] == pytest.approx(-5.93, abs=0.05)
    assert abs(full["pelvis_tilt"]) <= abs(RRA_10DOF["pelvis_tilt"])


# -- following the suggestions alone (the check as a user runs it) ---------------------------------------

def _follow(model, trial, xml, steps=6):
    adds, removes = [], []
    r = run(model, trial, external_loads=xml)
    for _ in range(steps):
        d = r.steps[-1]
        if d.suggest_remove:
            removes.append(d.suggest_remove)
        elif d.best is not None:
            adds.append(d.best.effect.label)
        else:
            return r, adds, removes
        r = run(model, trial, external_loads=xml, add=adds, remove=removes)
    return r, adds, removes


def test_subject01_following_the_suggestions_reaches_rra(gait10, tmp_path):
    """Following pinmsk's suggestions alone (add the best, drop what elimination names, until nothing is
    suggested) adds the torso offset and stops; the saved model's inverse dynamics has each mean pelvis
    residual at RRA's level or below (-1.56 N m, -2.36 N, -0.99 N against RRA's -3.38, -3.77, -2.85), with
    the kinematics as measured."""
    d, model, trial, xml = gait10
    r, adds, removes = _follow(model, trial, xml)
    assert adds == ["com_offset:torso"] and removes == []
    back = pinmsk.load_model(write_model(r.model, tmp_path / "subject01_followed.toml")["sidecar"])
    times = r.steps[-1].comparison.time
    means, res = _means(back, trial, xml, times, RRA_10DOF)
    for c, rra in RRA_10DOF.items():
        assert abs(means[c]) <= abs(rra), (c, means[c])
    first, last = r.residual_report()["steps"][0]["coordinates"], r.residual_report()["steps"][-1]["coordinates"]
    for c in RRA_10DOF:
        assert last[c]["mean"] == pytest.approx(means[c], abs=1e-6)
    # RMS and peak: pelvis tilt 12.8 -> 8.8 N m and 32.8 -> 24.3 N m; the forces within 1.1 % and 2 %
    assert last["pelvis_tilt"]["rms"] == pytest.approx(8.83, abs=0.05)
    assert last["pelvis_tilt"]["rms"] < 0.75 * first["pelvis_tilt"]["rms"]
    assert last["pelvis_tilt"]["peak"] < 0.8 * first["pelvis_tilt"]["peak"]
    for c in ("pelvis_tx", "pelvis_ty"):
        assert last[c]["rms"] < 1.015 * first[c]["rms"] and last[c]["peak"] < 1.02 * first[c]["peak"], c
    assert np.array_equal(r.steps[0].comparison.eq.motion_rows.q, r.steps[-1].comparison.eq.motion_rows.q)


# -- Gait2354: one stride ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def gait2354_diagnosis(gait2354):
    d, model, adjusted, trial, xml = gait2354
    return run(model, trial, external_loads=xml).steps[0]


def test_gait2354_one_stride_is_diagnosed_and_implausible_masses_are_flagged(gait2354_diagnosis):
    """One stride (43 analysable samples) is diagnosed with 2 folds; nothing is suggested; the segment
    masses that would absorb the residual (a toe of 1.24 kg, de Leva's range 0.09-0.27 kg) are flagged
    implausible and never suggested; the torso offset (across the trunk) is not significant."""
    d0 = gait2354_diagnosis
    assert d0.settings["folds"] == 2
    assert d0.best is None and d0.verdict == "missing_effect"
    by = {s.effect.label: s for s in d0.ranking}
    toes = by["segment_mass:toes_l"]
    assert toes.identifiability.get("plausible") is False and not toes.significant
    assert any("outside the plausible" in f for f in toes.identifiability["flags"])
    flagged = [s for s in d0.ranking if s.identifiability.get("plausible") is False]
    assert len(flagged) >= 3 and not any(s.significant for s in flagged)
    torso = by["com_offset:torso"]
    assert not torso.effect.params["dy"].vary and not torso.significant


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="pelvis_ty, 7.5x its 5.1-N floor, is 86 % of the noise-weighted sum of "
                   "squares: the fit moves the torso COM sideways (dz -2.8 cm) for 0.8 N less pelvis_ty RMS, "
                   "against RRA's +1.67 cm, and the mean pelvis_list moment rises from 7.1 to 16.6 N m")
def test_gait2354_torso_offset_moves_with_rra(gait2354):
    d, model, adjusted, trial, xml = gait2354
    r = run(model, trial, external_loads=xml, add=["com_offset:torso:dy=0"])
    fit = r.added[0].effect
    shift = TORSO_COM_2354[1] - TORSO_COM_2354[0]
    assert np.sign(fit.values["dx"]) == np.sign(shift[0]) and np.sign(fit.values["dz"]) == np.sign(shift[2])
    after = _report_means(r, 1)
    assert abs(after["pelvis_list"]) < abs(_report_means(r, 0)["pelvis_list"])
