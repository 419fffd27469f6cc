"""Headless Chromium for the report and the viewer: the rendered DOM of a page (``--dump-dom``, after
the load event, so the page's script has run) and screenshots of a page or URL (software WebGL on
request). Debian's package installs /usr/bin/chromium.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--hide-scrollbars",
    "--allow-file-access-from-files",
)
NO_GPU = ("--disable-gpu",)
SOFTWARE_WEBGL = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader")  # WebGL on the CPU (SwiftShader)


def find() -> str | None:
    """Path of a Chromium / Chrome executable on PATH, or None."""
    return next((p for p in map(shutil.which, NAMES) if p), None)


def _run(args: list[str], timeout: float, webgl: bool = False) -> str:
    exe = find()
    if exe is None:
        raise FileNotFoundError("no chromium on PATH (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory(prefix="holoflow-chromium-") as profile:
        proc = subprocess.run(
            [exe, *FLAGS, *(SOFTWARE_WEBGL if webgl else NO_GPU), f"--user-data-dir={profile}", *args],
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    if proc.returncode != 0:
        raise RuntimeError(f"chromium exited {proc.returncode}: {proc.stderr.strip()[-400:]}")
    return proc.stdout


def dump_dom(page: Path, budget_ms: int = 20000, timeout: float = 120.0) -> str:
    """The DOM of ``page`` (a local HTML file) once loaded, as HTML text."""
    return _run([f"--virtual-time-budget={budget_ms}", "--dump-dom", Path(page).absolute().as_uri()], timeout)


def screenshot(
    page: Path | str,
    png: Path,
    width: int = 1280,
    height: int = 2400,
    timeout: float = 120.0,
    webgl: bool = False,
    budget_ms: int = 20000,
) -> Path:
    """A ``width`` x ``height`` screenshot (CSS pixels, top of the page) of ``page`` (a local HTML file,
    or an http:// URL given as a str) to ``png``, after ``budget_ms`` of the page's virtual time.
    ``webgl``: software WebGL (SwiftShader) instead of no GPU at all."""
    png = Path(png).absolute()
    url = page if isinstance(page, str) and page.startswith("http") else Path(page).absolute().as_uri()
    _run(
        [f"--window-size={width},{height}", f"--virtual-time-budget={budget_ms}", f"--screenshot={png}", url],
        timeout,
        webgl,
    )
    if not png.is_file():
        raise RuntimeError(f"chromium wrote no screenshot to {png}")
    return png
