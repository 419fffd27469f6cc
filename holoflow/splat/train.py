"""3DGS optimisation: Adam with the original learning rates, 0.8 L1 + 0.2 (1 - SSIM) on supervised
pixels; adaptive density control (clone / split / prune, optional opacity reset) by the strategy
object of holoflow/splat/strategy.py."""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import torch
import torch.optim  # named for the warm templates: its optimisers load torch._dynamo on first use (executors/warm.py)

from holoflow.splat.model import GaussianModel
from holoflow.splat.rasterize import render
from holoflow.splat.strategy import DefaultStrategy


@dataclass
class TrainConfig:
    """Training settings; defaults are the original 3DGS ones unless a comment says otherwise."""

    iterations: int = 3000
    """Optimisation steps; one view per step, views in seeded random order (reshuffled per epoch)."""
    lr_means: float = 1.6e-4
    """Initial position lr, multiplied by the scene extent."""
    lr_means_final: float = 1.6e-6
    """Final position lr (times extent), reached by log-linear decay at ``lr_means_steps``."""
    lr_means_steps: int | None = None
    """Steps of the position-lr decay (None: ``iterations``)."""
    step_offset: int = 0
    """Steps of this model's optimisation done before this call: the position-lr decay and the SH band
    schedule continue from there (a later phase of the same model, as 3DGS's one schedule)."""
    lr_features: float = 2.5e-3
    """SH DC lr; higher bands use a twentieth of it."""
    lr_opacity: float = 5e-2
    lr_scaling: float = 5e-3
    lr_rotation: float = 1e-3
    lambda_dssim: float = 0.2
    """Loss = (1 - lambda) L1 + lambda (1 - SSIM), SSIM with an 11 px Gaussian window (metrics.ssim_map)."""
    lambda_depth: float = 0.0
    """Plus lambda x the mean relative error |z - target| / target of the rendered depth (alpha-normalised
    camera z) on the pixels of a view's ``depth`` target that are finite and rendered (alpha > 0.5); 0 =
    colour only (3DGS). Keeps the Gaussians on the surfaces the depth put them on while the colour loss
    fits the views: moving them off the surface changes nothing the base cameras see, and everything a
    step away does."""
    densify_every: int = 100
    densify_from: int = 500
    """Densify at steps it > densify_from with it % densify_every == 0 ..."""
    densify_until: int = 15000
    """... and it < densify_until (view-space gradients are accumulated until then)."""
    densify_grad_threshold: float = 2e-4
    """Mean view-space positional gradient norm (NDC units: pixel gradient times W/2, H/2)."""
    percent_dense: float = 0.01
    """Clone Gaussians whose largest scale is <= percent_dense * extent, split the larger ones."""
    prune_opacity: float = 0.005
    prune_screen_size: float = 20.0
    """Once it > size_prune_from, also prune radii above this (px) and scales above 0.1 x
    max(extent, the Gaussian's distance from the camera centroid): 3DGS's 0.1 x extent for everything
    within the extent, an angular limit beyond it, so a far sky shell is not pruned for being far."""
    size_prune_from: int = 3000
    opacity_reset_every: int = 0
    """Reset opacities to <= 0.01 every this many steps while densifying; 0 = off (paper: off)."""
    max_gaussians: int = 2_000_000
    """Cap on the count: densification keeps the highest-gradient candidates that fit, and says so."""
    sh_degree_every: int = 1000
    """Activate one more SH band every this many steps, up to the model's degree."""
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    random_background: bool = False
    """Composite every step over a new uniform random colour instead of ``background``: over black, a
    see-through pixel with brighter Gaussians fits an opaque target as well as an opaque one does;
    over a random colour only the opaque one fits."""
    backend: str = "auto"
    torch_threads: int | None = 1
    """torch intra-op threads while training (restored after); None leaves them. The numba kernels
    have their own pool; with small tensors torch's OpenMP barriers only cost time (5x measured on a
    loaded 2-core machine)."""
    scene_extent: float | None = None
    """Scene size (m) for lr scaling and size thresholds. None: max(1.1 x camera-centre radius,
    median distance of the initial Gaussians from the camera centroid); the second term keeps it
    meaningful for panorama rigs, whose cameras all sit near one point."""


