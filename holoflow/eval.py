"""``holoflow eval``: score the two-stage reconstruction on procedural scenes, where truth is exact.

For each prompt (a procedural scene) and each variant (the full method and the paper's ablations) it
runs the pipeline in an evaluation profile (appearance stages neutral, so the panorama is the scene's
true appearance up to resampling) and scores G0 (pre_opt) and G1 (transfer_opt):

- ``base``: PSNR / SSIM at the base cameras against the PANO set (the paper's protocol);
- ``supp``: PSNR / SSIM at the supplementary cameras against true renders of the scene;
- ``novel``: PSNR / SSIM at seeded random cameras off the centre against true renders;
- ``empty``: fraction of pixels with rendered alpha < 0.5 at the supplementary and novel cameras;
- ``supp_nr``: the paper's rendering-robustness scores (Table II / III): NIQE and BRISQUE
  (holoflow.nriqa) of each model rendered at the scored supplementary cameras at ``--nr-size`` px
  (the paper's views are 512 px), means over the cameras;
- LPIPS, TReS, MANIQA: learned networks with no weights here, reported as unavailable (never
  approximated).

``--run RUN`` (a run id or ``latest``) scores any finished run, procedural or a user's own panorama
(``holoflow run ... --use base_pano=photo.jpg``): the truth-free part of the paper's protocol only
(base-camera PSNR / SSIM against the PANO set, NIQE / BRISQUE at the supplementary cameras).

Every report names the engines that made the depth (``depth_engines``): on procedural scenes that is
the ``simulated`` engine, which reads the scene's true depth, so no figure here is a learned
network's.

Images are compared in sRGB [0, 1] (the space Gaussians are trained in, holoflow.recon.views).
Variants: ``full``; ``no_depth_filter`` (point_cloud.grad_threshold = 1e6: no point is dropped; the
store's canonical JSON has no infinity); ``no_pcd_phase`` (pre_opt.pcd_iters = 0); ``no_pcd_and_filter`` (both); ``no_inp`` (transfer_opt.use_inp = false:
transfer on the PANO set only). The paper's Table III rows are full, w/o initial (= no_pcd_phase),
w/o filter (= no_depth_filter) and w/o initial & filter (= no_pcd_and_filter).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from holoflow.bench import machine

PROMPTS = ["a cozy wooden cabin at night", "a sunny beach with palm trees",
           "a modern living room with a sofa and a lamp", "a stone courtyard with a fountain"]
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
DEPTH_STAGES = ("base_pano", "tangent_depth", "metric_align")
MAX_OFFSET_M = 1.0      # novel cameras: at most this far from the centre (metres)
ROOT = Path(__file__).resolve().parent.parent      # the project: pipeline.yaml, default store artifacts/


def hidden_from_centre(scene, origins, dirs) -> "torch.Tensor":
    """[N] bool: the surface seen along each ray (origins [N, 3] m, unit dirs [N, 3], world) is
    hidden from the panorama centre (the world origin), i.e. the panorama never saw it.

    A finite hit X is hidden when the ray from the centre towards X stops more than 1 cm + 0.2 % of
    |X| short of it; a sky ray (no hit) is hidden when the centre's ray in the same direction hits
    something (sky is at infinity, so direction alone decides)."""
    import torch

    from holoflow.scene import cast

    t = cast(scene, origins, dirs)[1].double()                                  # [N]
    sky = ~torch.isfinite(t)
    x = origins.double() + torch.nan_to_num(t, posinf=0.0)[:, None] * dirs.double()   # [N, 3] hit points
    r = x.norm(dim=1)                                                           # [N] m from the centre
    u = torch.where(sky[:, None] | (r[:, None] < 1e-9), dirs.double(), x / r.clamp_min(1e-9)[:, None])
    tc = cast(scene, torch.zeros_like(u), u)[1].double()                         # [N]
    return torch.where(sky, torch.isfinite(tc), tc < r * (1 - 2e-3) - 1e-2)


def hidden_masks(scene, viewmats, K, width: int, height: int) -> "torch.Tensor":
    """Per pixel of each camera, whether its surface is hidden from the centre: [C, H, W] bool
    (pixel-centre rays; see ``hidden_from_centre``)."""
    import torch

    from holoflow.geometry.camera import pinhole_rays

    o, d = pinhole_rays(K.double(), viewmats.double(), height, width)           # [C, H, W, 3] each
    return hidden_from_centre(scene, o.reshape(-1, 3), d.reshape(-1, 3)).reshape(len(viewmats), height, width)


def novel_cameras(scene, n: int, offset: float, seed: int, K=None, candidates: int = 16,
                  probe: int = 16) -> "torch.Tensor":
    """n seeded novel cameras off the centre that look at what the panorama could not see, viewmats
    [n, 4, 4].

    Each eye lies along a random direction u at a uniform random fraction in [offset / 2, offset] of
    the free distance from the centre to the first surface along u (capped at MAX_OFFSET_M), so it is
    inside the scene's free space and really off the base cameras' position. Its view direction is
    the one of ``candidates`` seeded directions (uniform on the sphere) whose ``probe`` x ``probe``
    pixel view (intrinsics K [3, 3] rescaled; None = 90 deg field of view) shows the largest fraction
    of surface hidden from the centre (first candidate on ties): novel-view scores then measure the
    disocclusions the INP set exists for, not only surfaces the panorama already saw."""
    import torch

    from holoflow.geometry.camera import look_at
    from holoflow.scene import cast

    g = torch.Generator().manual_seed(seed)
    u = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=1)
    frac = (0.5 + 0.5 * torch.rand(n, generator=g, dtype=torch.float64)) * offset
    look = torch.nn.functional.normalize(torch.randn(n, candidates, 3, generator=g, dtype=torch.float64), dim=2)
    free = cast(scene, torch.zeros(n, 3), u.float())[1].double()                 # [n] metres (inf = sky)
    dist = torch.minimum(frac * torch.nan_to_num(free, posinf=1e9), torch.full_like(frac, MAX_OFFSET_M))
    eyes = u * dist[:, None]                                                     # [n, 3]
    Kp = torch.tensor([[probe / 2, 0, probe / 2], [0, probe / 2, probe / 2], [0, 0, 1]], dtype=torch.float64)
    if K is not None:
        Kp = square_K(K, probe).double()
    vms = look_at(eyes[:, None].expand(n, candidates, 3), eyes[:, None] + look)     # [n, candidates, 4, 4]
    hidden = hidden_masks(scene, vms.reshape(-1, 4, 4), Kp, probe, probe).flatten(1).double().mean(1)
    pick = hidden.reshape(n, candidates).argmax(1)                               # [n] first on ties
    return vms[torch.arange(n), pick].float()


def square_K(K, size: int) -> "torch.Tensor":
    """Pinhole K [3, 3] (pixels) for a size x size image with the field of view of K [3, 3], whose
    principal point is the centre of its image (width 2 cx, height 2 cy)."""
    import torch

    s = torch.tensor([size / (2 * float(K[0, 2])), size / (2 * float(K[1, 2])), 1.0], dtype=torch.float64)
    return (K.double() * s[:, None]).to(K.dtype)


def true_views(scene, viewmats, K, width: int, height: int, samples: int = 2,
               cache: dict | None = None) -> "torch.Tensor":
    """True sRGB renders [C, H, W, 3] of the procedural scene at pinhole cameras (``samples`` per
    pixel side, antialiased like the base panorama). ``cache`` maps camera bytes -> render, so
    variants that share cameras ray-cast each view once."""
    import torch

    from holoflow.recon.views import linear_to_srgb
    from holoflow.scene import render_pinhole

    cache = {} if cache is None else cache
    out = []
    for vm in viewmats:
        key = (scene.prompt, scene.seed, vm.numpy().tobytes(), K.numpy().tobytes(), width, height, samples)
        if key not in cache:
            cache[key] = torch.from_numpy(render_pinhole(scene, K.numpy(), vm.numpy(), width, height,
                                                         samples=samples)[0])
        out.append(cache[key])
    return linear_to_srgb(torch.stack(out))


def score(model, viewmats, K, targets, backend: str, hidden=None) -> tuple[dict, "torch.Tensor"]:
    """PSNR / SSIM / empty fraction of ``model`` rendered at the cameras
    against targets [C, H, W, 3] sRGB; with ``hidden`` [C, H, W] bool (surface hidden from the
    centre) also ``hidden_psnr`` (PSNR over those pixels only, pooled), ``hidden_frac`` (their share)
    and ``hidden_empty``. Returns (scores, renders [C, H, W, 3])."""
    from holoflow import metrics
    from holoflow.recon.schedule import render_views

    views = [dict(image=t, viewmat=vm, K=K) for t, vm in zip(targets, viewmats)]
    rgb, alpha = render_views(model, views, backend)
    out = dict(psnr=metrics.psnr(rgb, targets), ssim=metrics.ssim(rgb, targets),
               empty=metrics.empty_fraction(alpha))
    if hidden is not None:
        out.update(hidden_psnr=metrics.psnr(rgb, targets, hidden), hidden_frac=float(hidden.double().mean()),
                   hidden_empty=float(((alpha[..., 0] < 0.5) & hidden).double().sum() / max(int(hidden.sum()), 1)))
    return out, rgb


def nr_scores(model, viewmats, K, size: int, backend: str) -> dict:
    """The paper's rendering-robustness scores of ``model`` at cameras viewmats [C, 4, 4] with
    intrinsics K [3, 3] rescaled to size x size px (``square_K``): mean NIQE and BRISQUE over the C
    renders (sRGB), with their spread (min / max) and C. A score whose parameters are missing is
    None with the reason under ``unavailable``."""
    import torch

    from holoflow import metrics, nriqa
    from holoflow.recon.schedule import render_views

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


@dataclass
class Views:
    """Cameras to score a model at: viewmats [C, 4, 4] (world-to-camera), K [3, 3], targets [C, H, W, 3]
    sRGB; optionally hidden [C, H, W] bool (surface hidden from the centre, see ``score``)."""

    viewmats: "torch.Tensor"
    K: "torch.Tensor"
    targets: "torch.Tensor"
    hidden: "torch.Tensor | None" = None


MODELS = (("G0", "pre_opt", "gaussians.ply"), ("G1", "transfer_opt", "scene.ply"))


def pano_views(run_dir: Path) -> Views:
    """The base cameras of a run folder (runs/<id>/) with the PANO set as targets (the paper's
    Table II protocol; needs no truth)."""
    import torch

    from holoflow.recon.views import intrinsics, load_view_set

    views, cams = load_view_set(run_dir / "pano_set", alpha_is_mask=False)
    return Views(torch.stack([v["viewmat"] for v in views]), intrinsics(cams), torch.stack([v["image"] for v in views]))


def base_views(run_dir: Path) -> tuple["Scene", Views]:
    """The procedural scene of a run folder (runs/<id>/) and its base cameras (``pano_views``)."""
    from holoflow.scene.model import Scene

    scene_file = run_dir / "base_pano" / "scene.json"
    if not scene_file.is_file():
        raise SystemExit(f"eval: {scene_file} missing: eval needs the procedural base_pano engine (truth); "
                         "for a run without truth use `holoflow eval --run RUN`")
    return Scene.from_json(scene_file.read_text()), pano_views(run_dir)


def score_models(run_dir: Path, views: dict[str, Views], backend: str, nr: tuple | None = None
                 ) -> tuple[dict, dict]:
    """G0 (pre_opt) and G1 (transfer_opt) of a run folder scored at each view set (``score``), and
    with ``nr`` = (viewmats, K, size) the no-reference scores there (``nr_scores``, key supp_nr):
    ({tag: {gaussians, set name: scores}}, {tag: {set name: renders [C, H, W, 3]}})."""
    from holoflow.splat import GaussianModel

    result: dict = {}
    renders: dict = {}
    for tag, stage, file in MODELS:
        model = GaussianModel.load_ply(run_dir / stage / file)
        result[tag], renders[tag] = {"gaussians": len(model)}, {}
        for name, v in views.items():
            result[tag][name], renders[tag][name] = score(model, v.viewmats, v.K, v.targets, backend, v.hidden)
        if nr is not None:
            result[tag]["supp_nr"] = nr_scores(model, *nr, backend)
    return result, renders


def supp_cameras(run_dir: Path, supp: int, seed: int) -> tuple["torch.Tensor", "torch.Tensor"]:
    """A seeded subset of ``supp`` supplementary cameras (pcd_set; 0 = all): (viewmats [C, 4, 4]
    world-to-camera, K [3, 3] of the set's images)."""
    import torch

    from holoflow.recon.views import intrinsics, read_cameras

    cams = read_cameras(run_dir / "pcd_set")
    vm = torch.stack([torch.tensor(v["viewmat"], dtype=torch.float32).reshape(4, 4) for v in cams["views"]])
    if 0 < supp < len(vm):
        pick = torch.randperm(len(vm), generator=torch.Generator().manual_seed(seed))[:supp]
        vm = vm[pick.sort().values]
    return vm, intrinsics(cams)


def depth_engines(run_dir: Path) -> dict[str, str]:
    """stage -> what made it, for the stages that decide the depth (DEPTH_STAGES), from the run's
    run.json and the store's step records: the engine ("auto -> layout" where a chooser picked one),
    "used FILE" for a stage given by ``--use``, "unknown" where the record is missing."""
    from holoflow.status import chosen_engine
    from holoflow.store import Store

    store = Store(run_dir.parent.parent)                      # runs/<id> lies in the store's root
    stages = (store.run_info(run_dir.name) or {}).get("stages", {})
    out = {}
    for name in DEPTH_STAGES:
        st = stages.get(name) or {}
        rec = store.record(st["key"]) if st.get("key") else None
        if st.get("how") == "used":
            out[name] = f"used {Path(st.get('source') or '?').name}"
        elif rec is None:
            out[name] = "unknown"
        else:
            engine, chosen = rec["provenance"].get("engine"), chosen_engine(rec)
            picked = chosen["engine"] if chosen else None
            out[name] = f"{engine} -> {picked}" if picked and picked != engine else str(engine)
    return out


def evaluate_run(run_dir: Path, novel: int, offset: float, supp: int, seed: int, backend: str,
                 nr_size: int = 512, cache: dict | None = None) -> dict:
    """Scores of G0 and G1 of one pipeline run (folder runs/<id>/ with one folder per stage):
    ``novel`` random cameras, a seeded subset of ``supp`` supplementary cameras (0 = all), NIQE /
    BRISQUE at those supplementary cameras rendered at ``nr_size`` px (0 = skip)."""
    import torch

    scene, base = base_views(run_dir)
    K, h, w = base.K, int(base.targets.shape[1]), int(base.targets.shape[2])
    supp_vm, supp_K = supp_cameras(run_dir, supp, seed)
    novel_vm = novel_cameras(scene, novel, offset, seed, K)
    views = {"base": base}
    for name, vm in (("supp", supp_vm), ("novel", novel_vm)):
        views[name] = Views(vm, K, true_views(scene, vm, K, w, h, cache=cache), hidden_masks(scene, vm, K, w, h))
    result, renders = score_models(run_dir, views, backend, (supp_vm, supp_K, nr_size) if nr_size else None)
    result["engines"] = depth_engines(run_dir)
    result["_renders"] = {"truth": views["novel"].targets, "hidden": views["novel"].hidden,
                          **{tag: r["novel"] for tag, r in renders.items()}}
    return result


def evaluate_nr(run_dir: Path, supp: int, seed: int, backend: str, nr_size: int) -> dict:
    """Truth-free scores of a finished run (a user's own panorama included): per model G0 / G1, base
    PSNR / SSIM / empty against the PANO set and ``supp_nr`` (NIQE / BRISQUE at ``supp`` seeded
    supplementary cameras, ``nr_size`` px; 0 = skip), plus the engines that made the depth."""
    nr = (*supp_cameras(run_dir, supp, seed), nr_size) if nr_size else None
    result, _ = score_models(run_dir, {"base": pano_views(run_dir)}, backend, nr)
    result["engines"] = depth_engines(run_dir)
    return result


def open_store(store: Path | None) -> "Store":
    """The store at ``store``, else $HOLOFLOW_STORE, else artifacts/ beside pipeline.yaml (as the CLI)."""
    import os

    from holoflow.store import Store

    return Store(store or os.environ.get("HOLOFLOW_STORE") or (ROOT / "artifacts"))


def run_pipeline(prompt: str, profile: str, sets: list[str], store: Path | None) -> tuple[Path, dict]:
    """Run (or reuse from the cache) the pipeline for ``prompt``; returns (run folder, summary)."""
    import io

    from holoflow import pipeline
    from holoflow.progress import make_display
    from holoflow.runner import Context, Options, run

    pipe = pipeline.load(ROOT / "pipeline.yaml")
    st = open_store(store)
    opts = Options(prompt=prompt, profile=profile, sets=list(sets))
    ctx = Context.build(pipe, st, opts)
    summary = run(ctx, opts, make_display(io.StringIO(), fancy=False))
    return st.run_dir(summary["run"]), summary


def strip_image(renders: dict, k: int = 4) -> "np.ndarray":
    """A picture: rows truth / G0 / G1 at the first k novel cameras, uint8 [3 H, k W, 3] (sRGB)."""
    import numpy as np

    rows = [np.concatenate(list(renders[t][:k].numpy()), 1) for t in ("truth", "G0", "G1")]
    return (np.clip(np.concatenate(rows, 0), 0, 1) * 255 + 0.5).astype(np.uint8)


def _fmt(x) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return f"{x:.4f}" if abs(x) < 1.5 else f"{x:.2f}"


def markdown(results: dict, args, availability: dict, machine: str) -> str:
    """The report: per-scene table (full method) and the ablation table (means over scenes)."""
    lines = ["# Reconstruction evaluation (`holoflow eval`)", "",
             f"Profile `{args.profile}`, seed {args.seed}, {args.novel} novel cameras and {args.supp or 'all'} "
             f"supplementary cameras per scene, {args.repeats} training seed(s) per run (tables: means) (novel offset "
             f"<= {args.offset} of the free distance, <= {MAX_OFFSET_M} m), backend `{args.backend}`. "
             f"Machine: {machine}. Images compared in sRGB [0, 1]; `empty` = fraction of pixels with "
             "rendered alpha < 0.5. base = vs PANO set at the base cameras (paper protocol); supp / novel = "
             "vs true renders of the procedural scene; novel hidden_psnr = PSNR over the novel views' pixels "
             "whose surface the panorama centre could not see (hidden_frac of them). supp_nr = NIQE / BRISQUE "
             f"(holoflow.nriqa; lower is better) of the renders at the scored supplementary cameras, {args.nr_size} "
             "px square, mean over the cameras (the paper's rendering robustness).", "",
             "Optional metrics: " + "; ".join(f"{k}: {v}" for k, v in availability.items()), ""]
    lines += paper_tables(results)
    cols = [("base", "psnr"), ("base", "ssim"), ("supp", "psnr"), ("supp", "ssim"), ("supp", "empty"),
            ("novel", "psnr"), ("novel", "ssim"), ("novel", "empty"), ("novel", "hidden_psnr"),
            ("novel", "hidden_frac"), ("supp_nr", "niqe"), ("supp_nr", "brisque")]
    head = "| scene | model | gaussians | " + " | ".join(f"{a} {b}" for a, b in cols) + " | seconds |"
    lines += ["## Full method per scene", "", head, "|" + "---|" * (len(cols) + 4)]
    for prompt, per in results.items():
        r = per.get("full")
        if r is None:
            continue
        for tag in ("G0", "G1"):
            lines.append(f"| {prompt} | {tag} | {round(r[tag]['gaussians'])} | "
                         + " | ".join(_fmt(r[tag].get(a, {}).get(b)) for a, b in cols) + f" | {_fmt(r['seconds'])} |")
    lines += ["", "## G1 - G0 at the novel cameras", "",
              f"Novel-view PSNR in dB, mean over {args.repeats} training seed(s) (`train_seed` of pre_opt and "
              "transfer_opt; the scene, its panorama, depth and view sets are the same); min / max over the "
              "seeds; hidden = the same difference on the pixels the centre never saw.", "",
              "| scene | variant | seeds | G0 novel psnr | G1 novel psnr | G1 - G0 | min | max | G1 - G0 hidden |",
              "|---|---|---|---|---|---|---|---|---|"]
    for variant in VARIANTS:
        lines += gain_rows(results, variant)
    lines += ["", "## Ablations (G1, mean over scenes)", "",
              "| variant | " + " | ".join(f"{a} {b}" for a, b in cols) + " |", "|" + "---|" * (len(cols) + 1)]
    for variant in VARIANTS:
        rs = [per[variant]["G1"] for per in results.values() if variant in per]
        if not rs:
            continue
        means = [_mean([r.get(a, {}).get(b) for r in rs]) for a, b in cols]
        lines.append(f"| {variant} (n={len(rs)}) | " + " | ".join(_fmt(m) for m in means) + " |")
    if getattr(args, "images", None) is not None and getattr(args, "out", None) is not None:
        rel = Path(os.path.relpath(args.images, args.out.parent))
        lines += ["", "Pictures (rows truth / G0 / G1 at the first 4 novel cameras; full method, first training seed): "
                  + ", ".join(f"[{prompt}]({(rel / picture_name(prompt)).as_posix()})"
                              for prompt, per in results.items() if "full" in per)]
    return "\n".join(lines) + "\n"


def picture_name(prompt: str) -> str:
    """File name of a scene's truth / G0 / G1 picture in the ``--images`` folder."""
    return f"eval_{_slug(prompt)}.png"


def paper_tables(results: dict) -> list[str]:
    """Markdown: which engines made the depth, then the paper's Table II protocol (G1: base PSNR /
    SSIM vs the PANO set, NIQE / BRISQUE at the supplementary cameras) and Table III rows (G1 NIQE /
    BRISQUE per ablation), means over scenes, each beside the paper's printed value."""
    eng = sorted({", ".join(f"{k}={v}" for k, v in r.get("engines", {}).items())
                  for per in results.values() for r in per.values()})
    lines = ["## Depth engines", "", "Depth of these runs was made by: " + "; ".join(eng or ["unknown"]) + "."]
    if any("simulated" in e for e in eng):
        lines[-1] += (" The `simulated` engine reads the procedural scene's true depth and corrupts it like a "
                      "relative-depth network would (docs/depth.md): these figures are not a learned network's.")
    lines.append("")

    def mean(variant, a, b):
        return _mean([per[variant]["G1"].get(a, {}).get(b) for per in results.values() if variant in per])

    t2 = PAPER_TABLE2
    lines += ["## Table II protocol (G1, mean over scenes)", "",
              "| | base PSNR | base SSIM | LPIPS | supp NIQE | supp BRISQUE |", "|---|---|---|---|---|---|"]
    if any("full" in per for per in results.values()):
        lines.append(f"| holoflow (full, n={sum('full' in per for per in results.values())}) | "
                     f"{_fmt(mean('full', 'base', 'psnr'))} | {_fmt(mean('full', 'base', 'ssim'))} | unavailable | "
                     f"{_fmt(mean('full', 'supp_nr', 'niqe'))} | {_fmt(mean('full', 'supp_nr', 'brisque'))} |")
    lines += [f"| paper (Ours) | {t2['psnr']:.3f} | {t2['ssim']:.3f} | {t2['lpips']:.3f} | {t2['niqe']:.3f} | "
              f"{t2['brisque']:.3f} |", "",
              "## Table III ablations (G1 at the supplementary cameras, mean over scenes)", "",
              "| paper row | variant | NIQE | paper NIQE | BRISQUE | paper BRISQUE | TReS ours / paper | "
              "MANIQA ours / paper |", "|---|---|---|---|---|---|---|---|"]
    for variant, (row, niqe, bris, tres, maniqa) in PAPER_TABLE3.items():
        n = sum(variant in per for per in results.values())
        if n:
            lines.append(f"| {row} | {variant} (n={n}) | {_fmt(mean(variant, 'supp_nr', 'niqe'))} | {niqe:.3f} | "
                         f"{_fmt(mean(variant, 'supp_nr', 'brisque'))} | {bris:.3f} | unavailable / {tres:.3f} | "
                         f"unavailable / {maniqa:.3f} |")
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
        h = _mean([x["G1"]["novel"].get("hidden_psnr", math.nan) - x["G0"]["novel"].get("hidden_psnr", math.nan)
                   for x in r["repeats"]])
        rows.append(f"| {prompt} | {variant} | {len(d)} | {_fmt(r['G0']['novel']['psnr'])} | "
                    f"{_fmt(r['G1']['novel']['psnr'])} | {sum(d) / len(d):+.2f} | {min(d):+.2f} | {max(d):+.2f} | "
                    + (f"{h:+.2f}" if not math.isnan(h) else "-") + " |")
    return rows


def _mean(xs):
    xs = [x for x in xs if x is not None and not math.isnan(x)]
    return sum(xs) / len(xs) if xs else math.nan


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="holoflow eval", description=__doc__.split("\n\n")[0])
    p.add_argument("prompts", nargs="*", default=PROMPTS, help="procedural scenes (default: 4 built-in prompts)")
    p.add_argument("--profile", default="eval")
    p.add_argument("--set", dest="sets", action="append", default=[], help="stage.param=value, applied to every run")
    p.add_argument("--variants", default="all", help=f"comma list of {', '.join(VARIANTS)} (default all)")
    p.add_argument("--novel", type=int, default=24, help="random novel cameras per scene")
    p.add_argument("--offset", type=float, default=0.3, help="novel eye offset, max fraction of the free distance")
    p.add_argument("--supp", type=int, default=16, help="supplementary cameras scored per scene (seeded subset; 0 = all)")
    p.add_argument("--seed", type=int, default=0, help="seed of the novel and scored supplementary cameras")
    p.add_argument("--repeats", type=int, default=1,
                   help="train pre_opt and transfer_opt this many times (train_seed 0..N-1) on the same "
                        "upstream artifacts; tables show means, the G1 - G0 table the spread")
    p.add_argument("--backend", default="cpu", choices=["cpu", "reference", "gsplat"])
    p.add_argument("--store", type=Path, default=None)
    p.add_argument("--nr-size", type=int, default=512,
                   help="px side of the supplementary-camera renders scored by NIQE / BRISQUE (paper: 512; "
                        "NIQE needs >= 192; 0 = skip)")
    p.add_argument("--run", default=None,
                   help="score a finished run of the store (id or 'latest'; any base panorama, a photo given "
                        "by --use included) without truth: base PSNR / SSIM vs the PANO set and NIQE / BRISQUE "
                        "at the supplementary cameras, printed; no pipeline is run, prompts / --variants / "
                        "--out / --images are not used")
    p.add_argument("--out", type=Path, default=Path("docs/eval.md"), help="markdown report")
    p.add_argument("--json", type=Path, default=None, help="also write every number as JSON")
    p.add_argument("--images", type=Path, default=None,
                   help="folder for truth/G0/G1 pictures (default: images/ beside --out)")
    args = p.parse_args(argv)
    args.images = args.images if args.images is not None else args.out.parent / "images"
    variants = list(VARIANTS) if args.variants == "all" else args.variants.split(",")
    from holoflow.nriqa import NIQE_MIN_SIDE

    if args.nr_size and args.nr_size < NIQE_MIN_SIDE:
        print(f"holoflow eval: --nr-size must be 0 or >= {NIQE_MIN_SIDE} (NIQE's patch covariance needs 2 x 2 "
              "patches of 96 px)", file=sys.stderr)
        return 2
    if args.run:
        return main_run(args)
    if args.repeats < 1:
        print("holoflow eval: --repeats must be >= 1", file=sys.stderr)
        return 2
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        print(f"holoflow eval: unknown variant(s) {unknown}; choose from {list(VARIANTS)}", file=sys.stderr)
        return 2

    from holoflow import metrics
    from holoflow.recon.preview import write_png

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
                r = evaluate_run(run_dir, args.novel, args.offset, args.supp, args.seed, args.backend,
                                 args.nr_size, cache)
                renders = r.pop("_renders")
                r["seconds"] = time.monotonic() - t0
                runs.append(r)
                if variant == "full" and k == 0:
                    args.images.mkdir(parents=True, exist_ok=True)
                    write_png(args.images / picture_name(prompt), strip_image(renders))
                print(f"eval: {prompt!r} {variant} train_seed {k}: G0 novel {_fmt(r['G0']['novel']['psnr'])} dB, "
                      f"G1 novel {_fmt(r['G1']['novel']['psnr'])} dB, G1 base {_fmt(r['G1']['base']['psnr'])} dB",
                      file=sys.stderr)
            results[prompt][variant] = dict(mean_tree(runs), repeats=runs, engines=runs[0]["engines"],
                                            run=run_dir.name)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(results, args, metrics.availability(), machine()))
    if args.json:
        args.json.write_text(json.dumps(dict(results=results, paper=dict(table2=PAPER_TABLE2, table3=PAPER_TABLE3),
                                             availability=metrics.availability(), nr_size=args.nr_size),
                                        indent=1, sort_keys=True))
    print(f"eval: report in {args.out}", file=sys.stderr)
    return 0


