"""The export stage's engine: a trained scene's Gaussians written in the formats asked for (the writers:
holoflow/export/splats.py for spz / splat / compressed_ply, holoflow/export/gltf.py for glb)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from holoflow.export.config import FORMATS
from holoflow.export.gltf import gaussians_glb_bytes
from holoflow.export.splats import activate, compressed_ply_bytes, splat_bytes, spz_bytes


def export_formats(
    fields: dict[str, np.ndarray], out_dir: str | Path, formats: list[str], workers: int = 1
) -> dict[str, int]:
    """Write the Gaussian formats among ``formats`` (spz, splat, compressed_ply, glb) of a 3DGS PLY's
    ``fields`` into ``out_dir`` (file names: holoflow.export.config.FORMATS); returns {file: bytes}.
    ``workers`` threads encode formats side by side (gzip and NumPy release the GIL); each format's
    bytes are the same for any count."""
    s = activate(fields)
    writers = {
        "spz": spz_bytes,
        "splat": splat_bytes,
        "compressed_ply": compressed_ply_bytes,
        "glb": gaussians_glb_bytes,
    }
    todo = [f for f in formats if f in writers]
    with ThreadPoolExecutor(max(1, workers)) as pool:
        encoded = list(pool.map(lambda f: writers[f](s), todo))
    sizes = {}
    for fmt, data in zip(todo, encoded):
        (Path(out_dir) / FORMATS[fmt]).write_bytes(data)
        sizes[FORMATS[fmt]] = len(data)
    return sizes
