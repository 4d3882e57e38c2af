"""Contacts declared in a model sidecar: ``[[contacts]]`` entries -> components.

Schema (TOML; one table per sphere; SI units)::

    [[contacts]]
    type = "hypervolumetric"     # "point" (alias "hunt_crossley") | "volumetric" | "hypervolumetric"
    frame = "heel_r"             # the body frame the sphere is fixed to
    radius = 0.050               # m: R of the volumetric spheres, L0 of the point contact (optional)
    center = "sole"              # optional: "sole" (centre one radius above the frame, along the
                                 #   frame's y), "frame" (centre at the frame) or [x, y] (m, frame axes);
                                 #   default "sole" for frames named heel_/metatarsal_/toe_ + r|l
                                 #   (gait2d's sole points), else "frame"
    ground_speed = 0.0           # optional, m/s along x (treadmill belt)
    smoothing = 1e-4             # optional, m (smooth positive part of the penetration)
    k_h = 8.0e5                  # any model parameter by name (or inside a [contacts.params] table):
    H = 0.74                     #   point: k_s n_s a_s L0; volumetric: k_v a_v R;
    mu_f = 0.2                   #   hypervolumetric: k_h a_h R H; all: mu_f v_s dx dy
    bounds = { R = [0.001, 0.055] }   # optional per-parameter [lo, hi]
    fixed = ["mu_f"]             # optional: parameters a fit must not change (default: all vary
                                 #   except dx, dy)

Parameters not given take the thesis optimum of Tables 4.2-4.4 for the site named by
the frame (``heel``, ``metatarsal``, ``toe``, with or without ``_r``/``_l``), else the
class defaults; for those sites the radius bound is the table's.
"""
from __future__ import annotations

import re
from typing import Any, Mapping

from ..errors import ModelError
from .foot import KINDS, RADIUS_UPPER, THESIS_VALUES

ALIASES = {"hunt_crossley": "point", "huntcrossley": "point", "point": "point",
           "volumetric": "volumetric", "linear_volumetric": "volumetric",
           "hypervolumetric": "hypervolumetric", "hyper_volumetric": "hypervolumetric"}
_KEYS = {"type", "frame", "radius", "center", "ground_speed", "smoothing", "params", "bounds", "fixed"}
_SOLE = re.compile(r"^(heel|metatarsal|toe)_(r|l)$")
_SITE = re.compile(r"^(heel|metatarsal|toe)(_(r|l))?$")


def from_spec(spec: Mapping[str, Any], *, where: str = "[[contacts]]"):
    """One contact component from a sidecar ``[[contacts]]`` table (see the module doc for the schema).

    ``where`` names the entry in error messages (e.g. ``"gait2d.toml [[contacts]] #3"``).
    """
    if not isinstance(spec, Mapping):
        raise ModelError(f"{where}: expected a table, got {type(spec).__name__}")
    typ = spec.get("type")
    if typ is None or str(typ).lower() not in ALIASES:
        raise ModelError(f"{where}: 'type' must be one of {', '.join(sorted(set(ALIASES)))}, got {typ!r}")
    kind = ALIASES[str(typ).lower()]
    cls = KINDS[kind]
    frame = spec.get("frame")
    if not isinstance(frame, str) or not frame:
        raise ModelError(f"{where}: give 'frame', the body frame the sphere is fixed to (e.g. \"heel_r\")")
    declared = {p.name for p in cls.parameters}
    params = dict(spec.get("params") or {})
    for k, v in spec.items():
        if k in _KEYS:
            continue
        if k not in declared:
            raise ModelError(f"{where} (frame {frame}): unknown key '{k}' for type '{kind}'; parameters are "
                             f"{', '.join(sorted(declared))}, options {', '.join(sorted(_KEYS))}")
        params[k] = v
    for k in params:
        if k not in declared:
            raise ModelError(f"{where} (frame {frame}): '{kind}' has no parameter '{k}' "
                             f"({', '.join(sorted(declared))})")
    if "radius" in spec:
        if cls.radius_name in params:
            raise ModelError(f"{where} (frame {frame}): give the radius once ('radius' or '{cls.radius_name}')")
        params[cls.radius_name] = spec["radius"]
    m = _SITE.match(frame)
    site = m.group(1) if m else None
    values = dict(THESIS_VALUES[kind][site]) if site else {}
    try:
        values.update({k: float(v) for k, v in params.items()})
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{where} (frame {frame}): parameter values must be numbers: {exc}") from None
    bounds = {cls.radius_name: (0.001, RADIUS_UPPER[site])} if site else {}
    for k, b in dict(spec.get("bounds") or {}).items():
        try:
            lo, hi = (float(x) for x in b)
        except (TypeError, ValueError):
            raise ModelError(f"{where} (frame {frame}): bounds for '{k}' must be [lo, hi], got {b!r}") from None
        bounds[k] = (lo, hi)
    center = spec.get("center", "sole" if _SOLE.match(frame) else "frame")
    if isinstance(center, str):
        if center not in ("sole", "frame"):
            raise ModelError(f"{where} (frame {frame}): center must be \"sole\", \"frame\" or [x, y], got {center!r}")
        center = None if center == "frame" else center
    try:
        c = cls(frame, ground_speed=float(spec.get("ground_speed", 0.0)),
                smoothing=float(spec.get("smoothing", 1e-4)), bounds=bounds, center=center, **values)
    except ModelError as exc:
        raise ModelError(f"{where} (frame {frame}): {exc}") from None
    fixed = spec.get("fixed") or ()
    if isinstance(fixed, str):
        fixed = (fixed,)
    for k in fixed:
        if k not in declared:
            raise ModelError(f"{where} (frame {frame}): 'fixed' names unknown parameter '{k}'")
    return c.fix(*fixed)
