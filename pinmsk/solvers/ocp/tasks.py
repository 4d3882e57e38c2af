"""Task files of ``pinmsk optimize``: a TOML (or JSON) description of an optimal-control problem.

The sections and keys are :data:`TASK_SCHEMA`; an unknown section or key is an
error naming it.  Task files written for the replaced single-shooting engine
keep working: their ``[solver] step`` sets the collocation intervals
(``duration / step``), and the keys that only tuned that engine's finite
differences and processes (``fd_step``, ``fd``, ``n_jobs``, ``restarts``,
``budget_factor``, ``precondition``, ``fv_smooth``) are accepted and have no
effect, which :func:`build_from_task` says on stderr.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pinocchio as pin

from ...errors import ModelError
from ...io.tables import read_trial
from ...io.toml_files import check_keys, read_toml
from ...model import Model, load_model
from ..parametrization import Fourier, Polynomial, Spline
from .constraints import ExcitationBounds, InitialState, TrackingTolerance
from .controls import GlobalControls, NodeControls
from .costs import Effort, MetabolicEnergy, TrackCoordinates
from .problem import SCHEMES, Collocation
from .target import Target

__all__ = ["TASK_SCHEMA", "load_task", "build_from_task", "scale_masses"]

_NO_EFFECT = {"fd_step", "fd", "n_jobs", "restarts", "budget_factor", "precondition", "fv_smooth"}

TASK_SCHEMA = {
    "model": {"name": "built-in model name or path of a .toml sidecar / .osim (required)",
              "moment_arms": "path variant, e.g. 'constant' or 'angle'",
              "tendon": "'rigid' or 'compliant' (implicit tendon-force dynamics)",
              "mass_scale": "scale factor on all segment masses and inertias (e.g. 0.5)"},
    "motion": {"kind": "'sine' | 'cycle' | 'file'", "coordinate": "tracked coordinate",
               "amplitude": "rad", "frequency": "Hz (sine)", "period": "s (cycle)",
               "offset": "rad", "phase": "rad (sine)", "duration": "s (default: one period)",
               "file": "trial file (.csv/.sto/.mot) holding the coordinate (kind = 'file')"},
    "parametrization": {"kind": "'nodes' (values at the collocation points) | 'polynomial' | 'fourier' | "
                                "'spline'",
                        "design": "formulation: 'ff' excitations | 'ifm' muscle forces | 'ift' joint torques",
                        "order": "polynomial order",
                        "n_harmonics": "Fourier K (2K + 1 terms)",
                        "period": "Fourier period tau (s; default the duration)",
                        "free_period": "true: tau is a decision variable (Sec. 3.3.6)",
                        "period_bounds": "[lower, upper] factors on tau with free_period",
                        "n_params": "spline coefficients"},
    "objective": {"kind": "'effort' | 'metabolic'", "exponent": "P of Eq. 3.5",
                  "weights": "'none' | 'volume'", "normalize": "divide by sum S_i (Eq. 3.5)",
                  "model": "'umberger2003' (metabolic)",
                  "normalizer": "metabolic: W the mean power is divided by (default 1)",
                  "smooth": "metabolic: width of the C1 switches of the heat rates (default 0.01)",
                  "tracking_weight": "1 - mu of Eq. 3.3"},
    "constraints": {"excitation_bounds": "[lower, upper] (Eq. 3.8)",
                    "tracking_tolerance": "rad (Eq. 3.7)",
                    "bound_points": "accepted; the bounds hold at every collocation point",
                    "tracking_points": "accepted; the tolerance holds at every collocation point",
                    "initial_state": "'target' (default: the motion's start, a(0) = u(0)) | 'free'"},
    "gait": {"kind": "'predictive' | 'tracking' (a gait2d half cycle or a measured walk, thesis Ch. 5; "
                     "replaces [motion])",
             "speed": "m/s (predictive; 'free' for a free speed)", "duration": "s (half cycle, or the tracked span)",
             "effort_weight": "weight of the mean squared activation",
             "guess": "'walking' (default: a walking-like guess from the speed alone) | 'standing' | 'quasi-random' | "
                      "a stride file of pinmsk optimize (its first half cycle; relative to the task file)",
             "foot_mass": "predictive: both feet's mass and inertia scaled by this (thesis Sec. 5.3: 0.67)",
             "mtp_stiffness": "predictive: N m/rad, the toe joints' passive spring (default 20; 'none': no spring)",
             "mtp_damping": "predictive: N m s/rad, the toe joints' damper (default 0.5)",
             "trunk": "rad, bound on the trunk angle (default 0.15)",
             "coarse_intervals": "predictive: intervals of the coarse first solve (0: none)",
             "smoothness_weight": "predictive: weight of the mean squared accelerations",
             "seed": "quasi-random guess seed", "knee_min": "rad, knee hyper-extension bound (Eq. 5.10)",
             "contact_smoothing": "m, width of the smoothed penetration",
             "muscle_model": "'degroote2016' (default: the model's muscles as De Groote 2016 units, which "
                             "converge) | 'model' (the model's own muscle law)",
             "coordinates": "tracking: OpenSim coordinates file (.sto/.mot), mapped onto gait2d",
             "grf": "tracking: ground reaction force file (.mot)", "start": "tracking: first time (s)",
             "grf_weight": "tracking: weight of the GRF term",
             "subject_weight": "tracking: 'none' (default: the measured GRF in N, as Moco) | N | 'grf' (the mean vertical GRF over the span): track the GRF in body weights"},
    "solver": {"intervals": "collocation intervals (default duration / step, or 50)",
               "scheme": "'hermite-simpson' (default) | 'trapezoidal'",
               "step": "interval length (s) when intervals is not given",
               "maxiter": "IPOPT iterations (default 1000)", "tol": "IPOPT tolerance (default 1e-8)",
               "constraint_tol": "accepted scaled constraint violation (default 1e-6)",
               "n_starts": "automatic initial guesses (default 1)",
               "hessian": "'exact' (default) | 'limited-memory'",
               "smooth": "metabolic: width of the heat-rate switches (as [objective] smooth)",
               **{k: "replaced engine's setting: accepted, no effect (exact derivatives, one process)"
                  for k in sorted(_NO_EFFECT)}},
}


def _check_keys(table: dict, section: str, where: str):
    check_keys(table, TASK_SCHEMA[section], where=where, section=f"[{section}]")


def shipped_tasks() -> dict[str, Path]:
    """The task files shipped with pinmsk (``data/tasks/``, installed as ``pinmsk._data.tasks``) by name."""
    from ...io.shared_data import shipped_data_dir
    folder = shipped_data_dir() / "tasks"
    return {p.stem: p for p in sorted(folder.glob("*.toml"))} if folder.is_dir() else {}


def resolve_task(task) -> Path:
    """The task file ``task`` names: a path that exists, else a shipped task by name (``gait2d_predictive``,
    with or without ``.toml``); ModelError listing the shipped tasks otherwise."""
    p = Path(str(task))
    if p.exists():
        return p
    shipped = shipped_tasks()
    name = p.stem if p.suffix.lower() in (".toml", "") and p.parent == Path(".") else None
    if name in shipped:
        return shipped[name]
    from ...trial import close_matches
    hint = close_matches(p.stem, list(shipped), n=1)
    did = f" (did you mean {hint[0]!r}?)" if hint else ""
    raise ModelError(f"task file not found: {p}{did}; shipped tasks, run by name (pinmsk optimize NAME): "
                     f"{', '.join(shipped) or 'none'}")


def load_task(task_path) -> dict:
    """Read and validate a task file (TOML or JSON; a path, or a shipped task's name: :func:`resolve_task`);
    see :data:`TASK_SCHEMA`."""
    p = resolve_task(task_path)
    if p.suffix.lower() == ".json":
        try:
            spec = json.loads(p.read_text())
        except json.JSONDecodeError as exc:
            raise ModelError(f"{p}: not valid JSON (line {exc.lineno}, column {exc.colno}): {exc.msg}") from None
    else:
        spec = read_toml(p, what="task file")
    for k in spec:
        if k not in TASK_SCHEMA:
            raise ModelError(f"{p}: unknown section '{k}'; valid sections: {', '.join(TASK_SCHEMA)}")
    if "model" not in spec or "name" not in spec.get("model", {}):
        raise ModelError(f"{p}: missing model: add a [model] table with name = \"finger\" (a "
                         "built-in name) or the path of a model sidecar .toml")
    if "motion" not in spec and "gait" not in spec:
        raise ModelError(f"{p}: missing [motion] table (the motion to track)")
    for k, v in spec.items():
        if not isinstance(v, dict):
            raise ModelError(f"{p}: [{k}] must be a table, not a {type(v).__name__}")
        _check_keys(v, k, str(p))
    return spec


def _target(spec, model, base_dir):
    mo = spec["motion"]
    kind = mo.get("kind", "sine")
    coord = mo.get("coordinate", model.coordinates[0])
    model.coordinate_index(coord)
    if kind == "file":
        f = Path(mo["file"])
        if base_dir is not None and not f.is_absolute():
            f = Path(base_dir) / f
        tr = read_trial(f)
        target = Target("samples", time=tr.time - tr.time[0], values=tr[coord])
    elif kind in ("sine", "cycle"):
        target = Target(kind, amplitude=mo.get("amplitude", 0.0), frequency=mo.get("frequency"),
                        period=mo.get("period"), offset=mo.get("offset", 0.0), phase=mo.get("phase", 0.0))
    else:
        raise ModelError(f"unknown motion kind '{kind}'; valid: sine, cycle, file")
    return coord, target, float(mo.get("duration", target.period))


def _controls(spec, duration):
    pa = dict(spec.get("parametrization", {}))
    design = pa.pop("design", "ff")
    pk = pa.pop("kind", "fourier")
    free_period = bool(pa.pop("free_period", False))
    period_bounds = tuple(pa.pop("period_bounds", (0.5, 2.0)))
    if pk == "nodes":
        return design, NodeControls()
    if pk == "polynomial":
        par = Polynomial(pa.get("order", 6), duration=duration)
    elif pk == "fourier":
        par = Fourier(pa.get("n_harmonics", 5), period=pa.get("period", duration))
    elif pk == "spline":
        par = Spline(pa.get("n_params", 10), duration=duration)
    else:
        raise ModelError(f"unknown parametrization kind '{pk}'; valid: nodes, polynomial, fourier, spline")
    return design, GlobalControls(par, free_period=free_period, period_bounds=period_bounds)


def build_from_task(spec: dict, *, base_dir=None, progress=None, verbose=None) -> Collocation:
    """A :class:`~pinmsk.solvers.ocp.problem.Collocation` from a validated task dict."""
    if "gait" in spec:
        from .gait import build_gait_task
        return build_gait_task(spec, base_dir=base_dir, verbose=verbose)
    ms = spec["model"]
    name = ms["name"]
    if base_dir is not None and str(name).endswith((".toml", ".urdf", ".osim")) and not Path(name).is_absolute():
        name = str(Path(base_dir) / name)
    model = load_model(name, moment_arms=ms.get("moment_arms"))
    scale = float(ms.get("mass_scale", 1.0))
    if scale != 1.0:
        model = scale_masses(model, scale)
    coord, target, duration = _target(spec, model, base_dir)
    design, controls = _controls(spec, duration)
    ob = dict(spec.get("objective", {}))
    tw = ob.pop("tracking_weight", None)
    co = spec.get("constraints", {})
    so = spec.get("solver", {})
    if tw is None and "tracking_tolerance" not in co:
        raise ModelError("task: give [objective] tracking_weight or [constraints] "
                         "tracking_tolerance (the motion must be tracked)")
    kind = ob.get("kind", "effort")
    if kind == "effort":
        phys = Effort(ob.get("exponent", 2), weights=ob.get("weights", "none"),
                      normalize=ob.get("normalize", True))
        extra = set(ob) - {"kind", "exponent", "weights", "normalize"}
    elif kind == "metabolic":
        phys = MetabolicEnergy(ob.get("model", "umberger2003"), normalizer=ob.get("normalizer", 1.0),
                               smooth=ob.get("smooth", so.get("smooth", 0.01)))
        extra = set(ob) - {"kind", "model", "normalizer", "smooth"}
    else:
        raise ModelError(f"task: unknown [objective] kind '{kind}'; valid: effort, metabolic")
    if extra:
        raise ModelError(f"task: [objective] key(s) {sorted(extra)} do not apply to kind '{kind}'")
    if tw is not None:
        if not 0 <= float(tw) <= 1:
            raise ModelError(f"task: [objective] tracking_weight must be in [0, 1], got {tw}")
        cost = (1.0 - float(tw)) * phys + float(tw) * TrackCoordinates(target, coordinate=coord)
    else:
        cost = phys
    cons = [ExcitationBounds(*co.get("excitation_bounds", (0.0, 1.0)))]
    if "tracking_tolerance" in co:
        cons.append(TrackingTolerance(target, co["tracking_tolerance"], coordinate=coord))
    init = co.get("initial_state", "target")
    if init == "target":
        cons.append(InitialState(q={coord: float(target(0.0))}, v={coord: float(target(0.0, 1))}))
    elif init != "free":
        raise ModelError(f"task: [constraints] initial_state must be 'target' or 'free', not {init!r}")
    if "intervals" in so:
        intervals = int(so["intervals"])
    elif "step" in so:
        intervals = max(int(round(duration / float(so["step"]))), 2)
    else:
        intervals = 50
    scheme = so.get("scheme", "hermite-simpson")
    if scheme not in SCHEMES:
        raise ModelError(f"task: [solver] scheme must be one of {', '.join(SCHEMES)}, not {scheme!r}")
    unused = sorted(_NO_EFFECT & set(so))
    if unused:
        print(f"pinmsk: note: [solver] {', '.join(unused)} tuned the replaced engine and have no effect "
              "(exact derivatives, one process)", file=sys.stderr)
    solver = {"max_iter": int(so.get("maxiter", 1000)), "tol": float(so.get("tol", 1e-8)),
              "constraint_tol": float(so.get("constraint_tol", 1e-6))}
    if "hessian" in so:
        solver["hessian"] = so["hessian"]
    return Collocation(model, cost=cost, constraints=cons, duration=duration, intervals=intervals,
                       scheme=scheme, controls=controls, formulation=design, tendon=ms.get("tendon"),
                       n_starts=int(so.get("n_starts", 1)), solver=solver, verbose=verbose)


def scale_masses(model, factor: float):
    """A new model whose segment masses and inertias are scaled by ``factor``."""
    if not factor > 0:
        raise ModelError(f"mass_scale must be > 0, got {factor}")
    pm = pin.Model(model.pin)
    for j in range(1, pm.njoints):
        I = pm.inertias[j]
        pm.inertias[j] = pin.Inertia(I.mass * factor, I.lever, I.inertia * factor)
    return Model(name=model.name, pin_model=pm, muscles=model.muscles, effects=model.effects,
                 contacts=model.contacts, meta=model.meta)

