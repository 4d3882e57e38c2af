"""Golden-file regression tests: today's results on shipped trials against stored reference values.

In the habit of lmfit's ``tests/test_NIST_Strd.py`` (certified values, a stated agreement): each case
runs one public command -- ``pinmsk id``, ``so``, ``fso``, ``diagnose --json`` and ``contact fit
--json`` -- on a trial shipped in ``data/`` (the contact fit on ``tests/golden/inputs/``, as no foot
trial ships in ``data/``) and compares the numbers with ``tests/golden/<case>.json`` within
tolerances set by the numerics of that command (each is justified where it is defined).  The
commands spell out the options whose defaults may change on purpose (the low-pass
cut-off), so a deliberate change of a default does not move the goldens; the defaults are tested
elsewhere.  Where the trial hides a known effect, the fresh result is also checked against that
truth, so a refresh cannot enshrine a wrong answer.  ``tests/golden/README.md`` says how each file
was made.

Refresh the files on purpose (after a change that is meant to move the numbers)::

    PINMSK_REFRESH_GOLDEN=1 python -m pytest -p no:cacheprovider tests/test_golden.py

rewrites every file and then FAILS each case with "refreshed ..." (review ``git diff tests/golden``
and rerun without the variable), so a refresh never passes silently; it is refused where the
``CI`` environment variable is set.
"""
from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

import pinmsk

from conftest import REPO, run_pinmsk

GOLDEN = Path(__file__).resolve().parent / "golden"
REFRESH_VAR = "PINMSK_REFRESH_GOLDEN"
DIGITS = 10   # significant digits stored: rounding (5e-11 relative) stays far below every tolerance


# ---------------------------------------------------------------------------- storing and refreshing


