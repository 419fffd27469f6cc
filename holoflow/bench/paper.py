"""`holoflow bench paper`: the paper profile end to end at the paper's sizes, timed per stage.

1024x512 base, 1536x768 stylize, 6144x3072 upscale and detail, 4096x2048 depth on 20 tangent faces at
512 px, 38 base views and 152 supplementary views at 512 px, 2000 + 2000 + 5000 3DGS iterations. Every
real engine runs with randomly initialised models of its published architecture and size
(``holoflow models random DIR --full``, or your own weights with ``--models DIR``): the images are
noise, the compute cost is the real one. The run is one ``holoflow run --json`` process into a fresh
store; per stage the bench reads the wall time, the peak GPU memory torch allocated and the peak host
RSS from the step records. Writes docs/bench-paper.md naming the GPU.

With ``--truth DIR`` (a truth set, docs/truth-sets.md) it runs the profile's reconstruction on the truth
set's own panorama and depth instead (``truth_run_args``: generation kept appearance-neutral, no weights
needed) and scores the scene from the truth cameras per ring (holoflow.evaluation.truth_scores); that
section of ``--out`` is rewritten between its markers, the rest of the file kept.
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

from holoflow.evaluation.machine import machine


def gpu_name() -> str:
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=name,memory.total,driver_version", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=20,
        )
        return out.stdout.strip().splitlines()[0] if out.returncode == 0 and out.stdout.strip() else "no GPU"
    except (OSError, subprocess.TimeoutExpired):
        return "no GPU"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench paper", description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda", choices=["cuda", "cpu"])
    ap.add_argument("--profile", default="paper", help="profile list (default paper; paper,tiny for a smoke run)")
    ap.add_argument(
        "--models",
        metavar="DIR",
        help="models folder with a manifest.json (default: write random "
        "full-size models to a temporary folder first, timed on its own)",
    )
    ap.add_argument("--tiny-models", action="store_true", help="random tiny models instead of full-size ones")
    ap.add_argument("--prompt", default="a cozy library")
    ap.add_argument("--timeout", type=float, default=3600, help="give up on the run after this many seconds")
    ap.add_argument("--out", default="docs/bench-paper.md")
    ap.add_argument("--truth", metavar="DIR", help="a truth set: the profile's reconstruction on its panorama, scored")
    ap.add_argument("--way", default="exact", choices=["exact", "simulated"], help="--truth: the depth the run gets")
    ap.add_argument("--pictures", default="docs/images", help="--truth: folder for the ring pictures")
    ap.add_argument(
        "--set", dest="sets", action="append", default=[], metavar="STAGE.PARAM=VALUE", help="--truth: as holoflow run"
    )
    args = ap.parse_args(argv)
    root = Path(__file__).resolve().parents[2]
    if args.truth:
        return truth_main(args, root)
    with tempfile.TemporaryDirectory(prefix="holoflow-bench-paper-") as tmp:
        models, t_models = args.models, None
        if models is None:
            from holoflow.networks.manifest import write_random

            models = str(Path(tmp) / "models")
            t0 = time.perf_counter()
            write_random(
                Path(models),
                full=not args.tiny_models,
                progress=lambda m: print(m, file=sys.stderr),
                depth_variant="large",
            )
            t_models = time.perf_counter() - t0
        store = Path(tmp) / "artifacts"
        cmd = [
            sys.executable,
            "-m",
            "holoflow",
            "run",
            args.prompt,
            "--profile",
            args.profile,
            "--models",
            models,
            "--device",
            args.device,
            "--store",
            str(store),
            "--json",
        ]
        print("holoflow bench paper: " + " ".join(cmd[2:]), file=sys.stderr)
        t0 = time.perf_counter()
        proc = subprocess.run(
            cmd,
            cwd=root,
            stdout=subprocess.PIPE,
            text=True,
            timeout=args.timeout,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            print(f"holoflow bench paper: the run failed (exit {proc.returncode})", file=sys.stderr)
            return 1
        summary = json.loads(proc.stdout)
        rows = stage_rows(store, summary)
    text = report(rows, wall, t_models, args, summary)
    out = root / args.out
    out.write_text(text)
    print(text)
    print(f"holoflow bench paper: wrote {out}", file=sys.stderr)
    return 0


def stage_rows(store: Path, summary: dict) -> list[dict]:
    """Per stage: engine, device, wall s, peak GPU MiB, peak RSS MiB and the step's own figures."""
    from holoflow.flow.store import Store

    st = Store(store)
    rows = []
    for name, e in summary["stages"].items():
        prov = (st.record(e["key"]) or {}).get("provenance", {}) if e.get("key") else {}
        meta = prov.get("meta", {})
        rows.append(
            dict(
                stage=name,
                engine=e.get("engine"),
                device=e.get("device"),
                how=e["how"],
                wall_s=prov.get("wall_s", e.get("seconds")),
                gpu_peak_mb=meta.get("gpu_peak_mb"),
                rss_mb=prov.get("peak_rss_mb"),
                gpu=meta.get("gpu"),
                gaussians=meta.get("gaussians"),
            )
        )
    return rows


