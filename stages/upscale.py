"""upscale: panorama -> panorama at the stage's width x height (pano.exr, R,G,B linear).

Engines (holoflow.imageops.config.UpscaleParams.ENGINES): ``lanczos`` (default, offline): wrap-aware
Lanczos-3 through OpenImageIO (holoflow.imageops.resize). ``realesrgan``: Real-ESRGAN (RRDBNet), tiled,
wrap-padded at the seam (holoflow.networks.realesrgan). An input wider than the stage's size keeps its
own (up to ``max_width``; holoflow/imageops/photo.py).
"""

from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.imageops.config import UpscaleParams
    from holoflow.imageops.photo import provenance, same_pixels
    from holoflow.io.exr import read_rgb_attrs, write_rgb

    cfg = job.config(UpscaleParams)
    path = job.input_file("pano", "pano.exr")
    pano, src = read_rgb_attrs(path)  # [H, W, 3] linear, header
    out, meta = UpscaleParams.ENGINES.get(job.engine)(pano, job.prompt, cfg, job.seed, job.device, job.progress)
    job.meta(engine=job.engine, max_width=cfg.max_width, **meta)
    write_rgb(
        job.output("pano.exr"),
        out,
        {
            "holoflow.stage": "upscale",
            "holoflow.engine": job.engine,
            **provenance(src, same_pixels(out, pano), cfg.max_width),
        },
    )
    return 0


if __name__ == "__main__":
    run_main(main, "upscale")
