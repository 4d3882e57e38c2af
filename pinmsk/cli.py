"""The ``pinmsk`` command line.

Every command has ``--help``.  Errors pinmsk recognises (bad files, unknown
names, infeasible problems) print one line ``pinmsk: error: ...`` on stderr
and exit with status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .errors import PinmskError


def _model(args):
    from .model import load_model
    return load_model(args.model, moment_arms=getattr(args, "moment_arms", None))


def _read(path, model=None):
    from .io import read_trial
    return read_trial(path, angular=None if model is None else model.rotational_coordinates)


def _write(trial, path):
    from .io import write_trial
    write_trial(trial, path)
    print(f"wrote {path}")


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


# -- commands ------------------------------------------------------------------

def cmd_models(args) -> int:
    from .builtin_models import builtin_names
    from .model import load_model
    print(f"{'model':<10} {'dof':>4} {'muscles':>8}  description")
    for name in builtin_names():
        try:
            m = load_model(name)
        except PinmskError as exc:
            print(f"{name:<10} {'?':>4} {'?':>8}  unavailable: {exc}")
            continue
        print(f"{name:<10} {m.nv:>4} {m.n_muscles:>8}  {m.meta.get('description', '')[:70]}")
    return 0


def cmd_info(args) -> int:
    m = _model(args)
    print(m.describe())
    return 0


def cmd_id(args) -> int:
    from .dynamics import inverse_dynamics
    model = _model(args)
    trial = _read(args.trial, model)
    out = inverse_dynamics(model, trial, cutoff=args.cutoff)
    _write(out, args.output)
    if args.plot:
        from . import plots
        for path in plots.save_channels(out, [f"{c}_moment" for c in model.coordinates], args.plot,
                                        stem="inverse_dynamics", ylabel="moment (N m)"):
            print(f"wrote {path}")
    return 0


def cmd_simulate(args) -> int:
    from .dynamics import simulate
    model = _model(args)
    moments = _read(args.moments, model) if args.moments else None
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
    _write(out, args.output)
    return 0


def cmd_demo(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from .diagnose import demo
    demo(out)
    return 0


# -- parser ----------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pinmsk", description="Human musculoskeletal dynamics on Pinocchio.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    s = sub.add_parser("models", help="list the built-in models with dof and muscle counts")
    s.set_defaults(func=cmd_models)

    s = sub.add_parser("info", help="describe a model (built-in name or path to .toml/.urdf)")
    s.add_argument("model")
    s.add_argument("--moment-arms", choices=["constant", "angle"], default=None,
                   help="muscle path variant (models that declare several)")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("id", help="inverse dynamics of a trial: <coord>_moment channels")
    s.add_argument("model")
    s.add_argument("trial", help="trial file (.csv with a time column, .sto or .mot)")
    s.add_argument("-o", "--output", required=True, help="output .sto or .csv")
    s.add_argument("--cutoff", type=float, default=None,
                   help="zero-lag Butterworth low-pass cut-off (Hz) before differentiation")
    s.add_argument("--moment-arms", choices=["constant", "angle"], default=None)
    s.add_argument("--plot", metavar="DIR", default=None, help="write PNG figures to DIR")
    s.set_defaults(func=cmd_id)

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
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("demo", help="the diagnosis loop on a shipped forearm trial with a hidden effect")
    s.add_argument("--out", default="pinmsk-demo", help="folder for figures and the report (default ./pinmsk-demo)")
    s.set_defaults(func=cmd_demo)

    for extra in _EXTRA_COMMANDS:
        extra(sub)
    return p


#: Functions ``f(subparsers)`` adding the solver and diagnosis commands.
_EXTRA_COMMANDS: list = []


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PinmskError as exc:
        print(f"pinmsk: error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"pinmsk: error: {exc.strerror}: {exc.filename}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("pinmsk: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
