"""The results report opens with a summary: unsolved frames, reserves and residuals, the worst
frames, the activations by muscle group; long lists are collapsed."""
from __future__ import annotations

import re

import numpy as np
import pytest

import pinmsk
from pinmsk.presentation import report
from pinmsk.presentation.plots import muscle_group


def test_muscle_group_drops_bundle_numbers_and_keeps_the_side():
    assert muscle_group("glmax1_r") == "glmax_r"
    assert muscle_group("glmax3_r") == "glmax_r"
    assert muscle_group("vasmed_l") == "vasmed_l"
    assert muscle_group("BICLH") == "BICLH"
    assert muscle_group("addlong_r") == "addlong_r"


def _results(n_muscles=30):
    t = np.linspace(0.0, 1.0, 51)
    ch, units = {}, {}
    for k in range(n_muscles):
        name = f"mus{chr(97 + k // 3)}{k % 3 + 1}_r"          # groups of three bundles: musa1_r ...
        ch[f"{name}_force"] = 100.0 * (k + 1) * t
        units[f"{name}_force"] = "N"
        ch[f"{name}_activation"] = (k + 1) / n_muscles * t
    ch["hip_flexion_r_reserve"] = np.where(np.arange(t.size) == 17, 40.0, 1.0)
    units["hip_flexion_r_reserve"] = "N*m"
    ch["pelvis_ty_residual"] = 5.0 * np.sin(2 * np.pi * t)
    units["pelvis_ty_residual"] = "N"
    ch["status"] = np.where(np.arange(t.size) == 30, 1.0, 0.0)
    return pinmsk.Trial(t, ch, units=units, meta={"analysis": "static_optimization"})


@pytest.fixture(scope="module")
def page_html():
    # figures={}: the summary and the tables without drawing figures (the browser test draws them)
    return report.render_results_report(model=pinmsk.load_model("forearm"), trial=None, results=_results(),
                                        figures={})


def test_summary_comes_first_with_reserves_and_worst_frames(page_html):
    html = page_html
    assert html.index("<h2>Summary</h2>") < html.index("<h2>Model</h2>")
    summary = html[html.index("<h2>Summary</h2>"):html.index("<h2>Model</h2>")]
    assert "1 of 51" in summary                                           # one frame not optimal
    rows = re.findall(r"<tr><td class=\"l\">(\w+_(?:reserve|residual))</td><td class=\"l\">([^<]*)</td>"
                      r"<td class=\"\">([^<]*)</td><td class=\"\">([^<]*)</td>", summary)
    assert rows[0] == ("hip_flexion_r_reserve", "N*m", "40", "0.34")      # largest first, at frame 17
    peak = np.max(np.abs(5.0 * np.sin(2 * np.pi * np.linspace(0, 1, 51))))
    assert rows[1][:3] == ("pelvis_ty_residual", "N", f"{peak:.4g}")
    assert re.search(r"<tr><td class=\"\">17</td><td class=\"\">0.34</td>"
                     r"<td class=\"l\">hip_flexion_r_reserve</td>", summary)
    # 30 muscles in 10 groups, the most active first
    assert "30 muscles in 10 groups" in summary
    first = re.search(r"most active first:</p>\s*<table>.*?<tr><td class=\"l\">(\w+)</td><td class=\"\">(\d+)</td>"
                      r"<td class=\"\">([^<]*)</td>", summary, re.S)
    assert first.groups() == ("musj_r", "3", "1")


def test_long_lists_are_collapsed(page_html):
    html = page_html
    after = html[html.index("<h2>Model</h2>"):]
    assert "<details><summary>30 muscles</summary>" in after
    assert re.search(r"<details><summary>\d+ channels</summary>", after)
    assert "white-space:pre-wrap" in html                                 # the model text wraps


def test_so_report_and_plot_draw_each_figure_once(tmp_path, monkeypatch):
    """``--report --plot``: the report embeds the PNGs --plot wrote, byte for byte."""
    import base64

    from pinmsk.io.tables import write_trial
    from pinmsk.presentation import plots
    from pinmsk.presentation.cli import main
    from pinmsk.solvers.analytical import gaussian_elbow_trial

    src = tmp_path / "gauss.csv"
    write_trial(gaussian_elbow_trial(n_frames=81), src)
    calls = []
    real = plots.results_figures
    monkeypatch.setattr(plots, "results_figures", lambda *a, **k: calls.append(1) or real(*a, **k))
    assert main(["so", "forearm", str(src), "-o", str(tmp_path / "so.sto"), "--report", str(tmp_path / "so.html"),
                 "--plot", str(tmp_path / "fig")]) == 0
    assert len(calls) == 1
    html = (tmp_path / "so.html").read_text()
    embedded = {base64.b64decode(b) for b in re.findall(r'src="data:image/png;base64,([^"]+)"', html)}
    written = {p.read_bytes() for p in (tmp_path / "fig").glob("*.png")}
    assert written and written <= embedded


def test_emg_table_marks_nearly_silent_muscles():
    t = np.linspace(0.0, 1.0, 51)
    shape = np.sin(np.pi * t)
    results = pinmsk.Trial(t, {"BRD_activation": 0.5 * shape, "BRA_activation": 1e-4 * shape,
                               "BRD_emg": shape, "BRA_emg": shape})
    html = report.render_results_report(model=pinmsk.load_model("forearm"), trial=None, results=results,
                                        figures={})
    rows = dict((m, (r, peak, note)) for m, r, peak, note in re.findall(
        r"<tr><td class=\"l\">(BR[AD])</td><td class=\"\">([^<]*)</td><td class=\"\">([^<]*)</td>"
        r"<td class=\"l\">([^<]*)</td></tr>", html))
    assert rows["BRD"] == ("1", "0.5", "")
    assert rows["BRA"] == ("1", "0.0001", "silent")          # same shape, r = 1, but silent
