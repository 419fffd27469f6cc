"""EXR read/write through OpenEXR: float32 channels, ZIP compression, byte-deterministic.

Channels are float32 arrays [H, W] keyed by name: colour as R, G, B (linear light), alpha / masks as A,
depth as Z (metres; the header's ``holoflow.depth_kind`` says radial / z / disparity), anything else by its
own name. Header attributes are str, int or float; other JSON-able values are stored as JSON strings and
decoded on read. Same arrays + attributes -> same bytes, which the store's early cutoff relies on.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

_STANDARD = {
    "channels",
    "compression",
    "dataWindow",
    "displayWindow",
    "lineOrder",
    "pixelAspectRatio",
    "screenWindowCenter",
    "screenWindowWidth",
    "type",
}
_JSON_PREFIX = "json:"


class ExrError(ValueError):
    """A file that is not a readable EXR, or arrays that cannot be written as one."""


def write_exr(path: str | Path, channels: dict[str, np.ndarray], attrs: dict[str, Any] | None = None) -> None:
    """Write float32 channels (each [H, W]) and header attributes to ``path``."""
    import OpenEXR

    if not channels:
        raise ExrError("write_exr: no channels")
    arrays = {name: np.ascontiguousarray(np.asarray(a, dtype=np.float32)) for name, a in channels.items()}
    shapes = {a.shape for a in arrays.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ExrError(
            f"write_exr: channels must share one [H, W] shape, got { {k: a.shape for k, a in arrays.items()} }"
        )
    height, width = next(iter(shapes))
    if height < 1 or width < 1:
        raise ExrError(f"write_exr: empty image {height}x{width}")
    header: dict[str, Any] = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (attrs or {}).items():
        if key in _STANDARD:
            raise ExrError(f"write_exr: attribute name {key!r} is reserved by OpenEXR")
        header[key] = _encode_attr(value)
    with OpenEXR.File(header, arrays) as f:
        f.write(str(path))


def read_exr(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read every channel (float32 [H, W]) and the non-standard header attributes."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise ExrError(f"{path}: no such file")
    with open(path, "rb") as fh:
        magic = fh.read(4)
    if magic != b"\x76\x2f\x31\x01":
        raise ExrError(f"{path}: not an EXR file (bad magic number)")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            header = dict(f.header())
            channels = {name: np.asarray(ch.pixels, dtype=np.float32) for name, ch in f.channels().items()}
    except Exception as exc:  # OpenEXR raises several types for damaged files
        raise ExrError(f"{path}: unreadable EXR ({exc})") from None
    attrs = {k: _decode_attr(v) for k, v in header.items() if k not in _STANDARD}
    return channels, attrs


def write_rgb(path: str | Path, rgb: np.ndarray, attrs: dict[str, Any] | None = None, **extra: np.ndarray) -> None:
    """Write a linear RGB image [H, W, 3] as R, G, B plus named extra channels (e.g. Z=depth, A=mask)."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ExrError(f"write_rgb: expected [H, W, 3], got {rgb.shape}")
    channels = {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], **extra}
    write_exr(path, channels, {"holoflow.colorspace": "linear", **(attrs or {})})


def read_rgb(path: str | Path) -> np.ndarray:
    """Read R, G, B of an EXR as float32 [H, W, 3]."""
    return read_rgb_attrs(path)[0]


def read_rgb_attrs(path: str | Path) -> tuple[np.ndarray, dict[str, Any]]:
    """R, G, B of an EXR as float32 [H, W, 3] and its non-standard header attributes, in one read."""
    channels, attrs = read_exr(path)
    missing = [c for c in "RGB" if c not in channels]
    if missing:
        raise ExrError(f"{path}: no {','.join(missing)} channel(s); has {sorted(channels)}")
    return np.stack([channels["R"], channels["G"], channels["B"]], axis=-1), attrs


def read_radial_depth(path: str | Path) -> np.ndarray:
    """Radial depth [H, W] float32 (metres, inf = sky) from an EXR's Z channel; ExrError when there is no Z
    or the header's ``holoflow.depth_kind`` says it is not radial (unset reads as radial)."""
    channels, attrs = read_exr(path)
    if "Z" not in channels or attrs.get("holoflow.depth_kind", "radial") != "radial":
        raise ExrError(f"{path}: no radial depth in channel Z (expected metric_align's depth.exr)")
    return channels["Z"]


def _encode_attr(value: Any) -> Any:
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, str):
        return value
    return _JSON_PREFIX + json.dumps(value, sort_keys=True, separators=(",", ":"))


def _decode_attr(value: Any) -> Any:
    if isinstance(value, str) and value.startswith(_JSON_PREFIX):
        return json.loads(value[len(_JSON_PREFIX) :])
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    return value
