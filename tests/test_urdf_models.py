"""The built-in models as ``pinmsk.load_model`` builds them: files, skeletons, anthropometry, conventions.

Every model of ``pinmsk.builtin_names()`` is loaded the way users load it, and its Pinocchio
model is compared with numbers read here, independently, from its URDF (joints, masses, centre of
mass, composite inertia, parsed with ElementTree) and its sidecar (gravity, coordinate order,
muscles, effects, parsed with tomllib).  A built-in model that fails to load fails its test; none
is skipped (example-robot-data, which human3d needs, is a dependency of pinmsk).

Expected anthropometric numbers are computed here from the thesis tables (and Winter's
anthropometry), independently of urdf/generate.py.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import pinmsk
from pinmsk.errors import ModelError

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from conftest import REPO

URDF_DIR = REPO / "urdf"
GAIT_ORDER = ["torso_x", "torso_y", "torso_angle", "hip_r", "hip_l", "knee_r", "knee_l",
              "ankle_r", "ankle_l", "mtp_r", "mtp_l"]
PIN_ORDER = ["torso_x", "torso_y", "torso_angle", "hip_l", "knee_l", "ankle_l", "mtp_l",
             "hip_r", "knee_r", "ankle_r", "mtp_r"]  # URDF parser: depth-first, siblings by joint name
#: what each built-in model is (a new built-in model must be added here, or its test fails)
EXPECTED = {  # name: (nq = nv, muscles, URDF shipped in urdf/)
    "finger": (1, 2, True), "finger_literature": (1, 2, True), "foot2d": (4, 0, True), "forearm": (1, 7, True), "gait2d": (11, 16, True),
    "human3d": (36, 0, False),
}


def _sidecar(name: str) -> dict:
    with open(URDF_DIR / f"{name}.toml", "rb") as fh:
        return tomllib.load(fh)


@pytest.fixture(scope="module")
def loaded():
    """Every built-in model, loaded once by ``pinmsk.load_model`` (a failure to load fails the tests)."""
    return {name: pinmsk.load_model(name) for name in pinmsk.builtin_names()}


@pytest.fixture(scope="module")
def models(loaded):
    """The Pinocchio models of the built-in models."""
    return {name: m.pin for name, m in loaded.items()}


def _frame_pos(model, q, frame):
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, float))
    return data.oMf[model.getFrameId(frame)].translation.copy()


def _q(model, **values):
    q = np.zeros(model.nq)
    for name, val in values.items():
        q[model.idx_qs[model.getJointId(name)]] = val
    return q


# ---------------------------------------------------------------------------- an independent URDF reading


def _floats(text, default="0 0 0"):
    return np.array([float(x) for x in (text or default).split()])


def _rpy(rpy):
    """URDF's fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _origin(elem):
    o = None if elem is None else elem.find("origin")
    if o is None:
        return np.zeros(3), np.eye(3)
    return _floats(o.get("xyz")), _rpy(_floats(o.get("rpy")))


