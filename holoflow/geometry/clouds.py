"""HoloDreamer's three point clouds from an equirect RGB-D panorama: P0, P_f and P_s.

P0 at ``p0_width`` (paper: the depth resolution); P_s at ``ps_width`` (the cloud the PCD set is
projected from); P_f, the cloud the Gaussians start from, at ``pf_width`` (0 = as fine as a
``view_size`` view resolves, capped at the panorama's width and ``pf_max_width``), built in this order
on its equirect grid:

1. sky (inf depth) on a far shell of radius ``sky_radius`` (0 = 2 x the 99th percentile of finite
   depth), so the scene stays enclosed (holoflow/geometry/pointcloud.py);
2. occlusion edges that the depth draws as ramps made steps (holoflow/geometry/edges.py);
3. per-pixel depth noise smoothed within each surface, never across an edge, and each pixel's surface
   normal (holoflow/geometry/surfaces.py): the Gaussians lie on their surfaces;
4. points whose relative depth gradient exceeds ``grad_threshold`` dropped (the paper's filter, 0.4);
5. the background layer: the far surface and the sky shell continued under every silhouette, as wide
   as an eye move of ``layer_baseline`` metres uncovers (holoflow/geometry/layers.py);
6. sampled by area (``pf_sampling``; polar caps sampled finer where the panorama's poles hold detail:
   holoflow/geometry/area.py).

Colour is resampled antialiased, depth point-sampled (no invented edge depths). Colours returned are
8-bit sRGB (the PLY convention, docs/conventions.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from holoflow.geometry.area import (called_for, equirect_to_area_points, polar_caps, view_pixel_rad, view_width)
from holoflow.geometry.config import PointCloudParams
from holoflow.geometry.edges import snap_depth_edges
from holoflow.geometry.layers import background_layer
from holoflow.geometry.pointcloud import (depth_gradient_mask, equirect_to_points, far_shell_radius, resample_rgbd,
                                          sky_to_shell)
from holoflow.geometry.sampling import resize_equirect
from holoflow.geometry.sphere import equirect_directions
from holoflow.geometry.surfaces import smooth_depth, surface_normals


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


def point_clouds(rgb: torch.Tensor, radial_depth: torch.Tensor, cfg: PointCloudParams, progress=None) -> Clouds:
    """P0, P_f and P_s (module docstring) of rgb [H, W, 3] (linear) and radial_depth [Hd, Wd] (metres,
    inf = sky). progress(done, total, what) is called after each cloud."""
    depth = radial_depth.double()
    sky_fraction = float((~(torch.isfinite(depth) & (depth > 0))).double().mean())
    shell = cfg.sky_radius if cfg.sky_radius > 0 else far_shell_radius(depth)
    srgb = _srgb(rgb)
    pf_width = cfg.pf_width or min(rgb.shape[1], view_width(cfg.view_size, cfg.view_fov_deg), cfg.pf_max_width)
    clouds, counts, extra = {}, {}, {}
    for i, (name, width) in enumerate({"p0": cfg.p0_width, "pf": pf_width, "ps": cfg.ps_width}.items()):
        col, d = resample_rgbd(srgb, depth, width)
        d = sky_to_shell(d, shell)
        if name == "pf":
            clouds[name], extra = _pf_cloud(srgb, col, d, cfg)
            counts.update(extra.pop("counts"))
        else:
            xyz, c = equirect_to_points(col, d)
            clouds[name] = Cloud(xyz, _to_u8(c))
        counts[name] = int(clouds[name].xyz.shape[0])
        if progress is not None:
            progress(i + 1, 3, "clouds")
    pf = {"width": pf_width, "sampling": cfg.pf_sampling, "spacing_rad": 2 * math.pi / pf_width,
          "view_pixel_rad": view_pixel_rad(cfg.view_size, cfg.view_fov_deg)}   # the footprint init's low-pass
    if extra.get("caps") is not None:
        pf["polar_caps"] = extra["caps"].to_json()
    if counts.get("pf_layer"):     # the last points of pf.ply, on every layer_stride-th row and column
        pf["layer"] = {"points": counts["pf_layer"], "spacing_rad": 2 * math.pi * cfg.layer_stride / pf_width}
    meta = dict(pf_width=pf_width, pf_sampling=cfg.pf_sampling, points=counts, polar_caps=pf.get("polar_caps"),
                polar_detail=extra.get("polar_detail"), sky_fraction=round(sky_fraction, 6),
                shell_radius=round(shell, 6), grad_threshold=cfg.grad_threshold, depth_size=list(depth.shape))
    return Clouds(clouds, pf, meta)


def _pf_cloud(srgb: torch.Tensor, col: torch.Tensor, d: torch.Tensor, cfg: PointCloudParams) -> tuple[Cloud, dict]:
    """P_f from its grid col [h, w, 3] (sRGB) and d [h, w] (radial m, sky on its shell), steps 2-6 of
    the module docstring: (the cloud, {"counts", "caps", "polar_detail"})."""
    d = snap_depth_edges(d, cfg.edge_radius, cfg.edge_ratio, cfg.layer_tol, cfg.edge_rounds)
    d = smooth_depth(d, cfg.smooth_radius, cfg.smooth_range)
    normals = surface_normals(d, cfg.layer_tol)                                     # [h, w, 3]
    keep = depth_gradient_mask(d, cfg.grad_threshold)
    layer = None
    if cfg.layer_baseline > 0:     # the far side continued under the silhouettes
        layer = background_layer(col, d, keep, cfg.layer_baseline, cfg.layer_tol, cfg.layer_max_deg,
                                 cfg.layer_stride, cfg.layer_slope)
    d = torch.where(keep, d, torch.full_like(d, float("nan")))
    caps, detail = None, None
    if cfg.pf_sampling == "area":
        caps = polar_caps(col.shape[1], srgb.shape[1], cfg.pf_polar_density, cfg.pf_polar_from_deg,
                          cfg.pf_polar_upsample)
        cap_rgb = None
        if caps is not None:
            cap_rgb = resize_equirect(srgb.permute(2, 0, 1), caps.width // 2, caps.width).permute(1, 2, 0)
            caps, detail = called_for(caps, cap_rgb, col.shape[1], cfg.pf_polar_detail)
            detail = {k: float(f"{v:.4g}") for k, v in detail.items()}
        xyz, c, pixel = equirect_to_area_points(col, d, caps, cap_rgb if caps is not None else None)
        n = normals.reshape(-1, 3)[pixel]
    else:
        xyz, c = equirect_to_points(col, d)
        n = normals[torch.isfinite(d) & (d > 0)]
    counts = {"pf_dropped_fraction": round(float((~keep).double().mean()), 6)}
    if layer is not None:      # the layer continues a far surface seen head on from the centre: discs face it
        lxyz, lc = equirect_to_points(layer[1], layer[0])
        ldirs = equirect_directions(*layer[0].shape, dtype=lxyz.dtype)[torch.isfinite(layer[0]) & (layer[0] > 0)]
        xyz, c, n = torch.cat([xyz, lxyz]), torch.cat([c, lc]), torch.cat([n, -ldirs.to(n.dtype)])
        counts["pf_layer"] = int(len(lxyz))
    return Cloud(xyz, _to_u8(c), n), {"counts": counts, "caps": caps, "polar_detail": detail}


def _srgb(linear: torch.Tensor) -> torch.Tensor:
    """[H, W, 3] linear light -> sRGB in [0, 1] (holoflow/imageops/color.py)."""
    from holoflow.imageops.color import linear_to_srgb_torch

    return linear_to_srgb_torch(linear.clamp(0, 1))


def _to_u8(c: torch.Tensor) -> torch.Tensor:
    return (c.clamp(0, 1) * 255.0 + 0.5).to(torch.uint8)
