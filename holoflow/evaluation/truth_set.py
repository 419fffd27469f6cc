"""Truth sets (docs/truth-sets.md): a panorama and pinhole views on rings around its centre, with exact
depth, so a scene reconstructed from the panorama can be scored where a viewer walks.

A truth set is a folder: ``cameras.json`` (intrinsics; per view its ``ring`` in metres off the centre,
``viewmat`` world-to-camera, ``eye``), ``views/NNN.png`` (sRGB 8-bit) and ``views/NNN.exr`` (linear
R, G, B + Z camera z, metres, +inf where the ray escapes), ``pano.png`` and ``pano_z.exr`` (linear RGB +
Z radial depth). World frame = holoflow's (docs/conventions.md): the panorama centre, +x right, +y
down, +z forward, metres. ``write_truth_set`` makes one from a procedural scene (holoflow.scene), with
the eyes of ``ring_eyes``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

RINGS = (0.0, 0.25, 0.5, 1.0)  # metres off the centre
PER_RING = 8


@dataclass
class TruthSet:
    """A truth set read into memory: K [3, 3] float32 (pixels), viewmats [V, 4, 4] float32, rings [V]
    metres, names [V], rgb [V, H, W, 3] sRGB float32 in [0, 1], z [V, H, W] float32 camera z (metres,
    +inf = escaped), the folder and its cameras.json."""

    folder: Path
    K: torch.Tensor
    viewmats: torch.Tensor
    rings: list[float]
    names: list[str]
    rgb: torch.Tensor
    z: torch.Tensor
    cameras: dict


def ring_eyes(rings: tuple[float, ...] = RINGS, per_ring: int = PER_RING) -> list[dict]:
    """The eyes of a truth set, ring by ring: for ring r and k = 0..per_ring-1, t = 2 pi k / per_ring,
    eye = r (cos(t + 2), 0, sin(t + 2)) metres, looking horizontally along (cos t, 0, sin t), so the
    eyes move sideways and back relative to where they look. [{ring, k, eye [3], look [3]}]."""
    out = []
    for r in rings:
        for k in range(per_ring):
            t = 2 * math.pi * k / per_ring
            out.append(
                dict(
                    ring=float(r),
                    k=k,
                    eye=[r * math.cos(t + 2), 0.0, r * math.sin(t + 2)],
                    look=[math.cos(t), 0.0, math.sin(t)],
                )
            )
    return out


def eye_viewmat(eye: list[float], look: list[float]) -> torch.Tensor:
    """World-to-camera viewmat [4, 4] float64 of an eye looking along ``look`` with the image's up = -y."""
    from holoflow.geometry.camera import look_at

    e = torch.tensor(eye, dtype=torch.float64)
    return look_at(e, e + torch.tensor(look, dtype=torch.float64))


def read_png(path: Path) -> np.ndarray:
    """An 8-bit RGB PNG as float32 [H, W, 3] in [0, 1] (its sRGB values)."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.float32) / 255.0


def read_truth_set(folder: Path) -> TruthSet:
    """Read a truth set folder (module docstring); raises FileNotFoundError naming what is missing."""
    from holoflow.io.exr import read_exr

    folder = Path(folder)
    f = folder / "cameras.json"
    if not f.is_file():
        raise FileNotFoundError(f"{f}: no truth set here (cameras.json missing; docs/truth-sets.md)")
    cams = json.loads(f.read_text())
    K = torch.tensor([[cams["fx"], 0, cams["cx"]], [0, cams["fy"], cams["cy"]], [0, 0, 1]], dtype=torch.float32)
    views = cams["views"]
    rgb = np.stack([read_png(folder / v["file"]) for v in views])  # [V, H, W, 3]
    z = np.stack([read_exr(folder / v["exr"])[0]["Z"] for v in views])  # [V, H, W]
    vm = torch.tensor([v["viewmat"] for v in views], dtype=torch.float32)  # [V, 4, 4]
    return TruthSet(
        folder,
        K,
        vm,
        [float(v["ring"]) for v in views],
        [str(v["name"]) for v in views],
        torch.from_numpy(rgb),
        torch.from_numpy(z),
        cams,
    )


def write_truth_set(
    folder: Path,
    scene,
    size: int = 512,
    fov_deg: float = 47.43,
    rings: tuple[float, ...] = RINGS,
    per_ring: int = PER_RING,
    pano_width: int = 1024,
    samples: int = 2,
) -> Path:
    """Write a truth set of a procedural ``scene`` (holoflow.scene.model.Scene) into ``folder``: the
    panorama (pano_width x pano_width / 2) and size x size px views with horizontal field of view
    ``fov_deg`` at the ``ring_eyes``, ray cast with ``samples`` x ``samples`` antialiasing. Returns
    the folder."""
    from holoflow.geometry.camera import intrinsics_from_fov
    from holoflow.imageops.color import linear_to_uint8
    from holoflow.io.exr import write_exr
    from holoflow.io.image import write_png
    from holoflow.scene import render_equirect, render_pinhole

    folder = Path(folder)
    (folder / "views").mkdir(parents=True, exist_ok=True)
    rgb, depth = render_equirect(scene, pano_width, pano_width // 2, samples)  # [H, W, 3], [H, W]
    write_exr(
        folder / "pano_z.exr",
        {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], "Z": depth},
        {"holoflow.depth_kind": "radial", "holoflow.colorspace": "linear"},
    )
    write_png(folder / "pano.png", linear_to_uint8(rgb))
    K = intrinsics_from_fov(fov_deg, size, size, dtype=torch.float64)
    views = []
    for i, e in enumerate(ring_eyes(rings, per_ring)):
        vm = eye_viewmat(e["eye"], e["look"])
        rgb, z = render_pinhole(scene, K, vm, size, size, samples)
        name = f"{i:03d}"
        write_png(folder / "views" / f"{name}.png", linear_to_uint8(rgb))
        write_exr(
            folder / "views" / f"{name}.exr",
            {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], "Z": z},
            {"holoflow.depth_kind": "z"},
        )
        views.append(
            dict(
                name=name,
                file=f"views/{name}.png",
                exr=f"views/{name}.exr",
                ring=e["ring"],
                k=e["k"],
                eye=e["eye"],
                viewmat=vm.tolist(),
                escaped=float((~np.isfinite(z)).mean()),
            )
        )
    cams = dict(
        width=size,
        height=size,
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        scene=f"procedural: {scene.prompt!r}, seed {scene.seed}",
        pano="pano_z.exr",
        views=views,
    )
    (folder / "cameras.json").write_text(json.dumps(cams, indent=1))
    return folder
