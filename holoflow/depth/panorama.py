"""Panorama depth, 360MonoDepth style: tangent faces -> relative disparity -> alignment -> frustum
blending -> one global metric scale and offset. The two stages (tangent_depth, metric_align) and the
bench call these functions; docs/depth.md explains the method.

Arrays: panoramas are numpy [H, W, 3] linear RGB; radial depth [H, W] metres (+inf sky); disparity
[H, W] relative radial disparity (~ 1/r up to a global affine map). Faces: holoflow.geometry.icosahedron.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoflow.depth import planes
from holoflow.depth.accuracy import depth_metrics
from holoflow.depth.config import MetricAlignParams, TangentDepthParams
from holoflow.depth.edges import sharpen_edges
from holoflow.depth.engines import resolve_engine
from holoflow.depth.face_alignment import Alignment, align_faces
from holoflow.depth.faces import face_rays, find_overlaps
from holoflow.depth.metric_alignment import disparity_to_depth, robust_affine_fit, sky_disparity, sky_mixed_edges
from holoflow.stage import Progress


@dataclass
class TangentDepth:
    """``disparity`` [H, W] blended radial disparity; ``raw`` / ``aligned`` [F, h, w] per-face engine
    output and aligned radial disparity (NaN invalid); ``alignment``; ``engine`` facts."""

    disparity: np.ndarray
    raw: np.ndarray
    aligned: np.ndarray
    alignment: Alignment
    engine: dict


def icosahedron_faces(face_size: int, padding: float):
    """The 20 padded icosahedron tangent faces (holoflow.geometry.icosahedron)."""
    from holoflow.geometry.icosahedron import tangent_faces

    if face_size < 2:
        raise ValueError(f"face_size must be >= 2 pixels, got {face_size}")
    return tangent_faces(padding=padding, size=face_size)


def resize_radial(radial: np.ndarray, height: int, width: int) -> np.ndarray:
    """Radial depth [H, W] -> [height, width] by the nearest source pixel (no mixing across edges or
    with sky)."""
    H, W = radial.shape
    rows = np.minimum(((np.arange(height) + 0.5) * H / height).astype(np.int64), H - 1)
    cols = np.minimum(((np.arange(width) + 0.5) * W / width).astype(np.int64), W - 1)
    return radial[rows[:, None], cols[None, :]]


def sample_faces(pano: np.ndarray, K, viewmat, size: int, mode: str = "bilinear", device: str = "cpu") -> np.ndarray:
    """Perspective faces [F, size, size, C] of an equirect image [H, W, C] (or [H, W]), resampled on
    ``device`` in float64."""
    from holoflow.geometry.sampling import equirect_to_pinhole

    img = np.asarray(pano, dtype=np.float64)
    img = img[..., None] if img.ndim == 2 else img
    t = _t(img, device).permute(2, 0, 1)
    out = equirect_to_pinhole(t, _t(K, device), _t(viewmat, device), size, size, mode=mode)  # [F, C, s, s]
    return out.permute(0, 2, 3, 1).cpu().numpy()


def sample_radial(radial: np.ndarray, K, viewmat, size: int) -> np.ndarray:
    """True radial depth [F, size, size] in the faces: nearest pixel, sky stays +inf."""
    disp = np.where(np.isfinite(radial) & (radial > 0), 1.0 / np.where(radial > 0, radial, 1.0), 0.0)
    d = sample_faces(disp, K, viewmat, size, mode="nearest")[..., 0]
    return np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), np.inf)


def estimate_disparity(
    pano: np.ndarray,
    truth: np.ndarray | None,
    engine: str,
    cfg: TangentDepthParams,
    seed: int = 0,
    device: str = "cpu",
    progress: Progress = None,
) -> TangentDepth:
    """Relative radial disparity [H, W] of a panorama [H, W, 3] (see the module docstring), with
    tangent_depth's ``cfg`` (face_size, padding, alignment, blend_ramp; ``width`` is the caller's).

    ``truth`` [H, W] radial depth (needed by the ``simulated`` engine only); ``engine`` a name in
    ``TangentDepthParams.ENGINES`` (``auto`` resolves by ``resolve_engine``; the result's engine facts
    say which ran and why); ``progress(done, total, what)``.
    """
    H, W = pano.shape[:2]
    engine, why = resolve_engine(engine, truth is not None)
    size = cfg.face_size
    faces = icosahedron_faces(size, cfg.padding)
    K, V = _np(faces.K), _np(faces.viewmat)
    images = sample_faces(pano, K, V, size, device=device).astype(np.float32)  # [F, h, w, 3]
    dirs, cos = face_rays(K, V, size, size)
    truth_faces = sample_radial(truth, K, V, size) if truth is not None else None
    raw, meta = _engine(TangentDepthParams, engine, "relative")(
        images, dirs, cos, truth_faces, seed, cfg, device, progress, pano=pano
    )
    meta = {**meta, "why": why}
    raw = np.asarray(raw, dtype=np.float64)
    if raw.shape != cos.shape:
        raise ValueError(f"depth engine {engine!r} returned {raw.shape}, expected {cos.shape}")
    overlaps = find_overlaps(K, V, size, size, stride=max(1, size // 64))
    al = align_faces(raw, np.isfinite(raw), cos, overlaps, cfg)
    from holoflow.geometry.icosahedron import frustum_weight

    disparity = blend_faces(al.radial, _np(frustum_weight(faces, cfg.blend_ramp)), K, V, H, W, device)
    return TangentDepth(disparity.astype(np.float32), raw.astype(np.float32), al.radial.astype(np.float32), al, meta)


def blend_faces(radial: np.ndarray, weights: np.ndarray, K, viewmat, H: int, W: int, device: str = "cpu") -> np.ndarray:
    """Frustum blending: per-face radial disparity [F, h, w] (NaN = invalid) -> equirect [H, W]
    (the projection runs on ``device`` in float64).

    ``weights`` [F, h, w] frustum weights; invalid pixels get weight 0 (and their neighbours' values, so
    bilinear taps at a face's valid border do not mix in a fill value). Equirect pixels no valid face
    covers take the nearest covered pixel (wrap-aware). Raises ValueError when no face is valid.
    """
    import scipy.ndimage as ndi

    from holoflow.geometry.sampling import pinhole_to_equirect

    radial = np.asarray(radial, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64).reshape(radial.shape)
    ok = np.isfinite(radial)
    if not ok.any():
        raise ValueError("no tangent face has a valid disparity (all sky, NaN or dropped); nothing to blend")
    filled = np.zeros_like(radial)
    for f in range(radial.shape[0]):
        if ok[f].any():
            idx = ndi.distance_transform_edt(~ok[f], return_distances=False, return_indices=True)
            filled[f] = radial[f][tuple(idx)]
    wt = np.where(ok, weights, 0.0)
    accum, wsum = pinhole_to_equirect(
        _t(filled[:, None], device), _t(K, device), _t(viewmat, device), H, W, weights=_t(wt[:, None], device)
    )
    accum, wsum = accum[0].cpu().numpy(), wsum[0].cpu().numpy()
    covered = wsum > 1e-12
    out = np.where(covered, accum / np.where(covered, wsum, 1.0), np.nan)
    if not covered.all():
        if not covered.any():
            raise ValueError("the valid faces cover no panorama pixel; nothing to blend")
        tiled = np.concatenate([out, out, out], axis=1)  # wrap-aware nearest fill
        idx = ndi.distance_transform_edt(np.isnan(tiled), return_distances=False, return_indices=True)
        out = tiled[tuple(idx)][:, W : 2 * W]
    return out


@dataclass
class MetricDepth:
    """``depth`` [H, W] radial metres (+inf sky); ``fit`` (scale, offset, residuals); ``faces`` used;
    ``engine`` facts."""

    depth: np.ndarray
    fit: dict
    faces: list[int]
    engine: dict


def metric_from_disparity(
    disparity: np.ndarray,
    pano: np.ndarray,
    truth: np.ndarray | None,
    engine: str,
    cfg: MetricAlignParams,
    seed: int = 0,
    device: str = "cpu",
    progress: Progress = None,
    relative_engine: str = "",
) -> MetricDepth:
    """Metric radial depth from a relative disparity [H, W] and metric depth (``engine``, a name in
    ``MetricAlignParams.ENGINES``; ``auto`` resolves by ``resolve_engine``) on a seeded subset of
    cfg.faces faces, with metric_align's ``cfg``; then, when ``cfg.refine`` asks for it for the
    ``relative_engine`` that made the disparity and the panorama is at least ``planes.MIN_WIDTH`` pixels
    across, its blurred steps made sharp (holoflow.depth.edges) and the whole straightened by the room's
    planes (holoflow.depth.planes)."""
    engine, why = resolve_engine(engine, truth is not None)
    size = cfg.face_size
    faces = icosahedron_faces(size, cfg.padding)
    chosen = sorted(int(i) for i in np.random.default_rng([seed, 1]).choice(20, cfg.faces, replace=False))
    K, V = _np(faces.K)[chosen], _np(faces.viewmat)[chosen]
    images = sample_faces(pano, K, V, size, device=device).astype(np.float32)
    dirs, cos = face_rays(K, V, size, size)
    truth_faces = sample_radial(truth, K, V, size) if truth is not None else None
    z, meta = _engine(MetricAlignParams, engine, "metric")(
        images, dirs, cos, truth_faces, [seed, 2], cfg, device, progress, pano=pano
    )
    meta = {**meta, "why": why}
    z = np.asarray(z, dtype=np.float64)
    ref = np.where(np.isfinite(z) & (z > 0), cos / np.where(z > 0, z, 1.0), np.nan)  # radial disparity
    x = sample_faces(disparity, K, V, size, device=device)[..., 0]
    fit = robust_affine_fit(x, ref, huber=cfg.huber)
    if not fit["scale"] > 0:
        raise ValueError(
            f"metric alignment gave a non-positive scale ({fit['scale']:.3g}): the relative "
            "disparity does not grow with the reference disparity (wrong engine output?)"
        )
    depth = disparity_to_depth(disparity, fit["scale"], fit["offset"], cfg.max_depth)
    limit = sky_disparity(fit["scale"] * x + fit["offset"], ~(np.isfinite(z) & (z > 0)) & np.isfinite(x))
    fit["sky_disparity"] = limit
    if limit is not None:  # what the metric engine calls sky starts there in the aligned disparity
        depth = np.where(fit["scale"] * disparity + fit["offset"] < limit, np.inf, depth)
    depth = sky_mixed_edges(depth)
    if planes.wanted(cfg.refine, relative_engine) and depth.shape[1] >= planes.MIN_WIDTH:
        import torch

        from holoflow.geometry.surfaces import depth_noise

        depth, fit["sharpened"] = sharpen_edges(depth)
        fit["depth_noise"] = depth_noise(torch.from_numpy(depth))  # what the planes will hide (point_cloud)
        yaw = None
        if cfg.room_yaw == "lines":
            from holoflow.depth.layout import room_yaw

            yaw, fit["room_yaw"] = room_yaw(pano)  # the layout's lines
        depth, fit["planes"] = planes.refine_with_planes(depth, yaw=yaw)
    return MetricDepth(depth.astype(np.float32), fit, chosen, meta)


def oracle_metrics(disparity: np.ndarray, truth: np.ndarray, max_depth: float = 3000.0) -> dict:
    """Scores of a relative disparity after the best global scale + offset fitted against the truth itself
    (an upper bound for metric_align; measures the tangent alignment alone)."""
    truth = resize_radial(truth, *disparity.shape)
    ref = np.where(np.isfinite(truth) & (truth > 0), 1.0 / np.where(truth > 0, truth, 1.0), np.nan)
    fit = robust_affine_fit(disparity, ref)
    depth = sky_mixed_edges(disparity_to_depth(disparity, fit["scale"], fit["offset"], max_depth))
    return depth_metrics(depth, truth)


def score(depth: np.ndarray, truth: np.ndarray) -> dict:
    """depth_metrics of a radial depth [H, W] against a truth of any size (nearest-resized)."""
    return depth_metrics(depth, resize_radial(truth, *depth.shape))


def _engine(params_class, name: str, kind: str):
    """The registered depth engine ``name`` of a stage's params class (ValueError, one line, if none)."""
    if name not in params_class.ENGINES.names:
        raise ValueError(f"unknown {kind} depth engine {name!r}; choose one of {params_class.ENGINES.names}")
    return params_class.ENGINES.get(name)


def _np(x) -> np.ndarray:
    return x.detach().cpu().numpy().astype(np.float64) if hasattr(x, "detach") else np.asarray(x, np.float64)


def _t(x, device: str = "cpu"):
    import torch

    return torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64)).to(device)
