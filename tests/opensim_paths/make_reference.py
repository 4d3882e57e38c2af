"""Write OpenSim's muscle path lengths and moment arms of Gait10dof18musc's scaled subject
(``Working_with_Static_Optimization/subject01.osim``) at the walk's IK poses (every 10th frame of
``IK/subject01_walk_IK.mot``) to ``subject01_walk_paths.json`` beside this file.

Run with the ``opensim`` package installed: ``python tests/opensim_paths/make_reference.py``.
Values come from ``GeometryPath.getLength`` and ``GeometryPath.computeMomentArm`` of OpenSim 4.x.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
MODEL = "opensim-models/Gait10dof18musc/Working_with_Static_Optimization/subject01.osim"
MOTION = "opensim-models/Gait10dof18musc/IK/subject01_walk_IK.mot"
OUT = HERE / "subject01_walk_paths.json"
STEP = 10


def reference(shared: Path) -> dict:
    """``{"coordinates", "muscles", "q" (N, c) rad/m, "lengths" (N, m), "moment_arms" (N, m, c)}`` from OpenSim."""
    import opensim as osim
    from pinmsk.io.tables import read_trial
    osim.Logger.setLevelString("Off")
    osim.Logger.removeFileSink()         # no opensim.log in the working directory
    model = osim.Model(str(shared / MODEL))
    state = model.initSystem()
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    names = [c.getName() for c in coords]
    ik = read_trial(shared / MOTION)            # SI (radians), as pinmsk reads the .mot
    q = np.asarray(ik.get(names), dtype=float)[::STEP]
    fs = model.getForceSet()
    muscles = [fs.get(i).getName() for i in range(fs.getSize())
               if osim.PathActuator.safeDownCast(fs.get(i)) is not None]
    gps = [osim.PathActuator.safeDownCast(fs.get(m)).getGeometryPath() for m in muscles]
    L = np.empty((len(q), len(muscles)))
    A = np.empty((len(q), len(muscles), len(names)))
    for n, row in enumerate(q):
        for c, v in zip(coords, row):
            c.setValue(state, float(v), False)
        model.realizePosition(state)
        for i, gp in enumerate(gps):
            L[n, i] = gp.getLength(state)
            for j, c in enumerate(coords):
                A[n, i, j] = gp.computeMomentArm(state, c)
    return {"model": MODEL, "motion": MOTION, "step": STEP, "opensim": osim.GetVersionAndDate(),
            "coordinates": names, "muscles": muscles, "q": q.tolist(), "lengths": L.tolist(),
            "moment_arms": A.tolist()}


def main() -> int:
    sys.path.insert(0, str(HERE.parent.parent))
    from pinmsk.io.shared_data import shared_data_dir
    shared = shared_data_dir()
    if shared is None:
        print("shared data not found (set PINMSK_SHARED_DATA)", file=sys.stderr)
        return 2
    OUT.write_text(json.dumps(reference(shared)))
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
