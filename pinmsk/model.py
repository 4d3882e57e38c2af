"""The musculoskeletal Model (frozen) and its Data (a workspace), as in Pinocchio.

A :class:`Model` never changes once built: it cannot be assigned to, its
``meta`` is a read-only mapping and its component lists are tuples.  Changing
something returns a new model::

    model = pinmsk.load_model("forearm")
    heavier = model.with_effect(Payload("hand", mass=2.0))   # or model + effect
    fixed = heavier.fix("payload:hand.mass")                  # model.parameters: one table

Algorithms take ``(model, ...)`` and work in a :class:`Data` the caller owns
(``model.create_data()``: Pinocchio's ``Data`` plus a cache of the kinematics
computed for each :class:`~pinmsk.components.Motion`), so two threads with two
Data objects share no state.  ``model.pin`` is the Pinocchio model; pinmsk never
modifies it (e.g. :meth:`Model.with_gravity` builds a copy), and neither should
callers.

Built-in models are a URDF plus a TOML sidecar in ``urdf/`` (schema in
``urdf/README.md``); ``load_model`` also takes the path of a user's sidecar
(``.toml``) or a bare URDF (no muscles).  :func:`_load_sidecar` is the one
sidecar -> Pinocchio loader.
"""
from __future__ import annotations

import difflib
import warnings
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np
import pinocchio as pin

from . import builtin_models
from .actuators import from_spec as actuator_from_spec
from .components import Component, Motion, ParameterKeyError, Parameters
from .contact.spec import from_spec as contact_from_spec
from .effects import registry
from .errors import ModelError, PinmskError
from .skeleton import skeleton_constant
from . import kinematics
from .kinematics import DEFAULT_CUTOFF
from .muscles import NaganoGerritsen, Thelen2003
from .muscles.models import MUSCLE_MODELS, MUSCLE_PARAMETERS
from .muscles.muscle_set import MUSCLE_PREFIX, MuscleSet
from .muscles.paths import MomentArmPath, PolynomialPath
from .io.toml_files import check_keys, read_toml

#: Every key a model sidecar may hold (``urdf/README.md``), per table; others are errors.
#: ``[[effects]]`` keys are the effect's own (type, target, params, its options and
#: parameters), ``[[actuators]]`` and ``[[contacts]]`` keys the actuator's and the contact's,
#: checked where they are built.
SIDECAR_SCHEMA = {
    "model": {"name": "model name (default: the file name)", "urdf": "the skeleton (required)",
              "gravity": "[gx, gy, gz] m/s^2, world frame", "up_axis": "'x' | 'y' | 'z' (display)",
              "description": "one line", "default_paths": "path variant used by default",
              "coordinate_order": "order of q, v, tau in pinmsk (a permutation of the joints)",
              "osim": "the OpenSim model it was imported from (relative to the sidecar; the viewer draws its "
                      "geometric muscle paths)",
              "osim_digest": "blake2b digest of that .osim when the sidecar was written"},
    "muscle_model": {"type": "'thelen2003' | 'nagano_gerritsen' | (imported models) 'thelen2003_opensim' | "
                             "'millard2012' | 'degroote2016'",
                     "tendon": "'rigid' | 'compliant' (default for static analyses)",
                     "tendon_model": "the type's own tendon law (thelen2003: 'thelen2003'; "
                                     "nagano_gerritsen: 'winters_quadratic')",
                     "tendon_strain": "tendon strain at F_max (default 0.04)",
                     "parallel_elastic": "the type's own choice (thelen2003: true; nagano_gerritsen: false)",
                     "tau_rise": "activation time constant (s; the type's default)",
                     "tau_fall": "deactivation time constant (s; the type's default)"},
    "muscles": {"name": "muscle name", "f_max": "N", "l_opt": "m", "l_slack": "m", "pennation": "rad",
                "volume": "m^3", "fast_fraction": "0..1", "width": "Nagano & Gerritsen only",
                "paths": "path variants { l0, moment_arms } or a fitted polynomial", "points": "display polyline",
                # the other per-muscle parameters of the muscle models (MUSCLE_PARAMETERS), each for its types
                **{k: f"{p.unit or '-'}: {p.doc}" for k, p in MUSCLE_PARAMETERS.items()
                   if k not in ("f_max", "l_opt", "l_slack", "pennation", "volume", "fast_fraction", "width")}},
    "effects": None,
    "actuators": None,
    "contacts": None,
    "coordinate_map": "OpenSim's coordinates -> dependent joints (pinmsk.opensim.skeleton.MAP_KEYS)",
}
#: Keys of one path variant, ``paths.<variant> = { ... }`` of a muscle: moment-arm polynomials per
#: coordinate (``l0``, ``moment_arms``: MomentArmPath) or one polynomial of the length in the coordinates
#: the muscle crosses (the rest: PolynomialPath, as ``pinmsk import`` writes an OpenSim model's fit).
SIDECAR_PATH_KEYS = {"l0": "muscle-tendon length at q = 0 (m)",
                     "moment_arms": "{ coordinate = [c0, c1, ...] } (m)",
                     "coordinates": "the coordinates of the length polynomial",
                     "center": "x = (q - center) / scale, per coordinate", "scale": "per coordinate",
                     "exponents": "[[e per coordinate], ...] one row per term",
                     "coefficients": "one per term (m)",
                     "max_length_error": "the fit's largest length error against the geometric path (m)",
                     "max_moment_arm_error": "the fit's largest moment-arm error (m)"}
#: The tendon law and parallel element each muscle type implements (``[muscle_model]`` may
#: state them, but not ask for another).
_MUSCLE_LAWS = {"thelen2003": ("thelen2003", True), "nagano_gerritsen": ("winters_quadratic", False)}
#: Pinocchio's gravity for a model built from a URDF alone (the URDF/ROS z-up convention).
PINOCCHIO_GRAVITY = (0.0, 0.0, -9.81)


def _freeze(x):
    """A read-only copy of metadata: dicts become mappingproxies, lists tuples."""
    if isinstance(x, Mapping):
        return MappingProxyType({k: _freeze(v) for k, v in x.items()})
    if isinstance(x, (list, tuple)):
        return tuple(_freeze(v) for v in x)
    return x


def _thaw(x):
    """Plain dicts again (mappingproxies do not pickle)."""
    if isinstance(x, Mapping):
        return {k: _thaw(v) for k, v in x.items()}
    if isinstance(x, tuple):
        return tuple(_thaw(v) for v in x)
    return x


