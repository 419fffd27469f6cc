"""Projection of 3D Gaussians to the image plane (EWA splatting), in plain differentiable torch.

Conventions (docs/conventions.md): pinhole ``K`` with pixel centres at +0.5 (cx = W/2 for a centred
camera), ``viewmat`` world-to-camera 4x4 with OpenCV axes (+x right, +y down, +z forward),
quaternions (w, x, y, z). Shared by every rasterizer backend so that they differ only in compositing.
"""

from __future__ import annotations

import math

import torch

EPS2D = 0.3  # low-pass added to the 2D covariance, px^2 (as in 3DGS / gsplat "classic")
ALPHA_MIN = 1.0 / 255  # a Gaussian-pixel pair with alpha below this is skipped
ALPHA_MAX = 0.99  # alpha cap
T_MIN = 1e-4  # compositing stops before transmittance would fall below this
SH_C0 = 0.28209479177387814


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """Rotation matrices [..., 3, 3] from quaternions [..., 4] (w, x, y, z), normalised here;
    a zero quaternion maps to the identity (with finite gradients)."""
    sq = (quats * quats).sum(-1, keepdim=True)
    ok = sq > 1e-24
    q = torch.where(ok, quats / torch.sqrt(sq.clamp_min(1e-24)), quats.new_tensor([1.0, 0.0, 0.0, 0.0]))
    w, x, y, z = q.unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    ]
    return torch.stack(rows, -1).reshape(*quats.shape[:-1], 3, 3)


def project_gaussians(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    viewmats: torch.Tensor,
    Ks: torch.Tensor,
    width: int,
    height: int,
    near: float = 0.01,
    far: float = 1e10,
) -> dict[str, torch.Tensor]:
    """Project Gaussians into C cameras.

    means [N, 3] world metres; quats [N, 4] wxyz; scales [N, 3] metres (positive);
    viewmats [C, 4, 4] world-to-camera; Ks [C, 3, 3] pixels.
    Returns (all [C, N, ...]): ``means2d`` [C, N, 2] px, ``conics`` [C, N, 3] (inverse 2D covariance
    a, b, c for a dx^2 + 2 b dx dy + c dy^2), ``cov2d`` [C, N, 3] (xx, xy, yy incl. the low-pass),
    ``depths`` [C, N] camera z (metres), ``valid`` [C, N] bool (near < z < far).
    Invalid entries carry finite placeholder values (and zero gradient), never NaN.
    """
    R = viewmats[:, :3, :3]  # [C, 3, 3]
    t = viewmats[:, :3, 3]  # [C, 3]
    p = torch.einsum("cij,nj->cni", R, means) + t[:, None, :]  # [C, N, 3]
    x, y, z = p.unbind(-1)  # [C, N]
    valid = (z > near) & (z < far)
    z = torch.where(valid, z, torch.ones_like(z))
    fx, fy = Ks[:, 0, 0, None], Ks[:, 1, 1, None]  # [C, 1]
    cx, cy = Ks[:, 0, 2, None], Ks[:, 1, 2, None]
    # Off-frustum clamp of the Jacobian: x/z limited to 1.3x the half field of view (3DGS / gsplat).
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    u = torch.minimum(torch.maximum(x / z, -(cx / fx + 0.3 * tan_x)), (width - cx) / fx + 0.3 * tan_x)
    v = torch.minimum(torch.maximum(y / z, -(cy / fy + 0.3 * tan_y)), (height - cy) / fy + 0.3 * tan_y)
    # J = [[fx/z, 0, -fx u/z], [0, fy/z, -fy v/z]]; rows of J @ R (camera rotation folded in).
    rz = fx / z
    r0 = rz[..., None] * (R[:, None, 0, :] - u[..., None] * R[:, None, 2, :])  # [C, N, 3]
    rz = fy / z
    r1 = rz[..., None] * (R[:, None, 1, :] - v[..., None] * R[:, None, 2, :])  # [C, N, 3]
    M = quat_to_rotmat(quats) * scales[:, None, :]  # [N, 3, 3] = R_q diag(s)
    # T = (J R_cam) M: 2 x 3 per Gaussian and camera; cov2d = T T^T + eps I.
    t0 = torch.einsum("cnj,njk->cnk", r0, M)  # [C, N, 3]
    t1 = torch.einsum("cnj,njk->cnk", r1, M)
    a = (t0 * t0).sum(-1) + EPS2D
    b = (t0 * t1).sum(-1)
    c = (t1 * t1).sum(-1) + EPS2D
    det = a * c - b * b
    conics = torch.stack([c / det, -b / det, a / det], -1)  # [C, N, 3]
    means2d = torch.stack([fx * x / z + cx, fy * y / z + cy], -1)  # [C, N, 2]
    return dict(means2d=means2d, conics=conics, cov2d=torch.stack([a, b, c], -1), depths=z, valid=valid)


