"""Where P_f needs its full width: the panorama's detail, measured by what thinning takes away.

P_f's width sets how sharp the scene is and how many Gaussians train. Most of a room is plain (walls,
ceiling, floor): there a point per two pixels renders what a point per pixel does. The detail (books,
plants, a picture, a window's bars) is a small share of the sphere, and there P_f's width is what a
view 0-1 m from the centre shows. So P_f is sampled at its full width only in the tiles of its grid
where halving the width takes the most away, as many tiles as make up a given share of the sphere's
area, and at half the width elsewhere: with a quarter of the sphere at full width, fewer points than
P_f three quarters as wide everywhere, and most of the full width's sharpness
(docs/reconstruction.md has the measurements).

Detail is measured in sRGB [0, 1] (what a viewer shows), as the mean square of the image against
itself resized to a smaller width and back (``resize_equirect``: antialiased down, bilinear up),
weighted by each row's area (cos latitude) where a whole panorama is scored.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from holoflow.geometry.sampling import resize_equirect

DETAIL_TILE_PX = 8  # tile side on P_f's grid: 0.7 deg at 2048 px, a view pixel's 7 at 512 px / 47 deg


def thinning_loss(srgb: torch.Tensor, width: int) -> torch.Tensor:
    """[H, W] mean square over the channels of srgb [H, W, C] (sRGB) against itself resized to
    ``width`` x ``width // 2`` and back: the detail that a grid that wide loses, per pixel."""
    H, W = srgb.shape[:2]
    x = srgb.permute(2, 0, 1).float()
    back = resize_equirect(resize_equirect(x, max(1, width // 2), width), H, W)
    return ((back - x) ** 2).mean(0)


def thinning_psnr(srgb: torch.Tensor, width: int) -> float:
    """PSNR (dB, peak 1) of srgb [H, W, C] (sRGB in [0, 1]) against itself thinned to ``width`` px
    and back, area-weighted over the sphere: how much of the panorama a grid that wide keeps."""
    H = srgb.shape[0]
    lat = math.pi / 2 - (torch.arange(H, dtype=torch.float64) + 0.5) * (math.pi / H)
    area = torch.cos(lat)[:, None]  # [H, 1]
    loss = thinning_loss(srgb, width).double()
    mse = float((loss * area).sum() / (area.sum() * loss.shape[1]))
    return 10.0 * math.log10(1.0 / max(mse, 1e-20))


def detail_tiles(srgb: torch.Tensor, share: float, tile: int = DETAIL_TILE_PX) -> torch.Tensor:
    """[ceil(H / tile), ceil(W / tile)] bool: the tiles of srgb [H, W, C] (P_f's grid, sRGB) where
    halving the width takes the most away (``thinning_loss`` averaged over the tile), most first, as
    many as cover ``share`` of the sphere's area (each tile weighs its centre row's cos latitude).
    share >= 1: every tile."""
    H, W = srgb.shape[:2]
    loss = thinning_loss(srgb, max(2, W // 2))
    loss = F.avg_pool2d(loss[None, None], tile, ceil_mode=True)[0, 0]  # [th, tw]
    th, tw = loss.shape
    if share >= 1:
        return torch.ones(th, tw, dtype=torch.bool)
    row = (torch.arange(th, dtype=torch.float64) + 0.5) * tile  # tile centre rows, pixels
    area = torch.cos(math.pi / 2 - row * (math.pi / H)).clamp_min(0)[:, None].expand(th, tw).reshape(-1)
    order = torch.argsort(loss.reshape(-1), descending=True, stable=True)
    covered = torch.cumsum(area[order], 0) / area.sum()
    pick = torch.zeros(th * tw, dtype=torch.bool)
    pick[order[covered <= share]] = True
    return pick.reshape(th, tw)
