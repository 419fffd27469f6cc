"""A user's photo stays their photo on its way to the detail panorama: the real stages
(stylize, upscale, detail) run through `holoflow run --use base_pano=PHOTO --until detail`."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from holoflow.imageops.photo import keep_size
from holoflow.io.exr import read_exr, read_rgb
from holoflow.io.image import read_panorama_image

ROOT = Path(__file__).resolve().parents[2]


def _photo(path: Path) -> Path:
    """A 256 x 128 PNG with detail at every scale (noise over gradients): wider than the tiny profile's
    128 px stages, so any resize or filter on the way would change its values."""
    import cv2

    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:128, 0:256]
    img = np.stack([x, y * 2, (x + y) % 256], -1).astype(np.float64)
    img = np.clip(0.6 * img + rng.normal(0, 40, img.shape), 0, 255).astype(np.uint8)
    cv2.imwrite(str(path), img[..., ::-1])
    return path


def _detail(tmp_path: Path, prompt: str, *extra: str) -> tuple[np.ndarray, dict]:
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        "run",
        prompt,
        "--pipeline",
        str(ROOT / "pipeline.yaml"),
        "--profile",
        "tiny",
        "--store",
        str(tmp_path / "store"),
        "--json",
        "--until",
        "detail",
        "--use",
        f"base_pano={_photo(tmp_path / 'photo.png')}",
        *extra,
    ]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    run = tmp_path / "store" / "runs" / json.loads(done.stdout)["run"]
    return read_rgb(run / "detail" / "pano.exr"), read_exr(run / "detail" / "pano.exr")[1]


def test_a_photo_without_a_style_reaches_detail_unchanged(tmp_path):
    pano, attrs = _detail(tmp_path, "a room")
    photo, _ = read_panorama_image(tmp_path / "photo.png")
    assert pano.shape == photo.shape == (128, 256, 3)
    np.testing.assert_array_equal(pano, photo.astype(np.float32))  # passed through: no arithmetic at all
    assert attrs["holoflow.unaltered"] == 1 and attrs["holoflow.max_width"] == 2048
    assert attrs["holoflow.source"].endswith("photo.png")


def test_a_style_word_still_styles_the_photo_at_its_own_size(tmp_path):
    pano, attrs = _detail(tmp_path, "a watercolor room")
    photo, _ = read_panorama_image(tmp_path / "photo.png")
    assert pano.shape == photo.shape
    assert np.abs(pano - photo).mean() > 0.01
    assert attrs["holoflow.unaltered"] == 0


def test_a_photo_wider_than_the_cap_is_resized_once_at_stylize(tmp_path):
    """Wider than ``max_width``: stylize brings it to the cap (and draws its lineart there), so upscale
    and detail never carry the photo's full size; the record keeps the cap."""
    cap = [f"--set={s}.max_width=192" for s in ("stylize", "upscale", "detail")]
    pano, attrs = _detail(tmp_path, "a room", *cap)
    run = max((tmp_path / "store" / "runs").iterdir())
    assert read_rgb(run / "stylize" / "pano.exr").shape == pano.shape == (96, 192, 3)
    assert read_exr(run / "stylize" / "lineart.exr")[0]["Y"].shape == (96, 192)
    assert read_rgb(run / "upscale" / "pano.exr").shape == (96, 192, 3)
    assert attrs["holoflow.max_width"] == 192 and attrs["holoflow.unaltered"] == 0


@pytest.mark.parametrize(
    "shape, size, cap, want",
    [
        ((1024, 2048), (1024, 512), 4096, (1024, 2048)),  # a photo wider than the stage keeps its size
        ((1024, 2048), (1024, 512), 1536, (768, 1536)),  # ... up to the cap
        ((256, 512), (2048, 1024), 4096, (1024, 2048)),  # a smaller input goes to the stage's size
        ((1024, 2048), (1024, 512), 0, (1024, 2048)),  # 0 = no cap
    ],
)
def test_keep_size(shape, size, cap, want):
    assert keep_size(shape, size[0], size[1], cap) == want


def test_an_unstyled_photo_keeps_its_pixels_up_to_max_width():
    from holoflow.imageops.lineart import lineart
    from holoflow.imageops.photo import unstyled_photo

    rng = np.random.default_rng(3)
    photo = rng.random((32, 64, 3), dtype=np.float32)
    out, lines, attrs, meta = unstyled_photo(photo, 32, 16, 128)  # wider than the stage: kept
    assert out is photo and np.array_equal(lines, lineart(photo))
    assert attrs == {"holoflow.style": "none"} and meta == {"style": "none (user's photo)"}
    out, lines, _, _ = unstyled_photo(photo, 32, 16, 48)  # wider than max_width: to it
    assert out.shape == (24, 48, 3) and lines.shape == (24, 48)
    out, _, _, _ = unstyled_photo(photo, 128, 64, 0)  # narrower than the stage: kept too
    assert out is photo
