"""Fused numba projection (forward + hand-written backward) for the fast CPU path.

Same math as ``project.project_gaussians`` (which the dense reference uses through autograd):
p = R m + t; J with x/z, y/z clamped to 1.3x the half field of view; cov2d = (J R) Rq S S Rq^T (J R)^T
+ 0.3 I; conic = cov2d^-1. One pass over Gaussians (prange) instead of ~50 tensor-sized torch ops.
Gradients flow to means, quats (through the normalisation) and scales; cameras are constants.
"""
from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from holoflow.splat.cpu import serial_twin
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
    R = (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
         2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
         2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))
    m = (R[0] * s0, R[1] * s1, R[2] * s2, R[3] * s0, R[4] * s1, R[5] * s2,
         R[6] * s0, R[7] * s1, R[8] * s2)
    S = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2], m[0] * m[3] + m[1] * m[4] + m[2] * m[5],
         m[0] * m[6] + m[1] * m[7] + m[2] * m[8], m[3] * m[3] + m[4] * m[4] + m[5] * m[5],
         m[3] * m[6] + m[4] * m[7] + m[5] * m[8], m[6] * m[6] + m[7] * m[7] + m[8] * m[8])
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
    lim = (-(cx / fx + 0.3 * tx), (width - cx) / fx + 0.3 * tx,
           -(cy / fy + 0.3 * ty), (height - cy) / fy + 0.3 * ty)
    return x, y, z, fx, fy, cx, cy, lim


@njit(cache=True)
def _rows(view, c, fx, fy, z, u, v):
    """r0 = fx/z (R0 - u R2), r1 = fy/z (R1 - v R2) (rows of J R)."""
    a, b = fx / z, fy / z
    r0 = (a * (view[c, 0, 0] - u * view[c, 2, 0]), a * (view[c, 0, 1] - u * view[c, 2, 1]),
          a * (view[c, 0, 2] - u * view[c, 2, 2]))
    r1 = (b * (view[c, 1, 0] - v * view[c, 2, 0]), b * (view[c, 1, 1] - v * view[c, 2, 1]),
          b * (view[c, 1, 2] - v * view[c, 2, 2]))
    return r0, r1


@njit(cache=True)
def _symv(S, r):
    """Sigma @ r for Sigma given by 6 scalars."""
    return (S[0] * r[0] + S[1] * r[1] + S[2] * r[2], S[1] * r[0] + S[3] * r[1] + S[4] * r[2],
            S[2] * r[0] + S[4] * r[1] + S[5] * r[2])


@njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(parallel=True, cache=True)
def _project_fwd(means, quats, scales, opac, view, Ks, width, height, near, far, min_opacity,
                 m2, con, cov, depth, ext, drawn, radii):
    """Writes, for the pairs of camera c and Gaussian n that are drawn (near < z < far, opacity >=
    ``min_opacity`` and the reach meets the image: what the tile culling can keep), and only there:
    m2 [C, N, 2], depth [C, N], con [C, N, 3], cov [C, N, 3], ext [C, N, 2] (reach of alpha >= 1/255,
    px), drawn [C, N] (True) and radii [C, N] int32 (ceil of the larger reach). The caller zeroes the
    outputs: a view of a panorama draws a few % of the pairs, and the others' pages are never touched.

    The covariance math is skipped where the centre lies farther off the image than a cheap bound on
    the reach: along x k sqrt(r0' Sigma r0 + 0.3) with r0 = fx/z (R0 - u R2) and r0' Sigma r0 <=
    |r0|^2 tr(Sigma)."""
    C = view.shape[0]
    N = means.shape[0]
    for n in prange(N):
        if not opac[n] >= min_opacity:
            continue
        kk = math.sqrt(2.0 * math.log(max(opac[n] / ALPHA_MIN, 1.0)))
        tr = scales[n, 0] * scales[n, 0] + scales[n, 1] * scales[n, 1] + scales[n, 2] * scales[n, 2]
        S = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        have_sigma = False
        for c in range(C):
            x, y, z, fx, fy, cx, cy, lim = _camera(view, Ks, c, means, n, width, height)
            if not (z > near and z < far):
                continue
            z = float(z)                        # float64 from here, as the backward pass has it
            mx, my = fx * x / z + cx, fy * y / z + cy
            u = min(max(x / z, lim[0]), lim[1])
            v = min(max(y / z, lim[2]), lim[3])
            r0, r1 = _rows(view, c, fx, fy, z, u, v)
            bx = kk * math.sqrt(_dot(r0, r0) * tr + EPS2D) * 1.0002 + 1e-3    # >= ex below, rounding too
            by = kk * math.sqrt(_dot(r1, r1) * tr + EPS2D) * 1.0002 + 1e-3
            if not _meets(mx, my, bx, by, width, height):
                continue
            if not have_sigma:
                _, _, _, S = _quat_sigma(quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3],
                                         scales[n, 0], scales[n, 1], scales[n, 2])
                have_sigma = True
            s1 = _symv(S, r1)
            a = _dot(r0, _symv(S, r0)) + EPS2D
            b = _dot(r0, s1)
            cc = _dot(r1, s1) + EPS2D
            ex = kk * math.sqrt(a) * 1.0001 + 1e-3
            ey = kk * math.sqrt(cc) * 1.0001 + 1e-3
            if not _meets(mx, my, ex, ey, width, height):
                continue
            det = a * cc - b * b
            m2[c, n, 0], m2[c, n, 1], depth[c, n] = mx, my, z
            con[c, n, 0], con[c, n, 1], con[c, n, 2] = cc / det, -b / det, a / det
            cov[c, n, 0], cov[c, n, 1], cov[c, n, 2] = a, b, cc
            ext[c, n, 0], ext[c, n, 1] = ex, ey
            drawn[c, n] = True
            radii[c, n] = math.ceil(max(ex, ey))


@njit(cache=True, inline="always")
def _meets(mx, my, ex, ey, width, height):
    """Whether the box of half-size (ex, ey) px around (mx, my) meets the image [0, W] x [0, H]."""
    return mx + ex >= 0.0 and my + ey >= 0.0 and mx - ex <= width and my - ey <= height


@njit(cache=True)
def _has_grad(drawn, g_m2, g_con, g_depth, n):
    """Whether Gaussian n receives any gradient through a camera that draws it."""
    for c in range(drawn.shape[0]):
        if drawn[c, n] and (g_m2[c, n, 0] != 0.0 or g_m2[c, n, 1] != 0.0 or g_con[c, n, 0] != 0.0
                            or g_con[c, n, 1] != 0.0 or g_con[c, n, 2] != 0.0 or g_depth[c, n] != 0.0):
            return True
    return False


