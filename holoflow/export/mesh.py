"""The panorama's RGB-D as a vertex-coloured triangle mesh (the paper's Text2Room-style baseline).

One vertex per equirect pixel centre at its radial depth (docs/conventions.md), two triangles per
2x2 block of neighbouring pixels, columns wrapping at the +-180 deg seam, and a fan to one vertex at
each pole (at the median depth of the row beside it) so the floor and ceiling have no hole.
A triangle is cut where depth jumps: its relative depth spread ``(max - min) / min`` exceeds
``edge_threshold`` (per pixel step, the quantity P_f's depth-gradient filter thresholds; a smooth
surface needs a near-grazing view to exceed 0.4). Sky (non-finite or non-positive depth) is either
left out or put on a dome of ``sky_radius``; a triangle joining sky and ground is always cut.
Triangles are wound counter-clockwise seen from the panorama's centre: their fronts face the viewer
inside the room (glTF's front face).
"""

from __future__ import annotations

import numpy as np
import torch


def rgbd_mesh(
    rgb: np.ndarray, radial_depth: np.ndarray, edge_threshold: float = 0.4, sky: str = "dome", sky_radius: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rgb [H, W, 3] (any colour space, passed through), radial_depth [H, W] metres (inf = sky) ->
    vertices [V, 3] float64 (holoflow's frame, metres), colors [V, 3] float64, faces [F, 3] int64.
    ``sky``: "dome" (sky on a sphere of ``sky_radius``, 0 = 2x the 99th percentile depth) or "omit".
    Vertices no face uses are dropped. ValueError for a depth map with no finite positive pixel."""
    from holoflow.geometry.pointcloud import far_shell_radius
    from holoflow.geometry.sphere import equirect_directions

    if sky not in ("dome", "omit"):
        raise ValueError(f"sky={sky!r}: use dome or omit")
    depth = np.asarray(radial_depth, np.float64)
    H, W = depth.shape
    bounded = np.isfinite(depth) & (depth > 0)
    if not bounded.any():
        raise ValueError("the depth map has no finite positive pixel: no mesh to build")
    radius = sky_radius if sky_radius > 0 else far_shell_radius(torch.from_numpy(depth))
    d = np.where(bounded, depth, radius)
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()  # [H, W, 3]
    verts = (dirs * d[..., None]).reshape(-1, 3)
    cols = np.asarray(rgb, np.float64).reshape(-1, 3)
    is_sky = ~bounded.reshape(-1)
    dflat = d.reshape(-1)
    # pole vertices: index H*W (top, -y) and H*W + 1 (bottom, +y)
    poles, pole_cols, pole_sky = [], [], []
    for row, up in ((0, -1.0), (H - 1, 1.0)):
        ok = bounded[row]
        r = float(np.median(depth[row][ok])) if ok.any() else radius
        poles.append([0.0, up * r, 0.0])
        pole_cols.append(cols.reshape(H, W, 3)[row][ok].mean(0) if ok.any() else cols.reshape(H, W, 3)[row].mean(0))
        pole_sky.append(not ok.any())
        dflat = np.append(dflat, r)
    verts = np.concatenate([verts, np.array(poles)])
    cols = np.concatenate([cols, np.array(pole_cols)])
    is_sky = np.concatenate([is_sky, np.array(pole_sky)])
    # grid triangles, wound inward: (p00, p10, p01) and (p01, p10, p11); u + 1 wraps
    v, u = np.meshgrid(np.arange(H - 1), np.arange(W), indexing="ij")
    p00, p01 = v * W + u, v * W + (u + 1) % W
    p10, p11 = p00 + W, p01 + W
    tris = [np.stack([p00, p10, p01], -1).reshape(-1, 3), np.stack([p01, p10, p11], -1).reshape(-1, 3)]
    u1 = np.arange(W)
    top, bottom = H * W, H * W + 1
    tris.append(np.stack([np.full(W, top), u1, (u1 + 1) % W], -1))  # top fan
    last = (H - 1) * W
    tris.append(np.stack([np.full(W, bottom), last + (u1 + 1) % W, last + u1], -1))  # bottom fan
    faces = np.concatenate(tris)
    # orient the fans by geometry (the grid is wound analytically): normal . centroid < 0 faces the centre
    fan = np.zeros(len(faces), bool)
    fan[-2 * W :] = True
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) > 0
    flip = fan & outward
    faces[flip] = faces[flip][:, [0, 2, 1]]
    # cut discontinuities, sky/ground seams, and (omit) sky
    fd = dflat[faces]  # [F, 3]
    fs = is_sky[faces]
    spread = (fd.max(1) - fd.min(1)) / fd.min(1)
    keep = (fs.all(1) | ~fs.any(1)) & (spread <= edge_threshold)
    if sky == "omit":
        keep &= ~fs.any(1)
    faces = faces[keep]
    used = np.zeros(len(verts), bool)
    used[faces.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return verts[used], cols[used], remap[faces].astype(np.int64)


def panorama_mesh_glb(
    rgb: np.ndarray,
    radial_depth: np.ndarray,
    width: int = 0,
    edge_threshold: float = 0.4,
    sky: str = "dome",
    sky_radius: float = 0.0,
) -> tuple[bytes, dict]:
    """mesh.glb's bytes and facts (grid, vertex and face counts) for a panorama: rgb [H, W, 3] linear,
    radial_depth [h, w] metres (inf = sky), both resampled to ``width`` x ``width // 2`` (0 = half the
    depth's width, P_f's resolution; colour antialiased, depth point-sampled), then :func:`rgbd_mesh`."""
    from holoflow.export.gltf import mesh_glb_bytes
    from holoflow.geometry.pointcloud import resample_rgbd

    depth = torch.from_numpy(np.asarray(radial_depth)).double()
    col, d = resample_rgbd(torch.from_numpy(np.asarray(rgb)).double(), depth, width or max(2, depth.shape[1] // 2))
    verts, cols, faces = rgbd_mesh(col.clamp(0, 1).numpy(), d.numpy(), edge_threshold, sky, sky_radius)
    info = {
        "mesh_grid": [int(d.shape[0]), int(d.shape[1])],
        "mesh_vertices": int(len(verts)),
        "mesh_faces": int(len(faces)),
    }
    return mesh_glb_bytes(verts, cols, faces), info
