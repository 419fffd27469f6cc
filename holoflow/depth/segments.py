"""Line segments of an equirect panorama as rays on the sphere (shared by ``vanishing`` and ``manhattan``).

OpenCV's LSD runs on pinhole views of the panorama (``equirect_to_pinhole``); each segment's two end
pixels are lifted to unit rays in the world frame of the panorama centre (docs/conventions.md: OpenCV
frame, +y down), so the segment lies on the great circle through both rays.
"""

from __future__ import annotations

import numpy as np


def view_segments(
    srgb8: np.ndarray,
    yaws: np.ndarray,
    pitches: np.ndarray,
    size: int = 256,
    fov_deg: float = 90.0,
    min_length: float = 10.0,
):
    """LSD segments of an 8-bit sRGB panorama [H, W, 3] seen by V pinhole views (``yaws`` [V] and
    ``pitches`` [V] in radians, + pitch = looking up; ``size`` px square, ``fov_deg`` degrees).
    Segments shorter than ``min_length`` view pixels are dropped. Returns (p1 [N, 3], p2 [N, 3]) unit
    end rays (world) and lengths [N] (view pixels)."""
    import cv2
    import torch

    from holoflow.geometry.camera import intrinsics_from_fov, look_at
    from holoflow.geometry.sampling import equirect_to_pinhole

    yaws, pitches = np.asarray(yaws, dtype=np.float64), np.asarray(pitches, dtype=np.float64)
    n_v = len(yaws)
    tg = np.stack([np.sin(yaws) * np.cos(pitches), -np.sin(pitches), np.cos(yaws) * np.cos(pitches)], 1)  # [V, 3]
    V = torch.stack([look_at(torch.zeros(3, dtype=torch.float64), torch.from_numpy(t)) for t in tg])  # [V, 4, 4]
    K = intrinsics_from_fov(fov_deg, size, size, dtype=torch.float64)[None].expand(n_v, 3, 3)
    pano = torch.from_numpy(srgb8.astype(np.float64) / 255.0).permute(2, 0, 1)
    imgs = equirect_to_pinhole(pano, K, V, size, size).permute(0, 2, 3, 1).numpy()  # [V, s, s, 3]
    lsd = cv2.createLineSegmentDetector()
    Kinv = np.linalg.inv(K[0].numpy())
    P1, P2, L = [], [], []
    for i in range(n_v):
        grey = cv2.cvtColor((np.clip(imgs[i], 0, 1) * 255).astype(np.uint8), cv2.COLOR_RGB2GRAY)
        lines = lsd.detect(grey)[0]
        if lines is None:
            continue
        seg = lines.reshape(-1, 4).astype(np.float64)
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        seg, length = seg[length >= min_length], length[length >= min_length]
        if not len(seg):
            continue
        R = V[i, :3, :3].numpy()  # world-to-camera; rows of x @ Kinv.T @ R are R^T K^-1 x (world rays)
        for ends, out in ((seg[:, :2], P1), (seg[:, 2:], P2)):
            p = np.c_[ends, np.ones(len(seg))] @ Kinv.T @ R
            out.append(p / np.linalg.norm(p, axis=1, keepdims=True))
        L.append(length)
    if not L:
        z = np.zeros((0, 3))
        return z, z, np.zeros(0)
    return np.concatenate(P1), np.concatenate(P2), np.concatenate(L)


def great_circle_normals(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """Unit normals [N, 3] (p1 x p2) of the great circles through end rays p1, p2 [N, 3]."""
    n = np.cross(p1, p2)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
