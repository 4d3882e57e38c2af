"""The corrected model out again: as a pinmsk model file, or as a copy of the user's OpenSim ``.osim``.

:func:`write_model` writes a model with its effects (the fitted values of a
diagnosis) as a TOML sidecar that :func:`pinmsk.load_model` reads back to the
same model: an imported ``.osim`` through :func:`~pinmsk.opensim.importer.write_import`
(URDF + sidecar with the coordinate map of its dependent joints, muscles,
actuators, contacts and ``[[effects]]``), any other sidecar model as a copy of
its sidecar pointing at the same URDF, with the model's components.

:func:`write_osim` writes a copy of the ``.osim`` a model was imported from, edited
in place (every byte outside the edits kept), with the model's effects where
OpenSim has the same physics:

============================  ======================================================================
effect                        in the ``.osim``
============================  ======================================================================
``segment_mass`` (delta)      the mass and inertia of each OpenSim body in the joint scaled by
                              ``1 + delta`` (centre of mass kept)
``scale`` (delta)             every body's mass and inertia scaled by ``1 + delta``
``com_offset`` (dx, dy, dz)   the body's ``mass_center`` moved by ``(dx, dy, dz)`` (body frame)
``payload`` (mass)            a ``Body`` of that mass (no rotational inertia) welded by a
                              ``WeldJoint`` at the payload's point in its OpenSim body
``joint_damping`` (c)         ``ExpressionBasedCoordinateForce`` ``-c*qdot``
``joint_spring`` (k, q0)      ``ExpressionBasedCoordinateForce`` ``-k*(q-q0)``
``end_stop_upper/_lower``     ``CoordinateLimitForce`` acting at that limit only (the other limit
                              moved a full turn out of reach), in OpenSim's degree units
============================  ======================================================================

Everything else (friction, passive-elastic curves, sensor and muscle-level
effects) is listed in the result's ``not_exported`` with the reason: the user
adds those by hand or keeps them in pinmsk.  An ``ExpressionBasedCoordinateForce``
applies its expression as a generalized force on its coordinate, and
OpenSim's inverse dynamics subtracts the model's applied forces, as pinmsk's
``tau = RNEA - sum Q_k`` does, so the inverse dynamics of the two agree.
"""
from __future__ import annotations

import inspect
import os
import xml.parsers.expat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..effects._base import is_prismatic
from ..errors import ModelError
from ..io.output_files import atomic_write

__all__ = ["write_model", "write_osim", "OsimExport", "plain_effects"]

#: Effect families an .osim can hold (see the module docstring).
EXPORTED = ("segment_mass", "scale", "com_offset", "payload", "joint_damping", "joint_spring",
            "end_stop_upper", "end_stop_lower")


# -- the model file ----------------------------------------------------------------------------

def plain_effects(model) -> list:
    """The model's components with each registered effect rebuilt from its family, target, options and
    values only (the bounds a diagnosis fits within are not part of the model): what a sidecar holds."""
    from ..actuators import IdealActuator
    from ..effects import registry
    out = []
    for comp in model.effects:
        if isinstance(comp, IdealActuator) or comp.kind == "contact":
            out.append(comp)
            continue
        try:
            cls = registry.get(comp.family)
        except ModelError:
            out.append(comp)
            continue
        if cls is not type(comp):
            out.append(comp)
            continue
        options = {n: getattr(comp, n) for n, p in inspect.signature(cls.__init__).parameters.items()
                   if p.kind is inspect.Parameter.KEYWORD_ONLY and getattr(comp, n, None) is not None}
        out.append(cls(comp.target, **options, **comp.values))
    return out


def _plain_model(model):
    return model._derive(effects=plain_effects(model))


def check_model_path(path) -> Path:
    """``path`` as a model file to write: a ``.toml`` whose stem is letters, digits, ``_ . -``."""
    p = Path(str(path))
    if p.suffix.lower() != ".toml":
        raise ModelError(f"--save-model {p}: a model file is a .toml sidecar (with its .urdf beside it); "
                         "give a path ending in .toml")
    import re
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", p.stem):
        raise ModelError(f"--save-model {p}: the file name {p.stem!r} must be letters, digits, '_', '.' or '-'")
    if p.exists() and p.is_dir():
        raise ModelError(f"--save-model {p} is a folder, not a file")
    return p


