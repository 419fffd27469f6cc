"""stylize: base panorama -> lineart (the paper's control signal) -> stylized panorama.

Writes pano.exr (R,G,B linear) and lineart.exr (Y in [0, 1], 1 = line), both at the stage's size.
Engines (holoflow.imageops.config.StylizeParams.ENGINES): ``classical`` (default, offline): wrap-aware
XDoG lineart, then the OpenCV style named by the prompt's style words (holoflow.imageops.styles;
``style`` param: auto | none | a style name); no style word -> passthrough. ``controlnet_lineart``:
SD 1.5 + ControlNet Lineart conditioned on the lineart of the base panorama
(holoflow.networks.controlnet_lineart).
"""
from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.imageops.config import StylizeParams
    from holoflow.io.exr import read_rgb, write_exr, write_rgb

    cfg = job.config(StylizeParams)
    base = read_rgb(job.input_file("pano", "pano.exr"))                               # [H, W, 3] linear
    out, lines, attrs, meta = StylizeParams.ENGINES.get(job.engine)(base, job.prompt, cfg, job.seed, job.device,
                                                                   job.progress)
    attrs = {"holoflow.stage": "stylize", "holoflow.engine": job.engine, **attrs}
    job.meta(engine=job.engine, **meta)
    write_rgb(job.output("pano.exr"), out, attrs)
    write_exr(job.output("lineart.exr"), {"Y": lines}, {**attrs, "holoflow.meaning": "lineart, 1 = line"})
    return 0


if __name__ == "__main__":
    run_main(main, "stylize")
