"""The muscle import hook of an OpenSim model: :func:`muscle_hook`.

For the model's Thelen2003Muscle, Millard2012EquilibriumMuscle and
DeGrooteFregly2016Muscle elements it builds one
:class:`~pinmsk.muscles.muscle_set.MuscleSet`:

* the muscle-tendon model from their properties
  (:func:`pinmsk.opensim.muscles.muscle_model_from_osim`);
* their geometric paths (:class:`pinmsk.opensim.paths.GeometricPaths`, OpenSim's
  path and wrapping algorithm) placed by OpenSim's exact kinematics of the XML
  (:class:`pinmsk.opensim.skeleton.OsimKinematics`), so the approximations of the
  Pinocchio skeleton (fitted joints) do not enter the paths;
* a :class:`~pinmsk.muscles.paths.PolynomialPath` fitted to them
  (:func:`pinmsk.opensim.paths.fit_polynomial_paths`) over the ranges of the
  coordinates each muscle crosses -- the OpenSim coordinates' ``range``
  properties, a rotation's at most :data:`MAX_ROTATION_SPAN` (180 degrees) wide
  around the middle of its range (no polynomial of degree <= 10 follows the
  wrapping transitions of arm26's 270-degree shoulder: 14 mm over the full range;
  ``ranges=`` gives a motion's ranges instead, as OpenSim's PolynomialPathFitter
  samples).  The coordinates a muscle can cross are those of the joints
  between its bodies in the tree (its path points', moving and conditional
  points' coordinates and wrap objects' bodies); unlocked ones are sampled
  (Latin hypercube, :data:`FIT_SAMPLES` training and :data:`TEST_SAMPLES`
  held-out poses), locked ones stay at their default values (their moment
  arms are 0 in pinmsk).

The fit is deferred to the paths' first use: the MuscleSet's path is a
:class:`~pinmsk.muscles.paths.PolynomialPathOnUse` whose :class:`DeferredPathFit` runs it (and is a
deferred item of the report), so an analysis that evaluates no path (inverse dynamics) fits none.
The report gets one entry per muscle group (the muscles crossing the same
coordinates) with the fit's largest length and moment-arm errors on the
held-out poses, and one entry with the muscle-curve notes
(:func:`pinmsk.opensim.muscles.summarize_notes`).  Muscles of other types and
path forces that are not muscles are left to the "not imported" entries.
"""
from __future__ import annotations

import math
from pathlib import Path
import xml.etree.ElementTree as ET
from collections import defaultdict

import numpy as np

from ..errors import ModelError
from ..io.osim import OsimDocument, _parse_xml
from ..muscles.muscle_set import MuscleSet
from ..muscles.paths import PolynomialPathOnUse
from .actuators import actuator_hook
from .forces import force_hook
from .muscles import MUSCLE_TYPES, muscle_model_from_osim, properties_from_xml, summarize_notes
from .hooks import HookResult
from .paths import GeometricPaths, fit_polynomial_paths, path_specs
from .report import APPROXIMATED, NOTE, ReportEntry, paths_warning
from .skeleton import OsimKinematics, Skeleton

__all__ = ["muscle_hook", "default_muscle_hook", "DEFAULT_HOOKS", "MAX_MUSCLES", "geometric_paths",
           "muscle_control_bounds", "osim_geometric_paths", "MAX_ROTATION_SPAN", "FIT_SAMPLES", "TEST_SAMPLES",
           "MAX_DEGREE", "TOLERANCE", "DeferredPathFit"]

#: Training and held-out poses of the polynomial fit (per fit; the fit's cost grows with them).
FIT_SAMPLES = 250
TEST_SAMPLES = 120
#: Highest polynomial degree tried, and the error (m) below which a lower degree is kept.
MAX_DEGREE = 10
TOLERANCE = 1e-4
#: Rotational coordinates whose range is wider than this (rad) are sampled over this span around the
#: middle of their range (a polynomial cannot follow the wrapping transitions of 240-270 degree ranges).
MAX_ROTATION_SPAN = math.pi