@njit(parallel=True, cache=True)
def _project_bwd(means, quats, scales, view, Ks, width, height, drawn, cov, g_m2, g_con, g_depth,
                 g_means, g_quats, g_scales):
    """Gradients through the cameras that draw each Gaussian (the others' outputs are not computed)."""
    C = view.shape[0]
    N = means.shape[0]
    for n in prange(N):
        if not _has_grad(drawn, g_m2, g_con, g_depth, n):     # not drawn in any camera (most of them)
            g_means[n, 0] = g_means[n, 1] = g_means[n, 2] = 0.0
            g_scales[n, 0] = g_scales[n, 1] = g_scales[n, 2] = 0.0
            g_quats[n, 0] = g_quats[n, 1] = g_quats[n, 2] = g_quats[n, 3] = 0.0
            continue
        q, Rq, m, S = _quat_sigma(quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3],
                                  scales[n, 0], scales[n, 1], scales[n, 2])
        gS = np.zeros(9)            # dL/dSigma, full 3x3 (symmetric)
        gmx = gmy = gmz = 0.0
        for c in range(C):
            if not drawn[c, n]:
                continue
            x, y, z, fx, fy, cx, cy, lim = _camera(view, Ks, c, means, n, width, height)
            ux, uy = x / z, y / z
            u = min(max(ux, lim[0]), lim[1])
            v = min(max(uy, lim[2]), lim[3])
            r0, r1 = _rows(view, c, fx, fy, z, u, v)
            a, b, cc = cov[c, n, 0], cov[c, n, 1], cov[c, n, 2]
            det = a * cc - b * b
            d2 = det * det
            gA, gB, gC = g_con[c, n, 0], g_con[c, n, 1], g_con[c, n, 2]
            ga = (-gA * cc * cc + gB * b * cc - gC * b * b) / d2
            gb = (2 * gA * b * cc - gB * (det + 2 * b * b) + 2 * gC * a * b) / d2
            gc = (-gA * b * b + gB * a * b - gC * a * a) / d2
            # cov2d = W Sigma W^T, W rows r0, r1, G = [[ga, gb/2], [gb/2, gc]]: gW = 2 G W Sigma
            p0, p1 = _symv(S, r0), _symv(S, r1)
            gw0 = (2 * ga * p0[0] + gb * p1[0], 2 * ga * p0[1] + gb * p1[1], 2 * ga * p0[2] + gb * p1[2])
            gw1 = (gb * p0[0] + 2 * gc * p1[0], gb * p0[1] + 2 * gc * p1[1], gb * p0[2] + 2 * gc * p1[2])
            for i in range(3):
                for k in range(3):
                    gS[3 * i + k] += (ga * r0[i] * r0[k] + 0.5 * gb * (r0[i] * r1[k] + r1[i] * r0[k])
                                      + gc * r1[i] * r1[k])
            gz = g_depth[c, n] - (_dot(gw0, r0) + _dot(gw1, r1)) / z
            gu = -(fx / z) * (gw0[0] * view[c, 2, 0] + gw0[1] * view[c, 2, 1] + gw0[2] * view[c, 2, 2])
            gv = -(fy / z) * (gw1[0] * view[c, 2, 0] + gw1[1] * view[c, 2, 1] + gw1[2] * view[c, 2, 2])
            gux = fx * g_m2[c, n, 0] + (gu if lim[0] <= ux <= lim[1] else 0.0)
            guy = fy * g_m2[c, n, 1] + (gv if lim[2] <= uy <= lim[3] else 0.0)
            gx, gy = gux / z, guy / z
            gz -= (gux * x + guy * y) / (z * z)
            gmx += view[c, 0, 0] * gx + view[c, 1, 0] * gy + view[c, 2, 0] * gz
            gmy += view[c, 0, 1] * gx + view[c, 1, 1] * gy + view[c, 2, 1] * gz
            gmz += view[c, 0, 2] * gx + view[c, 1, 2] * gy + view[c, 2, 2] * gz
        g_means[n, 0], g_means[n, 1], g_means[n, 2] = gmx, gmy, gmz
        # Sigma = M M^T -> gM = 2 gS M; M = Rq diag(s) -> gR = gM diag(s), gs_k = sum_i gM_ik Rq_ik
        gR = np.empty(9)
        for k in range(3):
            acc = 0.0
            for i in range(3):
                gM = 2 * (gS[3 * i] * m[k] + gS[3 * i + 1] * m[3 + k] + gS[3 * i + 2] * m[6 + k])
                gR[3 * i + k] = gM * scales[n, k]
                acc += gM * Rq[3 * i + k]
            g_scales[n, k] = acc
        w, qx, qy, qz, qn = q
        if qn == 0.0:
            g_quats[n, 0] = g_quats[n, 1] = g_quats[n, 2] = g_quats[n, 3] = 0.0
            continue
        gw = 2 * (-qz * gR[1] + qy * gR[2] + qz * gR[3] - qx * gR[5] - qy * gR[6] + qx * gR[7])
        gx_ = 2 * (qy * gR[1] + qz * gR[2] + qy * gR[3] - 2 * qx * gR[4] - w * gR[5]
                   + qz * gR[6] + w * gR[7] - 2 * qx * gR[8])
        gy_ = 2 * (-2 * qy * gR[0] + qx * gR[1] + w * gR[2] + qx * gR[3] + qz * gR[5]
                   - w * gR[6] + qz * gR[7] - 2 * qy * gR[8])
        gz_ = 2 * (-2 * qz * gR[0] - w * gR[1] + qx * gR[2] + w * gR[3] - 2 * qz * gR[4]
                   + qy * gR[5] + qx * gR[6] + qy * gR[7])
        dot = w * gw + qx * gx_ + qy * gy_ + qz * gz_
        g_quats[n, 0] = (gw - w * dot) / qn
        g_quats[n, 1] = (gx_ - qx * dot) / qn
        g_quats[n, 2] = (gy_ - qy * dot) / qn
        g_quats[n, 3] = (gz_ - qz * dot) / qn


