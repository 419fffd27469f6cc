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


def segment_normals(srgb8: np.ndarray, views: int = 8, size: int = 256, fov_deg: float = 90.0,
                    min_length: float = 12.0) -> tuple[np.ndarray, np.ndarray]:
    """Great-circle normals [N, 3] (world, unit) and lengths [N] (pixels) of the line segments seen by
    ``views`` horizontal perspective views of an 8-bit sRGB panorama [H, W, 3]."""
    import cv2
    import torch

    from holoflow.geometry.camera import intrinsics_from_fov, look_at
    from holoflow.geometry.sampling import equirect_to_pinhole

    yaws = np.arange(views) * 2 * np.pi / views
    targets = torch.tensor(np.stack([np.sin(yaws), np.zeros(views), np.cos(yaws)], 1), dtype=torch.float64)
    V = torch.stack([look_at(torch.zeros(3, dtype=torch.float64), t) for t in targets])  # [V, 4, 4]
    K = intrinsics_from_fov(fov_deg, size, size, dtype=torch.float64)[None].expand(views, 3, 3)
    pano = torch.from_numpy(srgb8.astype(np.float64) / 255.0).permute(2, 0, 1)
    imgs = equirect_to_pinhole(pano, K, V, size, size).permute(0, 2, 3, 1).numpy()  # [V, s, s, 3]
    lsd = cv2.createLineSegmentDetector()
    Kinv = np.linalg.inv(K[0].numpy())
    normals, lengths = [], []
    for i in range(views):
        grey = cv2.cvtColor((np.clip(imgs[i], 0, 1) * 255).astype(np.uint8), cv2.COLOR_RGB2GRAY)
        lines = lsd.detect(grey)[0]
        if lines is None:
            continue
        seg = lines.reshape(-1, 4).astype(np.float64)
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        seg, length = seg[length >= min_length], length[length >= min_length]
        if not len(seg):
            continue
        R = V[i, :3, :3].numpy()  # world-to-camera
        p1 = np.c_[seg[:, :2], np.ones(len(seg))] @ Kinv.T @ R  # camera rays -> world (R^T x)
        p2 = np.c_[seg[:, 2:], np.ones(len(seg))] @ Kinv.T @ R
        n = np.cross(p1, p2)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        normals.append(n)
        lengths.append(length)
    if not normals:
        return np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(normals), np.concatenate(lengths)


def vertical_direction(normals: np.ndarray, lengths: np.ndarray, max_tilt_deg: float = 30.0
                       ) -> tuple[np.ndarray | None, dict]:
    """The vertical vanishing direction (unit, pointing up, i.e. y < 0) from segment normals, or None
    when too few segments support one or it is further than ``max_tilt_deg`` from -y; and facts."""
    v = np.array([0.0, -1.0, 0.0])
    support = 0.0
    for tol in (10.0, 5.0, 3.0, 2.0):
        keep = np.abs(normals @ v) < np.sin(np.radians(tol))
        if keep.sum() < 6:
            return None, {"segments": int(len(normals)), "vertical_segments": int(keep.sum()),
                          "note": "too few vertical segments; no tilt correction"}
        n, w = normals[keep], lengths[keep]
        M = (n * w[:, None]).T @ n
        vals, vecs = np.linalg.eigh(M)
        v = vecs[:, 0] * (-1.0 if vecs[1, 0] > 0 else 1.0)
        support = float(w.sum() / max(lengths.sum(), 1e-9))
    tilt = float(np.degrees(np.arccos(np.clip(-v[1], -1.0, 1.0))))
    facts = {"segments": int(len(normals)), "vertical_segments": int(keep.sum()),
             "vertical_support": round(support, 3), "tilt_deg": round(tilt, 3)}
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
