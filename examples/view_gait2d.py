"""View the sagittal gait model walking, with muscles, ground reaction forces and a ghost.

    python examples/view_gait2d.py            # prints the URL; serves until Ctrl-C (in a terminal)
    python examples/view_gait2d.py --no-block # set the scene up, print the URL, exit

The gait is synthetic (sinusoidal joint angles at 1.2 m/s, vertical ground
reaction force under the stance foot), so the example needs no data.  The
second ("simulated") motion walks beside it as a translucent ghost, and the
joints are coloured by a made-up residual.
"""
import numpy as np

import pinmsk
from pinmsk.presentation.viewer import Viewer

from _common import serve_or_close, viewer_arguments

STANDING_HEIGHT = 1.068  # torso_y with heels on the ground at q = 0 (urdf/gait2d.urdf)


def synthetic_gait(model, *, cycles=2, period=1.1, rate=100.0, speed=1.2):
    t = np.arange(0.0, cycles * period + 0.5 / rate, 1.0 / rate)
    ph = 2 * np.pi * t / period
    q = {c: np.zeros_like(t) for c in model.coordinates}
    q["torso_x"] = speed * t
    q["torso_y"] = STANDING_HEIGHT - 0.03 + 0.015 * np.cos(2 * ph)
    q["torso_angle"] = 0.05 + 0.02 * np.sin(2 * ph)
    for side, shift in (("r", 0.0), ("l", np.pi)):
        p = ph + shift
        q[f"hip_{side}"] = -0.45 * np.sin(p)                   # + = extension
        q[f"knee_{side}"] = 0.55 * np.clip(np.sin(p - 0.6), 0, None) + 0.08
        q[f"ankle_{side}"] = 0.2 * np.sin(p - 1.2)
    grf = {}
    mass = float(sum(i.mass for i in model.pin.inertias))
    for side, shift in (("r", 0.0), ("l", np.pi)):
        stance = np.cos(ph + shift - 0.3) < 0.25
        grf[f"{side}_ground_force_vy"] = np.where(stance, 9.81 * mass * (0.6 + 0.4 * np.abs(np.sin(ph))), 0.0)
        grf[f"{side}_ground_force_vx"] = np.where(stance, 80 * np.sin(ph + shift), 0.0)
        grf[f"{side}_ground_force_px"] = q["torso_x"] + 0.05 * np.cos(ph + shift)
    act = {f"{m}_activation": np.clip(0.5 + 0.5 * np.sin(ph + 0.7 * i + (np.pi if m.endswith("_l") else 0)), 0, 1)
           for i, m in enumerate(model.muscle_names)}
    res = {f"{c}_residual": 0.2 * np.abs(np.sin(ph + i)) for i, c in enumerate(model.coordinates)}
    res["torso_y_residual"] = 1.0 + 0.5 * np.sin(2 * ph)       # the largest: worth looking at
    measured = pinmsk.Trial(t, q | grf)
    results = pinmsk.Trial(t, act | res)
    simulated = pinmsk.Trial(t, {c: v * (0.9 if c not in ("torso_x", "torso_y") else 1.0) for c, v in q.items()})
    return measured, results, simulated


def main(argv=None):
    args = viewer_arguments(argv, description=__doc__.splitlines()[0])

    model = pinmsk.load_model("gait2d")
    measured, results, simulated = synthetic_gait(model)
    viewer = Viewer(model)                                      # prints the URL
    viewer.play(measured, results=results, ghost=simulated, ghost_offset=0.6)
    serve_or_close(viewer, args)


if __name__ == "__main__":
    main()