def read_urdf(path) -> dict:
    """From the URDF text alone: joints (name -> type), link masses, their sum, and the mass, centre
    of mass and inertia about it at q = 0 (world frame) of the *moving* links (not the root link and
    what is welded to it: Pinocchio puts those in its fixed "universe" body)."""
    root = ET.parse(path).getroot()
    joints = {j.get("name"): j for j in root.findall("joint")}
    children = {j.find("child").get("link") for j in joints.values()}
    base = [lk.get("name") for lk in root.findall("link") if lk.get("name") not in children]
    assert len(base) == 1, f"{path}: one root link expected, found {base}"
    placement = {base[0]: (np.zeros(3), np.eye(3))}
    welded = {base[0]}                               # the root link and links fixed to it
    pending = list(joints.values())
    while pending:                                   # world placement of every link at q = 0
        j = next(j for j in pending if j.find("parent").get("link") in placement)
        pending.remove(j)
        parent, child = j.find("parent").get("link"), j.find("child").get("link")
        p, R = placement[parent]
        xyz, rot = _origin(j)
        placement[child] = (p + R @ xyz, R @ rot)
        if parent in welded and j.get("type") == "fixed":
            welded.add(child)
    masses, points, inertias = {}, [], []
    for link in root.findall("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        m = float(inertial.find("mass").get("value"))
        masses[link.get("name")] = m
        if link.get("name") in welded:
            continue
        p, R = placement[link.get("name")]
        xyz, rot = _origin(inertial)
        e = inertial.find("inertia").attrib
        local = np.array([[float(e["ixx"]), float(e["ixy"]), float(e["ixz"])],
                          [float(e["ixy"]), float(e["iyy"]), float(e["iyz"])],
                          [float(e["ixz"]), float(e["iyz"]), float(e["izz"])]])
        points.append((m, p + R @ xyz))
        inertias.append(R @ rot @ local @ (R @ rot).T)
    moving = sum(m for m, _ in points)
    com = sum(m * c for m, c in points) / moving
    inertia = sum(I + m * (np.dot(c - com, c - com) * np.eye(3) - np.outer(c - com, c - com))
                  for (m, c), I in zip(points, inertias))
    return {"joints": {n: j.get("type") for n, j in joints.items()}, "masses": masses,
            "mass": sum(masses.values()), "moving_mass": moving, "com": com, "inertia": inertia}


# ---------------------------------------------------------------------------- every built-in model loads


def test_builtin_names():
    names = pinmsk.builtin_names()
    assert list(names) == sorted(names)
    assert set(names) == set(EXPECTED), "a built-in model was added or removed: update EXPECTED"
    assert set(names) == {p.stem for p in URDF_DIR.glob("*.toml") if "urdf" in _sidecar(p.stem).get("model", {})}


@pytest.mark.parametrize("name", pinmsk.builtin_names())
def test_builtin_model_loads_and_matches_its_urdf_and_sidecar(name):
    model = pinmsk.load_model(name)                   # no try: a model that cannot load fails here
    spec = _sidecar(name)
    nq, n_muscles, shipped = EXPECTED[name]
    pm = model.pin
    assert model.name == spec["model"].get("name", name) == name
    assert model.nq == model.nv == pm.nq == pm.nv == nq
    assert pm.check(pm.createData())                 # a valid (subtree-contiguous) Pinocchio model
    urdf_path = Path(model.meta["urdf"])
    if shipped:
        assert urdf_path == (URDF_DIR / spec["model"]["urdf"]).resolve()
    else:   # "@example-robot-data:<path>": the file of the installed distribution
        rel = spec["model"]["urdf"].split(":", 1)[1]
        assert urdf_path.as_posix().endswith("share/example-robot-data/" + rel)
    urdf = read_urdf(urdf_path)
    movable = [j for j, kind in urdf["joints"].items() if kind != "fixed"]
    assert all(urdf["joints"][j] in ("revolute", "prismatic") for j in movable)   # 1 dof each
    assert sorted(model.coordinates) == sorted(movable) and len(movable) == nq
    assert model.coordinate_order == tuple(spec["model"].get("coordinate_order") or model.coordinates)
    for c in model.coordinates:                       # q, v columns are Pinocchio's velocity indices
        assert model.coordinate_index(c) == pm.joints[pm.getJointId(c)].idx_v
    # gravity: the sidecar's, not Pinocchio's URDF default (0, 0, -9.81)
    np.testing.assert_array_equal(model.gravity, spec["model"]["gravity"])
    np.testing.assert_array_equal(pm.gravity.linear, spec["model"]["gravity"])
    np.testing.assert_array_equal(pm.gravity.angular, [0.0, 0.0, 0.0])
    # masses: non-negative link by link, positive in all, and the URDF's.  Model.mass counts every
    # link; Pinocchio's total leaves out the root link, fixed to the world (human3d's pelvis, 10.65 kg)
    assert all(m >= 0 for m in urdf["masses"].values()) and urdf["moving_mass"] > 0
    assert model.mass == pytest.approx(urdf["mass"], rel=1e-12)
    assert pin.computeTotalMass(pm) == pytest.approx(urdf["moving_mass"], rel=1e-12)
    # the moving bodies at q = 0: centre of mass and composite inertia about it, from the URDF tree
    data = pm.createData()
    q0, v0 = np.zeros(pm.nq), np.zeros(pm.nv)
    np.testing.assert_allclose(pin.centerOfMass(pm, data, q0), urdf["com"], atol=1e-12)
    pin.ccrba(pm, data, q0, v0)
    assert data.Ig.mass == pytest.approx(urdf["moving_mass"], rel=1e-12)
    np.testing.assert_allclose(data.Ig.inertia, urdf["inertia"], rtol=1e-10,
                               atol=1e-12 * np.abs(urdf["inertia"]).max())
    for i in range(1, pm.njoints):                    # every body physical
        inertia = pm.inertias[i]
        assert inertia.mass >= 0
        ev = np.linalg.eigvalsh(inertia.inertia)
        assert np.all(ev >= -1e-15), (name, pm.names[i])
        if inertia.mass > 0:
            a, b, c = np.diag(inertia.inertia)
            assert a + b >= c and b + c >= a and a + c >= b, (name, pm.names[i])
    # muscles and effects: the sidecar's
    muscles = spec.get("muscles", [])
    assert model.n_muscles == len(muscles) == n_muscles
    assert model.muscle_names == tuple(m["name"] for m in muscles)
    if muscles:
        np.testing.assert_array_equal(model.muscles.f_max, [m["f_max"] for m in muscles])
    assert [c.family for c in model.effects] == [e["type"] for e in spec.get("effects", [])]


def test_loaded_model_remembers_its_files(loaded):
    for name, m in loaded.items():
        assert Path(m.meta["sidecar"]) == URDF_DIR / f"{name}.toml"
        assert m.meta["up_axis"] == _sidecar(name)["model"]["up_axis"] == "y"
        assert m.meta["description"] == _sidecar(name)["model"]["description"]


# ---------------------------------------------------------------------------- files


def test_committed_files_are_the_generator_output(monkeypatch):
    spec = importlib.util.spec_from_file_location("_pinmsk_urdf_generate", URDF_DIR / "generate.py")
    gen = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, gen)  # dataclasses look their module up
    spec.loader.exec_module(gen)
    for name, text in gen.render_all().items():
        committed = (URDF_DIR / name).read_text(encoding="utf-8")
        assert committed == text, f"urdf/{name} is stale: run python urdf/generate.py"


