"""View the 36-dof human3d skeleton (meshes from example-robot-data) swinging arms and legs.

    python examples/view_human3d.py            # prints the URL; serves until Ctrl-C (in a terminal)
    python examples/view_human3d.py --no-block # set the scene up, print the URL, exit

The motion is synthetic; a ghost with smaller amplitude stands beside it.
"""
import numpy as np

import pinmsk
from pinmsk.presentation.viewer import Viewer

from _common import serve_or_close, viewer_arguments


def synthetic_swing(model, *, duration=2.0, rate=60.0):
    t = np.arange(0.0, duration + 0.5 / rate, 1.0 / rate)
    ph = 2 * np.pi * t / duration
    q = {c: np.zeros_like(t) for c in model.coordinates}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        for name, amp in (("hip_Z", 0.4), ("shoulder_Z", -0.5)):
            if f"{side}_{name}" in q:
                q[f"{side}_{name}"] = sign * amp * np.sin(ph)
        if f"{side}_knee_Z" in q:
            q[f"{side}_knee_Z"] = -0.4 * np.clip(sign * np.sin(ph - 0.5), 0, None)
        if f"{side}_elbow_Z" in q:
            q[f"{side}_elbow_Z"] = 0.6 + 0.3 * np.sin(ph)
    return pinmsk.Trial(t, q), pinmsk.Trial(t, {c: 0.6 * v for c, v in q.items()})


def main(argv=None):
    args = viewer_arguments(argv, description=__doc__.splitlines()[0])

    model = pinmsk.load_model("human3d")
    measured, smaller = synthetic_swing(model)
    viewer = Viewer(model)                                      # prints the URL
    viewer.play(measured, ghost=smaller, ghost_offset=0.8)
    serve_or_close(viewer, args)


if __name__ == "__main__":
    main()
