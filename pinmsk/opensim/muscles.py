"""OpenSim muscles -> pinmsk muscle-tendon models, with a note of everything not carried exactly.

:func:`muscle_from_osim` maps one muscle element -- its type and its
properties as the .osim XML gives them -- to a :class:`MappedMuscle`: the
pinmsk model type and its per-muscle parameters, the muscle's OpenSim
properties (with OpenSim's defaults for absent ones) and notes.
:func:`muscle_model_from_osim` maps all muscles of a model to one vectorised
pinmsk model, as a :class:`~pinmsk.muscles.MuscleSet` holds them.

============================  ===================================  =====================================
OpenSim                       pinmsk                               carried
============================  ===================================  =====================================
Thelen2003Muscle (thesis      :class:`~pinmsk.muscles.Thelen2003`  curves exact except the tendon toe,
curve constants)                                                   which the thesis rounds (noted with
                                                                   its measured error)
Thelen2003Muscle (other       :class:`~pinmsk.muscles.             curves exact (OpenSim's constants
constants)                    Thelen2003OpenSim`                   per muscle)
Millard2012EquilibriumMuscle  :class:`~pinmsk.muscles.Millard2012` quintic Bezier curves exact, fiber
                                                                   damping, OpenSim's curve adjustments
DeGrooteFregly2016Muscle      :class:`~pinmsk.muscles.DeGroote2016` curves exact, fiber damping
============================  ===================================  =====================================

Properties come as a mapping from the XML tag to its text (or a number or a
bool); a nested curve element (``ActiveForceLengthCurve`` ...) is a nested
mapping, or dotted keys (``"ActiveForceLengthCurve.minimum_value"``); an empty
element or text means "not set" (OpenSim's default).
:func:`properties_from_xml` builds that mapping from an ``xml.etree`` element.

Notes (:class:`MuscleNote`) say what is approximated (with the measured
maximum error), ignored (with why) or adjusted (OpenSim's own changes at
model finalization, which pinmsk applies too).  :func:`summarize_notes` groups
identical notes of many muscles into one line each.

:func:`opensim_static_optimization_capacity` reproduces what OpenSim's
StaticOptimization uses as a muscle's force at full activation, which is
*not* the muscle's physical active force along the tendon for Millard 2012 and
De Groote 2016 muscles (see there).
"""
from __future__ import annotations

import math
import re
from collections import defaultdict
from dataclasses import dataclass, field, fields
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ..errors import ModelError
from ..muscles._common import OpenSimMuscleProperties
from ..muscles.degroote2016 import DeGrooteFregly2016Muscle
from ..muscles.millard2012 import (ActiveForceLengthCurve, FiberForceLengthCurve, ForceVelocityCurve,
                                   Millard2012EquilibriumMuscle, TendonForceLengthCurve)
from ..muscles.models import MUSCLE_MODELS, DeGroote2016, Millard2012, Thelen2003, Thelen2003OpenSim
from ..muscles.tendon import thelen_tendon_force
from ..muscles.thelen2003 import A_F, F_HAT, FV_EXTRAPOLATION, GAMMA, K_PE, PASSIVE_STRAIN0

__all__ = ["MUSCLE_TYPES", "MappedMuscle", "MuscleModelImport", "MuscleNote", "Thelen2003Muscle",
           "muscle_from_osim", "muscle_model_from_osim", "opensim_static_optimization_capacity",
           "properties_from_xml", "summarize_notes"]


