"""Colour fit at the viewing size: the Gaussians' base colours solved against the panorama's own
views at the size a viewer shows them.

Training at 64-128 px (what a CPU affords) leaves a scene whose 512 px views are blurred: each
Gaussian keeps roughly its pixel's colour, and front-to-back compositing of overlapping discs is no
interpolation filter. With the geometry fixed, a render is linear in the colours,

    I_v(p) = sum_i w_iv(p) c_i,        w_iv(p) = alpha_i(p) T_i(p)  (compositing weight),

so the colours that best reproduce the panorama's views are a linear least-squares problem. It is
solved by projected SART (simultaneous algebraic reconstruction): each iteration renders every
view once, back-projects the residual and moves each colour by its weight-normalised mean residual

    c_i <- clip(c_i - relax * sum_vp u_v w_iv(p) (I_v(p) - target_v(p)) / sum_vp u_v w_iv(p), 0, c_max),

a Jacobi step on the normal equations of the view-weighted (u_v) least squares that converges for
0 < relax < 2 since every pixel's weights sum to its alpha <= 1. The views near the zenith and nadir
weigh more (``polar_weights``): they see the polar caps' Gaussians head on, and the many side views
that see the same Gaussians obliquely at their edges would otherwise outvote them. Numerator and
denominator come from one backward pass: the render carries a fourth colour channel of ones, whose
gradient is sum_vp w_iv(p). Only the view-independent (DC) colour moves; higher SH bands, positions,
shapes and opacities stay as trained. Gaussians no view sees (denominator below ``min_weight``
pixels) keep their colour. Targets are sRGB in [0, 1], the training convention; colours may reach
c_max above 1, so that a Gaussian makes up for coverage below 1 next to a white highlight (the
renderer clamps at 0 only, as 3DGS).
"""

from __future__ import annotations

import math

import torch

from holoflow.stage import Progress


def viewing_views(pano: torch.Tensor, cams: dict, size: int) -> list[dict]:
    """The panorama pano [3, H, W] (linear light) seen through a view set's cameras (cameras.json
    dict: its viewmats and field of view, rotations about the centre) at ``size`` x ``size`` px,
    antialiased as the PANO set (holoflow.geometry.sampling.equirect_to_pinhole): views as
    ``load_view_set`` gives them (image sRGB [size, size, 3], viewmat [4, 4], K [3, 3], mask None)."""
    from holoflow.geometry.sampling import equirect_to_pinhole
    from holoflow.imageops.color import linear_to_srgb_torch
    from holoflow.recon.views import intrinsics

    K = intrinsics(cams)
    scale = torch.tensor([size / cams["width"], size / cams["height"], 1.0], dtype=K.dtype)
    K = K * scale[:, None]  # same field of view
    out = []
    chunk = 8
    vms = torch.stack([torch.tensor(v["viewmat"], dtype=torch.float32).reshape(4, 4) for v in cams["views"]])
    for s in range(0, len(vms), chunk):
        vm = vms[s : s + chunk]
        imgs = equirect_to_pinhole(pano.float(), K.expand(len(vm), 3, 3), vm, size, size, mode="antialias")
        for j in range(len(vm)):
            out.append(
                dict(
                    name=cams["views"][s + j]["name"],
                    viewmat=vm[j].clone(),
                    K=K.clone(),
                    mask=None,
                    image=linear_to_srgb_torch(imgs[j].permute(1, 2, 0)).contiguous(),
                )
            )
    return out


def polar_weights(views: list[dict], weight: float, pole_deg: float = 25.0) -> list[float]:
    """Per view: ``weight`` for a view whose axis lies within ``pole_deg`` of the zenith or nadir, else 1."""
    from holoflow.geometry.camera import polar_views

    if not views:
        return []
    polar = polar_views(torch.stack([v["viewmat"] for v in views]), pole_deg)
    return [float(weight) if bool(p) else 1.0 for p in polar]


