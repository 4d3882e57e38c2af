"""SO, MSO and EID on the forearm's Gaussian elbow motion (thesis Sec. 2.2.2-2.2.4).

    python examples/04_so_mso_eid.py [OUT_DIR]

All three in activation mode (F = a F_active + F_passive at the motion's
muscle lengths and velocities) with cost sum a^2:

* SO  -- each frame on its own (Eq. 2.14);
* MSO -- frame by frame, but a_k must be reachable from a_{k-1} under the
  Winters-Stark activation dynamics (thesis A.2, tau_rise 11 ms, tau_fall 68 ms);
* EID -- the whole trial as one sparse proxsuite QP, time-integral cost, the
  same dynamics coupling the frames.

To make the dynamics matter the motion is also run 2.5x faster (0.8 s).
Prints timings, objectives and the largest differences; writes one PNG per
speed to OUT_DIR.
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import pinmsk  # noqa: E402
from pinmsk.solvers import EID, ModifiedStaticOptimization, StaticOptimization  # noqa: E402
from pinmsk.solvers.analytical import gaussian_elbow_motion  # noqa: E402
from _common import output_folder

out = output_folder(sys.argv[1] if len(sys.argv) > 1 else None, "04_so_mso_eid")
model = pinmsk.load_model("forearm")
names = model.muscles.names
show = [0, 2, 3, 5]            # BRD, BICSH, BRA, TRIMH


def integral(t, c):
    return float(np.sum(np.diff(t) * 0.5 * (c[1:] + c[:-1])))


for label, duration, sigma in (("2 s (Fig. 3.13)", 2.0, 0.25), ("0.8 s", 0.8, 0.1)):
    motion = gaussian_elbow_motion(duration=duration, sigma=sigma, n_frames=201)
    so = StaticOptimization(mode="activation").fit(model, motion)
    mso = ModifiedStaticOptimization().fit(model, motion)
    eid = EID().fit(model, motion)
    t = motion.t
    print(f"motion {label}, {t.size} frames")
    for name, r, secs in (("SO", so, so.timing_["total_s"]), ("MSO", mso, mso.time_), ("EID", eid, eid.time_)):
        print(f"  {name:4s} {secs * 1e3:7.1f} ms   integral of sum a^2 dt = {integral(t, r.cost_):.5f}   "
              f"max violation {np.max(r.violation_):.1e} N m")
    print(f"  max |a_MSO - a_SO| = {np.max(np.abs(mso.activations_ - so.activations_)):.4f}, "
          f"max |a_EID - a_SO| = {np.max(np.abs(eid.activations_ - so.activations_)):.4f}, "
          f"max |F_EID - F_SO| = {np.max(np.abs(eid.forces_ - so.forces_)):.2f} N")
    fig, ax = plt.subplots(2, len(show), figsize=(3.2 * len(show), 5.5), sharex=True)
    for j, i in enumerate(show):
        for name, r, style in (("SO", so, "k-"), ("MSO", mso, "C1--"), ("EID", eid, "C0-")):
            ax[0, j].plot(t, r.activations_[:, i], style, lw=1.2, label=name)
            ax[1, j].plot(t, r.forces_[:, i], style, lw=1.2, label=name)
        ax[0, j].set_title(names[i])
        ax[1, j].set_xlabel("time (s)")
    ax[0, 0].set_ylabel("activation")
    ax[1, 0].set_ylabel("force (N)")
    ax[0, 0].legend()
    fig.suptitle(f"SO vs MSO vs EID, Gaussian elbow motion over {label}")
    fig.tight_layout()
    fig.savefig(out / f"so_mso_eid_{duration:g}s.png", dpi=110)
    plt.close(fig)
    print("  " + eid.report().replace("\n", "\n  "))
print(f"\nfigures written to {out.resolve()}")
