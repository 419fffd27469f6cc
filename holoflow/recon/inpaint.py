"""The INP set: which pixels of G0's render at a supplementary camera are missing, and how they are filled.

Missing mask (1 = missing), per supplementary view:

    missing = (rendered alpha < alpha_threshold)  OR  (no point of P_s landed: the PCD set's ``seen``)

Why both. Rendered alpha alone misses disocclusions: the PCD phase of pre_opt leaves hole pixels
unsupervised and the PANO phase sees them only from the centre, so G0 is free to put stretched,
opaque Gaussians there (foreground edges smeared into the gap) and alpha is high over wrong content.
The PCD mask alone (the paper's M_ij, taken literally) misses what G0 failed to cover where points did
land, and says nothing about G0. Their union fills every pixel that nothing observed, or that G0 does
not cover. ``seen`` and not the PCD set's A: A also leaves out P_s's occlusion-edge points, and that
test flags every surface seen at a grazing angle (far ground, each horizon); inpainting those pixels
from their far side painted sky over the ground (docs/reconstruction.md). Views whose mask is empty
are passed through un-inpainted.

Engines: ``opencv`` (classical, no weights; ``method`` background = ``background_fill`` then telea
for what it cannot reach, telea | ns via ``cv2.inpaint``, fsr_fast | fsr_best via
``cv2.xphoto.inpaint``) and ``lama`` (``holoflow.networks.lama``). Images are
display-referred sRGB [N, H, W, 3] in [0, 1]: the inpainters are built for display images. Observed
pixels are returned bit-exact; only missing pixels change.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from holoflow.recon.config import InpSetParams

OPENCV_METHODS = ("telea", "ns", "fsr_fast", "fsr_best")  # cv2 methods; ``background``: see inpaint_views


def missing_mask(alpha: np.ndarray, pcd_valid: np.ndarray | None, alpha_threshold: float = 0.5) -> np.ndarray:
    """Missing-pixel mask [N, H, W] bool (True = missing) from G0's rendered alpha [N, H, W] and the
    PCD set's validity [N, H, W] (1 = a point landed; None = no PCD mask)."""
    missing = np.asarray(alpha) < alpha_threshold
    if pcd_valid is not None:
        missing |= np.asarray(pcd_valid) < 0.5
    return missing


def inpaint_opencv(images: np.ndarray, masks: np.ndarray, method: str = "telea", radius: float = 5.0) -> np.ndarray:
    """Fill masked pixels with OpenCV's classical inpainting.

    images [N, H, W, 3] sRGB in [0, 1]; masks [N, H, W] (True/1 = missing); radius: neighbourhood in
    pixels (telea / ns). Returns [N, H, W, 3] float32; unmasked pixels are the input's, views with an
    empty mask are returned unchanged, fully masked views are set to mid grey (nothing to spread)."""
    import cv2

    if method not in OPENCV_METHODS:
        raise ValueError(f"inpaint: unknown opencv method {method!r}, expected one of {OPENCV_METHODS}")
    images = np.asarray(images, dtype=np.float32)
    masks = np.asarray(masks, dtype=bool)
    out = images.copy()
    for i in range(len(images)):
        m = masks[i]
        if not m.any():
            continue
        if m.all():
            out[i] = 0.5
            continue
        u8 = np.ascontiguousarray((np.clip(images[i], 0, 1) * 255.0 + 0.5).astype(np.uint8))
        m8 = m.astype(np.uint8)
        if method in ("telea", "ns"):
            flag = cv2.INPAINT_TELEA if method == "telea" else cv2.INPAINT_NS
            filled = cv2.inpaint(u8, m8, float(radius), flag)
        else:
            filled = np.zeros_like(u8)
            flag = cv2.xphoto.INPAINT_FSR_FAST if method == "fsr_fast" else cv2.xphoto.INPAINT_FSR_BEST
            cv2.xphoto.inpaint(u8, (1 - m8) * 255, filled, flag)  # xphoto: non-zero = valid
        out[i][m] = filled[m].astype(np.float32) / 255.0
    return out


DIRECTIONS = ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))  # (dy, dx)


def first_observed(valid: np.ndarray, step: tuple[int, int], max_dist: int) -> tuple[np.ndarray, np.ndarray]:
    """For every pixel, the nearest observed pixel along ``step`` (dy, dx) within ``max_dist`` steps.

    valid [H, W] bool (True = observed). Returns (row, col) index arrays [H, W] of that pixel (the
    pixel itself where none lies within reach) and the step count [H, W] (0 for observed pixels
    themselves, -1 where none lies within reach)."""
    valid = np.ascontiguousarray(valid, dtype=np.bool_)
    h, w = valid.shape
    rows, cols = np.empty((h, w), np.int64), np.empty((h, w), np.int64)
    dist = np.empty((h, w), np.int64)
    _walk(valid, int(step[0]), int(step[1]), int(max_dist), rows, cols, dist)
    return (rows, cols), dist


@njit(cache=True)
def _walk(valid, dy, dx, max_dist, rows, cols, dist):
    """Per pixel, walk ``step`` until an observed pixel, the border or ``max_dist`` steps (first_observed)."""
    h, w = valid.shape
    for y in range(h):
        for x in range(w):
            found = -1
            for k in range(max_dist + 1):
                yy, xx = y + k * dy, x + k * dx
                if yy < 0 or yy >= h or xx < 0 or xx >= w:
                    break
                if valid[yy, xx]:
                    found = k
                    break
            dist[y, x] = found
            k = max(found, 0)
            rows[y, x], cols[y, x] = y + k * dy, x + k * dx


