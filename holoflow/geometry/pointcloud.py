"""Equirect RGB-D -> point clouds, the depth-gradient filter, and z-buffered point projection.

Equirect depth is radial (distance along the pixel's ray, metres; docs/conventions.md); pinhole depth
is z. Non-finite or non-positive depth means "no surface" (sky) and is never turned into a point here:
the caller decides (the point_cloud stage puts sky on a far shell first).

Depth-gradient filter (HoloDreamer's P_f, threshold 0.4): the gradient is the *relative* depth change
per pixel step of the equirect grid,

    g(u, v) = sqrt(gx^2 + gy^2) / D(u, v),   gx = (D(u+1, v) - D(u-1, v)) / 2,  gy likewise in v,

dimensionless (fraction of the depth per pixel), central differences, columns wrapping at the seam
and rows continuing across the poles. Why relative and per pixel: metric scale is arbitrary before
alignment and the paper's scenes span metres to tens of metres, so an absolute gradient would filter
near and far objects differently; per pixel, a smooth surface seen at incidence angle a has
g = tan(a) * (pixel angle), tiny except at grazing angles (at 2048 px wide, g > 0.4 needs a > 89.6
deg), while a depth edge gives a jump that stays a jump at any resolution: g > 0.4 flags the pixels
beside a discontinuity where depth changes by more than ~1.8x across two pixels (the mixed-depth
pixels the paper wants gone), independently of the scene's scale.
"""

from __future__ import annotations

import torch

from holoflow.geometry.camera import project_points
from holoflow.geometry.sampling import pad_equirect
from holoflow.geometry.sphere import equirect_directions


