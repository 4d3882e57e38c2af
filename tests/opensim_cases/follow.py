"""Run pinmsk's diagnosis on the OpenSim-generated cases and judge it against each case's hidden truth.

:func:`follow` is the loop a user follows: diagnose, add the best significant candidate, diagnose again,
until nothing is significant.  :func:`judge` compares what was added with ``truth.json``: the right
family at the right target (a payload at the right site, within 2 cm, or on a fitted body axis that
passes within 2 cm of it, its distance along the axis then judged as a value, or at a fitted point
on the right body, its coordinates judged as values; or an exact alias the truth
declares, such as a payload at a body's centre of mass for a change of its mass), each value the fit
varies within 3 standard
errors (its relative error is reported too), nothing added that the truth does not hold, and the
final verdict ``at_noise_floor``.

Used by ``tests/test_diagnose_opensim_cases.py`` and, as a script, to print the table of every case::

    python tests/opensim_cases/follow.py [CASE ...]
"""
from __future__ import annotations

import json
import sys
import time
import warnings
from functools import lru_cache
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
CASES = HERE.parents[0] / "data" / "opensim_cases"


def case_names() -> list[str]:
    return sorted(p.name for p in CASES.iterdir() if (p / "truth.json").is_file())


def truth(name: str) -> dict:
    return json.loads((CASES / name / "truth.json").read_text())


def model_path(info: dict, shared: Path) -> Path | None:
    """The case's OpenSim model under the shared data folder (a zoo model unpacked once), or None."""
    rel = info["model"]
    if ":" in rel:
        archive, member = rel.split(":", 1)
        return _zoo_member(str(shared / archive), member)
    p = shared / rel
    return p if p.is_file() else None


@lru_cache(maxsize=None)
def _zoo_member(archive: str, member: str) -> Path | None:
    import tarfile
    import tempfile
    if not Path(archive).is_file():
        return None
    out = Path(tempfile.mkdtemp(prefix="pinmsk_zoo_"))
    with tarfile.open(archive) as tar:
        tar.extract(member, out)
    return out / member


@lru_cache(maxsize=None)
def load_model(path: str, nonlinear: str | None = None):
    """``pinmsk.load_model(path)`` (``nonlinear`` passed on when given), warnings silenced."""
    import pinmsk
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pinmsk.load_model(path) if nonlinear is None else pinmsk.load_model(path, nonlinear=nonlinear)


def external_loads(name: str, info: dict, shared: Path):
    ext = info.get("external_loads")
    if not ext:
        return None
    p = CASES / name / ext
    return p if p.is_file() else shared / ext


def follow(model, trial, *, max_steps: int = 4, **options):
    """``(first, final, added, labels)``: the first diagnosis, the last, the added effects as in the final
    model (after every joint refit, with their errors) and the labels in the order they were added."""
    from pinmsk.diagnose import diagnose, run
    d0 = diagnose(model, trial, **options)
    adds, r, d = [], None, d0
    while d.best is not None and len(adds) < max_steps:
        adds.append((d.best.family, d.best.target))
        r = run(model, trial, add=list(adds), first=d0, **options)
        d = r.final
        if d.best is not None and (d.best.family, d.best.target) in adds:
            break
    effects = r.final_effects() if r is not None else []
    return d0, d, effects, [f"{f}:{t}" for f, t in adds]


def frame_position(model, target: str) -> np.ndarray | None:
    """World position of frame ``target`` of the pinmsk model with every coordinate at zero."""
    import pinocchio as pin
    try:
        fid = model.frame_id(target)
    except Exception:
        return None
    pm = model.pin
    data = pm.createData()
    pin.framesForwardKinematics(pm, data, pin.neutral(pm))
    return np.array(data.oMf[fid].translation)


def site_position(model, eff) -> np.ndarray | None:
    """World position, every coordinate at zero, of where payload ``eff`` sits: its frame, or its point
    on a body (``<body>@com``, ``@end``, ``@axis``: :meth:`Payload.site`)."""
    p = frame_position(model, eff.target)
    if p is not None or not hasattr(eff, "site"):
        return p
    import pinocchio as pin
    try:
        j, point = eff.site(model)
    except Exception:
        return None
    pm = model.pin
    data = pm.createData()
    pin.forwardKinematics(pm, data, pin.neutral(pm))
    return np.array(data.oMi[j].act(np.asarray(point, dtype=float)))


