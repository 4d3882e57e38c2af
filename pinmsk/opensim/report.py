"""The import report of an OpenSim model: what became what, and what each approximation costs.

An :class:`ImportReport` lists one :class:`ReportEntry` per element of the
``.osim`` file that the import touched: the element (``file:line: <Type
name="...">``), what it became in pinmsk, the approximation made (empty when
the conversion is exact) and its measured maximum error.  Elements pinmsk does
not import (yet) are entries too, with status ``"not imported"``: nothing is
dropped silently.

``bounds`` maps body, marker and ``"center_of_mass"`` names to an upper bound
(m) of their position error from the approximations above them in the tree,
over the coordinates' ranges (see :mod:`pinmsk.opensim.skeleton`);
:meth:`ImportReport.error_bound` reads it (0 for exact frames).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping

__all__ = ["ReportEntry", "ImportReport", "paths_warning", "EXACT", "APPROXIMATED", "NOT_IMPORTED", "NOTE"]

EXACT = "exact"
APPROXIMATED = "approximated"
NOT_IMPORTED = "not imported"
NOTE = "note"
_STATUSES = (EXACT, APPROXIMATED, NOT_IMPORTED, NOTE)


@dataclass(frozen=True)
class ReportEntry:
    """One line of the report.

    ``element``: where it came from (``file:line: <Type name="...">``);
    ``became``: what it is in pinmsk; ``approximation``: what was approximated
    (empty if nothing); ``max_error``: the measured maximum error of the
    approximation (``unit``, default m), None if exact or not measured;
    ``status``: exact | approximated | not imported | note; ``details``: numbers
    behind the entry (ranges, rotation errors, ...).
    """

    element: str
    became: str
    approximation: str = ""
    max_error: float | None = None
    status: str = EXACT
    unit: str = "m"
    details: Mapping = field(default_factory=dict, compare=False)

    def __post_init__(self):
        if self.status not in _STATUSES:
            raise ValueError(f"ReportEntry status must be one of {_STATUSES}, got {self.status!r}")

    def __iter__(self):
        """``element, became, approximation, max_error = entry``."""
        return iter((self.element, self.became, self.approximation, self.max_error))

    def line(self) -> str:
        text = f"{self.element}: {self.became}"
        if self.approximation:
            text += f"; APPROXIMATED: {self.approximation}"
        if self.max_error is not None:
            text += f" (max error {_fmt(self.max_error, self.unit)})"
        return text


def paths_warning(entries) -> str:
    """The muscle-path part of an import's warning: how many paths the polynomials fit and their largest
    errors (``""`` if ``entries`` have no fitted paths)."""
    paths = [e for e in entries if e.status == APPROXIMATED and e.details.get("kind") == "muscle paths"]
    if not paths:
        return ""
    worst = max(paths, key=lambda e: e.max_error)
    return (f"{sum(len(e.details.get('muscles', ())) for e in paths)} muscle path(s) fitted by polynomials "
            f"(max length error {1e3 * max(e.details['length_max'] for e in paths):.3g} mm, max moment-arm "
            f"error {1e3 * max(e.details['moment_arm_max'] for e in paths):.3g} mm; worst group "
            f"{', '.join(worst.details['muscles'][:3])})")


def _deferred(item) -> bool:
    return not isinstance(item, ReportEntry)


def _fmt(x: float, unit: str) -> str:
    if unit == "m":
        return f"{x * 1000:.3g} mm" if x >= 1e-4 else f"{x:.2e} m"
    return f"{x:.3g} {unit}"


class ImportReport:
    """What an OpenSim import made of each element (see the module docstring).

    ``entries`` may hold *deferred* items besides :class:`ReportEntry` objects: work the import left
    for first use (an object with ``done`` (bool) and ``report_entries()``, such as the fit of the
    muscle paths, :class:`pinmsk.opensim.muscle_import.DeferredPathFit`).  :attr:`entries` is the
    whole report, so reading it runs that work; :attr:`entries_so_far` is what is known without it,
    and :attr:`pending` the deferred work not run yet.
    """

    __slots__ = ("source", "_items", "bounds")

    def __init__(self, source: str, entries: Iterable = (), bounds: Mapping[str, float] | None = None):
        set_ = object.__setattr__
        set_(self, "source", source)
        set_(self, "_items", tuple(entries))
        set_(self, "bounds", dict(bounds or {}))

    def __setattr__(self, name, value):
        raise AttributeError(f"ImportReport is immutable; cannot set {name!r}")

    def __reduce__(self):
        return (ImportReport, (self.source, self._items, self.bounds))

    def __eq__(self, other) -> bool:
        if not isinstance(other, ImportReport):
            return NotImplemented
        return self.source == other.source and self.entries == other.entries

    def __hash__(self) -> int:
        return hash(self.source)          # equal reports have the same source (the entries may be deferred)

    def __repr__(self) -> str:
        return f"ImportReport(source={self.source!r}, {len(self.entries_so_far)} entries, {len(self.pending)} pending)"

    @property
    def entries(self) -> tuple[ReportEntry, ...]:
        """Every entry, the deferred work's too (which this runs if it has not run yet)."""
        out = []
        for item in self._items:
            out.extend(item.report_entries() if _deferred(item) else (item,))
        return tuple(out)

    @property
    def entries_so_far(self) -> tuple[ReportEntry, ...]:
        """The entries known without running deferred work (those of deferred work already run included)."""
        out = []
        for item in self._items:
            if not _deferred(item):
                out.append(item)
            elif item.done:
                out.extend(item.report_entries())
        return tuple(out)

    @property
    def pending(self) -> tuple:
        """The deferred work not run yet (e.g. the muscle paths' fit, run when the paths are first used)."""
        return tuple(item for item in self._items if _deferred(item) and not item.done)

    @property
    def approximations(self) -> tuple[ReportEntry, ...]:
        return tuple(e for e in self.entries if e.status == APPROXIMATED)

    @property
    def not_imported(self) -> tuple[ReportEntry, ...]:
        # the deferred work (a muscle path fit) approximates what was imported; it never leaves anything
        # out, so this needs no fit
        return tuple(e for e in self.entries_so_far if e.status == NOT_IMPORTED)

    @property
    def exact(self) -> bool:
        """True if nothing was approximated and everything was imported."""
        return not self.approximations and not self.not_imported

    def error_bound(self, name: str) -> float:
        """Upper bound (m) of the position error of body, marker or ``"center_of_mass"`` ``name``."""
        return float(self.bounds.get(name, 0.0))

    def with_entries(self, entries: Iterable[ReportEntry], *, replacing: Iterable[str] = ()) -> "ImportReport":
        """A report with ``entries`` added; entries whose element is in ``replacing`` are removed first
        (how a later stage, e.g. the muscle import, replaces the "not imported" entries it handles)."""
        drop = set(replacing)
        kept = tuple(e for e in self._items if _deferred(e) or e.element not in drop)
        return ImportReport(self.source, kept + tuple(entries), self.bounds)

    def find(self, text: str) -> tuple[ReportEntry, ...]:
        """Entries whose element contains ``text`` (e.g. ``'name="knee_r"'``)."""
        return tuple(e for e in self.entries if text in e.element)

    def format(self, *, verbose: bool = False) -> str:
        """The report as text: approximations and what was not imported first, then (``verbose``) the rest."""
        lines = [f"import report of {self.source}: {len(self.entries)} elements, "
                 f"{len(self.approximations)} approximated, {len(self.not_imported)} not imported"]
        groups = [(APPROXIMATED, "approximated"), (NOT_IMPORTED, "not imported"), (NOTE, "notes")]
        if verbose:
            groups.append((EXACT, "exact"))
        for status, title in groups:
            chosen = [e for e in self.entries if e.status == status]
            if chosen:
                lines.append(f"{title}:")
                lines += [f"  {e.line()}" for e in chosen]
        if self.bounds:
            worst = max(self.bounds.items(), key=lambda kv: kv[1])
            lines.append(f"largest position error bound from the approximations: {_fmt(worst[1], 'm')} "
                         f"({worst[0]})")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.format()

    def to_dict(self) -> dict:
        return {"source": self.source,
                "entries": [{"element": e.element, "became": e.became, "approximation": e.approximation,
                             "max_error": e.max_error, "status": e.status, "unit": e.unit,
                             "details": dict(e.details)} for e in self.entries],
                "bounds": dict(self.bounds)}
