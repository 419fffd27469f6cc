"""detail: panorama -> detail-refined panorama at the stage's width x height (pano.exr, R,G,B linear).

Engines: ``classical`` (default, offline): wrap-aware Lanczos to the stage size, then a guided-filter
base / detail split with the detail boosted by ``strength`` (holoflow.imageops.detail).
``controlnet_tile``: ControlNet Tile img2img on overlapping tiles with circular blending across the
seam (holoflow.engines.controlnet_tile).
"""
from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.io.exr import read_rgb, write_rgb

    p = job.params
    width, height = job.image_size()
    strength = float(p["strength"])
    pano = read_rgb(job.input_file("pano", "pano.exr"))                               # [H, W, 3] linear
    if job.engine == "classical":
        from holoflow.imageops.detail import enhance_detail
        from holoflow.imageops.resize import lanczos_resize

        if pano.shape[:2] != (height, width):
            pano = lanczos_resize(pano, width, height)
        out = enhance_detail(pano, strength)
        job.meta(engine=job.engine, strength=strength)
    elif job.engine == "controlnet_tile":
        from holoflow.engines.controlnet_tile import refine

        out = refine(pano, job.prompt, width, height, strength, int(p["tile"]), int(p["overlap"]),
                     int(p["steps"]), job.seed, str(p.get("model", "")), str(p.get("controlnet", "")),
                     job.device, job.progress)
        job.meta(engine=job.engine, model=str(p.get("model", "")) or "default",
                 controlnet=str(p.get("controlnet", "")) or "default")
    else:
        raise ValueError(f"unknown engine {job.engine!r} (classical | controlnet_tile)")
    write_rgb(job.output("pano.exr"), out, {"holoflow.stage": "detail", "holoflow.engine": job.engine})
    return 0


if __name__ == "__main__":
    run_main(main, "detail")
