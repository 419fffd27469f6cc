"""The background layer (holoflow/geometry/layers.py): a synthetic step edge, the sky shell under a
silhouette, and a box in front of a wall seen 0.5 m off centre with and without the layer."""

import math

import pytest
import torch

from holoflow.geometry.camera import intrinsics_from_fov, look_at, pinhole_rays
from holoflow.geometry.layers import background_layer
from holoflow.geometry.pointcloud import (
    depth_gradient_mask,
    equirect_to_points,
    footprint_radius,
    project_points_zbuffer,
)
from holoflow.geometry.sphere import equirect_directions
from holoflow.recon.config import TransferOptParams

RED, BLUE = torch.tensor([1.0, 0.0, 0.0]), torch.tensor([0.0, 0.0, 1.0])


def step_edge(H=64, W=128, near=2.0, far=4.0):
    """A red far wall at ``far`` m with a blue slab at ``near`` m over columns 40..59; P_f's mask."""
    d = torch.full((H, W), far, dtype=torch.float64)
    d[:, 40:60] = near
    rgb = RED.expand(H, W, 3).clone()
    rgb[:, 40:60] = BLUE
    return rgb, d, depth_gradient_mask(d, 0.4)


def test_step_edge_band_width_depth_and_colour():
    rgb, d, keep = step_edge()
    assert keep[:, 39].all() and not keep[:, 40].any() and not keep[:, 59].any()  # the near side's edge is dropped
    step = 2 * math.pi / 128
    for baseline in (0.5, 1.0):
        ld, lc = background_layer(rgb, d, keep, baseline)
        row = torch.isfinite(ld[32])
        # the band a move of `baseline` uncovers, baseline (1/2 - 1/4) rad (+ the dropped edge pixel),
        # counted from the last far pixel (39 and 60)
        width = int(baseline * (1 / 2 - 1 / 4) / step + 1)
        assert width >= 3
        assert row[40 : 40 + width].all() and not row[40 + width : 60 - width].any()
        assert row[60 - width : 60].all() and not row[:40].any() and not row[60:].any()
        torch.testing.assert_close(ld[32][row], torch.full_like(ld[32][row], 4.0))  # the far wall's depth
        torch.testing.assert_close(lc[32][row], RED.expand(int(row.sum()), 3))  # the far wall's colour
    assert not torch.isfinite(background_layer(rgb, d, keep, 0.0)[0][8:56, 42:58]).any()  # off the poles
    full = torch.isfinite(background_layer(rgb, d, keep, 1.0)[0])
    sparse = torch.isfinite(background_layer(rgb, d, keep, 1.0, stride=2)[0])
    assert torch.equal(sparse[::2, ::2], full[::2, ::2]) and int(sparse.sum()) == int(full[::2, ::2].sum())


def test_layer_extends_a_slanted_far_surface_in_inverse_depth():
    # far surface whose inverse depth falls linearly with the column: with slope the layer continues the line
    H, W = 32, 128
    cols = torch.arange(W, dtype=torch.float64)
    inv = 0.25 - 0.001 * cols
    d = (1.0 / inv).expand(H, W).clone()
    d[:, 40:60] = 1.5
    rgb = RED.expand(H, W, 3).clone()
    keep = depth_gradient_mask(d, 0.4)
    ld, _ = background_layer(rgb, d, keep, 1.0, slope=True)
    band = torch.isfinite(ld[16])
    band[50:] = False  # the left edge's side only (the seam,
    band[:30] = False  # where inverse depth jumps, has its own)
    c = cols[band]
    assert len(c) >= 5
    torch.testing.assert_close(1.0 / ld[16][band], 0.25 - 0.001 * c, rtol=1e-9, atol=1e-12)


def test_sky_shell_continues_under_a_silhouette():
    # an object at 3 m against sky already put on a 100 m shell: the shell grows under its edge
    H, W = 64, 128
    d = torch.full((H, W), 100.0, dtype=torch.float64)
    d[20:44, 50:78] = 3.0
    rgb = torch.rand(H, W, 3, generator=torch.Generator().manual_seed(0))
    ld, _ = background_layer(rgb, d, depth_gradient_mask(d, 0.4), 1.0)
    under = torch.isfinite(ld[20:44, 50:78])
    assert under[:, :4].all() and under[:, -4:].all() and under[:4].all() and under[-4:].all()
    torch.testing.assert_close(ld[torch.isfinite(ld)], torch.full_like(ld[torch.isfinite(ld)], 100.0))


ROOM = torch.tensor([3.0, 2.0, 3.0], dtype=torch.float64)  # half sizes (m)
BOX = (torch.tensor([-0.3, -0.5, 1.5], dtype=torch.float64), torch.tensor([0.3, 0.5, 2.0], dtype=torch.float64))


