"""Camera rigs of the reconstruction: base cameras at the panorama centre covering the whole sphere,
and supplementary cameras around each base camera (HoloDreamer, Sec. 3.3 / appendix).

Base rig layout "fibonacci": one camera straight up, one straight down, and ``count - 2`` view
directions on a golden-angle (Fibonacci) spiral between them, at evenly spaced heights
y_i = -1 + (2 i + 1) / (count - 2), i = 0 .. count - 3, longitude step = golden angle (~137.5 deg)
starting at +z. Every camera is a look_at from the origin with world-up roll (straight up/down use
look_at's exact fallback). ``rig_coverage`` counts how many cameras see each equirect pixel.
Smallest square-view FOV that covers the sphere (measured on a 1024x512 grid): 38 cameras 47 deg
(the paper's 47.4 deg covers it, tested), 26 -> 58, 20 -> 68, 12 -> 88, 8 -> 120 deg.
"""

from __future__ import annotations

import math

import torch

from holoflow.geometry.camera import camera_centers, look_at, make_viewmat

LAYOUTS = ("fibonacci",)


def base_directions(count: int = 38, layout: str = "fibonacci", device=None, dtype=None) -> torch.Tensor:
    """Unit view directions [count, 3] of the base rig (module docstring)."""
    if layout not in LAYOUTS:
        raise ValueError(f"base_rig: unknown layout {layout!r} (known: {', '.join(LAYOUTS)})")
    if count < 2:
        raise ValueError(f"base_rig: need at least 2 cameras (both poles), got {count}")
    n = count - 2
    i = torch.arange(n, dtype=torch.float64)
    y = -1.0 + (2.0 * i + 1.0) / max(n, 1)
    r = torch.sqrt((1.0 - y * y).clamp(min=0))
    lon = i * (math.pi * (3.0 - math.sqrt(5.0)))
    spiral = torch.stack([r * torch.sin(lon), y, r * torch.cos(lon)], -1)
    poles = torch.tensor([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)
    dirs = torch.cat([poles[:1], spiral, poles[1:]], 0)
    return dirs.to(device=device, dtype=dtype or torch.get_default_dtype())


def base_rig(count: int = 38, layout: str = "fibonacci", device=None, dtype=None) -> torch.Tensor:
    """World-to-camera viewmats [count, 4, 4] of the base cameras (all at the origin)."""
    dirs = base_directions(count, layout, device=device, dtype=dtype)
    return look_at(torch.zeros_like(dirs), dirs)


SUPPLEMENTARY = ("above", "below", "left", "right")


def supplementary_rig(
    base_viewmats: torch.Tensor, depths_per_view: torch.Tensor, offset: float = 0.1, angle_deg: float = 10.0
) -> torch.Tensor:
    """Four supplementary viewmats [4 M, 4, 4] per base camera, ordered (above, below, left, right).

    Each is the base camera moved by ``offset * depths_per_view[i]`` (metres; ``offset`` is a fraction
    of the base view's typical scene depth, e.g. its median) along its own up / down / left / right
    axis, then turned by ``angle_deg`` back towards the base camera's optical axis (the camera above
    tilts down, the one on the left pans right ...), so it looks at the same scene from a shifted
    viewpoint and sees what the centre could not (disocclusions)."""
    M = base_viewmats.shape[0]
    dtype, dev = base_viewmats.dtype, base_viewmats.device
    depths = torch.as_tensor(depths_per_view, dtype=dtype, device=dev).reshape(M)
    R = base_viewmats[:, :3, :3]  # [M, 3, 3] rows: camera x, y, z in world
    centre = camera_centers(base_viewmats)  # [M, 3]
    # camera-frame move directions (above = -y, below = +y, left = -x, right = +x)
    moves = torch.tensor([[0, -1, 0], [0, 1, 0], [-1, 0, 0], [1, 0, 0]], dtype=dtype, device=dev)  # [4, 3]
    a = math.radians(angle_deg)
    # T_k: axes of the turned camera in the base camera's frame; above: z -> (0, sin a, cos a) tilts down
    turns = torch.stack([_rotation(0, -a), _rotation(0, a), _rotation(1, a), _rotation(1, -a)]).to(
        dtype=dtype, device=dev
    )
    out = []
    for k in range(4):
        cam_move = moves[k]
        eye = centre + depths[:, None] * offset * (cam_move @ R)  # [M, 3] (R^T move)
        R_new = turns[k].T @ R  # world -> turned camera: (R^T T)^T
        out.append(make_viewmat(R_new, -(R_new @ eye.unsqueeze(-1)).squeeze(-1)))
    return torch.stack(out, 1).reshape(4 * M, 4, 4)


def _rotation(axis: int, angle: float) -> torch.Tensor:
    """Rotation [3, 3] (float64) by ``angle`` radians about camera axis 0 (x) or 1 (y), right-handed."""
    c, s = math.cos(angle), math.sin(angle)
    if axis == 0:
        return torch.tensor([[1.0, 0, 0], [0, c, -s], [0, s, c]], dtype=torch.float64)
    return torch.tensor([[c, 0, s], [0, 1.0, 0], [-s, 0, c]], dtype=torch.float64)


def rig_coverage(
    K: torch.Tensor, viewmats: torch.Tensor, width: int, height: int, pano_height: int, pano_width: int
) -> torch.Tensor:
    """How many cameras see each equirect pixel centre's direction: [pano_height, pano_width] int.

    K [3, 3] or [M, 3, 3] for images of ``width`` x ``height``; only rotations count (directions)."""
    from holoflow.geometry.sphere import equirect_directions

    dirs = equirect_directions(pano_height, pano_width, device=viewmats.device, dtype=viewmats.dtype).reshape(-1, 3)
    M = viewmats.shape[0]
    Ks = K.expand(M, 3, 3)
    cam = torch.einsum("mij,nj->mni", viewmats[:, :3, :3], dirs)  # [M, N, 3] directions in each camera
    z = cam[..., 2]
    # inside the image <=> 0 <= fx x/z + cx <= width (and likewise y), multiplied through by z > 0
    px = Ks[:, 0, 0, None] * cam[..., 0] + Ks[:, 0, 2, None] * z
    py = Ks[:, 1, 1, None] * cam[..., 1] + Ks[:, 1, 2, None] * z
    seen = (z > 0) & (px >= 0) & (px <= width * z) & (py >= 0) & (py <= height * z)
    return seen.sum(0).reshape(pano_height, pano_width)
