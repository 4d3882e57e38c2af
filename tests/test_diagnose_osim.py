"""The diagnosis on exact OpenSim imports: dependent joints following OpenSim's coordinates.

gait10dof18musc ``subject01`` (knee translations that are functions of the knee angle) and RajagopalWalk
(a walker knee turning about three axes, a patella coupled to the knee angle by a
CoordinateCouplerConstraint) are compared in OpenSim's coordinates, every generalized force of the
Pinocchio joints mapped back by ``J^T`` (:meth:`pinmsk.diagnose.compare.EquationError.project`).  Checked
against a second computation path (pinmsk's own exact inverse dynamics, finite differences of the muscle
lengths in OpenSim's coordinates) and by the recovery of hidden effects synthesized by that inverse
dynamics on the richer model.  Needs ``../shared/data``; skips cleanly without it.
"""
import json
import time
import warnings

import numpy as np
import pytest

import pinmsk
from pinmsk.diagnose import compare, diagnose, run
from pinmsk.dynamics import inverse_dynamics
from pinmsk.effects import registry
from pinmsk.errors import ModelError, TrialError
from conftest import shared_folder
from pinmsk.io.shared_data import shared_data_dir
from pinmsk.kinematics import coordinate_map
from pinmsk.model import import_osim
from pinmsk.presentation.cli import main
from pinmsk.trial import Trial

GAIT = "opensim-models/Gait10dof18musc"
RAJAGOPAL = "opensim-models/RajagopalWalk/subject_walk_scaled.osim"
MOCO_WALK = "real/opensim-moco-walk-emg"
MOCO_2D = "opensim-models/Moco2DWalking"
PELVIS_2D = ("pelvis_tilt", "pelvis_tx", "pelvis_ty")


def _gait_dir():
    return shared_folder(GAIT, "subject01.osim")


@pytest.fixture(scope="module")
def gait():
    """``(folder, skeleton-only exact import, the IK walk, the ExternalLoads file)``."""
    d = _gait_dir()
    model, _ = import_osim(d / "subject01.osim", nonlinear="exact", hooks=())
    return d, model, pinmsk.read_trial(d / "IK" / "subject01_walk_IK.mot"), \
        d / "ExperimentalData" / "subject01_walk_grf.xml"


