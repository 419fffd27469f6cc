"""A stage's output files -> the report's figures and numbers. Driven by the files themselves, so any
stage (including one added to pipeline.yaml later) gets pictures:

- a top-level EXR: R,G,B as a colour image, A as a mask, Z (radial depth) and disparity Y as colour
  maps, line art / other Y as grey, any other channel as a colour map;
- a folder of EXRs (views/, faces/, renders/): one contact sheet per channel group (RGB, A, ...);
- PNG / GIF / JPEG files (e.g. transfer_opt's previews): embedded as they are;
- ``train_log.json`` (pre_opt / transfer_opt): loss and Gaussian-count curves over all phases;
- PLY files: pictures made by ``holoflow.report.clouds`` (passed in, rendered in one batch);
- JSON files and the key record's meta: scalar numbers for the metrics table.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from holoflow.report import pictures as pic

PANO_WIDTH = 1024  # panoramas and other top-level images are shown at most this wide, pixels
SHEET_TILES = 64  # a contact sheet shows at most this many files (the first ones, sorted)
SHEET_SIDE = 96  # contact sheet cell, pixels
SHEET_COLS = 10
SMOOTH = 10  # loss curves also show the mean of this many iterations
MAX_KEYS = 16  # a JSON object with more keys than this (e.g. one entry per face) is left out
MIME = {".png": "image/png", ".gif": "image/gif", ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}


@dataclass
class Figure:
    title: str
    uri: str  # data: URI
    caption: str = ""


# -- one EXR ---------------------------------------------------------------------------------------
def exr_figures(path: Path, rel: str) -> list[Figure]:
    """Figures of one EXR file (module docstring)."""
    from holoflow.io.exr import read_exr

    ch, attrs = read_exr(path)
    h, w = next(iter(ch.values())).shape
    size = f"{w} x {h}"
    out = []
    for layer, img, caption in layers(ch, attrs):
        shown = pic.fit_width(img, PANO_WIDTH)
        out.append(Figure(f"{rel} {layer}" if layer != "RGB" else rel, pic.image_uri(shown), f"{size}; {caption}"))
    return out


def layers(ch: dict[str, np.ndarray], attrs: dict[str, Any]) -> list[tuple[str, np.ndarray, str]]:
    """(layer name, uint8 [H, W, 3] picture, caption) for each displayable channel group."""
    out = []
    if all(c in ch for c in "RGB"):
        rgb = np.stack([ch["R"], ch["G"], ch["B"]], -1)
        out.append(("RGB", pic.colour(rgb), "linear RGB shown in sRGB"))
    for name in sorted(c for c in ch if not (c in "RGB" and all(k in ch for k in "RGB"))):
        out.append((name, *scalar_layer(name, ch[name], attrs)))
    return out


def scalar_layer(
    name: str, values: np.ndarray, attrs: dict[str, Any], vrange: tuple[float, float] | None = None
) -> tuple[np.ndarray, str]:
    """One channel [H, W] -> (uint8 picture, caption), chosen by channel name and header."""
    kind = attrs.get("holoflow.depth_kind")
    if name == "A":
        return pic.grey(values), "mask: white = 1 (observed / hit), black = 0 (missing)"
    if name == "Z" or (kind in ("radial", "z") and name.endswith("Z")):
        lo, hi = pic.robust_range(values)
        return pic.depth_map(values), (
            f"{kind or 'radial'} depth, inverse-depth colours (red near, blue far; "
            f"{lo:.2f}-{hi:.2f} m), grey = no value / sky"
        )
    if "line" in str(attrs.get("holoflow.meaning", "")):
        return pic.grey(1.0 - values), "line art, shown dark on white"
    lo, hi = vrange or pic.robust_range(values)
    label = "disparity" if kind == "disparity" else "value"
    return pic.colour_map(values, lo, hi), f"{label}, turbo colours over {lo:.3g}-{hi:.3g} (red = high)"


# -- a folder of EXRs: contact sheets --------------------------------------------------------------
def sheet_figures(folder: str, paths: list[Path]) -> list[Figure]:
    """Contact sheets of up to ``SHEET_TILES`` EXR files of one folder, one per channel group. Scalar
    channels share one colour range across the sheet, except those named ``raw*`` (per-file range:
    e.g. tangent_depth's per-face disparity before alignment, which has no common scale)."""
    from holoflow.io.exr import read_exr

    shown = paths[:SHEET_TILES]
    files = [read_exr(p) for p in shown]
    names = [p.stem for p in shown]
    groups: dict[str, list[np.ndarray]] = {}
    captions: dict[str, str] = {}
    scalars = sorted({c for ch, _ in files for c in ch if not _is_rgb(c, ch)})
    if any(all(c in ch for c in "RGB") for ch, _ in files):
        groups["RGB"] = [
            pic.colour(np.stack([ch[c] for c in "RGB"], -1)) if all(c in ch for c in "RGB") else _blank(ch)
            for ch, _ in files
        ]
        captions["RGB"] = "linear RGB shown in sRGB"
    for name in scalars:
        common = (
            None
            if name.startswith("raw")
            else pic.robust_range(np.concatenate([ch[name].ravel() for ch, _ in files if name in ch]))
        )
        tiles = []
        for ch, attrs in files:
            if name in ch:
                img, captions[name] = scalar_layer(name, ch[name], attrs, common)
                tiles.append(img)
            else:
                tiles.append(_blank(ch))
        if name.startswith("raw"):
            captions[name] += "; each tile its own range"
        groups[name] = tiles
    more = f"the first {len(shown)} of {len(paths)} files" if len(paths) > len(shown) else f"{len(paths)} files"
    h, w = next(iter(files[0][0].values())).shape
    out = []
    for layer, tiles in groups.items():
        sheet = pic.mosaic(tiles, SHEET_COLS, min(SHEET_SIDE, max(h, w) * 3))
        out.append(
            Figure(
                f"{folder}/ {layer}" if layer != "RGB" else f"{folder}/",
                pic.image_uri(sheet),
                f"{more} ({names[0]} ... {names[-1]}, row-major), each {w} x {h}; {captions[layer]}",
            )
        )
    return out


def _is_rgb(c: str, ch: dict) -> bool:
    return c in ("R", "G", "B") and all(k in ch for k in "RGB")


def _blank(ch: dict) -> np.ndarray:
    h, w = next(iter(ch.values())).shape
    return np.full((h, w, 3), 255, np.uint8)


# -- training curves ------------------------------------------------------------------------------
def train_log_figures(path: Path, rel: str) -> list[Figure]:
    """Loss and Gaussian-count curves of a ``train_log.json`` ({"phases": [{"name", "train": {"loss":
    [...], "count": [...]}}]}); phases are drawn one after the other with a marker where each starts."""
    log = json.loads(path.read_text())
    phases = [p for p in log.get("phases", []) if p.get("train", {}).get("loss")]
    if not phases:
        return []
    bounds, loss, count, start = [], [], [], 0
    for p in phases:
        tr = p["train"]
        bounds.append((start, str(p.get("name", ""))))
        loss.extend(tr["loss"])
        count.extend(tr.get("count", []))
        start += len(tr["loss"])
    series = [{"label": "loss", "y": loss}]
    if len(loss) >= 4 * SMOOTH:
        series.append(
            {"label": f"mean of {SMOOTH}", "y": moving_mean(loss, SMOOTH), "x": np.arange(SMOOTH - 1, len(loss))}
        )
    figs = [
        Figure(
            f"{rel}: loss",
            pic.data_uri(pic.curves_png(series, "training loss", "loss", log_y=True, bounds=bounds), "image/png"),
            f"{len(loss)} iterations over {len(phases)} phase(s): "
            + ", ".join(f"{p.get('name')} ({len(p['train']['loss'])})" for p in phases),
        )
    ]
    if count:
        figs.append(
            Figure(
                f"{rel}: Gaussians",
                pic.data_uri(
                    pic.curves_png([{"label": "Gaussians", "y": count}], "number of Gaussians", "count", bounds=bounds),
                    "image/png",
                ),
                f"{count[0]} -> {count[-1]} Gaussians (densification and pruning)",
            )
        )
    return figs


def moving_mean(y: list[float], n: int) -> np.ndarray:
    """Mean of each window of ``n`` consecutive values: [len(y) - n + 1]."""
    c = np.cumsum(np.concatenate([[0.0], np.asarray(y, dtype=float)]))
    return (c[n:] - c[:-n]) / n


# -- files as they are ----------------------------------------------------------------------------
def embedded_figure(path: Path, rel: str) -> Figure:
    return Figure(rel, pic.data_uri(path.read_bytes(), MIME[path.suffix.lower()]), "as written by the stage")


# -- numbers --------------------------------------------------------------------------------------
def scalars(obj: Any, prefix: str = "", depth: int = 3) -> dict[str, Any]:
    """Flatten the numbers, booleans and short strings of nested dicts (lists, and nested objects
    with more than ``MAX_KEYS`` keys, skipped) into {"a.b.c": value}, at most ``depth`` levels deep."""
    out: dict[str, Any] = {}
    if not isinstance(obj, dict) or depth == 0 or (prefix and len(obj) > MAX_KEYS):
        return out
    for k, v in obj.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(scalars(v, name + ".", depth - 1))
        elif isinstance(v, bool) or (isinstance(v, (int, float)) and math.isfinite(v)):
            out[name] = v
        elif isinstance(v, str) and len(v) <= 80:
            out[name] = v
    return out


def stage_metrics(record: dict[str, Any], files: dict[str, Path], limit: int = 40) -> dict[str, Any]:
    """The stage's numbers: its key record's meta, then the top-level JSON outputs' scalars (e.g.
    metric_align.json, train_log.json's fit) that the meta does not already say, at most ``limit``."""
    out = scalars(record.get("meta", {}))
    for rel, path in files.items():
        if rel.endswith(".json") and "/" not in rel and rel not in ("cameras.json", "transforms.json"):
            try:
                doc = json.loads(path.read_text())
            except (OSError, ValueError):
                continue
            body = {"fit": doc["fit"]} if rel == "train_log.json" and "fit" in doc else doc
            out.update({f"{rel}: {k}": v for k, v in scalars(body).items() if out.get(k, v) != v or k not in out})
    return dict(list(out.items())[:limit])


# -- a whole stage --------------------------------------------------------------------------------
def stage_figures(files: dict[str, Path], clouds: dict[str, Figure]) -> tuple[list[Figure], list[str]]:
    """Every figure of a stage's outputs ({name: path}) in file order, plus one note per file that
    could not be pictured. ``clouds``: pre-rendered point-cloud figures by output name."""
    figs: list[Figure] = []
    notes: list[str] = []
    folders: dict[str, list[Path]] = {}
    for rel, path in files.items():
        suffix = path.suffix.lower()
        try:
            if suffix in MIME:
                figs.append(embedded_figure(path, rel))
            elif suffix == ".exr" and "/" in rel:
                folders.setdefault(rel.rsplit("/", 1)[0], []).append(path)
            elif suffix == ".exr":
                figs.extend(exr_figures(path, rel))
            elif suffix == ".ply":
                if rel in clouds:
                    figs.append(clouds[rel])
                else:
                    notes.append(f"{rel}: no picture (unreadable PLY)")
            elif path.name == "train_log.json":
                figs.extend(train_log_figures(path, rel))
        except (OSError, ValueError, KeyError) as e:
            notes.append(f"{rel}: no picture ({type(e).__name__}: {str(e)[:160]})")
    for folder, paths in folders.items():
        try:
            figs.extend(sheet_figures(folder, paths))
        except (OSError, ValueError) as e:
            notes.append(f"{folder}/: no picture ({type(e).__name__}: {str(e)[:160]})")
    return figs, notes