def write_model(model, path) -> dict[str, Path]:
    """Write ``model`` (with its effects) as a sidecar ``path`` (``.toml``) that ``load_model`` reads back.

    An imported ``.osim`` model (``meta['osim']``) is written by
    :func:`~pinmsk.opensim.importer.write_import` next to ``path`` (``<stem>.urdf``, ``<stem>.toml``,
    ``<stem>_markers.toml``, ``<stem>_import_report.txt``): its skeleton, coordinate map, muscles and
    components.  A model loaded from a sidecar gets a copy of that sidecar with ``[model] urdf`` pointing at
    the same URDF (relative to ``path`` when it lies beside or below it, else its absolute path), its gravity, and the model's ``[[effects]]``, ``[[actuators]]`` and
    ``[[contacts]]``.  A bare URDF model gets a sidecar naming the URDF and the gravity.  The returned dict
    has ``"sidecar"`` (and, for an import, ``"urdf"``, ``"markers"``, ``"report"``).  A component the
    sidecar cannot hold is refused by name before anything is written.
    """
    p = check_model_path(path)
    plain = _plain_model(model)
    meta = model.meta
    if meta.get("osim"):
        from .importer import _component_entries, write_import
        # refused before any file is written: a component the sidecar cannot hold
        _, unwritten = _component_entries(plain.components)
        if unwritten:
            raise ModelError("cannot save the model: " + "; ".join(f"{lab} ({why})" for lab, why in unwritten))
        return write_import(plain, p.parent if str(p.parent) else ".", name=p.stem)
    return {"sidecar": _write_sidecar_model(plain, p)}


def _write_sidecar_model(model, p: Path) -> Path:
    from ..io.toml_files import read_toml
    from .importer import _component_entries, _toml_key, _toml_value
    entries, unwritten = _component_entries(model.components)
    if unwritten:
        raise ModelError("cannot save the model: " + "; ".join(f"{lab} ({why})" for lab, why in unwritten))
    src = model.meta.get("sidecar")
    urdf = model.meta.get("urdf")
    if not urdf:
        raise ModelError(f"cannot save model '{model.name}': it was built in memory (no URDF to point at); "
                         "save it from a model loaded from a URDF or a sidecar")
    spec = read_toml(src, what="model sidecar") if src else {"model": {"name": model.name}}
    mspec = dict(spec.get("model", {}))
    ref = str(mspec.get("urdf", ""))
    if not ref.startswith("@"):                 # a path: relative to the new sidecar's folder
        ref = _relative(Path(urdf), p.parent)
    mspec["urdf"] = ref
    mspec["gravity"] = [float(x) for x in np.asarray(model.gravity, dtype=float)]
    if model.meta.get("moment_arms") and "muscles" in spec:
        mspec["default_paths"] = model.meta["moment_arms"]
    if mspec.get("osim") and model.meta.get("source_osim"):
        mspec["osim"] = _relative(Path(model.meta["source_osim"]), p.parent)
    spec["model"] = mspec
    for section in ("effects", "actuators", "contacts"):
        spec.pop(section, None)
        if entries.get(section):
            spec[section] = entries[section]
    lines = [f"# pinmsk model sidecar: model '{model.name}'"
             + (f", from {Path(src).name}," if src else "") + " with its effects as fitted.",
             "# Format: urdf/README.md of pinmsk.", ""]
    for key, val in spec.items():
        if isinstance(val, dict):
            lines.append(f"[{_toml_key(key)}]")
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in val.items()]
            lines.append("")
        elif isinstance(val, list) and all(isinstance(x, dict) for x in val):
            for item in val:
                lines.append(f"[[{_toml_key(key)}]]")
                lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in item.items()]
                lines.append("")
        else:
            lines.insert(3, f"{_toml_key(key)} = {_toml_value(val)}")
    text = "\n".join(lines).rstrip("\n") + "\n"
    return atomic_write(p, lambda fh: fh.write(text), parents=True)


