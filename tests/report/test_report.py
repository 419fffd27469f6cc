"""holoflow report: a real tiny-profile run of the whole pipeline, then a partial one served from the
cache (so the report sees ran / cached / not-run stages), its HTML, and headless Chromium loading every
image.

Chromium tests skip when no chromium is installed, unless HOLOFLOW_REQUIRE_CHROMIUM=1 (set by .ci/run),
which turns the skip into a failure.
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from holoflow.flow.store import Store
from holoflow.report import chromium, clouds, main
from holoflow.report.runinfo import ReportError, collect

ROOT = Path(__file__).resolve().parents[2]
PIPELINE = ROOT / "pipeline.yaml"
PANOS = ("base_pano", "stylize", "upscale", "detail")


def _need_chromium():
    if chromium.find() is None:
        if os.environ.get("HOLOFLOW_REQUIRE_CHROMIUM") == "1":
            pytest.fail("HOLOFLOW_REQUIRE_CHROMIUM=1 but no chromium on PATH (apt-get install chromium)")
        pytest.skip(
            "no chromium on PATH (Debian: apt-get install chromium); set HOLOFLOW_REQUIRE_CHROMIUM=1 "
            "to make this a failure"
        )


def _holoflow(store, *args):
    cmd = [sys.executable, "-m", "holoflow", *args[:1], "--pipeline", str(PIPELINE), "--store", str(store), *args[1:]]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """(store, partial run id, full run id): the whole tiny pipeline, then `--until detail` (cached)."""
    store = tmp_path_factory.mktemp("report-store")
    ids = []
    for extra in ([], ["--until", "detail"]):
        _holoflow(store, "run", "a small wooden cabin", "--profile", "tiny", *extra)
        ids.append(os.readlink(store / "latest").split("/")[-1])
    assert ids[0] != ids[1]
    return store, ids[1], ids[0]


def _report(store, run, out):
    assert main([run, "--pipeline", str(PIPELINE), "--store", str(store), "-o", str(out)]) == 0
    return out.read_text()


def _img_titles(html):
    return re.findall(r'<img src="data:image/(?:png|jpeg|gif);base64,[A-Za-z0-9+/=]+" alt="([^"]*)"', html)


def _loaded(page):
    """(total, loaded, broken) as the page's own script counted them in headless Chromium."""
    body = re.search(r"<body([^>]*)>", chromium.dump_dom(page)).group(1)
    attrs = dict(re.findall(r'data-images-(\w+)="([^"]*)"', body))
    assert attrs, f"the page's load script did not run: <body{body}>"
    return int(attrs["total"]), int(attrs["loaded"]), attrs["broken"]


def test_full_run_report(runs, tmp_path):
    store, _, full = runs
    html = _report(store, full, tmp_path / "full.html")
    titles = _img_titles(html)
    assert html.count("<img ") == len(titles), "every image is an inline data: URI"
    for stage in PANOS:
        assert f'id="{stage}"' in html
    assert titles.count("pano.exr") == 4  # the four panoramas
    assert "lineart.exr Y" in titles and "disparity.exr Y" in titles and "depth.exr Z" in titles
    assert "faces/ aligned.Y" in titles and "faces/ raw.Y" in titles  # tangent faces mosaics
    for sheet in ("views/", "views/ A", "renders/"):  # PANO / PCD / INP sheets and masks
        assert sheet in titles
    assert titles.count("views/ A") == 2  # pcd_set and inp_set masks
    for cloud in ("p0.ply", "pf.ply", "ps.ply", "gaussians.ply", "scene.ply"):
        assert cloud in titles
    assert titles.count("train_log.json: loss") == 2 and titles.count("train_log.json: Gaussians") == 2
    assert "previews/look_around.png" in titles
    assert '<h2 id="viewing">what people see (512 px)</h2>' in html and "base PSNR dB (10 cameras)" in html
    assert "base cameras at 512 px" in titles and "novel cameras 0.5 m off centre" in titles
    assert (
        "not run"
        not in re.sub(r"<script>.*</script>", "", html, flags=re.S).split("<h2>stages")[1].split("<h2>metrics")[0]
    )
    record = json.loads((store / "keys" / f"{_key(store, full, 'transfer_opt')}.json").read_text())
    assert f"{record['provenance']['peak_rss_mb']:.4g}" in html  # peak memory in the summary

    _need_chromium()
    total, loaded, broken = _loaded(tmp_path / "full.html")
    assert (total, loaded, broken) == (len(titles), len(titles), "")