def background_fill(
    image: np.ndarray, missing: np.ndarray, depth: np.ndarray, max_dist: int = 32, tol: float = 0.1
) -> tuple[np.ndarray, np.ndarray]:
    """Fill disocclusion holes from their far (background) side.

    A hole that opens when the camera moves is surface hidden behind a nearer object, so its content
    continues the farther of the surfaces bordering it, not the occluder (a plain diffusion fill such
    as Telea blends both). For each missing pixel the nearest observed pixel is found along 8 directions
    (within ``max_dist`` px); among those hits, the ones whose depth is within ``tol`` (relative) of
    the farthest hit are averaged, weighted by 1 / distance.
    image [H, W, 3]; missing [H, W] bool; depth [H, W] metres (observed pixels' depth; missing ones
    are ignored). Returns (filled image [H, W, 3] float32, still-missing [H, W] bool: pixels with no
    observed pixel in reach). Observed pixels are returned unchanged."""
    image = np.asarray(image, np.float32)
    valid = ~np.asarray(missing, bool)
    hits = [first_observed(valid, d, max_dist) for d in DIRECTIONS]
    z = np.stack([np.where(dist > 0, depth[idx], -np.inf) for idx, dist in hits])  # [8, H, W]
    far = z.max(0)  # [H, W]
    use = np.isfinite(z) & (z >= far * (1.0 - tol))  # [8, H, W]
    wts = np.stack([np.where(u, 1.0 / np.maximum(dist, 1), 0.0) for u, (_, dist) in zip(use, hits)])
    col = np.stack([image[idx] for idx, _ in hits])  # [8, H, W, 3]
    total = wts.sum(0)  # [H, W]
    fill = (wts[..., None] * col).sum(0) / np.maximum(total, 1e-12)[..., None]
    out = image.copy()
    done = ~valid & (total > 0)
    out[done] = fill[done]
    return out, ~valid & ~done


def inpaint_views(
    images: np.ndarray,
    masks: np.ndarray,
    engine: str,
    cfg: InpSetParams,
    device: str = "cpu",
    progress=None,
    depths: np.ndarray | None = None,
) -> np.ndarray:
    """Inpaint only the views that have missing pixels, with ``engine`` (a name in
    ``InpSetParams.ENGINES``: opencv, lama) and inp_set's ``cfg``.
    images [N, H, W, 3] sRGB [0, 1]; masks [N, H, W] bool; depths [N, H, W] metres (the render's
    depth, needed by opencv method ``background``: ``background_fill``, then ``telea`` for what it
    cannot reach). Returns [N, H, W, 3] float32 where observed pixels equal the input."""
    images = np.asarray(images, dtype=np.float32)
    masks = np.asarray(masks, dtype=bool)
    todo = np.flatnonzero(masks.reshape(len(masks), -1).any(1))
    out = images.copy()
    if len(todo) == 0:
        return out
    filled = InpSetParams.ENGINES.get(engine)(
        images[todo], masks[todo], None if depths is None else np.asarray(depths)[todo], cfg, device, progress
    )
    m = masks[todo][..., None]
    out[todo] = np.where(m, filled, images[todo])
    return out


def opencv_engine(
    images: np.ndarray,
    masks: np.ndarray,
    depths: np.ndarray | None,
    cfg: InpSetParams,
    device: str = "cpu",
    progress=None,
) -> np.ndarray:
    """inp_set's ``opencv`` engine: cfg.method ``background`` (``background_fill`` within cfg.max_dist px,
    then telea for what it cannot reach; needs ``depths``) or a cv2 method (cfg.radius px)."""
    if cfg.method != "background":
        return inpaint_opencv(images, masks, cfg.method, cfg.radius)
    if depths is None:
        raise ValueError("inpaint: method 'background' needs the rendered depth")
    pre = [
        background_fill(images[i], masks[i], np.asarray(depths[i], np.float32), cfg.max_dist)
        for i in range(len(images))
    ]
    return inpaint_opencv(np.stack([f for f, _ in pre]), np.stack([r for _, r in pre]), "telea", cfg.radius)


def lama_engine(
    images: np.ndarray,
    masks: np.ndarray,
    depths: np.ndarray | None,
    cfg: InpSetParams,
    device: str = "cpu",
    progress=None,
) -> np.ndarray:
    """inp_set's ``lama`` engine (holoflow.networks.lama, weights: cfg.model); LaMa takes linear RGB."""
    import torch

    from holoflow.imageops.color import linear_to_srgb_torch, srgb_to_linear_torch
    from holoflow.networks import lama

    linear = srgb_to_linear_torch(torch.from_numpy(images)).numpy()
    filled = lama.inpaint(linear, masks.astype(np.float32), cfg.model, device, progress)
    return linear_to_srgb_torch(torch.from_numpy(np.asarray(filled, np.float32))).numpy()


def compile_ahead() -> None:
    """Compile ``_walk`` (or load it from numba's disk cache): ``first_observed`` passes a bool mask
    and int64 indices whatever its inputs. holoflow/flow/executors/ahead.py."""
    first_observed(np.ones((2, 2), bool), DIRECTIONS[0], 1)
