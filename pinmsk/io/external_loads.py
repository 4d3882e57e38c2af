"""OpenSim ExternalLoads ``.xml`` files: which force-plate columns act on which body.

An ExternalLoads file (OpenSim's ``ExternalLoads`` object, as written by the
GUI and used by the ID, SO, RRA and CMC tools) lists ``ExternalForce``
entries, each with

* ``applied_to_body`` -- the body that receives the load (``calcn_r``);
* ``force_expressed_in_body`` / ``point_expressed_in_body`` -- the frame of the
  force and of its point; pinmsk reads ``ground`` (world-frame wrenches, as
  every gait lab's files are) and refuses anything else by name;
* ``force_identifier``, ``point_identifier``, ``torque_identifier`` -- column
  prefixes in the data file; ``x``, ``y``, ``z`` complete them
  (``ground_force_v`` -> ``ground_force_vx``, ...);
* ``isDisabled`` -- ``true`` skips the entry (reported, never silently);

and a ``datafile`` (the ``.mot``/``.sto`` of the plates, relative to the XML).

:func:`read_external_loads` returns an :class:`ExternalLoads`; applying it to a
model and a trial is :func:`pinmsk.grf.plates_from_external_loads`.  No
``opensim`` package is needed.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import TrialError

__all__ = ["ExternalLoadSpec", "ExternalLoads", "read_external_loads"]


@dataclass(frozen=True)
class ExternalLoadSpec:
    """One ``ExternalForce`` entry: its name, receiving body and column prefixes."""

    name: str
    body: str
    force_identifier: str
    point_identifier: str | None
    torque_identifier: str | None

    def columns(self, kind: str) -> tuple[str, str, str] | None:
        """The three data columns of ``kind`` ("force", "point" or "torque"), or None."""
        prefix = {"force": self.force_identifier, "point": self.point_identifier,
                  "torque": self.torque_identifier}[kind]
        return None if not prefix else tuple(f"{prefix}{a}" for a in "xyz")


@dataclass(frozen=True)
class ExternalLoads:
    """The enabled entries of an ExternalLoads file, its data file and what was skipped."""

    path: Path
    loads: tuple[ExternalLoadSpec, ...]
    datafile: Path | None
    disabled: tuple[str, ...] = ()


def _text(elem, tag: str) -> str | None:
    child = elem.find(tag)
    if child is None or child.text is None:
        return None
    s = child.text.strip()
    return s or None


def read_external_loads(path) -> ExternalLoads:
    """Read an OpenSim ExternalLoads ``.xml`` (see the module docstring)."""
    from .opensim_setup import parse_xml

    path = Path(path)
    root = parse_xml(path, "ExternalLoads file", TrialError)
    el = root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")
    if el is None:
        raise TrialError(f"{path}: no <ExternalLoads> element; is this an OpenSim ExternalLoads file?")
    loads, disabled = [], []
    for i, ef in enumerate(el.iter("ExternalForce")):
        name = ef.get("name") or f"ExternalForce[{i}]"
        if (_text(ef, "isDisabled") or "false").lower() == "true":
            disabled.append(name)
            continue
        body = _text(ef, "applied_to_body")
        if body is None:
            raise TrialError(f"{path}: ExternalForce {name!r} has no <applied_to_body>")
        for tag in ("force_expressed_in_body", "point_expressed_in_body"):
            frame = _text(ef, tag) or "ground"
            if frame != "ground":
                raise TrialError(
                    f"{path}: ExternalForce {name!r} has <{tag}>{frame}</{tag}>; pinmsk reads "
                    "world-frame (ground) forces and points only: express the plate data in ground")
        force = _text(ef, "force_identifier")
        if force is None:
            raise TrialError(f"{path}: ExternalForce {name!r} has no <force_identifier>")
        loads.append(ExternalLoadSpec(name=name, body=body, force_identifier=force,
                                      point_identifier=_text(ef, "point_identifier"),
                                      torque_identifier=_text(ef, "torque_identifier")))
    if not loads:
        raise TrialError(f"{path}: no enabled ExternalForce entries"
                         + (f" (disabled: {', '.join(disabled)})" if disabled else ""))
    data = _text(el, "datafile")
    datafile = None if data is None or data.lower() == "unassigned" else (path.parent / data)
    return ExternalLoads(path=path, loads=tuple(loads), datafile=datafile, disabled=tuple(disabled))