def equirect_to_points(rgb: torch.Tensor, radial_depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Back-project an equirect RGB-D image: rgb [H, W, C], radial_depth [H, W] (metres) ->
    xyz [N, 3] (world, same dtype as depth) and rgb [N, C] of the pixels with finite depth > 0,
    in row-major pixel order."""
    H, W = radial_depth.shape
    dirs = equirect_directions(H, W, device=radial_depth.device, dtype=radial_depth.dtype)  # [H, W, 3]
    valid = torch.isfinite(radial_depth) & (radial_depth > 0)
    return dirs[valid] * radial_depth[valid][:, None], rgb[valid]


def depth_gradient(radial_depth: torch.Tensor, one_sided: bool = False) -> torch.Tensor:
    """Relative depth gradient g [H, W] per pixel (module docstring); inf/nan where depth is not finite > 0.
    one_sided: along each axis the smaller of the two one-sided differences instead of the central one,
    so a pixel beside a step (one neighbour on its own surface) scores its own surface's slope and only
    a pixel that differs from both neighbours (on a ramp, or alone) scores high; a pixel nearer than
    both neighbours along one axis only (a line one pixel thick in front of what is behind it) scores
    the other axis alone."""
    D = radial_depth
    P = pad_equirect(D[None], 1)[0]  # [H + 2, W + 2]
    if one_sided:
        c = P[1:-1, 1:-1]
        left, right, up, down = P[1:-1, :-2], P[1:-1, 2:], P[:-2, 1:-1], P[2:, 1:-1]
        gx = torch.minimum((right - c).abs(), (c - left).abs())
        gy = torch.minimum((down - c).abs(), (c - up).abs())
        # a line one pixel thick (a window bar, a stem): nearer than both neighbours across it, on its own
        # surface along it; that axis is its silhouette, not a ramp (a lone pixel, nearer along both, is not)
        thin_x, thin_y = (c < left) & (c < right), (c < up) & (c < down)
        gx = torch.where(thin_x & ~thin_y, torch.zeros_like(gx), gx)
        gy = torch.where(thin_y & ~thin_x, torch.zeros_like(gy), gy)
    else:
        gx = 0.5 * (P[1:-1, 2:] - P[1:-1, :-2])
        gy = 0.5 * (P[2:, 1:-1] - P[:-2, 1:-1])
    g = torch.sqrt(gx * gx + gy * gy) / D
    return torch.where(torch.isfinite(D) & (D > 0), g, torch.full_like(g, float("inf")))


def depth_gradient_mask(radial_depth: torch.Tensor, threshold: float = 0.4, one_sided: bool = False) -> torch.Tensor:
    """Keep-mask [H, W] bool: pixels whose relative depth gradient (``depth_gradient``) is <= ``threshold``
    (paper: 0.4, central differences)."""
    g = depth_gradient(radial_depth, one_sided)
    return torch.nan_to_num(g, nan=float("inf")) <= threshold


def project_points_zbuffer(
    xyz: torch.Tensor,
    rgb: torch.Tensor,
    K: torch.Tensor,
    viewmat: torch.Tensor,
    height: int,
    width: int,
    radius: int | torch.Tensor = 1,
    near: float = 1e-6,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Render points [N, 3] with colours [N, C] into a pinhole camera with a z-buffer.

    Each point in front of the camera (z > near) covers the (2 radius - 1)^2 pixels around the pixel
    it falls in (``radius``: one int, or one per point [N], e.g. ``footprint_radius``); per pixel the
    nearest point wins (ties: lowest point index, so results are deterministic). Returns image
    [H, W, C] (0 where empty), mask [H, W] (1 = hit, 0 = missing) and depth [H, W] (perspective z of
    the winner, inf where empty)."""
    dev = xyz.device
    N, C = rgb.shape
    radii = torch.as_tensor(radius, device=dev).long().expand(N)
    if N and int(radii.min()) < 1:
        raise ValueError(f"project_points_zbuffer: radius must be >= 1, got {int(radii.min())}")
    rmax = int(radii.max()) if N else 1
    uv, z = project_points(xyz, K.to(xyz.dtype), viewmat.to(xyz.dtype))
    ok = (z > near) & torch.isfinite(z) & torch.isfinite(uv).all(-1)
    ok &= (uv[:, 0] > -rmax) & (uv[:, 0] < width + rmax) & (uv[:, 1] > -rmax) & (uv[:, 1] < height + rmax)
    ids = ok.nonzero().squeeze(1)  # only points that can land in the image
    uv, z, radii = uv[ids], z[ids], radii[ids]
    ix, iy = torch.floor(uv[:, 0]).long(), torch.floor(uv[:, 1]).long()
    if dev.type == "cpu":
        from holoflow.geometry.zbuffer_cpu import zbuffer_numpy

        d, o = zbuffer_numpy(
            ix.numpy(),
            iy.numpy(),
            z.detach().contiguous().numpy(),
            ids.numpy(),
            radii.contiguous().numpy(),
            width,
            height,
            N,
        )
        depth, owner = torch.from_numpy(d), torch.from_numpy(o)
    else:
        depth, owner = _zbuffer_torch(ix, iy, z, ids, radii, rmax, width, height, N)
    hit = owner < N
    image = torch.zeros(height * width, C, dtype=rgb.dtype, device=dev)
    image[hit] = rgb[owner[hit]]
    return image.reshape(height, width, C), hit.reshape(height, width).to(xyz.dtype), depth.reshape(height, width)


def _zbuffer_torch(ix, iy, z, ids, radii, rmax: int, width: int, height: int, N: int):
    """(depth, owner) [H W] flat of ``project_points_zbuffer``: one masked pass per square offset."""
    dev = z.device
    pix_l, z_l, id_l = [], [], []
    for dy in range(-(rmax - 1), rmax):
        for dx in range(-(rmax - 1), rmax):
            px, py = ix + dx, iy + dy
            reach = max(abs(dx), abs(dy)) < radii  # this offset is inside the point's square
            sel = reach & (px >= 0) & (px < width) & (py >= 0) & (py < height)
            pix_l.append((py * width + px)[sel])
            z_l.append(z[sel])
            id_l.append(ids[sel])
    pix, zz, pid = torch.cat(pix_l), torch.cat(z_l), torch.cat(id_l)
    depth = torch.full((height * width,), float("inf"), dtype=z.dtype, device=dev)
    depth.scatter_reduce_(0, pix, zz, reduce="amin")
    win = zz == depth[pix]
    owner = torch.full((height * width,), N, dtype=torch.long, device=dev)
    owner.scatter_reduce_(0, pix[win], pid[win], reduce="amin")
    return depth, owner


def footprint_radius(
    xyz: torch.Tensor, viewmat: torch.Tensor, K: torch.Tensor, spacing_rad: float, max_radius: int = 8
) -> torch.Tensor:
    """Per-point splat radius [N] (long, 1..max_radius) that closes the sampling gaps of a cloud made
    from an equirect grid with angular step ``spacing_rad`` (2 pi / width): a point at distance r from
    the panorama centre stands for a patch about r * spacing_rad wide, which a camera sees
    s = fx * r * spacing_rad / z pixels wide; the square (2 R - 1) covers it when R = ceil((s + 1) / 2).
    Holes left after this are disocclusions, not sampling gaps (grazing surfaces aside)."""
    cam_z = xyz @ viewmat[:3, :3].to(xyz.dtype)[2] + viewmat[2, 3].to(xyz.dtype)  # [N]
    r = torch.linalg.vector_norm(xyz, dim=-1)
    fx = float(torch.sqrt(K[0, 0] * K[1, 1]))
    size = fx * r * spacing_rad / cam_z.clamp(min=1e-9)
    return torch.ceil((size + 1) / 2).clamp(1, max_radius).nan_to_num(1).long()


def far_shell_radius(radial_depth: torch.Tensor, factor: float = 2.0, quantile: float = 0.99) -> float:
    """Radius (metres) of the shell that holds unbounded pixels: ``factor`` x the ``quantile`` of the
    finite positive depths. Raises ValueError when no pixel has finite depth (nothing to scale by)."""
    finite = radial_depth[torch.isfinite(radial_depth) & (radial_depth > 0)]
    if finite.numel() == 0:
        raise ValueError("no pixel has finite positive depth: cannot size the far shell; set an explicit sky radius")
    return float(factor * torch.quantile(finite.double()[:: max(1, finite.numel() // 1_000_000)], quantile))


FAR_QUANTILE, SHELL_REL = 0.99, 0.999


def solid_points_mask(xyz: torch.Tensor) -> torch.Tensor:
    """[N] bool: the points of a panorama cloud xyz [N, 3] (metres, centre at the origin) that are not
    on the far sky shell: radius < 0.999 x the 99th percentile of the radii. That percentile is the
    shell whenever the sky covers more than 1% of the cloud (it then also drops sky points the depth
    stage left finite and farther still); with no sky it drops the farthest 1% of the geometry, which
    barely moves a median. All True when nothing would be left."""
    r = torch.linalg.vector_norm(xyz, dim=-1)  # [N]
    if r.numel() == 0:
        return torch.ones_like(r, dtype=torch.bool)
    far = torch.quantile(r.double()[:: max(1, r.numel() // 1_000_000)], FAR_QUANTILE)  # subsampled past 1M
    solid = r < SHELL_REL * far.to(r.dtype)
    return solid if solid.any() else torch.ones_like(solid)


def sky_to_shell(radial_depth: torch.Tensor, radius: float) -> torch.Tensor:
    """Depth [H, W] with every unbounded pixel (non-finite or <= 0) put on a sphere of ``radius`` metres,
    so the scene stays enclosed."""
    bounded = torch.isfinite(radial_depth) & (radial_depth > 0)
    return torch.where(bounded, radial_depth, torch.full_like(radial_depth, radius))


def resample_rgbd(
    rgb: torch.Tensor, radial_depth: torch.Tensor, width: int, guided: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """Equirect RGB-D at ``width`` x ``width // 2``: rgb [H, W, C] -> [h, w, C] antialiased and wrap-aware
    (resize_equirect); radial_depth [H, W] -> [h, w] point-sampled (nearest source pixel), so no depth
    is invented between a foreground edge and the background (and inf stays inf). Enlarged with
    ``guided``, the depth follows the resampled colour (sRGB in [0, 1]) instead:
    holoflow.geometry.upsample, whose edges land on the colour's and which still puts no depth between
    two surfaces."""
    from holoflow.geometry.sampling import resize_equirect, sample_equirect
    from holoflow.geometry.upsample import guided_depth_upsample

    height = max(1, width // 2)
    if rgb.shape[:2] != (height, width):
        rgb = resize_equirect(rgb.permute(2, 0, 1), height, width).permute(1, 2, 0)
    if radial_depth.shape != (height, width):
        if guided and radial_depth.shape[0] <= height and radial_depth.shape[1] <= width:
            return rgb, guided_depth_upsample(radial_depth, rgb[..., :3])
        dirs = equirect_directions(height, width, device=radial_depth.device, dtype=radial_depth.dtype)
        radial_depth = sample_equirect(radial_depth[None, None], dirs[None], "nearest")[0, 0]
    return rgb, radial_depth
