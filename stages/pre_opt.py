"""pre_opt: Pre Optimization. Gaussians from P_f, trained on the PCD set (loss masked to pixels a
point landed on), then on the PANO set (with ``depth_weight`` > 0 also on metric_align's depth); writes
G0 (gaussians.ply, 3DGS layout) and train_log.json."""

from __future__ import annotations


def main() -> int:
    from holoflow.stage import Job

    job = Job.from_argv()
    job.torch_threads(1)  # small tensors here; the numba kernels use job.cpus threads
    from holoflow.io.exr import read_exr
    from holoflow.io.ply import read_points
    from holoflow.recon.config import PreOptParams
    from holoflow.recon.optimize import cloud_footprint, pre_optimize, save_result
    from holoflow.recon.views import add_depth_targets, load_view_set

    cfg = job.config(PreOptParams)
    xyz, rgb = read_points(job.input_file("cloud", "pf.ply"))
    pcd_views, _ = load_view_set(job.input("pcd"), alpha_is_mask=True)
    pano_views, _ = load_view_set(job.input("pano"), alpha_is_mask=False)
    if cfg.depth_weight > 0:  # the PANO set's views learn the metric depth too
        add_depth_targets(pano_views, read_exr(job.input_file("depth", "depth.exr"))[0]["Z"])
    model, log = pre_optimize(
        xyz,
        rgb,
        pcd_views,
        pano_views,
        cfg,
        job.engine,
        job.seed,
        progress=job.progress,
        device=job.device,
        footprint=cloud_footprint(job.input("cloud"), cfg),
    )
    save_result(job, model, log, pano_views, "gaussians.ply")  # G0, its fit and train_log.json
    return 0


if __name__ == "__main__":
    from holoflow.stage import run_main

    run_main(main, "pre_opt")
