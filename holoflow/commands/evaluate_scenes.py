"""``holoflow eval scenes [PROMPT ...]``: score the two-stage reconstruction on procedural scenes, where truth
is exact (the paper's tables).

For each prompt (a procedural scene) and each variant (the full method and the paper's ablations) it
runs the pipeline in an evaluation profile (appearance stages neutral, so the panorama is the scene's
true appearance up to resampling) and scores G0 (pre_opt) and G1 (transfer_opt):

- ``base``: PSNR / SSIM at the base cameras against the PANO set (the paper's protocol);
- ``supp``: PSNR / SSIM at the supplementary cameras against true renders of the scene;
- ``novel``: PSNR / SSIM at seeded random cameras off the centre against true renders;
- ``empty``: fraction of pixels with rendered alpha < 0.5 at the supplementary and novel cameras;
- ``supp_nr``: the paper's rendering-robustness scores (Table II / III): NIQE and BRISQUE
  (holoflow.quality.nriqa) of each model rendered at the scored supplementary cameras at ``--nr-size`` px
  (the paper's views are 512 px), means over the cameras;
- LPIPS, TReS, MANIQA: learned networks with no weights here, reported as unavailable (never
  approximated).

Every report names the engines that made the depth (``depth_engines``): on procedural scenes that is
the ``simulated`` engine, which reads the scene's true depth, so no figure here is a learned
network's.

Images are compared in sRGB [0, 1] (the space Gaussians are trained in, holoflow.recon.views).
Variants: ``full``; ``no_depth_filter`` (point_cloud.grad_threshold = 1e6: no point is dropped; the
store's canonical JSON has no infinity); ``no_pcd_phase`` (pre_opt.pcd_iters = 0); ``no_pcd_and_filter`` (both);
``no_inp`` (transfer_opt.use_inp = false:
transfer on the PANO set only). The paper's Table III rows are full, w/o initial (= no_pcd_phase),
w/o filter (= no_depth_filter) and w/o initial & filter (= no_pcd_and_filter).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from holoflow.evaluation.machine import machine
from holoflow.evaluation.runs import run_pipeline
from holoflow.evaluation.scores import evaluate_run, strip_image
from holoflow.evaluation.tables import PAPER_TABLE2, PAPER_TABLE3, VARIANTS, _fmt, markdown, mean_tree, picture_name

PROMPTS = [
    "a cozy wooden cabin at night",
    "a sunny beach with palm trees",
    "a modern living room with a sofa and a lamp",
    "a stone courtyard with a fountain",
]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="holoflow eval scenes",
        description=__doc__.split("\n\n")[0],
        epilog="A finished run (a photo included) is scored by `holoflow eval run RUN`.",
    )
    p.add_argument("prompts", nargs="*", default=PROMPTS, help="procedural scenes (default: 4 built-in prompts)")
    p.add_argument("--profile", default="eval")
    p.add_argument("--set", dest="sets", action="append", default=[], help="stage.param=value, applied to every run")
    p.add_argument("--variants", default="all", help=f"comma list of {', '.join(VARIANTS)} (default all)")
    p.add_argument("--novel", type=int, default=24, help="random novel cameras per scene")
    p.add_argument("--offset", type=float, default=0.3, help="novel eye offset, max fraction of the free distance")
    p.add_argument(
        "--supp", type=int, default=16, help="supplementary cameras scored per scene (seeded subset; 0 = all)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the novel and scored supplementary cameras")
    p.add_argument(
        "--repeats",
        type=int,
        default=1,
        help="train pre_opt and transfer_opt this many times (train_seed 0..N-1) on the same "
        "upstream artifacts; tables show means, the G1 - G0 table the spread",
    )
    p.add_argument("--backend", default="cpu", choices=["cpu", "reference", "gsplat"])
    p.add_argument("--store", type=Path, default=None)
    p.add_argument(
        "--nr-size",
        type=int,
        default=512,
        help="px side of the supplementary-camera renders scored by NIQE / BRISQUE (paper: 512; "
        "NIQE needs >= 192; 0 = skip)",
    )
    p.add_argument("--out", type=Path, default=Path("eval.md"), help="markdown report (default ./eval.md)")
    p.add_argument("--json", type=Path, default=None, help="also write every number as JSON")
    p.add_argument(
        "--images", type=Path, default=None, help="folder for truth/G0/G1 pictures (default: images/ beside --out)"
    )
    args = p.parse_args(argv)
    args.images = args.images if args.images is not None else args.out.parent / "images"
    variants = list(VARIANTS) if args.variants == "all" else args.variants.split(",")
    from holoflow.quality.nriqa import NIQE_MIN_SIDE

    if args.nr_size and args.nr_size < NIQE_MIN_SIDE:
        print(
            f"holoflow eval: --nr-size must be 0 or >= {NIQE_MIN_SIDE} (NIQE's patch covariance needs 2 x 2 "
            "patches of 96 px)",
            file=sys.stderr,
        )
        return 2
    if args.repeats < 1:
        print("holoflow eval: --repeats must be >= 1", file=sys.stderr)
        return 2
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        print(f"holoflow eval: unknown variant(s) {unknown}; choose from {list(VARIANTS)}", file=sys.stderr)
        return 2

    from holoflow.io.image import write_png
    from holoflow.quality import metrics

    results: dict = {}
    cache: dict = {}
    for prompt in args.prompts:
        results[prompt] = {}
        for variant in variants:
            runs = []
            for k in range(args.repeats):
                t0 = time.monotonic()
                seeds = [f"pre_opt.train_seed={k}", f"transfer_opt.train_seed={k}"] if k else []
                run_dir, _ = run_pipeline(prompt, args.profile, args.sets + VARIANTS[variant] + seeds, args.store)
                r = evaluate_run(
                    run_dir, args.novel, args.offset, args.supp, args.seed, args.backend, args.nr_size, cache
                )
                renders = r.pop("_renders")
                r["seconds"] = time.monotonic() - t0
                runs.append(r)
                if variant == "full" and k == 0:
                    args.images.mkdir(parents=True, exist_ok=True)
                    write_png(args.images / picture_name(prompt), strip_image(renders))
                print(
                    f"eval: {prompt!r} {variant} train_seed {k}: G0 novel {_fmt(r['G0']['novel']['psnr'])} dB, "
                    f"G1 novel {_fmt(r['G1']['novel']['psnr'])} dB, G1 base {_fmt(r['G1']['base']['psnr'])} dB",
                    file=sys.stderr,
                )
            results[prompt][variant] = dict(mean_tree(runs), repeats=runs, engines=runs[0]["engines"], run=run_dir.name)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(results, args, metrics.availability(), machine()))
    if args.json:
        args.json.write_text(
            json.dumps(
                dict(
                    results=results,
                    paper=dict(table2=PAPER_TABLE2, table3=PAPER_TABLE3),
                    availability=metrics.availability(),
                    nr_size=args.nr_size,
                ),
                indent=1,
                sort_keys=True,
            )
        )
    print(f"eval: report in {args.out}", file=sys.stderr)
    return 0