# --------------------------------------------------------------------------- OpenSim Thelen
@dataclass(frozen=True)
class Thelen2003Muscle(OpenSimMuscleProperties):
    """The properties of one OpenSim ``Thelen2003Muscle``, with OpenSim's names, defaults and bounds."""

    FmaxTendonStrain: float = 0.04
    FmaxMuscleStrain: float = 0.6
    KshapeActive: float = 0.45
    KshapePassive: float = 5.0
    Af: float = 0.25
    Flen: float = 1.4
    fv_linear_extrap_threshold: float = 0.95
    maximum_pennation_angle: float = math.acos(0.1)
    activation_time_constant: float = 0.015
    deactivation_time_constant: float = 0.050
    minimum_activation: float = 0.01
    default_activation: float = 0.05
    default_fiber_length: float = 0.1

    def __post_init__(self):
        self._check_properties("FmaxTendonStrain", "FmaxMuscleStrain", "KshapeActive", "KshapePassive", "Af",
                               "activation_time_constant", "deactivation_time_constant")
        need = self._require
        need(self.Flen > 1.0, "Flen", "> 1")
        need(1.0 / self.Flen < self.fv_linear_extrap_threshold < 1.0, "fv_linear_extrap_threshold",
             f"in (1/Flen = {1.0 / self.Flen:g}, 1)")
        need(0.0 <= self.maximum_pennation_angle <= math.pi / 2, "maximum_pennation_angle", "in [0, pi/2]")

    def thesis_curves(self) -> bool:
        """Whether the curve constants are pinmsk's :class:`~pinmsk.muscles.Thelen2003` ones."""
        return (self.FmaxMuscleStrain, self.KshapeActive, self.KshapePassive, self.Af, self.Flen,
                self.fv_linear_extrap_threshold) == (PASSIVE_STRAIN0, GAMMA, K_PE, A_F, F_HAT,
                                                     FV_EXTRAPOLATION)

    def model_parameters(self) -> dict:
        """Keyword arguments of :class:`pinmsk.muscles.Thelen2003OpenSim` (SI units)."""
        return dict(f_max=float(self.max_isometric_force), l_opt=float(self.optimal_fiber_length),
                    l_slack=float(self.tendon_slack_length),
                    pennation=float(self.pennation_angle_at_optimal),
                    v_max=float(self.max_contraction_velocity * self.optimal_fiber_length),
                    tendon_strain=float(self.FmaxTendonStrain), passive_strain=float(self.FmaxMuscleStrain),
                    active_shape=float(self.KshapeActive), passive_shape=float(self.KshapePassive),
                    fv_shape=float(self.Af), eccentric_force=float(self.Flen),
                    fv_extrapolation=float(self.fv_linear_extrap_threshold),
                    max_pennation=float(self.maximum_pennation_angle),
                    tau_rise=float(self.activation_time_constant),
                    tau_fall=float(self.deactivation_time_constant))


# --------------------------------------------------------------------------- results
@dataclass(frozen=True)
class MuscleNote:
    """One thing about one muscle that pinmsk does not carry exactly (or that OpenSim itself changes).

    ``kind``: ``"approximated"`` (``max_error`` measured, in ``unit``, over ``domain``),
    ``"ignored"`` (not used by pinmsk's muscle model; ``detail`` says what it
    affects), ``"adjusted"`` (OpenSim changes the value when it finalizes the model;
    pinmsk uses OpenSim's value too), ``"unknown"`` (a property pinmsk does not
    know for this type; ignored) or ``"disabled"`` (``appliesForce`` false).
    """

    muscle: str
    kind: str
    what: str
    detail: str
    max_error: float | None = None
    unit: str = ""
    domain: str = ""

    def __str__(self) -> str:
        err = ""
        if self.max_error is not None:
            err = f" (max error {self.max_error:.3g}{' ' + self.unit if self.unit else ''}"
            err += f" over {self.domain})" if self.domain else ")"
        return f"{self.muscle}: {self.kind}: {self.what}: {self.detail}{err}"


@dataclass(frozen=True)
class MappedMuscle:
    """One OpenSim muscle mapped to pinmsk.

    ``model_type``: the pinmsk model (a key of :data:`pinmsk.muscles.models.MUSCLE_MODELS`);
    ``parameters``: that model's keyword arguments for this muscle (scalars, SI);
    ``tendon``: ``"rigid"`` or ``"compliant"`` (OpenSim's ``ignore_tendon_compliance``);
    ``opensim``: the OpenSim properties (defaults filled in); ``applies_force`` and
    ``control_bounds`` (``min_control``, ``max_control``: OpenSim's excitation bounds,
    which its static optimization uses as activation bounds) are not part of the
    muscle model and are left to the caller.
    """

    name: str
    element_type: str
    model_type: str
    parameters: Mapping[str, float]
    tendon: str
    opensim: Any
    applies_force: bool = True
    control_bounds: tuple[float, float] = (0.0, 1.0)
    notes: tuple[MuscleNote, ...] = ()

    def model(self):
        """This muscle alone as a pinmsk muscle-tendon model."""
        return MUSCLE_MODELS[self.model_type](names=[self.name], **self.parameters)


