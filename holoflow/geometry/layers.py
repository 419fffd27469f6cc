"""Layered background: the far surface continued under every near silhouette of an equirect RGB-D image.

A panorama sees one surface per direction. Moving the eye by ``b`` metres uncovers, beside a
silhouette at depth d_n in front of a surface at depth d_f, a band of the far surface about

    b (1 / d_n - 1 / d_f)  radians

wide (the parallax difference of the two depths). ``background_layer`` makes that band: it grows the
far surface under the near one, outwards from the edge, one pixel ring per round, until the band is as
wide as a move of ``baseline`` metres can uncover there (or ``max_deg``). The sky / far shell is one
such far surface (the point_cloud stage puts sky on its shell first), so it continues under the
silhouettes of whatever stands against it.

Growth (a front that starts at every source pixel): a pixel without a layer value takes one from the
neighbours (8-connected, columns wrapping) that got theirs in the previous round (in round 1: the
source pixels themselves, each carrying its own surface) when that value lies behind the pixel's own
surface by more than ``tol`` (relative) and the pixel is within the band of that value. Among the
candidates within ``tol`` of the farthest depth, the one with the shortest path from its edge
carries on, and their colours are averaged (the far side's colour, streaked along the front; never
the near object's). With ``farthest``, a pixel that has a layer value takes a farther one (by more
than ``tol``) when a front reaches it later: where the layers of two silhouettes meet, a step to
the side shows the farthest surface behind both (a door jamb, a wall beyond a cupboard), so that one
carries on; the sky's shell never takes a pixel over (the sky dome stands behind everything).
Without it the first layer to reach a pixel keeps it: each silhouette's own far side. P_f takes
both (holoflow/geometry/clouds.py): the first layers, and the farthest where it lies behind them.

The layer keeps the depth of its edge pixel, or with ``slope`` is extrapolated linearly in inverse
depth along the growth direction from the two source pixels at the edge (planes
stay nearly planar: 1 / depth is affine along an image line under a pinhole; on the sphere locally),
clamped to within a factor 1.5 of the edge's own depth. Off by default: on an estimated depth map
the two pixels at an edge are rarely the far surface's own (a ramp, noise), and their slope throws
the layer away from the surface it continues (docs/reconstruction.md).
The band is measured in angle on the sphere (a column step is cos(latitude) x a row step).

Pixels that are not sources (P_f's dropped edge pixels, whose depth mixes both sides) count as lying
at the nearest depth of their 3 x 3 neighbourhood: they sit on the silhouette and the far surface
continues under them too.

Conventions: radial depth in metres, equirect pixel centres (holoflow/geometry/sphere.py, docs/conventions.md).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit

MAX_DEPTH_RATIO = 1.5  # extrapolated layer depth stays within this factor of the edge's own depth


def background_layer(
    rgb: torch.Tensor,
    radial_depth: torch.Tensor,
    source: torch.Tensor,
    baseline: float,
    tol: float = 0.1,
    max_deg: float = 30.0,
    stride: int = 1,
    slope: bool = False,
    shell: float = math.inf,
    farthest: bool = True,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The far surfaces continued under the near silhouettes (module docstring).

    rgb [H, W, C] (any colour space: it is averaged), radial_depth [H, W] metres (finite > 0 wherever
    ``source``; the unfiltered depth elsewhere), source [H, W] bool (pixels whose own surface is known:
    P_f's kept pixels); baseline:
    the largest eye move (m) whose disocclusions the layer must cover; tol: relative depth step that
    counts as an occlusion edge; max_deg: cap on the band's width; slope: extrapolate the far
    surface's inverse-depth slope (module docstring); farthest: a farther surface takes a pixel over
    from a nearer layer that reached it first (module docstring; False: the first to arrive keeps it,
    each silhouette's own far side); shell: the sky's shell radius (m), whose layer never takes a
    pixel over (the sky dome is behind everything); stride: keep the layer on every
    stride-th row and column only (the layer is seen from off the centre only: sparser points, whose
    Gaussians start larger, cost less training). Returns (layer depth [H, W] metres,
    inf where the pixel has no layer; layer colour [H, W, C], 0 there): an equirect RGB-D image whose
    points (``pointcloud.equirect_to_points``, which skips inf) are the layer."""
    H, W = radial_depth.shape
    d = radial_depth.detach().cpu().double().numpy()
    src = source.detach().cpu().numpy().astype(np.bool_) & np.isfinite(d) & (d > 0)
    raw = np.where(np.isfinite(d) & (d > 0), d, np.inf)
    pad = np.pad(raw, ((1, 1), (0, 0)), constant_values=np.inf)
    nbr = pad[1 : H + 1].copy()  # [H, W] the nearest depth of each pixel's 3 x 3 neighbourhood
    for dy in (-1, 0, 1):
        for s in (-1, 0, 1):
            np.minimum(nbr, np.roll(pad, s, 1)[1 + dy : H + 1 + dy], out=nbr)
    near = np.where(src, d, nbr)  # non-sources: the nearest depth around them
    col = np.ascontiguousarray(rgb.detach().cpu().double().numpy().reshape(H, W, -1))
    lat = (0.5 - (np.arange(H) + 0.5) / H) * math.pi
    out_d = np.full((H, W), np.inf)
    out_c = np.zeros_like(col)
    _grow(
        d,
        src,
        near,
        col,
        np.cos(lat),
        2 * math.pi / W,
        float(baseline),
        float(tol),
        math.radians(max_deg),
        1.0 / shell,
        farthest,
        out_d,
        out_c,
        slope,
    )
    if stride > 1:
        sparse = np.ones((H, W), bool)
        sparse[::stride, ::stride] = False
        out_d[sparse] = np.inf
        out_c[sparse] = 0.0
    return (
        torch.from_numpy(out_d).to(radial_depth.dtype).to(radial_depth.device),
        torch.from_numpy(out_c).to(rgb.dtype).to(rgb.device),
    )