def _forearm_sidecar(tmp_path, **model_keys) -> Path:
    """A copy of the forearm sidecar in tmp_path with [model] entries set (a value: TOML text) or removed (None)."""
    lines = []
    for line in (URDF_DIR / "forearm.toml").read_text().splitlines():
        key = line.split("=")[0].strip()
        if key in model_keys:      # only [model] has these keys
            continue
        lines.append(line)
        if line.strip() == "[model]":
            lines += [f"{k} = {v}" for k, v in model_keys.items() if v is not None]
    path = tmp_path / "arm.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_sidecar_errors_name_the_file_and_the_entry(tmp_path):
    forearm_urdf = f'"{URDF_DIR / "forearm.urdf"}"'
    with pytest.raises(ModelError, match=r"arm.toml: needs a \[model\] table with a 'urdf' entry"):
        pinmsk.load_model(_forearm_sidecar(tmp_path, urdf=None))
    with pytest.raises(ModelError, match=r"arm.toml: urdf = 'nothere.urdf' does not exist"):
        pinmsk.load_model(_forearm_sidecar(tmp_path, urdf='"nothere.urdf"'))
    with pytest.raises(ModelError, match=r"arm.toml: \[model\]: gravity must be 3 finite numbers .*\[0, -9.81\]"):
        pinmsk.load_model(_forearm_sidecar(tmp_path, urdf=forearm_urdf, gravity="[0, -9.81]"))
    with pytest.raises(ModelError, match=r"coordinate_order must list exactly the URDF's joints "
                                         r"\['elbow_flexion'\]; got \['elbow'\]"):
        pinmsk.load_model(_forearm_sidecar(tmp_path, urdf=forearm_urdf, coordinate_order='["elbow"]'))
    with pytest.raises(ModelError, match=r"unknown key 'mass' in \[model\]"):
        pinmsk.load_model(_forearm_sidecar(tmp_path, urdf=forearm_urdf, mass="3.0"))
    ok = pinmsk.load_model(_forearm_sidecar(tmp_path, urdf=forearm_urdf))   # the copy itself is fine
    assert ok.nv == 1 and ok.n_muscles == 7


