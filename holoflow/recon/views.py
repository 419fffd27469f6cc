"""View sets (PANO / PCD / INP) as training views, and back to files.

A view set is a folder with ``cameras.json`` and ``views/*.exr`` (docs/artifacts.md). EXR colour is
linear light; Gaussians are trained on display-referred sRGB in [0, 1], the space every 3DGS viewer
shows SH colours in (and the space of the point-cloud PLY colours Gaussians start from), so
``scene.ply`` looks right in SuperSplat and PSNR is measured where the paper measures it.

A training view is a dict ``{"name", "image" [H, W, 3] sRGB float32, "mask" [H, W] float32 (1 =
supervise) or None, "viewmat" [4, 4] world-to-camera, "K" [3, 3]}`` (the ``holoflow.splat.train``
view contract, plus a name), and ``"seen"`` [H, W] float32 when the EXR has that channel (the PCD
set: 1 where any point of P_s landed); ``add_depth_targets`` gives the views at the centre a ``"depth"``
[H, W] (camera z, metres; NaN = not supervised) from the panorama's metric depth.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import torch

from holoflow.imageops.color import linear_to_srgb_torch, srgb_to_linear_torch
from holoflow.io.exr import read_exr, write_rgb


def read_cameras(folder: str | Path) -> dict:
    """``cameras.json`` of a view-set folder (docs/artifacts.md), via holoflow.geometry.camera_files."""
    from holoflow.geometry.camera_files import read_cameras as _read

    return _read(Path(folder) / "cameras.json")


def intrinsics(cams: dict) -> torch.Tensor:
    """Pinhole K [3, 3] (pixels, centres at +0.5) of a cameras.json dict."""
    return torch.tensor(
        [[cams["fx"], 0.0, cams["cx"]], [0.0, cams["fy"], cams["cy"]], [0.0, 0.0, 1.0]], dtype=torch.float32
    )


def load_view_set(folder: str | Path, alpha_is_mask: bool) -> tuple[list[dict], dict]:
    """Training views of a view-set folder, in cameras.json order, and the cameras dict.

    ``alpha_is_mask``: use the EXR's A channel as the supervision mask (the PCD set: 1 = a point
    landed); otherwise every pixel is supervised (PANO set; INP set, whose A only records what was
    inpainted). Returns (views, cameras)."""
    folder = Path(folder)
    cams = read_cameras(folder)
    K = intrinsics(cams)
    views = []
    for v in cams["views"]:
        ch, _ = read_exr(folder / v["file"])
        rgb = torch.from_numpy(np.stack([ch["R"], ch["G"], ch["B"]], -1))  # [H, W, 3] linear
        mask = None
        if alpha_is_mask:
            if "A" not in ch:
                raise ValueError(f"{folder / v['file']}: no A channel (the mask) in a masked view set")
            mask = torch.from_numpy((ch["A"] >= 0.5).astype(np.float32))  # [H, W]
        views.append(
            dict(
                name=v["name"],
                image=linear_to_srgb_torch(rgb).contiguous(),
                mask=mask,
                viewmat=torch.tensor(v["viewmat"], dtype=torch.float32).reshape(4, 4),
                K=K.clone(),
            )
        )
        if "seen" in ch:
            views[-1]["seen"] = torch.from_numpy((ch["seen"] >= 0.5).astype(np.float32))  # [H, W]
    return views, cams


def add_depth_targets(views: list[dict], radial_depth: np.ndarray, edge: float = 0.05) -> int:
    """Give each view whose camera sits at the panorama's centre a ``depth`` target [H, W]: the camera z
    (metres) of the radial depth [h, w] (equirect, +inf sky) seen through it, nearest pixel; NaN where
    nothing is supervised: the sky, and pixels whose 3 x 3 neighbourhood spans a relative depth step over
    ``edge`` (an occlusion edge, where a rendered pixel's expected depth mixes two surfaces). Views away
    from the centre (PCD and INP sets) get none. Returns how many views got one."""
    import torch.nn.functional as F

    from holoflow.geometry.camera import camera_centers, pinhole_rays
    from holoflow.geometry.sampling import equirect_to_pinhole

    r = torch.from_numpy(np.asarray(radial_depth, np.float64))
    disp = torch.where(torch.isfinite(r) & (r > 0), 1.0 / r.clamp_min(1e-12), torch.zeros_like(r))[None]  # [1, h, w]
    done = 0
    for v in views:
        V = v["viewmat"].double()
        if float(torch.linalg.vector_norm(camera_centers(V[None])[0])) > 1e-6:
            continue
        H, W = v["image"].shape[:2]
        K = v["K"].double()
        d = equirect_to_pinhole(disp, K, V, H, W, mode="nearest")[0, 0]  # [H, W] radial disparity
        _, rays = pinhole_rays(K[None], V[None], H, W)  # [1, H, W, 3]
        cos = torch.einsum("hwi,i->hw", rays[0], V[2, :3])  # the ray's cosine to the optical axis
        z = torch.where(d > 0, cos / d.clamp_min(1e-12), torch.full_like(d, float("inf")))
        logz = torch.where(torch.isfinite(z), z.log(), torch.full_like(z, 1e3))[None, None]
        spread = F.max_pool2d(logz, 3, 1, 1) + F.max_pool2d(-logz, 3, 1, 1)  # max - min around
        ok = torch.isfinite(z) & (spread[0, 0] < math.log1p(edge))
        v["depth"] = torch.where(ok, z, torch.full_like(z, float("nan"))).float()
        done += 1
    return done


def stack_cameras(views: list[dict]) -> tuple[torch.Tensor, torch.Tensor]:
    """viewmats [C, 4, 4] and Ks [C, 3, 3] of a list of views."""
    return torch.stack([v["viewmat"] for v in views]), torch.stack([v["K"] for v in views])


def write_images(folder: str | Path, files: list[str], images_srgb: np.ndarray, alpha: np.ndarray, stage: str) -> None:
    """Write ``folder/files[i]`` as EXR: R, G, B linear (from sRGB images [N, H, W, 3]), A = alpha [N, H, W]."""
    folder = Path(folder)
    linear = srgb_to_linear_torch(torch.from_numpy(np.asarray(images_srgb, np.float32))).numpy()
    for i, name in enumerate(files):
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        write_rgb(path, linear[i], {"holoflow.stage": stage}, A=np.asarray(alpha[i], np.float32))


def write_view_set(folder: str | Path, cams: dict, images_srgb: np.ndarray, alpha: np.ndarray, stage: str) -> None:
    """Write a view set: one EXR per camera of ``cams`` (same order; see ``write_images``), plus
    cameras.json and a nerfstudio transforms.json."""
    from holoflow.geometry.camera_files import write_cameras, write_transforms

    folder = Path(folder)
    write_images(folder, [v["file"] for v in cams["views"]], images_srgb, alpha, stage)
    write_cameras(folder / "cameras.json", cams)
    write_transforms(folder / "transforms.json", cams)


def dumps_log(log: dict) -> str:
    """A training log as stable JSON text (sorted keys, finite floats only)."""
    return json.dumps(log, sort_keys=True, indent=1, default=float, allow_nan=True)
