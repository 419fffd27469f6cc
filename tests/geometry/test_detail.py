"""P_f at full width only where the panorama holds detail (holoflow/geometry/detail.py): the tiles
picked are the detailed ones, a smooth panorama keeps the plain width, and the two samplings meet
without a crack."""

import math

import numpy as np
import torch

from holoflow.geometry.area import area_sample, equirect_to_area_points, polar_caps, view_pixel_rad
from holoflow.geometry.camera import intrinsics_from_fov
from holoflow.geometry.clouds import _pf_width
from holoflow.geometry.config import PointCloudParams
from holoflow.geometry.detail import detail_tiles, thinning_psnr
from holoflow.geometry.rigs import base_rig
from holoflow.recon.config import TransferOptParams
from holoflow.recon.optimize import init_model
from holoflow.splat import render
from holoflow.splat.project import EPS2D


def _checker_patch(H: int, W: int, rows: slice, cols: slice) -> torch.Tensor:
    """[H, W, 3] sRGB: mid grey, with a one-pixel checkerboard over ``rows`` x ``cols``."""
    img = torch.full((H, W, 3), 0.5)
    y, x = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    checker = ((y + x) % 2).float()[..., None].expand(H, W, 3)
    img[rows, cols] = 0.2 + 0.6 * checker[rows, cols]
    return img


def test_detail_tiles_are_the_detailed_ones():
    """A checkerboard patch on a plain grey panorama: with a share below the patch's area every tile
    picked lies in it; with a share above it, all of it is picked and the rest of the share follows
    from the plain tiles; share 1 picks everything."""
    H, W = 128, 256
    img = _checker_patch(H, W, slice(48, 80), slice(64, 128))  # 4 x 8 tiles of 8 px at the equator
    picked = detail_tiles(img, 0.02)
    patch = torch.zeros(16, 32, dtype=torch.bool)
    patch[6:10, 8:16] = True
    assert 0 < int(picked.sum()) <= 32 and not bool((picked & ~patch).any())
    assert bool(detail_tiles(img, 0.5)[patch].all())
    assert bool(detail_tiles(img, 1.0).all())


def test_a_smooth_panorama_keeps_the_plain_width():
    """The gate: a panorama with nothing finer than P_f's plain width keeps it, one with pixel-fine
    detail goes to pf_detail_width, and an explicit pf_width is never changed."""
    H, W = 1024, 2048
    cfg = PointCloudParams()
    lon = torch.linspace(0, 2 * math.pi, W)
    smooth = (0.5 + 0.3 * torch.sin(4 * lon))[None, :, None].expand(H, W, 3)
    width, why = _pf_width(smooth, cfg)
    assert width == cfg.pf_max_width and not why["on"] and why["thinning_psnr"] > cfg.pf_detail_psnr
    detailed = _checker_patch(H, W, slice(0, H), slice(0, W))
    width, why = _pf_width(detailed, cfg)
    assert width == cfg.pf_detail_width and why["on"] and why["thinning_psnr"] < 20
    assert _pf_width(detailed, PointCloudParams(pf_width=1024)) == (1024, None)
    assert thinning_psnr(smooth, 1536) > thinning_psnr(detailed, 1536) + 20


def test_all_tiles_sample_as_without_them():
    """Tiles that are all on change nothing: the same points in the same order."""
    rgb = torch.rand(64, 128, 3, generator=torch.Generator().manual_seed(0))
    depth = torch.full((64, 128), 2.0)
    plain = area_sample(rgb, depth)
    tiled = area_sample(rgb, depth, tiles=torch.ones(8, 16, dtype=torch.bool))
    for a, b in zip(plain, tiled):
        assert torch.equal(a, b)


def test_full_and_half_width_tiles_meet_without_a_crack():
    """A 2 m sphere of one colour sampled at full width in random tiles and at half width in the
    others (with polar caps, as point_cloud samples P_f), made into Gaussians by the trainers' footprint
    init, seen at the paper's view size from the 38 base cameras: covered everywhere as the plain
    sampling is (worst pixel alpha above 0.95). Keeping a point only where its centre lies in its
    tiles instead leaves cracks along the tiles' edges (the control)."""
    width, cfg, pc = 512, TransferOptParams(), PointCloudParams()
    H = width // 2
    rgb = torch.full((H, width, 3), 0.5, dtype=torch.float64)
    depth = torch.full((H, width), 2.0, dtype=torch.float64)
    caps = polar_caps(width, 2 * width, pc.pf_polar_density, pc.pf_polar_from_deg)
    cap_rgb = rgb[:1, :1].expand(caps.width // 2, caps.width, 3)
    tiles = torch.rand(H // 8, width // 8, generator=torch.Generator().manual_seed(1)) < 0.4
    low_pass = EPS2D * view_pixel_rad(pc.view_size, pc.view_fov_deg) ** 2
    rig = base_rig(38).float()
    K = intrinsics_from_fov(47.43, 512, 512).expand(len(rig), 3, 3).float()

    def worst_alpha(xyz: torch.Tensor, coarse: int) -> float:
        footprint = (
            2 * math.pi / width,
            cfg.footprint_width,
            cfg.footprint_thickness,
            caps,
            coarse,
            4 * math.pi / width,
            low_pass,
        )
        model = init_model(xyz.numpy(), np.full((len(xyz), 3), 128, np.uint8), cfg.init_opacity, footprint=footprint)
        with torch.no_grad():
            alpha = render(model, rig, K, 512, 512, backend="cpu", depth=False)["alpha"]
        return float(alpha.min())

    xyz, _, _, coarse = equirect_to_area_points(rgb, depth, caps, cap_rgb, tiles, 8)
    assert 0 < coarse < len(xyz)
    assert worst_alpha(xyz, coarse) > 0.95

    # the control: each sampling keeps a point only where its centre's depth pixel lies in its tiles
    def centred(grid: torch.Tensor, keep: torch.Tensor) -> torch.Tensor:
        lat = torch.pi / 2 - (torch.arange(grid.shape[0]) + 0.5) * torch.pi / grid.shape[0]
        dirs, _, d, pixel = area_sample(grid, depth, rows=~caps.holds(lat))
        ok = keep[pixel // width // 8, pixel % width // 8]
        return dirs[ok] * d[ok, None]

    half = rgb[::2, ::2]
    full, coarse_pts = centred(rgb, tiles), centred(half, ~tiles)
    own = xyz[: len(xyz) - coarse]
    cap_pts = own[caps.holds(torch.asin((-own[:, 1] / own.norm(dim=-1)).clamp(-1, 1)))]
    naive = torch.cat([cap_pts, full, coarse_pts])
    assert worst_alpha(naive, len(coarse_pts)) < 0.9
