"""Diagnosis figures: every axis carries its unit; the residual heat map's scale spans the data."""
from __future__ import annotations

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose.diagnosis import diagnose
from pinmsk.io.shared_data import shipped_trial
from pinmsk.io.tables import read_trial
from pinmsk.presentation import plots


@pytest.fixture(scope="module")
def diag():
    model = pinmsk.load_model("forearm")
    trial = read_trial(shipped_trial("forearm_payload.csv"))
    return diagnose(model, trial.slice_time(0.0, 3.0))


def test_comparison_and_contribution_axes_name_their_units(diag):
    fig = plots.plot_comparison(diag)
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == ["N m", "residual (N m)"]          # elbow_flexion is a rotation: a moment
    assert fig.axes[-1].get_xlabel() == "time (s)"
    fig = plots.plot_effect_contribution(diag)
    assert [ax.get_ylabel() for ax in fig.axes] == ["N m"]


def test_channel_unit_by_level(diag):
    c = diag.comparison
    assert plots.channel_unit(c, 0) == "N m"
    from dataclasses import replace
    assert plots.channel_unit(replace(c, mode="motion"), 0) == "rad"
    contact = replace(c, mode="contact", channels=("ground_force_vy", "ground_force_px"),
                      coordinates=("ground_force_vy", "ground_force_px"))
    assert [plots.channel_unit(contact, j) for j in range(2)] == ["N", "m"]


def test_heatmap_scale_spans_the_data_on_a_symmetric_log(diag):
    from matplotlib.colors import SymLogNorm

    fig = plots.plot_residual_heatmap(diag)
    im = fig.axes[0].images[0]
    z = diag.comparison.residual / diag.comparison.noise.sigma
    assert isinstance(im.norm, SymLogNorm)
    assert im.norm.vmax == pytest.approx(max(np.abs(z).max(), 2.0))
    assert im.norm.vmin == -im.norm.vmax
    # the colours show structure: few pixels at the ends of the scale (a saturating linear scale
    # clipped at 5 floors put most of this trial there)
    rgba = im.to_rgba(im.get_array())
    ends = np.all(np.isclose(rgba, im.cmap(1.0)), axis=-1) | np.all(np.isclose(rgba, im.cmap(0.0)), axis=-1)
    assert ends.mean() < 0.05
    assert np.mean(np.abs(z) >= 5.0) > 0.5                # this residual is far above the floor
    assert fig.axes[1].get_ylabel() == "residual / floor"
