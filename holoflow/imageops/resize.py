"""Wrap-aware Lanczos resize of panoramas through OpenImageIO."""
from __future__ import annotations

import math

import numpy as np

from holoflow.imageops.wrap import crop_columns, pad_columns

LANCZOS_PAD = 8     # source columns of circular padding (Lanczos-3 reaches 3 px; 8 leaves room when shrinking)


def lanczos_resize(img: np.ndarray, width: int, height: int, wrap: bool = True) -> np.ndarray:
    """Resize [H, W, C] float32 to [height, width, C] with OpenImageIO's lanczos3 filter.

    ``wrap``: pad columns circularly first, so the last and first columns stay neighbours. The padding
    is a multiple of W / gcd(W, width) source columns, so it maps to a whole number of output columns
    and the crop lands exactly on the original seam.
    """
    import OpenImageIO as oiio

    img = np.ascontiguousarray(np.asarray(img, dtype=np.float32))
    squeeze = img.ndim == 2
    if squeeze:
        img = img[..., None]
    h, w, c = img.shape
    if width < 1 or height < 1:
        raise ValueError(f"lanczos_resize: bad size {width}x{height}")
    if (h, w) == (height, width):
        return img[..., 0].copy() if squeeze else img.copy()
    src_pad = dst_pad = 0
    if wrap:
        step = w // math.gcd(w, width)                    # source columns per whole output column count
        src_pad = step * math.ceil(max(LANCZOS_PAD, 3 * w / width) / step)
        dst_pad = src_pad * width // w
        img = pad_columns(img, src_pad)
    buf = oiio.ImageBuf(img)
    roi = oiio.ROI(0, width + 2 * dst_pad, 0, height, 0, 1, 0, c)
    out = oiio.ImageBufAlgo.resize(buf, filtername="lanczos3", roi=roi)   # per-pixel: thread-count independent
    if out.has_error:
        raise RuntimeError(f"OpenImageIO resize failed: {out.geterror()}")
    res = crop_columns(np.asarray(out.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(height, -1, c), dst_pad)
    return res[..., 0] if squeeze else res
