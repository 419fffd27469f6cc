"""No rings at the poles: a constant-colour room made into Gaussians by the project's own
path (point_cloud's P_f sampling, the trainers' initial Gaussians, their default params) and seen
straight up and straight down at the paper's view size is covered everywhere, in the right colour."""

import math

import numpy as np
import pytest
import torch

from holoflow.geometry.area import (
    area_counts,
    area_sample,
    equirect_to_area_points,
    footprint_gaussians,
    polar_caps,
    view_pixel_rad,
)
from holoflow.geometry.camera import intrinsics_from_fov
from holoflow.geometry.config import PointCloudParams
from holoflow.geometry.pointcloud import equirect_to_points
from holoflow.geometry.rigs import base_rig
from holoflow.geometry.sphere import lonlat_to_direction
from holoflow.recon.config import TransferOptParams
from holoflow.recon.optimize import init_model
from holoflow.splat import render
from holoflow.splat.project import EPS2D

COLOUR = (0.6, 0.45, 0.3)  # sRGB, the PLY convention


def _room(width: int, sampling: str, cfg: TransferOptParams, pc: PointCloudParams = PointCloudParams()):
    """Gaussians of a 2 m sphere of one colour, P_f ``width`` px wide from a panorama twice as wide,
    sampled as ``sampling`` says (area: with ``pc``'s polar caps, as point_cloud makes them)."""
    H = width // 2
    rgb = torch.tensor(COLOUR, dtype=torch.float64).expand(H, width, 3)
    depth = torch.full((H, width), 2.0, dtype=torch.float64)
    caps = polar_caps(width, 2 * width, pc.pf_polar_density, pc.pf_polar_from_deg)
    if sampling == "area":
        cap_rgb = None if caps is None else rgb[:1, :1].expand(caps.width // 2, caps.width, 3)
        xyz, c, _, _ = equirect_to_area_points(rgb, depth, caps, cap_rgb)
    else:
        xyz, c = equirect_to_points(rgb, depth)
    low_pass = EPS2D * view_pixel_rad(pc.view_size, pc.view_fov_deg) ** 2  # as recon.schedule.cloud_footprint
    footprint = (2 * math.pi / width, cfg.footprint_width, cfg.footprint_thickness, caps, 0, 0.0, low_pass)
    return init_model(
        xyz.numpy(),
        (c.numpy() * 255 + 0.5).astype(np.uint8),
        cfg.init_opacity,
        footprint=footprint if cfg.init_scale == "footprint" else None,
    )


def _poles(model, size: int = 512, side: bool = False):
    """(rgb, alpha) of the views straight down and straight up (and, ``side``, the 36 other base views)."""
    rig = base_rig(38)
    vm = rig[[0, -1, *range(1, 37)]] if side else rig[[0, -1]]  # down, up (, the others)
    K = intrinsics_from_fov(47.43, size, size).expand(len(vm), 3, 3)
    with torch.no_grad():
        out = render(model, vm.float(), K.float(), size, size, backend="cpu", depth=False)
    return out["rgb"], out["alpha"]


def test_zenith_and_nadir_have_no_rings():
    """The poles are covered, in the right colour. Untrained, the discs leave the same thin seams
    everywhere (worst pixel alpha 0.976-0.982 at the default width), no rings: gaps that only the poles
    have (the control below: alpha < 0.5); after transfer_opt's colour fit (its defaults, here at
    256 px) the views that see a cap are within 0.011 of the colour, the others 0.006."""
    from holoflow.recon.colour_fit import fit_colours, polar_weights

    cfg = TransferOptParams()
    model = _room(512, PointCloudParams().pf_sampling, cfg)
    rgb, alpha = _poles(model, side=True)
    cover = alpha.flatten(1).min(1).values  # [38] worst pixel per view
    assert float(cover.min()) > 0.95, cover
    rig = base_rig(38).float()
    K = intrinsics_from_fov(47.43, 256, 256).float()
    views = [dict(image=torch.tensor(COLOUR).expand(256, 256, 3), viewmat=v, K=K, mask=None) for v in rig]
    fit_colours(
        model, views, cfg.fit_iters, weights=polar_weights(views, cfg.fit_polar_weight), max_colour=cfg.fit_max_colour
    )
    rgb, _ = _poles(model, side=True)
    err = (rgb - torch.tensor(COLOUR)).abs().flatten(1).max(1).values  # [38] worst pixel per view
    assert float(err.max()) < 0.02, err
    assert float(err[:2].max()) <= float(err[2:].max()) + 0.005, err


def test_one_point_per_pixel_leaves_rings():
    """The check above can fail: the paper's grid with 3DGS neighbour sizes shows the rings."""
    model = _room(512, "grid", TransferOptParams(init_scale="knn"))
    _, alpha = _poles(model)
    assert float(alpha.min()) < 0.5


def test_area_sampling_counts_and_colours():
    counts = area_counts(256, 512)
    assert int(counts[0]) == round(512 * math.sin(math.pi / 512)) and int(counts[128]) == 512
    assert abs(int(counts.sum()) / (256 * 512) - 2 / math.pi) < 0.01  # 64 % of the grid
    rng = torch.Generator().manual_seed(0)
    rgb = torch.rand(256, 512, 3, generator=rng, dtype=torch.float64)
    dirs, colour, _, _ = area_sample(rgb, torch.ones(256, 512, dtype=torch.float64))
    assert torch.allclose(torch.linalg.vector_norm(dirs, dim=-1), torch.ones(len(dirs), dtype=torch.float64))
    # each row's box averages keep the row's mean colour (the intervals tile the row exactly)
    row = torch.repeat_interleave(torch.arange(256), counts)
    means = torch.zeros(256, 3, dtype=torch.float64).index_add_(0, row, colour) / counts[:, None]
    assert torch.allclose(means, rgb.mean(1), atol=1e-12)


@pytest.mark.parametrize("d", [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (0.0, -1.0, 0.0), (0.6, 0.0, -0.8)])
def test_footprint_discs_face_the_centre(d):
    from holoflow.geometry.camera import quat_to_rotmat

    xyz = 3.0 * torch.tensor([d], dtype=torch.float64)
    scales, q = footprint_gaussians(xyz, 0.01, 0.6, 0.1)
    assert torch.allclose(scales, torch.tensor([[0.018, 0.018, 0.003]], dtype=torch.float64))
    R = quat_to_rotmat(q)[0]
    assert torch.allclose(R[:, 2], xyz[0] / 3.0, atol=1e-12)  # local z along the ray


def _ring_texture(width: int) -> torch.Tensor:
    """sRGB [width / 2, width, 3]: 24 light-dark cycles around every ring (fine near the poles)."""
    lon = (torch.arange(width, dtype=torch.float64) + 0.5) * (2 * math.pi / width) - math.pi
    v = 0.5 + 0.35 * torch.sin(24 * lon)
    return v[None, :, None].expand(width // 2, width, 3).clone()


def test_polar_caps_keep_the_detail_of_the_polar_rows():
    """Detail along the rings near a pole (a photo's polar rows are W px round) is lost by one point per
    d x d of P_f and kept by the caps (finer grid from the panorama, more points a ring, narrow
    ellipses): the untrained Gaussians' views straight up and down against the panorama's own."""
    from holoflow.geometry.sampling import equirect_to_pinhole

    pf_width, size = 256, 128
    pano = _ring_texture(2 * pf_width)
    col = torch.nn.functional.avg_pool2d(pano.permute(2, 0, 1)[None], 2)[0].permute(1, 2, 0)  # P_f's grid
    depth = torch.full((pf_width // 2, pf_width), 2.0, dtype=torch.float64)
    rig = base_rig(38)[[0, -1]]
    K = intrinsics_from_fov(47.43, size, size)
    want = equirect_to_pinhole(
        pano.permute(2, 0, 1).float(), K[None].expand(2, 3, 3), rig.float(), size, size, mode="antialias"
    ).permute(0, 2, 3, 1)
    cfg = TransferOptParams()
    psnr = {}
    for density in (1.0, 2.0):
        caps = polar_caps(pf_width, 2 * pf_width, density, 65.0)
        xyz, c, _, _ = equirect_to_area_points(col, depth, caps, None if caps is None else pano)
        model = init_model(
            xyz.numpy(),
            (c.numpy() * 255 + 0.5).astype(np.uint8),
            cfg.init_opacity,
            footprint=(2 * math.pi / pf_width, cfg.footprint_width, cfg.footprint_thickness, caps),
        )
        with torch.no_grad():
            rgb = render(model, rig.float(), K[None].expand(2, 3, 3).float(), size, size, backend="cpu", depth=False)[
                "rgb"
            ]
        psnr[density] = float(-10 * torch.log10(((rgb - want) ** 2).mean()))
    # measured: 16.3 dB without the caps, 20.4 with (untrained discs low-pass the pattern either way)
    assert psnr[2.0] > psnr[1.0] + 3.0, psnr


def test_polar_caps_meet_pf_without_a_gap():
    """P_f's last row and the caps' first are no further apart than P_f's own rows, at any edge, and the
    split between them lies between the two."""
    for pf_width, pano_width, density, edge in [
        (1536, 2048, 2.0, 65.0),
        (512, 4096, 2.0, 55.0),
        (256, 256, 2.0, 70.0),
        (1000, 1500, 1.5, 60.3),
    ]:
        caps = polar_caps(pf_width, pano_width, density, edge)
        split = math.radians(caps.split_deg)
        lat = torch.pi / 2 - (torch.arange(pf_width // 2) + 0.5) * torch.pi / (pf_width // 2)
        cap = torch.pi / 2 - (torch.arange(caps.width // 2) + 0.5) * torch.pi / (caps.width // 2)
        last, first = float(lat[lat < split].max()), float(cap[cap > split].min())
        assert last < split < first and last <= math.radians(edge)
        assert first - last <= torch.pi / (pf_width // 2) + 1e-12, (pf_width, pano_width, first - last)
    assert polar_caps(1536, 2048, 1.0, 65.0) is None


def test_cap_ellipses_are_narrow_along_the_ring():
    from holoflow.geometry.camera import quat_to_rotmat
    from holoflow.geometry.sphere import lonlat_to_direction

    caps = polar_caps(512, 1024, 2.0, 60.0)
    lon = torch.tensor([0.3, -2.0, 1.0], dtype=torch.float64)
    lat = torch.tensor([1.2, -1.3, 0.2], dtype=torch.float64)  # north cap, south cap, P_f
    xyz = 3.0 * lonlat_to_direction(lon, lat)
    scales, q = footprint_gaussians(xyz, 2 * math.pi / 512, 0.6, 0.1, caps)
    R = quat_to_rotmat(q)
    torch.testing.assert_close(R[:, :, 2], xyz / 3.0)  # facing the centre, as before
    east = torch.stack([torch.cos(lon), torch.zeros_like(lon), -torch.sin(lon)], -1)
    assert torch.allclose((R[:2, :, 0] * east[:2]).sum(-1).abs(), torch.ones(2, dtype=torch.float64))
    torch.testing.assert_close(scales[:2, 0], 0.6 * 3.0 * caps.ring_rad(lat[:2]))
    torch.testing.assert_close(scales[:2, 1], torch.full((2,), 0.6 * 3.0 * caps.row_rad, dtype=torch.float64))
    torch.testing.assert_close(scales[2], torch.tensor([0.6, 0.6, 0.1], dtype=torch.float64) * 3 * 2 * math.pi / 512)


def test_footprint_width_is_the_rendered_width():
    """With the rasterizer's low-pass at the viewing size, a disc's tangent variance plus that low-pass
    is (width x spacing)^2: what the view shows is as wide relative to the spacing on a fine grid (the
    caps) as on a coarse one; never below half the nominal width; thickness untouched."""
    caps = polar_caps(512, 1024, 2.0, 60.0)
    lat = torch.tensor([1.2, -1.3, 0.2], dtype=torch.float64)  # north cap, south cap, P_f
    xyz = 3.0 * lonlat_to_direction(torch.tensor([0.3, -2.0, 1.0], dtype=torch.float64), lat)
    plain, _ = footprint_gaussians(xyz, 2 * math.pi / 512, 0.6, 0.1, caps)
    low = EPS2D * view_pixel_rad(512, 47.43) ** 2
    scales, _ = footprint_gaussians(xyz, 2 * math.pi / 512, 0.6, 0.1, caps, low_pass_rad2=low)
    torch.testing.assert_close((scales[:, :2] / 3.0) ** 2 + low, (plain[:, :2] / 3.0) ** 2)
    assert bool((scales[:, :2] < plain[:, :2]).all())
    torch.testing.assert_close(scales[:, 2], plain[:, 2])
    floor, _ = footprint_gaussians(xyz, 2 * math.pi / 512, 0.6, 0.1, caps, low_pass_rad2=1.0)
    torch.testing.assert_close(floor[:, :2], plain[:, :2] / 2)


def test_caps_only_where_the_poles_hold_detail():
    """A cap stays on where thinning its rows to P_f's points loses more than at the sides: fine
    ring detail in the north cap turns it on, a smooth south pole (a plain floor, a sky) keeps P_f's
    sampling; ratio 0 keeps both."""
    from holoflow.geometry.area import called_for, ring_detail

    width = 512
    pano = _ring_texture(width)  # 24 cycles a ring, everywhere
    lat = math.pi / 2 - (torch.arange(width // 2) + 0.5) * math.pi / (width // 2)
    pano[lat < 0] = 0.4  # the southern half plain
    caps = polar_caps(width // 2, width, 2.0, 65.0)
    on, detail = called_for(caps, pano, width // 2, 1.0)
    assert on.north and not on.south and detail["south"] < 1e-20 and detail["north"] > detail["sides"] > 0
    both, _ = called_for(caps, pano, width // 2, 0.0)
    assert both.north and both.south
    assert called_for(caps, torch.full((width // 2, width, 3), 0.4, dtype=torch.float64), width // 2, 1.0)[0] is None
    # thinning to all the row's pixels loses nothing
    assert float(ring_detail(pano, torch.full((width // 2,), width)).abs().max()) < 1e-20
