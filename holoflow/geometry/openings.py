"""Window bars kept in their window: sky seen through an opening of the room, with what crosses it.

A depth network blurs a window's bars into the sky behind them, and a depth map point-sampled to P_f's
grid drops bars thinner than its pixels: either way the bars' pixels come out as sky, so their colour
lands on the far shell and moves with the sky from any eye off the centre (the bars vanish, or smear
across the panes). The colour still shows them. For every *opening* (a connected sky region enclosed
by finite depth: not touching a pole row, at most ``max_fraction`` of the panorama) this module

1. fits a plane to the frame around it: the finite pixels ``ring_px`` beyond its border, back-projected
   to metres, fitted by iteratively reweighted least squares (Tukey), so a bay's side reveals and the
   sill do not tilt it;
2. fits the sky's own colour inside it: a quadratic in the pixel coordinates per channel, again
   reweighted, so bars and frame pixels are outliers, not part of the fit;
3. calls a pixel a *bar* when its colour is more than ``colour_tol`` (sRGB, and at least 4 robust
   sigmas of the sky's residual) off the sky's and it belongs to an outlier region that touches the
   opening's border and reaches 2 px into it (bars hold onto their frame and cross it; a cloud in the
   middle of a pane stays sky, and so does the rim of pixels a frame shares with the sky), together
   with the one-pixel rim of mixed colour around it (on the sky it would draw ghost bars);
4. gives every bar pixel the depth where its ray meets the frame's plane (within 1.5 x the ring's
   depth range) and takes it out of the sky.

Pure functions on an equirect grid: colour [H, W, 3] sRGB in [0, 1], radial depth [H, W] in metres with
non-finite = sky, pixel centres at +0.5 (docs/conventions.md).
"""

from __future__ import annotations

import math

import numpy as np
import torch

TUKEY_C = 4.685  # Tukey's biweight constant (95 % efficiency for Gaussian residuals)


def keep_opening_bars(
    srgb: torch.Tensor,
    depth: torch.Tensor,
    ring_px: int = 3,
    colour_tol: float = 0.06,
    max_fraction: float = 0.05,
) -> tuple[torch.Tensor, dict]:
    """The module docstring's steps on srgb [H, W, 3] and radial depth [H, W] (metres, non-finite = sky):
    (the depth with every bar pixel at its frame's plane [H, W], {"openings": how many sky regions were
    openings, "bar_pixels": how many pixels left the sky})."""
    import cv2

    from holoflow.geometry.sphere import equirect_directions

    H, W = depth.shape
    d = depth.detach().cpu().double().numpy()
    col = srgb.detach().cpu().double().numpy()
    sky = ~(np.isfinite(d) & (d > 0))
    out = d.copy()
    found = {"openings": 0, "bar_pixels": 0}
    n, labels, boxes, _ = cv2.connectedComponentsWithStats(sky.astype(np.uint8), connectivity=8)
    dirs = None  # [H, W, 3] unit directions, made when the first bars are found
    pad = ring_px + 2
    for i in range(1, n):
        x, y, w, h, area = (int(v) for v in boxes[i])
        if area < 16 or area > max_fraction * H * W or y == 0 or y + h == H:
            continue
        y0, y1, x0, x1 = max(0, y - pad), min(H, y + h + pad), max(0, x - pad), min(W, x + w + pad)
        comp = labels[y0:y1, x0:x1] == i
        found["openings"] += 1
        bars = _bar_pixels(comp, *_sky_fit(col[y0:y1, x0:x1], comp), colour_tol)
        if not bars.any():
            continue
        ring = _dilate(comp, ring_px) & ~_dilate(comp, 1) & ~sky[y0:y1, x0:x1]
        if ring.sum() < 12:
            continue
        if dirs is None:
            dirs = equirect_directions(H, W, dtype=torch.float64).numpy()
        u, ring_d = dirs[y0:y1, x0:x1], d[y0:y1, x0:x1][ring]
        plane = _robust_plane(u[ring] * ring_d[:, None])
        if plane is None:
            continue
        normal, offset = plane  # offset > 0: a ray meets the plane at offset / cos, in front when cos > 0
        with np.errstate(divide="ignore"):
            t = offset / (u[bars] @ normal)  # [B] metres
        t = np.clip(np.where(t > 0, t, np.inf), ring_d.min() / 1.5, ring_d.max() * 1.5)  # edge-on: no bar lost
        out[y0:y1, x0:x1][bars] = t
        found["bar_pixels"] += int(bars.sum())
    return torch.from_numpy(out).to(depth.dtype).to(depth.device), found


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """mask [h, w] bool grown by r px (square)."""
    import cv2

    return cv2.dilate(mask.astype(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8)).astype(bool)


