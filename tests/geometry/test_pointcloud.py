"""RGB-D back-projection, the depth-gradient filter, and z-buffer projection of a known scene."""

import math

import pytest
import torch
import torch.nn.functional as F

from holoflow.geometry.camera import intrinsics_from_fov, look_at, pinhole_rays
from holoflow.geometry.pointcloud import depth_gradient, depth_gradient_mask, equirect_to_points, project_points_zbuffer
from holoflow.geometry.sphere import equirect_directions

ROOM = 2.0  # box room [-2, 2]^3
BALL_C, BALL_R = (0.35, 0.25, 1.0), 0.35


def cast(origins, dirs):
    """Distance along unit rays [..., 3] to the first hit in the box room with a ball inside."""
    safe = torch.where(dirs.abs() < 1e-12, torch.full_like(dirs, 1e-12), dirs)
    t_box = ((torch.sign(safe) * ROOM - origins) / safe).amin(-1)
    c = torch.tensor(BALL_C, dtype=dirs.dtype, device=dirs.device)
    oc = origins - c
    b = (oc * dirs).sum(-1)
    disc = b * b - ((oc * oc).sum(-1) - BALL_R**2)
    t_ball = -b - torch.sqrt(disc.clamp(min=0))
    hit_ball = (disc > 0) & (t_ball > 0)
    return torch.where(hit_ball & (t_ball < t_box), t_ball, t_box)


def colour(p):
    """Smooth colour [..., 3] of a world point."""
    return torch.stack(
        [
            0.5 + 0.4 * torch.sin(1.3 * p[..., 0] + 0.4 * p[..., 2]),
            0.5 + 0.4 * torch.cos(1.1 * p[..., 1] - 0.3 * p[..., 0]),
            0.5 + 0.3 * torch.sin(0.9 * p[..., 2] + p[..., 1]),
        ],
        -1,
    )


def rgbd_pano(H, W, dtype, device):
    d = equirect_directions(H, W, device=device, dtype=dtype)
    t = cast(torch.zeros_like(d), d)
    return colour(d * t[..., None]), t


def test_equirect_to_points_skips_non_finite(dtype, device):
    rgb = torch.rand(4, 8, 3, dtype=dtype, device=device)
    depth = torch.full((4, 8), 2.0, dtype=dtype, device=device)
    depth[0, 0], depth[1, 1], depth[2, 2], depth[3, 3] = float("inf"), float("nan"), 0.0, -1.0
    xyz, col = equirect_to_points(rgb, depth)
    assert xyz.shape == (28, 3) and col.shape == (28, 3)
    torch.testing.assert_close(
        torch.linalg.vector_norm(xyz, dim=-1), torch.full((28,), 2.0, dtype=dtype, device=device)
    )
    assert torch.equal(col[0], rgb[0, 1])


def test_depth_gradient_definition(dtype, device):
    # constant depth: zero gradient everywhere, poles and seam included
    D = torch.full((16, 32), 3.0, dtype=dtype, device=device)
    assert float(depth_gradient(D).abs().max()) == 0.0
    # a vertical step 2 m -> 4 m between two columns: the near side has g = (4 - 2) / 2 / 2 = 0.5 and is
    # dropped, the far side g = 0.25 is kept; the seam wraps (columns 0 and W-1 are neighbours)
    D = torch.full((16, 32), 2.0, dtype=dtype, device=device)
    D[:, 10:] = 4.0
    g = depth_gradient(D)
    torch.testing.assert_close(g[8, 9], torch.tensor(0.5, dtype=dtype, device=device))
    torch.testing.assert_close(g[8, 10], torch.tensor(0.25, dtype=dtype, device=device))
    torch.testing.assert_close(g[8, 31], torch.tensor(0.25, dtype=dtype, device=device))
    keep = depth_gradient_mask(D, 0.4)
    assert not keep[:, 9].any() and keep[:, 10].all() and keep[:, 20].all()
    D[3, 3] = float("inf")
    assert not depth_gradient_mask(D)[3, 3]


def test_depth_gradient_keeps_smooth_room(dtype, device):
    """In the analytic room only pixels at the ball's silhouette are dropped."""
    _, t = rgbd_pano(128, 256, dtype, device)
    keep = depth_gradient_mask(t, 0.4)
    assert 0.0 < float((~keep).float().mean()) < 0.01


