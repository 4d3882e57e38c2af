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


def _run(args: list[str], *, timeout: float) -> subprocess.CompletedProcess:
    exe = find_chromium()
    if exe is None:
        raise BrowserError("no Chromium executable found")
    with tempfile.TemporaryDirectory(prefix="pinmsk-chromium-") as profile:
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