def _relative(target: Path, folder: Path) -> str:
    full = Path(target).resolve()
    try:
        rel = Path(os.path.relpath(full, Path(folder).resolve())).as_posix()
    except ValueError:                          # another drive
        return full.as_posix()
    # beside or below the sidecar: relative (the folder moves as one); elsewhere: where it is
    return full.as_posix() if rel.startswith("..") else rel


# -- the .osim ---------------------------------------------------------------------------------

@dataclass
class OsimExport:
    """What :func:`write_osim` wrote: the file, the changes made and the effects left out (with why)."""

    path: Path
    changes: list = field(default_factory=list)
    not_exported: list = field(default_factory=list)      # [(label, reason)]

    def lines(self) -> list[str]:
        out = [f"wrote {self.path}"]
        out += [f"  {c}" for c in self.changes]
        if self.not_exported:
            out.append(f"pinmsk: warning: {len(self.not_exported)} effect(s) have no OpenSim force and are not in "
                       f"{self.path.name}: " + ", ".join(lab for lab, _ in self.not_exported))
            out += [f"  not exported: {lab}: {why}" for lab, why in self.not_exported]
        return out


@dataclass
class _Element:
    tag: str
    attrs: dict
    start: int               # byte of '<'
    open_end: int            # byte after the start tag's '>'
    close_start: int         # byte of '</tag>' (== open_end for an empty element)
    end: int                 # byte after the element
    parent: int | None
    children: list = field(default_factory=list)

    @property
    def empty(self) -> bool:
        return self.close_start == self.open_end and self.end == self.open_end


def _tag_end(data: bytes, i: int) -> int:
    """Byte after the '>' closing the tag that starts at ``i`` (quotes respected)."""
    q = None
    n = len(data)
    while i < n:
        c = data[i]
        if q is not None:
            if c == q:
                q = None
        elif c in (34, 39):
            q = c
        elif c == 62:
            return i + 1
        i += 1
    raise ModelError("the .osim ends inside a tag")


def _index(data: bytes) -> list[_Element]:
    """Every element of the document with its byte span (expat's positions)."""
    p = xml.parsers.expat.ParserCreate()
    els: list[_Element] = []
    stack: list[int] = []

    def start(name, attrs):
        i = p.CurrentByteIndex
        oe = _tag_end(data, i)
        e = _Element(name, dict(attrs), i, oe, oe, oe, stack[-1] if stack else None)
        if stack:
            els[stack[-1]].children.append(len(els))
        stack.append(len(els))
        els.append(e)

    def end(name):
        k = stack.pop()
        e = els[k]
        if data[e.open_end - 2:e.open_end] == b"/>":
            return                                  # an empty element: its spans are the start tag's
        i = p.CurrentByteIndex
        e.close_start = i
        e.end = _tag_end(data, i)

    p.StartElementHandler, p.EndElementHandler = start, end
    try:
        p.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        raise ModelError(f"the .osim is not valid XML ({exc})") from None
    return els


