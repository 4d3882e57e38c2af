"""C3D files through ``ezc3d`` (an optional extra: ``pip install pinmsk[c3d]``).

:func:`read_c3d` returns a :class:`C3DData` with

* ``markers`` -- a Trial of ``<label>_{x,y,z}`` in metres (the ``POINT:UNITS``
  parameter is honoured; residual < 0 or all-zero samples are gaps, then
  handled as in :func:`pinmsk.signals.gaps.fill_gaps`);
* ``analogs`` -- a Trial of every analog channel by label at the analog rate
  (values already scaled by ezc3d), in the file's label order; duplicate labels
  are an error;
* ``platforms`` -- one Trial per force platform (ezc3d's ``extract_forceplat_data``:
  ``ground_force_v[xyz]`` N, ``ground_force_p[xyz]`` m, ``ground_torque_[xyz]`` N m
  at the analog rate, in the lab frame), empty if the file has none.

No axis change is made: C3D labs are often z-up; map the axes to pinmsk's y-up
(``axes="xzy"``-style remapping is left to the caller; see :func:`remap_axes`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MissingDependencyError, TrialError
from ..signals.gaps import DEFAULT_MAX_GAP, fill_gaps
from ..trial import Trial
from .c3d_check import check_c3d_structure
from .trc import UNIT_SCALE

__all__ = ["read_c3d", "C3DData", "remap_axes", "require_ezc3d"]


def require_ezc3d():
    """Import ezc3d or raise :class:`~pinmsk.errors.MissingDependencyError` (an ImportError) telling how to install it."""
    try:
        import ezc3d  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingDependencyError(
            "reading C3D files needs the optional dependency 'ezc3d'; install it with "
            "`pip install pinmsk[c3d]` (or `pip install ezc3d` / `conda install -c conda-forge ezc3d`)"
        ) from exc
    return ezc3d


@dataclass
class C3DData:
    markers: Trial | None
    analogs: Trial | None
    platforms: list = field(default_factory=list)
    meta: dict = field(default_factory=dict)


def _unique(labels, path, what):
    seen, dup = set(), []
    for lab in labels:
        if lab in seen:
            dup.append(lab)
        seen.add(lab)
    if dup:
        raise TrialError(f"{path}: duplicate {what} label(s) {sorted(set(dup))}; duplicate column names are "
                         "ambiguous -- rename them in the acquisition software")


def read_c3d(path, *, max_gap: int = DEFAULT_MAX_GAP, platforms: bool = True) -> C3DData:
    """Read markers, analogs and force platforms of a C3D file (see the module docstring)."""
    ezc3d = require_ezc3d()
    path = Path(path)
    if not path.exists():
        raise TrialError(f"C3D file not found: {path}")
    check_c3d_structure(path)            # sizes that do not fit the file would hang or crash ezc3d
    try:
        c = ezc3d.c3d(str(path), extract_forceplat_data=platforms)
    except (OSError, RuntimeError, ValueError, IndexError, KeyError) as exc:   # ezc3d's errors on a broken file
        raise TrialError(f"{path}: cannot read it as a C3D file ({' '.join(str(exc).split())})") from None
    try:
        return _contents(c, path, max_gap, platforms)
    except TrialError:
        raise
    except (KeyError, IndexError, TypeError, ValueError, ZeroDivisionError, AttributeError) as exc:
        # a parameter the file lacks or holds in another shape (POINT:RATE, ANALOG:LABELS, ...)
        raise TrialError(f"{path}: cannot read it as a C3D file ({type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:200]})") from None


def _contents(c, path: Path, max_gap: int, platforms: bool) -> C3DData:
    """The markers, analogs and platforms of ezc3d's reading ``c`` of ``path``."""
    P = c["parameters"]
    out = C3DData(None, None, [], {"source": str(path)})
    pts = c["data"]["points"]            # (4, M, N)
    first = int(c["header"]["points"]["first_frame"])
    if pts.shape[1] > 0:
        rate = float(P["POINT"]["RATE"]["value"][0])
        labels = [s.strip() for s in P["POINT"]["LABELS"]["value"]][:pts.shape[1]]
        _unique(labels, path, "marker")
        unit = P["POINT"].get("UNITS", {}).get("value", ["mm"])[0].strip() or "mm"
        scale = UNIT_SCALE.get(unit.lower())
        if scale is None:
            raise TrialError(f"{path}: unknown POINT:UNITS {unit!r}")
        xyz = pts[:3].transpose(2, 1, 0) * scale  # (N, M, 3)
        resid = c["data"].get("meta_points", {}).get("residuals")
        missing = np.all(xyz == 0, axis=2)
        if resid is not None:
            missing |= (np.asarray(resid)[0].T < 0)
        xyz[missing] = np.nan
        n = xyz.shape[0]
        t = (first + np.arange(n)) / rate
        chans = {f"{m}_{a}": xyz[:, j, i] for j, m in enumerate(labels) for i, a in enumerate("xyz")}
        mk = Trial(t, chans, units={k: "m" for k in chans},
                   meta={"source": str(path), "format": "c3d", "markers": tuple(labels), "units": unit,
                         "rate": rate})
        out.markers = fill_gaps(mk, max_gap=max_gap)
    an = c["data"]["analogs"]            # (1, C, N)
    if an.shape[1] > 0:
        arate = float(P["ANALOG"]["RATE"]["value"][0])
        labels = [s.strip() for s in P["ANALOG"]["LABELS"]["value"]][:an.shape[1]]
        _unique(labels, path, "analog")
        n = an.shape[2]
        prate = float(P["POINT"]["RATE"]["value"][0]) if "POINT" in P else arate
        t = first / prate + np.arange(n) / arate
        out.analogs = Trial(t, {lab: an[0, j] for j, lab in enumerate(labels)},
                            meta={"source": str(path), "format": "c3d", "rate": arate})
    if platforms and "platform" in c["data"]:
        for k, pf in enumerate(c["data"]["platform"]):
            f = np.asarray(pf["force"]).T
            m = np.asarray(pf["moment"]).T
            cop = np.asarray(pf["center_of_pressure"]).T
            tq = np.asarray(pf["Tz"]).T
            u = {"mm": 1e-3, "m": 1.0}
            lu = u.get(str(pf.get("unit_position", "mm")).strip(), 1e-3)
            mu = u.get(str(pf.get("unit_moment", "Nmm")).replace("N", "").strip(), 1e-3)
            n = f.shape[0]
            t = first / float(P["POINT"]["RATE"]["value"][0]) + np.arange(n) / float(P["ANALOG"]["RATE"]["value"][0])
            ch = {f"ground_force_v{a}": f[:, i] for i, a in enumerate("xyz")}
            ch.update({f"ground_force_p{a}": cop[:, i] * lu for i, a in enumerate("xyz")})
            ch.update({f"ground_torque_{a}": tq[:, i] * mu for i, a in enumerate("xyz")})
            out.platforms.append(Trial(t, ch, meta={"source": str(path), "platform": k + 1,
                                                    "moment_about_origin": m * mu}))
    return out


