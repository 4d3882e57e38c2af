"""Contact identification (thesis Eq. 4.1-4.2), the CSU reader and bad input."""
import json
import math

import numpy as np
import pytest

from pinmsk.contact import ContactFit, fourier_basis, stance_cycle, synthetic_foot_trial
from pinmsk.pipeline import contact_fit_task
from pinmsk.contact.identify import ALL_TERMS, map_values
from pinmsk.errors import ModelError, SolverError, TrialError
from pinmsk.trial import Trial

from conftest import REPO, run_example

CSU = "real/csu-treadmill-leg2d/rawdata.txt"
SITES = ("heel", "metatarsal", "toe")


@pytest.fixture(scope="module")
def synth():
    return synthetic_foot_trial()


@pytest.fixture(scope="module")
def vol_trial():
    """Volumetric spheres (contained exactly in the hyper-volumetric model) with 0.3 % force-plate noise."""
    return synthetic_foot_trial(contact="volumetric", noise=0.003, seed=1)


def _perturbed(true, keys, rel=0.2, seed=1):
    rng = np.random.default_rng(seed)
    upper = {"heel": 0.055, "metatarsal": 0.050, "toe": 0.045}
    out = {}
    for s, p in true.items():
        out[s] = {k: p[k] * (1 + rel * rng.uniform(-1, 1)) for k in keys}
        if "R" in out[s]:
            out[s]["R"] = min(out[s]["R"], upper[s])
        if "v_s" in out[s]:
            out[s]["v_s"] = min(out[s]["v_s"], 0.1)
    return out


def test_fourier_basis_derivative_and_period():
    t = np.linspace(0, 1.3, 400)
    B, dB = fourier_basis(t, 1.3)
    assert B.shape == (400, 11)
    np.testing.assert_allclose(B[0], B[-1], atol=1e-12)  # periodic over the window
    num = np.gradient(B, t, axis=0)
    np.testing.assert_allclose(num[5:-5], dB[5:-5], atol=2e-3 * np.abs(dB).max())


def test_synthetic_trial_is_sane(synth):
    fy = synth["ground_force_vy"]
    assert 300 < fy.max() < 1000
    assert np.all(np.abs(fy[synth.time < 0.3]) < 1.0)  # swing: no force
    px = synth["ground_force_px"]
    lo = fy < 0.02 * fy.max()
    assert np.all(np.isnan(px[lo])) and np.all(np.isfinite(px[~lo]))


def test_hypervolumetric_fit_recovers_known_parameters(synth):
    """All 18 contact parameters from a start 20 % off (toe angle from the kinematics, as generated)."""
    true = synth.meta["true_params"]
    keys = ("k_h", "a_h", "R", "H", "mu_f", "v_s")
    fit = ContactFit(contact="hypervolumetric", cutoff=None, n_starts=1, ftol=1e-10,
                     initial=_perturbed(true, keys)).fit(None, synth)
    assert fit.objective_ < 1e-12
    got = fit.params_()
    for s in true:
        for k in keys:
            assert got[s][k] == pytest.approx(true[s][k], rel=0.02), (s, k)
    np.testing.assert_allclose(fit.fourier_, synth.meta["true_fourier"], atol=1e-4)
    assert fit.rmse_["normal_force"] < 0.5 and fit.rmse_["cop"] < 1e-3
    # Fig. 4.11 study: +10 % stiffness raises the peak normal force, by less than 10 %
    sens = fit.sensitivity()
    assert set(sens) == {"heel", "metatarsal", "toe"}
    assert all(0 <= v["peak_percent"] < 10 for v in sens.values())


def test_volumetric_fit_recovers_known_parameters():
    tr = synthetic_foot_trial(contact="volumetric")
    true = tr.meta["true_params"]
    keys = ("k_v", "a_v", "R")
    fit = ContactFit(contact="volumetric", cutoff=None, n_starts=1, fixed=("mu_f", "v_s"),
                     initial=_perturbed(true, keys, seed=2)).fit(None, tr)
    for s in true:
        for k in keys:
            assert fit.params_()[s][k] == pytest.approx(true[s][k], rel=0.02), (s, k)


