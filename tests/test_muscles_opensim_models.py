"""OpenSim's muscle models in pinmsk: De Groote 2016, Millard 2012 (quintic Bezier curves), Thelen 2003
with OpenSim's constants, and the mapping of .osim muscle properties (pinmsk.opensim.muscles).

Analytic key points and finite-difference derivatives always run; the comparisons with OpenSim's own
curve objects and muscles run when ``opensim`` is importable (skipped with the reason otherwise), the
.osim models when the shared data are present.
"""
import pickle
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from pinmsk.errors import ModelError, TrialError
from pinmsk.muscles import DeGroote2016, Millard2012, Thelen2003, Thelen2003OpenSim
from pinmsk.muscles.degroote2016 import (DeGrooteFregly2016Muscle, degroote_active_force_length,
                                         degroote_active_force_length_derivative, degroote_force_velocity,
                                         degroote_force_velocity_derivative, degroote_force_velocity_inverse,
                                         degroote_passive_force_length,
                                         degroote_passive_force_length_derivative, degroote_tendon_force,
                                         degroote_tendon_force_derivative, degroote_tendon_length)
from pinmsk.muscles.millard2012 import (ActiveForceLengthCurve, FiberForceLengthCurve, ForceVelocityCurve,
                                        ForceVelocityInverseCurve, Millard2012EquilibriumMuscle,
                                        QuinticBezierCurve, TendonForceLengthCurve)
from pinmsk.muscles.models import MUSCLE_MODELS
from pinmsk.muscles.muscle_set import MuscleSet
from pinmsk.muscles.tendon import thelen_tendon_force
from pinmsk.opensim.muscles import (muscle_from_osim, muscle_model_from_osim,
                                    opensim_static_optimization_capacity, properties_from_xml,
                                    summarize_notes)

from conftest import LazyOpenSim

osim = LazyOpenSim()   # imported inside the tests, never at collection (tests/conftest.py)
needs_opensim = pytest.mark.usefixtures("opensim_module")


def fd(f, x, h=1e-6):
    return (f(x + h) - f(x - h)) / (2.0 * h)


# --------------------------------------------------------------------------- De Groote curves
def test_degroote_key_points():
    # OpenSim's constants make the curves pass through their key points (header of DeGrooteFregly2016Muscle)
    for w in (1.0, 1.5):
        assert degroote_active_force_length(1.0, width_scale=w) == pytest.approx(1.0, abs=1e-15)
    assert degroote_force_velocity(0.0) == pytest.approx(1.0, abs=1e-15)
    assert degroote_force_velocity(-1.0) == pytest.approx(0.0, abs=1e-15)
    assert degroote_force_velocity(1.0) == pytest.approx(1.794, abs=5e-4)     # "Range: [0, 1.794]"
    for e0 in (0.6, 0.45):
        assert degroote_passive_force_length(0.2, strain=e0) == pytest.approx(0.0, abs=1e-15)
        assert degroote_passive_force_length(1.0 + e0, strain=e0) == pytest.approx(1.0, abs=1e-14)
    for et in (0.049, 0.033):
        assert degroote_tendon_force(1.0, strain=et) == pytest.approx(0.0, abs=1e-15)
        assert degroote_tendon_force(1.0 + et, strain=et) == pytest.approx(1.0, abs=1e-14)
    # width scale stretches the curve about its peak
    lx = np.linspace(0.5, 1.6, 23)
    np.testing.assert_allclose(degroote_active_force_length((lx - 1.0) * 1.7 + 1.0, width_scale=1.7),
                               degroote_active_force_length(lx), atol=1e-15)


def test_degroote_derivatives_and_inverses():
    lx = np.linspace(0.3, 1.7, 57)
    v = np.linspace(-1.2, 1.2, 49)
    lt = np.linspace(0.97, 1.08, 23)
    for w in (1.0, 1.4):
        np.testing.assert_allclose(degroote_active_force_length_derivative(lx, width_scale=w),
                                   fd(lambda x: degroote_active_force_length(x, width_scale=w), lx),
                                   rtol=1e-7, atol=1e-8)
    np.testing.assert_allclose(degroote_passive_force_length_derivative(lx, strain=0.5),
                               fd(lambda x: degroote_passive_force_length(x, strain=0.5), lx), rtol=1e-7)
    np.testing.assert_allclose(degroote_force_velocity_derivative(v), fd(degroote_force_velocity, v), rtol=1e-7)
    np.testing.assert_allclose(degroote_tendon_force_derivative(lt, strain=0.04),
                               fd(lambda x: degroote_tendon_force(x, strain=0.04), lt), rtol=1e-7)
    np.testing.assert_allclose(degroote_force_velocity_inverse(degroote_force_velocity(v)), v, atol=1e-13)
    f = np.linspace(-0.1, 3.0, 32)
    np.testing.assert_allclose(degroote_tendon_force(degroote_tendon_length(f, strain=0.06), strain=0.06), f,
                               atol=1e-13)


