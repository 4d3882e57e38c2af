"""Static optimization: against the analytical 1-dof optima, SLSQP, and on bad input.

The forearm follows the Gaussian 0 -> 120 deg elbow motion of thesis
Fig. 3.13 (sigma = 0.25 s over 2 s, see analytical.gaussian_elbow_motion);
its net moment changes sign around the peak, so both KKT branches (flexors
or extensors active) are exercised.
"""
import numpy as np
import pytest

from pinmsk import Trial, load_model, read_trial, write_trial
from pinmsk.components import Motion
from pinmsk.diagnose.synth import walking_motion
from pinmsk.dynamics import inverse_dynamics_array
from pinmsk.errors import InfeasibleError, ModelError, SolverError, TrialError
from pinmsk.solvers import StaticOptimization
from pinmsk.solvers.analytical import gaussian_elbow_trial, one_dof_activations, one_dof_forces
from pinmsk.solvers.static import build_problem, solve_frame_slsqp


@pytest.fixture(scope="module")
def gait2d():
    return load_model("gait2d")


def _rel_err(F, Fa, f_max):
    """|F - Fa| relative to max(|Fa|, 1e-3 F_max): 1e-6 means six correct digits."""
    return np.max(np.abs(F - Fa) / np.maximum(np.abs(Fa), 1e-3 * f_max))


# -- analytical optima on the forearm ------------------------------------------

@pytest.mark.parametrize("method", ["auto", "proxsuite"])
@pytest.mark.parametrize("P,minmax", [(1, False), (2, False), (3, False), (10, False), (2, True)])
def test_forearm_force_mode_matches_analytical(forearm, motion, P, minmax, method):
    so = StaticOptimization(exponent=P, minmax=minmax, method=method).fit(forearm, motion)
    R = so.problem_.R[:, :, 0]
    T = so.problem_.tau[:, 0]
    assert T.min() < 0 < T.max()              # the net moment changes sign: both branches used
    Fa = one_dof_forces(R, T, exponent=P, upper=forearm.muscles.f_max, minmax=minmax)
    assert _rel_err(so.forces_, Fa, forearm.muscles.f_max) < 1e-6
    # no co-contraction in one dof (Sec. 3.5.3)
    flex = R[0] > 0
    assert np.all((so.forces_[:, flex].max(1) < 1e-9) | (so.forces_[:, ~flex].max(1) < 1e-9))


@pytest.mark.parametrize("weights", ["fmax", "pcsa", "volume"])
def test_forearm_weights(forearm, motion, weights):
    so = StaticOptimization(exponent=2, weights=weights).fit(forearm, motion)
    n = {"fmax": forearm.muscles.f_max, "pcsa": forearm.muscles.pcsa, "volume": forearm.muscles.volume}[weights]
    Fa = one_dof_forces(so.problem_.R[:, :, 0], so.problem_.tau[:, 0], exponent=2, n=n,
                        upper=forearm.muscles.f_max)
    assert _rel_err(so.forces_, Fa, forearm.muscles.f_max) < 1e-6


def test_saturation_branch(forearm, motion):
    """Moments near capacity: muscles saturate at F_max and the rest share (water filling)."""
    tau = inverse_dynamics_array(forearm, motion) * 14.0
    for P in (2, 3):
        so = StaticOptimization(exponent=P).fit(forearm, motion, moments=tau)
        Fa = one_dof_forces(so.problem_.R[:, :, 0], tau[:, 0], exponent=P, upper=forearm.muscles.f_max)
        assert np.any(np.isclose(Fa, forearm.muscles.f_max))       # the branch is really exercised
        assert _rel_err(so.forces_, Fa, forearm.muscles.f_max) < 1e-6


@pytest.mark.parametrize("P", [2, 3])
def test_forearm_activation_mode_matches_analytical(forearm, motion, P):
    so = StaticOptimization(mode="activation", exponent=P, weights="volume").fit(forearm, motion)
    fa, fp = forearm.muscles.force_limits(motion.q, motion.v)
    a = one_dof_activations(so.problem_.R[:, :, 0], so.problem_.tau[:, 0], fa, fp, exponent=P,
                            s=forearm.muscles.volume)
    assert np.max(np.abs(so.activations_ - a)) < 1e-6
    np.testing.assert_allclose(so.forces_, a * fa + fp, atol=1e-6 * forearm.muscles.f_max.max())


def test_result_trial_and_files(forearm, motion, tmp_path):
    so = StaticOptimization().fit(forearm, motion)
    r = so.result_
    for n in forearm.muscles.names:
        assert f"{n}_force" in r and f"{n}_activation" in r
    for c in ("status", "cost", "violation"):
        assert c in r
    assert np.all(r["status"] >= 0)
    assert np.max(r["violation"]) < 1e-6
    np.testing.assert_allclose(r["cost"], np.sum(so.forces_ ** 2, axis=1))   # Eq. 3.13 with P = 2
    for suffix in (".sto", ".csv"):
        path = write_trial(r, tmp_path / f"so{suffix}")
        back = read_trial(path)
        np.testing.assert_allclose(back["BRD_force"], r["BRD_force"], rtol=5e-9)   # %.9g
    text = so.report()
    for word in ("objective", "iterations", "convergence", "violation", "Eq. 2.11"):
        assert word in text


