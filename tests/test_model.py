"""Model loading, immutability and composition."""
import pickle
import shutil

import numpy as np
import pytest

import pinmsk
from pinmsk.components import Component, Parameter
from pinmsk.errors import ModelError


class _Drag(Component):
    """Test-only linear drag, -c v, on one coordinate."""
    family = "test_drag"
    parameters = (Parameter("c", 0.5, 0.0, 10.0, "N m s/rad"),)

    def generalized_force(self, model, motion, params=None, cache=None):
        out = np.zeros_like(motion.v)
        j = model.coordinate_index(self.target)
        out[:, j] = -self._p(params)["c"] * motion.v[:, j]
        return out


def test_builtins_have_expected_sizes():
    sizes = {"finger": (1, 2), "forearm": (1, 7), "gait2d": (11, 16), "human3d": (36, 0)}
    for name, (nv, nm) in sizes.items():
        m = pinmsk.load_model(name)
        assert (m.nv, m.n_muscles) == (nv, nm), name
    g = pinmsk.load_model("gait2d")
    # arrays follow Pinocchio's depth-first joint order; written results follow Eq. 5.1
    assert g.coordinates == ("torso_x", "torso_y", "torso_angle", "hip_l", "knee_l", "ankle_l", "mtp_l",
                             "hip_r", "knee_r", "ankle_r", "mtp_r")
    assert g.coordinate_order == ("torso_x", "torso_y", "torso_angle", "hip_r", "hip_l", "knee_r", "knee_l",
                             "ankle_r", "ankle_l", "mtp_r", "mtp_l")
    assert np.allclose(g.gravity, [0, -9.81, 0])


def test_unknown_model_and_coordinate_suggest_names():
    with pytest.raises(ModelError, match="did you mean 'forearm'"):
        pinmsk.load_model("forarm")
    m = pinmsk.load_model("forearm")
    with pytest.raises(ModelError, match="did you mean 'elbow_flexion'"):
        m.coordinate_index("elbow_flexon")


def test_with_effect_returns_new_model_and_refuses_duplicates():
    m = pinmsk.load_model("forearm")
    d = _Drag("elbow_flexion", c=0.2)
    m2 = m + d
    assert m.components == () and m2.components == (d,)
    with pytest.raises(ModelError, match="appear twice"):
        m2.with_effect(_Drag("elbow_flexion", c=0.3))
    assert m2.without("test_drag:elbow_flexion").components == ()
    with pytest.raises(ModelError, match="no coordinate 'knee'"):
        m.with_effect(_Drag("knee"))
    with pytest.raises(ModelError, match="outside its bounds"):
        _Drag("elbow_flexion", c=-1.0)


def test_component_params_are_copied_not_mutated():
    d = _Drag("elbow_flexion", c=0.2)
    d2 = d.with_params(c=0.7, stderr={"c": 0.01})
    assert d.values == {"c": 0.2} and d2.values == {"c": 0.7}
    assert d2.params["c"].stderr == 0.01


def test_model_pickles():
    m = pinmsk.load_model("forearm") + _Drag("elbow_flexion", c=0.2)
    m2 = pickle.loads(pickle.dumps(m))
    assert m2.coordinates == m.coordinates and m2.muscle_names == m.muscle_names
    assert m2.components[0].values == {"c": 0.2}


def test_moment_arm_variants_differ():
    c = pinmsk.load_model("forearm", moment_arms="constant")
    a = pinmsk.load_model("forearm", moment_arms="angle")
    q = np.array([[0.2], [1.6]])
    rc = c.muscles.moment_arms(q)[:, :, 0]
    ra = a.muscles.moment_arms(q)[:, :, 0]
    assert np.allclose(rc[0], rc[1])                          # constant
    assert not np.allclose(ra[0], ra[1])                      # angle-dependent
    assert np.allclose(rc[0], [0.054, 0.0273, 0.037, 0.021, -0.02, -0.0258, -0.02])  # Table 3.5
    with pytest.raises(ModelError):
        pinmsk.load_model("forearm", moment_arms="spline")


def test_user_model_from_sidecar_path(tmp_path):
    from pinmsk.builtin_models import builtin_dir
    src = builtin_dir()
    shutil.copy(src / "forearm.urdf", tmp_path / "myarm.urdf")
    text = (src / "forearm.toml").read_text().replace('urdf = "forearm.urdf"', 'urdf = "myarm.urdf"')
    text = text.replace('name = "forearm"', 'name = "myarm"')
    (tmp_path / "myarm.toml").write_text(text)
    m = pinmsk.load_model(tmp_path / "myarm.toml")
    assert m.name == "myarm" and m.n_muscles == 7
    with pytest.warns(UserWarning, match=r"no gravity declared.*default \[0.0, 0.0, -9.81\].*gravity = "):
        bare = pinmsk.load_model(tmp_path / "myarm.urdf")
    assert bare.n_muscles == 0 and bare.coordinates == ("elbow_flexion",)
    np.testing.assert_array_equal(bare.gravity, [0.0, 0.0, -9.81])


def test_bad_sidecar_errors_name_the_problem(tmp_path):
    from pinmsk.builtin_models import builtin_dir
    src = builtin_dir()
    shutil.copy(src / "forearm.urdf", tmp_path / "forearm.urdf")
    text = (src / "forearm.toml").read_text()
    (tmp_path / "bad.toml").write_text(text.replace("f_max = 101.58", "f_max = -101.58"))
    with pytest.raises(ModelError, match=r"bad.toml: \[\[muscles\]\]: f_max = -101.58 for muscle 0 \('BRD'\); "
                                         r"it must be finite and > 0"):
        pinmsk.load_model(tmp_path / "bad.toml")
    (tmp_path / "broken.toml").write_text("[model\nname=")
    with pytest.raises(ModelError, match="invalid TOML"):
        pinmsk.load_model(tmp_path / "broken.toml")
    with pytest.raises(ModelError, match="not found"):
        pinmsk.load_model(tmp_path / "missing.toml")