def test_degroote_properties_are_checked_by_name():
    with pytest.raises(ModelError, match="active_force_width_scale"):
        DeGrooteFregly2016Muscle(active_force_width_scale=0.5)
    with pytest.raises(ModelError, match="pennation_angle_at_optimal"):
        DeGrooteFregly2016Muscle(pennation_angle_at_optimal=1.6)
    with pytest.raises(ModelError, match=r"damping = -0.1 for muscle 1 \('b'\)"):
        DeGroote2016(f_max=1.0, l_opt=0.1, l_slack=0.2, damping=[0.0, -0.1], names=["a", "b"])


# --------------------------------------------------------------------------- Millard curves
def _joints(curve: QuinticBezierCurve):
    return curve.ctrl_x[0, :, 0][1:]


def test_millard_curves_key_points():
    afl = ActiveForceLengthCurve(0.44, 0.63, 1.81, 0.86, 0.1)
    assert afl.value(1.0) == pytest.approx(1.0, abs=1e-15)
    assert afl.derivative(1.0) == pytest.approx(0.0, abs=1e-12)
    for x in (0.44, 1.81, 0.2, 2.2):
        assert afl.value(x) == pytest.approx(0.1, abs=1e-15)
    fpe = FiberForceLengthCurve(0.05, 0.6)
    assert fpe.value(1.05) == pytest.approx(0.0, abs=1e-15)
    assert fpe.value(1.6) == pytest.approx(1.0, abs=1e-15)
    assert fpe.derivative(1.6) == pytest.approx(2.0 / 0.55, rel=1e-12)   # OpenSim's fitted stiffness
    fv = ForceVelocityCurve()
    # (at the segment joints the power-basis polynomials round to ~1e-14, as OpenSim's do)
    assert (fv.value(-1.0), fv.value(0.0), fv.value(1.0)) == pytest.approx((0.0, 1.0, 1.4), abs=1e-13)
    assert fv.derivative(0.0) == pytest.approx(5.0, rel=1e-12)
    tfl = TendonForceLengthCurve(0.049)
    assert tfl.value(1.0) == pytest.approx(0.0, abs=1e-15)
    assert tfl.value(1.049) == pytest.approx(1.0, abs=1e-14)
    assert tfl.derivative(1.049) == pytest.approx(1.375 / 0.049, rel=1e-12)
    assert tfl.value(0.9) == 0.0 and tfl.derivative(0.9) == 0.0          # slack tendon
    f = np.linspace(-0.2, 1.5, 35)
    np.testing.assert_allclose(tfl.value(tfl.inverse(f)), np.maximum(f, 0.0), atol=1e-13)
    # the inverse force-velocity curve of the same settings inverts it exactly on [-1, 1]
    settings = dict(concentric_slope_at_vmax=0.1, concentric_slope_near_vmax=0.25, isometric_slope=5.0,
                    eccentric_slope_at_vmax=0.1, eccentric_slope_near_vmax=0.15,
                    max_eccentric_velocity_force_multiplier=1.4)
    v = np.linspace(-1.0, 1.0, 41)
    fv_of_v = ForceVelocityCurve(**settings).value(v)
    np.testing.assert_allclose(ForceVelocityInverseCurve(**settings).value(fv_of_v), v, atol=1e-12)


@pytest.mark.parametrize("curve", [ActiveForceLengthCurve(), ActiveForceLengthCurve(0.25, 0.77, 1.9, 0.75, 0.0),
                                   FiberForceLengthCurve(), FiberForceLengthCurve(0.1, 0.5, 0.3, 4.0, 0.3),
                                   ForceVelocityCurve(), ForceVelocityInverseCurve(),
                                   TendonForceLengthCurve(), TendonForceLengthCurve(0.04, 30.0, 0.5, 0.7)],
                         ids=lambda c: type(c).__name__)