def axis_distance(model, eff, point) -> tuple[float, float] | None:
    """``(distance along, distance off)`` of world ``point`` (coordinates at zero) from the axis of an
    ``@axis`` payload: where on its line the point is, and how far from the line."""
    if not str(eff.target).endswith("@axis"):
        return None
    import pinocchio as pin
    j, _ = eff.site(model)
    pm = model.pin
    data = pm.createData()
    pin.forwardKinematics(pm, data, pin.neutral(pm))
    u = np.asarray(pm.inertias[j].lever, dtype=float)
    u = data.oMi[j].rotation @ (u / np.linalg.norm(u))
    r = np.asarray(point, dtype=float) - data.oMi[j].translation
    along = float(r @ u)
    return along, float(np.linalg.norm(r - along * u))


def _matches(eff, t: dict, model) -> tuple[bool, str]:
    fam, tgt = eff.family, eff.target
    if fam != t["family"]:
        return False, ""
    if tgt == t["target"]:
        return True, "target"
    site = t.get("site", {})
    if fam == "payload" and str(tgt).endswith("@point"):
        if site.get("body") == str(tgt)[:-len("@point")]:
            return True, "a fitted point on the body"
        return False, ""
    if fam == "payload" and site.get("ground_at_zero") is not None and str(tgt).endswith("@axis"):
        along, off = axis_distance(model, eff, site["ground_at_zero"])
        if off <= 0.02:             # the true site is on the fitted axis: its distance is judged as a value
            return True, f"on the axis {1000 * off:.0f} mm off it, {along:.3f} m along"
        return False, ""
    if fam == "payload" and site.get("ground_at_zero") is not None and tgt:
        p = site_position(model, eff)
        if p is not None and np.linalg.norm(p - np.asarray(site["ground_at_zero"])) <= 0.02:
            return True, f"site within {1000 * np.linalg.norm(p - np.asarray(site['ground_at_zero'])):.0f} mm"
    return False, ""


def _match(eff, t: dict, model):
    """``(how, expected)``: ``eff`` is the truth effect ``t`` itself or one of its declared exact
    ``aliases`` (another family that changes the data identically, with its own values), else None."""
    ok, how = _matches(eff, t, model)
    if ok:
        if str(eff.target).endswith("@point"):
            return how, {**t, "params": {**t["params"], **dict(zip("xyz", map(float, t["site"]["location"])))}}
        if str(eff.target).endswith("@axis") and t.get("site", {}).get("ground_at_zero") is not None:
            along, _ = axis_distance(model, eff, t["site"]["ground_at_zero"])
            return how, {**t, "params": {**t["params"], "distance": along}}
        return how, t
    for a in t.get("aliases", ()):
        ok, how = _matches(eff, a, model)
        if ok:
            return f"alias {a['family']}:{a['target']}", a
    return None


def judge(info: dict, effects: list, model, *, k: float = 3.0) -> dict:
    """Each truth effect found (family, target or site), its values within ``k`` standard errors of the
    truth, and the added effects the truth does not hold."""
    found, extra = [], list(effects)
    for t in info["effects"]:
        hit = None
        for e in extra:
            m = _match(e, t, model)
            if m is not None:
                hit = (e, *m)
                break
        if hit is None:
            found.append({"truth": t, "found": None, "value_ok": False})
            continue
        e, how, expected = hit
        extra.remove(e)
        vals = {}
        ok = True
        for p, true in expected["params"].items():
            if p not in e.params:
                ok = False          # a truth parameter the fitted effect does not have: the names disagree
                vals[p] = {"true": true, "fit": None, "stderr": None, "within_stderr": False}
                continue
            if not e.params[p].vary:
                vals[p] = {"true": true, "fit": e.params[p].value, "held": True}
                continue            # held at its value by the fit (an end stop's transition): not judged
            got = e.params[p].value
            se = e.params[p].stderr
            err = got - true
            # no error: a value the model fixes (a planar model's out-of-plane offset) must be the truth's
            within_se = (abs(err) <= 1e-12 if se is None or not np.isfinite(se) else abs(err) <= k * se)
            vals[p] = {"true": true, "fit": got, "stderr": se, "within_stderr": bool(within_se),
                       "relative_error": float(err / true) if true else None}
            ok = ok and within_se
        found.append({"truth": t, "found": e.label, "how": how, "values": vals, "value_ok": ok})
    solved = all(f["found"] and f["value_ok"] for f in found) and not extra
    return {"effects": found, "extra": [e.label for e in extra], "solved": bool(solved)}


