"""point_cloud: equirect RGB-D -> the three point clouds of HoloDreamer (p0.ply, pf.ply, ps.ply).

P0 at ``p0_width`` (paper: the depth resolution, 4096); P_f at ``pf_width`` (paper 2048; 0 = as fine as
a ``view_size`` view resolves, capped at the panorama's width and ``pf_max_width``), sampled by area (``pf_sampling``:
holoflow/geometry/area.py; pf.json records its angular spacing for the Gaussians' footprints), with the
points whose relative depth gradient exceeds ``grad_threshold`` (paper 0.4) dropped (definition and
units: holoflow/geometry/pointcloud.py, docs/conventions.md) once the occlusion edges that the depth
draws as ramps are made steps (``edge_radius``: holoflow/geometry/edges.py); P_s at ``ps_width`` (paper 1024), the
cloud the PCD set is projected from. Sky (inf depth) goes on a far shell of radius ``sky_radius``
(0 = 2 x the 99th percentile of finite depth) so the scene stays enclosed. P_f's polar caps (beyond
``pf_polar_from_deg``) are sampled ``pf_polar_density`` times finer from the panorama itself
where the panorama's polar rows hold more detail than P_f's rings keep (``pf_polar_detail``;
holoflow/geometry/area.py). P_f also holds a
background layer (``layer_baseline`` > 0), after its grid's points: the far surface and the sky
shell continued under every silhouette, as wide as an eye move of ``layer_baseline`` metres
uncovers (holoflow/geometry/layers.py). Colour is resampled
antialiased, depth point-sampled (no invented edge depths). PLY colours are 8-bit sRGB
(docs/conventions.md); pano.exr is linear.
"""
from __future__ import annotations

