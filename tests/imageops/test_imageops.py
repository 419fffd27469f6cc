"""Classical image operations: colour, wrap padding, Lanczos, lineart, styles, detail — seams, determinism,
contracts, and lineart as a real structure map of the base panorama."""

import numpy as np
import pytest

from holoflow.imageops.color import linear_to_srgb, linear_to_uint8, srgb_to_linear, uint8_to_linear
from holoflow.imageops.detail import enhance_detail
from holoflow.imageops.lineart import lineart
from holoflow.imageops.resize import lanczos_resize, lanczos_resize_reference, lanczos_weights
from holoflow.imageops.styles import STYLE_WORDS, style_from_prompt, stylize
from holoflow.imageops.wrap import crop_columns, pad_columns

STYLES = sorted(set(STYLE_WORDS.values()))


@pytest.fixture(scope="module")
def base():
    """A rendered indoor panorama (linear RGB) and its radial depth, 256 x 128."""
    import torch

    from holoflow.scene import render_equirect, scene_from_prompt

    torch.set_num_threads(1)
    return render_equirect(scene_from_prompt("a living room with a red sofa and wooden shelves", 0), 256, 128, 1)


def seam_ok(img: np.ndarray) -> bool:
    """The last -> first column step is no larger than typical neighbouring-column steps (95th pct)."""
    img = np.clip(np.asarray(img, dtype=np.float32), 0.0, 1.0)
    img = img if img.ndim == 3 else img[..., None]
    steps = np.abs(np.diff(img, axis=1)).mean(axis=(0, 2))  # [W - 1]
    seam = np.abs(img[:, -1] - img[:, 0]).mean()
    return bool(seam <= np.percentile(steps, 95))


def roll_error(fn, img: np.ndarray, shift: int) -> float:
    """How far ``fn`` is from commuting with a longitude rotation (0 for an exactly wrap-aware op)."""
    a = np.roll(fn(img), shift, axis=1)
    b = fn(np.roll(img, shift, axis=1))
    return float(np.abs(np.clip(a, 0, 1) - np.clip(b, 0, 1)).mean())


def test_colour_round_trips():
    x = np.linspace(0, 1, 1001, dtype=np.float32)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-6)
    assert abs(float(linear_to_srgb(np.float32(0.18))) - 0.4614) < 1e-3
    u = np.arange(256, dtype=np.uint8)
    np.testing.assert_array_equal(linear_to_uint8(uint8_to_linear(u)), u)  # rounding to 8 bits absorbs any ulp


def test_pad_and_crop():
    img = np.arange(24, dtype=np.float32).reshape(2, 12)
    p = pad_columns(img, 3)
    assert p.shape == (2, 18)
    np.testing.assert_array_equal(p[:, :3], img[:, -3:])  # padding and cropping copy: exact on any CPU
    np.testing.assert_array_equal(p[:, -3:], img[:, :3])
    np.testing.assert_array_equal(crop_columns(p, 3), img)
    assert pad_columns(img, 30).shape == (2, 72)  # pad wider than W


@pytest.mark.parametrize("size", [(512, 256), (384, 192), (200, 100), (256, 128)])
def test_lanczos_contract_seam_and_wrap(base, size):
    rgb, _ = base
    out = lanczos_resize(rgb, *size)
    assert out.shape == (size[1], size[0], 3) and out.dtype == np.float32
    assert seam_ok(out)
    if size[0] % 256 == 0 or size[0] == 384:  # integer shift maps exactly
        shift = 16
        a = np.roll(out, shift * size[0] // 256, axis=1)
        b = lanczos_resize(np.roll(rgb, shift, axis=1), *size)
        assert np.abs(a - b).max() < 1e-4
    const = np.full((32, 64, 3), 0.25, np.float32)
    np.testing.assert_allclose(lanczos_resize(const, 96, 48), 0.25, atol=1e-5)
    with pytest.raises(ValueError):
        lanczos_resize(rgb, 0, 10)


@pytest.mark.parametrize("size", [(96, 48), (67, 33), (512, 256), (331, 160)])
@pytest.mark.parametrize("wrap", [True, False])
def test_lanczos_fast_path_matches_oiio_reference(size, wrap):
    """The separable sparse-matrix path against OpenImageIO's 2-D lanczos3 (shrinking 2.7-3.3x and
    enlarging 1.3-2x, odd sizes, with and without the longitude wrap), on random pixels in [0, 1)."""
    img = np.random.default_rng(3).random((128, 256, 3), dtype=np.float32)
    fast = lanczos_resize(img, *size, wrap=wrap)
    ref = lanczos_resize_reference(img, *size, wrap=wrap)
    assert fast.shape == ref.shape == (size[1], size[0], 3)
    np.testing.assert_allclose(fast, ref, atol=5e-4)


def test_lanczos_weights_rows_sum_to_one_and_wrap():
    w = lanczos_weights(300, 97, True).toarray()  # shrink, stretched kernel
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-12)
    assert (w[0, -5:] != 0).any() and (w[-1, :5] != 0).any()  # the seam's taps wrap
    c = lanczos_weights(300, 97, False).toarray()
    assert (c[0, -5:] == 0).all() and (c[-1, :5] == 0).all()  # rows: edge repeated
    np.testing.assert_allclose(lanczos_weights(10, 10, True).toarray(), np.eye(10), atol=1e-12)  # same size


