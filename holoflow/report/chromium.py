"""Headless Chromium for the report: the rendered DOM of a page (``--dump-dom``, after the load
event, so the page's script has run) and screenshots. Debian's package installs /usr/bin/chromium.
"""
from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars",
         "--allow-file-access-from-files")


def find() -> str | None:
    """Path of a Chromium / Chrome executable on PATH, or None."""
    return next((p for p in map(shutil.which, NAMES) if p), None)


def _run(args: list[str], timeout: float) -> str:
    exe = find()
    if exe is None:
        raise FileNotFoundError("no chromium on PATH (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory(prefix="holoflow-chromium-") as profile:
        proc = subprocess.run([exe, *FLAGS, f"--user-data-dir={profile}", *args], capture_output=True,
                              text=True, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"chromium exited {proc.returncode}: {proc.stderr.strip()[-400:]}")
    return proc.stdout


def dump_dom(page: Path, budget_ms: int = 20000, timeout: float = 120.0) -> str:
    """The DOM of ``page`` (a local HTML file) once loaded, as HTML text."""
    return _run([f"--virtual-time-budget={budget_ms}", "--dump-dom", Path(page).absolute().as_uri()], timeout)


def screenshot(page: Path, png: Path, width: int = 1280, height: int = 2400, timeout: float = 120.0) -> Path:
    """A ``width`` x ``height`` screenshot (CSS pixels, top of the page) of ``page`` to ``png``."""
    png = Path(png).absolute()
    _run([f"--window-size={width},{height}", "--virtual-time-budget=20000", f"--screenshot={png}",
          Path(page).absolute().as_uri()], timeout)
    if not png.is_file():
        raise RuntimeError(f"chromium wrote no screenshot to {png}")
    return png
