"""Drive headless Chromium from tests: screenshots and DOM dumps, no Python dependency.

Uses the plain ``chromium`` command line (Debian packages ``chromium`` and
``chromium-driver``; ``.ci/run`` installs them when missing).  Each call
starts a fresh browser with an empty profile and the flags this closed
network needs, and stops it when the page is done (``--virtual-time-budget``).

    exe = browser.chromium_or_skip()
    browser.screenshot(url, "shot.png", width=800, height=600)
    dom = browser.dump_dom("file:///tmp/report.html")
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--no-first-run", "--disable-quic", "--disable-extensions",
    "--disable-default-apps", "--hide-scrollbars", "--mute-audio",
)


class BrowserError(RuntimeError):
    """Chromium failed to start or to produce its output."""


def find_chromium() -> str | None:
    """Path of a Chromium executable ($PINMSK_CHROMIUM first), or None."""
    env = os.environ.get("PINMSK_CHROMIUM")
    if env:
        return env if Path(env).exists() else shutil.which(env)
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


def chromium_or_skip() -> str:
    """The Chromium executable, or skip the calling test saying why and what to install."""
    import pytest

    exe = find_chromium()
    if exe is None:
        pytest.skip("headless Chromium not found (looked for "
                    f"{', '.join(CANDIDATES)} and $PINMSK_CHROMIUM); install the Debian packages "
                    "'chromium chromium-driver' (.ci/run does when missing)")
    try:
        out = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"Chromium at {exe} cannot be started: {exc}")
    if out.returncode != 0:
        pytest.skip(f"Chromium at {exe} cannot be started: {out.stderr.strip()[-300:]}")
    return exe


def chrome_or_skip(**kwargs) -> "Chrome":
    """A started :class:`Chrome`, or skip the calling test saying why it cannot start."""
    import pytest

    chromium_or_skip()
    try:
        return Chrome(**kwargs)
    except BrowserError as exc:
        pytest.skip(f"headless Chromium could not be started: {exc}")


def _run(args: list[str], *, timeout: float) -> subprocess.CompletedProcess:
    exe = find_chromium()
    if exe is None:
        raise BrowserError("no Chromium executable found")
    with tempfile.TemporaryDirectory(prefix="pinmsk-chromium-", ignore_cleanup_errors=True) as profile:
        cmd = [exe, *FLAGS, f"--user-data-dir={profile}", *args]
        try:
            return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            raise BrowserError(f"Chromium did not finish within {timeout} s: {' '.join(cmd)}") from exc


def screenshot(url: str, path, *, width: int = 800, height: int = 600, budget_ms: int = 4000,
               timeout: float = 45.0) -> Path:
    """Load ``url`` headless, let it run ``budget_ms`` of virtual time, save a PNG to ``path``."""
    path = Path(path)
    if path.exists():
        path.unlink()
    res = _run([f"--window-size={width},{height}", f"--virtual-time-budget={budget_ms}",
                f"--screenshot={path}", url], timeout=timeout)
    if not path.exists() or path.stat().st_size == 0:
        raise BrowserError(f"Chromium wrote no screenshot of {url} (exit {res.returncode}):\n"
                           + res.stderr[-2000:])
    return path


def dump_dom(url: str, *, budget_ms: int = 4000, timeout: float = 45.0) -> str:
    """The page's DOM (outer HTML) after ``budget_ms`` of virtual time."""
    res = _run([f"--virtual-time-budget={budget_ms}", "--dump-dom", url], timeout=timeout)
    if res.returncode != 0 or not res.stdout.strip():
        raise BrowserError(f"Chromium could not dump {url} (exit {res.returncode}):\n" + res.stderr[-2000:])
    return res.stdout


def read_png(path) -> np.ndarray:
    """``(H, W, 3)`` uint8 RGB pixels of a PNG."""
    from PIL import Image

    with Image.open(path) as img:
        return np.asarray(img.convert("RGB"))


def warm_fraction(rgb: np.ndarray, *, margin: int = 30) -> float:
    """Fraction of pixels whose red exceeds blue by ``margin``: bone, muscle and arrow
    colours of the viewer (the meshcat background and our ground are blue/grey)."""
    rgb = rgb.astype(int)
    return float(np.mean(rgb[..., 0] - rgb[..., 2] > margin))


