"""OpenSim's ID-tool coordinate filter (:func:`pinmsk.signals.filtering.lowpass_opensim`) and the
ExternalLoads convention that uses it: the plain ``pinmsk id`` reproduces OpenSim's own ID output."""
import numpy as np
import pytest

import pinmsk
from conftest import shared_folder
from pinmsk.dynamics import inverse_dynamics_result
from pinmsk.signals.filtering import differentiate, lowpass_opensim


def test_gain_is_the_double_butterworth_of_order_three():
    """A double pass of a third-order Butterworth designed by the bilinear transform with a pre-warped
    cut-off: |H|^2 = 1 / (1 + (tan(pi f / fs) / tan(pi fc / fs))^6); 0.5 at the cut-off (long sines, the
    ends left out)."""
    rate, fc = 600.0, 6.0
    t = np.arange(6000) / rate
    for f in (0.5, 6.0, 12.0):
        want = 1 / (1 + (np.tan(np.pi * f / rate) / np.tan(np.pi * fc / rate)) ** 6)
        x = np.sin(2 * np.pi * f * t)
        y, pad = lowpass_opensim(x, rate=rate, cutoff=fc)
        core = slice(pad + 1000, pad + 5000)
        gain = np.sqrt(np.mean(y[core] ** 2) / np.mean(x[1000:5000] ** 2))
        assert gain == pytest.approx(want, rel=2e-3), f
    assert 1 / (1 + 1.0) == 0.5


def test_padding_is_half_the_trial_by_point_reflection():
    """Half the trial at each end; a constant comes back exactly and a ramp (which the point reflection
    continues) within 1e-5 of itself in the trial (the warm start's transient, decayed)."""
    y, pad = lowpass_opensim(np.full(41, 3.0), rate=100.0, cutoff=6.0)
    assert pad == 20 and y.shape == (81,) and np.allclose(y, 3.0, atol=1e-12)
    x = np.linspace(0.0, 1.0, 201)
    y, pad = lowpass_opensim(x, rate=200.0, cutoff=6.0)
    assert pad == 100 and np.max(np.abs(y[pad:pad + 201] - x)) < 1e-5


def test_opensim_method_differentiates_through_the_padded_spline():
    """On a parabola the symmetric filter changes only the offset, so the derivatives in the trial's core
    are the parabola's; a bad method is refused by name."""
    t = np.linspace(0.0, 2.0, 201)
    x = 1 + t + t ** 2
    q, v, a = differentiate(t, x, cutoff=6.0, method="opensim")
    core = slice(50, 151)
    assert np.allclose(v[core], 1 + 2 * t[core], atol=1e-3) and np.allclose(a[core], 2.0, atol=1e-2)
    with pytest.raises(pinmsk.TrialError, match="coordinate filter must be one of"):
        differentiate(t, x, cutoff=6.0, method="gcv")


def test_plain_id_with_external_loads_reproduces_opensims_reference():
    """``inverse_dynamics_result`` with OpenSim's ExternalLoads file (no other option) against the model's
    ``reference_outputs/ID/subject01_walk_ID.sto``: within 0.01 % RMS of peak on every column (it was 1.8 %
    with pinmsk's own 4th-order Butterworth), and the output says which filter ran."""
    d = shared_folder("opensim-models/Gait10dof18musc", "reference_outputs/ID/subject01_walk_ID.sto")
    model = pinmsk.load_model(d / "subject01.osim", nonlinear="exact")
    trial = pinmsk.read_trial(d / "IK" / "subject01_walk_IK.mot")
    res = inverse_dynamics_result(model, trial, external_loads=d / "ExperimentalData" / "subject01_walk_grf.xml")
    ref = pinmsk.read_trial(d / "reference_outputs" / "ID" / "subject01_walk_ID.sto")
    assert res.trial.meta["lowpass_method"] == "opensim"
    assert np.allclose(res.trial.time, ref.time, atol=1e-5)
    for n in ref.names:
        ours = res.trial[n.replace("_force", "_moment")]
        assert np.sqrt(np.mean((ours - ref[n]) ** 2)) < 1e-4 * np.max(np.abs(ref[n])), n
