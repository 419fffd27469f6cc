"""detail: panorama -> detail-refined panorama at the stage's width x height (pano.exr, R,G,B linear).

Engines (holoflow.imageops.config.DetailParams.ENGINES): ``classical`` (default, offline): wrap-aware
Lanczos to the stage size, then a guided-filter base / detail split with the detail boosted by
``strength`` (holoflow.imageops.detail). ``controlnet_tile``: ControlNet Tile img2img on overlapping
tiles with circular blending across the seam (holoflow.networks.controlnet_tile). A user's photo that
nothing styled or resized passes through unchanged with any engine (holoflow/imageops/photo.py); an
input wider than the stage's size keeps its own (up to ``max_width``).
"""

from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.imageops.config import DetailParams
    from holoflow.imageops.photo import provenance, same_pixels, unaltered
    from holoflow.io.exr import read_rgb_attrs, write_rgb

    cfg = job.config(DetailParams)
    path = job.input_file("pano", "pano.exr")
    pano, src = read_rgb_attrs(path)  # [H, W, 3] linear, header
    if unaltered(src):  # nothing to restore
        out, meta = pano, {"passthrough": "user's photo, not styled or resized"}
    else:
        out, meta = DetailParams.ENGINES.get(job.engine)(pano, job.prompt, cfg, job.seed, job.device, job.progress)
    job.meta(engine=job.engine, max_width=cfg.max_width, **meta)
    write_rgb(
        job.output("pano.exr"),
        out,
        {
            "holoflow.stage": "detail",
            "holoflow.engine": job.engine,
            **provenance(src, same_pixels(out, pano), cfg.max_width),
        },
    )
    return 0


if __name__ == "__main__":
    run_main(main, "detail")