def camera_centres(viewmats: torch.Tensor) -> torch.Tensor:
    """Camera centres [V, 3] (world) of world-to-camera viewmats [V, 4, 4]."""
    return -torch.einsum("vji,vj->vi", viewmats[:, :3, :3], viewmats[:, :3, 3])


def scene_extent(model: GaussianModel, viewmats: torch.Tensor) -> float:
    """Default extent (see ``TrainConfig.scene_extent``). viewmats [V, 4, 4] world-to-camera."""
    centres = camera_centres(viewmats)  # [V, 3]
    mid = centres.mean(0)
    cam = 1.1 * float((centres - mid).norm(dim=-1).max()) if len(centres) else 0.0
    pts = float((model.means.detach() - mid).norm(dim=-1).median()) if len(model) else 0.0
    return max(cam, pts, 1e-6)


def masked_loss(
    rgb: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None, lambda_dssim: float = 0.2
) -> torch.Tensor:
    """(1 - l) L1 + l (1 - SSIM) over supervised pixels. rgb, target [H, W, 3]; mask [H, W] (1 =
    supervise) or None. Unsupervised target pixels are replaced by the (detached) render, so SSIM
    windows that straddle a hole compare nothing invented."""
    from holoflow.quality.metrics import ssim_map

    m = torch.ones_like(rgb[..., :1]) if mask is None else mask.to(rgb).reshape(*rgb.shape[:2], 1)
    target = m * target + (1 - m) * rgb.detach()
    denom = (m.sum() * rgb.shape[-1]).clamp_min(1.0)
    l1 = ((rgb - target).abs() * m).sum() / denom
    if lambda_dssim == 0:
        return l1
    ssim = ssim_map(rgb.permute(2, 0, 1)[None], target.permute(2, 0, 1)[None], 11)
    ssim = (ssim[0].permute(1, 2, 0) * m).sum() / denom
    return (1 - lambda_dssim) * l1 + lambda_dssim * (1 - ssim)


def train(
    model: GaussianModel, views: list[dict], cfg: TrainConfig | None = None, progress=None, seed: int = 0
) -> dict:
    """Optimise ``model`` in place on ``views`` (dicts: image [H, W, 3] float linear, mask [H, W] or
    None, viewmat [4, 4] world-to-camera, K [3, 3]). ``progress(done, total, "iters")`` is called every
    step (holoflow.stage.Progress). Returns a JSON-able log: per-step loss, Gaussian count after each densification,
    timings, notes."""
    cfg = cfg or TrainConfig()
    if not views:
        raise ValueError("train: no views")
    threads = torch.get_num_threads()
    if cfg.torch_threads:
        torch.set_num_threads(cfg.torch_threads)
    try:
        return _train(model, views, cfg, progress, seed)
    finally:
        torch.set_num_threads(threads)