def test_millard_curve_derivatives_and_continuity(curve):
    c = curve.build_curve()
    lo, hi = float(c.x0[0]), float(c.x1[0])
    x = np.linspace(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo), 301)
    x = x[np.min(np.abs(x[:, None] - np.r_[_joints(c), lo, hi]), axis=1) > 1e-4]
    y, d1, d2 = c.evaluate(x, (0, 1, 2))
    h = 1e-6 * (hi - lo)
    np.testing.assert_allclose(d1, fd(c.value, x, h), rtol=1e-6, atol=1e-6 * np.max(np.abs(d1)))
    np.testing.assert_allclose(d2, fd(lambda t: c.derivative(t, 1), x, h), rtol=1e-5,
                               atol=1e-5 * np.max(np.abs(d2)))
    # C2 at every segment joint and at the domain ends (the corners have zero curvature there): across
    # +-1e-10 value, slope and curvature change by no more than 1e-6 of their largest magnitude
    scale = 1.0 + np.max(np.abs([y, d1, d2]), axis=1)
    for xj in np.r_[_joints(c), lo, hi]:
        left = np.array(c.evaluate(xj - 1e-10, (0, 1, 2)))
        right = np.array(c.evaluate(xj + 1e-10, (0, 1, 2)))
        assert np.all(np.abs(left - right) <= 1e-6 * scale), (xj, left - right)


def test_millard_curve_settings_are_checked_by_name():
    with pytest.raises(ModelError, match="transition_norm_fiber_length"):
        ActiveForceLengthCurve(min_norm_active_fiber_length=0.7, transition_norm_fiber_length=0.6)
    with pytest.raises(ModelError, match="all together"):
        FiberForceLengthCurve(stiffness_at_low_force=0.2)
    with pytest.raises(ModelError, match="isometric_slope"):
        ForceVelocityCurve(isometric_slope=0.8)
    with pytest.raises(ModelError, match="norm_force_at_toe_end"):
        TendonForceLengthCurve(0.049, 30.0, 1.5, 0.5)
    # in a model the muscle is named too
    with pytest.raises(ModelError, match=r"muscle 1 \('b'\).*shallow_ascending_slope"):
        Millard2012(f_max=1.0, l_opt=0.1, l_slack=0.2, names=["a", "b"], shallow_ascending_slope=[0.8, 5.0])


def test_stacked_curves_equal_single_curves():
    curves = [TendonForceLengthCurve(e).build_curve() for e in (0.033, 0.049, 0.1)]
    stack = QuinticBezierCurve.stack(curves)
    x = np.linspace(0.98, 1.12, 57)[:, None] * np.ones(3)
    got = stack.evaluate(x, (0, 1, 2))
    for j, c in enumerate(curves):
        for k, ref in enumerate(c.evaluate(x[:, j], (0, 1, 2))):
            np.testing.assert_array_equal(got[k][:, j], ref)
    np.testing.assert_allclose(stack.inverse(stack.value(x)), np.where(x < 1.0, 1.0, x), atol=1e-13)
    with pytest.raises(ModelError, match="3 muscles on the last axis"):
        stack.value(np.ones((4, 2)))


# --------------------------------------------------------------------------- models
MODELS = [DeGroote2016, Millard2012, Thelen2003OpenSim]


