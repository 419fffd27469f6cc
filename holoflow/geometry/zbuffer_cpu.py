"""The z-buffer of ``pointcloud.project_points_zbuffer`` as one numba loop (CPU tensors): each point
writes its square once, instead of one masked pass over every point per square offset. Same result
bit for bit (nearest z wins, ties to the lowest point index); the torch path stays the reference and
the path for other devices (tests compare the two)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def zbuffer(ix, iy, z, ids, radii, width, height, depth, owner):
    """Fill depth [H W] (inf = empty) and owner [H W] (``N`` = empty) in place: point k (pixel ix[k],
    iy[k], depth z[k], index ids[k]) covers the (2 radii[k] - 1)^2 pixels around its pixel."""
    for k in range(z.shape[0]):
        r = radii[k]
        for py in range(max(iy[k] - r + 1, 0), min(iy[k] + r - 1, height - 1) + 1):
            for px in range(max(ix[k] - r + 1, 0), min(ix[k] + r - 1, width - 1) + 1):
                p = py * width + px
                if z[k] < depth[p] or (z[k] == depth[p] and ids[k] < owner[p]):
                    depth[p] = z[k]
                    owner[p] = ids[k]


def zbuffer_numpy(
    ix: np.ndarray, iy: np.ndarray, z: np.ndarray, ids: np.ndarray, radii: np.ndarray, width: int, height: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """(depth [H W], owner [H W]) of the points (int64 pixel ix, iy [M]; z [M]; ids, radii [M] int64)."""
    depth = np.full(height * width, np.inf, z.dtype)
    owner = np.full(height * width, n, np.int64)
    zbuffer(ix, iy, z, ids, radii, width, height, depth, owner)
    return depth, owner


def compile_ahead() -> None:
    """Compile ``zbuffer`` (or load it from numba's disk cache) for what the point stages pass: int64
    pixels and float64 depths (their clouds are float64). holoflow/flow/executors/ahead.py."""
    one = np.zeros(1, np.int64)
    zbuffer_numpy(one, one, np.ones(1), one, one + 1, 2, 2, 1)
