"""Gaussians that lie on their surfaces (holoflow/geometry/surfaces.py, area.surface_footprint, clouds.py):
normals of an analytic room, depth noise smoothed within a surface and never across an edge, and the
project's own path (point_clouds -> the trainers' initial Gaussians) seen from eyes off the centre: a
wall with a network's per-pixel depth noise stays opaque, and at a box before a wall no Gaussian
spans the gap between the two."""

import math

import pytest
import torch

from holoflow.geometry.area import footprint_gaussians, surface_footprint
from holoflow.geometry.camera import intrinsics_from_fov, look_at, quat_to_rotmat
from holoflow.geometry.clouds import point_clouds
from holoflow.geometry.config import PointCloudParams
from holoflow.geometry.pointcloud import resample_rgbd
from holoflow.geometry.sphere import equirect_directions
from holoflow.geometry.surfaces import _padded, _shift, _window, depth_noise, smooth_depth, surface_normals
from holoflow.imageops.color import linear_to_srgb_torch
from holoflow.recon.config import TransferOptParams
from holoflow.recon.optimize import init_model
from holoflow.splat import render

from .test_layers import BOX, room_with_box  # the analytic box room

HALF = torch.tensor([2.0, 1.5, 2.5], dtype=torch.float64)  # a box room's half sizes (m)


def box_room_depth(H: int, W: int) -> torch.Tensor:
    """Radial depth [H, W] of the inside of an axis-aligned box room (half sizes HALF) from its centre."""
    dirs = equirect_directions(H, W, dtype=torch.float64)
    t = (HALF / dirs.abs().clamp_min(1e-12)).amin(-1)
    return t


def _cov(scales, quats):
    R = quat_to_rotmat(quats)
    return R @ torch.diag_embed(scales**2) @ R.transpose(-1, -2)


def test_normals_of_a_box_room_are_its_walls():
    H, W = 64, 128
    n = surface_normals(box_room_depth(H, W))
    p = equirect_directions(H, W, dtype=torch.float64) * box_room_depth(H, W)[..., None]
    wall = (p.abs() / HALF).argmax(-1)  # which pair of walls a pixel is on
    want = -torch.nn.functional.one_hot(wall, 3).double() * torch.sign(p.gather(-1, wall[..., None]))
    inner = torch.ones(H, W, dtype=torch.bool)  # farther from the room's edges than the window (2 px)
    for dy in range(-3, 4):
        for dx in range(-3, 4):
            inner &= torch.roll(torch.roll(wall, dy, 0), dx, 1) == wall
    assert torch.allclose(n[inner], want[inner], atol=1e-6)
    assert torch.allclose(torch.linalg.vector_norm(n, dim=-1), torch.ones(H, W, dtype=torch.float64))


@pytest.mark.parametrize("radius", [1, 3])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32, torch.bool])
def test_a_window_of_the_padded_panorama_reads_what_a_shift_reads(radius, dtype):
    """The filters' fast path (one padded copy, a view per offset) against the per-offset reference
    (gather the clamped rows, roll the wrapped columns): equal values, every offset, poles and seam."""
    x = torch.randn(9, 14 if radius == 1 else 2, 2, generator=torch.Generator().manual_seed(radius))  # 2 < radius
    x = x > 0 if dtype == torch.bool else x.to(dtype)
    xp = _padded(x, radius)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            assert torch.equal(_window(xp, radius, dy, dx), _shift(x, dy, dx))


def test_a_pixel_without_depth_or_neighbours_faces_the_centre():
    d = torch.full((16, 32), 2.0, dtype=torch.float64)
    d[5, 7] = float("nan")
    d[9, 20] = 1.0  # a lone near pixel
    n = surface_normals(d)
    dirs = equirect_directions(16, 32, dtype=torch.float64)
    assert torch.allclose(n[5, 7], -dirs[5, 7]) and torch.allclose(n[9, 20], -dirs[9, 20])
    assert torch.isfinite(n).all()


def test_smoothing_removes_pixel_noise_and_keeps_edges():
    g = torch.Generator().manual_seed(0)
    H, W = 256, 512
    depth = box_room_depth(H, W)
    near = torch.zeros(H, W, dtype=torch.bool)
    near[100:150, 200:300] = True
    depth = torch.where(near, 0.6 * depth, depth)  # a box 40 % nearer
    noisy = depth * torch.exp(0.02 * torch.randn(H, W, generator=g, dtype=torch.float64))
    out = smooth_depth(noisy, 3, 0.05)
    err_in, err_out = (noisy / depth).log().std(), (out / depth).log()
    inner = ~(near ^ torch.roll(near, 4, 1)) & ~(near ^ torch.roll(near, -4, 1))
    inner &= ~(near ^ torch.roll(near, 4, 0)) & ~(near ^ torch.roll(near, -4, 0))
    assert float(err_out[inner].std()) < 0.35 * float(err_in)  # noise averaged within surfaces
    assert float(err_out[~inner].abs().max()) < 0.1  # nothing mixed across the edge
    assert torch.equal(smooth_depth(noisy, 0, 0.05), noisy)