def _sky_fit(col: np.ndarray, comp: np.ndarray) -> tuple[np.ndarray, float]:
    """The sky's colour over the opening comp [h, w] (step 2): a quadratic in the pixel coordinates per
    channel, Tukey-reweighted so bars and frame pixels do not pull it. Returns (each pixel's distance
    from it [P], P = comp's pixels in row-major order, and the robust sigma of the distances of the
    pixels the fit kept)."""
    yy, xx = np.nonzero(comp)
    sy, sx = max(1.0, (yy.max() - yy.min()) / 2), max(1.0, (xx.max() - xx.min()) / 2)
    a, b = (yy - yy.mean()) / sy, (xx - xx.mean()) / sx
    design = np.stack([np.ones_like(a), a, b, a * a, a * b, b * b], 1)  # [P, 6]
    c = col[comp]  # [P, 3]
    resid = np.linalg.norm(c - np.median(c, 0), axis=1)  # start from the median colour
    for _ in range(8):
        # the scale from the best 30 % (a Gaussian's |x| has 0.385 sigma there): bars and the pixels
        # that mix them in can be half of a small pane, which would inflate a median's scale
        scale = max(float(np.quantile(resid, 0.3)) / 0.385, 1e-3)
        weights = np.clip(1 - (resid / (TUKEY_C * scale)) ** 2, 0, None) ** 2
        sw = np.sqrt(weights)[:, None]
        coef, *_ = np.linalg.lstsq(design * sw, c * sw, rcond=None)
        resid = np.linalg.norm(c - design @ coef, axis=1)  # [P]
    scale = max(float(np.quantile(resid, 0.3)) / 0.385, 1e-3)
    weights = np.clip(1 - (resid / (TUKEY_C * scale)) ** 2, 0, None) ** 2
    inlier = resid[weights > 0]
    return resid, 1.4826 * float(np.median(inlier)) if len(inlier) else 0.0


def _bar_pixels(comp: np.ndarray, resid: np.ndarray, sigma: float, colour_tol: float) -> np.ndarray:
    """The opening comp [h, w]'s pixels whose colour is off the sky's fit (resid [P] and sigma of
    ``_sky_fit``) by more than colour_tol and 4 sigmas, and whose outlier region touches the opening's border and
    reaches 2 px inside it (step 3), with their one-pixel rim."""
    import cv2

    odd = np.zeros_like(comp)
    odd[comp] = resid > max(colour_tol, 4 * sigma)
    if not odd.any():
        return odd
    inner = cv2.erode(comp.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    n, labels = cv2.connectedComponents(odd.astype(np.uint8), connectivity=8)
    touching = np.intersect1d(labels[odd & comp & ~inner], labels[odd & inner])
    bars = np.isin(labels, touching[touching > 0]) & odd
    return _dilate(bars, 1) & comp  # a bar's rim of mixed pixels goes with the bar, not onto the sky


def _robust_plane(points: np.ndarray) -> tuple[np.ndarray, float] | None:
    """A plane n . p = offset (|n| = 1, offset > 0: the centre on its inner side) through points [R, 3]
    metres by Tukey-reweighted total least squares; None when fewer than half of them fit it."""
    weights = np.ones(len(points))
    normal, offset = None, 0.0
    floor = 0.005 * float(np.median(np.linalg.norm(points, axis=1)))  # 5 mm at 1 m: no plane is flatter
    for _ in range(8):
        centre = (points * weights[:, None]).sum(0) / weights.sum()
        q = (points - centre) * np.sqrt(weights)[:, None]
        normal = np.linalg.svd(q, full_matrices=False)[2][-1]
        offset = float(normal @ centre)
        resid = np.abs(points @ normal - offset)
        scale = max(1.4826 * float(np.median(resid)), floor)
        weights = np.clip(1 - (resid / (TUKEY_C * scale)) ** 2, 0, None) ** 2
        if weights.sum() < 3:
            return None
    if (weights > 0).mean() < 0.5 or not math.isfinite(offset) or abs(offset) < 1e-9:
        return None
    if offset < 0:
        normal, offset = -normal, -offset
    return normal, offset
