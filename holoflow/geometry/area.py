"""Sampling a panorama by area, and Gaussians sized by their pixel's footprint.

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
(flattened: a disc facing the panorama centre), so neighbours cover each other at any view size. With
the surface's normal (holoflow/geometry/surfaces.py) the disc lies on the surface instead: the same
footprint, projected along the ray onto it (``surface_footprint``), so neighbours also cover each other
seen from an eye off the centre.

**Polar caps** (``PolarCaps``). A photo's rows near a pole are still W px round and its rows finer
than P_f's, so a view of the zenith or nadir resolves detail that one point per d x d loses. Beyond a latitude (P_f
keeps its
rows up to ``from_deg``; the caps start at the first row of their grid that reaches past P_f's last
row's edge, so the two touch) the caps are sampled from the panorama on a grid ``density`` times finer
than P_f's (rows at most twice the panorama's own) with ``density`` times P_f's points along each ring
(at most the grid's width); their Gaussians are ellipses sized by that finer spacing across and along
the ring (local x turned east). The caps' depth is read from P_f's depth grid (its edge and gradient
filters apply). Why rows finer than the panorama's: nearly opaque discs composite front to back, so
the Gaussians render a piecewise-constant image, not the linear interpolation between the panorama's
rows that its own views show; rows of the panorama upsampled bilinearly carry that interpolation in
their samples (docs/reconstruction.md has the measurements).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from holoflow.geometry.camera import quat_to_rotmat, rotmat_to_quat
from holoflow.geometry.sampling import resize_equirect
from holoflow.geometry.sphere import lonlat_to_direction


@dataclass(frozen=True)
class PolarCaps:
    """How P_f's polar caps are sampled (module docstring): the rows of a grid ``width`` px wide
    (``width // 2`` rows) beyond ``split_deg`` of latitude, ``ring_points`` x cos(lat) points a ring
    (at most ``width``); P_f keeps its rows within ``split_deg``. ``split_deg`` lies between P_f's
    last row and the caps' first, which touch (no wider gap than either grid's spacing)."""

    split_deg: float
    width: int
    ring_points: float
    north: bool = True
    south: bool = True

    @property
    def row_rad(self) -> float:
        """Angle between two cap rows (radians)."""
        return 2.0 * math.pi / self.width

    def ring_rad(self, lat: torch.Tensor) -> torch.Tensor:
        """Angle between two neighbours along the ring at latitudes lat [...] (radians of arc)."""
        n = torch.clamp(self.ring_points * torch.cos(lat), min=1.0, max=float(self.width))
        return 2.0 * math.pi * torch.cos(lat) / n

    def to_json(self) -> dict:
        return {
            "split_deg": self.split_deg,
            "width": self.width,
            "ring_points": self.ring_points,
            "north": self.north,
            "south": self.south,
        }

    def holds(self, lat: torch.Tensor) -> torch.Tensor:
        """[...] bool: latitudes lat [...] (radians) inside a cap that is on."""
        edge = math.radians(self.split_deg)
        return ((lat > edge) & self.north) | ((lat < -edge) & self.south)


def polar_caps(
    pf_width: int, pano_width: int, density: float, from_deg: float, upsample: float = 2.0
) -> PolarCaps | None:
    """P_f's caps for a ``pf_width`` px P_f of a ``pano_width`` px panorama at ``density`` (1 or
    from_deg >= 90: none): P_f keeps its rows up to ``from_deg``, the caps take over from the first row
    of a grid min(upsample x pano_width, density x pf_width) px wide that reaches past P_f's last
    row's edge, with density x pf_width points a ring at the equator's scale."""
    if density <= 1.0 or from_deg >= 90.0:
        return None
    width = max(pf_width, min(int(upsample * pano_width), int(math.ceil(density * pf_width))))
    width -= width % 2
    lat = row_latitudes(pf_width // 2).abs()
    last = float(lat[lat <= math.radians(from_deg)].max())  # P_f's last row centre
    step, cap_step = math.pi / (pf_width // 2), math.pi / (width // 2)
    cap = row_latitudes(width // 2).abs()
    first = float(cap[cap > last + step / 2 - cap_step / 2].min())  # the caps' first row centre
    return PolarCaps(math.degrees(0.5 * (last + first)), width, float(density * pf_width))


def called_for(caps: PolarCaps, cap_rgb: torch.Tensor, pf_width: int, ratio: float) -> tuple[PolarCaps | None, dict]:
    """The caps a panorama calls for: a cap stays on when what thinning its rows to P_f's points takes
    away (``ring_detail``, area-weighted mean over the cap's rows of the caps' grid cap_rgb [h, w, C])
    exceeds ``ratio`` x the same over the rows between the caps (every 4th; ``ratio`` 0: always on). A smooth
    ceiling or sky keeps P_f's sampling. Returns (caps with their flags, None when both are off;
    {"north", "south", "sides"}: the three means)."""
    lat = row_latitudes(cap_rgb.shape[0])
    edge = math.radians(caps.split_deg)
    pick = (lat.abs() > edge) | (torch.arange(len(lat)) % 4 == 0)  # the caps' rows, every 4th between
    lat = lat[pick]
    loss = ring_detail(cap_rgb[pick], torch.clamp(torch.round(pf_width * torch.cos(lat)), 1, cap_rgb.shape[1]))
    weight = torch.cos(lat)

    def mean(rows: torch.Tensor) -> float:
        return float((loss[rows] * weight[rows]).sum() / weight[rows].sum())

    detail = {"north": mean(lat > edge), "south": mean(lat < -edge), "sides": mean(lat.abs() <= edge)}
    north, south = (ratio == 0 or detail[k] > ratio * detail["sides"] for k in ("north", "south"))
    caps = PolarCaps(caps.split_deg, caps.width, caps.ring_points, north, south)
    return (caps if north or south else None), detail


def ring_detail(rgb: torch.Tensor, counts: torch.Tensor) -> torch.Tensor:
    """[H] float64: mean square (over the row's pixels and channels) of what area sampling takes away
    from each row of rgb [H, W, C]: the row thinned to counts [H] points (``ring_boxes``) and
    interpolated back linearly along the ring, against the row itself."""
    H, W, _ = rgb.shape
    n = counts.long().to(rgb.device)  # [H]
    _, _, points = ring_boxes(rgb.to(torch.float64), n)  # [N, C]
    first = torch.cumsum(n, 0) - n
    t = (torch.arange(W, dtype=torch.float64, device=rgb.device) + 0.5) * (n[:, None] / W) - 0.5  # [H, W]
    k0 = torch.floor(t).long()
    f = (t - k0)[..., None]
    a = points[first[:, None] + torch.remainder(k0, n[:, None])]
    b = points[first[:, None] + torch.remainder(k0 + 1, n[:, None])]
    return ((a + (b - a) * f - rgb.to(torch.float64)) ** 2).mean((1, 2))


def ring_boxes(rgb: torch.Tensor, counts: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Each row of rgb [H, W, C] cut into counts [H] equal longitude intervals from -pi: the row of each
    interval [N], its centre [N] (pixels, float64) and the exact box average of the row over it [N, C]
    (rgb's dtype; the row taken as constant over each pixel), rows top to bottom."""
    H, W = rgb.shape[:2]
    row = torch.repeat_interleave(torch.arange(H, device=rgb.device), counts)  # [N]
    first = torch.cumsum(counts, 0) - counts
    j = torch.arange(int(counts.sum()), device=rgb.device) - first[row]  # index within the row
    n = counts[row].to(torch.float64)
    u0, u1 = j * (W / n), (j + 1) * (W / n)  # [N] interval, pixels
    prefix = torch.cat([torch.zeros_like(rgb[:, :1]), torch.cumsum(rgb.to(torch.float64), 1)], 1)  # [H, W + 1, C]

    def integral(u: torch.Tensor) -> torch.Tensor:  # row sum over [0, u)
        k = torch.clamp(torch.floor(u).long(), 0, W - 1)
        return prefix[row, k] + (u - k)[:, None] * rgb[row, k].to(torch.float64)

    colour = ((integral(u1) - integral(u0)) / (u1 - u0)[:, None]).to(rgb.dtype)  # [N, C]
    return row, 0.5 * (u0 + u1), colour


def row_latitudes(height: int) -> torch.Tensor:
    """[H] latitude (radians, float64) of each row centre of an equirect grid H rows high."""
    return math.pi / 2 - (torch.arange(height, dtype=torch.float64) + 0.5) * (math.pi / height)


def area_counts(height: int, width: int) -> torch.Tensor:
    """Points per row [H] (long) of an area sampling of an H x W equirect grid (module docstring)."""
    return torch.clamp(torch.round(width * torch.cos(row_latitudes(height))), min=1).long()


def area_sample(
    rgb: torch.Tensor,
    radial_depth: torch.Tensor,
    counts: torch.Tensor | None = None,
    rows: torch.Tensor | None = None,
    tiles: torch.Tensor | None = None,
    tile_px: int = 8,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Area sampling of an equirect RGB-D image: rgb [H, W, C], radial_depth [Hd, Wd] (metres, any
    size; usually H x W) -> directions [N, 3] (unit, world), rgb [N, C] (box average over each point's
    longitude interval), depth [N] (the depth pixel under the point's centre; not filtered here) and
    that pixel [N] (long, row-major index into radial_depth: what else is known per depth pixel, e.g.
    its normal, is read there), rows top to bottom, longitudes ascending from -pi. ``counts`` [H]:
    points per row (default ``area_counts``); ``rows`` [H] bool: the rows to sample (default all);
    ``tiles`` [th, tw] bool: tiles of ``tile_px`` x ``tile_px`` depth pixels; only the points whose
    longitude interval reaches into a True tile of their row are kept (and those wider than a tile),
    so that two samplings kept on complementary tiles leave no gap between them."""
    H, W = rgb.shape[:2]
    Hd, Wd = radial_depth.shape
    counts = (area_counts(H, W) if counts is None else counts).to(rgb.device)  # [H]
    if rows is not None:
        counts = torch.where(rows.to(rgb.device), counts, torch.zeros_like(counts))
    row, centre, colour = ring_boxes(rgb, counts)  # [N], [N], [N, C]
    if tiles is not None:
        half = 0.5 * W / counts[row].to(torch.float64)  # [N] half the point's interval, pixels
        ty = (torch.floor((row + 0.5) * (Hd / H)).long() // tile_px).clamp(0, tiles.shape[0] - 1)
        to_tile = Wd / (W * tile_px)  # pixels of rgb -> tile columns

        def tile_at(u: torch.Tensor) -> torch.Tensor:
            return tiles[ty, torch.remainder(torch.floor(u * to_tile).long(), tiles.shape[1])]

        wide = 2 * half * (Wd / W) >= tile_px
        keep = tile_at(centre - half) | tile_at(centre + half - 1e-6) | wide
        row, centre, colour = row[keep], centre[keep], colour[keep]
    lat = row_latitudes(H).to(rgb.device)[row]
    drow = row if Hd == H else torch.floor((row + 0.5) * (Hd / H)).long()
    dcol = torch.floor(centre if Wd == W else centre * (Wd / W)).long()
    pixel = drow.clamp(0, Hd - 1) * Wd + dcol.clamp(0, Wd - 1)
    depth = radial_depth.reshape(-1)[pixel]
    dirs = lonlat_to_direction(centre * (2 * math.pi / W) - math.pi, lat).to(radial_depth.dtype)
    return dirs, colour, depth, pixel


def equirect_to_area_points(
    rgb: torch.Tensor,
    radial_depth: torch.Tensor,
    caps: PolarCaps | None = None,
    cap_rgb: torch.Tensor | None = None,
    detail: torch.Tensor | None = None,
    tile_px: int = 8,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, int]:
    """``equirect_to_points`` sampled by area: xyz [N, 3] (world, depth's dtype), rgb [N, C] and the
    depth pixel [N] (row-major index into radial_depth) of the area samples with finite depth > 0
    (module docstring), and how many of them (the last) were sampled at half width. rgb [H, W, C] and
    radial_depth [H, W] are P_f's grid; with ``caps``, the rows beyond caps.split_deg come from cap_rgb
    [caps.width // 2, caps.width, C] instead (depth still from radial_depth). With ``detail`` [th, tw]
    bool (tiles of ``tile_px`` px of P_f's grid, holoflow/geometry/detail.py), P_f's rows are sampled
    at full width only in the detail tiles and at half width (rgb resized, antialiased) in the others,
    those points last. Points run from the north pole south (each sampling's)."""
    H, W = rgb.shape[:2]
    lat = row_latitudes(H)
    inside = None if caps is None else ~caps.holds(lat)
    parts = [area_sample(rgb, radial_depth, rows=inside, tiles=detail, tile_px=tile_px)]
    if caps is not None:
        if cap_rgb is None or tuple(cap_rgb.shape[:2]) != (caps.width // 2, caps.width):
            raise ValueError(f"equirect_to_area_points: cap_rgb must be {caps.width // 2} x {caps.width}")
        cap_lat = row_latitudes(cap_rgb.shape[0])
        ring = torch.clamp(torch.round(caps.ring_points * torch.cos(cap_lat)), 1, caps.width).long()
        cap_rows = caps.holds(cap_lat)
        parts = [
            area_sample(cap_rgb, radial_depth, ring, cap_rows & (cap_lat > 0)),
            parts[0],
            area_sample(cap_rgb, radial_depth, ring, cap_rows & (cap_lat < 0)),
        ]
    coarse = 0
    if detail is not None:  # the other tiles at half width; rows reaching out of a cap belong to P_f
        half = resize_equirect(rgb.permute(2, 0, 1), H // 2, W // 2).permute(1, 2, 0)
        hlat = row_latitudes(H // 2)
        rows = None if caps is None else ~caps.holds(hlat - torch.sign(hlat) * (math.pi / (H // 2)) / 2)
        parts.append(area_sample(half, radial_depth, rows=rows, tiles=~detail, tile_px=tile_px))
        coarse = len(parts[-1][0])
    dirs, colour, depth, pixel = (torch.cat(x) for x in zip(*parts))
    valid = torch.isfinite(depth) & (depth > 0)
    coarse = int(valid[len(valid) - coarse :].sum()) if coarse else 0
    return dirs[valid] * depth[valid][:, None], colour[valid], pixel[valid], coarse


def footprint_gaussians(
    xyz: torch.Tensor,
    spacing_rad: float,
    width: float = 0.6,
    thickness: float = 0.1,
    caps: PolarCaps | None = None,
    layer_points: int = 0,
    layer_spacing_rad: float | torch.Tensor = 0.0,
    low_pass_rad2: float = 0.0,
    normals: torch.Tensor | None = None,
    max_stretch: float = 6.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Scales [N, 3] (metres) and quaternions [N, 4] (w, x, y, z) of Gaussians at points xyz [N, 3]
    sampled from the panorama centre (the origin) with angular spacing ``spacing_rad``: standard
    deviation ``width`` x r spacing along the tangent axes, ``thickness`` x r spacing along the ray
    (local z turned onto the ray). r is clamped away from 0. Points in the ``caps`` use the caps'
    spacings instead: caps.ring_rad along the ring (local x turned east), caps.row_rad across it; the
    last ``layer_points`` points (P_f's background layer and sky dome, sparser grids) ``layer_spacing_rad``
    (one value, or one per such point [layer_points]).

    ``low_pass_rad2``: the variance the rasterizer adds to every disc at the viewing size (its 0.3 px^2
    times a view pixel's angle squared, radians^2 at unit distance). It is taken off each tangent
    variance, so that ``width`` is the standard deviation a disc is *rendered* with at that size
    whatever its spacing in pixels: finer grids (the polar caps, a P_f as fine as the view) would
    otherwise render relatively wider, their neighbours overlapping more, and the front disc's colour
    would spread further (docs/reconstruction.md). Never below half of ``width`` x spacing.

    ``normals`` [N, 3] (unit, world; holoflow/geometry/surfaces.py): the discs lie on their surface
    instead of facing the centre: the footprint seen from the centre is projected along the ray onto
    the plane of the normal (``surface_footprint``), so a surface seen at incidence a gets discs
    1 / cos(a) longer down its slope (at most ``max_stretch``) and neighbours overlap from any eye."""
    r = torch.linalg.vector_norm(xyz, dim=-1).clamp_min(1e-9)  # [N]
    d = xyz / r[:, None]
    layer = torch.arange(len(r), device=r.device) >= len(r) - layer_points
    tail = torch.as_tensor(layer_spacing_rad, dtype=r.dtype, device=r.device).expand(layer_points)
    across = torch.cat([torch.full((len(r) - layer_points,), spacing_rad, dtype=r.dtype, device=r.device), tail])
    along = across
    in_cap = torch.zeros_like(layer)
    if caps is not None:
        lat = torch.asin((-d[:, 1]).clamp(-1.0, 1.0))
        in_cap = caps.holds(lat) & ~layer
        across = torch.where(in_cap, caps.row_rad, across)
        along = torch.where(in_cap, caps.ring_rad(lat).to(r.dtype), across)

    def tangent(spacing: torch.Tensor) -> torch.Tensor:  # [N] std at unit distance
        nominal = (width * spacing) ** 2
        return torch.sqrt(torch.clamp(nominal - low_pass_rad2, min=0.25 * nominal))

    if normals is not None:
        return surface_footprint(
            d, normals.to(d), r * tangent(along), r * tangent(across), thickness * r * across, max_stretch
        )
    scales = torch.stack([r * tangent(along), r * tangent(across), thickness * r * across], -1)
    # the shortest rotation taking +z to d: q = (1 + d_z, -d_y, d_x, 0), normalised; d = -z: 180 deg about x
    q = torch.stack([1 + d[:, 2], -d[:, 1], d[:, 0], torch.zeros_like(r)], -1)
    flip = (1 + d[:, 2]) < 1e-9
    q = torch.where(flip[:, None], q.new_tensor([0.0, 1.0, 0.0, 0.0]), q)
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    if bool(in_cap.any()):  # turn the ellipse about its normal so that local x points east
        q[in_cap] = _turn_east(q[in_cap], d[in_cap])
    return scales, q


def surface_footprint(
    rays: torch.Tensor,
    normals: torch.Tensor,
    east_std: torch.Tensor,
    north_std: torch.Tensor,
    thickness: torch.Tensor,
    max_stretch: float = 6.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Scales [N, 3] and quaternions [N, 4] (w, x, y, z) of discs lying on their surface: the footprint
    seen along rays [N, 3] (unit) as an ellipse across the ray, standard deviations east_std [N] (along
    growing longitude) and north_std [N] (metres), projected along the ray onto the plane of normals
    [N, 3] (unit): the in-plane axis across the slope keeps its length, the one down the slope (the
    ray's own projection) grows by 1 / |cos(incidence)|, at most ``max_stretch``. thickness [N]
    (metres) is the standard deviation along the normal (local z)."""
    east = torch.stack([rays[:, 2], torch.zeros_like(rays[:, 0]), -rays[:, 0]], -1)
    polar = torch.linalg.vector_norm(east, dim=-1, keepdim=True) < 1e-9  # straight up / down
    east = torch.where(polar, east.new_tensor([1.0, 0.0, 0.0]), east)
    east = east / torch.linalg.vector_norm(east, dim=-1, keepdim=True)
    north = torch.cross(rays, east, dim=-1)  # [N, 3], unit
    normals = normals / torch.linalg.vector_norm(normals, dim=-1, keepdim=True)
    cos = (normals * rays).sum(-1, keepdim=True)  # [N, 1]
    facing = cos.abs() > 1 - 1e-9  # no slope to speak of
    slope = torch.where(facing, east, rays)
    slope = slope - normals * (normals * slope).sum(-1, keepdim=True)  # the ray on the plane
    slope = slope / torch.linalg.vector_norm(slope, dim=-1, keepdim=True).clamp_min(1e-30)
    across = torch.cross(normals, slope, dim=-1)  # in the plane and across the ray
    down = torch.cross(rays, across, dim=-1)  # across the ray, onto `slope`
    stretch = 1.0 / cos.abs().clamp_min(1.0 / max_stretch)  # [N, 1]

    def onto_plane(v: torch.Tensor) -> torch.Tensor:  # [N, 3] -> [N, 2] in (across, slope)
        return torch.cat([(v * across).sum(-1, keepdim=True), (v * down).sum(-1, keepdim=True) * stretch], -1)

    A, B = onto_plane(east) * east_std[:, None], onto_plane(north) * north_std[:, None]  # [N, 2]
    c00 = A[:, 0] ** 2 + B[:, 0] ** 2  # the 2x2 covariance
    c01 = A[:, 0] * A[:, 1] + B[:, 0] * B[:, 1]
    c11 = A[:, 1] ** 2 + B[:, 1] ** 2
    phi = 0.5 * torch.atan2(2 * c01, c00 - c11)
    half, mean = torch.sqrt((0.5 * (c00 - c11)) ** 2 + c01**2), 0.5 * (c00 + c11)
    e1 = torch.cos(phi)[:, None] * across + torch.sin(phi)[:, None] * slope
    R = torch.stack([e1, torch.cross(normals, e1, dim=-1), normals], -1)  # columns: local x, y, z
    scales = torch.stack([torch.sqrt(mean + half), torch.sqrt((mean - half).clamp_min(0) + 1e-30), thickness], -1)
    return scales, rotmat_to_quat(R)


def _turn_east(q: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Quaternions q [M, 4] (taking local z to the rays d [M, 3]) composed with the turn about local z
    that takes local x onto east, the direction of growing longitude ((d_z, 0, -d_x), normalised)."""
    R = quat_to_rotmat(q)  # [M, 3, 3]
    east = torch.stack([d[:, 2], torch.zeros_like(d[:, 0]), -d[:, 0]], -1)
    east = east / torch.linalg.vector_norm(east, dim=-1, keepdim=True).clamp_min(1e-12)
    psi = torch.atan2((east * R[:, :, 1]).sum(-1), (east * R[:, :, 0]).sum(-1))  # [M]
    c, s = torch.cos(psi / 2), torch.sin(psi / 2)
    w, x, y, z = q.unbind(-1)
    # q (x) (c, 0, 0, s): the Hamilton product with a turn about local z
    return torch.stack([w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s], -1)


def view_pixel_rad(size: int, fov_deg: float) -> float:
    """Angle (radians) of the centre pixel of a ``size`` px view of horizontal field ``fov_deg``: 1 / focal."""
    return 2.0 * math.tan(math.radians(fov_deg) / 2) / size


def view_width(size: int, fov_deg: float) -> int:
    """Equirect width (px) whose pixels are as fine as a ``size`` px view of ``fov_deg`` at its centre:
    360 x (view pixels per degree), e.g. 512 px at 47.43 deg -> 3886."""
    return int(math.ceil(2 * math.pi / view_pixel_rad(size, fov_deg)))
