"""`holoflow bench geometry`: equirect -> perspective (e2p) and cube map, holoflow vs py360convert.

One analytic panorama (pixel value = a smooth function of the pixel centre's direction, so every
output pixel has an exact truth) at 2048 x 1024 is turned into 512 x 512 views (front, across the
+-180 deg seam, straight up, straight down, oblique) and a 6 x 256 cube map by
``holoflow.geometry.sampling.equirect_to_pinhole`` (bilinear and antialias modes) and by py360convert
(``e2p`` / ``e2c``, bilinear), in the same run on the same input. py360convert is pip-installed into a
temporary virtual environment (or ``--venv DIR``) and run there in a child process; it is timed with
its scipy backend and, when opencv is importable there (``--cv2`` installs it), with its cv2 backend
too. Each method's error is measured against the function evaluated along that method's own pixel
rays (py360convert puts its first and last pixel centres on the FOV edges, holoflow uses +0.5 pixel
centres; its rays come from its own ``xyzpers`` / ``xyzcube``). Times are per view, median of
``--repeat`` runs, py360convert's sampler cache cleared before each call (each view of a rig is a
new direction). One table per ``--threads`` count (default 1 and 2), the same count on both sides
(py360convert's scipy backend is single-threaded at any count). Writes docs/bench-geometry.md with the
machine and the load average before and after each table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from holoflow.evaluation.machine import machine

VIEWS = {  # name -> (lon deg, lat deg) of the optical axis (py360convert's u_deg, v_deg)
    "front": (0.0, 0.0),
    "seam": (180.0, 0.0),
    "north pole": (0.0, 90.0),
    "south pole": (0.0, -90.0),
    "oblique": (45.0, 30.0),
}
CUBE = {"F": (0, 0), "R": (90, 0), "B": (180, 0), "L": (-90, 0), "U": (0, 90), "D": (0, -90)}

_CHILD = r"""
import json, sys, time
import numpy as np
if sys.argv[2] == "scipy":
    sys.modules["cv2"] = None  # force py360convert's scipy backend
import py360convert
from py360convert import utils
if sys.argv[2] == "cv2":
    import cv2; cv2.setNumThreads(int(sys.argv[3]))
