"""Depth brought up to the colour's resolution, its edges put where the colour's are.

A depth network sees the panorama at a fraction of its size (the preview's depth is 1024 px across,
its P_f 1536). Read pixel by pixel from the coarse grid, every occlusion edge lands up to half a coarse
pixel off the colour's edge: a strip of the wall takes the chair's depth and a strip of the chair the
wall's, which from the centre is invisible and one step away is a fringe of the wrong colour around
every object, and a thin bar loses whatever the coarse grid did not catch.

``guided_depth_upsample`` is a joint bilateral upsampling (Kopf et al. 2007) that picks rather than
averages across an edge: each fine pixel looks at the 3 x 3 coarse pixels nearest it, weighs each by
its distance (Gaussian, ``sigma_px`` coarse pixels) and by how close the coarse pixel's colour (the
panorama shrunk to the coarse grid) is to its own (Gaussian in sRGB, ``sigma_rgb``); the best of them
is its surface. Its disparity is the mean over the candidates on that surface (within ``tol`` in relative
disparity of the best), each weighed by the same two Gaussians: a smooth surface is interpolated (within
the range of the coarse pixels around, the nearer and the more alike in colour the more), and a step
stays a step: no fine pixel takes a depth between two surfaces. Sky (inf) is a surface of its own and
stays inf.

Columns wrap at the seam; rows clamp at the poles. Shapes in comments; colours sRGB in [0, 1].
"""

from __future__ import annotations

import torch

from holoflow.geometry.sampling import resize_equirect


def guided_depth_upsample(
    radial_depth: torch.Tensor, guide: torch.Tensor, sigma_px: float = 0.75, sigma_rgb: float = 0.06, tol: float = 0.05
) -> torch.Tensor:
    """Radial depth [h, w] (metres; non-finite or <= 0 = sky) -> [H, W] (inf sky), the size of ``guide``
    [H, W, 3] (sRGB in [0, 1]), which must be at least as large along both axes. Module docstring for the
    rule."""
    h, w = radial_depth.shape
    H, W = guide.shape[:2]
    if H < h or W < w:
        raise ValueError(f"guided_depth_upsample: guide {H}x{W} is smaller than the depth {h}x{w}")
    dt = radial_depth.dtype
    guide = guide.to(dt)
    small = resize_equirect(guide.permute(2, 0, 1), h, w)  # [3, h, w]
    finite = torch.isfinite(radial_depth) & (radial_depth > 0)
    disp = torch.where(finite, 1.0 / torch.where(finite, radial_depth, torch.ones_like(radial_depth)), 0.0)  # [h, w]

    y = (torch.arange(H, device=guide.device, dtype=dt) + 0.5) * (h / H) - 0.5  # [H] coarse row coordinate
    x = (torch.arange(W, device=guide.device, dtype=dt) + 0.5) * (w / W) - 0.5  # [W]
    r0, c0 = torch.round(y).long(), torch.round(x).long()
    target = guide.permute(2, 0, 1)  # [3, H, W]
    offsets = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)]

    def at(dr: int, dc: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Rows [H] and columns [W] of the coarse pixel (dr, dc) from each fine pixel's nearest."""
        return (r0 + dr).clamp(0, h - 1), torch.remainder(c0 + dc, w)

    scores = []  # the nine candidates' scores [H, W], kept for the weights; the best is the first lowest
    for k, (dr, dc) in enumerate(offsets):
        rows, cols = at(dr, dc)
        dy2 = (y - rows.to(dt)) ** 2  # [H]
        dx2 = (x - (c0 + dc).to(dt)) ** 2  # [W]
        diff2 = ((small[:, rows][:, :, cols] - target) ** 2).sum(0)  # [H, W]
        score = (dy2[:, None] + dx2[None, :]) / (2 * sigma_px**2) + diff2 / (2 * sigma_rgb**2)
        d, sky = disp[rows][:, cols], ~finite[rows][:, cols]  # [H, W]
        scores.append(score)
        if k == 0:
            s_best, d_best, sky_best = score, d, sky
        else:
            better = score < s_best
            s_best = torch.where(better, score, s_best)
            d_best = torch.where(better, d, d_best)
            sky_best = torch.where(better, sky, sky_best)
    num = torch.zeros_like(s_best)  # [H, W] weighted disparity over the best's surface
    den = torch.zeros_like(s_best)
    for (dr, dc), score in zip(offsets, scores):
        rows, cols = at(dr, dc)
        d, sky = disp[rows][:, cols], ~finite[rows][:, cols]  # [H, W]
        same = torch.where(sky_best, sky, ~sky & ((d - d_best).abs() <= tol * d_best))
        weight = torch.exp(s_best - score) * same  # the best's weight is 1
        num += weight * d
        den += weight
    mean = num / den  # [H, W] disparity; the sky's is 0
    return 1.0 / mean  # the sky's is inf