def test_missing_example_robot_data_is_a_clear_error(monkeypatch):
    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "distribution", missing)
    with pytest.raises(ModelError, match=r"example-robot-data package, which is not installed; .*pip install example-robot-data"):
        pinmsk.load_model("human3d")


# ---------------------------------------------------------------------------- skeletons


def test_joint_names_and_order(models):
    assert list(models["finger"].names)[1:] == ["mcp_flexion"]
    assert list(models["forearm"].names)[1:] == ["elbow_flexion"]
    assert list(models["foot2d"].names)[1:] == ["ankle_x", "ankle_y", "foot_angle", "mtp"]
    assert list(models["gait2d"].names)[1:] == PIN_ORDER


def test_gait2d_coordinates_in_eq_5_1_order(loaded):
    g = loaded["gait2d"]
    assert g.coordinates == tuple(PIN_ORDER)          # arrays: Pinocchio's depth-first order
    assert g.coordinate_order == tuple(GAIT_ORDER)    # written results: Eq. 5.1
    m = g.pin
    # a q in Eq. 5.1 order placed through coordinate_index lands on the right Pinocchio joints
    q_user = np.zeros(11)
    q_user[GAIT_ORDER.index("hip_r")] = 0.3
    q = np.zeros(11)
    q[[g.coordinate_index(c) for c in GAIT_ORDER]] = q_user
    assert q[m.idx_qs[m.getJointId("hip_r")]] == 0.3
    # dynamics in user order: tau = M a + nle, M symmetric positive definite
    rng = np.random.default_rng(0)
    q, v, a = rng.normal(size=(3, 11))
    perm = [g.coordinate_index(c) for c in GAIT_ORDER]
    d = m.createData()
    tau_user = pin.rnea(m, d, q, v, a)[perm]
    M = pin.crba(m, d, q)
    M = np.triu(M) + np.triu(M, 1).T
    M_user = M[np.ix_(perm, perm)]
    nle_user = pin.nonLinearEffects(m, d, q, v)[perm]
    np.testing.assert_allclose(tau_user, M_user @ a[perm] + nle_user, atol=1e-10)
    assert np.all(np.linalg.eigvalsh(M_user) > 0)


def test_visual_geometry(loaded):
    g = loaded["gait2d"]
    new = g.pin
    geom = pin.buildGeomFromUrdf(new, g.meta["urdf"], pin.GeometryType.VISUAL,
                                 package_dirs=[str(d) for d in g.meta["package_dirs"]])
    assert geom.ngeoms > 0
    data, gdata = new.createData(), geom.createData()
    q = _q(new, torso_y=1.0, knee_r=0.7)
    pin.updateGeometryPlacements(new, data, geom, gdata, q)
    shank = next(i for i, gm in enumerate(geom.geometryObjects) if gm.name.startswith("shank_r"))
    # the shank cylinder's centre is half a shank below the knee, along the rotated shank
    knee = _frame_pos(new, q, "knee_r")
    Ls = 0.246 * 1.696
    np.testing.assert_allclose(gdata.oMg[shank].translation, knee + Ls / 2 * np.array([-math.sin(0.7), -math.cos(0.7), 0]),
                               atol=1e-12)


# ---------------------------------------------------------------------------- anthropometry


def test_total_masses(models):
    assert pin.computeTotalMass(models["finger"]) == pytest.approx(0.022, rel=1e-14)
    assert pin.computeTotalMass(models["forearm"]) == pytest.approx(0.016 * 80 + 0.006 * 80, rel=1e-14)  # 1.76 kg
    gait = 64.74 * (0.678 + 2 * 0.1 + 2 * 0.0465) + 2 * (0.6 + 0.6 + 0.2)
    assert gait == pytest.approx(65.66254, rel=1e-14)
    assert pin.computeTotalMass(models["gait2d"]) == pytest.approx(gait, rel=1e-14)


