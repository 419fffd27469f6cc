"""Adaptive density control as a strategy object (as gsplat's ``DefaultStrategy``): it owns its
statistics and decides when to clone, split, prune and reset opacity, apart from the model (the
Gaussians' tensors) and the rasterizer (which only reports ``means2d`` and ``radii``).

Per training step the trainer calls ``step_pre_optimizer`` after ``loss.backward()`` (gradient
statistics) and ``step_post_optimizer`` after ``opt.step()`` (densify / prune / reset). The rules are
the original 3DGS ones (``TrainConfig`` documents each threshold); the optimiser's Adam moments follow
every row that is kept, copied or removed.
"""

from __future__ import annotations

import math
import warnings

import torch

from holoflow.splat.model import GaussianModel
from holoflow.splat.project import quat_to_rotmat


class DefaultStrategy:
    """Clone / split / prune for one training run. ``cfg``: a ``TrainConfig`` (densify_*, percent_dense,
    prune_*, size_prune_from, max_gaussians, opacity_reset_every); ``extent`` the scene extent (m);
    ``centroid`` [3] the camera centroid (world); ``generator`` draws the split samples.

    ``state``: ``grad`` [N] summed view-space gradient norm (NDC units), ``count`` [N] views that saw
    each Gaussian, ``radii`` [N] largest screen radius (px), since the last densification."""

    def __init__(self, cfg, extent: float, centroid: torch.Tensor, generator: torch.Generator):
        self.cfg, self.extent, self.centroid, self.generator = cfg, extent, centroid, generator
        self.state: dict[str, torch.Tensor] = {}

    def initialize_state(self, n: int, device) -> None:
        """Zero statistics for ``n`` Gaussians."""
        self.state = {k: torch.zeros(n, device=device) for k in ("grad", "count", "radii")}

    @torch.no_grad()
    def step_pre_optimizer(
        self,
        it: int,
        means2d: torch.Tensor,
        radii: torch.Tensor,
        width: int,
        height: int,
        gaussian_ids: torch.Tensor | None = None,
    ) -> None:
        """Accumulate step ``it``'s statistics of one camera's ``width`` x ``height`` render:
        ``means2d`` [1, N, 2] (px, with ``.grad``) and ``radii`` [1, N] (px; 0 = not visible), or packed
        as the fast path's meta is: ``gaussian_ids`` [P] the Gaussian of each row of means2d [P, 2] and
        radii [P] (all visible)."""
        if it >= self.cfg.densify_until or means2d.grad is None:
            return
        st = self.state
        scale = means2d.new_tensor([width / 2, height / 2])
        if gaussian_ids is not None:
            g = (means2d.grad * scale).norm(dim=-1)  # [P] NDC units
            st["grad"].index_add_(0, gaussian_ids, g)
            st["count"].index_add_(0, gaussian_ids, torch.ones_like(g))
            st["radii"].scatter_reduce_(0, gaussian_ids, radii.float(), "amax")
            return
        r = radii[0].float()  # [N]
        vis = r > 0  # masks, not indices: no sync
        g = (means2d.grad[0] * scale).norm(dim=-1)  # [N] NDC units
        st["grad"] += torch.where(vis, g, 0.0)
        st["count"] += vis
        st["radii"] = torch.where(vis, torch.maximum(st["radii"], r), st["radii"])

    @torch.no_grad()
    def step_post_optimizer(self, model: GaussianModel, opt: torch.optim.Adam, it: int) -> dict | None:
        """After step ``it``'s optimiser step: densify and prune when due (returns the event: counts and
        a note when ``max_gaussians`` capped it; None otherwise), reset opacity when due."""
        cfg = self.cfg
        event = None
        if cfg.densify_from < it < cfg.densify_until and it % cfg.densify_every == 0:
            event = self._densify_and_prune(model, opt, it)
            self.initialize_state(len(model), model.means.device)
        if cfg.opacity_reset_every and it % cfg.opacity_reset_every == 0 and it < cfg.densify_until:
            reset_opacity(model, opt)
        return event

    def _densify_and_prune(self, model: GaussianModel, opt: torch.optim.Adam, it: int) -> dict:
        """Clone small / split large Gaussians with a high mean view-space gradient, then prune."""
        cfg, extent, stats = self.cfg, self.extent, self.state
        grads = torch.nan_to_num(stats["grad"] / stats["count"])  # [N]
        scales = torch.exp(model.log_scales.detach())  # [N, 3]
        big = scales.max(-1).values > cfg.percent_dense * extent
        hot = grads >= cfg.densify_grad_threshold
        clone, split = hot & ~big, hot & big
        note = None
        room = cfg.max_gaussians - len(model)
        n_want = int(clone.sum() + split.sum())  # +1 each
        if n_want > max(room, 0):
            cand = torch.nonzero(hot).squeeze(1)
            keep_n = max(room, 0)
            top = cand[torch.argsort(grads[cand], descending=True, stable=True)[:keep_n]]
            chosen = torch.zeros_like(hot)
            chosen[top] = True
            clone, split = clone & chosen, split & chosen
            note = (
                f"step {it}: max_gaussians={cfg.max_gaussians} reached; densified {keep_n} of "
                f"{n_want} candidates (highest gradients first)"
            )
            warnings.warn(note, stacklevel=4)
        p = {name: getattr(model, name).detach() for name in GaussianModel.PARAMS}
        extra = {k: v[clone] for k, v in p.items()}
        # Split: two samples from each Gaussian, scales / 1.6 (3DGS).
        idx = torch.nonzero(split).squeeze(1).repeat(2)
        std = scales[idx]  # [2S, 3]
        offs = torch.randn(std.shape, generator=self.generator).to(std) * std
        rot = quat_to_rotmat(p["quats"][idx])  # [2S, 3, 3]
        sp = {k: v[idx] for k, v in p.items()}
        sp["means"] = p["means"][idx] + torch.einsum("sij,sj->si", rot, offs)
        sp["log_scales"] = torch.log(std / (0.8 * 2))
        extra = {k: torch.cat([extra[k], sp[k]]) for k in p}
        replace_rows(model, opt, ~split, extra)
        n_after = len(model)
        # Prune.
        opac = torch.sigmoid(model.opacity_logits.detach())
        prune = opac < cfg.prune_opacity
        if it > cfg.size_prune_from:
            radii = torch.cat([stats["radii"][~split], stats["radii"].new_zeros(n_after - int((~split).sum()))])
            prune |= radii > cfg.prune_screen_size
            reach = torch.linalg.vector_norm(model.means.detach() - self.centroid, dim=-1).clamp(min=extent)  # [N]
            prune |= torch.exp(model.log_scales.detach()).max(-1).values > 0.1 * reach
        replace_rows(model, opt, ~prune, {k: p[k][:0] for k in p})
        return dict(
            step=it,
            cloned=int(clone.sum()),
            split=int(split.sum()),
            pruned=int(prune.sum()),
            count=len(model),
            note=note,
        )


