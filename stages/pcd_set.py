"""pcd_set: P_s seen by the supplementary cameras through a z-buffer (the PCD set + missing masks).

Four supplementary cameras per base camera of pano_set's cameras.json (above, below, left, right),
moved by ``offset`` x the base view's median geometry depth and turned ``angle_deg`` back to its axis;
P_s (point_cloud's ps.ply) projected into each, nearest point wins, each point covering its own
footprint (``splat_radius`` 0) so that what is missing is disocclusion, not sampling gaps; points on
occlusion edges (``edge_threshold``) left out of the image but kept in ``seen``. The method and its
reasons: holoflow/geometry/pcdset.py and docs/reconstruction.md. Writes views/NNN_K.exr (R,G,B
linear; A = 1 where a non-edge point landed, 0 = missing: pre_opt's loss mask; seen = 1 where any
point landed; K = 0 above, 1 below, 2 left, 3 right), cameras.json (kind "supplementary", base = base
camera index) and transforms.json.
"""

from __future__ import annotations


def main() -> int:
    from holoflow.stage import Job

    job = Job.from_argv()
    import kornia
    import torch

    from holoflow.geometry.camera_files import (
        cameras_json,
        cameras_tensors,
        read_cameras,
        write_cameras,
        write_transforms,
    )
    from holoflow.geometry.config import PcdSetParams
    from holoflow.geometry.pcdset import pcd_set
    from holoflow.geometry.rigs import SUPPLEMENTARY
    from holoflow.io.exr import write_rgb
    from holoflow.io.ply import read_points

    cfg = job.config(PcdSetParams)
    device = torch.device(job.device)
    xyz, rgb8 = read_points(job.input_file("cloud", "ps.ply"))
    base = read_cameras(job.input_file("cameras", "cameras.json"))
    K, base_V = (t.to(device) for t in cameras_tensors(base))  # float64
    W, H = int(base["width"]), int(base["height"])
    srgb = torch.from_numpy(rgb8).to(device).float() / 255.0  # [N, 3]
    linear = kornia.color.rgb_to_linear_rgb(srgb.T[:, :, None])[:, :, 0].T  # [N, 3] linear light
    pcd = pcd_set(torch.from_numpy(xyz).to(device).double(), linear, K, base_V, W, H, cfg)
    n = len(pcd.viewmats)
    names, files, bases, missing, unseen = [], [], [], [], []
    for j in range(n):
        b, k = divmod(j, 4)
        img, hit, seen = pcd.view(j)
        names.append(f"{base['views'][b]['name']}_{k}")
        files.append(f"views/{names[-1]}.exr")
        bases.append(b)
        missing.append(1.0 - float(hit.mean()))
        unseen.append(1.0 - float(seen.mean()))
        write_rgb(
            job.output(files[-1]),
            img.float().cpu().numpy(),
            {"holoflow.stage": "pcd_set", "holoflow.camera": names[-1], "holoflow.side": SUPPLEMENTARY[k]},
            A=hit.float().cpu().numpy(),
            seen=seen.float().cpu().numpy(),
        )
        job.progress(j + 1, n, "views")
    cams = cameras_json(K, pcd.viewmats, W, H, names, files, kinds=["supplementary"] * n, bases=bases)
    write_cameras(job.output("cameras.json"), cams)
    write_transforms(job.output("transforms.json"), cams)
    job.meta(
        views=n,
        points=int(len(xyz)),
        edge_points_dropped=len(pcd.edge_points),
        missing_fraction=round(sum(missing) / len(missing), 6),
        unseen_fraction=round(sum(unseen) / len(unseen), 6),
        splat_radius=cfg.splat_radius if cfg.splat_radius > 0 else "auto",
        median_depth=[round(m, 4) for m in pcd.medians],
    )
    return 0


if __name__ == "__main__":
    from holoflow.stage import run_main

    run_main(main, "pcd_set")
