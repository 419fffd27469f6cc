"""The classical (weight-free) engines of stylize, upscale and detail, at their stages' engine
signatures (holoflow/imageops/config.py). Panoramas are linear RGB [H, W, 3]."""

from __future__ import annotations

import numpy as np

from holoflow.imageops.config import DetailParams, StylizeParams, UpscaleParams


def stylize_classical(base: np.ndarray, prompt: str, cfg: StylizeParams, seed: int, device: str, progress):
    """Wrap-aware XDoG lineart, then the OpenCV style cfg.style names (auto: the prompt's style words;
    none or no style word: passthrough). Returns (pano, lineart [h, w], attrs, meta) at cfg's size, or
    the input's own when it is wider (``keep_size``: up to cfg.max_width)."""
    from holoflow.imageops.lineart import lineart
    from holoflow.imageops.photo import keep_size
    from holoflow.imageops.resize import lanczos_resize
    from holoflow.imageops.styles import requested_style, stylize

    style = requested_style(prompt, cfg.style)
    size = keep_size(base.shape, cfg.width, cfg.height, cfg.max_width)
    pano = base if base.shape[:2] == size else lanczos_resize(base, size[1], size[0])
    lines = lineart(pano)
    out = pano if style is None else stylize(pano, lines, style)
    return out, lines, {"holoflow.style": style or "none"}, {"style": style or "none (passthrough)"}


def upscale_lanczos(pano: np.ndarray, prompt: str, cfg: UpscaleParams, seed: int, device: str, progress):
    """Wrap-aware Lanczos-3 to cfg.width x cfg.height, or the input's own size when it is wider
    (``keep_size``: up to cfg.max_width). Returns (pano, meta)."""
    from holoflow.imageops.photo import keep_size
    from holoflow.imageops.resize import lanczos_resize

    h, w = keep_size(pano.shape, cfg.width, cfg.height, cfg.max_width)
    return lanczos_resize(pano, w, h), {"scale": round(w / pano.shape[1], 4)}


def detail_classical(pano: np.ndarray, prompt: str, cfg: DetailParams, seed: int, device: str, progress):
    """Wrap-aware Lanczos to cfg's size (or the input's own when it is wider, ``keep_size``), then the
    guided-filter detail boost by cfg.strength. Returns (pano, meta)."""
    from holoflow.imageops.detail import enhance_detail
    from holoflow.imageops.photo import keep_size
    from holoflow.imageops.resize import lanczos_resize

    h, w = keep_size(pano.shape, cfg.width, cfg.height, cfg.max_width)
    if pano.shape[:2] != (h, w):
        pano = lanczos_resize(pano, w, h)
    return enhance_detail(pano, cfg.strength), {"strength": cfg.strength}
