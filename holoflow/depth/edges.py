"""Sharp depth edges for a network's depth: no pixels hanging between a near object and what is behind.

A monocular network (and the blending of its faces) blurs every depth discontinuity over a few pixels,
so a pixel at a window frame holds a depth between the frame's and the sky's, a chair's edge one
between the chair and the wall. From the centre that is invisible; one step away those pixels float
in the air as a grey halo, ghosting the frame into the window. The truth is a step: each pixel belongs
to one side. ``sharpen_edges`` gives every pixel of a blurred step the side its disparity is nearer
to, which puts the step where the blur crossed half way: where the edge was.

Arrays: radial depth [H, W] metres (+inf sky), equirect (columns wrap).
"""

from __future__ import annotations

import numpy as np


def sharpen_edges(depth: np.ndarray, reach: int | None = None, jump: float = 0.25) -> tuple[np.ndarray, float]:
    """Radial depth [H, W] with its blurred steps made sharp, and the share of pixels moved.

    Within ``2 reach`` pixels of a pixel (a window wide enough to see past the blur's tails on both
    sides), the largest and smallest disparity (1 / depth; sky is 0) are the two sides of a step when they
    differ by more than ``jump`` of the largest; a pixel there takes the side its disparity is nearer to
    (sky when that is the far side). Pixels of a smooth
    surface (no such step around) and the step's two plateaus are returned unchanged. ``reach`` should
    cover the blur's half width; None: a network's, 2 px at 1024 px across, in proportion to the width
    (at least 1)."""
    import scipy.ndimage as ndi

    depth = np.asarray(depth, dtype=np.float64)
    reach = max(1, round(2 * depth.shape[1] / 1024)) if reach is None else reach
    disp = np.where(np.isfinite(depth) & (depth > 0), 1.0 / np.where(depth > 0, depth, 1.0), 0.0)  # [H, W]
    size, mode = 4 * reach + 1, ("nearest", "wrap")  # the sides: past the blur's tails on either side
    hi = ndi.maximum_filter(disp, size=size, mode=mode)
    lo = ndi.minimum_filter(disp, size=size, mode=mode)
    step = hi - lo > jump * hi
    out = np.where(disp - lo < hi - disp, lo, hi)
    moved = step & (out != disp)
    new = np.where(moved, out, disp)
    sharp = np.where(new > 0, 1.0 / np.where(new > 0, new, 1.0), np.inf)
    return np.where(moved, sharp, depth), float(moved.mean())
