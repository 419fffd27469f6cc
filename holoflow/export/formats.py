"""The export stage's engine: a trained scene's Gaussians written in the formats asked for (the writers:
holoflow/export/splats.py for spz / splat / compressed_ply, holoflow/export/gltf.py for glb)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from holoflow.export.config import FORMATS
from holoflow.export.gltf import gaussians_glb_bytes
from holoflow.export.splats import activate, compressed_ply_bytes, splat_bytes, spz_bytes


def export_formats(fields: dict[str, np.ndarray], out_dir: str | Path, formats: list[str]) -> dict[str, int]:
    """Write the Gaussian formats among ``formats`` (spz, splat, compressed_ply, glb) of a 3DGS PLY's
    ``fields`` into ``out_dir`` (file names: holoflow.export.config.FORMATS); returns {file: bytes}."""
    s = activate(fields)
    writers = {"spz": spz_bytes, "splat": splat_bytes, "compressed_ply": compressed_ply_bytes,
               "glb": gaussians_glb_bytes}
    sizes = {}
    for fmt in formats:
        if fmt in writers:
            data = writers[fmt](s)
            (Path(out_dir) / FORMATS[fmt]).write_bytes(data)
            sizes[FORMATS[fmt]] = len(data)
    return sizes
