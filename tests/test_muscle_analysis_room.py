"""Muscle analysis keeps going where a muscle's rigid-tendon fiber has no room (l_mt <= l_slack)."""
import tarfile
import types
import warnings

import numpy as np
import pytest

from conftest import shared_folder
from pinmsk.muscles.models import Thelen2003
from pinmsk.solvers.muscle_analysis import FiberRoomWarning, _fiber_lengths


def test_fiber_without_room_is_nan_at_those_frames_and_named_once():
    """Fiber length sqrt((l_mt - l_slack)^2 + h^2) (h = l_opt sin(alpha0)) where there is room; NaN where
    l_mt <= l_slack, in that muscle only, with one warning line naming it and its frames."""
    mtu = Thelen2003(f_max=[1000.0, 800.0], l_opt=[0.1, 0.08], l_slack=[0.2, 0.3], pennation=[0.0, 0.2],
                     names=["a", "b"])
    ms = types.SimpleNamespace(mtu=mtu, names=("a", "b"))
    l_mt = np.array([[0.35, 0.40], [0.34, 0.30], [0.33, 0.29], [0.32, 0.38]])
    v_mt = np.zeros_like(l_mt)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        l_ce = _fiber_lengths(ms, l_mt, v_mt)
    h = np.array([0.0, 0.08 * np.sin(0.2)])
    expect = np.sqrt((l_mt - [0.2, 0.3]) ** 2 + h ** 2)
    assert np.allclose(l_ce[:, 0], expect[:, 0], rtol=0, atol=1e-15)
    assert np.isnan(l_ce[1:3, 1]).all()
    assert np.allclose(l_ce[[0, 3], 1], expect[[0, 3], 1], rtol=0, atol=1e-15)
    msgs = [str(w.message) for w in caught if issubclass(w.category, FiberRoomWarning)]
    assert len(msgs) == 1 and "\n" not in msgs[0]
    assert "b (2 of 4 frames, first at frame 1)" in msgs[0] and "a (" not in msgs[0]


@pytest.mark.slow
def test_jumper_muscle_analysis_keeps_going_where_fibers_have_no_room(tmp_path):
    """Jumper (zoo): muscles whose rigid-tendon fiber has no room at some poses (tfl_l among them in OpenSim-range sweeps); the CLI writes the analysis,
    tfl_l's fiber length NaN there, every other channel finite."""
    from pinmsk.io.osim import read_osim
    from pinmsk.model import import_osim
    from pinmsk.solvers.muscle_analysis import muscle_analysis
    from pinmsk.trial import Trial
    zoo = shared_folder("osim-zoo", "zoo_models.tar.xz")
    with tarfile.open(zoo / "zoo_models.tar.xz") as tar:
        tar.extract("Jumper.osim", tmp_path, filter="data")
    model, _ = import_osim(tmp_path / "Jumper.osim")
    ranges = {c.name: c.range for c in read_osim(tmp_path / "Jumper.osim").coordinates}
    t = np.linspace(0.0, 1.0, 41)
    q = {}
    for k, c in enumerate(model.coordinate_order):
        lo, hi = ranges.get(c, (-0.3, 0.3))
        lo, hi = max(lo, -1.5), min(hi, 1.5)
        q[c] = 0.5 * (lo + hi) + 0.45 * (hi - lo) * np.sin(2 * np.pi * t + k)
    trial = Trial(t, q)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = muscle_analysis(model, trial)
    msgs = [str(w.message) for w in caught if issubclass(w.category, FiberRoomWarning)]
    assert len(msgs) == 1
    bad = [n for n in model.muscles.names if np.isnan(out[f"{n}_fiber_length"]).any()]
    assert bad and all(n in msgs[0] for n in bad)
    assert all(np.isfinite(out[f"{n}_length"]).all() for n in model.muscles.names)
