"""The ``pinmsk`` command line.

Every command has ``--help``.  Errors pinmsk recognises (bad files, unknown
names, infeasible problems) print one line ``pinmsk: error: ...`` on stderr
and exit with status 2, never a traceback.

The CLI is the one place that runs analyses on the user's behalf.  Each command
imports its analysis (Pinocchio, SciPy, matplotlib and meshcat behind it) when
it runs, so ``pinmsk --help`` and argument errors answer in a fraction of a
second (``tests/test_longtrials.py`` holds that); the light modules the parser
and the error handling need are imported here.
"""
from __future__ import annotations

import argparse
import functools
import os
import sys
import warnings
from pathlib import Path

import numpy as np

from ..builtin_models import builtin_names
from ..errors import MissingDependencyError, ModelError, PinmskError, RepairWarning
from ..io.channel_map import read_mapped
from ..io.output_files import check_output_file, output_folder, output_transaction
from ..io.tables import write_trial
from ..signals.filtering import DEFAULT_CUTOFF
from ..trial import moment_channels, parse_ground_reaction
from .progress import Progress


def _model(args):
    """The command's MODEL, after its TRIAL (if it has one) is checked: a trial that cannot be read is
    reported before the model is loaded (an .osim import, its muscle paths' fit, take seconds)."""
    from ..model import load_model
    if getattr(args, "trial", None):
        _check_trial(args)
    return load_model(args.model, moment_arms=getattr(args, "moment_arms", None),
                      nonlinear=getattr(args, "nonlinear", None))


def _check_trial(args) -> None:
    """Read the trial as :func:`_read` will (file, header, columns, ``--map``), without the model: its
    problems raise here; its warnings and notes are left to the real read."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        read_mapped(args.trial, model=None, cmap=getattr(args, "map", None),
                    strict=not getattr(args, "lenient", False), require_coordinates=False, **_units(args))


def _units(args) -> dict:
    """``--time-unit`` and ``--degrees`` as :func:`pinmsk.io.read_trial` takes them."""
    return dict(time_unit=getattr(args, "time_unit", None), in_degrees=True if getattr(args, "degrees", False) else None)


class _EffectFamiliesHelp(argparse.HelpFormatter):
    """Help that ends with the registered effect families (imported only when the help is shown)."""

    def format_help(self):
        import textwrap

        from ..effects import families

        names = textwrap.fill(", ".join(families()), width=76, initial_indent="  ", subsequent_indent="  ")
        return (super().format_help() + "\neffect families (--add FAMILY[:TARGET]; the catalog tries those "
                "that apply):\n" + names + "\n")


def _nonlinear_flag(s) -> None:
    """``--nonlinear`` on a command that takes a MODEL: how an .osim's nonlinear joint axes are imported."""
    s.add_argument("--nonlinear", choices=["exact", "fit"], default=None,
                   help="an .osim MODEL's joint axes that are nonlinear functions of a coordinate (a spline "
                        "knee): 'exact' (default) dependent joints computed from OpenSim's coordinates; 'fit' "
                        "best-fitting fixed-axis joints (their errors are in the import report)")


def _moment_arms_flag(s) -> None:
    """``--moment-arms`` on a command that takes a MODEL whose muscles declare path variants."""
    s.add_argument("--moment-arms", choices=["constant", "angle"], default=None,
                   help="muscle path variant of a model that declares several (the forearm's: 'constant' "
                        "moment arms, Table 3.5, or 'angle', moment arms varying with the joint angle); default: "
                        "the model's default_paths")


