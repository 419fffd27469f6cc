"""transfer_opt: Transfer Optimization. Fresh Gaussians from P_f, trained on the PANO and INP sets
together (with ``depth_weight`` > 0 the PANO set's views also on metric_align's depth), then
(``fit_iters`` > 0) their colours fitted to the detail panorama's views at the base cameras at the
viewing size ``fit_size`` (0: a quarter of P_f's width, holoflow/recon/optimize.py ``cloud_fit_size``;
holoflow/recon/colour_fit.py); writes the final scene (scene.ply, 3DGS layout), train_log.json and
sRGB previews rendered from inside the scene (previews/look_around.png strip, previews/look_around.gif)."""

from __future__ import annotations

import time


def main() -> int:
    from holoflow.stage import Job

    job = Job.from_argv()
    job.torch_threads(1)  # small tensors here; the numba kernels use job.cpus threads
    from holoflow.io.exr import read_exr, read_rgb
    from holoflow.io.ply import read_points
    from holoflow.recon.colour_fit import fit_colours, polar_weights, viewing_views
    from holoflow.recon.config import TransferOptParams
    from holoflow.recon.optimize import cloud_fit_size, cloud_footprint, save_result, transfer_optimize
    from holoflow.recon.preview import write_previews
    from holoflow.recon.views import add_depth_targets, load_view_set

    cfg = job.config(TransferOptParams)
    xyz, rgb = read_points(job.input_file("cloud", "pf.ply"))
    pano_views, cams = load_view_set(job.input("pano"), alpha_is_mask=False)
    if cfg.depth_weight > 0:  # the PANO set's views learn the metric depth too
        add_depth_targets(pano_views, read_exr(job.input_file("depth", "depth.exr"))[0]["Z"])
    inp_views, _ = load_view_set(job.input("inp"), alpha_is_mask=False) if cfg.use_inp else ([], None)
    model, log = transfer_optimize(
        xyz,
        rgb,
        pano_views,
        inp_views,
        cfg,
        job.engine,
        job.seed,
        progress=job.progress,
        device=job.device,
        footprint=cloud_footprint(job.input("cloud"), cfg),
    )
    if cfg.fit_iters > 0:
        import torch

        job.torch_threads(job.cpus)  # the fit's views and residuals are large tensors
        pano = torch.from_numpy(read_rgb(job.input_file("detail", "pano.exr"))).permute(2, 0, 1)  # [3, H, W]
        t0 = time.perf_counter()
        size = cloud_fit_size(job.input("cloud"), cfg.fit_size)
        views = viewing_views(pano, cams, size)
        log["colour_fit"] = fit_colours(
            model,
            views,
            cfg.fit_iters,
            job.engine,
            cfg.fit_relax,
            progress=job.progress,
            weights=polar_weights(views, cfg.fit_polar_weight),
            max_colour=cfg.fit_max_colour,
        )
        log["colour_fit"]["size"] = size
        log["seconds"]["colour_fit"] = round(time.perf_counter() - t0, 3)
        job.torch_threads(1)
    save_result(job, model, log, pano_views, "scene.ply")  # G1, its fit and train_log.json
    write_previews(model, job.output_dir / "previews", pano_views[0]["K"], job.engine, size=cfg.preview_size)
    return 0


if __name__ == "__main__":
    from holoflow.stage import run_main

    run_main(main, "transfer_opt")