def test_a_known_noise_smooths_what_laid_planes_hide():
    """A room whose walls were laid exactly on their planes and a noisy box before them: measured, the
    depth's noise is the planes' (none), so the box keeps its 2 % noise; given the noise the depth had
    before the planes (metric_align's ``holoflow.depth_noise``), it is averaged out."""
    g = torch.Generator().manual_seed(0)
    H, W = 128, 256
    depth = box_room_depth(H, W)
    box = torch.zeros(H, W, dtype=torch.bool)
    box[50:80, 100:160] = True
    truth = torch.where(box, 0.6 * depth, depth)
    noisy = torch.where(box, truth * torch.exp(0.02 * torch.randn(H, W, generator=g, dtype=torch.float64)), truth)
    inner = torch.zeros_like(box)
    inner[54:76, 104:156] = True
    err = lambda d: float((d / truth).log()[inner].std())  # noqa: E731
    assert err(smooth_depth(noisy, 3, 0.05, 10.0)) > 0.9 * err(noisy)  # the planes' noise: nothing to do
    assert err(smooth_depth(noisy, 3, 0.05, 10.0, noise=0.02)) < 0.5 * err(noisy)
    assert torch.equal(smooth_depth(noisy, 3, 0.05, 10.0, noise=0.0), noisy)


def test_without_a_known_noise_the_depth_is_measured_on_its_own_grid():
    """Exact depth (no noise in its header) enlarged onto a P_f grid 1.5 x as wide: the colour-guided
    resampling's unevenness, measured on that grid, reads as more noise than the depth has and would
    widen the smoothing's range until it rounds creases (grey_white_room at 1536 px: -0.3 dB at every
    ring); point_clouds measures the noise on the depth's own grid."""
    rgb, depth = room_with_box(64, 128)
    pc = PointCloudParams(p0_width=128, pf_width=192, ps_width=64)
    _, wide = resample_rgbd(linear_to_srgb_torch(rgb.float()).double(), depth, 192, guided=True)
    assert depth_noise(wide) > 1.2 * depth_noise(depth)
    measured = point_clouds(rgb.float(), depth, pc).clouds["pf"].xyz
    given = point_clouds(rgb.float(), depth, pc, noise=depth_noise(depth)).clouds["pf"].xyz
    assert torch.equal(measured, given)


def test_surface_footprint_facing_the_centre_is_the_centre_facing_disc():
    g = torch.Generator().manual_seed(1)
    d = torch.nn.functional.normalize(torch.randn(50, 3, generator=g, dtype=torch.float64), dim=-1)
    plain = footprint_gaussians(3 * d, 0.01, 0.6, 0.1)
    lying = footprint_gaussians(3 * d, 0.01, 0.6, 0.1, normals=-d)
    assert torch.allclose(_cov(*plain), _cov(*lying), atol=1e-12)


@pytest.mark.parametrize("incidence_deg", [0.0, 45.0, 70.0, 85.0])
def test_a_disc_on_a_slanted_surface_covers_its_footprint_there(incidence_deg):
    """The footprint seen from the centre, projected along the ray onto the surface: the disc's normal
    axis is the surface's, its long axis 1 / cos(incidence) (at most max_stretch) times the short."""
    a = math.radians(incidence_deg)
    ray = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    normal = torch.tensor([[0.0, math.sin(a), -math.cos(a)]], dtype=torch.float64)  # turned about east
    scales, q = surface_footprint(
        ray,
        normal,
        torch.full((1,), 0.01, dtype=torch.float64),
        torch.full((1,), 0.01, dtype=torch.float64),
        torch.full((1,), 0.001, dtype=torch.float64),
        max_stretch=6.0,
    )
    R = quat_to_rotmat(q)[0]
    assert torch.allclose(R[:, 2], normal[0], atol=1e-9)
    stretch = min(1 / math.cos(a), 6.0)
    assert scales[0, 0].item() == pytest.approx(0.01 * stretch, rel=1e-9)
    assert scales[0, 1].item() == pytest.approx(0.01, rel=1e-9)
    assert scales[0, 2].item() == pytest.approx(0.001, rel=1e-9)


def _gaussians(rgb: torch.Tensor, depth: torch.Tensor, pc: PointCloudParams, cfg: TransferOptParams):
    """The trainers' initial Gaussians from the project's own P_f (point_clouds, then init_model with
    the footprint cloud_footprint builds from pf.json and pf.ply's normals)."""
    result = point_clouds(rgb.float(), depth, pc)
    pf = result.clouds["pf"]
    footprint = (
        result.pf["spacing_rad"],
        cfg.footprint_width,
        cfg.footprint_thickness,
        None,
        result.pf.get("layer", {}).get("points", 0),
        result.pf.get("layer", {}).get("spacing_rad", 0.0),
        0.0,
        pf.normals.double() if cfg.footprint_orient == "surface" else None,
        cfg.footprint_max_stretch,
    )
    return init_model(pf.xyz.numpy(), pf.rgb.numpy(), cfg.init_opacity, footprint=footprint)


