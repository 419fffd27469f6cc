"""stylize: base panorama -> lineart (the paper's control signal) -> stylized panorama.

Writes pano.exr (R,G,B linear) and lineart.exr (Y in [0, 1], 1 = line), both at the stage's size.
Engines (holoflow.imageops.config.StylizeParams.ENGINES): ``classical`` (default, offline): wrap-aware
XDoG lineart, then the OpenCV style named by the prompt's style words (holoflow.imageops.styles;
``style`` param: auto | none | a style name); no style word -> passthrough. ``controlnet_lineart``:
SD 1.5 + ControlNet Lineart conditioned on the lineart of the base panorama
(holoflow.networks.controlnet_lineart). A user's photo (``--use base_pano=PHOTO``) with no style asked
for passes through unchanged with any engine, at its own size up to ``max_width`` (a wider one is
resized to that here, once; holoflow/imageops/photo.py).
"""

from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.imageops.config import StylizeParams
    from holoflow.imageops.photo import provenance, same_pixels, unaltered, unstyled_photo
    from holoflow.imageops.styles import requested_style
    from holoflow.io.exr import read_rgb_attrs, write_exr, write_rgb

    cfg = job.config(StylizeParams)
    path = job.input_file("pano", "pano.exr")
    base, src = read_rgb_attrs(path)  # [H, W, 3] linear, header
    if unaltered(src) and requested_style(job.prompt, cfg.style) is None:  # the photo stays the photo
        out, lines, attrs, meta = unstyled_photo(base, cfg.width, cfg.height, cfg.max_width)
    else:
        out, lines, attrs, meta = StylizeParams.ENGINES.get(job.engine)(
            base, job.prompt, cfg, job.seed, job.device, job.progress
        )
    attrs = {
        "holoflow.stage": "stylize",
        "holoflow.engine": job.engine,
        **attrs,
        **provenance(src, same_pixels(out, base), cfg.max_width),
    }
    meta["max_width"] = cfg.max_width
    job.meta(engine=job.engine, **meta)
    write_rgb(job.output("pano.exr"), out, attrs)
    write_exr(job.output("lineart.exr"), {"Y": lines}, {**attrs, "holoflow.meaning": "lineart, 1 = line"})
    return 0


if __name__ == "__main__":
    run_main(main, "stylize")
