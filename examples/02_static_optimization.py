"""Static optimization on the forearm (thesis Figs. 3.13-3.15, 3.18-3.19) and on gait2d.

    python examples/02_static_optimization.py [OUT_DIR]

Forearm: the Gaussian 0 -> 120 deg elbow flexion of Fig. 3.13 over 2 s
(sigma = 0.25 s, see pinmsk.solvers.analytical.gaussian_elbow_motion), seven
muscles with the constant moment arms of Table 3.5, cost sum F^P (Eq. 3.13)
for P = 1, 2, 3, 10 and the min/max criterion.  Each solution is checked
against the closed-form 1-dof optimum (Eq. 2.22-2.24, 3.31-3.40 with the KKT
branch choice and saturation).  gait2d: a synthetic walking-like motion with
16 bi-articular-capable muscles, P = 2, results written as .sto.
Headless: writes PNG figures and .sto files to OUT_DIR (default: a new temporary folder).
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import pinmsk  # noqa: E402
from pinmsk.diagnose.synth import walking_motion  # noqa: E402
from pinmsk.solvers import StaticOptimization  # noqa: E402
from pinmsk.solvers.analytical import gaussian_elbow_motion, one_dof_forces  # noqa: E402
from _common import output_folder

out = output_folder(sys.argv[1] if len(sys.argv) > 1 else None, "02_static_optimization")

model = pinmsk.load_model("forearm")
motion = gaussian_elbow_motion()                   # Fig. 3.13
names = model.muscles.names

# Fig. 3.13: the reference motion
fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
ax[0].plot(motion.t, np.rad2deg(motion.q[:, 0]))
ax[0].set(xlabel="time (s)", ylabel="elbow flexion (deg)", title="Fig. 3.13 reference angle")
ax[1].plot(motion.t, np.rad2deg(motion.v[:, 0]))
ax[1].set(xlabel="time (s)", ylabel="speed (deg/s)", title="angular speed")
fig.tight_layout()
fig.savefig(out / "fig3_13_reference_motion.png", dpi=110)
plt.close(fig)

cases = [(1, False), (2, False), (3, False), (10, False), (2, True)]
results = {}
print("forearm, 201 frames over 2 s")
for P, minmax in cases:
    so = StaticOptimization(exponent=P, minmax=minmax).fit(model, motion)
    R, T = so.problem_.R[:, :, 0], so.problem_.tau[:, 0]
    exact = one_dof_forces(R, T, exponent=P, upper=model.muscles.f_max, minmax=minmax)
    label = "min/max" if minmax else f"P = {P}"
    results[label] = so
    print(f"  {label:8s} {so.timing_['solve_s'] * 1e3:7.2f} ms ({so.timing_['solve_s'] / 201 * 1e6:6.1f} us/frame), "
          f"max |F - F_analytical| = {np.max(np.abs(so.forces_ - exact)):.2e} N, "
          f"max violation {np.max(so.violation_):.1e} N m")
    pinmsk.write_trial(so.result_, out / f"forearm_so_{'minmax' if minmax else f'P{P}'}.sto")
print()
print(results["P = 2"].report())

# Figs. 3.14-3.15: forces over time and the force space of the first two muscles
fig, axes = plt.subplots(len(results), 2, figsize=(10, 2.6 * len(results)))
for row, (label, so) in zip(axes, results.items()):
    for i, n in enumerate(names):
        row[0].plot(motion.t, so.forces_[:, i], label=n)
    row[0].set(ylabel="force (N)", title=f"SO, {label}: CPU {so.timing_['solve_s'] * 1e3:.1f} ms "
               f"(thesis: 6-31 s)")
    row[1].plot(so.forces_[:, 0], so.forces_[:, 1])
    row[1].set(xlabel=f"{names[0]} force (N)", ylabel=f"{names[1]} force (N)", title="force space")
axes[0, 0].legend(ncol=4, fontsize=7)
axes[-1, 0].set_xlabel("time (s)")
fig.tight_layout()
fig.savefig(out / "fig3_14_15_so_forces.png", dpi=110)
plt.close(fig)

# Figs. 3.18-3.19: net muscle moment, and the analytical P = 2 forces of the flexors
so2 = results["P = 2"]
T = so2.problem_.tau[:, 0]
exact = one_dof_forces(so2.problem_.R[:, :, 0], T, exponent=2, upper=model.muscles.f_max)
fig, ax = plt.subplots(1, 2, figsize=(10, 3.4))
ax[0].plot(motion.t, T)
ax[0].axhline(0, color="k", lw=0.5)
ax[0].set(xlabel="time (s)", ylabel="net muscle moment (N m)", title="Fig. 3.18")
for i, n in enumerate(names):
    ax[1].plot(motion.t, exact[:, i], label=f"{n} (Eq. 3.40)")
    ax[1].plot(motion.t, so2.forces_[:, i], "k:", lw=0.8)
ax[1].set(xlabel="time (s)", ylabel="force (N)", title="Fig. 3.19 analytical (dotted: SO)")
ax[1].legend(fontsize=7, ncol=2)
fig.tight_layout()
fig.savefig(out / "fig3_18_19_analytical.png", dpi=110)
plt.close(fig)

# gait2d: a walking-like motion without ground reaction forces.  SO balances the coordinates
# the muscles span; nothing holds the floating base up, so SO refuses unless the base gets
# reserves -- which then carry the body weight, reported in the table below.
gait = pinmsk.load_model("gait2d")
walk = walking_motion(gait, n_frames=400, duration=2.0)
t = walk.t
so = StaticOptimization(exponent=2, reserves=True).fit(gait, walk)
print()
print(so.report())
pinmsk.write_trial(so.result_, out / "gait2d_so_P2.sto")
fig, ax = plt.subplots(figsize=(9, 4))
for i, n in enumerate(gait.muscles.names):
    if n.endswith("_r"):
        ax.plot(t, so.forces_[:, i], label=n)
ax.set(xlabel="time (s)", ylabel="force (N)", title="gait2d SO (P = 2), right leg")
ax.legend(fontsize=7, ncol=2)
fig.tight_layout()
fig.savefig(out / "gait2d_so_forces.png", dpi=110)
plt.close(fig)
print(f"\nfigures and .sto files written to {out.resolve()}")
