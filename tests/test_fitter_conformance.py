"""The fitter conformance suite: every pinmsk fitter follows the rules of pinmsk.fitting.

As scikit-learn's ``check_estimator``: the constructor only stores its arguments,
``get_params`` / ``set_params`` / ``clone`` come from the signature, unknown parameter
names are refused by name, ``fit`` returns ``self``, learned attributes end in ``_`` and
appear only with ``fit``, and ``result_`` is the one :class:`~pinmsk.fitting.Result` type
with its statistics.  Each fitter runs on a tiny problem, and the clone is fitted again
to the same numbers.  :func:`test_every_fitter_is_covered` finds the fitters in the
source, so a new one cannot skip the suite.
"""
from __future__ import annotations

import functools
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

import pinmsk
from pinmsk import stats as pstats
from pinmsk.errors import SolverError
from pinmsk.fitting import Fitter, FitStatistics, Result

PACKAGE = Path(pinmsk.__file__).parent
CLASS = re.compile(r"^class (\w+)(?:\((.*)\))?:")


# -- the tiny problems: name -> (fitter class, its keyword arguments, the fit arguments) ---------

def _elbow(n_frames=21):
    from pinmsk.solvers.analytical import gaussian_elbow_motion
    return pinmsk.load_model("forearm"), gaussian_elbow_motion(n_frames=n_frames)


def _so():
    from pinmsk.solvers import StaticOptimization
    return StaticOptimization, dict(exponent=2, dofs=["elbow_flexion"]), _elbow()


def _mso():
    from pinmsk.solvers import ModifiedStaticOptimization
    return ModifiedStaticOptimization, dict(a0=np.zeros(7), dofs=("elbow_flexion",)), _elbow()


def _eid():
    from pinmsk.solvers import ExtendedInverseDynamics
    return ExtendedInverseDynamics, dict(weights="none", dofs=["elbow_flexion"]), _elbow()


def _fso():
    from pinmsk.solvers import ForwardStaticOptimization
    return ForwardStaticOptimization, dict(control_points=41, omega=10.0, gains=None), _elbow(41)


def _collocation():
    from conftest import require_casadi
    require_casadi()
    from pinmsk.solvers.ocp import Collocation, Effort, InitialState, Target, TrackCoordinates
    target = Target("sine", amplitude=0.2, frequency=4.0)
    return Collocation, dict(model=pinmsk.load_model("finger"),
                             cost=0.1 * Effort(2, normalize=False) + 0.9 * TrackCoordinates(target),
                             constraints=[InitialState(q={"mcp_flexion": 0.0}, v={"mcp_flexion": float(target(0.0, 1))})],
                             duration=0.25, intervals=10, solver={"max_iter": 100}), ()


def _coarse_to_fine():
    from conftest import require_casadi
    require_casadi()
    from pinmsk.solvers.ocp import Effort, InitialState, Target, TrackCoordinates
    from pinmsk.solvers.ocp.gait import CoarseToFine
    target = Target("sine", amplitude=0.2, frequency=4.0)
    return CoarseToFine, dict(model=pinmsk.load_model("finger"), coarse_intervals=5, intervals=10,
                              cost=0.1 * Effort(2, normalize=False) + 0.9 * TrackCoordinates(target),
                              constraints=[InitialState(q={"mcp_flexion": 0.0}, v={"mcp_flexion": float(target(0.0, 1))})],
                              duration=0.25, solver={"max_iter": 100}), ()


def _contact():
    from pinmsk.contact import ContactFit, synthetic_foot_trial
    trial = synthetic_foot_trial(contact="point", noise=0.0, seed=1, ground_speed=0.0)
    return ContactFit, dict(contact="point", cutoff=None, n_starts=1, nested=False, max_nfev=30,
                            initial={"heel": {"k_s": 2e5}}, fixed=["dx", "dy"]), (None, trial)


def _ik():
    from pinmsk.ik import InverseKinematics, markers_trial
    from pinmsk.markers import load_marker_set
    model = pinmsk.load_model("gait2d")
    ms = load_marker_set("gait2d").subset("csu")
    t = np.arange(12) / 100.0
    q = np.zeros((t.size, model.nq))
    q[:, model.coordinate_index("torso_y")] = 1.0
    q[:, model.coordinate_index("knee_r")] = 0.5 + 0.2 * np.sin(2 * np.pi * t)
    q[:, model.coordinate_index("hip_r")] = -0.2 * np.sin(2 * np.pi * t)
    return (InverseKinematics, dict(markers=ms, q0={"torso_y": 1.0}, weights={}),
            (model, markers_trial(model, ms, t, q, axes="xy")))


@functools.lru_cache(maxsize=1)
def _damped_comparison():
    from pinmsk.diagnose import compare, make_trial
    forearm = pinmsk.load_model("forearm")
    return compare(forearm, make_trial(forearm, ["joint_damping:elbow_flexion:c=0.3"], duration=3.0, seed=5))