def _rounded(x):
    """``x`` with every float rounded to DIGITS significant digits (JSON-ready; NaN/inf refused)."""
    if isinstance(x, dict):
        return {k: _rounded(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_rounded(v) for v in x]
    if isinstance(x, (float, np.floating)):
        assert math.isfinite(x), "a golden number must be finite"
        return float(f"{float(x):.{DIGITS}g}")
    if isinstance(x, np.integer):
        return int(x)
    return x


def _dumps(obj) -> str:
    """JSON with one key per line but each list of numbers or strings on one line (small, diffable files)."""
    text = json.dumps(obj, indent=1)
    return re.sub(r"\[[^\[\]{}]*\]", lambda m: "[" + ", ".join(x.strip() for x in m[0][1:-1].split(",\n")) + "]",
                  text) + "\n"


def _golden(name: str, fresh: dict) -> dict:
    """The stored golden ``name``; with PINMSK_REFRESH_GOLDEN=1, write ``fresh`` there instead and fail."""
    path = GOLDEN / name
    if os.environ.get(REFRESH_VAR):
        if os.environ.get("CI"):
            pytest.fail(f"{REFRESH_VAR} is set under CI (CI={os.environ['CI']!r}): goldens are refreshed "
                        "by hand and reviewed, never in CI")
        path.write_text(_dumps(_rounded(fresh)), encoding="utf-8")
        pytest.fail(f"refreshed {path.relative_to(REPO)} ({REFRESH_VAR} is set): review `git diff "
                    f"tests/golden`, then rerun without {REFRESH_VAR}")
    if not path.exists():
        pytest.fail(f"golden file {path.relative_to(REPO)} is missing; write it on purpose with "
                    f"{REFRESH_VAR}=1 python -m pytest tests/test_golden.py")
    return json.loads(path.read_text(encoding="utf-8"))


def _close(got, want, *, rtol: float, atol: float, where: str):
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    assert got.shape == want.shape, f"{where}: shape {got.shape}, golden {want.shape}"
    bad = ~(np.abs(got - want) <= atol + rtol * np.abs(want))
    if bad.any():
        i = int(np.flatnonzero(bad.ravel())[0])
        g, w = float(got.ravel()[i]), float(want.ravel()[i])
        pytest.fail(f"{where}: {int(bad.sum())} of {bad.size} values differ from the golden beyond "
                    f"rtol {rtol:g} + atol {atol:g}; first at index {i}: {g!r} vs golden {w!r} "
                    f"(difference {g - w:.3g})")


# ---------------------------------------------------------------------------- trial results (id, so, fso)


def _trial_record(command: list, trial, *, stride: int, skip=()) -> dict:
    """What a golden of a result trial holds: the command, every ``stride``-th frame of each channel,
    and each channel's RMS, min and max over all frames (so a change between stored frames shows too)."""
    names = [n for n in trial.names if n not in skip]
    rows = slice(0, None, stride)
    values = {n: np.asarray(trial[n], dtype=float) for n in names}
    return {"command": command, "frames": int(trial.n_frames), "stride": stride,
            "time": np.asarray(trial.time, dtype=float)[rows].tolist(),
            "values": {n: v[rows].tolist() for n, v in values.items()},
            "summary": {n: {"rms": float(np.sqrt(np.mean(v ** 2))), "min": float(v.min()), "max": float(v.max())}
                        for n, v in values.items()}}


#: absolute floor of every trial tolerance (in the channel's SI unit): a channel that is zero up to
#: round-off (FSO's idle triceps carry -7e-13 N) is not held to a fraction of that round-off
ROUND_OFF_FLOOR = 1e-9


def _compare_trial(fresh: dict, gold: dict, *, rtol: float, peak_atol: float, exact=()):
    """Every channel within ``rtol`` relative plus ``peak_atol`` x the channel's peak |value| (so values
    crossing zero are not held to a relative tolerance; at least ROUND_OFF_FLOOR); the channels in
    ``exact`` must match exactly."""
    assert fresh["command"] == gold["command"]
    assert fresh["frames"] == gold["frames"] and fresh["stride"] == gold["stride"]
    assert list(fresh["values"]) == list(gold["values"]), "the result has other channels than the golden"
    _close(fresh["time"], gold["time"], rtol=0.0, atol=1e-9, where="time")
    for name, want in gold["values"].items():
        s = gold["summary"][name]
        atol = max(peak_atol * max(abs(s["min"]), abs(s["max"])), ROUND_OFF_FLOOR)
        if name in exact:
            assert fresh["values"][name] == want, f"{name} differs from the golden"
            continue
        _close(fresh["values"][name], want, rtol=rtol, atol=atol, where=name)
        for key in ("rms", "min", "max"):
            _close(fresh["summary"][name][key], s[key], rtol=rtol, atol=atol, where=f"{name} {key}")


def _in_repo(command: list) -> list:
    """``command`` with its repository-relative file arguments (``data/...``, ``tests/...``) made absolute."""
    return [str(REPO / c) if c.startswith(("data/", "tests/")) else c for c in command]


def _run_trial_command(tmp_path, command: list) -> "pinmsk.Trial":
    out = tmp_path / "result.csv"
    run_pinmsk(*_in_repo(command), "-o", out, "--precision", "17")
    return pinmsk.read_trial(out)


# Inverse dynamics is a fixed chain -- zero-lag Butterworth, quintic-spline derivatives, RNEA -- in
# float64.  Perturbing the input trials by 1e-12 relative moves the moments by at most 7e-10 of the
# channel peak (gait2d torso_y; 2e-11 on the forearm), so agreement to 1e-6 relative plus 1e-7 of
# the peak leaves two orders of margin for other BLAS/LAPACK builds, while any modelling change is
# far larger (1 g more in the hand moves the forearm moment by 3.5e-3 N m, 8e-4 of its peak).
ID_RTOL, ID_PEAK_ATOL = 1e-6, 1e-7

ID_CASES = {   # golden file: (model, shipped trial, stride)
    "id_forearm_payload.json": ("forearm", "forearm_payload.csv", 20),
    "id_gait2d_hat_mass.json": ("gait2d", "gait2d_hat_mass.csv", 40),   # GRF on both feet, floating base
}


@pytest.mark.parametrize("name", sorted(ID_CASES))
def test_inverse_dynamics_matches_golden(name, tmp_path):
    model, trial, stride = ID_CASES[name]
    command = ["id", model, f"data/{trial}", "--cutoff", "6"]
    result = _run_trial_command(tmp_path, command)
    assert {f"{c}_moment" for c in pinmsk.load_model(model).coordinates} <= set(result.names)
    # the moments only: the coordinate channels repeat the input
    fresh = _trial_record(command, result, stride=stride, skip=pinmsk.load_model(model).coordinates)
    _compare_trial(fresh, _golden(name, fresh), rtol=ID_RTOL, peak_atol=ID_PEAK_ATOL)


# Static optimization solves one strictly convex QP per frame (sum F^2, or sum a^2 in activation
# mode) to 1e-9 of each dof's moment capacity, so the optimum is unique; 1e-12 input perturbations
# move forces, activations and reserves by at most 7e-10 of their peak.  A solver that stops
# elsewhere inside its tolerance moves a force by ~1e-9 x capacity / moment arm (~5e-6 N on the
# forearm), so: 1e-6 relative plus 1e-6 of the channel's peak.  `status` (the per-frame solver path
# code) must match exactly; `violation` (|R^T F - tau|, round-off size) is not stored but bounded.
SO_RTOL, SO_PEAK_ATOL = 1e-6, 1e-6

SO_CASES = {   # golden file: (model, shipped trial, extra options, stride)
    "so_forearm_payload_activation.json": ("forearm", "forearm_payload.csv", ["--mode", "activation"], 50),
    "so_gait2d_hat_mass_reserves.json": ("gait2d", "gait2d_hat_mass.csv", ["--reserves"], 60),
}


@pytest.mark.parametrize("name", sorted(SO_CASES))
def test_static_optimization_matches_golden(name, tmp_path):
    model, trial, extra, stride = SO_CASES[name]
    command = ["so", model, f"data/{trial}", "--cutoff", "6", *extra]
    result = _run_trial_command(tmp_path, command)
    assert np.max(np.abs(result["violation"])) < 1e-6          # N m: every frame balanced
    # in force mode the activations follow from the forces; activation mode stores them
    skip = ["violation"] + ([n for n in result.names if n.endswith("_activation")] if "activation" not in extra else [])
    fresh = _trial_record(command, result, stride=stride, skip=skip)
    _compare_trial(fresh, _golden(name, fresh), rtol=SO_RTOL, peak_atol=SO_PEAK_ATOL, exact=("status",))


# Forward static optimization chains 400 RK4 steps and 100 QPs, each QP's forces driving the next
# state, so differences can grow along the trial (the PID tracking keeps them bounded).  Measured:
# 1e-12 input perturbations move every channel by <= 6e-11 of its peak.  The tolerance is ten times
# SO's for that accumulation: 1e-5 relative plus 1e-5 of the peak (2e-4 N on BRA, 2e-5 rad on the
# angle) -- still well below a change of the model (1 g in the hand: 8e-4 of the moment peak).
FSO_RTOL, FSO_PEAK_ATOL = 1e-5, 1e-5


def test_forward_static_optimization_matches_golden(tmp_path):
    command = ["fso", "forearm", "data/forearm_payload.csv", "--cutoff", "6"]
    result = _run_trial_command(tmp_path, command)
    assert np.max(np.abs(result["elbow_flexion_error"])) < math.radians(1.0)   # it tracks the trial
    # force mode: the activations follow from the forces
    fresh = _trial_record(command, result, stride=25, skip=[n for n in result.names if n.endswith("_activation")])
    _compare_trial(fresh, _golden("fso_forearm_payload.json", fresh), rtol=FSO_RTOL, peak_atol=FSO_PEAK_ATOL)


# ---------------------------------------------------------------------------- diagnosis JSON


# The diagnosis is deterministic: residuals and their RMS from the ID chain above, a noise floor from
# third differences plus 3 seeded Monte-Carlo realisations, least-squares effect fits (jointly with the
# effects added before), 5-fold blocked cross-validation.  1e-12 input perturbations move its numbers by
# <= 3e-8 relative (re-measured after the joint refit: <= 3e-11, a parameter at a bound or without a
# standard error by <= 1e-7), so RMSE, noise floor and windows are held to 1e-6 relative and explained
# fractions to 1e-6.  A fitted parameter may sit anywhere inside the
# optimizer's stopping tolerance, which is tiny beside its statistical uncertainty: 1e-3 of its
# standard error (plus 1e-6 relative); a parameter without one (at a bound, or not identifiable:
# stored as null) gets 1e-4 relative; a fit with a parameter flagged not identifiable is held to that
# flag, not to its numbers (_compare_fit).  Standard errors come from the Jacobian at the optimum: 1e-4
# relative.  The ranking order, the verdict and every yes/no must match exactly.
DX_RTOL, DX_FRACTION_ATOL, DX_STDERR_SHARE, DX_FREE_RTOL, DX_STDERR_RTOL = 1e-6, 1e-6, 1e-3, 1e-4, 1e-4

DIAGNOSE_CASES = {   # golden file: (model, shipped trial, --add steps)
    "diagnose_forearm_payload.json": ("forearm", "forearm_payload.csv", []),
    "diagnose_forearm_payload_damping_loop.json": ("forearm", "forearm_payload_damping.csv",
                                                   ["payload:hand", "joint_damping"]),
    "diagnose_gait2d_hat_mass.json": ("gait2d", "gait2d_hat_mass.csv", []),
}

# data/README.md: the hidden effects, and what the diagnosis must find (within a few per cent)
TRUTH = {
    "diagnose_forearm_payload.json": {"best": ("payload", "hand", "mass", 1.0), "verdict": "missing_effect"},
    "diagnose_gait2d_hat_mass.json": {"best": ("segment_mass", "hat", "delta", 0.1), "verdict": "missing_effect"},
    "diagnose_forearm_payload_damping_loop.json": {
        "added": [("payload", "hand", "mass", 0.5), ("joint_damping", "elbow_flexion", "c", 0.2)],
        "verdict": "at_noise_floor"},
}


def _compare_fit(fresh: dict, gold: dict, where: str):
    """Fitted ``params`` within DX_STDERR_SHARE of their standard error, ``stderr`` within DX_STDERR_RTOL."""
    assert list(fresh["params"]) == list(gold["params"]), f"{where}: other parameters than the golden"
    flags = gold.get("identifiability", {}).get("flags") or []
    if any("is not identifiable" in f for f in flags):
        # a fit the data leave free in some direction: where the optimizer stops along it, and so every
        # parameter and standard error of the fit, is rounding on this machine's BLAS (passive_elastic's
        # theta_0 at 1e-7 rad on one machine, 5e-10 on another, k_hi's standard error 3.6 against 88);
        # the golden holds that the fit is reported unidentifiable, with the same parameters, and its
        # explained fraction and residuals (compared by the caller), not those numbers
        assert fresh["identifiability"]["identifiable"] is False, f"{where}: identifiable now"
        assert sorted(f for f in fresh["identifiability"]["flags"] if "is not identifiable" in f), \
            f"{where}: no parameter flagged unidentifiable now"
        return
    for k, want in gold["params"].items():
        se = gold["stderr"].get(k)               # a parameter the fit holds (vary=False) has no error
        assert (k in fresh["stderr"]) == (k in gold["stderr"]), f"{where} {k}: held by one fit, not the other"
        assert (fresh["stderr"].get(k) is None) == (se is None), f"{where} {k}: stderr null-ness differs"
        # a held parameter taken from the data (an end stop's limit at a motion's zero) is compared above
        # the round-off floor: 1e-16 and 5e-23 are the same zero
        atol = DX_STDERR_SHARE * se if se is not None else ROUND_OFF_FLOOR
        rtol = DX_RTOL if se is not None else DX_FREE_RTOL
        _close(fresh["params"][k], want, rtol=rtol, atol=atol, where=f"{where} {k}")
        if se is not None:
            _close(fresh["stderr"][k], se, rtol=DX_STDERR_RTOL, atol=0.0, where=f"{where} stderr {k}")


def _tie_groups(ranking) -> list:
    """The ranking as consecutive groups (sets) of candidates whose explained fractions tie."""
    groups, last = [], None
    for r in ranking:
        key = (r["effect"], r["target"])
        if last is not None and abs(r["explained_fraction"] - last) < DX_FRACTION_ATOL:
            groups[-1].add(key)
        else:
            groups.append({key})
        last = r["explained_fraction"]
    return groups


def _compare_diagnosis(fresh: dict, gold: dict):
    assert fresh["command"] == gold["command"]
    assert fresh["verdict"] == gold["verdict"]
    assert fresh["inputs"] == gold["inputs"]
    for key in ("rmse", "noise_floor"):
        assert list(fresh[key]) == list(gold[key]), f"{key}: other channels than the golden"
        _close(list(fresh[key].values()), list(gold[key].values()), rtol=DX_RTOL, atol=0.0, where=key)
    assert [(w["channel"], w["start"], w["end"]) for w in fresh["worst_windows"]] == \
        [(w["channel"], w["start"], w["end"]) for w in gold["worst_windows"]]
    _close([w["rmse"] for w in fresh["worst_windows"]], [w["rmse"] for w in gold["worst_windows"]],
           rtol=DX_RTOL, atol=0.0, where="worst_windows rmse")
    order = [(r["effect"], r["target"]) for r in fresh["ranking"]]
    # candidates the golden ranks as a tie (explained fractions within DX_FRACTION_ATOL: aliases such as
    # a sensor gain and a segment mass on a one-body model, equal to ~1e-10) may come in either order
    assert _tie_groups(fresh["ranking"]) == _tie_groups(gold["ranking"]), f"ranking order now {order}"
    by_key = {(r["effect"], r["target"]): r for r in fresh["ranking"]}
    for want in gold["ranking"]:
        got = by_key[(want["effect"], want["target"])]
        where = f"ranking {want['effect']}:{want['target']}"
        assert got["significant"] == want["significant"], f"{where}: significant"
        _close(got["explained_fraction"], want["explained_fraction"], rtol=0.0, atol=DX_FRACTION_ATOL,
               where=f"{where} explained_fraction")
        assert list(got["rmse_after"]) == list(want["rmse_after"])
        _close(list(got["rmse_after"].values()), list(want["rmse_after"].values()), rtol=DX_RTOL, atol=0.0,
               where=f"{where} rmse_after")
        _compare_fit(got, want, where)
    assert [(a["effect"], a["target"]) for a in fresh["added"]] == [(a["effect"], a["target"]) for a in gold["added"]]
    for got, want in zip(fresh["added"], gold["added"]):
        _compare_fit(got, want, f"added {want['effect']}:{want['target']}")
    assert set(fresh) == set(gold), f"JSON keys now {sorted(fresh)}, golden {sorted(gold)}"
    # the floating-base residuals of each step: inverse dynamics, deterministic (1e-6 N or N m)
    rf, rg = fresh["residual_report"], gold["residual_report"]
    assert (rf is None) == (rg is None), "residual_report null-ness differs"
    for sf, sg in zip((rf or {}).get("steps", ()), (rg or {}).get("steps", ())):
        assert sf["model"] == sg["model"] and list(sf["coordinates"]) == list(sg["coordinates"])
        for c, want in sg["coordinates"].items():
            got = sf["coordinates"][c]
            assert got["status"] == want["status"], f"residual_report step {sg['step']} {c}: status"
            _close([got[k] for k in ("mean", "rms", "peak")], [want[k] for k in ("mean", "rms", "peak")],
                   rtol=DX_RTOL, atol=1e-6, where=f"residual_report step {sg['step']} {c}")


def _check_truth(name: str, js: dict):
    truth = TRUTH[name]
    assert js["verdict"] == truth["verdict"]
    if "best" in truth:
        effect, target, param, value = truth["best"]
        best = next(r for r in js["ranking"] if r["significant"])
        assert (best["effect"], best["target"]) == (effect, target)
        assert best["params"][param] == pytest.approx(value, rel=0.05)
    for a, (effect, target, param, value) in zip(js["added"], truth.get("added", ())):
        assert (a["effect"], a["target"]) == (effect, target)
        assert a["params"][param] == pytest.approx(value, rel=0.05)


@pytest.mark.parametrize("name", sorted(DIAGNOSE_CASES))
def test_diagnosis_json_matches_golden(name, tmp_path):
    model, trial, add = DIAGNOSE_CASES[name]
    command = ["diagnose", model, f"data/{trial}", "--cutoff", "6", *[x for e in add for x in ("--add", e)]]
    out = tmp_path / "diagnosis.json"
    run_pinmsk(*_in_repo(command), "--json", out)
    fresh = {"command": command, **json.loads(out.read_text())}
    _check_truth(name, fresh)
    _compare_diagnosis(fresh, _golden(name, fresh))


# ---------------------------------------------------------------------------- contact fit


# ContactFit minimises Eq. 4.2 over 18 sphere parameters from 4 starts; each start stops when a step
# lowers J by less than ftol = 1e-6 of J.  Measured on this trial: the four starts reach the same J
# within 1.4e-8 relative, and tightening ftol to 1e-10 lowers J by 1.5e-9 and the AIC by 5e-7, while
# it moves the fitted parameters by up to 6.7e-4 relative (toe stiffness: the objective is flat
# along stiffness-damping ridges) and the COP RMSE by 2.4e-4.  So: J, its terms, AIC and BIC tight
# (1e-6 relative; the AIC, n ln J + 2k, to 1e-3 absolute), each parameter within 2e-3 of the largest
# |value| that parameter takes over the three spheres (a damping that ends near zero at one sphere
# is judged on the scale of the others), RMSEs within 1e-3 relative, load shares within 1e-4.
CF_RTOL, CF_IC_ATOL, CF_PARAM_SHARE, CF_RMSE_RTOL, CF_SHARE_ATOL = 1e-6, 1e-3, 2e-3, 1e-3, 1e-4
CF_INPUT = "tests/golden/inputs/foot2d_step_in_place.csv"
CF_KEYS = ("contact", "relax", "toe", "objective", "objective_full", "terms", "params", "toe_fourier",
           "load_shares", "rmse", "n_free", "aic", "bic", "converged", "starts", "start_labels", "nested",
           "ground_speed", "window", "settings")   # not "seconds" (a timing), "nfev" or "best_start"
# (the optimizer's path: the starts reach the same J within 1.4e-8, so which one wins is a coin toss)


def test_contact_fit_matches_golden(tmp_path):
    command = ["contact", "fit", "foot2d", CF_INPUT, "--cutoff", "0"]   # noise-free kinematics: no low-pass
    out = tmp_path / "contact.json"
    run_pinmsk(*_in_repo(command), "--json", out)
    raw = json.loads(out.read_text())
    fresh = {"command": command, **{k: raw[k] for k in CF_KEYS}}
    # truth (tests/golden/README.md: hyper-volumetric spheres of thesis Tables 4.2-4.4): the well
    # identified parameters are recovered, the fit reaches the force-plate noise (1 % of the peak)
    p = fresh["params"]
    assert p["heel"]["R"] == pytest.approx(0.05, abs=5e-4) and p["metatarsal"]["R"] == pytest.approx(0.049, abs=1e-3)
    assert p["heel"]["mu_f"] == pytest.approx(0.2, rel=0.02)
    assert p["metatarsal"]["mu_f"] == pytest.approx(0.22, rel=0.05)
    peak = np.nanmax(pinmsk.read_trial(REPO / CF_INPUT)["ground_force_vy"])
    assert fresh["rmse"]["normal_force"] < 1.2 * 0.01 * peak   # down to the force-plate noise, 1 % of the peak
    gold = _golden("contact_fit_foot2d_step_in_place.json", fresh)

    for key in ("command", "contact", "relax", "toe", "n_free", "converged", "start_labels", "window",
                "settings", "ground_speed"):
        assert fresh[key] == gold[key], f"{key}: {fresh[key]!r}, golden {gold[key]!r}"
    _close(fresh["objective"], gold["objective"], rtol=CF_RTOL, atol=0.0, where="objective")
    _close(fresh["objective_full"], gold["objective_full"], rtol=CF_RTOL, atol=0.0, where="objective_full")
    assert list(fresh["terms"]) == list(gold["terms"])
    _close(list(fresh["terms"].values()), list(gold["terms"].values()), rtol=CF_RTOL, atol=1e-12, where="terms")
    _close([fresh["aic"], fresh["bic"]], [gold["aic"], gold["bic"]], rtol=0.0, atol=CF_IC_ATOL, where="aic, bic")
    _close(fresh["starts"], gold["starts"], rtol=CF_RTOL, atol=0.0, where="objective of each start")
    assert list(fresh["nested"]) == list(gold["nested"])
    _close(list(fresh["nested"].values()), list(gold["nested"].values()), rtol=CF_RTOL, atol=0.0,
           where="nested models' objectives")
    _close(fresh["toe_fourier"], gold["toe_fourier"], rtol=1e-9, atol=1e-12, where="toe_fourier")  # a linear fit
    assert list(fresh["params"]) == list(gold["params"])
    for site, params in gold["params"].items():
        assert list(fresh["params"][site]) == list(params), f"{site}: other parameters than the golden"
        for k, want in params.items():
            scale = max(abs(gold["params"][s][k]) for s in gold["params"])
            _close(fresh["params"][site][k], want, rtol=0.0, atol=CF_PARAM_SHARE * scale, where=f"{site}.{k}")
    _close(list(fresh["rmse"].values()), list(gold["rmse"].values()), rtol=CF_RMSE_RTOL, atol=0.0, where="rmse")
    _close(list(fresh["load_shares"].values()), list(gold["load_shares"].values()), rtol=0.0, atol=CF_SHARE_ATOL,
           where="load_shares")