def _train(model: GaussianModel, views: list[dict], cfg: TrainConfig, progress, seed: int) -> dict:
    gen = torch.Generator().manual_seed(seed)  # CPU generator: same draws on any device
    dev = model.means.device
    viewmats = torch.stack([torch.as_tensor(v["viewmat"], dtype=torch.float32) for v in views]).to(dev)
    extent = cfg.scene_extent or scene_extent(model, viewmats)
    centroid = camera_centres(viewmats).mean(0)  # [3]
    opt = _make_optimizer(model, cfg, extent)
    lr_steps = cfg.lr_means_steps or cfg.iterations
    n = len(model)
    strategy = DefaultStrategy(cfg, extent, centroid, gen)
    strategy.initialize_state(n, dev)
    bg = torch.tensor(cfg.background, dtype=torch.float32, device=dev)
    log = dict(config=asdict(cfg), seed=seed, extent=extent, initial_count=n, count=[], densify=[], notes=[])
    order: list[int] = []
    losses: list[torch.Tensor] = []  # read back once at the end: no sync per step
    on_dev = _views_on(views, dev)  # images, masks, Ks moved once
    t0 = time.perf_counter()
    for it in range(1, cfg.iterations + 1):
        frac = min((cfg.step_offset + it) / max(lr_steps, 1), 1.0)
        opt.param_groups[0]["lr"] = extent * math.exp(
            (1 - frac) * math.log(cfg.lr_means) + frac * math.log(cfg.lr_means_final)
        )
        if not order:
            order = torch.randperm(len(views), generator=gen).tolist()
        order_i = order.pop()
        v = on_dev[order_i]
        image = v["image"]
        H, W = image.shape[:2]
        sh_degree = min(model.sh_degree, (cfg.step_offset + it - 1) // max(cfg.sh_degree_every, 1))
        target = v.get("depth") if cfg.lambda_depth > 0 else None
        step_bg = torch.rand(3, generator=gen).to(dev) if cfg.random_background else bg
        out = render(
            model,
            viewmats[order_i][None],
            v["K"][None],
            W,
            H,
            backend=cfg.backend,
            background=step_bg,
            sh_degree=sh_degree,
            depth=target is not None,
        )
        means2d = out["meta"]["means2d"]
        if means2d.requires_grad:
            means2d.retain_grad()
        mask = v.get("mask")
        loss = masked_loss(out["rgb"][0], image, mask, cfg.lambda_dssim)
        if target is not None:
            loss = loss + cfg.lambda_depth * depth_loss(out["depth"][0, ..., 0], out["alpha"][0, ..., 0], target)
        loss.backward()
        losses.append(loss.detach())
        strategy.step_pre_optimizer(it, means2d, out["meta"]["radii"], W, H, out["meta"].get("gaussian_ids"))
        with torch.no_grad():
            opt.step()
            opt.zero_grad(set_to_none=True)
        event = strategy.step_post_optimizer(model, opt, it)
        if event is not None:
            log["densify"].append(event)
            if event.get("note"):
                log["notes"].append(event["note"])
        log["count"].append(len(model))
        if progress is not None:
            progress(it, cfg.iterations, "iters")
    log["loss"] = torch.stack(losses).tolist()
    log["time_s"] = time.perf_counter() - t0
    log["final_count"] = len(model)
    return log


def _views_on(views: list[dict], dev: torch.device) -> list[dict]:
    """image [H, W, 3], mask [H, W] (or None), depth [H, W] (or None) and K [3, 3] of every view as
    float32 on ``dev``."""
    f32 = lambda t: None if t is None else torch.as_tensor(t, dtype=torch.float32).to(dev)  # noqa: E731
    keys = ("image", "mask", "depth", "K")
    return [{k: f32(v.get(k)) for k in keys} for v in views]


def depth_loss(depth: torch.Tensor, alpha: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean relative error of the rendered depth: depth [H, W] accumulated camera z (sum of w_i z_i),
    alpha [H, W], target [H, W] camera z (m; NaN / inf = not supervised); over the target's finite
    pixels with alpha > 0.5 (0 when there is none)."""
    ok = torch.isfinite(target) & (target > 0) & (alpha > 0.5)
    if not bool(ok.any()):
        return depth.sum() * 0.0
    z = depth[ok] / alpha[ok]
    return ((z - target[ok]).abs() / target[ok]).mean()


def _make_optimizer(model: GaussianModel, cfg: TrainConfig, extent: float) -> torch.optim.Adam:
    groups = [
        ("means", cfg.lr_means * extent),
        ("sh_dc", cfg.lr_features),
        ("sh_rest", cfg.lr_features / 20),
        ("opacity_logits", cfg.lr_opacity),
        ("log_scales", cfg.lr_scaling),
        ("quats", cfg.lr_rotation),
    ]
    # fused: one kernel per group instead of ~10 tensor-sized ops (5.6x faster per step on the CPU
    # for 130k Gaussians at SH degree 3: 7.1 against 40.0 ms); same update rule, float rounding only
    return torch.optim.Adam(
        [{"params": [getattr(model, k)], "lr": lr, "name": k} for k, lr in groups], lr=0.0, eps=1e-15, fused=True
    )
