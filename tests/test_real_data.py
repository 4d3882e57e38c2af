"""Case studies on the real data in ../shared/data (skipped when absent).

Numbers asserted here are the measured ones with margins; see the examples for the full tables.
"""
import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import pinmsk
from pinmsk import TrialError
from pinmsk.io.trc import read_trc

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "examples"))


@pytest.fixture
def real(shared_data):
    d = shared_data / "real"
    if not d.is_dir():
        pytest.skip("../shared/data/real is absent")
    return d


@pytest.mark.parametrize("rel,rate,n_markers,frames", [
    ("opensim-moco-walk-emg/markers_walk.trc", 100.0, 41, 238),
    ("bmclab-walk-cortex/walk1.trc", 150.0, 28, 364),
    ("bmclab-walk-cortex/walk2.trc", 150.0, 28, 251),      # 27 virtual markers without data dropped
    ("pyomeca-box-lift-emg/markers.trc", 100.0, 51, 93),   # comma-separated excerpt, NumFrames=652
])
def test_real_trc_files(real, rel, rate, n_markers, frames):
    p = real / rel
    if not p.exists():
        pytest.skip(f"{rel} absent")
    tr = read_trc(p)
    assert len(tr.meta["markers"]) == n_markers and tr.n_frames == frames
    assert tr.rate == pytest.approx(rate, rel=1e-6)
    assert tr.meta["units"] == "mm"
    # metres: a walking person's markers lie within a few metres and heights below 2 m
    ys = np.array([np.nanmax(tr[f"{m}_y"]) for m in tr.meta["markers"]])
    assert 0.5 < np.nanmax(ys) < 2.0


def _read_moco(real, name: str) -> pinmsk.Trial:
    """``opensim-moco-walk-emg/<name>``, read leniently (the Moco headers are sloppy); skip when absent."""
    folder = real / "opensim-moco-walk-emg"
    if not folder.is_dir():
        pytest.skip("opensim-moco-walk-emg absent")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pinmsk.read_trial(folder / name, strict=False)


def test_real_wrong_sign_force_plate_is_detected(real):
    from pinmsk.grf import check_vertical_force
    grf = _read_moco(real, "grf_walk.mot")
    check_vertical_force(grf, body_mass=84.0)
    d = grf.to_dict(); d.pop("time")
    d["ground_force_l_vy"] = -d["ground_force_l_vy"]
    with pytest.raises(TrialError, match="'ground_force_l_vy'.*negative during stance"):
        check_vertical_force(pinmsk.Trial(grf.time, d))


def test_real_emg_rate_checks(real):
    from pinmsk.signals.sampling import check_rate
    emg = _read_moco(real, "electromyography.sto")
    assert check_rate(emg, 2000.0, what="EMG") == pytest.approx(2000.0, rel=1e-6)
    with pytest.raises(TrialError, match="stated to be sampled at 1000 Hz"):
        check_rate(emg, 1000.0, what="EMG")


def test_real_c3d_markers_analogs(real):
    pytest.importorskip("ezc3d")
    p = real / "pyomeca-box-lift-emg" / "markers_analogs.c3d"
    if not p.exists():
        pytest.skip("c3d absent")
    from pinmsk.io.c3d import read_c3d
    from pinmsk.signals.emg import envelopes
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = read_c3d(p)
    assert d.markers.n_frames == 580 and len(d.markers.meta["markers"]) == 51
    assert d.markers.rate == pytest.approx(100.0) and d.analogs.rate == pytest.approx(2000.0)
    assert "Biceps.EMG4" in d.analogs.names and d.analogs.n_frames == 11600
    env = envelopes(d.analogs, channels=["Biceps.EMG4", "Triceps.EMG5"], stated_rate=2000.0)
    assert np.all(env.values >= 0) and np.max(env["Biceps.EMG4"]) > 0


