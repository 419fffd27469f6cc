"""`holoflow view` on the tiny run, opened in headless Chromium with software WebGL: the splats are
drawn where the panorama says they should be, and Ctrl-C (SIGINT) stops the server, leaving no
process and a free port behind.

Skips without chromium, unless HOLOFLOW_REQUIRE_CHROMIUM=1 (set by .ci/run) makes that a failure.
"""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from holoflow.report import chromium

ROOT = Path(__file__).resolve().parents[2]
WIDTH, HEIGHT, FOV_DEG = 800, 600, 75.0  # window (CSS px) and viser's default vertical fov
PATCH_DEG = 10.0  # half-size of the compared patch around the view's centre


def _need_chromium():
    if chromium.find() is None:
        if os.environ.get("HOLOFLOW_REQUIRE_CHROMIUM") == "1":
            pytest.fail("HOLOFLOW_REQUIRE_CHROMIUM=1 but no chromium on PATH (apt-get install chromium)")
        pytest.skip("no chromium on PATH (Debian: apt-get install chromium)")


def _wait_for_url(proc, log: Path, timeout: float = 120.0) -> str:
    """The http:// URL the viewer prints once it serves the scene."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = re.search(r"at (http://\S+?)/? ", log.read_text())
        if found:
            return found.group(1)
        assert proc.poll() is None, f"the viewer exited {proc.returncode}: {log.read_text()[-2000:]}"
        time.sleep(0.2)
    raise AssertionError(f"no URL within {timeout} s: {log.read_text()[-2000:]}")


def _children(pid: int) -> set[int]:
    """Every descendant process of ``pid`` (Linux /proc)."""
    out: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        for child in (task / "children").read_text().split():
            out |= {int(child)} | _children(int(child))
    return out


def _pano_centre_colour(run: Path) -> np.ndarray:
    """Mean 8-bit sRGB colour of the detail panorama within PATCH_DEG of its centre (+z, level)."""
    from holoflow.imageops.color import linear_to_uint8
    from holoflow.io.exr import read_rgb

    pano = linear_to_uint8(read_rgb(run / "detail" / "pano.exr")).astype(np.float64)  # [H, W, 3]
    H, W = pano.shape[:2]
    d = max(1, round(PATCH_DEG / 360 * W))
    return pano[H // 2 - d : H // 2 + d, W // 2 - d : W // 2 + d].reshape(-1, 3).mean(0)


def _centre(shot: np.ndarray) -> np.ndarray:
    """The screenshot's [HEIGHT, WIDTH, 3] pixels within PATCH_DEG of the view centre: [n, 3]."""
    half = round(np.tan(np.radians(PATCH_DEG)) / np.tan(np.radians(FOV_DEG / 2)) * HEIGHT / 2)
    return shot[HEIGHT // 2 - half : HEIGHT // 2 + half, WIDTH // 2 - half : WIDTH // 2 + half].reshape(-1, 3)


def test_viewer_draws_the_scene_and_stops_cleanly(two_runs, tmp_path):
    _need_chromium()
    import imageio.v3 as iio

    store, first, _ = two_runs
    run = store / "runs" / first["run"]
    log = tmp_path / "view.log"
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "holoflow", "view", first["run"], "--store", str(store), "--port", "0"],
            cwd=ROOT,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        url = _wait_for_url(proc, log)
        assert url.startswith("http://127.0.0.1:")
        expected = _pano_centre_colour(run)
        # software WebGL on a busy 2-core machine sometimes has not drawn the whole scene within the
        # first budget (seen: centre 153-178 against 125, the white page showing through): one
        # second look with a longer budget; the test fails when both miss the panorama's colour
        for budget in (15000, 45000):
            png = chromium.screenshot(
                url, tmp_path / f"view-{budget}.png", WIDTH, HEIGHT, timeout=180, webgl=True, budget_ms=budget
            )
            centre = _centre(iio.imread(png)[..., :3].astype(np.float64))
            if np.abs(centre.mean(0) - expected).max() < 25:
                break
        children = _children(proc.pid)
    finally:
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(timeout=60)
    assert rc == 0 and "holoflow view: stopped" in log.read_text(), log.read_text()[-2000:]
    assert not [p for p in children if Path(f"/proc/{p}").exists()], "the viewer left processes behind"
    from holoflow.commands.view import port_free

    assert port_free("127.0.0.1", int(url.rsplit(":", 1)[1]))

    # the empty viewer is a near-white background, far from this scene's dim colours
    assert np.abs(centre.mean(0) - expected).max() < 25, (centre.mean(0), expected)