@pytest.mark.parametrize("cls", MODELS, ids=lambda c: c.__name__)
def test_model_isometric_force_at_optimal_length(cls):
    pen = np.array([0.0, 0.2, 0.4])
    mtu = cls(f_max=[500.0, 800.0, 1200.0], l_opt=[0.1, 0.08, 0.05], l_slack=[0.2, 0.3, 0.25],
              pennation=pen, names=["a", "b", "c"])
    l_mt = (mtu.l_slack + mtu.l_opt * np.cos(pen))[None]
    fa, fp = mtu.force_limits(l_mt, np.zeros((1, 3)))
    np.testing.assert_allclose(fa[0], mtu.f_max * np.cos(pen), rtol=1e-12)
    np.testing.assert_allclose(mtu.force(1.0, l_mt, np.zeros((1, 3))), fa + fp, rtol=1e-13)
    # F = a F_active + F_passive (activation does not scale velocity in De Groote / Millard; Thelen at v = 0)
    l_mt2 = l_mt * np.linspace(0.95, 1.1, 7)[:, None]
    v = np.zeros_like(l_mt2) if cls is Thelen2003OpenSim else np.linspace(-0.3, 0.3, 7)[:, None] * mtu.l_opt
    fa, fp = mtu.force_limits(l_mt2, v)
    for a in (0.3, 1.0):
        np.testing.assert_allclose(mtu.force(a, l_mt2, v), np.maximum(a * fa + fp, 0.0)
                                   if cls is Millard2012 else a * fa + fp, rtol=1e-12, atol=1e-9)
    # compliant equilibrium: tendon force equals the fiber force along it
    eq = mtu.equilibrium(l_mt2 + 0.005, np.full(3, 0.7))
    l_t = l_mt2 + 0.005 - np.sqrt(eq["l_ce"] ** 2 - mtu.height ** 2)
    np.testing.assert_allclose(mtu.tendon_force(l_t), eq["force"], rtol=1e-12)
    fl, _, fpe, _ = mtu._length_curves(eq["l_ce"] / mtu.l_opt)
    cos = np.sqrt(1.0 - (mtu.height / eq["l_ce"]) ** 2)
    np.testing.assert_allclose(eq["force"], mtu.f_max * (0.7 * fl + fpe) * cos, rtol=1e-9)
    with pytest.raises(ModelError, match="no contraction dynamics"):
        mtu.contraction_rate(eq["l_ce"], l_mt2, 0.5)
    with pytest.raises(ModelError, match="no inverse muscle model"):
        mtu.inverse(eq["force"], 0 * l_mt2, l_mt2, 0 * l_mt2, 0 * l_mt2)
    # immutable, comparable, picklable, registered
    assert pickle.loads(pickle.dumps(mtu)) == mtu and mtu.replace() == mtu
    assert mtu.replace(f_max=[1.0, 2.0, 3.0]) != mtu
    assert MUSCLE_MODELS[cls.model_type] is cls
    with pytest.raises(AttributeError):
        mtu.f_max = 1.0


def test_models_refuse_bad_inputs_by_name():
    mtu = Millard2012(f_max=1000.0, l_opt=0.1, l_slack=0.2, names=["soleus"])
    with pytest.raises(TrialError, match="soleus"):
        mtu.force_limits(np.array([[np.nan]]), np.zeros((1, 1)))
    with pytest.raises(ModelError, match="unknown parameter.*tendon_strain0"):
        Millard2012(f_max=1000.0, l_opt=0.1, l_slack=0.2, tendon_strain0=0.04)
    with pytest.raises(ModelError, match="fv_extrapolation"):
        Thelen2003OpenSim(f_max=1.0, l_opt=0.1, l_slack=0.2, eccentric_force=1.8, fv_extrapolation=0.5)


def test_millard_rigid_floor_and_clamp():
    mtu = Millard2012(f_max=1000.0, l_opt=0.1, l_slack=0.2, damping=0.5)
    # shortening fast at low activation: the damping force would push; OpenSim floors the fiber force at 0
    f = mtu.force(0.01, np.array([0.3]), np.array([-0.9]))
    assert f[0] == 0.0
    fa, fp = mtu.force_limits(np.array([0.3]), np.array([-0.9]))
    assert fp[0] < 0 and 0.01 * fa[0] + fp[0] < 0
    # below the active curve's minimum length the fiber is clamped: no force
    short = 0.2 + 0.9 * mtu.min_norm_active_fiber_length * 0.1
    assert mtu.force(1.0, np.array([short]), np.array([0.0]))[0] == 0.0


def test_per_muscle_curves_and_muscle_set():
    a = Millard2012(f_max=1000.0, l_opt=0.1, l_slack=0.2, tendon_strain=0.033, names=["a"])
    b = Millard2012(f_max=600.0, l_opt=0.12, l_slack=0.25, active_minimum_value=0.1, names=["b"])
    ab = Millard2012(f_max=[1000.0, 600.0], l_opt=[0.1, 0.12], l_slack=[0.2, 0.25],
                     tendon_strain=[0.033, 0.049], active_minimum_value=[0.0, 0.1], names=["a", "b"])
    l_mt = np.array([[0.31, 0.36], [0.29, 0.38]])
    got = ab.equilibrium(l_mt, 0.5)["force"]
    np.testing.assert_allclose(got[:, 0], a.equilibrium(l_mt[:, :1], 0.5)["force"][:, 0], rtol=1e-12)
    np.testing.assert_allclose(got[:, 1], b.equilibrium(l_mt[:, 1:], 0.5)["force"][:, 0], rtol=1e-12)

    class Path:
        def lengths(self, q):
            return 0.33 + 0.02 * np.asarray(q)[:, :1] * np.ones(2)

        def velocities(self, q, v):
            return 0.02 * np.asarray(v)[:, :1] * np.ones(2)

    ms = MuscleSet(names=["a", "b"], model_type=ab.model_type, mtu=ab, path=Path())
    table = ms.parameter_table()
    assert {"muscle:a.f_max", "muscle:b.damping", "muscle:a.v_max"} <= set(table)
    stronger = ms.with_params({"a.f_max": 2000.0})
    fa0 = ms.force_limits(np.zeros((1, 1)), np.zeros((1, 1)))[0]
    fa1 = stronger.force_limits(np.zeros((1, 1)), np.zeros((1, 1)))[0]
    np.testing.assert_allclose(fa1, fa0 * [2.0, 1.0], rtol=1e-13)
    assert stronger.mtu.tendon_strain[0] == 0.033      # the curve settings survive the rebuild