def fit_colours(
    model,
    views: list[dict],
    iterations: int,
    backend: str = "cpu",
    relax: float = 1.0,
    min_weight: float = 0.05,
    chunk: int = 8,
    progress: Progress = None,
    weights: list[float] | None = None,
    max_colour: float = 1.0,
) -> dict:
    """Projected SART on ``model``'s DC colours (module docstring), in place: ``iterations`` passes
    over ``views`` (one image size; image sRGB [H, W, 3], viewmat [4, 4], K [3, 3]), each view's
    pixels weighted by ``weights`` (None: all 1), colours kept in [0, ``max_colour``]. Returns the log:
    PSNR (dB, all pixels of all views, unweighted) before each pass and the number of Gaussians the
    views see."""
    from holoflow.splat import rasterize
    from holoflow.splat.project import SH_C0
    from holoflow.splat.rasterize import camera_colors

    if iterations <= 0 or not views:
        return {"iterations": 0}
    h, w = views[0]["image"].shape[:2]
    dev = model.means.device
    means, quats = model.means.detach(), model.quats.detach()
    scales, opac = torch.exp(model.log_scales.detach()), torch.sigmoid(model.opacity_logits.detach())
    view_dependent = model.sh_degree > 0
    weights = [1.0] * len(views) if weights is None else [float(x) for x in weights]
    if len(weights) != len(views) or min(weights) < 0:
        raise ValueError(f"fit_colours: {len(views)} views need as many weights >= 0, got {weights}")
    psnr, seen = [], 0

    def one_pass() -> tuple[torch.Tensor, torch.Tensor, float]:
        num = torch.zeros(len(means), 3, device=dev, dtype=torch.float64)
        den = torch.zeros(len(means), device=dev, dtype=torch.float64)
        sq, count = 0.0, 0
        step = 1 if view_dependent else chunk  # SH > 0: colours differ per camera
        for s in range(0, len(views), step):
            part = views[s : s + step]
            vm = torch.stack([v["viewmat"] for v in part]).to(dev)
            K = torch.stack([v["K"] for v in part]).to(dev)
            rgb = camera_colors(means, model.sh.detach(), vm[:1], model.sh_degree)[0]  # [N, 3]
            feats = torch.cat([rgb, torch.ones(len(means), 1, device=dev)], 1).requires_grad_(True)
            out = rasterize(means, quats, scales, opac, feats, vm, K, w, h, backend=backend, depth=False)
            target = torch.stack([v["image"] for v in part]).to(dev)
            resid = (out["rgb"][..., :3] - target).detach()  # [c, H, W, 3]
            u = torch.tensor(weights[s : s + step], device=dev, dtype=resid.dtype)[:, None, None]  # [c, 1, 1]
            loss = (out["rgb"][..., :3] * (resid * u[..., None])).sum() + (out["rgb"][..., 3] * u).sum()
            (g,) = torch.autograd.grad(loss, feats)  # [N, 4]
            num += g[:, :3].double()
            den += g[:, 3].double()
            sq += float((resid.double() ** 2).sum())
            count += resid.numel()
        return num, den, sq / max(count, 1)

    for it in range(iterations):
        num, den, mse = one_pass()
        psnr.append(-10.0 * math.log10(max(mse, 1e-20)))
        with torch.no_grad():
            ok = den > min_weight
            seen = int(ok.sum())
            step = torch.where(ok[:, None], num / den.clamp_min(min_weight)[:, None], torch.zeros_like(num))
            base = SH_C0 * model.sh_dc[:, 0, :].double() + 0.5  # the DC colour, sRGB
            new = torch.where(ok[:, None], (base - relax * step).clamp(0.0, max_colour), base)
            model.sh_dc[:, 0, :] = ((new - 0.5) / SH_C0).to(model.sh_dc.dtype)
        if progress is not None:
            progress(it + 1, iterations, "colour fit")
    return {
        "iterations": iterations,
        "size": [w, h],
        "views": len(views),
        "relax": relax,
        "weights": sorted(set(weights)),
        "max_colour": max_colour,
        "psnr_before_pass": [round(p, 4) for p in psnr],
        "seen_gaussians": seen,
    }