def test_one_set_of_terms_for_every_model():
    """Default: all three Eq. 4.2 terms for every contact model (the point contact's friction is
    fitted too); tracking the vertical force only holds the friction pair, which nothing then
    depends on, at its initial value."""
    tr = synthetic_foot_trial(contact="point")
    assert ContactFit().terms == ALL_TERMS
    fit = ContactFit(contact="point", cutoff=None, n_starts=1, max_nfev=3).fit(None, tr)
    assert fit.n_free_ == 18 and fit.objective_ == pytest.approx(fit.objective_full_)
    fn = ContactFit(contact="point", cutoff=None, n_starts=1, max_nfev=60, terms=("normal_force",)).fit(None, tr)
    assert fn.n_free_ == 12 and fn.terms_["normal_force"] == pytest.approx(fn.objective_)
    assert fn.objective_ <= fn.objective_full_
    assert fn.params_()["toe"]["mu_f"] == 0.2 and fn.settings_()["fixed"]["v_s"] == ["heel 0.02", "metatarsal 0.02",
                                                                                     "toe 0.02"]
    with pytest.raises(ModelError, match="terms must be a non-empty subset"):
        ContactFit(terms=("vertical",)).fit(None, tr)


@pytest.mark.parametrize("kind, relax, toe", [("point", False, "kinematic"), ("volumetric", True, "kinematic"),
                                              ("hypervolumetric", False, "kinematic"),
                                              ("hypervolumetric", True, "fit")])
def test_exact_jacobian_matches_finite_differences(synth, kind, relax, toe):
    """The forward-mode Jacobian (the contact laws run on Dual numbers) against central differences,
    at a point away from the thesis values, offsets and toe coefficients included."""
    from scipy.optimize._numdiff import approx_derivative
    fit = ContactFit(contact=kind, relax=relax, toe=toe, cutoff=None, n_starts=1, max_nfev=1).fit(None, synth)
    res = fit.residual_
    rng = np.random.default_rng(5)
    x = np.clip(res.to_x(res.p0) + rng.uniform(-0.1, 0.1, res.p0.size), res.lo_x, res.hi_x)
    J = res.jacobian(x)
    num = approx_derivative(res, x, method="3-point", rel_step=1e-6)
    assert J.shape == (3 * synth.n_frames, res.p0.size) and np.abs(J).max() > 0
    np.testing.assert_allclose(J, num, atol=1e-6 * np.abs(num).max())


def test_dual_numbers_refuse_what_they_cannot_differentiate():
    from pinmsk.contact.dual import Dual
    d = Dual.variables(np.array([0.3, 2.0]))
    y = np.arctan(d[0]) * np.exp(d[1]) / np.sqrt(d[1])
    np.testing.assert_allclose(y.der, [np.exp(2) / np.sqrt(2) / 1.09,
                                       np.arctan(0.3) * np.exp(2) * (2 ** -0.5 - 0.5 * 2 ** -1.5)])
    with pytest.raises(TypeError):
        np.cumsum(d)
    with pytest.raises(TypeError):
        np.sinh(d)
    # tanh is supported (the smooth switches of OpenSim's SmoothSphereHalfSpaceForce)
    np.testing.assert_allclose(np.tanh(d).der, np.diag(1.0 / np.cosh([0.3, 2.0]) ** 2), rtol=1e-14)


