"""Reading the depth stages' inputs: a panorama's RGB, its truth depth (Z), a disparity EXR."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_pano(path: str | Path) -> np.ndarray:
    """Linear RGB [H, W, 3] of a panorama EXR."""
    from holoflow.io.exr import read_rgb

    return read_rgb(path)


def read_truth(folder: str | Path | None, name: str = "pano.exr") -> np.ndarray | None:
    """True radial depth [H, W] (metres, +inf sky) from ``folder/name``'s Z channel, or None when the
    folder, the file or the Z channel is absent, or the header says the Z is not radial."""
    from holoflow.io.exr import read_exr

    if folder is None or not (Path(folder) / name).is_file():
        return None
    channels, attrs = read_exr(Path(folder) / name)
    if "Z" not in channels or attrs.get("holoflow.depth_kind", "radial") != "radial":
        return None
    z = channels["Z"].astype(np.float64)
    return np.where(np.isnan(z) | (z <= 0), np.inf, z)


def read_disparity(path: str | Path) -> tuple[np.ndarray, str]:
    """Relative disparity [H, W] (Y channel) of a tangent_depth output and the engine that made it (its
    header's ``holoflow.engine``, "" if unnamed); raises ValueError if the Y channel is absent."""
    from holoflow.io.exr import read_exr

    channels, attrs = read_exr(path)
    if "Y" not in channels:
        raise ValueError(f"{path}: no Y channel (expected tangent_depth's disparity.exr)")
    return channels["Y"].astype(np.float64), str(attrs.get("holoflow.engine", ""))