# --------------------------------------------------------------------------- mapping .osim properties
def test_mapping_defaults_notes_and_types():
    m, notes = muscle_from_osim("Thelen2003Muscle", {"name": "bic", "max_isometric_force": "600",
                                                     "optimal_fiber_length": "0.12",
                                                     "tendon_slack_length": "0.2"})
    assert m.model_type == "thelen2003" and m.parameters["v_max"] == pytest.approx(1.2)
    assert m.parameters["tau_rise"] == 0.015 and m.tendon == "compliant"
    toe = [n for n in notes if n.what == "tendon force-length"][0]
    eps = np.linspace(0.0, 0.08, 8001)
    assert toe.max_error == pytest.approx(np.max(np.abs(thelen_tendon_force(eps) - thelen_tendon_force(
        eps, exact_toe=True))), rel=1e-3)
    assert 1e-4 < toe.max_error < 1e-3
    m2, _ = muscle_from_osim("Thelen2003Muscle", {"KshapeActive": "0.5", "Flen": 1.8,
                                                  "FmaxTendonStrain": "0.033"}, name="x")
    assert m2.model_type == "thelen2003_opensim" and m2.parameters["active_shape"] == 0.5
    assert not [n for n in m2.notes if n.kind == "approximated"]
    # Millard: OpenSim's curve adjustment of the undamped elastic-tendon model is applied and noted
    m3, notes3 = muscle_from_osim("Millard2012EquilibriumMuscle", {
        "fiber_damping": "0", "ActiveForceLengthCurve": {"minimum_value": "0"},
        "FiberForceLengthCurve": {"strain_at_one_norm_force": "0.6", "curviness": ""},
        "TendonForceLengthCurve.strain_at_one_norm_force": "0.04"}, name="sol")
    assert m3.parameters["active_minimum_value"] == 0.1 and m3.parameters["concentric_slope_at_vmax"] == 0.125
    assert m3.parameters["passive_strain"] == 0.6 and m3.parameters["tendon_strain"] == 0.04
    assert any(n.kind == "adjusted" and "minimum_value 0 -> 0.1" in n.detail for n in notes3)
    m4, _ = muscle_from_osim("DeGrooteFregly2016Muscle", {"ignore_tendon_compliance": "true",
                                                          "fiber_damping": "0.01", "min_control": "0.02",
                                                          "mystery_property": "1"}, name="d")
    assert m4.tendon == "rigid" and m4.parameters["damping"] == 0.01 and m4.control_bounds == (0.02, 1.0)
    assert any(n.kind == "unknown" and n.what == "mystery_property" for n in m4.notes)
    assert m4.model().n == 1
    lines = summarize_notes(list(notes) + list(m2.notes))
    act = [line for line in lines if "activation dynamics" in line]
    assert len(act) == 1 and act[0].endswith("[2 muscle(s): bic, x]")
    toe_line = [line for line in lines if "tendon force-length" in line][0]
    assert f"max error {toe.max_error:.3g} F_max" in toe_line and toe_line.endswith("[1 muscle(s): bic]")


def test_mapping_refuses_bad_input_by_name():
    with pytest.raises(ModelError, match="Schutte1993Muscle.*not supported"):
        muscle_from_osim("Schutte1993Muscle", {}, name="x")
    with pytest.raises(ModelError, match="'vas'.*max_isometric_force = 'lots' is not a number"):
        muscle_from_osim("Millard2012EquilibriumMuscle", {"max_isometric_force": "lots"}, name="vas")
    with pytest.raises(ModelError, match=r"osim:12.*ActiveForceLengthCurve.*shallow_ascending_slope"):
        muscle_from_osim("Millard2012EquilibriumMuscle",
                         {"ActiveForceLengthCurve": {"shallow_ascending_slope": "9"}},
                         name="vas", where="m.osim:12: <Millard2012EquilibriumMuscle name='vas'>")
    with pytest.raises(ModelError, match="ignore_tendon_compliance = 'maybe'"):
        muscle_from_osim("DeGrooteFregly2016Muscle", {"ignore_tendon_compliance": "maybe"}, name="d")
    with pytest.raises(ModelError, match="mixes 2 OpenSim muscle types"):
        muscle_model_from_osim([("a", "Thelen2003Muscle", {}), ("b", "DeGrooteFregly2016Muscle", {})])


