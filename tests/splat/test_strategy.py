"""The densification strategy alone (holoflow/splat/strategy.py): its statistics, clone vs split, the
cap, pruning, opacity reset and the Adam moments that follow every row; no rasterizer, no trainer."""

import math

import numpy as np
import pytest
import torch

from holoflow.splat import GaussianModel, TrainConfig
from holoflow.splat.strategy import DefaultStrategy


def _setup(n=6, **cfg_over):
    g = torch.Generator().manual_seed(0)
    xyz = torch.randn(n, 3, generator=g).numpy() + np.array([0, 0, 4], np.float32)
    model = GaussianModel.from_points(xyz, np.full((n, 3), 0.5, np.float32), opacity=0.5)
    with torch.no_grad():  # Gaussians 0..2 small (clone), 3..5 large (split) for extent 1
        model.log_scales[:3] = math.log(0.001)
        model.log_scales[3:] = math.log(0.1)
    opt = torch.optim.Adam(
        [{"params": [getattr(model, k)], "lr": 1e-3, "name": k} for k in GaussianModel.PARAMS], eps=1e-15
    )
    for k in GaussianModel.PARAMS:  # non-zero moments, to see them follow the rows
        p = getattr(model, k)
        opt.state[p] = {"step": torch.tensor(1.0), "exp_avg": torch.ones_like(p), "exp_avg_sq": torch.ones_like(p)}
    cfg = TrainConfig(densify_every=10, densify_from=0, densify_until=100, size_prune_from=10_000, **cfg_over)
    strat = DefaultStrategy(cfg, 1.0, torch.zeros(3), torch.Generator().manual_seed(1))
    strat.initialize_state(n, "cpu")
    return model, opt, strat


def _grads(strat, model, hot, it=1, size=100):
    """One step's statistics: Gaussians in ``hot`` with a large view-space gradient, all visible."""
    n = len(model)
    means2d = torch.zeros(1, n, 2, requires_grad=True)
    means2d.grad = torch.zeros(1, n, 2)
    means2d.grad[0, hot, 0] = 1e-2
    strat.step_pre_optimizer(it, means2d, torch.full((1, n), 3.0), size, size)


def test_statistics_accumulate_over_visible_gaussians_only():
    model, _, strat = _setup()
    n = len(model)
    means2d = torch.zeros(1, n, 2, requires_grad=True)
    means2d.grad = torch.ones(1, n, 2) * 1e-3
    radii = torch.tensor([[0.0, 2, 2, 2, 5, 0]])
    for it in (1, 2):
        strat.step_pre_optimizer(it, means2d, radii, 200, 100)
    expected = 2 * math.hypot(1e-3 * 100, 1e-3 * 50)  # NDC units, two views
    assert torch.allclose(strat.state["grad"], torch.tensor([0, 1, 1, 1, 1, 0]) * expected)
    assert strat.state["count"].tolist() == [0, 2, 2, 2, 2, 0]
    assert strat.state["radii"].tolist() == [0, 2, 2, 2, 5, 0]
    strat.step_pre_optimizer(100, means2d, radii, 200, 100)  # past densify_until: ignored
    assert strat.state["count"].tolist() == [0, 2, 2, 2, 2, 0]


def test_packed_statistics_equal_dense_ones():
    # the fast path's meta has one row per drawn Gaussian (gaussian_ids); gsplat's and the reference's
    # one per Gaussian with radius 0 where not drawn: the same statistics either way
    g = torch.Generator().manual_seed(3)
    n, rows = 7, torch.tensor([1, 2, 4, 6])
    grad = torch.randn(1, n, 2, generator=g) * 1e-3
    radii = torch.zeros(1, n)
    radii[0, rows] = torch.tensor([2.0, 5.0, 1.0, 3.0])
    states = []
    for packed in (False, True):
        _, _, strat = _setup(n)
        for it in (1, 2):
            if packed:
                m2 = torch.zeros(len(rows), 2, requires_grad=True)
                m2.grad = grad[0, rows] * it
                strat.step_pre_optimizer(it, m2, radii[0, rows].int(), 200, 100, rows)
            else:
                m2 = torch.zeros(1, n, 2, requires_grad=True)
                m2.grad = grad * it
                strat.step_pre_optimizer(it, m2, radii, 200, 100)
        states.append(strat.state)
    for k in ("grad", "count", "radii"):
        assert torch.equal(states[0][k], states[1][k]), k
    assert states[1]["count"].tolist() == [0, 2, 2, 0, 2, 0, 2]


def test_clone_small_split_large_then_state_restarts():
    model, opt, strat = _setup()
    _grads(strat, model, [0, 3])
    assert strat.step_post_optimizer(model, opt, 5) is None  # not a densify step
    event = strat.step_post_optimizer(model, opt, 10)
    assert (event["cloned"], event["split"], event["pruned"], event["count"]) == (1, 1, 0, 6 + 1 + 1)
    assert len(model) == 8 and strat.state["grad"].shape == (8,) and float(strat.state["grad"].sum()) == 0
    kept = 5  # 6 - the split one
    m = opt.state[model.means]["exp_avg"]
    assert m.shape == (8, 3) and bool((m[:kept] == 1).all()) and bool((m[kept:] == 0).all())
    assert all(g["params"][0] is getattr(model, g["name"]) for g in opt.param_groups)
    split_scales = torch.exp(model.log_scales[-2:].detach())
    assert torch.allclose(split_scales, torch.full_like(split_scales, 0.1 / 1.6))


def test_max_gaussians_caps_to_the_highest_gradients_and_says_so():
    model, opt, strat = _setup(max_gaussians=7)
    _grads(strat, model, [0, 1, 2])
    with pytest.warns(UserWarning, match="max_gaussians=7 reached; densified 1 of 3"):
        event = strat.step_post_optimizer(model, opt, 10)
    assert event["cloned"] == 1 and len(model) == 7 and "max_gaussians" in event["note"]


def test_prune_transparent_and_opacity_reset():
    model, opt, strat = _setup(opacity_reset_every=20)
    with torch.no_grad():
        model.opacity_logits[2] = -10.0
    event = strat.step_post_optimizer(model, opt, 10)
    assert event["pruned"] == 1 and len(model) == 5
    strat.step_post_optimizer(model, opt, 20)
    assert float(torch.sigmoid(model.opacity_logits.detach()).max()) <= 0.01 + 1e-6
    assert float(opt.state[model.opacity_logits]["exp_avg"].abs().sum()) == 0