def test_nested_starts_contain_the_simpler_models(vol_trial):
    """The hyper-volumetric fit starts from the volumetric and point optima: the volumetric optimum
    maps into it exactly (H = 1), so it ends at least as low; on volumetric data it also beats the
    point contact, whose Hunt-Crossley damping is no limit of Eq. 4.15."""
    fit = ContactFit(cutoff=None, n_starts=3).fit(None, vol_trial)
    vol, point = fit.nested_["volumetric"], fit.nested_["point"]
    assert [lab.split(" (")[0] for lab in fit.start_labels_] == ["initial guess", "volumetric optimum",
                                                                "point optimum"]
    res = fit.residual_
    r = res(res.to_x(res.start(map_values(vol, "hypervolumetric"))))
    assert float(r @ r) == pytest.approx(vol.objective_, rel=1e-9)
    assert fit.objective_ <= vol.objective_ * (1 + 1e-9)
    assert fit.objective_ <= point.objective_ * (1 + 1e-3)
    assert fit.objective_ < 2e-5
    # the volumetric fit started from the point optimum too: one point fit serves both
    assert [lab.split(" (")[0] for lab in vol.start_labels_] == ["initial guess", "point optimum", "random 1"]
    assert vol.nested_["point"] is point
    with pytest.raises(ModelError, match="n_starts must be an integer >= 1"):
        ContactFit(n_starts=0).fit(None, vol_trial)


def test_toe_from_kinematics_keeps_the_toe_tip_on_its_floor(synth):
    from pinmsk.contact import load_foot2d, toe_from_kinematics
    from pinmsk.contact.foot import Foot2dGeometry, foot2d_site_kinematics
    geom = Foot2dGeometry.from_model(load_foot2d())
    q = np.column_stack([synth["ankle_x"], synth["ankle_y"], synth["foot_angle"], np.zeros(synth.n_frames)])
    swing = synth.time < 0.4
    mtp = toe_from_kinematics(geom, q, swing=swing)
    assert np.all(mtp <= 0) and np.all(mtp >= -1.2)
    q[:, 3] = mtp
    kin = foot2d_site_kinematics(geom, q, np.zeros_like(q))
    hT, hP = kin["toe"].position[:, 1], kin["metatarsal"].position[:, 1]
    floor = np.percentile(hP[~swing], 5)
    stance = ~swing
    assert np.all(hT[stance] >= floor - 1e-9)
    up = stance & (mtp < -1e-6)  # extended toes: the tip is exactly on the floor
    assert up.sum() > 5 and np.allclose(hT[up], floor, atol=1e-9)
    assert np.all(hT[swing] >= min(0.05, hT[swing].max()) - 1e-9)  # toes clear in swing


def test_toe_fit_is_bounded_around_the_kinematic_estimate(synth):
    fit = ContactFit(toe="fit", cutoff=None, n_starts=1, max_nfev=20, toe_range=0.01,
                     initial={"heel": {"k_h": 6e5}}).fit(None, synth)
    assert np.all(np.abs(fit.fourier_ - fit.toe_kinematic_) <= 0.01 + 1e-12)
    assert fit.toe_deviation_ <= 11 * 0.01
    assert ContactFit().toe == "kinematic"
    with pytest.raises(ModelError, match="toe_range must be > 0"):
        ContactFit(toe="fit", toe_range=0.0).fit(None, synth)


def test_fit_leaves_blas_threads_as_it_found_them(synth):
    from threadpoolctl import threadpool_info
    before = [d["num_threads"] for d in threadpool_info()]
    ContactFit(cutoff=None, n_starts=2, n_jobs=2, max_nfev=3).fit(None, synth)
    assert [d["num_threads"] for d in threadpool_info()] == before


def test_double_hump_and_load_shares(synth):
    fit = ContactFit(cutoff=None, n_starts=1, max_nfev=3).fit(None, synth)
    sh = fit.load_shares()
    assert set(sh) == {"heel", "metatarsal", "toe"} and sum(sh.values()) == pytest.approx(1.0)
    dh = fit.double_hump()
    assert dh["measured_depth"] == pytest.approx(dh["model_depth_at_measured_events"], abs=0.02)
    t1, tv, t2 = dh["measured_events_s"]
    assert t1 <= tv <= t2