def test_partial_run_shows_not_run(runs, tmp_path):
    store, partial, full = runs
    html = _report(store, partial, tmp_path / "partial.html")
    assert (
        html.count('<span class="badge notrun">not run</span>') == 2 * 9
    )  # table row + heading, 9 stages (export too)
    assert html.count('<span class="badge cached">cached</span>') == 2 * len(PANOS)
    assert html.count("<td>this run</td>") == 0 and html.count(f"<td>{full}</td>") == len(PANOS)
    titles = _img_titles(html)
    assert titles.count("pano.exr") == 4 and not any(t.endswith(".ply") for t in titles)
    _need_chromium()
    assert _loaded(tmp_path / "partial.html") == (len(titles), len(titles), "")


def test_chromium_check_catches_a_broken_image(tmp_path):
    """The load check itself: a page with one good and one corrupt image counts one broken."""
    from holoflow.report import page, pictures

    good = pictures.image_uri(np.zeros((4, 6, 3), np.uint8))
    html = (
        f"<!DOCTYPE html><html><body><img src='{good}' alt='good'>"
        f"<img src='data:image/png;base64,iVBORw0KGgoAAAA' alt='bad'><script>{page.SCRIPT}</script></body></html>"
    )
    (tmp_path / "p.html").write_text(html)
    _need_chromium()
    assert _loaded(tmp_path / "p.html") == (2, 1, "bad")


def test_unknown_run_is_a_user_error(tmp_path, capsys):
    assert main(["nope", "--pipeline", str(PIPELINE), "--store", str(tmp_path)]) == 2
    assert "no run 'nope'" in capsys.readouterr().err
    with pytest.raises(ReportError, match="no latest run"):
        collect(Store(tmp_path))


def test_cloud_renderers_agree(tmp_path):
    """pyvista (child process) and the z-buffer fallback put a floor's points in the same place."""
    from holoflow.io.ply import write_points

    g = np.linspace(-2, 2, 60)
    x, z = np.meshgrid(g, g)
    xyz = np.stack([x.ravel(), np.full(x.size, 1.5), z.ravel()], 1).astype(np.float32)  # floor 1.5 m below
    rgb = np.tile(np.array([[200, 30, 30]], np.uint8), (len(xyz), 1))
    write_points(tmp_path / "floor.ply", xyz, rgb)
    (img,), renderer = clouds.render_files([(tmp_path / "floor.ply", tmp_path / "floor.png")])
    ref = clouds.render_zbuffer(*clouds.read_cloud(tmp_path / "floor.ply"))
    assert ref.shape == (clouds.SIZE[1], clouds.SIZE[0], 3)
    if not renderer.startswith("pyvista"):
        pytest.skip(f"pyvista could not render here: {renderer}")
    import cv2

    # point footprints differ (VTK points vs z-buffer squares): compare the closed-up silhouettes
    a, b = (
        cv2.dilate((im.astype(int).sum(-1) < 700).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0 for im in (img, ref)
    )
    iou = (a & b).sum() / (a | b).sum()
    assert a.sum() > 20000 and iou > 0.9, iou


def test_cloud_fallback_when_pyvista_fails(tmp_path, monkeypatch):
    from holoflow.io.ply import write_points

    write_points(tmp_path / "c.ply", np.array([[0, 1, 1], [0.5, 1, 2]], np.float32), np.full((2, 3), 9, np.uint8))
    monkeypatch.setattr(clouds.subprocess, "run", lambda *a, **k: subprocess.CompletedProcess(a, 1, "", "no EGL"))
    (img,), renderer = clouds.render_files([(tmp_path / "c.ply", tmp_path / "c.png")])
    assert renderer == "holoflow z-buffer projection (pyvista failed: no EGL)"
    assert img.shape == (clouds.SIZE[1], clouds.SIZE[0], 3) and (img == 9).all(-1).sum() >= 2


def _key(store, run, stage):
    return json.loads((store / "runs" / run / "run.json").read_text())["stages"][stage]["key"]


def test_outputs_gone_from_the_store_are_noted_not_broken(runs, tmp_path):
    """A run whose objects were deleted (e.g. by gc) still gives a page without broken images."""
    import shutil

    store, partial, _ = runs
    copy = tmp_path / "store"
    shutil.copytree(store / "runs" / partial, copy / "runs" / partial, symlinks=True)
    shutil.copytree(store / "keys", copy / "keys")  # records kept, objects gone
    html = _report(copy, partial, tmp_path / "gone.html")
    assert not _img_titles(html)
    assert html.count("output(s) no longer in the store") == len(PANOS)
