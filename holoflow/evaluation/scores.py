"""Scores of a run's two models, G0 (pre_opt) and G1 (transfer_opt): PSNR / SSIM / empty fraction at
each camera set, NIQE / BRISQUE at the supplementary cameras (holoflow.quality), and a picture."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from holoflow.evaluation.cameras import (
    Views,
    base_views,
    hidden_masks,
    novel_cameras,
    square_K,
    supp_cameras,
    true_views,
)
from holoflow.evaluation.runs import depth_engines

if TYPE_CHECKING:
    import numpy as np
    import torch


def score(model, viewmats, K, targets, backend: str, hidden=None) -> tuple[dict, "torch.Tensor"]:
    """PSNR / SSIM / empty fraction of ``model`` rendered at the cameras
    against targets [C, H, W, 3] sRGB; with ``hidden`` [C, H, W] bool (surface hidden from the
    centre) also ``hidden_psnr`` (PSNR over those pixels only, pooled), ``hidden_frac`` (their share)
    and ``hidden_empty``. Returns (scores, renders [C, H, W, 3])."""
    from holoflow.quality import metrics
    from holoflow.recon.optimize import render_views

    views = [dict(image=t, viewmat=vm, K=K) for t, vm in zip(targets, viewmats)]
    rgb, alpha = render_views(model, views, backend)
    out = dict(psnr=metrics.psnr(rgb, targets), ssim=metrics.ssim(rgb, targets), empty=metrics.empty_fraction(alpha))
    if hidden is not None:
        out.update(
            hidden_psnr=metrics.psnr(rgb, targets, hidden),
            hidden_frac=float(hidden.double().mean()),
            hidden_empty=float(((alpha[..., 0] < 0.5) & hidden).double().sum() / max(int(hidden.sum()), 1)),
        )
    return out, rgb


def nr_scores(model, viewmats, K, size: int, backend: str) -> dict:
    """The paper's rendering-robustness scores of ``model`` at cameras viewmats [C, 4, 4] with
    intrinsics K [3, 3] rescaled to size x size px (``square_K``): mean NIQE and BRISQUE over the C
    renders (sRGB), with their spread (min / max) and C. A score whose parameters are missing is
    None with the reason under ``unavailable``."""
    import torch

    from holoflow.quality import metrics, nriqa
    from holoflow.recon.optimize import render_views

    Ks = square_K(K, size).float()
    blank = torch.zeros(size, size, 3)
    rgb, _ = render_views(model, [dict(image=blank, viewmat=vm, K=Ks) for vm in viewmats], backend)
    out: dict = {"cameras": len(viewmats), "size": size}
    for name, fn in (("niqe", metrics.niqe), ("brisque", metrics.brisque)):
        try:
            vals = [fn(x) for x in rgb]
        except nriqa.Unavailable as e:
            out[name] = None
            out.setdefault("unavailable", {})[name] = str(e)
            continue
        out.update({name: sum(vals) / len(vals), f"{name}_min": min(vals), f"{name}_max": max(vals)})
    return out


MODELS = (("G0", "pre_opt", "gaussians.ply"), ("G1", "transfer_opt", "scene.ply"))


def score_models(run_dir: Path, views: dict[str, Views], backend: str, nr: tuple | None = None) -> tuple[dict, dict]:
    """G0 (pre_opt) and G1 (transfer_opt) of a run folder scored at each view set (``score``), and
    with ``nr`` = (viewmats, K, size) the no-reference scores there (``nr_scores``, key supp_nr):
    ({tag: {gaussians, set name: scores}}, {tag: {set name: renders [C, H, W, 3]}})."""
    from holoflow.splat import GaussianModel
    from holoflow.splat.rasterize import backend_device

    result: dict = {}
    renders: dict = {}
    for tag, stage, file in MODELS:
        model = GaussianModel.load_ply(run_dir / stage / file).to(backend_device(backend))
        result[tag], renders[tag] = {"gaussians": len(model)}, {}
        for name, v in views.items():
            result[tag][name], renders[tag][name] = score(model, v.viewmats, v.K, v.targets, backend, v.hidden)
        if nr is not None:
            result[tag]["supp_nr"] = nr_scores(model, *nr, backend)
    return result, renders


def evaluate_run(
    run_dir: Path,
    novel: int,
    offset: float,
    supp: int,
    seed: int,
    backend: str,
    nr_size: int = 512,
    cache: dict | None = None,
) -> dict:
    """Scores of G0 and G1 of one pipeline run (folder runs/<id>/ with one folder per stage):
    ``novel`` random cameras, a seeded subset of ``supp`` supplementary cameras (0 = all), NIQE /
    BRISQUE at those supplementary cameras rendered at ``nr_size`` px (0 = skip)."""

    scene, base = base_views(run_dir)
    K, h, w = base.K, int(base.targets.shape[1]), int(base.targets.shape[2])
    supp_vm, supp_K = supp_cameras(run_dir, supp, seed)
    novel_vm = novel_cameras(scene, novel, offset, seed, K)
    views = {"base": base}
    for name, vm in (("supp", supp_vm), ("novel", novel_vm)):
        views[name] = Views(vm, K, true_views(scene, vm, K, w, h, cache=cache), hidden_masks(scene, vm, K, w, h))
    result, renders = score_models(run_dir, views, backend, (supp_vm, supp_K, nr_size) if nr_size else None)
    result["engines"] = depth_engines(run_dir)
    result["_renders"] = {
        "truth": views["novel"].targets,
        "hidden": views["novel"].hidden,
        **{tag: r["novel"] for tag, r in renders.items()},
    }
    return result


def strip_image(renders: dict, k: int = 4) -> "np.ndarray":
    """A picture: rows truth / G0 / G1 at the first k novel cameras, uint8 [3 H, k W, 3] (sRGB)."""
    import numpy as np

    rows = [np.concatenate(list(renders[t][:k].numpy()), 1) for t in ("truth", "G0", "G1")]
    return (np.clip(np.concatenate(rows, 0), 0, 1) * 255 + 0.5).astype(np.uint8)