def test_lineart_contract_and_wrap(base):
    rgb, _ = base
    lines = lineart(rgb)
    assert lines.shape == rgb.shape[:2] and lines.dtype == np.float32
    assert 0.0 <= lines.min() and lines.max() <= 1.0 and lines.max() > 0.5
    assert seam_ok(lines)
    assert roll_error(lineart, rgb, 37) < 1e-6
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    np.testing.assert_array_equal(lineart(rgb), lines)


def test_lineart_marks_the_base_images_edges(base):
    """Lines lie where the base has structure: depth discontinuities (object outlines) and strong
    luminance gradients get far more line than flat regions."""
    import cv2

    rgb, depth = base
    lines = lineart(rgb)
    d = np.log(depth)
    jump = np.zeros(d.shape, bool)
    dx = np.abs(d - np.roll(d, 1, axis=1)) > 0.08
    dy = np.zeros_like(dx)
    dy[1:] = np.abs(d[1:] - d[:-1]) > 0.08
    jump |= dx | dy
    jump = cv2.dilate(jump.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    gray = linear_to_srgb(np.clip(rgb, 0, 1)).mean(2)
    grad = np.hypot(cv2.Sobel(gray, cv2.CV_32F, 1, 0), cv2.Sobel(gray, cv2.CV_32F, 0, 1))
    flat = (grad < np.percentile(grad, 40)) & ~jump
    strong = grad > np.percentile(grad, 95)
    assert lines[jump].mean() > 3 * lines[flat].mean()
    assert lines[strong].mean() > 5 * lines[flat].mean()
    # and it is not the depth map's shadow of itself: correlation with the gradient map is clearly positive
    assert np.corrcoef(lines.ravel(), grad.ravel())[0, 1] > 0.3


def test_style_words():
    assert style_from_prompt("a forest, watercolor") == "watercolor"
    assert style_from_prompt("an anime city at night") == "cartoon"
    assert style_from_prompt("Oil painting of a harbour") == "oil"
    assert style_from_prompt("a pencil sketch of a kitchen") == "pencil"
    assert style_from_prompt("a plain living room") is None


@pytest.mark.parametrize("style", STYLES)
def test_styles_contract_seam_determinism(base, style):
    rgb, _ = base
    lines = lineart(rgb)
    out = stylize(rgb, lines, style)
    assert out.shape == rgb.shape and out.dtype == np.float32 and np.isfinite(out).all()
    assert out.min() >= 0.0 and out.max() <= 1.0
    assert seam_ok(out)
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    np.testing.assert_array_equal(stylize(rgb, lines, style), out)
    assert roll_error(lambda x: stylize(x, lineart(x), style), rgb, 64) < 0.01
    assert np.abs(out - np.clip(rgb, 0, 1)).mean() > 0.005  # it does something


def test_styles_keep_the_lineart_geometry(base):
    """A style's own lineart still lines up with the base's lineart (same edges, same places)."""
    rgb, _ = base
    lines = lineart(rgb)
    for style in ("watercolor", "oil", "cartoon", "pastel"):
        again = lineart(stylize(rgb, lines, style))
        assert np.corrcoef(lines.ravel(), again.ravel())[0, 1] > 0.4, style


def test_unknown_style_is_an_error(base):
    with pytest.raises(ValueError, match="unknown style"):
        stylize(base[0], lineart(base[0]), "cubism")


def test_detail_enhancement(base):
    import cv2

    rgb, _ = base
    np.testing.assert_array_equal(enhance_detail(rgb, 0.0), rgb)  # strength 0 returns the input
    out = enhance_detail(rgb, 0.8)
    assert out.shape == rgb.shape and out.dtype == np.float32 and np.isfinite(out).all()
    assert seam_ok(out)
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    np.testing.assert_array_equal(enhance_detail(rgb, 0.8), out)
    assert roll_error(lambda x: enhance_detail(x, 0.8), rgb, 50) < 1e-6

    def high(x):
        g = linear_to_srgb(np.clip(x, 0, 1)).mean(2)
        return np.abs(g - cv2.GaussianBlur(g, (0, 0), 2.0)).mean()

    assert high(out) > 1.2 * high(rgb)  # more fine detail
    assert abs(float(linear_to_srgb(np.clip(out, 0, 1)).mean() - linear_to_srgb(np.clip(rgb, 0, 1)).mean())) < 0.02
    with pytest.raises(ValueError):
        enhance_detail(rgb, -1.0)
