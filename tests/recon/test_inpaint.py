"""The INP-set mask rule and the OpenCV inpainting engine."""
import numpy as np
import pytest

from holoflow.recon.inpaint import OPENCV_METHODS, inpaint_views, missing_mask


def _scene(n=3, h=32, w=32):
    yy, xx = np.mgrid[0:h, 0:w] / 32.0
    base = np.stack([xx, yy, 0.5 + 0 * xx], -1).astype(np.float32)     # smooth ramp [H, W, 3]
    return np.repeat(base[None], n, 0)


def test_missing_mask_is_union_of_alpha_and_pcd_holes():
    alpha = np.ones((1, 4, 4), np.float32)
    alpha[0, 0, 0] = 0.2                          # G0 has nothing here
    pcd = np.ones((1, 4, 4), np.float32)
    pcd[0, 3, 3] = 0                              # no point landed here (disocclusion)
    m = missing_mask(alpha, pcd, 0.5)
    assert m[0, 0, 0] and m[0, 3, 3] and m.sum() == 2
    assert missing_mask(alpha, None, 0.5).sum() == 1


@pytest.mark.parametrize("method", OPENCV_METHODS)
def test_opencv_fills_every_missing_pixel_and_keeps_the_rest(method):
    imgs = _scene()
    masks = np.zeros(imgs.shape[:3], bool)
    masks[0, 10:16, 12:20] = True                 # view 0: a hole
    masks[2, :, :3] = True                        # view 2: a border strip
    holed = imgs.copy()
    holed[masks] = 0.0                            # the hole carries garbage
    out = inpaint_views(holed, masks, "opencv", {"method": method, "radius": 3})
    assert np.array_equal(out[~masks], holed[~masks])          # observed pixels bit-exact
    assert np.array_equal(out[1], holed[1])                    # nothing missing: untouched
    err = np.abs(out[masks] - imgs[masks]).mean()
    assert err < 0.1, f"{method}: fill error {err}"            # smooth ramp: fill is close to truth
    assert np.isfinite(out).all()


def test_views_without_missing_pixels_are_not_inpainted():
    imgs = _scene(2)
    masks = np.zeros(imgs.shape[:3], bool)
    # an unknown engine would raise if it were called: with nothing missing it must not be
    out = inpaint_views(imgs, masks, "no-such-engine", {})
    assert np.array_equal(out, imgs)


def test_fully_missing_view_is_finite():
    imgs = _scene(1)
    out = inpaint_views(imgs, np.ones(imgs.shape[:3], bool), "opencv", {"method": "telea"})
    assert np.isfinite(out).all()
