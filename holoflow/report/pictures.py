"""Pictures for the run report: EXR channels -> 8-bit sRGB images, colour maps, mosaics, curves, and
their encoding as ``data:`` URIs. Pure functions of arrays; nothing here reads the store.

Conventions: images handed around are uint8 [H, W, 3] sRGB, RGB order. EXR colour is linear light
(docs/conventions.md) and goes through the sRGB curve; depth and disparity go through a colour map.
"""

from __future__ import annotations

import base64
import math

import numpy as np

from holoflow.imageops.color import linear_to_uint8, to_uint8

NO_DATA = (40, 40, 40)  # colour of pixels without a value (sky in a depth map, NaN), sRGB uint8


def colour(rgb_linear: np.ndarray) -> np.ndarray:
    """Linear RGB [H, W, 3] -> uint8 sRGB [H, W, 3]; non-finite values become 0."""
    return linear_to_uint8(np.nan_to_num(rgb_linear, nan=0.0, posinf=0.0, neginf=0.0))


def grey(values: np.ndarray) -> np.ndarray:
    """Values [H, W] already in [0, 1] (masks, line art) -> uint8 [H, W, 3], clipped, 1 = white."""
    g = to_uint8(np.nan_to_num(values, nan=0.0, posinf=1.0, neginf=0.0))
    return np.repeat(g[..., None], 3, axis=2)


