"""Sharp depth edges (holoflow/depth/edges.py): a network's blurred step becomes a step again at the
place the blur crossed half way, smooth surfaces and plateaus are left alone, and a frame's blurred
border with the sky goes to one side or the other, never hanging between."""

import numpy as np
import scipy.ndimage as ndi

from holoflow.depth.edges import sharpen_edges

REACH = 2  # a network's blur at 1024 px across (sigma 1.5 px here), on a narrow strip of it


def blurred_step(near: float = 1.5, far: float = 4.0, sigma: float = 1.5, W: int = 64) -> tuple:
    """Depth [32, W] of a near surface (columns < W / 2) before a far one, its disparity blurred like a
    network's, and the true step."""
    truth = np.where(np.arange(W) < W // 2, near, far)[None].repeat(32, 0).astype(np.float64)
    disp = ndi.gaussian_filter1d(1.0 / truth, sigma, axis=1, mode="nearest")
    return 1.0 / disp, truth


def test_a_blurred_step_is_a_step_again():
    blurred, truth = blurred_step()
    assert (np.abs(blurred / truth - 1) > 0.05).sum() >= 4 * 32  # pixels hang between the two sides
    out, moved = sharpen_edges(blurred, reach=REACH)
    assert np.allclose(out, truth, rtol=0.02)
    assert moved > 0


def test_smooth_surfaces_and_plateaus_are_unchanged():
    ramp = np.linspace(2.0, 2.6, 64)[None].repeat(32, 0)  # a slanted wall: 1 % per pixel at most
    out, moved = sharpen_edges(ramp, reach=REACH)
    assert moved == 0.0 and np.array_equal(out, ramp)
    blurred, _ = blurred_step()
    out, _ = sharpen_edges(blurred, reach=REACH)
    far_from_edge = np.r_[0:20, 44:64]
    assert np.array_equal(out[:, far_from_edge], blurred[:, far_from_edge])


def test_a_border_with_the_sky_goes_to_one_side():
    W = 64
    disp = np.where(np.arange(W) < W // 2, 1 / 3.0, 0.0)[None].repeat(32, 0)
    disp = ndi.gaussian_filter1d(disp, 1.5, axis=1, mode="nearest")
    depth = np.where(disp > 1e-3, 1.0 / np.maximum(disp, 1e-12), np.inf)  # metric_align's max_depth: 1 km
    out, _ = sharpen_edges(depth, reach=REACH)
    finite = out[np.isfinite(out)]
    assert np.allclose(finite, 3.0, rtol=0.02)  # every surface pixel on the frame, none in the air
    assert np.isinf(out[:, W // 2 + 2 :]).all() and np.isfinite(out[:, : W // 2 - 1]).all()