def test_forearm_com_and_inertia_by_hand(models):
    m = models["forearm"]
    # Winter, BM 80 kg, BH 1.8 m: forearm L = 0.146*1.8 = 0.2628, COM 0.43 L = 0.113004,
    # k = 0.303 L = 0.0796284; hand L = 0.108*1.8 = 0.1944, COM 0.2628 + 0.506*0.1944 = 0.3611664,
    # k = 0.297*0.1944 = 0.0577368.
    c = (1.28 * 0.113004 + 0.48 * 0.3611664) / 1.76
    assert c == pytest.approx(0.18068465454545, abs=1e-12)
    i_elbow = 1.28 * (0.0796284**2 + 0.113004**2) + 0.48 * (0.0577368**2 + 0.3611664**2)
    L_upper = 0.186 * 1.8
    data = m.createData()
    for q, direction in ((0.0, [0, -1, 0]), (math.pi / 2, [1, 0, 0]), (2.0, [math.sin(2.0), -math.cos(2.0), 0])):
        com = pin.centerOfMass(m, data, np.array([q]))
        np.testing.assert_allclose(com, np.array([0, -L_upper, 0]) + c * np.array(direction), atol=1e-14)
        M = pin.crba(m, data, np.array([q]))
        assert M[0, 0] == pytest.approx(i_elbow, rel=1e-13)
    hand = _frame_pos(m, [0.0], "hand")
    np.testing.assert_allclose(hand, [0, -L_upper - 0.3611664, 0], atol=1e-14)


def test_finger_is_a_horizontal_pendulum_flexed_by_gravity(models):
    m = models["finger"]
    data = m.createData()
    # finger composite: COM = sum m_i x_i / m with phalanx COMs at mid-length
    Lp, Lm, Ld = 0.245 * 0.19, 0.143 * 0.19, 0.097 * 0.19
    c = (0.013 * Lp / 2 + 0.006 * (Lp + Lm / 2) + 0.003 * (Lp + Lm + Ld / 2)) / 0.022
    tau = pin.rnea(m, data, np.zeros(1), np.zeros(1), np.zeros(1))
    assert tau[0] == pytest.approx(-0.022 * 9.81 * c, rel=1e-12)  # holding it needs an extension moment
    tip = _frame_pos(m, [0.3], "fingertip")
    assert tip[1] < 0 and tip[0] > 0  # flexion moves the tip down
    assert np.linalg.norm(_frame_pos(m, [0.0], "fingertip") - [Lp + Lm + Ld, 0, 0]) < 1e-15


def test_gait2d_segments(models):
    m = models["gait2d"]
    BM, BH = 64.74, 1.696
    q = np.zeros(11)
    hip, knee, ankle = (_frame_pos(m, q, f"{j}_r") for j in ("hip", "knee", "ankle"))
    assert -hip[1] == pytest.approx((1 - 0.626) * 0.288 * BH, abs=1e-14)  # hips below the HAT COM
    assert hip[1] - knee[1] == pytest.approx(0.245 * BH, abs=1e-14)
    assert knee[1] - ankle[1] == pytest.approx(0.246 * BH, abs=1e-14)
    for j in ("hip", "knee", "ankle"):
        assert _frame_pos(m, q, f"{j}_r")[2] == -_frame_pos(m, q, f"{j}_l")[2]
    mass = {m.names[i]: m.inertias[i].mass for i in range(1, m.njoints)}
    assert mass["torso_angle"] == pytest.approx(0.678 * BM, rel=1e-14)
    assert mass["hip_r"] == pytest.approx(0.100 * BM, rel=1e-14)
    assert mass["knee_l"] == pytest.approx(0.0465 * BM, rel=1e-14)
    assert mass["ankle_r"] == pytest.approx(1.2, rel=1e-14)
    assert mass["mtp_l"] == pytest.approx(0.2, rel=1e-14)
    assert mass["torso_x"] == 0.0 and mass["torso_y"] == 0.0
    # inertia about each COM, Table 5.1 RoG (k = RoG * L)
    izz = {n: m.inertias[m.getJointId(n)].inertia[2, 2] for n in ("torso_angle", "hip_r", "knee_r", "mtp_r")}
    assert izz["torso_angle"] == pytest.approx(0.678 * BM * (0.496 * 0.288 * BH) ** 2, rel=1e-13)
    assert izz["hip_r"] == pytest.approx(0.1 * BM * (0.323 * 0.245 * BH) ** 2, rel=1e-13)
    assert izz["knee_r"] == pytest.approx(0.0465 * BM * (0.302 * 0.246 * BH) ** 2, rel=1e-13)
    assert izz["mtp_r"] == pytest.approx(1e-4, rel=1e-13)
    thigh_com = m.inertias[m.getJointId("hip_r")].lever
    np.testing.assert_allclose(thigh_com, [0, -0.433 * 0.245 * BH, 0], atol=1e-15)