def test_toe_channel_and_flat_modes(synth):
    true = synth.meta["true_params"]
    keys = ("k_h", "R", "H")
    fit = ContactFit(toe="channel", cutoff=None, n_starts=1, fixed=("a_h", "mu_f", "v_s"),
                     initial=_perturbed(true, keys, rel=0.1, seed=4)).fit(None, synth)
    assert fit.params_()["heel"]["k_h"] == pytest.approx(true["heel"]["k_h"], rel=0.02)
    assert fit.n_free_ == 9 and fit.fourier_ is None
    flat = ContactFit(toe="flat", cutoff=None, n_starts=1, max_nfev=5).fit(None, synth)
    assert flat.n_free_ == 18 and len(flat.fourier_) == 11
    with pytest.raises(ModelError, match="toe must be"):
        ContactFit(toe="free").fit(None, synth)


def test_fit_contact_models_fits_each_model_once(synth):
    from pinmsk.contact import fit_contact_models
    from pinmsk.contact.identify import VARIANTS
    fits = fit_contact_models(None, synth, cutoff=None, n_starts=3, max_nfev=10)
    assert list(fits) == list(VARIANTS)
    assert fits[("hypervolumetric", False)].nested_["point"] is fits[("point", False)]
    assert fits[("hypervolumetric", False)].nested_["volumetric"] is fits[("volumetric", False)]
    assert fits[("hypervolumetric", True)].nested_["hypervolumetric"] is fits[("hypervolumetric", False)]


def test_multistart_and_relaxed_run(synth):
    fit = ContactFit(contact="hypervolumetric", relax=True, cutoff=None, n_starts=3, max_nfev=15,
                     seed=3).fit(None, synth)
    assert len(fit.starts_) == 3 and fit.objective_ == pytest.approx(min(fit.starts_), rel=1e-9)
    assert fit.start_labels_[1:] == ["hypervolumetric optimum (dx = dy = 0)", "random 1 (seed 3)"]
    # the relaxed spheres contain the fixed ones: never worse than the fixed-centre optimum
    assert fit.objective_ <= fit.nested_["hypervolumetric"].objective_ * (1 + 1e-9)
    assert all(abs(fit.params_()[s]["dx"]) <= 0.02 for s in ("heel", "metatarsal", "toe"))


def test_fit_cli_run_writes_json_and_plots(synth, tmp_path):
    out = contact_fit_task(None, synth, contact="hypervolumetric", json_path=tmp_path / "fit.json",
                      plot_dir=tmp_path / "plots", n_starts=1, max_nfev=5, cutoff=None)
    data = json.loads((tmp_path / "fit.json").read_text())
    assert set(data) >= {"objective", "params", "rmse", "seconds"}
    assert set(data["rmse"]) == {"normal_force", "friction_force", "cop"}
    assert set(data["params"]) == {"heel", "metatarsal", "toe"} and "k_h" in data["params"]["heel"]
    assert math.isfinite(data["objective"]) and data["seconds"] > 0
    assert all((tmp_path / "plots" / p).exists() for p in ("grf_hypervolumetric.png", "cop_hypervolumetric.png"))
    assert out["objective"] == data["objective"]


# -- bad input --------------------------------------------------------------------

def _with(trial, **cols):
    d = {n: trial[n] for n in trial.names}
    d.update(cols)
    return Trial(trial.time, d, meta=dict(trial.meta))


def test_spheres_that_never_touch_the_ground_are_refused(synth):
    lifted = _with(synth, ankle_y=np.asarray(synth["ankle_y"]) + 0.5)
    with pytest.raises(ModelError, match="never touch the ground.*'heel'.*ankle_y"):
        ContactFit(cutoff=None, n_starts=1).fit(None, lifted)


