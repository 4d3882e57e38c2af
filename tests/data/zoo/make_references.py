"""OpenSim's inverse dynamics of every model in the shared OpenSim model zoo, on a synthetic motion.

    python tests/data/zoo/make_references.py [--zoo DIR] [--out tests/data/zoo/references.npz]

Each coordinate follows ``x(t) = c + A sin(2 pi f t + phi)`` over 1 s (201 frames), with ``A = min(0.2,
range / 4)`` (rad or m), ``c`` its default value moved into ``[min + A, max - A]``, ``f = 0.7 + 0.13 i`` Hz and
``phi = i`` for the model's i-th coordinate; locked coordinates stay at their default values and the
dependent coordinate of each CoordinateCouplerConstraint is set from its function, as OpenSim's
solvers set it (kept in the references, float64).  The motion is written as a .mot file and OpenSim's ``InverseDynamicsTool`` (no filter)
computes the generalized forces (the muscles excluded, as its setup files exclude them); the references keep every other frame between 0.1 s and 0.9 s (the
spline derivatives' end effects left out), in float32; the muscles' lengths (and moment arms, up to 20 muscles) at 3 frames in float64.  Needs the optional peer ``opensim``.

:func:`synthetic_motion` is what the tests rebuild the motion with (they need no ``opensim``).
"""
from __future__ import annotations

import argparse
import json
import math
import tarfile
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
T = np.linspace(0.0, 1.0, 201)
KEEP = np.arange(20, 181, 2)


def synthetic_motion(coords):
    """``(N, n)`` coordinate values of ``coords``: ``[(name, default, lo, hi, locked), ...]``."""
    out = np.zeros((T.size, len(coords)))
    for i, (_, d, lo, hi, locked) in enumerate(coords):
        if locked:
            out[:, i] = d
            continue
        span = hi - lo if math.isfinite(hi - lo) else 1.0
        amp = min(0.2, 0.25 * span)
        c = min(max(d, lo + amp), hi - amp)
        out[:, i] = c + amp * np.sin(2 * np.pi * (0.7 + 0.13 * i) * T + i)
    return out


def _write_mot(path, names, X):
    with open(path, "w") as f:
        f.write(f"motion\nversion=1\nnRows={len(T)}\nnColumns={len(names) + 1}\ninDegrees=no\nendheader\n")
        f.write("time\t" + "\t".join(names) + "\n")
        for k in range(len(T)):
            f.write("\t".join(f"{v:.15g}" for v in [T[k], *X[k]]) + "\n")


def reference(osim_path: Path, work: Path):
    """``(coords, ID labels, ID values (n_keep, m), dependent names, their values, muscle lengths, moment arms,
    muscle names)`` of one model, or None when OpenSim cannot load it."""
    import opensim as osim
    try:
        model = osim.Model(str(osim_path))
        model.initSystem()
    except Exception:
        return None
    cs = model.getCoordinateSet()
    coords = [(c.getName(), c.getDefaultValue(), c.getRangeMin(), c.getRangeMax(), bool(c.getDefaultLocked()))
              for c in (cs.get(i) for i in range(cs.getSize()))]
    names = [c[0] for c in coords]
    X = synthetic_motion(coords)
    col = {n: i for i, n in enumerate(names)}
    dependent = []
    for k in range(model.getConstraintSet().getSize()):
        cc = osim.CoordinateCouplerConstraint.safeDownCast(model.getConstraintSet().get(k))
        if cc is None or cc.getPropertyByName("isEnforced").toString().strip().lower() == "false":
            continue
        ind = [cc.getIndependentCoordinateNames().get(j) for j in range(cc.getIndependentCoordinateNames().getSize())]
        fn, s = cc.getFunction(), float(cc.getPropertyByName("scale_factor").toString())
        dep = col[cc.getDependentCoordinateName()]
        dependent.append(cc.getDependentCoordinateName())
        for r in range(len(T)):
            x = osim.Vector(len(ind), 0.0)
            for j, n in enumerate(ind):
                x.set(j, float(X[r, col[n]]))
            X[r, dep] = s * fn.calcValue(x)
    lengths, arms = _paths(model, names, X)
    mot = work / f"{osim_path.stem}.mot"
    _write_mot(mot, names, X)
    tool = osim.InverseDynamicsTool()
    tool.setModel(model)
    tool.setCoordinatesFileName(str(mot))
    tool.setStartTime(0.0)
    tool.setEndTime(1.0)
    tool.setLowpassCutoffFrequency(-1)
    excluded = osim.ArrayStr()
    excluded.append("Muscles")          # as OpenSim's ID setup files do: the muscles' forces are the unknowns
    tool.setExcludedForces(excluded)
    tool.setResultsDir(str(work))
    tool.setOutputGenForceFileName(f"{osim_path.stem}_id.sto")
    tool.run()
    table = osim.TimeSeriesTable(str(work / f"{osim_path.stem}_id.sto"))
    labels = list(table.getColumnLabels())
    values = np.stack([table.getDependentColumn(lb).to_numpy() for lb in labels], 1)[KEEP]
    return (coords, labels, values.astype(np.float32), dependent, X[:, [col[n] for n in dependent]], lengths, arms,
            _muscle_names(model))


