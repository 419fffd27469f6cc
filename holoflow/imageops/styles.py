"""Classical styles for the stylize stage, picked from the prompt's style words.

Each style is an OpenCV filter on the 8-bit sRGB panorama (wrap-padded) that keeps the lineart
geometry: the filters are local and edge-preserving, and the line-based styles draw the lineart itself.
No style word -> ``None`` (passthrough). Vocabulary in ``STYLE_WORDS`` (documented in docs/panorama.md).
"""

from __future__ import annotations

import re

import numpy as np

from holoflow.imageops.color import linear_to_uint8, uint8_to_linear
from holoflow.imageops.wrap import wrap_filter

STYLE_WORDS = {
    "watercolor": "watercolor",
    "watercolour": "watercolor",
    "aquarelle": "watercolor",
    "oil": "oil",
    "impasto": "oil",
    "impressionist": "impressionist",
    "impressionism": "impressionist",
    "pencil": "pencil",
    "sketch": "pencil",
    "graphite": "pencil",
    "charcoal": "pencil",
    "cartoon": "cartoon",
    "anime": "cartoon",
    "comic": "cartoon",
    "manga": "cartoon",
    "cel": "cartoon",
    "ink": "ink",
    "lineart": "ink",
    "pastel": "pastel",
    "pixel": "pixel",
    "pixelated": "pixel",
    "8bit": "pixel",
}


def style_from_prompt(prompt: str) -> str | None:
    """The first style word of the prompt (``STYLE_WORDS``), or None."""
    for word in re.findall(r"[a-z0-9]+", prompt.lower()):
        if word in STYLE_WORDS:
            return STYLE_WORDS[word]
    return None


def requested_style(prompt: str, style: str) -> str | None:
    """The style a stage's ``style`` param asks for: auto = the prompt's first style word (None without
    one), none = None, else the named style (checked)."""
    name = style_from_prompt(prompt) if style == "auto" else None if style == "none" else style
    if name is not None and name not in set(STYLE_WORDS.values()):
        raise ValueError(f"unknown style {name!r}; use auto, none or one of {sorted(set(STYLE_WORDS.values()))}")
    return name


def stylize(rgb: np.ndarray, lines: np.ndarray, style: str) -> np.ndarray:
    """Apply ``style`` to a linear RGB panorama [H, W, 3] with its lineart [H, W] (1 = line) -> linear RGB."""
    fn = _STYLES.get(style)
    if fn is None:
        raise ValueError(f"unknown style {style!r}; known: {sorted(_STYLES)}")
    img = linear_to_uint8(np.clip(rgb, 0.0, 1.0))  # [H, W, 3] sRGB, RGB order
    pad = max(16, img.shape[1] // 16)
    out = wrap_filter(img, pad, fn)
    out = _draw_lines(out, lines, _LINE_WEIGHT.get(style, 0.0))
    return uint8_to_linear(out)


def _draw_lines(img: np.ndarray, lines: np.ndarray, weight: float) -> np.ndarray:
    if weight <= 0:
        return img
    k = 1.0 - weight * np.clip(lines, 0.0, 1.0)[..., None]
    return np.clip(img.astype(np.float32) * k + 0.5, 0, 255).astype(np.uint8)


def _watercolor(img: np.ndarray) -> np.ndarray:
    import cv2

    s = cv2.stylization(img, sigma_s=40, sigma_r=0.35)
    soft = cv2.GaussianBlur(s, (0, 0), 1.2)
    return np.clip(0.8 * soft.astype(np.float32) + 0.2 * 245.0, 0, 255).astype(np.uint8)


def _oil(img: np.ndarray, size_div: int = 110, levels: int = 20) -> np.ndarray:
    """Oil-paint filter: each pixel takes the mean colour of the most frequent luma level in its
    window (the classic histogram-mode filter; written with box filters, so it is deterministic)."""
    import cv2

    size = max(3, img.shape[0] // size_div) | 1
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    q = (gray.astype(np.int32) * levels) // 256  # [H, W] level
    f = img.astype(np.float32)
    best = np.full(gray.shape, -1.0, np.float32)
    out = np.zeros_like(f)
    for level in range(levels):
        m = (q == level).astype(np.float32)
        count = cv2.boxFilter(m, -1, (size, size), normalize=False, borderType=cv2.BORDER_REFLECT)
        better = count > best
        if not better.any():
            continue
        total = cv2.boxFilter(f * m[..., None], -1, (size, size), normalize=False, borderType=cv2.BORDER_REFLECT)
        best = np.where(better, count, best)
        out = np.where(better[..., None], total / np.maximum(count, 1e-6)[..., None], out)
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def _impressionist(img: np.ndarray) -> np.ndarray:
    import cv2

    out = _oil(img, 60)
    hsv = cv2.cvtColor(out, cv2.COLOR_RGB2HSV).astype(np.float32)
    hsv[..., 1] = np.clip(hsv[..., 1] * 1.35, 0, 255)
    return cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2RGB)


def _pencil(img: np.ndarray) -> np.ndarray:
    import cv2

    gray, _ = cv2.pencilSketch(img, sigma_s=40, sigma_r=0.08, shade_factor=0.05)
    return np.repeat(gray[..., None], 3, axis=2)


def _cartoon(img: np.ndarray) -> np.ndarray:
    import cv2

    s = img
    for _ in range(2):
        s = cv2.bilateralFilter(s, 7, 40, 5)
    lab = cv2.cvtColor(s, cv2.COLOR_RGB2Lab)
    lab[..., 0] = (lab[..., 0] // 36) * 36 + 18  # flat tone bands
    return cv2.cvtColor(lab, cv2.COLOR_Lab2RGB)


def _ink(img: np.ndarray) -> np.ndarray:
    import cv2

    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float32)
    wash = 235.0 - 0.25 * (255.0 - gray)  # faint grey wash
    return np.repeat(np.clip(wash, 0, 255).astype(np.uint8)[..., None], 3, axis=2)


def _pastel(img: np.ndarray) -> np.ndarray:
    import cv2

    s = cv2.edgePreservingFilter(img, flags=cv2.RECURS_FILTER, sigma_s=30, sigma_r=0.3)
    hsv = cv2.cvtColor(s, cv2.COLOR_RGB2HSV).astype(np.float32)
    hsv[..., 1] *= 0.55
    hsv[..., 2] = 255.0 * (hsv[..., 2] / 255.0) ** 0.6
    return cv2.cvtColor(np.clip(hsv, 0, 255).astype(np.uint8), cv2.COLOR_HSV2RGB)


def _pixel(img: np.ndarray) -> np.ndarray:
    """Blocks of about width/128 pixels (a divisor of the padded width, so blocks tile the seam)."""
    import cv2

    h, w = img.shape[:2]
    target = max(2, w // 160)
    block = next(b for b in range(target, 0, -1) if w % b == 0 and h % b == 0)
    small = cv2.resize(img, (w // block, h // block), interpolation=cv2.INTER_AREA)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_NEAREST)


_STYLES = {
    "watercolor": _watercolor,
    "oil": _oil,
    "impressionist": _impressionist,
    "pencil": _pencil,
    "cartoon": _cartoon,
    "ink": _ink,
    "pastel": _pastel,
    "pixel": _pixel,
}
# how strongly each style draws the lineart over its result (0 = not at all)
_LINE_WEIGHT = {
    "watercolor": 0.35,
    "pencil": 0.6,
    "cartoon": 0.85,
    "ink": 0.95,
    "pastel": 0.25,
    "oil": 0.15,
    "impressionist": 0.1,
}
