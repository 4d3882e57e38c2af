"""Results figures (pinmsk.presentation.plots): muscles, EMG, SO vs FSO -- real numbers, headless."""
from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

import pinmsk
from pinmsk.presentation import plots
from pinmsk.errors import PinmskError
from pinmsk.solvers.analytical import gaussian_elbow_trial
from pinmsk.solvers.static import StaticOptimization


@pytest.fixture(scope="module")
def so():
    model = pinmsk.load_model("forearm")
    trial = gaussian_elbow_trial(n_frames=81)
    return model, trial, StaticOptimization().fit(model, trial)


def test_muscles_in_and_force_figure(so, tmp_path):
    model, _, fit = so
    assert plots.muscles_in(fit.result_, "force") == list(model.muscle_names)
    fig = plots.plot_muscles(fit.result_, quantity="force", path=tmp_path / "f.png")
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    assert [l.get_label() for l in ax.lines] == list(model.muscle_names)
    np.testing.assert_allclose(ax.lines[0].get_ydata(), fit.forces_[:, 0])
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_emg_correlation_independent(so):
    _, _, fit = so
    r = fit.result_
    t = np.asarray(r.time)
    # EMG on a finer time base (another Trial), channels named <muscle>
    te = np.linspace(t[0], t[-1], 401)
    rng = np.random.default_rng(1)
    emg = pinmsk.Trial(te, {"BRD": np.interp(te, t, r["BRD_activation"]) + 0.01 * rng.normal(size=te.size),
                            "TRILH": np.sin(te)})
    got = plots.emg_correlations(r, emg)
    assert set(got) == {"BRD", "TRILH"}
    expect = np.corrcoef(r["TRILH_activation"], np.sin(t))[0, 1]
    assert got["TRILH"] == pytest.approx(expect, abs=1e-12)
    assert got["BRD"] > 0.99
    fig = plots.plot_muscles(r, quantity="activation", emg=emg)
    labels = [l.get_label() for ax in fig.axes for l in ax.lines]
    assert any(f"r = {expect:.2f}" in s for s in labels)
    with pytest.raises(PinmskError, match="no EMG found"):
        plots.plot_muscles(r, emg=True)


def test_so_vs_fso_alignment_and_difference(so):
    model, trial, fit = so
    a = fit.result_
    t2 = np.linspace(0.1, 1.9, 50)
    b = pinmsk.Trial(t2, {f"{m}_force": 3.0 * t2 + 1.0 for m in model.muscle_names})   # linear: exact interp
    t, mus, A, B = plots.align_results(a, b)
    assert t[0] >= 0.1 - 1e-9 and t[-1] <= 1.9 + 1e-9 and mus == list(model.muscle_names)
    fig = plots.plot_results_comparison(a, b)
    diff = fig.axes[1].lines[0].get_ydata()      # BRD; the zero line comes last
    ta = np.asarray(a.time)
    inside = (ta >= 0.1 - 1e-9) & (ta <= 1.9 + 1e-9)
    np.testing.assert_allclose(diff, 3.0 * ta[inside] + 1.0 - fit.forces_[inside, 0], atol=1e-9)
    far = pinmsk.Trial(t2 + 10, {"BRD_force": t2})
    with pytest.raises(PinmskError, match="do not overlap"):
        plots.align_results(a, far)


def test_save_channels_and_results_figures(so, tmp_path):
    model, trial, fit = so
    r = fit.result_
    paths = plots.save_channels(r, [f"{m}_force" for m in model.muscle_names] * 2, tmp_path, stem="x",
                                per_figure=8)
    assert [p.name for p in paths] == ["x_1.png", "x_2.png"]
    mom = trial.with_channels(elbow_flexion_moment=np.sin(np.asarray(trial.time)))
    out = plots.save_results_figures(r, tmp_path / "res", trial=mom)
    assert set(out) == {"moments", "forces", "activations"}
    assert all(p.stat().st_size > 1000 for p in out.values())