pano = np.load(sys.argv[1] + "/pano.npy")
cfg = json.loads(open(sys.argv[1] + "/cfg.json").read())
out = {}
def timed(fn):
    ts = []
    for _ in range(cfg["repeat"]):
        for name in ("from_perspective", "from_cubemap"):
            getattr(utils.EquirecSampler, name).cache_clear()
        t = time.perf_counter(); r = fn(); ts.append(time.perf_counter() - t)
    return r, sorted(ts)[len(ts) // 2]
for name, (u, v) in cfg["views"].items():
    img, t = timed(lambda: py360convert.e2p(pano, cfg["fov"], u, v, (cfg["size"], cfg["size"])))
    xyz = utils.xyzpers(np.deg2rad(cfg["fov"]), np.deg2rad(cfg["fov"]), -np.deg2rad(u), np.deg2rad(v),
                        (cfg["size"], cfg["size"]), 0.0)
    np.save(f"{sys.argv[1]}/{sys.argv[2]}_{name}.npy", img); np.save(f"{sys.argv[1]}/rays_{name}.npy", xyz)
    out[name] = t
cube, t = timed(lambda: py360convert.e2c(pano, cfg["face"], cube_format="horizon"))
np.save(f"{sys.argv[1]}/{sys.argv[2]}_cube.npy", cube)
np.save(f"{sys.argv[1]}/rays_cube.npy", utils.xyzcube(cfg["face"]))
out["cube"] = t
out["version"] = py360convert.__version__ if hasattr(py360convert, "__version__") else "?"
print(json.dumps(out))
"""


def field(d):
    """The analytic panorama: smooth function of unit directions [..., 3] -> [..., 3] (values in [0, 1])."""
    import torch

    x, y, z = d.unbind(-1)
    return torch.stack(
        [
            0.5 + 0.3 * torch.sin(6 * x + 2 * z) * torch.cos(5 * y),
            0.5 + 0.25 * torch.sin(4 * y + 3 * x) + 0.15 * z,
            0.5 + 0.2 * torch.cos(7 * z - 2 * y) + 0.2 * x * y,
        ],
        -1,
    )


def _venv(given: str | None, cv2: bool, tmp: Path) -> Path:
    """Python of a virtual environment with py360convert (created with pip when not given)."""
    if given:
        return Path(given) / "bin" / "python"
    env = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(env)], check=True)
    pkgs = ["py360convert"] + (["opencv-python-headless"] if cv2 else [])
    subprocess.run([str(env / "bin" / "pip"), "install", "-q", *pkgs], check=True)
    return env / "bin" / "python"


def _load() -> float:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench geometry", description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=int, default=2048, help="panorama width (height = width / 2)")
    ap.add_argument("--size", type=int, default=512, help="perspective view side, pixels")
    ap.add_argument("--fov", type=float, default=47.43, help="view field of view, degrees")
    ap.add_argument("--face", type=int, default=256, help="cube face side, pixels")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--venv", help="existing virtual environment with py360convert (default: a new temporary one)")
    ap.add_argument(
        "--cv2", action="store_true", help="also install opencv into the venv and time py360convert's cv2 backend"
    )
    ap.add_argument("--device", default="cpu")
    ap.add_argument(
        "--threads",
        default="1,2",
        help="comma-separated CPU thread counts; one table each, the same count on both sides",
    )
    ap.add_argument("--out", default="docs/bench-geometry.md")
    args = ap.parse_args(argv)

    import numpy as np
    import torch

    from holoflow.geometry.camera import intrinsics_from_fov, look_at, pinhole_rays
    from holoflow.geometry.sampling import equirect_to_pinhole
    from holoflow.geometry.sphere import equirect_directions, lonlat_to_direction

    dev = torch.device(args.device)
    W, H = args.width, args.width // 2
    pano = field(equirect_directions(H, W, device=dev, dtype=torch.float64)).float()  # [H, W, 3]
    header = machine()
    tables: list[tuple[int, list[dict], float, float, list[str]]] = []
    with tempfile.TemporaryDirectory(prefix="holoflow-bench-geometry-") as tmp_s:
        tmp = Path(tmp_s)
        np.save(tmp / "pano.npy", pano.cpu().numpy())
        (tmp / "cfg.json").write_text(
            json.dumps({"views": VIEWS, "fov": args.fov, "size": args.size, "face": args.face, "repeat": args.repeat})
        )
        python = _venv(args.venv, args.cv2, tmp)
        has_cv2 = subprocess.run([str(python), "-c", "import cv2"], capture_output=True).returncode == 0
        backends = ["scipy"] + (["cv2"] if has_cv2 else [])

        def their_error(name: str, backend: str) -> tuple[float, float]:
            img = torch.from_numpy(np.load(tmp / f"{backend}_{name}.npy")).double()
            xyz = torch.from_numpy(np.load(tmp / f"rays_{name}.npy")).double()
            d = xyz * torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64)  # py360convert's y is up
            err = (img - field(d / torch.linalg.vector_norm(d, dim=-1, keepdim=True))).abs()
            return float(err.max()), float(err.mean())

        def ours(axes: list[tuple[float, float]], size: int, fov: float, mode: str):
            dirs = lonlat_to_direction(
                torch.tensor([math.radians(a[0]) for a in axes], dtype=torch.float64),
                torch.tensor([math.radians(a[1]) for a in axes], dtype=torch.float64),
            )
            V = look_at(torch.zeros_like(dirs), dirs).float().to(dev)
            K = intrinsics_from_fov(fov, size, size, dtype=torch.float32).to(dev).expand(len(axes), 3, 3)
            src = pano.permute(2, 0, 1).contiguous()
            equirect_to_pinhole(src, K, V, size, size, mode=mode)  # warm-up (allocator, kernels)
            ts = []
            for _ in range(args.repeat):
                if dev.type == "cuda":
                    torch.cuda.synchronize()
                t = time.perf_counter()
                out = equirect_to_pinhole(src, K, V, size, size, mode=mode)
                if dev.type == "cuda":
                    torch.cuda.synchronize()
                ts.append(time.perf_counter() - t)
            _, rays = pinhole_rays(K.double(), V.double(), size, size)
            err = (out.double().permute(0, 2, 3, 1) - field(rays)).abs()
            return sorted(ts)[len(ts) // 2] / len(axes), err

        for threads in [int(t) for t in args.threads.split(",")]:
            load0 = _load()
            torch.set_num_threads(threads)
            theirs = {}
            for b in backends:
                env = {**os.environ, "OMP_NUM_THREADS": str(threads), "OPENBLAS_NUM_THREADS": str(threads)}
                res = subprocess.run(
                    [str(python), "-c", _CHILD, str(tmp), b, str(threads)],
                    capture_output=True,
                    text=True,
                    check=True,
                    env=env,
                )
                theirs[b] = json.loads(res.stdout.strip().splitlines()[-1])
            rows: list[dict] = []
            for name, axis in VIEWS.items():
                row = {"case": f"e2p {args.size}x{args.size} {name}"}
                for mode in ("bilinear", "antialias"):
                    t, err = ours([axis], args.size, args.fov, mode)
                    row[f"holoflow {mode}"] = (t, float(err.max()), float(err.mean()))
                for b in backends:
                    row[f"py360convert {b}"] = (theirs[b][name], *their_error(name, b))
                rows.append(row)
            row = {"case": f"cube map 6x{args.face}x{args.face}"}
            for mode in ("bilinear", "antialias"):
                t, err = ours(list(CUBE.values()), args.face, 90.0, mode)
                row[f"holoflow {mode}"] = (t * 6, float(err.max()), float(err.mean()))
            for b in backends:
                row[f"py360convert {b}"] = (theirs[b]["cube"], *their_error("cube", b))
            rows.append(row)
            tables.append((threads, rows, load0, _load(), backends))
        version = theirs["scipy"].get("version", "?")

    lines = [
        "# Geometry bench: equirect -> perspective, holoflow vs py360convert",
        "",
        f"Command: `holoflow bench geometry {' '.join(argv)}`".rstrip() + "  ",
        f"Machine: {header}; torch {torch.__version__} on {args.device}; py360convert {version} in a venv.  ",
        f"Input: analytic {W}x{H} float32 panorama (holoflow.bench.geometry.field); views {args.size}x{args.size} "
        f"at {args.fov} deg; cube faces {args.face}. Error = |output - function along the method's own pixel rays|, "
        "max / mean over all pixels and channels. Time per view (cube: all 6 faces), median of "
        f"{args.repeat}.  ",
        "Threads, N per table: holoflow `torch.set_num_threads(N)`; py360convert's cv2 backend "
        "`cv2.setNumThreads(N)` (its remap is parallel); its scipy backend runs `scipy.ndimage.map_coordinates`, "
        "which is single-threaded whatever N (OMP/OpenBLAS set to N too).",
    ]
    for threads, rows, load0, load1, backends in tables:
        methods = [k for k in rows[0] if k != "case"]
        lines += [
            "",
            f"## {threads} thread{'s' if threads > 1 else ''} (load average {load0:.1f} before, {load1:.1f} after)",
            "",
            "| case | "
            + " | ".join(f"{m} ms" for m in methods)
            + " | "
            + " | ".join(f"{m} max / mean err" for m in methods)
            + " |",
            "|---" * (1 + 2 * len(methods)) + "|",
        ]
        for r in rows:
            times = " | ".join(f"{1000 * r[m][0]:.1f}" for m in methods)
            errs = " | ".join(f"{r[m][1]:.2e} / {r[m][2]:.2e}" for m in methods)
            lines.append(f"| {r['case']} | {times} | {errs} |")
        lines.append("")
        for b in backends:  # summary: medians over the cases of this table
            ref = f"py360convert {b}"
            speed = sorted(r[ref][0] / r["holoflow bilinear"][0] for r in rows)[len(rows) // 2]
            slowest = min(r[ref][0] / r["holoflow bilinear"][0] for r in rows)
            err = sorted(r["holoflow bilinear"][1] / r[ref][1] for r in rows)[len(rows) // 2]
            lines.append(
                f"- holoflow bilinear vs {ref}: {speed:.2f}x its speed (median over the cases; "
                f"worst case {slowest:.2f}x), {err:.2f}x its max error (median)."
            )
    text = "\n".join(lines) + "\n"
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
