"""Time the real-model engines at the paper's sizes with randomly initialised full-size models.

    holoflow bench engines --full --device cuda --out docs/bench-engines.md
    holoflow bench engines               # tiny models, test sizes (CPU smoke run)

Compute does not depend on weight values, so random weights of the published architectures (SD 1.5
UNet + VAE + CLIP-L, ControlNet, RRDBNet x4plus, big-lama, Depth Anything large, ZoeDepth NK)
give the engines' real cost without downloading anything. Each time is one engine call, model
loading from a local folder included, as a stage pays it. Writes a markdown table naming the machine.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

# (engine, what, paper sizes, tiny sizes)
CASES = {
    "diffusion360": (
        "base_pano 1024x512, 30 steps",
        dict(width=1024, height=512, steps=30),
        dict(width=64, height=32, steps=2),
    ),
    "controlnet_lineart": (
        "stylize 1536x768, 20 steps",
        dict(width=1536, height=768, steps=20),
        dict(width=64, height=32, steps=2),
    ),
    "realesrgan": (
        "upscale x4 1536x768 -> 6144x3072, tile 512",
        dict(src=(768, 1536), width=6144, height=3072, tile=512),
        dict(src=(32, 64), width=256, height=128, tile=64),
    ),
    "controlnet_tile": (
        "detail 6144x3072, tiles 512/64, 20 steps x 0.5",
        dict(width=6144, height=3072, tile=512, overlap=64, steps=20),
        dict(width=64, height=32, tile=32, overlap=8, steps=2),
    ),
    "depth_anything": ("20 tangent faces 512x512", dict(n=20, side=512), dict(n=4, side=32)),
    "zoedepth": ("6 tangent faces 512x512 (+ flip)", dict(n=6, side=512), dict(n=2, side=32)),
    "lama": ("152 views 512x512, 15% holes", dict(n=152, side=512), dict(n=4, side=32)),
}


def _machine(device: str) -> str:
    from holoflow.evaluation.machine import machine

    text = machine()
    if device.startswith("cuda"):
        import torch

        text += f", {torch.cuda.get_device_name(0)}, torch {torch.__version__}"
    return text


def _image(h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.random((h, w, 3), dtype=np.float32)


def run_case(name: str, size: dict, folder: Path, full: bool, device: str) -> float:
    """Build (once) the random model for ``name`` under ``folder`` and time one engine call, seconds."""
    from holoflow.networks import random_models as rm

    sd = folder / "sd"
    if name in ("diffusion360", "controlnet_lineart", "controlnet_tile") and not sd.exists():
        rm.save_sd(sd, full=full)
        rm.save_controlnet(sd, folder / "controlnet", full=full)
    cnet = str(folder / "controlnet")
    if name == "diffusion360":
        from holoflow.networks.diffusion360 import generate_pano

        call = lambda: generate_pano(
            "a cozy wooden cabin",
            size["width"],
            size["height"],
            steps=size["steps"],  # noqa
            model=str(sd),
            device=device,
        )
    elif name == "controlnet_lineart":
        from holoflow.networks.controlnet_lineart import stylize

        pano = _image(size["height"], size["width"], 0)
        call = lambda: stylize(
            pano,
            pano[..., 0],
            "watercolor",
            size["width"],
            size["height"],  # noqa
            steps=size["steps"],
            model=str(sd),
            controlnet=cnet,
            device=device,
        )
    elif name == "realesrgan":
        from holoflow.networks.realesrgan import upscale

        weights = rm.save_rrdbnet(folder / "x4.pth", 4, full=full)
        pano = _image(*size["src"], 0)
        call = lambda: upscale(
            pano,
            size["width"],
            size["height"],
            model=str(weights),
            tile=size["tile"],  # noqa
            device=device,
        )
    elif name == "controlnet_tile":
        from holoflow.networks.controlnet_tile import refine

        pano = _image(size["height"], size["width"], 0)
        call = lambda: refine(
            pano,
            "detailed",
            size["width"],
            size["height"],
            strength=0.5,
            tile=size["tile"],  # noqa
            overlap=size["overlap"],
            steps=size["steps"],
            model=str(sd),
            controlnet=cnet,
            device=device,
        )
    elif name == "depth_anything":
        from holoflow.networks.depth_anything import relative_disparity

        path = rm.save_depth_anything(folder / "da", full=full)
        faces = np.stack([_image(size["side"], size["side"], i) for i in range(size["n"])])
        call = lambda: relative_disparity(faces, model=str(path), device=device)  # noqa
    elif name == "zoedepth":
        from holoflow.networks.zoedepth import metric_depth

        path = rm.save_zoedepth(folder / "zoe", full=full)
        faces = np.stack([_image(size["side"], size["side"], i) for i in range(size["n"])])
        call = lambda: metric_depth(faces, model=str(path), device=device)  # noqa
    else:
        from holoflow.networks.lama import inpaint

        path = rm.save_lama(folder / "lama.safetensors", full=full)
        views = np.stack([_image(size["side"], size["side"], i) for i in range(size["n"])])
        masks = (np.random.default_rng(1).random(views.shape[:3]) < 0.15).astype(np.float32)
        call = lambda: inpaint(views, masks, model=str(path), device=device)  # noqa
    if device.startswith("cuda"):
        import torch

        torch.cuda.synchronize()
    t0 = time.perf_counter()
    call()
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench engines", description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="published architectures at the paper's sizes")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--only", nargs="*", default=list(CASES), choices=list(CASES))
    ap.add_argument("--out", default="", help="markdown file for the table (default: print only)")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.only:
            what, paper, tiny = CASES[name]
            seconds = run_case(name, paper if args.full else tiny, Path(tmp), args.full, args.device)
            rows.append(f"| {name} | {what if args.full else 'tiny model, test size'} | {seconds:.1f} |")
            print(rows[-1], flush=True)
    table = "\n".join(
        [
            f"Engines timed with random {'full-size' if args.full else 'tiny'} models on {args.device}: "
            f"{_machine(args.device)}.",
            "One call each, model loading from local disk included.",
            "",
            "| engine | work | seconds |",
            "|---|---|---|",
            *rows,
            "",
        ]
    )
    if args.out:
        Path(args.out).write_text(table)
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
