"""Self-contained HTML reports in a real browser: every figure loads, nothing is fetched
from the network.  The harness is checked on a page built here with matplotlib; the
report of ``pinmsk.presentation.report`` is checked when that module exists."""
from __future__ import annotations

import base64
import io

import numpy as np
import pytest

import browser


def _png_figure(seed: int) -> bytes:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(seed)
    fig, ax = plt.subplots(figsize=(4, 3), dpi=80)
    ax.plot(np.cumsum(rng.normal(size=200)), color="tab:red")
    ax.set_title(f"figure {seed}")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


@pytest.fixture(scope="module")
def page():
    """One headless Chromium page for the module's checks (starting Chromium is most of a check's time)."""
    with browser.chrome_or_skip(width=1000, height=800) as p:
        p.send("Network.enable")
        yield p


def check_html_in_browser(page, path, *, min_images: int = 1, screenshot=None) -> list:
    """Open ``path`` in the headless Chromium ``page``; assert it is self-contained and its figures load.

    Returns the images as ``[src prefix, complete, width, height]``.
    """
    page.navigate("about:blank")
    page.events.clear()             # only this page's requests count
    page.navigate(path.resolve().as_uri())
    images = page.wait_for(f"""(() => {{ const im = {browser.IMAGES_JS.strip()};
        return im.length >= {min_images} && im.every(i => i[1]) ? im : null; }})()""", timeout=20)
    external = [u for u in page.requested_urls() if not u.startswith(("file:", "data:"))]
    if screenshot is not None:
        page.screenshot(screenshot)
    assert not external, f"the report fetches from the network: {external[:5]}"
    broken = [i for i in images if i[2] == 0 or i[3] == 0]
    assert not broken, f"figures that did not load: {broken}"
    return images


def test_self_contained_html_with_embedded_figures(page, tmp_path):
    imgs = "".join(
        f'<figure><img alt="f{k}" src="data:image/png;base64,{base64.b64encode(_png_figure(k)).decode()}">'
        f"</figure>" for k in range(3))
    html = tmp_path / "report.html"
    html.write_text(f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>t</title></head>"
                    f"<body><h1>report</h1>{imgs}<table><tr><td>1</td></tr></table></body></html>")
    images = check_html_in_browser(page, html, min_images=3, screenshot=tmp_path / "report.png")
    assert [i[2:] for i in images] == [[320, 240]] * 3          # 4x3 in at 80 dpi
    rgb = browser.read_png(tmp_path / "report.png")
    assert browser.warm_fraction(rgb) > 0.001                   # the red curves are drawn


def test_broken_figure_is_reported(page, tmp_path):
    html = tmp_path / "broken.html"
    html.write_text('<html><body><img src="data:image/png;base64,AAAA"></body></html>')
    with pytest.raises(AssertionError, match="did not load"):
        check_html_in_browser(page, html)


def test_network_fetch_is_reported(page, tmp_path):
    html = tmp_path / "external.html"
    png = base64.b64encode(_png_figure(0)).decode()
    html.write_text(f'<html><body><img src="data:image/png;base64,{png}">'
                    '<script src="http://127.0.0.1:9/missing.js"></script></body></html>')
    with pytest.raises(AssertionError, match="fetches from the network"):
        check_html_in_browser(page, html)


def test_pinmsk_report_in_browser(page, tmp_path):
    import pinmsk
    from pinmsk.presentation.report import write_failure_report

    model = pinmsk.load_model("forearm")
    t = np.linspace(0, 1, 51)
    trial = pinmsk.Trial(t, {"elbow_flexion": 0.5 + t, "elbow_flexion_moment": np.sin(t)})
    out = tmp_path / "report.html"
    with pytest.raises(pinmsk.PinmskError) as err:       # too short to diagnose: the failure page
        pinmsk.diagnose.run(model, trial)
    write_failure_report(out, model, trial, err.value)
    check_html_in_browser(page, out, min_images=1)


def test_results_report_of_static_optimization_in_browser(page, tmp_path):
    """A results report of a real SO on the forearm: every <img> loads in Chromium."""
    import pinmsk
    from pinmsk.presentation.report import write_results_report
    from pinmsk.solvers.analytical import gaussian_elbow_trial
    from pinmsk.solvers.static import StaticOptimization

    model = pinmsk.load_model("forearm")
    trial = gaussian_elbow_trial(n_frames=101)
    so = StaticOptimization().fit(model, trial)
    trial = trial.with_channels(BRD_emg=np.asarray(so.result_["BRD_activation"]) ** 0.5)
    out = write_results_report(tmp_path / "so.html", model=model, trial=trial, results=so.result_,
                               title="static optimization", text=so.report())
    images = check_html_in_browser(page, out, min_images=3, screenshot=tmp_path / "so.png")
    assert len(images) == 3 and all(i[0].startswith("data:image/png") for i in images)
    assert [i[2:] for i in images][:2] == [[900, 400], [900, 400]]     # forces, activations
    rgb = browser.read_png(tmp_path / "so.png")
    assert browser.distinct_colors(rgb) > 8                              # figures drawn, not blank


def test_report_shows_no_absolute_path_in_browser(page, tmp_path, monkeypatch):
    """The text a reader sees names files relative to the working folder, or by their name."""
    from pathlib import Path

    import pinmsk
    from pinmsk.presentation.report import write_results_report

    work = tmp_path / "work"
    (work / "out").mkdir(parents=True)
    monkeypatch.chdir(work)
    pkg = Path(pinmsk.__file__).resolve().parent
    t = np.linspace(0.0, 1.0, 21)
    trial = pinmsk.Trial(t, {"elbow_flexion": 0.5 * t}, meta={"source": str(pkg / "data" / "elbow.mot")})
    results = pinmsk.Trial(t, {"BRD_activation": t}, meta={"source": str(work / "out" / "so.sto")})
    out = write_results_report(work / "out" / "so.html", model=pinmsk.load_model("forearm"), trial=trial,
                               results=results, text=f"wrote {work / 'out' / 'so.sto'}")
    check_html_in_browser(page, out, min_images=1)
    text = page.evaluate("document.body.innerText")
    assert "elbow.mot" in text and "out/so.sto" in text
    assert str(tmp_path) not in text and str(pkg.parent) not in text


def test_results_report_opens_with_its_summary_and_long_lists_closed(page, tmp_path):
    """Summary first on the screen; the 51-channel and 24-muscle lists collapsed until opened."""
    import pinmsk
    from pinmsk.presentation.report import write_results_report
    from test_report_summary import _results

    out = write_results_report(tmp_path / "so.html", model=pinmsk.load_model("forearm"), trial=None,
                               results=_results(24))
    check_html_in_browser(page, out, min_images=2, screenshot=tmp_path / "so.png")
    first = page.evaluate("(() => { const h = document.querySelector('h2'); "
                          "return [h.textContent, h.getBoundingClientRect().top]; })()")
    assert first[0] == "Summary" and first[1] < 150
    closed = page.evaluate("[...document.querySelectorAll('details')].map(d => "
                           "[d.querySelector('summary').textContent, d.open, d.getBoundingClientRect().height])")
    names = [c[0] for c in closed]
    assert "51 channels" in names and "24 muscles" in names
    assert all(not c[1] and c[2] < 40 for c in closed)                # closed: one line tall
