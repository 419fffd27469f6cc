"""stylize: base panorama -> lineart (the paper's control signal) -> stylized panorama.

Writes pano.exr (R,G,B linear) and lineart.exr (Y in [0, 1], 1 = line), both at the stage's size.
Engines: ``classical`` (default, offline): wrap-aware XDoG lineart, then the OpenCV style named by
the prompt's style words (holoflow.imageops.styles; ``style`` param: auto | none | a style name); no
style word -> passthrough. ``controlnet_lineart``: SD 1.5 + ControlNet Lineart conditioned on the
lineart of the base panorama (holoflow.engines.controlnet_lineart).
"""
from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.imageops.lineart import lineart
    from holoflow.imageops.resize import lanczos_resize
    from holoflow.imageops.styles import STYLE_WORDS, style_from_prompt, stylize
    from holoflow.io.exr import read_rgb, write_exr, write_rgb

    p = job.params
    width, height = job.image_size()
    base = read_rgb(job.input_file("pano", "pano.exr"))                               # [H, W, 3] linear
    attrs = {"holoflow.stage": "stylize", "holoflow.engine": job.engine}
    if job.engine == "classical":
        style = str(p.get("style", "auto"))
        if style == "auto":
            style = style_from_prompt(job.prompt)
        elif style == "none":
            style = None
        elif style not in set(STYLE_WORDS.values()):
            raise ValueError(f"unknown style {style!r}; use auto, none or one of {sorted(set(STYLE_WORDS.values()))}")
        pano = base if base.shape[:2] == (height, width) else lanczos_resize(base, width, height)
        lines = lineart(pano)
        out = pano if style is None else stylize(pano, lines, style)
        attrs["holoflow.style"] = style or "none"
        job.meta(engine=job.engine, style=style or "none (passthrough)")
    elif job.engine == "controlnet_lineart":
        from holoflow.engines.controlnet_lineart import stylize as cn_stylize

        base_lines = lineart(base)
        out = cn_stylize(base, base_lines, job.prompt, width, height, int(p["steps"]), float(p["strength"]),
                         job.seed, str(p.get("model", "")), str(p.get("controlnet", "")), job.device, job.progress)
        lines = lanczos_resize(base_lines, width, height).clip(0.0, 1.0)
        job.meta(engine=job.engine, model=str(p.get("model", "")) or "default",
                 controlnet=str(p.get("controlnet", "")) or "default")
    else:
        raise ValueError(f"unknown engine {job.engine!r} (classical | controlnet_lineart)")
    write_rgb(job.output("pano.exr"), out, attrs)
    write_exr(job.output("lineart.exr"), {"Y": lines}, {**attrs, "holoflow.meaning": "lineart, 1 = line"})
    return 0


if __name__ == "__main__":
    run_main(main, "stylize")
