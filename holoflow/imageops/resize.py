"""Wrap-aware Lanczos-3 resize of panoramas: separable, as two sparse matrix products (the fast path),
with OpenImageIO's 2-D lanczos3 resize as the reference (``lanczos_resize_reference``)."""

from __future__ import annotations

import math

import numpy as np

from holoflow.imageops.wrap import crop_columns, pad_columns

LANCZOS_PAD = (
    8  # reference path: source columns of circular padding (Lanczos-3 reaches 3 px; 8 leaves room when shrinking)
)


def lanczos_weights(n_in: int, n_out: int, wrap: bool):
    """The 1-D Lanczos-3 resampling matrix [n_out, n_in] (scipy CSR, float64 rows summing to 1).

    Output sample j sits at source coordinate x = (j + 0.5) n_in / n_out - 0.5 (pixel centres); when
    shrinking the kernel is stretched by n_in / n_out (antialiased), when enlarging it is the plain
    3-lobe kernel. Taps beyond the ends wrap around (``wrap``: longitude) or repeat the end sample."""
    from scipy.sparse import csr_matrix

    scale = n_in / n_out
    stretch = max(scale, 1.0)
    reach = 3.0 * stretch  # source pixels either side
    x = (np.arange(n_out) + 0.5) * scale - 0.5  # [n_out]
    taps = int(math.ceil(2 * reach)) + 1
    k = np.floor(x - reach).astype(np.int64)[:, None] + 1 + np.arange(taps)[None, :]  # [n_out, taps]
    d = (k - x[:, None]) / stretch
    w = np.where(np.abs(d) < 3.0, np.sinc(d) * np.sinc(d / 3.0), 0.0)
    w /= w.sum(axis=1, keepdims=True)
    k = np.mod(k, n_in) if wrap else np.clip(k, 0, n_in - 1)
    rows = np.repeat(np.arange(n_out), taps)
    return csr_matrix((w.ravel(), (rows, k.ravel())), shape=(n_out, n_in))  # duplicates (clipped taps) summed


def lanczos_resize(img: np.ndarray, width: int, height: int, wrap: bool = True) -> np.ndarray:
    """Resize [H, W, C] (or [H, W]) float32 to [height, width, C] with a separable Lanczos-3 filter
    (``lanczos_weights``; rows first, then columns, float32 products).

    ``wrap``: columns wrap around (the seam of an equirect panorama), rows repeat the edge row. Matches
    ``lanczos_resize_reference`` (OpenImageIO) to ~1e-4 and costs a tap count per axis instead of its
    square (figures: docs/panorama.md)."""
    img = np.asarray(img, dtype=np.float32)
    squeeze = img.ndim == 2
    if squeeze:
        img = img[..., None]
    h, w, c = img.shape
    if width < 1 or height < 1:
        raise ValueError(f"lanczos_resize: bad size {width}x{height}")
    if (h, w) == (height, width):
        return img[..., 0].copy() if squeeze else img.copy()
    rows = lanczos_weights(h, height, False).astype(np.float32)
    cols = lanczos_weights(w, width, wrap).astype(np.float32)
    out = (rows @ img.reshape(h, w * c)).reshape(height, w, c)  # [height, w, c]
    out = (cols @ out.transpose(1, 0, 2).reshape(w, height * c)).reshape(width, height, c)
    res = np.ascontiguousarray(out.transpose(1, 0, 2), dtype=np.float32)  # [height, width, c]
    return res[..., 0] if squeeze else res


def lanczos_resize_reference(img: np.ndarray, width: int, height: int, wrap: bool = True) -> np.ndarray:
    """The reference for ``lanczos_resize``: OpenImageIO's 2-D lanczos3 resize of [H, W, C] float32.

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
    src_pad = dst_pad = 0
    if wrap:
        step = w // math.gcd(w, width)  # source columns per whole output column count
        src_pad = step * math.ceil(max(LANCZOS_PAD, 3 * w / width) / step)
        dst_pad = src_pad * width // w
        img = pad_columns(img, src_pad)
    buf = oiio.ImageBuf(img)
    roi = oiio.ROI(0, width + 2 * dst_pad, 0, height, 0, 1, 0, c)
    out = oiio.ImageBufAlgo.resize(buf, filtername="lanczos3", roi=roi)
    if out.has_error:
        raise RuntimeError(f"OpenImageIO resize failed: {out.geterror()}")
    res = crop_columns(np.asarray(out.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(height, -1, c), dst_pad)
    return res[..., 0] if squeeze else res
