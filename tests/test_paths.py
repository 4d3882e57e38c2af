"""pinmsk.muscles.paths: polynomial moment-arm paths.

Derivatives are checked against central finite differences, the vectorised
evaluation against a per-frame numpy.polyval loop, and the gait2d lengths
against Eq. 5.12 computed by hand from Table 5.3.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

import pinmsk
from pinmsk import builtin_models as bm
from pinmsk.errors import ModelError, PinmskError
from pinmsk.muscles.paths import DisplayPoints, MomentArmPath, display_points_from_sidecar, path_variants


def _coordinates(name):
    return pinmsk.load_model(name).coordinates


def _cases():
    """(model, variant) for every built-in sidecar with muscles and each of its path variants."""
    out = []
    for name in bm.builtin_names():
        cfg = bm.read_sidecar(name)
        if cfg.get("muscles"):
            out += [(name, v) for v in path_variants(cfg["muscles"])]
    return out


CASES = _cases()


def test_cases_cover_the_muscle_models():
    assert {("finger", "constant"), ("forearm", "constant"), ("forearm", "angle"), ("gait2d", "constant")} <= set(CASES)


@pytest.fixture(scope="module", params=CASES, ids=[f"{m}-{v}" for m, v in CASES])
def path(request):
    name, variant = request.param
    cfg = bm.read_sidecar(name)
    return MomentArmPath.from_sidecar(cfg["muscles"], _coordinates(name), variant, source=name)


def _random_q(path, n, seed):
    return np.random.default_rng(seed).uniform(-0.5, 2.0, size=(n, path.nv))


# ---------------------------------------------------------------------------- derivatives


def test_moment_arm_is_minus_dlength_dq(path):
    q = _random_q(path, 7, 1)
    h = 1e-5
    r = path.moment_arms(q)
    for j in range(path.nv):
        dq = np.zeros(path.nv)
        dq[j] = h
        fd = -(path.lengths(q + dq) - path.lengths(q - dq)) / (2 * h)
        np.testing.assert_allclose(r[:, :, j], fd, rtol=0, atol=1e-8)


def test_moment_arm_derivatives_are_finite_differences(path):
    q = _random_q(path, 7, 2)
    h = 1e-5
    for order in (1, 2):
        d = path.moment_arm_derivative(q, order)
        lower = path.moment_arms if order == 1 else (lambda x: path.moment_arm_derivative(x, 1))
        for j in range(path.nv):
            dq = np.zeros(path.nv)
            dq[j] = h
            fd = (lower(q + dq) - lower(q - dq))[:, :, j] / (2 * h)
            np.testing.assert_allclose(d[:, :, j], fd, rtol=0, atol=1e-7)
    assert path.moment_arm_derivative(q[0], 3).shape == (path.n_muscles, path.nv)


def _trajectory(path, t):
    """q(t) = q0 + A sin(w t + phi) with its exact first and second derivatives."""
    rng = np.random.default_rng(3)
    q0, A, w, phi = rng.uniform(0, 1, path.nv), rng.uniform(0.1, 0.6, path.nv), rng.uniform(2, 8, path.nv), rng.uniform(0, 6, path.nv)
    arg = np.outer(t, w) + phi
    return q0 + A * np.sin(arg), A * w * np.cos(arg), -A * w * w * np.sin(arg)


def test_velocity_is_dlength_dt(path):
    t = np.linspace(0.0, 1.0, 11)
    h = 1e-5
    q, v, _ = _trajectory(path, t)
    fd = (path.lengths(_trajectory(path, t + h)[0]) - path.lengths(_trajectory(path, t - h)[0])) / (2 * h)
    np.testing.assert_allclose(path.velocities(q, v), fd, rtol=0, atol=1e-8)


def test_acceleration_is_dvelocity_dt(path):
    t = np.linspace(0.0, 1.0, 11)
    h = 1e-5
    q, v, a = _trajectory(path, t)
    qp, vp, _ = _trajectory(path, t + h)
    qm, vm, _ = _trajectory(path, t - h)
    fd = (path.velocities(qp, vp) - path.velocities(qm, vm)) / (2 * h)
    np.testing.assert_allclose(path.accelerations(q, v, a), fd, rtol=0, atol=1e-7)


def test_vectorised_equals_per_frame_polyval(path):
    q = _random_q(path, 5, 2)
    v = _random_q(path, 5, 4)
    L = path.lengths(q)
    R = path.moment_arms(q)
    for n in range(q.shape[0]):
        for i in range(path.n_muscles):
            length = path.l0[i]
            for j in range(path.nv):
                c = path.coeffs[i, j]
                R_ij = np.polyval(c[::-1], q[n, j])
                assert R[n, i, j] == pytest.approx(R_ij, abs=1e-15)
                integral = np.polyval(np.concatenate([(c / np.arange(1, c.size + 1))[::-1], [0.0]]), q[n, j])
                length -= integral
            assert L[n, i] == pytest.approx(length, abs=1e-14)
        # single frames give the same numbers, without the frame axis
        np.testing.assert_array_equal(path.lengths(q[n]), L[n])
        np.testing.assert_array_equal(path.moment_arms(q[n]), R[n])
        np.testing.assert_allclose(path.velocities(q[n], v[n]), -R[n] @ v[n], atol=1e-15)


def test_shapes(path):
    q = _random_q(path, 4, 0)
    m, nv = path.n_muscles, path.nv
    assert path.lengths(q).shape == (4, m)
    assert path.moment_arms(q).shape == (4, m, nv)
    assert path.velocities(q, q).shape == (4, m)
    assert path.accelerations(q, q, q).shape == (4, m)
    assert path.lengths(q[0]).shape == (m,)
    assert path.moment_arms(q[0]).shape == (m, nv)
    np.testing.assert_array_equal(path.lengths(np.zeros(nv)), path.l0)


# ---------------------------------------------------------------------------- thesis values

# Table 5.3: r_A, r_K, r_H, l0 (m)
TABLE_5_3 = {
    "iliopsoas": (0.0, 0.0, -0.050, 0.248),
    "rectus_femoris": (0.0, 0.050, -0.034, 0.474),
    "glutei": (0.0, 0.0, 0.062, 0.271),
    "hamstrings": (0.0, -0.034, 0.072, 0.383),
    "vasti": (0.0, 0.042, 0.0, 0.271),
    "gastrocnemius": (0.053, -0.020, 0.0, 0.404),
    "tibialis_anterior": (-0.037, 0.0, 0.0, 0.464),
    "soleus": (0.053, 0.0, 0.0, 0.201),
}


def test_gait2d_lengths_reproduce_eq_5_12():
    cfg = bm.read_sidecar("gait2d")
    coords = _coordinates("gait2d")
    path = MomentArmPath.from_sidecar(cfg["muscles"], coords, "constant")
    q = np.zeros(len(coords))
    values = {"hip_r": 0.1, "knee_r": 0.3, "ankle_r": -0.2, "hip_l": -0.4, "knee_l": 1.1, "ankle_l": 0.25, "mtp_r": 0.5}
    for k, val in values.items():
        q[coords.index(k)] = val
    lengths = dict(zip(path.muscles, path.lengths(q)))
    # the example of the brief, by hand: vasti_r = 0.271 + 0.042 * 0.3
    assert lengths["vasti_r"] == pytest.approx(0.271 + 0.042 * 0.3, abs=1e-15)
    for side in "rl":
        phi_H, phi_K = values[f"hip_{side}"], values[f"knee_{side}"]
        phi_A = values[f"ankle_{side}"]  # thesis ankle angle, zero at neutral (urdf/README.md)
        for muscle, (r_A, r_K, r_H, l0) in TABLE_5_3.items():
            expected = l0 - r_H * phi_H + r_K * phi_K - r_A * (phi_A - math.pi / 2)  # Eq. 5.12
            assert lengths[f"{muscle}_{side}"] == pytest.approx(expected, abs=1e-14), (muscle, side)
    # moment arms r = -dl/dq: hip r_H, knee -r_K, ankle r_A; nothing on the other leg or the torso
    R = path.moment_arms(q)
    i = path.muscles.index("gastrocnemius_l")
    expected = np.zeros(len(coords))
    expected[coords.index("knee_l")] = 0.020
    expected[coords.index("ankle_l")] = 0.053
    np.testing.assert_array_equal(R[i], expected)


def test_forearm_constant_moment_arms_are_table_3_5():
    cfg = bm.read_sidecar("forearm")
    path = MomentArmPath.from_sidecar(cfg["muscles"], ["elbow_flexion"], "constant")
    r = dict(zip(path.muscles, path.moment_arms(np.array([1.0]))[:, 0]))
    assert r == pytest.approx({"BRD": 0.054, "BICLH": 0.0273, "BICSH": 0.037, "BRA": 0.021,
                               "TRILH": -0.02, "TRIMH": -0.0258, "TRILT": -0.02}, abs=1e-15)


def test_finger_moment_arms():
    cfg = bm.read_sidecar("finger")
    path = MomentArmPath.from_sidecar(cfg["muscles"], ["mcp_flexion"], "constant")
    np.testing.assert_array_equal(path.moment_arms(np.array([[0.2], [-0.2]]))[:, :, 0], [[0.01, -0.01]] * 2)


# ---------------------------------------------------------------------------- construction and errors


def test_constructor_is_keyword_only_and_validates():
    with pytest.raises(TypeError):
        MomentArmPath(("a",), ("q",), [0.1], [[[0.01]]])  # noqa
    with pytest.raises(ModelError, match=r"l0 must have shape \(2,\)"):
        MomentArmPath(muscles=("a", "b"), coordinates=("q",), l0=[0.1], coeffs=np.zeros((2, 1, 1)))
    with pytest.raises(ModelError, match=r"coeffs must have shape \(1, 2, K>=1\)"):
        MomentArmPath(muscles=("a",), coordinates=("q", "p"), l0=[0.1], coeffs=np.zeros((1, 1, 1)))
    with pytest.raises(ModelError, match="repeated: a"):
        MomentArmPath(muscles=("a", "a"), coordinates=("q",), l0=[0.1, 0.2], coeffs=np.zeros((2, 1, 1)))
    with pytest.raises(ModelError, match="finite"):
        MomentArmPath(muscles=("a",), coordinates=("q",), l0=[np.nan], coeffs=np.zeros((1, 1, 1)))


def test_immutable_and_picklable():
    p = MomentArmPath(muscles=("a", "b"), coordinates=("q",), l0=[0.1, 0.2], coeffs=[[[0.01, 0.002]], [[-0.02, 0.0]]])
    with pytest.raises(AttributeError):
        p.l0 = np.zeros(2)
    with pytest.raises(ValueError):
        p.l0[0] = 1.0  # read-only array
    with pytest.raises(ValueError):
        p.coeffs[0, 0, 0] = 1.0
    q = np.array([[0.3], [1.2]])
    p2 = pickle.loads(pickle.dumps(p))
    assert p2.muscles == p.muscles and p2.coordinates == p.coordinates
    np.testing.assert_array_equal(p2.lengths(q), p.lengths(q))
    assert p.degree == 1 and "2 muscles x 1 coordinates" in repr(p)


def test_bad_frame_shapes_say_what_is_expected():
    p = MomentArmPath(muscles=("a",), coordinates=("q", "p"), l0=[0.1], coeffs=np.zeros((1, 2, 1)))
    with pytest.raises(PinmskError, match=r"q must have shape \(2,\) or \(N, 2\) for coordinates \(q, p\), got \(3,\)"):
        p.lengths(np.zeros(3))
    with pytest.raises(PinmskError, match="same number of frames"):
        p.velocities(np.zeros((4, 2)), np.zeros((5, 2)))
    with pytest.raises(PinmskError, match="all be single frames"):
        p.velocities(np.zeros(2), np.zeros((1, 2)))


def _entries():
    return [
        {"name": "BRD", "paths": {"constant": {"l0": 0.3, "moment_arms": {"elbow_flexion": [0.054]}}}},
        {"name": "TRILH", "paths": {"constant": {"l0": 0.3, "moment_arms": {"elbow_flexion": -0.02}}}},
    ]


def test_from_sidecar_pads_degrees_and_accepts_scalars():
    e = _entries()
    e[0]["paths"]["constant"]["moment_arms"]["elbow_flexion"] = [0.02, 0.01, -0.003]
    p = MomentArmPath.from_sidecar(e, ["elbow_flexion", "wrist"], "constant")
    assert p.coeffs.shape == (2, 2, 3)
    np.testing.assert_array_equal(p.coeffs[1, 0], [-0.02, 0.0, 0.0])
    np.testing.assert_array_equal(p.coeffs[:, 1], 0.0)  # coordinates not listed: zero moment arm


def test_unknown_coordinate_names_muscle_coordinate_and_suggestion():
    e = _entries()
    e[1]["paths"]["constant"]["moment_arms"] = {"elbow_flexon": [-0.02]}
    with pytest.raises(ModelError) as err:
        MomentArmPath.from_sidecar(e, ["elbow_flexion"], "constant", source="arm.toml")
    msg = str(err.value)
    assert "muscle 'TRILH' in arm.toml" in msg
    assert "coordinate 'elbow_flexon'" in msg
    assert "did you mean 'elbow_flexion'?" in msg
    assert "The model's coordinates are: elbow_flexion" in msg


def test_missing_variant_names_muscle_and_variant():
    with pytest.raises(ModelError, match=r"muscle 'BRD' has no path variant 'angle'\. Its variants: constant"):
        MomentArmPath.from_sidecar(_entries(), ["elbow_flexion"], "angle")
    with pytest.raises(ModelError, match=r"no path variant 'constnt'; did you mean 'constant'\?"):
        MomentArmPath.from_sidecar(_entries(), ["elbow_flexion"], "constnt")


def test_other_bad_entries():
    e = _entries()
    del e[0]["paths"]["constant"]["l0"]
    with pytest.raises(ModelError, match=r"muscle 'BRD': paths.constant needs l0"):
        MomentArmPath.from_sidecar(e, ["elbow_flexion"], "constant")
    e = _entries()
    e[0]["paths"]["constant"]["moment_arms"]["elbow_flexion"] = []
    with pytest.raises(ModelError, match="non-empty list of finite numbers"):
        MomentArmPath.from_sidecar(e, ["elbow_flexion"], "constant")
    e = _entries()
    e[1]["name"] = "BRD"
    with pytest.raises(ModelError, match="repeated: BRD"):
        MomentArmPath.from_sidecar(e, ["elbow_flexion"], "constant")
    with pytest.raises(ModelError, match="has no name"):
        MomentArmPath.from_sidecar([{"paths": {}}], ["elbow_flexion"], "constant")


def test_path_variants():
    assert path_variants(bm.read_sidecar("forearm")["muscles"]) == ("angle", "constant")
    assert path_variants(_entries()) == ("constant",)


# ---------------------------------------------------------------------------- display points


def test_display_points():
    pts = display_points_from_sidecar(bm.read_sidecar("gait2d")["muscles"])
    assert len(pts) == 16 and all(isinstance(p, DisplayPoints) for p in pts)
    vas = next(p for p in pts if p.muscle == "vasti_r")
    assert vas.bodies[0] == "thigh_r" and vas.bodies[-1] == "shank_r"
    assert vas.positions.shape == (len(vas.bodies), 3) and not vas.positions.flags.writeable
    with pytest.raises(ModelError, match=r"unknown body 'thigh'; did you mean 'thigh_r'\?"):
        display_points_from_sidecar([{"name": "x", "points": [["thigh", 0, 0, 0], ["shank_r", 0, 0, 0]]}],
                                    bodies=["thigh_r", "shank_r"])
    with pytest.raises(ModelError, match=r"must be \[\"body\", x, y, z\]"):
        display_points_from_sidecar([{"name": "x", "points": [["thigh_r", 0, 0], ["shank_r", 0, 0, 0]]}])
    with pytest.raises(ModelError, match="at least 2 points"):
        DisplayPoints(muscle="x", bodies=["a"], positions=[[0, 0, 0]])