def describe_truth(info: dict) -> str:
    return ", ".join(f"{t['family']}:{t['target']} " + " ".join(f"{k}={v:.4g}" for k, v in t["params"].items())
                     for t in info["effects"]) or "none"


def describe(effect) -> str:
    out = []
    for n, p in effect.params.items():
        se = f" ± {p.stderr:.2g}" if p.stderr is not None and np.isfinite(p.stderr) else ""
        out.append(f"{n}={p.value:.4g}{se}")
    return f"{effect.label} ({', '.join(out)})"


def run_case(name: str, shared: Path, *, nonlinear: str | None = None, **options) -> dict:
    """Diagnose case ``name``, follow the suggestions, judge: a row of the table.  A refusal (a
    :class:`~pinmsk.errors.PinmskError`) is a row with ``error`` set."""
    from pinmsk.errors import PinmskError
    from pinmsk.io.tables import read_trial
    info = truth(name)
    path = model_path(info, shared)
    if path is None:
        return {"case": name, "skipped": f"model {info['model']} absent"}
    model = load_model(str(path), nonlinear)
    trial = read_trial(CASES / name / info["trial"])
    ext = external_loads(name, info, shared)
    if ext is not None:
        options.setdefault("external_loads", ext)
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d0, d, effects, labels = follow(model, trial, **options)
    except PinmskError as exc:
        return {"case": name, "truth": describe_truth(info), "error": str(exc),
                "seconds": time.perf_counter() - t0, "judge": {"solved": False}}
    sec = time.perf_counter() - t0
    top = d0.ranking[0] if d0.ranking else None
    j = judge(info, effects, model)
    j["solved"] = j["solved"] and d.verdict == "at_noise_floor"   # and the user is told it is done
    return {"case": name, "truth": describe_truth(info),
            "top": (describe(top.effect) + (" [sig]" if top.significant else " [not sig]")) if top else "-",
            "added": [describe(e) for e in effects], "order": labels, "verdict_first": d0.verdict,
            "verdict": d.verdict, "ratio_first": float(d0.ratio), "ratio": float(d.ratio),
            "judge": j, "seconds": sec}


def main(argv=None):
    from pinmsk.io.shared_data import shared_data_dir
    import argparse
    ap = argparse.ArgumentParser(description="the diagnosis on the OpenSim-generated cases, judged")
    ap.add_argument("cases", nargs="*")
    ap.add_argument("--nonlinear", default=None, help="load_model's nonlinear= (exact or fit)")
    ap.add_argument("--frames", default=None, help="comma-separated frames for payload candidates")
    ap.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    args = ap.parse_args(argv)
    names = args.cases or case_names()
    shared = shared_data_dir(required=True)
    opts = {"nonlinear": args.nonlinear}
    if args.frames:
        opts["frames"] = args.frames.split(",")
    rows = []
    for n in names:
        r = run_case(n, shared, **opts)
        rows.append(r)
        if "skipped" in r:
            print(f"{n}: skipped ({r['skipped']})")
            continue
        if "error" in r:
            print(f"{n} | truth {r['truth']} | refused: {r['error'][:160]} | FAILED | {r['seconds']:.1f} s")
            continue
        print(f"{n} | truth {r['truth']} | top {r['top']} | added {'; '.join(r['added']) or '-'} | "
              f"{r['verdict_first']} {r['ratio_first']:.2f}x -> {r['verdict']} {r['ratio']:.2f}x | "
              f"{'SOLVED' if r['judge']['solved'] else 'FAILED'} | {r['seconds']:.1f} s", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str) + "\n")
    return rows


if __name__ == "__main__":
    sys.path.insert(0, str(HERE.parents[1]))     # this checkout's pinmsk, not an installed one
    main()
