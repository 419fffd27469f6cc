"""Small helpers shared by the real-model engines: devices, progress, wrap resize (colour:
holoflow.imageops.color).

Engines take and return numpy float32 linear RGB ``[H, W, 3]`` in [0, 1]; networks see sRGB.
Panoramas wrap in longitude: column W is column 0 (docs/engines.md).
"""

from __future__ import annotations

import numpy as np

from holoflow.stage import Progress


def report(progress: Progress, done: int, total: int, what: str) -> None:
    if progress is not None:
        progress(int(done), int(total), what)


def torch_device(device: str):
    """``cuda``/``cuda:N`` when asked for and present, ``cpu`` otherwise (``auto`` picks)."""
    import torch

    name = (device or "cpu").lower()
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError("device 'cuda' requested but torch sees no CUDA device")
    return torch.device(name)


def half_on_cuda(device):
    """torch.float16 on CUDA (what the paper's models run in), torch.float32 on CPU."""
    import torch

    return torch.float16 if device.type == "cuda" else torch.float32


def to_chw(rgb: np.ndarray, device, dtype=None):
    """numpy ``[H, W, C]`` -> torch ``[1, C, H, W]``."""
    import torch

    t = torch.from_numpy(np.ascontiguousarray(rgb, dtype=np.float32)).permute(2, 0, 1)[None]
    return t.to(device=device, dtype=dtype or torch.float32)


def to_hwc(t) -> np.ndarray:
    """torch ``[1, C, H, W]`` -> numpy float32 ``[H, W, C]``."""
    return t[0].permute(1, 2, 0).float().cpu().numpy().astype(np.float32)


def _resample_matrix(n_in: int, n_out: int, wrap: bool, a: int = 3):
    """``[n_out, n_in]`` Lanczos-a weights, antialiased when shrinking; wrap or clamp at the ends.

    Pixel centres at +0.5: output i samples input coordinate (i + 0.5) * n_in / n_out - 0.5.
    """
    import torch

    scale = n_in / n_out
    support = a * max(scale, 1.0)  # input pixels
    centre = (torch.arange(n_out, dtype=torch.float64) + 0.5) * scale - 0.5  # [n_out]
    taps = torch.arange(-int(np.ceil(support)) - 1, int(np.ceil(support)) + 2, dtype=torch.float64)
    idx = torch.floor(centre)[:, None] + taps[None]  # [n_out, T]
    d = (idx - centre[:, None]) / max(scale, 1.0)
    w = torch.sinc(d) * torch.sinc(d / a) * (d.abs() < a)
    w = w / w.sum(1, keepdim=True).clamp_min(1e-12)
    idx = idx.long() % n_in if wrap else idx.long().clamp(0, n_in - 1)
    m = torch.zeros(n_out, n_in, dtype=torch.float64)
    m.scatter_add_(1, idx, w)
    return m


def resize_wrap(img, height: int, width: int):
    """Lanczos-3 resize of ``[..., C, H, W]`` to ``[..., C, height, width]``.

    Longitude wraps (column W is column 0); rows clamp at the poles. Separable, exact at the seam.
    """
    import torch

    h, w = img.shape[-2:]
    if (h, w) == (height, width):
        return img
    mx = _resample_matrix(w, width, wrap=True).to(img.device, torch.float32)  # [width, w]
    my = _resample_matrix(h, height, wrap=False).to(img.device, torch.float32)  # [height, h]
    out = torch.matmul(img.float(), mx.T)  # [..., C, h, width]
    return torch.matmul(my, out).to(img.dtype)  # [..., C, height, width]
