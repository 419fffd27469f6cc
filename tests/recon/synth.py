"""A tiny synthetic reconstruction problem with exact truth, built from the rasterizer itself.

Truth: a Gaussian "room" (walls of a 4 m cube around the origin, smooth colour patterns) with a
foreground box that occludes part of the +z wall, so offset cameras see disocclusions. From it:
- PANO set: truth rendered by base cameras at the origin (6 cube faces, 90 deg FOV);
- P_f: the base renders back-projected (RGB-D -> points), i.e. only what the centre sees;
- PCD set: P_f projected into supplementary cameras (offset +-x / +-y of each base camera) with a
  z-buffer; A = 1 where a point landed, R,G,B = that point's colour.
Files follow docs/artifacts.md (cameras.json, views/*.exr, pf.ply).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from holoflow.geometry.camera import intrinsics_from_fov, look_at
from holoflow.imageops.color import srgb_to_linear_torch
from holoflow.io.exr import write_rgb
from holoflow.io.ply import write_points
from holoflow.splat.model import GaussianModel
from holoflow.splat.project import SH_C0
from holoflow.splat.rasterize import render

FACES = [(0, 0, 1), (1, 0, 0), (0, 0, -1), (-1, 0, 0), (0, -1, 0), (0, 1, 0)]  # +z, +x, -z, -x, up, down


def _wall_points(h: float) -> tuple[np.ndarray, np.ndarray]:
    g = np.arange(-2 + h / 2, 2, h)
    a, b = np.meshgrid(g, g, indexing="ij")
    a, b = a.ravel(), b.ravel()
    pts, cols = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            p = np.zeros((len(a), 3))
            others = [i for i in range(3) if i != axis]
            p[:, axis] = 2.0 * sign
            p[:, others[0]], p[:, others[1]] = a, b
            k = axis * 2 + (sign > 0)
            c = np.stack(
                [
                    0.5 + 0.35 * np.sin(1.3 * a + k),
                    0.5 + 0.35 * np.cos(1.1 * b + 0.7 * k),
                    0.45 + 0.3 * np.sin(0.9 * (a + b) + 0.3 * k),
                ],
                1,
            )
            pts.append(p)
            cols.append(c)
    return np.concatenate(pts), np.concatenate(cols)


def _box_points(center, half: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    g = np.arange(-half + h / 2, half, h)
    a, b = (x.ravel() for x in np.meshgrid(g, g, indexing="ij"))
    pts = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            p = np.zeros((len(a), 3))
            others = [i for i in range(3) if i != axis]
            p[:, axis] = half * sign
            p[:, others[0]], p[:, others[1]] = a, b
            pts.append(p)
    p = np.concatenate(pts) + np.asarray(center)
    c = np.stack([0.85 + 0.1 * np.sin(6 * p[:, 0]), 0.25 + 0.1 * np.cos(5 * p[:, 1]), 0.2 + 0 * p[:, 2]], 1)
    return p, c


def truth_model() -> GaussianModel:
    """The truth: ~16k opaque isotropic Gaussians on the room walls and a foreground box."""
    wp, wc = _wall_points(0.08)
    bp, bc = _box_points((0.35, 0.25, 1.1), 0.3, 0.04)
    xyz = np.concatenate([wp, bp])
    rgb = np.concatenate([wc, bc])
    scale = np.concatenate([np.full(len(wp), 0.06), np.full(len(bp), 0.03)])
    n = len(xyz)
    return GaussianModel(
        means=torch.from_numpy(xyz),
        log_scales=torch.from_numpy(np.log(scale))[:, None].repeat(1, 3),
        quats=torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
        opacity_logits=torch.full((n,), 4.0),
        sh_dc=torch.from_numpy((rgb - 0.5) / SH_C0)[:, None, :],
        sh_rest=torch.zeros(n, 0, 3),
    )


def base_cameras() -> torch.Tensor:
    d = torch.tensor(FACES, dtype=torch.float64)
    return look_at(torch.zeros_like(d), d).float()  # [6, 4, 4]


def supplementary_cameras(base: torch.Tensor, offset: float = 0.6) -> torch.Tensor:
    """4 per base camera: moved by ``offset`` m along -y, +y, -x, +x of the camera, same orientation."""
    out = []
    for vm in base:
        R = vm[:3, :3]
        for axis, sign in ((1, -1), (1, 1), (0, -1), (0, 1)):
            eye = sign * offset * R[axis]  # camera axis in world
            t = -R @ eye
            m = vm.clone()
            m[:3, 3] = t
            out.append(m)
    return torch.stack(out)


@torch.no_grad()
def render_truth(viewmats: torch.Tensor, size: int) -> tuple[torch.Tensor, torch.Tensor]:
    """sRGB truth [C, S, S, 3] and camera z depth [C, S, S] at 90 deg FOV."""
    model = truth_model()
    K = intrinsics_from_fov(90.0, size, size).float()
    out = render(model, viewmats, K[None].expand(len(viewmats), 3, 3), size, size, backend="cpu")
    alpha = out["alpha"][..., 0].clamp_min(1e-6)
    return out["rgb"].clamp(0, 1), out["depth"][..., 0] / alpha


def _cameras_json(viewmats: torch.Tensor, size: int, kind: str, names: list[str]) -> dict:
    K = intrinsics_from_fov(90.0, size, size)
    return {
        "width": size,
        "height": size,
        "fx": float(K[0, 0]),
        "fy": float(K[1, 1]),
        "cx": float(K[0, 2]),
        "cy": float(K[1, 2]),
        "views": [
            {"name": n, "file": f"views/{n}.exr", "viewmat": vm.tolist(), "kind": kind, "base": int(n.split("_")[0])}
            for n, vm in zip(names, viewmats)
        ],
    }


def _write_set(folder: Path, cams: dict, rgb_srgb: torch.Tensor, alpha: np.ndarray | None) -> None:
    lin = srgb_to_linear_torch(rgb_srgb).numpy()
    for i, v in enumerate(cams["views"]):
        p = folder / v["file"]
        p.parent.mkdir(parents=True, exist_ok=True)
        extra = {} if alpha is None else {"A": alpha[i].astype(np.float32)}
        write_rgb(p, lin[i], {"holoflow.stage": "test"}, **extra)
    (folder / "cameras.json").write_text(json.dumps(cams))


def zbuffer(
    xyz: np.ndarray, rgb: np.ndarray, viewmat: np.ndarray, K: np.ndarray, size: int, radius: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Project coloured points with a z-buffer, each point covering (2 radius + 1)^2 pixels.
    Returns image [S, S, 3] and mask [S, S] (1 = a point landed)."""
    cam = xyz @ viewmat[:3, :3].T + viewmat[:3, 3]
    keep = cam[:, 2] > 1e-3
    cam, col = cam[keep], rgb[keep]
    u = np.floor(K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2]).astype(int)
    v = np.floor(K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]).astype(int)
    z = np.full((size, size), np.inf)
    img = np.zeros((size, size, 3))
    for order in np.argsort(-cam[:, 2]):  # far to near: near wins
        for dv in range(-radius, radius + 1):
            for du in range(-radius, radius + 1):
                x, y = u[order] + du, v[order] + dv
                if 0 <= x < size and 0 <= y < size and cam[order, 2] <= z[y, x]:
                    z[y, x] = cam[order, 2]
                    img[y, x] = col[order]
    return img, np.isfinite(z).astype(np.float32)


