"""point_cloud: equirect RGB-D -> the three point clouds of HoloDreamer (p0.ply, pf.ply, ps.ply).

P0 at ``p0_width`` (paper: the depth resolution, 4096); P_f at ``pf_width`` (paper 2048; 0 = as fine as
a ``view_size`` view resolves, capped at the panorama's width and ``pf_max_width``), sampled by area (``pf_sampling``:
holoflow/geometry/area.py; pf.json records its angular spacing for the Gaussians' footprints), with the
points whose relative depth gradient exceeds ``grad_threshold`` (paper 0.4) dropped (definition and
units: holoflow/geometry/pointcloud.py, docs/conventions.md) once the occlusion edges that the depth
draws as ramps are made steps (``edge_radius``: holoflow/geometry/edges.py); P_s at ``ps_width`` (paper 1024), the
cloud the PCD set is projected from. Sky (inf depth) goes on a far shell of radius ``sky_radius``
(0 = 2 x the 99th percentile of finite depth) so the scene stays enclosed. P_f also holds a
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

    from holoflow.geometry.area import equirect_to_area_points, view_width
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
    counts = {}
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
            xyz, c = equirect_to_area_points(polar_colour(srgb, col, cfg.pf_polar_density), d,
                                             cfg.pf_polar_density, cfg.pf_polar_from_deg)
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
    polar = cfg.pf_sampling == "area" and cfg.pf_polar_density > 1
    job.output("pf.json").write_text(json.dumps({"width": pf_width, "sampling": cfg.pf_sampling,
                                                 "spacing_rad": 2 * math.pi / pf_width,
                                                 "polar_density": cfg.pf_polar_density if polar else 1.0,
                                                 "polar_from_deg": cfg.pf_polar_from_deg if polar else 90.0},
                                                sort_keys=True))
    job.meta(pf_width=pf_width, pf_sampling=cfg.pf_sampling, points=counts, sky_fraction=round(sky_fraction, 6),
             shell_radius=round(shell, 6), grad_threshold=threshold, depth_size=list(depth.shape))
    print(f"point_cloud: {counts}, shell radius {shell:.3f} m, sky {100 * sky_fraction:.2f}%")
    return 0


def polar_colour(srgb, col, polar_density: float):
    """P_f's colour image for area sampling: col [h, w, 3] (the panorama srgb [H, W, 3] resampled to
    P_f's grid) when ``polar_density`` is 1, else srgb resampled to h rows only, keeping up to
    ``polar_density`` x w of its columns, so the denser polar rows average the panorama's own pixels."""
    from holoflow.geometry.sampling import resize_equirect

    h, w = col.shape[:2]
    wide = min(srgb.shape[1], math.ceil(w * polar_density))
    if polar_density <= 1 or wide <= w:
        return col
    return resize_equirect(srgb.permute(2, 0, 1), h, wide).permute(1, 2, 0)


if __name__ == "__main__":
    run_main(main, "point_cloud")