def stage_table(rows: list[dict]) -> list[str]:
    """Markdown lines: one row per stage of ``stage_rows``."""
    fmt = lambda v, f="{:.1f}": "-" if v is None else f.format(v)  # noqa: E731
    lines = [
        "| stage | engine | device | wall s | peak GPU MiB | peak RSS MiB | Gaussians |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['stage']} | {r['engine']} | {r['device']} | {fmt(r['wall_s'])} | {fmt(r['gpu_peak_mb'], '{:.0f}')} "
            f"| {fmt(r['rss_mb'], '{:.0f}')} | {fmt(r['gaussians'], '{:,}')} |"
        )
    return lines


def report(rows: list[dict], wall: float, t_models: float | None, args, summary: dict) -> str:
    gpu = next((r["gpu"] for r in rows if r.get("gpu")), None) or gpu_name()
    recon = sum(
        r["wall_s"] or 0 for r in rows if r["stage"] in ("pcd_set", "pano_set", "pre_opt", "inp_set", "transfer_opt")
    )
    lines = [
        "# Bench: the paper profile end to end at the paper's sizes",
        "",
        f"`holoflow bench paper --device {args.device} --profile {args.profile}`; GPU: **{gpu}**; host: {machine()}.",
        "Every real engine ran with randomly initialised models of its published architecture and size "
        "(`holoflow models random DIR --full`), so the images are noise and the compute is the real one. "
        "Times are each step's wall clock as its own process (Python start-up, imports and model loading "
        "included); peak GPU memory is what torch allocated in that step.",
        "",
        *stage_table(rows),
    ]
    lines += [
        "",
        f"End to end: **{wall:.1f} s** ({wall / 60:.2f} min) for `holoflow run` with all 12 steps"
        + (f"; writing the random full-size models took {t_models:.1f} s more, once." if t_models else "."),
        f"Reconstruction (pano_set, pcd_set, pre_opt, inp_set, transfer_opt): {recon:.1f} s "
        f"(the paper reports 0.271 h = {0.271 * 3600:.0f} s for its reconstruction).",
        "",
    ]
    return "\n".join(lines)


TRUTH_BEGIN = "<!-- holoflow bench paper --truth: begin (generated; edit outside these markers) -->"
TRUTH_END = "<!-- holoflow bench paper --truth: end -->"
TRUTH_RINGS_PICTURED = ("0.5", "1")


def truth_run_args(truth: Path, way: str, pano_width: int, models: str | None) -> list[str]:
    """``holoflow run`` arguments (--use / --set) that run a profile's reconstruction on the truth set in
    ``truth``: its panorama (``pano_width`` px wide) kept as it is through stylize, upscale and detail
    (the classical engines, no style, no detail boost, no resize: the truth applies), its depth given
    (``way`` exact) or the simulated network's (``way`` simulated), and the INP set filled by OpenCV
    unless ``models`` (a models folder) is given."""
    from holoflow.bench.accuracy import NEUTRAL
    from holoflow.bench.profiles import TRUTH_WAYS

    uses, sets = TRUTH_WAYS[way]
    sets = (
        list(NEUTRAL)
        + list(sets)
        + [
            "stylize.engine=classical",
            "upscale.engine=lanczos",
            "detail.engine=classical",
            f"upscale.max_width={pano_width}",
            f"detail.max_width={pano_width}",
        ]
    )
    if way == "exact":
        sets.append("tangent_depth.engine=given")  # read by nothing downstream: metric_align is given
    if models is None:
        sets.append("inp_set.engine=opencv")
    out = [a for u in uses for a in ("--use", u.replace("DIR", str(truth)))]
    return out + [a for x in sets for a in ("--set", x)]


