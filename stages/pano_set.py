"""pano_set: the panorama seen by the base cameras (the PANO set).

``cameras`` base cameras of layout ``rig`` (holoflow.geometry.rigs: poles + Fibonacci spiral), all at
the panorama centre, ``size`` x ``size`` pixels, horizontal field of view ``fov_deg`` (paper: 38
cameras, 512 px, focal 582.69 px = 47.43 deg, as LucidDreamer). Views are resampled antialiased and
wrap-aware (holoflow.geometry.sampling.equirect_to_pinhole). Writes views/NNN.exr (R,G,B linear),
cameras.json (docs/artifacts.md) and a nerfstudio transforms.json. Warns (and records in @meta) when
the rig leaves part of the sphere unseen.
"""

from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    import torch

    from holoflow.geometry.camera import intrinsics_from_fov
    from holoflow.geometry.camera_files import cameras_json, write_cameras, write_transforms
    from holoflow.geometry.config import PanoSetParams
    from holoflow.geometry.rigs import base_rig, rig_coverage
    from holoflow.geometry.sampling import equirect_to_pinhole_batches
    from holoflow.io.exr import read_rgb, write_rgb

    cfg = job.config(PanoSetParams)
    count, size, fov = cfg.cameras, cfg.size, cfg.fov_deg
    device = torch.device(job.device)
    pano = torch.from_numpy(read_rgb(job.input_file("pano", "pano.exr"))).to(device).permute(2, 0, 1)  # [3, H, W]
    K = intrinsics_from_fov(fov, size, size, device=device, dtype=torch.float32)
    viewmats = base_rig(count, cfg.rig, device=device, dtype=torch.float32)  # [M, 4, 4]
    names = [f"{i:03d}" for i in range(count)]
    files = [f"views/{n}.exr" for n in names]
    for start, views in equirect_to_pinhole_batches(pano, K, viewmats, size, size):  # [n, 3, size, size]
        for i, view in enumerate(views, start):
            write_rgb(
                job.output(files[i]),
                view.permute(1, 2, 0).cpu().numpy(),
                {"holoflow.stage": "pano_set", "holoflow.camera": names[i]},
            )
        job.progress(start + len(views), count, "views")
    cams = cameras_json(K, viewmats, size, size, names, files)
    write_cameras(job.output("cameras.json"), cams)
    write_transforms(job.output("transforms.json"), cams)
    cover = rig_coverage(K.double(), viewmats.double(), size, size, 256, 512)
    unseen = float((cover == 0).double().mean())
    if unseen > 0:
        print(
            f"pano_set: warning: {100 * unseen:.2f}% of the sphere is seen by no base camera "
            f"({count} cameras at {fov} deg); raise cameras or fov_deg"
        )
    job.meta(
        cameras=count,
        size=size,
        fov_deg=fov,
        focal_px=round(float(K[0, 0]), 4),
        unseen_fraction=unseen,
        max_overlap=int(cover.max()),
    )
    return 0


if __name__ == "__main__":
    run_main(main, "pano_set")