def cast(origins, dirs):
    """Ray cast (origins, unit dirs [..., 3], inside the room) into a 6 x 4 x 6 m room with a 0.6 x 1 x
    0.5 m box 1.5 m in front of the centre (z): (distance [...] m, hit the box [...] bool)."""
    inv = 1.0 / torch.where(dirs.abs() < 1e-12, torch.full_like(dirs, 1e-12), dirs)
    t_room = ((torch.sign(inv) * ROOM - origins) * inv).amin(-1)  # exit of the room
    t1, t2 = (BOX[0] - origins) * inv, (BOX[1] - origins) * inv
    t_in, t_out = torch.minimum(t1, t2).amax(-1), torch.maximum(t1, t2).amin(-1)
    box = (t_in < t_out) & (t_in > 0)
    return torch.where(box, t_in, t_room), box


def room_with_box(H, W):
    """The analytic RGB-D panorama of ``cast`` from the origin: rgb [H, W, 3] (walls in 0.5 m stripes,
    the box blue), radial depth [H, W]."""
    dirs = equirect_directions(H, W, dtype=torch.float64)  # [H, W, 3]
    depth, box = cast(torch.zeros_like(dirs), dirs)
    x = dirs * depth[..., None]
    stripe = (torch.floor(2 * (x[..., 0] + x[..., 1] + x[..., 2])) % 2)[..., None]
    wall = 0.3 + 0.5 * stripe * torch.tensor([1.0, 0.8, 0.2], dtype=torch.float64)
    return torch.where(box[..., None], BLUE.double(), wall), depth


def box_room_cloud(H: int, W: int, with_layer: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """P_f of ``room_with_box`` (gradient-filtered grid points) and, with_layer, the background layer's
    points behind the box's silhouette: xyz [N, 3], rgb [N, 3]."""
    rgb, depth = room_with_box(H, W)
    keep = depth_gradient_mask(depth, 0.4)
    xyz, col = equirect_to_points(rgb, torch.where(keep, depth, torch.full_like(depth, float("nan"))))
    if with_layer:
        ld, lc = background_layer(rgb, depth, keep, 1.0)
        lxyz, lcol = equirect_to_points(lc, ld)
        xyz, col = torch.cat([xyz, lxyz]), torch.cat([col, lcol])
    return xyz, col


@pytest.mark.parametrize("with_layer", [True, False])
def test_box_in_front_of_wall_no_hole_half_a_metre_off(with_layer):
    """P_f (gradient filter, plus the layer) seen from 0.5 m right of the centre, looking past the box: no
    pixel whose wall the box hides from the centre is empty with the layer; without it they are."""
    H, W = 128, 256
    xyz, col = box_room_cloud(H, W, with_layer)
    size = 96
    K = intrinsics_from_fov(47.43, size, size, dtype=torch.float64)
    eye = torch.tensor([[0.5, 0.0, 0.0]], dtype=torch.float64)
    V = look_at(eye, eye + torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64))[0]
    o, d = pinhole_rays(K, V, size, size)  # [H, W, 3] each
    t, on_box = cast(o, d)
    X = o + t[..., None] * d  # what the camera sees
    r = torch.linalg.vector_norm(X, dim=-1)
    hidden = ~on_box & (cast(torch.zeros_like(X), X / r[..., None])[0] < r - 1e-6)  # the box hides it
    assert hidden.double().mean() > 0.03
    radius = footprint_radius(xyz, V, K, 2 * math.pi / W)
    _, hit, _ = project_points_zbuffer(xyz, col, K, V, size, size, radius)
    empty = (hit < 0.5) & hidden
    if with_layer:
        assert not empty.any()
    else:
        assert empty.double().sum() > 0.3 * hidden.double().sum()


