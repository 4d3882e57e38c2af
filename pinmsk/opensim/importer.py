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

:func:`write_import` writes the model as a URDF plus a TOML sidecar (and the
marker set and the report) that ``load_model`` reads back to the same model: the
skeleton (with a link for each contact sphere's frame), the coordinate map of an
exact import (its OpenSim functions), the muscles (parameters, fitted path
polynomials and their errors), the actuators, the contacts and the effects, and
the path of the source ``.osim`` (whose geometric muscle paths the viewer draws).

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
from typing import Any, Mapping, Sequence

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ..io.osim import OsimDocument, read_osim
from .hooks import HookResult, ImportHook
from .report import APPROXIMATED, NOT_IMPORTED, ImportReport, ReportEntry, paths_warning
from .skeleton import LOCKED_MODES, NONLINEAR_MODES, Skeleton, build_skeleton

__all__ = ["OsimImport", "HookResult", "ImportHook", "read_import", "write_import", "warn_report",
           "urdf_string", "osim_digest"]


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


def read_import(path, *, locked: str = "joint", nonlinear: str = "exact",
                hooks: Sequence[ImportHook] = ()) -> OsimImport:
    """The :class:`OsimImport` of the OpenSim model at ``path`` (see the module docstring).

    ``locked``: ``"joint"`` (default) keeps locked coordinates as joints, ``"weld"`` fixes them at their
    default values.  ``nonlinear``: ``"exact"`` (default) gives each joint axis that is a nonlinear function
    of a coordinate a Pinocchio joint of its own (a dependent joint, filled from OpenSim's coordinates by
    ``meta['coordinate_map']``, so the skeleton has more joints than OpenSim has coordinates; analyses take
    and report OpenSim's coordinates); ``"fit"`` replaces such joints by best-fitting fixed-axis joints
    (their errors are in the report).  ``hooks`` import muscles, actuators and contacts.
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
    known = report.entries_so_far          # the muscle paths' fit is deferred to their first use
    fitted = " besides the muscle paths' polynomial fits" if report.pending else ""
    meta["description"] = (f"imported from OpenSim model '{doc.name}' ({p.name}): "
                           f"{sum(e.status == APPROXIMATED for e in known)} approximated element(s){fitted}, "
                           f"{sum(e.status == NOT_IMPORTED for e in known)} element(s) not imported "
                           "(model.meta['import_report'])")
    return OsimImport(name=p.stem, pin_model=pm, meta=meta, report=report, skeleton=skel, muscles=muscles,
                      components=tuple(components))


def warn_report(report: ImportReport, *, stacklevel: int = 3) -> None:
    """One UserWarning naming the approximated joints (with their errors) and counting what is not
    imported, if there is any (``load_model`` of an .osim: the numbers are never silently approximate).
    Deferred work is not run for it: the muscle paths' fit warns when it runs (on first use)."""
    import warnings

    entries = report.entries_so_far
    parts = []
    joints = [e for e in entries if e.status == APPROXIMATED and e.details.get("kind") != "muscle paths"]
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
    paths = paths_warning(entries)
    if paths:
        parts.append(paths)
    missing = [e for e in entries if e.status == NOT_IMPORTED]
    if missing:
        parts.append(f"{len(missing)} element(s) not imported yet ({missing_names(missing)})")
    if parts:
        warnings.warn(f"{Path(report.source).name}: {'; '.join(parts)}; the import report is "
                      "model.meta['import_report']", UserWarning, stacklevel=stacklevel)


def missing_names(entries, most: int = 6) -> str:
    """The elements of report ``entries`` by type and name: ``HuntCrossleyForce foot_r, foot_l;
    PrescribedController R-inverter-controls`` (at most ``most`` names a type, then how many more)."""
    by_type: dict[str, list[str]] = {}
    for e in entries:
        tag = e.element.split("<", 1)[-1]
        kind = tag.split(" ", 1)[0].rstrip(">")
        name = tag.split('name="', 1)[1].split('"', 1)[0] if 'name="' in tag else ""
        names = by_type.setdefault(kind, [])
        if name and name not in names:
            names.append(name)
    out = []
    for kind in sorted(by_type):
        names = by_type[kind]
        more = f" and {len(names) - most} more" if len(names) > most else ""
        out.append(f"{kind} {', '.join(names[:most])}{more}" if names else kind)
    return "; ".join(out)


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
        # Simbody's Ball and Free mobilizers: their rotations' speeds are angular-velocity components
        "euler_rate_convention": _euler_rate_convention(doc),
        # each FreeJoint's/BallJoint's body-fixed X-Y-Z rotation coordinates (OpenSim's ID tool convention)
        "euler_rotation_coordinates": [[c.name for c in j.coordinates[:3]] for j in doc.joints
                                       if j.type in ("FreeJoint", "BallJoint") and len(j.coordinates) >= 3],
    }


