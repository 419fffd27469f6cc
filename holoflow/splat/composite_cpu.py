"""Fast CPU compositing: 16x16 pixel tiles, per-tile depth order, numba kernels for the forward pass
and a hand-written backward pass, glued to torch autograd.

Forward per pixel (front to back): sigma = 0.5 (a dx^2 + c dy^2) + b dx dy, alpha = min(0.99,
o exp(-sigma)); skip alpha < 1/255; stop before T would fall below 1e-4; out += f alpha T.
Backward walks each pixel's list back to front from the final transmittance (3DGS paper):
T_i = T_{i+1} / (1 - alpha_i) and a running suffix sum S = sum_{j>i} f_j w_j give
dL/dalpha_i = T_i <g, f_i> - <g, S> / (1 - alpha_i).

Work follows the Gaussian-pixel pairs that can matter, not pixels x Gaussians: every Gaussian
carries the pixel box where alpha >= 1/255 is possible (``project.pixel_extent``); Gaussians whose
box misses the image are culled before sorting; the rest are sorted front to back once and
counting-sorted into tile lists (stable, so each list stays in depth order). A tile task visits its
list once; per entry and pixel row it solves the ellipse sigma <= ln(255 o) for the exact column span,
so only pixels inside the 1/255 ellipse are evaluated, and it stops when every pixel of the tile has
saturated. Per-(tile, Gaussian) gradients are summed inside the tile task into their own slot and
the slots are summed per Gaussian in a fixed order: deterministic whatever the thread count. Kernels
are dtype-generic (float32 and float64 inputs, float64 arithmetic inside).
"""

from __future__ import annotations

import math
import types

import numba
import numpy as np
import torch
from numba import njit, prange

from holoflow.splat.project import ALPHA_MAX, ALPHA_MIN, T_MIN

TILE = 16  # tile side, px
SPAN_EPS = 1e-3  # px margin of the solved row span (pixels in it are still tested exactly)


@njit(parallel=True, cache=True)
def _boxes(visible, means2d, extent, opac, width, height, box):
    """Pixel box [N, 4] (x0, x1, y0, y1, inclusive, clipped to the image) of each Gaussian's 1/255
    reach; returns on-screen [N] bool (visible, finite, opacity >= 1/255 and the box meets the image).
    means2d, extent [N, 2] px; pixel (col, row) is sampled at (col + 0.5, row + 0.5)."""
    N = means2d.shape[0]
    keep = np.zeros(N, np.bool_)
    for g in prange(N):
        mx, my, ex, ey = means2d[g, 0], means2d[g, 1], extent[g, 0], extent[g, 1]
        box[g, 0], box[g, 1], box[g, 2], box[g, 3] = 0, -1, 0, -1
        if not (
            visible[g]
            and opac[g] >= ALPHA_MIN
            and math.isfinite(mx)
            and math.isfinite(my)
            and math.isfinite(ex)
            and math.isfinite(ey)
        ):
            continue
        x0 = math.ceil(min(max(mx - ex - 0.5, -1.0), width + 1.0))  # clipped: no int overflow
        x1 = math.floor(min(max(mx + ex - 0.5, -1.0), width + 1.0))
        y0 = math.ceil(min(max(my - ey - 0.5, -1.0), height + 1.0))
        y1 = math.floor(min(max(my + ey - 0.5, -1.0), height + 1.0))
        if x1 >= 0 and y1 >= 0 and x0 <= width - 1 and y0 <= height - 1 and x0 <= x1 and y0 <= y1:
            box[g, 0], box[g, 1] = max(x0, 0), min(x1, width - 1)
            box[g, 2], box[g, 3] = max(y0, 0), min(y1, height - 1)
            keep[g] = True
    return keep


