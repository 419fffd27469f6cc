"""pcd_set: P_s seen by the supplementary cameras through a z-buffer (the PCD set + missing masks).

For every base camera of pano_set's cameras.json, four supplementary cameras (above, below, left,
right; holoflow.geometry.rigs.supplementary_rig) are moved by ``offset`` x that base view's median
scene depth (the median z of P_s's z-buffer from the base camera) and turned ``angle_deg`` back
towards the base view's axis. The median leaves out the sky: points at >= 0.999 x the 99th
percentile of P_s's radii, which is point_cloud's far shell whenever the sky covers more than 1% of
the panorama (then it also drops sky pixels the depth stage left finite and farther still; with no
sky it drops the farthest 1% of the geometry, which barely moves a median). So an outdoor view's
offset follows its ground and objects, not the sky. P_s (point_cloud's ps.ply) is projected into each with a z-buffer,
nearest point wins, each point covering (2 R - 1)^2 pixels: R = ``splat_radius``, or with 0 (auto) each
point's own footprint (holoflow.geometry.pointcloud.footprint_radius, from P_s's angular step
2 pi / width, width = sqrt(2 N) since P_s keeps every pixel of its width x width/2 grid), so the
missing pixels are disocclusions rather than sampling gaps. Points of P_s on occlusion edges (relative
depth gradient over ``edge_threshold``, the measure point_cloud filters P_f with; 0 = keep all) are left
out of the image: P_s is made from the unfiltered P0, so its edge points are the depth-mixed "rubber
sheet" between a foreground object and what lies behind it, which would otherwise paint the
disocclusion with smeared colour. The same test also flags surfaces seen at grazing incidence (at a
256 px wide P_s, ground beyond ~25 m from a 1.6 m eye, and every horizon), so the edge points are
projected on their own into the ``seen`` channel: 1 where any point of P_s landed. inp_set inpaints
where nothing was seen, not where only edge points were (docs/reconstruction.md). Writes
views/NNN_K.exr (R,G,B linear; A = 1 where a non-edge point landed, 0 = missing: pre_opt's loss mask;
seen = 1 where any point landed; K = 0 above, 1 below, 2 left, 3 right), cameras.json (kind
"supplementary", base = base camera index) and transforms.json.
"""
from __future__ import annotations

import math
import os


def main() -> int:
    from holoflow.stage import Job

    job = Job.from_argv()
    import kornia
    import torch

    torch.set_num_threads(max(1, (os.cpu_count() or 2) // 2))  # spinning workers cost more than they bring on shared cores

    from holoflow.geometry.export import cameras_json, cameras_tensors, read_cameras, write_cameras, write_transforms
    from holoflow.geometry.pointcloud import (depth_gradient, footprint_radius, project_points_zbuffer,
                                              solid_points_mask)
    from holoflow.geometry.rigs import SUPPLEMENTARY, supplementary_rig
    from holoflow.io.exr import write_rgb
    from holoflow.io.ply import read_points

    p = job.params
    offset, angle, radius = float(p["offset"]), float(p["angle_deg"]), int(p["splat_radius"])
    if radius < 0:
        raise ValueError(f"splat_radius must be >= 1, or 0 for automatic, got {radius}")
    device = torch.device(job.device)
    xyz, rgb8 = read_points(job.input_file("cloud", "ps.ply"))
    if len(xyz) == 0:
        raise ValueError("ps.ply holds no points")
    base = read_cameras(job.input_file("cameras", "cameras.json"))
    K, base_V = (t.to(device) for t in cameras_tensors(base))  # float64
    W, H = int(base["width"]), int(base["height"])
    pts = torch.from_numpy(xyz).to(device).double()  # [N, 3]
    srgb = torch.from_numpy(rgb8).to(device).float() / 255.0  # [N, 3]
    edge = float(p.get("edge_threshold", 0.0))
    edge_pts = pts[:0]  # [E, 3] P_s's edge points: left out of the image, kept for the seen mask
    if edge > 0:  # P_s is a full equirect grid, row-major: width = sqrt(2 N)
        w = int(round(math.sqrt(2 * len(xyz))))
        if w * (w // 2) != len(xyz):
            raise ValueError(f"ps.ply: {len(xyz)} points are not a full equirect grid (edge_threshold needs one)")
        grad = depth_gradient(torch.linalg.vector_norm(pts, dim=-1).reshape(w // 2, w))  # [H, W]
        keep = (torch.nan_to_num(grad, nan=float("inf")) <= edge).reshape(-1)  # [N]
        pts, srgb, edge_pts = pts[keep], srgb[keep], pts[~keep]
    n_edge = len(xyz) - len(pts)
    linear = kornia.color.rgb_to_linear_rgb(srgb.T[:, :, None])[:, :, 0].T  # [N, 3] linear light
    M = base_V.shape[0]
    spacing = 2.0 * math.pi / math.sqrt(2.0 * len(xyz))  # P_s's angular step, radians

    def radii(viewmat, points=pts):
        return radius if radius > 0 else footprint_radius(points, viewmat, K, spacing)

    r = torch.linalg.vector_norm(pts, dim=-1)  # [N] m
    solid = solid_points_mask(pts)  # not the far sky shell, nor beyond it
    geo, geo_rgb = pts[solid], linear[solid]  # [G, 3] each
    medians = []
    for i in range(M):  # typical depth of the geometry (not the sky) seen by each base camera
        _, hit, z = project_points_zbuffer(geo, geo_rgb, K, base_V[i], H, W, radii(base_V[i], geo))
        zs = z[hit > 0]
        medians.append(float(zs.median()) if zs.numel() else float(r[solid].median()))
    medians_t = torch.tensor(medians, dtype=torch.float64, device=device)
    sup = supplementary_rig(base_V, medians_t, offset, angle)  # [4 M, 4, 4]
    names, files, bases, missing, unseen = [], [], [], [], []
    for j in range(4 * M):
        b, k = divmod(j, 4)
        img, hit, _ = project_points_zbuffer(pts, linear, K, sup[j], H, W, radii(sup[j]))
        seen = hit
        if len(edge_pts):
            _, edge_hit, _ = project_points_zbuffer(edge_pts, edge_pts[:, :0], K, sup[j], H, W,  # coverage only
                                                    radii(sup[j], edge_pts))
            seen = torch.maximum(hit, edge_hit)
        name = f"{base['views'][b]['name']}_{k}"
        names.append(name)
        files.append(f"views/{name}.exr")
        bases.append(b)
        missing.append(1.0 - float(hit.mean()))
        unseen.append(1.0 - float(seen.mean()))
        write_rgb(job.output(files[-1]), img.float().cpu().numpy(),
                  {"holoflow.stage": "pcd_set", "holoflow.camera": name, "holoflow.side": SUPPLEMENTARY[k]},
                  A=hit.float().cpu().numpy(), seen=seen.float().cpu().numpy())
        job.progress(j + 1, 4 * M, "views")
    cams = cameras_json(K, sup, W, H, names, files, kinds=["supplementary"] * (4 * M), bases=bases)
    write_cameras(job.output("cameras.json"), cams)
    write_transforms(job.output("transforms.json"), cams)
    job.meta(views=4 * M, points=int(len(xyz)), edge_points_dropped=n_edge,
             missing_fraction=round(sum(missing) / len(missing), 6),
             unseen_fraction=round(sum(unseen) / len(unseen), 6),
             splat_radius=radius if radius > 0 else "auto",
             median_depth=[round(m, 4) for m in medians])
    return 0


if __name__ == "__main__":
    from holoflow.stage import run_main

    run_main(main, "pcd_set")
