"""Camera files: holoflow's cameras.json, nerfstudio transforms.json, COLMAP text.

cameras.json (docs/artifacts.md): ``{"width", "height", "fx", "fy", "cx", "cy", "views": [{"name",
"file", "viewmat" (4x4 world-to-camera, OpenCV axes, row-major nested lists), "kind" ("base" |
"supplementary"), "base" (index of the base camera)}]}``; one pinhole K shared by every view, pixel
centres at +0.5 (nerfstudio and COLMAP use the same pixel convention, so K passes through unchanged).

nerfstudio stores camera-to-world matrices in OpenGL axes (+x right, +y up, +z backwards):
c2w_gl = inverse(viewmat) @ diag(1, -1, -1, 1). COLMAP's images.txt stores world-to-camera in OpenCV
axes as a quaternion (w, x, y, z) and a translation.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch

from holoflow.geometry.camera import invert_viewmat, make_viewmat, quat_to_rotmat, rotmat_to_quat

_GL = torch.diag(torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=torch.float64))  # OpenCV <-> OpenGL camera axes


def cameras_json(
    K: torch.Tensor,
    viewmats: torch.Tensor,
    width: int,
    height: int,
    names: list[str],
    files: list[str],
    kinds: list[str] | None = None,
    bases: list[int] | None = None,
) -> dict:
    """A cameras.json dict from a shared K [3, 3] and viewmats [M, 4, 4] (world-to-camera)."""
    M = viewmats.shape[0]
    if not len(names) == len(files) == M:
        raise ValueError(f"cameras_json: {M} viewmats but {len(names)} names and {len(files)} files")
    kinds = kinds or ["base"] * M
    bases = bases if bases is not None else list(range(M))
    K = K.detach().double().cpu()
    V = viewmats.detach().double().cpu()
    views = [
        {"name": names[i], "file": files[i], "viewmat": V[i].tolist(), "kind": kinds[i], "base": int(bases[i])}
        for i in range(M)
    ]
    return {
        "width": int(width),
        "height": int(height),
        "fx": float(K[0, 0]),
        "fy": float(K[1, 1]),
        "cx": float(K[0, 2]),
        "cy": float(K[1, 2]),
        "views": views,
    }


def cameras_tensors(cams: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """K [3, 3] and viewmats [M, 4, 4] (float64) of a cameras.json dict."""
    K = torch.tensor(
        [[cams["fx"], 0.0, cams["cx"]], [0.0, cams["fy"], cams["cy"]], [0.0, 0.0, 1.0]], dtype=torch.float64
    )
    V = torch.tensor([v["viewmat"] for v in cams["views"]], dtype=torch.float64).reshape(-1, 4, 4)
    return K, V


_KEYS = ("width", "height", "fx", "fy", "cx", "cy", "views")


def write_cameras(path: str | Path, cams: dict) -> None:
    """Write a cameras.json dict (keys of docs/artifacts.md only; a ``K`` added by read_cameras is dropped)."""
    missing = [k for k in _KEYS if k not in cams]
    if missing:
        raise ValueError(f"write_cameras: missing keys {missing}")
    out = {k: cams[k] for k in _KEYS}
    Path(path).write_text(json.dumps(out, indent=1) + "\n")


def read_cameras(path: str | Path) -> dict:
    """Read cameras.json; the dict gets ``K`` (3x3 nested list) added for convenience."""
    cams = json.loads(Path(path).read_text())
    missing = [k for k in _KEYS if k not in cams]
    if missing:
        raise ValueError(f"{path}: not a cameras.json (missing {missing})")
    cams["K"] = cameras_tensors(cams)[0].tolist()
    return cams


def write_transforms(path: str | Path, cams: dict) -> None:
    """nerfstudio transforms.json for a cameras.json dict (file paths relative to the json's folder)."""
    _, V = cameras_tensors(cams)
    c2w = invert_viewmat(V) @ _GL  # [M, 4, 4] camera-to-world, OpenGL camera axes
    frames = [
        {
            "file_path": v["file"],
            "transform_matrix": c2w[i].tolist(),
            "holoflow_name": v["name"],
            "holoflow_kind": v.get("kind", "base"),
            "holoflow_base": int(v.get("base", i)),
        }
        for i, v in enumerate(cams["views"])
    ]
    out = {
        "camera_model": "OPENCV",
        "fl_x": cams["fx"],
        "fl_y": cams["fy"],
        "cx": cams["cx"],
        "cy": cams["cy"],
        "w": cams["width"],
        "h": cams["height"],
        "k1": 0.0,
        "k2": 0.0,
        "p1": 0.0,
        "p2": 0.0,
        "frames": frames,
    }
    Path(path).write_text(json.dumps(out, indent=1) + "\n")


def read_transforms(path: str | Path) -> dict:
    """A cameras.json dict from a nerfstudio transforms.json (pinhole intrinsics at the top level)."""
    t = json.loads(Path(path).read_text())
    views = []
    for i, f in enumerate(t["frames"]):
        c2w = torch.tensor(f["transform_matrix"], dtype=torch.float64) @ _GL
        views.append(
            {
                "name": f.get("holoflow_name", Path(f["file_path"]).stem),
                "file": f["file_path"],
                "viewmat": invert_viewmat(c2w).tolist(),
                "kind": f.get("holoflow_kind", "base"),
                "base": int(f.get("holoflow_base", i)),
            }
        )
    return {
        "width": int(t["w"]),
        "height": int(t["h"]),
        "fx": float(t["fl_x"]),
        "fy": float(t["fl_y"]),
        "cx": float(t["cx"]),
        "cy": float(t["cy"]),
        "views": views,
    }


def write_colmap(folder: str | Path, cams: dict) -> None:
    """COLMAP text model in ``folder``: cameras.txt (one PINHOLE camera), images.txt (qvec wxyz and
    tvec of world-to-camera, OpenCV axes; no 2D points), empty points3D.txt."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _, V = cameras_tensors(cams)
    q = rotmat_to_quat(V[:, :3, :3])
    t = V[:, :3, 3]
    (folder / "cameras.txt").write_text(
        "# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[fx, fy, cx, cy]\n"
        f"1 PINHOLE {cams['width']} {cams['height']} {cams['fx']!r} {cams['fy']!r} {cams['cx']!r} {cams['cy']!r}\n"
    )
    lines = ["# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "# POINTS2D[] (none)"]
    for i, v in enumerate(cams["views"]):
        vals = " ".join(repr(float(x)) for x in [*q[i].tolist(), *t[i].tolist()])
        lines += [f"{i + 1} {vals} 1 {v['file']}", ""]
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    (folder / "points3D.txt").write_text("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[]\n")


def read_colmap(folder: str | Path) -> dict:
    """A cameras.json dict from a COLMAP text model with one PINHOLE (or SIMPLE_PINHOLE) camera."""
    folder = Path(folder)
    cam_lines = [ln.split() for ln in (folder / "cameras.txt").read_text().splitlines() if ln and ln[0] != "#"]
    _, model, w, h, *params = cam_lines[0]
    if model == "SIMPLE_PINHOLE":
        params = [params[0], params[0], params[1], params[2]]
    elif model != "PINHOLE":
        raise ValueError(f"{folder}/cameras.txt: camera model {model} is not a pinhole")
    fx, fy, cx, cy = map(float, params[:4])
    img_lines = [ln for ln in (folder / "images.txt").read_text().splitlines() if not ln.startswith("#")]
    views = []
    for ln in img_lines[::2]:  # every image line is followed by its (here empty) POINTS2D line
        if not ln.strip():
            continue
        parts = ln.split()
        qt = torch.tensor([float(x) for x in parts[1:8]], dtype=torch.float64)
        V = make_viewmat(quat_to_rotmat(qt[:4]), qt[4:])
        name = " ".join(parts[9:])
        views.append({"name": Path(name).stem, "file": name, "viewmat": V.tolist(), "kind": "base", "base": len(views)})
    return {"width": int(w), "height": int(h), "fx": fx, "fy": fy, "cx": cx, "cy": cy, "views": views}