def test_nan_grf_in_swing_is_refused(synth):
    fy = np.array(synth["ground_force_vy"])
    fy[5] = np.nan
    with pytest.raises(TrialError, match="ground_force_vy.*NaN.*t = 0.05 s.*set them to 0"):
        ContactFit(cutoff=None, n_starts=1).fit(None, _with(synth, ground_force_vy=fy))


def test_undefined_cop_under_load_is_refused(synth):
    px = np.array(synth["ground_force_px"])
    i = int(np.argmax(synth["ground_force_vy"]))
    px[i] = np.nan
    with pytest.raises(TrialError, match="COP.*undefined"):
        ContactFit(cutoff=None, n_starts=1).fit(None, _with(synth, ground_force_px=px))


def test_bounds_excluding_the_initial_guess_are_refused(synth):
    with pytest.raises(SolverError, match=r"initial guess heel.R = 0.05 m is outside its bounds \[0.06, 0.07\]"):
        ContactFit(cutoff=None, bounds={"heel": {"R": (0.06, 0.07)}}).fit(None, synth)
    with pytest.raises(ModelError, match="unknown site"):
        ContactFit(cutoff=None, initial={"ankle": {"R": 0.05}}).fit(None, synth)
    with pytest.raises(ModelError, match="unknown contact model"):
        ContactFit(contact="elastic").fit(None, synth)


def test_missing_channels_are_named(synth):
    with pytest.raises(Exception, match="foot_angle"):
        ContactFit(cutoff=None).fit(None, synth.drop(["foot_angle"]))


# -- CSU data ------------------------------------------------------------------------

def test_csu_reader(shared_data, tmp_path):
    from pinmsk.contact import read_csu_foot2d
    tr = read_csu_foot2d(shared_data / CSU, body_mass=67.2)
    assert tr.n_frames == 301 and tr.rate == pytest.approx(100.0)
    fy, fx = tr["ground_force_vy"], tr["ground_force_vx"]
    mz = tr["ground_moment_origin_z"]
    ok = fy >= 20
    np.testing.assert_allclose(tr["ground_force_px"][ok], mz[ok] / fy[ok])  # belt at y = 0
    assert np.all(np.isnan(tr["ground_force_px"][~ok]))
    assert all(np.all(np.isfinite(tr[c])) for c in ("ankle_x", "ankle_y", "foot_angle"))
    assert tr.meta["filled"]["RLM.PosX"] == 5  # the marker gap near t = 7.45 s
    assert -1.1 < tr.meta["ground_speed"] < -0.8  # belt backwards at ~0.94 m/s
    # belt height shifts heights and the COP (M_z = x F_y - y F_x)
    tr2 = read_csu_foot2d(shared_data / CSU, belt_height=0.01)
    np.testing.assert_allclose(tr2["RHEE_y"], tr["RHEE_y"] - 0.01)
    np.testing.assert_allclose(tr2["ground_force_px"][ok], (mz[ok] + 0.01 * fx[ok]) / fy[ok])
    t0, t1 = stance_cycle(tr)
    assert 7.9 < t0 < 8.1 and 9.1 < t1 < 9.3


def test_csu_reader_bad_file(tmp_path):
    from pinmsk.contact import read_csu_foot2d
    p = tmp_path / "bad.txt"
    p.write_text("TimeStamp\tFP2.ForX\n7.0\t1.0\n")
    with pytest.raises(TrialError, match="header line starting with '%'"):
        read_csu_foot2d(p)
    p.write_text("% TimeStamp\tRLM.PosX\tFP2.ForX\tFP2.ForY\tFP2.MomZ\n7.0\tNaN\t0\t0\t0\n7.01\t1\t0\t0\t0\n")
    with pytest.raises(TrialError, match="RLM.PosX.*edge of the file"):
        read_csu_foot2d(p)