class Model:
    """A skeleton (Pinocchio model) with muscles, effects and contacts. Frozen.

    The constructor copies ``pin_model``, so changing it afterwards does not
    change the Model.  Attributes cannot be assigned; the ``with_*`` methods,
    :meth:`without`, :meth:`fix` and :meth:`free` return new models.
    """

    __slots__ = ("name", "muscles", "effects", "contacts", "meta", "coordinates",
                 "_pin", "_coord_index", "_parameters")

    def __init__(self, *, name: str, pin_model: pin.Model, muscles=None,
                 effects: Sequence[Component] = (), contacts: Sequence[Component] = (),
                 meta: Mapping | None = None):
        self._setup(name=name, pin_model=pin.Model(pin_model), muscles=muscles, effects=effects,
                    contacts=contacts, meta=meta)

    @classmethod
    def _make(cls, *, name, pin_model, muscles, effects, contacts, meta) -> "Model":
        """A model that shares ``pin_model`` (derived models of one skeleton; never modified)."""
        self = object.__new__(cls)
        self._setup(name=name, pin_model=pin_model, muscles=muscles, effects=effects,
                    contacts=contacts, meta=meta)
        return self

    def _setup(self, *, name, pin_model, muscles, effects, contacts, meta) -> None:
        if pin_model.nq != pin_model.nv:
            raise ModelError(
                f"model '{name}': pinmsk supports skeletons of 1-dof joints (nq == nv); "
                f"this one has nq={pin_model.nq}, nv={pin_model.nv}"
            )
        put = object.__setattr__
        put(self, "_pin", pin_model)
        put(self, "name", str(name))
        put(self, "muscles", muscles)
        put(self, "effects", tuple(effects))
        put(self, "contacts", tuple(contacts))
        put(self, "meta", _freeze(dict(meta or {})))
        put(self, "coordinates", tuple(pin_model.names[j] for j in range(1, pin_model.njoints)))
        put(self, "_coord_index", MappingProxyType({c: pin_model.joints[j].idx_v
                                                    for j, c in enumerate(pin_model.names) if j > 0}))
        put(self, "_parameters", None)
        for comp in self.effects + self.contacts:
            if not isinstance(comp, Component):
                raise ModelError(f"model '{name}': components must be Component instances, "
                                 f"not {type(comp).__name__}")
        labels = [c.label for c in self.effects + self.contacts]
        dup = sorted({x for x in labels if labels.count(x) > 1})
        if dup:
            raise ModelError(f"model '{name}': components {dup} appear twice; remove one first")
        for comp in self.effects + self.contacts:
            comp.check_target(self)

    def _derive(self, **changes) -> "Model":
        kw = dict(name=self.name, pin_model=self._pin, muscles=self.muscles, effects=self.effects,
                  contacts=self.contacts, meta=self.meta)
        kw.update(changes)
        return Model._make(**kw)

    def __setattr__(self, key, value):
        raise AttributeError(f"pinmsk.Model is immutable (cannot set '{key}'); use with_effect, without, "
                             "with_muscles, with_gravity, with_parameters, fix or free, which return a new model")

    def __delattr__(self, key):
        raise AttributeError(f"pinmsk.Model is immutable (cannot delete '{key}')")

    # -- skeleton -------------------------------------------------------
    @property
    def pin(self) -> pin.Model:
        """The Pinocchio model (read-only by convention: pinmsk never modifies it; copy it
        with ``pinocchio.Model(model.pin)`` to change something)."""
        return self._pin

    @property
    def nq(self) -> int:
        return self._pin.nq

    @property
    def nv(self) -> int:
        return self._pin.nv

    @property
    def n_muscles(self) -> int:
        return 0 if self.muscles is None else self.muscles.n

    @property
    def muscle_names(self) -> tuple[str, ...]:
        return () if self.muscles is None else self.muscles.names

    @property
    def gravity(self) -> np.ndarray:
        """Gravity in the world frame, (3,) m/s^2 (a read-only copy; see :meth:`with_gravity`)."""
        g = np.array(self._pin.gravity.linear, dtype=float)
        g.flags.writeable = False
        return g

    @property
    def mass(self) -> float:
        return float(sum(inert.mass for inert in self._pin.inertias))

    @property
    def components(self) -> tuple[Component, ...]:
        return self.effects + self.contacts

    def create_data(self) -> "Data":
        """A fresh workspace for this model: Pinocchio's ``Data`` plus a kinematics cache.

        Give one to each thread; see :class:`Data`.
        """
        return Data(self)

    def coordinate_index(self, name: str) -> int:
        """Column of coordinate ``name`` in ``q``/``v`` (ModelError with suggestions)."""
        try:
            return self._coord_index[name]
        except (KeyError, TypeError):
            close = difflib.get_close_matches(str(name), self.coordinates, n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise ModelError(
                f"model '{self.name}' has no coordinate '{name}'{hint} "
                f"(coordinates: {', '.join(self.coordinates)})"
            ) from None

    def frame_id(self, name: str) -> int:
        """Pinocchio frame id of a frame/body/joint ``name`` (ModelError with suggestions)."""
        if name is not None and self._pin.existFrame(name):
            return self._pin.getFrameId(name)
        names = [f.name for f in self._pin.frames]
        close = difflib.get_close_matches(str(name), names, n=3)
        hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
        raise ModelError(f"model '{self.name}' has no frame '{name}'{hint}")

    @property
    def coordinate_order(self) -> tuple[str, ...]:
        """Coordinates in the order the model's sidecar lists them (e.g. thesis Eq. 5.1 for
        gait2d), used for columns of written results.  Arrays (``q``, ``v``, ``tau``)
        follow :attr:`coordinates`, Pinocchio's depth-first joint order."""
        order = self.meta.get("coordinate_order")
        return tuple(order) if order else self.coordinates

    @property
    def rotational_coordinates(self) -> tuple[str, ...]:
        """Coordinates of revolute joints (radians; degrees in files that say inDegrees=yes)."""
        pm = self._pin
        return tuple(pm.names[j] for j in range(1, pm.njoints)
                     if pm.joints[j].shortname().startswith("JointModelR"))

    @property
    def frame_names(self) -> tuple[str, ...]:
        # keyed by the frame count too: import hooks may add frames (contact spheres) to a built skeleton
        pm = self._pin
        return skeleton_constant(pm, f"frame_names:{pm.nframes}", lambda m: tuple(f.name for f in m.frames))

    def with_gravity(self, gravity) -> "Model":
        """A new model whose skeleton (a copy) has ``gravity`` (3 finite numbers, m/s^2)."""
        pm = pin.Model(self._pin)
        _set_gravity(pm, gravity, f"model '{self.name}'")
        return self._derive(pin_model=pm)

    def with_skeleton(self, pin_model: pin.Model) -> "Model":
        """A new model on (a copy of) another Pinocchio skeleton, with the same components
        (their targets are checked against it)."""
        return self._derive(pin_model=pin.Model(pin_model))

    def with_segment_mass(self, body: str, scale: float) -> "Model":
        """A new model whose body ``body`` has ``scale`` times its mass, at the same density and shape:
        the mass, the rotational inertia about the centre of mass and so the first moment all scale
        by ``scale``, the centre of mass stays (the same law as the ``segment_mass`` effect with
        ``delta = scale - 1``, here folded into a copy of the skeleton, so every analysis and the
        optimal-control engine see it, body weight included).  Pinocchio merges bodies welded by
        fixed joints into their joint's inertia: those are scaled together.  E.g. thesis Sec. 5.3's
        foot at 67 %: ``model.with_segment_mass("foot_r", 0.67).with_segment_mass("foot_l", 0.67)``."""
        s = float(scale)
        if not (np.isfinite(s) and s > 0):
            raise ModelError(f"with_segment_mass: scale of body '{body}' must be a finite number > 0, got {scale!r}")
        j = self._pin.frames[self.frame_id(body)].parentJoint
        if j == 0 or self._pin.inertias[j].mass <= 0:
            moving = [self._pin.names[i] for i in range(1, self._pin.njoints) if self._pin.inertias[i].mass > 0]
            raise ModelError(f"with_segment_mass: body '{body}' of model '{self.name}' does not move or has no "
                             f"mass (joints with mass: {', '.join(moving)})")
        pm = pin.Model(self._pin)
        inert = pm.inertias[j]
        pm.inertias[j] = pin.Inertia(inert.mass * s, np.array(inert.lever), np.array(inert.inertia) * s)
        return self._derive(pin_model=pm)

    # -- components -----------------------------------------------------
    def with_effect(self, *effects: Component) -> "Model":
        """A new model with ``effects`` added (duplicates of an existing label are refused)."""
        eff = list(self.effects)
        con = list(self.contacts)
        for e in effects:
            if not isinstance(e, Component):
                raise ModelError(f"with_effect takes components, not {type(e).__name__}")
            (con if e.kind == "contact" else eff).append(e)
        return self._derive(effects=eff, contacts=con)

    def __add__(self, other: Component) -> "Model":
        return self.with_effect(other)

    def without(self, label: str) -> "Model":
        """A new model without the component labelled ``label`` (``family:target``)."""
        comps = self.effects + self.contacts
        if label not in [c.label for c in comps]:
            raise ModelError(f"model '{self.name}' has no component '{label}' "
                             f"(has: {', '.join(c.label for c in comps) or 'none'})")
        return self._derive(effects=[e for e in self.effects if e.label != label],
                            contacts=[c for c in self.contacts if c.label != label])

    def component(self, label: str) -> Component:
        for c in self.effects + self.contacts:
            if c.label == label:
                return c
        raise ModelError(f"model '{self.name}' has no component '{label}' "
                         f"(has: {', '.join(c.label for c in self.components) or 'none'})")

    def with_muscles(self, muscles) -> "Model":
        """A new model with another :class:`~pinmsk.muscles.muscle_set.MuscleSet` (or None)."""
        return self._derive(muscles=muscles)

    # -- parameters -----------------------------------------------------
    @property
    def parameters(self) -> Parameters:
        """Every effect, contact and muscle parameter, one read-only :class:`Parameters` table.

        Names are prefixed by their owner: ``<component label>.<name>`` for effects and
        contacts (``joint_damping:elbow_flexion.c``, ``hypervolumetric:heel_r.k_h``) and
        ``muscle:<muscle>.<name>`` for muscles (``muscle:BIClong.f_max``).  Each row
        has value, min, max, vary, unit (and stderr after a fit).
        """
        if self._parameters is None:
            rows = [p for c in self.components for p in c.parameter_table().values()]
            if self.muscles is not None:
                rows += list(self.muscles.parameter_table().values())
            object.__setattr__(self, "_parameters", Parameters(rows))
        return self._parameters

    def with_parameters(self, values: Mapping[str, float] | Parameters | None = None, *,
                        vary: Mapping[str, bool] | None = None,
                        bounds: Mapping[str, tuple[float, float]] | None = None,
                        stderr: Mapping[str, float] | None = None) -> "Model":
        """A new model with parameters changed by their :attr:`parameters` names.

        ``values`` maps names to values, or is a :class:`Parameters` table (such as
        ``model.parameters.fix(...)``), whose values, bounds and vary flags are all
        applied.  ``vary`` fixes (False) or frees (True) parameters for fits;
        ``bounds`` maps names to ``(lo, hi)``.
        """
        changes: dict[str, dict[str, dict]] = {}
        if isinstance(values, Parameters):
            table = values
            values, vary, bounds = {}, dict(vary or {}), dict(bounds or {})
            for n, p in table.items():
                values[n] = p.value
                vary.setdefault(n, p.vary)
                bounds.setdefault(n, (p.min, p.max))
        for what, mapping in (("values", values), ("vary", vary), ("bounds", bounds), ("stderr", stderr)):
            for name, x in (mapping or {}).items():
                owner, pname = self._owner(name)
                changes.setdefault(owner, {}).setdefault(what, {})[pname] = x
        if not changes:
            return self
        muscles = self.muscles
        comps = {c.label: c for c in self.components}
        for owner, kw in changes.items():
            if owner == MUSCLE_PREFIX:
                muscles = muscles.with_params(kw.pop("values", None), **kw)
            else:
                comps[owner] = comps[owner].with_params(kw.pop("values", None), **kw)
        return self._derive(muscles=muscles, effects=[comps[c.label] for c in self.effects],
                            contacts=[comps[c.label] for c in self.contacts])

    def fix(self, *names: str) -> "Model":
        """A new model in which fits keep the parameters ``names`` at their values."""
        return self.with_parameters(vary={n: False for n in names})

    def free(self, *names: str) -> "Model":
        """A new model in which fits may change the parameters ``names``."""
        return self.with_parameters(vary={n: True for n in names})

    def _owner(self, name: str) -> tuple[str, str]:
        """``(component label or 'muscle', name inside it)`` of a :attr:`parameters` name."""
        try:
            self.parameters[name]
        except ParameterKeyError as exc:
            raise ParameterKeyError(f"model '{self.name}': {exc}") from None
        if name.startswith(MUSCLE_PREFIX + ":"):
            return MUSCLE_PREFIX, name[len(MUSCLE_PREFIX) + 1:]
        label, pname = name.rsplit(".", 1)
        return label, pname

    # -- trials ---------------------------------------------------------
    def motion(self, trial, *, cutoff=DEFAULT_CUTOFF, signals: Iterable[str] | None = None) -> Motion:
        """The model's :class:`Motion` from a Trial: :func:`pinmsk.kinematics.motion` (6 Hz default)."""
        return kinematics.motion(self, trial, cutoff=cutoff, signals=signals)

    def describe(self) -> str:
        """A short human-readable summary (used by ``pinmsk info``).  A model with a coordinate map (an
        OpenSim import's dependent joints) is described by OpenSim's coordinates, the dependent joints
        listed as such."""
        cmap = kinematics.coordinate_map(self)
        if cmap is None:
            size = f"{self.nv} dof"
        else:
            coords = [c for c in cmap.osim_coordinates if c not in cmap.welded]
            size = (f"{len(coords)} coordinates (OpenSim's; the Pinocchio skeleton has {self.nv} joints, "
                    f"{len(cmap.dependent)} of them dependent)")
        lines = [f"model {self.name}: {size}, {self.n_muscles} muscles, "
                 f"mass {self.mass:.3f} kg, gravity {np.round(self.gravity, 3).tolist()} m/s^2"]
        if self.meta.get("description"):
            lines.append(f"  {self.meta['description']}")
        if cmap is None:
            lines.append("  coordinates: " + ", ".join(self.coordinate_order))
        else:
            only = [c for c in coords if c not in self._coord_index]
            lines.append(f"  coordinates ({len(coords)}, what motions give and results report): " + ", ".join(coords))
            if only:
                lines.append(f"  coordinates that drive only dependent joints: {', '.join(only)}")
            lines.append(f"  dependent joints ({len(cmap.dependent)}, functions of the coordinates, exact): " + ", ".join(
                f"{d.name} = {_function_label(d.function)}({', '.join(d.of)})" for d in cmap.dependent.values()))
        if self.muscles is not None:
            lines.append(f"  muscles ({self.muscles.model_type}, {self.muscles.tendon} tendon): "
                         + ", ".join(self.muscles.names))
        if self.components:
            lines.append("  components: " + ", ".join(c.label for c in self.components))
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"<pinmsk.Model {self.name}: {self.nv} dof, {self.n_muscles} muscles, {len(self.components)} components>"

    def __reduce__(self):
        # Pinocchio models pickle; rebuild through the constructor.
        return (_rebuild, (self.name, self._pin, self.muscles, self.effects, self.contacts, _thaw(self.meta)))


def _function_label(f) -> str:
    """``SimmSpline``, ``1.147 * SimmSpline`` (a MultiplierFunction), ...: an OpenSim function's kind."""
    inner = getattr(f, "function", None)
    if inner is not None and hasattr(f, "scale"):
        return f"{f.scale:.6g} * {_function_label(inner)}"
    return type(f).__name__


def _rebuild(name, pm, muscles, effects, contacts, meta):
    return Model._make(name=name, pin_model=pm, muscles=muscles, effects=effects, contacts=contacts, meta=meta)


class Data:
    """The workspace of one :class:`Model`, as Pinocchio's ``Data`` is of its ``Model``.

    ``pin`` is a ``pinocchio.Data`` of ``model.pin``.  :meth:`cached` keeps what
    components compute from a motion's kinematics (frame Jacobians and point
    accelerations, the joint torque regressor, contact-site kinematics) keyed by
    the :class:`~pinmsk.components.Motion` object (immutable, so its identity is a
    sound key), for the last ``max_motions`` motions; components prepared on the
    same motion with the same Data share that work.

    A Data is not thread-safe: give each thread its own (``model.create_data()``);
    two Data objects share nothing.  It serves every model built on the same
    skeleton (``model + effect`` keeps the skeleton).
    """

    __slots__ = ("model", "pin", "max_motions", "_entries")

    def __init__(self, model: Model, *, max_motions: int = 4):
        self.model = model
        self.pin = model.pin.createData()
        self.max_motions = int(max_motions)
        self._entries: list[tuple[Motion, dict]] = []   # [(motion, {key: value})], most recent last

    def cached(self, model, key, motion: Motion, compute: Callable[[Any], Any]):
        """``compute(self.pin)`` for ``motion``, computed once per ``(key, motion)``.

        ``key`` names the quantity (e.g. ``("frame_point", frame_id)``); ``model`` must
        share this Data's skeleton.
        """
        if model.pin is not self.model.pin:
            raise ModelError(f"this Data was created by model '{self.model.name}', whose skeleton is not "
                             f"that of model '{model.name}'; use {model.name}.create_data()")
        for i, (mo, values) in enumerate(self._entries):
            if mo is motion:
                if i != len(self._entries) - 1:
                    self._entries.append(self._entries.pop(i))
                break
        else:
            values = {}
            self._entries.append((motion, values))
            if len(self._entries) > self.max_motions:
                del self._entries[0]
        if key not in values:
            values[key] = compute(self.pin)
        return values[key]

    def clear(self) -> None:
        """Forget every cached quantity."""
        self._entries.clear()

    def __repr__(self) -> str:
        n = sum(len(v) for _, v in self._entries)
        return f"<pinmsk.Data of {self.model.name}: {n} cached quantities over {len(self._entries)} motion(s)>"


# -- loading ---------------------------------------------------------------

def load_model(name_or_path: str | Path, *, moment_arms: str | None = None,
               tendon: str | None = None, gravity=None, nonlinear: str | None = None) -> Model:
    """Load a built-in model by name (``finger``, ``forearm``, ``gait2d``, ``human3d``)
    or a user's model from a sidecar ``.toml`` (which names its URDF), a bare ``.urdf`` or an
    OpenSim ``.osim`` (:func:`import_osim`; its report is ``meta['import_report']``).

    An ``.osim`` is imported with ``nonlinear="exact"`` unless ``nonlinear="fit"`` is given (see
    :func:`pinmsk.opensim.importer.read_import`): joints whose axes are nonlinear functions of a
    coordinate (a spline knee) get dependent joints filled from OpenSim's coordinates, so trials and
    results are in OpenSim's coordinates.  The import is cached in this process (:func:`import_osim`):
    loading the same unchanged file with the same options again returns the same (frozen) Model.

    ``moment_arms`` picks a path variant declared in the sidecar (e.g.
    ``"constant"`` or ``"angle"``); ``tendon`` overrides the sidecar's
    default tendon (``"rigid"`` or ``"compliant"``).  ``gravity`` (3 numbers,
    m/s^2) overrides the sidecar's; a bare URDF (or a sidecar without
    ``gravity``) otherwise keeps Pinocchio's URDF/ROS convention ``[0, 0, -9.81]``
    (z up), with a warning saying so.
    """
    p = Path(str(name_or_path))
    if p.suffix.lower() == ".osim":
        if moment_arms is not None or tendon is not None:
            raise ModelError(f"{p}: moment_arms and tendon do not apply to an OpenSim model (its muscles "
                             "come from the .osim: their paths are fitted polynomials, their tendons as OpenSim sets them)")
        from .opensim.importer import warn_report
        try:
            model, report = import_osim(p, gravity=gravity, nonlinear=nonlinear or "exact")
        except PinmskError:
            raise
        except (TypeError, ValueError, KeyError, IndexError, AttributeError, OverflowError, RuntimeError) as exc:
            # a value of a kind the import's checks did not expect (Pinocchio raises RuntimeError on an
            # inertia it refuses): named with the file, not a traceback
            what = " ".join(str(exc).split()) or type(exc).__name__
            raise ModelError(f"{p}: cannot import this .osim ({type(exc).__name__}: {what[:200]})") from None
        warn_report(report)
        return model
    if nonlinear is not None:
        raise ModelError(f"{p}: nonlinear= applies to an OpenSim .osim model (how its nonlinear joints are "
                         "imported); this model is already a skeleton")
    if p.suffix.lower() == ".urdf":
        if not p.exists():
            raise ModelError(f"URDF file not found: {p}")
        try:
            pm = pin.buildModelFromUrdf(str(p))
        except Exception as exc:  # pinocchio raises bare ValueError/RuntimeError
            raise ModelError(f"Pinocchio could not load URDF {p}: {exc}") from None
        if gravity is None:
            _warn_default_gravity(p)
        _set_gravity(pm, gravity, p)
        return Model._make(name=p.stem, pin_model=pm, muscles=None, effects=(), contacts=(),
                           meta={"urdf": str(p)})
    if p.suffix.lower() == ".toml":
        if not p.exists():
            raise ModelError(f"model sidecar not found: {p}")
        sidecar = p
    else:
        names = builtin_models.builtin_names()
        if str(name_or_path) not in names:
            close = difflib.get_close_matches(str(name_or_path), names, n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise ModelError(
                f"no built-in model '{name_or_path}'{hint} (built-ins: {', '.join(names)}); "
                "or pass the path of a .toml sidecar, a .urdf or an OpenSim .osim file"
            )
        sidecar = builtin_models.builtin_sidecar(str(name_or_path))
    try:
        return _load_sidecar(sidecar, moment_arms=moment_arms, tendon=tendon, gravity=gravity)
    except PinmskError:
        raise
    except (TypeError, ValueError, KeyError, IndexError, AttributeError, OverflowError) as exc:
        # a value of the wrong kind where the checks above did not look (a table for a number, a list
        # too short): named with the file rather than shown as a traceback
        what = " ".join(str(exc).split()) or type(exc).__name__
        raise ModelError(f"{sidecar}: invalid model sidecar ({type(exc).__name__}: {what[:200]})") from None


def import_osim(path, *, locked: str = "joint", nonlinear: str = "exact", gravity=None, hooks=None,
                fit_over=None):
    """``(Model, ImportReport)`` of an OpenSim ``.osim`` (the parts: :func:`pinmsk.opensim.importer.read_import`,
    whose docstring gives the options; ``load_model`` takes the defaults).  ``hooks`` default: the
    muscle import (:func:`pinmsk.opensim.muscle_import.muscle_hook`) and the contacts
    (:func:`pinmsk.opensim.contacts.contact_hook`); ``()`` imports the skeleton only.

    ``fit_over`` (a Trial or a coordinates/states file in OpenSim's coordinates): the muscle paths'
    polynomial surrogates are fitted over that motion's ranges, widened by 10 degrees, as OpenSim's
    PolynomialPathFitter and PredSim fit them, instead of over the coordinates' whole ranges (where a
    hip muscle's wrapping can cost millimetres of moment arm at the motion's own poses); the report says
    which ranges were used and the fit error over them.

    Imports are cached in this process, keyed by the file (resolved path, modification time in ns, size
    and a digest of its content) and the options (``locked``, ``nonlinear``, ``gravity``, the hook objects): importing the same
    unchanged file with the same options returns the same Model and report (the Model is frozen, so
    sharing it is safe), without refitting the muscle paths (arm26: 2-4 s).  A changed file is imported
    again.  :func:`clear_import_cache` empties the cache; ``pinmsk import`` writes a sidecar that loads
    fast in a new process.

    Imports with the default hooks (not ``fit_over``) are also kept on disk (:mod:`pinmsk.io.cache`: the
    user's cache folder, ``PINMSK_CACHE_DIR``, off with ``PINMSK_NO_CACHE=1``), keyed by the file's path
    and bytes, the files it names (``file="..."``), the options, the hooks and pinmsk's code: a new
    process reads the model back (a corrupt entry is imported again).  The muscle paths' polynomials are
    fitted when first used (:class:`pinmsk.opensim.muscle_import.DeferredPathFit`; the report's
    ``pending`` until then), and the fit is kept on disk too.
    """
    from .opensim.contacts import contact_hook
    from .opensim.muscle_import import DEFAULT_HOOKS
    if fit_over is not None:
        from functools import partial

        from .io.tables import read_trial
        from .opensim.muscle_import import MAX_MUSCLES, muscle_hook
        from .trial import Trial
        if hooks is not None:
            raise ModelError("import_osim: give hooks= or fit_over=, not both (fit_over sets the muscle hook)")
        motion = fit_over if isinstance(fit_over, Trial) else read_trial(fit_over)
        hooks = (partial(muscle_hook, motion=motion, max_muscles=MAX_MUSCLES), *DEFAULT_HOOKS[1:], contact_hook)
    hooks = tuple((*DEFAULT_HOOKS, contact_hook) if hooks is None else hooks)
    key = _import_key(path, locked, nonlinear, gravity, hooks)
    if key is not None and key in _IMPORTS:
        _IMPORTS[key] = _IMPORTS.pop(key)            # most recently used last
        return _IMPORTS[key]
    from .io import cache
    stored = _stored_key(path, key, hooks) if fit_over is None else None
    out = _stored_import(cache.load("import", stored)) if stored else None
    if out is None:
        out = _build_import(path, locked=locked, nonlinear=nonlinear, gravity=gravity, hooks=hooks)
        if stored:
            for item in out[1].pending:           # the muscle paths' fit, when it runs, is cached too
                if hasattr(item, "cache_key"):
                    item.cache_key = stored
            cache.store("import", stored, out)
    if key is not None:
        _IMPORTS[key] = out
        while len(_IMPORTS) > MAX_CACHED_IMPORTS:
            del _IMPORTS[next(iter(_IMPORTS))]
    return out


def _build_import(path, *, locked, nonlinear, gravity, hooks):
    from .opensim.importer import read_import
    from .opensim.report import NOTE, ReportEntry
    imp = read_import(path, locked=locked, nonlinear=nonlinear, hooks=hooks)
    report = imp.report
    if gravity is not None:
        _set_gravity(imp.pin_model, gravity, f"{path}: import_osim")
        report = report.with_entries([ReportEntry(element=f"{path}: <gravity>", status=NOTE, became=(
            f"replaced by gravity {imp.pin_model.gravity.linear.tolist()} m/s^2 (given to the import)"))])
    model = Model._make(name=imp.name, pin_model=imp.pin_model, muscles=imp.muscles, effects=(), contacts=(),
                        meta={**imp.meta, "import_report": report})
    return (model.with_effect(*imp.components) if imp.components else model), report


def _stored_key(path, key, hooks) -> str | None:
    """The import cache's key (:mod:`pinmsk.io.cache`) of an import: the in-process key's file and options,
    the content of the files the .osim names (``file="..."`` attributes), the hooks by qualified name and
    pinmsk's code; None (not stored) if the cache is off or a hook is not one of pinmsk's module-level
    functions (a user's hook may change without changing its name)."""
    import re
    import sys

    from .io import cache
    if key is None or cache.cache_dir() is None:
        return None
    names = []
    for hook in hooks:
        module, qual = getattr(hook, "__module__", None), getattr(hook, "__qualname__", "")
        if (module is None or not module.startswith("pinmsk.") or "<" in qual
                or getattr(sys.modules.get(module), qual, None) is not hook):
            return None
        names.append(f"{module}.{qual}")
    p = Path(key[0])
    try:
        text = p.read_bytes()
        linked = []
        for ref in sorted(set(re.findall(rb'\bfile\s*=\s*"([^"]+)"', text))):
            f = p.parent / ref.decode(errors="replace")
            linked += [ref, f.read_bytes() if f.is_file() else b"<missing>"]
    except OSError:
        return None
    path_, _mtime, _size, _digest, locked, nonlinear, g, _hooks = key
    return cache.key("osim-import", cache.code_fingerprint(), path_, text, *linked, locked, nonlinear, g,
                     tuple(names))


def _stored_import(value):
    """A cached ``(Model, ImportReport)``, or None if ``value`` is not one."""
    from .opensim.report import ImportReport
    if (isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], Model)
            and isinstance(value[1], ImportReport)):
        return value
    return None


