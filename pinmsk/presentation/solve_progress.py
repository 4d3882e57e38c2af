"""Progress of ``pinmsk optimize``: one line per IPOPT solve (a *stage*) and a summary line.

:class:`SolveProgress` is the ``monitor`` of :class:`pinmsk.solvers.ocp.Collocation`
(``start(label)``, ``iteration(k, objective, violation)``, ``end(record)``).  On a terminal
it draws one live line per stage with tqdm (iteration, objective, constraint violation
``inf_pr``, elapsed time), replaced at the stage's end by the stage's result line; on any
other stream (a pipe, a log file) it writes only that result line, once per stage, so a
piped run is neither silent nor flooded.  ``PINMSK_PROGRESS=1`` / ``0`` forces the live
line on / off (:mod:`pinmsk.presentation.progress`).

:func:`summary_line` is the one line ``pinmsk optimize`` ends with: status, objective, time
and, for a gait, speed (m/s), stride length (m) and cost of transport (J/kg/m), read from
the dict written to ``OUT.json`` (:meth:`~pinmsk.solvers.ocp.Collocation.to_dict` plus
:func:`~pinmsk.solvers.ocp.gait.stride_result`'s numbers).
"""
from __future__ import annotations

import sys
import time

from .progress import _duration, _enabled

__all__ = ["SolveProgress", "stage_line", "summary_line"]


def _elapsed(seconds: float) -> str:
    return f"{seconds:.1f} s" if seconds < 60 else _duration(seconds)


def _iterate_text(iteration: int, objective: float, violation: float) -> str:
    return f"iter {iteration}, objective {objective:.6g}, inf_pr {violation:.2e}"


def stage_line(number: int, label: str, record: dict | None, *, iteration: int = 0,
               objective: float = float("nan"), violation: float = float("nan"),
               seconds: float = 0.0) -> str:
    """``optimize stage 2 (25 intervals): Solve_Succeeded, iter 812, objective 1.23, inf_pr 1.00e-07, 45.2 s``.

    ``record``: the stage's record (status, iterations, objective, violation, seconds) of
    :meth:`Collocation.fit`, or None for a stage that was interrupted (the last iterate seen).
    """
    if record is None:
        head, it, obj, viol, sec = "interrupted", iteration, objective, violation, seconds
    else:
        head = ("converged" if record["converged"] else "NOT CONVERGED") + f" ({record['status'].split(';')[0]})"
        it, obj, viol, sec = record["iterations"], record["objective"], record["violation"], record["seconds"]
    return f"optimize stage {number} ({label}): {head}, {_iterate_text(it, obj, viol)}, {_elapsed(sec)}"


class SolveProgress:
    """The progress of each IPOPT solve of an optimal-control fit on ``stream`` (default stderr).

    ``live``: draw the live tqdm line (default: when ``stream`` is a terminal, or
    ``PINMSK_PROGRESS=1``); otherwise each stage writes only its result line at its end.
    ``lines`` holds every result line written.
    """

    def __init__(self, stream=None, *, live: bool | None = None):
        self.stream = stream if stream is not None else sys.stderr
        self.live = _enabled(self.stream, live)
        self.lines: list[str] = []
        self.stage = 0
        self._bar = None
        self._label = ""
        self._t0 = 0.0
        self._last = (0, float("nan"), float("nan"))

    def start(self, label: str) -> None:
        self.stage += 1
        self._label = label
        self._t0 = time.perf_counter()
        self._last = (0, float("nan"), float("nan"))
        if self.live:
            import shutil
            from tqdm import tqdm
            # the terminal's size, or 100 x 24 where it reports none: a pseudo-terminal of size 0 x 0
            # would make tqdm draw nothing (it hides lines below the last row)
            size = shutil.get_terminal_size((100, 24))
            self._bar = tqdm(total=None, desc=self._text("starting"), file=self.stream, unit="it",
                             leave=False, ncols=size.columns, nrows=size.lines, mininterval=0.2,
                             bar_format="{desc}, {elapsed}")

    def iteration(self, iteration: int, objective: float, violation: float) -> None:
        self._last = (iteration, objective, violation)
        if self._bar is not None:
            self._bar.set_description_str(self._text(_iterate_text(iteration, objective, violation)), refresh=False)
            self._bar.update(1)

    def _text(self, what: str) -> str:
        return f"optimize stage {self.stage} ({self._label}): {what}"

    def end(self, record: dict | None) -> None:
        it, obj, viol = self._last
        line = stage_line(self.stage, self._label, record, iteration=it, objective=obj, violation=viol,
                          seconds=time.perf_counter() - self._t0)
        if self._bar is not None:
            self._bar.close()          # leave=False: the live line is cleared, the result line replaces it
            self._bar = None
        self.lines.append(line)
        try:
            self.stream.write(line + "\n")
            self.stream.flush()
        except (OSError, ValueError):  # a closed stream must not stop the computation
            pass


def _number(x, fmt: str) -> str:
    return "n/a" if x is None else format(float(x), fmt)


def summary_line(summary: dict) -> str:
    """``optimize: converged (Solve_Succeeded), objective 1.234, 152 iterations, 2:31; speed 1.300 m/s, ...``

    ``summary``: the ``OUT.json`` dict (``converged``, ``status``, ``objective``, ``iterations``,
    ``seconds``; a gait's ``speed``, ``stride_length``, ``cost_of_transport``).
    """
    head = "converged" if summary["converged"] else "NOT CONVERGED (not a solution)"
    out = (f"optimize: {head} ({summary['status']}), objective {float(summary['objective']):.6g}, "
           f"{int(summary['iterations'])} iterations, {_elapsed(float(summary['seconds']))}")
    if "speed" in summary:
        stride = summary.get("stride_length")
        out += (f"; speed {_number(summary['speed'], '.3f')} m/s, "
                f"stride {_number(stride, '.3f')} m" + ("" if stride is not None else " (not a full stride)")
                + f", cost of transport {_number(summary.get('cost_of_transport'), '.3f')} J/kg/m")
    return out
