"""Seeded synthetic Gaussian scenes and cameras for tests and benchmarks (OpenCV axes)."""

from __future__ import annotations

import math

import torch


def intrinsics(width: int, height: int, fov_x_deg: float = 60.0) -> torch.Tensor:
    """Pinhole K [3, 3] (float32), square pixels, centred axis (``geometry.camera.intrinsics_from_fov``)."""
    from holoflow.geometry.camera import intrinsics_from_fov

    return intrinsics_from_fov(fov_x_deg, width, height, dtype=torch.float32)


def look_at(eye, target) -> torch.Tensor:
    """World-to-camera viewmat [4, 4] (float32) from sequences (``geometry.camera.look_at``)."""
    from holoflow.geometry.camera import look_at as _look_at

    return _look_at(torch.as_tensor(eye, dtype=torch.float64), torch.as_tensor(target, dtype=torch.float64)).float()


def surface_scene(
    n: int, seed: int = 0, depth: float = 4.0, fov_x_deg: float = 60.0, aspect: float = 1.0
) -> dict[str, torch.Tensor]:
    """n activated Gaussians on a wavy surface filling the view of a camera at the origin looking
    along +z (surface at about ``depth`` metres), like a 3DGS scene after init: scales from the point
    spacing, random anisotropy and rotation, opacity in [0.2, 0.9], random colours.
    Returns dict(means [n, 3], quats [n, 4], scales [n, 3], opacities [n], colors [n, 3])."""
    g = torch.Generator().manual_seed(seed)
    half_x = depth * math.tan(math.radians(fov_x_deg) / 2) * 1.1
    half_y = half_x / aspect
    u = (torch.rand(n, generator=g) * 2 - 1) * half_x
    v = (torch.rand(n, generator=g) * 2 - 1) * half_y
    z = depth + 0.4 * torch.sin(1.7 * u) * torch.cos(2.3 * v) + 0.05 * torch.randn(n, generator=g)
    spacing = math.sqrt(4 * half_x * half_y / max(n, 1))
    scales = spacing * (0.5 + torch.rand(n, 3, generator=g))
    return dict(
        means=torch.stack([u, v, z], 1),
        quats=torch.randn(n, 4, generator=g),
        scales=scales,
        opacities=0.2 + 0.7 * torch.rand(n, generator=g),
        colors=torch.rand(n, 3, generator=g),
    )


def room_scene(n: int, seed: int = 0, half: float = 2.0) -> dict[str, torch.Tensor]:
    """n activated Gaussians on the six walls of a cube [-half, half]^3 around the origin, the
    inside-out layout of a panorama scene: a camera at the origin sees only the part in its view.
    Scales from the point spacing, random anisotropy and rotation, opacity in [0.2, 0.9].
    Returns the same dict as ``surface_scene``."""
    g = torch.Generator().manual_seed(seed)
    face = torch.randint(0, 6, (n,), generator=g)
    uv = (torch.rand(n, 2, generator=g) * 2 - 1) * half
    axis, sign = face // 2, (face % 2) * 2 - 1
    means = torch.zeros(n, 3)
    means[torch.arange(n), axis] = sign.float() * half
    other = torch.stack([(axis + 1) % 3, (axis + 2) % 3], 1)
    means[torch.arange(n), other[:, 0]] = uv[:, 0]
    means[torch.arange(n), other[:, 1]] = uv[:, 1]
    spacing = math.sqrt(6 * (2 * half) ** 2 / max(n, 1))
    return dict(
        means=means,
        quats=torch.randn(n, 4, generator=g),
        scales=spacing * (0.5 + torch.rand(n, 3, generator=g)),
        opacities=0.2 + 0.7 * torch.rand(n, generator=g),
        colors=torch.rand(n, 3, generator=g),
    )