#: How many imported models :func:`import_osim` keeps (least recently used dropped first).
MAX_CACHED_IMPORTS = 16
_IMPORTS: dict = {}


def clear_import_cache(path=None) -> None:
    """Forget the models :func:`import_osim` cached in this process: all of them, or those of the file at
    ``path`` (the next import reads the on-disk cache, :mod:`pinmsk.io.cache`, or the file)."""
    if path is None:
        _IMPORTS.clear()
        return
    p = str(Path(str(path)).resolve())
    for key in [k for k in _IMPORTS if k[0] == p]:
        del _IMPORTS[key]


def _import_key(path, locked, nonlinear, gravity, hooks):
    """The cache key of an import, or None (not cached) if the file cannot be stat'ed or an option is not
    hashable; the import itself then says what is wrong."""
    import hashlib
    try:
        p = Path(str(path)).resolve()
        st = p.stat()
        # the content's digest too: a file rewritten within the file system's time resolution (tests, scripts)
        # with the same size is not taken for the old one (~1 ms for a 1 MB .osim)
        digest = hashlib.blake2b(p.read_bytes(), digest_size=16).hexdigest()
        g = None if gravity is None else tuple(float(x) for x in np.asarray(gravity, dtype=float).reshape(-1))
        key = (str(p), st.st_mtime_ns, st.st_size, digest, locked, nonlinear, g, hooks)
        hash(key)
    except (OSError, TypeError, ValueError):
        return None
    return key