@pytest.mark.parametrize("radius", [1, 2])
def test_zbuffer_reproduces_view_and_flags_disocclusion(dtype, device, radius):
    """Points from a 768x384 RGB-D pano of the room, seen from a camera moved 0.3 m right: where the
    surface the camera sees was visible from the centre, the projection shows it (colour within 0.03,
    z within 2 cm); exactly the pixels whose surface was hidden from the centre (behind the ball) are
    missing, up to one pixel at the boundary of that region. Colour/depth checks skip pixels within one
    pixel of a silhouette, where the nearer of two surfaces sharing the pixel wins."""
    H, W = 384, 768
    rgb, t = rgbd_pano(H, W, dtype, device)
    xyz, col = equirect_to_points(rgb, t)
    size = 48
    K = intrinsics_from_fov(60.0, size, size, device=device, dtype=dtype)
    eye = torch.tensor([0.3, 0.0, 0.0], dtype=dtype, device=device)
    V = look_at(eye, torch.tensor([0.3, 0.25, 1.0], dtype=dtype, device=device))
    img, mask, depth = project_points_zbuffer(xyz, col, K, V, size, size, radius=radius)
    assert img.shape == (size, size, 3) and mask.shape == depth.shape == (size, size)
    o, d = pinhole_rays(K, V, size, size)
    th = cast(o, d)
    p = o + th[..., None] * d  # surface seen by each pixel
    back = cast(torch.zeros_like(p), p / torch.linalg.vector_norm(p, dim=-1, keepdim=True))
    visible = (back - torch.linalg.vector_norm(p, dim=-1)).abs() < 1e-3  # seen from the centre
    assert 0.02 < 1 - float(visible.float().mean()) < 0.5  # the view does contain a disocclusion
    v = visible.to(dtype)[None, None]
    core_vis = -F.max_pool2d(-v, 3, 1, 1)[0, 0] > 0.5  # visible, away from the boundary
    core_hid = F.max_pool2d(v, 3, 1, 1)[0, 0] < 0.5  # hidden, away from the boundary
    if radius == 1:
        assert (mask[core_vis] == 1).all()
        assert (mask[core_hid] == 0).all()
    else:  # bigger splats fill one more pixel ring into the hole, never more
        far_hid = F.max_pool2d(v, 5, 1, 2)[0, 0] < 0.5
        far_hid[[0, -1]], far_hid[:, [0, -1]] = False, False  # points just outside the image splat in
        assert (mask[core_vis] == 1).all() and (mask[far_hid] == 0).all()
    # colour and depth where visible, away from silhouettes (a pixel there holds two surfaces)
    z_true = th * (d @ V[2, :3])
    zt = z_true[None, None]
    k = 2 * radius + 1  # a splat reaches radius - 1 pixels over a silhouette
    smooth = (F.max_pool2d(zt, k, 1, radius) + F.max_pool2d(-zt, k, 1, radius))[0, 0] < 0.05 * z_true
    core_vis = core_vis & smooth
    err = (img - colour(p)).abs().amax(-1)
    assert float(err[core_vis].max()) < 0.03 * radius
    assert float((depth - z_true)[core_vis].abs().max()) < 0.02 * radius
    assert torch.isinf(depth[mask == 0]).all()


def test_zbuffer_nearest_wins_and_edge_cases(dtype, device):
    K = intrinsics_from_fov(90.0, 4, 4, device=device, dtype=dtype)
    V = torch.eye(4, dtype=dtype, device=device)
    xyz = torch.tensor(
        [[0.1, 0.1, 2.0], [0.1, 0.1, 1.0], [0.1, 0.1, 3.0], [0, 0, -1.0], [float("nan"), 0, 1], [100.0, 0, 1]],
        dtype=dtype,
        device=device,
    )
    col = torch.tensor([[1.0], [2.0], [3.0], [4.0], [5.0], [6.0]], dtype=dtype, device=device)
    img, mask, depth = project_points_zbuffer(xyz, col, K, V, 4, 4)
    assert int(mask.sum()) == 1 and float(img[2, 2, 0]) == 2.0 and float(depth[2, 2]) == 1.0
    empty = project_points_zbuffer(xyz[:0], col[:0], K, V, 4, 4)
    assert float(empty[1].sum()) == 0.0