def main_run(args) -> int:
    """``holoflow eval --run RUN``: print the truth-free scores of one finished run beside the
    paper's Table II values (and with --json write every number)."""
    from holoflow import metrics

    st = open_store(args.store)
    run_id = st.latest_run_id() if args.run == "latest" else args.run
    run_dir = st.run_dir(run_id) if run_id else None
    if run_dir is None or not (run_dir / "transfer_opt" / "scene.ply").is_file():
        print(f"holoflow eval: no finished run {args.run!r} (with transfer_opt/scene.ply) in {st.root}; "
              f"runs there: {', '.join(st.run_ids()[-5:]) or 'none'}", file=sys.stderr)
        return 2
    t0 = time.monotonic()
    r = evaluate_nr(run_dir, args.supp, args.seed, args.backend, args.nr_size)
    info = st.run_info(run_id) or {}
    r.update(run=run_id, prompt=info.get("prompt"), profile=info.get("profile"), seconds=time.monotonic() - t0,
             availability=metrics.availability(), paper=dict(table2=PAPER_TABLE2))
    t2 = PAPER_TABLE2
    print(f"run {run_id} ({info.get('profile')}), depth made by: "
          + ", ".join(f"{k}={v}" for k, v in r["engines"].items()))
    print(f"{'':8s}{'base PSNR':>10s}{'base SSIM':>10s}{'supp NIQE':>10s}{'BRISQUE':>10s}")
    for tag in ("G0", "G1"):
        b, n = r[tag]["base"], r[tag].get("supp_nr", {})
        print(f"{tag:8s}" + "".join(f"{_fmt(x):>10s}" for x in (b["psnr"], b["ssim"], n.get("niqe"), n.get("brisque"))))
    print(f"{'paper':8s}" + "".join(f"{x:>10}" for x in (t2["psnr"], t2["ssim"], t2["niqe"], t2["brisque"])))
    print(f"NIQE / BRISQUE: means over {r['G1'].get('supp_nr', {}).get('cameras', 0)} supplementary cameras "
          f"rendered at {args.nr_size} px; paper = its Table II (Ours); lower is better for both")
    if args.json:
        args.json.write_text(json.dumps(r, indent=1, sort_keys=True))
    return 0


def _slug(text: str) -> str:
    return "_".join("".join(c if c.isalnum() else " " for c in text.lower()).split())[:40]
