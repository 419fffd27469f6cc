"""Point-cloud pictures for the run report: a cut-away bird's-eye view of a PLY (points, or the
centres of a 3DGS scene in their DC colour).

Renderer: pyvista (VTK) off-screen, run in a child process (``python -m holoflow.report.clouds SPEC``)
so that a VTK without a usable OpenGL context (no EGL / OSMesa / X) can only fail that child, never
the report. When the child fails, the same camera is rendered in-process with the project's own
z-buffer point projection (``holoflow.geometry.pointcloud.project_points_zbuffer``), and the picture's
caption says which renderer made it.

View: points above the panorama centre (world y < 0; world up is -y, docs/conventions.md) are cut away
so that an enclosed room shows its floor and walls; the camera looks at the origin from above and
behind at ``EYE_DIR``, from ``EYE_DISTANCE`` times the 90th percentile of the kept points' radius.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

SH_C0 = 0.28209479177387814  # degree-0 spherical harmonic; DC colour = 0.5 + SH_C0 * f_dc
EYE_DIR = (0.45, -0.75, -0.5)  # world direction from the origin to the eye (up and behind)
EYE_DISTANCE = 2.2
FOV_DEG = 40.0  # vertical field of view
MAX_POINTS = 300_000  # a seeded random subset is drawn above this
SIZE = (640, 400)  # picture width, height in pixels
BACKGROUND = (1.0, 1.0, 1.0)


def read_cloud(path: str | Path, max_points: int = MAX_POINTS, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """xyz [N, 3] float32 and rgb [N, 3] uint8 (sRGB) of a point-cloud PLY or a 3DGS PLY (centres,
    DC colour); at most ``max_points`` points (seeded random subset, original order kept)."""
    from holoflow.io import ply

    try:
        g = ply.read_gaussians(path)
        xyz = np.stack([g["x"], g["y"], g["z"]], 1)
        dc = np.stack([g["f_dc_0"], g["f_dc_1"], g["f_dc_2"]], 1)
        rgb = (np.clip(0.5 + SH_C0 * dc, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    except ply.PlyError as e:
        if "not a 3DGS PLY" not in str(e):
            raise
        xyz, rgb = ply.read_points(path)
    keep = np.isfinite(xyz).all(1)
    xyz, rgb = xyz[keep], rgb[keep]
    if len(xyz) > max_points:
        pick = np.sort(np.random.default_rng(seed).choice(len(xyz), max_points, replace=False))
        xyz, rgb = xyz[pick], rgb[pick]
    return xyz.astype(np.float32), rgb


def cutaway(xyz: np.ndarray, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop the points above the panorama centre (world y < 0)."""
    keep = xyz[:, 1] >= 0.0
    return xyz[keep], rgb[keep]


def camera(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(eye [3], target [3]) of the report's view of a (cut-away) cloud [N, 3], world metres."""
    r = np.linalg.norm(xyz, axis=1)
    scale = float(np.percentile(r, 90)) if len(r) else 1.0
    d = np.asarray(EYE_DIR, np.float64)
    return d / np.linalg.norm(d) * EYE_DISTANCE * max(scale, 1e-6), np.zeros(3)


def render_zbuffer(xyz: np.ndarray, rgb: np.ndarray, size: tuple[int, int] = SIZE) -> np.ndarray:
    """uint8 [H, W, 3] of the cut-away cloud with the project's z-buffer point projection (2 px
    squares, nearest point wins), white background."""
    import torch

    from holoflow.geometry.camera import intrinsics_from_fov, look_at
    from holoflow.geometry.pointcloud import project_points_zbuffer

    xyz, rgb = cutaway(xyz, rgb)
    eye, target = camera(xyz)
    w, h = size
    K = intrinsics_from_fov(FOV_DEG, h, h, dtype=torch.float64)  # square pixels, vertical FOV
    K[0, 2] = w / 2
    vm = look_at(torch.tensor(eye), torch.tensor(target))
    img, mask, _ = project_points_zbuffer(
        torch.from_numpy(xyz).double(), torch.from_numpy(rgb).double(), K, vm, h, w, radius=2
    )
    out = img.numpy()
    out[mask.numpy() == 0] = np.asarray(BACKGROUND) * 255.0
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def render_pyvista(xyz: np.ndarray, rgb: np.ndarray, size: tuple[int, int] = SIZE) -> np.ndarray:
    """uint8 [H, W, 3] of the cut-away cloud with pyvista off-screen (same camera as the z-buffer)."""
    import pyvista as pv

    xyz, rgb = cutaway(xyz, rgb)
    eye, target = camera(xyz)
    plotter = pv.Plotter(off_screen=True, window_size=list(size))
    try:
        plotter.set_background(BACKGROUND)
        if len(xyz):
            plotter.add_points(
                pv.PolyData(xyz.astype(np.float32)),
                scalars=rgb,
                rgb=True,
                point_size=3.0,
                render_points_as_spheres=False,
            )
        plotter.camera_position = [tuple(eye), tuple(target), (0.0, -1.0, 0.0)]
        plotter.camera.view_angle = FOV_DEG
        return np.asarray(plotter.screenshot(return_img=True))[..., :3].copy()
    finally:
        plotter.close()


def render_files(jobs: list[tuple[Path, Path]], timeout: float = 300.0) -> tuple[list[np.ndarray | None], str]:
    """Render each (ply, png) job; returns the pictures (None for an unreadable PLY) and the name of
    the renderer used. pyvista runs in a child process; if it fails, all go through the z-buffer."""
    if not jobs:
        return [], "none"
    env = dict(os.environ)
    if not env.get("DISPLAY"):
        env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # no X: skip VTK's X attempt
    spec = json.dumps([[str(a), str(b)] for a, b in jobs])
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "holoflow.report.clouds", spec],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        ok, why = proc.returncode == 0, _last_line(proc.stderr) or f"exit code {proc.returncode}"
    except subprocess.TimeoutExpired:
        ok, why = False, f"timed out after {timeout:g} s"
    if ok:
        return [_read_png(png) for _, png in jobs], "pyvista (VTK, off-screen)"
    pictures = []
    for ply_path, _ in jobs:
        try:
            pictures.append(render_zbuffer(*read_cloud(ply_path)))
        except (OSError, ValueError):
            pictures.append(None)
    return pictures, f"holoflow z-buffer projection (pyvista failed: {why})"


def _read_png(path: Path) -> np.ndarray | None:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return None if img is None else img[..., ::-1].copy()


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1][:200] if lines else ""


def _child(spec: str) -> int:
    """Child process: render every [ply, png] of the JSON ``spec`` with pyvista; an unreadable PLY
    writes no PNG (the parent shows it as missing); a VTK failure is a non-zero exit."""
    import cv2

    from holoflow.io.ply import PlyError

    for ply_path, png in json.loads(spec):
        try:
            xyz, rgb = read_cloud(ply_path)
        except (OSError, PlyError):
            continue
        img = render_pyvista(xyz, rgb)
        if img.size == 0 or not cv2.imwrite(png, np.ascontiguousarray(img[..., ::-1])):
            print(f"could not write {png}", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(_child(sys.argv[1]))
