"""The scipy.signal-free filters (pinmsk.signals.iir) and dense spline maps (pinmsk.signals.bspline) against
SciPy's own functions, on both sides of the length where filtering hands over to SciPy."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from pinmsk.signals import bspline, filtering, iir

from scipy import signal


@pytest.fixture(autouse=True)
def numpy_paths(monkeypatch):
    """The numpy code paths by length alone (this module has imported SciPy, which would switch them off)."""
    monkeypatch.setattr(iir, "use_numpy", lambda n, *args, **kwargs: n <= iir.SHORT)
    monkeypatch.setattr(bspline, "use_dense", lambda n: n <= bspline.DENSE)


def test_scipy_takes_over_once_imported_or_after_the_budget(monkeypatch):
    monkeypatch.undo()
    assert not iir.use_numpy(100)                        # scipy.signal is imported (above)
    assert iir.use_numpy(100, module="a.module.not.imported", spent=[0.0])
    assert not iir.use_numpy(100, module="a.module.not.imported", spent=[iir.BUDGET])
    assert not iir.use_numpy(iir.SHORT + 1, module="a.module.not.imported", spent=[0.0])


@pytest.mark.parametrize("order", range(1, 11))
def test_the_butterworth_design_and_its_initial_state_are_scipys(order):
    for wn in (0.005, 0.04, 0.12, 0.3, 0.5, 0.77, 0.97):
        ref = signal.butter(order, wn, output="sos")
        np.testing.assert_allclose(iir.butter_sos(order, wn), ref, rtol=1e-13, atol=1e-300)
        np.testing.assert_allclose(iir.sosfilt_zi(ref), signal.sosfilt_zi(ref), rtol=1e-11, atol=1e-14)


@pytest.mark.parametrize("n", [40, iir.SHORT, iir.SHORT + 1])
def test_the_recursions_are_scipys(n):
    rng = np.random.default_rng(n)
    x = rng.standard_normal((n, 3)).cumsum(axis=0)
    sos = signal.butter(4, 0.07, output="sos")
    zi = signal.sosfilt_zi(sos)[:, :, None] * x[0]
    y, zf = iir.sosfilt(sos, x, zi=zi)
    y_ref, zf_ref = signal.sosfilt(sos, x, axis=0, zi=zi)
    np.testing.assert_allclose(y, y_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(zf, zf_ref, rtol=1e-13, atol=1e-12)
    b, a = signal.butter(3, 0.1)
    for k in range(3):                      # one channel at a time: 1-D signals too
        zi = signal.lfiltic(b, a, y=x[2::-1, k], x=x[2::-1, k])
        np.testing.assert_allclose(iir.lfiltic(b, a, y=x[2::-1, k], x=x[2::-1, k]), zi, rtol=1e-13, atol=1e-13)
        y, zf = iir.lfilter(b, a, x[:, k], zi=zi)
        y_ref, zf_ref = signal.lfilter(b, a, x[:, k], zi=zi)
        np.testing.assert_allclose(y, y_ref, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(zf, zf_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(iir.lfilter_zi(b, a), signal.lfilter_zi(b, a), rtol=1e-12)


def test_lowpass_is_scipys_sosfiltfilt_step_by_step():
    rng = np.random.default_rng(3)
    t = np.arange(300) / 100.0
    x = np.column_stack([np.sin(2 * np.pi * 1.3 * t), np.cos(t)]) + 0.05 * rng.standard_normal((300, 2))
    pad = filtering.filter_padlen(4, rate=100.0, cutoff=6.0, n=300)
    ref = signal.sosfiltfilt(signal.butter(4, 6.0 / 50.0, output="sos"), x, axis=0, padtype="odd", padlen=pad)
    np.testing.assert_allclose(filtering.lowpass(x, rate=100.0, cutoff=6.0), ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n", [6, 9, 151, bspline.DENSE])
def test_dense_spline_maps_are_scipys(n, monkeypatch):
    from scipy import interpolate
    rng = np.random.default_rng(n)
    t = np.sort(rng.uniform(0.0, 2.0, n)) if n < 20 else np.arange(n) / 60.0
    x = np.sin(3.0 * t)[:, None] * np.arange(1.0, 4.0) + 0.01 * rng.standard_normal((n, 3))
    np.testing.assert_array_equal(bspline.not_a_knot(t, 5), interpolate.make_interp_spline(t, x, k=5).t)
    dense = filtering._QuinticOperators(t)
    assert dense.lu is None                                    # the dense maps
    ref = interpolate.make_interp_spline(t, x, k=5)
    c = dense.solve(x)
    np.testing.assert_allclose(c, ref.c, rtol=1e-10, atol=1e-10 * np.abs(ref.c).max())
    for d, op in ((1, dense.d1), (2, dense.d2)):
        want = ref.derivative(d)(t)
        np.testing.assert_allclose(op @ c, want, rtol=0, atol=1e-10 * np.abs(want).max())
    monkeypatch.setattr(bspline, "DENSE", 0)                   # SciPy's sparse maps: the same numbers
    sparse = filtering._QuinticOperators(t)
    assert sparse.lu is not None
    np.testing.assert_allclose(sparse.d2 @ sparse.solve(x), dense.d2 @ c, rtol=0, atol=1e-11 * np.abs(want).max())


def test_differentiating_a_short_trial_imports_no_scipy_signal_or_interpolate():
    code = ("import sys, numpy as np\n"
            "from pinmsk.signals.filtering import differentiate\n"
            "t = np.arange(200) / 100.0\n"
            "differentiate(t, np.sin(t)[:, None] * [1.0, 2.0], cutoff=6.0)\n"
            "print(sorted(m for m in sys.modules if m.startswith(('scipy.signal', 'scipy.interpolate', "
            "'scipy.sparse'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
