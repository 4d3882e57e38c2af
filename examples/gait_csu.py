"""CSU treadmill walking on gait2d: right-leg IK from six markers, ID with the measured force plate.

Data: ``csu-treadmill-leg2d/rawdata.txt`` (GaitAnalysisToolKit leg2d test data, Apache-2.0; subject 7 of
van den Bogert et al. 2013, 67.2 kg), read from ``../shared/data/real`` (``$PINMSK_SHARED_DATA``);
nothing is copied.  Without the data the script says so and exits 0.

    python examples/gait_csu.py --out out/csu

* markers RSHO, RGTRO, RLEK, RLM, RHEE, RMT5 (100 Hz, m) -> ``InverseKinematics`` with the ``csu`` set of
  ``urdf/markers_gait2d.toml`` (x and y only; free: torso_x, torso_y, torso_angle, hip_r, knee_r,
  ankle_r; the left leg is not measured and stays at 0);
* force plate FP2: the COP from the moment about the global origin on the belt (``pinmsk.io.cleveland_gait``),
  applied to ``foot_r`` as a world-frame wrench;
* inverse dynamics after a 6 Hz zero-lag low-pass of the coordinates (as leg2d's test);
* hip, knee and ankle moments per kg (body mass 67.2 kg from the repository's test.m) and the
  residual forces and moment at the torso coordinates.

Caveats: only the right foot's plate is in the file, so the torso residuals include the whole left-foot
GRF during left stance and double support; they are also reported over the frames where the right plate
carries more than 80 % of body weight (mostly right single support).  The markers sit on gait2d's
anthropometry, not the subject's (no static calibration), so the marker RMS errors are centimetres.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import pinmsk
from pinmsk.contact import read_csu_foot2d
from pinmsk.grf import external_forces, torso_residuals
from pinmsk.ik import InverseKinematics
from pinmsk.markers import load_marker_set

from _common import data_file_main

BODY_MASS = 67.2   # kg, test.m of GaitAnalysisToolKit
CUTOFF = 6.0       # Hz


def run(path: Path, out: Path, *, plots: bool = True) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    model = pinmsk.load_model("gait2d")
    raw = read_csu_foot2d(path, body_mass=BODY_MASS)
    mset = load_marker_set("gait2d").subset("csu")
    ik = InverseKinematics(markers=mset, axes="xy", q0={"torso_y": 1.0}).fit(model, raw)
    kin = ik.result_
    ext = external_forces(model, raw, frames={None: "foot_r"}, planar=True)
    idt = pinmsk.inverse_dynamics(model, kin, cutoff=CUTOFF, external=ext)
    res_trial, rsum = torso_residuals(model, idt, body_mass=BODY_MASS, height=1.70)
    fy = np.asarray(raw["ground_force_vy"])
    single = fy > 0.8 * BODY_MASS * 9.81
    rsum_single = {c: {"rms": float(np.sqrt(np.mean(np.asarray(res_trial[f"{c}_residual"])[single] ** 2))),
                       "frames": int(single.sum())} for c in rsum}
    stance = fy > 20.0
    moments = {}
    for j in ("hip_r", "knee_r", "ankle_r"):
        m = np.asarray(idt[f"{j}_moment"]) / BODY_MASS
        moments[j] = {"max_nm_per_kg": float(m.max()), "min_nm_per_kg": float(m.min()),
                      "stance_mean_nm_per_kg": float(m[stance].mean())}
    result = {
        "body_mass_kg": BODY_MASS, "frames": kin.n_frames, "cutoff_hz": CUTOFF,
        "ik_marker_rms_mm": {k: 1000 * v for k, v in ik.marker_rms_.items()},
        "ik_mean_iterations": float(ik.iterations_.mean()),
        "moments": moments,
        "torso_residuals": rsum,
        "torso_residuals_right_single_support": rsum_single,
        "joint_angle_range_deg": {j: [float(np.degrees(kin[j]).min()), float(np.degrees(kin[j]).max())]
                                  for j in ("hip_r", "knee_r", "ankle_r")},
        "caveats": [
            "only the right force plate is in the file: the torso residuals include the unmeasured left-foot "
            "GRF; see torso_residuals_right_single_support",
            "model markers use gait2d's anthropometry, not the subject's (no static trial)",
        ],
    }
    table = ["| quantity | value |", "|---|---|"]
    for j, v in moments.items():
        table.append(f"| {j} moment max / min (N m/kg) | {v['max_nm_per_kg']:.2f} / {v['min_nm_per_kg']:.2f} |")
    for c, v in rsum.items():
        extra = f" ({v['rms_percent_bw']:.1f} % BW)" if "rms_percent_bw" in v else ""
        table.append(f"| {c} residual RMS, all / right single support ({v['unit']}) | {v['rms']:.1f}{extra} / "
                     f"{rsum_single[c]['rms']:.1f} |")
    table.append("| IK marker RMS (mm) | " + ", ".join(f"{k} {v:.0f}" for k, v in result["ik_marker_rms_mm"].items())
                 + " |")
    (out / "gait_csu_table.md").write_text("\n".join(table) + "\n")
    (out / "gait_csu.json").write_text(json.dumps(result, indent=2))
    if plots:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        t = kin.time
        fig, ax = plt.subplots(4, 1, figsize=(8, 10), sharex=True)
        for j in ("hip_r", "knee_r", "ankle_r"):
            ax[0].plot(t, np.degrees(kin[j]), label=j)
            ax[1].plot(t, idt[f"{j}_moment"] / BODY_MASS, label=j)
        ax[0].set_ylabel("angle (deg)")
        ax[1].set_ylabel("moment (N m/kg)")
        ax[0].legend(fontsize=7)
        ax[2].plot(t, res_trial["torso_x_residual"], label="torso_x (N)")
        ax[2].plot(t, res_trial["torso_y_residual"], label="torso_y (N)")
        ax[2].plot(t, res_trial["torso_angle_residual"], label="torso_angle (N m)")
        ax[2].legend(fontsize=7)
        ax[2].set_ylabel("residual")
        ax[3].plot(t, 1000 * ik.frame_rms_)
        ax[3].set_ylabel("IK RMS (mm)")
        ax[3].set_xlabel("time (s)")
        fig.tight_layout()
        fig.savefig(out / "csu_gait.png", dpi=110)
        plt.close(fig)
    print("\n".join(table))
    return result


def main(argv=None) -> int:
    return data_file_main(argv, description=__doc__.splitlines()[0], name="gait_csu", out="out/csu",
                          relative="real/csu-treadmill-leg2d/rawdata.txt", run=run)


if __name__ == "__main__":
    sys.exit(main())
