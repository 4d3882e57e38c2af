"""TRC reading, units, gaps (interpolated, flagged, never forward-filled), model marker sets."""

import numpy as np
import pytest

from pinmsk import Trial, TrialError, ModelError
from pinmsk.signals.gaps import fill_gaps, find_gaps
from pinmsk.markers import load_marker_set
from pinmsk.trial import marker_array, marker_names
from pinmsk.io.trc import read_trc, write_trc


def _walk(n=50, rate=100.0):
    t = np.arange(n) / rate
    # two markers moving on straight lines at constant speed (m)
    ch = {"A_x": 0.1 + 1.2 * t, "A_y": 1.0 + 0.0 * t, "A_z": 0.2 - 0.3 * t,
          "B_x": -0.4 + 1.2 * t, "B_y": 0.1 + 0.05 * t, "B_z": 0.25 + 0 * t}
    return Trial(t, ch, meta={"markers": ("A", "B")})


def test_gap_interpolation_is_exact_on_a_line():
    tr = _walk()
    d = tr.to_dict(); d.pop("time")
    truth = {k: v.copy() for k, v in d.items()}
    for a in "xyz":
        d[f"A_{a}"][10:14] = np.nan          # 4-frame gap
    d["B_y"][30] = np.nan                    # one coordinate missing = the marker is missing
    gapped = Trial(tr.time, d, meta={"markers": ("A", "B")})
    out = fill_gaps(gapped, max_gap=5)
    for k, v in truth.items():
        np.testing.assert_allclose(out[k], v, rtol=0, atol=1e-12)
    gaps = out.meta["gaps"]
    assert [(g.marker, g.start, g.stop, g.filled) for g in gaps] == [("A", 10, 14, True), ("B", 30, 31, True)]


def test_long_and_edge_gaps_are_flagged_not_filled():
    tr = _walk()
    d = tr.to_dict(); d.pop("time")
    for a in "xyz":
        d[f"A_{a}"][10:30] = np.nan   # 20 frames > max_gap
        d[f"B_{a}"][:3] = np.nan      # at the start: cannot interpolate
    gapped = Trial(tr.time, d, meta={"markers": ("A", "B")})
    with pytest.warns(UserWarning, match="max_gap=5"):
        out = fill_gaps(gapped, max_gap=5)
    assert np.all(np.isnan(out["A_x"][10:30]))            # not forward-filled
    assert np.all(np.isnan(out["B_y"][:3]))
    assert np.isfinite(out["A_x"][9]) and np.isfinite(out["A_x"][30])
    flagged = [g for g in out.meta["gaps"] if not g.filled]
    assert {(g.marker, g.length) for g in flagged} == {("A", 20), ("B", 3)}
    # raising max_gap fills the interior one exactly
    out2 = fill_gaps(gapped, max_gap=25, warn=False)
    np.testing.assert_allclose(out2["A_x"], tr["A_x"], atol=1e-12)


@pytest.mark.parametrize("units,scale", [("mm", 1000.0), ("m", 1.0), ("cm", 100.0)])
def test_trc_round_trip_honours_header_units(tmp_path, units, scale):
    tr = _walk()
    p = write_trc(tr, tmp_path / f"w_{units}.trc", units=units)
    assert f"\t{units}\t" in p.read_text().splitlines()[2]
    back = read_trc(p)
    assert marker_names(back) == ("A", "B")
    np.testing.assert_allclose(marker_array(back), marker_array(tr), atol=1e-7)
    assert back.meta["units"] == units and back.meta["rate"] == 100.0


def test_trc_gap_cells_are_read_as_gaps(tmp_path):
    tr = _walk()
    d = tr.to_dict(); d.pop("time")
    for a in "xyz":
        d[f"B_{a}"][20:23] = np.nan
    p = write_trc(Trial(tr.time, d, meta={"markers": ("A", "B")}), tmp_path / "g.trc")
    assert "\t\t\t" in p.read_text().splitlines()[26]   # empty cells
    back = read_trc(p, max_gap=3)
    np.testing.assert_allclose(back["B_x"], tr["B_x"], atol=1e-7)
    with pytest.warns(UserWarning, match="B: 3 frame"):
        short = read_trc(p, max_gap=2)
    assert np.all(np.isnan(short["B_x"][20:23]))