def muscle_hook(doc: OsimDocument, skeleton: Skeleton, *, ranges=None, max_muscles: int | None = None,
                motion=None):
    """``hook(doc, skeleton) -> HookResult``: the model's muscles as one MuscleSet (see the module docstring).

    ``ranges`` (``{coordinate: (lo, hi)}``, e.g. :func:`pinmsk.opensim.paths.motion_ranges` of a motion, as
    OpenSim's PolynomialPathFitter samples) replaces the sampling ranges of the coordinates it names; bind
    it with ``functools.partial(muscle_hook, ranges=...)`` to pass the hook to ``import_osim(hooks=...)``.
    ``motion`` (a :class:`~pinmsk.trial.Trial` in OpenSim's coordinates, OpenSim's state-path labels
    too) gives those ranges: each coordinate it holds (not locked, not a coupler's dependent, which the
    coupling sets) over its frames widened by 10 degrees (:func:`~pinmsk.opensim.paths.motion_ranges`),
    within the coordinate's own fit range; ``import_osim(path, fit_over=trial)`` binds it.

    ``max_muscles`` (default :data:`MAX_MUSCLES` for the default hook, None = no limit when called
    directly): a model with more muscles is not fitted (its muscles stay "not imported", with one
    report entry saying why and how to import them), so that ``load_model`` stays quick.
    """
    chosen = [m for m in doc.muscles if m.type in MUSCLE_TYPES]
    if not chosen:
        return HookResult()
    if max_muscles is not None and len(chosen) > max_muscles:
        return HookResult(entries=(ReportEntry(
            element=f"{doc.source}: <ForceSet> {len(chosen)} muscles",
            became=(f"muscles not imported by default: fitting {len(chosen)} muscle paths takes about 0.05 s per "
                    f"muscle (more than {max_muscles} muscles); import them with pinmsk.model.import_osim(path, "
                    "hooks=[pinmsk.opensim.muscle_import.muscle_hook])"), status=NOTE),))
    names = [m.name for m in chosen]
    root = _etree(doc.source)
    elements = {e.get("name"): e for e in root.iter() if e.tag in MUSCLE_TYPES}
    for m in chosen:
        if m.path is None or not m.path.points:
            raise ModelError(f"{m.where}: the muscle has no path points (<GeometryPath>/<PathPointSet>)")
    imp = muscle_model_from_osim([(m.name, m.type, properties_from_xml(elements[m.name])) for m in chosen],
                                 where=[m.where for m in chosen])
    specs = {s.muscle: s for s in path_specs(doc)}
    specs = [specs[n] for n in names]

    kin = OsimKinematics(doc)
    locked = {c.name: c.default_value for c in doc.coordinates if c.locked}
    model_coords = tuple(skeleton.pin_model.names[j] for j in range(1, skeleton.pin_model.njoints))
    crossing = _crossed_coordinates(doc, kin, specs)
    # coupled coordinates (CoordinateCouplerConstraint) are set from their independent ones in every
    # sampled pose, as the model ties them: no pose the model cannot take, moment arms with the coupling
    couplers = tuple(c for c in skeleton.coordinate_map.couplers if c[0] not in locked)
    coupled = {c[0] for c in couplers}
    # a coupled coordinate's muscles cross its independent coordinates
    crossing = {m: cs | {c for d, ind, _, _ in couplers if d in cs for c in ind} for m, cs in crossing.items()}
    crossed = set().union(*crossing.values())
    fit_coords = tuple(c for c in kin.coordinates if c in crossed and c not in locked and c not in coupled)
    missing = sorted(c for c in fit_coords if c not in model_coords)
    if missing:
        raise ModelError(f"{doc.source}: the muscle paths depend on coordinate(s) {missing}, which the imported "
                         "skeleton does not have as joints (import with nonlinear='fit')")
    lock_cols = [(kin.coordinates.index(c), v) for c, v in locked.items()]
    # the geometric paths hold the couplers too (muscle analysis, the viewer): OpenSim enforces them
    coupled_cols = [(kin.coordinates.index(d), [kin.coordinates.index(i) for i in ind], f, float(scale))
                    for d, ind, f, scale in couplers]

    geometric = GeometricPaths(specs, coordinates=kin.coordinates,
                               placements=_Placements(kin, lock_cols, coupled_cols))
    given = dict(ranges or {})
    motion_entry = []
    if motion is not None:
        from_motion, motion_entry = _motion_ranges(doc, skeleton, motion, locked, coupled)
        given = {**from_motion, **given}
    unknown = sorted(set(given) - set(kin.coordinates))
    if unknown:
        raise ModelError(f"{doc.source}: muscle fit ranges name coordinate(s) {unknown} the model does not have")
    ranges = {**_fit_ranges(doc, skeleton), **{c: (float(lo), float(hi)) for c, (lo, hi) in given.items()}}
    fit = DeferredPathFit(geometric=geometric, ranges=ranges, coordinates=fit_coords, couplings=couplers,
                          crossing=crossing, model_coordinates=model_coords, source=str(doc.source),
                          muscles=tuple(names))
    path = PolynomialPathOnUse(fit, muscles=names, coordinates=model_coords)
    muscles = MuscleSet(names=names, model_type=imp.model_type, mtu=imp.mtu, path=path, tendon=imp.tendon)

    entries = motion_entry + [fit]
    used = [c for c in couplers if c[0] in crossed]
    if used:
        entries.append(ReportEntry(
            element=f"{doc.source}: <ConstraintSet>", status=NOTE,
            became=("muscle paths fitted along the coupling(s) " + "; ".join(
                f"{d} = {s:g} * {f!r}({', '.join(ind)})" for d, ind, f, s in used)
                + ": every sampled pose sets the coupled coordinate as the model ties it; the polynomials are "
                "in the independent coordinates and their moment arms include the coupling (as OpenSim's "
                "MomentArmSolver computes them); about the coupled coordinates they are 0")))
    notes = summarize_notes(imp.notes)
    entries.append(ReportEntry(
        element=f"{doc.source}: <ForceSet> {len(chosen)} muscles",
        became=(f"MuscleSet of {len(chosen)} {imp.model_type} muscles ({imp.tendon} tendon)"
                + ("; curve notes: " + " | ".join(notes) if notes else "; curves exact")),
        status=NOTE, details={"notes": tuple(notes), "geometric_paths": geometric,
                              "control_bounds": {m.name: m.control_bounds for m in imp.muscles}}))
    return HookResult(muscles=muscles, entries=tuple(entries), handled=tuple(m.where for m in chosen))


