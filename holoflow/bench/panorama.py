"""`holoflow bench panorama`: the four panorama stages' default engines, timed and shown.

For each prompt: procedural base_pano -> classical stylize (lineart + style) -> Lanczos upscale ->
classical detail, at the preview profile's sizes (and, with --paper, the paper profile's sizes), timing
each engine (wall and CPU seconds, in this process, torch on one thread as the stage sets it). Writes
small PNG previews of every stage to docs/images/ and the timing table to docs/bench-panorama.md,
naming the machine. A contact sheet shows a dozen prompts' base panoramas side by side.
"""

from __future__ import annotations

import argparse
import os
import re
import time
from pathlib import Path

from holoflow.evaluation.machine import machine

SHOWCASE = {  # preview name -> prompt: indoor, outdoor, stylized
    "living-room": "a cozy living room with a red sofa and wooden shelves",
    "meadow-watercolor": "a sunny meadow with trees and hills by a lake, watercolor",
    "city-night-anime": "a city street with tall buildings at night with lamps, anime",
    "library-oil": "a grand library with wooden shelves and a marble floor, oil painting",
}
DOZEN = [
    "a cozy living room with a red sofa",
    "a small bedroom with a lamp at night",
    "a modern kitchen with white tiles",
    "a grand library with wooden shelves",
    "a round marble hall",
    "an L-shaped loft with brick walls",
    "a sunny meadow with trees and hills",
    "a dense forest at sunset",
    "a sandy beach by the ocean at noon",
    "a desert with red rocks at dawn",
    "a foggy city street with tall buildings",
    "a snowy mountain village in winter",
]
SIZES = {  # stage -> (preview size, paper size), from pipeline.yaml's defaults and paper profile
    "base_pano": ((2048, 1024), (1024, 512)),  # the procedural engine's own width; the paper's
    "stylize": ((2048, 1024), (1536, 768)),  # a base wider than stylize's width keeps it up to max_width
    "upscale": ((2048, 1024), (6144, 3072)),
    "detail": ((2048, 1024), (6144, 3072)),
}


def _slug(text: str) -> str:
    return "-".join(re.findall(r"[a-z0-9]+", text.lower())[:5])


def _timed(fn, *args, **kw):
    w, c = time.perf_counter(), time.process_time()
    out = fn(*args, **kw)
    return out, time.perf_counter() - w, time.process_time() - c


def run_chain(prompt: str, sizes: dict[str, tuple[int, int]], samples: int = 2, seed: int = 0):
    """The four default engines in sequence; returns per-stage images (linear RGB) and (wall, cpu) times."""
    from holoflow.imageops.detail import enhance_detail
    from holoflow.imageops.lineart import lineart
    from holoflow.imageops.resize import lanczos_resize
    from holoflow.imageops.styles import style_from_prompt, stylize
    from holoflow.scene import render_equirect, scene_from_prompt

    times, images = {}, {}

    def base():
        return render_equirect(scene_from_prompt(prompt, seed), *sizes["base_pano"], samples)

    (rgb, _), *times["base_pano"] = _timed(base)
    images["base_pano"] = rgb

    def styled():
        pano = rgb if rgb.shape[1] == sizes["stylize"][0] else lanczos_resize(rgb, *sizes["stylize"])
        lines = lineart(pano)
        style = style_from_prompt(prompt)
        return (pano if style is None else stylize(pano, lines, style)), lines

    (sty, lines), *times["stylize"] = _timed(styled)
    images["stylize"], images["lineart"] = sty, lines
    up, *times["upscale"] = _timed(lanczos_resize, sty, *sizes["upscale"])
    images["upscale"] = up
    det, *times["detail"] = _timed(
        enhance_detail, up if up.shape[1] == sizes["detail"][0] else lanczos_resize(up, *sizes["detail"]), 0.5
    )
    images["detail"] = det
    return images, times


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench panorama", description=__doc__.splitlines()[0])
    ap.add_argument("--paper", action="store_true", help="also time the paper profile's sizes (slow)")
    ap.add_argument("--docs", default="docs", help="docs folder (default docs/)")
    ap.add_argument("--preview-width", type=int, default=384, help="PNG preview width (default 384)")
    args = ap.parse_args(argv)

    import torch

    from holoflow.imageops.preview import write_preview
    from holoflow.scene import render_equirect, scene_from_prompt

    torch.set_num_threads(max(1, (os.cpu_count() or 2) // 2))
    docs = Path(args.docs)
    images_dir = docs / "images"
    host = machine()
    rows = []
    for name, prompt in SHOWCASE.items():
        imgs, times = run_chain(prompt, {k: v[0] for k, v in SIZES.items()})
        for stage in ("base_pano", "lineart", "stylize", "upscale", "detail"):
            img = 1.0 - imgs[stage] if stage == "lineart" else imgs[stage]
            write_preview(images_dir / f"pano-{name}-{stage}.png", img, width=args.preview_width)
        rows.append(("preview", prompt, times))
        print(prompt, {k: f"{v[0]:.2f}s" for k, v in times.items()}, flush=True)
    if args.paper:
        prompt = SHOWCASE["meadow-watercolor"]
        _, times = run_chain(prompt, {k: v[1] for k, v in SIZES.items()})
        rows.append(("paper", prompt, times))
        print("paper", prompt, {k: f"{v[0]:.2f}s" for k, v in times.items()}, flush=True)
    for prompt in DOZEN:
        rgb, _ = render_equirect(scene_from_prompt(prompt, 0), 512, 256, 2)
        write_preview(images_dir / f"dozen-{_slug(prompt)}.png", rgb, width=256)

    engines = {"base_pano": "procedural", "stylize": "classical", "upscale": "lanczos", "detail": "classical"}
    lines = [
        "# Panorama stages: default engine timings",
        "",
        f"Measured by `holoflow bench panorama{' --paper' if args.paper else ''}` on {host}; the "
        "machine was shared with other jobs, so wall time is inflated; CPU time is this process's own.",
        "",
        "| profile | prompt | stage (engine) | output size | wall s | CPU s |",
        "|---|---|---|---|---|---|",
    ]
    for profile, prompt, times in rows:
        for stage, (wall, cpu) in times.items():
            w, h = SIZES[stage][0 if profile == "preview" else 1]
            lines.append(f"| {profile} | {prompt} | {stage} ({engines[stage]}) | {w}x{h} | {wall:.2f} | {cpu:.2f} |")
    (docs / "bench-panorama.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {docs / 'bench-panorama.md'} and previews in {images_dir}")
    return 0
