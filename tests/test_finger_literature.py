"""The literature-based finger (built-in ``finger_literature``).

Its parameters are the cited values (urdf/finger_literature.toml, urdf/README.md): the inertia
about the MCP is recomputed here from the segment table, the lumped flexor from the FDSI and FDPI
values of the Gonzalez, Buchanan & Delp (1997) wrist model; and the frequency limit's mechanism is
checked on the optimal-control engine with real numbers.  casadi only (never opensim here).
"""
import json
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import pinmsk

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

# Segments, approximately after Buchner, Hines & Hemami 1988: (length m, mass kg, radius m), uniform cylinders.
SEGMENTS = [(0.045, 0.014, 0.0085), (0.026, 0.007, 0.0075), (0.018, 0.004, 0.0065)]
# opensim-models Models/WristModel/wrist.osim (Gonzalez et al. 1997 after Lieber et al. 1992):
# (F_max N, l_opt m, l_slack m, pennation rad)
FDSI = (51.3, 0.0835, 0.338, 0.10471976)
FDPI = (53.1, 0.0749, 0.322, 0.12217305)
EDCI = (23.4, 0.0700, 0.385, 0.05235988)


@pytest.fixture(scope="module")
def model():
    return pinmsk.load_model("finger_literature")


def test_inertia_about_the_mcp_is_the_segment_composite(model):
    x, mass, i_mcp, first = 0.0, 0.0, 0.0, 0.0
    for length, m, radius in SEGMENTS:
        c = x + length / 2                       # the segment's COM along the finger
        i_mcp += m * (3 * radius**2 + length**2) / 12 + m * c**2    # parallel-axis theorem
        mass += m
        first += m * c
        x += length
    pm = model.pin
    assert model.coordinates == ("mcp_flexion",)
    M = pin.crba(pm, pm.createData(), np.zeros(1))
    assert M[0, 0] == pytest.approx(i_mcp, rel=1e-12) == pytest.approx(5.949389583333333e-05, rel=1e-12)
    assert pin.computeTotalMass(pm) == pytest.approx(mass, rel=1e-12) == pytest.approx(0.025)
    np.testing.assert_allclose(pin.centerOfMass(pm, pm.createData(), np.zeros(1)), [first / mass, 0, 0],
                               atol=1e-15)
    # horizontal at q = 0, gravity flexes it: the gravity moment is m g x_com (rnea at rest, about -z)
    tau = pin.rnea(pm, pm.createData(), np.zeros(1), np.zeros(1), np.zeros(1))
    assert tau[0] == pytest.approx(-mass * 9.81 * first / mass, rel=1e-12)


def test_muscle_parameters_are_the_cited_values(model):
    ms = model.muscles
    mtu = ms.mtu
    assert ms.names == ("flexor", "extensor")
    f = FDSI[0] + FDPI[0]
    flexor = (f, *(sum(a[k] * a[0] for a in (FDSI, FDPI)) / f for k in (1, 2, 3)))   # F_max-weighted lumping
    for i, cited in enumerate((flexor, EDCI)):
        np.testing.assert_allclose([mtu.f_max[i], mtu.l_opt[i], mtu.l_slack[i], mtu.pennation[i]], cited,
                                   rtol=1e-12)
    np.testing.assert_allclose(mtu.f_max, [104.4, 23.4], rtol=1e-15)
    np.testing.assert_allclose(mtu.v_max, 10 * mtu.l_opt, rtol=1e-12)      # Thelen 2003 / wrist.osim: 10 l_opt/s
    assert (mtu.tau_rise, mtu.tau_fall) == (0.011, 0.068)
    # constant MCP moment arms (An et al. 1983, approximately) and fibers at l_opt at q = 0 (rigid tendon)
    q = np.array([[0.0], [0.21], [-0.21]])
    np.testing.assert_allclose(ms.moment_arms(q)[:, :, 0], [[0.011, -0.0086]] * 3, rtol=1e-15)
    l_mt = ms.lengths(q)
    np.testing.assert_allclose(l_mt[0], mtu.l_slack + mtu.l_opt * np.cos(mtu.pennation), rtol=1e-12)
    np.testing.assert_allclose(l_mt[1] - l_mt[0], [-0.011 * 0.21, 0.0086 * 0.21], rtol=1e-9)


def test_tracking_cost_rises_with_frequency_across_the_limit(model):
    """The mechanism on the engine: 8 Hz tracks (J2 ~ 5e-4), 32 Hz does not (J2 ~ 0.43 > 0.25);
    J1 rises with it (the extensor saturates).  Two solves, ~0.4 s each."""
    pytest.importorskip("casadi")
    sys.path.insert(0, str(EXAMPLES))
    import finger_frequency_limit as ffl
    lo, _ = ffl.solve(model, 8.0)
    hi, _ = ffl.solve(model, 32.0)
    assert lo.converged and hi.converged
    assert lo.terms["tracking"] < 2e-3 < ffl.J2_LIMIT < hi.terms["tracking"] < 0.5
    assert lo.terms["effort"] < hi.terms["effort"]
    assert lo.objective == pytest.approx(0.1 * lo.terms["effort"] + 0.9 * lo.terms["tracking"], rel=1e-9)
    ext = np.asarray(hi["extensor_activation"], dtype=float)
    assert ext.max() > 0.9                                   # the weak extensor is near full activation


def test_steady_cycle_is_limited_by_activation_dynamics(model):
    """A periodic tapping cycle at 8 Hz: tracked with the model's time constants (J2 ~ 0.06),
    lost with both doubled (J2 > 0.25; the steady-cycle limit falls from 10.9 to 7.2 Hz)."""
    pytest.importorskip("casadi")
    sys.path.insert(0, str(EXAMPLES))
    import finger_frequency_limit as ffl
    mtu = model.muscles.mtu
    slow = ffl.with_mtu(model, tau_rise=2 * mtu.tau_rise, tau_fall=2 * mtu.tau_fall)
    assert (slow.muscles.mtu.tau_rise, slow.muscles.mtu.tau_fall) == (0.022, 0.136)
    base, _ = ffl.solve(model, 8.0, periodic=True)
    lost, _ = ffl.solve(slow, 8.0, periodic=True)
    assert base.converged and lost.converged
    assert base.terms["tracking"] < 0.1 < ffl.J2_LIMIT < lost.terms["tracking"]
    q = np.asarray(base["mcp_flexion"], dtype=float)
    assert q[-1] == pytest.approx(q[0], abs=1e-6)          # the cycle closes


@pytest.mark.slow
def test_finger_frequency_limit_quick(tmp_path):
    """The example end to end (--quick: coarse scan, no bisection; ~8 s).  The default test
    test_tracking_cost_rises_with_frequency_across_the_limit covers the same solve."""
    pytest.importorskip("casadi")
    sys.path.insert(0, str(EXAMPLES))
    import finger_frequency_limit as ffl
    ffl.main(["--out", str(tmp_path), "--quick"])
    data = json.loads((tmp_path / "finger_frequency_limit.json").read_text())
    assert (tmp_path / "finger_frequency_limit.png").exists()
    assert 16.0 < data["max_frequency"] < 32.0           # between the scan's last tracked and first lost
    assert data["solved"]["16.0"]["J2"] < ffl.J2_LIMIT < data["solved"]["32.0"]["J2"]
    assert data["at_6Hz"]["converged"] and data["at_6Hz"]["J2"] < 1e-3
    assert data["studies"]["single period (thesis)"]["sweep"]["v_max"][0]["label"] == "x0.5"