@njit(parallel=True, cache=True)
def _bin_tiles(order, box, means2d, conics, opac, feats, width, height, chunks):
    """Pack the on-screen Gaussians front to back and list them per tile.

    order [n] on-screen Gaussians front to back; box [N, 4] from ``_boxes``; means2d [N, 2] px;
    conics [N, 3]; opac [N]; feats [N, F]. Returns rec [n, 7] (mx, my, a, b, c, o, sigma bound
    ln(255 o) + 1e-6), pbox [n, 4] (packed boxes), ft [n, F] (float64), offsets [tiles + 1],
    ids [M] (packed index, ascending = front to back within each tile; tiles row-major),
    pstart [n + 1] and ent [M] (each Gaussian's entries, by tile).

    A stable counting sort in ``chunks`` contiguous runs of the packed order: each run counts its
    entries per tile, a prefix over (tile, run) places the runs one after another inside every tile,
    then each run writes its entries. The lists are the same for any ``chunks``."""
    n = order.shape[0]
    F = feats.shape[1]
    ntx = (width + TILE - 1) // TILE
    ntiles = ntx * ((height + TILE - 1) // TILE)
    rec = np.empty((n, 7))
    pbox = np.empty((n, 4), np.int64)
    ft = np.empty((n, F))
    pstart = np.zeros(n + 1, np.int64)  # entries of Gaussian p: ent[pstart[p]:pstart[p + 1]]
    for p in prange(n):
        g = order[p]
        rec[p, 0], rec[p, 1] = means2d[g, 0], means2d[g, 1]
        rec[p, 2], rec[p, 3], rec[p, 4] = conics[g, 0], conics[g, 1], conics[g, 2]
        rec[p, 5] = opac[g]
        rec[p, 6] = math.log(opac[g] / ALPHA_MIN) + 1e-6
        for f in range(F):
            ft[p, f] = feats[g, f]
        for j in range(4):
            pbox[p, j] = box[g, j]
        pstart[p + 1] = (
            (box[g, 1] // TILE - box[g, 0] // TILE + 1)  # tiles its box meets
            * (box[g, 3] // TILE - box[g, 2] // TILE + 1)
        )
    for p in range(n):
        pstart[p + 1] += pstart[p]
    step = (n + chunks - 1) // chunks  # run c: packed indices [c step, (c + 1) step)
    counts = np.zeros((chunks, ntiles), np.int64)
    for c in prange(chunks):
        for p in range(c * step, min(n, (c + 1) * step)):
            for ty in range(pbox[p, 2] // TILE, pbox[p, 3] // TILE + 1):
                for tx in range(pbox[p, 0] // TILE, pbox[p, 1] // TILE + 1):
                    counts[c, ty * ntx + tx] += 1
    offsets = np.zeros(ntiles + 1, np.int64)
    pos = np.empty((chunks, ntiles), np.int64)  # where run c writes its next entry of tile t
    for t in range(ntiles):
        at = offsets[t]
        for c in range(chunks):
            pos[c, t] = at
            at += counts[c, t]
        offsets[t + 1] = at
    ids = np.empty(offsets[-1], np.int64)
    ent = np.empty(offsets[-1], np.int64)
    for c in prange(chunks):
        for p in range(c * step, min(n, (c + 1) * step)):
            i = pstart[p]
            for ty in range(pbox[p, 2] // TILE, pbox[p, 3] // TILE + 1):
                for tx in range(pbox[p, 0] // TILE, pbox[p, 1] // TILE + 1):
                    t = ty * ntx + tx
                    ids[pos[c, t]] = p
                    ent[i] = pos[c, t]
                    pos[c, t] += 1
                    i += 1
    return rec, pbox, ft, offsets, ids, pstart, ent


@njit(cache=True, inline="always")
def _row_span(rec, pbox, p, py, px0, px1):
    """Columns [lo, hi] of row py within [px0, px1] where sigma <= bound can hold (ellipse chord,
    widened by SPAN_EPS); hi < lo when none. Also returns dy = py + 0.5 - my."""
    dy = py + 0.5 - rec[p, 1]
    a, b = rec[p, 2], rec[p, 3]
    disc = b * b * dy * dy - a * (rec[p, 4] * dy * dy - 2.0 * rec[p, 6])
    lo, hi = max(px0, pbox[p, 0]), min(px1, pbox[p, 1])
    if not a > 0.0:  # degenerate conic: the whole box, tested pixel by pixel
        return lo, hi, dy
    if disc < 0.0:
        return lo, lo - 1, dy
    r = math.sqrt(disc)
    c0 = rec[p, 0] - 0.5 - b * dy / a
    flo = c0 - r / a - SPAN_EPS
    fhi = c0 + r / a + SPAN_EPS
    if flo > lo:
        lo = int(math.ceil(min(flo, hi + 1.0)))
    if fhi < hi:
        hi = int(math.floor(max(fhi, lo - 1.0)))
    return lo, hi, dy


@njit(cache=True, inline="always")
def _row_exp(ca, cb, sy, dx, dy):
    """exp(-sigma) at the first pixel of a row span (offset dx, dy from the centre) and the ratio
    exp(-(sigma(dx + 1) - sigma(dx))) to the next one. Along a row sigma is quadratic in dx, so
    exp(-sigma) steps by a ratio r that itself steps by q = exp(-a): two products a pixel instead of
    an exp (a third of the compositing time), the same values in the forward and backward passes.
    Spans are at most a tile (16 px) long, so the products drift by a few ulps at most."""
    return math.exp(-((0.5 * ca * dx + cb * dy) * dx + sy)), math.exp(-(ca * dx + 0.5 * ca + cb * dy))


@njit(cache=True, inline="always")
def _tile_origin(t, width):
    ntx = (width + TILE - 1) // TILE
    return (t % ntx) * TILE, (t // ntx) * TILE


@njit(parallel=True, cache=True)
def _forward(rec, pbox, ft, offsets, ids, width, height, out, t_final, n_last, evals):
    """One tile per task: entries front to back, each over its rows' ellipse spans; the task ends
    early once every pixel has saturated. out [H, W, F], t_final [H, W], n_last [H, W] (one past the
    last composited entry; the tile's list start if none), evals [tiles] (pairs evaluated)."""
    F = ft.shape[1]
    for t in prange(offsets.shape[0] - 1):
        s, e = offsets[t], offsets[t + 1]
        ox, oy = _tile_origin(t, width)
        tw, th = min(TILE, width - ox), min(TILE, height - oy)
        T = np.ones((TILE, TILE))
        acc = np.zeros((TILE, TILE, F))
        last = np.full((TILE, TILE), s)
        done = np.zeros((TILE, TILE), np.bool_)
        alive = tw * th
        ev = 0
        for k in range(s, e):
            p = ids[k]
            mx, ca, cb, cc, op, bound = rec[p, 0], rec[p, 2], rec[p, 3], rec[p, 4], rec[p, 5], rec[p, 6]
            q = math.exp(-ca)
            for py in range(max(oy, pbox[p, 2]), min(oy + th - 1, pbox[p, 3]) + 1):
                lo, hi, dy = _row_span(rec, pbox, p, py, ox, ox + tw - 1)
                ev += max(hi - lo + 1, 0)
                j = py - oy
                sy = 0.5 * cc * dy * dy
                e_next, r = _row_exp(ca, cb, sy, lo + 0.5 - mx, dy)
                for px in range(lo, hi + 1):
                    ex = e_next  # exp(-sigma) at px
                    e_next *= r
                    r *= q
                    i = px - ox
                    if done[j, i]:
                        continue
                    dx = px + 0.5 - mx
                    sig = (0.5 * ca * dx + cb * dy) * dx + sy
                    if sig < 0.0 or sig > bound:
                        continue
                    a = min(ALPHA_MAX, op * ex)
                    if a < ALPHA_MIN:
                        continue
                    t_next = T[j, i] * (1.0 - a)
                    if t_next < T_MIN:
                        done[j, i] = True
                        alive -= 1
                        continue
                    w = a * T[j, i]
                    for f in range(F):
                        acc[j, i, f] += ft[p, f] * w
                    T[j, i] = t_next
                    last[j, i] = k + 1
            if alive == 0:
                break
        evals[t] = ev
        for j in range(th):
            for i in range(tw):
                for f in range(F):
                    out[oy + j, ox + i, f] = acc[j, i, f]
                t_final[oy + j, ox + i] = T[j, i]
                n_last[oy + j, ox + i] = last[j, i]


@njit(parallel=True, cache=True)
def _backward(rec, pbox, ft, offsets, ids, width, height, t_final, n_last, g_out, eg):
    """Back to front per tile. eg [M, 6 + F] per entry (all written): d/d(mx, my), d/d(conic a, b, c),
    d/d opacity, d/d feats."""
    F = ft.shape[1]
    for t in prange(offsets.shape[0] - 1):
        s, e = offsets[t], offsets[t + 1]
        ox, oy = _tile_origin(t, width)
        tw, th = min(TILE, width - ox), min(TILE, height - oy)
        T = np.empty((TILE, TILE))
        stop = s  # entries at or past every pixel's n_last: no effect
        for j in range(th):
            for i in range(tw):
                T[j, i] = t_final[oy + j, ox + i]
                stop = max(stop, n_last[oy + j, ox + i])
        eg[stop:e] = 0.0
        S = np.zeros((TILE, TILE, F))
        gft = np.zeros(F)
        for k in range(stop - 1, s - 1, -1):
            p = ids[k]
            mx, ca, cb, cc, op, bound = rec[p, 0], rec[p, 2], rec[p, 3], rec[p, 4], rec[p, 5], rec[p, 6]
            q = math.exp(-ca)
            gm0 = gm1 = gc0 = gc1 = gc2 = go = 0.0
            gft[:] = 0.0
            for py in range(max(oy, pbox[p, 2]), min(oy + th - 1, pbox[p, 3]) + 1):
                lo, hi, dy = _row_span(rec, pbox, p, py, ox, ox + tw - 1)
                j = py - oy
                sy = 0.5 * cc * dy * dy
                e_next, r = _row_exp(ca, cb, sy, lo + 0.5 - mx, dy)
                for px in range(lo, hi + 1):
                    ex = e_next  # exp(-sigma) at px, as the forward pass had it
                    e_next *= r
                    r *= q
                    if k >= n_last[py, px]:
                        continue
                    i = px - ox
                    dx = px + 0.5 - mx
                    sig = (0.5 * ca * dx + cb * dy) * dx + sy
                    if sig < 0.0 or sig > bound:
                        continue
                    a_raw = op * ex
                    a = min(ALPHA_MAX, a_raw)
                    if a < ALPHA_MIN:
                        continue
                    T[j, i] = T[j, i] / (1.0 - a)
                    w = a * T[j, i]
                    gdot = 0.0
                    sdot = 0.0
                    for f in range(F):
                        gf = g_out[py, px, f]
                        gft[f] += gf * w
                        gdot += gf * ft[p, f]
                        sdot += gf * S[j, i, f]
                        S[j, i, f] += ft[p, f] * w
                    if a_raw > ALPHA_MAX:
                        continue
                    g_a = T[j, i] * gdot - sdot / (1.0 - a)
                    go += ex * g_a
                    g_sig = -a * g_a
                    gc0 += g_sig * 0.5 * dx * dx
                    gc1 += g_sig * dx * dy
                    gc2 += g_sig * 0.5 * dy * dy
                    gm0 -= g_sig * (ca * dx + cb * dy)
                    gm1 -= g_sig * (cb * dx + cc * dy)
            eg[k, 0], eg[k, 1] = gm0, gm1
            eg[k, 2], eg[k, 3], eg[k, 4] = gc0, gc1, gc2
            eg[k, 5] = go
            for f in range(F):
                eg[k, 6 + f] = gft[f]


@njit(parallel=True, cache=True)
def _gather_grads(pstart, ent, order, eg, g_m2, g_con, g_op, g_ft):
    """Sum per-entry gradients into per-Gaussian ones (original indices), tiles in fixed order."""
    F = g_ft.shape[1]
    for p in prange(pstart.shape[0] - 1):
        g = order[p]
        acc = np.zeros(6 + F)
        for i in range(pstart[p], pstart[p + 1]):
            k = ent[i]
            for j in range(6 + F):
                acc[j] += eg[k, j]
        g_m2[g, 0], g_m2[g, 1] = acc[0], acc[1]
        g_con[g, 0], g_con[g, 1], g_con[g, 2] = acc[2], acc[3], acc[4]
        g_op[g] = acc[5]
        for f in range(F):
            g_ft[g, f] = acc[6 + f]


# Serial twins for small problems: waking the thread pool costs more than it saves there,
# and much more on a loaded machine.
def serial_twin(dispatcher):
    """The same kernel compiled without parallel=True, under its own name (own cache entry)."""
    f = dispatcher.py_func
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial", f.__defaults__, f.__closure__)
    g.__qualname__ = f.__qualname__ + "_serial"
    return njit(cache=True)(g)


_boxes_serial = serial_twin(_boxes)
_bin_tiles_serial = serial_twin(_bin_tiles)
_forward_serial = serial_twin(_forward)
_backward_serial = serial_twin(_backward)
_gather_grads_serial = serial_twin(_gather_grads)
PARALLEL_MIN_ENTRIES = 2000  # tile entries below which the serial kernels run (measured, 2 idle cores: a
#                                 128 px view of 16k entries composites in 11.4 ms parallel, 21.7 ms serial)
PARALLEL_MIN_GAUSSIANS = 50000  # Gaussians below which the serial culling runs


def depth_order(depths: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Indices of kept Gaussians sorted front to back, ties by index. Sorts one int64 key
    (float32 bits of the depth, then the index): several times faster than a stable argsort."""
    idx = np.nonzero(keep)[0]
    bits = max(int(len(depths) - 1).bit_length(), 1)
    if bits > 32:
        return idx[np.argsort(depths[idx], kind="stable")]
    d = np.maximum(depths[idx], 0).astype(np.float32).view(np.int32).astype(np.int64)
    return np.sort((d << bits) | idx) & ((1 << bits) - 1)


def bin_camera(means2d, conics, opac, feats, depths, visible, extent, width, height):
    """Cull, depth-sort and tile-bin one camera (numpy arrays [N, ...]). Returns (order, pack) with
    pack = (rec, pbox, ft, offsets, ids, pstart, ent) as ``_bin_tiles``."""
    N = means2d.shape[0]
    box = np.empty((N, 4), np.int64)
    keep = (_boxes if N >= PARALLEL_MIN_GAUSSIANS else _boxes_serial)(
        visible, means2d, extent, opac, width, height, box
    )
    order = depth_order(depths, keep)
    if len(order) >= PARALLEL_MIN_GAUSSIANS:
        return order, _bin_tiles(order, box, means2d, conics, opac, feats, width, height, 4 * numba.get_num_threads())
    return order, _bin_tiles_serial(order, box, means2d, conics, opac, feats, width, height, 1)


def count_pairs(means2d, conics, opac, feats, depths, visible, extent, width, height) -> int:
    """Gaussian-pixel pairs the forward kernel visits for one camera (numpy arrays [N, ...] as
    ``bin_camera``): the work measure of `holoflow bench splat`."""
    order, pack = bin_camera(means2d, conics, opac, feats, depths, visible, extent, width, height)
    ntiles = ((width + TILE - 1) // TILE) * ((height + TILE - 1) // TILE)
    evals = np.zeros(ntiles, np.int64)
    _forward_serial(
        *pack[:5],
        width,
        height,
        np.empty((height, width, feats.shape[1]), feats.dtype),
        np.empty((height, width)),
        np.empty((height, width), np.int64),
        evals,
    )
    return int(evals.sum())


class _CompositeCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, opacities, feats, depths, visible, extent, width, height):
        # means2d [C, N, 2], conics [C, N, 3], opacities [C, N], feats [C, N, F], depths [C, N]
        # (sort key), visible [C, N]; extent [C, N, 2] px. depths, visible, extent: no gradient.
        C, N, F = feats.shape
        np_in = [t.detach().contiguous().numpy() for t in (means2d, conics, opacities, feats)]
        m2 = np_in[0].astype(np.float64)
        ex = extent.detach().to(torch.float64).contiguous().numpy()
        dp, vis = depths.detach().contiguous().numpy(), visible.contiguous().numpy()
        out = np.empty((C, height, width, F), np_in[3].dtype)
        t_final = np.empty((C, height, width))
        n_last = np.empty((C, height, width), np.int64)
        ntiles = ((width + TILE - 1) // TILE) * ((height + TILE - 1) // TILE)
        evals = np.zeros((C, ntiles), np.int64)
        packs = []
        for c in range(C):
            order, pack = bin_camera(m2[c], np_in[1][c], np_in[2][c], np_in[3][c], dp[c], vis[c], ex[c], width, height)
            fwd = _forward if pack[4].shape[0] >= PARALLEL_MIN_ENTRIES else _forward_serial
            fwd(*pack[:5], width, height, out[c], t_final[c], n_last[c], evals[c])
            packs.append((order, pack))
        ctx.saved = (packs, t_final, n_last, width, height, [a.shape for a in np_in], np_in[3].dtype)
        ctx.evals = int(evals.sum())
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, grad_out):
        packs, t_final, n_last, width, height, shapes, dtype = ctx.saved
        F = shapes[3][2]
        g_out = grad_out.detach().to(torch.float64).contiguous().numpy()
        grads = [np.zeros(sh, dtype) for sh in shapes]
        for c, (order, (rec, pbox, ft, offsets, ids, pstart, ent)) in enumerate(packs):
            eg = np.empty((ids.shape[0], 6 + F))
            par = ids.shape[0] >= PARALLEL_MIN_ENTRIES
            (_backward if par else _backward_serial)(
                rec, pbox, ft, offsets, ids, width, height, t_final[c], n_last[c], g_out[c], eg
            )
            (_gather_grads if par else _gather_grads_serial)(pstart, ent, order, eg, *[g[c] for g in grads])
        return (*[torch.from_numpy(g) for g in grads], None, None, None, None, None)


def composite_cpu(
    means2d: torch.Tensor,
    conics: torch.Tensor,
    opacities: torch.Tensor,
    feats: torch.Tensor,
    depths: torch.Tensor,
    visible: torch.Tensor,
    extent: torch.Tensor,
    width: int,
    height: int,
) -> torch.Tensor:
    """Fast compositing, same contract as ``reference.composite_dense`` plus ``extent`` [C, N, 2]
    (px half-size of each Gaussian's reach, see ``project.pixel_extent``). Returns [C, H, W, F]."""
    return _CompositeCPU.apply(means2d, conics, opacities, feats, depths, visible, extent, width, height)
