"""Checks the command line makes before any work: output file types and effect names.

A command that would fail on its output's suffix, or on a misspelt effect, after minutes of
computation fails here instead, in a fraction of a second, with one line naming the argument.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import OutputError

__all__ = ["OUTPUT_SUFFIXES", "check_output_suffixes", "check_effect_names"]

_TRIAL = (".sto", ".mot", ".csv")

#: (command, argument) -> the suffixes that argument's file may have; ``None`` as the command: any.
OUTPUT_SUFFIXES: dict[tuple[str | None, str], tuple[str, ...]] = {
    ("id", "output"): _TRIAL,
    ("muscles", "output"): _TRIAL,
    ("simulate", "output"): _TRIAL,
    ("so", "output"): _TRIAL,
    ("fso", "output"): _TRIAL,
    ("synth", "output"): _TRIAL,
    ("optimize", "output"): _TRIAL,
    ("ik", "output"): (".mot", ".sto"),
    ("ik", "marker_errors"): _TRIAL,
    ("scale", "output"): (".osim",),
    (None, "json"): (".json",),
    (None, "report"): (".html", ".htm"),
    (None, "save_model"): (".toml",),
    (None, "save_osim"): (".osim",),
}

_FLAGS = {"output": "-o/--output", "marker_errors": "--marker-errors", "json": "--json", "report": "--report",
          "save_model": "--save-model", "save_osim": "--save-osim"}


def check_output_suffixes(args) -> None:
    """Refuse an output file whose suffix its command cannot write (:data:`OUTPUT_SUFFIXES`)."""
    command = getattr(args, "command", None)
    for (cmd, dest), suffixes in OUTPUT_SUFFIXES.items():
        if cmd not in (None, command):
            continue
        value = getattr(args, dest, None)
        if not value or not isinstance(value, (str, Path)):
            continue
        suffix = Path(value).suffix.lower()
        if suffix not in suffixes:
            shown = repr(suffix) if suffix else "no suffix"
            raise OutputError(f"{_FLAGS[dest]} {value}: pinmsk {command} writes {' or '.join(suffixes)} "
                              f"there, not {shown}; nothing was run")


def check_effect_names(args) -> None:
    """The effects named by ``--add`` (diagnose) and ``--effect`` (synth), parsed before the model is
    loaded: an unknown one is refused with a "did you mean" and the list of effects."""
    specs = [*(getattr(args, "add", None) or ()), *(getattr(args, "effect", None) or ())]
    if not specs:
        return
    from ..effects import registry
    for spec in specs:
        registry.get(str(spec).split(":", 1)[0].strip())
