"""pinmsk.gait_validation: the measures on analytical strides, and the measured walk validated against itself."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import brentq

from pinmsk import Trial
from pinmsk import gait_validation as gv
from pinmsk.errors import TrialError


# -- analytical ------------------------------------------------------------------------------

C = 0.2   # g(x) = sin x + C sin 3x over stance x in [0, pi]: a symmetric double hump


def _hump(p, stance=60.0, peak=100.0):
    x = np.pi * np.clip(p / stance, 0.0, 1.0)
    return peak * (np.sin(x) + C * np.sin(3 * x))


def test_double_hump_analytical_peaks_valley_and_timing():
    p = np.linspace(0.0, 100.0, 100001)
    h = gv.double_hump(p, _hump(p))
    x1 = brentq(lambda x: np.cos(x) + 3 * C * np.cos(3 * x), 0.1, np.pi / 2 - 1e-9)   # g'(x) = 0
    g1 = np.sin(x1) + C * np.sin(3 * x1)
    assert h["first_peak_at_pct"] == pytest.approx(60.0 * x1 / np.pi, abs=2e-3)
    assert h["second_peak_at_pct"] == pytest.approx(60.0 * (1 - x1 / np.pi), abs=2e-3)
    assert h["first_peak_bw_pct"] == pytest.approx(100 * g1, rel=1e-8)
    assert h["second_peak_bw_pct"] == pytest.approx(100 * g1, rel=1e-8)
    assert h["valley_at_pct"] == pytest.approx(30.0, abs=2e-3)
    assert h["valley_bw_pct"] == pytest.approx(100 * (1 - C), rel=1e-8)     # g(pi/2) = 1 - C


def test_double_hump_refuses_a_stride_without_stance():
    with pytest.raises(TrialError, match="never exceeds 5 % of body weight"):
        gv.double_hump(np.linspace(0, 100, 11), np.zeros(11))


def test_heel_strikes_interpolate_the_crossing():
    t = np.linspace(0, 1, 11)
    f = np.where(t < 0.45, 0.0, 100.0)
    # 0 at 0.4, 100 at 0.5: 20 N is crossed at 0.42
    np.testing.assert_allclose(gv.heel_strikes(t, f, threshold=20.0), [0.42])


def test_correlation_and_rms_of_a_signal_with_itself():
    x = np.sin(np.linspace(0, 6, 50)) ** 2
    assert gv.curve_correlation(x, x) == pytest.approx(1.0, abs=1e-15)
    assert gv.curve_correlation(x, 3 * x + 1) == pytest.approx(1.0, abs=1e-12)
    assert gv.curve_rms(x, x) == 0.0
    assert gv.curve_rms(x, x + 2.0) == pytest.approx(2.0)
    assert np.isnan(gv.curve_correlation(x, np.ones_like(x)))        # a flat curve has no correlation


def _synthetic_stride(n=400, T=1.1, speed=1.3, bw=700.0, closed=True, shift=0.0):
    """A periodic gait2d-like stride whose right heel strike is at ``shift`` of the stride."""
    t = np.linspace(0, T, n + 1) if closed else np.arange(n) * T / n
    ph = np.mod(t / T - shift, 1.0)                 # phase from the right heel strike
    pl = np.mod(ph - 0.5, 1.0)
    ang = lambda u, a, k: np.radians(a * np.sin(2 * np.pi * u) + k * np.cos(4 * np.pi * u))  # noqa: E731
    ch = {}
    for s, u in (("r", ph), ("l", pl)):
        ch[f"hip_{s}"], ch[f"knee_{s}"], ch[f"ankle_{s}"] = ang(u, 20, 5), ang(u, 30, 10), ang(u, 10, 3)
        fy = _hump(100 * u) * bw / 100.0
        fy[100 * u > 60.0] = 0.0
        ch[f"{s}_ground_force_vy"] = fy
        ch[f"{s}_ground_force_vx"] = 0.1 * fy * np.cos(np.pi * u / 0.6)
        ch[f"soleus_{s}_activation"] = 0.5 + 0.4 * np.sin(2 * np.pi * u)
    ch["torso_x"] = speed * t
    return Trial(t, ch)


def test_gait_cycle_of_a_synthetic_stride_finds_its_heel_strikes_and_scalars():
    T, speed = 1.1, 1.3
    ref = gv.gait_cycle(_synthetic_stride(T=T, speed=speed), body_weight=700.0)
    shifted = gv.gait_cycle(_synthetic_stride(T=T, speed=speed, shift=0.3, closed=False), body_weight=700.0)
    assert ref.stride_time == pytest.approx(T)
    assert shifted.stride_time == pytest.approx(T)
    assert ref.cadence == pytest.approx(120 / T)
    assert ref.stride_length == pytest.approx(speed * T)
    assert shifted.speed == pytest.approx(speed)
    for name in ref.angles:               # the stride starts at the heel strike, wherever it is sampled
        assert gv.curve_rms(ref.angles[name], shifted.angles[name]) < 0.05
    np.testing.assert_allclose(ref.angles["knee_r"], ref.angles["knee_l"], atol=0.05)
    h = gv.double_hump(gv.FINE, ref.grf_fine["r_vy"])
    assert h["valley_bw_pct"] == pytest.approx(100 * (1 - C), abs=0.5)
    assert h["valley_at_pct"] == pytest.approx(30.0, abs=0.3)


def test_body_weight_defaults_to_the_mean_vertical_grf_and_speed_to_torso_x():
    tr = _synthetic_stride()
    cyc = gv.gait_cycle(tr)
    t = tr.time[:-1]
    expected = np.mean(tr["r_ground_force_vy"][:-1] + tr["l_ground_force_vy"][:-1])
    assert cyc.body_weight == pytest.approx(expected)
    assert any("mean total vertical GRF" in n for n in cyc.notes)
    assert cyc.speed == pytest.approx(1.3)
    assert t.size == tr.n_frames - 1


def test_validate_gait_without_references_reports_published_bands():
    v = gv.validate_gait(_synthetic_stride(T=1.14, speed=1.25), winter=False, measured=False,
                         cost_of_transport=3.1, body_weight=700.0)
    st = v.numbers["spatiotemporal"]
    assert st["cadence_steps_per_min"]["value"] == pytest.approx(120 / 1.14)
    assert st["cadence_steps_per_min"]["within"] is True
    assert st["stride_length_m"]["value"] == pytest.approx(1.25 * 1.14)
    assert st["cost_of_transport_j_per_kg_m"]["within"] is True
    assert "Waters" in st["cost_of_transport_j_per_kg_m"]["source"]
    assert v.numbers["joint_angles"] == {}
    json.loads(v.to_json())


def test_gait_cycle_names_missing_coordinates():
    tr = _synthetic_stride().drop(["knee_l"])
    with pytest.raises(TrialError, match="knee_l"):
        gv.gait_cycle(tr)


def test_report_and_figures_are_written(tmp_path):
    v = gv.validate_gait(_synthetic_stride(), winter=False, measured=False, body_weight=700.0)
    path = v.write_report(tmp_path / "gait.html", figures_dir=tmp_path)
    text = path.read_text()
    assert "Vertical GRF double hump" in text and "data:image/png;base64" in text
    assert {p.name for p in tmp_path.glob("*.png")} == {"gait_angles.png", "gait_grf.png", "gait_activations.png"}


# -- measured ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def walk():
    from pinmsk.io.shared_data import shared_data_dir
    d = shared_data_dir()
    if d is None or not (d / gv.MEASURED_WALK).exists():
        pytest.skip("opensim-moco-walk-emg is absent from the shared data")
    return gv.measured_walk_cycle()


def test_measured_walk_body_weight_and_stride(walk):
    # SOURCE.md: the scaled model's masses sum to ~85.3 kg; right heel strikes 0.267 s and 1.41 s
    assert walk.body_weight / gv.G == pytest.approx(85.3, abs=1.0)
    assert walk.stride_time == pytest.approx(1.144, abs=0.003)
    assert 1.1 < walk.speed < 1.4
    assert not any(np.isnan(a).any() for a in walk.angles.values())    # the two legs cover the stride


def test_measured_walk_validated_against_itself(walk):
    tr = gv.measured_walk_as_stride(rate=1000.0)
    ch = tr.to_dict()
    t = ch.pop("time")
    for g in gv.EMG_GROUPS:     # activations = the EMG envelopes themselves
        ch[f"{g}_r_activation"] = np.interp(100 * t / walk.stride_time, gv.PERCENT, walk.muscles[f"{g}_r"])
    v = gv.validate_gait(Trial(t, ch, meta=dict(tr.meta)), winter=False)
    n = v.numbers
    assert n["body_weight_n"] == pytest.approx(walk.body_weight)
    assert n["stride_time_s"] == pytest.approx(walk.stride_time, rel=1e-9)
    for name, x in n["joint_angles"]["measured_walk"].items():
        assert x["rms_deg"] < 0.1, name
        assert x["correlation"] > 0.9999, name
    for side in "rl":
        a, b = n["grf"]["simulation"][side], n["grf"]["measured_walk"][side]
        for k in ("first_peak_bw_pct", "valley_bw_pct", "second_peak_bw_pct"):
            assert a[k] == pytest.approx(b[k], abs=0.5), (side, k)
        for k in ("first_peak_at_pct", "valley_at_pct", "second_peak_at_pct"):
            assert a[k] == pytest.approx(b[k], abs=1.0), (side, k)
    assert n["grf"]["rms_bw_pct"]["r_vy"] < 0.5
    for g, x in n["emg"].items():
        assert x["correlation_r"] > 0.999, g
    # the walk's double hump (right): ~110 % BW at ~18 %, valley ~72 % at ~33 %, ~113 % at ~49 %
    h = n["grf"]["measured_walk"]["r"]
    assert 100 < h["first_peak_bw_pct"] < 120 and 60 < h["valley_bw_pct"] < 85
    assert 10 < h["first_peak_at_pct"] < 25 and 40 < h["second_peak_at_pct"] < 55


def test_winter_reference_against_the_measured_walk(walk):
    """Two healthy subjects: the knee curves correlate (> 0.9) within ~10 deg RMS (IK of Table A.1, ~1 s)."""
    w = gv.winter_cycle()
    if w is None:
        pytest.skip("winter-gait-bmc is absent from the shared data")
    r = gv.compare_angles(w, walk)
    assert r["knee_r"]["correlation"] > 0.9 and r["knee_r"]["rms_deg"] < 12.0
    assert w.cadence == pytest.approx(121.7, abs=0.5)       # frames 28-97 at ~70 Hz


def test_read_stride_takes_the_sidecar_and_validate_gait_reads_a_path(tmp_path):
    from pinmsk.io.tables import write_trial
    tr = _synthetic_stride(T=1.14, speed=1.25)
    path = tmp_path / "OUT.sto"
    write_trial(tr, path)
    (tmp_path / "OUT.sto.json").write_text(json.dumps({"converged": True, "speed": 1.2, "cost_of_transport": 3.4,
                                                       "body_weight": 650.0, "stride_length": None}))
    v = gv.validate_gait(path, winter=False, measured=False)
    assert v.numbers["speed_m_per_s"] == pytest.approx(1.2)          # the sidecar's, not torso_x's 1.25
    assert v.numbers["body_weight_n"] == pytest.approx(650.0)
    assert v.numbers["spatiotemporal"]["cost_of_transport_j_per_kg_m"]["value"] == pytest.approx(3.4)
    assert v.numbers["stride_time_s"] == pytest.approx(1.14, rel=1e-6)
    text = v.to_json(tmp_path / "v.json")
    assert "NaN" not in text and json.loads((tmp_path / "v.json").read_text())["label"] == "simulation"


def test_read_stride_names_a_broken_sidecar(tmp_path):
    from pinmsk.io.tables import write_trial
    path = tmp_path / "OUT.sto"
    write_trial(_synthetic_stride(), path)
    (tmp_path / "OUT.sto.json").write_text('{"speed": 1.2,\n "x": }')
    with pytest.raises(TrialError, match=r"OUT\.sto\.json: line 2, column \d+: not JSON"):
        gv.read_stride(path)


# -- benchmarks/bench_gait_moco.py: the parent side (never imports opensim) -------------------------

def _bench():
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_gait_moco.py"
    spec = importlib.util.spec_from_file_location("bench_gait_moco", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_bench_gait_moco_symmetry_names_and_arguments(capsys):
    b = _bench()
    assert b._swap_side("/jointset/hip_r/hip_flexion_r/value") == "/jointset/hip_l/hip_flexion_l/value"
    assert b._swap_side("/forceset/rect_fem_l/activation") == "/forceset/rect_fem_r/activation"
    with pytest.raises(SystemExit):
        b.main(["--problems", "tracking,walking"])
    assert "unknown ['walking']" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        b.main(["--moco-only", "--pinmsk-only"])
    assert "exclude each other" in capsys.readouterr().err
    assert b.MOCO_INTERVALS == {"tracking": 24, "predictive": 50}   # MocoTrack's 0.02 s mesh; the example's 50


#: the pinmsk tracking solution against Moco's reference data: measured 2.47 deg (hip_flexion_l) and 1.28 % BW
#: (right fore-aft) here, 217 s (see the bench's docstring); the bounds leave a margin for other machines
RMS_DEG_BOUND, GRF_BW_BOUND = 4.0, 3.0


def _moco_dir(shared_data):
    d = shared_data / "opensim-models" / "Moco2DWalking"
    if not (d / "2D_gait.osim").exists():
        pytest.skip("Moco2DWalking is absent from the shared data")
    return d


def test_bench_gait_moco_pinmsk_problems_are_mocos(shared_data):
    """The pinmsk side's problems (built, not solved; the solve: test_bench_gait_moco_pinmsk_tracking_converges):
    Moco's goals, weights, contact groups, bounds, durations and intervals on the imported 2D_gait.osim."""
    pytest.importorskip("casadi")
    import numpy as np

    import pinmsk
    import warnings
    b = _bench()
    d = _moco_dir(shared_data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")            # the import's fitted-path note
        model = pinmsk.load_model(d / "2D_gait.osim")
    assert b._contact_spheres(d / "2D_gait.osim") == {"contactHeel_r": "heel_r", "contactHeel_l": "heel_l",
                                                       "contactFront_r": "front_r", "contactFront_l": "front_l"}
    fit = b.build_pinmsk("tracking", d, model=model)
    fit._setup()
    terms = {t.name: t for t in fit.cost.terms()}
    assert {n: t.weight for n, t in terms.items()} == {"control_effort": 10.0, "state_tracking": 1.0, "contact": 1.0}
    assert terms["control_effort"].exponent == 2 and terms["control_effort"].per is None
    assert terms["control_effort"]._wm.size == 18 and terms["control_effort"]._wa.size == 1   # + lumbarAct
    st = terms["state_tracking"]
    assert len(st._rows) == 20                                       # 10 values + 10 position derivatives
    labels = [c.label.split(":")[-1] for c in fit._pm.contacts]
    ct = terms["contact"]
    assert {g: [labels[i] for i in ix] for g, ix in ct._idx.items()} == {"Right_GRF": ["heel_r", "front_r"],
                                                                         "Left_GRF": ["heel_l", "front_l"]}
    assert ct._den == pytest.approx(62.0 * 9.80665)
    assert (fit.duration, fit.intervals, fit.scheme) == (b.HALF_CYCLE, 24, "hermite-simpson")
    lo, hi = fit._vbounds["q"]
    j = model.coordinate_index("knee_angle_r")
    assert (lo[j], hi[j]) == pytest.approx((np.radians(-50.0), 0.0))
    ref = st.reference(np.array([0.0, 0.2]))
    assert abs(ref["pelvis_tx_speed"][1] - 1.2) < 0.3               # the reference walks at about 1.2 m/s
    pred = b.build_pinmsk("predictive", d, model=model)
    pred._setup()
    (effort,) = pred.cost.terms()
    assert (effort.weight, effort.exponent, effort.per) == (10.0, 3, "distance")
    assert (pred.duration, pred.intervals) == ((0.4, 0.6), 50)
    assert [type(c).__name__ for c in pred.constraints] == ["Symmetric", "Periodic", "Bounds", "AverageSpeed"]
    assert pred.constraints[0].controls == ("lumbarAct",)      # Moco's addControlPair("/lumbarAct")
    assert pred.constraints[0]._mirror_act == {0: 0}


@pytest.mark.slow
def test_bench_gait_moco_pinmsk_tracking_converges(shared_data):
    """Moco's tracking problem solved by pinmsk (about 2 min here): converged, joint angles within a few
    degrees of the tracked reference and GRF within a few % of body weight (bounds measured: RMS_DEG_BOUND);
    the default test_bench_gait_moco_pinmsk_problems_are_mocos covers the same problem's construction."""
    pytest.importorskip("casadi")
    import pinmsk
    b = _bench()
    d = _moco_dir(shared_data)
    model = pinmsk.load_model(d / "2D_gait.osim")
    r = b.build_pinmsk("tracking", d, model=model).fit().result_
    assert r.converged, r.status
    cmp = b.pinmsk_against_reference(r, d, 62.0)
    assert max(cmp["reference_rms_deg"].values()) < RMS_DEG_BOUND
    assert max(cmp["grf_rms_bw_pct"].values()) < GRF_BW_BOUND
    assert r.objective == pytest.approx(sum(w * r.terms[n] for n, w in
                                            (("control_effort", 10.0), ("state_tracking", 1.0), ("contact", 1.0))))


def test_bench_gait_moco_reference_against_itself_is_zero(shared_data):
    ref = shared_data / "opensim-models" / "Moco2DWalking" / "referenceCoordinates.sto"
    if not ref.exists():
        pytest.skip("Moco2DWalking is absent from the shared data")
    rms = _bench().reference_rms_deg(ref, ref)
    assert set(rms) == set(_bench().ANGLES)
    assert max(rms.values()) < 1e-9


def test_bench_gait_moco_reads_the_last_ipopt_iterate_of_a_killed_run(tmp_path):
    log = tmp_path / "predictive.log"
    log.write_text("iter    objective    inf_pr   inf_du lg(mu)\n   0  3.89e-01 4.40e+00 2.62e-02   0.0\n"
                   "  25r  1.75e-01 4.18e-01 8.45e-02  -8.2\nNumber of nonzeros 12\n")
    assert _bench()._last_iterate(log) == {"iterations": 25, "objective": 0.175, "inf_pr": 0.418, "inf_du": 0.0845,
                                           "note": "last IPOPT iterate at the timeout"}
    log.write_text("no iterations\n")
    assert _bench()._last_iterate(log) == {}
