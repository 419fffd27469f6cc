"""upscale: panorama -> panorama at the stage's width x height (pano.exr, R,G,B linear).

Engines: ``lanczos`` (default, offline): wrap-aware Lanczos-3 through OpenImageIO
(holoflow.imageops.resize). ``realesrgan``: Real-ESRGAN (RRDBNet), tiled, wrap-padded at the seam
(holoflow.engines.realesrgan).
"""
from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.io.exr import read_rgb, write_rgb

    p = job.params
    width, height = job.image_size()
    pano = read_rgb(job.input_file("pano", "pano.exr"))                               # [H, W, 3] linear
    if job.engine == "lanczos":
        from holoflow.imageops.resize import lanczos_resize

        out = lanczos_resize(pano, width, height)
        job.meta(engine=job.engine, scale=round(width / pano.shape[1], 4))
    elif job.engine == "realesrgan":
        from holoflow.engines.realesrgan import upscale

        out = upscale(pano, width, height, str(p.get("model", "")), int(p["tile"]), job.device, job.progress)
        job.meta(engine=job.engine, model=str(p.get("model", "")) or "default")
    else:
        raise ValueError(f"unknown engine {job.engine!r} (lanczos | realesrgan)")
    write_rgb(job.output("pano.exr"), out, {"holoflow.stage": "upscale", "holoflow.engine": job.engine})
    return 0


if __name__ == "__main__":
    run_main(main, "upscale")
