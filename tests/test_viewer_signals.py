"""`pinmsk view` stops its meshcat server on every way out, in a real subprocess.

meshcat starts its server in a session of its own and stops it from
``atexit``; a signal's default action skips ``atexit``, which would leave the
server running and holding its port.  Each test starts the viewer, waits for
its "serving" line, ends it one way and checks that the server process is gone
and its web port can be bound again.
"""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO

pytest.importorskip("meshcat")
pytestmark = pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads child processes from /proc")


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (Linux /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            ppid = int(stat[stat.rindex(")") + 2:].split()[1])
            if ppid == pid:
                out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return state[state.rindex(")") + 2] != "Z"


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _start_viewer():
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "pinmsk", "view", "forearm"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
    t_end = time.monotonic() + 60
    lines = []
    while time.monotonic() < t_end:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if "press Ctrl-C" in line:
            break
    else:  # pragma: no cover
        proc.kill()
        pytest.fail("the viewer printed no 'serving' line in 60 s: " + "".join(lines))
    if proc.poll() is not None:
        pytest.fail(f"the viewer exited ({proc.returncode}): {''.join(lines)}{proc.stderr.read()}")
    port = int(re.search(r"http://127\.0\.0\.1:(\d+)", "".join(lines)).group(1))
    servers = [p for p in _children(proc.pid)
               if "meshcat" in Path(f"/proc/{p}/cmdline").read_bytes().decode(errors="replace")]
    assert len(servers) == 1, servers
    assert not _port_free(port), "the meshcat server is not holding its port"
    return proc, servers[0], port


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT], ids=["TERM", "HUP", "INT"])
def test_viewer_ended_by_a_signal_stops_its_server(sig):
    proc, server, port = _start_viewer()
    try:
        proc.send_signal(sig)
        proc.wait(timeout=20)
    finally:
        if proc.poll() is None:  # pragma: no cover
            proc.kill()
    # SIGTERM/SIGHUP end with the shell's 128 + signum; Ctrl-C ends the serving loop normally
    assert proc.returncode == (0 if sig == signal.SIGINT else 128 + sig), proc.stderr.read()
    t_end = time.monotonic() + 5
    while _alive(server) and time.monotonic() < t_end:
        time.sleep(0.05)
    assert not _alive(server), f"meshcat server {server} left running after {sig.name}"
    assert _port_free(port), f"port {port} still held after {sig.name}"


def test_signals_raise_exit_and_restore_the_handlers():
    from pinmsk.presentation.viewer import signals_raise_exit

    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(SystemExit) as exc:
        with signals_raise_exit():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)       # the handler runs between bytecodes; never reached
    assert exc.value.code == 128 + signal.SIGTERM
    assert signal.getsignal(signal.SIGTERM) is before
