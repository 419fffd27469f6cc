"""Resampling between equirect panoramas and pinhole images, wrap-aware at the seam and the poles.

Panoramas are [C, H, W] or [B, C, H, W] tensors (conventions: holoflow.geometry.sphere); pinhole
cameras are K [B, 3, 3] + world-to-camera viewmat [B, 4, 4] (holoflow.geometry.camera), all at
the panorama centre's frame. Longitude wraps (column W is column 0); a row beyond a pole continues
on the opposite meridian (row -1 at lon is row 0 at lon + pi), so bilinear taps stay on the sphere.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from holoflow.geometry.camera import pinhole_rays, project_points
from holoflow.geometry.sphere import direction_to_lonlat, equirect_directions, lonlat_to_equirect_pixel

_PAD = 2  # spherical padding, pixels on every side; enough for bilinear and nearest taps


def pad_equirect(pano: torch.Tensor, pad: int = _PAD) -> torch.Tensor:
    """Spherical padding [..., C, H, W] -> [..., C, H + 2 pad, W + 2 pad]: columns wrap around the
    seam; rows beyond a pole are the rows before it, flipped, half a turn away (exact for even W)."""
    H, W = pano.shape[-2:]
    if pad > W or pad > H:  # tiny images: index arithmetic handles repeated wraps
        cols = torch.remainder(torch.arange(-pad, W + pad, device=pano.device), W)
        rows = torch.arange(-pad, H + pad, device=pano.device)
        beyond = (rows < 0) | (rows >= H)
        src = torch.where(rows < 0, -rows - 1, torch.where(rows >= H, 2 * H - 1 - rows, rows)).clamp(0, H - 1)
        col_idx = torch.where(beyond[:, None], torch.remainder(cols + W // 2, W)[None, :], cols[None, :])
        flat = (src[:, None] * W + col_idx).reshape(-1)
        return pano.flatten(-2)[..., flat].reshape(*pano.shape[:-2], H + 2 * pad, W + 2 * pad)

    def wrap(x: torch.Tensor) -> torch.Tensor:
        return torch.cat([x[..., W - pad:], x, x[..., :pad]], dim=-1) if pad else x

    turned = torch.roll(pano[..., :pad, :], W // 2, -1).flip(-2), torch.roll(pano[..., H - pad:, :], W // 2, -1).flip(-2)
    return wrap(torch.cat([turned[0], pano, turned[1]], dim=-2))


def sample_equirect(pano: torch.Tensor, dirs: torch.Tensor, mode: str = "bilinear") -> torch.Tensor:
    """Sample a panorama [C, H, W] (shared by all B) or panoramas [B, C, H, W] along world directions
    [B, ..., 3] -> [B, C, ...].

    ``mode``: "bilinear" or "nearest"; taps wrap at the seam and cross the poles (pad_equirect)."""
    if mode not in ("bilinear", "nearest"):
        raise ValueError(f"sample_equirect: mode must be bilinear or nearest, got {mode!r}")
    C, H, W = pano.shape[-3:]
    B = dirs.shape[0]
    lon, lat = direction_to_lonlat(dirs.to(pano.dtype))
    u, v = lonlat_to_equirect_pixel(lon, lat, W, H)  # [B, ...]
    gx = (u + _PAD) * (2.0 / (W + 2 * _PAD)) - 1.0
    gy = (v + _PAD) * (2.0 / (H + 2 * _PAD)) - 1.0
    padded = pad_equirect(pano)  # [(B,) C, H + 2 pad, W + 2 pad], padded once
    if pano.dim() == 3:  # one panorama: every view's taps in one grid
        grid = torch.stack([gx, gy], -1).reshape(1, 1, -1, 2)
        out = F.grid_sample(padded[None], grid, mode=mode, padding_mode="border", align_corners=False)
        return out.reshape(C, B, *dirs.shape[1:-1]).transpose(0, 1)
    grid = torch.stack([gx, gy], -1).reshape(B, 1, -1, 2)
    out = F.grid_sample(padded, grid, mode=mode, padding_mode="border", align_corners=False)
    return out.reshape(B, C, *dirs.shape[1:-1])


def equirect_to_pinhole(pano: torch.Tensor, K: torch.Tensor, viewmat: torch.Tensor, height: int, width: int,
                        mode: str = "bilinear", supersample: int = 2) -> torch.Tensor:
    """Perspective views [B, C, height, width] of a panorama [C, H, W] (shared) or [B, C, H, W].

    K [B, 3, 3], viewmat [B, 4, 4] (only the rotation matters: the panorama is seen from its centre).
    ``mode``: "bilinear" / "nearest" sample each pixel centre; "antialias" first shrinks the panorama
    (resize_equirect) until one of its pixels is no wider than a view pixel at the view's centre, then
    averages ``supersample`` x ``supersample`` bilinear samples per view pixel."""
    if K.dim() == 2:
        K, viewmat = K[None], viewmat[None]
    B = K.shape[0]
    if mode in ("bilinear", "nearest"):
        _, dirs = pinhole_rays(K, viewmat, height, width)  # [B, h, w, 3]
        return sample_equirect(pano, dirs, mode)
    if mode != "antialias":
        raise ValueError(f"equirect_to_pinhole: mode must be bilinear, nearest or antialias, got {mode!r}")
    s = int(supersample)
    scale = K.new_tensor([s, s, 1.0]).diag()
    H, W = pano.shape[-2:]
    levels: dict[tuple[int, int], torch.Tensor] = {}  # prefiltered shared panorama per level
    out = []
    for b in range(B):  # per view: its own prefilter level
        focal = float(torch.sqrt(K[b, 0, 0] * K[b, 1, 1]))
        shrink = W / (2.0 * math.pi * focal)  # pano pixels per view pixel at the view centre
        w2 = max(2, int(round(W / shrink))) if shrink > 1.0 else W
        h2 = max(1, int(round(H * w2 / W))) if shrink > 1.0 else H
        if pano.dim() == 3:
            if (h2, w2) not in levels:
                levels[(h2, w2)] = resize_equirect(pano, h2, w2)
            src = levels[(h2, w2)]
        else:
            src = resize_equirect(pano[b], h2, w2)
        _, dirs = pinhole_rays(scale @ K[b], viewmat[b], height * s, width * s)  # [h s, w s, 3]
        fine = sample_equirect(src, dirs[None], "bilinear")  # [1, C, h s, w s]
        out.append(F.avg_pool2d(fine, s) if s > 1 else fine)
    return torch.cat(out, 0)


def pinhole_to_equirect(images: torch.Tensor, K: torch.Tensor, viewmat: torch.Tensor, height: int, width: int,
                        weights: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Accumulate perspective views [B, C, h, w] onto an equirect grid: (accum [C, H, W], weight_sum [1, H, W]).

    Each equirect pixel centre's direction is projected into every view (rotation only: the views are
    at the panorama centre); where it lands inside the image (in front of the camera), the view's
    bilinear colour times its weight (``weights`` [B, 1, h, w], bilinear too; default 1) is added to
    ``accum`` and the weight to ``weight_sum``. The blend is accum / weight_sum where weight_sum > 0."""
    B, C, h, w = images.shape
    dirs = equirect_directions(height, width, device=images.device, dtype=images.dtype).reshape(-1, 3)
    accum = images.new_zeros(C, height * width)
    wsum = images.new_zeros(1, height * width)
    rot = viewmat.clone()
    rot[..., :3, 3] = 0
    for b in range(B):
        uv, z = project_points(dirs, K[b], rot[b])  # [N, 2], [N]
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)
        grid = torch.stack([uv[:, 0] * (2.0 / w) - 1.0, uv[:, 1] * (2.0 / h) - 1.0], -1)[inside]
        grid = grid.reshape(1, 1, -1, 2)
        col = F.grid_sample(images[b:b + 1], grid, mode="bilinear", padding_mode="border",
                            align_corners=False).reshape(C, -1)
        if weights is None:
            wt = torch.ones_like(col[:1])
        else:
            wt = F.grid_sample(weights[b:b + 1].to(images.dtype), grid, mode="bilinear", padding_mode="border",
                               align_corners=False).reshape(1, -1)
        idx = inside.nonzero().squeeze(1)
        accum.index_add_(1, idx, col * wt)
        wsum.index_add_(1, idx, wt)
    return accum.reshape(C, height, width), wsum.reshape(1, height, width)


def resize_equirect(pano: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Resize a panorama [..., C, H, W] -> [..., C, height, width], wrap-aware (columns are circular)
    and antialiased when shrinking (bilinear filter widened to the source footprint)."""
    H, W = pano.shape[-2:]
    if (H, W) == (height, width):
        return pano
    lead = pano.shape[:-3]
    x = pano.reshape(-1, *pano.shape[-3:])
    g = math.gcd(W, width)
    need = int(math.ceil(W / width)) + 2  # source columns of filter support beyond each edge
    k = max(1, int(math.ceil(need / (W // g))))
    p, q = k * (W // g), k * (width // g)  # p source columns pad <-> exactly q output columns
    cols = torch.remainder(torch.arange(-p, W + p, device=pano.device), W)
    x = x[..., cols]
    out = F.interpolate(x, size=(height, width + 2 * q), mode="bilinear", align_corners=False,
                        antialias=(height < H or width < W))
    return out[..., q:q + width].reshape(*lead, pano.shape[-3], height, width)