def robust_range(values: np.ndarray, lo: float = 1.0, hi: float = 99.0) -> tuple[float, float]:
    """(low, high) percentiles of the finite values; (0, 1) when there are none; high > low always."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return 0.0, 1.0
    a, b = (float(x) for x in np.percentile(v, [lo, hi]))
    return a, (b if b > a else a + max(abs(a) * 1e-6, 1e-12))


def colour_map(values: np.ndarray, vmin: float | None = None, vmax: float | None = None) -> np.ndarray:
    """Scalar field [H, W] -> uint8 [H, W, 3] with the turbo map (low = blue, high = red) over
    [vmin, vmax] (default: 1st / 99th percentile); non-finite pixels are ``NO_DATA`` grey."""
    import cv2

    if vmin is None or vmax is None:
        lo, hi = robust_range(values)
        vmin = lo if vmin is None else vmin
        vmax = hi if vmax is None else vmax
    finite = np.isfinite(values)
    t = np.clip((np.where(finite, values, vmin) - vmin) / max(vmax - vmin, 1e-12), 0.0, 1.0)
    bgr = cv2.applyColorMap(to_uint8(t), cv2.COLORMAP_TURBO)  # [H, W, 3] BGR
    out = bgr[..., ::-1].copy()
    out[~finite] = NO_DATA
    return out


def depth_map(depth: np.ndarray) -> np.ndarray:
    """Radial depth [H, W] (metres, +inf = sky) -> uint8 colour map of inverse depth: near = red,
    far = blue, sky = ``NO_DATA``. Inverse depth spreads the colours where the detail is (near)."""
    inv = np.where(np.isfinite(depth) & (depth > 0), 1.0 / np.maximum(depth, 1e-12), np.nan)
    return colour_map(inv)


def fit_width(img: np.ndarray, width: int) -> np.ndarray:
    """Area-downscale uint8 [H, W, 3] to at most ``width`` pixels wide (never upscales)."""
    import cv2

    if img.shape[1] <= width:
        return img
    height = max(1, round(img.shape[0] * width / img.shape[1]))
    return cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA)


def fit_box(img: np.ndarray, side: int) -> np.ndarray:
    """Resize uint8 [H, W, 3] so its longer side is ``side`` (area when shrinking, nearest when
    growing, so tiny views stay crisp)."""
    import cv2

    h, w = img.shape[:2]
    s = side / max(h, w)
    size = (max(1, round(w * s)), max(1, round(h * s)))
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_NEAREST)


def mosaic(
    tiles: list[np.ndarray], cols: int, side: int, gap: int = 2, background: tuple[int, int, int] = (255, 255, 255)
) -> np.ndarray:
    """Tiles (uint8 [h, w, 3], any sizes) fitted into ``side`` x ``side`` cells, row-major in a grid
    of ``cols`` columns with ``gap`` pixels between cells -> uint8 [rows * (side + gap) - gap, ...]."""
    if not tiles:
        raise ValueError("mosaic: no tiles")
    cols = max(1, min(cols, len(tiles)))
    rows = math.ceil(len(tiles) / cols)
    out = np.empty((rows * (side + gap) - gap, cols * (side + gap) - gap, 3), np.uint8)
    out[:] = background
    for i, tile in enumerate(tiles):
        t = fit_box(tile, side)
        r, c = divmod(i, cols)
        y = r * (side + gap) + (side - t.shape[0]) // 2
        x = c * (side + gap) + (side - t.shape[1]) // 2
        out[y : y + t.shape[0], x : x + t.shape[1]] = t
    return out


def encode(img: np.ndarray, fmt: str = "png", quality: int = 88) -> bytes:
    """uint8 [H, W, 3] RGB -> PNG or JPEG bytes."""
    import cv2

    ext, flags = (".jpg", [cv2.IMWRITE_JPEG_QUALITY, quality]) if fmt == "jpeg" else (".png", [])
    ok, buf = cv2.imencode(ext, np.ascontiguousarray(img[..., ::-1]), flags)
    if not ok:
        raise ValueError(f"could not encode a {img.shape} image as {fmt}")
    return buf.tobytes()


def data_uri(data: bytes, mime: str) -> str:
    """``data:`` URI of some bytes (base64)."""
    return f"data:{mime};base64," + base64.b64encode(data).decode("ascii")


def is_flat(img: np.ndarray, levels: int = 32) -> bool:
    """Does uint8 [H, W, 3] use at most ``levels`` distinct colours (masks, charts: PNG stays small
    and exact), rather than continuous tones (photographs, colour maps: JPEG is far smaller)?"""
    flat = img.reshape(-1, 3)[:: max(1, img.shape[0] * img.shape[1] // 65536)]
    packed = (flat[:, 0].astype(np.int32) << 16) | (flat[:, 1].astype(np.int32) << 8) | flat[:, 2]
    return len(np.unique(packed)) <= levels


def image_uri(img: np.ndarray) -> str:
    """uint8 [H, W, 3] -> data URI: PNG for flat pictures (``is_flat``), JPEG for continuous tones."""
    fmt = "png" if is_flat(img) else "jpeg"
    return data_uri(encode(img, fmt), f"image/{fmt}")


def curves_png(
    series: list[dict],
    title: str,
    ylabel: str,
    log_y: bool = False,
    bounds: list[tuple[int, str]] = (),
    size: tuple[float, float] = (6.0, 2.6),
) -> bytes:
    """A line chart as PNG bytes. ``series``: [{"label", "y": [...], "x": [...] (optional)}];
    ``bounds``: (x, label) vertical markers (e.g. where a training phase starts)."""
    import io

    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=100, layout="constrained")
    ax = fig.add_subplot()
    for s in series:
        y = np.asarray(s["y"], dtype=float)
        x = np.asarray(s.get("x", np.arange(len(y))), dtype=float)
        ax.plot(x, y, lw=1.2, label=s["label"])
    for x, label in bounds:
        ax.axvline(x, color="0.6", lw=0.8, ls="--")
        ax.text(x, 1.0, f" {label}", transform=ax.get_xaxis_transform(), va="top", fontsize=8, color="0.35")
    if log_y and all(np.all(np.asarray(s["y"], float) > 0) for s in series):
        ax.set_yscale("log")
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("iteration", fontsize=9)
    ax.set_ylabel(ylabel, fontsize=9)
    ax.tick_params(labelsize=8)
    ax.grid(alpha=0.3)
    if len(series) > 1:
        ax.legend(fontsize=8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