#: The most muscles the default hook fits at import (Rajagopal's 80, the largest shared model, take
#: 3-4.5 s of CPU with its skeleton on 2 loaded shared cores: benchmarks/bench_osim_import.py).
MAX_MUSCLES = 120


def default_muscle_hook(doc: OsimDocument, skeleton: Skeleton):
    """The muscle hook of ``load_model``: :func:`muscle_hook` up to :data:`MAX_MUSCLES` muscles."""
    return muscle_hook(doc, skeleton, max_muscles=MAX_MUSCLES)


#: The hooks :func:`pinmsk.model.import_osim` (and ``load_model``) runs by default: the muscles, the
#: actuators (:func:`pinmsk.opensim.actuators.actuator_hook`) and the passive forces
#: (:func:`pinmsk.opensim.forces.force_hook`).
DEFAULT_HOOKS = (default_muscle_hook, actuator_hook, force_hook)


class DeferredPathFit:
    """The polynomial fit of an import's muscle paths (:func:`~pinmsk.opensim.paths.fit_polynomial_paths`),
    run when the paths or the report's fit entries are first needed, once.

    It is the ``fit`` of the muscles' :class:`~pinmsk.muscles.paths.PolynomialPathOnUse` and a deferred
    item of the :class:`~pinmsk.opensim.report.ImportReport` (``done``, ``report_entries()``: one entry per
    muscle group, as :func:`muscle_hook` describes).  With a ``cache_key`` (set by the import cache,
    :func:`pinmsk.model.import_osim`) the fitted polynomials are read from and written to the import cache
    (:mod:`pinmsk.io.cache`) under that key, so a later process does not fit them again.  Fitting issues
    one UserWarning with the fits' largest errors, as ``load_model`` does for the skeleton's approximations.
    :attr:`runs` counts the fits this process has run (reading the cache is not one).
    """

    runs = 0

    def __init__(self, *, geometric, ranges, coordinates, couplings, crossing, model_coordinates, source, muscles):
        self.geometric, self.ranges, self.coordinates = geometric, dict(ranges), tuple(coordinates)
        self.couplings, self.crossing = tuple(couplings), dict(crossing)
        self.model_coordinates, self.source, self.muscles = tuple(model_coordinates), str(source), tuple(muscles)
        self.cache_key = None
        self._result = None

    @property
    def done(self) -> bool:
        return self._result is not None

    def __call__(self):
        """The fitted :class:`~pinmsk.muscles.paths.PolynomialPath`."""
        return self._run()[0]

    def report_entries(self) -> tuple[ReportEntry, ...]:
        return self._run()[2]

    def _run(self):
        if self._result is None:
            from ..io import cache
            stored = cache.load("paths", self.cache_key) if self.cache_key else None
            if stored is None or not self._valid(stored):
                path, fits = fit_polynomial_paths(
                    self.geometric, ranges=self.ranges, coordinates=self.coordinates, couplings=self.couplings,
                    crossing=self.crossing, n_train=FIT_SAMPLES, n_test=TEST_SAMPLES, max_degree=MAX_DEGREE,
                    tolerance=TOLERANCE, model_coordinates=self.model_coordinates)
                type(self).runs += 1
                stored = (path, tuple(fits))
                if self.cache_key:
                    cache.store("paths", self.cache_key, stored)
            path, fits = stored
            entries = tuple(_fit_entries(self.source, self.muscles, fits, self.ranges))
            self._result = (path, fits, entries)
            text = paths_warning(entries)
            if text:
                import warnings
                warnings.warn(f"{Path(self.source).name}: {text}; the import report is model.meta['import_report']",
                              UserWarning, stacklevel=4)
        return self._result

    def _valid(self, stored) -> bool:
        """A cached fit of these muscles over these coordinates (anything else is refitted)."""
        try:
            path, fits = stored
            return (tuple(path.muscles) == self.muscles and tuple(path.coordinates) == self.model_coordinates
                    and len(fits) == len(self.muscles) and all(f.muscle == m for f, m in zip(fits, self.muscles)))
        except (TypeError, ValueError, AttributeError):
            return False