def test_trial_input_with_inverse_dynamics(forearm):
    trial = gaussian_elbow_trial()
    so = StaticOptimization().fit(forearm, trial)
    assert so.forces_.shape == (trial.n_frames, 7)
    assert np.max(so.violation_) < 1e-6


# -- multi-dof, bi-articular: gait2d against SLSQP ---------------------------------

GAIT2D_SPANNED = ("hip_l", "knee_l", "ankle_l", "hip_r", "knee_r", "ankle_r")


def test_gait2d_default_dofs_are_the_spanned_ones_and_the_rest_is_reported(gait2d):
    mo = walking_motion(gait2d, n_frames=50)
    # a floating base without GRF needs body weight at torso_y: refused by name without reserves
    with pytest.raises(InfeasibleError, match=r"no muscle spans torso_x, torso_y, torso_angle.*torso_y \(peak"):
        StaticOptimization().fit(gait2d, mo)
    so = StaticOptimization(reserves=True).fit(gait2d, mo)
    assert set(so.dofs_) == set(GAIT2D_SPANNED)
    # the reserve at an unspanned coordinate is exactly the force inverse dynamics needs there
    tau = inverse_dynamics_array(gait2d, mo)
    j = gait2d.coordinate_index("torso_y")
    np.testing.assert_allclose(so.result_["torso_y_reserve"], tau[:, j], rtol=1e-12)
    assert np.max(np.abs(tau[:, j])) > 0.9 * gait2d.mass * 9.81      # holds the body up
    assert "torso_y" in so.report() and "ideal reserves" in so.report()
    # explicit dofs: the others are left out on purpose, and reported as such
    so2 = StaticOptimization(dofs=GAIT2D_SPANNED).fit(gait2d, mo)
    np.testing.assert_allclose(so2.forces_, so.forces_, atol=1e-6 * so.problem_.f_max.max())
    assert "left out by request" in so2.report()
    with pytest.raises(ModelError, match="mtp_r"):
        StaticOptimization(dofs=["hip_r", "mtp_r"]).fit(gait2d, mo)


@pytest.mark.parametrize("P,minmax,mode", [(2, False, "force"), (3, False, "force"), (1, False, "force"),
                                           (2, False, "activation"), (2, True, "force")])
def test_gait2d_matches_slsqp(gait2d, P, minmax, mode):
    mo = walking_motion(gait2d, n_frames=120)
    so = StaticOptimization(exponent=P, minmax=minmax, mode=mode, dofs=GAIT2D_SPANNED).fit(gait2d, mo)
    prob = so.problem_
    x = so.forces_ / prob.f_max if mode == "force" else so.activations_
    for k in range(0, prob.n_frames, 12):
        xr = solve_frame_slsqp(prob, k, minmax=minmax)
        if minmax:   # the min/max optimum value is unique, the forces need not be
            assert abs(np.max(prob.u * xr) - np.max(prob.u * x[k])) <= 1e-6 * np.max(prob.u * xr)
        else:
            cost_r = np.sum(prob.k * xr ** prob.exponent)
            assert so.cost_[k] <= cost_r * (1 + 1e-9)
            assert np.max(np.abs(xr - x[k])) < 1e-4
    assert np.max(so.violation_) < 1e-6


def test_auto_and_proxsuite_paths_agree(gait2d):
    mo = walking_motion(gait2d, n_frames=60)
    for P in (2, 3, 1):
        a = StaticOptimization(exponent=P, dofs=GAIT2D_SPANNED).fit(gait2d, mo)
        b = StaticOptimization(exponent=P, method="proxsuite", dofs=GAIT2D_SPANNED).fit(gait2d, mo)
        assert a.n_batched_ > 0 and b.n_batched_ == 0
        np.testing.assert_allclose(a.forces_, b.forces_, atol=1e-5 * a.problem_.f_max.max())


# -- infeasible frames and reserves ------------------------------------------------

def test_infeasible_raises_with_frames_dof_and_deficit(forearm, motion):
    tau = inverse_dynamics_array(forearm, motion) * 20.0
    with pytest.raises(InfeasibleError) as ei:
        StaticOptimization().fit(forearm, motion, moments=tau)
    msg = str(ei.value)
    assert "frame" in msg and "elbow_flexion" in msg and "short by" in msg and "reserves=True" in msg