def _warn_default_gravity(where) -> None:
    warnings.warn(
        f"{where}: no gravity declared, so Pinocchio's default {list(PINOCCHIO_GRAVITY)} m/s^2 (-z) is "
        "in use; if the model is y-up (as OpenSim), declare it in a sidecar .toml: [model] urdf = "
        "\"...\" and gravity = [0.0, -9.81, 0.0] (or load_model(..., gravity=[0, -9.81, 0]))",
        UserWarning, stacklevel=3)


def _set_gravity(pm: pin.Model, gravity, where) -> None:
    if gravity is None:
        return
    try:
        g = np.asarray(gravity, dtype=float)
    except (TypeError, ValueError):
        g = None
    if g is None or g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ModelError(f"{where}: gravity must be 3 finite numbers (m/s^2), got {gravity}")
    pm.gravity = pin.Motion(np.concatenate([g, np.zeros(3)]))


def _load_sidecar(sidecar: Path, *, moment_arms: str | None, tendon: str | None, gravity=None) -> Model:
    """The one sidecar -> (Pinocchio skeleton + components) loader behind :func:`load_model`."""
    spec = read_toml(sidecar, what="model sidecar")
    _check_sidecar(spec, sidecar)
    mspec = spec.get("model")
    if not isinstance(mspec, dict) or "urdf" not in mspec:
        raise ModelError(f"{sidecar}: needs a [model] table with a 'urdf' entry")
    urdf, package_dirs = builtin_models.resolve_urdf(sidecar, mspec["urdf"])
    try:
        pm = pin.buildModelFromUrdf(str(urdf))
    except Exception as exc:  # pinocchio raises bare ValueError/RuntimeError
        raise ModelError(f"{sidecar}: Pinocchio could not load URDF {urdf}: {exc}") from None
    if mspec.get("gravity") is None and gravity is None:
        _warn_default_gravity(sidecar)
    _set_gravity(pm, mspec.get("gravity"), f"{sidecar}: [model]")
    _set_gravity(pm, gravity, "load_model")
    name = mspec.get("name", sidecar.stem)
    coords = tuple(pm.names[j] for j in range(1, pm.njoints))
    order = mspec.get("coordinate_order")
    if order is not None and sorted(order) != sorted(coords):
        raise ModelError(f"{sidecar}: [model] coordinate_order must list exactly the URDF's joints "
                         f"{sorted(coords)}; got {order}")
    meta = {
        "sidecar": str(sidecar), "urdf": str(urdf), "package_dirs": [str(d) for d in package_dirs],
        "description": mspec.get("description", ""), "up_axis": mspec.get("up_axis", "z"),
        "coordinate_order": list(order) if order else None,
    }
    if mspec.get("osim"):           # where the viewer finds the geometric muscle paths of an imported model
        meta["source_osim"] = str((sidecar.parent / str(mspec["osim"])).resolve())
        meta["source_osim_digest"] = mspec.get("osim_digest")
    if "coordinate_map" in spec:
        from .opensim.skeleton import CoordinateMap
        cmap = CoordinateMap.from_spec(spec["coordinate_map"], joints=coords, where=str(sidecar))
        meta["coordinate_map"] = cmap
        meta["dependent_coordinates"] = {n: {"joint": d.joint, "axis": d.axis, "of": list(d.of),
                                             "function": repr(d.function)} for n, d in cmap.dependent.items()}
    muscles = None
    entries = spec.get("muscles", [])
    if entries:
        mm = spec.get("muscle_model", {})
        variant = moment_arms or mspec.get("default_paths", "constant")
        meta["moment_arms"] = variant
        path, errors = _sidecar_path(entries, coords, variant, sidecar)
        if errors:
            meta["path_fit_errors"] = errors
        muscles = _build_muscles(entries, mm, path, tendon or mm.get("tendon", "rigid"), sidecar)
    effects = [registry.from_spec(e, where=f"{sidecar} [[effects]] #{i + 1}")
               for i, e in enumerate(spec.get("effects", []))]
    effects += [actuator_from_spec(a, where=f"{sidecar} [[actuators]] #{i + 1}")
                for i, a in enumerate(spec.get("actuators", []))]
    contacts = [contact_from_spec(c, where=f"{sidecar} [[contacts]] #{i + 1}")
                for i, c in enumerate(spec.get("contacts", []))]
    model = Model._make(name=name, pin_model=pm, muscles=muscles, effects=(), contacts=(), meta=meta)
    return model.with_effect(*effects, *contacts) if effects or contacts else model


