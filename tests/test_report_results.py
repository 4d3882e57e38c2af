"""pinmsk.presentation.report.write_results_report: a self-contained HTML of a real SO result."""
from __future__ import annotations

import base64
import io
import re

import numpy as np
import pytest
from PIL import Image

import pinmsk
from pinmsk.presentation import report
from pinmsk.solvers.analytical import gaussian_elbow_trial
from pinmsk.solvers.static import StaticOptimization


def make_report(path, *, with_emg=True, **kw):
    model = pinmsk.load_model("forearm")
    trial = gaussian_elbow_trial(n_frames=81)
    so = StaticOptimization().fit(model, trial)
    r = so.result_
    if with_emg:
        trial = trial.with_channels(BRD_emg=np.asarray(r["BRD_activation"]) ** 0.5)
    out = report.write_results_report(path, model=model, trial=trial, results=r, title="SO <forearm>",
                                      text=so.report(), **kw)
    return out, model, trial, so


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    d = tmp_path_factory.mktemp("rep")
    return make_report(d / "so.html")


def _images(html):
    return re.findall(r'<img[^>]*src="([^"]*)"', html)


def test_figures_are_valid_pngs(built):
    out, *_ = built
    html = out.read_text()
    srcs = _images(html)
    assert len(srcs) == 3                                  # forces, activations, vs EMG
    for s in srcs:
        assert s.startswith("data:image/png;base64,")
        img = Image.open(io.BytesIO(base64.b64decode(s.split(",", 1)[1])))
        img.load()
        assert img.format == "PNG"
        assert img.size in {(900, 400), (1000, int(100 * (0.8 + 2.0)))}
    assert not re.search(r'src="https?:', html) and "http://" not in html.split("<body>")[1].split("<pre>")[0]
    assert "SO &lt;forearm&gt;" in html and "<forearm>" not in html


def test_tables_hold_independent_numbers(built):
    out, model, trial, so = built
    html = out.read_text()
    for i, m in enumerate(model.muscle_names):
        peak = np.max(so.forces_[:, i])
        mean_a = np.mean(so.activations_[:, i])
        assert re.search(rf"<td class=\"l\">{m}</td><td class=\"\">{peak:.4g}</td>", html), m
        assert f"{mean_a:.4g}" in html
    assert f'<td class="l">0</td><td class="">{len(trial.time)}</td>' in html   # status 0 on every frame
    assert "Static optimization (force mode)" in html                            # solver text in <pre>
    assert "elbow_flexion_speed" in html and "81" in html                        # data summary
    assert "Pearson r" in html


def test_moments_extra_figures_tables_and_atomic(tmp_path):
    from pinmsk.presentation import plots
    fig = plots.new_figure(3, 2)
    fig.subplots().plot([0, 1])
    model = pinmsk.load_model("forearm")
    trial = gaussian_elbow_trial(n_frames=41)
    trial = trial.with_channels(elbow_flexion_moment=np.cos(np.asarray(trial.time)))
    so = StaticOptimization().fit(model, trial)
    out = report.write_results_report(tmp_path / "sub" / "r.html", model=model, trial=trial, results=so.result_,
                                      title="t", extra_figures={"extra": fig},
                                      tables={"my table": (["a", "b"], [["x", 1.5]])})
    html = out.read_text()
    assert "joint moments" in html and "my table" in html and "<td class=\"\">1.5</td>" in html
    sizes = [Image.open(io.BytesIO(base64.b64decode(s.split(",", 1)[1]))).size for s in _images(html)]
    assert (300, 200) in sizes and len(sizes) == 4
    assert [p.name for p in out.parent.iterdir()] == ["r.html"]     # no temp file left
    assert out.stat().st_mode & 0o044                               # readable by others like any file