def build_gsplat() -> float | None:
    """Seconds to build (or load) gsplat's CUDA extension in a process of its own, so that its one-off
    compile is not counted in pre_opt's time; None when gsplat is not installed or fails to build."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", "from gsplat.cuda._backend import _C; assert _C is not None"],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        print(f"holoflow bench paper: gsplat's CUDA extension did not build:\n{proc.stderr[-2000:]}", file=sys.stderr)
        return None
    return time.perf_counter() - t0


def pano_width(path: Path) -> int:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise SystemExit(f"holoflow bench paper: cannot read {path}: {oiio.geterror()}")
    width = inp.spec().width
    inp.close()
    return int(width)


def truth_main(args, root: Path) -> int:
    """``--truth DIR``: the profile's reconstruction on the truth set, timed per step and scored per ring."""
    from holoflow.bench.profiles import update_block
    from holoflow.evaluation.truth_scores import ring_strip, score_truth
    from holoflow.report.pictures import encode

    truth = Path(args.truth).resolve()
    if not (truth / "cameras.json").is_file():
        raise SystemExit(f"holoflow bench paper: {truth} is not a truth set (no cameras.json)")
    build_s = build_gsplat() if args.device == "cuda" else None
    with tempfile.TemporaryDirectory(prefix="holoflow-bench-paper-") as tmp:
        store = Path(tmp) / "artifacts"
        cmd = [sys.executable, "-m", "holoflow", "run", "a room", "--profile", args.profile, "--device", args.device]
        cmd += [
            "--until",
            "transfer_opt",
            "--store",
            str(store),
            "--json",
        ]  # the scene scored; no export + (["--models", args.models] if args.models else [])
        cmd += truth_run_args(truth, args.way, pano_width(truth / "pano_z.exr"), args.models)
        cmd += [a for x in args.sets for a in ("--set", x)]
        print("holoflow bench paper: " + " ".join(cmd[2:]), file=sys.stderr)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, cwd=root, stdout=subprocess.PIPE, text=True, timeout=args.timeout)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            print(f"holoflow bench paper: the run failed (exit {proc.returncode})", file=sys.stderr)
            return 1
        summary = json.loads(proc.stdout)
        rows = [r for r in stage_rows(store, summary) if r["how"] != "used"]
        scene = store / "runs" / summary["run"] / "transfer_opt" / "scene.ply"
        scores, pictures = score_truth(scene, truth, "gsplat" if args.device == "cuda" else "cpu")
    names = {}
    folder = root / args.pictures
    for key in TRUTH_RINGS_PICTURED:
        if key in pictures:
            folder.mkdir(parents=True, exist_ok=True)
            names[key] = f"bench-paper-truth-{args.way}-ring-{key}.jpg"
            (folder / names[key]).write_bytes(encode(ring_strip(*pictures[key], side=160), "jpeg", 90))
    block = truth_report(rows, scores, wall, build_s, args, truth, names)
    out = root / args.out
    update_block(out, block, TRUTH_BEGIN, TRUTH_END)
    print(block)
    print(f"holoflow bench paper: wrote {out}", file=sys.stderr)
    return 0


def truth_report(
    rows: list[dict], scores: dict, wall: float, build_s: float | None, args, truth: Path, pictures: dict
) -> str:
    """The ``--truth`` section: per step seconds, per ring scores, pictures (markdown between markers)."""
    gpu = next((r["gpu"] for r in rows if r.get("gpu")), None) or gpu_name()
    lines = [
        TRUTH_BEGIN,
        "",
        f"`holoflow bench paper --truth {truth.name} --way {args.way} --device {args.device} --profile "
        f"{args.profile}{''.join(' --set ' + x for x in args.sets)}`: the profile's reconstruction on the "
        "truth set's own panorama with "
        + ("its exact depth" if args.way == "exact" else "the simulated network's depth")
        + f" (bench.paper.truth_run_args), scored from its {scores['views']} cameras. GPU: **{gpu}**; "
        f"host: {machine()}."
        + (
            f" gsplat's CUDA extension took {build_s:.0f} s to build or load beforehand (not counted)."
            if build_s
            else ""
        ),
        "",
        *stage_table(rows),
    ]
    steps = sum(r["wall_s"] or 0 for r in rows)
    lines += [
        "",
        f"Every step together: {steps:.1f} s (`holoflow run` end to end {wall:.1f} s).",
        "",
        "| ring | PSNR dB (per-view mean) | SSIM | depth AbsRel | empty % | alpha < 0.9 % |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for key, r in scores["rings"].items():
        lines.append(
            f"| {key} m | {r['psnr']:.2f} ({r['psnr_mean']:.2f}) | {r['ssim']:.3f} | {r['abs_rel']:.3f} | "
            f"{100 * r['empty']:.2f} | {100 * r['cracked']:.2f} |"
        )
    lines.append("")
    for key, name in pictures.items():
        lines.append(f"- {key} m (truth above render): ![ring {key} m](images/{name})")
    return "\n".join(lines + ["", TRUTH_END]) + "\n"
