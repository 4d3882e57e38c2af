"""Write a benchmark's output onto the documentation's benchmarks page, ``docs/benchmarks.md``.

Each script ends with ``sys.exit(run(main))``: ``main`` runs with its standard output copied, and when
it succeeds the script's section of the page, between ``<!-- begin NAME -->`` and ``<!-- end NAME -->``
(NAME the script's file name without ``.py``), is replaced by the command, the date (UTC), the
machine and the output.  A section the page lacks is appended.  Not recorded: a run with
``--no-record`` (taken off the arguments before ``main`` reads them) or ``--quick`` (a partial run),
a failed run, and the scripts a benchmark starts itself (``PINMSK_BENCH_RECORDING`` is set for them).
"""
from __future__ import annotations

import datetime as _dt
import io
import os
import platform
import re
import sys
from pathlib import Path

PAGE = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md"
ENV = "PINMSK_BENCH_RECORDING"


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def memory_gib() -> str:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                return f"{int(line.split()[1]) / 2**20:.0f} GiB"
    except OSError:
        pass
    return "? GiB"


def _version(name: str) -> str:
    try:
        from importlib.metadata import version
        return version(name)
    except Exception:                     # not installed
        return "-"


def machine() -> str:
    """One line: CPU, cores, memory, OS, Python and the numerical packages' versions."""
    load = ""
    if hasattr(os, "getloadavg"):
        load = ", load average {:.1f}".format(os.getloadavg()[0])
    return (f"{platform.machine()} {cpu_name()}, {os.cpu_count()} logical CPUs, {memory_gib()}, "
            f"{platform.system()} {platform.release()}, Python {platform.python_version()}, "
            f"pin {_version('pin')}, numpy {_version('numpy')}, scipy {_version('scipy')}, "
            f"proxsuite {_version('proxsuite')}, casadi {_version('casadi')}, opensim {_version('opensim')}{load}")


def section(name: str, command: str, output: str, when: _dt.datetime | None = None, host: str | None = None) -> str:
    when = when or _dt.datetime.now(_dt.timezone.utc)
    return (f"<!-- begin {name} -->\n"
            f"Last run {when:%Y-%m-%d %H:%M} UTC: `{command}`\n\n"
            f"Machine: {host or machine()}\n\n"
            f"```text\n{output.rstrip()}\n```\n"
            f"<!-- end {name} -->")


def record(name: str, command: str, output: str, page: Path | None = None) -> None:
    """Put ``output`` into ``name``'s section of ``page`` (default :data:`PAGE`; appended if the page has none)."""
    page = PAGE if page is None else page
    text = page.read_text() if page.is_file() else "# Benchmarks\n"
    block = section(name, command, output)
    pattern = re.compile(rf"<!-- begin {re.escape(name)} -->.*?<!-- end {re.escape(name)} -->", re.S)
    if pattern.search(text):
        text = pattern.sub(lambda m: block, text)
    else:
        text = text.rstrip() + f"\n\n## {name}\n\n{block}\n"
    tmp = page.with_suffix(".md.tmp")
    tmp.write_text(text)
    tmp.replace(page)


class _Tee(io.TextIOBase):
    def __init__(self, stream):
        self.stream, self.buffer_ = stream, io.StringIO()

    def write(self, s):
        self.buffer_.write(s)
        return self.stream.write(s)

    def flush(self):
        self.stream.flush()


def run(main, script: str | None = None):
    """Run ``main()`` and record its output (see the module notes); returns what ``main`` returned."""
    script = Path(script or sys.argv[0])
    argv = sys.argv[1:]
    quiet = "--no-record" in argv
    sys.argv = [sys.argv[0], *(a for a in argv if a != "--no-record")]
    if quiet or "--quick" in argv or os.environ.get(ENV):
        return main()
    os.environ[ENV] = "1"
    tee = _Tee(sys.stdout)
    old, sys.stdout = sys.stdout, tee
    try:
        rc = main()
    finally:
        sys.stdout = old
        os.environ.pop(ENV, None)
    if rc in (None, 0):
        command = " ".join(["python", f"benchmarks/{script.name}", *sys.argv[1:]])
        record(script.stem, command, tee.buffer_.getvalue())
        print(f"recorded in {PAGE} ({script.stem})")
    return rc
