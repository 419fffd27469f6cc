"""Metric alignment: one global scale and offset mapping the blended disparity to metric disparity.

References are metric depths on a few tangent faces, converted to radial disparity y = 1 / r. The
blended relative disparity x at the same directions is fitted as y ~ a * x + b by iteratively
reweighted least squares on *relative* residuals (a x + b - y) / y, with Huber weights, so that
near and far pixels count alike and outliers (edge mixing, a metric network's sky) are down-weighted;
a last plain least-squares pass on the inliers (|residual| <= 3 huber) removes the Huber bias.
The depth 1 / (a x + b) is +inf (sky) below 1 / max_depth, and a blended pixel at the sky's border
that is mostly sky joins it (``sky_mixed_edges``).

Where the metric engine calls reference pixels sky (no finite depth: a window's view, the open sky),
those pixels also say where the sky begins in the aligned disparity: a relative network gives the sky
a small disparity, not zero, which alignment turns into a finite distance (a few to tens of metres),
and its points would hang in the air behind every window. ``sky_disparity`` picks the aligned
disparity below which the references are sky with the fewest mistakes, and every pixel below it is
sky. With no sky among the references the rule is off.
"""

from __future__ import annotations

import numpy as np


def robust_affine_fit(x: np.ndarray, y: np.ndarray, huber: float = 0.05, iters: int = 20) -> dict:
    """Fit y ~ a x + b (x, y [N], y > 0 finite) by Huber IRLS on relative residuals.

    ``huber`` is the Huber threshold on the relative residual. Returns ``scale`` a, ``offset`` b,
    ``n``, ``rel_rms`` / ``rel_median_abs`` (final relative residuals), ``inlier_frac`` (|res| <= huber),
    ``iters``. Raises ValueError when fewer than 2 usable pairs or x has no spread.
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    keep = np.isfinite(x) & np.isfinite(y) & (y > 0)
    x, y = x[keep], y[keep]
    if x.size < 2:
        raise ValueError(
            f"metric alignment: {x.size} usable reference pixels (need >= 2); "
            "the metric faces may be all sky or invalid"
        )
    if not np.ptp(x) > 1e-12 * max(np.abs(x).max(), 1e-30):
        raise ValueError(
            "metric alignment: the blended disparity is constant over the reference pixels; "
            "scale and offset are not determined"
        )
    A = np.stack([x / y, 1.0 / y], 1)  # rows of the relative residual: A @ [a, b] - 1
    w = np.ones(x.size)
    coef = np.zeros(2)
    done = 0
    for done in range(1, iters + 1):
        sw = np.sqrt(w)
        new, *_ = np.linalg.lstsq(A * sw[:, None], sw, rcond=None)
        r = A @ new - 1.0
        w = np.where(np.abs(r) <= huber, 1.0, huber / np.maximum(np.abs(r), 1e-300))
        converged = np.allclose(new, coef, rtol=1e-9, atol=0)
        coef = new
        if converged:
            break
    r = A @ coef - 1.0
    keep = np.abs(r) <= 3 * huber  # last pass: plain least squares on the inliers (trimmed)
    if keep.sum() >= 2 and np.ptp(x[keep]) > 0:
        coef, *_ = np.linalg.lstsq(A[keep], np.ones(int(keep.sum())), rcond=None)
        r = A @ coef - 1.0
    return {
        "scale": float(coef[0]),
        "offset": float(coef[1]),
        "n": int(x.size),
        "rel_rms": float(np.sqrt(np.mean(r**2))),
        "rel_median_abs": float(np.median(np.abs(r))),
        "inlier_frac": float(np.mean(np.abs(r) <= huber)),
        "iters": done,
    }


def sky_disparity(aligned: np.ndarray, sky: np.ndarray, min_pixels: int = 50) -> float | None:
    """The aligned disparity (1 / m) below which reference pixels are sky with the fewest
    misclassified pixels: aligned [N] (a x + b at the references), sky [N] bool (the metric engine
    found no finite depth there). None with fewer than ``min_pixels`` sky references (the rule is off).
    Ties take the lowest threshold (the least sky)."""
    aligned, sky = np.asarray(aligned, np.float64).ravel(), np.asarray(sky, bool).ravel()
    keep = np.isfinite(aligned)
    aligned, sky = aligned[keep], sky[keep]
    if int(sky.sum()) < min_pixels or bool(sky.all()):
        return None
    order = np.argsort(aligned, kind="stable")
    a, s = aligned[order], sky[order]
    # threshold between a[k - 1] and a[k]: the k lowest are called sky
    surface_below = np.concatenate([[0], np.cumsum(~s)])  # surface pixels called sky
    sky_above = int(s.sum()) - np.concatenate([[0], np.cumsum(s)])  # sky pixels called surface
    k = int(np.argmin(surface_below + sky_above))
    if k == 0:
        return None
    return float(a[k - 1] if k == len(a) else 0.5 * (a[k - 1] + a[k]))


def disparity_to_depth(disparity: np.ndarray, scale: float, offset: float, max_depth: float) -> np.ndarray:
    """Radial depth (metres) = 1 / (scale * disparity + offset); +inf where that metric disparity is
    below 1 / ``max_depth`` (sky, unbounded) or the input is not finite."""
    metric = scale * np.asarray(disparity, dtype=np.float64) + offset
    far = ~(np.isfinite(metric) & (metric >= 1.0 / max_depth))
    return np.where(far, np.inf, 1.0 / np.where(far, 1.0, metric))


def sky_mixed_edges(depth: np.ndarray, reach: int = 2) -> np.ndarray:
    """Radial depth [H, W] (equirect, +inf sky) with its sky-edge mixtures made sky.

    Resampling and blending the faces mixes a sky pixel (disparity 0) with its surface neighbour, so a
    pixel at a sky border can hold any disparity between 0 and the surface's: a point up to max_depth
    away, beyond the scene's far shell. A finite pixel within ``reach`` pixels of the sky (a mixture is
    1-2 pixels wide; columns wrap) whose disparity is under half the largest one within ``reach`` is
    mostly sky and becomes sky, in one pass (no cascade). Every other pixel is returned unchanged. The
    largest disparity around may be a nearer object's: a far surface's border pixel beside one over
    twice as near goes to the sky too (at most ``reach`` pixels of a far silhouette lost, rather than
    points thrown up to max_depth).
    """
    depth = np.asarray(depth, dtype=np.float64)
    disp = np.where(np.isfinite(depth) & (depth > 0), 1.0 / np.where(depth > 0, depth, 1.0), 0.0)  # [H, W]
    if disp.all():  # no sky (a room): nothing to do
        return depth
    import scipy.ndimage as ndi

    size, mode = 2 * reach + 1, ("nearest", "wrap")
    near_sky = ndi.minimum_filter(disp, size=size, mode=mode) == 0.0
    mixed = (disp > 0) & near_sky & (disp < 0.5 * ndi.maximum_filter(disp, size=size, mode=mode))
    return np.where(mixed, np.inf, depth)
