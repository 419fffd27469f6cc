"""Pinhole cameras: intrinsics, look-at view matrices, pixel rays, projection, quaternions.

K is [..., 3, 3] in pixels with pixel centres at +0.5 (a W x H image centred on its axis has
cx = W/2, cy = H/2). A viewmat is [..., 4, 4] world-to-camera, OpenCV axes (+x right, +y down,
+z forward), as in gsplat: x_cam = R @ x_world + t with R = viewmat[:3, :3], t = viewmat[:3, 3].
Quaternions are (w, x, y, z). docs/conventions.md has the full list.
"""

from __future__ import annotations

import math

import torch


def intrinsics(fx, fy, cx, cy, device=None, dtype=None) -> torch.Tensor:
    """Pinhole K [..., 3, 3] from focal lengths and principal point (pixels; floats or tensors [...])."""
    vals = [torch.as_tensor(a, device=device, dtype=dtype or torch.get_default_dtype()) for a in (fx, fy, cx, cy)]
    fx, fy, cx, cy = torch.broadcast_tensors(*vals)
    zero, one = torch.zeros_like(fx), torch.ones_like(fx)
    return torch.stack([fx, zero, cx, zero, fy, cy, zero, zero, one], -1).reshape(*fx.shape, 3, 3)


def intrinsics_from_fov(fov_deg: float, width: int, height: int, device=None, dtype=None) -> torch.Tensor:
    """K [3, 3] with horizontal field of view ``fov_deg`` (degrees), square pixels, centred axis."""
    f = (width / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    return intrinsics(f, f, width / 2.0, height / 2.0, device=device, dtype=dtype)


def fov_from_focal(focal: float, size: int) -> float:
    """Field of view in degrees of ``size`` pixels at focal length ``focal`` pixels."""
    return math.degrees(2.0 * math.atan(size / (2.0 * focal)))


def look_at(eye: torch.Tensor, target: torch.Tensor, up: torch.Tensor | None = None) -> torch.Tensor:
    """World-to-camera viewmat [..., 4, 4] of a camera at ``eye`` [..., 3] looking at ``target`` [..., 3].

    ``up`` [..., 3] is the world direction that should appear up in the image; default (0, -1, 0)
    (world up, since +y is down). When the view direction is parallel to ``up`` (straight up or down)
    the image's up is taken as the limit of tilting from the horizon: looking down (+y) the image top
    points to +z, looking up (-y) it points to -z; for a user ``up`` the fallback is the world axis
    least aligned with the view direction. The rotation stays orthonormal and maps the view direction
    exactly to +z."""
    eye, target = torch.broadcast_tensors(eye, target)
    f = target - eye
    f = f / torch.linalg.vector_norm(f, dim=-1, keepdim=True)  # [..., 3]
    if up is None:
        up_t = torch.tensor([0.0, -1.0, 0.0], dtype=f.dtype, device=f.device).expand_as(f)
        fallback = torch.zeros_like(f)
        fallback[..., 2] = torch.where(f[..., 1] >= 0, 1.0, -1.0)
    else:
        up_t = torch.as_tensor(up, dtype=f.dtype, device=f.device).expand_as(f)
        axis = torch.argmin(f.abs(), dim=-1)  # [...]
        fallback = torch.nn.functional.one_hot(axis, 3).to(f.dtype)
    x = torch.linalg.cross(f, up_t)
    norm = torch.linalg.vector_norm(x, dim=-1, keepdim=True)
    degenerate = norm < 1e-6
    x = torch.where(degenerate, torch.linalg.cross(f, fallback), x)
    x = x / torch.linalg.vector_norm(x, dim=-1, keepdim=True)
    y = torch.linalg.cross(f, x)  # unit: f and x are orthonormal
    R = torch.stack([x, y, f], dim=-2)  # [..., 3, 3] rows = camera axes in world
    return make_viewmat(R, -(R @ eye.unsqueeze(-1)).squeeze(-1))


def make_viewmat(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """viewmat [..., 4, 4] from rotation R [..., 3, 3] and translation t [..., 3] (world-to-camera)."""
    out = torch.zeros(*R.shape[:-2], 4, 4, dtype=R.dtype, device=R.device)
    out[..., :3, :3] = R
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def camera_centers(viewmat: torch.Tensor) -> torch.Tensor:
    """World positions [..., 3] of cameras with world-to-camera ``viewmat`` [..., 4, 4]: -R^T t."""
    R, t = viewmat[..., :3, :3], viewmat[..., :3, 3]
    return -(R.transpose(-1, -2) @ t.unsqueeze(-1)).squeeze(-1)


def elevation_deg(viewmats: torch.Tensor) -> torch.Tensor:
    """[C] degrees of each camera's view axis (world, the viewmat's third row; viewmats [C, 4, 4])
    above the horizon: +90 = zenith (world +y is down), float64."""
    axis = viewmats[:, 2, :3].double()
    return torch.rad2deg(torch.asin((-axis[:, 1] / axis.norm(dim=1)).clamp(-1, 1)))


def polar_views(viewmats: torch.Tensor, pole_deg: float) -> torch.Tensor:
    """[C] bool: the camera's view axis lies within ``pole_deg`` degrees of the zenith or the nadir."""
    return elevation_deg(viewmats).abs() >= 90.0 - pole_deg


def invert_viewmat(viewmat: torch.Tensor) -> torch.Tensor:
    """Rigid inverse [..., 4, 4] (world-to-camera <-> camera-to-world)."""
    R, t = viewmat[..., :3, :3], viewmat[..., :3, 3]
    Rt = R.transpose(-1, -2)
    return make_viewmat(Rt, -(Rt @ t.unsqueeze(-1)).squeeze(-1))


def pixel_grid(height: int, width: int, device=None, dtype=None) -> torch.Tensor:
    """Pixel-centre coordinates [H, W, 2] as (x, y) = (col + 0.5, row + 0.5)."""
    dtype = dtype or torch.get_default_dtype()
    y, x = torch.meshgrid(
        torch.arange(height, device=device, dtype=dtype) + 0.5,
        torch.arange(width, device=device, dtype=dtype) + 0.5,
        indexing="ij",
    )
    return torch.stack([x, y], dim=-1)


def pinhole_rays(K: torch.Tensor, viewmat: torch.Tensor, height: int, width: int) -> tuple[torch.Tensor, torch.Tensor]:
    """World-frame rays of every pixel centre: origins [..., H, W, 3], unit dirs [..., H, W, 3].

    K [..., 3, 3], viewmat [..., 4, 4] (leading dims broadcast)."""
    pix = pixel_grid(height, width, device=K.device, dtype=K.dtype)  # [H, W, 2]
    fx, fy = K[..., 0, 0, None, None], K[..., 1, 1, None, None]
    cx, cy = K[..., 0, 2, None, None], K[..., 1, 2, None, None]
    skew = K[..., 0, 1, None, None]
    yc = (pix[..., 1] - cy) / fy  # [..., H, W]
    xc = (pix[..., 0] - cx - skew * yc) / fx
    cam = torch.stack([xc, yc, torch.ones_like(xc)], dim=-1)  # [..., H, W, 3]
    cam = cam / torch.linalg.vector_norm(cam, dim=-1, keepdim=True)
    R = viewmat[..., :3, :3]
    lead = torch.broadcast_tensors(cam[..., 0, 0, 0], R[..., 0, 0])[0].shape  # not broadcast_shapes: it imports sympy
    flat = cam.expand(*lead, height, width, 3).reshape(*lead, height * width, 3)
    dirs = (flat @ R.expand(*lead, 3, 3)).reshape(*lead, height, width, 3)  # rows: (R^T cam)^T
    origins = camera_centers(viewmat)[..., None, None, :].expand_as(dirs)
    return origins, dirs


def project_points(
    points: torch.Tensor, K: torch.Tensor, viewmat: torch.Tensor, eps: float = 1e-9
) -> tuple[torch.Tensor, torch.Tensor]:
    """Project world points [..., N, 3]: pixel coords uv [..., N, 2] (centres at +0.5) and depth z [..., N].

    Points with z <= eps (behind or on the camera plane) get uv computed with z clamped to eps:
    finite but meaningless; select z > 0 before using them."""
    cam = torch.einsum("...ij,...nj->...ni", viewmat[..., :3, :3], points) + viewmat[..., None, :3, 3]
    z = cam[..., 2]
    zs = z.clamp(min=eps)
    pix = torch.einsum("...ij,...nj->...ni", K, cam)
    return torch.stack([pix[..., 0] / zs, pix[..., 1] / zs], dim=-1), z


def rotmat_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices [..., 3, 3] -> unit quaternions (w, x, y, z) [...,4] with w >= 0."""
    m = R
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = torch.stack(
        [
            torch.stack(
                [1 + trace, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1
            ),
            torch.stack(
                [
                    m[..., 2, 1] - m[..., 1, 2],
                    1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
                    m[..., 0, 1] + m[..., 1, 0],
                    m[..., 0, 2] + m[..., 2, 0],
                ],
                -1,
            ),
            torch.stack(
                [
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 0, 1] + m[..., 1, 0],
                    1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2],
                    m[..., 1, 2] + m[..., 2, 1],
                ],
                -1,
            ),
            torch.stack(
                [
                    m[..., 1, 0] - m[..., 0, 1],
                    m[..., 0, 2] + m[..., 2, 0],
                    m[..., 1, 2] + m[..., 2, 1],
                    1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2],
                ],
                -1,
            ),
        ],
        dim=-2,
    )  # [..., 4, 4]: candidate k is 4 * q_k * q (best conditioned where |q_k| is largest)
    diag = torch.stack([trace, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], -1)
    best = torch.argmax(diag, dim=-1)  # [...]
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4)).squeeze(-2)
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    return torch.where(q[..., :1] < 0, -q, q)


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """Quaternions (w, x, y, z) [..., 4] (normalised here) -> rotation matrices [..., 3, 3]."""
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        ],
        -1,
    ).reshape(*q.shape[:-1], 3, 3)