@pytest.fixture(scope="module")
def rajagopal(tmp_path_factory):
    """``(model path, skeleton-only exact import, Moco's coordinates as the user has them, loads file)``."""
    from pinmsk.io.channel_map import read_mapped
    d = shared_data_dir()
    if d is None or not (d / RAJAGOPAL).is_file() or not (d / MOCO_WALK / "coordinates.sto").is_file():
        pytest.skip(f"../shared/data/{RAJAGOPAL} or ../shared/data/{MOCO_WALK} is absent")
    path, walk = d / RAJAGOPAL, d / MOCO_WALK
    model, _ = import_osim(path, nonlinear="exact", hooks=())
    loads = tmp_path_factory.mktemp("rajagopal") / "grf_walk.xml"       # its datafile, relative to the model
    loads.write_text((path.parent / "grf_walk.xml").read_text().replace(
        "<datafile>grf_walk.mot</datafile>", f"<datafile>{walk / 'grf_walk.mot'}</datafile>"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # Moco's nColumns header
        trial = read_mapped(walk / "coordinates.sto", model=model, strict=False)
    return path, model, trial, loads


def _with_moments(trial, moments: Trial, names=None) -> Trial:
    """The trial's coordinates plus the ``<coord>_moment`` channels of ``moments`` (all, or ``names``)."""
    names = [n for n in moments.names if n.endswith("_moment")] if names is None else names
    return Trial(trial.time, {**{n: np.asarray(trial[n]) for n in trial.names},
                              **{n: np.asarray(moments[n]) for n in names}})


def _no_dependent_target(model, labels):
    cmap = coordinate_map(model)
    bad = set(cmap.dependent) | {dep for dep, *_ in cmap.couplers}
    hit = [lb for lb in labels if lb.split(":", 1)[-1] in bad]
    assert not hit, f"candidates on dependent joints or coupled coordinates: {hit}"


# -- (a) the user's command on subject01's walk -------------------------------------------------

def test_subject01_walk_is_diagnosed_in_opensims_coordinates(gait):
    """The IK walk with its GRF has no moments: torque level on the floating base's rows alone, finite
    numbers, and no candidate on the knees' dependent translations."""
    _, model, ik, loads = gait
    d = diagnose(model, ik, external_loads=loads)
    c = d.comparison
    assert c.mode == "torque"
    assert c.coordinates == PELVIS_2D
    assert np.all(np.isfinite(c.eq.e)) and np.all(np.isfinite(c.noise.sigma))
    assert np.isfinite(d.rmse["total"]) and d.rmse["total"] > 1.0        # a real walk's residual, N and N m
    assert d.ranking and all(np.isfinite(s.explained_fraction) for s in d.ranking)
    _no_dependent_target(model, [s.label for s in d.ranking])
    # the pelvis rows are inverse dynamics' residuals there (measured 0): pinmsk id's, frame by frame
    ref = inverse_dynamics(model, ik, external_loads=loads)
    for j, name in enumerate(PELVIS_2D):
        np.testing.assert_allclose(c.eq.e[:, j], -np.asarray(ref[f"{name}_moment"])[c.eq.rows], rtol=0, atol=1e-9)


def test_the_command_line_diagnoses_subject01_walk(gait, tmp_path, capsys):
    d, _, _, loads = gait
    out = tmp_path / "d.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # the muscle paths' import note
        rc = main(["diagnose", str(d / "subject01.osim"), str(d / "IK" / "subject01_walk_IK.mot"),
                   "--external-loads", str(loads), "--json", str(out)])
    assert rc == 0, capsys.readouterr().err
    summary = json.loads(out.read_text())
    text = json.dumps(summary)
    assert "knee_r_translation1" not in text and "NaN" not in text


# -- (c) the diagnosis' inverse dynamics is pinmsk id's, on OpenSim's coordinates -----------------

def test_the_comparison_inverse_dynamics_is_pinmsks_on_every_opensim_coordinate(gait):
    """With pinmsk's own exact ID as the measured moments (and the GRF), the torque level compares every
    OpenSim coordinate, and its inverse dynamics agrees with ``pinmsk.inverse_dynamics`` (a second path:
    ``source_coordinates`` on the whole ID, not the diagnosis' sparse ``J^T``) to rounding."""
    _, model, ik, loads = gait
    ref = inverse_dynamics(model, ik, external_loads=loads)
    c = compare(model, _with_moments(ik, ref), external_loads=loads)
    assert set(c.coordinates) == set(coordinate_map(model).osim_coordinates)
    for j, name in enumerate(c.coordinates):
        np.testing.assert_allclose(c.eq.tau_id[:, j], np.asarray(ref[f"{name}_moment"])[c.eq.rows],
                                   rtol=0, atol=1e-9)
    assert np.max(np.abs(c.eq.e)) < 1e-9


def test_motion_level_is_refused_by_name_on_an_exact_model(gait):
    _, model, ik, loads = gait
    trial = _with_moments(ik, inverse_dynamics(model, ik, external_loads=loads))
    with pytest.raises(ModelError, match=r"motion-level comparison .*\(knee_r_translation1, .*\) are dependent "
                                         r"joints.*use mode='torque' or 'muscle'"):
        compare(model, trial, mode="motion")


def test_synthetic_trials_are_refused_by_name_on_an_exact_model(gait):
    from pinmsk.diagnose import make_trial
    _, model, _, _ = gait
    with pytest.raises(ModelError, match=r"make_trial \(pinmsk synth\) moves the Pinocchio joints .* "
                                         r"\(knee_r_translation1"):
        make_trial(model, [])


# -- (b) hidden effects recovered on the exact model ---------------------------------------------

@pytest.mark.filterwarnings("ignore::pinmsk.errors.ResidualWarning")      # no GRF: the actuated rows only
@pytest.mark.parametrize("family, target, name, value", [
    ("joint_damping", "knee_angle_r", "c", 2.0),          # acts on a coordinate that is a joint
    pytest.param("segment_mass", "tibia_r", "delta", 0.15,  # its generalized forces reach the dependent joints
                 marks=pytest.mark.slow),
])
def test_a_hidden_effect_is_recovered_on_the_exact_model(gait, family, target, name, value):
    """Measured moments from pinmsk's exact ID of the richer model without the GRF (white noise of 0.2 N m
    added), compared on the actuated coordinates: the
    diagnosis of the plain model ranks the hidden effect first, significant, and recovers its value
    within three standard errors; added, the remade comparison is at its noise floor."""
    _, model, ik, _ = gait
    hidden = registry.get(family)(target).with_params(**{name: value})
    rich = inverse_dynamics(model.with_effect(hidden), ik)
    names = [f"{c}_moment" for c in coordinate_map(model).osim_coordinates if c not in PELVIS_2D]
    rng = np.random.default_rng(0)
    noisy = Trial(rich.time, {n: np.asarray(rich[n]) + 0.2 * rng.standard_normal(rich.n_frames) for n in names})
    trial = _with_moments(ik, noisy, names)
    d = diagnose(model, trial)
    assert d.comparison.coordinates == tuple(n[: -len("_moment")] for n in names)
    best = d.ranking[0]
    assert best.label == hidden.label and best.significant
    se = best.stderr[name]
    assert np.isfinite(se) and 0 < se < 0.2 * value
    assert abs(best.params[name] - value) < 3 * se
    _no_dependent_target(model, [s.label for s in d.ranking])
    # added (the diagnosis loop's next step, the comparison remade for the richer model): the noise is left
    after = run(model, trial, add=[hidden.label], first=d).steps[-1]
    assert after.model.component(hidden.label) is not None
    assert after.rmse["total"] < 0.6 * d.rmse["total"] and after.verdict == "at_noise_floor"


# -- muscle level ---------------------------------------------------------------------------------

def test_muscle_level_on_the_exact_model_uses_opensims_moment_arms(gait):
    """Muscle level on subject01 with its muscles and excitations: the moment arms the comparison uses are
    ``-dl/dq`` of OpenSim's coordinates (central differences of the muscle lengths through the coordinate
    map), and the diagnosis runs to finite numbers."""
    d, _, ik, loads = gait
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = pinmsk.load_model(d / "subject01.osim")
    cmap = coordinate_map(model)
    u = {f"{m}_excitation": 0.2 + 0.1 * np.sin(2 * np.pi * np.asarray(ik.time) + k)
         for k, m in enumerate(model.muscle_names)}
    trial = Trial(ik.time, {**{n: np.asarray(ik[n]) for n in ik.names}, **u})
    c = compare(model, trial, mode="muscle", external_loads=loads)
    assert "knee_angle_r" in c.coordinates and set(PELVIS_2D) <= set(c.coordinates)
    rows = c.eq.rows[::10]
    mo = c.eq.motion
    q_os = np.column_stack([mo.q[rows, model.coordinate_index(x)] for x in cmap.osim_coordinates])
    h = 1e-6
    for j, name in enumerate(c.coordinates):
        k = cmap.osim_coordinates.index(name)
        dq = np.zeros_like(q_os)
        dq[:, k] = h
        dl = model.muscles.lengths(cmap.expand(q_os + dq)[0]) - model.muscles.lengths(cmap.expand(q_os - dq)[0])
        np.testing.assert_allclose(c.eq.moment_arms[rows, :, j], -dl / (2 * h), rtol=0, atol=1e-7)
    assert np.max(np.abs(c.eq.moment_arms[:, :, c.coordinates.index("knee_angle_r")])) > 0.01
    # signals for some muscles only (Moco's walk records 10 of Rajagopal's 80): refused, naming them
    part = Trial(ik.time, {**{n: np.asarray(ik[n]) for n in ik.names}, **dict(list(u.items())[:2])})
    with pytest.raises(TrialError, match=r"excitation channels for some muscles \(2 of 18\) but not "
                                         rf"{model.muscle_names[2]}_excitation, .* and 8 more"):
        compare(model, part, mode="muscle", external_loads=loads)
    dg = diagnose(model, trial, mode="muscle", external_loads=loads, comparison=c)
    assert np.isfinite(dg.rmse["total"])
    _no_dependent_target(model, [s.label for s in dg.ranking])


# -- (d) the Rajagopal walk ---------------------------------------------------------------------

def test_rajagopal_walk_is_diagnosed_with_its_missing_coordinates_defaulted(rajagopal):
    """Moco's walk lacks the mtp angles: refused by name with the flag; with ``missing_coordinates="default"``
    (as OpenSim's ID tool) diagnosed on the six pelvis rows, no candidate on the walker knee's dependent
    joints or the coupled patella angle."""
    _, model, trial, loads = rajagopal
    with pytest.raises(TrialError, match=r"'mtp_angle_r'.*--missing-coordinates default"):
        compare(model, trial, external_loads=loads)
    t0 = time.perf_counter()
    d = diagnose(model, trial, external_loads=loads, missing_coordinates="default")
    print(f"\nRajagopal walk: diagnose() {time.perf_counter() - t0:.2f} s, {trial.n_frames} frames")
    c = d.comparison
    assert c.coordinates == ("pelvis_tilt", "pelvis_list", "pelvis_rotation", "pelvis_tx", "pelvis_ty", "pelvis_tz")
    assert np.all(np.isfinite(c.eq.e)) and np.isfinite(d.rmse["total"])
    assert d.ranking and all(np.isfinite(s.explained_fraction) for s in d.ranking)
    _no_dependent_target(model, [s.label for s in d.ranking])
    assert not [s.label for s in d.ranking if "walker_knee" in s.label]     # bodies by their OpenSim names
    assert any("mtp_angle_r: not in the trial; held at its default" in n for n in c.inputs.notes)


def test_rajagopal_patella_moment_folds_into_the_knee(rajagopal):
    """OpenSim's ID reports the coupled patella angle's own moment; the comparison folds it into the knee
    angle through the coupler's slope (``J^T`` with the couplers applied), the model's and the measured
    alike: with pinmsk's ID as the measurement the residual vanishes on every compared coordinate, and the
    knee's modelled moment is ID's knee moment plus ``f'(q) tau_beta``."""
    _, model, trial, loads = rajagopal
    ref = inverse_dynamics(model, trial, external_loads=loads, missing_coordinates="default")
    c = compare(model, _with_moments(trial, ref), external_loads=loads, missing_coordinates="default")
    assert "knee_angle_r" in c.coordinates and "knee_angle_r_beta" not in c.coordinates
    assert np.max(np.abs(c.eq.e)) < 1e-8
    cmap = coordinate_map(model)
    dep, indep, f, scale = next(x for x in cmap.couplers if x[0] == "knee_angle_r_beta")
    rows = c.eq.rows
    knee = c.eq.motion.q[rows, model.coordinate_index(indep[0])]
    expect = np.asarray(ref["knee_angle_r_moment"])[rows] + scale * f.derivative(knee, 1) * np.asarray(
        ref["knee_angle_r_beta_moment"])[rows]
    got = c.eq.tau_id[:, c.coordinates.index("knee_angle_r")]
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-9)
    assert np.max(np.abs(got - np.asarray(ref["knee_angle_r_moment"])[rows])) > 1e-3   # the fold is not nil
    # the sparse projection is the coordinate map's dense J^T (couplers applied) for any joint forces
    from pinmsk.kinematics import source_positions
    Q = np.random.default_rng(1).standard_normal((2, rows.size, model.nv))
    dense = np.stack([cmap.generalized_forces(source_positions(model, c.eq.motion_rows), x, couplers=True)
                      for x in Q])[:, :, [cmap.osim_coordinates.index(x) for x in c.coordinates]]
    np.testing.assert_allclose(c.eq.project(Q), dense, rtol=0, atol=1e-12)
    k = [c.coordinates.index("knee_angle_l"), 0]
    np.testing.assert_allclose(c.eq.project(Q, k), dense[:, :, k], rtol=0, atol=1e-12)
    # the noise floor's path: no perturbation of OpenSim's coordinates gives the motion back (the walker
    # knee and the patella mapped again); one of the knee angle moves its dependent joints with it
    z = np.zeros((c.eq.motion.n_frames, len(c.eq.kinematic_channels)))
    same = c.eq.perturbed_motion(z, z, z)
    for x in ("q", "v", "a"):
        np.testing.assert_allclose(getattr(same, x), getattr(c.eq.motion, x), rtol=0, atol=1e-9)
    dq = z.copy()
    dq[:, c.eq.kinematic_channels.index("knee_angle_r")] = 1e-3
    moved = c.eq.perturbed_motion(dq, z, z).q - c.eq.motion.q
    assert np.max(np.abs(moved[:, model.coordinate_index("walker_knee_r_translation1")])) > 1e-7
    assert np.max(np.abs(moved[:, model.coordinate_index("patellofemoral_r_rotation1")])) > 1e-5


def test_without_names_an_unknown_component_on_the_command_line(gait, capsys):
    d, _, _, loads = gait
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(["diagnose", str(d / "subject01.osim"), str(d / "IK" / "subject01_walk_IK.mot"),
                   "--external-loads", str(loads), "--without", "joint_damping:knee_angle_r"])
    assert rc == 2
    assert "has no component 'joint_damping:knee_angle_r'" in capsys.readouterr().err


@pytest.mark.slow          # imports Rajagopal's 80 muscle paths
def test_without_drops_a_component_on_the_command_line(rajagopal, tmp_path, capsys):
    path, _, _, loads = rajagopal
    walk = shared_data_dir() / MOCO_WALK
    base = ["diagnose", str(path), str(walk / "coordinates.sto"), "--external-loads", str(loads),
            "--missing-coordinates", "default", "--lenient"]
    out = tmp_path / "d.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(base + ["--without", "coordinate_actuator:lumbar_ext", "--without",
                          "coordinate_actuator:lumbar_bend", "--json", str(out)])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    effects = next(line for line in cap.out.splitlines() if line.startswith("model effects:"))
    assert "coordinate_actuator:lumbar_rot" in effects
    assert "coordinate_actuator:lumbar_ext" not in effects and "coordinate_actuator:lumbar_bend" not in effects
    assert json.loads(out.read_text())["inputs"]


