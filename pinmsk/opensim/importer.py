"""Importing an OpenSim model as pinmsk parts: :func:`read_import`, :func:`write_import`.

:func:`read_import` reads the ``.osim`` (:func:`pinmsk.io.osim.read_osim`), builds
the skeleton (:func:`pinmsk.opensim.skeleton.build_skeleton`: bodies, joints,
coordinates, gravity, markers as frames) and returns an :class:`OsimImport`: the
Pinocchio model, the model's ``meta``, the muscles and components the hooks made,
and the :class:`~pinmsk.opensim.report.ImportReport`.  ``model.py`` builds the
frozen :class:`~pinmsk.model.Model` from it (``opensim/`` sits below ``model.py``):
:func:`pinmsk.model.import_osim` returns ``(Model, ImportReport)`` and
``pinmsk.load_model("model.osim")`` the model (with one warning if something is
approximated or not imported).

Muscles, actuators and contacts are brought in by *hooks* (``hooks=``): each is
called as ``hook(doc, skeleton)`` and returns a :class:`HookResult` -- a
:class:`~pinmsk.muscles.muscle_set.MuscleSet` (or None), components (effects,
contacts), its report entries, and the ``where`` strings
(:attr:`pinmsk.io.osim.OsimElement.where`) of the elements it handled.  Every
muscle, actuator, contact force and other element no hook handled gets a
"not imported" entry, so nothing is dropped silently.

:func:`write_import` writes the skeleton as a URDF plus a TOML sidecar (and the
marker set and the report) that ``load_model`` reads back to the same skeleton.

The ``meta`` carries what the skeleton does not hold: ``osim`` (the source),
``coordinate_order`` (OpenSim's), ``locked_coordinates``, ``clamped_coordinates``,
``coupled_coordinates``, ``osim_motion_types`` (Rotational / Translational /
Coupled: OpenSim converts only Rotational coordinates between degrees and radians
in its files), ``coordinate_map`` (:class:`~pinmsk.opensim.skeleton.CoordinateMap`),
``markers`` and ``import_report``.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence
from xml.sax.saxutils import quoteattr

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ..io.osim import OsimDocument, read_osim
from .report import NOT_IMPORTED, ImportReport, ReportEntry
from .skeleton import LOCKED_MODES, NONLINEAR_MODES, Skeleton, build_skeleton

__all__ = ["OsimImport", "HookResult", "ImportHook", "read_import", "write_import", "warn_report",
           "urdf_string"]


@dataclass(frozen=True)
class HookResult:
    """What an import hook made: ``muscles`` (a MuscleSet or None), ``components`` (effects and contacts),
    its report ``entries``, and the ``handled`` elements (their ``where`` strings)."""

    muscles: Any = None
    components: tuple = ()
    entries: tuple[ReportEntry, ...] = ()
    handled: tuple[str, ...] = ()


#: ``hook(doc, skeleton) -> HookResult``.
ImportHook = Callable[[OsimDocument, Skeleton], HookResult]


@dataclass(frozen=True)
class OsimImport:
    """The parts of an imported OpenSim model (``model.py`` makes the Model of them)."""

    name: str
    pin_model: pin.Model
    meta: dict
    report: ImportReport
    skeleton: Skeleton
    muscles: Any = None
    components: tuple = field(default_factory=tuple)


def read_import(path, *, locked: str = "joint", nonlinear: str = "fit",
                hooks: Sequence[ImportHook] = ()) -> OsimImport:
    """The :class:`OsimImport` of the OpenSim model at ``path`` (see the module docstring).

    ``locked``: ``"joint"`` (default) keeps locked coordinates as joints, ``"weld"`` fixes them at their
    default values.  ``nonlinear``: ``"fit"`` (default) replaces joints whose axes are nonlinear in a
    coordinate by best-fitting fixed-axis joints (their errors are in the report); ``"exact"`` gives each
    such axis a Pinocchio joint of its own (a dependent coordinate, filled by ``meta['coordinate_map']``;
    the model then has more coordinates than OpenSim's).  ``hooks`` import muscles, actuators and contacts.
    """
    p = Path(str(path))
    if p.suffix.lower() != ".osim":
        raise ModelError(f"{p}: an OpenSim model file ends in .osim")
    if nonlinear not in NONLINEAR_MODES:
        raise ModelError(f"nonlinear must be one of {NONLINEAR_MODES}, got {nonlinear!r}")
    doc = read_osim(p)
    skel = build_skeleton(doc, locked=locked, nonlinear=nonlinear)
    pm = skel.pin_model
    entries = list(skel.entries)
    handled: set[str] = set()
    muscles, components = None, []
    for hook in hooks:
        res = hook(doc, skel)
        if res.muscles is not None:
            if muscles is not None:
                raise ModelError(f"{p}: two import hooks both made the muscles")
            muscles = res.muscles
        components += list(res.components)
        entries += list(res.entries)
        handled.update(res.handled)
    entries += _not_imported(doc, handled)
    report = ImportReport(source=str(p), entries=tuple(entries), bounds=dict(skel.bounds))
    meta = _meta(doc, skel, p)
    meta["import_report"] = report
    meta["description"] = (f"imported from OpenSim model '{doc.name}' ({p.name}): {len(report.approximations)} "
                           f"approximated element(s), {len(report.not_imported)} element(s) not imported "
                           "(model.meta['import_report'])")
    return OsimImport(name=p.stem, pin_model=pm, meta=meta, report=report, skeleton=skel, muscles=muscles,
                      components=tuple(components))


def warn_report(report: ImportReport, *, stacklevel: int = 3) -> None:
    """One UserWarning naming the approximated joints (with their errors) and counting what is not
    imported, if there is any (``load_model`` of an .osim: the numbers are never silently approximate)."""
    import warnings

    parts = []
    paths = [e for e in report.approximations if e.details.get("kind") == "muscle paths"]
    joints = [e for e in report.approximations if e.details.get("kind") != "muscle paths"]
    if joints:
        each = []
        for e in joints:
            name = e.element.split("name=", 1)[-1].strip(">").strip('"')
            rot = e.details.get("max_rotation_error_rad")
            each.append(f"{name} {e.max_error * 1000:.3g} mm" + (f" / {np.degrees(rot):.2g} deg" if rot and rot > 1e-6 else ""))
        text = (f"{len(joints)} joint(s) approximated by fixed-axis joints (max error of the "
                f"child body's origin / orientation: {', '.join(each)})")
        if report.bounds:
            frame, worst = max(report.bounds.items(), key=lambda kv: kv[1])
            text += f", positions below them off by up to {worst * 1000:.3g} mm (a bound; at {frame})"
        parts.append(text)
    if paths:
        worst = max(paths, key=lambda e: e.max_error)
        parts.append(f"{sum(len(e.details.get('muscles', ())) for e in paths)} muscle path(s) fitted by polynomials "
                     f"(max length error {1e3 * max(e.details['length_max'] for e in paths):.3g} mm, max moment-arm "
                     f"error {1e3 * max(e.details['moment_arm_max'] for e in paths):.3g} mm; worst group "
                     f"{', '.join(worst.details['muscles'][:3])})")
    if report.not_imported:
        kinds = sorted({e.element.split("<", 1)[-1].split(" ", 1)[0] for e in report.not_imported})
        parts.append(f"{len(report.not_imported)} element(s) not imported yet ({', '.join(kinds)})")
    if parts:
        warnings.warn(f"{Path(report.source).name}: {'; '.join(parts)}; the import report is "
                      "model.meta['import_report']", UserWarning, stacklevel=stacklevel)


def _meta(doc: OsimDocument, skel: Skeleton, path: Path) -> dict:
    return {
        "osim": str(path), "osim_import_options": dict(skel.options), "up_axis": "y",
        "coordinate_order": list(skel.coordinate_order),
        "locked_coordinates": dict(skel.locked), "welded_coordinates": dict(skel.welded),
        "clamped_coordinates": list(skel.clamped), "coupled_coordinates": [dict(c) for c in skel.couplings],
        "osim_motion_types": dict(skel.motion_types),
        "coordinate_map": skel.coordinate_map,
        "dependent_coordinates": {n: {"joint": d.joint, "axis": d.axis, "of": list(d.of), "function": repr(d.function)}
                                  for n, d in skel.dependent.items()},
        "virtual_coordinates": list(skel.virtual),
        "markers": [{"name": n, "body": b, "position": T[:3, 3].tolist()} for n, (b, T) in skel.markers.items()],
        "credits": doc.credits,
    }


def _not_imported(doc: OsimDocument, handled: set) -> list[ReportEntry]:
    out = []
    for m in doc.muscles:
        if m.where in handled:
            continue
        what = "muscle" if m.is_muscle else "path force"
        out.append(ReportEntry(element=m.where, became=f"{what} with {len(m.path.points) if m.path else 0} path "
                               f"points, {len(m.path.wraps) if m.path else 0} wraps: not imported yet",
                               status=NOT_IMPORTED))
    for a in doc.actuators:
        if a.where not in handled:
            target = a.coordinate or ", ".join(a.bodies) or "?"
            out.append(ReportEntry(element=a.where, became=f"actuator on {target}: not imported yet",
                                   status=NOT_IMPORTED))
    for c in doc.contact_forces:
        if c.where not in handled:
            out.append(ReportEntry(element=c.where, became=f"contact between {', '.join(c.geometry)}: not imported "
                                   "yet", status=NOT_IMPORTED))
    for o in doc.other:
        if o.where not in handled:
            out.append(ReportEntry(element=o.where, became=f"{o.category}: not imported (pinmsk has no equivalent "
                                   "yet)", status=NOT_IMPORTED))
    return out


# ---------------------------------------------------------------------------
# URDF + sidecar
# ---------------------------------------------------------------------------

def write_import(model_or_path, out_dir, *, name: str | None = None) -> dict[str, Path]:
    """Write the skeleton of an OpenSim model as ``<name>.urdf`` + ``<name>.toml`` (the sidecar that
    :func:`pinmsk.load_model` reads), ``<name>_markers.toml`` (its marker set) and
    ``<name>_import_report.txt``, in ``out_dir`` (created if needed).  Nothing is left behind on error.

    ``model_or_path``: the ``.osim`` path, or a model imported from one (it is re-imported from its
    ``meta['osim']`` with the same options and gravity).  Returns ``{"urdf", "sidecar", "markers", "report"}``
    paths.
    """
    from ..io.output_files import atomic_write, output_folder, output_transaction

    if isinstance(model_or_path, (str, Path)):
        path, options, gravity = Path(model_or_path), {}, None     # the file's own gravity
    else:
        meta = getattr(model_or_path, "meta", None)
        if meta is None or not meta.get("osim"):
            raise ModelError("write_import takes an .osim path or a model imported from one "
                             f"(model '{getattr(model_or_path, 'name', model_or_path)}' has no meta['osim'])")
        path, options = Path(meta["osim"]), dict(meta.get("osim_import_options") or {})
        gravity = np.asarray(model_or_path.gravity, dtype=float)
    locked = options.get("locked", "joint")
    if locked not in LOCKED_MODES:
        raise ModelError(f"write_import: unknown locked option {locked!r}")
    imp = read_import(path, locked=locked, nonlinear=options.get("nonlinear", "fit"))
    report, skel = imp.report, imp.skeleton
    gravity = np.asarray(skel.doc.gravity, dtype=float) if gravity is None else gravity
    stem = name or re.sub(r"[^A-Za-z0-9_.-]", "_", path.stem)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", stem):
        raise ModelError(f"write_import: name {stem!r} must be letters, digits, '_', '.' or '-'")
    urdf_text = urdf_string(skel, name=stem)
    out = Path(out_dir)
    files = {"urdf": out / f"{stem}.urdf", "sidecar": out / f"{stem}.toml",
             "markers": out / f"{stem}_markers.toml", "report": out / f"{stem}_import_report.txt"}
    with output_transaction():
        output_folder(out)
        atomic_write(files["urdf"], lambda fh: fh.write(urdf_text))
        atomic_write(files["sidecar"], lambda fh: fh.write(_sidecar(imp, stem, path, gravity)))
        atomic_write(files["markers"], lambda fh: fh.write(_markers_toml(imp.meta, path)))
        atomic_write(files["report"], lambda fh: fh.write(report.format(verbose=True) + "\n"))
    return files


def _num(x: float) -> str:
    return repr(float(x)) if np.isfinite(x) else ("1e308" if x > 0 else "-1e308")


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def urdf_string(skel: Skeleton, *, name: str) -> str:
    """The URDF of a skeleton (links, joints in the parser's order, marker links), as text."""
    lines = ['<?xml version="1.0"?>',
             f"<!-- written by pinmsk from {skel.doc.source}; an OpenSim model's skeleton: y is up, gravity "
             f"{list(skel.doc.gravity)} m/s^2 (in the sidecar) -->",
             f"<robot name={quoteattr(name)}>"]
    marker_links = {n: b for n, (b, _) in skel.markers.items()}
    for link in skel.links.values():
        if link.inertia is None:
            lines.append(f"  <link name={quoteattr(link.name)}/>")
            continue
        I = link.inertia
        lines += [f"  <link name={quoteattr(link.name)}>",
                  "    <inertial>",
                  f'      <origin xyz="{_vec(link.com)}" rpy="0 0 0"/>',
                  f'      <mass value="{_num(link.mass)}"/>',
                  f'      <inertia ixx="{_num(I[0][0])}" ixy="{_num(I[0][1])}" ixz="{_num(I[0][2])}" '
                  f'iyy="{_num(I[1][1])}" iyz="{_num(I[1][2])}" izz="{_num(I[2][2])}"/>',
                  "    </inertial>",
                  "  </link>"]
    for mname in marker_links:
        lines.append(f"  <link name={quoteattr(mname)}/>")
    used = {j.name for j in skel.joints} | set(skel.links) | set(marker_links)
    for uj in skel.joints:
        lines += _urdf_joint(uj.name, uj.kind, uj.parent, uj.child, uj.origin, uj.axis, uj.limits)
    for mname, (body, T) in skel.markers.items():
        jname = f"{mname}_marker_joint"
        i = 1
        while jname in used:
            jname, i = f"{mname}_marker_joint_{i}", i + 1
        used.add(jname)
        lines += _urdf_joint(jname, "fixed", body, mname, T, None, None)
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def _urdf_joint(name, kind, parent, child, T, axis, limits) -> list[str]:
    rpy = pin.rpy.matrixToRpy(np.asarray(T[:3, :3], dtype=float))
    out = [f"  <joint name={quoteattr(name)} type=\"{kind}\">",
           f"    <parent link={quoteattr(parent)}/>",
           f"    <child link={quoteattr(child)}/>",
           f'    <origin xyz="{_vec(T[:3, 3])}" rpy="{_vec(rpy)}"/>']
    if kind != "fixed":
        from .skeleton import EFFORT_LIMIT, VELOCITY_LIMIT
        out += [f'    <axis xyz="{_vec(axis)}"/>',
                f'    <limit lower="{_num(limits[0])}" upper="{_num(limits[1])}" effort="{_num(EFFORT_LIMIT)}" '
                f'velocity="{_num(VELOCITY_LIMIT)}"/>']
    out.append("  </joint>")
    return out


def _toml_str(s: str) -> str:
    return json.dumps(str(s), ensure_ascii=False)


def _sidecar(imp: OsimImport, stem: str, source: Path, gravity) -> str:
    report = imp.report
    order = ", ".join(_toml_str(c) for c in imp.meta["coordinate_order"])
    g = ", ".join(_num(x) for x in gravity)
    lines = [f"# pinmsk model sidecar written by pinmsk's OpenSim import from {source.name}.",
             "# The skeleton only: bodies, joints, coordinates, gravity, markers (as frames; also in",
             f"# {stem}_markers.toml).  What was approximated or not imported: {stem}_import_report.txt.",
             "# Sidecar format: urdf/README.md of pinmsk.",
             ""]
    for e in report.approximations:
        lines.append(f"# APPROXIMATED: {e.line()}")
    for e in report.entries:
        if e.status == "note" and any(w in e.became for w in ("coupled", "locked", "dependent", "angular-velocity")):
            lines.append(f"# NOTE: {e.line()}")
    if len(lines) > 5:
        lines.append("")
    lines += ["[model]",
              f"name = {_toml_str(stem)}",
              f"urdf = {_toml_str(stem + '.urdf')}",
              f"gravity = [{g}]",
              'up_axis = "y"',
              f"description = {_toml_str(imp.meta['description'].replace(_REPORT_KEY, stem + '_import_report.txt'))}",
              f"coordinate_order = [{order}]", ""]
    return "\n".join(lines)


_REPORT_KEY = "model.meta['import_report']"


def _markers_toml(meta: dict, source: Path) -> str:
    lines = [f"# The marker set of OpenSim model {source.name} (positions in their bodies' frames, m).", ""]
    for m in meta.get("markers") or ():
        lines += ["[[markers]]", f"name = {_toml_str(m['name'])}", f"body = {_toml_str(m['body'])}",
                  f"position = [{', '.join(_num(x) for x in m['position'])}]", ""]
    return "\n".join(lines)
