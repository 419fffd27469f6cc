"""inp_set: G0 rendered at every supplementary camera; with ``observed: pcd`` the PCD set's own colour
replaces the render wherever a point landed (its A); missing pixels (rendered alpha below
alpha_threshold and no PCD colour, or no point of P_s landed at all: the PCD set's ``seen`` channel,
or its A where a PCD set made elsewhere has none) filled by the inpainting engine. Writes
views/NNN_K.exr (R,G,B inpainted, linear; A = 1 observed, 0 inpainted), renders/NNN_K.exr (G0's render
before inpainting: R,G,B + A = rendered alpha, for inspection), cameras.json, transforms.json."""

from __future__ import annotations


def main() -> int:
    from holoflow.stage import Job

    job = Job.from_argv()
    job.torch_threads(1)  # small tensors here; the numba kernels use job.cpus threads
    import numpy as np
    import torch

    from holoflow.recon.config import InpSetParams
    from holoflow.recon.inpaint import inpaint_views, missing_mask
    from holoflow.recon.optimize import render_views
    from holoflow.recon.views import load_view_set, write_images, write_view_set
    from holoflow.splat import GaussianModel

    cfg = job.config(InpSetParams)
    model = GaussianModel.load_ply(job.input_file("gaussians", "gaussians.ply")).to(job.device)
    views, cams = load_view_set(job.input("pcd"), alpha_is_mask=True)
    rgb, alpha, depth = render_views(model, views, "auto", with_depth=True)  # [N, H, W, 3], 2 x [N, H, W, 1]
    rgb, alpha, depth = rgb.numpy(), alpha[..., 0].numpy(), depth[..., 0].numpy()
    pcd_seen = torch.stack([v.get("seen", v["mask"]) for v in views]).numpy()  # [N, H, W] 1 = a point landed
    missing = missing_mask(alpha, pcd_seen, cfg.alpha_threshold)
    observed = rgb
    if cfg.observed == "pcd":  # the projection of P_s itself wherever a non-edge point landed
        landed = torch.stack([v["mask"] for v in views]).numpy() > 0.5  # [N, H, W]
        observed = np.where(landed[..., None], torch.stack([v["image"] for v in views]).numpy(), rgb)
        missing &= ~landed
    filled = inpaint_views(observed, missing, job.engine, cfg, job.device, progress=job.progress, depths=depth)
    write_view_set(job.output_dir, cams, filled, (~missing).astype(np.float32), "inp_set")
    write_images(
        job.output_dir, [v["file"].replace("views/", "renders/", 1) for v in cams["views"]], rgb, alpha, "inp_set"
    )
    per_view = missing.reshape(len(missing), -1).mean(1)
    job.meta(
        views=len(views),
        inpainted_views=int((per_view > 0).sum()),
        missing_fraction=float(missing.mean()),
        max_view_missing=float(per_view.max(initial=0.0)),
        engine=job.engine,
        method=cfg.method if job.engine == "opencv" else cfg.model,
    )
    return 0


if __name__ == "__main__":
    from holoflow.stage import run_main

    run_main(main, "inp_set")
