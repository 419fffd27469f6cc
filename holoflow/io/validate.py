"""What odd values mean: the rules an imported panorama is repaired or refused by, and the finite-output
check every step's files pass before they are committed (docs/hard-inputs.md).

Colour (R, G, B, linear light) is repaired, never refused, as long as one pixel is finite: NaN and
-inf become 0, +inf becomes ``MAX_LINEAR``, negative values become 0 (light is never negative) and
values above ``MAX_LINEAR`` (the largest half float, what an HDR EXR can hold) become ``MAX_LINEAR``.
A depth channel (Z, radial metres, +inf = sky) holding NaN, -inf, zero or negative values is not
trusted at all: it is dropped and the depth stages estimate depth from the picture (``auto`` ->
layout). Every count goes to the run record and the run's output.

A step's outputs: every float in an EXR or PLY must be finite, except +inf in a depth channel (Z of an
EXR whose ``holoflow.depth_kind`` is radial, z or unset): sky. The first file that breaks it fails the step in
one line naming the stage, the file, the channel and the counts, before anything is committed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MAX_LINEAR = 65504.0  # largest finite half float: the brightest value an HDR EXR can hold
DEPTH_KINDS = ("radial", "z")  # EXR depth kinds whose Z may be +inf (sky)


def repair_colour(rgb: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """Linear colour [..., 3] made finite and in [0, MAX_LINEAR] by the module's rule -> (float32 copy,
    counts of values changed per reason; empty when nothing changed). Raises ValueError when no value
    is finite (nothing to keep)."""
    x = np.asarray(rgb, np.float32)
    counts = {"nan": int(np.isnan(x).sum()), "+inf": int(np.isposinf(x).sum()), "-inf": int(np.isneginf(x).sum())}
    finite = np.isfinite(x)
    if x.size and not finite.any():
        raise ValueError("no colour value is finite (all NaN / inf); fix: check the file")
    counts["negative"] = int((finite & (x < 0)).sum())
    counts["above_max"] = int((finite & (x > MAX_LINEAR)).sum())
    counts = {k: v for k, v in counts.items() if v}
    if not counts:
        return x, {}
    out = np.nan_to_num(x, nan=0.0, posinf=MAX_LINEAR, neginf=0.0)
    return np.clip(out, 0.0, MAX_LINEAR, out=out), counts


def depth_problems(z: np.ndarray) -> dict[str, int]:
    """Counts of the values that make a depth channel (metres, +inf = sky) untrustworthy: NaN, -inf,
    zero, negative. Empty when it is usable."""
    z = np.asarray(z)
    counts = {
        "nan": int(np.isnan(z).sum()),
        "-inf": int(np.isneginf(z).sum()),
        "zero": int((z == 0).sum()),
        "negative": int((np.isfinite(z) & (z < 0)).sum()),
    }
    return {k: v for k, v in counts.items() if v}


def describe(counts: dict[str, int], total: int) -> str:
    """'12 nan, 3 negative of 6144 values' (counts as ``repair_colour`` / ``depth_problems`` give them)."""
    return ", ".join(f"{v} {k}" for k, v in counts.items()) + f" of {total} values"


def colour_rule() -> str:
    return f"NaN and -inf -> 0, +inf -> {MAX_LINEAR:g}, negative -> 0, above {MAX_LINEAR:g} -> {MAX_LINEAR:g}"


def output_problem(folder: str | Path) -> str | None:
    """The first non-finite value among a step's output files (EXR and PLY under ``folder``, sorted by
    name): 'FILE: channel C has N NaN, M inf' or None when every value is finite (+inf allowed in
    depth channels only)."""
    folder = Path(folder)
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        ext = path.suffix.lower()
        bad = _exr_problem(path) if ext == ".exr" else _ply_problem(path) if ext == ".ply" else None
        if bad:
            return f"{path.relative_to(folder).as_posix()}: {bad}"
    return None


def _exr_problem(path: Path) -> str | None:
    from .exr import read_exr

    channels, attrs = read_exr(path)
    sky_ok = attrs.get("holoflow.depth_kind", "radial") in DEPTH_KINDS  # no kind: radial, as readers take it
    for name in sorted(channels):
        a = channels[name]
        if np.isfinite(a).all():
            continue
        nan, pinf, ninf = int(np.isnan(a).sum()), int(np.isposinf(a).sum()), int(np.isneginf(a).sum())
        if name == "Z" and sky_ok and not nan and not ninf:
            continue  # +inf: sky
        return f"channel {name} has {nan} NaN, {pinf} +inf, {ninf} -inf of {a.size} values"
    return None


def _ply_problem(path: Path) -> str | None:
    from plyfile import PlyData

    with open(path, "rb") as f:
        ply = PlyData.read(f)
    for el in ply.elements:
        for name in el.data.dtype.names or ():
            a = el.data[name]
            if a.dtype.kind == "f" and not np.isfinite(a).all():
                return f"{el.name} property {name} has {int((~np.isfinite(a)).sum())} non-finite of {a.size} values"
    return None


class InputRefused(ValueError):
    """A user's file that cannot be imported: one line, with the fix."""


