"""Contacts declared in a model sidecar: ``[[contacts]]`` entries -> components (:func:`from_spec`), and
back (:func:`to_spec`, what ``pinmsk import`` writes).

Schema (TOML; one table per sphere; SI units).  The thesis's spheres against the ground y = 0::

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
    free = ["dx"]                # optional: parameters a fit may change that are fixed by default

Parameters not given take the thesis optimum of Tables 4.2-4.4 for the site named by
the frame (``heel``, ``metatarsal``, ``toe``, with or without ``_r``/``_l``), else the
class defaults; for those sites the radius bound is the table's.

OpenSim's sphere-half-space forces (:class:`~pinmsk.contact.SmoothSphereHalfSpaceForce`,
:class:`~pinmsk.contact.HuntCrossleyForce`; what ``pinmsk import`` writes for an OpenSim model's
``SmoothSphereHalfSpaceForce`` and ``HuntCrossleyForce``), with OpenSim's parameter names::

    [[contacts]]
    type = "SmoothSphereHalfSpaceForce"   # or "HuntCrossleyForce" (also their families
                                          #   "smooth_sphere_half_space", "hunt_crossley_force")
    frame = "heel_r"             # the frame of the ContactSphere (pinmsk import: a URDF link placed where
                                 #   OpenSim places the sphere, so the centre is at its origin)
    location = [0.0, 0.0, 0.0]   # optional: the sphere centre in the frame (m)
    plane_normal = [0.0, 1.0, 0.0]   # optional: the ContactHalfSpace's outward normal (world; its frame's -x)
    plane_point = [0.0, 0.0, 0.0]    # optional: a point of its surface (world, m)
    radius = 0.035               # the parameters, OpenSim's names: radius stiffness dissipation
    stiffness = 3067776.0        #   static_friction dynamic_friction viscous_friction transition_velocity;
    dissipation = 2.0            #   SmoothSphereHalfSpaceForce also constant_contact_force hertz_smoothing
                                 #   hunt_crossley_smoothing (OpenSim's defaults where absent)
    bounds, fixed, free          # as above

Unknown keys are refused with a "did you mean" (:func:`pinmsk.io.toml_files.check_keys`).
"""
from __future__ import annotations

import difflib
import re
from typing import Any, Mapping

from ..components import parameter_settings, read_parameter_settings
from ..errors import ModelError
from ..io.toml_files import check_keys
from .foot import KINDS, RADIUS_UPPER, THESIS_VALUES
from .half_space import HalfSpaceContact
from .hunt_crossley import HuntCrossleyForce
from .smooth_sphere import SmoothSphereHalfSpaceForce

__all__ = ["from_spec", "to_spec", "ALIASES", "HALF_SPACE_TYPES"]

#: OpenSim's sphere-half-space forces by their OpenSim class names (the ``type`` :func:`to_spec` writes).
HALF_SPACE_TYPES = {"SmoothSphereHalfSpaceForce": SmoothSphereHalfSpaceForce, "HuntCrossleyForce": HuntCrossleyForce}
#: ``type`` (lower case) -> the thesis kind (:data:`~pinmsk.contact.foot.KINDS`) or the OpenSim type.
ALIASES = {"hunt_crossley": "point", "huntcrossley": "point", "point": "point",
           "volumetric": "volumetric", "linear_volumetric": "volumetric",
           "hypervolumetric": "hypervolumetric", "hyper_volumetric": "hypervolumetric",
           **{name.lower(): name for name in HALF_SPACE_TYPES},
           **{cls.family: name for name, cls in HALF_SPACE_TYPES.items()}}
