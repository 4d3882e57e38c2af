"""Foot contact identification (thesis Ch. 4) on real treadmill walking.

Drives foot2d with the foot located by its heel and 5th-metatarsal markers in
the CSU treadmill trial (:func:`pinmsk.io.cleveland_gait.read_csu`, ``anchor="heel"``: foot
angle from the marker line, heel sphere site at a calibrated offset from the
heel marker), fits the point (Eq. 4.4), linear volumetric (Eq. 4.5-4.8),
hyper-volumetric (Eq. 4.9-4.15) and relaxed hyper-volumetric (Sec. 4.1.4)
contact models to the measured GRF and COP (Eq. 4.2) over one cycle from
toe-off to toe-off, prints the table of errors, load shares and the double
hump of the vertical force, writes GRF/COP figures, and repeats the
sensitivity study of Fig. 4.11 for the volumetric models.

The toe angle is, by default, identified beforehand from the kinematics and
held fixed (``--toe kinematic``, the thesis procedure); ``--toe fit`` fits the
Eq. 4.1 series with the contact parameters, each coefficient within
+-``--toe-range`` rad of the kinematic estimate.

    python examples/05_contact_identification.py [--data rawdata.txt] [--out DIR]
                                                 [--starts N] [--quick]
                                                 [--toe kinematic fit] [--anchor heel|ankle]

Every other setting is :class:`pinmsk.contact.ContactFit`'s default -- the settings of
``pinmsk contact fit`` (all three Eq. 4.2 terms, one cycle from toe-off to toe-off, 12 Hz
kinematics low-pass, 4 starts including the simpler models' optima); each fit prints them.

Without the real data (``../shared/data/real/csu-treadmill-leg2d``) it runs on
the project's synthetic foot trial.  ``--quick`` does one short start per model
(what the test suite runs).
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

from pinmsk.contact import synthetic_foot_trial  # noqa: E402
from pinmsk.contact.identify import VARIANTS, fit_contact_models, settings_lines  # noqa: E402
from pinmsk.presentation.plots import contact_fit_figures  # noqa: E402
from _common import output_folder

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parent.parent / "shared" / "data" / "real" / "csu-treadmill-leg2d" / "rawdata.txt"
THESIS_SENSITIVITY = {"heel": 2.4, "metatarsal": 6.3, "toe": 1.3}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--out", default=os.environ.get("PINMSK_EXAMPLE_OUT"),
                    help="output folder (default: a new temporary folder)")
    ap.add_argument("--starts", type=int, default=None, help="starting points per model (default: ContactFit's)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--relax-range", type=float, default=0.02,
                    help="+- bound of the relaxed sphere offsets dx, dy (m; thesis: 0.015-0.02)")
    ap.add_argument("--toe", nargs="+", default=["kinematic", "fit"], choices=["kinematic", "fit", "flat"],
                    help="toe angle: identified from the kinematics and held fixed (thesis procedure), "
                         "and/or the Eq. 4.1 series fitted with the contact parameters within --toe-range, "
                         "and/or (legacy) fixed to 'toes flat while the heel is up'")
    ap.add_argument("--toe-range", type=float, default=0.02,
                    help="+- bound (rad) of each toe Fourier coefficient around its kinematic value (--toe fit)")
    ap.add_argument("--anchor", default="heel", choices=["heel", "ankle"],
                    help="locate the foot from the heel + MT5 markers (heel) or hang it from the malleolus marker")
    ap.add_argument("--max-nfev", type=int, default=None)
    args = ap.parse_args(argv)

    data = args.data
    if data is None and os.environ.get("PINMSK_SHARED_DATA"):
        data = Path(os.environ["PINMSK_SHARED_DATA"]) / "real" / "csu-treadmill-leg2d" / "rawdata.txt"
    if data is None:
        data = DEFAULT_DATA
    opts = {}
    if data.exists():
        from pinmsk.contact import read_csu_foot2d
        trial = read_csu_foot2d(data, body_mass=67.2, anchor=args.anchor)
        source = f"CSU treadmill trial {data}"
    else:
        trial = synthetic_foot_trial()
        source = "synthetic foot trial (real data not found)"
        opts["cutoff"] = None   # noise-free synthetic kinematics
    print(f"data: {source}; belt speed {trial.meta.get('ground_speed', 0.0):.3f} m/s")
    if args.quick:
        opts.update(n_starts=1, max_nfev=30)
    for key, val in (("n_starts", args.starts), ("max_nfev", args.max_nfev)):
        if val is not None:
            opts[key] = val

    args.out = output_folder(args.out, "05_contact_identification")
    fits = {}
    for toe in args.toe:
        models = fit_contact_models(None, trial, VARIANTS, toe=toe, relax_range=args.relax_range,
                                    toe_range=args.toe_range, **opts)
        for (kind, relax), fit in models.items():
            name = f"{kind}{' relaxed' if relax else ''} (toe {toe})"
            contact_fit_figures(fit, args.out / f"toe_{toe}")
            fits[name] = fit
            if len(fits) == 1:
                print("\n".join(settings_lines(fit.settings_())))
            print(fit.report())
    window = next(iter(fits.values())).window_

    print("\nTable: Eq. 4.2 error J (the minimised terms, the same for every model), J_all (all three "
          "terms) and its terms;\nRMSE normal / friction (N), COP (mm); share of the normal impulse H/P/T; "
          "double-hump depth 1 - valley/mean(peaks) of the model at the measured events (measured: see below)")
    print(f"{'model':<38}{'J':>8}{'J_all':>8}{'J_fn':>8}{'J_ff':>8}{'J_cop':>8}{'fn':>7}{'ff':>7}{'cop':>7}"
          f"{'H/P/T':>16}{'hump':>7}{'s':>7}")
    hump = {}
    for name, f in fits.items():
        r, T, sh = f.rmse_, f.terms_, f.load_shares()
        hump[name] = f.double_hump()
        print(f"{name:<38}{f.objective_:>8.4f}{f.objective_full_:>8.4f}{T['normal_force']:>8.4f}"
              f"{T['friction_force']:>8.4f}{T['cop']:>8.4f}{r['normal_force']:>7.1f}{r['friction_force']:>7.1f}"
              f"{1000 * r['cop']:>7.1f}{sh['heel']:>6.2f}/{sh['metatarsal']:.2f}/{sh['toe']:.2f}"
              f"{hump[name]['model_depth_at_measured_events']:>7.3f}{f.seconds_:>7.1f}")
    if hump:
        print(f"measured double-hump depth: {next(iter(hump.values()))['measured_depth']:.3f}")

    sens = {}
    for name in [n for n in fits if n.startswith(("volumetric", "hypervolumetric"))]:
        sens[name] = fits[name].sensitivity(factor=1.1)
        print(f"\nFig. 4.11 ({name}): +10 % stiffness at one sphere -> change of the peak total normal force")
        for s, v in sens[name].items():
            print(f"  {s:<11} {v['peak_percent']:6.2f} %  (mean {v['mean_percent']:5.2f} %; "
                  f"thesis {THESIS_SENSITIVITY[s]} %)")
    summary = {"source": source, "window": window, "anchor": trial.meta.get("anchor"),
               "heel_offset": trial.meta.get("heel_offset"),
               "fits": {n: f.to_dict() for n, f in fits.items()}, "sensitivity": sens, "double_hump": hump}
    (args.out / "contact_summary.json").write_text(json.dumps(summary, indent=2))
    print(f"\nfigures and contact_summary.json in {args.out}")
    return summary


if __name__ == "__main__":
    main()