@njit(cache=True)
def _grow(d, src, near, col, coslat, step, baseline, tol, max_ang, inv_shell, takeover, out_d, out_c, use_slope):
    """The growth rounds of ``background_layer``; fills out_d [H, W] (layer depth, inf = none) and
    out_c [H, W, C] in place."""
    H, W = d.shape
    C = col.shape[2]
    inv0 = np.zeros((H, W))  # inverse depth of the edge pixel a value came from
    slope = np.zeros((H, W))  # its inverse-depth change per pixel step
    steps = np.zeros((H, W))  # pixel steps from the edge
    ang = np.zeros((H, W))  # angle from the edge (rad)
    rnd = np.full((H, W), -1, np.int64)  # round the pixel got its layer value
    stamp = np.full((H, W), -1, np.int64)  # last round the pixel was a candidate
    front = np.empty(H * W, np.int64)  # pixels that got a value in the previous round
    nf = 0
    cand = np.empty(H * W, np.int64)
    best_i = np.empty(8)
    best_0 = np.empty(8)
    best_s = np.empty(8)
    best_k = np.empty(8)
    best_a = np.empty(8)
    best_q = np.empty(8, np.int64)
    r = 0
    while True:
        r += 1
        nc = 0  # candidates: neighbours of the front
        if r == 1:
            for p in range(H * W):
                cand[nc] = p
                nc += 1
        else:
            for f in range(nf):
                qy, qx = front[f] // W, front[f] % W
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        py, px = qy + dy, (qx + dx) % W
                        if (dy == 0 and dx == 0) or py < 0 or py >= H:
                            continue
                        if stamp[py, px] != r and (takeover or rnd[py, px] < 0):
                            stamp[py, px] = r
                            cand[nc] = py * W + px
                            nc += 1
        nf_new = 0
        for c in range(nc):
            py, px = cand[c] // W, cand[c] % W
            if rnd[py, px] == r or (rnd[py, px] >= 0 and not takeover):
                continue
            n_ok = 0
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    qy, qx = py + dy, (px + dx) % W
                    if (dy == 0 and dx == 0) or qy < 0 or qy >= H:
                        continue
                    if r == 1:
                        if not src[qy, qx]:
                            continue
                        i0 = 1.0 / d[qy, qx]
                        s = 0.0  # continue the far surface's slope when it is smooth
                        ry, rx = qy + dy, (qx + dx) % W  # the next pixel beyond q, away from p
                        if use_slope and 0 <= ry < H and src[ry, rx] and abs(d[ry, rx] / d[qy, qx] - 1.0) < tol:
                            s = i0 - 1.0 / d[ry, rx]
                        k = 1.0
                        a0 = 0.0
                    else:
                        if rnd[qy, qx] != r - 1:
                            continue
                        i0, s, k, a0 = inv0[qy, qx], slope[qy, qx], steps[qy, qx] + 1.0, ang[qy, qx]
                    a = a0 + step * math.sqrt((dx * coslat[py]) ** 2 + dy * dy)
                    ib = min(max(i0 + k * s, i0 / MAX_DEPTH_RATIO), i0 * MAX_DEPTH_RATIO)
                    inv_near = 1.0 / near[py, px]
                    if ib > (1.0 - tol) * inv_near:  # not behind this pixel's surface
                        continue
                    if a > max_ang or a > baseline * (inv_near - ib) + step:  # beyond what a move uncovers
                        continue
                    best_i[n_ok], best_0[n_ok], best_s[n_ok], best_k[n_ok], best_a[n_ok] = ib, i0, s, k, a
                    best_q[n_ok] = qy * W + qx
                    n_ok += 1
            if n_ok == 0:
                continue
            far = best_i[0]
            for t in range(1, n_ok):
                far = min(far, best_i[t])
            if rnd[py, px] >= 0 and (far > (1.0 - tol) / out_d[py, px] or far <= inv_shell * (1.0 + 1e-9)):
                continue  # a layer as near or nearer is there, or this is the sky's
            j = -1
            wsum = 0.0
            for ch in range(C):
                out_c[py, px, ch] = 0.0
            for t in range(n_ok):
                if best_i[t] * (1.0 - tol) <= far:  # within tol of the farthest
                    if j < 0 or best_a[t] < best_a[j]:  # the straightest path carries on
                        j = t
                    qy, qx = best_q[t] // W, best_q[t] % W
                    for ch in range(C):
                        out_c[py, px, ch] += col[qy, qx, ch] if r == 1 else out_c[qy, qx, ch]
                    wsum += 1.0
            for ch in range(C):
                out_c[py, px, ch] /= wsum
            inv0[py, px], slope[py, px], steps[py, px], ang[py, px] = best_0[j], best_s[j], best_k[j], best_a[j]
            out_d[py, px] = 1.0 / best_i[j]
            rnd[py, px] = r
            cand[nf_new] = cand[c]  # reuse cand's slots already read as the next front
            nf_new += 1
        if nf_new == 0:
            break
        for f in range(nf_new):
            front[f] = cand[f]
        nf = nf_new


def compile_ahead() -> None:
    """Compile ``_grow`` (or load it from numba's disk cache): ``background_layer`` passes float64
    arrays whatever its inputs' dtype. holoflow/flow/executors/ahead.py."""
    d = torch.tensor([[1.0, 1.0, 2.0, 2.0], [1.0, 1.0, 2.0, 2.0]])  # [2, 4] a near and a far half
    background_layer(torch.zeros(2, 4, 3), d, torch.ones(2, 4, dtype=torch.bool), 0.5)