class _Doc:
    def __init__(self, data: bytes):
        self.data = data
        self.els = _index(data)
        self.edits: list[tuple[int, int, bytes]] = []
        nl = b"\r\n" if b"\r\n" in data[:4096] else b"\n"
        self.nl = nl

    def find(self, tag, parent_tag=None) -> list[int]:
        return [k for k, e in enumerate(self.els) if e.tag == tag
                and (parent_tag is None or (e.parent is not None and self.els[e.parent].tag == parent_tag))]

    def child(self, k, tag) -> int | None:
        for c in self.els[k].children:
            if self.els[c].tag == tag:
                return c
        return None

    def text(self, k) -> str:
        e = self.els[k]
        return self.data[e.open_end:e.close_start].decode("utf-8")

    def set_text(self, k, text: str) -> None:
        e = self.els[k]
        if e.empty:
            self.edits.append((e.start, e.end, f"<{e.tag}>{text}</{e.tag}>".encode()))
        else:
            self.edits.append((e.open_end, e.close_start, text.encode("utf-8")))

    def indent_of(self, pos: int) -> bytes:
        """The whitespace from the line's start to ``pos``."""
        s = self.data.rfind(b"\n", 0, pos) + 1
        ws = self.data[s:pos]
        return ws if ws.strip() == b"" else b""

    def unit(self) -> bytes:
        return b"\t" if b"\n\t" in self.data[:20000] else b"    "

    def append_children(self, k, blocks: list[str]) -> None:
        """Insert XML ``blocks`` as the last children of element ``k`` (an ``<objects>`` list)."""
        e = self.els[k]
        ind = self.indent_of(e.start)
        inner = ind + self.unit()
        body = b"".join(self.nl + _reindent(b, inner, self.unit(), self.nl) for b in blocks)
        if e.empty:
            self.edits.append((e.start, e.end, f"<{e.tag}>".encode() + body + self.nl + ind
                               + f"</{e.tag}>".encode()))
        else:
            # after the last child (or the open tag), before the whitespace of the closing tag's line
            pos = e.close_start - len(self.indent_of(e.close_start))
            pos = pos - len(self.nl) if self.data[pos - len(self.nl):pos] == self.nl else pos
            self.edits.append((pos, pos, body))

    def result(self) -> bytes:
        out = self.data
        for a, b, rep in sorted(self.edits, key=lambda x: (x[0], x[1]), reverse=True):
            out = out[:a] + rep + out[b:]
        return out


def _reindent(block: str, indent: bytes, unit: bytes, nl: bytes) -> bytes:
    """A block written with one tab per level, indented by ``indent`` with the document's ``unit``."""
    lines = block.strip("\n").split("\n")
    out = []
    for ln in lines:
        n = len(ln) - len(ln.lstrip("\t"))
        out.append(indent + unit * n + ln.lstrip("\t").encode("utf-8"))
    return nl.join(out)


def _num(x: float) -> str:
    return repr(float(x))


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def _floats(text: str, n: int, where: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split()], dtype=float)
    except ValueError:
        v = np.zeros(0)
    if v.size != n:
        raise ModelError(f"{where}: expected {n} numbers, found {text.strip()!r}")
    return v


def check_osim_path(path) -> Path:
    p = Path(str(path))
    if p.suffix.lower() != ".osim":
        raise ModelError(f"--save-osim {p}: an OpenSim model file ends in .osim")
    if p.exists() and p.is_dir():
        raise ModelError(f"--save-osim {p} is a folder, not a file")
    return p


