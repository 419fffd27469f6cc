"""Colour, the one module: linear light <-> sRGB (IEC 61966-2-1) on numpy arrays and on torch tensors,
8-bit conversion, luminance. numpy only at import (the torch pair imports kornia when called)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import torch


def linear_to_srgb(x: np.ndarray, clip: bool = False) -> np.ndarray:
    """Linear light -> sRGB-encoded values (float32); negatives clip to 0, values above 1 pass the curve
    (``clip``: clipped to 1 first, as networks take them)."""
    x = np.asarray(x, dtype=np.float32)
    x = np.clip(x, 0.0, 1.0) if clip else np.maximum(x, 0.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055).astype(np.float32)


def srgb_to_linear(x: np.ndarray, clip: bool = False) -> np.ndarray:
    """sRGB-encoded values -> linear light (float32); negatives clip to 0 (``clip``: values above 1 too)."""
    x = np.asarray(x, dtype=np.float32)
    x = np.clip(x, 0.0, 1.0) if clip else np.maximum(x, 0.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4)).astype(np.float32)


def linear_to_srgb_torch(x: "torch.Tensor") -> "torch.Tensor":
    """Linear light [..., H, W, 3] tensor -> sRGB-encoded [0, 1] (clamped first; kornia's curve): what
    the Gaussians are trained and scored on (holoflow.recon.views)."""
    import kornia

    c = x.clamp(0, 1).movedim(-1, -3)  # [..., 3, H, W]
    return kornia.color.linear_rgb_to_rgb(c).clamp(0, 1).movedim(-3, -1)


def srgb_to_linear_torch(x: "torch.Tensor") -> "torch.Tensor":
    """sRGB-encoded [0, 1] [..., H, W, 3] tensor -> linear light (clamped first; kornia's curve)."""
    import kornia

    return kornia.color.rgb_to_linear_rgb(x.clamp(0, 1).movedim(-1, -3)).movedim(-3, -1)


def to_uint8(srgb: np.ndarray) -> np.ndarray:
    """sRGB floats in [0, 1] -> uint8 (rounded, clipped)."""
    return np.clip(np.asarray(srgb, dtype=np.float32) * 255.0 + 0.5, 0, 255).astype(np.uint8)


def linear_to_uint8(rgb: np.ndarray) -> np.ndarray:
    """Linear RGB [..., 3] -> 8-bit sRGB [..., 3] (what 8-bit image operations take)."""
    return to_uint8(linear_to_srgb(rgb))


def uint8_to_linear(img: np.ndarray) -> np.ndarray:
    """8-bit sRGB -> linear float32."""
    return srgb_to_linear(np.asarray(img, dtype=np.float32) / 255.0)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance [...] of linear RGB [..., 3]."""
    rgb = np.asarray(rgb, dtype=np.float32)
    return (0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]).astype(np.float32)