def distinct_colors(rgb: np.ndarray, *, step: int = 16) -> int:
    """Number of distinct colours after quantising each channel to ``step`` levels."""
    q = (rgb // step).reshape(-1, 3).astype(np.int64)
    return int(np.unique(q[:, 0] * 65536 + q[:, 1] * 256 + q[:, 2]).size)


# --------------------------------------------------------------------------
# DevTools protocol: a live page we can query and wait on (uses tornado's
# websocket client, which meshcat already depends on).

class Chrome:
    """A headless Chromium with one page, driven over the DevTools protocol.

        with Chrome(width=800, height=600) as page:
            page.navigate(url)
            page.wait_for("window.viewer !== undefined", timeout=20)
            value = page.evaluate("1 + 1")
            page.screenshot("shot.png")
    """

    def __init__(self, *, width: int = 800, height: int = 600, timeout: float = 30.0):
        import asyncio
        import json
        import re
        import urllib.request

        exe = find_chromium()
        if exe is None:
            raise BrowserError("no Chromium executable found")
        self._profile = tempfile.TemporaryDirectory(prefix="pinmsk-chromium-", ignore_cleanup_errors=True)
        self._loop = asyncio.new_event_loop()
        self._id = 0
        self._ws = None
        #: DevTools events received so far ({"method": ..., "params": ...}), oldest first.
        self.events: list[dict] = []
        cmd = [exe, *FLAGS, f"--user-data-dir={self._profile.name}", f"--window-size={width},{height}",
               "--remote-debugging-port=0", "--remote-allow-origins=*", "about:blank"]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            port = None
            lines = []
            import time as _time
            t_end = _time.monotonic() + timeout
            while port is None and _time.monotonic() < t_end:
                line = self.proc.stderr.readline()
                if not line:
                    if self.proc.poll() is not None:
                        break
                    continue
                lines.append(line)
                m = re.search(r"DevTools listening on ws://[^:]+:(\d+)/", line)
                if m:
                    port = int(m.group(1))
            if port is None:
                raise BrowserError("Chromium did not open its DevTools port:\n" + "".join(lines)[-2000:])
            # keep draining stderr so Chromium never blocks on a full pipe
            import threading
            threading.Thread(target=lambda: [None for _ in self.proc.stderr], daemon=True).start()
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=timeout) as r:
                targets = json.load(r)
            page = next(t for t in targets if t.get("type") == "page")
            self._loop.run_until_complete(self._connect(page["webSocketDebuggerUrl"], timeout))
            self.send("Page.enable")
            self.send("Runtime.enable")
            self.send("Emulation.setDeviceMetricsOverride",
                      {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        except BaseException:
            self.close()
            raise

    async def _connect(self, url, timeout):
        import asyncio

        from tornado.websocket import websocket_connect

        self._ws = await asyncio.wait_for(websocket_connect(url, max_message_size=256 * 1024 * 1024),
                                          timeout)

    async def _call(self, method, params, timeout):
        import asyncio
        import json

        self._id += 1
        my_id = self._id
        await self._ws.write_message(json.dumps({"id": my_id, "method": method, "params": params or {}}))
        while True:
            msg = await asyncio.wait_for(self._ws.read_message(), timeout)
            if msg is None:
                raise BrowserError("the DevTools connection closed")
            data = json.loads(msg)
            if "method" in data and "id" not in data:
                self.events.append(data)
                continue
            if data.get("id") == my_id:
                if "error" in data:
                    raise BrowserError(f"{method}: {data['error']}")
                return data.get("result", {})

    def send(self, method: str, params: dict | None = None, *, timeout: float = 30.0) -> dict:
        """Send one DevTools command and return its result."""
        return self._loop.run_until_complete(self._call(method, params, timeout))

    def navigate(self, url: str, *, timeout: float = 30.0) -> None:
        self.send("Page.navigate", {"url": url}, timeout=timeout)
        self.wait_for("document.readyState === 'complete'", timeout=timeout)

    def evaluate(self, expression: str, *, timeout: float = 30.0):
        """Value of a JavaScript expression in the page (JSON-serialisable results)."""
        res = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                             "awaitPromise": True}, timeout=timeout)
        if "exceptionDetails" in res:
            raise BrowserError(f"JavaScript error in {expression[:80]!r}: "
                               f"{res['exceptionDetails'].get('exception', {}).get('description', res)}")
        return res.get("result", {}).get("value")

    def wait_for(self, expression: str, *, timeout: float = 20.0, interval: float = 0.1):
        """Poll ``expression`` until it is truthy; return its value (BrowserError on timeout)."""
        import time as _time

        t_end = _time.monotonic() + timeout
        last = None
        while _time.monotonic() < t_end:
            try:
                last = self.evaluate(expression)
            except BrowserError as exc:
                last = exc
            if last and not isinstance(last, BrowserError):
                return last
            _time.sleep(interval)
        raise BrowserError(f"timed out after {timeout} s waiting for {expression!r} (last: {last!r})")

    def requested_urls(self) -> list[str]:
        """URLs the page requested (needs ``send("Network.enable")`` before navigating)."""
        return [e["params"]["request"]["url"] for e in self.events
                if e.get("method") == "Network.requestWillBeSent"]

    def screenshot(self, path) -> Path:
        import base64

        res = self.send("Page.captureScreenshot", {"format": "png"})
        path = Path(path)
        path.write_bytes(base64.b64decode(res["data"]))
        return path

    def close(self) -> None:
        if self._ws is not None:
            try:
                self._ws.close()
            except Exception:
                pass
            self._ws = None
        if getattr(self, "proc", None) is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        if not self._loop.is_closed():
            self._loop.close()
        _remove_profile(self._profile.name)
        self._profile.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


#: JavaScript: the meshcat viewer's scene tree as {path: object type} (no nodes created).
MESHCAT_SCENE_JS = """
(() => {
  const out = {};
  const walk = (node, path) => {
    for (const [name, child] of Object.entries(node.children)) {
      const p = path + "/" + name;
      if (child.object) out[p] = child.object.type + (child.object.visible ? "" : ":hidden");
      walk(child, p);
    }
  };
  walk(viewer.scene_tree, "");
  return out;
})()
"""

#: JavaScript: the meshcat animation: number of actions and duration (s).
MESHCAT_ANIMATION_JS = """
({actions: viewer.animator.actions.length, duration: viewer.animator.duration,
  time: viewer.animator.time, playing: viewer.animator.playing})
"""

#: JavaScript: every <img> of the page as [src prefix, complete, naturalWidth, naturalHeight].
IMAGES_JS = """
Array.from(document.images).map(i => [i.src.slice(0, 22), i.complete, i.naturalWidth, i.naturalHeight])
"""


def _remove_profile(path: str, attempts: int = 20) -> None:
    """Delete a Chromium profile folder; its helper processes may still write to it for a moment
    after the browser exits, so retry briefly instead of failing the test on cleanup."""
    import shutil
    import time
    for _ in range(attempts):
        try:
            shutil.rmtree(path)
            return
        except FileNotFoundError:
            return
        except OSError:
            time.sleep(0.1)
    shutil.rmtree(path, ignore_errors=True)