def write_osim(model, path, *, source=None) -> OsimExport:
    """Write a copy of the ``.osim`` ``model`` was imported from (``source``, default ``meta['osim']``, or
    the ``[model] osim`` of the sidecar it was loaded from) with
    the model's effects as OpenSim properties and forces (module docstring); returns an :class:`OsimExport`
    with the changes and the effects left out.  Effects the source's import already has (its actuators and
    contacts) are not added again."""
    p = check_osim_path(path)
    origin = source or model.meta.get("osim") or model.meta.get("source_osim")
    if not origin:
        raise ModelError(f"--save-osim: model '{model.name}' was not imported from an OpenSim .osim; "
                         "save it with --save-model OUT.toml")
    src = Path(str(origin))
    if not src.is_file():
        raise ModelError(f"--save-osim: the model's source {src} is not there any more")
    data = src.read_bytes()
    doc = _Doc(data)
    res = OsimExport(p)
    bodies = {doc.els[k].attrs.get("name"): k for k in doc.find("Body")}
    coords = {doc.els[k].attrs.get("name"): k for k in doc.find("Coordinate")}
    pm = model.pin
    from ..actuators import IdealActuator
    inertial = []
    new_bodies, new_joints, new_forces = [], [], []
    used = set(bodies) | {doc.els[k].attrs.get("name") for k, e in enumerate(doc.els)
                          if e.attrs.get("name")}

    def fresh(name):
        n, i = name, 1
        while n in used:
            n, i = f"{name}_{i}", i + 1
        used.add(n)
        return n

    def joint_bodies(body):
        fid = model.frame_id(body)
        j = pm.frames[fid].parentJoint
        return [f.name for f in pm.frames if f.type.name == "BODY" and f.parentJoint == j and f.name in bodies]

    for comp in model.effects:
        fam = comp.family
        if isinstance(comp, IdealActuator) or comp.kind == "contact":
            continue
        v = comp.values
        if fam in ("segment_mass", "scale", "com_offset") or (getattr(comp, "inertial", False)
                                                              and fam != "payload"):
            inertial.append(comp)
        elif fam == "payload":
            if "@" in comp.target:                      # at a body's centre of mass, far end or axis
                body, point = _site_in_body(model, comp, bodies)
            else:
                body, point = _frame_in_body(model, comp.target, bodies)
            if body is None:
                res.not_exported.append((comp.label, f"frame {comp.target} is on no OpenSim body"))
                continue
            bname = fresh(f"payload_{comp.target}")
            jname = fresh(f"{bname}_weld")
            oname = fresh(f"{body}_{bname}_offset")
            parent = "/ground" if body == "ground" else f"/bodyset/{body}"
            new_bodies.append(f"""<Body name="{bname}">
\t<mass>{_num(v['mass'])}</mass>
\t<mass_center>0 0 0</mass_center>
\t<inertia>0 0 0 0 0 0</inertia>
</Body>""")
            new_joints.append(f"""<WeldJoint name="{jname}">
\t<socket_parent_frame>{oname}</socket_parent_frame>
\t<socket_child_frame>/bodyset/{bname}</socket_child_frame>
\t<frames>
\t\t<PhysicalOffsetFrame name="{oname}">
\t\t\t<socket_parent>{parent}</socket_parent>
\t\t\t<translation>{_vec(point)}</translation>
\t\t\t<orientation>0 0 0</orientation>
\t\t</PhysicalOffsetFrame>
\t</frames>
</WeldJoint>""")
            res.changes.append(f"{comp.label}: body {bname} ({v['mass']:.6g} kg) welded to {body} at {_vec(point)} m")
        elif fam in ("joint_damping", "joint_spring", "end_stop_upper", "end_stop_lower"):
            if comp.target not in coords:
                res.not_exported.append((comp.label, f"{comp.target} is not a coordinate of {src.name}"))
                continue
            if fam == "joint_damping":
                expr = f"-{_num(v['c'])}*qdot"
            elif fam == "joint_spring":
                expr = f"-{_num(v['k'])}*(q-({_num(v['q0'])}))"
            if fam in ("joint_damping", "joint_spring"):
                name = fresh(f"{fam}_{comp.target}")
                new_forces.append(f"""<ExpressionBasedCoordinateForce name="{name}">
\t<coordinate>{comp.target}</coordinate>
\t<expression>{expr}</expression>
</ExpressionBasedCoordinateForce>""")
                res.changes.append(f"{comp.label}: ExpressionBasedCoordinateForce {name}: {expr}")
                continue
            rot = not is_prismatic(model, comp.target)
            w = np.pi / 180.0 if rot else 1.0          # OpenSim: N m/deg, deg, N m s/deg for a rotation
            k, lim, d, c = v["stiffness"] * w, v["limit"] / w, v["transition"] / w, v["damping"] * w
            far = 360.0 if rot else 1.0e3
            k_other = k if k > 0 else 1.0
            if fam == "end_stop_upper":
                up, lo, ku, kl = lim, lim - 2 * far, k, k_other
            else:
                up, lo, ku, kl = lim + 2 * far, lim, k_other, k
            name = fresh(f"{fam}_{comp.target}")
            new_forces.append(f"""<CoordinateLimitForce name="{name}">
\t<coordinate>{comp.target}</coordinate>
\t<upper_stiffness>{_num(ku)}</upper_stiffness>
\t<upper_limit>{_num(up)}</upper_limit>
\t<lower_stiffness>{_num(kl)}</lower_stiffness>
\t<lower_limit>{_num(lo)}</lower_limit>
\t<damping>{_num(c)}</damping>
\t<transition>{_num(d)}</transition>
\t<compute_dissipation_energy>false</compute_dissipation_energy>
</CoordinateLimitForce>""")
            side = "upper" if fam == "end_stop_upper" else "lower"
            res.changes.append(f"{comp.label}: CoordinateLimitForce {name} at the {side} limit {lim:.6g} "
                               f"{'deg' if rot else 'm'} (the other limit out of reach)")
        else:
            res.not_exported.append((comp.label, _why_not(fam)))
    _inertias(doc, model, inertial, bodies, src, res)
    for blocks, set_tag in ((new_bodies, "BodySet"), (new_joints, "JointSet"), (new_forces, "ForceSet")):
        if not blocks:
            continue
        sets = doc.find(set_tag)
        if not sets:
            raise ModelError(f"{src}: no <{set_tag}> to add {len(blocks)} element(s) to")
        objs = doc.child(sets[0], "objects")
        if objs is None:
            raise ModelError(f"{src}: <{set_tag}> has no <objects>")
        doc.append_children(objs, blocks)
    out = doc.result()
    _index(out)                                   # the edited document is well-formed
    atomic_write(p, lambda fh: fh.write(out), parents=True, binary=True)
    return res


