"""Base panorama: text-to-image latent diffusion with Diffusion360's circular blending.

Any StableDiffusionPipeline-compatible folder works; the default is the Diffusion360 base model
(``archerfmy0831/sd-t2i-360panoimage/sd-base``, DreamBooth-tuned on SUN360 equirectangular images,
trigger token ``<360panorama>``). Circular blending (holoflow/networks/circular.py) runs after every
denoising step, so the panorama is seamless at +-180 deg.
"""

from __future__ import annotations

import numpy as np

from holoflow.imageops.color import srgb_to_linear
from holoflow.networks.circular import (
    NEGATIVE_PROMPT,
    decode_periodic,
    initial_noise,
    latent_grid,
    load_sd,
    overlap_columns,
    step_callback,
)
from holoflow.networks.common import resize_wrap, to_hwc, torch_device
from holoflow.networks.weights import resolve
from holoflow.stage import Progress

TRIGGER = "<360panorama>, "


def generate_pano(
    prompt: str,
    width: int = 1024,
    height: int = 512,
    steps: int = 30,
    guidance: float = 7.5,
    seed: int = 0,
    model: str = "",
    device: str = "cpu",
    progress: Progress = None,
    *,
    negative_prompt: str = NEGATIVE_PROMPT,
    trigger: str = TRIGGER,
    scheduler: str = "unipc",
) -> np.ndarray:
    """Equirectangular panorama for ``prompt``: linear RGB ``[height, width, 3]`` in [0, 1].

    steps: denoising steps; guidance: classifier-free guidance scale; seed: initial noise.
    """
    import torch

    path = resolve(model, "diffusion360", "base_pano.model")
    dev = torch_device(device)
    pipe = load_sd("txt2img", path, None, dev, scheduler)
    s = pipe.vae_scale_factor
    h, w = latent_grid(width, height, s)
    k = overlap_columns(w)
    latents = initial_noise(seed, (1, pipe.unet.config.in_channels, h, w), k, dev, pipe.unet.dtype)
    with torch.inference_mode():
        ext = pipe(
            prompt=trigger + prompt,
            negative_prompt=negative_prompt,
            height=h * s,
            width=(w + k) * s,
            num_inference_steps=steps,
            guidance_scale=guidance,
            latents=latents,
            output_type="latent",
            callback_on_step_end=step_callback(k, steps, progress),
            callback_on_step_end_tensor_inputs=["latents"],
        ).images  # [1, C, h, w + k]
    img = decode_periodic(pipe.vae, ext[..., :w], pad=k)  # [1, 3, h*s, w*s]
    return srgb_to_linear(to_hwc(resize_wrap(img, height, width)), clip=True)


def base_pano_engine(prompt: str, cfg, seed: int, device: str, progress: Progress):
    """base_pano's ``diffusion360`` engine (holoflow.scene.config.BasePanoParams): no depth."""
    from holoflow.scene.config import Panorama

    rgb = generate_pano(prompt, cfg.width, cfg.height, cfg.steps, cfg.guidance, seed, cfg.model, device, progress)
    return Panorama(rgb, meta={"model": cfg.model or "default"})
