"""Winter's stride (Table A.1 raw markers) on gait2d: joint angles by IK, and how the low-pass
cut-off changes the swing-phase knee moment.

Data: ``winter-gait-bmc/WinterTableA1.txt`` (Winter 2009, *Biomechanics and Motor Control of Human
Movement*, 4th ed., Appendix A, Table A.1, via BMClab/BMC, CC BY 4.0), read from
``../shared/data/real`` (``$PINMSK_SHARED_DATA``); nothing is copied.  Without it the script exits 0.

    python examples/gait_winter.py --out out/winter

* The 8 raw markers (cm, ~70 Hz, sagittal) are converted to m and **scaled uniformly** to gait2d's size
  (factor = gait2d's trochanter-to-malleolus marker distance / the subject's median one; Winter's
  subject is 1.56 m, gait2d 1.70 m).  A uniform scale changes no joint angle.
* ``InverseKinematics`` with the ``winter`` marker set (x, y; free: torso 3 dofs, right hip, knee,
  ankle, MTP); per-marker RMS errors reported.
* Swing phase: the second right swing, toe-off at frame 70 to heel contact at about frame 97 (BMC and
  other users of the data; the book was not checked), away from the filter's start-up at the ends.  In swing the right foot carries no load, so the knee moment needs no
  force plate: it is the shank-foot inertia and gravity alone, computed here for cut-offs of 3-15 Hz
  and without filtering.  Moments are per kg of gait2d's mass (65.7 kg) since the segment parameters
  are gait2d's, not the subject's.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import pinmsk
from pinmsk.ik import InverseKinematics
from pinmsk.gait_validation import read_table_a1, scale_to_model
from pinmsk.markers import load_marker_set

from _common import data_file_main

SWING = (69, 95)       # 0-based: right toe-off (frame 70, 1-based) .. the frame before heel contact (~97)
CUTOFFS = (3.0, 4.0, 6.0, 8.0, 10.0, 15.0, None)


def run(path: Path, out: Path, *, plots: bool = True) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    model = pinmsk.load_model("gait2d")
    mset = load_marker_set("gait2d").subset("winter")
    mk, scale = scale_to_model(read_table_a1(path), mset)
    ik = InverseKinematics(markers=mset, axes="xy", q0={"torso_y": 1.0}).fit(model, mk)
    kin = ik.result_
    a, b = SWING
    swing = {}
    curves = {}
    for c in CUTOFFS:
        idt = pinmsk.inverse_dynamics(model, kin, cutoff=c)      # no GRF: valid for the swing leg only
        k = np.asarray(idt["knee_r_moment"])[a:b + 1] / model.mass
        curves[c] = k
        swing["unfiltered" if c is None else f"{c:g}Hz"] = {
            "peak_flexor_nm_per_kg": float(k.max()), "peak_extensor_nm_per_kg": float(k.min())}
    ref = curves[6.0]
    for c in CUTOFFS:
        key = "unfiltered" if c is None else f"{c:g}Hz"
        swing[key]["rms_difference_from_6hz_nm_per_kg"] = float(np.sqrt(np.mean((curves[c] - ref) ** 2)))
    angles = {j: {"min_deg": float(np.degrees(kin[j]).min()), "max_deg": float(np.degrees(kin[j]).max())}
              for j in ("hip_r", "knee_r", "ankle_r")}
    result = {"marker_scale": scale, "frames": kin.n_frames, "rate_hz": float(1 / np.median(np.diff(kin.time))),
              "ik_marker_rms_mm": {k: 1000 * v for k, v in ik.marker_rms_.items()},
              "joint_angles_deg": angles, "swing_frames": [a + 1, b + 1],
              "swing_knee_moment_by_cutoff": swing,
              "notes": "moments per kg of gait2d's mass (its segment parameters); swing events from BMC/other "
                       "users, not checked against the book"}
    table = ["| cut-off | swing knee peak flexor / extensor (N m/kg) | RMS diff from 6 Hz |", "|---|---|---|"]
    for k, v in swing.items():
        table.append(f"| {k} | {v['peak_flexor_nm_per_kg']:.3f} / {v['peak_extensor_nm_per_kg']:.3f} | "
                     f"{v['rms_difference_from_6hz_nm_per_kg']:.3f} |")
    table += ["", "| joint | min (deg) | max (deg) |", "|---|---|---|"]
    for j, v in angles.items():
        table.append(f"| {j} | {v['min_deg']:.1f} | {v['max_deg']:.1f} |")
    (out / "gait_winter_table.md").write_text("\n".join(table) + "\n")
    (out / "gait_winter.json").write_text(json.dumps(result, indent=2))
    if plots:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(2, 1, figsize=(8, 7))
        for j in ("hip_r", "knee_r", "ankle_r"):
            ax[0].plot(kin.time, np.degrees(kin[j]), label=j)
        ax[0].axvspan(kin.time[a], kin.time[b], color="0.9")
        ax[0].set_ylabel("angle (deg)")
        ax[0].set_title("hip + extension, knee + flexion, ankle + plantarflexion; grey: swing", fontsize=9)
        ax[0].legend(fontsize=7)
        ts = kin.time[a:b + 1]
        for c, k in curves.items():
            ax[1].plot(ts, k, label="unfiltered" if c is None else f"{c:g} Hz")
        ax[1].set_ylabel("swing knee moment (N m/kg, + flexor)")
        ax[1].set_xlabel("time (s)")
        ax[1].legend(fontsize=7, ncol=4)
        fig.tight_layout()
        fig.savefig(out / "winter_swing_knee.png", dpi=110)
        plt.close(fig)
    print("\n".join(table))
    return result


def main(argv=None) -> int:
    return data_file_main(argv, description=__doc__.splitlines()[0], name="gait_winter", out="out/winter",
                          relative="real/winter-gait-bmc/WinterTableA1.txt", run=run)


if __name__ == "__main__":
    sys.exit(main())