def _inertias(doc: _Doc, model, inertial, bodies, src, res: OsimExport) -> None:
    """Write the bodies' masses, centres of mass and inertias after the inertial effects.

    The effects are folded into a copy of the skeleton (``apply_inertia``, as forward dynamics does).
    A joint that carries one OpenSim body with mass gets that body's new inertia exactly (expressed in
    the body's frame: mass, centre of mass, inertia about it); a joint of several welded bodies (which
    Pinocchio merges) is changed by scaling each body when the effects only scale (``segment_mass``,
    ``scale``), else by moving the target body's centre of mass so that the joint's moves as fitted
    (its rotational inertia then differs by the cross terms, which the change list says).
    """
    import pinocchio as pin
    if not inertial:
        return
    pm = model.pin
    new = pin.Model(pm)
    for c in inertial:
        c.apply_inertia(model, new)
    body_frames = {f.name: k for k, f in enumerate(pm.frames) if f.type == pin.FrameType.BODY and f.name in bodies}
    for c in inertial:
        res.changes.append(f"{c.label}: " + ", ".join(f"{n} = {v:.6g}" for n, v in c.values.items()))
    for j in range(1, pm.njoints):
        old_pi = pm.inertias[j].toDynamicParameters()
        new_pi = new.inertias[j].toDynamicParameters()
        if np.allclose(old_pi, new_pi, rtol=0.0, atol=1e-15):
            continue
        names = [b for b, k in body_frames.items() if pm.frames[k].parentJoint == j]
        massive = [b for b in names if _body_mass(doc, bodies[b], src) > 0]
        if len(massive) == 1:
            b = massive[0]
            inert = pm.frames[body_frames[b]].placement.actInv(new.inertias[j])
            I = np.asarray(inert.inertia, dtype=float)
            _set_body(doc, bodies[b], src, b, inert.mass, np.asarray(inert.lever, dtype=float),
                      [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])
            res.changes.append(f"  body {b}: mass {inert.mass:.6g} kg, mass_center "
                               + " ".join(f"{x:.6g}" for x in inert.lever) + " m")
            continue
        ratio = new_pi[0] / old_pi[0] if old_pi[0] > 0 else 1.0
        if np.allclose(new_pi, ratio * old_pi, rtol=1e-12, atol=1e-15):
            for b in massive:
                m = _body_mass(doc, bodies[b], src)
                com, I6 = _body_com_inertia(doc, bodies[b], src, b)
                _set_body(doc, bodies[b], src, b, m * ratio, com, I6 * ratio)
            res.changes.append(f"  bodies {', '.join(massive)} (one Pinocchio joint): mass and inertia x {ratio:.6g}")
            continue
        # several bodies and a moved centre of mass: move the heaviest body's so the joint's moves as fitted
        masses = {b: _body_mass(doc, bodies[b], src) for b in massive}
        b = max(masses, key=masses.get)
        kb = body_frames[b]
        M_new = new_pi[0]
        c_old = pm.inertias[j].lever
        c_new = new.inertias[j].lever
        R = pm.frames[kb].placement.rotation
        extra = np.asarray(c_new) * M_new - ratio * np.asarray(c_old) * old_pi[0]     # first moment to move
        shift = R.T @ extra / (masses[b] * ratio)
        for bb in massive:
            m = masses[bb]
            com, I6 = _body_com_inertia(doc, bodies[bb], src, bb)
            _set_body(doc, bodies[bb], src, bb, m * ratio, com + (shift if bb == b else 0.0), I6 * ratio)
        res.changes.append(f"  bodies {', '.join(massive)} (one Pinocchio joint): mass x {ratio:.6g}, the centre of "
                           f"mass of {b} moved by {_vec(shift)} m (rotational inertia approximate: the bodies are "
                           "welded together in pinmsk)")


