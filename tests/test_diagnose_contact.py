"""Diagnosis hook of the contact models: the contact mode of pinmsk.diagnose.

Ground truth: a hyper-volumetric foot (thesis Table 4.4 parameters) made by
:func:`pinmsk.contact.synthetic_foot_trial` with the pivot 30 mm above the belt
(deep enough that the spheres' cap volume departs from a power law) and force
plate noise of 0.3 % of the peak; its vertical GRF has a heel-strike plateau,
a foot-flat hump, a valley and a push-off hump.
"""
import json

import numpy as np
import pytest

from pinmsk.contact import load_foot2d, synthetic_foot_trial
from pinmsk.diagnose import compare, diagnose, run
from pinmsk.errors import ModelError, TrialError

CHANNELS = ("ground_force_vy", "ground_force_vx", "ground_force_px")


@pytest.fixture(scope="module")
def foot():
    return load_foot2d()


@pytest.fixture(scope="module")
def trial():
    return synthetic_foot_trial(contact="hypervolumetric", noise=0.003, seed=1, clearance=0.03)


@pytest.fixture(scope="module")
def first(foot, trial):
    return diagnose(foot, trial, cutoff=None)     # noise-free synthetic kinematics: no low-pass


@pytest.fixture(scope="module")
def loop(foot, trial, first):
    return run(foot, trial, add=[first.best.label], first=first, cutoff=None)


def test_auto_chooses_contact_mode(first):
    c = first.comparison
    assert c.mode == "contact"
    assert c.channels == CHANNELS
    assert "unloaded frames" in c.noise.method and "third differences" in c.noise.method
    # the force-plate noise is recovered from the swing frames (true: 0.3 % of the peak)
    true_vy = 0.003 * np.max(c.trial["ground_force_vy"])
    assert first.noise_floor["ground_force_vy"] == pytest.approx(true_vy, rel=0.3)


def test_bare_foot_misses_a_volumetric_contact(first):
    assert first.verdict == "missing_effect"
    fams = [s.family for s in first.ranking]
    assert set(fams) == {"point", "volumetric", "hypervolumetric", "hypervolumetric_relaxed"}
    assert first.ranking[0].family in ("hypervolumetric", "hypervolumetric_relaxed")   # the true family
    assert first.best is first.ranking[0]
    assert fams.index("point") > fams.index("hypervolumetric")
    assert fams.index("point") > fams.index("hypervolumetric_relaxed")
    # the point contact follows the GRF less well than the true family, and is worse in BIC.  (Not
    # necessarily worse than the linear volumetric sphere: with free exponents and Hunt-Crossley
    # damping it fits this trial's vertical force better than H = 1 does.)
    point, best = first.score("point"), first.best
    assert point.rmse_after["ground_force_vy"] > 1.2 * best.rmse_after["ground_force_vy"]
    assert point.fit.bic_change > best.fit.bic_change + 10
    out = first.to_dict()
    assert {"inputs", "rmse", "noise_floor", "worst_windows", "ranking", "verdict", "added", "noise_model", "refit",
                "pairs", "outside_catalog", "stopping"} <= set(out)
    for entry in out["ranking"]:
        assert {"effect", "target", "params", "rmse_after", "explained_fraction", "significant"} <= set(entry)
        assert entry["target"] == "heel,metatarsal,toe"
        assert set(entry["rmse_after"]) == set(CHANNELS) | {"total"}
        assert "heel.R" in entry["params"] or "heel.L0" in entry["params"]
    json.dumps(out)


