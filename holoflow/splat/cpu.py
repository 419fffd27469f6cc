"""Fast CPU compositing: image-row bins in depth order, numba kernels for the forward pass and a
hand-written backward pass, glued to torch autograd.

Forward per pixel (front to back): sigma = 0.5 (a dx^2 + c dy^2) + b dx dy, alpha = min(0.99,
o exp(-sigma)); skip alpha < 1/255; stop before T would fall below 1e-4; out += f alpha T.
Backward walks each pixel's list back to front from the final transmittance (3DGS paper):
T_i = T_{i+1} / (1 - alpha_i) and a running suffix sum S = sum_{j>i} f_j w_j give
dL/dalpha_i = T_i <g, f_i> - <g, S> / (1 - alpha_i).

Work follows the Gaussian-pixel pairs that can matter, not pixels x Gaussians: every Gaussian
carries the pixel box where alpha >= 1/255 is possible (``project.pixel_extent``); Gaussians are
packed front to back and listed per image row; a row task visits its list once and scatters each
entry over its pixel span (per-pixel early stop). Per-(row, Gaussian) gradients go to their own slots
and are summed in a fixed order, so results are deterministic whatever the thread count. Kernels are
dtype-generic (float32 and float64 inputs, float64 arithmetic inside).
"""
from __future__ import annotations

import math
import types

import numpy as np
import torch
from numba import njit, prange

from holoflow.splat.project import ALPHA_MAX, ALPHA_MIN, T_MIN

@njit(cache=True)
def _bin_rows(order, means2d, extent, conics, opac, feats, width, height):
    """Pack visible Gaussians front to back and list them per image row.

    order [n] visible Gaussians front to back; means2d, extent [N, 2] px; conics [N, 3]; opac [N];
    feats [N, F]. Returns rec [n, 9] (mx, my, a, b, c, o, sigma bound ln(255 o) + 1e-6, x0, x1),
    ft [n, F] (packed, float64), offsets [H + 1], ids [M] (packed index, ascending = front to back
    within each row), pstart [n + 1] and ent [M] (each Gaussian's entries, by row). Gaussians whose
    pixel box misses the image get no row entries."""
    n = order.shape[0]
    F = feats.shape[1]
    rec = np.zeros((n, 9))
    ft = np.empty((n, F))
    y0s = np.zeros(n, np.int64)
    y1s = np.full(n, -1, np.int64)
    for p in range(n):
        g = order[p]
        mx, my, ex, ey = means2d[g, 0], means2d[g, 1], extent[g, 0], extent[g, 1]
        for f in range(F):
            ft[p, f] = feats[g, f]
        if not (math.isfinite(mx) and math.isfinite(my) and math.isfinite(ex) and math.isfinite(ey)):
            continue
        x0 = math.ceil(min(max(mx - ex - 0.5, -1.0), width + 1.0))     # clipped: no int overflow
        x1 = math.floor(min(max(mx + ex - 0.5, -1.0), width + 1.0))
        y0 = math.ceil(min(max(my - ey - 0.5, -1.0), height + 1.0))
        y1 = math.floor(min(max(my + ey - 0.5, -1.0), height + 1.0))
        if not (x1 >= 0 and y1 >= 0 and x0 <= width - 1 and y0 <= height - 1):
            continue
        rec[p, 0], rec[p, 1] = mx, my
        rec[p, 2], rec[p, 3], rec[p, 4] = conics[g, 0], conics[g, 1], conics[g, 2]
        rec[p, 5] = opac[g]
        rec[p, 6] = math.log(opac[g] / ALPHA_MIN) + 1e-6 if opac[g] > 0 else -1.0
        rec[p, 7], rec[p, 8] = max(x0, 0), min(x1, width - 1)
        y0s[p], y1s[p] = max(y0, 0), min(y1, height - 1)
    counts = np.zeros(height + 1, np.int64)
    for p in range(n):
        for y in range(y0s[p], y1s[p] + 1):
            counts[y + 1] += 1
    offsets = np.cumsum(counts)
    pos = offsets[:-1].copy()
    ids = np.empty(offsets[-1], np.int64)
    pstart = np.zeros(n + 1, np.int64)          # entries of Gaussian p: ent[pstart[p]:pstart[p + 1]]
    for p in range(n):
        pstart[p + 1] = pstart[p] + max(y1s[p] - y0s[p] + 1, 0)
    ent = np.empty(offsets[-1], np.int64)
    for p in range(n):
        for y in range(y0s[p], y1s[p] + 1):
            ids[pos[y]] = p
            ent[pstart[p] + y - y0s[p]] = pos[y]
            pos[y] += 1
    return rec, ft, offsets, ids, pstart, ent


