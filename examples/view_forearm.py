"""View the forearm model playing an elbow flexion, muscles coloured by activation.

    python examples/view_forearm.py            # prints the URL; serves until Ctrl-C (in a terminal)
    python examples/view_forearm.py --no-block # set the scene up, print the URL, exit

The motion and the activations are synthetic (a smooth flexion-extension and a
flexor/extensor pattern that follows it), so the example needs no data.  The
"simulated" motion lags the measured one by 0.1 s and is drawn as a ghost
beside it; its elbow residual is the coloured ball at the elbow.
"""
import numpy as np

import pinmsk
from pinmsk.presentation.viewer import Viewer

from _common import serve_or_close, viewer_arguments


def synthetic_trials(model, duration=4.0, rate=100.0):
    t = np.arange(0.0, duration + 0.5 / rate, 1.0 / rate)
    q = 1.2 - 1.0 * np.cos(2 * np.pi * t / duration)           # 0.2 .. 2.2 rad and back
    qd = np.gradient(q, t)
    flex = np.clip(0.25 + 0.6 * np.sin(q) * (qd > 0) + 0.15 * np.sin(q), 0, 1)
    ext = np.clip(0.05 + 0.5 * (qd < 0) * np.sin(q), 0, 1)
    channels = {"elbow_flexion": q}
    for name in model.muscle_names:
        channels[f"{name}_activation"] = ext if name.startswith("TRI") else flex
    measured = pinmsk.Trial(t, {"elbow_flexion": q})
    results = pinmsk.Trial(t, {k: v for k, v in channels.items() if k != "elbow_flexion"}
                           | {"elbow_flexion_residual": 0.5 * np.sin(4 * np.pi * t / duration) ** 2})
    simulated = pinmsk.Trial(t, {"elbow_flexion": np.interp(t - 0.1, t, q)})
    return measured, results, simulated


def main(argv=None):
    args = viewer_arguments(argv, description=__doc__.splitlines()[0])

    model = pinmsk.load_model("forearm")
    measured, results, simulated = synthetic_trials(model)
    viewer = Viewer(model)                                      # prints the URL
    viewer.play(measured, results=results, ghost=simulated, ghost_offset=0.35)
    serve_or_close(viewer, args)


if __name__ == "__main__":
    main()
