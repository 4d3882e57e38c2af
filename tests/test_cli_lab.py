"""The lab path from the command line: GRF used, 6 Hz by default, residuals and unspanned coordinates named."""
import numpy as np

import pinmsk
from pinmsk import read_trial, write_trial
from pinmsk.presentation.cli import main

from test_kinematics import _external_loads_xml, bouncing


def data(name):
    from pathlib import Path
    return str(Path(__file__).resolve().parents[1] / "data" / name)


def test_id_uses_the_trials_grf_and_filters_by_default(tmp_path, capsys):
    out = tmp_path / "id.sto"
    assert main(["id", "gait2d", data("gait2d_hat_mass.csv"), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "6 Hz" in text and "-> foot_r" in text and "-> foot_l" in text and "floating-base residuals" in text
    got = read_trial(out)
    head = got.meta["header"]        # what was applied travels with the file
    assert head["lowpass_cutoff_hz"] == "6.0" and head["grf_lowpass_cutoff_hz"] == "6.0"
    assert "-> foot_r" in head["ground_reaction"] and "torso_y peak" in head["residuals"]
    w = pinmsk.load_model("gait2d").mass * 9.81
    # with the GRF the torso carries only the hidden HAT mass (tens of N), not the body weight
    assert np.max(np.abs(got["torso_y_moment"])) < 0.15 * w
    ref = pinmsk.inverse_dynamics(pinmsk.load_model("gait2d"), read_trial(data("gait2d_hat_mass.csv")))
    np.testing.assert_allclose(got["knee_r_moment"], ref["knee_r_moment"], rtol=5e-9, atol=1e-9)   # %.9g
    # the old behaviour (no filter, no GRF) is only there when asked for, and then named
    assert main(["id", "gait2d", data("gait2d_hat_mass.csv"), "-o", str(out), "--no-grf"]) == 0
    err = capsys.readouterr().err
    assert "no ground reaction forces" in err and "torso_y" in err and "body weight" in err
    assert np.max(np.abs(read_trial(out)["torso_y_moment"])) > 0.95 * w


def test_id_and_so_on_the_forearm_work_with_the_default_filter(tmp_path, capsys):
    out = tmp_path / "id.sto"
    assert main(["id", "forearm", data("forearm_payload.csv"), "-o", str(out)]) == 0
    filt = read_trial(out)["elbow_flexion_moment"]
    assert main(["id", "forearm", data("forearm_payload.csv"), "-o", str(out), "--cutoff", "0"]) == 0
    raw = read_trial(out)["elbow_flexion_moment"]
    # unfiltered noisy angles differentiate into a moment many times the filtered one
    assert np.ptp(raw) > 5 * np.ptp(filt) and np.ptp(filt) < 30.0
    so = tmp_path / "so.sto"
    assert main(["so", "forearm", data("forearm_payload.csv"), "-o", str(so)]) == 0
    assert "BICLH_force" in read_trial(so).names


def test_so_measured_moments_and_unspanned_coordinates(tmp_path, capsys):
    so = tmp_path / "so.sto"
    assert main(["so", "forearm", data("forearm_payload.csv"), "-o", str(so)]) == 0
    assert "--moments measured" in capsys.readouterr().out       # says it balanced ID, not the dynamometer
    assert main(["so", "forearm", data("forearm_payload.csv"), "-o", str(so), "--moments", "measured"]) == 0
    assert "measured <coord>_moment channels" in capsys.readouterr().out
    so2 = tmp_path / "so2.sto"
    assert main(["so", "gait2d", data("gait2d_hat_mass.csv"), "-o", str(so2)]) == 2
    err = capsys.readouterr().err
    assert "no muscle spans torso_x, torso_y, torso_angle" in err and "--reserves" in err
    assert not so2.exists()
    assert main(["so", "gait2d", data("gait2d_hat_mass.csv"), "-o", str(so2), "--reserves"]) == 0
    out = capsys.readouterr().out
    assert "not spanned by any muscle" in out and "torso_y" in out
    got = read_trial(so2)
    assert got.meta["header"]["balanced_moments"].startswith("inverse dynamics with the trial's ground reaction")
    assert "torso_y_reserve" in got.names and np.max(np.abs(got["torso_y_reserve"])) < 100.0


def test_grf_file_and_external_loads_from_the_cli(tmp_path, capsys):
    m = pinmsk.load_model("gait2d")
    tr = bouncing(m, rate=100.0)
    kin = tmp_path / "kin.sto"
    write_trial(tr.select(list(m.coordinates)), kin)
    grf = tmp_path / "walk_grf.mot"
    fast = bouncing(m, rate=1000.0)
    write_trial(fast.select([n for n in fast.names if "ground" in n]), grf)
    out = tmp_path / "id.sto"
    assert main(["id", "gait2d", str(kin), "--grf", str(grf), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert str(grf) in text and "-> foot_r" in text
    assert np.max(np.abs(read_trial(out)["torso_y_moment"][30:-30])) < 0.01 * m.mass * 9.81
    # OpenSim naming and an ExternalLoads file
    ren = {n: (n[2:] if n.startswith("r_") else "1_" + n[2:]) for n in fast.names if "ground" in n}
    write_trial(pinmsk.Trial(fast.time, {v: fast[k] for k, v in ren.items()}), tmp_path / "os_grf.mot")
    xml = _external_loads_xml(tmp_path / "loads.xml", "os_grf.mot")
    assert main(["id", "gait2d", str(kin), "--external-loads", str(xml), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "right (ground_force_v[xyz]) -> foot_r" in text
    # an ExternalLoads file follows OpenSim's convention (the loads unfiltered, as its ID tool applies
    # them) and says so; the bounce's impacts then stay in the residual, and --grf-cutoff filters them
    assert "ground reaction none (OpenSim's ExternalLoads convention" in text
    assert main(["id", "gait2d", str(kin), "--external-loads", str(xml), "--grf-cutoff", "6", "-o", str(out)]) == 0
    capsys.readouterr()
    assert np.max(np.abs(read_trial(out)["torso_y_moment"][30:-30])) < 0.01 * m.mass * 9.81
    # a plate that cannot be placed is refused by name, and nothing is written
    bad = _external_loads_xml(tmp_path / "bad.xml", "os_grf.mot", body_r="pelvis_nope")
    out2 = tmp_path / "none.sto"
    assert main(["id", "gait2d", str(kin), "--external-loads", str(bad), "-o", str(out2)]) == 2
    assert "pelvis_nope" in capsys.readouterr().err and not out2.exists()