@njit(parallel=True, cache=True)
def _forward(rec, ft, offsets, ids, width, out, t_final, n_last):
    """One image row per task: entries visited front to back, each scattered over its pixel span.
    out [H, W, F], t_final [H, W], n_last [H, W] (one past the last composited entry; row start if none)."""
    F = ft.shape[1]
    for py in prange(offsets.shape[0] - 1):
        s, e = offsets[py], offsets[py + 1]
        fy = py + 0.5
        T = np.ones(width)
        acc = np.zeros((width, F))
        last = np.full(width, s)
        done = np.zeros(width, np.bool_)
        alive = width
        for k in range(s, e):
            p = ids[k]
            for px in range(int(rec[p, 7]), int(rec[p, 8]) + 1):
                if done[px]:
                    continue
                dx = px + 0.5 - rec[p, 0]
                dy = fy - rec[p, 1]
                sig = 0.5 * (rec[p, 2] * dx * dx + rec[p, 4] * dy * dy) + rec[p, 3] * dx * dy
                if sig < 0.0 or sig > rec[p, 6]:
                    continue
                a = min(ALPHA_MAX, rec[p, 5] * math.exp(-sig))
                if a < ALPHA_MIN:
                    continue
                t_next = T[px] * (1.0 - a)
                if t_next < T_MIN:
                    done[px] = True
                    alive -= 1
                    continue
                w = a * T[px]
                for f in range(F):
                    acc[px, f] += ft[p, f] * w
                T[px] = t_next
                last[px] = k + 1
            if alive == 0:
                break
        for px in range(width):
            for f in range(F):
                out[py, px, f] = acc[px, f]
            t_final[py, px] = T[px]
            n_last[py, px] = last[px]


@njit(parallel=True, cache=True)
def _backward(rec, ft, offsets, ids, width, t_final, n_last, g_out, e_m2, e_con, e_op, e_ft):
    """Back to front per row. Per entry k: e_m2 [M, 2], e_con [M, 3], e_op [M], e_ft [M, F] (all
    written)."""
    F = ft.shape[1]
    for py in prange(offsets.shape[0] - 1):
        s, e = offsets[py], offsets[py + 1]
        fy = py + 0.5
        T = t_final[py].copy()
        S = np.zeros((width, F))
        gft = np.zeros(F)
        for k in range(e - 1, s - 1, -1):
            p = ids[k]
            gm0 = gm1 = gc0 = gc1 = gc2 = go = 0.0
            gft[:] = 0.0
            for px in range(int(rec[p, 7]), int(rec[p, 8]) + 1):
                if k >= n_last[py, px]:
                    continue
                dx = px + 0.5 - rec[p, 0]
                dy = fy - rec[p, 1]
                sig = 0.5 * (rec[p, 2] * dx * dx + rec[p, 4] * dy * dy) + rec[p, 3] * dx * dy
                if sig < 0.0 or sig > rec[p, 6]:
                    continue
                ex = math.exp(-sig)
                a_raw = rec[p, 5] * ex
                a = min(ALPHA_MAX, a_raw)
                if a < ALPHA_MIN:
                    continue
                T[px] = T[px] / (1.0 - a)
                w = a * T[px]
                gdot = 0.0
                sdot = 0.0
                for f in range(F):
                    gf = g_out[py, px, f]
                    gft[f] += gf * w
                    gdot += gf * ft[p, f]
                    sdot += gf * S[px, f]
                    S[px, f] += ft[p, f] * w
                if a_raw > ALPHA_MAX:
                    continue
                g_a = T[px] * gdot - sdot / (1.0 - a)
                go += ex * g_a
                g_sig = -a * g_a
                gc0 += g_sig * 0.5 * dx * dx
                gc1 += g_sig * dx * dy
                gc2 += g_sig * 0.5 * dy * dy
                gm0 -= g_sig * (rec[p, 2] * dx + rec[p, 3] * dy)
                gm1 -= g_sig * (rec[p, 3] * dx + rec[p, 4] * dy)
            e_m2[k, 0], e_m2[k, 1] = gm0, gm1
            e_con[k, 0], e_con[k, 1], e_con[k, 2] = gc0, gc1, gc2
            e_op[k] = go
            for f in range(F):
                e_ft[k, f] = gft[f]


