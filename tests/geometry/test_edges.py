"""Ramp-drawn occlusion edges made steps (holoflow/geometry/edges.py): a ramp between a near and a far
surface, smooth surfaces left alone, and the box before a wall (tests/geometry/test_layers.py)
with its depth blurred as an estimator draws it, seen off centre."""

import math

import pytest
import torch
import torch.nn.functional as F

from holoflow.geometry.camera import intrinsics_from_fov, look_at
from holoflow.geometry.edges import snap_depth_edges
from holoflow.geometry.layers import background_layer
from holoflow.geometry.pointcloud import depth_gradient_mask, equirect_to_points
from holoflow.recon.config import TransferOptParams

from .test_layers import room_with_box  # the analytic box room


def test_a_ramp_becomes_a_step_and_its_layer_lies_on_the_far_side():
    # evl_room_B's door frame, one row: wall 1.0 m, a 4 px ramp, wall 1.6 m
    row = torch.tensor([1.0] * 12 + [1.01, 1.04, 1.15, 1.35, 1.35, 1.5] + [1.57] * 14, dtype=torch.float64)
    d = row.expand(16, -1).clone()
    s = snap_depth_edges(d, radius=2, ratio=0.25, tol=0.1, rounds=2)
    near, far = (s <= 1.04 * 1.1), (s >= 1.5 / 1.1)
    assert (near | far).all()  # no pixel left in between
    assert near[:, :15].all() and far[:, 15:].all()  # each went to the side it is nearer
    assert torch.equal(s[:, :14], d[:, :14]) and torch.equal(s[:, 18:], d[:, 18:])  # the plateaus keep theirs
    rgb = torch.rand(16, 32, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    for depth, ok in ((s, True), (d, False)):
        ld, _ = background_layer(rgb, depth, depth_gradient_mask(depth, 0.4), 1.0)
        under = ld[8, :15][torch.isfinite(ld[8, :15])]  # the layer under the near side
        assert len(under) > 0
        assert bool((under >= 1.5).all()) == ok  # the ramp's 1.15 / 1.35 m without


def chimney_recess_sky(band: int, recess: float = 2.47) -> torch.Tensor:
    """grey_white_room, one row 16 times: a chimney breast's edge at 2.0 m, beside it the side of a
    window's recess at ``recess`` m seen for ``band`` pixels, then the sky on its shell at 7.5 m (P_f
    at 1536 px)."""
    row = [2.0] * 12 + [recess + 0.002 * i for i in range(band)] + [7.5] * 12
    return torch.tensor(row, dtype=torch.float64).expand(16, -1).clone()


@pytest.mark.parametrize("band", [3, 6])
def test_a_surface_between_a_near_edge_and_the_sky_stays(band):
    d = chimney_recess_sky(band)
    assert torch.equal(snap_depth_edges(d), d)  # the recess keeps its depth: no pixel of it moves


def test_a_ramp_beside_a_surface_between_an_edge_and_the_sky_still_snaps():
    d = chimney_recess_sky(3, recess=2.6)  # a recess deep enough that the wall's edge is an edge to it
    d[:, 10:12] = torch.tensor([2.25, 2.3], dtype=torch.float64)  # the wall's edge drawn as a ramp
    s = snap_depth_edges(d)
    assert torch.equal(s[:, 12:], d[:, 12:])  # the recess stays
    assert (s[:, 10] == 2.0).all() and (s[:, 11] >= 2.6).all()  # each ramp pixel went to the end nearer it


def test_smooth_surfaces_are_left_alone():
    # walls seen obliquely all round (inverse depth smooth in the column, the seam included) and a
    # floor seen at 80 deg incidence (relative gradient tan 80 deg x the pixel angle)
    H, W = 32, 128
    cols = torch.arange(W, dtype=torch.float64)
    d = (1.0 / (0.5 + 0.15 * torch.sin(2 * math.pi * cols / W))).expand(H, W).clone()  # 1.5 .. 2.9 m, <= 2.3 % a pixel
    assert torch.equal(snap_depth_edges(d), d)
    rows = torch.arange(H, dtype=torch.float64)[:, None]
    g = math.tan(math.radians(80)) * 2 * math.pi / 1536  # a surface at 80 deg incidence in a 1536 px P_f
    d2 = torch.exp(g * rows).expand(H, W).clone()
    assert torch.equal(snap_depth_edges(d2), d2)
    assert torch.equal(snap_depth_edges(d, radius=0), d)


def ramped_box_cloud(H: int, W: int, ramp: int, snap: bool, slope: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """P_f + layer of ``room_with_box`` with its inverse depth box-filtered ramp x ramp (columns
    wrapping): every silhouette a ramp, as a depth estimator draws it; ``snap``: the ramps made steps
    first (the point_cloud stage); ``slope``: the layer extrapolates the far side's slope."""
    rgb, depth = room_with_box(H, W)
    r = ramp // 2
    x = torch.cat([1 / depth[:, -r:], 1 / depth, 1 / depth[:, :r]], 1)[None, None]
    depth = 1 / F.avg_pool2d(F.pad(x, (0, 0, r, r), mode="replicate"), ramp, 1)[0, 0]
    if snap:
        depth = snap_depth_edges(depth)
    keep = depth_gradient_mask(depth, 0.4)
    xyz, col = equirect_to_points(rgb, torch.where(keep, depth, torch.full_like(depth, float("nan"))))
    ld, lc = background_layer(rgb, depth, keep, 1.0, slope=slope)
    lxyz, lcol = equirect_to_points(lc, ld)
    return torch.cat([xyz, lxyz]), torch.cat([col, lcol])


@pytest.mark.parametrize(
    "ramp, eye_m, snap, slope",
    [(3, 1.0, True, False), (3, 1.0, False, False), (7, 0.5, True, False), (7, 0.5, True, True)],
)
def test_box_with_ramped_depth_off_centre(ramp, eye_m, snap, slope):
    """The footprint Gaussians of P_f + layer (transfer_opt's init) rendered ``eye_m`` right of the
    centre (the layer's baseline is 1 m), looking past the box: no pixel empty with the stage's
    defaults (ramps snapped, no slope), and none either where kept ramps start the layer at their
    intermediate depths or a slope across a wide ramp throws it off the wall: the farthest layer takes
    over under them (holoflow/geometry/layers.py)."""
    from holoflow.recon.optimize import init_model
    from holoflow.splat import render

    H, W = 128, 256
    xyz, col = ramped_box_cloud(H, W, ramp, snap, slope)
    model = init_model(
        xyz.numpy(),
        (col.numpy() * 255 + 0.5).astype("uint8"),
        0.99,
        footprint=(2 * math.pi / W, TransferOptParams().footprint_width, 0.1),
    )
    size = 96
    K = intrinsics_from_fov(47.43, size, size, dtype=torch.float32)
    eye = torch.tensor([[eye_m, 0.0, 0.0]])
    V = look_at(eye, eye + torch.tensor([[0.0, 0.0, 1.0]]))
    with torch.no_grad():
        alpha = render(model, V, K[None], size, size, backend="cpu")["alpha"][0, ..., 0]
    assert int((alpha < 0.5).sum()) == 0
