"""`holoflow bench splat`: rasterizer speed, fast CPU path vs dense torch reference.

For 10k / 100k / 1M Gaussians (plus 1k, small enough for the reference) at 128^2, 256^2 and 512^2:
forward and forward+backward wall time (best of --repeat after a warm-up), Gaussian-pixel pairs the
fast path evaluates (pixels x Gaussians-per-pixel), pairs per second, peak RSS. The reference runs
where its [pixels x Gaussians] tensors fit --ref-mem-gb, and is marked "skipped (memory)" elsewhere.
Each configuration runs in its own process (clean peak RSS). Scene: ``synthetic.surface_scene``, a
wavy surface filling a 60 deg view, scales from the point spacing (like a fresh 3DGS init).
Writes docs/bench-splat.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from holoflow.evaluation.machine import machine

CONFIGS = [
    (1_000, 128),
    (10_000, 128),
    (10_000, 256),
    (10_000, 512),
    (100_000, 128),
    (100_000, 256),
    (100_000, 512),
    (1_000_000, 128),
    (1_000_000, 256),
    (1_000_000, 512),
]


def _peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _time(fn, repeat: int) -> float:
    fn()  # warm-up (JIT cache load, allocations)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run_one(n: int, size: int, repeat: int, ref_mem_gb: float, threads: int | None, scene: str = "surface") -> dict:
    """Measure one configuration in this process; returns a JSON-able row."""
    import numpy as np
    import torch

    from holoflow.splat import rasterize
    from holoflow.splat.composite_cpu import count_pairs
    from holoflow.splat.project_cpu import project_cpu
    from holoflow.splat.synthetic import intrinsics, look_at, room_scene, surface_scene

    if threads:
        torch.set_num_threads(threads)
    idle = _peak_rss_mb()
    sc = (room_scene if scene == "room" else surface_scene)(n, seed=0)
    vm, K = look_at([0, 0, 0], [0, 0, 1])[None], intrinsics(size, size, 60.0)[None]
    params = [sc[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")]

    def fwd(backend):
        def f():
            with torch.no_grad():
                rasterize(*params, vm, K, size, size, backend=backend)

        return f

    def fwd_bwd(backend):
        def f():
            out = rasterize(*params, vm, K, size, size, backend=backend)
            (out["rgb"].sum() + out["alpha"].sum()).backward()

        return f

    row = dict(n=n, size=size, scene=scene)
    row["fast_fwd_s"] = _time(fwd("cpu"), repeat)
    row["fast_fwd_bwd_s"] = _time(fwd_bwd("cpu"), repeat)
    row["fast_peak_rss_mb"] = _peak_rss_mb()
    with torch.no_grad():  # pairs evaluated by the fast path
        pr = project_cpu(*params[:4], vm, K, size, size, 0.01, 1e10)  # packed: the drawn ones
        g = pr["gaussian_ids"]
        feats = torch.cat([sc["colors"][g], pr["depths"][:, None], torch.ones(len(g), 1)], 1).numpy()
        pairs = float(
            count_pairs(
                pr["means2d"].numpy().astype(np.float64),
                pr["conics"].numpy(),
                sc["opacities"][g].numpy(),
                feats,
                pr["depths"].numpy(),
                np.ones(len(g), bool),
                pr["ext"].numpy(),
                size,
                size,
            )
        )
    row["pairs"] = pairs
    row["gaussians_per_pixel"] = pairs / size**2
    ref_bytes = 12 * 4 * size * size * n  # ~12 float32 [P, N] tensors kept for backward
    if ref_bytes <= ref_mem_gb * 2**30:
        row["ref_fwd_s"] = _time(fwd("reference"), max(1, repeat // 2))
        row["ref_fwd_bwd_s"] = _time(fwd_bwd("reference"), max(1, repeat // 2))
        row["ref_peak_rss_mb"] = _peak_rss_mb()
    else:
        row["ref_skipped_gb"] = ref_bytes / 2**30
    row["idle_rss_mb"] = idle
    return row


def _numba_threads() -> int:
    import numba

    return numba.config.NUMBA_NUM_THREADS


def _fmt_ms(s):
    return f"{1e3 * s:.1f}"


def table(rows: list[dict]) -> str:
    head = (
        "| Gaussians | image | fast fwd ms | fast fwd+bwd ms | ref fwd ms | ref fwd+bwd ms | "
        "ref / fast (fwd+bwd) | Gaussians per pixel | pairs/s (fwd) | peak RSS MB (fast / ref) |\n"
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n"
    )
    lines = []
    for r in rows:
        if "ref_fwd_s" in r:
            ref = (
                _fmt_ms(r["ref_fwd_s"]),
                _fmt_ms(r["ref_fwd_bwd_s"]),
                f"{r['ref_fwd_bwd_s'] / r['fast_fwd_bwd_s']:.0f}x",
                f"{r['ref_peak_rss_mb']:.0f}",
            )
        else:
            ref = (f"skipped (memory, ~{r['ref_skipped_gb']:.0f} GB)", "skipped", "-", "-")
        lines.append(
            f"| {r['n']:,} | {r['size']}x{r['size']} | {_fmt_ms(r['fast_fwd_s'])} | "
            f"{_fmt_ms(r['fast_fwd_bwd_s'])} | {ref[0]} | {ref[1]} | {ref[2]} | "
            f"{r['gaussians_per_pixel']:.1f} | {r['pairs'] / r['fast_fwd_s'] / 1e6:.0f} M | "
            f"{r['fast_peak_rss_mb']:.0f} / {ref[3]} |"
        )
    return head + "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench splat", description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per measurement (best kept)")
    ap.add_argument(
        "--ref-mem-gb", type=float, default=4.0, help="skip the dense reference above this estimated memory"
    )
    ap.add_argument("--max-n", type=int, default=1_000_000, help="largest Gaussian count to run")
    ap.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch intra-op threads (numba kernels use their own pool; 1 as in training)",
    )
    ap.add_argument("--out", default="docs/bench-splat.md")
    ap.add_argument(
        "--scene",
        choices=("surface", "room", "both"),
        default="both",
        help="surface: every Gaussian in view (worst case); room: inside-out walls",
    )
    ap.add_argument("--sizes", default="", help="only these configs, e.g. 100000x128,1000000x512")
    ap.add_argument("--one", nargs=2, type=int, metavar=("N", "SIZE"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(*args.one, args.repeat, args.ref_mem_gb, args.threads, args.scene)))
        return 0
    load0 = os.getloadavg()
    configs = [tuple(int(v) for v in c.split("x")) for c in args.sizes.split(",")] if args.sizes else CONFIGS
    scenes = ("surface", "room") if args.scene == "both" else (args.scene,)
    tables = {}
    for scene in scenes:
        rows = []
        for n, size in configs:
            if n > args.max_n:
                continue
            cmd = [
                sys.executable,
                "-m",
                "holoflow.bench.splat",
                "--one",
                str(n),
                str(size),
                "--repeat",
                str(args.repeat),
                "--ref-mem-gb",
                str(args.ref_mem_gb),
                "--scene",
                scene,
            ] + (["--threads", str(args.threads)] if args.threads else [])
            res = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if res.returncode != 0:
                print(res.stderr, file=sys.stderr)
                return res.returncode
            rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(
                f"{scene}: {n:>9,} Gaussians {size}x{size}: fwd {_fmt_ms(rows[-1]['fast_fwd_s'])} ms, "
                f"fwd+bwd {_fmt_ms(rows[-1]['fast_fwd_bwd_s'])} ms",
                flush=True,
            )
        tables[scene] = rows
    load1 = os.getloadavg()
    idle = next(iter(tables.values()))[0]["idle_rss_mb"]
    md = (
        f"# Splatting rasterizer benchmark\n\n"
        f"`holoflow bench splat` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}). Machine: "
        f"{machine()}. Load average (1/5/15 min) at start {load0[0]:.1f}/{load0[1]:.1f}/"
        f"{load0[2]:.1f}, at end {load1[0]:.1f}/{load1[1]:.1f}/{load1[2]:.1f}: the machine is shared, "
        f"so times are upper bounds of what the code does on an idle one.\n\n"
        f"torch intra-op threads: {args.threads} (as `train` uses); numba kernels: "
        f"{_numba_threads()} threads. One 60 deg camera; loss = sum(rgb) + sum(alpha). "
        f"Best of {args.repeat} after a warm-up; "
        f"the dense reference (every Gaussian at every pixel, torch autograd) runs where its "
        f"[pixels x Gaussians] tensors fit {args.ref_mem_gb:g} GB. 'Gaussians per pixel' = "
        f"Gaussian-pixel pairs the fast path evaluates / pixels; 'pairs/s' uses the forward time. "
        f"Peak RSS includes the interpreter, torch and numba (about {idle:.0f} MB before the scene "
        f"is built). Scales come from the point spacing, opacity 0.2-0.9.\n\n"
    )
    for scene, rows in tables.items():
        md += (
            f"## Scene `{scene}`\n\n"
            + (
                "`synthetic.surface_scene(N)`: a wavy surface filling the view, every Gaussian "
                "visible (the worst case).\n\n"
                if scene == "surface"
                else "`synthetic.room_scene(N)`: Gaussians on the walls of a 4 m cube around the camera, "
                "inside-out like a panorama scene; the view sees about 1/18 of them.\n\n"
            )
            + table(rows)
            + "\n"
        )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(md)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
