"""Depth supervision (holoflow/recon/views.add_depth_targets, holoflow/splat/train depth_loss): the
PANO set's views get the panorama's metric depth as camera z, edges and sky left unsupervised, and a
trainer with ``lambda_depth`` pulls Gaussians set off their surface back onto it, which colour alone
cannot see from the centre."""

import math

import numpy as np
import torch

from holoflow.geometry.camera import intrinsics_from_fov, look_at
from holoflow.geometry.sphere import equirect_directions
from holoflow.recon.views import add_depth_targets
from holoflow.splat import GaussianModel, TrainConfig, render, train
from holoflow.splat.train import depth_loss

HALF = torch.tensor([2.0, 1.5, 2.5], dtype=torch.float64)


def box_room(H: int = 128, W: int = 256) -> np.ndarray:
    """Radial depth [H, W] of an axis-aligned box room (half sizes HALF) seen from its centre."""
    dirs = equirect_directions(H, W, dtype=torch.float64)
    return (HALF / dirs.abs().clamp_min(1e-12)).amin(-1).numpy()


def view(eye=(0.0, 0.0, 0.0), target=(0.0, 0.0, 1.0), size: int = 32) -> dict:
    vm = look_at(torch.tensor(eye, dtype=torch.float32), torch.tensor(target, dtype=torch.float32))
    K = intrinsics_from_fov(60.0, size, size)
    return dict(image=torch.zeros(size, size, 3), mask=None, viewmat=vm, K=K)


def test_views_at_the_centre_get_camera_z_and_no_edges():
    views = [view(), view(target=(1.0, 0.0, 0.0)), view(eye=(0.3, 0.0, 0.0))]
    assert add_depth_targets(views, box_room()) == 2
    assert "depth" not in views[2]  # away from the centre: the panorama's depth does not hold there
    z = views[0]["depth"]
    assert torch.allclose(z[torch.isfinite(z)], torch.full_like(z[torch.isfinite(z)], 2.5), rtol=0.02)
    assert torch.isfinite(z).float().mean() > 0.9
    side = views[1]["depth"]  # looks at the wall x = 2 across the room's corner lines
    assert torch.allclose(side[torch.isfinite(side)].min(), torch.tensor(2.0), rtol=0.02)


def test_sky_and_depth_steps_are_not_supervised():
    r = box_room()
    r[:, :8] = np.inf  # a strip of sky behind the camera's back (columns at -180 deg)
    r[60:70, 120:136] = 1.0  # a near box straight ahead
    views = [view(size=48)]
    add_depth_targets(views, r)
    z = views[0]["depth"]
    near = torch.isfinite(z) & (z < 1.5)
    assert int(near.sum()) > 4
    nan = ~torch.isfinite(z)
    assert int(nan.sum()) > 0  # the box's outline
    ring = torch.nn.functional.max_pool2d(near.float()[None, None], 3, 1, 1)[0, 0].bool() & ~near
    assert bool(nan[ring].all())  # every pixel next to the box is left out


def test_depth_loss_is_relative_and_ignores_what_is_unsupervised():
    depth, alpha = torch.tensor([[2.2, 4.0], [1.0, 3.0]]), torch.tensor([[1.0, 1.0], [0.2, 1.0]])
    target = torch.tensor([[2.0, float("nan")], [1.0, 3.0]])
    assert math.isclose(float(depth_loss(depth, alpha, target)), (0.1 + 0.0) / 2, rel_tol=1e-6)
    none = depth_loss(depth, alpha, torch.full((2, 2), float("nan")))
    assert float(none) == 0.0


def test_training_with_depth_pulls_gaussians_back_to_the_surface():
    # a grey wall 2 m ahead, its Gaussians set 10 % too far: the centre view's colours are right already
    g = torch.Generator().manual_seed(0)
    n = 400
    xy = (torch.rand(n, 2, generator=g) - 0.5) * 2.6
    xyz = torch.cat([xy, torch.full((n, 1), 2.2)], 1).numpy()
    K = intrinsics_from_fov(60.0, 32, 32)
    vm = look_at(torch.zeros(3), torch.tensor([0.0, 0.0, 1.0]))
    r = np.full((64, 128), np.inf)  # the target: a plane z = 2 seen from the centre
    dirs = equirect_directions(64, 128, dtype=torch.float64).numpy()
    r = np.where(dirs[..., 2] > 0.1, 2.0 / np.maximum(dirs[..., 2], 1e-6), np.inf)
    means = []
    for lam in (0.0, 1.0):
        model = GaussianModel.from_points(xyz, np.full((n, 3), 0.5, np.float32))
        with torch.no_grad():
            target_img = render(model, vm[None], K[None], 32, 32, backend="cpu")["rgb"][0]
        views = [dict(image=target_img, mask=None, viewmat=vm, K=K)]
        add_depth_targets(views, r)
        cfg = TrainConfig(
            iterations=40, lambda_depth=lam, lr_means_final=1.6e-4, densify_from=10_000, backend="cpu", scene_extent=2.0
        )  # the position lr held at its start (3DGS decays it 100x): 40 Adam steps of ~3 mm
        train(model, views, cfg, seed=0)
        means.append(float(model.means[:, 2].detach().mean()))
    assert abs(means[0] - 2.2) < 0.002  # colour alone: nothing moves
    assert means[1] < 2.2 - 0.005  # the depth loss moves the wall towards z = 2
