"""detail: panorama -> detail-refined panorama at the stage's width x height (pano.exr, R,G,B linear).

Engines (holoflow.imageops.config.DetailParams.ENGINES): ``classical`` (default, offline): wrap-aware
Lanczos to the stage size, then a guided-filter base / detail split with the detail boosted by
``strength`` (holoflow.imageops.detail). ``controlnet_tile``: ControlNet Tile img2img on overlapping
tiles with circular blending across the seam (holoflow.networks.controlnet_tile).
"""
from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.imageops.config import DetailParams
    from holoflow.io.exr import read_rgb, write_rgb

    cfg = job.config(DetailParams)
    pano = read_rgb(job.input_file("pano", "pano.exr"))                               # [H, W, 3] linear
    out, meta = DetailParams.ENGINES.get(job.engine)(pano, job.prompt, cfg, job.seed, job.device, job.progress)
    job.meta(engine=job.engine, **meta)
    write_rgb(job.output("pano.exr"), out, {"holoflow.stage": "detail", "holoflow.engine": job.engine})
    return 0


if __name__ == "__main__":
    run_main(main, "detail")