MIN_HEIGHT = 8  # px: an equirect panorama smaller than 16 x 8 has no room for the depth stages' faces


def check_equirect_size(name: str, width: int, height: int) -> None:
    """Refuse a panorama that is not 2:1 or smaller than 2 MIN_HEIGHT x MIN_HEIGHT, in one line."""
    if width != 2 * height:
        raise InputRefused(
            f"{name} is {width}x{height}, not a 2:1 equirect panorama; fix: pass a full "
            f"360x180 equirect image (e.g. {2 * height}x{height}) or one with GPano crop metadata"
        )
    if height < MIN_HEIGHT:
        raise InputRefused(
            f"{name} is {width}x{height}, too small for a panorama (at least "
            f"{2 * MIN_HEIGHT}x{MIN_HEIGHT}); fix: pass a larger image"
        )


def check_exr(path: str | Path, equirect: bool = True) -> tuple[dict[str, np.ndarray] | None, dict, dict]:
    """A user's single-file EXR for a stage, under the module's rules (``equirect``: also the panorama
    size rule) -> (channels to write instead of the file, or None when the file is kept byte for byte;
    its header attributes; facts for the run record: ``repaired`` / ``dropped`` notes). Raises
    InputRefused (one line)."""
    from .exr import ExrError, read_exr

    path = Path(path)
    try:
        channels, attrs = read_exr(path)
    except ExrError as e:
        raise InputRefused(
            f"{path.name} does not open as EXR ({e}); fix: pass an OpenEXR file (e.g. oiiotool IN -o OUT.exr)"
        ) from None
    if not channels:
        raise InputRefused(f"{path.name} has no channels; fix: pass an EXR with R, G, B (and Z)")
    if equirect:
        h, w = next(iter(channels.values())).shape
        check_equirect_size(path.name, w, h)
    facts: dict = {}
    out = dict(channels)
    colour = all(c in channels for c in "RGB")
    if colour:
        rgb, counts = _repair_or_refuse(path.name, np.stack([channels[c] for c in "RGB"], -1))
        if counts:
            out.update(R=rgb[..., 0], G=rgb[..., 1], B=rgb[..., 2])
            facts["repaired"] = f"R,G,B: {describe(counts, rgb.size)} ({colour_rule()})"
    if "Z" in channels and (bad := depth_problems(channels["Z"])):
        what = describe(bad, channels["Z"].size)
        if not colour:
            raise InputRefused(
                f"{path.name}: depth channel Z has {what}; depth must be > 0 metres or +inf "
                f"(sky); fix: mark unknown depth as +inf or pass the file without Z"
            )
        del out["Z"]
        facts["dropped"] = (
            f"Z: {what} (NaN, -inf, 0 and negative depths are not trusted: the depth "
            f"channel is dropped and depth is estimated from the picture)"
        )
    for name in sorted(set(channels) - set("RGBZ")):
        if not np.isfinite(channels[name]).all():
            raise InputRefused(
                f"{path.name}: channel {name} has {int((~np.isfinite(channels[name])).sum())} "
                f"non-finite values; fix: pass the file without it or with finite values"
            )
    return (out if facts else None), attrs, facts


def _repair_or_refuse(name: str, rgb: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    try:
        return repair_colour(rgb)
    except ValueError as e:
        raise InputRefused(f"{name}: {e}") from None