_SETTINGS = ("params", "bounds", "fixed", "free")
_KEYS = ("type", "frame", "radius", "center", "ground_speed", "smoothing") + _SETTINGS
_HALF_SPACE_KEYS = ("type", "frame", "location", "plane_normal", "plane_point") + _SETTINGS
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
        close = difflib.get_close_matches(str(typ).lower(), list(ALIASES), n=1)
        hint = f" (did you mean '{ALIASES[close[0]]}'?)" if close else ""
        raise ModelError(f"{where}: 'type' must be one of {', '.join(sorted(set(ALIASES.values())))}, got "
                         f"{typ!r}{hint}")
    kind = ALIASES[str(typ).lower()]
    cls = HALF_SPACE_TYPES.get(kind) or KINDS[kind]
    frame = spec.get("frame")
    if not isinstance(frame, str) or not frame:
        raise ModelError(f"{where}: give 'frame', the body frame the sphere is fixed to (e.g. \"heel_r\")")
    declared = [p.name for p in cls.parameters]
    entry = f"{where} (frame {frame})"
    check_keys(spec, [*(_HALF_SPACE_KEYS if kind in HALF_SPACE_TYPES else _KEYS), *declared], where=where,
               section=f"a '{kind}' contact (frame {frame})")
    params = dict(spec.get("params") or {})
    for k in params:
        if k not in declared:
            raise ModelError(f"{entry}: '{kind}' has no parameter '{k}' ({', '.join(sorted(declared))})")
    for k, v in spec.items():
        if k in declared:
            if k in params:
                raise ModelError(f"{entry}: parameter '{k}' is given twice (also in 'params')")
            params[k] = v
    try:
        values = {k: float(v) for k, v in params.items()}
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{entry}: parameter values must be numbers: {exc}") from None
    bounds, vary = read_parameter_settings(spec, declared, where=entry)
    try:
        if kind in HALF_SPACE_TYPES:
            c = cls(frame, bounds=bounds, **values,
                    **{k: spec[k] for k in ("location", "plane_normal", "plane_point") if k in spec})
        else:
            c = _thesis_sphere(cls, kind, frame, spec, values, bounds, entry)
        return c.with_params(vary=vary) if vary else c
    except ModelError as exc:
        raise ModelError(f"{entry}: {exc}") from None


def _thesis_sphere(cls, kind: str, frame: str, spec, values: dict, bounds: dict, entry: str):
    """A thesis sphere (:data:`~pinmsk.contact.foot.KINDS`): the site's Table 4.2-4.4 values and radius bound
    under the values and bounds given."""
    if "radius" in spec:
        if cls.radius_name in values:
            raise ModelError(f"give the radius once ('radius' or '{cls.radius_name}')")
        try:
            values[cls.radius_name] = float(spec["radius"])
        except (TypeError, ValueError):
            raise ModelError(f"radius must be a number, got {spec['radius']!r}") from None
    m = _SITE.match(frame)
    site = m.group(1) if m else None
    values = {**(THESIS_VALUES[kind][site] if site else {}), **values}
    bounds = {**({cls.radius_name: (0.001, RADIUS_UPPER[site])} if site else {}), **bounds}
    center = spec.get("center", "sole" if _SOLE.match(frame) else "frame")
    if isinstance(center, str):
        if center not in ("sole", "frame"):
            raise ModelError(f"center must be \"sole\", \"frame\" or [x, y], got {center!r}")
        center = None if center == "frame" else center
    try:
        ground_speed, smoothing = float(spec.get("ground_speed", 0.0)), float(spec.get("smoothing", 1e-4))
    except (TypeError, ValueError):
        raise ModelError("ground_speed and smoothing must be numbers") from None
    return cls(frame, ground_speed=ground_speed, smoothing=smoothing, bounds=bounds, center=center, **values)


def to_spec(component) -> dict:
    """The ``[[contacts]]`` table of a contact component, which :func:`from_spec` reads back to an equal
    component with the same bounds and ``vary`` flags: every parameter value and option written (standard
    errors of a fit are not).  A ModelError names a contact class the format has no entry for."""
    settings = parameter_settings(component)
    values = component.values
    if isinstance(component, HalfSpaceContact) and type(component) in HALF_SPACE_TYPES.values():
        name = next(n for n, c in HALF_SPACE_TYPES.items() if c is type(component))
        return {"type": name, "frame": component.target, "location": list(component.location),
                "plane_normal": list(component.plane_normal), "plane_point": list(component.plane_point),
                **values, **settings}
    kind = next((k for k, c in KINDS.items() if c is type(component)), None)
    if kind is None:
        raise ModelError(f"{component.label}: a sidecar [[contacts]] entry holds the types "
                         f"{', '.join([*KINDS, *HALF_SPACE_TYPES])}, not a {type(component).__name__}")
    m = _SITE.match(component.target)
    if m:       # from_spec gives a site's sphere the table's radius bound: write the bound unless it is that one
        p = component.params[component.radius_name]
        bounds = dict(settings.get("bounds", {}))
        if (p.min, p.max) == (0.001, RADIUS_UPPER[m.group(1)]):
            bounds.pop(component.radius_name, None)
        else:
            bounds[component.radius_name] = [p.min, p.max]
        settings = {k: v for k, v in {**settings, "bounds": bounds}.items() if v}
    center = component.center
    return {"type": kind, "frame": component.target,
            "center": "frame" if center is None else (center if isinstance(center, str) else list(center)),
            "ground_speed": component.ground_speed, "smoothing": component.smoothing, **values, **settings}