class _Placements:
    """Body placements of OpenSim's kinematics, locked coordinates at their defaults and coupled ones (``coupled``:
    ``(column, independent columns, function, scale)``) set by their couplers (picklable, so the model that keeps
    the geometric paths in its report pickles)."""

    def __init__(self, kin: OsimKinematics, lock_cols, coupled=()):
        self.kin, self.lock_cols, self.coupled = kin, tuple(lock_cols), tuple(coupled)

    def __call__(self, bodies, q):
        if self.lock_cols or self.coupled:
            q = np.array(q, dtype=float)
            for j, v in self.lock_cols:
                q[:, j] = v
            for j, cols, f, scale in self.coupled:
                q[:, j] = scale * f.value(q[:, cols[0]] if len(cols) == 1 else q[:, cols])
        poses = self.kin.body_poses(q)
        T = np.stack([poses[b] for b in bodies], axis=1)
        return T[..., :3, :3], T[..., :3, 3]


def geometric_paths(report) -> GeometricPaths | None:
    """The exact (geometric) paths an import's muscle hook fitted its polynomials to, from its report."""
    for e in getattr(report, "entries_so_far", ()):
        gp = e.details.get("geometric_paths")
        if gp is not None:
            return gp
    return None


def muscle_control_bounds(report) -> dict | None:
    """``{muscle: (min_control, max_control)}`` of an import's muscles (OpenSim's excitation bounds, which its
    static optimization takes as activation bounds), from its report; None if it has none."""
    for e in getattr(report, "entries_so_far", ()):
        cb = e.details.get("control_bounds")
        if cb is not None:
            return dict(cb)
    return None


def osim_geometric_paths(source) -> GeometricPaths | None:
    """The geometric paths of every ``<GeometryPath>`` of an .osim file (muscles of any type, path
    actuators, ligaments), placed as :func:`muscle_hook` places them (OpenSim's kinematics of the XML,
    locked coordinates at their default values); None if the model has no path.  Cheap (no fit): what
    the viewer draws when an import kept no geometric paths (a skeleton-only import, or more muscles
    than :data:`MAX_MUSCLES`)."""
    from ..io.osim import read_osim
    doc = read_osim(source)
    specs = path_specs(doc)
    if not specs:
        return None
    kin = OsimKinematics(doc)
    lock_cols = [(kin.coordinates.index(c.name), c.default_value) for c in doc.coordinates if c.locked]
    return GeometricPaths(specs, coordinates=kin.coordinates, placements=_Placements(kin, lock_cols))


def _etree(source) -> ET.Element:
    """The .osim as an ``xml.etree`` tree, read by :mod:`pinmsk.io.osim`'s parser (which takes OpenSim's
    ``A::B`` tags that a namespace-aware parser refuses, and renames OpenSim's renamed types)."""
    def convert(node):
        e = ET.Element(node.tag, dict(node.attrib))
        e.text = node.text
        e.extend(convert(c) for c in node.children)
        return e
    with open(source, "rb") as fh:
        return convert(_parse_xml(fh.read(), str(source)))


