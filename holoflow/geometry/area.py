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

Polar rows (``polar_from_deg`` < |lat|) may keep ``polar_density`` times as many points along the ring
(capped at the colour image's width): a photo's polar rows are W px round, so a view of the zenith or
nadir resolves tangential detail that one point per d x d loses. Those points' Gaussians are narrowed
along the ring by the same factor (ellipses: ``width`` x r d / density east-west, ``width`` x r d
north-south), so they still tile the ring without overlapping more.
"""
from __future__ import annotations

import math

import torch

from holoflow.geometry.sphere import lonlat_to_direction


def ring_density(lat: torch.Tensor, polar_density: float = 1.0, polar_from_deg: float = 90.0) -> torch.Tensor:
    """Points along the ring per area-sampling point, at latitudes lat [...] (radians): ``polar_density``
    where |lat| > ``polar_from_deg``, else 1 (module docstring)."""
    polar = lat.abs() > math.radians(polar_from_deg)
    return torch.where(polar, torch.full_like(lat, float(polar_density)), torch.ones_like(lat))


def area_counts(height: int, width: int, polar_density: float = 1.0, polar_from_deg: float = 90.0,
                max_count: int | None = None) -> torch.Tensor:
    """Points per row [H] (long) of an area sampling of an H x W equirect grid (module docstring), at
    most ``max_count`` (default W) a row."""
    lat = math.pi / 2 - (torch.arange(height, dtype=torch.float64) + 0.5) * (math.pi / height)
    n = torch.round(width * torch.cos(lat) * ring_density(lat, polar_density, polar_from_deg))
    return torch.clamp(n, 1, max_count or width).long()


def area_sample(rgb: torch.Tensor, radial_depth: torch.Tensor, polar_density: float = 1.0,
                polar_from_deg: float = 90.0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Area sampling of an equirect RGB-D image: rgb [H, Wc, C], radial_depth [H, W] (metres; Wc >= W:
    the colour may keep more columns than the depth) -> directions [N, 3] (unit, world), rgb [N, C] (box
    average over each point's longitude interval) and depth [N] (the pixel under the point; not filtered
    here), rows top to bottom, longitudes ascending from -pi. Rows keep ``area_counts(H, W,
    polar_density, polar_from_deg, Wc)`` points."""
    H, Wd = radial_depth.shape
    W = rgb.shape[1]
    if rgb.shape[0] != H or W < Wd:
        raise ValueError(f"area_sample: rgb {tuple(rgb.shape)} must have depth's {H} rows and >= {Wd} columns")
    counts = area_counts(H, Wd, polar_density, polar_from_deg, W).to(rgb.device)     # [H]
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
    depth = radial_depth[row, torch.clamp(torch.floor(centre * (Wd / W)).long(), 0, Wd - 1)]
    lon = centre * (2 * math.pi / W) - math.pi
    lat = math.pi / 2 - (row.to(torch.float64) + 0.5) * (math.pi / H)
    dirs = lonlat_to_direction(lon, lat).to(radial_depth.dtype)
    return dirs, colour, depth


def equirect_to_area_points(rgb: torch.Tensor, radial_depth: torch.Tensor, polar_density: float = 1.0,
                            polar_from_deg: float = 90.0) -> tuple[torch.Tensor, torch.Tensor]:
    """``equirect_to_points`` sampled by area: xyz [N, 3] (world, depth's dtype) and rgb [N, C] of the
    area samples with finite depth > 0 (module docstring; ``area_sample``'s arguments)."""
    dirs, colour, depth = area_sample(rgb, radial_depth, polar_density, polar_from_deg)
    valid = torch.isfinite(depth) & (depth > 0)
    return dirs[valid] * depth[valid][:, None], colour[valid]


def footprint_gaussians(xyz: torch.Tensor, spacing_rad: float, width: float = 0.6, thickness: float = 0.1,
                        polar_density: float = 1.0, polar_from_deg: float = 90.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Scales [N, 3] (metres) and quaternions [N, 4] (w, x, y, z) of Gaussians at points xyz [N, 3]
    sampled from the panorama centre (the origin) with angular spacing ``spacing_rad``: standard
    deviation ``width`` x r spacing along the tangent axes, ``thickness`` x r spacing along the ray
    (local z turned onto the ray). r is clamped away from 0. Points of the denser polar rows
    (``ring_density`` > 1) get ``width`` x r spacing / density along the ring (local x turned east)."""
    r = torch.linalg.vector_norm(xyz, dim=-1).clamp_min(1e-9)                   # [N]
    d = xyz / r[:, None]
    s = r * spacing_rad
    lat = torch.asin((-d[:, 1]).clamp(-1.0, 1.0))
    along = s / ring_density(lat, polar_density, polar_from_deg)                # [N] east-west
    scales = torch.stack([width * along, width * s, thickness * s], -1)
    # the shortest rotation taking +z to d: q = (1 + d_z, -d_y, d_x, 0), normalised; d = -z: 180 deg about x
    q = torch.stack([1 + d[:, 2], -d[:, 1], d[:, 0], torch.zeros_like(r)], -1)
    flip = (1 + d[:, 2]) < 1e-9
    q = torch.where(flip[:, None], q.new_tensor([0.0, 1.0, 0.0, 0.0]), q)
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    narrow = along < s
    if bool(narrow.any()):     # turn the disc about its normal so that local x points east
        q[narrow] = _turn_east(q[narrow], d[narrow])
    return scales, q


def _turn_east(q: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Quaternions q [M, 4] (taking local z to the rays d [M, 3]) composed with the turn about local z
    that takes local x onto east, the direction of growing longitude ((d_z, 0, -d_x), normalised)."""
    from holoflow.geometry.camera import quat_to_rotmat

    R = quat_to_rotmat(q)                                                       # [M, 3, 3]
    east = torch.stack([d[:, 2], torch.zeros_like(d[:, 0]), -d[:, 0]], -1)
    east = east / torch.linalg.vector_norm(east, dim=-1, keepdim=True).clamp_min(1e-12)
    psi = torch.atan2((east * R[:, :, 1]).sum(-1), (east * R[:, :, 0]).sum(-1))   # [M]
    c, s = torch.cos(psi / 2), torch.sin(psi / 2)
    w, x, y, z = q.unbind(-1)
    # q (x) (c, 0, 0, s): the Hamilton product with a turn about z
    return torch.stack([w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s], -1)


def view_width(size: int, fov_deg: float) -> int:
    """Equirect width (px) whose pixels are as fine as a ``size`` px view of ``fov_deg`` at its centre:
    360 x (view pixels per degree), e.g. 512 px at 47.43 deg -> 3886."""
    focal = 0.5 * size / math.tan(math.radians(fov_deg) / 2)
    return int(math.ceil(2 * math.pi * focal))
