"""The eval report: the variants scored (the full method and the paper's ablations), the paper's own
numbers, and the markdown tables."""

from __future__ import annotations

import math
import os
from pathlib import Path

from holoflow.evaluation.cameras import MAX_OFFSET_M

VARIANTS = {
    "full": [],
    "no_depth_filter": ["point_cloud.grad_threshold=1000000.0"],
    "no_pcd_phase": ["pre_opt.pcd_iters=0"],
    "no_pcd_and_filter": ["pre_opt.pcd_iters=0", "point_cloud.grad_threshold=1000000.0"],
    "no_inp": ["transfer_opt.use_inp=false"],
}

# the paper's Table II (HoloDreamer row) and Table III (ablations), as printed in the paper
PAPER_TABLE2 = {"psnr": 40.189, "ssim": 0.984, "lpips": 0.041, "niqe": 5.372, "brisque": 32.372, "hours": 0.271}


PAPER_TABLE3 = {  # variant: (paper row name, NIQE, BRISQUE, TReS, MANIQA)
    "full": ("Full", 5.372, 32.372, 77.009, 0.402),
    "no_pcd_phase": ("w/o initial", 5.369, 32.598, 76.491, 0.399),
    "no_depth_filter": ("w/o filter", 5.441, 32.693, 76.990, 0.401),
    "no_pcd_and_filter": ("w/o initial & filter", 5.419, 32.625, 76.367, 0.398),
}


def _fmt(x) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return f"{x:.4f}" if abs(x) < 1.5 else f"{x:.2f}"


