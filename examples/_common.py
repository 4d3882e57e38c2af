"""What several example scripts share: the viewer examples' serving options, and the data examples' ``main``.

Not an example itself; the scripts import it from their own folder.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from pinmsk.io.shared_data import shared_data_dir


def output_folder(given, name: str) -> Path:
    """Where an example writes: the folder ``given`` (created), or a new temporary folder (printed), never
    the current folder unasked."""
    if given:
        out = Path(given)
        out.mkdir(parents=True, exist_ok=True)
        return out
    out = Path(tempfile.mkdtemp(prefix=f"pinmsk-{name}-"))
    print(f"{name}: no output folder given; writing to {out}")
    return out


def viewer_arguments(argv, *, description: str) -> argparse.Namespace:
    """``--no-block``, ``--block`` and ``--timeout`` of the viewer examples, parsed from ``argv``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--no-block", action="store_true", help="set the scene up, print the URL and exit")
    parser.add_argument("--block", action="store_true",
                        help="keep serving even without a terminal (default: serve only in a terminal)")
    parser.add_argument("--timeout", type=float, default=None, help="stop after this many seconds")
    return parser.parse_args(argv)


def serve_or_close(viewer, args: argparse.Namespace) -> None:
    """Serve until Ctrl-C (or ``--timeout``) in a terminal or with ``--block``; otherwise close the viewer."""
    if args.no_block or not (args.block or sys.stdin.isatty()):
        if not args.no_block:
            print("no terminal: not serving; pass --block to keep the viewer up")
        viewer.close()
    else:
        viewer.serve(timeout=args.timeout)


def data_file_main(argv, *, description: str, name: str, out: str, relative: str, run) -> int:
    """``main`` of an example that reads one file of the shared data: ``--out``, ``--data``, ``--no-plots``.

    Calls ``run(path, out_folder, plots=...)`` on ``<data>/<relative>``, or says the
    file is absent and returns 0 (nothing is written then).
    """
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--out", default=None, help=f"output folder (default: a new temporary folder; e.g. {out})")
    p.add_argument("--data", default=None)
    p.add_argument("--no-plots", action="store_true")
    a = p.parse_args(argv)
    d = Path(a.data) if a.data else shared_data_dir()
    path = None if d is None else d / relative
    if path is None or not path.exists():
        print(f"{name}: ../shared/data/{relative} is absent; nothing to do")
        return 0
    run(path, output_folder(a.out, name), plots=not a.no_plots)
    return 0
