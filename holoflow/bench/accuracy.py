"""`holoflow bench accuracy`: what accuracy costs in time.

Sweeps the knobs that trade accuracy for time one at a time around a base point (the ``eval``
profile: appearance stages neutral, so the procedural scene's truth applies): panorama and depth
resolution, alignment grid, point density, number of base cameras, view resolution, iterations per
stage, densification on / off; plus the preview profile's sizes with neutral appearance.

Every point runs through the real runner against ONE shared store, so a point recomputes only the
stages its change reaches and a killed sweep resumes where it stopped. Per point:

- time: each stage's wall and CPU seconds from its run record (``provenance.wall_s / cpu_s``, the
  cost of computing it, also when this point was served from the cache), and their sum = what a
  fresh run of that configuration costs;
- accuracy: depth AbsRel / delta1 of metric_align against truth (``metric_align.json``); PSNR / SSIM
  of G0 (pre_opt) and G1 (transfer_opt) at the base cameras against the PANO set (the paper's
  protocol) and at seeded novel cameras off the centre against true renders (``holoflow.evaluation``),
  the novel cameras at one fixed size and field of view for every point, so points compare.

Writes a CSV (one row per point), a Pareto plot (time vs novel-view PSNR, time vs AbsRel) and the
paper profile's CPU time extrapolated from the measured per-stage scaling (``extrapolate``).
``--quick`` runs three points of the tiny profile (for tests).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from holoflow.bench.profiles import PHOTO_PROMPT, PHOTOS, SCENES, TRUTH_WAYS, named, stage_costs

PROMPT = "a cozy wooden cabin at night"
NEUTRAL = ["stylize.style=none", "detail.strength=0.0"]  # truth applies (the eval profile's choice)
STAGES = [
    "base_pano",
    "stylize",
    "upscale",
    "detail",
    "tangent_depth",
    "metric_align",
    "point_cloud",
    "pano_set",
    "pcd_set",
    "pre_opt",
    "inp_set",
    "transfer_opt",
]
SPLAT = ("pre_opt", "inp_set", "transfer_opt")
STORE = Path("/tmp/holoflow-bench-accuracy/store")


@dataclass(frozen=True)
class Point:
    """One sweep point: ``axis`` (the knob), ``label`` (its value) and the ``--set`` overrides."""

    name: str
    axis: str
    label: str
    sets: tuple[str, ...]
    profile: str = "eval"


def _iters(scale: float, profile: str = "eval") -> tuple[str, ...]:
    """Overrides scaling the profile's pre_opt and transfer_opt iteration counts by ``scale``."""
    p = resolved_params(profile, [])
    return (
        f"pre_opt.pcd_iters={round(p['pre_opt']['pcd_iters'] * scale)}",
        f"pre_opt.pano_iters={round(p['pre_opt']['pano_iters'] * scale)}",
        f"transfer_opt.iters={round(p['transfer_opt']['iters'] * scale)}",
    )


