"""Model marker sets: which marker sits on which body, where (body frame, m).

:func:`load_marker_set` reads a TOML ``[[markers]]`` table, e.g.
``urdf/markers_gait2d.toml``.  Reading measured markers is :mod:`pinmsk.io.trc`
(and :mod:`pinmsk.io.c3d`); their gaps are :mod:`pinmsk.signals.gaps`.
:func:`model_marker_set` gives a model's own markers (an imported ``.osim``'s MarkerSet).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from .builtin_models import builtin_dir
from .errors import ModelError
from .io.toml_files import read_toml

__all__ = ["ModelMarker", "MarkerSet", "load_marker_set", "model_marker_set"]


@dataclass(frozen=True)
class ModelMarker:
    """A marker fixed in a body: ``position`` (m) in the frame of ``body``; ``weight`` in IK."""

    name: str
    body: str
    position: tuple[float, float, float]
    weight: float = 1.0
    description: str = ""


@dataclass(frozen=True)
class MarkerSet:
    """Named model markers, optionally grouped into sets (``sets["csu"] = ("RSHO", ...)``)."""

    markers: tuple[ModelMarker, ...]
    sets: dict
    model: str | None = None
    source: str | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.markers)

    def __getitem__(self, name: str) -> ModelMarker:
        for m in self.markers:
            if m.name == name:
                return m
        raise ModelError(f"marker set {self.source or ''} has no marker {name!r} (has: {', '.join(self.names)})")

    def __len__(self) -> int:
        return len(self.markers)

    def subset(self, names: Iterable[str]) -> "MarkerSet":
        """The markers of a named set (``"csu"``) or of a list of marker names, in that order."""
        if isinstance(names, str):
            if names not in self.sets:
                raise ModelError(f"marker set {self.source or ''} has no set {names!r} "
                                 f"(sets: {', '.join(self.sets) or 'none'})")
            names = self.sets[names]
        return MarkerSet(tuple(self[n] for n in names), {}, self.model, self.source)

    def renamed(self, mapping: dict) -> "MarkerSet":
        """Rename markers (``{"RSHO": "R.Shoulder"}``) so they match the measured names."""
        ms = tuple(ModelMarker(mapping.get(m.name, m.name), m.body, m.position, m.weight, m.description)
                   for m in self.markers)
        return MarkerSet(ms, {}, self.model, self.source)


def load_marker_set(path) -> MarkerSet:
    """Read model markers from a TOML file with a ``[[markers]]`` table.

    Each entry has ``name``, ``body`` (a frame of the model), ``position`` =
    ``[x, y, z]`` (m, in that body's frame) and optionally ``weight`` (default
    1) and ``description``.  An optional ``[sets]`` table maps set names to lists
    of marker names (e.g. ``csu = ["RSHO", ...]``).  A bare name such as
    ``"gait2d"`` loads the built-in ``urdf/markers_gait2d.toml``.
    """
    p = Path(path)
    if not p.suffix and not p.exists():

        p = builtin_dir() / f"markers_{path}.toml"
    doc = read_toml(p, what="marker set file")
    entries = doc.get("markers")
    if not entries:
        raise ModelError(f"{p}: no [[markers]] table")
    out, seen = [], set()
    for k, e in enumerate(entries):
        where = f"{p}: [[markers]] entry {k + 1}"
        for key in ("name", "body", "position"):
            if key not in e:
                raise ModelError(f"{where} has no {key!r}")
        if e["name"] in seen:
            raise ModelError(f"{where}: duplicate marker name {e['name']!r}")
        seen.add(e["name"])
        pos = e["position"]
        if len(pos) != 3:
            raise ModelError(f"{where} ({e['name']}): position must be [x, y, z] in metres, got {pos!r}")
        w = float(e.get("weight", 1.0))
        if not w >= 0:
            raise ModelError(f"{where} ({e['name']}): weight must be >= 0, got {w}")
        out.append(ModelMarker(str(e["name"]), str(e["body"]), tuple(float(x) for x in pos), w,
                               str(e.get("description", ""))))
    sets = {k: tuple(v) for k, v in doc.get("sets", {}).items()}
    for s, names in sets.items():
        bad = [n for n in names if n not in seen]
        if bad:
            raise ModelError(f"{p}: set {s!r} names unknown markers {bad}")
    return MarkerSet(tuple(out), sets, doc.get("model", {}).get("name") if isinstance(doc.get("model"), dict)
                     else doc.get("model"), str(p))


def model_marker_set(model) -> MarkerSet:
    """The markers of ``model``: an imported ``.osim``'s MarkerSet (``model.meta["markers"]``: name,
    body, position in the body's frame, m), else the built-in marker set of that name
    (``urdf/markers_<name>.toml``); ModelError naming the model when it has neither."""
    entries = (getattr(model, "meta", None) or {}).get("markers")
    if entries:
        return MarkerSet(tuple(ModelMarker(str(e["name"]), str(e["body"]), tuple(float(x) for x in e["position"]))
                               for e in entries), {}, model.name, f"model '{model.name}'")
    p = builtin_dir() / f"markers_{model.name}.toml"
    if p.exists():
        return load_marker_set(p)
    raise ModelError(f"model '{model.name}' has no markers (an .osim's <MarkerSet> or a built-in "
                     f"markers_{model.name}.toml); give a marker set file")
