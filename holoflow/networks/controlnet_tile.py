"""Detail refinement: ControlNet Tile img2img on overlapping tiles, seamless across +-180 deg.

Each tile of the panorama is re-noised to ``strength`` and denoised by SD 1.5 + ControlNet Tile
with the tile itself as control (the model adds detail while keeping the content), as in
Diffusion360's refinement. Defaults: Diffusion360's ``sr-base`` + ``sr-control`` (the base and tile
ControlNet its refinement uses).

Tiling wraps in longitude: tile columns are evenly spaced around the full circle and a tile may
run past column W-1 into column 0, so the seam is inside tiles, never on a tile border; results
are feather-blended (linear ramps over the overlap) and accumulated modulo W. Rows are evenly
spaced from the top to the bottom edge. Tile ``i`` (row-major) is denoised with seed ``seed + i``, alone
or ``batch`` tiles per pipeline call.
"""

from __future__ import annotations

import math

import numpy as np

from holoflow.imageops.color import linear_to_srgb, srgb_to_linear
from holoflow.networks.circular import NEGATIVE_PROMPT, load_sd
from holoflow.networks.common import report, resize_wrap, to_chw, torch_device
from holoflow.networks.weights import resolve
from holoflow.stage import Progress


def tile_grid(width: int, height: int, tile: int, overlap: int) -> tuple[list[int], list[int], int, int]:
    """Tile origins (xs wrapping around the circle, ys within the image) and tile size (tw, th).

    Tiles are ``min(tile, side)`` rounded down to a multiple of 8; neighbours overlap by at least
    ``overlap`` px (horizontally also across the seam). There are always >= 2 tile columns, so the
    seam lies inside a tile even when one tile spans the whole width.
    """
    tw = max(8, min(tile, width) // 8 * 8)
    th = max(8, min(tile, height) // 8 * 8)
    nx = max(2, math.ceil(width / max(tw - overlap, 1)))
    ny = max(1, math.ceil((height - overlap) / max(th - overlap, 1))) if th < height else 1
    xs = [round(i * width / nx) for i in range(nx)]
    ys = [round(i * (height - th) / (ny - 1)) for i in range(ny)] if ny > 1 else [0]
    return xs, ys, tw, th


def _ramp(n: int, overlap: int, lo: bool, hi: bool) -> np.ndarray:
    """Feather weights ``[n]``: rise over ``overlap`` px at a side shared with a neighbour."""
    x = np.arange(n, dtype=np.float64) + 0.5
    r = np.ones(n)
    if overlap > 0 and lo:
        r = np.minimum(r, x / overlap)
    if overlap > 0 and hi:
        r = np.minimum(r, (n - x) / overlap)
    return np.maximum(r, 1e-3)


def refine(
    pano: np.ndarray,
    prompt: str,
    width: int = 6144,
    height: int = 3072,
    strength: float = 0.5,
    tile: int = 512,
    overlap: int = 64,
    steps: int = 20,
    seed: int = 0,
    model: str = "",
    controlnet: str = "",
    device: str = "cpu",
    progress: Progress = None,
    *,
    batch: int = 1,
    guidance: float = 7.5,
    negative_prompt: str = NEGATIVE_PROMPT,
    scheduler: str = "unipc",
) -> np.ndarray:
    """Refined panorama, linear RGB ``[height, width, 3]`` (the input is first resized to that).

    strength: img2img denoising strength in [0, 1] (0 returns the resized input); batch: tiles denoised
    together (each keeps its own seed; batching changes only float rounding).
    """
    import torch

    if not 0.0 <= strength <= 1.0:
        raise ValueError(f"strength must be in [0, 1], got {strength}")
    img = resize_wrap(to_chw(linear_to_srgb(pano, clip=True), "cpu"), height, width)[0].clamp(0, 1)  # [3, H, W] sRGB
    if strength == 0.0 or int(steps * strength) < 1:
        return srgb_to_linear(img.permute(1, 2, 0).numpy(), clip=True)
    base = resolve(model, "tile_base", "detail.model")
    cnet = resolve(controlnet, "controlnet_tile", "detail.controlnet")
    dev = torch_device(device)
    pipe = load_sd("controlnet_img2img", base, cnet, dev, scheduler)
    xs, ys, tw, th = tile_grid(width, height, tile, overlap)
    acc = np.zeros((3, height, width + tw), np.float64)  # unwrapped, folded at the end
    wsum = np.zeros((height, width + tw), np.float64)
    wrapped = torch.cat([img, img[..., :tw]], dim=-1)  # [3, H, W + tw]
    tiles = [(ty, y0, x0) for ty, y0 in enumerate(ys) for x0 in xs]  # tile i = tiles[i], seed + i
    n = len(tiles)
    wx = _ramp(tw, overlap, lo=True, hi=True)
    for start in range(0, n, batch):
        report(progress, start, n, "tiles")
        group = range(start, min(start + batch, n))
        crops = torch.cat(
            [wrapped[None, :, tiles[i][1] : tiles[i][1] + th, tiles[i][2] : tiles[i][2] + tw] for i in group]
        ).to(dev, pipe.unet.dtype)  # [b, 3, th, tw]
        with torch.inference_mode():
            out = pipe(
                prompt=[prompt] * len(group),
                negative_prompt=[negative_prompt] * len(group),
                image=crops,
                control_image=crops,
                height=th,
                width=tw,
                strength=float(strength),
                num_inference_steps=steps,
                guidance_scale=guidance,
                output_type="pt",
                generator=[torch.Generator("cpu").manual_seed(seed + i) for i in group],
            ).images
        for k, i in enumerate(group):  # out [b, 3, th, tw] in [0, 1]
            ty, y0, x0 = tiles[i]
            wt = _ramp(th, overlap, lo=ty > 0, hi=ty < len(ys) - 1)[:, None] * wx[None, :]
            acc[:, y0 : y0 + th, x0 : x0 + tw] += out[k].float().cpu().numpy() * wt
            wsum[y0 : y0 + th, x0 : x0 + tw] += wt
    acc[:, :, :tw] += acc[:, :, width:]
    wsum[:, :tw] += wsum[:, width:]
    out = (acc[:, :, :width] / np.maximum(wsum[:, :width], 1e-12)).astype(np.float32)
    report(progress, n, n, "tiles")
    return srgb_to_linear(np.clip(out.transpose(1, 2, 0), 0, 1), clip=True)


def detail_engine(pano: np.ndarray, prompt: str, cfg, seed: int, device: str, progress: Progress):
    """detail's ``controlnet_tile`` engine (holoflow.imageops.config.DetailParams): (pano, meta)."""
    out = refine(
        pano,
        prompt,
        cfg.width,
        cfg.height,
        cfg.strength,
        cfg.tile,
        cfg.overlap,
        cfg.steps,
        seed,
        cfg.model,
        cfg.controlnet,
        device,
        progress,
        batch=cfg.batch,
    )
    return out, {"model": cfg.model or "default", "controlnet": cfg.controlnet or "default"}
