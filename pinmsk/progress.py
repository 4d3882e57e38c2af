"""A minimal progress bar on stderr for long loops in the CLI (no extra dependency).

Silent when stderr is not a terminal unless ``force=True``; the library's
algorithms take an optional ``progress`` object with ``update(n)``.
"""
from __future__ import annotations

import sys
import time


class Progress:
    """``with Progress(total, "ID") as bar: bar.update(1)`` draws ``ID [#####     ] 50% 1.2 s``."""

    def __init__(self, total: int, label: str = "", *, stream=None, force: bool = False, width: int = 30):
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream or sys.stderr
        self.enabled = force or getattr(self.stream, "isatty", lambda: False)()
        self.width = width
        self.count = 0
        self._t0 = time.perf_counter()
        self._last = 0.0

    def update(self, n: int = 1) -> None:
        self.count += n
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and self.count < self.total:
            return
        self._last = now
        frac = min(self.count / self.total, 1.0)
        fill = int(round(frac * self.width))
        self.stream.write(f"\r{self.label} [{'#' * fill}{' ' * (self.width - fill)}] "
                          f"{100 * frac:3.0f}% {now - self._t0:.1f} s")
        self.stream.flush()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
        return False