def _alpha(model, eye, look, size=96):
    K = intrinsics_from_fov(47.43, size, size, dtype=torch.float32)
    eye = torch.tensor([eye], dtype=torch.float32)
    V = look_at(eye, eye + torch.tensor([look], dtype=torch.float32))
    with torch.no_grad():
        return render(model, V, K[None], size, size, backend="cpu")["alpha"][0, ..., 0]


@pytest.mark.parametrize("smooth_radius, cracks", [(3, False), (0, True)])
def test_a_noisy_wall_seen_half_a_metre_off_stays_opaque(smooth_radius, cracks):
    """A box room whose depth carries 3 % per-pixel noise (a network's), made into Gaussians by the
    project's path, seen from 0.5 m left of the centre looking at the far wall: with the noise smoothed
    within the surfaces (the default) every pixel stays opaque; without, the discs' depths scatter and
    cracks open (alpha < 0.9)."""
    H, W = 192, 384
    g = torch.Generator().manual_seed(2)
    depth = box_room_depth(H, W) * torch.exp(0.03 * torch.randn(H, W, generator=g, dtype=torch.float64))
    rgb = torch.full((H, W, 3), 0.5)
    pc = PointCloudParams(pf_width=W, layer_baseline=0.0, pf_polar_density=1.0, smooth_radius=smooth_radius)
    model = _gaussians(rgb, depth, pc, TransferOptParams())
    alpha = _alpha(model, [-0.5, 0.0, 0.0], [0.0, 0.0, 1.0])
    cracked = int((alpha < 0.9).sum())
    if cracks:
        assert cracked >= 2
    else:
        assert cracked == 0


@pytest.mark.parametrize("edge_radius, stretched", [(3, False), (0, True)])
def test_no_gaussian_spans_the_gap_between_a_box_and_the_wall(edge_radius, stretched):
    """room_with_box: a box whose front face (z = 1.5 m) stands 1.5 m before the wall (z = 3 m); from
    the centre nothing else of it shows. Its depth is drawn as an estimator draws it (inverse depth
    box-filtered over 5 px: every silhouette a ramp). With the ramps made steps (the default) no
    initial Gaussian is centred in the space between the face and the wall behind it, and none on the
    face reaches into it (2 standard deviations along its ray under 0.15 m of the 1.5 m); with the
    ramps kept, Gaussians hang in the gap (a rubber sheet)."""
    import torch.nn.functional as F

    H, W = 128, 256
    rgb, depth = room_with_box(H, W)
    x = torch.cat([1 / depth[:, -2:], 1 / depth, 1 / depth[:, :2]], 1)[None, None]
    depth = 1 / F.avg_pool2d(F.pad(x, (0, 0, 2, 2), mode="replicate"), 5, 1)[0, 0]
    pc = PointCloudParams(pf_width=W, pf_polar_density=1.0, layer_baseline=0.0, edge_radius=edge_radius)
    model = _gaussians(rgb.float(), depth, pc, TransferOptParams())
    means = model.means.detach().double()
    ray = means / torch.linalg.vector_norm(means, dim=-1, keepdim=True)
    behind = (means[:, 0].abs() < 0.5) & (means[:, 1].abs() < 0.7)  # the box's silhouette, widened
    gap = behind & (means[:, 2] > BOX[0][2] + 0.05) & (means[:, 2] < 2.9)
    if stretched:
        assert int(gap.sum()) > 10
        return
    assert int(gap.sum()) == 0
    face = (means[:, 2] - BOX[0][2]).abs() < 0.02
    assert int(face.sum()) > 50
    cov = _cov(torch.exp(model.log_scales.detach().double()), model.quats.detach().double())
    along = torch.sqrt(torch.einsum("ni,nij,nj->n", ray, cov, ray))
    assert float(2 * along[face].max()) < 0.15


@pytest.mark.parametrize("sides, width, whole", [("one_sided", 2, True), ("one_sided", 1, True), ("central", 2, False)])
def test_a_thin_near_bar_keeps_its_points(sides, width, whole):
    """A bar one or two pixels wide at 1 m before a wall at 3 m (a window bar, a lamp's stem): with the
    one-sided gradient filter (the default) every one of its pixels becomes a point; the paper's central
    differences drop them, as each lies beside a step. The one-sided filter drops a lone pixel at 1 m (a
    flying pixel), which the central differences cannot see."""
    H, W = 64, 128
    depth = torch.full((H, W), 3.0, dtype=torch.float64)
    depth[10:50, 60 : 60 + width] = 1.0
    depth[30, 100] = 1.0  # alone
    rgb = torch.full((H, W, 3), 0.5)
    pc = PointCloudParams(
        pf_width=W, pf_sampling="grid", layer_baseline=0.0, pf_polar_density=1.0, grad_sides=sides, sky_dome=False
    )
    xyz = point_clouds(rgb, depth, pc).clouds["pf"].xyz
    near = torch.linalg.vector_norm(xyz, dim=-1) < 1.5
    lone = near & (xyz[:, 0] > 0.5)  # the lone pixel's direction is far right of the bar
    assert int((near & ~lone).sum()) == (40 * width if whole else 0)
    assert int(lone.sum()) == (0 if sides == "one_sided" else 1)