def _check_sidecar(spec: dict, sidecar: Path) -> None:
    """Refuse unknown tables and keys of a sidecar (see :data:`SIDECAR_SCHEMA`) with a "did you mean"."""
    for section in spec:
        if section not in SIDECAR_SCHEMA:
            close = difflib.get_close_matches(section, list(SIDECAR_SCHEMA), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ModelError(f"{sidecar}: unknown table '{section}'{hint}; a model sidecar has "
                             "[model], [muscle_model], [[muscles]], [[effects]], [[actuators]], [[contacts]] and "
                             "[coordinate_map]")
    for section in ("model", "muscle_model"):
        if section in spec:
            check_keys(spec[section], SIDECAR_SCHEMA[section], where=str(sidecar), section=f"[{section}]")
    for section in ("muscles", "effects", "actuators", "contacts"):
        if section in spec and not (isinstance(spec[section], list)
                                    and all(isinstance(e, dict) for e in spec[section])):
            raise ModelError(f"{sidecar}: '{section}' must be an array of tables, [[{section}]]")
    for i, entry in enumerate(spec.get("muscles", [])):
        label = f"[[muscles]] '{entry['name']}'" if entry.get("name") else f"[[muscles]] #{i + 1}"
        check_keys(entry, SIDECAR_SCHEMA["muscles"], where=str(sidecar), section=label)
        paths = entry.get("paths", {})
        if not isinstance(paths, dict):
            raise ModelError(f"{sidecar}: {label}: 'paths' must be a table of path variants")
        for variant, table in paths.items():
            check_keys(table, SIDECAR_PATH_KEYS, where=str(sidecar), section=f"{label} paths.{variant}")


def _sidecar_path(entries, coords, variant: str, sidecar: Path):
    """``(path, fit errors)`` of path variant ``variant``: a MomentArmPath (``l0``, ``moment_arms``) or, for the
    polynomials ``pinmsk import`` writes, a PolynomialPath with ``{muscle: {"length", "moment_arm"}}`` errors."""
    tables = [e.get("paths", {}).get(variant) for e in entries]
    poly = [isinstance(t, dict) and "coefficients" in t for t in tables]
    if not any(poly):
        return MomentArmPath.from_sidecar(entries, coords, variant, source=sidecar), {}
    names = [e.get("name") for e in entries]
    if not all(poly):
        other = names[poly.index(False)]
        raise ModelError(f"{sidecar}: path variant {variant!r} is a polynomial for some muscles but not for "
                         f"'{other}'; give every muscle the same kind of path")
    terms, errors = [], {}
    for name, t in zip(names, tables):
        missing = [k for k in ("coordinates", "exponents", "coefficients") if k not in t]
        if missing:
            raise ModelError(f"{sidecar}: [[muscles]] '{name}' paths.{variant} needs {', '.join(missing)}")
        terms.append({k: t[k] for k in ("coordinates", "center", "scale", "exponents", "coefficients") if k in t})
        if "max_length_error" in t or "max_moment_arm_error" in t:
            errors[name] = {"length": t.get("max_length_error"), "moment_arm": t.get("max_moment_arm_error")}
    try:
        return PolynomialPath(muscles=names, coordinates=coords, terms=terms), errors
    except (ModelError, TypeError, ValueError) as exc:
        raise ModelError(f"{sidecar}: [[muscles]] paths.{variant}: {exc}") from None


#: Keys of a [[muscles]] entry that are not parameters of the muscle model.
_MUSCLE_ENTRY_KEYS = ("name", "paths", "points")


def _build_imported_muscles(entries, mm: dict, path, tendon: str, sidecar: Path, kind: str, names):
    """The MuscleSet of a sidecar whose muscles are an imported OpenSim model's (``pinmsk import``): every
    per-muscle key is a constructor argument of the muscle model ``kind``, ``tau_rise``/``tau_fall`` its
    time constants; what the type does not take is refused by name."""
    for key in ("tendon_model", "parallel_elastic", "tendon_strain"):
        if key in mm:
            raise ModelError(f"{sidecar}: [muscle_model] {key} is for the thelen2003 and nagano_gerritsen types; "
                             f"type '{kind}' has per-muscle curve parameters in [[muscles]]")
    keys = sorted({k for e in entries for k in e if k not in _MUSCLE_ENTRY_KEYS})
    kwargs: dict[str, Any] = {k: mm[k] for k in ("tau_rise", "tau_fall") if k in mm}
    for key in keys:
        lacking = [e["name"] for e in entries if key not in e]
        if lacking:
            raise ModelError(f"{sidecar}: [[muscles]] '{lacking[0]}' has no '{key}', which other muscles give; "
                             "give it for every muscle or none")
        try:
            kwargs[key] = np.array([float(e[key]) for e in entries])
        except (TypeError, ValueError):
            bad = next(e for e in entries if not isinstance(e[key], (int, float)))
            raise ModelError(f"{sidecar}: [[muscles]] '{bad['name']}' {key} = {bad[key]!r} must be a number") from None
    cls = MUSCLE_MODELS[kind]
    try:
        mtu = cls(names=names, **kwargs)
    except TypeError as exc:
        raise ModelError(f"{sidecar}: [[muscles]]: muscle type '{kind}' does not take these parameters ({exc})") from None
    except ModelError as exc:
        raise ModelError(f"{sidecar}: [[muscles]]: {exc}") from None
    try:
        return MuscleSet(names=names, model_type=kind, mtu=mtu, path=path, tendon=tendon)
    except ModelError as exc:
        raise ModelError(f"{sidecar}: [[muscles]]: {exc}") from None


def _build_muscles(entries, mm: dict, path, tendon: str, sidecar: Path):
    kind = mm.get("type", "thelen2003")
    names = [e.get("name") for e in entries]
    for i, n in enumerate(names):
        if not n:
            raise ModelError(f"{sidecar}: muscle entry {i + 1} has no name")
    if kind in MUSCLE_MODELS and kind not in _MUSCLE_LAWS:
        return _build_imported_muscles(entries, mm, path, tendon, sidecar, kind, names)

    def col(key, default=None, required=True):
        vals = []
        for e in entries:
            if key in e:
                v = e[key]
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise ModelError(f"{sidecar}: muscle '{e['name']}': {key} = {v!r} must be a number")
                vals.append(float(v))
            elif required and default is None:
                raise ModelError(f"{sidecar}: muscle '{e['name']}' has no '{key}'")
            else:
                vals.append(np.nan if default is None else default)
        return np.array(vals)

    # the values are checked where they are stored: by the muscle model (pinmsk.muscles.models.MUSCLE_PARAMETERS)
    common = dict(names=names, f_max=col("f_max"), l_opt=col("l_opt"), l_slack=col("l_slack"),
                  pennation=col("pennation", 0.0), fast_fraction=col("fast_fraction", 0.5, required=False),
                  volume=col("volume", required=False) if any("volume" in e for e in entries) else None)
    if kind not in _MUSCLE_LAWS:
        close = difflib.get_close_matches(str(kind), list(MUSCLE_MODELS), n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ModelError(f"{sidecar}: unknown muscle_model type '{kind}'{hint} "
                         f"(known: {', '.join(MUSCLE_MODELS)})")
    for key in ("tau_rise", "tau_fall"):
        if key in mm:
            common[key] = mm[key]
    if kind == "thelen2003" and any("v_max" in e for e in entries):
        common["v_max"] = col("v_max")
    own = {"name", "paths", "points", "f_max", "l_opt", "l_slack", "pennation", "volume", "fast_fraction",
           "v_max" if kind == "thelen2003" else "width"}
    for e in entries:
        other = sorted(set(e) - own)
        if other:
            raise ModelError(f"{sidecar}: [[muscles]] '{e['name']}': {', '.join(other)} is not a parameter of muscle "
                             f"type '{kind}'")
    law, parallel = _MUSCLE_LAWS[kind]
    if mm.get("tendon_model", law) != law:
        raise ModelError(f"{sidecar}: [muscle_model] tendon_model = {mm['tendon_model']!r}, but type '{kind}' "
                         f"has the {law!r} tendon; remove the key or change the type")
    if mm.get("parallel_elastic", parallel) is not parallel:
        raise ModelError(f"{sidecar}: [muscle_model] parallel_elastic = {mm['parallel_elastic']!r}, but type "
                         f"'{kind}' {'has' if parallel else 'has no'} parallel elastic element; remove the key")
    strain = mm.get("tendon_strain")
    if strain is not None:
        if not (isinstance(strain, (int, float)) and 0 < strain < 1):
            raise ModelError(f"{sidecar}: [muscle_model] tendon_strain must be a number in (0, 1), got {strain!r}")
        common["tendon_strain0"] = float(strain)
    points = {e["name"]: [tuple(p) for p in e.get("points", [])] for e in entries}
    try:
        if kind == "thelen2003":
            mtu = Thelen2003(**common)
        else:
            mtu = NaganoGerritsen(**common, width=col("width"))
        return MuscleSet(names=names, model_type=kind, mtu=mtu, path=path, tendon=tendon,
                         display_points=points)
    except ModelError as exc:
        raise ModelError(f"{sidecar}: [[muscles]]: {exc}") from None