@dataclass(frozen=True)
class MuscleModelImport:
    """All muscles of a model mapped to one vectorised pinmsk muscle-tendon model.

    ``mtu``: the model (muscles in input order); ``model_type``; ``tendon``: the
    MuscleSet tendon mode the OpenSim muscles ask for (``"compliant"`` only when
    all have compliant tendons); ``muscles``: the per-muscle mappings; ``notes``: all
    their notes plus model-level ones.
    """

    mtu: Any
    model_type: str
    tendon: str
    muscles: tuple[MappedMuscle, ...]
    notes: tuple[MuscleNote, ...] = field(default=())


# --------------------------------------------------------------------------- properties
#: OpenSim's ``min_control`` of a muscle that does not set it: Thelen2003Muscle and
#: Millard2012EquilibriumMuscle set it to their default ``minimum_activation`` (0.01) when constructed,
#: before the XML is read (``constructProperties``: ``setMinControl(get_minimum_activation())``); other
#: muscles keep Muscle's 0.
DEFAULT_MIN_CONTROL = {"Thelen2003Muscle": 0.01, "Millard2012EquilibriumMuscle": 0.01}
#: The OpenSim muscle types pinmsk maps.
MUSCLE_TYPES = ("Thelen2003Muscle", "Millard2012EquilibriumMuscle", "DeGrooteFregly2016Muscle")

_CURVE_CLASSES = {"ActiveForceLengthCurve": ActiveForceLengthCurve,
                  "FiberForceLengthCurve": FiberForceLengthCurve,
                  "ForceVelocityCurve": ForceVelocityCurve,
                  "TendonForceLengthCurve": TendonForceLengthCurve}
_MILLARD_CURVE_FIELD = {"ActiveForceLengthCurve": "active_force_length_curve",
                        "FiberForceLengthCurve": "fiber_force_length_curve",
                        "ForceVelocityCurve": "force_velocity_curve",
                        "TendonForceLengthCurve": "tendon_force_length_curve"}
_OPENSIM_CLASSES = {"Thelen2003Muscle": Thelen2003Muscle,
                    "Millard2012EquilibriumMuscle": Millard2012EquilibriumMuscle,
                    "DeGrooteFregly2016Muscle": DeGrooteFregly2016Muscle}

#: Properties of the OpenSim base classes (Object, Force, Actuator, PathActuator, Muscle) that do not
#: enter a muscle's force: the path is mapped elsewhere (pinmsk.opensim.paths).
_NOT_MECHANICAL = {"GeometryPath", "path", "optimal_force", "appliesForce", "isDisabled", "min_control",
                   "max_control", "name", "Appearance", "components", "statebounds_activation",
                   "default_activation", "default_fiber_length", "default_normalized_tendon_force",
                   "ignore_activation_dynamics", "socket_parent_frame", "authors", "references"}
#: Properties that shape activation dynamics or forward integration only: pinmsk notes them as ignored.
_DYNAMICS_ONLY = {
    "minimum_activation": "OpenSim clamps activation to at least this value; pinmsk's solvers bound "
                          "activation themselves",
    "tendon_compliance_dynamics_mode": "Moco's explicit/implicit tendon dynamics; no effect on forces",
}

_NUMBER = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*$")


def properties_from_xml(element) -> dict:
    """A muscle element's properties as :func:`muscle_from_osim` takes them (``xml.etree`` element).

    Leaf children map to their text; children with children (the curve objects)
    to nested dicts.  ``GeometryPath`` is skipped (paths are mapped elsewhere).
    """
    out: dict = {}
    for child in element:
        tag = child.tag
        if not isinstance(tag, str) or tag == "GeometryPath":
            continue
        out[tag] = properties_from_xml(child) if len(child) else (child.text or "").strip()
    return out


