"""The INP-set mask rule and the OpenCV inpainting engine."""

import numpy as np
import pytest

from holoflow.recon.config import InpSetParams
from holoflow.recon.inpaint import (
    DIRECTIONS,
    OPENCV_METHODS,
    background_fill,
    first_observed,
    inpaint_views,
    missing_mask,
)


def _scene(n=3, h=32, w=32):
    yy, xx = np.mgrid[0:h, 0:w] / 32.0
    base = np.stack([xx, yy, 0.5 + 0 * xx], -1).astype(np.float32)  # smooth ramp [H, W, 3]
    return np.repeat(base[None], n, 0)


def test_missing_mask_is_union_of_alpha_and_pcd_holes():
    alpha = np.ones((1, 4, 4), np.float32)
    alpha[0, 0, 0] = 0.2  # G0 has nothing here
    pcd = np.ones((1, 4, 4), np.float32)
    pcd[0, 3, 3] = 0  # no point landed here (disocclusion)
    m = missing_mask(alpha, pcd, 0.5)
    assert m[0, 0, 0] and m[0, 3, 3] and m.sum() == 2
    assert missing_mask(alpha, None, 0.5).sum() == 1


@pytest.mark.parametrize("method", OPENCV_METHODS)
def test_opencv_fills_every_missing_pixel_and_keeps_the_rest(method):
    imgs = _scene()
    masks = np.zeros(imgs.shape[:3], bool)
    masks[0, 10:16, 12:20] = True  # view 0: a hole
    masks[2, :, :3] = True  # view 2: a border strip
    holed = imgs.copy()
    holed[masks] = 0.0  # the hole carries garbage
    out = inpaint_views(holed, masks, "opencv", InpSetParams(method=method, radius=3))
    assert np.array_equal(out[~masks], holed[~masks])  # observed pixels bit-exact
    assert np.array_equal(out[1], holed[1])  # nothing missing: untouched
    err = np.abs(out[masks] - imgs[masks]).mean()
    assert err < 0.1, f"{method}: fill error {err}"  # smooth ramp: fill is close to truth
    assert np.isfinite(out).all()


def test_views_without_missing_pixels_are_not_inpainted():
    imgs = _scene(2)
    masks = np.zeros(imgs.shape[:3], bool)
    # an unknown engine would raise if it were called: with nothing missing it must not be
    out = inpaint_views(imgs, masks, "no-such-engine", InpSetParams())
    assert np.array_equal(out, imgs)


def test_fully_missing_view_is_finite():
    imgs = _scene(1)
    out = inpaint_views(imgs, np.ones(imgs.shape[:3], bool), "opencv", InpSetParams(method="telea"))
    assert np.isfinite(out).all()


def _disocclusion(h=16, w=32):
    """A far red wall (depth 10 m) behind a near green box (depth 2 m, columns 8..15) and the hole a
    camera move opens right of the box (columns 16..21): image [H, W, 3], missing [H, W], depth [H, W]."""
    img = np.zeros((h, w, 3), np.float32)
    img[..., 0] = 0.8
    img[..., 2] = np.linspace(0.1, 0.3, w)[None]  # a gentle ramp on the wall
    depth = np.full((h, w), 10.0, np.float32)
    img[:, 8:16] = (0.1, 0.9, 0.1)
    depth[:, 8:16] = 2.0
    missing = np.zeros((h, w), bool)
    missing[:, 16:22] = True
    truth = img.copy()  # the hole hides the wall
    return img, missing, depth, truth


def test_first_observed_matches_a_pixel_walk():
    rng = np.random.default_rng(0)
    valid = rng.random((9, 11)) < 0.3
    for step in DIRECTIONS:
        (ry, rx), dist = first_observed(valid, step, 5)
        for y in range(9):
            for x in range(11):
                k = next(
                    (
                        k
                        for k in range(0, 6)
                        if 0 <= y + k * step[0] < 9
                        and 0 <= x + k * step[1] < 11
                        and valid[y + k * step[0], x + k * step[1]]
                    ),
                    -1,
                )
                assert dist[y, x] == k
                if k >= 0:
                    assert (ry[y, x], rx[y, x]) == (y + k * step[0], x + k * step[1])


def test_background_fill_continues_the_far_side_not_the_occluder():
    img, missing, depth, truth = _disocclusion()
    holed = img.copy()
    holed[missing] = 0.0
    out, left = background_fill(holed, missing, depth)
    assert not left.any()
    assert np.array_equal(out[~missing], holed[~missing])
    err_bg = np.abs(out[missing] - truth[missing]).mean()
    telea = inpaint_views(holed[None], missing[None], "opencv", InpSetParams(method="telea", radius=5))[0]
    err_telea = np.abs(telea[missing] - truth[missing]).mean()
    assert out[missing][:, 1].max() < 0.05  # no green from the box leaks in
    assert err_bg < 0.02 and err_bg < 0.5 * err_telea


def test_background_method_needs_depth_and_fills_everything():
    img, missing, depth, truth = _disocclusion()
    m = missing.copy()
    m[:, 28:] = True  # a border strip
    with pytest.raises(ValueError):
        inpaint_views(img[None], m[None], "opencv", InpSetParams(method="background"))
    # max_dist 2: the hole's middle columns are out of reach and left to telea
    out = inpaint_views(
        img[None], m[None], "opencv", InpSetParams(method="background", max_dist=2), depths=depth[None]
    )[0]
    assert np.isfinite(out).all() and np.array_equal(out[~m], img[~m])
