"""pinmsk on one zoo model against the stored OpenSim references (``references.npz``, made by
``make_references.py``): the import, then inverse dynamics of the same synthetic motion.

:func:`check` is shared by ``tests/test_osim_zoo.py`` and ``benchmarks/bench_zoo.py`` (which writes
``docs/zoo.md``); it needs no ``opensim``.
"""
from __future__ import annotations

import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from make_references import KEEP, T, synthetic_motion

HERE = Path(__file__).resolve().parent
REFERENCES = HERE / "references.npz"

#: The goal: ID within this fraction of each coordinate's peak (RMS over the frames).
ID_GOAL = 5e-3
#: The goal for the geometric muscle paths: lengths and moment arms within this (m) of OpenSim's.
PATH_GOAL = 1e-6


def references() -> tuple[dict, dict]:
    """``(index, arrays)`` of the stored references: ``index[model]`` is None where OpenSim cannot load it."""
    with np.load(REFERENCES) as z:
        return json.loads(str(z["index"])), {k: z[k] for k in z.files if k != "index"}


@dataclass
class ZooResult:
    """One model's outcome: ``status`` 'pass', 'fail' (ID off the goal) or 'refused' (one-line error)."""

    model: str
    status: str
    import_s: float = float("nan")
    fit_s: float = float("nan")         # the muscle paths' deferred work
    worst: float = float("nan")         # largest RMS error / peak over the coordinates
    worst_coordinate: str = ""
    message: str = ""
    errors: dict = field(default_factory=dict)
    not_imported: tuple = ()
    path_length: float = float("nan")   # largest muscle-length difference at the stored poses (m)
    path_arm: float = float("nan")      # largest moment-arm difference there (m)


def check(osim: Path, index: dict, arrays: dict, *, convention: str = "opensim") -> ZooResult:
    """Import ``osim`` and compare its inverse dynamics with OpenSim's ID tool on the stored motion."""
    from pinmsk.errors import PinmskError
    from pinmsk.model import import_osim
    from pinmsk.trial import Trial
    from pinmsk.dynamics import inverse_dynamics_result
    from pinmsk.tools.layout import id_table

    name = osim.stem
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model, report = import_osim(osim)
    except PinmskError as exc:
        return ZooResult(name, "refused", message=str(exc))
    t1 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        str(report)                     # the deferred muscle-path work (polynomial fit) is done here
    fit_s = time.perf_counter() - t1
    dt = t1 - t0
    ref = index.get(name)
    if ref is None:
        return ZooResult(name, "fail", dt, fit_s, message="imported, but OpenSim does not load it")
    coords = [tuple(c) for c in ref["coordinates"]]
    names = [c[0] for c in coords]
    X = synthetic_motion(coords)
    for j, dep in enumerate(ref.get("dependent", ())):
        X[:, names.index(dep)] = arrays[f"{name}__dependent"][:, j]
    trial = Trial.from_array(T, names, X)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = inverse_dynamics_result(model, trial, cutoff=None, convention=convention).trial
    out = id_table(model, out)           # OpenSim's labels: <coord>_moment, <coord>_force of translations
    got = {c: np.asarray(out[c])[KEEP] for c in out.names}
    expect = arrays[f"{name}__id"].astype(float)
    errors = {}
    for j, label in enumerate(ref["labels"]):
        v = expect[:, j]
        p = got.get(label)
        if p is None:
            errors[label] = float("inf")
            continue
        peak = float(np.abs(v).max())
        err = float(np.sqrt(np.mean((p - v) ** 2)))
        errors[label] = err / peak if peak > 1e-6 else err          # a zero reference: the absolute error
    worst_c = max(errors, key=errors.get)
    path_length, path_arm = _path_errors(osim, ref, arrays, X)
    left = tuple(e.element for e in report.entries if e.status == "not imported")
    return ZooResult(name, "pass" if errors[worst_c] <= ID_GOAL else "fail", dt, fit_s, errors[worst_c], worst_c,
                     errors=errors, not_imported=left, path_length=path_length, path_arm=path_arm)


def _path_errors(osim, ref, arrays, X):
    """Largest |length| and |moment arm| differences (m) of the geometric paths from OpenSim's at the
    stored poses (NaN where none are stored; moment arms only without coupled coordinates, whose OpenSim
    moment arms are total derivatives)."""
    from make_references import POSES
    from pinmsk.opensim.muscle_import import osim_geometric_paths
    if f"{osim.stem}__lengths" not in arrays:
        return float("nan"), float("nan")
    gp = osim_geometric_paths(osim)
    names = [c[0] for c in ref["coordinates"]]
    q = X[list(POSES)][:, [names.index(c) for c in gp.coordinates]]
    ln, arm = gp.lengths_and_moment_arms(q)
    cols = [list(gp.muscles).index(m) for m in ref["muscles"]]
    dl = float(np.abs(ln[:, cols] - arrays[f"{osim.stem}__lengths"]).max())
    da = float("nan")
    if f"{osim.stem}__arms" in arrays and not ref.get("dependent"):
        expect = arrays[f"{osim.stem}__arms"][:, :, [names.index(c) for c in gp.coordinates]]
        da = float(np.abs(arm[:, cols] - expect).max())
    return dl, da
