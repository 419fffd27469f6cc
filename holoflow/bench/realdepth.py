"""`holoflow bench realdepth`: depth accuracy on real panoramas with measured depth, through the
default pipeline.

Every item of ``--data`` (default ``../shared/data/realdepth``, see its README: ``NAME_rgb.png`` +
``NAME_depth.exr`` with a ``truth.scale`` header) is run as a user would run it:
``holoflow run "a room" --use base_pano=NAME_rgb.png --until metric_align`` in a scratch store, once
with the default engines (``auto`` -> ``layout`` on a photo) and once with the constant ``prior``
baseline (``--set tangent_depth.engine=prior --set metric_align.engine=prior``); the metric_align
output (what point_cloud reads) is scored against the truth: ``metric`` items as they are,
``relative`` items after a median scale fit, ``ordinal`` items after a median scale fit too (order
and shape only: read with care). Procedural scenes (``--prompts``) are run the same way, scored on
their own truth (default engine there: ``auto`` -> simulated; plus ``layout`` forced).

The layout estimate is sensitive to resampling (docs/depth-layout.md, round 5), so each item's figure
carries noise: ``--turns N`` (default 4) also runs the layout engine straight on the panorama it
receives in that run (the detail output at the depth's width), turned about the vertical axis by
i x 45 / N degrees (i < N; a multiple of 90 degrees is an exact symmetry, 45 the view spacing), and
reports the spread of its AbsRel over the turns: a change smaller than that spread is noise.
Writes docs/bench-realdepth.md and docs/images/realdepth-*.png. Skips with a message when the data
folder is absent.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from holoflow.evaluation.machine import load, machine

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "realdepth"
PROMPTS = ("a cozy living room with a sofa and a lamp", "a sunny meadow with trees")
ENGINES = {"prior": ["--set", "tangent_depth.engine=prior", "--set", "metric_align.engine=prior"], "default": []}


def run_pipeline(store: Path, prompt: str, extra: list[str]) -> tuple[np.ndarray, dict, float]:
    """``holoflow run PROMPT EXTRA --until metric_align`` in ``store``; (depth [H, W], metric_align.json,
    seconds the two depth steps took in that run: the sum of their records' ``wall_s``, 0 if cached)."""
    from holoflow.flow.store import Store
    from holoflow.io.exr import read_exr

    env = {**os.environ, "HOLOFLOW_STORE": str(store)}
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run(
        [sys.executable, "-m", "holoflow", "run", prompt, *extra, "--until", "metric_align"],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"holoflow run failed: {proc.stderr.strip().splitlines()[-1:]}")
    st = Store(store)
    run = st.run_ids()[-1]
    stages = st.run_info(run)["stages"]
    seconds = sum(
        st.record(stages[n]["key"])["provenance"]["wall_s"]
        for n in ("tangent_depth", "metric_align")
        if stages[n]["how"] == "ran"
    )
    out = st.run_dir(run) / "metric_align"
    ch, _ = read_exr(out / "depth.exr")
    return ch["Z"].astype(np.float64), json.loads((out / "metric_align.json").read_text()), seconds


def detail_input(store: Path, width: int) -> np.ndarray:
    """The latest run's detail panorama (linear RGB [H, W, 3]) resized to ``width``: what the depth
    engines receive."""
    from holoflow.depth.inputs import read_pano
    from holoflow.flow.store import Store
    from holoflow.geometry.sampling import resize_pano

    st = Store(store)
    return resize_pano(read_pano(st.run_dir(st.run_ids()[-1]) / "detail" / "pano.exr"), width)


def read_truth(path: Path) -> tuple[np.ndarray, str]:
    """Radial truth [H, W] (NaN no measurement, +inf sky) and its ``truth.scale``."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        header = dict(f.header())
        z = np.asarray(f.channels()["Z"].pixels, dtype=np.float64)
    return z, str(header.get("truth.scale", "metric"))


def score(depth: np.ndarray, truth: np.ndarray, scale: str) -> dict:
    """AbsRel / RMSE / delta1 (holoflow.depth.accuracy) of a prediction against a truth of ``scale``."""
    from holoflow.depth.accuracy import depth_metrics
    from holoflow.depth.panorama import resize_radial

    t = resize_radial(np.where(np.isnan(truth), 0.0, truth), *depth.shape)  # NaN -> 0: left out
    fit = 1.0
    if scale != "metric":
        ok = np.isfinite(t) & (t > 0) & np.isfinite(depth) & (depth > 0)
        fit = float(np.median(t[ok] / depth[ok])) if ok.any() else 1.0
    m = depth_metrics(depth * fit, t)
    return {**m, "fit_scale": fit}


def turned_abs_rel(pano: np.ndarray, truth: np.ndarray, scale: str, turns: int) -> list[float]:
    """AbsRel of the layout engine (default config) on the linear RGB panorama [H, W, 3] turned about
    the vertical axis by i x 45 / ``turns`` degrees, i < ``turns`` (whole columns), each estimate turned
    back and scored against ``truth`` like the pipeline's output (``score``)."""
    from holoflow.depth.layout import estimate_layout_depth

    W = pano.shape[1]
    out = []
    for i in range(turns):
        cols = int(round(i * W / (8 * turns)))  # 45 degrees = W / 8 columns
        depth = estimate_layout_depth(np.roll(pano, cols, axis=1)).depth
        out.append(score(np.roll(depth.astype(np.float64), -cols, axis=1), truth, scale)["abs_rel"])
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(
        prog="holoflow bench realdepth", description=" ".join(__doc__.split("\n\n")[0].split())
    )
    ap.add_argument("--data", default=str(DATA), help="folder of NAME_rgb.png + NAME_depth.exr")
    ap.add_argument("--out", default="docs", help="folder for bench-realdepth.md (images/ beneath it)")
    ap.add_argument("--prompts", default="|".join(PROMPTS), help="procedural scenes, '|'-separated ('' = none)")
    ap.add_argument("--only", default="", help="comma-separated item names (default: all)")
    ap.add_argument(
        "--turns",
        type=int,
        default=4,
        help="layout runs per item, turned by i x 45 / N degrees, for the AbsRel spread (0 = none)",
    )
    args = ap.parse_args(argv)
    data = Path(args.data)
    if not data.is_dir():
        print(f"bench realdepth: {data} is absent; nothing to measure (skipped)")
        return 0
    names = sorted(p.name[: -len("_rgb.png")] for p in data.glob("*_rgb.png"))
    if args.only:
        names = [n for n in names if n in args.only.split(",")]
    rows, pics = [], []
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="hf-realdepth-") as tmp:
        for name in names:
            truth, scale = read_truth(data / f"{name}_depth.exr")
            row = {"name": name, "scale": scale}
            preds = {}
            for eng, extra in ENGINES.items():
                depth, rep, sec = run_pipeline(
                    Path(tmp) / name, "a room", ["--use", f"base_pano={data / f'{name}_rgb.png'}", *extra]
                )
                row[eng] = score(depth, truth, scale)
                row[eng]["seconds"] = round(sec, 1)
                row[eng]["engine"] = rep["engine"]["engine"]
                if eng == "default":
                    lay = rep["engine"].get("layout", {})
                    row["scene"] = lay.get("scene")
                    row["tilt_deg"] = (lay.get("upright") or {}).get("tilt_deg")
                preds[eng] = depth
                print(
                    f"{name} {eng}: {rep['engine']['engine']} AbsRel {row[eng]['abs_rel']:.3f} "
                    f"delta1 {row[eng]['delta1']:.3f} ({sec:.1f} s)",
                    flush=True,
                )
            if args.turns > 0 and row["default"]["engine"] == "layout":
                row["turns"] = turned_abs_rel(
                    detail_input(Path(tmp) / name, preds["default"].shape[1]), truth, scale, args.turns
                )
                print(
                    f"{name} layout over {args.turns} turns: AbsRel " + " ".join(f"{a:.3f}" for a in row["turns"]),
                    flush=True,
                )
            rows.append(row)
            pics.append((name, data / f"{name}_rgb.png", truth, preds))
        proc_rows = []
        for prompt in [p for p in args.prompts.split("|") if p]:
            row = {"name": prompt}
            for eng, extra in {
                **ENGINES,
                "layout": ["--set", "tangent_depth.engine=layout", "--set", "metric_align.engine=layout"],
            }.items():
                depth, rep, sec = run_pipeline(Path(tmp) / "procedural", prompt, extra)
                m = rep.get("truth_metrics", {})
                row[eng] = {**m, "engine": rep["engine"]["engine"], "seconds": round(sec, 1)}
                print(
                    f"{prompt} {eng}: {rep['engine']['engine']} AbsRel {m.get('abs_rel', float('nan')):.3f}", flush=True
                )
            proc_rows.append(row)
    out = Path(args.out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    write_pictures(out / "images", pics)
    write_table(out / "bench-realdepth.md", rows, proc_rows, time.perf_counter() - t_all, data)
    print(f"wrote {out / 'bench-realdepth.md'}")
    return 0


def write_pictures(folder: Path, pics) -> None:
    """One PNG per item: RGB | truth / default engine | its error. Depth as log depth 0.5..20 m
    (bright = near, black = no value or sky); error as log(default / truth), red = too far, blue =
    too near, full colour at a factor of 3."""
    import cv2

    from holoflow.depth.panorama import resize_radial

    H, W = 256, 512
    for name, rgb_path, truth, preds in pics:
        rgb = cv2.resize(cv2.imread(str(rgb_path)), (W, H), interpolation=cv2.INTER_AREA)
        t = resize_radial(np.where(np.isnan(truth), 0.0, truth), H, W)
        d = resize_radial(np.where(np.isnan(preds["default"]), 0.0, preds["default"]), H, W)

        def shade(z):
            v = 1.0 - np.log(np.clip(z, 0.5, 20.0) / 0.5) / np.log(40.0)
            img = cv2.applyColorMap((np.clip(v, 0, 1) * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
            img[~(np.isfinite(z) & (z > 0))] = 0
            return img

        ok = np.isfinite(t) & (t > 0) & np.isfinite(d) & (d > 0)
        e = np.where(ok, np.log(np.where(ok, d, 1.0) / np.where(ok, t, 1.0)) / np.log(3.0), 0.0)  # [H, W]
        err = np.zeros((H, W, 3), np.uint8)  # BGR
        err[..., 2] = (np.clip(e, 0, 1) * 255).astype(np.uint8)
        err[..., 0] = (np.clip(-e, 0, 1) * 255).astype(np.uint8)
        tiles = [rgb, shade(t), shade(d), err]
        for img, label in zip(tiles, ("image", "truth", "default", "default / truth (red far, blue near)")):
            cv2.putText(img, label, (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2)
        cv2.imwrite(str(folder / f"realdepth-{name}.png"), np.vstack([np.hstack(tiles[:2]), np.hstack(tiles[2:])]))


def spread(abs_rels: list[float] | None) -> str:
    """'mean (min-max)' of per-turn AbsRel values, '-' when there are none."""
    if not abs_rels:
        return "-"
    return f"{np.mean(abs_rels):.3f} ({min(abs_rels):.3f}-{max(abs_rels):.3f})"


def write_table(path: Path, rows, proc_rows, seconds: float, data: Path) -> None:
    def f(m, k):
        v = m.get(k)
        return "-" if v is None or (isinstance(v, float) and np.isnan(v)) else f"{v:.3f}"

    lines = [
        "# Depth on real panoramas (`holoflow bench realdepth`)",
        "",
        f"Measured {time.strftime('%Y-%m-%d')} on {machine()} (load {load()}), {seconds:.0f} s in all. "
        "Data: the real panoramas with measured depth in `../shared/data/realdepth/` (third-party files, "
        "sources in its README: 3D60 re-renders of Matterport3D and Stanford2D3D, Structured3D, RealSee3D, "
        "Google Street View); never copied into the project.",
        "",
        'Each item runs through the **default pipeline** (`holoflow run "a room" --use base_pano=NAME_rgb.png '
        "--until metric_align`, preview profile) and the **metric_align output** is scored (docs/depth.md, "
        "Metrics). `default` = the default engines (`auto` -> `layout` on an image without truth); `prior` = "
        "the constant room prior (`--set tangent_depth.engine=prior --set metric_align.engine=prior`). "
        "`metric` items are scored as they are; `relative` and `ordinal` items after a median scale fit "
        "(ordinal: coarse, read with care).",
        "",
        "`s` = seconds the two depth steps (tangent_depth + metric_align) took: what the accuracy "
        "costs. `turns` = AbsRel of the layout engine straight on the panorama it "
        "received, turned about the vertical axis (module docstring): mean (min-max); a difference "
        "smaller than this spread is noise.",
        "",
        "| item | truth | scene | prior AbsRel | prior RMSE | prior delta1 | prior s | default AbsRel | "
        "default RMSE | default delta1 | default s | turns AbsRel |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['scale']} | {r.get('scene') or '-'} | {f(r['prior'], 'abs_rel')} | "
            f"{f(r['prior'], 'rmse')} | {f(r['prior'], 'delta1')} | {r['prior']['seconds']:.1f} | "
            f"{f(r['default'], 'abs_rel')} | {f(r['default'], 'rmse')} | {f(r['default'], 'delta1')} | "
            f"{r['default']['seconds']:.1f} | {spread(r.get('turns'))} |"
        )
    indoor = [
        r
        for r in rows
        if r["scale"] == "metric" and r.get("scene", "indoor") == "indoor" and not r["name"].startswith("gsv")
    ]
    if indoor:
        med = {
            e: {k: float(np.median([r[e][k] for r in indoor])) for k in ("abs_rel", "rmse", "delta1")}
            for e in ("prior", "default")
        }
        turned = [r["turns"] for r in indoor if r.get("turns")]
        med_turns = (
            f"**{np.median([np.mean(t) for t in turned]):.3f}** (median of means)" if len(turned) == len(indoor) else ""
        )
        lines.append(
            f"| **median, {len(indoor)} indoor metric items** | | | **{f(med['prior'], 'abs_rel')}** | "
            f"**{f(med['prior'], 'rmse')}** | **{f(med['prior'], 'delta1')}** | | "
            f"**{f(med['default'], 'abs_rel')}** | **{f(med['default'], 'rmse')}** | "
            f"**{f(med['default'], 'delta1')}** | | {med_turns} |"
        )
        goal = med["default"]["abs_rel"] <= 0.20 and med["default"]["delta1"] >= 0.70
        lines += [
            "",
            "Goal of the default engine on the indoor metric items: AbsRel <= 0.20 and delta1 >= 0.70 -> "
            f"**{'met' if goal else 'NOT met'}** (median AbsRel {f(med['default'], 'abs_rel')}, "
            f"delta1 {f(med['default'], 'delta1')}).",
        ]
    if proc_rows:
        lines += [
            "",
            "## Procedural scenes (exact truth)",
            "",
            "| prompt | default (auto -> simulated) AbsRel / delta1 | prior AbsRel / delta1 | layout AbsRel / delta1 |",
            "|---|---|---|---|",
        ]
        for r in proc_rows:
            lines.append(
                f"| {r['name']} | {f(r['default'], 'abs_rel')} / {f(r['default'], 'delta1')} | "
                f"{f(r['prior'], 'abs_rel')} / {f(r['prior'], 'delta1')} | "
                f"{f(r['layout'], 'abs_rel')} / {f(r['layout'], 'delta1')} |"
            )
    lines += [
        "",
        "Pictures (image | truth / default | default / truth; depth as log depth 0.5-20 m, bright = "
        "near, black = no value or sky; error red = too far, blue = too near, full at a factor of 3): "
        + ", ".join(f"[{r['name']}](images/realdepth-{r['name']}.png)" for r in rows),
        "",
    ]
    path.write_text("\n".join(lines))
