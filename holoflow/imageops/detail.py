"""Wrap-aware detail enhancement: guided-filter base / detail split of sRGB luma, detail boosted."""

from __future__ import annotations

import numpy as np

from holoflow.imageops.color import linear_to_srgb, srgb_to_linear
from holoflow.imageops.wrap import wrap_filter


def enhance_detail(rgb: np.ndarray, strength: float = 0.5, radius: int | None = None, eps: float = 1e-3) -> np.ndarray:
    """Boost fine detail of a linear RGB panorama [H, W, 3] -> linear RGB [H, W, 3].

    The sRGB luma is split into a base (guided filter of itself, ``radius`` px, regularisation ``eps``)
    and a detail layer; the detail is scaled by ``1 + 2 * strength`` and every channel moves with the
    luma change, so hues stay. ``strength`` 0 returns the input unchanged. Values above 1 (sun, lamps)
    keep their excess. Deterministic; columns are padded circularly by the filter's reach.
    """
    import cv2

    if strength < 0:
        raise ValueError(f"detail strength must be >= 0, got {strength}")
    rgb = np.asarray(rgb, dtype=np.float32)
    if strength == 0:
        return rgb.copy()
    radius = max(2, rgb.shape[1] // 256) if radius is None else radius
    srgb = linear_to_srgb(np.clip(rgb, 0.0, 1.0))  # [H, W, 3]
    luma = (0.2126 * srgb[..., 0] + 0.7152 * srgb[..., 1] + 0.0722 * srgb[..., 2]).astype(np.float32)

    def base_of(img: np.ndarray) -> np.ndarray:
        return cv2.ximgproc.guidedFilter(img, img, radius, eps)

    base = wrap_filter(luma, 2 * radius + 2, base_of)
    boost = (2.0 * strength) * (luma - base)  # [H, W] extra detail
    out = srgb_to_linear(np.clip(srgb + boost[..., None], 0.0, 1.0))
    return np.where(rgb > 1.0, rgb, out).astype(np.float32)
