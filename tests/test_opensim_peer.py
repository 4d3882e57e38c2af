"""OpenSim as an optional peer: the benchmark harness, and a physics cross-check with no model conversion.

Skipped, with the reason, when ``opensim`` is not importable (``pip install opensim``); the
harness test also needs ``../shared/data/opensim-models`` (see its SOURCE.md).  OpenSim is never
a pinmsk dependency: only this file and ``benchmarks/bench_opensim.py`` import it.
"""
import importlib.util
import os

import numpy as np
import pytest

import pinmsk
from pinmsk import skeleton
from pinmsk.io.shared_data import shared_data_dir

from conftest import REPO, LazyOpenSim

osim = LazyOpenSim()   # imported inside the tests, never at collection (tests/conftest.py)

needs_opensim = pytest.mark.usefixtures("opensim_module")


def _harness():
    """benchmarks/bench_opensim.py as a module, without leaking its thread-limit env defaults."""
    saved = dict(os.environ)
    try:
        spec = importlib.util.spec_from_file_location("bench_opensim", REPO / "benchmarks" / "bench_opensim.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    finally:
        os.environ.clear()
        os.environ.update(saved)
    return mod


@pytest.fixture
def arm26():
    d = shared_data_dir()
    folder = None if d is None else d / "opensim-models" / "Arm26"
    if folder is None or not folder.is_dir():
        pytest.skip("../shared/data/opensim-models/Arm26 is absent (OpenSim's Arm26 model and reference outputs)")
    return folder


# ---------------------------------------------------------------------------
# The harness reproduces OpenSim's own reference output
# ---------------------------------------------------------------------------

@needs_opensim
def test_harness_reproduces_arm26_reference_inverse_dynamics(arm26, tmp_path):
    bo = _harness()
    staged = bo.stage(arm26, tmp_path / "Arm26")
    setup = staged / "arm26_Setup_InverseDynamics.xml"
    # the setup filters at 6 Hz and names FilteredResults: the Filtered reference is its output
    assert "FilteredResults" in setup.read_text()
    _, sto = bo.opensim_id(osim, setup, results=tmp_path / "filtered")
    ref = arm26 / "reference_outputs"
    err, scale = bo.compare_sto(sto, ref / "InverseDynamics_Filtered" / "arm26_InverseDynamics.sto")
    assert scale > 1.0  # moments of a few N m: the comparison is not vacuous
    assert err <= 1e-6 * scale, f"max |diff| {err:.3g} vs reference (max |tau| {scale:.3g})"
    # the same harness without the filter reproduces the Unfiltered reference
    _, sto_u = bo.opensim_id(osim, setup, cutoff=-1.0, results=tmp_path / "unfiltered")
    err_u, scale_u = bo.compare_sto(sto_u, ref / "InverseDynamics_Unfiltered" / "arm26_InverseDynamics.sto")
    assert err_u <= 1e-6 * scale_u
    # and the two references really differ (so each comparison can tell them apart)
    assert bo.compare_sto(sto, sto_u)[0] > 1e-3
    # nothing was written next to the inputs (results and logs stay in the results folders)
    assert not (staged / "opensim.log").exists() and not (staged / "FilteredResults").exists()


# ---------------------------------------------------------------------------
# Physics cross-check: one pendulum built in both, same q(t)
# ---------------------------------------------------------------------------

MASS = 1.7
COM = np.array([0.05, -0.25, 0.02])            # body frame, m
INERTIA = (0.03, 0.01, 0.025, 0.002, -0.001, 0.0015)  # about the COM: Ixx Iyy Izz Ixy Ixz Iyz, kg m^2
PARENT_LOC = np.array([0.1, 1.2, -0.05])       # joint frame in ground, m
PARENT_TILT = 1.2                              # rad about x: pin axis (0, -sin, cos) in ground
CHILD_LOC = np.array([0.0, 0.3, 0.0])          # joint frame in the body frame, m

URDF = """<?xml version="1.0"?>
<robot name="pendulum">
  <link name="world"/>
  <link name="link">
    <inertial>
      <origin xyz="{cx} {cy} {cz}" rpy="0 0 0"/>
      <mass value="{m}"/>
      <inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="{ixy}" ixz="{ixz}" iyz="{iyz}"/>
    </inertial>
  </link>
  <joint name="pin" type="revolute">
    <parent link="world"/>
    <child link="link"/>
    <origin xyz="{px} {py} {pz}" rpy="{tilt} 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-10" upper="10" effort="1000" velocity="100"/>
  </joint>
</robot>
"""


def _trajectory(n=201, duration=2.0):
    """q, v, a (rad, rad/s, rad/s^2) of q(t) = 0.3 + 1.2 sin(2 pi 0.8 t) + 0.4 sin(2 pi 2.1 t + 0.5)."""
    t = np.linspace(0.0, duration, n)
    q, v, a = np.full(n, 0.3), np.zeros(n), np.zeros(n)
    for amp, f, ph in ((1.2, 0.8, 0.0), (0.4, 2.1, 0.5)):
        w = 2 * np.pi * f
        q += amp * np.sin(w * t + ph)
        v += amp * w * np.cos(w * t + ph)
        a -= amp * w ** 2 * np.sin(w * t + ph)
    return t, q, v, a


def _opensim_pendulum(gravity):
    model = osim.Model()
    model.setName("pendulum")
    model.setGravity(osim.Vec3(*map(float, gravity)))
    body = osim.Body("link", MASS, osim.Vec3(*COM), osim.Inertia(*INERTIA))  # inertia about the COM
    model.addBody(body)
    joint = osim.PinJoint("pin", model.getGround(), osim.Vec3(*PARENT_LOC), osim.Vec3(PARENT_TILT, 0, 0),
                          body, osim.Vec3(*CHILD_LOC), osim.Vec3(0, 0, 0))
    model.addJoint(joint)
    state = model.initSystem()
    return model, joint.updCoordinate(), state


@needs_opensim
def test_pendulum_inverse_dynamics_matches_opensim(tmp_path):
    # pinmsk: the URDF's link frame is the joint (child) frame, so the COM is COM - CHILD_LOC there
    c = COM - CHILD_LOC
    ixx, iyy, izz, ixy, ixz, iyz = INERTIA
    path = tmp_path / "pendulum.urdf"
    path.write_text(URDF.format(cx=c[0], cy=c[1], cz=c[2], m=MASS, ixx=ixx, iyy=iyy, izz=izz, ixy=ixy,
                                ixz=ixz, iyz=iyz, px=PARENT_LOC[0], py=PARENT_LOC[1], pz=PARENT_LOC[2],
                                tilt=PARENT_TILT))
    model = pinmsk.load_model(path)
    assert model.nv == 1
    gravity = np.asarray(model.pin.gravity.linear, dtype=float)  # a bare URDF has no gravity: use pinmsk's
    assert np.linalg.norm(gravity) > 9.0

    t, q, v, a = _trajectory()
    tau_pm = skeleton.rnea(model, q[:, None], v[:, None], a[:, None])[:, 0]

    with _harness().quiet(osim):
        om, coord, state = _opensim_pendulum(gravity)
    solver = osim.InverseDynamicsSolver(om)
    tau_os = np.empty_like(q)
    for k in range(q.size):
        state.setTime(float(t[k]))
        coord.setValue(state, float(q[k]), False)
        coord.setSpeedValue(state, float(v[k]))
        om.realizeVelocity(state)
        tau_os[k] = solver.solve(state, osim.Vector(1, float(a[k]))).get(0)

    # For a pin about the joint z axis only the mass, the COM's offset from the axis, Izz (about the
    # COM, in the joint frame) and the joint placement / tilt enter tau; a 1 % error in Izz gives
    # ~5e-4 relative, far above the tolerance.  Both terms matter over the trajectory:
    g_only = skeleton.rnea(model, q[:, None], 0 * v[:, None], 0 * a[:, None])[:, 0]
    assert np.ptp(g_only) > 1.0 and np.max(np.abs(tau_pm - g_only)) > 1.0
    scale = np.max(np.abs(tau_os))
    err = np.max(np.abs(tau_pm - tau_os))
    assert err <= 1e-6 * scale, f"max |tau_pinmsk - tau_opensim| = {err:.3g} N m (max |tau| {scale:.3g})"