def test_csu_reader_locates_the_foot_from_heel_and_mt5_markers(shared_data):
    """anchor='heel': the heel site follows the heel marker at a constant foot-frame offset, sits at
    heel_height in foot flat and above the measured COP during heel-only loading."""
    from pinmsk.contact import load_foot2d
    from pinmsk.contact.foot import Foot2dGeometry, foot2d_site_kinematics
    from pinmsk.contact import read_csu_foot2d
    tr = read_csu_foot2d(shared_data / CSU)
    assert tr.meta["anchor"] == "heel" and tr.meta["heel_calibration_frames"] >= 5
    ox, oy = tr.meta["heel_offset"]
    assert 0.02 < ox < 0.07 and -0.04 < oy < 0.0  # ahead of and below the skin marker on the heel
    geom = Foot2dGeometry.from_model(load_foot2d())
    th = np.asarray(tr["foot_angle"])
    q = np.column_stack([tr["ankle_x"], tr["ankle_y"], th, np.zeros_like(th)])
    H = foot2d_site_kinematics(geom, q, np.zeros_like(q))["heel"].position
    c, s = np.cos(th), np.sin(th)
    np.testing.assert_allclose(H[:, 0], tr["RHEE_x"] + c * ox + s * oy, atol=1e-12)
    np.testing.assert_allclose(H[:, 1], tr["RHEE_y"] - s * ox + c * oy, atol=1e-12)
    fy = np.asarray(tr["ground_force_vy"])
    flat = fy > 0.5 * fy.max()
    assert np.median(H[flat, 1]) == pytest.approx(0.045, abs=2e-3)
    # the malleolus marker is not the ankle joint: the foot2d ankle sits several cm from it
    assert np.hypot(*tr.meta["ankle_from_marker"]) > 0.02
    # given offset, and the old hanging-from-the-malleolus mode
    tr2 = read_csu_foot2d(shared_data / CSU, heel_offset=(ox, oy))
    np.testing.assert_allclose(tr2["ankle_x"], tr["ankle_x"], atol=1e-12)
    tr3 = read_csu_foot2d(shared_data / CSU, anchor="ankle")
    np.testing.assert_allclose(tr3["ankle_x"], tr3["RLM_x"])
    with pytest.raises(TrialError, match="anchor must be 'heel'"):
        read_csu_foot2d(shared_data / CSU, anchor="knee")


@pytest.mark.slow          # the contact models' nesting is checked on synthetic data by default
def test_real_data_hypervolumetric_is_not_worse_than_what_it_contains(shared_data):
    """CSU trial, the CLI's defaults: the hyper-volumetric fit ends below the volumetric one (contained
    exactly) and below the undamped point contact (contained in the small-penetration limit).  The
    damped point contact ends lower still (J 0.097 against 0.100): its Hunt-Crossley damping
    k_s a_s d^n v, with n as low as 0.3, is no limit of Eq. 4.15's a_h V v."""
    from pinmsk.contact import read_csu_foot2d
    tr = read_csu_foot2d(shared_data / CSU)
    fit = ContactFit().fit(None, tr)
    assert fit.window_ == pytest.approx((7.99, 9.18)) and fit.settings_()["window_source"].startswith("one cycle")
    vol = fit.nested_["volumetric"]
    assert fit.objective_ <= vol.objective_ * (1 + 1e-9)
    undamped = ContactFit(contact="point", fixed=("a_s",), initial={s: {"a_s": 0.0} for s in SITES}).fit(None, tr)
    assert fit.objective_ <= undamped.objective_ * (1 + 1e-3)
    assert fit.objective_ < 0.105 and fit.load_shares()["heel"] > 0.2  # the heel sphere carries load
    assert fit.seconds_ < 20


def test_example_05_runs_headless(tmp_path):
    run_example("05_contact_identification.py", "--quick", "--toe", "flat", "--out", tmp_path)
    summary = json.loads((tmp_path / "contact_summary.json").read_text())
    assert len(summary["fits"]) == 4 and all("(toe flat)" in k for k in summary["fits"])
    assert len(summary["sensitivity"]) == 3  # volumetric, hyper-volumetric, relaxed
    assert all(set(v) == {"heel", "metatarsal", "toe"} for v in summary["sensitivity"].values())
    assert set(summary["double_hump"]) == set(summary["fits"])
    assert (tmp_path / "toe_flat" / "grf_hypervolumetric_relaxed.png").exists()


