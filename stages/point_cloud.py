"""point_cloud: equirect RGB-D -> the three point clouds of HoloDreamer (p0.ply, pf.ply, ps.ply).

P0 at the depth resolution, P_f (the Gaussians' initialisation: the paper's depth-gradient filter,
here also with edges made steps, depth noise smoothed within surfaces, a normal per point and a
background layer under the silhouettes) and P_s (the PCD set's cloud): holoflow/geometry/clouds.py.
pf.json records P_f's sampling, which the Gaussians' footprints need. PLY colours are 8-bit sRGB
(docs/conventions.md); pf.ply carries normals (nx ny nz); pano.exr is linear.
"""

from __future__ import annotations

import json

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    import torch

    from holoflow.geometry.clouds import point_clouds
    from holoflow.geometry.config import PointCloudParams
    from holoflow.io.exr import read_exr, read_rgb
    from holoflow.io.ply import write_points

    cfg = job.config(PointCloudParams)
    rgb = torch.from_numpy(read_rgb(job.input_file("pano", "pano.exr")))  # [H, W, 3] linear
    channels, attrs = read_exr(job.input_file("depth", "depth.exr"))
    if "Z" not in channels:
        raise ValueError(f"depth.exr has no Z channel (has {sorted(channels)})")
    kind = attrs.get("holoflow.depth_kind", "radial")
    if kind != "radial":
        raise ValueError(f"depth.exr holds {kind} depth; point_cloud needs radial (equirect) depth")
    noise = attrs.get("holoflow.depth_noise")  # a network's noise before metric_align laid the planes
    depth = torch.from_numpy(channels["Z"])  # radial m, inf = sky
    result = point_clouds(rgb, depth, cfg, job.progress, None if noise is None else float(noise))
    for name, cloud in result.clouds.items():
        normals = None if cloud.normals is None else cloud.normals.float().numpy()
        write_points(job.output(f"{name}.ply"), cloud.xyz.float().numpy(), cloud.rgb.numpy(), normals)
    job.output("pf.json").write_text(json.dumps(result.pf, sort_keys=True))
    job.meta(**result.meta)
    meta = result.meta
    print(
        f"point_cloud: {meta['points']}, shell radius {meta['shell_radius']:.3f} m, "
        f"sky {100 * meta['sky_fraction']:.2f}%"
    )
    if meta["pf_detail"] is not None:
        why = meta["pf_detail"]
        kept = f"the panorama thinned to {why['plain_width']} px scores {why['thinning_psnr']:.1f} dB"
        if why["on"]:
            share = f"{100 * why['share']:.0f} %"
            print(f"point_cloud: P_f {meta['pf_width']} px in the most detailed {share} of the sphere, half elsewhere")
            print(f"point_cloud: ({kept})")
        else:
            print(f"point_cloud: P_f {meta['pf_width']} px ({kept}: no detail it loses)")
    if meta["polar_detail"] is not None:
        on = [k for k in ("north", "south") if (meta["polar_caps"] or {}).get(k)]
        lost = ", ".join(f"{k} {meta['polar_detail'][k]:.3g}" for k in ("north", "south", "sides"))
        print(f"point_cloud: polar caps {' and '.join(on) or 'off'} (what P_f's rings would lose: {lost})")
    return 0


if __name__ == "__main__":
    run_main(main, "point_cloud")