def _body_mass(doc: _Doc, k: int, src) -> float:
    c = doc.child(k, "mass")
    return 0.0 if c is None else float(_floats(doc.text(c), 1, f"{src}: <mass>")[0])


def _body_com_inertia(doc: _Doc, k: int, src, name) -> tuple[np.ndarray, np.ndarray]:
    c, i = doc.child(k, "mass_center"), doc.child(k, "inertia")
    com = np.zeros(3) if c is None else _floats(doc.text(c), 3, f"{src}: Body {name} <mass_center>")
    I6 = np.zeros(6) if i is None else _floats(doc.text(i), 6, f"{src}: Body {name} <inertia>")
    return com, I6


def _set_body(doc: _Doc, k: int, src, name, mass, com, I6) -> None:
    for tag, val, n in (("mass", [mass], 1), ("mass_center", com, 3), ("inertia", I6, 6)):
        c = doc.child(k, tag)
        if c is None:
            raise ModelError(f"{src}: Body {name} has no <{tag}> to write the fitted value in")
        val = np.asarray(val, dtype=float)
        old = _floats(doc.text(c), n, f"{src}: Body {name} <{tag}>")
        scale = max(float(np.max(np.abs(old))), float(np.max(np.abs(val))), 1e-300)
        if np.max(np.abs(val - old)) > 1e-13 * scale:        # an unchanged value keeps its text
            # 15 digits: the round-off of the frame changes (1e-16 relative) is not written as data
            val = np.where(np.abs(val) < 1e-15 * scale, 0.0, val)
            doc.set_text(c, " ".join(repr(float(f"{x:.15g}")) for x in val))


def _site_in_body(model, comp, bodies) -> tuple[str | None, np.ndarray]:
    """``(body, the payload's point in the body's frame)``: a payload at ``<body>@com``, ``@end`` or
    ``@axis`` (its point is given in the frame of the body's joint)."""
    body = comp.target.split("@", 1)[0]
    if body not in bodies:
        return None, np.zeros(3)
    f = model.pin.frames[model.frame_id(body)]
    _, point = comp.site(model)
    return body, np.asarray(f.placement.actInv(np.asarray(point, dtype=float)), dtype=float)


def _why_not(family: str) -> str:
    return {
        "coulomb_friction": "OpenSim has no Coulomb friction on a coordinate (a smoothed one could be an "
                            "ExpressionBasedCoordinateForce, but its smoothing would be a new parameter)",
        "passive_elastic": "its restoring shape has no OpenSim force of the same law",
        "riener_edrich_1999": "OpenSim has no force of this law",
        "sensor_gain": "a measurement effect (of the data, not of the body)",
        "sensor_offset": "a measurement effect (of the data, not of the body)",
    }.get(family, "a correction of the force-plate data: apply it to the ground reaction file, not the model"
          if family.startswith("plate_") else
          "no OpenSim force of the same physics (a measurement, muscle-level or other effect)")


def _frame_in_body(model, frame: str, bodies) -> tuple[str | None, np.ndarray]:
    """``(OpenSim body, point in its frame)`` of the origin of pinmsk frame ``frame``."""
    pm = model.pin
    fid = model.frame_id(frame)
    k = fid
    while True:
        f = pm.frames[k]
        if f.name in bodies and f.type.name == "BODY":
            break
        if k == 0 or f.parentFrame == k:
            return None, np.zeros(3)
        k = f.parentFrame
    body = pm.frames[k]
    target = pm.frames[fid]
    if body.parentJoint != target.parentJoint:
        return None, np.zeros(3)
    rel = body.placement.inverse() * target.placement
    return body.name, np.array(rel.translation, dtype=float)
