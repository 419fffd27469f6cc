"""The paper's two optimisation schedules (Enhanced Two-Stage Panorama Reconstruction).

Pre Optimization (G0): Gaussians from P_f; the PCD set first, with the loss masked to pixels where
a point landed, so the densification that happens in this phase is steered by several viewpoints
around each base camera; then the PANO set alone, to restore the panorama's detail.
Transfer Optimization (G1): fresh Gaussians from P_f, trained on the PANO and INP sets together.

Each phase is one ``holoflow.splat.train`` call with a fresh optimiser state. The position-lr decay
and the SH band schedule restart at each phase with ``lr_decay: phase`` (the preview profiles, where
it was measured), or run once over all of a model's phases with ``lr_decay: model`` (3DGS's single
schedule; the paper profile: the paper gives iteration counts per phase, nothing more). Opacity reset is off
by default (``opacity_reset_every: 0``), as in the paper: it would wipe the point cloud's placement.
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch

from holoflow.quality import metrics
from holoflow.recon.config import OptimParams, PreOptParams, TransferOptParams
from holoflow.stage import Progress

TRAIN_SEED_STRIDE = 1_000_003  # train_seed k moves every phase's seed by k x this (a prime, far from 1000 i)


def init_model(
    xyz: np.ndarray,
    rgb_u8: np.ndarray,
    opacity: float,
    device: str = "cpu",
    sh_degree: int = 0,
    footprint: tuple | None = None,
):
    """Gaussians (SH degree ``sh_degree``, higher bands 0) at the points xyz [N, 3] metres, coloured
    rgb [N, 3] uint8 (sRGB), with
    initial ``opacity`` (a stage's ``init_opacity``; 3DGS: 0.1; a surface point cloud tolerates more,
    which shortens training), on ``device``. ``footprint`` = (angular spacing of the cloud in
    radians, width, thickness[, polar caps, layer points, layer spacing, low-pass, normals, max stretch]):
    each Gaussian covers its point's pixel, on its surface where normals are given
    (holoflow.geometry.area.footprint_gaussians); None: the 3DGS nearest-neighbour size."""
    from holoflow.splat import GaussianModel

    if len(xyz) == 0:
        raise ValueError("the point cloud is empty: nothing to initialise Gaussians from")
    if not 0.0 < opacity < 1.0:
        raise ValueError(f"init_opacity must be in (0, 1), got {opacity}")
    shape = {}
    if footprint is not None:
        from holoflow.geometry.area import footprint_gaussians

        scales, quats = footprint_gaussians(torch.from_numpy(np.asarray(xyz, np.float64)), *footprint)
        shape = dict(scales=scales, quats=quats)
    return GaussianModel.from_points(
        np.asarray(xyz, np.float32),
        np.asarray(rgb_u8, np.float32) / 255.0,
        sh_degree=sh_degree,
        opacity=opacity,
        **shape,
    ).to(device)


def cloud_footprint(cloud_dir, cfg: OptimParams) -> tuple | None:
    """``init_model``'s footprint for the P_f of a point_cloud output folder: (its pf.json's angular
    spacing, cfg.footprint_width, cfg.footprint_thickness, its polar caps or None, the point count of its
    half-width points, background layer, window recesses and sky dome (its last points) and their
    spacing per point, the
    rasterizer's low-pass at its viewing size in radians^2, its pf.ply's normals [N, 3] with
    ``footprint_orient: surface`` (else None: discs face the centre) and cfg.footprint_max_stretch), or
    None with ``init_scale: knn`` or no pf.json (a cloud of the user's own)."""
    from pathlib import Path

    from holoflow.geometry.area import PolarCaps
    from holoflow.splat.project import EPS2D

    pf = read_pf(cloud_dir) if cfg.init_scale == "footprint" else None
    if pf is None:
        return None
    caps = PolarCaps(**pf["polar_caps"]) if "polar_caps" in pf else None
    # grids of their own after P_f's points, in order
    tails = [pf[k] for k in ("coarse", "layer", "reveal", "dome") if k in pf]
    tail_points = sum(int(t["points"]) for t in tails)
    tail_spacing = (
        torch.cat([torch.full((int(t["points"]),), float(t["spacing_rad"]), dtype=torch.float64) for t in tails])
        if tails
        else 0.0
    )
    low_pass = EPS2D * float(pf.get("view_pixel_rad", 0.0)) ** 2  # 0.3 px^2 at the view size
    normals = None
    if cfg.footprint_orient == "surface":
        from holoflow.io.ply import read_point_normals

        found = read_point_normals(Path(cloud_dir) / "pf.ply")
        normals = None if found is None else torch.from_numpy(found).double()
    return (
        float(pf["spacing_rad"]),
        cfg.footprint_width,
        cfg.footprint_thickness,
        caps,
        tail_points,
        tail_spacing,
        low_pass,
        normals,
        cfg.footprint_max_stretch,
    )


def cloud_fit_size(cloud_dir, fit_size: int) -> int:
    """The colour fit's view size (px): ``fit_size``, or with 0 a quarter of the width of the P_f in a
    point_cloud output folder (its pf.json; 384 without one): the fit's pixels keep the same share of
    P_f's spacing whatever P_f's width (holoflow/recon/config.py ``fit_size``)."""
    if fit_size:
        return fit_size
    width = int((read_pf(cloud_dir) or {}).get("width", 0))
    return max(8, width // 4) if width else 384


def read_pf(cloud_dir) -> dict | None:
    """The pf.json of a point_cloud output folder (P_f's width, spacing and tails), None without one."""
    import json
    from pathlib import Path

    path = Path(cloud_dir) / "pf.json"
    return json.loads(path.read_text()) if path.is_file() else None


def panorama_extent(xyz: np.ndarray) -> float:
    """Scene extent (metres) for the trainer's learning-rate scale and size thresholds: the median
    distance from the panorama centre of the points of P_f [N, 3] off the far sky shell
    (``solid_points_mask``). The trainer's own default, the median over all points, is the shell's
    radius as soon as the sky holds half the cloud (on the eval beach 365 m against surfaces ~2 m
    away), which would scale every position step and the clone/split size by that much."""
    from holoflow.geometry.pointcloud import solid_points_mask

    pts = torch.from_numpy(np.asarray(xyz, np.float64))
    if len(pts) == 0:
        raise ValueError("the point cloud is empty: no scene extent")
    r = torch.linalg.vector_norm(pts[solid_points_mask(pts)], dim=-1)
    return max(float(r.median()), 1e-6)


def train_config(
    iterations: int, cfg: OptimParams, backend: str, extent: float | None = None, lr_span: tuple[int, int] | None = None
):
    """A ``holoflow.splat.TrainConfig`` for one phase from a stage's params (``cfg``): ``densify_every``,
    ``densify_from`` and ``densify_stop`` (densification runs at steps densify_from < it <=
    min(densify_stop x iterations, iterations - densify_every)),
    ``opacity_reset_every`` (0 = never, the paper) and ``max_gaussians``; ``backend`` is the
    rasterizer (the stage's engine); ``extent`` the scene extent in metres (None: the trainer's
    default); ``lr_span`` (steps done before this phase, total steps of the model) makes the position
    lr decay and the SH bands continue one schedule across phases (``cfg.lr_decay == "model"``); None
    runs both within the phase."""
    from holoflow.splat import TrainConfig

    every, iters = cfg.densify_every, int(iterations)
    # densification ends at densify_stop x iterations (3DGS: 15k of 30k) and leaves at least
    # ``every`` steps to train what it added last
    return TrainConfig(
        iterations=iters,
        densify_every=every,
        densify_from=cfg.densify_from,
        densify_until=max(1, min(int(cfg.densify_stop * iters), iters - every) + 1),
        opacity_reset_every=cfg.opacity_reset_every,
        max_gaussians=cfg.max_gaussians,
        lambda_depth=cfg.depth_weight,
        random_background=cfg.background == "random",
        backend=backend,
        scene_extent=extent,
        **({} if lr_span is None else dict(step_offset=lr_span[0], lr_means_steps=lr_span[1])),
    )


def run_phases(
    model,
    phases: list[tuple[str, list[dict], int]],
    cfg: OptimParams,
    backend: str,
    seed: int,
    progress: Progress = None,
    extent: float | None = None,
) -> dict:
    """Train ``model`` in place through ``phases`` = [(name, views, iterations)], in order; phases with
    0 iterations are skipped. ``progress(done, total, "iters")`` counts iterations over all phases.
    Phase i draws its views from seed + 1000 i + TRAIN_SEED_STRIDE x ``cfg.train_seed``:
    another train_seed gives an independent optimisation of the same inputs (training noise).
    ``extent``: the scene extent (m) of every phase (``panorama_extent``; None: the trainer's default).
    Returns the log: per phase the trainer's log and the Gaussian count after it; wall seconds per
    phase under ``log["seconds"]`` ({phase: s}), kept apart so a caller can move them out of an
    artifact (stages put them in the key record's meta: train_log.json stays byte-deterministic)."""
    from holoflow.splat import train

    total = sum(max(0, n) for _, _, n in phases)
    done = 0
    log: dict = {"phases": [], "total_iterations": total, "seconds": {}}
    for i, (name, views, iters) in enumerate(phases):
        if iters <= 0:
            continue
        if not views:
            raise ValueError(f"phase {name}: no training views")
        start = done

        def phase_progress(k, _n=None, _what="", _start=start):
            if progress is not None:
                progress(_start + int(k), total, "iters")

        t0 = time.perf_counter()
        phase_seed = seed + 1000 * i + TRAIN_SEED_STRIDE * cfg.train_seed
        span = (start, total) if cfg.lr_decay == "model" else None
        tlog = train(
            model, views, train_config(iters, cfg, backend, extent, span), progress=phase_progress, seed=phase_seed
        )
        done += iters
        tlog.pop("time_s", None)
        log["seconds"][name] = round(time.perf_counter() - t0, 3)
        log["phases"].append(
            dict(name=name, iterations=iters, views=len(views), gaussians=int(model.means.shape[0]), train=tlog)
        )
    return log


def pre_optimize(
    xyz: np.ndarray,
    rgb_u8: np.ndarray,
    pcd_views: list[dict],
    pano_views: list[dict],
    cfg: PreOptParams,
    backend: str,
    seed: int,
    progress: Progress = None,
    device: str = "cpu",
    footprint=None,
):
    """G0: init from P_f (``footprint``: ``init_model``'s), ``cfg.pcd_iters`` on the PCD set (masked),
    then ``cfg.pano_iters`` on the PANO set, trained on ``device``. Returns (model, log)."""
    model = init_model(xyz, rgb_u8, cfg.init_opacity, device, cfg.sh_degree, footprint)
    log = run_phases(
        model,
        [("pcd", pcd_views, cfg.pcd_iters), ("pano", pano_views, cfg.pano_iters)],
        cfg,
        backend,
        seed,
        progress,
        panorama_extent(xyz),
    )
    return model, log


def transfer_optimize(
    xyz: np.ndarray,
    rgb_u8: np.ndarray,
    pano_views: list[dict],
    inp_views: list[dict],
    cfg: TransferOptParams,
    backend: str,
    seed: int,
    progress: Progress = None,
    device: str = "cpu",
    footprint=None,
):
    """G1: fresh init from P_f (``footprint``: ``init_model``'s), ``cfg.iters`` on PANO + INP sets
    together (INP left out when ``cfg.use_inp`` is false: the paper's ablation), trained on
    ``device``. Returns (model, log)."""
    model = init_model(xyz, rgb_u8, cfg.init_opacity, device, cfg.sh_degree, footprint)
    views = pano_views + (inp_views if cfg.use_inp else [])
    log = run_phases(
        model,
        [("pano+inp" if cfg.use_inp else "pano", views, cfg.iters)],
        cfg,
        backend,
        seed,
        progress,
        panorama_extent(xyz),
    )
    return model, log


@torch.no_grad()
def render_views(model, views: list[dict], backend: str, chunk: int = 8, with_depth: bool = False):
    """Render ``model`` at every view's camera (all views share one image size).
    Returns rgb [C, H, W, 3] (sRGB, clamped to [0, 1]) and alpha [C, H, W, 1]; with ``with_depth``
    also the expected camera z [C, H, W, 1] in metres (accumulated depth / alpha; 0 where alpha is 0)."""
    from holoflow.splat import render

    h, w = views[0]["image"].shape[:2]
    dev = model.means.device
    rgbs, alphas, depths = [], [], []
    for s in range(0, len(views), chunk):
        part = views[s : s + chunk]
        vm = torch.stack([v["viewmat"] for v in part]).to(dev)
        K = torch.stack([v["K"] for v in part]).to(dev)
        out = render(model, vm, K, w, h, backend=backend, depth=with_depth)
        rgbs.append(out["rgb"].clamp(0, 1).cpu())
        alphas.append(out["alpha"].cpu())
        if with_depth:
            depths.append((out["depth"] / out["alpha"].clamp_min(1e-6)).where(out["alpha"] > 0, 0.0).cpu())
    if with_depth:
        return torch.cat(rgbs), torch.cat(alphas), torch.cat(depths)
    return torch.cat(rgbs), torch.cat(alphas)


def score_views(model, views: list[dict], backend: str) -> dict:
    """PSNR (dB, masked by the views' masks when they have them), SSIM (unmasked sets only) and empty
    fraction of ``model`` against the views' own images: the fit to the training set."""
    rgb, alpha = render_views(model, views, backend)
    target = torch.stack([v["image"] for v in views]).cpu()
    masks = [v["mask"] for v in views]
    mask = torch.stack(masks) if all(m is not None for m in masks) else None
    p = metrics.psnr(rgb, target, mask)
    return dict(
        psnr=None if math.isnan(p) else p,
        ssim=metrics.ssim(rgb, target) if mask is None else None,  # SSIM windows ignore masks
        empty_fraction=metrics.empty_fraction(alpha),
    )


def save_result(job, model, log: dict, pano_views: list[dict], ply_name: str) -> None:
    """The end of pre_opt / transfer_opt: ``model`` as ``ply_name`` (3DGS layout), its fit at the base
    cameras into ``log["fit"]``, train_log.json without the wall times (those, the fit and the final
    loss go to the key record's meta), so the artifact's bytes depend on the inputs only."""
    from holoflow.recon.views import dumps_log

    model.save_ply(job.output(ply_name))
    log["fit"] = {"pano": score_views(model, pano_views, job.engine)}
    seconds = log.pop("seconds")
    job.output("train_log.json").write_text(dumps_log(log))
    last = log["phases"][-1]["train"] if log["phases"] else {}
    job.meta(
        gaussians=len(model),
        final_loss=last["loss"][-1] if last.get("loss") else None,
        psnr_pano=log["fit"]["pano"]["psnr"],
        ssim_pano=log["fit"]["pano"]["ssim"],
        backend=job.engine,
        phase_seconds=seconds,
    )
