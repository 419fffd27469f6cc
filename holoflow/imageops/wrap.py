"""Wrap-aware filtering: pad columns circularly (longitude wraps), filter, crop back."""

from __future__ import annotations

from typing import Callable

import numpy as np


def pad_columns(img: np.ndarray, pad: int) -> np.ndarray:
    """[H, W, ...] -> [H, W + 2 pad, ...]: ``pad`` columns from the far side on each side (any pad >= 0,
    also larger than W)."""
    width = img.shape[1]
    cols = np.arange(-pad, width + pad) % width
    return np.ascontiguousarray(img[:, cols])


def crop_columns(img: np.ndarray, pad: int) -> np.ndarray:
    """Inverse of ``pad_columns``: drop ``pad`` columns on each side."""
    return np.ascontiguousarray(img[:, pad : img.shape[1] - pad]) if pad else img


def wrap_filter(img: np.ndarray, pad: int, fn: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Apply an image filter ``fn`` (same-size in, same-size out) with circular column padding.

    ``pad`` must cover the filter's reach in pixels; rows (the poles) use ``fn``'s own border rule.
    """
    return crop_columns(fn(pad_columns(img, pad)), pad)