@pytest.mark.parametrize("with_layer", [True, False])
def test_box_scene_after_a_tiny_optimisation(with_layer):
    """Gaussians from P_f (+ layer), sized by their pixel's footprint as the trainers do, 30 steps on
    the panorama's base views (holoflow's CPU rasterizer), rendered 0.5 m right of the centre: alpha >= 0.5 on every
    pixel the box hides from the centre with
    the layer; without it a good part of them stays empty (training from the centre cannot fill them)."""
    from holoflow.geometry.rigs import base_rig
    from holoflow.geometry.sampling import equirect_to_pinhole
    from holoflow.recon.optimize import init_model
    from holoflow.splat import TrainConfig, render, train

    H, W = 64, 128
    xyz, col = box_room_cloud(H, W, with_layer)
    model = init_model(
        xyz.numpy(),
        (col.numpy() * 255 + 0.5).astype("uint8"),
        0.99,
        footprint=(2 * math.pi / W, TransferOptParams().footprint_width, 0.1),
    )  # transfer_opt's init
    size = 32
    K = intrinsics_from_fov(90.0, size, size, dtype=torch.float32)
    V = base_rig(12, dtype=torch.float32)
    rgb, _ = room_with_box(H, W)
    images = equirect_to_pinhole(rgb.permute(2, 0, 1).float(), K.expand(12, 3, 3), V, size, size)  # [12, 3, s, s]
    views = [dict(image=im.permute(1, 2, 0).contiguous(), mask=None, viewmat=v, K=K) for im, v in zip(images, V)]
    train(
        model,
        views,
        TrainConfig(iterations=30, densify_every=10, densify_from=5, densify_until=20, backend="cpu"),
        seed=0,
    )
    size = 64
    K = intrinsics_from_fov(47.43, size, size, dtype=torch.float64)
    eye = torch.tensor([[0.5, 0.0, 0.0]], dtype=torch.float64)
    Vn = look_at(eye, eye + torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64))[0]
    o, d = pinhole_rays(K, Vn, size, size)
    t, on_box = cast(o, d)
    X = o + t[..., None] * d
    r = torch.linalg.vector_norm(X, dim=-1)
    hidden = ~on_box & (cast(torch.zeros_like(X), X / r[..., None])[0] < r - 1e-6)
    with torch.no_grad():
        alpha = render(model, Vn[None].float(), K[None].float(), size, size, backend="cpu")["alpha"][0, ..., 0]
    empty = (alpha < 0.5) & hidden
    if with_layer:
        assert not empty.any()
    else:
        assert empty.double().sum() > 0.3 * hidden.double().sum()


def _two_silhouettes(H=64, W=128):
    """A far wall at 3 m (columns < 40), a near slab at 1 m (40..47), a middle wall at 1.4 m (>= 48): both
    walls continue under the slab, and a step to the side shows the farthest of them behind it."""
    d = torch.full((H, W), 1.4, dtype=torch.float64)
    d[:, :40] = 3.0
    d[:, 40:48] = 1.0
    rgb = RED.expand(H, W, 3).clone()
    return rgb, d, depth_gradient_mask(d, 0.4, one_sided=True)


def test_the_farthest_surface_takes_the_layer_over_and_the_sky_never_does():
    """Where the layers of two silhouettes meet, the farther surface carries on under the nearer one's
    layer (a move uncovers what lies behind both: an evl_room_B door jamb left 20 % of a view empty
    0.5 m off the centre when the first layer to arrive kept its pixels); the sky's shell, with the
    sky dome behind everything, never takes a pixel over."""
    rgb, d, keep = _two_silhouettes()
    ld, _ = background_layer(rgb, d, keep, 1.0)
    row = ld[32, 40:48]
    assert torch.allclose(row, torch.full_like(row, 3.0))  # every pixel under the slab: the far wall
    for first in (background_layer(rgb, d, keep, 1.0, shell=3.0), background_layer(rgb, d, keep, 1.0, farthest=False)):
        row = first[0][32, 40:48]  # the far surface is the sky's shell, or no layer takes over
        assert bool((row < 2.0).any()) and bool((row > 2.0).any())  # each keeps what reached it first


def test_pf_keeps_each_silhouettes_own_layer_and_the_farthest_behind_it():
    """P_f's layer points: the first layer under the slab (each wall's own continuation) and, where the
    far wall reaches under the middle wall's layer, the far wall too: both depths behind the slab's
    columns that the middle wall's layer reached first."""
    from holoflow.geometry.clouds import point_clouds
    from holoflow.geometry.config import PointCloudParams

    rgb, d, _ = _two_silhouettes()
    cfg = PointCloudParams(pf_width=128, pf_sampling="grid", pf_polar_density=1.0, layer_stride=1, sky_dome=False)
    pf = point_clouds(rgb, d, cfg)
    layer = pf.clouds["pf"].xyz[-pf.pf["layer"]["points"] :]
    r = torch.linalg.vector_norm(layer, dim=-1)
    lon = torch.rad2deg(torch.atan2(layer[:, 0], layer[:, 2]))
    under = (lon > -180 + 44 * 360 / 128) & (lon < -180 + 48 * 360 / 128) & (layer[:, 1].abs() < 0.1)
    # columns 44..47, where the middle wall's layer arrives first: both walls lie behind the slab there
    assert bool(((r[under] - 3.0).abs() < 0.05).any()) and bool(((r[under] - 1.4).abs() < 0.05).any())
