"""Stylized panorama: ControlNet Lineart v1.1 (SD 1.5) conditioned on the base panorama's lineart.

The paper's style step: the lineart keeps the equirectangular geometry, the prompt brings the
style. Text-to-image with the lineart as control, with the same circular blending as the base
(holoflow/networks/circular.py); the control image is extended with the same wrapped columns as
the latent. Defaults: SD 1.5 (``stable-diffusion-v1-5/stable-diffusion-v1-5``) and
``lllyasviel/control_v11p_sd15_lineart``.
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


def stylize(
    pano: np.ndarray,
    lineart: np.ndarray,
    prompt: str,
    width: int = 1536,
    height: int = 768,
    steps: int = 20,
    strength: float = 1.0,
    seed: int = 0,
    model: str = "",
    controlnet: str = "",
    device: str = "cpu",
    progress: Progress = None,
    *,
    guidance: float = 7.5,
    negative_prompt: str = NEGATIVE_PROMPT,
    scheduler: str = "unipc",
) -> np.ndarray:
    """Stylized panorama, linear RGB ``[height, width, 3]`` in [0, 1].

    lineart: ``[H, W]`` in [0, 1], 1 = line (white lines on black, as ControlNet Lineart was
    trained). strength: ControlNet conditioning scale. pano: the base panorama; this txt2img path
    takes its geometry from the lineart alone and only checks that the two have the same size.
    """
    import torch

    if pano.shape[:2] != lineart.shape[:2]:
        raise ValueError(f"lineart {lineart.shape[:2]} and panorama {pano.shape[:2]} differ in size")
    base = resolve(model, "sd15", "stylize.model")
    cnet = resolve(controlnet, "controlnet_lineart", "stylize.controlnet")
    dev = torch_device(device)
    pipe = load_sd("controlnet", base, cnet, dev, scheduler)
    s = pipe.vae_scale_factor
    h, w = latent_grid(width, height, s)
    k = overlap_columns(w)
    line = torch.from_numpy(np.ascontiguousarray(lineart, np.float32))[None, None].clamp(0, 1)
    line = resize_wrap(line, h * s, w * s).clamp(0, 1).expand(1, 3, h * s, w * s)  # [1, 3, H, W]
    control = torch.cat([line, line[..., : k * s]], dim=-1).to(dev, pipe.unet.dtype)  # [1, 3, H, W + ks]
    latents = initial_noise(seed, (1, pipe.unet.config.in_channels, h, w), k, dev, pipe.unet.dtype)
    with torch.inference_mode():
        ext = pipe(
            prompt=prompt,
            negative_prompt=negative_prompt,
            image=control,
            height=h * s,
            width=(w + k) * s,
            num_inference_steps=steps,
            guidance_scale=guidance,
            controlnet_conditioning_scale=float(strength),
            latents=latents,
            output_type="latent",
            callback_on_step_end=step_callback(k, steps, progress),
            callback_on_step_end_tensor_inputs=["latents"],
        ).images
    img = decode_periodic(pipe.vae, ext[..., :w], pad=k)
    return srgb_to_linear(to_hwc(resize_wrap(img, height, width)), clip=True)


def stylize_engine(base: np.ndarray, prompt: str, cfg, seed: int, device: str, progress: Progress):
    """stylize's ``controlnet_lineart`` engine (holoflow.imageops.config.StylizeParams): the base
    panorama's lineart conditions SD 1.5. Returns (pano, lineart [h, w], attrs, meta) at cfg's size."""
    from holoflow.imageops.lineart import lineart
    from holoflow.imageops.resize import lanczos_resize

    base_lines = lineart(base)
    out = stylize(
        base,
        base_lines,
        prompt,
        cfg.width,
        cfg.height,
        cfg.steps,
        cfg.strength,
        seed,
        cfg.model,
        cfg.controlnet,
        device,
        progress,
    )
    lines = lanczos_resize(base_lines, cfg.width, cfg.height).clip(0.0, 1.0)
    return out, lines, {}, {"model": cfg.model or "default", "controlnet": cfg.controlnet or "default"}