@pytest.mark.parametrize("P", [1, 2, 3])
def test_reserves_used_only_where_needed(forearm, motion, P):
    tau = inverse_dynamics_array(forearm, motion) * 20.0
    so = StaticOptimization(exponent=P, reserves=True).fit(forearm, motion, moments=tau)
    r = so.reserves_[:, 0]
    R = so.problem_.R[:, :, 0]
    flex_cap = np.sum(np.clip(R, 0, None) * forearm.muscles.f_max, axis=1)
    ext_cap = np.sum(np.clip(-R, 0, None) * forearm.muscles.f_max, axis=1)
    deficit = np.where(tau[:, 0] > 0, np.maximum(tau[:, 0] - flex_cap, 0), np.minimum(tau[:, 0] + ext_cap, 0))
    np.testing.assert_allclose(r, deficit, atol=1e-6)
    assert np.all((so.status_ == 2) == (np.abs(deficit) > 1e-6 * so.problem_.scale[0]))
    assert "elbow_flexion_reserve" in so.result_
    assert "reserves" in so.report()


def test_reserves_zero_when_feasible(forearm, motion):
    a = StaticOptimization(reserves=True).fit(forearm, motion)
    b = StaticOptimization().fit(forearm, motion)
    assert np.max(np.abs(a.reserves_)) < 1e-9
    np.testing.assert_allclose(a.forces_, b.forces_, atol=1e-8)


# -- bad input ------------------------------------------------------------------

def test_trial_missing_coordinate(forearm):
    tr = Trial(np.linspace(0, 1, 20), {"elbow_flex": np.zeros(20)})
    with pytest.raises(TrialError, match="elbow_flexion"):
        StaticOptimization().fit(forearm, tr)


def test_nan_in_trial(forearm):
    q = np.linspace(0, 1, 30)
    q[7] = np.nan
    with pytest.raises(TrialError, match="elbow_flexion"):
        StaticOptimization().fit(forearm, Trial(np.linspace(0, 1, 30), {"elbow_flexion": q}))


def test_nan_in_moments(forearm, motion):
    tau = inverse_dynamics_array(forearm, motion)
    tau[5, 0] = np.nan
    with pytest.raises(TrialError, match="frame 5"):
        StaticOptimization().fit(forearm, motion, moments=tau)


def test_zero_length(forearm):
    mo = Motion(np.zeros(0), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((0, 1)))
    with pytest.raises(TrialError, match="no frames"):
        StaticOptimization().fit(forearm, mo)
    with pytest.raises(TrialError):
        StaticOptimization().fit(forearm, Trial(np.zeros(0), {"elbow_flexion": np.zeros(0)}))


def test_nonpositive_fmax(forearm, motion):
    class Weak:
        def __init__(self, ms):
            self._ms = ms
            self.f_max = np.array(ms.f_max, dtype=float)
            self.f_max[2] = 0.0

        def __getattr__(self, name):
            return getattr(self._ms, name)

    class Model:
        name = "weak"
        muscles = Weak(forearm.muscles)

        def __getattr__(self, name):
            return getattr(forearm, name)

    with pytest.raises(ModelError, match="BICSH.*F_max"):
        StaticOptimization().fit(Model(), motion)


def test_bad_options(forearm, motion):
    for kw, word in [(dict(mode="torque"), "mode"), (dict(weights="mass"), "weights"),
                     (dict(exponent=0.5), "exponent"), (dict(method="cvx"), "method"),
                     (dict(tol=0), "tol")]:
        with pytest.raises(SolverError, match=word):
            StaticOptimization(**kw).fit(forearm, motion)
    with pytest.raises(SolverError, match="not fitted"):
        StaticOptimization().report()


def test_moments_shape_checked(forearm, motion):
    with pytest.raises(TrialError, match="moments"):
        StaticOptimization().fit(forearm, motion, moments=np.zeros((3, 1)))


def test_model_without_muscles(motion):
    from pinmsk.model import Model
    fm = load_model("forearm")
    bare = Model(name="bare", pin_model=fm.pin)
    with pytest.raises(ModelError, match="no muscles"):
        StaticOptimization().fit(bare, motion)


def test_build_problem_scaling(forearm, motion):
    prob = build_problem(forearm, motion)
    assert np.max(np.sum(np.abs(prob.A), axis=2)) <= 1.0 + 1e-12
    np.testing.assert_allclose(prob.scale[0], np.sum(np.abs(prob.R[0, :, 0]) * forearm.muscles.f_max))


def test_so_says_the_models_activation_dynamics_do_not_change_its_frames(forearm, motion):
    # an effect in the model is used or named, never silently ignored: SO's activations are
    # per frame, so activation dynamics leave them unchanged, and the report says so
    from pinmsk.effects import ActivationDynamics
    plain = StaticOptimization().fit(forearm, motion)
    withad = StaticOptimization().fit(forearm + ActivationDynamics("muscles"), motion)
    assert np.array_equal(plain.forces_, withad.forces_)
    assert "activation_dynamics:muscles act between excitation and activation" in withad.report()
    assert "act between excitation" not in plain.report()
