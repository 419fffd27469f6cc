"""base_pano: text prompt -> equirectangular panorama (pano.exr; R,G,B linear, Z = radial depth when known).

Engines (holoflow.scene.config.BasePanoParams.ENGINES): ``procedural`` (default, offline): the prompt's
words build a Scene (holoflow.scene) that is ray-cast to the panorama; Z holds the exact radial depth
(+inf for sky) and scene.json the scene, so later stages can render truth from any camera.
``diffusion360``: the paper's Diffusion360 base model with circular latent blending
(holoflow.networks.diffusion360); no depth.
"""

from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.io.exr import write_rgb
    from holoflow.scene.config import BasePanoParams

    cfg = job.config(BasePanoParams).sized_for(job.engine)
    pano = BasePanoParams.ENGINES.get(job.engine)(job.prompt, cfg, job.seed, job.device, job.progress)
    depth = {} if pano.depth is None else {"Z": pano.depth}
    write_rgb(
        job.output("pano.exr"),
        pano.rgb,
        {"holoflow.stage": "base_pano", "holoflow.engine": job.engine, **pano.attrs},
        **depth,
    )
    for name, text in pano.files.items():
        job.output(name).write_text(text)
    job.meta(engine=job.engine, **pano.meta)
    return 0


if __name__ == "__main__":
    run_main(main, "base_pano")
