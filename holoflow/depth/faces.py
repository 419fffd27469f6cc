"""Pixel geometry of the tangent faces that the alignment needs: rays, obliquity, overlaps.

Faces are pinhole cameras at the panorama centre (docs/conventions.md): ``K`` [F, 3, 3] with pixel
centres at +0.5, ``viewmat`` [F, 4, 4] world-to-camera, OpenCV axes. A face pixel (col, row) sits at
(x, y) = (col + 0.5, row + 0.5). Its obliquity ``cos`` is the cosine of the angle between its ray and the
optical axis, so perspective depth z = radial depth * cos, and radial disparity = cos * z-disparity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def face_rays(K: np.ndarray, viewmat: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit world directions [F, h, w, 3] of every face pixel and their obliquity cos [F, h, w]."""
    import torch

    from holoflow.geometry.camera import pinhole_rays

    K_t = torch.as_tensor(np.asarray(K), dtype=torch.float64)
    V_t = torch.as_tensor(np.asarray(viewmat), dtype=torch.float64)
    _, dirs = pinhole_rays(K_t, V_t, h, w)  # [F, h, w, 3]
    axis = V_t[:, 2, :3]  # optical axis in world = third row of R
    cos = torch.einsum("fhwi,fi->fhw", dirs, axis)
    return dirs.numpy(), cos.numpy()


def project(dirs: np.ndarray, K: np.ndarray, viewmat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project unit world directions [N, 3] into faces at the centre (K [J, 3, 3], viewmat [J, 4, 4]):
    pixel coords x, y [J, N] and obliquity cos [J, N] (<= 0: behind the face; x, y then meaningless)."""
    import torch

    from holoflow.geometry.camera import project_points

    K_t = torch.as_tensor(np.asarray(K), dtype=torch.float64)
    pts = torch.as_tensor(dirs, dtype=torch.float64).expand(K_t.shape[0], -1, -1)
    uv, z = project_points(pts, K_t, torch.as_tensor(np.asarray(viewmat), dtype=torch.float64))
    return uv[..., 0].numpy(), uv[..., 1].numpy(), z.numpy()


def bilinear_taps(x: np.ndarray, y: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear taps of pixel coords x, y [N] (pixel centres at +0.5) on an h x w image.

    Returns flat indices [N, 4], weights [N, 4] and ``inside`` [N]: all four taps within the image.
    """
    fx, fy = x - 0.5, y - 0.5
    x0, y0 = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
    ax, ay = fx - x0, fy - y0
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + 1 <= w - 1) & (y0 + 1 <= h - 1)
    x0c, y0c = np.clip(x0, 0, w - 1), np.clip(y0, 0, h - 1)
    x1c, y1c = np.clip(x0 + 1, 0, w - 1), np.clip(y0 + 1, 0, h - 1)
    idx = np.stack([y0c * w + x0c, y0c * w + x1c, y1c * w + x0c, y1c * w + x1c], 1)
    wts = np.stack([(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay], 1)
    return idx, wts, inside


@dataclass
class Overlaps:
    """Pixel pairs seeing the same direction in two faces (i < j).

    ``face_a`` [P] and ``pix_a`` [P] (flat pixel index in face a); ``face_b`` [P], ``x_b``, ``y_b`` [P]
    (pixel coords of the matching point in face b), ``idx_b`` [P, 4] and ``wts_b`` [P, 4] (its bilinear
    taps); ``cos_a``, ``cos_b`` [P] obliquities.
    """

    face_a: np.ndarray
    pix_a: np.ndarray
    cos_a: np.ndarray
    face_b: np.ndarray
    x_b: np.ndarray
    y_b: np.ndarray
    idx_b: np.ndarray
    wts_b: np.ndarray
    cos_b: np.ndarray

    def __len__(self) -> int:
        return int(self.face_a.size)


def find_overlaps(K: np.ndarray, viewmat: np.ndarray, h: int, w: int, stride: int = 1) -> Overlaps:
    """All pixel pairs (face i pixel on a ``stride`` lattice, face j > i) that see the same direction."""
    dirs, cos = face_rays(K, viewmat, h, w)
    F = dirs.shape[0]
    rows, cols = np.meshgrid(np.arange(0, h, stride), np.arange(0, w, stride), indexing="ij")
    pix = (rows * w + cols).ravel()  # [n]
    parts: list[tuple] = []
    for i in range(F - 1):
        xs, ys, cbs = project(dirs[i].reshape(-1, 3)[pix], K[i + 1 :], viewmat[i + 1 :])  # [F - i - 1, n]
        for j in range(i + 1, F):
            x, y, cb = xs[j - i - 1], ys[j - i - 1], cbs[j - i - 1]
            idx, wts, inside = bilinear_taps(x, y, h, w)
            ok = inside & (cb > 1e-6)
            if ok.any():
                parts.append(
                    (
                        np.full(ok.sum(), i),
                        pix[ok],
                        cos[i].ravel()[pix[ok]],
                        np.full(ok.sum(), j),
                        x[ok],
                        y[ok],
                        idx[ok],
                        wts[ok],
                        cb[ok],
                    )
                )
    if not parts:
        e, f = np.zeros(0, dtype=np.int64), np.zeros(0)
        return Overlaps(e, e, f, e, f, f, np.zeros((0, 4), np.int64), np.zeros((0, 4)), f)
    cat = [np.concatenate(c) for c in zip(*parts)]
    return Overlaps(*cat)
