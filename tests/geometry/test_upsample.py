"""Depth enlarged to the colour's grid: edges on the colour's edges, steps kept, surfaces interpolated."""

import math

import pytest
import torch

from holoflow.geometry.pointcloud import resample_rgbd
from holoflow.geometry.sampling import resize_equirect
from holoflow.geometry.upsample import guided_depth_upsample

NEAR, FAR = 2.0, 4.0


def step_scene(H: int, W: int, edge: int, dtype=torch.float64, seed: int = 0):
    """Fine colour [H, W, 3] and depth [H, W]: a textured near surface (columns < ``edge``) before a
    textured far one of another colour."""
    g = torch.Generator().manual_seed(seed)
    near = torch.arange(W) < edge  # [W]
    base = torch.where(near[:, None], torch.tensor([0.8, 0.3, 0.2]), torch.tensor([0.2, 0.4, 0.8]))  # [W, 3]
    colour = (base[None] + 0.04 * torch.rand(H, W, 3, generator=g)).to(dtype)  # [H, W, 3]
    depth = torch.where(near, NEAR, FAR).to(dtype).expand(H, W).clone()  # [H, W]
    return colour, depth


def shrink_depth(depth: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """The depth a coarse network sees: the fine pixel nearest each coarse pixel's centre."""
    H, W = depth.shape
    rows = ((torch.arange(h) + 0.5) * H / h).long().clamp(max=H - 1)
    cols = ((torch.arange(w) + 0.5) * W / w).long().clamp(max=W - 1)
    return depth[rows][:, cols]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("fine,coarse", [((48, 96), (24, 48)), ((48, 96), (32, 64))])
def test_edge_lands_on_the_colour_edge(dtype, fine, coarse):
    """Each fine pixel takes the surface its colour belongs to, wherever the coarse grid put the step; the
    nearest coarse pixel gets it wrong beside the edge."""
    colour, truth = step_scene(*fine, edge=37, dtype=dtype)
    small = shrink_depth(truth, *coarse)
    out = guided_depth_upsample(small, colour)
    assert out.dtype == dtype and out.shape == truth.shape
    torch.testing.assert_close(out, truth)
    _, nearest = resample_rgbd(colour, small, fine[1], guided=False)
    assert (nearest != truth).any()


def test_steps_stay_steps():
    """Two surfaces, random colours and a random coarse layout: no fine pixel lies between them."""
    g = torch.Generator().manual_seed(3)
    small = torch.where(torch.rand(16, 32, generator=g) < 0.5, NEAR, FAR).double()
    colour = torch.rand(40, 80, 3, generator=g).double()
    out = guided_depth_upsample(small, colour)
    assert bool(((out - NEAR).abs() < 1e-12).logical_or((out - FAR).abs() < 1e-12).all())


def smooth_depth(n: int, m: int) -> torch.Tensor:
    """A smooth radial depth [n, m] that varies with latitude (2.5 - 3.5 m)."""
    lat = (0.5 - (torch.arange(n, dtype=torch.float64) + 0.5) / n) * math.pi
    return (3.0 + 0.5 * torch.sin(lat))[:, None].expand(n, m).clone()


def test_smooth_surface_is_interpolated():
    """Under a plain colour a smooth depth comes out within a quarter of one coarse step of the truth;
    under random texture every value stays within the range of the coarse pixels around it."""
    h, w, H, W = 32, 64, 64, 128
    coarse, truth = smooth_depth(h, w), smooth_depth(H, W)
    step = float((coarse[1:] / coarse[:-1] - 1).abs().max())
    plain = guided_depth_upsample(coarse, torch.full((H, W, 3), 0.5, dtype=torch.float64))
    assert float((plain / truth - 1).abs().max()) < 0.25 * step
    textured = guided_depth_upsample(coarse, torch.rand(H, W, 3, generator=torch.Generator().manual_seed(1)).double())
    rows = (torch.arange(H) * h) // H  # the coarse row each fine row lies in
    lo = coarse[(rows - 1).clamp(0, h - 1), :1].expand(H, W).minimum(coarse[(rows + 1).clamp(max=h - 1), :1])
    hi = coarse[(rows - 1).clamp(0, h - 1), :1].expand(H, W).maximum(coarse[(rows + 1).clamp(max=h - 1), :1])
    assert bool(((textured >= lo - 1e-12) & (textured <= hi + 1e-12)).all())


def test_sky_stays_sky_and_never_leaks():
    colour, depth = step_scene(48, 96, edge=30)
    depth[:, 30:] = math.inf  # the far side is sky
    out = guided_depth_upsample(shrink_depth(depth, 24, 48), colour)
    assert torch.equal(torch.isinf(out), torch.isinf(depth))
    assert bool((out[torch.isfinite(out)] == NEAR).all())


def test_seam_wraps():
    """The step at the seam comes out as in the middle: shifting the scene by whole coarse pixels
    shifts the result."""
    colour, truth = step_scene(48, 96, edge=37)
    small = shrink_depth(truth, 24, 48)
    out = guided_depth_upsample(small, colour)
    rolled = guided_depth_upsample(torch.roll(small, 20, 1), torch.roll(colour, 40, 1))
    torch.testing.assert_close(rolled, torch.roll(out, 40, 1), rtol=0, atol=0)


def test_guide_smaller_than_depth_is_refused():
    with pytest.raises(ValueError, match="smaller than the depth"):
        guided_depth_upsample(torch.ones(32, 64), torch.rand(16, 32, 3))


def test_resample_rgbd_guides_only_when_enlarging():
    colour, truth = step_scene(48, 96, edge=37)
    shrunk_rgb, shrunk = resample_rgbd(colour, truth, 48)
    assert shrunk.shape == (24, 48) and set(shrunk.unique().tolist()) <= {NEAR, FAR}
    torch.testing.assert_close(shrunk_rgb, resize_equirect(colour.permute(2, 0, 1), 24, 48).permute(1, 2, 0))
    _, enlarged = resample_rgbd(colour, shrink_depth(truth, 24, 48), 96, guided=True)
    torch.testing.assert_close(enlarged, truth)


def reference_upsample(depth, guide, sigma_px=0.75, sigma_rgb=0.06, tol=0.05):
    """The module docstring's rule pixel by pixel: depth [h, w], guide [H, W, 3] -> [H, W]."""
    h, w = depth.shape
    H, W = guide.shape[:2]
    small = resize_equirect(guide.permute(2, 0, 1), h, w)  # [3, h, w]
    out = torch.empty(H, W, dtype=depth.dtype)
    for i in range(H):
        for j in range(W):
            y, x = (i + 0.5) * h / H - 0.5, (j + 0.5) * w / W - 0.5
            cands = []  # (score, disparity, sky)
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    r, c = min(max(round(y) + dr, 0), h - 1), round(x) + dc
                    dist2 = (y - r) ** 2 + (x - c) ** 2
                    rgb2 = float(((small[:, r, c % w] - guide[i, j]) ** 2).sum())
                    z = float(depth[r, c % w])
                    sky = not (math.isfinite(z) and z > 0)
                    cands.append((dist2 / (2 * sigma_px**2) + rgb2 / (2 * sigma_rgb**2), 0.0 if sky else 1 / z, sky))
            s0, d0, sky0 = min(cands, key=lambda c: c[0])  # the first of the lowest
            same = [(s, d) for s, d, sky in cands if (sky if sky0 else not sky and abs(d - d0) <= tol * d0)]
            num = sum(math.exp(s0 - s) * d for s, d in same)
            den = sum(math.exp(s0 - s) for s, _ in same)
            out[i, j] = den / num if num > 0 else math.inf
    return out


def test_matches_the_rule_pixel_by_pixel():
    """The vectorised upsampling against a plain loop over pixels and their nine candidates, on a
    coarse depth with steps, a smooth ramp and sky, under a random colour guide."""
    g = torch.Generator().manual_seed(3)
    h, w, H, W = 6, 12, 12, 24
    depth = 2.0 + torch.rand(h, w, generator=g, dtype=torch.float64)
    depth[:, 7:] += 3.0  # a step
    depth[0, 2:5] = math.inf  # sky
    guide = torch.rand(H, W, 3, generator=g, dtype=torch.float64)
    fast = guided_depth_upsample(depth, guide)
    slow = reference_upsample(depth, guide)
    assert torch.equal(torch.isinf(fast), torch.isinf(slow))
    finite = torch.isfinite(slow)
    assert torch.allclose(fast[finite], slow[finite], rtol=1e-12, atol=0)