def _flatten(props: Mapping, where: str) -> dict:
    """Dotted keys (``"ActiveForceLengthCurve.minimum_value"``) folded into nested dicts."""
    out: dict = {}
    for key, value in props.items():
        if not isinstance(key, str):
            raise ModelError(f"{where}: property names must be strings, got {key!r}")
        head, _, rest = key.replace("/", ".").partition(".")
        if rest:
            sub = out.setdefault(head, {})
            if not isinstance(sub, dict):
                raise ModelError(f"{where}: property {head!r} is given both as a value and with children")
            sub[rest] = value
        elif isinstance(value, Mapping):
            out.setdefault(head, {}).update(value)
        else:
            out[head] = value
    return out


def _unset(value) -> bool:
    return value is None or (isinstance(value, str) and not value.strip())


def _number(value, prop: str, where: str) -> float:
    if isinstance(value, bool):
        raise ModelError(f"{where}: {prop} = {value!r} must be a number")
    if isinstance(value, (int, float, np.floating, np.integer)):
        x = float(value)
    elif isinstance(value, str) and _NUMBER.match(value):
        x = float(value)
    else:
        raise ModelError(f"{where}: {prop} = {value!r} is not a number")
    if not math.isfinite(x):
        raise ModelError(f"{where}: {prop} = {value!r} is not finite")
    return x


def _boolean(value, prop: str, where: str) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, str) and value.strip().lower() in ("true", "false"):
        return value.strip().lower() == "true"
    raise ModelError(f"{where}: {prop} = {value!r} must be true or false")


def _typed(cls, values: Mapping, where: str, notes: list, muscle: str, prefix: str = "") -> dict:
    """``values`` converted to the field types of the dataclass ``cls``; unknown keys noted."""
    kinds = {f.name: f.type for f in fields(cls)}
    out = {}
    for key, value in values.items():
        if key not in kinds:
            continue
        if _unset(value):
            continue                          # OpenSim's default (also for the optional curve settings)
        kind = str(kinds[key])
        if "bool" in kind:
            out[key] = _boolean(value, prefix + key, where)
        elif kind == "str":
            out[key] = str(value).strip()
        else:
            out[key] = _number(value, prefix + key, where)
    return out


def _build(cls, kwargs, where):
    try:
        return cls(**kwargs)
    except ModelError as exc:
        raise ModelError(f"{where}: {exc}") from None


# --------------------------------------------------------------------------- mapping
def _tendon_toe_error(strain0: float) -> float:
    """Max |thesis - OpenSim| Thelen tendon force (F_max) over strains 0 .. 2 strain0."""
    eps = np.linspace(0.0, 2.0 * strain0, 4001)
    return float(np.max(np.abs(thelen_tendon_force(eps, strain0=strain0)
                               - thelen_tendon_force(eps, strain0=strain0, exact_toe=True))))


