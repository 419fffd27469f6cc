"""Fused numba projection (forward + hand-written backward) for the fast CPU path.

Same math as ``project.project_gaussians`` (which the dense reference uses through autograd):
p = R m + t; J with x/z, y/z clamped to 1.3x the half field of view; cov2d = (J R) Rq S S Rq^T (J R)^T
+ 0.3 I; conic = cov2d^-1. Numba kernels over Gaussians (prange) instead of ~50 tensor-sized torch ops.
Gradients flow to means, quats (through the normalisation) and scales; cameras are constants.

Packed outputs (as gsplat's ``packed=True``): only the (camera, Gaussian) pairs that are drawn, camera
by camera, each camera's in Gaussian index order. A view of a panorama scene draws a few % of the
pairs; [C, N] outputs cost more to write (and to fault in) than the math. The first pass tests every
pair (a [C, N] bool), the drawn ones are counted per fixed chunk of Gaussians and camera, and the
second pass computes and writes them at the offsets a prefix sum of the counts gave: the same bytes
for any thread count.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from holoflow.splat.composite_cpu import serial_twin
from holoflow.splat.project import ALPHA_MIN, EPS2D


@njit(cache=True)
def _quat_sigma(q0, q1, q2, q3, s0, s1, s2):
    """Unit quaternion (zero -> identity), |q|, rotation (9 scalars, row-major) and the 3D covariance
    Sigma = Rq diag(s)^2 Rq^T (6 scalars: 00 01 02 11 12 22)."""
    sq = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    if sq > 1e-24:
        n = math.sqrt(sq)
        w, x, y, z = q0 / n, q1 / n, q2 / n, q3 / n
    else:
        n = 0.0
        w, x, y, z = 1.0, 0.0, 0.0, 0.0
    R = (
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    )
    m = (R[0] * s0, R[1] * s1, R[2] * s2, R[3] * s0, R[4] * s1, R[5] * s2, R[6] * s0, R[7] * s1, R[8] * s2)
    S = (
        m[0] * m[0] + m[1] * m[1] + m[2] * m[2],
        m[0] * m[3] + m[1] * m[4] + m[2] * m[5],
        m[0] * m[6] + m[1] * m[7] + m[2] * m[8],
        m[3] * m[3] + m[4] * m[4] + m[5] * m[5],
        m[3] * m[6] + m[4] * m[7] + m[5] * m[8],
        m[6] * m[6] + m[7] * m[7] + m[8] * m[8],
    )
    return (w, x, y, z, n), R, m, S


@njit(cache=True)
def _camera(view, Ks, c, means, n, width, height):
    """Camera-space point, clamp limits and the two rows of J R (before the clamp test)."""
    mx, my, mz = means[n, 0], means[n, 1], means[n, 2]
    x = view[c, 0, 0] * mx + view[c, 0, 1] * my + view[c, 0, 2] * mz + view[c, 0, 3]
    y = view[c, 1, 0] * mx + view[c, 1, 1] * my + view[c, 1, 2] * mz + view[c, 1, 3]
    z = view[c, 2, 0] * mx + view[c, 2, 1] * my + view[c, 2, 2] * mz + view[c, 2, 3]
    fx, fy, cx, cy = Ks[c, 0, 0], Ks[c, 1, 1], Ks[c, 0, 2], Ks[c, 1, 2]
    tx, ty = 0.5 * width / fx, 0.5 * height / fy
    lim = (-(cx / fx + 0.3 * tx), (width - cx) / fx + 0.3 * tx, -(cy / fy + 0.3 * ty), (height - cy) / fy + 0.3 * ty)
    return x, y, z, fx, fy, cx, cy, lim


@njit(cache=True)
def _rows(view, c, fx, fy, z, u, v):
    """r0 = fx/z (R0 - u R2), r1 = fy/z (R1 - v R2) (rows of J R)."""
    a, b = fx / z, fy / z
    r0 = (
        a * (view[c, 0, 0] - u * view[c, 2, 0]),
        a * (view[c, 0, 1] - u * view[c, 2, 1]),
        a * (view[c, 0, 2] - u * view[c, 2, 2]),
    )
    r1 = (
        b * (view[c, 1, 0] - v * view[c, 2, 0]),
        b * (view[c, 1, 1] - v * view[c, 2, 1]),
        b * (view[c, 1, 2] - v * view[c, 2, 2]),
    )
    return r0, r1


@njit(cache=True)
def _symv(S, r):
    """Sigma @ r for Sigma given by 6 scalars."""
    return (
        S[0] * r[0] + S[1] * r[1] + S[2] * r[2],
        S[1] * r[0] + S[3] * r[1] + S[4] * r[2],
        S[2] * r[0] + S[4] * r[1] + S[5] * r[2],
    )


@njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


CHUNK = 4096  # Gaussians per task of the two forward passes


@njit(cache=True, inline="always")
def _screen(view, Ks, c, means, n, width, height, near, far, kk, tr):
    """Pair (c, n) up to the covariance: (meets, z, mx, my, r0, r1). ``meets``: near < z < far and the
    centre (mx, my) px lies within a cheap bound on the reach of the image: along x
    k sqrt(r0' Sigma r0 + 0.3) with r0 = fx/z (R0 - u R2) and r0' Sigma r0 <= |r0|^2 tr(Sigma)."""
    x, y, z, fx, fy, cx, cy, lim = _camera(view, Ks, c, means, n, width, height)
    zero = (0.0, 0.0, 0.0)
    if not (z > near and z < far):
        return False, 1.0, 0.0, 0.0, zero, zero
    z = float(z)  # float64 from here
    mx, my = fx * x / z + cx, fy * y / z + cy
    u = min(max(x / z, lim[0]), lim[1])
    v = min(max(y / z, lim[2]), lim[3])
    r0, r1 = _rows(view, c, fx, fy, z, u, v)
    bx = kk * math.sqrt(_dot(r0, r0) * tr + EPS2D) * 1.0002 + 1e-3  # >= the exact reach, rounding too
    by = kk * math.sqrt(_dot(r1, r1) * tr + EPS2D) * 1.0002 + 1e-3
    return _meets(mx, my, bx, by, width, height), z, mx, my, r0, r1


@njit(cache=True, inline="always")
def _cov2d(S, r0, r1, kk):
    """cov2d (a, b, c) = W Sigma W^T + 0.3 I with W rows r0, r1, and the reach (ex, ey) px of alpha >= 1/255."""
    s1 = _symv(S, r1)
    a = _dot(r0, _symv(S, r0)) + EPS2D
    b = _dot(r0, s1)
    cc = _dot(r1, s1) + EPS2D
    return a, b, cc, kk * math.sqrt(a) * 1.0001 + 1e-3, kk * math.sqrt(cc) * 1.0001 + 1e-3


@njit(cache=True, inline="always")
def _reach_factor(opac, n):
    """sqrt(2 ln(255 o)) of Gaussian n: the Mahalanobis radius where its alpha falls to 1/255."""
    return math.sqrt(2.0 * math.log(max(opac[n] / ALPHA_MIN, 1.0)))


@njit(parallel=True, cache=True)
def _project_test(means, quats, scales, opac, view, Ks, width, height, near, far, min_opacity, drawn):
    """First pass: drawn [C, N] (zeroed by the caller) set where near < z < far, opacity >=
    ``min_opacity`` and the 1/255 reach meets the image."""
    C, N = view.shape[0], means.shape[0]
    for n in prange(N):
        if not opac[n] >= min_opacity:
            continue
        kk = _reach_factor(opac, n)
        tr = scales[n, 0] * scales[n, 0] + scales[n, 1] * scales[n, 1] + scales[n, 2] * scales[n, 2]
        S = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        have_sigma = False
        for c in range(C):
            meets, z, mx, my, r0, r1 = _screen(view, Ks, c, means, n, width, height, near, far, kk, tr)
            if not meets:
                continue
            if not have_sigma:
                _, _, _, S = _quat_sigma(
                    quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3], scales[n, 0], scales[n, 1], scales[n, 2]
                )
                have_sigma = True
            a, b, cc, ex, ey = _cov2d(S, r0, r1, kk)
            drawn[c, n] = _meets(mx, my, ex, ey, width, height)


@njit(parallel=True, cache=True)
def _count_chunks(drawn, counts):
    """counts [chunks, C]: drawn pairs per chunk of ``CHUNK`` Gaussians and camera."""
    C, N = drawn.shape
    for k in prange((N + CHUNK - 1) // CHUNK):
        for c in range(C):
            total = 0
            for n in range(k * CHUNK, min(N, (k + 1) * CHUNK)):
                total += drawn[c, n]
            counts[k, c] = total


@njit(parallel=True, cache=True)
def _project_write(
    means, quats, scales, opac, view, Ks, width, height, near, far, drawn, pos, gid, m2, con, cov, depth, ext, radii
):
    """Second pass: the drawn pairs' outputs, pair p of chunk k and camera c at pos[k, c] (then + 1):
    gid [P] Gaussian index, m2 [P, 2] px, con [P, 3] conic, cov [P, 3] cov2d, depth [P] camera z,
    ext [P, 2] px reach of alpha >= 1/255, radii [P] int32 (ceil of the larger reach)."""
    C, N = view.shape[0], means.shape[0]
    for k in prange((N + CHUNK - 1) // CHUNK):
        for n in range(k * CHUNK, min(N, (k + 1) * CHUNK)):
            kk = _reach_factor(opac, n)
            tr = scales[n, 0] * scales[n, 0] + scales[n, 1] * scales[n, 1] + scales[n, 2] * scales[n, 2]
            S = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            have_sigma = False
            for c in range(C):
                if not drawn[c, n]:
                    continue
                _, z, mx, my, r0, r1 = _screen(view, Ks, c, means, n, width, height, near, far, kk, tr)
                if not have_sigma:
                    _, _, _, S = _quat_sigma(
                        quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3], scales[n, 0], scales[n, 1], scales[n, 2]
                    )
                    have_sigma = True
                a, b, cc, ex, ey = _cov2d(S, r0, r1, kk)
                det = a * cc - b * b
                p = pos[k, c]
                pos[k, c] += 1
                gid[p] = n
                m2[p, 0], m2[p, 1], depth[p] = mx, my, z
                con[p, 0], con[p, 1], con[p, 2] = cc / det, -b / det, a / det
                cov[p, 0], cov[p, 1], cov[p, 2] = a, b, cc
                ext[p, 0], ext[p, 1] = ex, ey
                radii[p] = math.ceil(max(ex, ey))


@njit(cache=True, inline="always")
def _meets(mx, my, ex, ey, width, height):
    """Whether the box of half-size (ex, ey) px around (mx, my) meets the image [0, W] x [0, H]."""
    return mx + ex >= 0.0 and my + ey >= 0.0 and mx - ex <= width and my - ey <= height


@njit(parallel=True, cache=True)
def _project_bwd_pairs(
    means, quats, scales, view, Ks, width, height, start, gid, slot, cov, g_m2, g_con, g_depth, gS, gm
):
    """Each drawn pair's gradient added into its Gaussian's row ``slot[p]`` of dL/dSigma gS [U, 9] (full
    3x3) and dL/dmean gm [U, 3] (float64, zeroed by the caller; U the Gaussians some camera draws):
    camera after camera (pairs of one camera are distinct Gaussians, so its pairs run in parallel),
    the sums in camera order for any thread count."""
    for c in range(view.shape[0]):
        for p in prange(start[c], start[c + 1]):
            n, row = gid[p], slot[p]
            _, _, _, S = _quat_sigma(
                quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3], scales[n, 0], scales[n, 1], scales[n, 2]
            )
            x, y, z, fx, fy, cx, cy, lim = _camera(view, Ks, c, means, n, width, height)
            ux, uy = x / z, y / z
            u = min(max(ux, lim[0]), lim[1])
            v = min(max(uy, lim[2]), lim[3])
            r0, r1 = _rows(view, c, fx, fy, z, u, v)
            a, b, cc = cov[p, 0], cov[p, 1], cov[p, 2]
            det = a * cc - b * b
            d2 = det * det
            gA, gB, gC = g_con[p, 0], g_con[p, 1], g_con[p, 2]
            ga = (-gA * cc * cc + gB * b * cc - gC * b * b) / d2
            gb = (2 * gA * b * cc - gB * (det + 2 * b * b) + 2 * gC * a * b) / d2
            gc = (-gA * b * b + gB * a * b - gC * a * a) / d2
            # cov2d = W Sigma W^T, W rows r0, r1, G = [[ga, gb/2], [gb/2, gc]]: gW = 2 G W Sigma
            p0, p1 = _symv(S, r0), _symv(S, r1)
            gw0 = (2 * ga * p0[0] + gb * p1[0], 2 * ga * p0[1] + gb * p1[1], 2 * ga * p0[2] + gb * p1[2])
            gw1 = (gb * p0[0] + 2 * gc * p1[0], gb * p0[1] + 2 * gc * p1[1], gb * p0[2] + 2 * gc * p1[2])
            for i in range(3):
                for k in range(3):
                    gS[row, 3 * i + k] += (
                        ga * r0[i] * r0[k] + 0.5 * gb * (r0[i] * r1[k] + r1[i] * r0[k]) + gc * r1[i] * r1[k]
                    )
            gz = g_depth[p] - (_dot(gw0, r0) + _dot(gw1, r1)) / z
            gu = -(fx / z) * (gw0[0] * view[c, 2, 0] + gw0[1] * view[c, 2, 1] + gw0[2] * view[c, 2, 2])
            gv = -(fy / z) * (gw1[0] * view[c, 2, 0] + gw1[1] * view[c, 2, 1] + gw1[2] * view[c, 2, 2])
            gux = fx * g_m2[p, 0] + (gu if lim[0] <= ux <= lim[1] else 0.0)
            guy = fy * g_m2[p, 1] + (gv if lim[2] <= uy <= lim[3] else 0.0)
            gx, gy = gux / z, guy / z
            gz -= (gux * x + guy * y) / (z * z)
            gm[row, 0] += view[c, 0, 0] * gx + view[c, 1, 0] * gy + view[c, 2, 0] * gz
            gm[row, 1] += view[c, 0, 1] * gx + view[c, 1, 1] * gy + view[c, 2, 1] * gz
            gm[row, 2] += view[c, 0, 2] * gx + view[c, 1, 2] * gy + view[c, 2, 2] * gz


@njit(parallel=True, cache=True)
def _project_bwd_params(quats, scales, drawn_ids, gS, gm, g_means, g_quats, g_scales):
    """dL/dSigma and dL/dmean of the Gaussians ``drawn_ids`` [U] (rows of gS [U, 9], gm [U, 3]) ->
    their gradients of means, quats and scales (zeroed by the caller: the others keep 0)."""
    for u in prange(drawn_ids.shape[0]):
        n = drawn_ids[u]
        q, Rq, m, _ = _quat_sigma(
            quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3], scales[n, 0], scales[n, 1], scales[n, 2]
        )
        g_means[n, 0], g_means[n, 1], g_means[n, 2] = gm[u, 0], gm[u, 1], gm[u, 2]
        # Sigma = M M^T -> gM = 2 gS M; M = Rq diag(s) -> gR = gM diag(s), gs_k = sum_i gM_ik Rq_ik
        gR = np.empty(9)
        for k in range(3):
            acc = 0.0
            for i in range(3):
                gM = 2 * (gS[u, 3 * i] * m[k] + gS[u, 3 * i + 1] * m[3 + k] + gS[u, 3 * i + 2] * m[6 + k])
                gR[3 * i + k] = gM * scales[n, k]
                acc += gM * Rq[3 * i + k]
            g_scales[n, k] = acc
        w, qx, qy, qz, qn = q
        if qn == 0.0:
            continue
        gw = 2 * (-qz * gR[1] + qy * gR[2] + qz * gR[3] - qx * gR[5] - qy * gR[6] + qx * gR[7])
        gx_ = 2 * (
            qy * gR[1] + qz * gR[2] + qy * gR[3] - 2 * qx * gR[4] - w * gR[5] + qz * gR[6] + w * gR[7] - 2 * qx * gR[8]
        )
        gy_ = 2 * (
            -2 * qy * gR[0] + qx * gR[1] + w * gR[2] + qx * gR[3] + qz * gR[5] - w * gR[6] + qz * gR[7] - 2 * qy * gR[8]
        )
        gz_ = 2 * (
            -2 * qz * gR[0] - w * gR[1] + qx * gR[2] + w * gR[3] - 2 * qz * gR[4] + qy * gR[5] + qx * gR[6] + qy * gR[7]
        )
        dot = w * gw + qx * gx_ + qy * gy_ + qz * gz_
        g_quats[n, 0] = (gw - w * dot) / qn
        g_quats[n, 1] = (gx_ - qx * dot) / qn
        g_quats[n, 2] = (gy_ - qy * dot) / qn
        g_quats[n, 3] = (gz_ - qz * dot) / qn


_project_test_serial = serial_twin(_project_test)
_count_chunks_serial = serial_twin(_count_chunks)
_project_write_serial = serial_twin(_project_write)
_project_bwd_pairs_serial = serial_twin(_project_bwd_pairs)
_project_bwd_params_serial = serial_twin(_project_bwd_params)
PARALLEL_MIN_WORK = 20000  # Gaussians x cameras below which the serial kernels run


class _ProjectCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, quats, scales, opacities, viewmats, Ks, width, height, near, far):
        C, N = viewmats.shape[0], means.shape[0]
        dt = means.dtype
        a = [t.detach().to(dt).contiguous().numpy() for t in (means, quats, scales, opacities, viewmats, Ks)]
        par = C * N >= PARALLEL_MIN_WORK
        drawn = np.zeros((C, N), np.bool_)
        counts = np.zeros(((N + CHUNK - 1) // CHUNK, C), np.int64)
        min_opacity = float(np.asarray(ALPHA_MIN, a[3].dtype))  # 1/255 as the opacities' dtype rounds it
        (_project_test if par else _project_test_serial)(*a, width, height, near, far, min_opacity, drawn)
        (_count_chunks if par else _count_chunks_serial)(drawn, counts)
        start = np.zeros(C + 1, np.int64)
        np.cumsum(counts.sum(0), out=start[1:])
        pos = start[:-1][None] + np.cumsum(counts, 0) - counts  # [chunks, C]
        P = int(start[-1])
        gid, depth, radii = np.empty(P, np.int64), np.empty(P, a[0].dtype), np.empty(P, np.int32)
        m2, con = np.empty((P, 2), a[0].dtype), np.empty((P, 3), a[0].dtype)
        cov, ext = np.empty((P, 3)), np.empty((P, 2))
        (_project_write if par else _project_write_serial)(
            *a, width, height, near, far, drawn, pos, gid, m2, con, cov, depth, ext, radii
        )
        ctx.saved = (a, width, height, start, gid, cov)
        const = [torch.from_numpy(x) for x in (cov, ext, radii, gid, start)]
        ctx.mark_non_differentiable(*const)
        ctx.set_materialize_grads(False)  # no zero-filled gradients for the constant outputs
        return (torch.from_numpy(m2), torch.from_numpy(con), torch.from_numpy(depth), *const)

    @staticmethod
    def backward(ctx, g_m2, g_con, g_depth, *_):
        (means, quats, scales, _op, view, Ks), width, height, start, gid, cov = ctx.saved
        P, N, C = gid.shape[0], means.shape[0], view.shape[0]
        prep = lambda g, shape: (
            np.zeros(shape, means.dtype)
            if g is None  # noqa: E731
            else g.detach().to(torch.from_numpy(means).dtype).contiguous().numpy()
        )
        # the Gaussians some camera draws, and each pair's row among them (one camera: the pairs)
        drawn_ids, slot = (gid, np.arange(P)) if C == 1 else np.unique(gid, return_inverse=True)
        gS, gm = np.zeros((len(drawn_ids), 9)), np.zeros((len(drawn_ids), 3))
        par = C * N >= PARALLEL_MIN_WORK
        (_project_bwd_pairs if par else _project_bwd_pairs_serial)(
            means,
            quats,
            scales,
            view,
            Ks,
            width,
            height,
            start,
            gid,
            slot,
            cov,
            prep(g_m2, (P, 2)),
            prep(g_con, (P, 3)),
            prep(g_depth, (P,)),
            gS,
            gm,
        )
        g_means, g_quats, g_scales = np.zeros_like(means), np.zeros_like(quats), np.zeros_like(scales)
        (_project_bwd_params if par else _project_bwd_params_serial)(
            quats, scales, drawn_ids, gS, gm, g_means, g_quats, g_scales
        )
        return (
            torch.from_numpy(g_means),
            torch.from_numpy(g_quats),
            torch.from_numpy(g_scales),
            None,
            None,
            None,
            None,
            None,
            None,
            None,
        )


def project_cpu(means, quats, scales, opacities, viewmats, Ks, width, height, near, far) -> dict:
    """Fast projection for the tile compositor, packed: the pairs of camera c are rows
    ``camera_start[c]:camera_start[c + 1]`` [C + 1] of gaussian_ids [P] (ascending), means2d [P, 2] px,
    conics [P, 3], depths [P] (camera z), cov2d [P, 3], ext [P, 2] (``project.pixel_extent``) and radii
    [P] int32 (ceil of the larger reach, >= 1): ``project.project_gaussians``' outputs where a pair is
    drawn (near < z < far, opacity >= 1/255, the 1/255 reach meets the image). Differentiable w.r.t.
    means, quats and scales through means2d, conics and depths."""
    m2, con, depth, cov, ext, radii, gid, start = _ProjectCPU.apply(
        means, quats, scales, opacities, viewmats, Ks, width, height, float(near), float(far)
    )
    return dict(
        means2d=m2, conics=con, depths=depth, cov2d=cov, ext=ext, radii=radii, gaussian_ids=gid, camera_start=start
    )
