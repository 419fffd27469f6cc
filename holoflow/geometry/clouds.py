"""HoloDreamer's three point clouds from an equirect RGB-D panorama: P0, P_f and P_s.

P0 at ``p0_width`` (paper: the depth resolution); P_s at ``ps_width`` (the cloud the PCD set is
projected from); P_f, the cloud the Gaussians start from, at ``pf_width`` (0 = as fine as a
``view_size`` view resolves, capped at the panorama's width and ``pf_max_width``; up to
``pf_detail_width`` when the panorama holds detail that width loses: ``pf_detail_psnr``), built in this
order on its equirect grid:

1. (every cloud) window bars the depth lost to the sky put back in their window's plane
   (``opening_bars``, holoflow/geometry/openings.py), then sky (inf depth) on a far shell of radius
   ``sky_radius`` (0 = 2 x the 99th percentile of finite depth), so the scene stays enclosed
   (holoflow/geometry/pointcloud.py); P_f's shell in the colour of the sky inside its openings
   (``clean_sky``);
2. occlusion edges that the depth draws as ramps made steps (holoflow/geometry/edges.py);
3. per-pixel depth noise smoothed within each surface, never across an edge, and each pixel's surface
   normal (holoflow/geometry/surfaces.py): the Gaussians lie on their surfaces;
4. points whose relative depth gradient exceeds ``grad_threshold`` dropped (the paper's filter, 0.4),
   one-sided by default (``grad_sides``): with the ramps made steps, each side of an edge keeps its own
   pixels, so a thin near object (a window bar, a lamp's stem) keeps its points;
5. the background layer: the far surface and the sky shell continued under every silhouette, as wide
   as an eye move of ``layer_baseline`` metres uncovers (holoflow/geometry/layers.py): each
   silhouette's own far side, and where a farther surface reaches under it, that one too; where the
   panorama shows sky, a sky dome behind everything (``sky_dome``): one coarse point per direction that
   is not sky but within ``sky_dome_reach_deg`` of it, just beyond the shell, coloured by the sky
   around it (``clean_sky``: the sky inside the openings, never the rim a frame mixes in), so that an
   eye off the centre looking out of a window past its frame sees sky, never the void; with the dome
   the layer leaves the sky shell out (the dome covers those directions; the layer's sky, streaked
   outwards from the opening's edge, only drew a second, streaked sky in front of it); before the dome,
   the side of a window's recess and the frame that the wall's edge hides from the centre
   (``opening_reveals``, holoflow/geometry/openings.py), so that such an eye sees them, not the sky;
6. sampled by area (``pf_sampling``; polar caps sampled finer where the panorama's poles hold detail:
   holoflow/geometry/area.py); at ``pf_detail_width``, at that width only in the tiles holding the
   most detail (``pf_detail_share`` of the sphere) and at half of it in the others, whose points
   follow P_f's own (holoflow/geometry/detail.py).

Colour is resampled antialiased; depth is point-sampled when shrunk and, when the cloud is wider than
the depth (``depth_upsample``), enlarged guided by the colour (holoflow/geometry/upsample.py): either way
no depth is invented between two surfaces. Colours returned are
8-bit sRGB (the PLY convention, docs/conventions.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from holoflow.geometry.area import called_for, equirect_to_area_points, polar_caps, view_pixel_rad, view_width
from holoflow.geometry.config import PointCloudParams
from holoflow.geometry.detail import DETAIL_TILE_PX, detail_tiles, thinning_psnr
from holoflow.geometry.edges import snap_depth_edges
from holoflow.geometry.layers import background_layer
from holoflow.geometry.openings import keep_opening_bars, opening_reveals
from holoflow.geometry.pointcloud import (
    depth_gradient_mask,
    equirect_to_points,
    far_shell_radius,
    resample_rgbd,
    sky_to_shell,
)
from holoflow.geometry.sampling import resize_equirect
from holoflow.geometry.sphere import equirect_directions
from holoflow.geometry.surfaces import depth_noise, smooth_depth, surface_normals
from holoflow.imageops.color import linear_to_srgb_torch

SKY_RIM_PX = 2  # clean_sky: sky pixels this close to anything else mix in its colour
REVEAL_WIDTH = 1536  # px: opening_reveals' pixel sizes hold a window at this width; finer grids are resampled


@dataclass
class Cloud:
    """One point cloud: xyz [N, 3] (world metres), rgb [N, 3] (uint8 sRGB), normals [N, 3] (unit,
    towards the centre) or None."""

    xyz: torch.Tensor
    rgb: torch.Tensor
    normals: torch.Tensor | None = None


@dataclass
class Clouds:
    """The three clouds, P_f's sampling record (pf.json: what the Gaussians' footprints need) and the
    figures a run reports (meta)."""

    clouds: dict[str, Cloud]
    pf: dict
    meta: dict = field(default_factory=dict)


def point_clouds(
    rgb: torch.Tensor, radial_depth: torch.Tensor, cfg: PointCloudParams, progress=None, noise: float | None = None
) -> Clouds:
    """P0, P_f and P_s (module docstring) of rgb [H, W, 3] (linear) and radial_depth [Hd, Wd] (metres,
    inf = sky); ``noise``: the depth's per-pixel noise (relative) when its maker knows it (metric_align's
    ``holoflow.depth_noise``: a network's, measured before the room's planes replaced most of it), else
    measured on radial_depth's own grid (a cloud's resampling adds an unevenness that is no noise).
    progress(done, total, what) is called after each cloud."""
    depth = radial_depth.double()
    if noise is None:
        noise = depth_noise(depth)
    sky_fraction = float((~(torch.isfinite(depth) & (depth > 0))).double().mean())
    shell = cfg.sky_radius if cfg.sky_radius > 0 else far_shell_radius(depth)
    srgb = linear_to_srgb_torch(rgb)  # clamped to [0, 1] first
    pf_width, detail = _pf_width(srgb, cfg)
    clouds, counts, extra = {}, {}, {}
    yaw, walls = None, None  # the room's wall heading, for the windows' planes
    if cfg.opening_bars and cfg.opening_plane == "walls" and sky_fraction > 0:
        from holoflow.depth.layout import room_yaw

        yaw, walls = room_yaw(rgb.detach().cpu().numpy())
    for i, (name, width) in enumerate({"p0": cfg.p0_width, "pf": pf_width, "ps": cfg.ps_width}.items()):
        col, d = resample_rgbd(srgb, depth, width, guided=cfg.depth_upsample == "guided")
        if cfg.opening_bars:
            d, found = keep_opening_bars(col, d, colour_tol=cfg.opening_colour_tol, yaw=yaw)
            counts[f"{name}_opening_bar_pixels"] = found["bar_pixels"]
            counts[f"{name}_opening_frame_pixels"] = found["frame_pixels"]
        sky = ~(torch.isfinite(d) & (d > 0))
        d = sky_to_shell(d, shell)
        if name == "pf":
            by_detail = detail is not None and detail["on"]
            clouds[name], extra = _pf_cloud(srgb, col, d, sky, shell, cfg, by_detail, noise)
            counts.update(extra.pop("counts"))
        else:
            xyz, c = equirect_to_points(col, d)
            clouds[name] = Cloud(xyz, _to_u8(c))
        counts[name] = int(clouds[name].xyz.shape[0])
        if progress is not None:
            progress(i + 1, 3, "clouds")
    pf = {
        "width": pf_width,
        "sampling": cfg.pf_sampling,
        "spacing_rad": 2 * math.pi / pf_width,
        "view_pixel_rad": view_pixel_rad(cfg.view_size, cfg.view_fov_deg),
    }  # the footprint init's low-pass
    if extra.get("caps") is not None:
        pf["polar_caps"] = extra["caps"].to_json()
    if counts.get("pf_coarse"):  # after P_f's own points: the plain tiles' points, at half its width
        pf["coarse"] = {"points": counts["pf_coarse"], "spacing_rad": 2 * math.pi / (pf_width // 2)}
    if counts.get("pf_layer"):  # then the layer's, on every layer_stride-th row and column
        pf["layer"] = {"points": counts["pf_layer"], "spacing_rad": 2 * math.pi * cfg.layer_stride / pf_width}
    if counts.get("pf_reveal"):  # after the layer: the openings' reveals, at their grid's spacing
        pf["reveal"] = {"points": counts["pf_reveal"], "spacing_rad": 2 * math.pi / extra["reveal_width"]}
    if counts.get("pf_dome"):  # last: the sky dome's points
        pf["dome"] = {"points": counts["pf_dome"], "spacing_rad": 2 * math.pi / extra["dome_width"]}
    meta = dict(
        pf_width=pf_width,
        pf_sampling=cfg.pf_sampling,
        points=counts,
        polar_caps=pf.get("polar_caps"),
        polar_detail=extra.get("polar_detail"),
        pf_detail=detail,
        room_yaw=walls,
        sky_fraction=round(sky_fraction, 6),
        shell_radius=round(shell, 6),
        grad_threshold=cfg.grad_threshold,
        depth_size=list(depth.shape),
    )
    return Clouds(clouds, pf, meta)


def _pf_width(srgb: torch.Tensor, cfg: PointCloudParams) -> tuple[int, dict | None]:
    """P_f's width (px) for the panorama srgb [H, W, 3] and, where ``pf_detail_width`` could apply,
    what decided it: {"on", "plain_width", "thinning_psnr" (dB, the panorama thinned to the plain
    width), "share"} (holoflow/geometry/detail.py)."""
    if cfg.pf_width:
        return cfg.pf_width, None
    limit = min(srgb.shape[1], view_width(cfg.view_size, cfg.view_fov_deg))
    plain = min(limit, cfg.pf_max_width)
    wide = min(limit, cfg.pf_detail_width)
    wide -= wide % (2 * DETAIL_TILE_PX)
    if cfg.pf_sampling != "area" or wide <= plain:
        return plain, None
    psnr = thinning_psnr(srgb, plain)
    on = psnr < cfg.pf_detail_psnr
    detail = {"on": on, "plain_width": plain, "thinning_psnr": round(psnr, 3), "share": cfg.pf_detail_share}
    return (wide if on else plain), detail


def _pf_cloud(
    srgb: torch.Tensor,
    col: torch.Tensor,
    d: torch.Tensor,
    sky: torch.Tensor,
    shell: float,
    cfg: PointCloudParams,
    by_detail: bool,
    noise: float,
) -> tuple[Cloud, dict]:
    """P_f from its grid col [h, w, 3] (sRGB) and d [h, w] (radial m, the sky [h, w] on its shell of
    radius ``shell``), steps 2-6 of the module docstring; ``by_detail``: sampled at full width only in
    its most detailed tiles (holoflow/geometry/detail.py); ``noise``: the depth's noise for the smoothing
    (``point_clouds``'s). The windows' reveals are found on the grid
    resampled to at most ``REVEAL_WIDTH``. Returns (the cloud, {"counts", "caps", "polar_detail",
    "dome_width", "reveal_width"})."""
    d_open = torch.where(sky, torch.full_like(d, math.inf), d)  # the openings' sky, for their reveals
    reveal_width = min(col.shape[1], REVEAL_WIDTH)
    sky_col = clean_sky(col, sky)  # [h, w, 3]: what lies unseen behind the room is sky, not its rims
    d = snap_depth_edges(d, cfg.edge_radius, cfg.edge_ratio, cfg.layer_tol, cfg.edge_rounds)
    d = smooth_depth(d, cfg.smooth_radius, cfg.smooth_range, cfg.smooth_noise, noise)
    normals = surface_normals(d, cfg.layer_tol)  # [h, w, 3]
    keep = depth_gradient_mask(d, cfg.grad_threshold, cfg.grad_sides == "one_sided")
    layers = []
    if cfg.layer_baseline > 0:  # the far sides continued under the silhouettes: each its own, then the farthest
        args = (
            torch.where(sky[..., None], sky_col, col),  # the layer's sky: the sky's colour
            d,
            keep,
            cfg.layer_baseline,
            cfg.layer_tol,
            cfg.layer_max_deg,
            cfg.layer_stride,
            cfg.layer_slope,
        )
        own = background_layer(*args, shell=shell, farthest=False)
        far = background_layer(*args, shell=shell, farthest=True)
        behind = torch.isfinite(far[0]) & ~(torch.isfinite(own[0]) & (far[0] < own[0] * (1 + cfg.layer_tol)))
        layers = [own, (torch.where(behind, far[0], torch.full_like(far[0], math.inf)), far[1])]
    d = torch.where(keep, d, torch.full_like(d, float("nan")))
    caps, detail = None, None
    pf_col = torch.where(sky[..., None], sky_col, col)  # the shell's sky without a frame's rim: no ghost frames
    if cfg.pf_sampling == "area":
        caps = polar_caps(
            col.shape[1], srgb.shape[1], cfg.pf_polar_density, cfg.pf_polar_from_deg, cfg.pf_polar_upsample
        )
        cap_rgb = None
        if caps is not None:
            cap_rgb = resize_equirect(srgb.permute(2, 0, 1), caps.width // 2, caps.width).permute(1, 2, 0)
            caps, detail = called_for(caps, cap_rgb, col.shape[1], cfg.pf_polar_detail)
            detail = {k: float(f"{v:.4g}") for k, v in detail.items()}
        tiles = detail_tiles(col, cfg.pf_detail_share) if by_detail else None
        xyz, c, pixel, coarse = equirect_to_area_points(pf_col, d, caps, cap_rgb, tiles, DETAIL_TILE_PX)
        n = normals.reshape(-1, 3)[pixel]
    else:
        xyz, c = equirect_to_points(pf_col, d)
        n = normals[torch.isfinite(d) & (d > 0)]
        coarse = 0
    counts = {"pf_dropped_fraction": round(float((~keep).double().mean()), 6)}
    if coarse:
        counts["pf_coarse"] = coarse
    dome = cfg.sky_dome and bool(sky.any())
    for ld, lcol in layers:  # the layer continues a far surface seen head on from the centre: discs face it
        if dome:  # the sky's own layer is left to the dome, which stands behind everything there
            ld = torch.where(ld >= shell * (1 - 1e-9), torch.full_like(ld, math.inf), ld)
        lxyz, lc = equirect_to_points(lcol, ld)
        ldirs = equirect_directions(*ld.shape, dtype=lxyz.dtype)[torch.isfinite(ld) & (ld > 0)]
        xyz, c, n = _append((xyz, c, n), (lxyz, lc, -ldirs))
        counts["pf_layer"] = counts.get("pf_layer", 0) + int(len(lxyz))
    if cfg.opening_reveals:  # the recesses' sides that the near jamb hides from the centre
        rcol, rd = resample_rgbd(col, d_open, reveal_width) if reveal_width < col.shape[1] else (col, d_open)
        rxyz, rc, _ = opening_reveals(rcol, rd, 2 * math.pi / reveal_width)
        rdirs = rxyz / torch.linalg.vector_norm(rxyz, dim=-1, keepdim=True).clamp_min(1e-12)
        xyz, c, n = _append((xyz, c, n), (rxyz, rc, -rdirs))  # discs facing the centre, as the layer's
        counts["pf_reveal"] = int(len(rxyz))
    dome_width = max(8, col.shape[1] // cfg.sky_dome_coarse)
    if dome:
        dxyz, dc = sky_dome(sky_col, sky, shell * 1.05, dome_width, math.radians(cfg.sky_dome_reach_deg))
        xyz, c, n = _append((xyz, c, n), (dxyz, dc, -dxyz / torch.linalg.vector_norm(dxyz, dim=-1, keepdim=True)))
        counts["pf_dome"] = int(len(dxyz))
    found = {"counts": counts, "caps": caps, "polar_detail": detail, "dome_width": dome_width}
    return Cloud(xyz, _to_u8(c), n), {**found, "reveal_width": reveal_width}


def clean_sky(rgb: torch.Tensor, sky: torch.Tensor, rim_px: int = SKY_RIM_PX) -> torch.Tensor:
    """Every pixel of an equirect grid rgb [H, W, C] given the colour of the sky [H, W] (bool) around
    it, from the sky's pixels more than ``rim_px`` px from anything else (``fill_from``): the rim a frame
    or a bar shares with the sky mixes in their colour, which on the unseen sky behind them (the layer,
    the dome) would draw ghost frames and grey panes. Sky too thin to have an inside keeps its own
    colour; without sky, rgb comes back unchanged."""
    import torch.nn.functional as F

    from holoflow.geometry.sampling import pad_equirect

    if not bool(sky.any()):
        return rgb
    k = 2 * rim_px + 1
    other = pad_equirect((~sky).to(rgb.dtype)[None], rim_px)  # [1, H + 2r, W + 2r]
    inside = sky & (F.max_pool2d(other[None], k, stride=1)[0, 0] == 0)
    return fill_from(rgb, inside if bool(inside.any()) else sky)


def sky_dome(
    rgb: torch.Tensor, sky: torch.Tensor, radius: float, width: int, reach: float = math.pi
) -> tuple[torch.Tensor, torch.Tensor]:
    """The sky dome (module docstring, step 5) of an equirect grid rgb [H, W, C] that holds the sky's
    colour everywhere (``clean_sky``), whose sky is sky [H, W] (bool, at least one pixel): points xyz
    [M, 3] on a sphere of ``radius`` metres, one per pixel of a ``width`` x ``width // 2`` grid whose
    direction the panorama does not see as sky and lies within ``reach`` radians of a direction it
    does, and their colour [M, C]."""
    h = max(1, width // 2)
    small = resize_equirect(torch.cat([rgb, sky[..., None].to(rgb.dtype)], -1).permute(2, 0, 1), h, width)
    small = small.permute(1, 2, 0)  # [h, w, C + 1]
    dirs = equirect_directions(h, width, dtype=rgb.dtype)  # [h, w, 3]
    where = small[..., -1] < 0.999  # not all sky: the dome behind
    if reach < math.pi:
        seen = dirs[small[..., -1] > 0]  # [S, 3] directions with some sky (the filter keeps every sky pixel's)
        near = torch.zeros_like(where)
        for chunk in torch.split(torch.nonzero(where), 4096):  # [c, 2] cells: the largest cosine to the sky
            near[chunk[:, 0], chunk[:, 1]] = (dirs[chunk[:, 0], chunk[:, 1]] @ seen.T).amax(1) >= math.cos(reach)
        where &= near
    return dirs[where] * radius, small[..., :-1][where]


def fill_from(values: torch.Tensor, known: torch.Tensor) -> torch.Tensor:
    """values [H, W, C] with the pixels where known [H, W] is False filled from the known ones (pull-push:
    averages over ever coarser grids, columns wrapping, then back down, each pixel taking the finest
    level that knows it; the coarsest level's unknown pixels the mean). Every pixel is known when any is; otherwise
    values come back unchanged."""
    if bool(known.all()) or not bool(known.any()):
        return values
    w = known.to(values.dtype)[..., None]
    levels = [(values * w, w)]
    while bool((levels[-1][1] == 0).any()) and min(levels[-1][1].shape[:2]) > 1:
        v, w = levels[-1]
        H, W = v.shape[:2]
        if W % 2:  # wrap one column in
            v, w = torch.cat([v, v[:, :1]], 1), torch.cat([w, w[:, :1]], 1)
        if H % 2:
            v, w = torch.cat([v, v[-1:]], 0), torch.cat([w, w[-1:]], 0)
        levels.append((_sum_2x2(v), _sum_2x2(w)))
    v, w = levels[-1]
    mean = v.sum((0, 1)) / w.sum((0, 1)).clamp_min(1e-12)  # what is left: the mean
    out = torch.where(w > 0, v / w.clamp_min(1e-12), mean)
    for v, w in reversed(levels[:-1]):
        up = out.repeat_interleave(2, 0).repeat_interleave(2, 1)[: v.shape[0], : v.shape[1]]
        out = torch.where(w > 0, v / w.clamp_min(1e-12), up)
    return out


def _append(cloud: tuple, more: tuple) -> tuple:
    """(xyz, colours, normals) of a cloud with ``more`` such tensors after its own, in its dtypes."""
    return tuple(torch.cat([a, b.to(a.dtype)]) for a, b in zip(cloud, more))


def _sum_2x2(x: torch.Tensor) -> torch.Tensor:
    """[2h, 2w, C] -> [h, w, C]: sums of 2 x 2 blocks."""
    return x.reshape(x.shape[0] // 2, 2, x.shape[1] // 2, 2, -1).sum((1, 3))


def _to_u8(c: torch.Tensor) -> torch.Tensor:
    return (c.clamp(0, 1) * 255.0 + 0.5).to(torch.uint8)