@pytest.mark.parametrize("dtype_", [torch.float32, torch.float64])
def test_zbuffer_numba_kernel_matches_the_torch_reference(dtype_):
    """The CPU kernel and the torch path give the same depth and owner, bit for bit: random squares
    of radius 1..5 crossing the borders, depths drawn from a few values so ties are common."""
    from holoflow.geometry.pointcloud import _zbuffer_torch
    from holoflow.geometry.zbuffer_cpu import zbuffer_numpy

    g = torch.Generator().manual_seed(0)
    n, w, h = 3000, 37, 23
    ix, iy = torch.randint(-4, w + 4, (n,), generator=g), torch.randint(-4, h + 4, (n,), generator=g)
    z = torch.randint(1, 6, (n,), generator=g).to(dtype_) / 2
    ids = torch.randperm(5 * n, generator=g)[:n]
    radii = torch.randint(1, 6, (n,), generator=g)
    want_d, want_o = _zbuffer_torch(ix, iy, z, ids, radii, 5, w, h, 5 * n)
    got_d, got_o = zbuffer_numpy(ix.numpy(), iy.numpy(), z.numpy(), ids.numpy(), radii.numpy(), w, h, 5 * n)
    # exact on any CPU: both keep, per pixel, the nearest of the same depths (compares and copies only)
    assert torch.equal(torch.from_numpy(got_d), want_d) and torch.equal(torch.from_numpy(got_o), want_o)


def test_footprint_radius_closes_sampling_gaps(dtype, device):
    """A sparse cloud (128x64 pano, 2.8 deg per point) seen by 1.25 deg pixels: one-pixel splats leave
    gaps everywhere; footprint radii hit >= 97% of the pixels whose surface was visible from the centre
    (the rest: the ball near its limb, where the pano samples the surface at grazing incidence, which
    the footprint does not model) and none of the pixels hidden from it (beyond one splat)."""
    from holoflow.geometry.pointcloud import footprint_radius

    rgb, t = rgbd_pano(64, 128, dtype, device)
    xyz, col = equirect_to_points(rgb, t)
    K = intrinsics_from_fov(60.0, 48, 48, device=device, dtype=dtype)
    V = look_at(
        torch.tensor([0.3, 0.0, 0.0], dtype=dtype, device=device),
        torch.tensor([0.3, 0.25, 1.0], dtype=dtype, device=device),
    )
    o, d = pinhole_rays(K, V, 48, 48)
    p = o + cast(o, d)[..., None] * d
    back = cast(torch.zeros_like(p), p / torch.linalg.vector_norm(p, dim=-1, keepdim=True))
    visible = ((back - torch.linalg.vector_norm(p, dim=-1)).abs() < 1e-3).to(dtype)[None, None]
    core_vis = -F.max_pool2d(-visible, 3, 1, 1)[0, 0] > 0.5
    _, thin, _ = project_points_zbuffer(xyz, col, K, V, 48, 48, radius=1)
    radii = footprint_radius(xyz, V, K, 2 * math.pi / 128)
    assert radii.dtype == torch.long and 1 <= int(radii.min()) and int(radii.max()) <= 8
    _, full, _ = project_points_zbuffer(xyz, col, K, V, 48, 48, radius=radii)
    assert float(thin[core_vis].mean()) < 0.7
    assert float(full[core_vis].mean()) > 0.97
    from holoflow.geometry.camera import project_points

    uv, z = project_points(xyz, K, V)
    seen = (z > 0) & (uv >= 0).all(-1) & (uv < 48).all(-1)
    r = int(radii[seen].max())  # largest splat that lands in the view
    far_hid = F.max_pool2d(visible, 2 * r - 1, 1, r - 1)[0, 0] < 0.5
    assert (full[far_hid] == 0).all() and bool(far_hid.any())


def test_solid_points_mask_drops_exactly_the_sky_shell(dtype, device):
    """Outdoor-like cloud: the box room's lower 45 % of rows plus a sky on the far shell (the upper 55 %,
    so the median radius is the shell's): the mask keeps every room point and no shell point. Indoors
    (no sky) it drops at most the farthest ~1 % and leaves the median in place."""
    from holoflow.geometry.pointcloud import far_shell_radius, sky_to_shell, solid_points_mask

    rgb, t = rgbd_pano(64, 128, dtype, device)
    sky = torch.zeros_like(t, dtype=torch.bool)
    sky[: int(0.55 * 64)] = True
    depth = sky_to_shell(torch.where(sky, torch.full_like(t, float("inf")), t), far_shell_radius(t))
    xyz, _ = equirect_to_points(rgb, depth)
    solid = solid_points_mask(xyz)
    assert torch.equal(solid, ~sky.reshape(-1))  # a threshold far from both the shell and the room: no ulp moves it
    room, _ = equirect_to_points(rgb, t)
    kept = solid_points_mask(room)
    r = torch.linalg.vector_norm(room, dim=-1)
    assert float(kept.double().mean()) >= 0.985
    assert float(r[kept].median()) == pytest.approx(float(r.median()), rel=0.01)
    assert bool(solid_points_mask(xyz[:1]).all())
