"""PNG previews (sRGB, 8-bit) of linear images, for docs and people; never an artifact the pipeline reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from holoflow.imageops.color import linear_to_uint8
from holoflow.io.image import write_png


def write_preview(path: str | Path, image: np.ndarray, width: int | None = None, linear: bool = True) -> None:
    """Write [H, W, 3] (linear RGB, or sRGB floats when ``linear`` is False) or [H, W] (grey, [0, 1]) as
    a PNG (holoflow.io.image.write_png), area-downscaled to ``width`` pixels wide when given.
    Non-finite values are written as 0."""
    import cv2

    img = np.nan_to_num(np.asarray(image, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
        linear = False
    if width is not None and width < img.shape[1]:
        height = max(1, round(img.shape[0] * width / img.shape[1]))
        img = cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA)
    out = linear_to_uint8(img) if linear else np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_png(path, out)