def test_fit_cli_run_from_files(shared_data, tmp_path):
    """The CLI path: model by name, trial as the CSU file, the library's defaults (one cycle)."""
    out = contact_fit_task("foot2d", shared_data / CSU, contact="volumetric", json_path=tmp_path / "o.json",
                      n_starts=1, max_nfev=3)
    assert out["window"][0] == pytest.approx(7.99) and math.isfinite(out["objective"])
    assert json.loads((tmp_path / "o.json").read_text())["params"]["toe"]["R"] <= 0.045
    st = out["settings"]
    assert st["cutoff_hz"] == 12.0 and st["terms"] == list(ALL_TERMS) and st["toe"] == "kinematic"
    assert "heel and 5th-metatarsal markers" in st["foot_placement"]


def test_cli_prints_the_settings(vol_trial, tmp_path, capsys):
    from pinmsk.presentation.cli import main
    from pinmsk.io.tables import write_trial
    path = tmp_path / "foot.csv"
    write_trial(vol_trial, path)
    assert main(["contact", "fit", "foot2d", str(path), "--contact", "point", "--starts", "2", "--cutoff", "0",
                 "--terms", "normal_force"]) == 0
    text = capsys.readouterr().out
    for line in ("settings: point contact, Eq. 4.2 terms: normal_force",
                 "(101 frames; whole trial (it holds fewer than two toe-offs)); kinematics: none (GRF unfiltered)",
                 "foot placement: the trial's ankle_x, ankle_y, foot_angle channels",
                 "toe angle: identified from the kinematics beforehand, held fixed",
                 "free (12): k_s; n_s; a_s; L0", "fixed: mu_f = heel 0.2, metatarsal 0.2, toe 0.2;",
                 "starts (2): initial guess (thesis Table 4.2); random 1 (seed 0); jacobian exact",
                 "start 1, initial guess (thesis Table 4.2): J", "point contact fitted in"):
        assert line in text, line
    assert main(["contact", "fit", "foot2d", str(path), "--starts", "0"]) == 2
    assert "pinmsk: error: ContactFit: n_starts must be an integer >= 1, got 0" in capsys.readouterr().err


def test_csu_reader_needs_the_foot_models_heel_site_to_anchor_by_the_heel(tmp_path):
    """The reader (io) knows no model: anchoring by the heel needs the site, named in the error."""
    from pinmsk.io.cleveland_gait import read_csu
    with pytest.raises(TrialError, match="heel_site=.*read_csu_foot2d"):
        read_csu(tmp_path / "walk.txt")


def test_ground_speed_is_given_or_its_source_is_said(synth):
    """A treadmill's belt speed is an input: given, it is used; else the trial's, else 0, and the settings say which."""
    from pinmsk.contact.identify import settings_lines

    fit = dict(contact="point", n_starts=1, max_nfev=3, cutoff=None)
    given = contact_fit_task(None, synth, ground_speed=0.4, **fit)["settings"]
    assert given["ground_speed"] == 0.4 and given["ground_speed_source"] == "given"
    assert "(given)" in "\n".join(settings_lines(given))
    own = contact_fit_task(None, synth, **fit)["settings"]
    assert synth.meta["ground_speed"] == -1.0                      # the synthetic treadmill's belt
    assert own["ground_speed"] == -1.0 and own["ground_speed_source"] == "the trial's"
    channels = synth.to_dict()
    channels.pop("time")
    bare = Trial(synth.time, channels, meta={k: v for k, v in synth.meta.items() if k != "ground_speed"})
    none = contact_fit_task(None, bare, **fit)["settings"]
    assert none["ground_speed"] == 0.0 and "overground" in none["ground_speed_source"]