def replace_rows(
    model: GaussianModel, opt: torch.optim.Adam, keep: torch.Tensor, extra: dict[str, torch.Tensor]
) -> None:
    """Keep rows ``keep`` [N] bool of every parameter and append ``extra`` rows; Adam moments follow
    (zeros for the new rows)."""
    for group in opt.param_groups:
        name = group["name"]
        old = group["params"][0]
        new = torch.cat([old.detach()[keep], extra[name].to(old)]).requires_grad_(True)
        state = opt.state.pop(old, None)
        if state:
            for key in ("exp_avg", "exp_avg_sq"):
                state[key] = torch.cat([state[key][keep], torch.zeros_like(extra[name])])
            opt.state[new] = state
        group["params"][0] = new
        setattr(model, name, new)


def reset_opacity(model: GaussianModel, opt: torch.optim.Adam) -> None:
    """Opacity <= 0.01 for every Gaussian; its Adam moments restart."""
    logit = model.opacity_logits.detach()
    capped = torch.minimum(logit, torch.full_like(logit, math.log(0.01 / 0.99)))
    group = next(g for g in opt.param_groups if g["name"] == "opacity_logits")
    old = group["params"][0]
    new = capped.clone().requires_grad_(True)
    state = opt.state.pop(old, None)
    if state:
        state["exp_avg"] = torch.zeros_like(new)
        state["exp_avg_sq"] = torch.zeros_like(new)
        opt.state[new] = state
    group["params"][0] = new
    model.opacity_logits = new
