"""Foot contact identification (thesis Ch. 4) on real treadmill walking.

Drives foot2d with the measured ankle (lateral malleolus) position and foot
angle of the CSU treadmill trial, fits the point (Eq. 4.4), linear volumetric
(Eq. 4.5-4.8), hyper-volumetric (Eq. 4.9-4.15) and relaxed hyper-volumetric
(Sec. 4.1.4) contact models to the measured GRF and COP (Eq. 4.2) over one
cycle from toe-off to toe-off, prints the table of fitted parameters and
errors, writes GRF/COP figures, and repeats the sensitivity study of Fig. 4.11.

    python examples/05_contact_identification.py [--data rawdata.txt] [--out DIR]
                                                 [--starts 4] [--jobs 2] [--quick]

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

from pinmsk.contact import ContactFit, stance_cycle, synthetic_foot_trial  # noqa: E402

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parent.parent / "shared" / "data" / "real" / "csu-treadmill-leg2d" / "rawdata.txt"
THESIS_SENSITIVITY = {"heel": 2.4, "metatarsal": 6.3, "toe": 1.3}
VARIANTS = (("point", False), ("volumetric", False), ("hypervolumetric", False), ("hypervolumetric", True))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=Path(os.environ.get("PINMSK_EXAMPLE_OUT", HERE / "out" / "contact")))
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--relax-range", type=float, default=0.02,
                    help="+- bound of the relaxed sphere offsets dx, dy (m; thesis: 0.015-0.02)")
    ap.add_argument("--toe", nargs="+", default=["fit", "flat"], choices=["fit", "flat"],
                    help="toe angle: Fourier series fitted with the contact parameters (Eq. 4.1, as the "
                         "issue asks) and/or fixed to 'toes flat while the heel is up'")
    args = ap.parse_args(argv)

    data = args.data
    if data is None and os.environ.get("PINMSK_SHARED_DATA"):
        data = Path(os.environ["PINMSK_SHARED_DATA"]) / "real" / "csu-treadmill-leg2d" / "rawdata.txt"
    if data is None:
        data = DEFAULT_DATA
    if data.exists():
        from pinmsk.csu import read_csu
        trial = read_csu(data, body_mass=67.2)
        window = stance_cycle(trial)
        source = f"CSU treadmill trial {data}"
        cutoff = 12.0
    else:
        trial = synthetic_foot_trial()
        window = None
        source = "synthetic foot trial (real data not found)"
        cutoff = None
    print(f"data: {source}; window {window}; belt speed {trial.meta.get('ground_speed', 0.0):.3f} m/s")
    opts = dict(n_starts=1, max_nfev=30) if args.quick else dict(n_starts=args.starts, n_jobs=args.jobs)

    args.out.mkdir(parents=True, exist_ok=True)
    fits = {}
    for toe in args.toe:
        for kind, relax in VARIANTS:
            name = f"{kind}{' relaxed' if relax else ''}" + ("" if toe == "fit" else f" (toe {toe})")
            fit = ContactFit(contact=kind, relax=relax, window=window, cutoff=cutoff, toe=toe,
                             relax_range=args.relax_range, **opts).fit(None, trial)
            fit.plot(args.out / f"toe_{toe}")
            fits[name] = fit
            print(fit.report())

    print("\nTable (Eq. 4.2 error J, minimised terms; J_all = all three terms; RMSE normal/friction N, COP mm)")
    print(f"{'model':<36}{'J':>9}{'J_all':>9}{'fn':>8}{'ff':>8}{'cop':>8}{'s':>8}")
    for name, f in fits.items():
        r = f.rmse_
        print(f"{name:<36}{f.objective_:>9.4f}{f.objective_full_:>9.4f}{r['normal_force']:>8.1f}"
              f"{r['friction_force']:>8.1f}{1000 * r['cop']:>8.1f}{f.seconds_:>8.1f}")

    sens = {}
    for name in [n for n in fits if n.startswith("hypervolumetric relaxed")]:
        sens[name] = fits[name].sensitivity(factor=1.1)
        print(f"\nFig. 4.11 ({name}): +10 % k_h at one sphere -> change of the peak total normal force")
        for s, v in sens[name].items():
            print(f"  {s:<11} {v['peak_percent']:6.2f} %  (mean {v['mean_percent']:5.2f} %; "
                  f"thesis {THESIS_SENSITIVITY[s]} %)")
    summary = {"source": source, "window": window,
               "fits": {n: f.to_dict() for n, f in fits.items()}, "sensitivity": sens}
    (args.out / "contact_summary.json").write_text(json.dumps(summary, indent=2))
    print(f"\nfigures and contact_summary.json in {args.out}")
    return summary


if __name__ == "__main__":
    main()
