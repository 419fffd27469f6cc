"""`holoflow view [RUN | STAGE | FILE.ply]`: look around a scene in the browser, on viser.

Shows the final scene (transfer_opt's scene.ply) as Gaussian splats, with toggles for G0 (pre_opt),
P_f and P_s (point_cloud), the base (pano_set) and supplementary (inp_set, else pcd_set) camera
frustums showing their images, the panorama (detail) on a far sphere, and a button that plays a
look-around path from the centre. The viewer's world is holoflow's (docs/conventions.md: +x right,
+y down, +z forward, metres); viser's up direction is set to -y and its frustums take OpenCV cameras,
so nothing is converted.

What it opens: nothing (the store's latest run), a run id or run folder, a stage name or folder
(transfer_opt, pre_opt), or any 3DGS PLY file (then only that file). Binds 127.0.0.1 unless ``--host``
says otherwise (``--host 0.0.0.0`` shares the scene with everyone who can reach the port). Layers
above ``--max-splats`` are subsampled (uniformly, seeded) with a message. Ctrl-C stops the server and
exits 0. A port in use, or a target that is not a scene, ends with one line on stderr and exit code 2.
viser (its web client ships in the wheel: no network) is imported only here, never at CLI start-up.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SCENE_FILES = {"transfer_opt": "scene.ply", "pre_opt": "gaussians.ply"}
IMAGE_MAX = 256  # frustum images are downsampled to at most this many pixels on the long side
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


class ViewError(Exception):
    """A mistake the user can fix: printed as one line."""


@dataclass
class Layers:
    """What to show: the scene PLY and, when it comes from a run, that run's other artifacts
    (name -> path; only those that exist)."""

    scene: Path
    extras: dict[str, Path] = field(default_factory=dict)


def resolve(target: str | None, store: Path) -> Layers:
    """Layers for ``target`` (module docstring); ViewError saying what to give instead."""
    if target and Path(target).is_file():
        return Layers(scene=Path(target))
    stage = "transfer_opt"
    if target is None or target in SCENE_FILES:
        stage = target or stage
        if not (store / "latest").exists():
            raise ViewError(
                f"no run in the store {store}: run `holoflow run` first, or give --store, a RUN folder or a FILE.ply"
            )
        run = (store / "latest").resolve()
    elif Path(target).is_dir():
        run = Path(target).resolve()
        if run.name in SCENE_FILES:  # a stage's folder
            stage, run = run.name, run.parent
    elif (store / "runs" / target).is_dir():
        run = (store / "runs" / target).resolve()
    else:
        raise ViewError(f"{target!r} is not a file, a run, or a stage ({', '.join(SCENE_FILES)}) of {store}")
    scene = run / stage / SCENE_FILES[stage]
    if not scene.is_file():
        raise ViewError(f"{run} has no {stage}/{scene.name}: not a finished run (run `holoflow run`)")
    extras = {
        "G0": run / "pre_opt" / "gaussians.ply",
        "P_f": run / "point_cloud" / "pf.ply",
        "P_s": run / "point_cloud" / "ps.ply",
        "base cameras": run / "pano_set",
        "supplementary cameras": run / ("inp_set" if (run / "inp_set").is_dir() else "pcd_set"),
        "panorama sphere": run / "detail" / "pano.exr",
    }
    return Layers(scene=scene, extras={k: v for k, v in extras.items() if v.exists() and v != scene})


def subsample(n: int, cap: int, what: str) -> np.ndarray | None:
    """Sorted indices of ``cap`` of ``n`` items (seeded), with a message; None when n <= cap."""
    if n <= cap:
        return None
    print(f"holoflow view: {what} has {n} items; showing {cap} of them (--max-splats)", flush=True)
    return np.sort(np.random.default_rng(0).choice(n, cap, replace=False))


def load_splats(path: Path, cap: int) -> dict:
    """A 3DGS PLY as viser's splat arrays (float32): centers [N, 3] m, covariances [N, 3, 3] m^2
    (R diag(s^2) R^T), rgbs [N, 3] in [0, 1] (the SH DC colour, sRGB), opacities [N, 1]."""
    import torch

    from holoflow.export.splats import activate
    from holoflow.geometry.camera import quat_to_rotmat
    from holoflow.io.ply import read_gaussians

    try:
        s = activate(read_gaussians(path))
    except (ValueError, KeyError) as exc:
        raise ViewError(f"not a 3DGS scene: {str(exc).splitlines()[0]}") from None
    keep = subsample(len(s), cap, path.name)
    if keep is not None:
        s = s.subset(keep)
    R = quat_to_rotmat(torch.from_numpy(s.quats)).numpy()  # [N, 3, 3]
    cov = (R * s.scales[:, None, :] ** 2) @ R.transpose(0, 2, 1)  # [N, 3, 3]
    return {
        "centers": s.means.astype(np.float32),
        "covariances": cov.astype(np.float32),
        "rgbs": np.clip(s.rgb, 0, 1).astype(np.float32),
        "opacities": s.opacities[:, None].astype(np.float32),
    }


def port_free(host: str, port: int) -> bool:
    """Whether a server could listen on (host, port) now (SO_REUSEADDR, as viser's server binds)."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError:
            return False
    return True


def build(server, layers: Layers, splats: dict, cap: int) -> tuple[float, dict[str, list]]:
    """Add every layer to the viser ``server`` (``splats``: the scene's load_splats arrays): (the scene's
    radius in metres, name -> node handles). Only the scene is visible at first; the radius (90th
    percentile of centre distances) sizes the frustums, points and the panorama sphere."""
    from holoflow.io.ply import read_points

    scene = server.scene
    scene.set_up_direction("-y")  # holoflow's up is -y
    radius = float(np.quantile(np.linalg.norm(splats["centers"], axis=1), 0.9)) if len(splats["centers"]) else 1.0
    handles = {"scene": [scene.add_gaussian_splats("/scene", **splats)]}
    for name, path in layers.extras.items():
        if name == "G0":
            nodes = [scene.add_gaussian_splats("/G0", **load_splats(path, cap), visible=False)]
        elif name in ("P_f", "P_s"):
            xyz, rgb = read_points(path)  # [N, 3] m, [N, 3] uint8
            keep = subsample(len(xyz), cap, path.name)
            if keep is not None:
                xyz, rgb = xyz[keep], rgb[keep]
            nodes = [scene.add_point_cloud(f"/{name}", xyz, rgb, point_size=0.005 * radius, visible=False)]
        elif name.endswith("cameras"):
            nodes = add_frustums(scene, path, name.split()[0], 0.08 * radius)
        else:
            nodes = [add_pano_sphere(scene, path, 20.0 * radius)]
        handles[name] = nodes
    return radius, handles


def add_frustums(scene, folder: Path, kind: str, size: float) -> list:
    """One frustum per view of a view-set folder (cameras.json, docs/conventions.md), showing its image
    (linear EXR -> 8-bit sRGB, downsampled to IMAGE_MAX); ``size`` in metres."""
    from holoflow.imageops.color import linear_to_uint8
    from holoflow.io.exr import read_rgb

    cams = json.loads((folder / "cameras.json").read_text())
    fov = 2 * np.arctan(cams["height"] / (2 * cams["fy"]))  # vertical, radians
    step = max(1, -(-max(cams["width"], cams["height"]) // IMAGE_MAX))
    nodes = []
    for i, v in enumerate(cams["views"]):
        c2w = np.linalg.inv(np.array(v["viewmat"], np.float64).reshape(4, 4))  # camera-to-world, OpenCV
        image = linear_to_uint8(read_rgb(folder / v["file"])[::step, ::step])
        nodes.append(
            scene.add_camera_frustum(
                f"/cameras/{kind}/{i:03d}",
                fov=float(fov),
                aspect=cams["width"] / cams["height"],
                scale=size,
                thickness=1.5,
                thickness_units="screen",
                image=image,
                wxyz=rotmat_to_wxyz(c2w[:3, :3]),
                position=c2w[:3, 3],
                color=(230, 120, 20) if kind == "base" else (40, 120, 230),
                visible=False,
            )
        )
    return nodes


def rotmat_to_wxyz(R: np.ndarray) -> np.ndarray:
    """A rotation matrix [3, 3] -> its unit quaternion [4] (w, x, y, z)."""
    import torch

    from holoflow.geometry.camera import rotmat_to_quat

    return rotmat_to_quat(torch.from_numpy(R)).numpy()


def add_pano_sphere(scene, pano: Path, radius: float):
    """The panorama (linear EXR) on a sphere of ``radius`` metres around the centre, vertex-coloured
    (8-bit sRGB) at up to 512 x 256."""
    import torch
    import trimesh

    from holoflow.export.mesh import rgbd_mesh
    from holoflow.geometry.pointcloud import resample_rgbd
    from holoflow.imageops.color import linear_to_uint8
    from holoflow.io.exr import read_rgb

    rgb = torch.from_numpy(read_rgb(pano)).double()  # [H, W, 3] linear
    rgb, _ = resample_rgbd(rgb, torch.ones(rgb.shape[:2], dtype=torch.float64), min(512, rgb.shape[1]))
    v, c, f = rgbd_mesh(rgb.numpy(), np.full(rgb.shape[:2], radius), sky="omit")
    mesh = trimesh.Trimesh(v, f, vertex_colors=linear_to_uint8(c), process=False)
    return scene.add_mesh_trimesh("/panorama_sphere", mesh, visible=False)


def look_around(client, seconds: float = 8.0, steps: int = 120) -> None:
    """Turn the client's camera once around the vertical axis, standing at the centre, looking level."""
    for k in range(steps + 1):
        a = 2 * np.pi * k / steps
        with client.atomic():
            client.camera.position = (0.0, 0.0, 0.0)
            client.camera.look_at = (float(np.sin(a)), 0.0, float(np.cos(a)))
            client.camera.up_direction = (0.0, -1.0, 0.0)
        time.sleep(seconds / steps)


def add_gui(server, handles: dict[str, list]) -> None:
    """A checkbox per layer and the look-around button."""
    for name, nodes in handles.items():
        box = server.gui.add_checkbox(name, initial_value=nodes[0].visible if nodes else False)

        def toggle(_event, nodes=nodes, box=box) -> None:
            for node in nodes:
                node.visible = box.value

        box.on_update(toggle)
    button = server.gui.add_button("Look around")

    @button.on_click
    def _(event) -> None:
        clients = [event.client] if event.client is not None else list(server.get_clients().values())
        for client in clients:
            threading.Thread(target=look_around, args=(client,), daemon=True).start()


def serve(layers: Layers, splats: dict, host: str, port: int, cap: int) -> None:
    """Build the scene on a viser server at (host, port), print the URL, serve until Ctrl-C."""
    try:
        import viser
    except ModuleNotFoundError:
        raise ViewError("viser is not installed: pip install -e '.[view]'") from None
    for sig in (signal.SIGINT, signal.SIGTERM):  # Ctrl-C and `kill` stop it, even where SIGINT was ignored
        signal.signal(sig, _interrupt)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:
        if port and server.get_port() != port:  # viser moves on to the next free port
            raise ViewError(f"port {port} on {host} is in use: pick another with --port")
        radius, handles = build(server, layers, splats, cap)
        server.initial_camera.position = (0.0, 0.0, -0.05 * radius)  # at the centre, looking forward (+z)
        server.initial_camera.look_at = (0.0, 0.0, 1.0)
        server.initial_camera.up = (0.0, -1.0, 0.0)
        add_gui(server, handles)
        if host not in LOCAL_HOSTS:
            print(
                f"holoflow view: listening on {host}: anyone who can reach port {server.get_port()} sees this scene",
                flush=True,
            )
        url_host = socket.gethostname() if host in ("0.0.0.0", "::") else host
        print(f"holoflow view: {layers.scene} at http://{url_host}:{server.get_port()}/  (Ctrl-C stops)", flush=True)
        while True:
            time.sleep(0.5)
    finally:
        server.stop()


def _interrupt(_signum, _frame) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="holoflow view", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "target",
        nargs="?",
        help="RUN (id or folder), STAGE (transfer_opt | pre_opt) or FILE.ply; default: the store's latest run",
    )
    p.add_argument("--pipeline", default="pipeline.yaml", help="pipeline file; its folder holds the default store")
    p.add_argument("--store", help="store folder (default $HOLOFLOW_STORE, else artifacts/ beside the pipeline)")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1: this machine "
        "only; 0.0.0.0 shares the scene with everyone who can reach the port)",
    )
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; 0 = any free port)")
    p.add_argument("--max-splats", type=int, default=1_000_000, help="subsample larger layers to this many")
    args = p.parse_args(argv)

    from holoflow.flow.pipeline import find_pipeline

    store = Path(args.store or os.environ.get("HOLOFLOW_STORE") or find_pipeline(args.pipeline).parent / "artifacts")
    try:
        layers = resolve(args.target, store)
        if not port_free(args.host, args.port):
            raise ViewError(f"port {args.port} on {args.host} is in use: pick another with --port")
        cap = max(1, args.max_splats)
        serve(layers, load_splats(layers.scene, cap), args.host, args.port, cap)
    except ViewError as exc:
        print(f"holoflow view: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("holoflow view: stopped", flush=True)
    return 0