def _motion_ranges(doc, skeleton, motion, locked, coupled) -> tuple[dict, list]:
    """The fit ranges a motion gives (:func:`muscle_hook`'s ``motion``) and a report entry on them."""
    from ..io.channel_map import with_state_path_coordinates
    from .paths import motion_ranges
    names = [c.name for c in doc.coordinates]
    trial = with_state_path_coordinates(motion, names)
    use = [c for c in names if c in trial and c not in locked and c not in coupled]
    src = trial.meta.get("source", "the motion")
    if not use:
        raise ModelError(f"{doc.source}: the motion to fit the muscle paths over ({src}) has none of the model's "
                         f"coordinates ({', '.join(names[:8])}{', ...' if len(names) > 8 else ''})")
    trial.check_finite(use, what="(the motion the muscle paths are fitted over)")
    out = motion_ranges(trial.get(use), use, limits=_fit_ranges(doc, skeleton))
    rest = [c for c in names if c not in use and c not in locked and c not in coupled]
    became = (f"muscle paths fitted over the motion {src} ({trial.n_frames} frames): the ranges of its "
              f"{len(use)} coordinates widened by 10 degrees, as OpenSim's PolynomialPathFitter samples")
    if rest:
        became += f"; {', '.join(rest)} (not in the motion) over their own ranges"
    return out, [ReportEntry(element=f"{doc.source}: <ForceSet> muscle paths", status=NOTE, became=became)]


def _fit_ranges(doc, skeleton) -> dict[str, tuple[float, float]]:
    """The sampling range of each coordinate: its OpenSim range, rotations at most :data:`MAX_ROTATION_SPAN`
    wide (around the middle of the range)."""
    out = {}
    for c in doc.coordinates:
        lo, hi = (float(v) for v in c.range)
        if skeleton.motion_types.get(c.name) == "Rotational" and hi - lo > MAX_ROTATION_SPAN:
            mid = 0.5 * (lo + hi)
            lo, hi = mid - 0.5 * MAX_ROTATION_SPAN, mid + 0.5 * MAX_ROTATION_SPAN
        out[c.name] = (lo, hi)
    return out


def _fit_entries(source, names, fits, ranges) -> list[ReportEntry]:
    """One report entry per group of muscles crossing the same coordinates."""
    groups = defaultdict(list)
    for m, f in zip(names, fits):
        groups[f.coordinates].append((m, f))
    out = []
    for coords, members in groups.items():
        l_max = max(f.length_max for _, f in members)
        r_max = max(f.moment_arm_max for _, f in members)
        worst = max(members, key=lambda mf: max(mf[1].length_max, mf[1].moment_arm_max))[0]
        span = ", ".join(f"{c} [{ranges[c][0]:.3g}, {ranges[c][1]:.3g}]" for c in coords) or "no coordinate"
        muscle_names = [m for m, _ in members]
        out.append(ReportEntry(
            element=f"{source}: muscles {', '.join(muscle_names)}",
            became=f"{len(members)} muscle path(s) as polynomials of degree <= "
                   f"{max(f.degree for _, f in members)} in {', '.join(coords) or 'no coordinate'}",
            approximation=(f"geometric paths fitted over the coordinate ranges {span}: max length error "
                           f"{1e3 * l_max:.3g} mm, max moment-arm error {1e3 * r_max:.3g} mm (worst {worst}; "
                           f"{members[0][1].n_test} held-out poses)"),
            max_error=max(l_max, r_max), status=APPROXIMATED,
            details={"kind": "muscle paths", "muscles": tuple(muscle_names), "coordinates": coords, "length_max": l_max,
                     "moment_arm_max": r_max, "fits": tuple(f for _, f in members)}))
    return out


def _crossed_coordinates(doc, kin: OsimKinematics, specs) -> dict[str, set]:
    """Per muscle: the coordinates whose joints lie between its bodies in the tree, and those its
    moving and conditional points name."""
    parent = {jk.child: jk for jk in kin.joints}

    def chain(body):
        out = []
        while body in parent:
            out.append(parent[body])
            body = parent[body].parent
        return out

    out = {}
    for s in specs:
        bodies = set(s.bodies)
        # a joint lies between the bodies if some but not all of them are below it
        below = defaultdict(int)
        joints = {}
        for b in bodies:
            for jk in chain(b):
                key = id(jk)
                below[key] += 1
                joints[key] = jk
        coords = set(s.coordinates)
        for key, n in below.items():
            if n < len(bodies):
                coords.update(joints[key].coordinates)
        out[s.muscle] = coords
    return out

