"""A minimal progress line on stderr for long steps in the CLI (no extra dependency).

The library's long loops (inverse dynamics, SO, FSO, batch, the dynamic
optimizer) take an optional ``progress`` object with ``update(n)``; the CLI
passes a :class:`Progress`.  It draws nothing unless stderr is a terminal, so
piped or logged runs stay clean, and nothing for steps that end within
``delay`` seconds (2 s), so quick commands print only their results.
:meth:`Progress.note` prints one permanent line (a result, e.g. a batch's
finished trial) on the same stream, terminal or not, above the bar.
"""
from __future__ import annotations

import os
import sys
import time

#: ``PINMSK_PROGRESS=1`` draws progress even when stderr is not a terminal; ``0`` never draws it.
ENV = "PINMSK_PROGRESS"

#: Seconds a step runs before its progress line appears (shorter steps draw nothing).
DEFAULT_DELAY = 2.0


def _enabled(stream, force) -> bool:
    if force is not None:
        return bool(force)
    env = os.environ.get(ENV, "").strip().lower()
    if env in ("1", "yes", "true", "on"):
        return True
    if env in ("0", "no", "false", "off"):
        return False
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):   # no isatty, or a closed stream
        return False


def _duration(s: float) -> str:
    s = int(round(max(s, 0.0)))
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def _count(x: float) -> str:
    for div, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if x >= div:
            return f"{x / div:.3g}{suffix}"
    return f"{x:.3g}"


class Progress:
    """``with Progress(total, "ID", unit="frames") as bar: bar.update(n)`` on stderr.

    Draws ``ID [######        ]  40% 400k/1M frames, 210k frames/s, ETA 0:03``
    at most ten times a second, once the step has run for ``delay`` seconds
    (default :data:`DEFAULT_DELAY`, 2 s).
    ``total=None`` (an unknown end, e.g. optimizer iterations) draws the count
    and rate only.  ``force=True`` / ``False`` draws it / never draws it;
    with ``force=None`` (default) the environment decides (``PINMSK_PROGRESS=1``
    on, ``PINMSK_PROGRESS=0`` off), else whether ``stream`` (default stderr) is a
    terminal.  When not drawn, ``update`` only adds to ``count``.
    """

    def __init__(self, total: int | None, label: str = "", *, unit: str = "", stream=None,
                 force: bool | None = None, delay: float | None = None, width: int = 20):
        self.total = None if total is None else max(int(total), 1)
        self.label = label
        self.unit = f" {unit}" if unit else ""
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = _enabled(self.stream, force)
        self.delay = DEFAULT_DELAY if delay is None else float(delay)
        self.width = width
        self.count = 0
        self.shown = False
        self._t0 = time.perf_counter()
        self._last = -1.0
        self._length = 0

    def update(self, n: int = 1) -> None:
        self.count += n
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 or now - self._t0 < self.delay:
            return
        self._last = now
        self._draw(now)

    def line(self, now: float | None = None) -> str:
        """The progress text at time ``now`` (default: the current time)."""
        now = time.perf_counter() if now is None else now
        elapsed = max(now - self._t0, 1e-9)
        rate = self.count / elapsed
        parts = [self.label] if self.label else []
        if self.total is not None:
            frac = min(self.count / self.total, 1.0)
            fill = int(round(frac * self.width))
            parts.append(f"[{'#' * fill}{' ' * (self.width - fill)}] {100 * frac:3.0f}%")
            parts.append(f"{_count(self.count)}/{_count(self.total)}{self.unit}, "
                         f"{_count(rate)}{self.unit}/s, ")
            if self.count >= self.total:
                parts[-1] += f"done in {_duration(elapsed)}"
            elif rate > 0:
                parts[-1] += f"ETA {_duration((self.total - self.count) / rate)}"
            else:
                parts[-1] += "ETA ?"
        else:
            parts.append(f"{_count(self.count)}{self.unit}, {_count(rate)}{self.unit}/s, "
                         f"{_duration(elapsed)}")
        return " ".join(parts)

    def note(self, text: str) -> None:
        """Print ``text`` as its own line on the stream (always, drawn bar or not), the bar redrawn below it."""
        try:
            if self.shown and self.enabled:
                self.stream.write("\r" + " " * self._length + "\r")
            self.stream.write(text + "\n")
            self.stream.flush()
        except (OSError, ValueError):   # a closed stream must not stop the computation
            return
        if self.shown and self.enabled:
            self._draw(time.perf_counter())

    def _draw(self, now: float) -> None:
        text = self.line(now)
        pad = max(self._length - len(text), 0)
        self._length = len(text)
        try:
            self.stream.write("\r" + text + " " * pad)
            self.stream.flush()
        except (OSError, ValueError):   # a closed terminal must not stop the computation
            self.enabled = False
            return
        self.shown = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.shown and self.enabled:
            self._draw(time.perf_counter())
            try:
                self.stream.write("\n")
                self.stream.flush()
            except (OSError, ValueError):
                pass
        return False