def remap_axes(trial: Trial, mapping: dict) -> Trial:
    """Rename/sign-flip axis suffixes, e.g. z-up lab to y-up: ``{"x": "x", "y": "-z", "z": "y"}``.

    Each new axis ``a`` takes the old axis ``mapping[a]`` (optionally negated with ``-``) for
    every channel ending in ``_x/_y/_z`` and for ``ground_force_v?``/``p?``/``ground_torque_?``.
    """
    d = trial.to_dict(); d.pop("time")
    out = {}
    for name, x in d.items():
        base, ax = None, None
        for suf in ("_x", "_y", "_z"):
            if name.endswith(suf):
                base, ax = name[:-1], suf[1]
        for pre in ("ground_force_v", "ground_force_p"):
            if name.startswith(pre) and len(name) == len(pre) + 1:
                base, ax = pre, name[-1]
        if base is None:
            out[name] = x
            continue
        out.setdefault("__pending__", []).append((base, ax))
    pending = out.pop("__pending__", [])
    bases = sorted({b for b, _ in pending})
    for b in bases:
        for new, old in mapping.items():
            sign = -1.0 if old.startswith("-") else 1.0
            src = f"{b}{old.lstrip('-')}"
            if src in d:
                out[f"{b}{new}"] = sign * d[src]
    return Trial(trial.time, out, units=dict(trial.units), meta=dict(trial.meta))
