"""Depth accuracy against truth: AbsRel, RMSE, delta < 1.25, sky kept out.

Both maps are depths in the same kind and unit (e.g. radial metres). A pixel is scored when the truth
is finite and > 0 (sky, +inf in the truth, is excluded) and ``mask`` (if given) is set. A predicted
non-finite or non-positive depth on a scored pixel is a *miss*: it counts against delta1 and coverage
and is left out of AbsRel / RMSE, whose values would otherwise be infinite.
"""

from __future__ import annotations

import numpy as np


def depth_metrics(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> dict[str, float]:
    """Scores of ``pred`` [...] against ``truth`` [...] (same shape, depths).

    Returns ``abs_rel`` (mean |p - t| / t), ``rmse`` (metres), ``delta1`` (fraction of scored pixels with
    max(p/t, t/p) < 1.25, misses count as failures), ``coverage`` (fraction of scored pixels with a
    finite positive prediction), ``sky_false`` (fraction of truth-sky pixels predicted finite) and
    ``n`` (scored pixels). NaN scores when nothing is scored.
    """
    pred = np.asarray(pred, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    if pred.shape != truth.shape:
        raise ValueError(f"depth_metrics: shapes differ {pred.shape} vs {truth.shape}")
    keep = np.isfinite(truth) & (truth > 0)
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool)
    sky = np.isposinf(truth) if mask is None else np.isposinf(truth) & np.asarray(mask, dtype=bool)
    hit = keep & np.isfinite(pred) & (pred > 0)
    n = int(keep.sum())
    out = {"n": n, "sky_false": float((np.isfinite(pred) & sky).sum() / max(int(sky.sum()), 1))}
    if n == 0:
        return {**out, "abs_rel": float("nan"), "rmse": float("nan"), "delta1": float("nan"), "coverage": float("nan")}
    p, t = pred[hit], truth[hit]
    ratio = np.maximum(p / t, t / p) if p.size else np.zeros(0)
    return {
        **out,
        "abs_rel": float(np.mean(np.abs(p - t) / t)) if p.size else float("nan"),
        "rmse": float(np.sqrt(np.mean((p - t) ** 2))) if p.size else float("nan"),
        "delta1": float((ratio < 1.25).sum() / n),
        "coverage": float(hit.sum() / n),
    }