def test_gait2d_foot_geometry_matches_table_4_1(models):
    m = models["gait2d"]
    q = np.zeros(11)
    A, H, P, T = (_frame_pos(m, q, f) for f in ("ankle_r", "heel_r", "metatarsal_r", "toe_r"))
    assert np.linalg.norm(H - A) == pytest.approx(0.074, abs=1e-14)
    assert np.linalg.norm(P - A) == pytest.approx(0.110, abs=1e-14)
    assert np.linalg.norm(T - P) == pytest.approx(0.073, abs=1e-14)
    cos_beta = np.dot(H - A, P - A) / (0.074 * 0.110)
    assert math.degrees(math.acos(cos_beta)) == pytest.approx(106.0, abs=1e-9)  # beta = angle HAP
    assert H[1] == pytest.approx(P[1], abs=1e-15) and P[1] == pytest.approx(T[1], abs=1e-15)  # sole flat
    assert H[0] < A[0] < P[0] < T[0]
    # the MTP joint sits at P
    np.testing.assert_allclose(_frame_pos(m, q, "mtp_r"), P, atol=1e-15)


def test_gait2d_sign_conventions(models):
    m = models["gait2d"]
    stand = _q(m, torso_x=0.3, torso_y=1.2)
    com_hat = _frame_pos(m, stand, "hat")
    np.testing.assert_allclose(com_hat, [0.3, 1.2, 0], atol=1e-15)  # Eq. 5.1: torso COM position
    d = lambda q, f: _frame_pos(m, q, f) - _frame_pos(m, stand, f)  # noqa: E731
    lean = _q(m, torso_x=0.3, torso_y=1.2, torso_angle=0.2)
    assert d(lean, "hip_r")[0] < 0  # leaning forward swings the hips (below the COM) back
    assert d(_q(m, torso_y=1.2, torso_x=0.3, hip_r=0.3), "knee_r")[0] < 0  # extension: knee goes back
    assert d(_q(m, torso_y=1.2, torso_x=0.3, hip_l=0.3), "knee_l")[0] < 0
    q = _q(m, torso_y=1.2, torso_x=0.3, knee_r=0.5)
    assert (_frame_pos(m, q, "ankle_r") - _frame_pos(m, q, "knee_r"))[0] < 0  # flexion: shank swings back
    assert d(_q(m, torso_y=1.2, torso_x=0.3, ankle_r=0.3), "toe_r")[1] < 0  # plantarflexion: toes down
    assert d(_q(m, torso_y=1.2, torso_x=0.3, mtp_r=0.3), "toe_r")[1] < 0  # toe flexion: toes down
    assert d(_q(m, torso_y=1.2, torso_x=0.3, mtp_r=0.3), "metatarsal_r")[1] == pytest.approx(0, abs=1e-15)
    # standing: heel, metatarsal and toe on the ground y = 0 at the documented torso height
    h = -_frame_pos(m, np.zeros(11), "heel_r")[1]
    for f in ("heel_r", "metatarsal_r", "toe_r", "heel_l", "metatarsal_l", "toe_l"):
        assert _frame_pos(m, _q(m, torso_y=h), f)[1] == pytest.approx(0, abs=1e-14)
    assert h == pytest.approx(1.0681, abs=5e-5)


def test_human3d_is_y_up(models):
    m = models["human3d"]
    # y is up in this model: the head is above the pelvis, the feet below
    q0 = np.zeros(m.nq)
    assert _frame_pos(m, q0, "middle_head")[1] > 0.3
    assert _frame_pos(m, q0, "left_foot")[1] < -0.8


def test_human3d_meshes_resolve_through_the_package_dir(loaded):
    h = loaded["human3d"]
    geom = pin.buildGeomFromUrdf(h.pin, h.meta["urdf"], pin.GeometryType.VISUAL,
                                 package_dirs=[str(d) for d in h.meta["package_dirs"]])
    assert geom.ngeoms > 0
    assert all(Path(g.meshPath).is_file() for g in geom.geometryObjects if g.meshPath)
    assert all(g.meshPath.startswith(h.meta["package_dirs"][0]) for g in geom.geometryObjects)


