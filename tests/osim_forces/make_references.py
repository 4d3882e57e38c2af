"""Write ``references.npz``: OpenSim's numbers for tests/test_osim_forces.py.

Run from the repository root with the opensim peer installed and ../shared/data present::

    python tests/osim_forces/make_references.py

For each model of :data:`cases.FORCES` at the states of :func:`cases.states`: each listed force's
generalized forces, from OpenSim's InverseDynamicsSolver with only that force applied minus with
none (``<model>/<force>``, (N, n) in OpenSim's coordinate order); for :data:`cases.ID_MODELS` the
inverse dynamics with every force applied (``<model>/__id__``); and the states themselves.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cases  # noqa: E402


def _solve(osim, model, state, names, Q, V, A):
    """OpenSim's InverseDynamicsSolver over the frames, (N, n) in ``names`` order."""
    cs = model.getCoordinateSet()
    where = {}
    for i in range(cs.getSize()):
        state.updU().setToZero()
        cs.get(i).setSpeedValue(state, 1.0)
        u = state.getU()
        where[cs.get(i).getName()] = next(j for j in range(u.size()) if u.get(j) == 1.0)
    solver = osim.InverseDynamicsSolver(model)
    out = np.zeros_like(Q)
    for k in range(Q.shape[0]):
        for j, name in enumerate(names):
            c = cs.get(name)
            c.setValue(state, float(Q[k, j]), False)
            c.setSpeedValue(state, float(V[k, j]))
        model.realizeVelocity(state)
        udot = osim.Vector(state.getNU(), 0.0)
        for j, name in enumerate(names):
            udot.set(where[name], float(A[k, j]))
        tau = solver.solve(state, udot)
        out[k] = [tau.get(where[name]) for name in names]
    return out


def _model(osim, path, keep):
    """The model with only the forces named in ``keep`` applied (all, for ``keep=None``)."""
    model = osim.Model(str(path))
    state = model.initSystem()
    fs = model.getForceSet()
    for i in range(fs.getSize()):
        if keep is not None and fs.get(i).getName() not in keep:
            fs.get(i).setAppliesForce(state, False)
    return model, state


def main() -> None:
    import opensim as osim
    from pinmsk.io.shared_data import shared_data_dir

    osim.Logger.setLevelString("Off")
    archive = shared_data_dir() / cases.ZOO
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        paths = cases.extract(archive, sorted(set(cases.FORCES) | set(cases.ID_MODELS)), Path(tmp))
        for name, path in paths.items():
            names, t, Q, V, A = cases.states(path)
            out[f"{name}/__names__"] = np.array(names)
            out[f"{name}/__free__"] = np.array([r[3] for r in cases.coordinate_table(path)])
            for key, x in (("t", t), ("q", Q), ("v", V), ("a", A)):
                out[f"{name}/__{key}__"] = x
            probe = osim.Model(str(path))
            fs = probe.getForceSet()
            forces = [fs.get(i).getName() for i in range(fs.getSize())
                      if fs.get(i).getConcreteClassName() in cases.FORCES.get(name, ())]
            off = _solve(osim, *_model(osim, path, ()), names, Q, V, A) if forces else None
            for f in forces:
                out[f"{name}/{f}"] = _solve(osim, *_model(osim, path, (f,)), names, Q, V, A) - off
                print(f"{name}/{f}: peak {np.abs(out[f'{name}/{f}']).max():.4g}")
            if name in cases.ID_MODELS:
                out[f"{name}/__id__"] = _solve(osim, *_model(osim, path, None), names, Q, V, A)
    np.savez_compressed(cases.REFERENCES, **out)
    print(f"wrote {cases.REFERENCES} ({cases.REFERENCES.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
