"""Preview renders from inside a Gaussian scene: a look-around strip (PNG) and a turning GIF.

Cameras sit at the panorama centre (the world origin) and turn about the vertical axis (world up is
-y, docs/conventions.md), level with the horizon. Renders are sRGB (what the Gaussians hold) and
written as 8-bit PNG / GIF with Pillow.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from holoflow.io.image import write_png


def yaw_cameras(n: int, pitch_deg: float = 0.0) -> torch.Tensor:
    """n world-to-camera viewmats [n, 4, 4] at the origin, yaw 0, 360/n, ... degrees (yaw 0 looks along
    +z, positive yaw turns towards +x), pitched up by ``pitch_deg``."""
    from holoflow.geometry.camera import look_at

    yaw = torch.arange(n, dtype=torch.float64) * (2 * math.pi / n)  # [n]
    pitch = torch.full_like(yaw, math.radians(pitch_deg))
    d = torch.stack([pitch.cos() * yaw.sin(), -pitch.sin(), pitch.cos() * yaw.cos()], -1)  # [n, 3]
    return look_at(torch.zeros_like(d), d).float()


def to_uint8(img: torch.Tensor | np.ndarray) -> np.ndarray:
    """sRGB [..., 3] in [0, 1] -> uint8 (rounded)."""
    a = np.asarray(img.detach().cpu() if isinstance(img, torch.Tensor) else img, dtype=np.float32)
    return (np.clip(a, 0, 1) * 255.0 + 0.5).astype(np.uint8)


def write_gif(path: str | Path, frames_u8: list[np.ndarray], ms_per_frame: int = 120) -> None:
    """Write an endlessly looping GIF from uint8 frames [H, W, 3]."""
    from PIL import Image

    imgs = [Image.fromarray(np.ascontiguousarray(f), "RGB") for f in frames_u8]
    imgs[0].save(str(path), save_all=True, append_images=imgs[1:], duration=ms_per_frame, loop=0)


@torch.no_grad()
def render_at(model, viewmats: torch.Tensor, K: torch.Tensor, size: int, backend: str) -> torch.Tensor:
    """sRGB renders [C, size, size, 3] of ``model`` (background black). K [3, 3] is rescaled from its
    own image size (2 cx) to ``size`` so the field of view is kept."""
    from holoflow.splat import render

    dev = model.means.device
    Ks = (K * (size / (2 * float(K[0, 2])))).clone().to(dev)
    Ks[2, 2] = 1.0
    out = []
    for s in range(0, len(viewmats), 8):
        vm = viewmats[s : s + 8].to(dev)
        out.append(
            render(model, vm, Ks[None].expand(len(vm), 3, 3), size, size, backend=backend, depth=False)["rgb"]
            .clamp(0, 1)
            .cpu()
        )
    return torch.cat(out)


def write_previews(
    model, folder: str | Path, K: torch.Tensor, backend: str, size: int, strip_views: int = 8, gif_frames: int = 24
) -> list[Path]:
    """``size`` x ``size`` px renders (transfer_opt's ``preview_size``): previews/look_around.png (``strip_views``
    level views side by side, then the same pitched
    +-45 deg in rows above / below) and previews/look_around.gif (``gif_frames`` level views).
    Returns the written paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rows = [render_at(model, yaw_cameras(strip_views, pitch), K, size, backend) for pitch in (45.0, 0.0, -45.0)]
    strip = np.concatenate([np.concatenate(list(to_uint8(r)), 1) for r in rows], 0)
    write_png(folder / "look_around.png", strip)
    frames = to_uint8(render_at(model, yaw_cameras(gif_frames), K, size, backend))
    write_gif(folder / "look_around.gif", list(frames))
    return [folder / "look_around.png", folder / "look_around.gif"]