def _euler_rate_convention(doc: OsimDocument) -> str | None:
    """The note on the FreeJoints and BallJoints (Simbody's Ball and Free mobilizers, whose rotations' speeds
    are angular-velocity components) that inverse dynamics writes in its header and warning; None without."""
    from .skeleton import EULER_RATE_NOTE
    euler = [f"{j.name} ({j.type})" for j in doc.joints if j.type in ("FreeJoint", "BallJoint")]
    return f"joints {', '.join(euler)}: {EULER_RATE_NOTE}" if euler else None


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

def write_import(model_or_path, out_dir, *, name: str | None = None, hooks: Sequence[ImportHook] | None = None,
                 nonlinear: str | None = None) -> dict[str, Path]:
    """Write an OpenSim model as ``<name>.urdf`` + ``<name>.toml`` (the sidecar that :func:`pinmsk.load_model`
    reads back to the same model), ``<name>_markers.toml`` (its marker set) and ``<name>_import_report.txt``,
    in ``out_dir`` (created if needed).  Nothing is left behind on error.

    The sidecar carries the skeleton's gravity and coordinate order, the map from OpenSim's coordinates to
    the dependent joints of an exact skeleton (``[coordinate_map]``: each joint's OpenSim function, not
    samples; :meth:`~pinmsk.opensim.skeleton.CoordinateMap.to_spec`), the muscles (``[muscle_model]``,
    ``[[muscles]]``: the muscle model's type and parameters, each path polynomial with its fit errors), the
    actuators (``[[actuators]]``, :func:`pinmsk.actuators.to_spec`), the contacts (``[[contacts]]``,
    :func:`pinmsk.contact.spec.to_spec`; the frame of each OpenSim contact sphere becomes a link of the URDF,
    fixed to its body where OpenSim places the sphere), the effects (``[[effects]]``: type, target,
    parameter values and options) and ``[model] osim``, the source ``.osim`` relative to the sidecar (with
    its digest), from which the viewer draws the geometric muscle paths.  Each component's entry is read
    back and compared with the component before anything is written; one that would not come back equal
    (a component type the format has no entry for, an effect with bounds or fixed parameters, which
    ``[[effects]]`` cannot hold) is left out with a UserWarning and a ``# NOT WRITTEN`` comment naming it.
    Standard errors of fitted parameters are not written.

    ``model_or_path``: the ``.osim`` path (imported with ``import_osim``'s default hooks, or ``hooks``, and
    ``nonlinear``, default ``"exact"``), or a model imported from one (its muscles, components, gravity and
    report are written; the skeleton is rebuilt from its ``meta['osim']`` with the same options).  Returns
    ``{"urdf", "sidecar", "markers", "report"}`` paths.
    """
    from ..io.output_files import atomic_write, output_folder, output_transaction

    if isinstance(model_or_path, (str, Path)):
        path, options, gravity = Path(model_or_path), {}, None     # the file's own gravity
        if nonlinear is not None:
            options["nonlinear"] = nonlinear
        muscles = report = description = frames_model = None
        components = ()
    else:
        meta = getattr(model_or_path, "meta", None)
        if meta is None or not meta.get("osim"):
            raise ModelError("write_import takes an .osim path or a model imported from one "
                             f"(model '{getattr(model_or_path, 'name', model_or_path)}' has no meta['osim'])")
        if nonlinear is not None or hooks is not None:
            raise ModelError("write_import: nonlinear= and hooks= apply to an .osim path; a model is written "
                             "as it was imported")
        path, options = Path(meta["osim"]), dict(meta.get("osim_import_options") or {})
        gravity = np.asarray(model_or_path.gravity, dtype=float)
        muscles, report, description = model_or_path.muscles, meta.get("import_report"), meta.get("description")
        components, frames_model = tuple(model_or_path.components), model_or_path.pin
    locked = options.get("locked", "joint")
    if locked not in LOCKED_MODES:
        raise ModelError(f"write_import: unknown locked option {locked!r}")
    if hooks is None and muscles is None and report is None:
        from .contacts import contact_hook
        from .muscle_import import DEFAULT_HOOKS
        hooks = (*DEFAULT_HOOKS, contact_hook)          # import_osim's defaults
    imp = read_import(path, locked=locked, nonlinear=options.get("nonlinear", "exact"), hooks=hooks or ())
    if report is None:
        report, muscles, components = imp.report, imp.muscles, imp.components
    import warnings
    with warnings.catch_warnings():     # the fit's errors are written to the sidecar and the report
        warnings.filterwarnings("ignore", message=r".*muscle path\(s\) fitted by polynomials", category=UserWarning)
        report.entries                  # runs the deferred work (the muscle paths' fit)
    skel = imp.skeleton
    entries, unwritten = _component_entries(components)
    if unwritten:
        import warnings
        warnings.warn(f"write_import: {len(unwritten)} component(s) are not written to the sidecar: "
                      f"{'; '.join(f'{label} ({why})' for label, why in unwritten)}; add them to the loaded "
                      "model again (model + component)", UserWarning, stacklevel=2)
    frames = _component_frames(entries, skel, imp.pin_model if frames_model is None else frames_model)
    gravity = np.asarray(skel.doc.gravity, dtype=float) if gravity is None else gravity
    stem = name or re.sub(r"[^A-Za-z0-9_.-]", "_", path.stem)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", stem):
        raise ModelError(f"write_import: name {stem!r} must be letters, digits, '_', '.' or '-'")
    out = Path(out_dir)
    urdf_text = urdf_string(skel, name=stem, frames=frames)
    sidecar_text = _sidecar(imp, stem, path, gravity, report=report, muscles=muscles,
                            description=description or imp.meta["description"], entries=entries,
                            unwritten=[label for label, _ in unwritten], source_path=_relative(path, out))
    files = {"urdf": out / f"{stem}.urdf", "sidecar": out / f"{stem}.toml",
             "markers": out / f"{stem}_markers.toml", "report": out / f"{stem}_import_report.txt"}
    with output_transaction():
        output_folder(out)
        atomic_write(files["urdf"], lambda fh: fh.write(urdf_text))
        atomic_write(files["sidecar"], lambda fh: fh.write(sidecar_text))
        atomic_write(files["markers"], lambda fh: fh.write(_markers_toml(imp.meta, path)))
        atomic_write(files["report"], lambda fh: fh.write(report.format(verbose=True) + "\n"))
    return files