def test_rajagopal_case_study(real, tmp_path):
    if not (real / "opensim-moco-walk-emg").is_dir():
        pytest.skip("opensim-moco-walk-emg absent")
    import gait_rajagopal
    assert gait_rajagopal.main(["--out", str(tmp_path), "--data", str(real.parent)]) == 0
    res = json.loads((tmp_path / "gait_rajagopal.json").read_text())
    ido = res["id_vs_opensim"]
    assert set(ido) == {"hip", "knee", "ankle"} and set(ido["hip"]) == {"r", "l"}
    for s in "rl":
        assert ido["ankle"][s]["correlation"] > 0.97 and ido["ankle"][s]["rms_difference_nm_per_kg"] < 0.25
        assert ido["knee"][s]["correlation"] > 0.9 and ido["knee"][s]["rms_difference_nm_per_kg"] < 0.2
        assert ido["hip"][s]["correlation"] > 0.88 and ido["hip"][s]["rms_difference_nm_per_kg"] < 0.3
    so = res["so_vs_emg"]
    assert set(so) == {"soleus", "gastrocnemius", "tibialis_anterior", "hamstrings", "vasti",
                       "rectus_femoris", "glutei"}
    assert so["soleus"]["correlation"] > 0.7 and so["gastrocnemius"]["correlation"] > 0.7
    assert res["so"]["reserve_frames"] == 0
    assert 80 < res["subject_mass_kg"] < 88
    # the torso's vertical residual is the missing mass: (subject - model) g, mean over the trial
    miss = (res["subject_mass_kg"] - res["model_mass_kg"]) * 9.81
    assert res["torso_residuals"]["torso_y"]["mean"] == pytest.approx(-miss, rel=0.1)
    if isinstance(res.get("diagnosis"), dict):
        # gait2d is not scaled to this subject: the whole-body scale, not the HAT alone
        assert res["diagnosis"]["best"] == "scale"
        assert "model 65.7 kg" in res["diagnosis"]["summary"]
    for png in ("rajagopal_moments.png", "rajagopal_so_vs_emg.png"):
        assert (tmp_path / png).stat().st_size > 10_000


def test_csu_case_study(real, tmp_path):
    if not (real / "csu-treadmill-leg2d").is_dir():
        pytest.skip("csu-treadmill-leg2d absent")
    import gait_csu
    assert gait_csu.main(["--out", str(tmp_path), "--data", str(real.parent)]) == 0
    res = json.loads((tmp_path / "gait_csu.json").read_text())
    assert 1.3 < res["moments"]["ankle_r"]["max_nm_per_kg"] < 1.8          # push-off plantarflexor peak
    assert -0.8 < res["moments"]["knee_r"]["min_nm_per_kg"] < -0.4          # early-stance extensor
    assert max(res["ik_marker_rms_mm"].values()) < 15
    assert res["torso_residuals_right_single_support"]["torso_y"]["rms"] < 100
    assert res["torso_residuals"]["torso_y"]["rms"] > 300                   # the unmeasured left foot
    assert (tmp_path / "csu_gait.png").exists()


def test_winter_case_study(real, tmp_path):
    if not (real / "winter-gait-bmc").is_dir():
        pytest.skip("winter-gait-bmc absent")
    import gait_winter
    assert gait_winter.main(["--out", str(tmp_path), "--data", str(real.parent)]) == 0
    res = json.loads((tmp_path / "gait_winter.json").read_text())
    assert 55 < res["joint_angles_deg"]["knee_r"]["max_deg"] < 75          # swing knee flexion
    assert max(res["ik_marker_rms_mm"].values()) < 15
    sw = res["swing_knee_moment_by_cutoff"]
    assert 0.15 < sw["6Hz"]["peak_flexor_nm_per_kg"] < 0.45
    assert sw["unfiltered"]["rms_difference_from_6hz_nm_per_kg"] > 5 * sw["8Hz"]["rms_difference_from_6hz_nm_per_kg"]
    assert (tmp_path / "winter_swing_knee.png").exists()


def test_pipeline_on_real_trials(real, tmp_path):
    if not (real / "csu-treadmill-leg2d").is_dir() or not (real / "opensim-moco-walk-emg").is_dir():
        pytest.skip("data absent")
    from pinmsk.pipeline import batch
    m = real / "opensim-moco-walk-emg"
    trials = [{"name": "csu", "kind": "csu", "path": str(real / "csu-treadmill-leg2d" / "rawdata.txt"),
               "body_mass": 67.2, "cutoff": 6.0},
              {"name": "rajagopal", "kind": "opensim", "coordinates": str(m / "coordinates.sto"),
               "grf": str(m / "grf_walk.mot"), "trc": str(m / "markers_walk.trc")}]
    rows = batch(trials, out=tmp_path, jobs=2)
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert 1.3 < rows[0]["ankle_r_peak_abs_nm_per_kg"] < 1.8
    assert 1.1 < rows[1]["ankle_r_peak_abs_nm_per_kg"] < 1.5
