"""Dense PyTorch reference compositing: every Gaussian evaluated at every pixel, differentiable by
autograd. Small and obviously right; memory is O(C * H * W * N), so only for small scenes.

Same rules as the fast path: depth order (stable), alpha = min(0.99, o exp(-sigma)), pairs with
alpha < 1/255 (or sigma < 0) skipped, compositing stops before transmittance drops below 1e-4.
"""

from __future__ import annotations

import torch

from holoflow.splat.project import ALPHA_MAX, ALPHA_MIN, T_MIN


def composite_dense(
    means2d: torch.Tensor,
    conics: torch.Tensor,
    opacities: torch.Tensor,
    feats: torch.Tensor,
    depths: torch.Tensor,
    visible: torch.Tensor,
    width: int,
    height: int,
) -> torch.Tensor:
    """Alpha-composite front to back.

    means2d [C, N, 2] px; conics [C, N, 3]; opacities [C, N]; feats [C, N, F] (any channels);
    depths [C, N] sort key; visible [C, N] bool. Returns [C, H, W, F] = sum_i w_i feats_i with
    w_i = alpha_i T_i (so a constant-1 channel gives the accumulated alpha)."""
    C, N, F = feats.shape
    ys, xs = torch.meshgrid(
        torch.arange(height, dtype=feats.dtype, device=feats.device) + 0.5,
        torch.arange(width, dtype=feats.dtype, device=feats.device) + 0.5,
        indexing="ij",
    )
    xs, ys = xs.reshape(-1, 1), ys.reshape(-1, 1)  # [P, 1]
    outs = []
    for c in range(C):
        key = torch.where(visible[c], depths[c], torch.full_like(depths[c], float("inf")))
        order = torch.argsort(key, stable=True)
        order = order[visible[c][order]]  # [n] front to back
        m, q, o, f = means2d[c, order], conics[c, order], opacities[c, order], feats[c, order]
        dx, dy = xs - m[:, 0], ys - m[:, 1]  # [P, n]
        sigma = 0.5 * (q[:, 0] * dx * dx + q[:, 2] * dy * dy) + q[:, 1] * dx * dy
        alpha = torch.clamp(o * torch.exp(-sigma.clamp_min(0)), max=ALPHA_MAX)
        alpha = torch.where((sigma >= 0) & (alpha >= ALPHA_MIN), alpha, torch.zeros_like(alpha))
        t_next = torch.cumprod(1 - alpha, dim=1)  # [P, n]
        t = torch.cat([torch.ones_like(t_next[:, :1]), t_next[:, :-1]], 1)
        w = torch.where(t_next >= T_MIN, alpha * t, torch.zeros_like(alpha))
        outs.append((w @ f).reshape(height, width, F))
    return torch.stack(outs, 0) if outs else feats.new_zeros(0, height, width, F)