import json
import math

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    import kornia
    import torch

    from holoflow.geometry.area import view_pixel_rad, view_width
    from holoflow.geometry.config import PointCloudParams
    from holoflow.geometry.edges import snap_depth_edges
    from holoflow.geometry.layers import background_layer
    from holoflow.geometry.pointcloud import (depth_gradient_mask, equirect_to_points, far_shell_radius,
                                              resample_rgbd, sky_to_shell)
    from holoflow.io.exr import read_exr, read_rgb
    from holoflow.io.ply import write_points

    cfg = job.config(PointCloudParams)
    threshold, sky_radius = cfg.grad_threshold, cfg.sky_radius
    rgb = torch.from_numpy(read_rgb(job.input_file("pano", "pano.exr")))  # [H, W, 3] linear
    pf_width = cfg.pf_width or min(rgb.shape[1], view_width(cfg.view_size, cfg.view_fov_deg), cfg.pf_max_width)
    widths = {"p0": cfg.p0_width, "pf": pf_width, "ps": cfg.ps_width}
    channels, attrs = read_exr(job.input_file("depth", "depth.exr"))
    if "Z" not in channels:
        raise ValueError(f"depth.exr has no Z channel (has {sorted(channels)})")
    kind = attrs.get("holoflow.depth_kind", "radial")
    if kind != "radial":
        raise ValueError(f"depth.exr holds {kind} depth; point_cloud needs radial (equirect) depth")
    depth = torch.from_numpy(channels["Z"]).double()  # [H, W] radial metres, inf = sky
    sky_fraction = float((~(torch.isfinite(depth) & (depth > 0))).double().mean())
    shell = sky_radius if sky_radius > 0 else far_shell_radius(depth)
    # linear -> 8-bit sRGB, the PLY colour convention
    srgb = kornia.color.linear_rgb_to_rgb(rgb.clamp(0, 1).permute(2, 0, 1)).permute(1, 2, 0)
    counts, pf_caps, polar_detail = {}, None, None
    for i, (name, width) in enumerate(widths.items()):
        col, d = resample_rgbd(srgb, depth, width)
        d = sky_to_shell(d, shell)
        keep = torch.ones_like(d, dtype=torch.bool)
        layer = None
        if name == "pf":
            d = snap_depth_edges(d, cfg.edge_radius, cfg.edge_ratio, cfg.layer_tol, cfg.edge_rounds)
            keep = depth_gradient_mask(d, threshold)
            if cfg.layer_baseline > 0:     # the far side continued under the silhouettes
                layer = background_layer(col, d, keep, cfg.layer_baseline, cfg.layer_tol, cfg.layer_max_deg,
                                         cfg.layer_stride, cfg.layer_slope)
            d = torch.where(keep, d, torch.full_like(d, float("nan")))
        if name == "pf" and cfg.pf_sampling == "area":
            xyz, c, pf_caps, polar_detail = pf_area_points(srgb, col, d, cfg)
        else:
            xyz, c = equirect_to_points(col, d)
        if layer is not None:
            lxyz, lc = equirect_to_points(layer[1], layer[0])
            xyz, c = torch.cat([xyz, lxyz]), torch.cat([c, lc])
            counts["pf_layer"] = int(len(lxyz))
        rgb8 = (c.clamp(0, 1) * 255.0 + 0.5).to(torch.uint8).numpy()
        write_points(job.output(f"{name}.ply"), xyz.float().numpy(), rgb8)
        counts[name] = int(xyz.shape[0])
        if name == "pf":
            counts["pf_dropped_fraction"] = round(float((~keep).double().mean()), 6)
        job.progress(i + 1, 3, "clouds")
    pf = {"width": pf_width, "sampling": cfg.pf_sampling, "spacing_rad": 2 * math.pi / pf_width,
          "view_pixel_rad": view_pixel_rad(cfg.view_size, cfg.view_fov_deg)}   # the footprint init's low-pass
    if pf_caps is not None:
        pf["polar_caps"] = pf_caps.to_json()
    if counts.get("pf_layer"):     # the last points of pf.ply, on every layer_stride-th row and column
        pf["layer"] = {"points": counts["pf_layer"], "spacing_rad": 2 * math.pi * cfg.layer_stride / pf_width}
    job.output("pf.json").write_text(json.dumps(pf, sort_keys=True))
    job.meta(pf_width=pf_width, pf_sampling=cfg.pf_sampling, points=counts, polar_caps=pf.get("polar_caps"),
             polar_detail=polar_detail, sky_fraction=round(sky_fraction, 6),
             shell_radius=round(shell, 6), grad_threshold=threshold, depth_size=list(depth.shape))
    print(f"point_cloud: {counts}, shell radius {shell:.3f} m, sky {100 * sky_fraction:.2f}%")
    if polar_detail is not None:
        on = [k for k in ("north", "south") if pf_caps is not None and getattr(pf_caps, k)]
        lost = ", ".join(f"{k} {polar_detail[k]:.3g}" for k in ("north", "south", "sides"))
        print(f"point_cloud: polar caps {' and '.join(on) or 'off'} (what P_f's rings would lose: {lost})")
    return 0


def pf_area_points(srgb, col, d, cfg):
    """P_f's points by area (holoflow/geometry/area.py) from its grid col [h, w, 3] (sRGB) and d [h, w]
    (radial m, NaN = dropped), with the polar caps sampled from the panorama srgb [H, W, 3] where it
    calls for them: (xyz [N, 3], colour [N, 3], the caps or None, what P_f's rings would lose per
    region or None)."""
    from holoflow.geometry.area import called_for, equirect_to_area_points, polar_caps
    from holoflow.geometry.sampling import resize_equirect

    pf_width = col.shape[1]
    caps = polar_caps(pf_width, srgb.shape[1], cfg.pf_polar_density, cfg.pf_polar_from_deg, cfg.pf_polar_upsample)
    if caps is None:
        return (*equirect_to_area_points(col, d), None, None)
    cap_rgb = resize_equirect(srgb.permute(2, 0, 1), caps.width // 2, caps.width).permute(1, 2, 0)   # [h, w, 3]
    caps, detail = called_for(caps, cap_rgb, pf_width, cfg.pf_polar_detail)
    xyz, c = equirect_to_area_points(col, d, caps, cap_rgb)
    return xyz, c, caps, {k: float(f"{v:.4g}") for k, v in detail.items()}


if __name__ == "__main__":
    run_main(main, "point_cloud")