_project_fwd_serial = serial_twin(_project_fwd)
_project_bwd_serial = serial_twin(_project_bwd)
PARALLEL_MIN_WORK = 20000   # Gaussians x cameras below which the serial kernels run


class _ProjectCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, quats, scales, opacities, viewmats, Ks, width, height, near, far):
        C, N = viewmats.shape[0], means.shape[0]
        dt = means.dtype
        a = [t.detach().to(dt).contiguous().numpy() for t in (means, quats, scales, opacities, viewmats, Ks)]
        zeros = lambda *shape, dt=a[0].dtype: np.zeros(shape, dt)   # noqa: E731 (calloc: a page on first write)
        m2, con, depth = zeros(C, N, 2), zeros(C, N, 3), zeros(C, N)
        cov, ext = zeros(C, N, 3, dt=np.float64), zeros(C, N, 2, dt=np.float64)
        drawn, radii = zeros(C, N, dt=np.bool_), zeros(C, N, dt=np.int32)
        min_opacity = float(np.asarray(ALPHA_MIN, a[3].dtype))    # 1/255 as the opacities' dtype rounds it
        fwd = _project_fwd if C * N >= PARALLEL_MIN_WORK else _project_fwd_serial
        fwd(*a, width, height, near, far, min_opacity, m2, con, cov, depth, ext, drawn, radii)
        ctx.saved = (a, width, height, drawn, cov)
        const = [torch.from_numpy(x) for x in (cov, ext, drawn, radii)]
        ctx.mark_non_differentiable(*const)
        ctx.set_materialize_grads(False)    # no zero-filled [C, N] gradients for the constant outputs
        return (torch.from_numpy(m2), torch.from_numpy(con), torch.from_numpy(depth), *const)

    @staticmethod
    def backward(ctx, g_m2, g_con, g_depth, *_):
        (means, quats, scales, _op, view, Ks), width, height, drawn, cov = ctx.saved
        N = means.shape[0]
        prep = lambda g, shape: (np.zeros(shape, means.dtype) if g is None  # noqa: E731
                                 else g.detach().to(torch.from_numpy(means).dtype).contiguous().numpy())
        C = view.shape[0]
        gm, gq, gs = np.empty_like(means), np.empty_like(quats), np.empty_like(scales)
        bwd = _project_bwd if C * N >= PARALLEL_MIN_WORK else _project_bwd_serial
        bwd(means, quats, scales, view, Ks, width, height, drawn, cov,
            prep(g_m2, (C, N, 2)), prep(g_con, (C, N, 3)), prep(g_depth, (C, N)), gm, gq, gs)
        return (torch.from_numpy(gm), torch.from_numpy(gq), torch.from_numpy(gs),
                None, None, None, None, None, None, None)


def project_cpu(means, quats, scales, opacities, viewmats, Ks, width, height, near, far) -> dict:
    """Fast projection for the tile compositor: ``project.project_gaussians``' means2d, conics,
    depths and cov2d plus ``ext`` [C, N, 2] (``project.pixel_extent``), ``drawn`` [C, N] and ``radii``
    [C, N] int32 (see ``_project_fwd``), all computed only where drawn and 0 elsewhere (no ``valid``:
    a drawn pair is valid). Differentiable w.r.t. means, quats and scales through the cameras that
    draw each Gaussian."""
    m2, con, depth, cov, ext, drawn, radii = _ProjectCPU.apply(
        means, quats, scales, opacities, viewmats, Ks, width, height, float(near), float(far))
    return dict(means2d=m2, conics=con, depths=depth, cov2d=cov, ext=ext, drawn=drawn, radii=radii)