def test_point_contact_misses_at_the_double_hump(first):
    """The point contact's vertical-force error sits on the humps (heel-strike loading, the valley
    and the push-off hump), not spread over the cycle, and above the winner's there; the winner's
    worst vertical-force window is near the floor."""
    point = first.score("point")
    c = first.comparison
    fy = c.measured[:, 0]
    loaded = np.flatnonzero(fy > 0.25 * fy.max())
    t0, t1 = c.time[loaded[0]] - 0.03, c.time[loaded[-1]] + 0.03     # the humps, with their rise and fall
    assert t1 - t0 < 0.7 * (c.time[-1] - c.time[0])
    worst = [w for w in point.worst_windows if w["channel"] == "ground_force_vy"][0]
    assert worst["end"] > t0 and worst["start"] < t1
    r = point.fit.delta[:, 0] + c.residual[:, 0]            # the point contact's own residual
    rb = first.best.fit.delta[:, 0] + c.residual[:, 0]
    inside = (c.time >= t0) & (c.time <= t1)
    assert np.sum(r[inside] ** 2) > 0.6 * np.sum(r ** 2)
    assert np.sum(r[inside] ** 2) > 1.5 * np.sum(rb[inside] ** 2)
    best = [w for w in first.best.worst_windows if w["channel"] == "ground_force_vy"][0]
    assert best["rmse"] < 2 * first.noise_floor["ground_force_vy"] and worst["rmse"] > best["rmse"]


def test_adding_the_winner_reaches_the_noise_floor(loop, first):
    final = loop.final
    assert final.comparison.mode == "contact"
    assert len(final.model.contacts) == 3
    assert {c.target for c in final.model.contacts} == {"heel", "metatarsal", "toe"}
    for ch in CHANNELS:
        assert final.rmse[ch] <= 1.5 * final.noise_floor[ch], ch
    assert final.verdict == "at_noise_floor"
    assert final.best is None
    out = loop.to_dict()
    assert out["added"][0]["effect"] == first.best.label
    assert out["rmse"]["ground_force_vy"] < first.rmse["ground_force_vy"] / 50
    assert "step 1: added" in loop.summary_text()


@pytest.mark.parametrize("add", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["diagnose", "add"])
def test_cli_diagnose_json(tmp_path, foot, capsys, add):
    """``pinmsk diagnose foot2d TRIAL --json`` (CSV keeps no ground speed: a trial on a still plate).

    With ``--add volumetric`` (slow: a second diagnosis refits every candidate) it ends at the
    noise floor; the default suite checks that step through ``run`` (the ``loop`` fixture)."""
    from pinmsk.presentation.cli import main
    from pinmsk.io.tables import write_trial
    tr = synthetic_foot_trial(contact="volumetric", noise=0.003, seed=3, clearance=0.03, ground_speed=0.0)
    path = tmp_path / "foot.csv"
    write_trial(tr, path)
    out = tmp_path / "d.json"
    assert main(["diagnose", "foot2d", str(path), "--json", str(out), "--cutoff", "0",
                 *(["--add", "volumetric"] if add else [])]) == 0
    text = capsys.readouterr().out
    assert "contact-level comparison" in text
    d = json.loads(out.read_text())
    assert {"inputs", "rmse", "noise_floor", "worst_windows", "ranking", "verdict", "added", "noise_model", "refit",
                "pairs", "outside_catalog", "stopping"} <= set(d)
    assert set(d["rmse"]) == set(CHANNELS) | {"total"}
    # the true model class ranks first before adding (the final ranking is relative to the fitted model),
    # and its stiffnesses and radii are recovered
    assert "1. volumetric" in text.split("step 1:")[0]
    if add:
        assert "step 1: added volumetric" in text
        assert d["added"][0]["effect"] == "volumetric"
        assert d["verdict"] == "at_noise_floor"
        fitted = d["added"][0]["params"]
    else:
        assert d["added"] == [] and d["verdict"] == "missing_effect"
        assert d["ranking"][0]["effect"] == "volumetric"
        fitted = d["ranking"][0]["params"]
    for site, true in tr.meta["true_params"].items():
        for name in ("k_v", "R"):
            assert fitted[f"{site}.{name}"] == pytest.approx(true[name], rel=0.05), (site, name)


def test_bad_input(first, trial):
    from pinmsk.model import load_model
    with pytest.raises(TrialError, match="not a kinematically driven foot"):
        compare(load_model("forearm"), trial, mode="contact")
    with pytest.raises(ModelError, match="pick one of: .*point"):
        first.fit("spring")
    with pytest.raises(ModelError, match="candidates= does not apply"):
        diagnose(first.model, trial, cutoff=None, candidates=["joint_damping"])
