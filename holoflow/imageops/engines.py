"""The classical (weight-free) engines of stylize, upscale and detail, at their stages' engine
signatures (holoflow/imageops/config.py). Panoramas are linear RGB [H, W, 3]."""
from __future__ import annotations

import numpy as np

from holoflow.imageops.config import DetailParams, StylizeParams, UpscaleParams


def stylize_classical(base: np.ndarray, prompt: str, cfg: StylizeParams, seed: int, device: str, progress):
    """Wrap-aware XDoG lineart, then the OpenCV style cfg.style names (auto: the prompt's style words;
    none or no style word: passthrough). Returns (pano, lineart [h, w], attrs, meta) at cfg's size."""
    from holoflow.imageops.lineart import lineart
    from holoflow.imageops.resize import lanczos_resize
    from holoflow.imageops.styles import STYLE_WORDS, style_from_prompt, stylize

    style = style_from_prompt(prompt) if cfg.style == "auto" else None if cfg.style == "none" else cfg.style
    if style is not None and style not in set(STYLE_WORDS.values()):
        raise ValueError(f"unknown style {style!r}; use auto, none or one of {sorted(set(STYLE_WORDS.values()))}")
    pano = base if base.shape[:2] == (cfg.height, cfg.width) else lanczos_resize(base, cfg.width, cfg.height)
    lines = lineart(pano)
    out = pano if style is None else stylize(pano, lines, style)
    return out, lines, {"holoflow.style": style or "none"}, {"style": style or "none (passthrough)"}


def upscale_lanczos(pano: np.ndarray, prompt: str, cfg: UpscaleParams, seed: int, device: str, progress):
    """Wrap-aware Lanczos-3 to cfg.width x cfg.height. Returns (pano, meta)."""
    from holoflow.imageops.resize import lanczos_resize

    return lanczos_resize(pano, cfg.width, cfg.height), {"scale": round(cfg.width / pano.shape[1], 4)}


def detail_classical(pano: np.ndarray, prompt: str, cfg: DetailParams, seed: int, device: str, progress):
    """Wrap-aware Lanczos to cfg's size, then the guided-filter detail boost by cfg.strength. Returns
    (pano, meta)."""
    from holoflow.imageops.detail import enhance_detail
    from holoflow.imageops.resize import lanczos_resize

    if pano.shape[:2] != (cfg.height, cfg.width):
        pano = lanczos_resize(pano, cfg.width, cfg.height)
    return enhance_detail(pano, cfg.strength), {"strength": cfg.strength}