def test_mixed_thelen_constants_map_to_the_exact_model():
    imp = muscle_model_from_osim([("a", "Thelen2003Muscle", {"max_isometric_force": "100"}),
                                  ("b", "Thelen2003Muscle", {"KshapePassive": "4"})])
    assert imp.model_type == "thelen2003_opensim" and imp.mtu.names == ("a", "b")
    assert list(imp.mtu.passive_shape) == [5.0, 4.0]
    assert not [n for n in imp.notes if n.kind == "approximated"]
    same = muscle_model_from_osim([("a", "Thelen2003Muscle", {}), ("b", "Thelen2003Muscle", {})])
    assert same.model_type == "thelen2003" and isinstance(same.mtu, Thelen2003)


def _osim_muscles(path):
    root = ET.parse(path).getroot()
    return [(e.get("name"), e.tag, properties_from_xml(e)) for e in root.iter()
            if e.tag in ("Thelen2003Muscle", "Millard2012EquilibriumMuscle", "DeGrooteFregly2016Muscle")]


@pytest.mark.parametrize("rel, kind, n, tendon", [
    ("Tug_of_War/Tug_of_War_Millard.osim", "millard2012", 2, "compliant"),
    ("Moco2DWalking/2D_gait.osim", "degroote2016", 18, "rigid"),
    ("Arm26/arm26.osim", "thelen2003_opensim", 6, "compliant"),
])
def test_shared_models_isometric_force_at_optimal_length(shared_data, rel, kind, n, tendon):
    path = shared_data / "opensim-models" / rel
    if not path.exists():
        pytest.skip(f"{path} is absent")
    entries = _osim_muscles(path)
    imp = muscle_model_from_osim(entries)
    assert (imp.model_type, imp.mtu.n, imp.tendon) == (kind, n, tendon)
    xml_fmax = np.array([float(p["max_isometric_force"]) for _, _, p in entries])
    np.testing.assert_array_equal(imp.mtu.f_max, xml_fmax)
    mtu = imp.mtu
    l_mt = (mtu.l_slack + mtu.l_opt * np.cos(mtu.pennation))[None]
    fa, _ = mtu.force_limits(l_mt, np.zeros_like(l_mt))
    # at l_ce = l_opt, v = 0 the active fiber force is max_isometric_force
    np.testing.assert_allclose(fa[0] / np.cos(mtu.pennation), xml_fmax, rtol=1e-12)


# --------------------------------------------------------------------------- against OpenSim
@needs_opensim
def test_degroote_curves_match_opensim():
    mus = osim.DeGrooteFregly2016Muscle()
    lx, v, lt = np.linspace(0.2, 1.8, 161), np.linspace(-1.2, 1.2, 121), np.linspace(0.95, 1.1, 76)
    for w, e0, et in ((1.0, 0.6, 0.049), (1.6, 0.45, 0.033)):
        mus.set_active_force_width_scale(w)
        mus.set_passive_fiber_strain_at_one_norm_force(e0)
        mus.set_tendon_strain_at_one_norm_force(et)
        p = DeGrooteFregly2016Muscle(active_force_width_scale=w, passive_fiber_strain_at_one_norm_force=e0,
                                     tendon_strain_at_one_norm_force=et)
        for ours, theirs, x in (
                (p.active_force_length_multiplier, mus.calcActiveForceLengthMultiplier, lx),
                (p.active_force_length_multiplier_derivative,
                 mus.calcActiveForceLengthMultiplierDerivative, lx),
                (p.passive_force_multiplier, mus.calcPassiveForceMultiplier, lx),
                (p.passive_force_multiplier_derivative, mus.calcPassiveForceMultiplierDerivative, lx),
                (p.force_velocity_multiplier, mus.calcForceVelocityMultiplier, v),
                (p.force_velocity_inverse, mus.calcForceVelocityInverseCurve, np.linspace(0.0, 1.7, 35)),
                (p.tendon_force_multiplier, mus.calcTendonForceMultiplier, lt),
                (p.tendon_force_multiplier_derivative, mus.calcTendonForceMultiplierDerivative, lt),
                (p.tendon_force_length_inverse, mus.calcTendonForceLengthInverseCurve, np.linspace(0, 2, 21))):
            np.testing.assert_allclose(ours(x), [theirs(float(t)) for t in x], rtol=1e-12, atol=1e-13)