# ---------------------------------------------------------------------------- sidecars


def test_sidecar_model_tables():
    for name in ("finger", "forearm", "gait2d"):
        cfg = _sidecar(name)
        assert cfg["model"]["name"] == name
        assert cfg["model"]["gravity"] == [0.0, -9.81, 0.0]
        assert cfg["model"]["up_axis"] == "y"
        assert cfg["model"]["default_paths"] in cfg["muscles"][0]["paths"]
    assert _sidecar("forearm")["muscle_model"] == {"type": "thelen2003", "tendon": "rigid"}
    assert _sidecar("finger")["muscle_model"]["type"] == "thelen2003"
    gait = _sidecar("gait2d")
    assert gait["muscle_model"]["type"] == "nagano_gerritsen"
    assert gait["muscle_model"]["tendon_model"] == "winters_quadratic"
    assert gait["model"]["coordinate_order"] == GAIT_ORDER
    assert gait["effects"] == [{"type": "riener_edrich_1999", "side": "r"}, {"type": "riener_edrich_1999", "side": "l"}]


TABLE_3_2 = {  # l_opt cm, F_max N, l_slack cm, pennation deg, V cm^3
    "BRD": (27.03, 101.58, 6.04, 5.00, 83.19),
    "BICLH": (15.36, 392.91, 22.93, 10.00, 182.92),
    "BICSH": (13.07, 461.76, 22.98, 10.00, 182.92),
    "BRA": (10.28, 853.90, 1.75, 15.00, 256.96),
    "TRILH": (15.24, 692.21, 19.05, 15.00, 290.67),
    "TRIMH": (6.17, 1268.87, 19.64, 15.00, 237.28),
    "TRILT": (4.90, 619.67, 12.19, 15.00, 92.04),
}
TABLE_3_5 = {"BRD": 5.40, "BICLH": 2.73, "BICSH": 3.70, "BRA": 2.10, "TRILH": -2.00, "TRIMH": -2.58, "TRILT": -2.00}


def test_forearm_muscles_match_tables_3_2_and_3_5(loaded):
    muscles = _sidecar("forearm")["muscles"]
    assert [m["name"] for m in muscles] == list(TABLE_3_2)
    for m in muscles:
        l_opt, f_max, l_slack, penn, vol = TABLE_3_2[m["name"]]
        assert m["l_opt"] == pytest.approx(l_opt / 100, rel=1e-14)
        assert m["f_max"] == pytest.approx(f_max, rel=1e-14)
        assert m["l_slack"] == pytest.approx(l_slack / 100, rel=1e-14)
        assert m["pennation"] == pytest.approx(math.radians(penn), rel=1e-14)
        assert m["volume"] == pytest.approx(vol * 1e-6, rel=1e-14)
        assert m["paths"]["constant"]["moment_arms"] == {"elbow_flexion": [pytest.approx(TABLE_3_5[m["name"]] / 100)]}
    # the loaded model carries them (its default path variant: constant moment arms, Table 3.5)
    ms = loaded["forearm"].muscles
    np.testing.assert_allclose(ms.l_opt, [TABLE_3_2[n][0] / 100 for n in ms.names], rtol=1e-14)
    np.testing.assert_allclose(ms.l_slack, [TABLE_3_2[n][2] / 100 for n in ms.names], rtol=1e-14)
    np.testing.assert_allclose(ms.pennation, [math.radians(TABLE_3_2[n][3]) for n in ms.names], rtol=1e-14)
    r = ms.moment_arms(np.array([[0.7]]))
    np.testing.assert_allclose(np.ravel(r), [TABLE_3_5[n] / 100 for n in ms.names], rtol=1e-12)


def test_forearm_angle_variant_shape():
    muscles = _sidecar("forearm")["muscles"]
    s = np.linspace(0.0, 2.6, 2601)
    for m in muscles:
        r = np.polynomial.polynomial.polyval(s, m["paths"]["angle"]["moment_arms"]["elbow_flexion"])
        mean = np.sum((r[1:] + r[:-1]) / 2 * np.diff(s)) / 2.6  # trapezoid; exact to O(h^2)
        assert mean == pytest.approx(TABLE_3_5[m["name"]] / 100, rel=1e-6)
        assert np.all(np.sign(r) == np.sign(TABLE_3_5[m["name"]]))
        if TABLE_3_5[m["name"]] > 0:
            assert 1.5 <= s[np.argmax(r)] <= 1.9  # flexor moment arms peak near 90-105 deg
        else:
            assert np.all(np.diff(np.abs(r)) < 0)  # triceps: decreasing with flexion