def muscle_from_osim(element_type: str, properties: Mapping, *, name: str | None = None,
                     where: str | None = None) -> tuple[MappedMuscle, list[MuscleNote]]:
    """Map one OpenSim muscle to pinmsk: ``(MappedMuscle, notes)``.

    ``element_type``: the XML element name (``"Millard2012EquilibriumMuscle"``, ...);
    ``properties``: its properties (see the module docstring; ``name`` defaults to
    ``properties["name"]``); ``where``: a location for error messages (e.g.
    ``"arm26.osim:123: <Thelen2003Muscle name="TRIlong">"``).  Absent properties take
    OpenSim's defaults.  Raises :class:`~pinmsk.errors.ModelError` naming the muscle
    and the property for an unsupported type, a non-numeric value or a value out
    of OpenSim's bounds.
    """
    name = str(name if name is not None else properties.get("name", "") or "")
    where = where or f"<{element_type} name={name!r}>"
    if element_type not in MUSCLE_TYPES:
        raise ModelError(f"{where}: muscle type {element_type} is not supported; pinmsk maps "
                         f"{', '.join(MUSCLE_TYPES)} (replace it in OpenSim, e.g. with "
                         "DeGrooteFregly2016Muscle.replaceMuscles)")
    props = _flatten(properties, where)
    notes: list[MuscleNote] = []
    note = lambda kind, what, detail, **kw: notes.append(MuscleNote(name, kind, what, detail, **kw))
    cls = _OPENSIM_CLASSES[element_type]
    own = {f.name for f in fields(cls)}
    known = own | _NOT_MECHANICAL | (set(_CURVE_CLASSES) if cls is Millard2012EquilibriumMuscle else set())
    for key in props:
        if key not in known:
            note("unknown", key, f"not a {element_type} property pinmsk knows; ignored")
    applies = _boolean(props["appliesForce"], "appliesForce", where) if not _unset(props.get("appliesForce")) \
        else not (_boolean(props["isDisabled"], "isDisabled", where) if not _unset(props.get("isDisabled"))
                  else False)
    if not applies:
        note("disabled", "appliesForce", "false: OpenSim applies no force of this muscle")
    bounds = tuple(_number(props[k], k, where) if not _unset(props.get(k)) else d
                   for k, d in (("min_control", DEFAULT_MIN_CONTROL.get(element_type, 0.0)), ("max_control", 1.0)))
    for key, why in _DYNAMICS_ONLY.items():
        if key in own and not _unset(props.get(key)):
            note("ignored", key, f"{props[key]}: {why}")

    kwargs = _typed(cls, props, where, notes, name)
    if element_type == "Millard2012EquilibriumMuscle":
        for tag, fname in _MILLARD_CURVE_FIELD.items():
            sub = props.get(tag)
            if _unset(sub):
                continue
            if not isinstance(sub, Mapping):
                raise ModelError(f"{where}: {tag} must be a curve element with properties, got {sub!r}")
            curve_cls = _CURVE_CLASSES[tag]
            ckeys = {f.name for f in fields(curve_cls)} | {"name"}
            for key in sub:
                if key not in ckeys:
                    note("unknown", f"{tag}.{key}", f"not a {tag} property pinmsk knows; ignored")
            kwargs[fname] = _build(curve_cls, _typed(curve_cls, sub, where, notes, name, tag + "."),
                                   f"{where}: {tag}")
    osim = _build(cls, kwargs, where)
    tendon = "rigid" if osim.ignore_tendon_compliance else "compliant"
    activation = ("pinmsk's activation dynamics (Winters-Stark, thesis Eq. A.2) with OpenSim's time "
                  "constants {:g} s / {:g} s; OpenSim's {} differs in form (affects excitations and "
                  "forward simulation, not forces)")

    if element_type == "Thelen2003Muscle":
        params = osim.model_parameters()
        note("ignored", "activation dynamics", activation.format(
            osim.activation_time_constant, osim.deactivation_time_constant,
            "first-order model with time constants scaled by 0.5 + 1.5 a"))
        if osim.thesis_curves():
            model_type = "thelen2003"
            params = {k: params[k] for k in ("f_max", "l_opt", "l_slack", "pennation", "v_max",
                                              "tau_rise", "tau_fall")}
            params["tendon_strain0"] = float(osim.FmaxTendonStrain)
            note("approximated", "tendon force-length",
                 "pinmsk's Thelen2003 uses the thesis' rounded toe constants (0.609 strain0, "
                 "1.712/strain0); OpenSim the exact ones", max_error=_tendon_toe_error(osim.FmaxTendonStrain),
                 unit="F_max", domain=f"tendon strain 0..{2 * osim.FmaxTendonStrain:g}")
            note("approximated", "force-velocity",
                 "identical for v >= -(0.25 + 0.75 a) v_max; faster shortening: pinmsk continues the "
                 "curve linearly below 0, OpenSim floors it at 0")
            if osim.pennation_angle_at_optimal > 0:
                floor = (osim.optimal_fiber_length * math.sin(osim.pennation_angle_at_optimal)
                         / math.sin(max(osim.maximum_pennation_angle, 1e-300)))
                note("ignored", "maximum_pennation_angle",
                     f"{osim.maximum_pennation_angle:g} rad: pinmsk's Thelen2003 has no fiber-length floor "
                     f"(OpenSim gives no force at or below {floor:.4g} m, the fiber length at that angle)")
        else:
            model_type = "thelen2003_opensim"
    elif element_type == "Millard2012EquilibriumMuscle":
        model_type = "millard2012"
        effective, changes = osim.effective()
        for c in changes:
            note("adjusted", "curve settings", c)
        params = osim.model_parameters()
        note("ignored", "activation dynamics", activation.format(
            osim.activation_time_constant, osim.deactivation_time_constant,
            "first-order model with time constants scaled by 0.5 + 1.5 a"))
    else:
        model_type = "degroote2016"
        params = osim.model_parameters()
        note("ignored", "activation dynamics", activation.format(
            osim.activation_time_constant, osim.deactivation_time_constant,
            f"tanh-smoothed model (activation_dynamics_smoothing {osim.activation_dynamics_smoothing:g})"))
    mapped = MappedMuscle(name=name, element_type=element_type, model_type=model_type,
                          parameters=params, tendon=tendon, opensim=osim, applies_force=applies,
                          control_bounds=bounds, notes=tuple(notes))
    return mapped, notes


