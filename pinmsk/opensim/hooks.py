"""What an import hook returns (:class:`HookResult`), apart from the importer so that the hooks
(:mod:`.muscle_import`, ...) and :func:`pinmsk.opensim.importer.write_import`, which runs the default
hooks, need not import each other."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from ..io.osim import OsimDocument
from .report import ReportEntry
from .skeleton import Skeleton

__all__ = ["HookResult", "ImportHook"]


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
