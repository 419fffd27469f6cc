"""base_pano's embedded engine: the prompt's words build a procedural Scene, ray-cast to the panorama."""

from __future__ import annotations

from holoflow.scene.config import BasePanoParams, Panorama


def procedural_pano(prompt: str, cfg: BasePanoParams, seed: int, device: str, progress) -> Panorama:
    """The Scene of ``prompt`` (seeded) rendered at cfg.width x cfg.height with cfg.samples^2 samples per
    pixel: exact radial depth (+inf sky) and scene.json, so later stages can render truth anywhere."""
    import numpy as np

    from holoflow.scene import render_equirect, scene_from_prompt

    scene = scene_from_prompt(prompt, seed)
    progress(0, 1, "render")
    rgb, depth = render_equirect(scene, cfg.width, cfg.height, cfg.samples, device=device)
    progress(1, 1, "render")
    return Panorama(
        rgb,
        depth,
        {"holoflow.depth_kind": "radial", "holoflow.scene_kind": scene.kind},
        {"scene.json": scene.to_json()},
        dict(
            scene=scene.kind,
            objects=scene.objects,
            effects=scene.effects.words,
            sky_fraction=round(float((~np.isfinite(depth)).mean()), 4),
        ),
    )
