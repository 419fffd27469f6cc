"""Circular blending for latent diffusion on equirectangular panoramas (shared by the SD engines).

A latent of ``w`` columns covers 360 deg of longitude. The denoiser (a UNet with zero padding) does
not know that column ``w-1`` neighbours column 0, so it is run on an EXTENDED latent of ``w + k``
columns whose last ``k`` columns repeat the first ``k`` (the same longitudes, seen again after the
seam). Then:

1. the initial noise is periodic: columns ``w..w+k-1`` are copies of ``0..k-1``;
2. after every denoising step (``callback_on_step_end``) the two copies of the overlap are
   cross-faded and written back to both places: for ``j`` in ``0..k-1``, with
   ``t_j = (j + 0.5) / k``, ``v_j = (1 - t_j) * x[w + j] + t_j * x[j]``; near the image's left
   border (``j`` small) the right copy, which the UNet saw in the interior, wins, and near the
   right border the left copy wins;
3. the result is cropped to the first ``w`` columns, so column ``w-1`` and column 0 (= ``w``) are
   neighbours the UNet produced side by side: no seam at +-180 deg;
4. the VAE decodes the cropped latent with ``k`` columns of wrap padding on both sides, cropped
   after, so the decoder also sees the true neighbours across the seam.

``k`` is about 1/16 of the width (at least 2 latent columns, rounded so that ``w + k`` is a
multiple of 8): 8 latent columns = 64 px = 22.5 deg at 1024 px wide.
"""

from __future__ import annotations

import math

from holoflow.networks.common import report
from holoflow.stage import Progress

NEGATIVE_PROMPT = "blur, worst quality, low quality, watermark, text, logo, username, seam, border, frame, collage"
SCHEDULERS = ("unipc", "euler_a", "model")


def overlap_columns(w: int, frac: float = 1 / 16, min_cols: int = 2, align: int = 8) -> int:
    """Latent columns ``k`` repeated after the seam for a latent ``w`` columns wide."""
    k = max(min_cols, math.ceil(w * frac))
    return min(math.ceil((w + k) / align) * align - w, max(w, min_cols))


def extend_periodic(x, k: int):
    """``[..., w]`` -> ``[..., w + k]``: the first ``k`` columns repeated after the last."""
    import torch

    return torch.cat([x, x[..., :k]], dim=-1)


def blend_overlap(x, k: int):
    """Cross-fade the two copies of the overlap of an extended latent ``[B, C, h, w + k]`` (in place).

    After this, ``x[..., w + j] == x[..., j]`` for ``j < k``; the weight on the right copy falls
    linearly from ``1 - 0.5/k`` at ``j = 0`` to ``0.5/k`` at ``j = k - 1``.
    """
    import torch

    w = x.shape[-1] - k
    t = (torch.arange(k, device=x.device, dtype=torch.float32) + 0.5) / k  # [k]
    t = t.to(x.dtype)
    v = (1 - t) * x[..., w:] + t * x[..., :k]  # [B, C, h, k]
    x[..., :k] = v
    x[..., w:] = v
    return x


def step_callback(k: int, total: int, progress: Progress, what: str = "steps"):
    """``callback_on_step_end`` that blends the overlap after every step and reports progress."""

    def callback(pipe, i, t, kwargs):
        kwargs["latents"] = blend_overlap(kwargs["latents"], k)
        report(progress, i + 1, total, what)
        return kwargs

    return callback


def initial_noise(seed: int, shape: tuple[int, ...], k: int, device, dtype):
    """Seeded standard normal latent ``shape = (B, C, h, w)`` extended periodically to ``w + k``.

    Drawn on the CPU so a seed gives the same noise on every device.
    """
    import torch

    g = torch.Generator("cpu").manual_seed(int(seed))
    noise = torch.randn(shape, generator=g, dtype=torch.float32)
    return extend_periodic(noise, k).to(device=device, dtype=dtype)


def decode_periodic(vae, latents, pad: int):
    """VAE-decode ``latents [B, C, h, w]`` with ``pad`` columns of wrap padding -> sRGB ``[B, 3, H, W]``."""
    import torch

    w = latents.shape[-1]
    p = min(pad, w)
    x = torch.cat([latents[..., w - p :], latents, latents[..., :p]], dim=-1)
    x = x / vae.config.scaling_factor
    if getattr(vae.config, "shift_factor", None):
        x = x + vae.config.shift_factor
    with torch.inference_mode():
        img = vae.decode(x.to(vae.dtype)).sample  # [B, 3, H, W + 2ps]
    s = img.shape[-1] // x.shape[-1]
    return (img[..., p * s : (p + w) * s].float() / 2 + 0.5).clamp(0, 1)


def latent_grid(width: int, height: int, vae_scale: int) -> tuple[int, int]:
    """Latent (h, w) for a panorama of ``width x height`` px: rounded up so pixel sizes are % 8."""
    align = max(1, 8 // vae_scale)
    h = math.ceil(height / vae_scale / align) * align
    w = math.ceil(width / vae_scale / align) * align
    return h, w


def set_scheduler(pipe, name: str) -> None:
    """``unipc`` (deterministic multistep, default), ``euler_a`` (Diffusion360's base sampler;
    ancestral noise makes the overlap copies diverge more between blends), or ``model`` (keep)."""
    from diffusers import EulerAncestralDiscreteScheduler, UniPCMultistepScheduler

    if name not in SCHEDULERS:
        raise ValueError(f"scheduler must be one of {SCHEDULERS}, got {name!r}")
    if name == "unipc":
        pipe.scheduler = UniPCMultistepScheduler.from_config(pipe.scheduler.config)
    elif name == "euler_a":
        pipe.scheduler = EulerAncestralDiscreteScheduler.from_config(pipe.scheduler.config)


def load_sd(kind: str, base, controlnet, device, scheduler: str = "unipc"):
    """A diffusers SD 1.x pipeline from local folders: ``kind`` in {"txt2img", "controlnet",
    "controlnet_img2img"}. No safety checker / feature extractor is loaded (none is needed to
    denoise, and their image processor would pull in torchvision)."""
    import torch
    from diffusers import (
        ControlNetModel,
        StableDiffusionControlNetImg2ImgPipeline,
        StableDiffusionControlNetPipeline,
        StableDiffusionPipeline,
    )
    from diffusers.utils import logging as dlog

    dlog.set_verbosity_error()
    dtype = torch.float16 if device.type == "cuda" else torch.float32
    common = dict(
        safety_checker=None, feature_extractor=None, requires_safety_checker=False, dtype=dtype, local_files_only=True
    )
    if kind == "txt2img":
        pipe = StableDiffusionPipeline.from_pretrained(str(base), **common)
    else:
        cnet = ControlNetModel.from_pretrained(str(controlnet), dtype=dtype, local_files_only=True)
        cls = StableDiffusionControlNetPipeline if kind == "controlnet" else StableDiffusionControlNetImg2ImgPipeline
        pipe = cls.from_pretrained(str(base), controlnet=cnet, **common)
    set_scheduler(pipe, scheduler)
    pipe.set_progress_bar_config(disable=True)
    return pipe.to(device)
