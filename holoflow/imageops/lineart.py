"""Lineart: the control signal of the stylize stage (the paper's ControlNet Lineart input).

A classical line extractor: eXtended Difference-of-Gaussians (XDoG, Winnemoeller et al. 2012) on the
sRGB luminance, soft-thresholded into dark-on-light strokes, then inverted so that 1 = line, 0 = paper.
Wrap-aware: columns are padded circularly before filtering.
"""

from __future__ import annotations

import math

import numpy as np

from holoflow.imageops.color import linear_to_srgb, luminance
from holoflow.imageops.wrap import wrap_filter


def lineart(
    rgb: np.ndarray,
    sigma: float | None = None,
    k: float = 1.6,
    tau: float = 0.985,
    phi: float = 60.0,
    epsilon: float = 0.0,
) -> np.ndarray:
    """Line map [H, W] float32 in [0, 1] (1 = line) of a linear RGB panorama [H, W, 3].

    ``sigma``: inner Gaussian in pixels (default scales with width: 0.6 px at 1024 wide, at least 0.5);
    ``k``: outer / inner sigma ratio; ``tau``: DoG weight (below 1 keeps edges, drops flat areas);
    ``phi``: sharpness of the soft threshold at ``epsilon``.
    """
    import cv2

    width = rgb.shape[1]
    sigma = max(0.5, 0.6 * width / 1024.0) if sigma is None else sigma
    gray = np.clip(luminance(linear_to_srgb(np.clip(rgb, 0.0, 1.0))), 0.0, 1.0)  # [H, W] sRGB luma
    pad = int(math.ceil(4 * k * sigma)) + 2

    def dog(img: np.ndarray) -> np.ndarray:
        g1 = cv2.GaussianBlur(img, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
        g2 = cv2.GaussianBlur(img, (0, 0), k * sigma, borderType=cv2.BORDER_REFLECT)
        return g1 - tau * g2

    d = wrap_filter(gray, pad, dog) / max(1e-6, 1.0 - tau)  # ~ luma units
    paper = np.where(d >= epsilon, 1.0, 1.0 + np.tanh(phi * (1.0 - tau) * (d - epsilon)))
    return np.clip(1.0 - paper, 0.0, 1.0).astype(np.float32)
