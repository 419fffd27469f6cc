"""`holoflow bench exports [RUN]`: how faithful each export of a run is, drawn at the PANO-set cameras.

scene.ply (read by holoflow), scene.splat (parsed here from its 32-byte records), scene.spz and
scene.compressed.ply (read by gsply, an independent reader; SPZ's RUB axes turned back) are rendered
with holoflow's CPU rasterizer at the PANO set's cameras (exports with their DC colour; scene.ply with
its own SH, degree 0 in the preview profile) and compared with the PANO set's images: PSNR in dB on sRGB values
in [0, 1], each export also against the scene.ply render. scene.ply's own PSNR is the bound the
exports are held to. mesh.glb is loaded with trimesh. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from holoflow.evaluation.machine import load, machine

#: antimatter15 .splat record: position f32 x3, scale f32 x3, RGBA u8 x4, quaternion u8 x4 (w, x, y, z)
SPLAT_RECORD = np.dtype([("p", "<f4", 3), ("s", "<f4", 3), ("c", "u1", 4), ("q", "u1", 4)])


def read_splat(path: Path) -> dict:
    """scene.splat -> activated arrays (float32): means [N, 3], quats [N, 4], scales [N, 3],
    opacities [N], rgb [N, 3]."""
    rec = np.frombuffer(Path(path).read_bytes(), SPLAT_RECORD)
    return dict(
        means=rec["p"].copy(),
        quats=(rec["q"].astype(np.float32) - 128) / 128,
        scales=rec["s"].copy(),
        opacities=rec["c"][:, 3] / np.float32(255),
        rgb=rec["c"][:, :3] / np.float32(255),
    )


def read_gsply(path: Path, rub: bool) -> dict:
    """An SPZ (``rub``: +Y-up axes, turned back to holoflow's) or a PLY gsply reads -> activated
    arrays (float32) as :func:`read_splat`."""
    import gsply

    g = gsply.read_spz(path) if rub else gsply.plyread(str(path))
    flip = np.array([1, -1, -1], np.float32) if rub else np.ones(3, np.float32)  # diag(1, -1, -1)
    qflip = np.concatenate([[1], flip]).astype(np.float32)
    sh0 = np.asarray(g.sh0, np.float32).reshape(len(g.means), 3)
    return dict(
        means=np.asarray(g.means, np.float32) * flip,
        quats=np.asarray(g.quats, np.float32) * qflip,
        scales=np.exp(np.asarray(g.scales, np.float32)),
        opacities=1 / (1 + np.exp(-np.asarray(g.opacities, np.float32).reshape(-1))),
        rgb=0.5 + 0.28209479177387814 * sh0,
    )


def fidelity(run: Path) -> list[tuple[str, int, float, float]]:
    """(file, Gaussians, PSNR vs the PANO set, PSNR vs the scene.ply render) for scene.ply and each
    splat export of the run folder ``run`` (module docstring); dB."""
    import torch

    from holoflow.quality.metrics import psnr
    from holoflow.recon.views import load_view_set, stack_cameras
    from holoflow.splat.model import GaussianModel
    from holoflow.splat.rasterize import rasterize, render

    views, _ = load_view_set(run / "pano_set", alpha_is_mask=False)
    viewmats, Ks = stack_cameras(views)
    target = torch.stack([v["image"] for v in views])  # [C, H, W, 3] sRGB
    H, W = target.shape[1:3]
    model = GaussianModel.load_ply(run / "transfer_opt" / "scene.ply")
    with torch.no_grad():
        ply = render(model, viewmats, Ks, W, H, backend="cpu")["rgb"].clamp(0, 1)
    rows = [("scene.ply", len(model.means), psnr(ply, target), float("inf"))]
    for name, reader in (
        ("scene.splat", read_splat),
        ("scene.spz", lambda p: read_gsply(p, True)),
        ("scene.compressed.ply", lambda p: read_gsply(p, False)),
    ):
        a = {k: torch.from_numpy(np.ascontiguousarray(v, np.float32)) for k, v in reader(run / "export" / name).items()}
        rgb = rasterize(
            a["means"], a["quats"], a["scales"], a["opacities"], a["rgb"], viewmats, Ks, W, H, backend="cpu"
        )["rgb"].clamp(0, 1)
        rows.append((name, len(a["means"]), psnr(rgb, target), psnr(rgb, ply)))
    return rows


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench exports", description=__doc__.splitlines()[0])
    ap.add_argument("run", nargs="?", default="latest", help="run id, or 'latest' (default)")
    ap.add_argument("--store", default=os.environ.get("HOLOFLOW_STORE", "artifacts"), help="store folder")
    args = ap.parse_args(argv)
    import trimesh

    run = Path(args.store) / ("latest" if args.run == "latest" else f"runs/{args.run}")
    rows = fidelity(run)
    mesh = trimesh.load(str(run / "export" / "mesh.glb"), force="mesh", process=False)
    cams = (run / "pano_set" / "cameras.json").read_text()
    print(f"Run {run.resolve().name} ({cams.count('viewmat')} PANO-set views); {machine()}; load {load()}\n")
    print("| file | Gaussians | PSNR vs PANO set (dB) | PSNR vs scene.ply render (dB) |\n|---|---|---|---|")
    for name, n, p_set, p_ply in rows:
        print(f"| {name} | {n} | {p_set:.2f} | {p_ply:.1f} |")
    print(
        f"\nmesh.glb (trimesh): {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, "
        f"finite: {bool(np.isfinite(mesh.vertices).all())}"
    )
    return 0