def _effect():
    from pinmsk import effects
    from pinmsk.diagnose import EffectFit
    return EffectFit, dict(effect=effects.JointDamping("elbow_flexion"), max_nfev=50), (_damped_comparison(),)


CASES = {"StaticOptimization": _so, "ModifiedStaticOptimization": _mso, "ExtendedInverseDynamics": _eid,
         "ForwardStaticOptimization": _fso, "Collocation": _collocation, "CoarseToFine": _coarse_to_fine, "ContactFit": _contact,
         "InverseKinematics": _ik, "EffectFit": _effect}


def _same(a, b) -> bool:
    """Equal parameter values: arrays element-wise, containers item by item, other objects by ``==``."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a is b or a == b


def _learned(est) -> set:
    return {k for k in vars(est) if not k.startswith("_")} - set(type(est)._param_names())


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request):
    """(name, an unfitted fitter, its keyword arguments, its fit arguments, the same fitter fitted)."""
    cls, kwargs, args = CASES[request.param]()
    est = cls(**kwargs)
    fitted = cls(**kwargs)
    assert fitted.fit(*args) is fitted                       # fit returns self
    return request.param, est, kwargs, args, fitted


# -- the checks ---------------------------------------------------------------------------------

def test_constructor_only_stores(case):
    name, est, kwargs, _, _ = case
    assert isinstance(est, Fitter) and type(est).__name__ == name
    params = type(est)._param_names()
    assert set(vars(est)) == set(params), "the constructor set something that is not a parameter"
    assert _learned(est) == set() and not hasattr(est, "result_")
    with pytest.raises(SolverError, match=f"this {name} has not run yet.*call fit\\("):
        est.report()
    got = est.get_params(deep=False)
    assert list(got) == list(params)
    assert all(got[k] is v for k, v in kwargs.items())        # stored as given, not converted or copied
    assert est.set_params(**got) is est and _same(est.get_params(deep=False), got)


def test_clone_is_an_equal_unfitted_copy(case):
    _, est, _, _, fitted = case
    for source in (est, fitted):
        c = source.clone()
        assert type(c) is type(source) and c is not source
        assert _same(c.get_params(deep=False), source.get_params(deep=False))
        assert _learned(c) == set()
        for k, v in c.get_params(deep=False).items():       # containers copied: the clone edits its own
            if isinstance(v, (dict, list, np.ndarray)):
                assert v is not getattr(source, k)


def test_set_params_refuses_unknown_names(case):
    name, est, _, _, _ = case
    p = type(est)._param_names()
    with pytest.raises(SolverError, match=f"{name} has no parameter 'no_such_option'.*its parameters: "
                                          f"{p[0]}, {p[1]}"):
        est.clone().set_params(no_such_option=1)
    # a near miss is named
    with pytest.raises(SolverError, match=f"did you mean '{p[-1]}'"):
        est.clone().set_params(**{p[-1] + "x": 1})
    with pytest.raises(SolverError, match="is not a fitter"):
        est.clone().set_params(**{f"{p[-1]}__inner": 1})


def test_learned_attributes_end_in_underscore(case):
    _, est, _, _, fitted = case
    learned = _learned(fitted)
    assert "result_" in learned
    assert all(k.endswith("_") for k in learned), sorted(k for k in learned if not k.endswith("_"))
    assert not any(hasattr(est, k) for k in learned)          # none before fit
    assert _same(fitted.get_params(deep=False), est.get_params(deep=False))   # fit leaves the parameters


def test_result_is_the_one_result_type(case):
    _, _, _, _, fitted = case
    r = fitted.result_
    assert type(r) is Result and isinstance(r, pinmsk.Trial) and r.n_frames >= 2 and r.n_channels >= 1
    s = r.stats
    assert isinstance(s, FitStatistics)
    assert isinstance(s.n, int) and isinstance(s.k, int) and s.k > 0 and isinstance(s.converged, bool)
    assert isinstance(s.sse, float) and s.violation >= 0 and isinstance(s.iterations, int)
    assert r.converged is s.converged and r.k == s.k          # the statistics read as attributes
    if s.least_squares:                                       # AIC/BIC from pinmsk.stats, the one formula
        assert s.n > s.k and math.isfinite(s.sse)
        assert s.aic == pytest.approx(pstats.aic(s.sse, n=s.n, k=s.k, variance=s.variance))
        assert s.bic - s.aic == pytest.approx(s.k * (math.log(s.n) - 2))
    else:                                                     # an effort minimisation: no likelihood
        assert s.n == 0 and math.isnan(s.aic) and math.isnan(s.bic)
    text = fitted.report()
    assert text == r.report() and text.splitlines()[0] and all(ln.startswith("  ") for ln in text.splitlines()[1:])
    json.dumps(fitted.to_dict(), allow_nan=False)             # JSON-ready
    json.dumps(s.to_dict(), allow_nan=False)


def test_clone_fits_to_the_same_numbers(case):
    _, est, _, args, fitted = case
    again = est.clone().fit(*args)
    np.testing.assert_allclose(again.result_.values, fitted.result_.values, rtol=1e-9, atol=1e-12)
    assert again.result_.stats.k == fitted.result_.stats.k
    assert again.result_.stats.sse == pytest.approx(fitted.result_.stats.sse, rel=1e-9, nan_ok=True)


# -- numbers the suite can check for some fitters --------------------------------------------

def test_statistics_of_known_fits():
    """The damping fit recovers c = 0.3 and its AIC/BIC change matches a hand computation."""
    cls, kwargs, args = _effect()
    est = cls(**kwargs).fit(*args)
    s = est.result_.stats
    assert est.params_["c"] == pytest.approx(0.3, rel=0.1)
    assert s.k == 1 and s.variance == "estimated" and s.sse < s.sse_before
    assert s.bic_change == pytest.approx(s.n * math.log(s.sse / s.sse_before) + math.log(s.n))
    assert s.aic_change == pytest.approx(s.n * math.log(s.sse / s.sse_before) + 2)
    assert est.result_.params == est.params_ and est.result_.effect is est.effect_
    # the channels are the fitted effect's change of the equation error: c * velocity
    v = args[0].eq.motion_rows.v[:, 0]
    np.testing.assert_allclose(-est.result_["elbow_flexion_moment"], est.params_["c"] * v, rtol=1e-6, atol=1e-9)


def test_result_details_and_pickling(tmp_path):
    import pickle
    st = FitStatistics(n=10, k=2, sse=4.0, variance="known", converged=True, message="ok", iterations=3)
    r = Result([0.0, 1.0], {"x": [1.0, 2.0]}, stats=st, info={"params": {"a": 1.0}})
    assert r.params == {"a": 1.0} and r.aic == pytest.approx(8.0) and r.bic == pytest.approx(4 + 2 * math.log(10))
    back = pickle.loads(pickle.dumps(r))
    assert type(back) is Result and back.stats.to_dict() == st.to_dict() and back.params == {"a": 1.0}
    assert type(r.select(["x"])) is pinmsk.Trial              # new trials are plain Trials
    with pytest.raises(AttributeError, match="no attribute 'parms'; did you mean 'params'"):
        r.parms
    with pytest.raises(ValueError, match="would hide"):
        Result([0.0], {"x": [1.0]}, stats=st, info={"values": 1})
    with pytest.raises(ValueError, match="variance must be"):
        FitStatistics(n=3, variance="unknown")


# -- every fitter is in the suite ------------------------------------------------------------------

#: classes with a ``fit`` method that are not fitters: a parametrization fits a curve and returns
#: its coefficients; ``Diagnosis.fit(effect)`` looks a ranked effect's fit up or runs EffectFit
NOT_FITTERS = {"Parametrization", "Diagnosis"}


def _classes_with_fit():
    """``{class name: (file, derives from Fitter)}`` of the classes in pinmsk that define ``fit`` or derive
    from Fitter (read from the source: top-level classes and their methods, by indentation)."""
    out = {}
    for path in PACKAGE.rglob("*.py"):
        text = path.read_text()
        if "def fit(" not in text and "Fitter)" not in text:
            continue
        current = None
        for line in text.splitlines():
            m = CLASS.match(line)
            if m:
                current = m.group(1)
                if "Fitter" in (m.group(2) or ""):
                    out[current] = (path.relative_to(PACKAGE.parent), True)
            elif current and line.startswith("    def fit("):
                out.setdefault(current, (path.relative_to(PACKAGE.parent), False))
            elif line and not line[0].isspace() and not line.startswith(("#", ")", '"')):
                current = None
    # a subclass of a Fitter found here is a Fitter too (e.g. CoarseToFine(Collocation))
    for path in PACKAGE.rglob("*.py"):
        for line in path.read_text().splitlines():
            m = CLASS.match(line)
            if m and m.group(1) in out and not out[m.group(1)][1]:
                bases = [b.strip() for b in (m.group(2) or "").strip("()").split(",")]
                if any(out.get(b, (None, False))[1] for b in bases):
                    out[m.group(1)] = (out[m.group(1)][0], True)
    return out


def test_every_fitter_is_covered():
    found = _classes_with_fit()
    not_fitters = {n: p for n, (p, is_fitter) in found.items() if not is_fitter and n not in NOT_FITTERS}
    assert not not_fitters, f"classes with fit() that are not Fitters: {not_fitters}"
    fitters = {n for n, (_, is_fitter) in found.items() if is_fitter}
    assert fitters == set(CASES), f"fitters not in the conformance suite: {sorted(fitters - set(CASES))}"