def _num(x: float) -> str:
    return repr(float(x)) if np.isfinite(x) else ("1e308" if x > 0 else "-1e308")


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def quoteattr(text: str) -> str:
    """``xml.sax.saxutils.quoteattr`` (imported when a URDF is written: it imports urllib)."""
    from xml.sax.saxutils import quoteattr as quote
    return quote(text)


def urdf_string(skel: Skeleton, *, name: str, frames: Mapping[str, tuple[str, np.ndarray]] | None = None) -> str:
    """The URDF of a skeleton (links, joints in the parser's order, marker links), as text; ``frames``
    (``{name: (link, 4x4 placement in it)}``, e.g. the contact spheres' frames) become links too, each fixed
    to its link by a joint ``<name>_frame_joint``."""
    lines = ['<?xml version="1.0"?>',
             f"<!-- written by pinmsk from {skel.doc.source}; an OpenSim model's skeleton: y is up, gravity "
             f"{list(skel.doc.gravity)} m/s^2 (in the sidecar) -->",
             f"<robot name={quoteattr(name)}>"]
    marker_links = {n: b for n, (b, _) in skel.markers.items()}
    frames = dict(frames or {})
    clash = sorted(set(frames) & (set(skel.links) | set(marker_links)))
    if clash:
        raise ModelError(f"urdf_string: frame(s) {clash} are already links of the skeleton")
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
    for mname in [*marker_links, *frames]:
        lines.append(f"  <link name={quoteattr(mname)}/>")
    used = {j.name for j in skel.joints} | set(skel.links) | set(marker_links) | set(frames)
    for uj in skel.joints:
        lines += _urdf_joint(uj.name, uj.kind, uj.parent, uj.child, uj.origin, uj.axis, uj.limits)
    for suffix, fixed in (("marker_joint", skel.markers), ("frame_joint", frames)):
        for mname, (body, T) in fixed.items():
            jname = f"{mname}_{suffix}"
            i = 1
            while jname in used:
                jname, i = f"{mname}_{suffix}_{i}", i + 1
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


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml_key(k: str) -> str:
    return k if _BARE_KEY.fullmatch(k) else _toml_str(k)


