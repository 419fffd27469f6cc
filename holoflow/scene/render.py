"""Render a Scene to an equirect panorama or a pinhole image, with exact depth, through ``cast``.

Rays come from holoflow.geometry (docs/conventions.md): equirect pixel centres at +0.5, top row up;
pinhole K with pixel centres at +0.5 and a world-to-camera ``viewmat`` (OpenCV axes). Antialiasing is
edge-adaptive: every pixel casts its centre ray (which also gives the depth), and pixels whose colour
or depth differs from a neighbour's are re-rendered as the mean of ``samples x samples`` sub-pixel rays.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch

from holoflow.scene.model import Scene
from holoflow.scene.shade import cast

RayFn = Callable[[int, int], tuple[torch.Tensor, torch.Tensor]]  # (h, w) -> origins, dirs [h, w, 3]

COLOR_STEP = 0.04  # sqrt-colour difference that triggers supersampling
DEPTH_STEP = 0.03  # relative depth difference that triggers supersampling


def render_equirect(
    scene: Scene, width: int, height: int, samples: int = 2, device: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Equirect panorama from the origin: linear RGB [H, W, 3] float32 and radial depth [H, W] float32
    (metres along the ray, +inf for sky). ``device``: torch device to trace on (default CPU)."""
    from holoflow.geometry.sphere import equirect_directions

    def rays(h: int, w: int):
        d = equirect_directions(h, w, device=device, dtype=torch.float32)
        return torch.zeros_like(d), d

    rgb, t = _render(scene, rays, width, height, samples, wrap=True)
    return rgb, t


def render_pinhole(
    scene: Scene, K, viewmat, width: int, height: int, samples: int = 1, device: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole view from any camera: linear RGB [H, W, 3] float32 and z-depth [H, W] float32 (metres
    along the camera's optical axis, +inf where nothing is hit). K [3, 3] pixels, viewmat [4, 4]
    world-to-camera (OpenCV axes); numpy arrays or tensors."""
    from holoflow.geometry.camera import pinhole_rays

    K = torch.as_tensor(K, dtype=torch.float64, device=device)
    viewmat = torch.as_tensor(viewmat, dtype=torch.float64, device=device)

    def rays(h: int, w: int):
        Ks = K.clone()
        Ks[0] *= w / width  # the same view on an h x w pixel grid
        Ks[1] *= h / height
        o, d = pinhole_rays(Ks, viewmat, h, w)
        return o.to(torch.float32), d.to(torch.float32)

    rgb, t = _render(scene, rays, width, height, samples, wrap=False)
    _, d = rays(height, width)
    forward = viewmat[2, :3].to(torch.float32)  # camera +z in world coordinates
    cos = (d.reshape(-1, 3) * forward).sum(1).reshape(height, width).cpu().numpy()
    return rgb, (t * cos).astype(np.float32)


def _render(
    scene: Scene, rays: RayFn, width: int, height: int, samples: int, wrap: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Centre ray per pixel, then ``samples``^2 sub-pixel rays where an edge needs them."""
    if width < 1 or height < 1 or samples < 1:
        raise ValueError(f"render: need width, height, samples >= 1, got {width}x{height}, {samples}")
    o, d = rays(height, width)
    rgb, t = cast(scene, o.reshape(-1, 3), d.reshape(-1, 3))
    rgb, t = rgb.reshape(height, width, 3), t.reshape(height, width)
    if samples > 1:
        flag = needs_supersampling(rgb, t, wrap)  # [H, W]
        rows, cols = flag.nonzero(as_tuple=True)
        if len(rows):
            fo, fd = rays(height * samples, width * samples)  # [H s, W s, 3]
            sub = torch.arange(samples, device=rows.device)
            fr = (rows[:, None, None] * samples + sub[None, :, None]).expand(-1, samples, samples)
            fc = (cols[:, None, None] * samples + sub[None, None, :]).expand(-1, samples, samples)
            fine, _ = cast(scene, fo[fr, fc].reshape(-1, 3), fd[fr, fc].reshape(-1, 3))
            rgb[rows, cols] = fine.reshape(len(rows), samples * samples, 3).mean(1)
    return rgb.cpu().numpy().astype(np.float32), t.cpu().numpy().astype(np.float32)


def needs_supersampling(rgb: torch.Tensor, t: torch.Tensor, wrap: bool) -> torch.Tensor:
    """[H, W] bool: pixels that differ from their right or lower neighbour in colour or depth.

    ``wrap``: the last column's right neighbour is the first column (equirect longitude)."""
    c = rgb.clamp(0.0, 1.0).sqrt()
    finite = torch.isfinite(t)
    tt = torch.where(finite, t, torch.zeros_like(t))

    def differ(a: slice, b: slice, dim: int) -> torch.Tensor:
        ca, cb = c[a] if dim == 0 else c[:, a], c[b] if dim == 0 else c[:, b]
        ta, tb = tt[a] if dim == 0 else tt[:, a], tt[b] if dim == 0 else tt[:, b]
        fa, fb = finite[a] if dim == 0 else finite[:, a], finite[b] if dim == 0 else finite[:, b]
        jump = (ta - tb).abs() > DEPTH_STEP * torch.minimum(ta, tb)
        return ((ca - cb).abs().amax(-1) > COLOR_STEP) | (fa != fb) | (fa & fb & jump)

    flag = torch.zeros_like(finite)
    down = differ(slice(0, -1), slice(1, None), 0)  # [H-1, W]
    flag[:-1] |= down
    flag[1:] |= down
    right = differ(slice(0, -1), slice(1, None), 1)  # [H, W-1]
    flag[:, :-1] |= right
    flag[:, 1:] |= right
    if wrap and t.shape[1] > 1:
        seam = differ(slice(-1, None), slice(0, 1), 1)  # last vs first column
        flag[:, -1:] |= seam
        flag[:, :1] |= seam
    return flag