def muscle_model_from_osim(muscles: Iterable[tuple[str, str, Mapping]], *,
                           where: Sequence[str] | None = None) -> MuscleModelImport:
    """Map a model's muscles -- ``(name, element_type, properties)`` each -- to one pinmsk model.

    All muscles of one pinmsk model share its type: Thelen2003Muscles map to
    :class:`~pinmsk.muscles.Thelen2003` only if all have the thesis curve
    constants and one tendon strain, else all to
    :class:`~pinmsk.muscles.Thelen2003OpenSim` (exact).  A model mixing OpenSim
    muscle families (e.g. Thelen and Millard) is refused by name.  ``where``: one
    location per muscle for error messages.
    """
    muscles = list(muscles)
    if not muscles:
        raise ModelError("the model has no muscles to map")
    mapped: list[MappedMuscle] = []
    notes: list[MuscleNote] = []
    for i, (name, etype, props) in enumerate(muscles):
        m, n = muscle_from_osim(etype, props, name=name, where=where[i] if where else None)
        mapped.append(m)
        notes.extend(n)
    families = defaultdict(list)
    for m in mapped:
        families[m.element_type].append(m.name)
    if len(families) > 1:
        listing = "; ".join(f"{t}: {', '.join(v[:5])}{' ...' if len(v) > 5 else ''}"
                            for t, v in families.items())
        raise ModelError(f"pinmsk holds one muscle model per model, but this one mixes {len(families)} "
                         f"OpenSim muscle types ({listing}); convert them to one type in OpenSim")
    types = {m.model_type for m in mapped}
    strains = {m.parameters.get("tendon_strain0") for m in mapped if m.model_type == "thelen2003"}
    if types == {"thelen2003"} and len(strains) > 1:
        notes.append(MuscleNote("(all)", "adjusted", "muscle model",
                                "the Thelen2003Muscles differ in FmaxTendonStrain, which pinmsk's Thelen2003 "
                                "holds once per model: all map to Thelen2003OpenSim (exact)"))
    if len(types) > 1 or (types == {"thelen2003"} and len(strains) > 1):
        # some Thelen muscles need the per-muscle constants: all take the exact OpenSim curves
        mapped = [_as_thelen_opensim(m) for m in mapped]
        notes = [n for n in notes if not (n.kind == "approximated" and n.what in
                                          ("tendon force-length", "force-velocity"))
                 and n.what != "maximum_pennation_angle"]
        types = {"thelen2003_opensim"}
    model_type = types.pop()
    cls = MUSCLE_MODELS[model_type]
    keys = list(mapped[0].parameters)
    columns: dict = {}
    for k in keys:
        if k == "tendon_strain0":
            columns[k] = mapped[0].parameters[k]
        else:
            columns[k] = np.array([m.parameters[k] for m in mapped], dtype=float)
    for k in ("tau_rise", "tau_fall"):
        vals = columns[k]
        if np.ptp(vals) > 0:
            notes.append(MuscleNote("(all)", "approximated", k,
                                    f"pinmsk holds one activation time constant per model; the muscles' "
                                    f"range {vals.min():g}..{vals.max():g} s, using the median"))
        columns[k] = float(np.median(vals))
    names = [m.name for m in mapped]
    try:
        mtu = cls(names=names, **columns)
    except ModelError as exc:
        raise ModelError(f"muscles: {exc}") from None
    tendons = {m.tendon for m in mapped}
    tendon = "compliant" if tendons == {"compliant"} else "rigid"
    if len(tendons) > 1:
        rigid = [m.name for m in mapped if m.tendon == "rigid"]
        notes.append(MuscleNote("(all)", "approximated", "tendon",
                                f"{len(rigid)} muscle(s) ignore tendon compliance ({', '.join(rigid[:5])}"
                                f"{' ...' if len(rigid) > 5 else ''}), the others do not; pinmsk's MuscleSet "
                                "has one tendon mode: rigid"))
    return MuscleModelImport(mtu=mtu, model_type=model_type, tendon=tendon, muscles=tuple(mapped),
                             notes=tuple(notes))