# -- contacts against a measured GRF ----------------------------------------------------------------

def test_contacts_and_a_measured_grf_are_refused_with_the_flag_that_drops_them():
    """2D_gait's contact spheres and a measured GRF on the same foot would count the ground twice: refused,
    naming each contact and ``--without`` for it; the model without them is compared."""
    from pinmsk.opensim.contacts import contact_hook
    d = shared_data_dir()
    if d is None or not (d / MOCO_2D / "2D_gait.osim").is_file():
        pytest.skip(f"../shared/data/{MOCO_2D} is absent")
    model, _ = import_osim(d / MOCO_2D / "2D_gait.osim", hooks=(contact_hook,))
    t = np.linspace(0.0, 2.0, 201)
    q = {c: 0.05 * np.sin(2 * np.pi * t + k) for k, c in enumerate(model.coordinates)}
    q["pelvis_ty"] = 0.9 + q["pelvis_ty"]
    n = t.size
    grf = {"ground_force_r_vx": np.zeros(n), "ground_force_r_vy": np.full(n, 600.0),
           "ground_force_r_vz": np.zeros(n), "ground_force_r_px": np.full(n, 0.1),
           "ground_force_r_py": np.zeros(n), "ground_force_r_pz": np.zeros(n)}
    trial = Trial(t, {**q, **grf})
    with pytest.raises(TrialError, match=r"the ground would act twice; leave the contacts out "
                                         r"\(--without smooth_sphere_half_space:heel_r "
                                         r"--without smooth_sphere_half_space:front_r;"):
        compare(model, trial, mode="torque", cutoff=0)
    bare = model.without("smooth_sphere_half_space:heel_r").without("smooth_sphere_half_space:front_r")
    c = compare(bare, trial, mode="torque", cutoff=0)
    assert set(PELVIS_2D) <= set(c.coordinates) and np.all(np.isfinite(c.eq.e))