def test_units_contradicting_header_are_refused(tmp_path):
    tr = _walk()
    p = write_trc(tr, tmp_path / "w.trc", units="mm")
    text = p.read_text().splitlines()
    text[2] = text[2].replace("\tmm\t", "\tm\t")        # header says m, numbers are mm
    bad = tmp_path / "bad.trc"
    bad.write_text("\n".join(text) + "\n")
    with pytest.raises(TrialError, match=r"Units='m'.*contradict.*look like 'mm'"):
        read_trc(bad)
    back = read_trc(bad, units="mm")                     # the override fixes it
    np.testing.assert_allclose(back["A_x"], tr["A_x"], atol=1e-7)


def test_duplicate_marker_names_are_refused(tmp_path):
    tr = Trial(np.arange(5) / 100.0, {"A_x": np.ones(5), "A_y": np.ones(5), "A_z": np.ones(5),
                                       "B_x": np.zeros(5), "B_y": np.zeros(5), "B_z": np.zeros(5)},
               meta={"markers": ("A", "B")})
    p = write_trc(tr, tmp_path / "d.trc", units="m")
    lines = p.read_text().splitlines()
    lines[3] = lines[3].replace("\tB", "\tA")
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrialError, match="duplicate marker name.*'A'"):
        read_trc(p)


def test_rate_contradicting_time_column(tmp_path):
    p = write_trc(_walk(), tmp_path / "r.trc")
    lines = p.read_text().splitlines()
    lines[2] = lines[2].replace("100\t100", "200\t200", 1)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrialError, match="DataRate=200 Hz.*100 Hz"):
        read_trc(p)


def test_find_gaps_lists_runs():
    tr = _walk()
    d = tr.to_dict(); d.pop("time")
    d["A_x"][[3, 4, 8]] = np.nan
    g = find_gaps(Trial(tr.time, d, meta={"markers": ("A", "B")}), max_gap=1)
    assert [(x.start, x.stop, x.filled) for x in g] == [(3, 5, False), (8, 9, True)]


def test_builtin_gait2d_marker_set():
    ms = load_marker_set("gait2d")
    assert ms.sets["csu"] == ("RSHO", "RGTRO", "RLEK", "RLM", "RHEE", "RMT5")
    assert len(ms.subset("winter")) == 8
    assert ms["RLM"].body == "shank_r"
    assert ms.renamed({"RSHO": "R.Shoulder"}).names[0] == "R.Shoulder"
    with pytest.raises(ModelError, match="no set 'nope'"):
        ms.subset("nope")


def test_marker_set_errors(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text('[[markers]]\nname = "A"\nposition = [0, 0, 0]\n')
    with pytest.raises(ModelError, match="has no 'body'"):
        load_marker_set(p)
    p.write_text('[[markers]]\nname = "A"\nbody = "x"\nposition = [0, 0]\n')
    with pytest.raises(ModelError, match=r"position must be \[x, y, z\]"):
        load_marker_set(p)


def test_c3d_without_ezc3d_says_how_to_install(monkeypatch, tmp_path):
    import sys
    monkeypatch.setitem(sys.modules, "ezc3d", None)      # import ezc3d -> ImportError
    from pinmsk.io.c3d import read_c3d
    with pytest.raises(ImportError, match=r"pip install pinmsk\[c3d\]"):
        read_c3d(tmp_path / "x.c3d")


def test_remap_axes_z_up_to_y_up():
    from pinmsk.io.c3d import remap_axes
    t = np.arange(3.0)
    tr = Trial(t, {"A_x": t, "A_y": 2 * t, "A_z": 3 * t, "ground_force_vz": 10 * t, "ground_force_vx": t,
                   "ground_force_vy": 0 * t, "emg": t})
    out = remap_axes(tr, {"x": "x", "y": "z", "z": "-y"})        # lab z-up -> y-up, right-handed
    np.testing.assert_allclose(out["A_y"], 3 * t)
    np.testing.assert_allclose(out["A_z"], -2 * t)
    np.testing.assert_allclose(out["ground_force_vy"], 10 * t)
    np.testing.assert_allclose(out["emg"], t)