def test_forearm_fibers_optimal_at_mid_range():
    for m in _sidecar("forearm")["muscles"]:
        for variant, p in m["paths"].items():
            c = p["moment_arms"]["elbow_flexion"]
            l_mid = p["l0"] - sum(ck * 1.3 ** (k + 1) / (k + 1) for k, ck in enumerate(c))
            assert l_mid - m["l_slack"] == pytest.approx(m["l_opt"] * math.cos(m["pennation"]), abs=1e-14), (
                m["name"], variant)


def test_finger_muscles():
    muscles = {m["name"]: m for m in _sidecar("finger")["muscles"]}
    assert set(muscles) == {"flexor", "extensor"}
    assert muscles["flexor"]["paths"]["constant"]["moment_arms"] == {"mcp_flexion": [0.01]}
    assert muscles["extensor"]["paths"]["constant"]["moment_arms"] == {"mcp_flexion": [-0.01]}
    for m in muscles.values():
        assert m["f_max"] == 100.0 and m["pennation"] == 0.0
        assert m["paths"]["constant"]["l0"] == pytest.approx(m["l_slack"] + m["l_opt"], abs=1e-15)
        assert m["volume"] == pytest.approx(m["f_max"] * m["l_opt"] / 0.25e6, rel=1e-14)


TABLE_5_3 = {  # F_max, l_opt, l_slack, pennation deg, f_fast, width
    "iliopsoas": (821, 0.102, 0.142, 7.5, 0.50, 1.298),
    "rectus_femoris": (663, 0.081, 0.398, 5.0, 0.65, 1.443),
    "glutei": (1705, 0.200, 0.157, 3.0, 0.45, 0.625),
    "hamstrings": (1770, 0.104, 0.334, 7.5, 0.35, 1.197),
    "vasti": (7403, 0.093, 0.223, 4.4, 0.50, 0.627),
    "gastrocnemius": (1639, 0.055, 0.420, 14.3, 0.50, 0.888),
    "tibialis_anterior": (1528, 0.082, 0.317, 6.0, 0.25, 0.442),
    "soleus": (3883, 0.055, 0.245, 23.6, 0.20, 1.039),
}


def test_gait2d_muscles_match_table_5_3(loaded):
    muscles = _sidecar("gait2d")["muscles"]
    assert [m["name"] for m in muscles] == [f"{n}_{s}" for s in "rl" for n in TABLE_5_3]
    for m in muscles:
        f_max, l_opt, l_slack, penn, ffast, width = TABLE_5_3[m["name"][:-2]]
        assert (m["f_max"], m["l_opt"], m["l_slack"], m["fast_fraction"], m["width"]) == (
            f_max, l_opt, l_slack, ffast, width)
        assert m["pennation"] == pytest.approx(math.radians(penn), rel=1e-14)
        assert m["volume"] == pytest.approx(f_max * l_opt / 0.25e6, rel=1e-14)  # Eq. B.3, sigma = 0.25 MPa
        assert all(k.endswith("_" + m["name"][-1]) for k in m["paths"]["constant"]["moment_arms"])
    ms = loaded["gait2d"].muscles
    np.testing.assert_array_equal(ms.l_opt, [TABLE_5_3[n[:-2]][1] for n in ms.names])
    np.testing.assert_array_equal(ms.fast_fraction, [TABLE_5_3[n[:-2]][4] for n in ms.names])


def test_display_points_sit_on_urdf_links(models):
    from pinmsk.muscles.paths import display_points_from_sidecar

    for name in ("finger", "forearm", "gait2d"):
        m = models[name]
        bodies = [f.name for f in m.frames if f.type == pin.FrameType.BODY]
        cfg = _sidecar(name)
        pts = display_points_from_sidecar(cfg["muscles"], bodies=bodies, source=name)
        assert len(pts) == len(cfg["muscles"])