def markdown(results: dict, args, availability: dict, machine: str) -> str:
    """The report: per-scene table (full method) and the ablation table (means over scenes)."""
    lines = [
        "# Reconstruction evaluation (`holoflow eval`)",
        "",
        f"Profile `{args.profile}`, seed {args.seed}, {args.novel} novel cameras and {args.supp or 'all'} "
        f"supplementary cameras per scene, {args.repeats} training seed(s) per run (tables: means) (novel offset "
        f"<= {args.offset} of the free distance, <= {MAX_OFFSET_M} m), backend `{args.backend}`. "
        f"Machine: {machine}. Images compared in sRGB [0, 1]; `empty` = fraction of pixels with "
        "rendered alpha < 0.5. base = vs PANO set at the base cameras (paper protocol); supp / novel = "
        "vs true renders of the procedural scene; novel hidden_psnr = PSNR over the novel views' pixels "
        "whose surface the panorama centre could not see (hidden_frac of them). supp_nr = NIQE / BRISQUE "
        f"(holoflow.quality.nriqa; lower is better) of the renders at the scored supplementary cameras, {args.nr_size} "
        "px square, mean over the cameras (the paper's rendering robustness).",
        "",
        "Optional metrics: " + "; ".join(f"{k}: {v}" for k, v in availability.items()),
        "",
    ]
    lines += paper_tables(results)
    cols = [
        ("base", "psnr"),
        ("base", "ssim"),
        ("supp", "psnr"),
        ("supp", "ssim"),
        ("supp", "empty"),
        ("novel", "psnr"),
        ("novel", "ssim"),
        ("novel", "empty"),
        ("novel", "hidden_psnr"),
        ("novel", "hidden_frac"),
        ("supp_nr", "niqe"),
        ("supp_nr", "brisque"),
    ]
    head = "| scene | model | gaussians | " + " | ".join(f"{a} {b}" for a, b in cols) + " | seconds |"
    lines += ["## Full method per scene", "", head, "|" + "---|" * (len(cols) + 4)]
    for prompt, per in results.items():
        r = per.get("full")
        if r is None:
            continue
        for tag in ("G0", "G1"):
            lines.append(
                f"| {prompt} | {tag} | {round(r[tag]['gaussians'])} | "
                + " | ".join(_fmt(r[tag].get(a, {}).get(b)) for a, b in cols)
                + f" | {_fmt(r['seconds'])} |"
            )
    lines += [
        "",
        "## G1 - G0 at the novel cameras",
        "",
        f"Novel-view PSNR in dB, mean over {args.repeats} training seed(s) (`train_seed` of pre_opt and "
        "transfer_opt; the scene, its panorama, depth and view sets are the same); min / max over the "
        "seeds; hidden = the same difference on the pixels the centre never saw.",
        "",
        "| scene | variant | seeds | G0 novel psnr | G1 novel psnr | G1 - G0 | min | max | G1 - G0 hidden |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for variant in VARIANTS:
        lines += gain_rows(results, variant)
    lines += [
        "",
        "## Ablations (G1, mean over scenes)",
        "",
        "| variant | " + " | ".join(f"{a} {b}" for a, b in cols) + " |",
        "|" + "---|" * (len(cols) + 1),
    ]
    for variant in VARIANTS:
        rs = [per[variant]["G1"] for per in results.values() if variant in per]
        if not rs:
            continue
        means = [_mean([r.get(a, {}).get(b) for r in rs]) for a, b in cols]
        lines.append(f"| {variant} (n={len(rs)}) | " + " | ".join(_fmt(m) for m in means) + " |")
    if getattr(args, "images", None) is not None and getattr(args, "out", None) is not None:
        rel = Path(os.path.relpath(args.images, args.out.parent))
        lines += [
            "",
            "Pictures (rows truth / G0 / G1 at the first 4 novel cameras; full method, first training seed): "
            + ", ".join(
                f"[{prompt}]({(rel / picture_name(prompt)).as_posix()})"
                for prompt, per in results.items()
                if "full" in per
            ),
        ]
    return "\n".join(lines) + "\n"


def picture_name(prompt: str) -> str:
    """File name of a scene's truth / G0 / G1 picture in the ``--images`` folder."""
    return f"eval_{_slug(prompt)}.png"


def paper_tables(results: dict) -> list[str]:
    """Markdown: which engines made the depth, then the paper's Table II protocol (G1: base PSNR /
    SSIM vs the PANO set, NIQE / BRISQUE at the supplementary cameras) and Table III rows (G1 NIQE /
    BRISQUE per ablation), means over scenes, each beside the paper's printed value."""
    eng = sorted(
        {
            ", ".join(f"{k}={v}" for k, v in r.get("engines", {}).items())
            for per in results.values()
            for r in per.values()
        }
    )
    lines = ["## Depth engines", "", "Depth of these runs was made by: " + "; ".join(eng or ["unknown"]) + "."]
    if any("simulated" in e for e in eng):
        lines[-1] += (
            " The `simulated` engine reads the procedural scene's true depth and corrupts it like a "
            "relative-depth network would (docs/depth.md): these figures are not a learned network's."
        )
    lines.append("")

    def mean(variant, a, b):
        return _mean([per[variant]["G1"].get(a, {}).get(b) for per in results.values() if variant in per])

    t2 = PAPER_TABLE2
    lines += [
        "## Table II protocol (G1, mean over scenes)",
        "",
        "| | base PSNR | base SSIM | LPIPS | supp NIQE | supp BRISQUE |",
        "|---|---|---|---|---|---|",
    ]
    if any("full" in per for per in results.values()):
        lines.append(
            f"| holoflow (full, n={sum('full' in per for per in results.values())}) | "
            f"{_fmt(mean('full', 'base', 'psnr'))} | {_fmt(mean('full', 'base', 'ssim'))} | unavailable | "
            f"{_fmt(mean('full', 'supp_nr', 'niqe'))} | {_fmt(mean('full', 'supp_nr', 'brisque'))} |"
        )
    lines += [
        f"| paper (Ours) | {t2['psnr']:.3f} | {t2['ssim']:.3f} | {t2['lpips']:.3f} | {t2['niqe']:.3f} | "
        f"{t2['brisque']:.3f} |",
        "",
        "## Table III ablations (G1 at the supplementary cameras, mean over scenes)",
        "",
        "| paper row | variant | NIQE | paper NIQE | BRISQUE | paper BRISQUE | TReS ours / paper | "
        "MANIQA ours / paper |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for variant, (row, niqe, bris, tres, maniqa) in PAPER_TABLE3.items():
        n = sum(variant in per for per in results.values())
        if n:
            lines.append(
                f"| {row} | {variant} (n={n}) | {_fmt(mean(variant, 'supp_nr', 'niqe'))} | {niqe:.3f} | "
                f"{_fmt(mean(variant, 'supp_nr', 'brisque'))} | {bris:.3f} | unavailable / {tres:.3f} | "
                f"unavailable / {maniqa:.3f} |"
            )
    return lines + [""]


def mean_tree(trees: list[dict]) -> dict:
    """Leaf-wise mean of dicts with the same nested keys (numbers; NaN / None ignored, as ``_mean``)."""
    out = {}
    for k, v in trees[0].items():
        if isinstance(v, dict):
            out[k] = mean_tree([t[k] for t in trees])
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[k] = _mean([t[k] for t in trees])
    return out


def gain_rows(results: dict, variant: str) -> list[str]:
    """Table rows: per scene G1 - G0 novel-view PSNR over the repeats (mean, min, max) and on the
    hidden pixels (mean), for ``variant``."""
    rows = []
    for prompt, per in results.items():
        r = per.get(variant)
        if r is None:
            continue
        d = [x["G1"]["novel"]["psnr"] - x["G0"]["novel"]["psnr"] for x in r["repeats"]]
        h = _mean(
            [
                x["G1"]["novel"].get("hidden_psnr", math.nan) - x["G0"]["novel"].get("hidden_psnr", math.nan)
                for x in r["repeats"]
            ]
        )
        rows.append(
            f"| {prompt} | {variant} | {len(d)} | {_fmt(r['G0']['novel']['psnr'])} | "
            f"{_fmt(r['G1']['novel']['psnr'])} | {sum(d) / len(d):+.2f} | {min(d):+.2f} | {max(d):+.2f} | "
            + (f"{h:+.2f}" if not math.isnan(h) else "-")
            + " |"
        )
    return rows


def _mean(xs):
    xs = [x for x in xs if x is not None and not math.isnan(x)]
    return sum(xs) / len(xs) if xs else math.nan


def _slug(text: str) -> str:
    return "_".join("".join(c if c.isalnum() else " " for c in text.lower()).split())[:40]
