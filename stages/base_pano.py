"""base_pano: text prompt -> equirectangular panorama (pano.exr; R,G,B linear, Z = radial depth when known).

Engines: ``procedural`` (default, offline): the prompt's words build a Scene (holoflow.scene) that is
ray-cast to the panorama; Z holds the exact radial depth (+inf for sky) and scene.json the scene, so
later stages can render truth from any camera. ``diffusion360``: the paper's Diffusion360 base model
with circular latent blending (holoflow.engines.diffusion360); no depth.
"""
from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.io.exr import write_rgb

    p = job.params
    width, height = job.image_size()
    attrs = {"holoflow.stage": "base_pano", "holoflow.engine": job.engine}
    if job.engine == "procedural":
        import os

        import numpy as np
        import torch

        from holoflow.scene import render_equirect, scene_from_prompt

        # one thread per two cores: on a shared 2-core machine torch's spinning workers cost more than
        # they bring (measured, docs/panorama.md)
        torch.set_num_threads(max(1, (os.cpu_count() or 2) // 2))
        samples = int(p.get("samples", 2))
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        scene = scene_from_prompt(job.prompt, job.seed)
        job.progress(0, 1, "render")
        rgb, depth = render_equirect(scene, width, height, samples, device=job.device)
        job.progress(1, 1, "render")
        write_rgb(job.output("pano.exr"), rgb, {**attrs, "holoflow.depth_kind": "radial",
                                                 "holoflow.scene_kind": scene.kind}, Z=depth)
        job.output("scene.json").write_text(scene.to_json())
        job.meta(engine=job.engine, scene=scene.kind, objects=scene.objects, effects=scene.effects.words,
                 sky_fraction=round(float((~np.isfinite(depth)).mean()), 4))
    elif job.engine == "diffusion360":
        from holoflow.engines.diffusion360 import generate_pano

        rgb = generate_pano(job.prompt, width, height, int(p["steps"]), float(p["guidance"]), job.seed,
                            str(p.get("model", "")), job.device, job.progress)
        write_rgb(job.output("pano.exr"), rgb, attrs)
        job.meta(engine=job.engine, model=str(p.get("model", "")) or "default")
    else:
        raise ValueError(f"unknown engine {job.engine!r} (procedural | diffusion360)")
    return 0


if __name__ == "__main__":
    run_main(main, "base_pano")
