"""View the 36-dof human3d skeleton (meshes from example-robot-data) swinging arms and legs.

    python examples/view_human3d.py            # prints the URL; serves until Ctrl-C (in a terminal)
    python examples/view_human3d.py --no-block # set the scene up, print the URL, exit

The motion is synthetic; a ghost with smaller amplitude stands beside it.
"""
import argparse
import sys

import numpy as np

import pinmsk
from pinmsk.viewer import Viewer


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
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-block", action="store_true", help="set the scene up, print the URL and exit")
    parser.add_argument("--block", action="store_true",
                        help="keep serving even without a terminal (default: serve only in a terminal)")
    parser.add_argument("--timeout", type=float, default=None, help="stop after this many seconds")
    args = parser.parse_args(argv)

    model = pinmsk.load_model("human3d")
    measured, smaller = synthetic_swing(model)
    viewer = Viewer(model)                                      # prints the URL
    viewer.play(measured, ghost=smaller, ghost_offset=0.8)
    if args.no_block or not (args.block or sys.stdin.isatty()):
        if not args.no_block:
            print("no terminal: not serving; pass --block to keep the viewer up")
        viewer.close()
    else:
        viewer.serve(timeout=args.timeout)


if __name__ == "__main__":
    main()