def _pano(width: int) -> tuple[str, ...]:
    return tuple(f"{s}.{k}={v}" for s in ("upscale", "detail") for k, v in (("width", width), ("height", width // 2)))


def _depth(width: int, face: int) -> tuple[str, ...]:
    return (f"tangent_depth.width={width}", f"tangent_depth.face_size={face}", f"metric_align.face_size={face}")


def full_points() -> list[Point]:
    """The real sweep around the eval profile (docs/accuracy.md), most informative first, so a sweep
    stopped early still covers every axis once."""
    off = ("pre_opt.densify_from=1000000", "transfer_opt.densify_from=1000000")
    return [
        Point("base", "base", "eval", ()),
        Point("iters-x0.25", "iterations", "x0.25", _iters(0.25)),
        Point("iters-x0.5", "iterations", "x0.5", _iters(0.5)),
        Point("points-128", "point density", "P_f 128", ("point_cloud.pf_width=128",)),
        Point("views-32", "view size", "32 px", ("pano_set.size=32",)),
        Point("no-densify", "densify", "off", off),
        Point("grid-2x2", "align grid", "2x2", ("tangent_depth.grid=[2, 2]",)),
        Point("depth-256", "depth res", "256 / face 64", _depth(256, 64)),
        Point("cameras-20", "base cameras", "20 @ 70 deg", ("pano_set.cameras=20", "pano_set.fov_deg=70")),
        Point("pano-512", "pano res", "512x256", _pano(512)),
        Point("preview", "profile", "preview (neutral)", tuple(NEUTRAL), profile="preview"),
        Point("iters-x2", "iterations", "x2", _iters(2)),
        Point("views-96", "view size", "96 px", ("pano_set.size=96",)),
        Point("grid-4x4", "align grid", "4x4", ("tangent_depth.grid=[4, 4]",)),
        Point("cameras-26", "base cameras", "26 @ 60 deg", ("pano_set.cameras=26", "pano_set.fov_deg=60")),
        Point("depth-1024", "depth res", "1024 / face 256", _depth(1024, 256)),
        Point("pano-2048", "pano res", "2048x1024", _pano(2048)),
        Point("points-512", "point density", "P_f 512", ("point_cloud.pf_width=512",)),
    ]


def quick_points() -> list[Point]:
    """Three tiny points: a base, fewer iterations (reuses every upstream stage), no densification."""
    return [
        Point("base", "base", "tiny", tuple(NEUTRAL), "tiny"),
        Point("iters-x0.5", "iterations", "x0.5", tuple(NEUTRAL) + _iters(0.5, "tiny"), "tiny"),
        Point(
            "no-densify",
            "densify",
            "off",
            tuple(NEUTRAL) + ("pre_opt.densify_from=1000000", "transfer_opt.densify_from=1000000"),
            "tiny",
        ),
    ]


# -- one point ------------------------------------------------------------------------------------
def novel_intrinsics(size: int, fov_deg: float):
    """Pinhole K [3, 3] of the fixed novel-view camera (pixel centres at +0.5)."""
    import torch

    from holoflow.geometry.camera import intrinsics_from_fov

    return intrinsics_from_fov(fov_deg, size, size, dtype=torch.float32)


def score_run(
    run_dir: Path, novel: int, novel_size: int, novel_fov: float, offset: float, seed: int, backend: str, cache: dict
) -> dict:
    """Accuracy of one run folder: depth truth metrics, then G0 / G1 PSNR / SSIM at the base cameras
    (vs the PANO set) and at ``novel`` seeded cameras (vs true renders, ``novel_size`` px square,
    ``novel_fov`` deg), scored by ``holoflow.evaluation``. Flat dict of floats."""
    from holoflow.evaluation.cameras import Views, base_views, novel_cameras, true_views
    from holoflow.evaluation.scores import score_models

    depth = json.loads((run_dir / "metric_align" / "metric_align.json").read_text()).get("truth_metrics", {})
    scene, base = base_views(run_dir)
    K = novel_intrinsics(novel_size, novel_fov)
    novel_vm = novel_cameras(scene, novel, offset, seed)  # [novel, 4, 4]
    novel_views = Views(novel_vm, K, true_views(scene, novel_vm, K, novel_size, novel_size, cache=cache))
    scores, _ = score_models(run_dir, {"base": base, "novel": novel_views}, backend)
    out = {"abs_rel": depth.get("abs_rel", math.nan), "delta1": depth.get("delta1", math.nan)}
    for tag, s in scores.items():
        t = tag.lower()
        out.update(
            {
                f"{t}_gaussians": s["gaussians"],
                f"{t}_base_psnr": s["base"]["psnr"],
                f"{t}_base_ssim": s["base"]["ssim"],
                f"{t}_novel_psnr": s["novel"]["psnr"],
                f"{t}_novel_ssim": s["novel"]["ssim"],
                f"{t}_novel_empty": s["novel"]["empty"],
            }
        )
    return out


def measure(point: Point, args, store_root: Path, cache: dict) -> tuple[dict, Path]:
    """Run (or serve from the store) one point and score it: (one CSV row, the run folder). The pipeline part holds
    ``args.lock`` (an flock shared with other timing runs); scoring does not."""
    from holoflow.evaluation.runs import run_pipeline
    from holoflow.flow.store import Store

    with _flock(args.lock):
        load = os.getloadavg()[0]
        t0 = time.monotonic()
        run_dir, summary = run_pipeline(args.prompt, point.profile, list(point.sets) + args.sets, store_root)
        run_s = time.monotonic() - t0
    costs = stage_costs(Store(store_root), summary)
    row = {
        "point": point.name,
        "axis": point.axis,
        "label": point.label,
        "profile": point.profile,
        "sets": " ".join(point.sets),
        "ran": " ".join(n for n, c in costs.items() if c["how"] == "ran"),
        "sweep_s": round(run_s, 2),
        "load1_before": round(load, 2),
        "load1_after": round(os.getloadavg()[0], 2),
    }
    row["total_wall_s"] = round(sum(c["wall_s"] for c in costs.values()), 2)
    row["total_cpu_s"] = round(sum(c["cpu_s"] for c in costs.values()), 2)
    for name in STAGES:
        row[f"{name}_s"] = costs.get(name, {}).get("wall_s", math.nan)
        row[f"{name}_cpu_s"] = costs.get(name, {}).get("cpu_s", math.nan)
    row.update(
        score_run(run_dir, args.novel, args.novel_size, args.novel_fov, args.offset, args.seed, args.backend, cache)
    )
    return row, run_dir


class _flock:
    """``with _flock(path)``: hold an exclusive flock on ``path`` (None = no lock)."""

    def __init__(self, path: Path | None):
        self.path, self.fd = path, None

    def __enter__(self):
        if self.path is not None:
            import fcntl

            self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
            fcntl.flock(self.fd, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc):
        if self.fd is not None:
            os.close(self.fd)  # closing releases the lock


# -- extrapolation --------------------------------------------------------------------------------
def stage_drivers(params: dict[str, dict]) -> dict[str, dict[str, float]]:
    """The work each stage's time grows with, from resolved params {stage: params}: per stage
    {driver name: amount}. Model (``fit_costs``): seconds = fixed + sum_k c_k * amount_k, the fixed
    part being process start, imports, JIT warm-up and file I/O. Panorama stages: output pixels; depth
    stages: tangent-face pixels + depth pixels; view sets: views x view pixels (+ panorama pixels,
    P_s points); optimisation stages: iterations, iterations x P_f points (~ initial Gaussians) and
    iterations x view pixels."""
    p = params
    pf = p["point_cloud"]["pf_width"] ** 2 / 2
    view_px = p["pano_set"]["size"] ** 2
    cams = p["pano_set"]["cameras"]
    depth_px = p["tangent_depth"]["width"] ** 2 / 2
    pixels = {n: p[n]["width"] * p[n]["height"] for n in ("base_pano", "stylize", "upscale", "detail")}
    iters = {
        "pre_opt": p["pre_opt"]["pcd_iters"] + p["pre_opt"]["pano_iters"],
        "transfer_opt": p["transfer_opt"]["iters"],
    }
    return {
        **{n: {"pixels": px} for n, px in pixels.items()},
        "tangent_depth": {"pixels": 20 * p["tangent_depth"]["face_size"] ** 2 + depth_px},
        "metric_align": {"pixels": p["metric_align"]["faces"] * p["metric_align"]["face_size"] ** 2 + depth_px},
        "point_cloud": {"points": p["point_cloud"]["p0_width"] ** 2 / 2},
        "pano_set": {"view pixels": cams * view_px, "pano pixels": pixels["detail"]},
        "pcd_set": {"view pixels": 4 * cams * view_px, "P_s points": p["point_cloud"]["ps_width"] ** 2 / 2},
        "inp_set": {"view pixels": 4 * cams * view_px, "P_f points": pf},
        **{
            n: {"iterations": it, "iterations x P_f points": it * pf, "iterations x view pixels": it * view_px}
            for n, it in iters.items()
        },
    }


def fit_costs(drivers: list[dict[str, float]], seconds: list[float]) -> dict:
    """Non-negative least squares of seconds = fixed + sum_k c_k * driver_k over the measured points.
    A driver that never varies over them cannot be told from the fixed part: it is left out and named
    in ``unvaried`` (its growth is then missing from an extrapolation). Returns {fixed, coef: {name:
    c}, unvaried: [names]}."""
    import numpy as np
    from scipy.optimize import nnls

    keep = [i for i, t in enumerate(seconds) if math.isfinite(t)]
    names = list(drivers[0])
    varied = [n for n in names if len({drivers[i][n] for i in keep}) > 1]
    A = np.array([[1.0] + [drivers[i][n] for n in varied] for i in keep])  # [points, 1 + K]
    y = np.array([seconds[i] for i in keep])
    scale = np.abs(A).max(0)  # conditioning
    sol, _ = nnls(A / scale, y)
    sol = sol / scale
    return {
        "fixed": float(sol[0]),
        "coef": {n: float(c) for n, c in zip(varied, sol[1:])},
        "unvaried": [n for n in names if n not in varied],
    }


def predict(fit: dict, drivers: dict[str, float]) -> float:
    """Seconds a ``fit_costs`` model predicts for one stage's drivers."""
    return fit["fixed"] + sum(c * drivers[n] for n, c in fit["coef"].items())


def extrapolate(rows: list[dict], drivers: list[dict], target: dict, key: str = "cpu_s") -> dict[str, dict]:
    """Per stage: ``fit_costs`` over the rows' stage times (column ``{stage}_{key}``), evaluated at the
    ``target`` drivers. {stage: {fixed, coef, unvaried, seconds, max_measured_s}}."""
    out = {}
    for name in STAGES:
        ys = [float(r[f"{name}_{key}"]) for r in rows]
        fit = fit_costs([d[name] for d in drivers], ys)
        out[name] = {
            **fit,
            "seconds": predict(fit, target[name]),
            "max_measured_s": max((y for y in ys if math.isfinite(y)), default=math.nan),
        }
    return out


def resolved_params(profile: str, sets: list[str]) -> dict[str, dict]:
    from holoflow.flow import pipeline

    pipe = pipeline.load(Path(__file__).resolve().parents[2] / "pipeline.yaml")
    return {n: r.params for n, r in pipeline.resolve(pipe, profile, sets).items()}


# -- outputs --------------------------------------------------------------------------------------
def pareto(points: list[tuple[float, float]], higher_better: bool) -> list[int]:
    """Indices of the points no other point beats in both time (lower) and score; sorted by time."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], -points[i][1] if higher_better else points[i][1]))
    front, best = [], -math.inf
    for i in order:
        s = points[i][1] if higher_better else -points[i][1]
        if s > best:
            front.append(i)
            best = s
    return front


def write_csv(path: Path, rows: list[dict]) -> None:
    keys = list(rows[0])
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()})


def plot(rows: list[dict], path: Path, machine: str, time_key: str, paper_s: float | None) -> None:
    """Two panels: fresh-run time (``time_key`` column, seconds) vs G1 novel-view PSNR and vs depth
    AbsRel, one colour per swept knob, Pareto fronts dashed, the paper's sizes as a vertical line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5), dpi=100)
    axis_names = list(dict.fromkeys(r["axis"] for r in rows))
    colors = {a: plt.cm.tab10(i % 10) for i, a in enumerate(axis_names)}
    for ax, key, better, ylabel in (
        (axes[0], "g1_novel_psnr", True, "G1 novel-view PSNR, dB (higher is better)"),
        (axes[1], "abs_rel", False, "depth AbsRel vs truth (lower is better)"),
    ):
        pts = [(float(r[time_key]), float(r[key])) for r in rows]
        for r, (x, y) in zip(rows, pts):
            star = r["axis"] in ("base", "profile")
            ax.scatter([x], [y], color=colors[r["axis"]], s=90 if star else 30, marker="*" if star else "o", zorder=3)
            if star or key != "abs_rel" or r["abs_rel"] != rows[0]["abs_rel"]:  # depth-neutral knobs overlap
                ax.annotate(r["point"], (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
        front = pareto(pts, better)
        ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "k--", lw=1)
        ax.set_xscale("log")
        xs = [x for x, _ in pts]
        if paper_s and paper_s > 20 * max(xs):  # far off the measured range: point at it
            ax.set_xlim(min(xs) / 1.5, max(xs) * 3)
            ax.annotate(
                f"paper sizes: ~{paper_s / 3600:.0f} CPU h here\n(extrapolated; accuracy not measured) ->",
                (1.0, 0.02),
                xycoords="axes fraction",
                fontsize=7,
                ha="right",
                color="grey",
            )
        elif paper_s:
            ax.axvline(paper_s, color="grey", lw=1, ls=":")
            ax.annotate(
                "paper sizes (time extrapolated,\naccuracy not measured)",
                (paper_s, 0.5),
                xycoords=("data", "axes fraction"),
                fontsize=7,
                ha="right",
                xytext=(-4, 0),
                textcoords="offset points",
            )
        what = "CPU" if "cpu" in time_key else "wall"
        ax.set_xlabel(f"{what} seconds of a fresh run (sum over the stages' run records; log scale)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
    handles = [
        plt.Line2D([], [], marker="*" if a in ("base", "profile") else "o", ls="", color=colors[a], label=a)
        for a in axis_names
    ]
    axes[0].legend(handles=handles + [plt.Line2D([], [], ls="--", color="k", label="Pareto front")], fontsize=7)
    fig.suptitle(f"holoflow bench accuracy, '{rows[0]['prompt']}', machine: {machine}", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, metadata={"Software": None})
    plt.close(fig)


def plot_stages(rows: list[dict], path: Path, machine: str) -> None:
    """Horizontal stacked bars: CPU seconds of each stage (from its run record) per point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 0.32 * len(rows) + 1.6), dpi=100)
    left = [0.0] * len(rows)
    for i, name in enumerate(STAGES):
        widths = [float(r[f"{name}_cpu_s"]) for r in rows]
        ax.barh(range(len(rows)), widths, left=left, color=plt.cm.tab20(i % 20), label=name)
        left = [a + b for a, b in zip(left, widths)]
    ax.set_yticks(range(len(rows)), [r["point"] for r in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("CPU seconds of a fresh run, per stage (run records)")
    ax.set_title(f"Where the time goes - machine: {machine}", fontsize=9)
    ax.legend(fontsize=7, ncol=4, loc="lower right")
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    fig.savefig(path, metadata={"Software": None})
    plt.close(fig)


def paper_estimate(rows: list[dict], points: list[Point], key: str) -> dict:
    """Seconds (``key``: cpu_s or wall_s column) of the paper profile's sizes on this machine with the
    measured engines, extrapolated stage by stage from the rows (``extrapolate``)."""
    drivers = [stage_drivers(resolved_params(p.profile, list(p.sets))) for p in points]
    target = stage_drivers(resolved_params("paper", []))
    per = extrapolate(rows, drivers, target, key)
    return {"stages": per, "total_s": sum(v["seconds"] for v in per.values())}


def _f(x, digits: int = 2) -> str:
    x = float(x)
    return "-" if math.isnan(x) else f"{x:.{digits}f}"


def tables(rows: list[dict], paper: dict | None, machine: str) -> str:
    """Markdown: the points (time and accuracy), CPU seconds per stage, and the paper extrapolation."""
    out = [
        f"Machine: {machine}. Prompt: *{rows[0]['prompt']}*. Times are the stages' run records "
        "(CPU = user + system seconds of the step process; wall under the load shown).",
        "",
        "| point | knob | value | fresh run CPU s | wall s | load | AbsRel | delta1 | G0 base PSNR | "
        "G1 base PSNR | G1 base SSIM | G0 novel PSNR | G1 novel PSNR | G1 novel SSIM | G1 Gaussians | recomputed |",
        "|" + "---|" * 16,
    ]
    for r in rows:
        out.append(
            f"| {r['point']} | {r['axis']} | {r['label']} | {_f(r['total_cpu_s'], 1)} | "
            f"{_f(r['total_wall_s'], 1)} | {_f(r['load1_before'], 1)} | {_f(r['abs_rel'], 4)} | "
            f"{_f(r['delta1'], 4)} | {_f(r['g0_base_psnr'])} | {_f(r['g1_base_psnr'])} | "
            f"{_f(r['g1_base_ssim'], 4)} | {_f(r['g0_novel_psnr'])} | {_f(r['g1_novel_psnr'])} | "
            f"{_f(r['g1_novel_ssim'], 4)} | "
            f"{r['g1_gaussians']} | {r['ran'] or '(all cached)'} |"
        )
    out += [
        "",
        "CPU seconds per stage (from the run records):",
        "",
        "| point | " + " | ".join(STAGES) + " |",
        "|" + "---|" * (len(STAGES) + 1),
    ]
    for r in rows:
        out.append(f"| {r['point']} | " + " | ".join(_f(r[f"{n}_cpu_s"], 1) for n in STAGES) + " |")
    if paper:
        out += [
            "",
            f"Paper sizes on this machine, extrapolated (total {_f(paper['total_s'] / 3600, 1)} CPU hours):",
            "",
            "| stage | fixed s | per-unit costs (s) | drivers that never varied | measured max s | extrapolated s |",
            "|---|---|---|---|---|---|",
        ]
        for n, v in paper["stages"].items():
            coef = ", ".join(f"{k}: {c:.3g}" for k, c in v["coef"].items()) or "-"
            out.append(
                f"| {n} | {_f(v['fixed'], 1)} | {coef} | {', '.join(v['unvaried']) or '-'} | "
                f"{_f(v['max_measured_s'], 1)} | {_f(v['seconds'], 0)} |"
            )
    return "\n".join(out) + "\n"


def stage_pictures(run_dir: Path, folder: Path, prefix: str = "accuracy-base") -> list[Path]:
    """Pictures of one run's intermediate artifacts for the docs (``{prefix}-*.png`` in ``folder``):
    depth (disparity, metric depth, truth), the 20 aligned tangent faces, P_f and the final scene's
    centres (cut-away bird's-eye view), and the view sets (PANO, PCD with missing pixels in magenta,
    INP, G0 renders). Uses the run report's picture helpers (holoflow.report)."""
    import numpy as np

    from holoflow.io.exr import read_exr
    from holoflow.report import clouds
    from holoflow.report.pictures import colour, colour_map, depth_map, encode, fit_width, mosaic

    def save(name: str, img) -> Path:
        path = folder / f"{prefix}-{name}.png"
        path.write_bytes(encode(img))
        return path

    def ch(path: Path, name: str):
        return read_exr(path)[0][name]

    def rgb(path: Path):
        chans = read_exr(path)[0]
        return colour(np.stack([chans[c] for c in "RGB"], -1)), chans

    folder.mkdir(parents=True, exist_ok=True)
    depth = [
        colour_map(ch(run_dir / "tangent_depth" / "disparity.exr", "Y")),
        depth_map(ch(run_dir / "metric_align" / "depth.exr", "Z")),
        depth_map(ch(run_dir / "base_pano" / "pano.exr", "Z")),
    ]
    width = min(d.shape[1] for d in depth)
    gap = np.full((4, width, 3), 255, np.uint8)
    rows = [fit_width(d, width) for d in depth]
    out = [save("depth", np.concatenate([rows[0], gap, rows[1], gap, rows[2]], 0))]
    faces = sorted((run_dir / "tangent_depth" / "faces").glob("face_*.exr"))
    out.append(save("faces", mosaic([colour_map(ch(f, "aligned.Y")) for f in faces], 10, 96)))
    pictures = [
        clouds.render_zbuffer(*clouds.read_cloud(run_dir / stage / file), size=(480, 300))
        for stage, file in (("point_cloud", "pf.ply"), ("transfer_opt", "scene.ply"))
    ]
    out.append(save("clouds", np.concatenate([pictures[0], np.full((300, 4, 3), 255, np.uint8), pictures[1]], 1)))
    tiles = [rgb(run_dir / "pano_set" / "views" / f"{i:03d}.exr")[0] for i in range(6)]
    supp = [f"{b:03d}_{k}" for b in (0, 1) for k in range(4)][:6]  # 4 per base camera
    for sub in ("pcd_set/views", "inp_set/renders", "inp_set/views"):
        for name in supp:
            img, chans = rgb(run_dir / sub / f"{name}.exr")
            if sub == "pcd_set/views":
                img[chans["A"] < 0.5] = (255, 0, 255)  # missing pixels
            tiles.append(img)
    return out + [save("views", mosaic(tiles, 6, 96))]


def main(argv: list[str] | None = None) -> int:
    from holoflow.evaluation.machine import machine

    ap = argparse.ArgumentParser(prog="holoflow bench accuracy", description=__doc__.split("\n\n")[0])
    ap.add_argument("--prompt", default=PROMPT, help="procedural scene")
    ap.add_argument(
        "--store", type=Path, default=STORE, help="shared store of the sweep (the same store again resumes / reuses)"
    )
    ap.add_argument("--points", default="all", help="comma list of point names (default all)")
    ap.add_argument("--set", dest="sets", action="append", default=[], help="stage.param=value for every point")
    ap.add_argument("--novel", type=int, default=8, help="novel cameras")
    ap.add_argument("--novel-size", type=int, default=64, help="novel view side, px (same for every point)")
    ap.add_argument("--novel-fov", type=float, default=60.0, help="novel view field of view, deg")
    ap.add_argument("--offset", type=float, default=0.3, help="novel eye offset, max fraction of the free distance")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--backend", default="cpu", choices=["cpu", "reference", "gsplat"])
    ap.add_argument(
        "--lock",
        type=Path,
        default=None,
        help="flock held while each point's pipeline runs (e.g. /tmp/holoflow-bench.lock)",
    )
    ap.add_argument(
        "--time",
        dest="time_key",
        default="total_cpu_s",
        choices=["total_cpu_s", "total_wall_s"],
        help="time axis of the plot (CPU seconds are robust to a shared machine's load)",
    )
    ap.add_argument("--csv", type=Path, default=Path("docs/bench-accuracy.csv"))
    ap.add_argument("--plot", type=Path, default=Path("docs/images/accuracy-pareto.png"))
    ap.add_argument("--json", type=Path, default=None, help="also write rows + paper extrapolation as JSON")
    ap.add_argument("--tables", type=Path, default=None, help="also write the results as markdown tables")
    ap.add_argument(
        "--pictures",
        type=Path,
        default=None,
        help="folder for pictures of the first point's artifacts (accuracy-base-*.png)",
    )
    ap.add_argument("--quick", action="store_true", help="three tiny points (tests)")
    ap.add_argument(
        "--profiles",
        default=None,
        help="comma list of profiles (e.g. preview,quality,paper): instead of the knob sweep, run each "
        "on --scenes and --photos and score it at the viewing size (holoflow.bench.profiles); "
        "a profile the pipeline lacks or that needs a GPU / weights absent here is skipped",
    )
    ap.add_argument("--scenes", default=";".join(SCENES), help="--profiles: procedural prompts, ';'-separated")
    ap.add_argument(
        "--photos",
        default=str(PHOTOS),
        help="--profiles: folder of 360 photos, each run as --use base_pano=PHOTO ('' = none)",
    )
    ap.add_argument("--photo-prompt", default=PHOTO_PROMPT, help="--profiles: the prompt of the photo runs")
    ap.add_argument(
        "--truth",
        default="",
        help="--profiles: a truth set folder (docs/truth-sets.md; e.g. "
        "../shared/data/truth/grey_white_room) run --truth-ways ways and scored per ring (skipped "
        "with a note when absent)",
    )
    ap.add_argument(
        "--scene-truth",
        action="store_true",
        help="--profiles: also score each procedural scene against a truth set ray cast from it "
        "(512 px views on rings 0 / 0.25 / 0.5 / 1 m, kept in the store's truth/ folder)",
    )
    ap.add_argument(
        "--truth-ways",
        default=None,
        help=f"--profiles / --walk: comma list of {', '.join(TRUTH_WAYS)}: exact depth, the simulated network's "
        "depth, RGB only (default: all three for --profiles, exact for --walk)",
    )
    ap.add_argument(
        "--walk",
        action="store_true",
        help="instead of the knob sweep, the knobs that buy accuracy off the centre, one at a time around "
        "--walk-profile, on the --truth set, scored per ring with their seconds (holoflow.bench.walking; "
        "--points picks some)",
    )
    ap.add_argument("--walk-profile", default="preview", help="--walk: the profile the knobs are turned around")
    ap.add_argument("--size", type=int, default=512, help="--profiles: viewing size, px")
    ap.add_argument("--fov", type=float, default=47.43, help="--profiles: viewing field of view, deg")
    ap.add_argument("--nr-cameras", type=int, default=12, help="--profiles: cameras NIQE / BRISQUE are taken at")
    ap.add_argument(
        "--doc",
        type=Path,
        default=None,
        help="--profiles: markdown file whose generated block (between markers) gets the table",
    )
    args = ap.parse_args(argv)
    if args.walk:
        from holoflow.bench import walking

        args.store = args.store if args.store != STORE else STORE.with_name("store-walk")
        args.truth_ways = args.truth_ways or "exact"
        return walking.run(args)
    args.truth_ways = args.truth_ways or ",".join(TRUTH_WAYS)
    if args.profiles:
        from holoflow.bench import profiles

        args.store = args.store if args.store != STORE else STORE.with_name("store-profiles")
        if args.pictures is None and args.doc:
            args.pictures = args.doc.parent / "images"
        return profiles.run(args)
    if args.quick:
        args.novel, args.novel_size = min(args.novel, 2), min(args.novel_size, 16)
    points = named(quick_points() if args.quick else full_points(), args.points, "holoflow bench accuracy")
    if points is None:
        return 2

    mach = machine()
    rows, cache, paper = [], {}, None
    for i, p in enumerate(points):
        row, run_dir = measure(p, args, args.store, cache)
        if i == 0 and args.pictures:
            stage_pictures(run_dir, args.pictures)
        row["prompt"] = args.prompt
        rows.append(row)
        print(
            f"accuracy: {p.name:12s} ran [{row['ran']}] fresh run {row['total_cpu_s']:.1f} CPU-s "
            f"({row['total_wall_s']:.1f} s wall), AbsRel {row['abs_rel']:.4f}, G1 novel "
            f"{row['g1_novel_psnr']:.2f} dB, base {row['g1_base_psnr']:.2f} dB (load {row['load1_before']})",
            file=sys.stderr,
            flush=True,
        )
        # a stopped sweep still leaves its rows and plot
        write_csv(args.csv, rows)
        paper = paper_estimate(rows, points[: i + 1], args.time_key[6:]) if len(rows) > 1 else None
        plot(rows, args.plot, mach, args.time_key, paper["total_s"] if paper else None)
        plot_stages(rows, args.plot.with_name(args.plot.stem + "-stages.png"), mach)
        if args.tables:
            args.tables.write_text(tables(rows, paper, mach))
        if args.json:
            args.json.write_text(json.dumps({"machine": mach, "rows": rows, "paper": paper}, indent=1, default=str))
    print(
        f"accuracy: {len(rows)} points; CSV {args.csv}, plot {args.plot}"
        + (f"; paper sizes extrapolated to {paper['total_s']:.0f} s on this machine" if paper else ""),
        file=sys.stderr,
    )
    return 0