def _as_thelen_opensim(m: MappedMuscle) -> MappedMuscle:
    if m.model_type == "thelen2003_opensim":
        return m
    return MappedMuscle(name=m.name, element_type=m.element_type, model_type="thelen2003_opensim",
                        parameters=m.opensim.model_parameters(), tendon=m.tendon, opensim=m.opensim,
                        applies_force=m.applies_force, control_bounds=m.control_bounds,
                        notes=tuple(n for n in m.notes if n.kind != "approximated"))


def summarize_notes(notes: Iterable[MuscleNote], *, max_names: int = 6) -> list[str]:
    """One line per distinct note, naming the muscles it applies to (errors: the largest)."""
    groups: dict = defaultdict(list)
    for n in notes:
        groups[(n.kind, n.what, n.detail, n.unit, n.domain)].append(n)
    lines = []
    for (kind, what, detail, unit, domain), ns in groups.items():
        names = [n.muscle for n in ns]
        who = ", ".join(names[:max_names]) + (f" and {len(names) - max_names} more" if len(names) > max_names
                                                else "")
        errs = [n.max_error for n in ns if n.max_error is not None]
        err = ""
        if errs:
            err = (f" (max error {max(errs):.3g}{' ' + unit if unit else ''}"
                   f"{' over ' + domain if domain else ''})")
        lines.append(f"{kind}: {what}: {detail}{err} [{len(names)} muscle(s): {who}]")
    return lines


# --------------------------------------------------------------------------- OpenSim SO
def opensim_static_optimization_capacity(mtu, l_mt, v_mt) -> np.ndarray:
    """The force (N) OpenSim's StaticOptimization takes for each muscle at full activation.

    OpenSim's static optimization sets each muscle's force to ``a F_opt`` with
    ``F_opt = calcInextensibleTendonActiveFiberForce(s, 1)`` and no passive force.
    For Thelen 2003 that is the active force along the tendon (``force_limits``'
    ``F_active``), but not for the other two:

    - Millard2012EquilibriumMuscle evaluates the pennation angle at the
      *normalized* fiber length (``asin(h / (l_ce / l_opt))``, h in metres), so a
      pennated muscle's capacity is almost unprojected;
    - DeGrooteFregly2016Muscle returns the active *fiber* force, not projected
      on the tendon (no ``cos(alpha)``).

    Use this to reproduce OpenSim's SO activations like for like; the muscle
    models' ``force_limits`` give the physical forces.  ``l_mt``, ``v_mt``: (N, m).
    """
    if isinstance(mtu, (Thelen2003, Thelen2003OpenSim)):
        return mtu.force_limits(l_mt, v_mt)[0]
    if not isinstance(mtu, (Millard2012, DeGroote2016)):
        raise ModelError(f"no OpenSim static-optimization capacity for {type(mtu).__name__} muscles")
    slack, l_ce, _, _, fl, _, fv = mtu.rigid_curves(l_mt, v_mt)
    f = mtu.f_max * fl * fv
    if isinstance(mtu, Millard2012):
        l_norm = l_ce / mtu.l_opt
        sin_max = np.sin(mtu.max_pennation)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = mtu.height / l_norm
        pennated = mtu.pennation > np.finfo(float).eps
        phi = np.where(pennated & (l_norm > mtu.l_min) & (s < sin_max), np.arcsin(np.minimum(s, 1.0)),
                       np.where(pennated, mtu.max_pennation, 0.0))
        f = np.where(l_ce <= mtu.l_min, 0.0, f * np.cos(phi))
    return np.where(slack, 0.0, f)
