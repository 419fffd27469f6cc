"""Equirectangular pixel <-> longitude/latitude <-> unit direction (docs/conventions.md).

Pixel coordinates (u, v) are continuous: pixel (col, row) has its centre at (col + 0.5, row + 0.5).
lon = 2*pi*u/W - pi in [-pi, pi), lat = pi/2 - pi*v/H in [-pi/2, pi/2]; direction =
(cos lat sin lon, -sin lat, cos lat cos lon) in the world frame (+x right, +y down, +z forward), so the
image centre looks along +z and the top row looks up (-y). Angles are radians.
"""

from __future__ import annotations

import math

import torch


def equirect_pixel_to_lonlat(
    u: torch.Tensor, v: torch.Tensor, width: int, height: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Continuous equirect pixel coords (u, v) [...] -> (lon, lat) [...] in radians."""
    lon = u * (2.0 * math.pi / width) - math.pi
    lat = math.pi / 2.0 - v * (math.pi / height)
    return lon, lat


def lonlat_to_equirect_pixel(
    lon: torch.Tensor, lat: torch.Tensor, width: int, height: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """(lon, lat) [...] radians -> continuous equirect pixel coords (u, v) [...]; u wrapped into [0, W)."""
    u = torch.remainder((lon + math.pi) * (width / (2.0 * math.pi)), float(width))
    u = torch.where(u >= width, torch.zeros_like(u), u)  # remainder may round up to W
    v = (math.pi / 2.0 - lat) * (height / math.pi)
    return u, v


def lonlat_to_direction(lon: torch.Tensor, lat: torch.Tensor) -> torch.Tensor:
    """(lon, lat) [...] radians -> unit directions [..., 3] (world frame)."""
    c = torch.cos(lat)
    return torch.stack([c * torch.sin(lon), -torch.sin(lat), c * torch.cos(lon)], dim=-1)


def direction_to_lonlat(dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Directions [..., 3] (any non-zero length) -> (lon in [-pi, pi], lat in [-pi/2, pi/2]) [...].

    At the poles lon is whatever atan2 gives for x = z = 0 (0 or pi); the direction is still exact."""
    x, y, z = dirs.unbind(-1)
    lon = torch.atan2(x, z)
    lat = torch.atan2(-y, torch.hypot(x, z))
    return lon, lat


def equirect_directions(height: int, width: int, device=None, dtype=None) -> torch.Tensor:
    """Unit world directions [H, W, 3] of the equirect pixel centres."""
    dtype = dtype or torch.get_default_dtype()
    u = torch.arange(width, device=device, dtype=dtype) + 0.5  # [W]
    v = torch.arange(height, device=device, dtype=dtype) + 0.5  # [H]
    lon, lat = equirect_pixel_to_lonlat(u, v, width, height)
    return lonlat_to_direction(lon[None, :].expand(height, width), lat[:, None].expand(height, width))