@njit(parallel=True, cache=True)
def _gather_grads(pstart, ent, order, e_m2, e_con, e_op, e_ft, g_m2, g_con, g_op, g_ft):
    """Sum per-entry gradients into per-Gaussian ones (original indices), rows in fixed order."""
    for p in prange(pstart.shape[0] - 1):
        g = order[p]
        for i in range(pstart[p], pstart[p + 1]):
            k = ent[i]
            g_m2[g, 0] += e_m2[k, 0]
            g_m2[g, 1] += e_m2[k, 1]
            for j in range(3):
                g_con[g, j] += e_con[k, j]
            g_op[g] += e_op[k]
            for f in range(e_ft.shape[1]):
                g_ft[g, f] += e_ft[k, f]


# Serial twins for small problems: waking the thread pool costs more than it saves there,
# and much more on a loaded machine.
def serial_twin(dispatcher):
    """The same kernel compiled without parallel=True, under its own name (own cache entry)."""
    f = dispatcher.py_func
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial", f.__defaults__,
                           f.__closure__)
    g.__qualname__ = f.__qualname__ + "_serial"
    return njit(cache=True)(g)


_forward_serial = serial_twin(_forward)
_backward_serial = serial_twin(_backward)
_gather_grads_serial = serial_twin(_gather_grads)
PARALLEL_MIN_ENTRIES = 20000   # row entries below which the serial kernels run


def depth_order(depths: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """Indices of visible Gaussians sorted front to back, ties by index. Sorts one int64 key
    (float32 bits of the depth, then the index): several times faster than a stable argsort."""
    idx = np.nonzero(visible)[0]
    bits = max(int(len(depths) - 1).bit_length(), 1)
    if bits > 32:
        return idx[np.argsort(depths[idx], kind="stable")]
    d = np.maximum(depths[idx], 0).astype(np.float32).view(np.int32).astype(np.int64)
    return np.sort((d << bits) | idx) & ((1 << bits) - 1)


class _CompositeCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, opacities, feats, orders, extent, width, height):
        # means2d [C, N, 2], conics [C, N, 3], opacities [C, N], feats [C, N, F]; orders: per camera
        # visible Gaussians front to back; extent [C, N, 2] px (no gradient)
        C, N, F = feats.shape
        np_in = [t.detach().contiguous().numpy() for t in (means2d, conics, opacities, feats)]
        m2 = np_in[0].astype(np.float64)
        ex = extent.detach().to(torch.float64).contiguous().numpy()
        out = np.empty((C, height, width, F), np_in[3].dtype)
        t_final = np.empty((C, height, width))
        n_last = np.empty((C, height, width), np.int64)
        packs = []
        for c in range(C):
            pack = _bin_rows(orders[c], m2[c], ex[c], np_in[1][c], np_in[2][c], np_in[3][c], width, height)
            fwd = _forward if pack[3].shape[0] >= PARALLEL_MIN_ENTRIES else _forward_serial
            fwd(*pack[:4], width, out[c], t_final[c], n_last[c])
            packs.append(pack)
        ctx.saved = (packs, orders, t_final, n_last, width, [a.shape for a in np_in], np_in[3].dtype)
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, grad_out):
        packs, orders, t_final, n_last, width, shapes, dtype = ctx.saved
        F = shapes[3][2]
        g_out = grad_out.detach().to(torch.float64).contiguous().numpy()
        grads = [np.zeros(sh, dtype) for sh in shapes]
        for c, (rec, ft, offsets, ids, pstart, ent) in enumerate(packs):
            M = ids.shape[0]
            e = (np.empty((M, 2)), np.empty((M, 3)), np.empty(M), np.empty((M, F)))
            par = M >= PARALLEL_MIN_ENTRIES
            (_backward if par else _backward_serial)(rec, ft, offsets, ids, width, t_final[c],
                                                     n_last[c], g_out[c], *e)
            (_gather_grads if par else _gather_grads_serial)(pstart, ent, orders[c], *e,
                                                             *[g[c] for g in grads])
        return (*[torch.from_numpy(g) for g in grads], None, None, None, None)


def composite_cpu(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor,
                  feats: torch.Tensor, depths: torch.Tensor, visible: torch.Tensor,
                  extent: torch.Tensor, width: int, height: int) -> tuple[torch.Tensor, list]:
    """Fast compositing, same contract as ``reference.composite_dense`` plus ``extent`` [C, N, 2]
    (px half-size of each Gaussian's reach, see ``project.pixel_extent``).
    Returns (out [C, H, W, F], orders: per camera the visible Gaussians front to back)."""
    dp, vis = depths.detach().numpy(), visible.numpy()
    orders = [depth_order(dp[c], vis[c]) for c in range(feats.shape[0])]
    out = _CompositeCPU.apply(means2d, conics, opacities, feats, orders, extent, width, height)
    return out, orders
