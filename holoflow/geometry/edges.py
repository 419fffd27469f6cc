"""Depth edges made steps: the pixels of a ramp between a near and a far surface moved onto one side.

A depth estimator (and resampling) draws an occlusion edge as a ramp a few pixels wide: the pixels
between a door frame at 1.0 m and the wall at 1.6 m hold 1.04, 1.15, 1.35, 1.5 m. As points those
pixels are a curtain of discs strung between the two surfaces, which an eye 0.5 m off the centre
sees torn; and every step of the ramp larger than the layer's ``tol`` starts a background layer at
its own, intermediate depth (holoflow/geometry/layers.py), which the far surface's layer cannot pass.

``snap_depth_edges`` runs ``rounds`` times: around each pixel it takes the nearest (lo) and farthest
(hi) depth of the (2 ``radius`` + 1)^2 window (columns wrap, rows clamp); where hi > lo (1 +
``ratio``) the window holds an edge, and a pixel of it that lies more than ``tol`` (relative) from
both ends is moved to the end nearer in inverse depth (parallax: what an eye move sees), unless it
belongs to a surface of its own: a ramp pixel has few neighbours at its depth (a ramp's level is a
line along the edge), while a third surface between the two (the side of a window's recess between
the wall's edge and the sky) fills the window with pixels within ``tol`` / 4 of it, more than two
lines' worth (2 (2 ``radius`` + 1) + 1). Pixels within ``tol`` of an end, and everything away from
edges, keep their depth, so a smooth surface (whose window spans less than ``ratio``) is never
touched. A surface at incidence a spans about 2 ``radius`` tan(a) x the pixel angle: with radius 3
and ratio 0.25 on a 1536 px wide P_f, only one seen beyond 84 deg (2048 px: 85.6 deg) is stepped.

Conventions: radial depth in metres, finite > 0 (the sky already on its shell; holoflow/geometry/pointcloud.py).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def _padded(d: torch.Tensor, radius: int) -> torch.Tensor:
    """d [H, W] grown by ``radius`` px on every side, columns wrapping, rows clamped: [H + 2r, W + 2r]."""
    x = torch.cat([d[:, -radius:], d, d[:, :radius]], 1)[None, None]  # [1, 1, H, W + 2r]
    return F.pad(x, (0, 0, radius, radius), mode="replicate")[0, 0]


def _window_min_max(d: torch.Tensor, radius: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Min and max [H, W] of d [H, W] over (2 radius + 1)^2 windows, columns wrapping, rows clamped."""
    x = _padded(d, radius)[None, None]
    k = 2 * radius + 1
    return -F.max_pool2d(-x, k, 1)[0, 0], F.max_pool2d(x, k, 1)[0, 0]


def _level_support(d: torch.Tensor, radius: int, tol: float) -> torch.Tensor:
    """How many pixels [H, W] of each (2 radius + 1)^2 window of d [H, W] (columns wrapping, rows
    clamped) lie within ``tol`` (relative) of its centre pixel's depth, the centre included."""
    x = _padded(d, radius)  # [H + 2r, W + 2r]
    H, W = d.shape
    count = torch.zeros(H, W, dtype=torch.int32, device=d.device)
    for dy in range(2 * radius + 1):
        for dx in range(2 * radius + 1):
            count += (torch.abs(x[dy : dy + H, dx : dx + W] - d) <= tol * d).int()
    return count


def snap_depth_edges(
    radial_depth: torch.Tensor, radius: int = 3, ratio: float = 0.25, tol: float = 0.1, rounds: int = 2
) -> torch.Tensor:
    """The ramps of radial_depth [H, W] (metres, finite > 0) moved onto their near or far side (module
    docstring): [H, W], same dtype. radius (px): half window; ratio: far / near - 1 that makes a
    window an edge; tol: relative distance from an end within which a pixel stays; rounds: passes
    (0 or radius 0: unchanged)."""
    d = radial_depth
    if radius < 1:
        return d
    for _ in range(rounds):
        lo, hi = _window_min_max(d, radius)
        mid = (hi > lo * (1 + ratio)) & (d > lo * (1 + tol)) & (hi > d * (1 + tol))
        if bool(mid.any()):  # a surface of its own between the two ends stays
            mid &= _level_support(d, radius, tol / 4) <= 2 * (2 * radius + 1)
        to_near = (1 / lo - 1 / d) < (1 / d - 1 / hi)
        d = torch.where(mid, torch.where(to_near, lo, hi), d)
    return d
