"""Sampling a panorama by area, and Gaussians sized by their pixel's footprint (issue 31).

An equirect row at latitude lat covers a ring of circumference 2 pi cos(lat): one point per pixel
crowds the poles with W points on rings a few pixels round, which look like thin concentric rings of
Gaussians when seen straight on. Here row i of an H x W panorama (H = W / 2, pixel angle
d = pi / H) keeps n_i = max(1, round(W cos lat_i)) points, evenly spaced in longitude from -pi, so
every point stands for about d x d of the sphere (radians, at unit distance). Colour is the exact
box average of the row over the point's longitude interval (antialiased: a polar point averages the
many pixels it replaces); depth is point-sampled (the pixel under the sample's centre), so no depth
is invented across an edge. The total is about W H 2 / pi points, 64 % of the grid.

A point at radial distance r then covers a patch r d wide facing the centre: its Gaussian gets
standard deviation ``width`` x r d along the two tangent axes and ``thickness`` x r d along the ray
(flattened: a disc facing the panorama centre), so neighbours cover each other at any view size.
"""
from __future__ import annotations

import math

import torch

from holoflow.geometry.sphere import lonlat_to_direction


def area_counts(height: int, width: int) -> torch.Tensor:
    """Points per row [H] (long) of an area sampling of an H x W equirect grid (module docstring)."""
    lat = math.pi / 2 - (torch.arange(height, dtype=torch.float64) + 0.5) * (math.pi / height)
    return torch.clamp(torch.round(width * torch.cos(lat)), min=1).long()


def area_sample(rgb: torch.Tensor, radial_depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Area sampling of an equirect RGB-D image: rgb [H, W, C], radial_depth [H, W] (metres) ->
    directions [N, 3] (unit, world), rgb [N, C] (box average over each point's longitude interval)
    and depth [N] (the pixel under the point; not filtered here), rows top to bottom, longitudes
    ascending from -pi."""
    H, W = radial_depth.shape
    counts = area_counts(H, W).to(rgb.device)                                   # [H]
    row = torch.repeat_interleave(torch.arange(H, device=rgb.device), counts)   # [N]
    first = torch.cumsum(counts, 0) - counts
    j = torch.arange(int(counts.sum()), device=rgb.device) - first[row]         # index within the row
    n = counts[row].to(torch.float64)
    u0, u1 = j * (W / n), (j + 1) * (W / n)                                     # [N] interval, pixels
    prefix = torch.cat([torch.zeros_like(rgb[:, :1]), torch.cumsum(rgb.to(torch.float64), 1)], 1)  # [H, W + 1, C]

    def integral(u: torch.Tensor) -> torch.Tensor:                              # sum of the row over [0, u)
        k = torch.clamp(torch.floor(u).long(), 0, W - 1)
        return prefix[row, k] + (u - k)[:, None] * rgb[row, k].to(torch.float64)

    colour = ((integral(u1) - integral(u0)) / (u1 - u0)[:, None]).to(rgb.dtype)  # [N, C]
    centre = 0.5 * (u0 + u1)
    depth = radial_depth[row, torch.clamp(torch.floor(centre).long(), 0, W - 1)]
    lon = centre * (2 * math.pi / W) - math.pi
    lat = math.pi / 2 - (row.to(torch.float64) + 0.5) * (math.pi / H)
    dirs = lonlat_to_direction(lon, lat).to(radial_depth.dtype)
    return dirs, colour, depth


def equirect_to_area_points(rgb: torch.Tensor, radial_depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``equirect_to_points`` sampled by area: xyz [N, 3] (world, depth's dtype) and rgb [N, C] of the
    area samples with finite depth > 0 (module docstring)."""
    dirs, colour, depth = area_sample(rgb, radial_depth)
    valid = torch.isfinite(depth) & (depth > 0)
    return dirs[valid] * depth[valid][:, None], colour[valid]


def footprint_gaussians(xyz: torch.Tensor, spacing_rad: float, width: float = 0.6, thickness: float = 0.1
                        ) -> tuple[torch.Tensor, torch.Tensor]:
    """Scales [N, 3] (metres) and quaternions [N, 4] (w, x, y, z) of Gaussians at points xyz [N, 3]
    sampled from the panorama centre (the origin) with angular spacing ``spacing_rad``: standard
    deviation ``width`` x r spacing along the tangent axes, ``thickness`` x r spacing along the ray
    (local z turned onto the ray). r is clamped away from 0."""
    r = torch.linalg.vector_norm(xyz, dim=-1).clamp_min(1e-9)                   # [N]
    d = xyz / r[:, None]
    s = r * spacing_rad
    scales = torch.stack([width * s, width * s, thickness * s], -1)
    # the shortest rotation taking +z to d: q = (1 + d_z, -d_y, d_x, 0), normalised; d = -z: 180 deg about x
    q = torch.stack([1 + d[:, 2], -d[:, 1], d[:, 0], torch.zeros_like(r)], -1)
    flip = (1 + d[:, 2]) < 1e-9
    q = torch.where(flip[:, None], q.new_tensor([0.0, 1.0, 0.0, 0.0]), q)
    return scales, q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)


def view_width(size: int, fov_deg: float) -> int:
    """Equirect width (px) whose pixels are as fine as a ``size`` px view of ``fov_deg`` at its centre:
    360 x (view pixels per degree), e.g. 512 px at 47.43 deg -> 3886."""
    focal = 0.5 * size / math.tan(math.radians(fov_deg) / 2)
    return int(math.ceil(2 * math.pi * focal))
