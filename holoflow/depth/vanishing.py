"""Vanishing directions of a panorama on the sphere: the camera's tilt from vertical line segments.

Line segments (OpenCV LSD) are detected on ``views`` perspective views around the horizon; each
segment's two end rays span a great circle with unit normal n (world frame). A 3D line through the
vertical vanishing direction v (a vertical edge: wall corner, door frame) has n . v = 0, so v is the
direction most normals are perpendicular to: start at the image's up (-y), keep the normals within a
shrinking angle of perpendicular (10, 5, 3, 2 deg), and take the smallest eigenvector of their
length-weighted scatter matrix. Conventions: docs/conventions.md (+y down: up is -y).
"""

from __future__ import annotations

import numpy as np


def segment_normals(
    srgb8: np.ndarray, views: int = 8, size: int = 256, fov_deg: float = 90.0, min_length: float = 12.0
) -> tuple[np.ndarray, np.ndarray]:
    """Great-circle normals [N, 3] (world, unit) and lengths [N] (pixels) of the line segments seen by
    ``views`` horizontal perspective views of an 8-bit sRGB panorama [H, W, 3] (``segments.view_segments``)."""
    from holoflow.depth.segments import great_circle_normals, view_segments

    yaws = np.arange(views) * 2 * np.pi / views
    p1, p2, lengths = view_segments(srgb8, yaws, np.zeros(views), size, fov_deg, min_length)
    return great_circle_normals(p1, p2), lengths


def vertical_direction(
    normals: np.ndarray, lengths: np.ndarray, max_tilt_deg: float = 30.0
) -> tuple[np.ndarray | None, dict]:
    """The vertical vanishing direction (unit, pointing up, i.e. y < 0) from segment normals, or None
    when too few segments support one or it is further than ``max_tilt_deg`` from -y; and facts."""
    v = np.array([0.0, -1.0, 0.0])
    support = 0.0
    for tol in (10.0, 5.0, 3.0, 2.0):
        keep = np.abs(normals @ v) < np.sin(np.radians(tol))
        if keep.sum() < 6:
            return None, {
                "segments": int(len(normals)),
                "vertical_segments": int(keep.sum()),
                "note": "too few vertical segments; no tilt correction",
            }
        n, w = normals[keep], lengths[keep]
        M = (n * w[:, None]).T @ n
        vals, vecs = np.linalg.eigh(M)
        v = vecs[:, 0] * (-1.0 if vecs[1, 0] > 0 else 1.0)
        support = float(w.sum() / max(lengths.sum(), 1e-9))
    tilt = float(np.degrees(np.arccos(np.clip(-v[1], -1.0, 1.0))))
    facts = {
        "segments": int(len(normals)),
        "vertical_segments": int(keep.sum()),
        "vertical_support": round(support, 3),
        "tilt_deg": round(tilt, 3),
    }
    if tilt > max_tilt_deg:
        return None, {**facts, "note": f"tilt {tilt:.1f} deg > max_tilt_deg; not corrected"}
    return v, facts


def rotation_to_upright(v: np.ndarray) -> np.ndarray:
    """Rotation R [3, 3] with R @ v = (0, -1, 0) (the smallest rotation, Rodrigues)."""
    up = np.array([0.0, -1.0, 0.0])
    axis = np.cross(v, up)
    s, c = np.linalg.norm(axis), float(np.dot(v, up))
    if s < 1e-12:
        return np.eye(3)
    k = axis / s
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * Kx + (1 - c) * Kx @ Kx


def rotate_equirect(img: np.ndarray, R: np.ndarray, mode: str = "bilinear") -> np.ndarray:
    """The panorama [H, W(, C)] seen from a camera rotated by R: out(d) = img(R^T d)."""
    import torch

    from holoflow.geometry.sampling import sample_equirect
    from holoflow.geometry.sphere import equirect_directions

    a = np.asarray(img, dtype=np.float64)
    a = a[..., None] if a.ndim == 2 else a
    H, W = a.shape[:2]
    dirs = equirect_directions(H, W, dtype=torch.float64) @ torch.from_numpy(R)  # rows: R^T d
    out = sample_equirect(torch.from_numpy(np.ascontiguousarray(a)).permute(2, 0, 1), dirs[None], mode=mode)
    out = out[0].permute(1, 2, 0).numpy()
    return out[..., 0] if np.asarray(img).ndim == 2 else out
