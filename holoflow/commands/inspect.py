"""`holoflow inspect`: what is in an EXR or PLY file (or every such file of a stage's outputs).

EXR (through OpenImageIO): size, channels and their pixel types, every header attribute (holoflow's
provenance and convention attributes included), per-channel min / max / mean over finite values and
NaN / +inf / -inf counts. PLY (through plyfile): per element its count and properties; for a vertex
element with x, y, z the bounding box. Other files: size and sha256.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


class InspectError(ValueError):
    pass


def inspect_target(path: Path) -> dict[str, Any]:
    """A report for a file, or {"files": {relative name: report}} for a folder."""
    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file())
        return {"path": str(path), "files": {p.relative_to(path).as_posix(): inspect_file(p) for p in files}}
    return inspect_file(path)


def inspect_files(files: dict[str, Path]) -> dict[str, Any]:
    """Reports for named files (e.g. a stage's outputs: relative name -> object path)."""
    return {"files": {name: {**inspect_file(p, name), "path": name} for name, p in sorted(files.items())}}


def inspect_file(path: Path, name: str | None = None) -> dict[str, Any]:
    """Report for one file; ``name`` (default: the path) decides the format by its suffix."""
    ext = Path(name or path).suffix.lower()
    if ext == ".exr":
        return inspect_exr(path)
    if ext == ".ply":
        return inspect_ply(path)
    from holoflow.flow.store import sha256_file

    return {"path": str(path), "kind": "file", "bytes": path.stat().st_size, "sha256": sha256_file(path)}


def inspect_exr(path: Path) -> dict[str, Any]:
    import numpy as np
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InspectError(f"{path}: not a readable EXR ({oiio.geterror()})")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")  # [H, W, C]
    finally:
        inp.close()
    if pixels is None:
        raise InspectError(f"{path}: could not read pixels")
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    channels = {}
    for i, name in enumerate(spec.channelnames):
        c = pixels[..., i]
        finite = c[np.isfinite(c)]
        channels[name] = {
            "type": str(spec.channelformat(i)),
            "min": float(finite.min()) if finite.size else None,
            "max": float(finite.max()) if finite.size else None,
            "mean": float(finite.mean(dtype=np.float64)) if finite.size else None,
            "nan": int(np.isnan(c).sum()),
            "posinf": int(np.isposinf(c).sum()),
            "neginf": int(np.isneginf(c).sum()),
        }
    attrs = {a.name: _plain(a.value) for a in spec.extra_attribs}
    return {
        "path": str(path),
        "kind": "exr",
        "width": spec.width,
        "height": spec.height,
        "channels": channels,
        "attributes": attrs,
    }


def inspect_ply(path: Path) -> dict[str, Any]:
    import numpy as np
    from plyfile import PlyData

    try:
        with open(path, "rb") as f:
            ply = PlyData.read(f)
    except Exception as e:  # plyfile raises several exception types for a malformed file
        raise InspectError(f"{path}: not a readable PLY ({type(e).__name__}: {e})") from None
    elements = {}
    for el in ply.elements:
        info: dict[str, Any] = {
            "count": int(el.count),
            "properties": {p.name: str(el.data.dtype[p.name]) for p in el.properties},
        }
        names = set(el.data.dtype.names or ())
        if {"x", "y", "z"} <= names and el.count:
            xyz = np.stack([el.data[k].astype(np.float64) for k in "xyz"], axis=1)  # [N, 3]
            ok = np.isfinite(xyz).all(axis=1)
            info["bbox_min"] = xyz[ok].min(axis=0).tolist() if ok.any() else None
            info["bbox_max"] = xyz[ok].max(axis=0).tolist() if ok.any() else None
            info["non_finite"] = int((~ok).sum())
        elements[el.name] = info
    return {
        "path": str(path),
        "kind": "ply",
        "format": "ascii" if ply.text else "binary",
        "comments": list(ply.comments),
        "elements": elements,
    }


def _plain(v: Any) -> Any:
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    try:
        return [_plain(x) for x in v]
    except TypeError:
        return str(v)


def format_report(rep: dict[str, Any]) -> str:
    if "files" in rep:
        return "\n\n".join(format_report(r) for r in rep["files"].values())
    lines = [f"{rep['path']}"]
    if rep["kind"] == "exr":
        lines.append(f"  EXR {rep['width']} x {rep['height']}, channels {', '.join(rep['channels'])}")
        for k, v in sorted(rep["attributes"].items()):
            lines.append(f"  {k}: {v}")
        lines.append(
            f"  {'channel':<8} {'type':<6} {'min':>12} {'max':>12} {'mean':>12} {'nan':>6} {'+inf':>6} {'-inf':>6}"
        )
        for name, c in rep["channels"].items():
            f = [("-" if c[k] is None else f"{c[k]:.6g}") for k in ("min", "max", "mean")]
            lines.append(
                f"  {name:<8} {c['type']:<6} {f[0]:>12} {f[1]:>12} {f[2]:>12} {c['nan']:>6} "
                f"{c['posinf']:>6} {c['neginf']:>6}"
            )
    elif rep["kind"] == "ply":
        lines.append(f"  PLY ({rep['format']})" + (f", comments: {rep['comments']}" if rep["comments"] else ""))
        for name, el in rep["elements"].items():
            lines.append(f"  {name}: {el['count']} x ({', '.join(f'{k} {t}' for k, t in el['properties'].items())})")
            if el.get("bbox_min") is not None:
                lo = ", ".join(f"{x:.4g}" for x in el["bbox_min"])
                hi = ", ".join(f"{x:.4g}" for x in el["bbox_max"])
                lines.append(f"    bbox [{lo}] .. [{hi}], non-finite {el['non_finite']}")
    else:
        lines.append(f"  {rep['bytes']} bytes, sha256 {rep['sha256']}")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """`holoflow inspect PATH|STAGE [--json]`."""
    import json

    from holoflow.commands import fail
    from holoflow.commands.options import common, load, parser

    p = parser("inspect")
    p.add_argument("target", metavar="PATH|STAGE")
    common(p, resolve_opts=False)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    target = Path(args.target)
    step = None
    try:
        if target.exists():
            report = inspect_target(target)
        else:
            pipe, store = load(args)
            if args.target not in pipe.stages:
                return fail(
                    f"{args.target}: neither a file nor a stage; fix: give an EXR/PLY path or one "
                    f"of: {', '.join(pipe.stages)}"
                )
            step, outputs = stage_outputs(store, args.target)
            if outputs is None:
                return fail(f"stage '{args.target}' has no recorded outputs; fix: holoflow run first")
            report = inspect_files({rel: store.object_path(e["digest"]) for rel, e in outputs.items()})
            report["step"] = step
    except InspectError as e:
        return fail(str(e))
    if args.json:
        print(json.dumps(report, indent=1, default=str))
        return 0
    if step is not None:
        print("step: " + ", ".join(f"{k}={json.dumps(v)}" for k, v in step.items() if v is not None))
    print(format_report(report))
    return 0


def stage_outputs(store, stage: str):
    """(step facts, output map) of ``stage`` in the latest run, else from its last record."""
    st = ((store.run_info(store.latest_run_id()) or {}).get("stages") or {}).get(stage)
    key = st.get("key") if st else store.last_key(stage)
    rec = store.record(key) if key else None
    if rec is None:
        return ({"how": st["how"], "source": st.get("source")}, st["outputs"]) if st else (None, None)
    prov = rec["provenance"]
    facts = {
        "key": rec["key"],
        **{
            k: prov.get(k)
            for k in ("engine", "params", "seed", "device", "wall_s", "peak_rss_mb", "started", "meta", "versions")
        },
    }
    return facts, rec["outputs"]