def build(root: Path, size: int = 24) -> dict[str, Path]:
    """Write the inputs of pre_opt / inp_set / transfer_opt under ``root``; returns the input folders."""
    base = base_cameras()
    supp = supplementary_cameras(base)
    rgb, depth = render_truth(base, size)
    # P_f: back-project every base pixel (RGB-D -> points)
    K = intrinsics_from_fov(90.0, size, size).double()
    ys, xs = torch.meshgrid(torch.arange(size) + 0.5, torch.arange(size) + 0.5, indexing="ij")
    rays = torch.stack([(xs - K[0, 2]) / K[0, 0], (ys - K[1, 2]) / K[1, 1], torch.ones_like(xs)], -1)  # [S, S, 3]
    pts = []
    for i, vm in enumerate(base.double()):
        cam = rays * depth[i].double()[..., None]
        pts.append(((cam - vm[:3, 3]) @ vm[:3, :3]).reshape(-1, 3))  # R^T (p - t)
    xyz = torch.cat(pts).numpy().astype(np.float32)
    col = rgb.reshape(-1, 3).numpy()
    cloud = root / "cloud"
    cloud.mkdir(parents=True)
    write_points(cloud / "pf.ply", xyz, (col * 255 + 0.5).astype(np.uint8))
    names = [f"{i:03d}" for i in range(len(base))]
    _write_set(root / "pano", _cameras_json(base, size, "base", names), rgb, None)
    imgs, masks = [], []
    for vm in supp.numpy():
        img, m = zbuffer(xyz, col, vm, K.numpy(), size)
        imgs.append(img)
        masks.append(m)
    snames = [f"{i // 4:03d}_{i % 4}" for i in range(len(supp))]
    _write_set(
        root / "pcd",
        _cameras_json(supp, size, "supplementary", snames),
        torch.from_numpy(np.stack(imgs)).float(),
        np.stack(masks),
    )
    return {"cloud": cloud, "pano": root / "pano", "pcd": root / "pcd"}


def novel_cameras(n: int, seed: int = 0, offset: float = 0.5) -> torch.Tensor:
    """n seeded cameras inside the room, off the centre, looking in random directions."""
    g = torch.Generator().manual_seed(seed)
    eye = (torch.rand(n, 3, generator=g, dtype=torch.float64) * 2 - 1) * offset
    d = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=1)
    return look_at(eye, eye + d).float()


def job_spec(tmp: Path, stage: str, engine: str, params: dict, inputs: dict[str, Path]) -> Path:
    out = tmp / f"{stage}_out"
    out.mkdir()
    spec = {
        "stage": stage,
        "engine": engine,
        "params": params,
        "seed": 0,
        "prompt": "",
        "inputs": {k: str(v) for k, v in inputs.items()},
        "output_dir": str(out),
        "work_dir": str(tmp / f"{stage}_work"),
        "device": "cpu",
    }
    path = tmp / f"{stage}.json"
    path.write_text(json.dumps(spec))
    return path
