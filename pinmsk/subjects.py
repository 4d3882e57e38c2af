"""A lab folder of subjects: ``pinmsk batch FOLDER`` runs each subject's own batch.

Layout (one sub-folder per subject; other sub-folders are ignored and named)::

    FOLDER/
      S01/
        S01_static.trc        # a .trc whose name holds "static": what makes a folder a subject
        walk_1.trc ...
        batch.toml            # either a batch config (pinmsk.pipeline), run by batch_cli ...
      S02/
        static.trc
        S02_Setup_Scale.xml   # ... or OpenSim setups, run by pinmsk.tools.run_setup
        S02_Setup_IK.xml        (ScaleTool, then InverseKinematicsTool, InverseDynamicsTool,
        S02_Setup_ID.xml         AnalyzeTool; by file name within a tool)

A subject with ``batch.toml`` gets everything :func:`pinmsk.pipeline.batch_cli` does
(its ``out`` folder, resume from done markers, ``force``, the HTML report).  A subject
with setups runs each setup as OpenSim would (paths relative to the setup, results in its
``<results_directory>``); ``.xml`` files of other kinds (marker sets, external loads, task
sets) are the setups' inputs and are not run.  Setups are run every time (their inputs are
whatever the setups name, so no done marker is kept for them).  ``shard=(i, n)`` runs the
subjects with index ``k % n == i - 1`` (sorted by name): one subject per job of an array.

:func:`batch_folder` writes ``FOLDER/subjects.csv`` (``subjects-i-of-n.csv`` for a shard):
one row per subject with its kind, status, trials (or setups) run, skipped, failed and time.
"""
from __future__ import annotations

import csv
import time as _time
from pathlib import Path

from .errors import PinmskError, TrialError
from .io.output_files import atomic_write
from .presentation.progress import Progress

__all__ = ["find_subjects", "subject_setups", "batch_folder", "CONFIG_NAME", "TOOL_ORDER"]

#: The batch config a subject folder may hold.
CONFIG_NAME = "batch.toml"

#: The order a subject's OpenSim setups run in.
TOOL_ORDER = ("ScaleTool", "InverseKinematicsTool", "InverseDynamicsTool", "AnalyzeTool")


def _static_trc(folder: Path):
    return sorted(p for p in folder.glob("*.trc") if "static" in p.name.lower())


def find_subjects(folder) -> tuple[list[Path], list[Path]]:
    """(subject folders, other sub-folders) of ``folder``, sorted by name; a subject holds a static .trc."""
    folder = Path(folder)
    if not folder.is_dir():
        raise TrialError(f"{folder}: not a folder")
    subs = sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
    subjects = [p for p in subs if _static_trc(p)]
    if not subjects:
        raise TrialError(f"{folder}: no subject folders (a sub-folder holding a static .trc, "
                         "a .trc file whose name contains 'static')")
    return subjects, [p for p in subs if p not in subjects]


def subject_setups(folder) -> list[Path]:
    """The OpenSim setups of a subject folder that pinmsk runs, in :data:`TOOL_ORDER`."""
    from .io.opensim_setup import read_setup
    found = []
    for p in sorted(Path(folder).glob("*.xml")):
        try:
            tool = read_setup(p).tool
        except PinmskError:            # not an OpenSim document: an input of some other kind
            continue
        if tool in TOOL_ORDER:
            found.append((TOOL_ORDER.index(tool), p.name, p))
    return [p for *_, p in sorted(found)]


def _run_subject(folder: Path, *, scheduler, jobs, force) -> dict:
    t0 = _time.perf_counter()
    row = {"subject": folder.name, "kind": "", "status": "ok", "run": 0, "skipped": 0, "failed": 0}
    try:
        config = folder / CONFIG_NAME
        if config.is_file():
            from .pipeline import batch_cli
            s = batch_cli(config, scheduler=scheduler, jobs=jobs, force=force)
            row.update(kind="config", run=len(s["rows"]) - len(s["skipped"]) - len(s["failed"]),
                       skipped=len(s["skipped"]), failed=len(s["failed"]), report=s["report"])
            if s["failed"]:
                row["status"] = f"failed: {len(s['failed'])} trial(s): {', '.join(s['failed'])}"
        else:
            row["kind"] = "setups"
            setups = subject_setups(folder)
            if not setups:
                raise TrialError(f"{folder}: no {CONFIG_NAME} and no OpenSim setup "
                                 f"({', '.join(TOOL_ORDER)}) to run")
            from .tools import run_setup
            files = []
            for setup in setups:
                files += run_setup(setup)
                row["run"] += 1
            row["files"] = len(files)
    except PinmskError as exc:
        row["status"] = f"failed: {exc}"
        row["failed"] = max(row["failed"], 1)
    row["time_total_s"] = _time.perf_counter() - t0
    return row


def batch_folder(folder, *, scheduler=None, jobs=None, force: bool = False, shard=None) -> dict:
    """Run every subject of ``folder`` (see the module docstring); one line per finished subject.

    Returns ``{"rows", "table", "failed", "ignored", "shard"}``: the subjects' rows, the
    ``subjects.csv`` written, the names of the subjects that failed (or had failed trials),
    the sub-folders that are not subjects, and ``(i, n)`` or None.
    """
    from .pipeline import _suffix, parse_shard, shard_indices
    folder = Path(folder)
    sh = None if shard is None else (parse_shard(shard) if isinstance(shard, str) else tuple(shard))
    subjects, ignored = find_subjects(folder)
    subjects = [subjects[k] for k in shard_indices(len(subjects), sh)]
    rows = []
    with Progress(len(subjects), "subjects", unit="subjects") as bar:
        for k, sub in enumerate(subjects, start=1):
            row = _run_subject(sub, scheduler=scheduler, jobs=jobs, force=force)
            rows.append(row)
            what = (f"done in {row['time_total_s']:.1f} s" if row["status"] == "ok"
                    else f"FAILED: {row['status'].removeprefix('failed: ')}")
            bar.note(f"subject [{k}/{len(subjects)}] {sub.name} ({row['kind']}): {what}")
            bar.update(1)
    cols = ["subject", "kind", "status", "run", "skipped", "failed", "files", "report", "time_total_s"]

    def write(fh):
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: (f"{v:.6g}" if isinstance(v, float) else v) for c, v in r.items()})

    table = atomic_write(folder / f"subjects{_suffix(sh)}.csv", write)
    return {"rows": rows, "table": str(table), "failed": [r["subject"] for r in rows if r["status"] != "ok"],
            "ignored": [p.name for p in ignored], "shard": sh}