@needs_opensim
@pytest.mark.parametrize("ours, theirs, lo, hi", [
    (ActiveForceLengthCurve(), lambda: osim.ActiveForceLengthCurve(), 0.0, 2.2),
    (ActiveForceLengthCurve(0.25, 0.77, 1.9, 0.75, 0.0),
     lambda: osim.ActiveForceLengthCurve(0.25, 0.77, 1.9, 0.75, 0.0), 0.0, 2.2),
    (FiberForceLengthCurve(), lambda: osim.FiberForceLengthCurve(), 0.5, 2.0),
    (FiberForceLengthCurve(0.1, 0.5, 0.3, 4.0, 0.3),
     lambda: osim.FiberForceLengthCurve(0.1, 0.5, 0.3, 4.0, 0.3), 0.5, 2.0),
    (ForceVelocityCurve(), lambda: osim.ForceVelocityCurve(), -1.3, 1.3),
    (ForceVelocityCurve(0.0, 0.3, 4.0, 0.0, 0.2, 1.6, 0.3, 0.7),
     lambda: osim.ForceVelocityCurve(0.0, 0.3, 4.0, 0.0, 0.2, 1.6, 0.3, 0.7), -1.3, 1.3),
    (ForceVelocityInverseCurve(), lambda: osim.ForceVelocityInverseCurve(), -0.2, 1.6),
    (TendonForceLengthCurve(), lambda: osim.TendonForceLengthCurve(), 0.98, 1.08),
    (TendonForceLengthCurve(0.033, 45.0, 0.5, 0.7), lambda: osim.TendonForceLengthCurve(0.033, 45.0, 0.5, 0.7),
     0.98, 1.08),
], ids=lambda p: type(p).__name__ if not callable(p) or isinstance(p, type) else "")
def test_millard_curves_match_opensim(ours, theirs, lo, hi):
    theirs = theirs()
    x = np.linspace(lo, hi, 701)
    y, d1, d2 = ours.build_curve().evaluate(x, (0, 1, 2))
    ref = np.array([[theirs.calcValue(float(t)), theirs.calcDerivative(float(t), 1),
                     theirs.calcDerivative(float(t), 2)] for t in x])
    # measured: values 1e-12, slopes 1e-10 (relative) -- OpenSim stops its Newton solve at 100 eps
    np.testing.assert_allclose(y, ref[:, 0], atol=1e-11)
    np.testing.assert_allclose(d1, ref[:, 1], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(d2, ref[:, 2], rtol=1e-7, atol=1e-7)


def _slider(muscle):
    """A one-muscle OpenSim model: the muscle from the origin to a body on a slider (length = coordinate)."""
    model = osim.Model()
    body = osim.Body("b", 1.0, osim.Vec3(0), osim.Inertia(1))
    model.addBody(body)
    joint = osim.SliderJoint("s", model.getGround(), osim.Vec3(0), osim.Vec3(0), body, osim.Vec3(0),
                             osim.Vec3(0))
    model.addJoint(joint)
    muscle.addNewPathPoint("o", model.getGround(), osim.Vec3(0))
    muscle.addNewPathPoint("i", body, osim.Vec3(0))
    model.addForce(muscle)
    return model, model.initSystem(), joint.get_coordinates(0)


def _opensim_muscle(kind, rigid):
    if kind == "thelen":
        mus = osim.Thelen2003Muscle("m", 800.0, 0.12, 0.25, 0.3)
        for setter, value in (("KshapeActive", 0.5), ("KshapePassive", 4.0), ("Af", 0.3), ("Flen", 1.8),
                              ("FmaxTendonStrain", 0.033)):
            getattr(mus, f"set_{setter}")(value)
        ours = Thelen2003OpenSim(f_max=800.0, l_opt=0.12, l_slack=0.25, pennation=0.3, active_shape=0.5,
                                 passive_shape=4.0, fv_shape=0.3, eccentric_force=1.8, tendon_strain=0.033)
    elif kind == "millard":
        mus = osim.Millard2012EquilibriumMuscle("m", 800.0, 0.12, 0.25, 0.3)
        ours = Millard2012(**Millard2012EquilibriumMuscle(
            max_isometric_force=800.0, optimal_fiber_length=0.12, tendon_slack_length=0.25,
            pennation_angle_at_optimal=0.3, ignore_tendon_compliance=rigid).model_parameters())
    else:
        mus = osim.DeGrooteFregly2016Muscle()
        mus.setName("m")
        mus.set_max_isometric_force(800.0)
        mus.set_optimal_fiber_length(0.12)
        mus.set_tendon_slack_length(0.25)
        mus.set_pennation_angle_at_optimal(0.3)
        mus.set_fiber_damping(0.05)
        ours = DeGroote2016(**DeGrooteFregly2016Muscle(
            max_isometric_force=800.0, optimal_fiber_length=0.12, tendon_slack_length=0.25,
            pennation_angle_at_optimal=0.3, fiber_damping=0.05).model_parameters())
    mus.set_ignore_tendon_compliance(rigid)
    mus.set_ignore_activation_dynamics(rigid)
    return mus, ours


@needs_opensim
@pytest.mark.parametrize("kind", ["millard", "degroote"])
def test_rigid_tendon_force_matches_opensim(kind):
    mus, ours = _opensim_muscle(kind, rigid=True)
    model, s, coord = _slider(mus)
    L, V, A = np.meshgrid(np.linspace(0.30, 0.47, 6), [-0.8, 0.0, 0.6], [0.05, 1.0], indexing="ij")
    ref, cap = [], []
    for length, speed, a in zip(L.ravel(), V.ravel(), A.ravel()):
        coord.setValue(s, float(length))
        coord.setSpeedValue(s, float(speed))
        mus.setActivation(s, float(a))
        model.realizeDynamics(s)
        ref.append(mus.getTendonForce(s))
        cap.append(mus.calcInextensibleTendonActiveFiberForce(s, 1.0))
    got = ours.force(A.ravel(), L.ravel(), V.ravel())
    np.testing.assert_allclose(got, ref, atol=1e-9)                      # measured ~1e-11 N of 800 N
    np.testing.assert_allclose(opensim_static_optimization_capacity(ours, L.ravel(), V.ravel()), cap, atol=1e-9)
    # ...which is not the physical active force along the tendon of a pennated muscle
    assert np.max(np.abs(ours.force_limits(L.ravel(), V.ravel())[0] - cap)) > 10.0


@needs_opensim
@pytest.mark.parametrize("kind", ["thelen", "millard", "degroote"])
def test_compliant_equilibrium_matches_opensim(kind):
    mus, ours = _opensim_muscle(kind, rigid=False)
    model, s, coord = _slider(mus)
    for length, a in ((0.33, 0.1), (0.37, 0.5), (0.42, 1.0)):
        coord.setValue(s, length)
        coord.setSpeedValue(s, 0.0)
        mus.setActivation(s, a)
        model.equilibrateMuscles(s)
        model.realizeDynamics(s)
        eq = ours.equilibrium(np.array([length]), np.array([a]))
        # OpenSim's equilibrium solvers stop at ~1e-8 of F_max
        assert eq["force"][0] == pytest.approx(mus.getTendonForce(s), abs=1e-4)
        assert eq["l_ce"][0] == pytest.approx(mus.getFiberLength(s), abs=1e-9)
        coord.setSpeedValue(s, 0.2)
        model.realizeVelocity(s)
        fa = ours.force_limits(np.array([length]), np.array([0.2]))[0][0]
        if kind == "thelen":
            assert fa == pytest.approx(mus.calcInextensibleTendonActiveFiberForce(s, 1.0), abs=1e-8)


@needs_opensim
def test_thelen_active_force_matches_opensim_at_every_activation():
    mus, ours = _opensim_muscle("thelen", rigid=False)
    model, _, _ = _slider(mus)          # the model owns the muscle: keep it alive
    lce, vn, a = (g.ravel() for g in np.meshgrid(np.linspace(0.07, 0.17, 6), np.linspace(-1.3, 1.3, 9),
                                                  [0.02, 0.3, 1.0], indexing="ij"))
    ref = [mus.calcActiveFiberForceAlongTendon(float(ai), float(li), float(vi * ours.v_max[0]))
           for ai, li, vi in zip(a, lce, vn)]
    cos = np.sqrt(1.0 - (ours.height / lce) ** 2)
    fl = ours._length_curves(lce / ours.l_opt)[0]
    got = ours.f_max * a * fl * ours._active_velocity_factor(a, vn) * cos
    # OpenSim inverts its force-velocity curve by Newton to 1e-6 (normalized velocity): measured 5e-9 N
    np.testing.assert_allclose(got, ref, atol=1e-7)