#: The frames of the synthetic motion where muscle lengths (and, up to ARM_MUSCLES muscles, moment arms)
#: are kept.
POSES = (50, 100, 150)
ARM_MUSCLES = 20


def _muscle_names(model):
    import opensim as osim
    fs = model.getForceSet()
    return [f.getName() for f in (fs.get(i) for i in range(fs.getSize())) if osim.Muscle.safeDownCast(f) is not None]


def _paths(model, names, X):
    """OpenSim's muscle lengths (len(POSES), m) and moment arms (len(POSES), m, n) or None, at POSES."""
    import opensim as osim
    fs = model.getForceSet()
    muscles = [mu for mu in (osim.Muscle.safeDownCast(fs.get(i)) for i in range(fs.getSize())) if mu is not None]
    m = len(muscles)
    if m == 0:
        return None, None
    state = model.getWorkingState()
    cs = model.getCoordinateSet()
    L = np.zeros((len(POSES), m))
    R = np.zeros((len(POSES), m, len(names))) if m <= ARM_MUSCLES else None
    for k, r in enumerate(POSES):
        for j, n in enumerate(names):
            cs.get(n).setValue(state, float(X[r, j]), False)
        model.realizePosition(state)
        for i in range(m):
            mus = muscles[i]
            L[k, i] = mus.getLength(state)
            if R is not None:
                for j, n in enumerate(names):
                    R[k, i, j] = mus.computeMomentArm(state, cs.get(n))
    return L, R


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--zoo", type=Path, default=Path("/work/shared/data/osim-zoo/zoo_models.tar.xz"))
    ap.add_argument("--out", type=Path, default=HERE / "references.npz")
    args = ap.parse_args(argv)
    arrays, index = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        with tarfile.open(args.zoo) as tar:
            tar.extractall(work, filter="data")
        for p in sorted(work.glob("*.osim")):
            got = reference(p, work)
            if got is None:
                index[p.stem] = None
                print(f"{p.stem}: OpenSim does not load it")
                continue
            coords, labels, values, dependent, xdep, lengths, arms, muscle_names = got
            index[p.stem] = {"coordinates": [list(c) for c in coords], "labels": labels, "dependent": dependent}
            if lengths is not None:
                index[p.stem]["muscles"] = muscle_names
                arrays[f"{p.stem}__lengths"] = lengths
                if arms is not None:
                    arrays[f"{p.stem}__arms"] = arms
            arrays[f"{p.stem}__id"] = values
            if dependent:
                arrays[f"{p.stem}__dependent"] = xdep
            print(f"{p.stem}: {len(labels)} generalized forces")
    np.savez_compressed(args.out, index=np.array(json.dumps(index)), **arrays)
    print(f"wrote {args.out} ({args.out.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