def _toml_value(v) -> str:
    """A TOML value (strings, numbers, booleans, lists, inline tables) with floats that read back exactly
    (infinities as TOML's ``inf``)."""
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if np.isnan(v):
            raise ModelError("write_import: cannot write NaN as a TOML value")
        return repr(float(v)) if np.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise ModelError(f"write_import: cannot write {v!r} as TOML")


def _sidecar(imp: OsimImport, stem: str, source: Path, gravity, *, report: ImportReport, muscles,
             description: str, entries: Mapping[str, list] | None = None, unwritten=(), source_path=None) -> str:
    order = ", ".join(_toml_str(c) for c in imp.meta["coordinate_order"])
    g = ", ".join(_num(x) for x in gravity)
    cmap = imp.skeleton.coordinate_map
    exact = cmap is not None and not cmap.identity
    entries = dict(entries or {})
    parts = [what for what, key in (("the actuators", "actuators"), ("the contacts (their spheres' frames are "
                                     "links of the URDF)", "contacts"), ("the effects", "effects")) if entries.get(key)]
    if exact:
        parts.append("the map from OpenSim's coordinates to the dependent joints")
    lines = [f"# pinmsk model sidecar written by pinmsk's OpenSim import from {source.name}.",
             "# Bodies, joints, coordinates, gravity and markers (as frames; also in "
             f"{stem}_markers.toml), the muscles",
             "# (their paths as the fitted polynomials, with the fits' errors)"
             + "".join(f",\n# {p}" for p in parts[:-1]) + (f" and\n# {parts[-1]}." if parts else "."),
             f"# What was approximated or not imported: {stem}_import_report.txt.  Format: urdf/README.md of pinmsk.",
             ""]
    head = len(lines)
    if unwritten:
        lines.append(f"# NOT WRITTEN (they would not read back equal; see the warning of write_import): "
                     f"{', '.join(unwritten)}")
    for e in report.approximations:
        lines.append(f"# APPROXIMATED: {e.line()}")
    for e in report.entries:
        if e.status == "note" and any(w in e.became for w in ("coupled", "locked", "dependent", "angular-velocity")):
            lines.append(f"# NOTE: {e.line()}")
    if len(lines) > head:
        lines.append("")
    paths = _path_errors(report) if muscles is not None else {}
    lines += ["[model]",
              f"name = {_toml_str(stem)}",
              f"urdf = {_toml_str(stem + '.urdf')}",
              f"gravity = [{g}]",
              'up_axis = "y"',
              f"description = {_toml_str(description.replace(_REPORT_KEY, stem + '_import_report.txt'))}",
              f"coordinate_order = [{order}]"]
    if source_path is not None:
        lines += [f"osim = {_toml_str(source_path)}", f"osim_digest = {_toml_str(osim_digest(source))}"]
    if muscles is not None:
        lines.append(f"default_paths = {_toml_str(FITTED_PATHS)}")
        lines += [""] + _muscles_toml(muscles, paths)
    for section in ("effects", "actuators", "contacts"):
        for spec in entries.get(section, ()):
            lines += ["", f"[[{section}]]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in spec.items()]
    if exact:
        lines += [""] + _coordinate_map_toml(cmap)
    return "\n".join(lines) + "\n"


def osim_digest(path) -> str:
    """The digest ``[model] osim_digest`` of a sidecar records of its source .osim (blake2b, 128 bits, hex)."""
    import hashlib
    return hashlib.blake2b(Path(path).read_bytes(), digest_size=16).hexdigest()


def _relative(path: Path, out: Path) -> str:
    """``path`` relative to the folder ``out`` (POSIX separators), or absolute where it cannot be (another drive)."""
    import os
    try:
        return Path(os.path.relpath(Path(path).resolve(), Path(out).resolve())).as_posix()
    except ValueError:
        return Path(path).resolve().as_posix()


def _component_entries(components) -> tuple[dict[str, list[dict]], list[tuple[str, str]]]:
    """``({"effects" | "actuators" | "contacts": [sidecar tables]}, [(label, why not written)])``: each
    component's table, kept only if it reads back (through TOML text, as ``load_model`` reads it) to a
    component equal to it in parameters (values, bounds, vary; not standard errors) and options."""
    from ..actuators import IdealActuator
    from ..actuators import from_spec as actuator_from_spec
    from ..actuators import to_spec as actuator_to_spec
    from ..contact.spec import from_spec as contact_from_spec
    from ..contact.spec import to_spec as contact_to_spec
    from ..effects import registry
    from ..io.toml_files import tomllib

    out: dict[str, list[dict]] = {"effects": [], "actuators": [], "contacts": []}
    unwritten = []
    for comp in components:
        if isinstance(comp, IdealActuator):
            section, write, read = "actuators", actuator_to_spec, actuator_from_spec
        elif comp.kind == "contact":
            section, write, read = "contacts", contact_to_spec, contact_from_spec
        else:
            section, write, read = "effects", _effect_spec, registry.from_spec
        try:
            spec = write(comp)
            spec = tomllib.loads(f"x = {_toml_value(spec)}")["x"]          # what load_model will read
            back = read(dict(spec), where=f"the sidecar's [[{section}]] entry of {comp.label}")
        except ModelError as exc:
            unwritten.append((comp.label, str(exc)))
            continue
        if not _same_component(back, comp):
            unwritten.append((comp.label, f"its [[{section}]] entry does not hold all of its settings "
                                          "(bounds or fixed parameters of an effect, or an option)"))
            continue
        out[section].append(spec)
    return out, unwritten


def _effect_spec(effect) -> dict:
    """An effect's ``[[effects]]`` table (:func:`pinmsk.effects.registry.from_spec`): its family, target,
    parameter values and keyword options (the attributes of the same names)."""
    import inspect
    from ..effects import registry
    cls = registry.get(effect.family)
    if cls is not type(effect):
        raise ModelError(f"effect class {type(effect).__name__} is not the registered '{effect.family}'")
    options = {n: getattr(effect, n) for n, p in inspect.signature(cls.__init__).parameters.items()
               if p.kind is inspect.Parameter.KEYWORD_ONLY and getattr(effect, n, None) is not None}
    return {"type": effect.family, **({} if effect.target is None else {"target": effect.target}), **options,
            **effect.values}


def _same_component(a, b) -> bool:
    """``a`` and ``b`` are the same component: equal (type, target, values, options) with the same parameter
    table (bounds and vary flags; standard errors aside) and the same public attributes (its options)."""
    from dataclasses import replace

    def state(c):
        return ({k: replace(p, stderr=None) for k, p in c.params.items()},
                {k: v for k, v in vars(c).items() if not k.startswith("_")})
    try:
        return type(a) is type(b) and a == b and state(a) == state(b)
    except (TypeError, ValueError):          # attributes that do not compare (arrays): not known to be the same
        return False


def _component_frames(entries: Mapping[str, list], skel: Skeleton, pm: pin.Model) -> dict[str, tuple[str, np.ndarray]]:
    """``{frame: (link, 4x4 placement in it)}`` of the frames the written components are fixed to that the
    skeleton's URDF has not (the contact spheres' frames the contact hook added to ``pm``)."""
    have = set(skel.links) | set(skel.markers) | {j.name for j in skel.joints}
    names = [e["frame"] for e in entries.get("contacts", ())]
    names += [e[key] for e in entries.get("effects", ()) for key in ("target", "frame2")
              if isinstance(e.get(key), str) and pm.existFrame(e[key])]
    out = {}
    for name in dict.fromkeys(names):
        if name in have:
            continue
        if not pm.existFrame(name):
            raise ModelError(f"write_import: a component is fixed to frame '{name}', which the model lacks")
        f = pm.frames[pm.getFrameId(name)]
        k = f.parentFrame
        while k > 0 and not (pm.frames[k].name in skel.links and pm.frames[k].type == pin.FrameType.BODY):
            k = pm.frames[k].parentFrame
        body = pm.frames[k]
        if body.name not in skel.links or body.parentJoint != f.parentJoint:
            raise ModelError(f"write_import: frame '{name}' is on no body of the skeleton")
        out[name] = (body.name, (body.placement.inverse() * f.placement).homogeneous)
    return out


#: The path variant name of an imported model's fitted polynomials in its sidecar.
FITTED_PATHS = "fitted"
#: Muscle-model constructor arguments written in ``[muscle_model]`` (one value per model), by sidecar key.
_MODEL_SCALARS = {"tendon_strain0": "tendon_strain", "tau_rise": "tau_rise", "tau_fall": "tau_fall"}


def _path_errors(report: ImportReport) -> dict[str, tuple[float, float]]:
    """``{muscle: (max length error, max moment-arm error)}`` of the polynomial fits in the report (m)."""
    out = {}
    for e in report.entries:
        for f in e.details.get("fits", ()) if e.details.get("kind") == "muscle paths" else ():
            out[f.muscle] = (float(f.length_max), float(f.moment_arm_max))
    return out


def _muscles_toml(muscles, errors: Mapping[str, tuple[float, float]]) -> list[str]:
    """``[muscle_model]`` and ``[[muscles]]`` of a MuscleSet with a PolynomialPath (the sidecar's format)."""
    from ..muscles.paths import PolynomialPath

    path = muscles.path
    if not isinstance(path, PolynomialPath):
        raise ModelError(f"write_import: the muscles' paths are a {type(path).__name__}; an imported model's "
                         "are a PolynomialPath")
    kwargs = muscles.mtu._kwargs()      # the muscle model's constructor arguments (what replace() rebuilds)
    lines = ["[muscle_model]", f"type = {_toml_str(muscles.model_type)}", f"tendon = {_toml_str(muscles.tendon)}"]
    per_muscle = []
    for key, value in kwargs.items():
        if key == "names" or value is None:
            continue
        if key in _MODEL_SCALARS:
            lines.append(f"{_MODEL_SCALARS[key]} = {_toml_value(float(value))}")
        elif np.ndim(value) == 1 and np.size(value) == muscles.n:
            per_muscle.append(key)
        else:
            raise ModelError(f"write_import: muscle model {muscles.model_type} argument {key!r} = {value!r} has no "
                             "sidecar key")
    by_name = dict(zip(path.muscles, path.terms))
    for i, name in enumerate(muscles.names):
        lines += ["", "[[muscles]]", f"name = {_toml_str(name)}"]
        lines += [f"{k} = {_toml_value(float(np.asarray(kwargs[k])[i]))}" for k in per_muscle]
        t = by_name[name]
        lines += [f"[muscles.paths.{FITTED_PATHS}]",
                  f"coordinates = {_toml_value(list(t['coordinates']))}",
                  f"center = {_toml_value([float(x) for x in t['center']])}",
                  f"scale = {_toml_value([float(x) for x in t['scale']])}",
                  f"exponents = {_toml_value([list(map(int, e)) for e in t['exponents']])}",
                  f"coefficients = {_toml_value([float(x) for x in t['coefficients']])}"]
        if name in errors:
            lines += [f"max_length_error = {_toml_value(errors[name][0])}",
                      f"max_moment_arm_error = {_toml_value(errors[name][1])}"]
    return lines


def _coordinate_map_toml(cmap) -> list[str]:
    """The ``[coordinate_map]`` table (:meth:`~pinmsk.opensim.skeleton.CoordinateMap.to_spec`)."""
    spec = cmap.to_spec()
    lines = ["# OpenSim's coordinates -> the Pinocchio joints: each dependent joint is its OpenSim function of",
             "# its coordinates (the CustomJoint axis' function), so motions are given in OpenSim's coordinates.",
             "[coordinate_map]"]
    for key in ("osim_coordinates", "defaults", "welded"):
        lines.append(f"{key} = {_toml_value(spec[key])}")
    for what in ("dependent", "couplers"):
        for rec in spec[what]:
            lines += ["", f"[[coordinate_map.{what}]]"] + [f"{k} = {_toml_value(v)}" for k, v in rec.items()]
    return lines


_REPORT_KEY = "model.meta['import_report']"


def _markers_toml(meta: dict, source: Path) -> str:
    lines = [f"# The marker set of OpenSim model {source.name} (positions in their bodies' frames, m).", ""]
    for m in meta.get("markers") or ():
        lines += ["[[markers]]", f"name = {_toml_str(m['name'])}", f"body = {_toml_str(m['body'])}",
                  f"position = [{', '.join(_num(x) for x in m['position'])}]", ""]
    return "\n".join(lines)