def pixel_extent(cov2d: torch.Tensor, opacities: torch.Tensor) -> torch.Tensor:
    """Half-extents [..., 2] (px) of the region where opacity * exp(-sigma) >= 1/255.

    Mahalanobis radius k = sqrt(2 ln(255 o)); along x the ellipse reaches k sqrt(cov_xx). Outside it a
    Gaussian is skipped by the 1/255 rule anyway, so this bound loses nothing. 0 where o < 1/255."""
    k = torch.sqrt(2 * torch.log((opacities / ALPHA_MIN).clamp_min(1.0)))  # [...]
    ext = k[..., None] * torch.sqrt(torch.stack([cov2d[..., 0], cov2d[..., 2]], -1).clamp_min(0))
    return ext * 1.0001 + 1e-3


_SH_C1 = 0.4886025119029199
_SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
_SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)


def eval_sh(sh: torch.Tensor, dirs: torch.Tensor, degree: int | None = None) -> torch.Tensor:
    """Real spherical harmonics up to degree 3 (3DGS basis and sign convention).

    sh [..., K, 3] with K = (deg+1)^2 coefficients; dirs [..., 3] unit viewing directions (camera to
    Gaussian). Returns rgb [..., 3] = sum_k Y_k(dir) sh_k + 0.5, clamped at 0 (as 3DGS / gsplat)."""
    K = sh.shape[-2]
    deg = int(round(math.sqrt(K))) - 1 if degree is None else degree
    if (int(round(math.sqrt(K)))) ** 2 != K or not 0 <= deg <= 3 or (deg + 1) ** 2 > K:
        raise ValueError(f"eval_sh: {K} coefficients do not fit SH degree {deg} (<= 3)")
    out = SH_C0 * sh[..., 0, :]
    if deg >= 1:
        x, y, z = dirs[..., 0:1], dirs[..., 1:2], dirs[..., 2:3]
        out = out - _SH_C1 * y * sh[..., 1, :] + _SH_C1 * z * sh[..., 2, :] - _SH_C1 * x * sh[..., 3, :]
        if deg >= 2:
            xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
            out = (
                out
                + _SH_C2[0] * xy * sh[..., 4, :]
                + _SH_C2[1] * yz * sh[..., 5, :]
                + _SH_C2[2] * (2 * zz - xx - yy) * sh[..., 6, :]
                + _SH_C2[3] * xz * sh[..., 7, :]
                + _SH_C2[4] * (xx - yy) * sh[..., 8, :]
            )
            if deg >= 3:
                out = (
                    out
                    + _SH_C3[0] * y * (3 * xx - yy) * sh[..., 9, :]
                    + _SH_C3[1] * xy * z * sh[..., 10, :]
                    + _SH_C3[2] * y * (4 * zz - xx - yy) * sh[..., 11, :]
                    + _SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[..., 12, :]
                    + _SH_C3[4] * x * (4 * zz - xx - yy) * sh[..., 13, :]
                    + _SH_C3[5] * z * (xx - yy) * sh[..., 14, :]
                    + _SH_C3[6] * x * (xx - 3 * yy) * sh[..., 15, :]
                )
    return torch.clamp_min(out + 0.5, 0.0)
