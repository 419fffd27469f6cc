"""PLY read/write through plyfile, in the layouts every viewer reads (binary little-endian).

Point clouds: ``x y z`` float32, optionally ``nx ny nz`` float32 (unit normals), ``red green blue`` uchar.
Gaussians (INRIA 3DGS layout): ``x y z nx ny nz f_dc_0..2 [f_rest_0..] opacity scale_0..2 rot_0..3``,
all float32, stored BEFORE activation: opacity is a logit, scales are log-scales, f_dc = (rgb - 0.5) /
0.28209479 (SH degree 0 coefficient), rot is a (w, x, y, z) quaternion, not necessarily normalised.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

SH_C0 = 0.28209479177387814


class PlyError(ValueError):
    """A file that is not a readable PLY, or arrays that do not fit a layout."""


def write_points(path: str | Path, xyz: np.ndarray, rgb: np.ndarray, normals: np.ndarray | None = None) -> None:
    """Write a coloured point cloud: xyz [N, 3] (float32 metres), rgb [N, 3] (uint8) and, when given,
    normals [N, 3] (float32 unit vectors: nx ny nz after x y z, as MeshLab and Open3D read them)."""
    xyz = np.asarray(xyz, dtype=np.float32).reshape(-1, 3)
    rgb = np.asarray(rgb)
    if rgb.dtype != np.uint8:
        raise PlyError(f"write_points: rgb must be uint8, got {rgb.dtype}")
    rgb = rgb.reshape(-1, 3)
    if len(rgb) != len(xyz):
        raise PlyError(f"write_points: {len(xyz)} points but {len(rgb)} colours")
    dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
        if len(normals) != len(xyz):
            raise PlyError(f"write_points: {len(xyz)} points but {len(normals)} normals")
        dtype += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    vertex = np.empty(len(xyz), dtype=dtype + [("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for i, name in enumerate("xyz"):
        vertex[name] = xyz[:, i]
        if normals is not None:
            vertex["n" + name] = normals[:, i]
    for i, name in enumerate(("red", "green", "blue")):
        vertex[name] = rgb[:, i]
    _write(path, vertex)


def read_points(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a point cloud: xyz [N, 3] float32, rgb [N, 3] uint8 (grey 128 when the file has no colour)."""
    v = _read_vertex(path)
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float32)
    names = v.dtype.names
    if all(c in names for c in ("red", "green", "blue")):
        rgb = np.stack([v["red"], v["green"], v["blue"]], axis=1).astype(np.uint8)
    else:
        rgb = np.full((len(xyz), 3), 128, np.uint8)
    return xyz, rgb


def read_point_normals(path: str | Path) -> np.ndarray | None:
    """The normals [N, 3] float32 of a point cloud written with them (``write_points``), else None."""
    v = _read_vertex(path)
    if not all(c in v.dtype.names for c in ("nx", "ny", "nz")):
        return None
    return np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float32)


def gaussian_fields(num_rest: int = 0) -> list[str]:
    """Property names of the 3DGS layout, in file order; ``num_rest`` = count of f_rest_* values."""
    return (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(num_rest)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )


def write_gaussians(path: str | Path, fields: dict[str, np.ndarray]) -> None:
    """Write Gaussians in the 3DGS layout. ``fields`` maps each property name to a [N] array;
    normals default to zero. Missing or unexpected names raise PlyError."""
    num_rest = sum(1 for k in fields if k.startswith("f_rest_"))
    names = gaussian_fields(num_rest)
    n = len(np.asarray(fields["x"])) if "x" in fields else 0
    extra = set(fields) - set(names)
    missing = [k for k in names if k not in fields and k not in ("nx", "ny", "nz")]
    if extra or missing:
        raise PlyError(f"write_gaussians: unexpected {sorted(extra)}, missing {missing}")
    vertex = np.zeros(n, dtype=[(k, "<f4") for k in names])
    for k in names:
        if k in fields:
            a = np.asarray(fields[k], dtype=np.float32).reshape(-1)
            if len(a) != n:
                raise PlyError(f"write_gaussians: {k} has {len(a)} values, x has {n}")
            vertex[k] = a
    _write(path, vertex)


def read_gaussians(path: str | Path) -> dict[str, np.ndarray]:
    """Read a 3DGS PLY into {property name: float32 [N]} (values before activation)."""
    v = _read_vertex(path)
    required = [k for k in gaussian_fields(0) if k not in ("nx", "ny", "nz")]
    missing = [k for k in required if k not in v.dtype.names]
    if missing:
        raise PlyError(f"{path}: not a 3DGS PLY, missing {missing}")
    return {k: np.asarray(v[k], dtype=np.float32) for k in v.dtype.names}


def _write(path: str | Path, vertex: np.ndarray) -> None:
    from plyfile import PlyData, PlyElement

    PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<").write(str(path))


def _read_vertex(path: str | Path) -> np.ndarray:
    from plyfile import PlyData

    path = Path(path)
    if not path.is_file():
        raise PlyError(f"{path}: no such file")
    try:
        ply = PlyData.read(str(path))
        return ply["vertex"].data
    except Exception as exc:
        raise PlyError(f"{path}: unreadable PLY ({exc})") from None