def _read(path, model=None, args=None, *, coordinates: bool = True):
    """Read a trial as ``--lenient`` / ``--map`` ask (:func:`pinmsk.io.channel_map.read_mapped`).

    Each repair of a lenient read is one ``pinmsk: warning:`` line, each choice a map made
    one ``pinmsk: note:`` line.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RepairWarning)
        trial = read_mapped(path, model=model, cmap=getattr(args, "map", None),
                            strict=not getattr(args, "lenient", False), require_coordinates=coordinates,
                            **_units(args))
    for w in caught:
        if issubclass(w.category, RepairWarning):
            print(f"pinmsk: warning: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    for note in trial.meta.get("channel_map", {}).get("notes", ()):
        print(f"pinmsk: note: {note}", file=sys.stderr)
    return trial


def _unit_flags(s) -> None:
    """``--degrees`` and ``--time-unit`` on a command that reads a trial."""
    s.add_argument("--degrees", action="store_true",
                   help="the trial's angles are in degrees (a CSV cannot say so; a .sto/.mot's inDegrees is "
                        "overridden): converted to radians on reading")
    s.add_argument("--time-unit", choices=["s", "ms"], default=None,
                   help="unit of the trial's time column (default: the unit in its label, 'Time (ms)', else s)")


def _add_read_flags(s) -> None:
    """``--lenient``, ``--map``, ``--degrees`` and ``--time-unit`` on a command that reads a trial (read by
    :func:`_read`)."""
    _unit_flags(s)
    s.add_argument("--lenient", action="store_true",
                   help="read files whose header row/column counts disagree with the data, or that "
                        "repeat a time stamp; prints one warning per repair")
    s.add_argument("--map", metavar="MAP", default=None,
                   help="rename columns first: a TOML map file ([rename] old = \"new\", optional "
                        "[scale], [offset] keyed by the old or the new name) or a built-in map: opensim-gait2d, "
                        "rajagopal-gait2d, gait10dof-gait2d (docs/tutorials/own_csv.md)")


def _write(trial, path, precision=None):
    write_trial(trial, path, precision=precision)
    print(f"wrote {path}")


def _precision(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or not 1 <= value <= 17:
        raise argparse.ArgumentTypeError(f"expected significant digits from 1 to 17, got {text!r}")
    return value


def _precision_flag(s) -> None:
    """``--precision N`` on a command that writes a trial."""
    s.add_argument("--precision", type=_precision, default=None, metavar="N",
                   help="significant digits written per value (default 9; 17 = exact float64)")


def _progress(total, label, unit=""):
    """A progress line on stderr for a step that may take long (drawn on a terminal only)."""
    return Progress(total, label, unit=unit)


def _inputs(args) -> dict:
    """The trial-preparation options every analysis takes (see :func:`pinmsk.kinematics.prepare`)."""
    return dict(cutoff=args.cutoff, grf=args.grf, external_loads=args.external_loads,
                ground_reaction="ignore" if args.no_grf else "auto",
                grf_cutoff="auto" if args.grf_cutoff is None else args.grf_cutoff,
                missing_coordinates=args.missing_coordinates)


def _named_values(items, model, what) -> np.ndarray:
    out = np.zeros(model.nv)
    for item in items or []:
        if "=" not in item:
            raise PinmskError(f"{what} entries look like COORD=VALUE (radians), got '{item}'")
        name, val = item.split("=", 1)
        try:
            out[model.coordinate_index(name.strip())] = float(val)
        except ValueError:
            raise PinmskError(f"{what}: '{val}' is not a number (in '{item}')") from None
    return out


def _plot(args, trial, channels, stem, ylabel) -> None:
    """``--plot DIR``: PNG figures of ``channels`` over time."""
    if getattr(args, "plot", None):
        from . import plots
        for path in plots.save_channels(trial, channels, args.plot, stem=stem, ylabel=ylabel):
            print(f"wrote {path}")


# -- commands ------------------------------------------------------------------

def cmd_models(args) -> int:
    from ..model import load_model
    from .model_table import models_table
    rows = []
    for name in builtin_names():
        try:
            m = load_model(name)
        except PinmskError as exc:
            rows.append((name, "?", "?", f"unavailable: {exc}"))
            continue
        rows.append((name, m.nv, m.n_muscles, m.meta.get("description", "")))
    print("\n".join(models_table(rows)))
    return 0


def cmd_info(args) -> int:
    m = _model(args)
    print(m.describe())
    return 0


def cmd_import(args) -> int:
    from ..model import import_osim
    from ..opensim.importer import write_import
    fit_over = None
    if args.fit_over:       # read here, so a file's problem is named with the CLI's own strictness
        from ..io.tables import read_trial
        fit_over = read_trial(args.fit_over, strict=not args.lenient, **_units(args))
    # the report is printed
    model, report = import_osim(args.model, nonlinear=args.nonlinear or "exact", fit_over=fit_over)
    files = write_import(model, args.out, name=args.name)
    print(report.format(verbose=args.verbose))
    for what in ("urdf", "sidecar", "markers", "report"):
        print(f"wrote {files[what]}")
    return 0


def cmd_id(args) -> int:
    from ..dynamics import inverse_dynamics_result
    model = _model(args)
    trial = _read(args.trial, model, args)
    with _progress(trial.n_frames, "ID", "frames") as bar:
        res = inverse_dynamics_result(model, trial, **_inputs(args), progress=bar, convention=args.convention)
    print(res.report())
    out = res.trial
    from ..tools.layout import id_table, is_opensim_model
    if is_opensim_model(model):          # OpenSim's ID file: generalized forces only, by motion type
        out = id_table(model, out, keep_meta=True)
    _write(out, args.output, args.precision)
    _plot(args, out, [n for n in moment_channels(model.coordinate_order) if n in out]    # OpenSim's, with a map
          or [n for n in out.names if n.endswith("_moment")], "inverse_dynamics", "moment (N m)")
    return 0


def cmd_ik(args) -> int:
    from ..tools.inverse_kinematics import command
    command(args, _progress)
    return 0


def cmd_muscles(args) -> int:
    from ..solvers.muscle_analysis import muscle_analysis
    model = _model(args)
    trial = _read(args.trial, model, args)
    out = muscle_analysis(model, trial, **_inputs(args))
    _write(out, args.output, args.precision)
    return 0


def cmd_simulate(args) -> int:
    from ..dynamics import simulate
    model = _model(args)
    moments = _read(args.moments, model, args, coordinates=False) if args.moments else None
    if args.duration is None and moments is None:
        raise PinmskError("simulate needs --duration (s) or --moments TRIAL to set the time span")
    if moments is not None and args.duration is None:
        t = np.asarray(moments.time, dtype=float)
    else:
        t0 = 0.0 if moments is None else float(moments.time[0])
        t = t0 + np.arange(int(round(args.duration * args.rate)) + 1) / args.rate
    q0 = _named_values(args.q0, model, "--q0")
    v0 = _named_values(args.v0, model, "--v0")
    out = simulate(model, t=t, q0=q0, v0=v0, moments=moments, method=args.method)
    _write(out, args.output, args.precision)
    _plot(args, out, list(model.coordinate_order), "simulation", "coordinate (rad or m)")
    return 0


def cmd_demo(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from ..demo import demo
    demo(out)
    return 0


def _so_options(args) -> dict:
    return dict(mode=args.mode, exponent=args.exponent, weights=args.weights,
                reserves=args.reserves)


def _report_results(args, model, trial, result, title, text):
    figures = None
    if args.plot:
        from . import plots
        figures = plots.save_results_figures(result, args.plot, trial=trial, coordinates=model.coordinates)
        for path in figures.values():
            print(f"wrote {path}")
    if args.report:
        from .report import write_results_report
        # the report embeds the PNGs just written instead of drawing the figures again
        write_results_report(args.report, model=model, trial=trial, results=result,
                             title=title.replace("_", " "), text=text, figures=figures)
        print(f"wrote {args.report}")


def _run_solver(args, solver, total: int | None, label: str, title: str, *, opensim_files: bool = False) -> int:
    """Fit a muscle-redundancy solver on the trial with a progress bar, then write and report
    (``opensim_files``: a model from OpenSim gets OpenSim's activation and force files)."""
    model = _model(args)
    trial = _read(args.trial, model, args)
    # FSO evaluates the paths at every integration step, one frame at a time: there the surrogates,
    # checked against the exact paths at the trial's frames (the exact paths cost minutes per trial)
    model = _analysis_paths(args, model, trial, surrogate=label == "FSO")
    kw = _inputs(args)
    if getattr(args, "moments", None):
        kw["moments"] = args.moments
    with _progress(trial.n_frames if total is None else total, label,
                   "frames" if total is None else "steps") as bar:
        solver.fit(model, trial, progress=bar, **kw)
    text = solver.report()
    print(text)
    from ..tools.layout import is_opensim_model, so_paths, so_tables
    if opensim_files and is_opensim_model(model):
        tables = so_tables(model, solver.result_, [a.name for a in solver.actuators_])
        for path, table in zip(so_paths(args.output), tables):
            if getattr(args, "_paths_line", None):
                table = table.with_meta(paths=args._paths_line)
            _write(table, path, args.precision)
    else:
        result = solver.result_
        if getattr(args, "_paths_line", None):
            result = result.with_meta(paths=args._paths_line)          # in the output's header
        _write(result, args.output, args.precision)
    _report_results(args, model, trial, solver.result_, title, text)
    return 0


def _analysis_paths(args, model, trial, *, surrogate: bool = False):
    """The model with the paths ``--surrogate-paths`` / ``--path-tolerance`` ask for
    (:func:`pinmsk.opensim.path_check.choose_paths`); the choice is printed as one header line."""
    from ..opensim.muscle_import import geometric_paths
    from ..opensim.path_check import choose_paths
    if getattr(model, "muscles", None) is None or geometric_paths(model.meta.get("import_report")) is None:
        return model            # a model with only its own paths runs on them
    q = np.column_stack([np.asarray(trial[c], dtype=float) if c in trial else
                         np.zeros(trial.n_frames) for c in model.coordinates])
    model, line = choose_paths(model, q, surrogate=surrogate or getattr(args, "surrogate_paths", False),
                               exact_hint="" if surrogate else "or use the exact paths (leave out --surrogate-paths)",
                               tolerance=1e-3 * getattr(args, "path_tolerance", 1.0))
    print(line)
    args._paths_line = line
    return model


def cmd_so(args) -> int:
    from ..solvers.static import StaticOptimization
    dofs = [d.strip() for d in args.dofs.split(",") if d.strip()] if args.dofs else None
    so = StaticOptimization(**_so_options(args), minmax=args.minmax, dofs=dofs, actuators=args.actuators,
                            convention=args.convention)
    return _run_solver(args, so, None, "SO", "static_optimization", opensim_files=True)


def cmd_fso(args) -> int:
    from ..solvers.fso import ForwardStaticOptimization
    fso = ForwardStaticOptimization(**_so_options(args), tracking=args.tracking, enforce=args.enforce,
                                    control_points=args.control_points, integrator=args.integrator,
                                    allow_divergence=args.allow_divergence)
    return _run_solver(args, fso, args.control_points, "FSO", "forward_static_optimization")


def _folds(text: str) -> int:
    """``--folds N``: a whole number of cross-validation blocks, 2 or more."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a whole number of blocks (2 or more), got '{text}'") from None
    if n < 2:
        raise argparse.ArgumentTypeError(f"cross-validation needs 2 blocks or more, got {n}")
    return n
def _check_saves(args) -> None:
    """``--save-model`` / ``--save-osim`` paths of the diagnosis, refused before any work if they cannot be."""
    from ..opensim.export import check_model_path, check_osim_path
    if getattr(args, "save_model", None):
        check_model_path(args.save_model)
    if getattr(args, "save_osim", None):
        check_osim_path(args.save_osim)
        mp = Path(str(args.model))
        named = False
        if mp.suffix.lower() == ".toml" and mp.is_file():      # a sidecar written from an .osim names it
            from ..io.toml_files import read_toml
            named = bool(read_toml(mp, what="model sidecar").get("model", {}).get("osim"))
        if mp.suffix.lower() != ".osim" and not named:
            raise PinmskError(f"--save-osim writes a copy of an OpenSim model; MODEL {args.model} is not an .osim "
                              "(nor a sidecar imported from one); save it with --save-model OUT.toml")


def _save_corrected(args, model) -> None:
    """Write the diagnosed model with its added effects: ``--save-model`` (sidecar) and ``--save-osim``."""
    from ..opensim.export import write_model, write_osim
    if getattr(args, "save_model", None):
        files = write_model(model, args.save_model)
        for what in ("sidecar", "urdf", "markers", "report"):
            if what in files:
                print(f"wrote {files[what]}")
    if getattr(args, "save_osim", None):
        res = write_osim(model, args.save_osim)
        for line in res.lines():
            print(line, file=sys.stderr if line.startswith("pinmsk: warning") else sys.stdout)


def cmd_diagnose(args) -> int:
    from ..diagnose import run
    if getattr(args, "noise", None):                 # stated noise levels, for every diagnosis of the loop
        from ..diagnose.noise import parse_noise
        run = functools.partial(run, noise=parse_noise(args.noise))
    from .report import save_diagnosis
    _check_saves(args)
    model = _model(args)
    for label in args.without or ():
        model = model.without(label)        # a component left out on request (e.g. contacts vs measured GRF)
    trial = _read(args.trial, model, args)
    kw = _inputs(args)
    if kw.pop("ground_reaction") == "ignore":
        trial = trial.drop([n for n in trial.names if parse_ground_reaction(n) is not None])
    loop = {k: v for k, v in (("folds", args.folds), ("window", args.window)) if v is not None}
    r = run(model, trial, add=args.add or [], remove=args.remove or [], mode=args.mode,
            frames=args.frame or None, **loop, **kw)
    save_diagnosis(r, json_path=args.json, report_path=args.report, plot_dir=args.plot)
    print(r.summary_text())
    for path in (args.json, args.report):
        if path:
            print(f"wrote {path}")
    _save_corrected(args, r.model)
    return 0


def cmd_synth(args) -> int:
    from ..diagnose.synth import make_trial
    trial = make_trial(args.model, args.effect or [], duration=args.duration, rate=args.rate,
                       noise=None if args.no_noise else "realistic", seed=args.seed,
                       measure=args.measure or None)
    _write(trial, args.output, args.precision)
    return 0


def cmd_contact_fit(args) -> int:
    from ..contact.identify import settings_lines
    from ..pipeline import contact_fit_task
    opts = {}   # only what the user gave: the rest are ContactFit's defaults (printed below)
    if args.contact:
        opts["contact"] = args.contact
    if args.relax:
        opts["relax"] = True
    if args.starts is not None:
        opts["n_starts"] = args.starts
    if args.terms:
        opts["terms"] = tuple(args.terms)
    if args.toe:
        opts["toe"] = args.toe
    if args.cutoff is not None:
        opts["cutoff"] = args.cutoff or None
    if args.ground_speed is not None:
        opts["ground_speed"] = args.ground_speed
    trial = args.trial
    if args.degrees or args.time_unit:        # a .csv/.sto/.mot in other units (a CSU text file has its own)
        from ..io.tables import read_trial
        trial = read_trial(args.trial, **_units(args))
    out = contact_fit_task(args.model, trial, json_path=args.json, plot_dir=args.plot, **opts)
    print("\n".join(settings_lines(out["settings"])))
    for k, (label, j) in enumerate(zip(out["start_labels"], out["starts"])):
        print(f"  start {k + 1}, {label}: J {j:.5g}{' (best)' if k == out['best_start'] else ''}")
    rm, tm = out["rmse"], out["terms"]
    print(f"{out['contact']}{' (relaxed centres)' if out['relax'] else ''} contact fitted in {out['seconds']:.1f} s: "
          f"objective (Eq. 4.2) {out['objective']:.4g} (normal {tm['normal_force']:.4g}, friction "
          f"{tm['friction_force']:.4g}, COP {tm['cop']:.4g})")
    print(f"  rmse: normal force {rm['normal_force']:.4g} N, friction force {rm['friction_force']:.4g} N, "
          f"COP {1000 * rm['cop']:.3g} mm")
    for site, params in out["params"].items():
        print(f"  {site}: " + ", ".join(f"{k} = {v:.4g}" for k, v in params.items()))
    for path in [args.json, *out.get("figures", [])]:
        if path:
            print(f"wrote {path}")
    return 0


_OPTIMIZE_EPILOG = (
    "Direct collocation (Hermite-Simpson or trapezoidal) solved by IPOPT with exact derivatives (CasADi).\n"
    "[parametrization] design: 'ff' excitations ([model] tendon = 'rigid' | 'compliant'), 'ifm'\n"
    "  muscle-tendon forces, 'ift' joint torques; kind: 'nodes' | 'polynomial' | 'fourier' | 'spline';\n"
    "  free_period = true frees the Fourier period.\n"
    "Every key of every section: pinmsk.solvers.ocp.tasks.TASK_SCHEMA (unknown keys are errors).\n"
    "A problem that does not converge exits with status 2 and writes nothing; with --keep-unconverged it\n"
    "  writes the last iterate (\"converged\": false in OUT.json) and still exits with status 2.\n"
    "Progress: one line per IPOPT solve stage on stderr (live on a terminal), then a summary line.\n"
    "A [gait] task with --report OUT.html also writes the gait validation report of the solved stride.\n"
    "Examples: data/tasks/*.toml")


def _check_gait_report(args) -> None:
    """``--report``: refused by name, before the solve, for a task without ``[gait]`` or without matplotlib."""
    from ..solvers.ocp.tasks import load_task
    if "gait" not in load_task(args.task):
        raise ModelError(f"--report: {args.task} has no [gait] table; the HTML report validates a gait "
                         "(use --plot DIR for the figures of other tasks)")
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise MissingDependencyError("--report needs matplotlib for its figures (pip install matplotlib); "
                                     "nothing solved or written") from None


def cmd_optimize(args) -> int:
    from ..pipeline import optimize_task
    if args.report:
        _check_gait_report(args)
    from .solve_progress import SolveProgress, summary_line
    if args.keep_unconverged and not args.output:
        raise PinmskError("--keep-unconverged writes the last iterate to -o OUT: give -o; nothing was run")
    # the live line only without IPOPT's own log on the terminal (both would interleave)
    progress = SolveProgress(live=False if args.verbose else None)
    res = optimize_task(args.task, args.output, precision=args.precision, monitor=progress,
                        verbose=args.verbose, solver_log=args.solver_log, max_iter=args.max_iter,
                        keep_unconverged=args.keep_unconverged)
    if not res.converged:      # --keep-unconverged: written, flagged, and not a solution (status 2)
        print(f"pinmsk: error: {args.task}: the optimizer did not converge ({res.status}); the last iterate "
              f"was written to {args.output} and {args.output}.json (converged=false)", file=sys.stderr)
        return 2
    print(res.report())
    print(summary_line(res.summary))
    if args.report:
        # the stride just solved (the Result written to OUT.sto: its info carries the JSON's speed,
        # cost of transport and body weight) against Winter's Table A.1, the measured walk and the
        # published bands (gait_validation.validate_gait; references absent from the data are noted)
        from ..gait_validation import validate_gait
        validate_gait(res, label=Path(args.task).stem).write_report(args.report, title=f"pinmsk optimize {args.task}")
        print(f"wrote {args.report}")
    _plot(args, res, [n for n in res.names if n.endswith(("_excitation", "_activation"))],
          "optimize_controls", "excitation / activation")
    _plot(args, res, [n for n in res.names if n.endswith("_desired")]
          + [n[: -len("_desired")] for n in res.names if n.endswith("_desired")],
          "optimize_motion", "coordinate (rad)")
    if args.output:
        print(f"wrote {args.output} and {args.output}.json")
    return 0


def cmd_view(args) -> int:
    from .viewer import view_cli
    model = _model(args)          # loaded once (an .osim import is not quick)
    trial = _read(args.trial, model, args) if args.trial else None
    view_cli(model, trial, args.results, open_browser=args.open,
             block=not args.no_block, timeout=args.timeout)
    return 0


def cmd_run(args) -> int:
    from ..tools import run_setup
    for path in run_setup(args.setup, results_dir=args.results_dir):
        print(f"wrote {path}")
    return 0


def cmd_scale(args) -> int:
    from ..tools.scale import scale_subject
    written = scale_subject(args.model, args.static, mass=args.mass, output=args.output,
                            measurements=args.setup_measurements, marker_set=args.marker_set,
                            time_range=args.time, place=args.place_markers, report=print)
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_batch(args) -> int:
    from ..pipeline import batch_cli
    if Path(args.config).is_dir():
        from ..subjects import batch_folder
        summary = batch_folder(args.config, scheduler=args.scheduler, jobs=args.jobs, force=args.force,
                               shard=args.shard)
        n = len(summary["rows"])
        shard = f" (shard {summary['shard'][0]}/{summary['shard'][1]})" if summary["shard"] else ""
        print(f"{n - len(summary['failed'])}/{n} subjects done{shard}; table {summary['table']}")
        if summary["ignored"]:
            print(f"  not subjects (no static .trc): {', '.join(summary['ignored'])}", file=sys.stderr)
        return 1 if summary["failed"] else 0
    summary = batch_cli(args.config, scheduler=args.scheduler, jobs=args.jobs, force=args.force,
                        shard=args.shard)
    n = len(summary["rows"])
    shard = f" (shard {summary['shard'][0]}/{summary['shard'][1]})" if summary["shard"] else ""
    print(f"{n - len(summary['failed'])}/{n} trials done{shard}, {len(summary['skipped'])} skipped "
          f"(done before: same inputs and options); summary table {summary['table']}, "
          f"report {summary['report']}")
    for name in summary["failed"]:
        reason = summary.get("reasons", {}).get(name, "failed").removeprefix("failed: ")
        print(f"  failed: {name}: {reason}", file=sys.stderr)
    return 1 if summary["failed"] else 0


# -- parser ----------------------------------------------------------------------

def _version() -> str:
    """The installed distribution's version, or the package's own when not installed."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("pinmsk")
    except PackageNotFoundError:
        from .. import __version__
        return __version__


class _VersionAction(argparse.Action):
    """``--version``: looks the version up only when asked (importlib.metadata is not free)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"pinmsk {_version()}")
        parser.exit()


def input_flags(s) -> None:
    """The flags of every command that analyses a trial: filter and external loads."""
    s.add_argument("--cutoff", type=float, default=DEFAULT_CUTOFF, metavar="HZ",
                   help=f"zero-lag Butterworth low-pass (Hz) of the coordinates and the GRF before "
                        f"differentiating (default {DEFAULT_CUTOFF:g}; 0 = no filter, right for noise-free "
                        "synthetic data)")
    s.add_argument("--grf-cutoff", type=float, default=None, metavar="HZ",
                   help="low-pass of the GRF (default: the same as --cutoff, which avoids artificial residual "
                        "peaks; with --external-loads, OpenSim's convention: unfiltered, as its ID tool "
                        "applies them; 0 = unfiltered)")
    s.add_argument("--grf", metavar="FILE", default=None,
                   help="ground reaction forces at their own rate (.mot/.sto/.csv with [side_]ground_force_v[xyz], "
                        "_p[xyz], ground_torque_[xyz]); default: the trial's own GRF channels")
    s.add_argument("--external-loads", metavar="XML", default=None,
                   help="an OpenSim ExternalLoads .xml: which columns act on which body (reads its datafile "
                        "unless --grf or the trial gives the data)")
    s.add_argument("--no-grf", action="store_true",
                   help="leave the ground reaction forces out on purpose (recorded in the output)")
    # pinmsk.kinematics.MISSING_COORDINATE_MODES, spelled out: importing kinematics here would load Pinocchio
    # for `pinmsk --help` (tests/test_osim_id.py checks that the two agree)
    s.add_argument("--missing-coordinates", choices=("refuse", "default"), default="refuse",
                   help="an imported .osim model's coordinate the trial leaves out (not locked, not set by a "
                        "coupler): refuse it by name (default), or hold it at its default value as OpenSim's ID "
                        "tool does (noted in the output)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pinmsk", description="Human musculoskeletal dynamics on Pinocchio.")
    p.add_argument("--version", action=_VersionAction, help="print the version (pinmsk X.Y.Z) and exit")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    s = sub.add_parser("models", help="list the built-in models with dof and muscle counts")
    s.set_defaults(func=cmd_models)

    s = sub.add_parser("info", help="describe a model (built-in name or path to .toml/.urdf/.osim)")
    s.add_argument("model")
    _moment_arms_flag(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("import", help="an OpenSim .osim model as URDF + TOML sidecar, with the import report",
                       description="Write MODEL.osim as <name>.urdf, <name>.toml (the sidecar pinmsk.load_model "
                                   "reads), <name>_markers.toml and <name>_import_report.txt in OUT, and print "
                                   "the report: what became what, and each approximation with its measured "
                                   "error over the coordinate ranges.")
    s.add_argument("model", metavar="MODEL.osim")
    s.add_argument("-o", "--out", required=True, metavar="DIR", help="folder for the files (created)")
    s.add_argument("--name", default=None, help="file stem (default: the .osim's)")
    s.add_argument("--verbose", action="store_true", help="also list what was imported exactly")
    s.add_argument("--fit-over", metavar="TRIAL", default=None,
                   help="fit the muscle paths' polynomials over this motion's coordinate ranges (+-10 degrees, as "
                        "OpenSim's PolynomialPathFitter) instead of the coordinates' whole ranges: an IK .mot or a "
                        "states/coordinates .sto")
    s.add_argument("--lenient", action="store_true",
                   help="read a --fit-over file whose header row/column counts disagree with the data")
    _unit_flags(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_import)

    s = sub.add_parser("id", help="inverse dynamics of a trial: <coord>_moment channels")
    s.add_argument("model")
    s.add_argument("trial", help="trial file (.csv with a time column, .sto or .mot)")
    s.add_argument("-o", "--output", required=True,
                   help="output .sto or .csv (an OpenSim model's as OpenSim's ID tool writes it: the "
                        "generalized forces only, <coord>_moment and <coord>_force for translations)")
    _precision_flag(s)
    input_flags(s)
    _moment_arms_flag(s)
    s.add_argument("--convention", choices=["pinmsk", "opensim"], default="pinmsk",
                   help="FreeJoint/BallJoint rotations: 'pinmsk' differentiates the Euler angles (physically "
                        "consistent, default); 'opensim' reproduces OpenSim's InverseDynamicsTool, which reads "
                        "the angles' rates as angular velocity")
    s.add_argument("--plot", metavar="DIR", default=None, help="write PNG figures to DIR")
    _add_read_flags(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_id)

    s = sub.add_parser("ik", help="inverse kinematics from a marker file, as OpenSim's IK tool: a .mot of coordinates",
                       description="Solve the model's coordinates frame by frame from measured markers (OpenSim's "
                                   "IK problem: weighted marker and coordinate tasks) and write the .mot and "
                                   "the marker errors (.sto) as OpenSim's InverseKinematicsTool writes them.")
    s.add_argument("model", help="built-in name, .toml or .osim (exact import)")
    s.add_argument("trc", metavar="TRC", help="marker file (.trc)")
    s.add_argument("-o", "--output", required=True, help="output motion (.mot)")
    s.add_argument("--tasks", metavar="TASKS.xml", default=None,
                   help="an OpenSim IK task set (IKMarkerTask / IKCoordinateTask weights); default: every "
                        "model marker in the file, weight 1")
    s.add_argument("--coordinates", metavar="FILE", default=None,
                   help="coordinate file (.mot/.sto) giving the targets of from_file coordinate tasks")
    s.add_argument("--time", nargs=2, type=float, metavar=("START", "END"), default=None,
                   help="time range (s); default: the whole file")
    s.add_argument("--marker-errors", metavar="FILE", default=None,
                   help="marker error file (default: <output stem>_ik_marker_errors.sto beside the output)")
    _precision_flag(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_ik)

    s = sub.add_parser("muscles", help="muscle analysis of a trial: <muscle>_length, _fiber_length, "
                                       "_moment_arm_<coord> channels")
    s.add_argument("model")
    s.add_argument("trial", help="trial file (.csv with a time column, .sto or .mot)")
    s.add_argument("-o", "--output", required=True, help="output .sto or .csv")
    _precision_flag(s)
    input_flags(s)
    _add_read_flags(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_muscles)

    s = sub.add_parser("simulate", help="forward dynamics driven by <coord>_moment channels (or none)")
    s.add_argument("model")
    s.add_argument("--moments", metavar="TRIAL", default=None,
                   help="trial with <coord>_moment channels driving the model")
    s.add_argument("--duration", type=float, default=None, help="seconds (default: the moments trial)")
    s.add_argument("--rate", type=float, default=1000.0, help="output sample rate in Hz (default 1000)")
    s.add_argument("--q0", nargs="*", metavar="COORD=RAD", help="initial coordinates (default 0)")
    s.add_argument("--v0", nargs="*", metavar="COORD=RAD_S", help="initial speeds (default 0)")
    s.add_argument("--method", default="rk4", help="rk4 (fixed step) or a solve_ivp method, e.g. RK45")
    s.add_argument("-o", "--output", required=True, help="output .sto or .csv")
    _precision_flag(s)
    s.add_argument("--plot", metavar="DIR", default=None, help="write PNG figures to DIR")
    _add_read_flags(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("demo", help="the diagnosis loop on a shipped forearm trial with a hidden effect")
    s.add_argument("--out", default="pinmsk-demo", help="folder for figures and the report (default ./pinmsk-demo)")
    s.set_defaults(func=cmd_demo)

    def so_flags(s):
        s.add_argument("model")
        s.add_argument("trial", help="trial with the coordinates (and optionally <coord>_moment)")
        s.add_argument("--surrogate-paths", action="store_true",
                       help="an imported model's polynomial path surrogates instead of its exact paths (fso: always), "
                            "checked against the exact paths at the trial's frames (docs/paths.md)")
        s.add_argument("--path-tolerance", type=float, default=1.0, metavar="MM",
                       help="largest surrogate error (mm, length or moment arm) --surrogate-paths accepts "
                            "(default 1)")
        s.add_argument("-o", "--output", required=True, help="output .sto or .csv")
        _precision_flag(s)
        s.add_argument("--mode", choices=["force", "activation"], default="force",
                       help="unknowns: muscle forces (0..F_max) or activations (F = a F_active + F_passive)")
        s.add_argument("--exponent", type=float, default=2.0, help="P in sum (F/N)^P (1 = LP, 2 = QP, >2 SQP)")
        s.add_argument("--weights", choices=["none", "fmax", "pcsa", "volume"], default="none",
                       help="normaliser N_i of each muscle (thesis Eq. 2.11-2.14)")
        s.add_argument("--reserves", action="store_true",
                       help="ideal reserve actuators per dof at high cost instead of failing on infeasible frames; "
                            "coordinates no muscle spans (a floating base) get reserves equal to the force they need")
        _moment_arms_flag(s)
        input_flags(s)
        s.add_argument("--plot", metavar="DIR", default=None, help="write PNG figures to DIR")
        s.add_argument("--report", metavar="OUT.html", default=None, help="write a self-contained HTML report")
        _add_read_flags(s)
        _nonlinear_flag(s)

    s = sub.add_parser("so", help="static optimization: muscle forces and activations frame by frame "
                                  "(an OpenSim model's in OpenSim's two files, OUT_activation and OUT_force)")
    so_flags(s)
    s.add_argument("--minmax", action="store_true", help="min/max criterion (thesis Eq. 2.13) as an epigraph LP")
    s.add_argument("--moments", choices=["id", "measured"], default="id",
                   help="moments to balance: 'id' inverse dynamics with the trial's GRF (default) or "
                        "'measured', the trial's own <coord>_moment channels")
    s.add_argument("--dofs", metavar="COORD,COORD", default=None,
                   help="balance only these coordinates (default: every coordinate a muscle spans; the "
                        "others must need no force, or --reserves)")
    s.add_argument("--actuators", metavar="FILE.xml", default=None,
                   help="an OpenSim force set file of reserve and residual actuators (CoordinateActuator, "
                        "PointActuator, TorqueActuator) sharing the moments with the muscles, besides the model's "
                        "own; each costs |control|^P and gets <name>_control and <name>_force channels")
    s.add_argument("--convention", choices=["pinmsk", "opensim"], default="pinmsk",
                   help="muscle model: pinmsk's (passive forces included, default) or OpenSim's "
                        "StaticOptimization (F = a F_opt without passive force, activations within the muscles' "
                        "min/max controls), for like-for-like comparisons")
    s.set_defaults(func=cmd_so)

    s = sub.add_parser("fso", help="forward static optimization: track a motion forward in time (thesis Sec. 3.4)")
    so_flags(s)
    s.add_argument("--tracking", choices=["q", "qv", "qva", "pid"], default="pid",
                   help="tracking term: Eq. 3.16 (q), 3.17 (qv), 3.18 (qva) or the PID form 3.19")
    s.add_argument("--enforce", choices=["constraint", "cost"], default="constraint",
                   help="tracking as a QP constraint or as a weighted cost term (Eq. 3.15)")
    s.add_argument("--control-points", type=int, default=None,
                   help="number of control points (default 100, more if the PID loop needs them to be stable)")
    s.add_argument("--integrator", default="rk4", help="rk4 (fixed step) or a solve_ivp method such as RK45")
    s.add_argument("--allow-divergence", action="store_true",
                   help="write the result even if the tracking error exceeds 1 deg (flagged: 'diverged' channel)")
    s.set_defaults(func=cmd_fso)

    s = sub.add_parser("diagnose", help="where the model fails and which physical effect is missing",
                       formatter_class=_EffectFamiliesHelp)
    s.add_argument("model")
    s.add_argument("trial", help="measured trial: coordinates plus <coord>_moment, EMG/excitations or GRF")
    s.add_argument("--add", action="append", metavar="EFFECT[:TARGET[:NAME=VALUE,...]]",
                   help="fit this effect jointly with the ones added before (their values move), add it, then "
                        "diagnose again (repeat to iterate; the output prints what the refit changed); "
                        "NAME=VALUE holds that parameter at the value")
    s.add_argument("--remove", action="append", metavar="LABEL",
                   help="after the adds, drop this effect from the model (e.g. one the diagnosis names as no "
                        "longer significant), refit the others jointly and diagnose again (repeatable)")
    s.add_argument("--folds", type=_folds, default=None, metavar="N",
                   help="cross-validation blocks (default 5, fewer on a trial too short for blocks of 20 "
                        "samples; the choice is printed with the ranking)")
    s.add_argument("--window", type=float, default=None, metavar="S",
                   help="length in s of the worst time windows reported (default 1, shorter on a short trial)")
    s.add_argument("--json", metavar="OUT.json", default=None, help="write the summary as JSON")
    s.add_argument("--report", metavar="OUT.html", default=None, help="write a self-contained HTML report")
    s.add_argument("--plot", metavar="DIR", default=None, help="write PNG figures to DIR")
    s.add_argument("--save-model", metavar="OUT.toml", default=None,
                   help="write the model with the added effects (their fitted values) as a sidecar that "
                        "`pinmsk id OUT.toml ...` runs on (an imported .osim: URDF + sidecar with its coordinate map)")
    s.add_argument("--save-osim", metavar="OUT.osim", default=None,
                   help="an .osim MODEL: write a copy of it with the adjusted masses and centres of mass and the "
                        "added effects as OpenSim forces where one exists (the rest are listed)")
    s.add_argument("--mode", default="auto", choices=["auto", "torque", "motion", "muscle", "contact"],
                   help="comparison level (default: chosen from the trial's channels)")
    input_flags(s)
    s.add_argument("--frame", action="append", metavar="FRAME",
                   help="frames to try frame effects (e.g. a payload) at, besides the defaults")
    s.add_argument("--without", action="append", metavar="LABEL",
                   help="leave this component of the model out (repeatable; e.g. the contact spheres when the "
                        "trial's measured GRF loads the feet); `pinmsk info MODEL` lists the labels")
    _moment_arms_flag(s)
    s.add_argument("--noise", action="append", metavar="NAME=SIGMA",
                   help="a noise level you know, in place of the one fitted to the data: a measured channel "
                        "(pelvis_tx=0.5mm, knee_angle_r=0.2deg, elbow_flexion_moment=0.2) or a group (angles, "
                        "translations, moments, ground_reaction, excitations); white noise of that RMS, "
                        "SI units unless deg/mm is given (repeat for several)")
    _add_read_flags(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_diagnose)

    s = sub.add_parser("synth", help="write a synthetic trial of a model with hidden effects and noise")
    s.add_argument("model")
    s.add_argument("--effect", action="append", metavar="FAMILY:TARGET:P=V[,P=V]",
                   help="hidden effect, e.g. payload:hand:mass=1.0 (repeatable)")
    s.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    s.add_argument("--rate", type=float, default=100.0, help="Hz (default 100)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--measure", action="append", choices=["moments", "excitations", "grf"],
                   help="channel groups to record (default: by model)")
    s.add_argument("--no-noise", action="store_true", help="noise-free channels")
    s.add_argument("-o", "--output", required=True, help="output .csv or .sto")
    _precision_flag(s)
    s.set_defaults(func=cmd_synth)

    s = sub.add_parser("contact", help="foot-ground contact models (thesis Ch. 4)")
    csub = s.add_subparsers(dest="contact_command", metavar="SUBCOMMAND")
    csub.required = True
    c = csub.add_parser("fit", help="identify contact parameters against measured GRF and COP (Eq. 4.2)")
    c.add_argument("model", help="model with heel/metatarsal/toe sites, e.g. foot2d")
    c.add_argument("trial", help="trial with foot kinematics and GRF (.csv/.sto/.mot or the CSU leg2d text)")
    c.add_argument("--contact", choices=["point", "volumetric", "hypervolumetric"], default=None,
                   help="contact model (default hypervolumetric)")
    c.add_argument("--relax", action="store_true", help="also fit the sphere centres (dx, dy; Sec. 4.1.4)")
    c.add_argument("--starts", type=int, default=None,
                   help="starting points: the thesis values, the contained models' optima, then random (default 4)")
    c.add_argument("--terms", nargs="+", choices=["normal_force", "friction_force", "cop"], default=None,
                   help="Eq. 4.2 terms minimised (default all three, for every model)")
    c.add_argument("--toe", choices=["kinematic", "fit", "flat", "channel"], default=None,
                   help="toe angle: from the kinematics, held fixed (default); fitted; legacy flat; the mtp channel")
    c.add_argument("--cutoff", type=float, default=None, metavar="HZ",
                   help="low-pass of the driving kinematics (default 12 Hz; 0 = none)")
    c.add_argument("--ground-speed", type=float, default=None, metavar="M/S",
                   help="belt speed of a treadmill trial (m/s, along x); default the trial's own "
                        "(a CSU file measures it), else 0 (overground)")
    c.add_argument("--json", metavar="OUT.json", default=None,
                   help="write objective, params, rmse and seconds as JSON")
    c.add_argument("--plot", metavar="DIR", default=None, help="write GRF and COP figures (PNG) to DIR")
    _unit_flags(c)
    c.set_defaults(func=cmd_contact_fit)

    s = sub.add_parser(
        "optimize", help="dynamic optimization from a task file (model, motion, "
                         "parametrization, objective, constraints)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Optimal control by direct collocation with exact derivatives (thesis Ch. 3, 5.1).",
        epilog=_OPTIMIZE_EPILOG)
    s.add_argument("task", help="TOML task file, or the name of a shipped one (gait2d_predictive, "
                                "forearm_ift_j1, ...: data/tasks/)")
    s.add_argument("-o", "--output", default=None, help="result trial (.sto/.csv), plus OUT.json")
    _precision_flag(s)
    s.add_argument("--plot", metavar="DIR", default=None, help="write PNG figures to DIR")
    s.add_argument("--report", metavar="OUT.html", default=None,
                   help="[gait] tasks: write the validation report (joint angles vs Winter and the measured "
                        "walk, GRF double hump, activations vs EMG, published bands; needs matplotlib)")
    s.add_argument("--solver-log", metavar="FILE", default=None,
                   help="write IPOPT's own iteration log of every solve stage to FILE (replaced)")
    s.add_argument("--verbose", action="store_true",
                   help="print IPOPT's own log on stdout (default: none; a terminal shows one live progress "
                        "line per stage on stderr, a pipe one line per stage at its end)")
    s.add_argument("--max-iter", metavar="N", type=int, default=None,
                   help="IPOPT's iteration limit of each stage (default: the task's [solver] maxiter)")
    s.add_argument("--keep-unconverged", action="store_true",
                   help="if IPOPT does not converge, still write the last iterate to -o OUT and OUT.json, "
                        "flagged \"converged\": false (e.g. a gait task's next guess); the exit status stays 2")
    s.set_defaults(func=cmd_optimize)

    s = sub.add_parser("view", help="meshcat viewer: the model, optionally playing a trial with results")
    s.add_argument("model")
    s.add_argument("trial", nargs="?", default=None, help="motion to play (coordinates over time)")
    s.add_argument("--results", default=None,
                   help="results on the same time base: <muscle>_activation/_force, <coord>_residual, GRF")
    s.add_argument("--open", action="store_true", help="open a browser tab (if a display exists)")
    s.add_argument("--no-block", action="store_true", help="return at once instead of serving until Ctrl-C")
    s.add_argument("--timeout", type=float, default=None, help="serve for this many seconds, then stop")
    _add_read_flags(s)
    _nonlinear_flag(s)
    s.set_defaults(func=cmd_view)

    s = sub.add_parser("run", help="run an OpenSim setup file (InverseDynamicsTool, AnalyzeTool, ...): "
                                   "results as OpenSim writes them")
    s.add_argument("setup", help="OpenSim setup .xml (its paths resolve against its folder)")
    s.add_argument("--results-dir", metavar="DIR", default=None,
                   help="write the results in DIR instead of the setup's <results_directory>")
    s.set_defaults(func=cmd_run)

    s = sub.add_parser(
        "scale", help="scale an OpenSim model to a subject from a static trial, as OpenSim's ScaleTool",
        description="Scale MODEL (.osim) to the subject of STATIC (.trc) and --mass: writes OUTPUT and "
                    "<OUTPUT stem>_scale_set.xml (OpenSim's formats).  With --setup-measurements, the "
                    "measurements of that file (a <MeasurementSet> or a ScaleTool setup) scale the bodies they "
                    "name; without it, each body carrying two or more markers found in STATIC is scaled "
                    "uniformly by the mean ratio of its own marker pairs' distances (trial / model default "
                    "pose), and every other body by the mean of those factors.  Masses keep their "
                    "distribution and sum to --mass.")
    s.add_argument("model", help="the generic OpenSim model (.osim, OpenSim 4 format)")
    s.add_argument("static", help="the static trial (.trc)")
    s.add_argument("--mass", type=float, required=True, help="the subject's mass (kg)")
    s.add_argument("-o", "--output", required=True, help="the scaled model (.osim)")
    s.add_argument("--setup-measurements", default=None, metavar="MEASUREMENTS.xml",
                   help="a measurement set file, or a ScaleTool setup whose measurement set is used")
    s.add_argument("--marker-set", default=None, metavar="MARKERS.xml",
                   help="an OpenSim marker set merged into the model first (markers of the same name replaced)")
    s.add_argument("--time", type=float, nargs=2, default=None, metavar=("START", "END"),
                   help="the time range averaged (s; default: the whole trial)")
    s.add_argument("--place-markers", action="store_true",
                   help="also solve the static pose and move the model's free markers onto the trial (all "
                        "weights 1); writes <OUTPUT stem>_static_pose.mot")
    s.set_defaults(func=cmd_scale)

    s = sub.add_parser("batch", help="run IK -> ID -> SO -> report over the trials of a config file "
                                           "(or of each subject of a folder)")
    s.add_argument("config", metavar="CONFIG|FOLDER",
                   help="TOML config listing trials (see pinmsk.pipeline), or a folder of subject folders "
                        "(each with a static .trc and a batch.toml or OpenSim setups; see pinmsk.subjects)")
    s.add_argument("--jobs", type=int, default=None, help="parallel local workers (default: all cores)")
    s.add_argument("--scheduler", default=None,
                   help="Dask distributed scheduler ADDRESS (needs `pip install distributed`)")
    s.add_argument("--force", action="store_true",
                   help="run every trial again (default: skip trials whose folder is complete for the same "
                        "inputs and options)")
    s.add_argument("--shard", metavar="I/N", default=None,
                   help="run only the trials (for a FOLDER: the subjects) with index %% N == I-1 (I from 1; "
                        "e.g. a Slurm array's $SLURM_ARRAY_TASK_ID/N); writes summary-I-of-N.csv and "
                        "report-I-of-N.html")
    s.set_defaults(func=cmd_batch)
    return p


#: Arguments naming output files, and output folders, of any command (checked before it runs).
_OUTPUT_FILES = ("output", "json", "report", "save_model", "save_osim", "solver_log")
_OUTPUT_FOLDERS = ("plot", "out")


def _check_outputs(args) -> None:
    """Refuse, before any work, outputs of a type the command cannot write or whose folder is missing or
    read-only, and misspelt effect names; create --plot folders."""
    from .cli_checks import check_effect_names, check_output_suffixes
    check_output_suffixes(args)
    check_effect_names(args)
    for name in _OUTPUT_FILES:
        if getattr(args, name, None):
            check_output_file(getattr(args, name))
    for name in _OUTPUT_FOLDERS:
        if getattr(args, name, None):
            output_folder(getattr(args, name))


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one line ``pinmsk: warning: ...`` on stderr (no source line)."""
    print(f"pinmsk: warning: {message}", file=sys.stderr if file is None else file)


def _run(argv) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            with output_transaction():
                _check_outputs(args)
                return int(args.func(args) or 0)
    except PinmskError as exc:
        print(f"pinmsk: error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        where = f": {exc.filename}" if exc.filename else ""
        print(f"pinmsk: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("pinmsk: interrupted", file=sys.stderr)
        return 130


def main(argv=None) -> int:
    """Run the command line; returns the exit status (2 for errors pinmsk recognises).

    BLAS runs on one thread (:func:`pinmsk._blas.one_thread`) unless the user set its thread count:
    the commands' many small solves are slower with more, several-fold on a busy machine.

    A closed output pipe (``pinmsk models | head -1``) ends the command quietly
    with status 1, as the Python documentation recommends for ``SIGPIPE``
    (library/signal.html, "Note on SIGPIPE"): stdout is pointed at devnull so
    the interpreter's final flush cannot fail again.
    """
    from .._blas import one_thread
    one_thread()
    try:
        try:
            return _run(argv)
        finally:
            sys.stdout.flush()
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
