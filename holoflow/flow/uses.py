"""Your own files as a stage's outputs (`holoflow run --use STAGE=PATH`): checked, imported into the
store (an image panorama decoded to the stage's linear EXR), and remembered so `status` sees the same
digests without decoding again."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from .pipeline import PipelineError

if TYPE_CHECKING:
    from .context import Context


def import_note(facts: dict | None) -> str:
    """'; repaired ...; dropped ...' for a step line: what an import changed (holoflow.io.validate)."""
    return "".join(f"; {k} {facts[k]}" for k in ("repaired", "dropped") if facts and k in facts)


def dropped_uses(ctx: Context) -> dict[str, str]:
    """Stages the latest run took from a user's file (``--use``) that ``ctx`` does not: stage -> source."""
    latest = ctx.store.run_info(ctx.store.latest_run_id()) or {}
    return {
        name: str(s.get("source"))
        for name, s in latest.get("stages", {}).items()
        if s.get("how") == "used" and name not in ctx.uses
    }


def import_use(ctx: Context, stage: str, src: Path) -> dict[str, dict]:
    """Validate the user's file(s) for ``stage`` and hash them into the store; returns the output map."""
    s = ctx.pipe.stages[stage]
    if src.is_dir():
        files = {p.relative_to(src).as_posix(): p for p in sorted(src.rglob("*")) if p.is_file()}
        if not files:
            raise PipelineError(f"--use {stage}={src}: the folder is empty; fix: point at the stage's files")
    elif s.primary and s.primary.endswith(".exr") and src.suffix.lower() in IMAGE_EXTS:
        return _import_image(ctx, stage, src)
    elif s.primary and s.primary.endswith(".exr") and src.suffix.lower() == ".exr":
        return _import_exr(ctx, stage, src)
    else:
        name = s.primary or src.name
        if s.primary and Path(s.primary).suffix.lower() != src.suffix.lower():
            raise PipelineError(
                f"--use {stage}={src}: {stage}'s main output is {s.primary}, got a "
                f"{src.suffix or 'suffix-less'} file; fix: convert it (e.g. oiiotool IN -o "
                f"OUT{Path(s.primary).suffix})"
            )
        files = {name: src}
    for rel, p in files.items():
        _validate_file(stage, p)
    return _copy_in(ctx, stage, files)


def _copy_in(ctx: Context, stage: str, files: dict[str, Path]) -> dict[str, dict]:
    outputs = {}
    for rel, p in files.items():
        tmp = ctx.store.staging(f"use-{stage}") / "f"
        shutil.copyfile(p, tmp)
        outputs[rel] = ctx.store.put(tmp)
        tmp.parent.rmdir()
    return outputs


IMAGE_EXTS = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".hdr")  # holoflow.io.image.IMAGE_EXTS less .exr


def _import_image(ctx: Context, stage: str, src: Path) -> dict[str, dict]:
    """A photo / image panorama for an EXR stage: decoded to linear RGB (holoflow.io.image), written as
    the stage's primary EXR; the facts (file, digest, colour handling, GPano) go to the run record.
    The same file through the same decoder code is decoded once per store (``import_cache``): a rerun
    with a 6656 px photo costs its sha256, not a decode and a 265 MB EXR."""
    from holoflow.io.exr import write_rgb
    from holoflow.io.image import ImageImportError, read_panorama_image
    from holoflow.io.validate import InputRefused

    from .store import sha256_file

    sha, name = sha256_file(src), src.name
    hit = import_cache(ctx, sha, facts=True)
    if hit is not None and hit["facts"].get("file") == name:
        ctx.imports[stage] = hit["facts"]
        return hit["outputs"]
    try:
        rgb, facts = read_panorama_image(src)
    except (ImageImportError, InputRefused) as e:
        raise PipelineError(f"--use {stage}: {e}") from None
    tmp = ctx.store.staging(f"use-{stage}") / "f.exr"
    write_rgb(
        tmp,
        rgb,
        {
            "holoflow.source": facts["file"],
            "holoflow.source_sha256": facts["sha256"],
            "holoflow.source_colour": facts["colour"],
        },
    )
    out = {ctx.pipe.stages[stage].primary: ctx.store.put(tmp)}
    tmp.parent.rmdir()
    ctx.imports[stage] = facts
    import_cache(ctx, facts["sha256"], out, facts)
    return out


def _import_exr(ctx: Context, stage: str, src: Path) -> dict[str, dict]:
    """A single EXR for an EXR stage under holoflow.io.validate's rules: kept byte for byte when it
    passes, else written repaired (the notes go to the run record and the step's line), or refused."""
    from holoflow.io.exr import write_exr
    from holoflow.io.validate import InputRefused, check_exr

    from .store import sha256_file

    s = ctx.pipe.stages[stage]
    equirect = s.config is not None and s.config.__module__.startswith("holoflow.")  # holoflow's own EXR stages
    try:
        channels, attrs, facts = check_exr(src, equirect)
    except InputRefused as e:
        raise PipelineError(f"--use {stage}: {e}") from None
    if channels is None:
        return _copy_in(ctx, stage, {ctx.pipe.stages[stage].primary: src})
    sha = sha256_file(src)
    tmp = ctx.store.staging(f"use-{stage}") / "f.exr"
    write_exr(
        tmp,
        channels,
        {**attrs, "holoflow.source": src.name, "holoflow.source_sha256": sha, "holoflow.import_notes": facts},
    )
    out = {ctx.pipe.stages[stage].primary: ctx.store.put(tmp)}
    tmp.parent.rmdir()
    ctx.imports[stage] = {"file": src.name, "sha256": sha, **facts}
    import_cache(ctx, sha, out)
    return out


def import_cache(ctx: Context, source_sha: str, outputs: dict | None = None, facts: dict | None = None) -> dict | None:
    """Remember (``outputs`` given) or look up the outputs an image file imported to, by the file's
    sha256 and the decoder's code (holoflow/io/image.py and what it imports), so that ``status`` sees
    the same input digests as the run and a rerun skips the decode. A lookup returns the outputs, or
    with ``facts=True`` {"outputs", "facts"} (None when the facts were not recorded); None when absent
    or when an output object has left the store (``holoflow gc``)."""
    from .code_closure import HOLOFLOW_ROOT
    from .store import canonical_json, sha256_bytes

    path = ctx.store.root / "cache" / "imports.json"
    decoder_code = ctx.hasher.closure(Path(HOLOFLOW_ROOT) / "holoflow" / "io" / "image.py")  # no import
    decoder = sha256_bytes(canonical_json(decoder_code).encode())[:16]
    key = f"{source_sha}:{decoder}"
    try:
        table = json.loads(path.read_text())
    except (OSError, ValueError):
        table = {}
    if outputs is None:
        entry = table.get(key)
        if not isinstance(entry, dict) or not all(
            ctx.store.object_path(o["digest"]).is_file() for o in entry.get("outputs", {}).values()
        ):
            return None
        if facts:
            return entry if "facts" in entry else None
        return entry["outputs"]
    table[key] = {"outputs": outputs, **({"facts": facts} if facts is not None else {})}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(table, sort_keys=True))
    os.replace(tmp, path)
    return outputs


def _validate_file(stage: str, p: Path) -> None:
    ext = p.suffix.lower()
    if ext == ".exr":
        from holoflow.io.exr import ExrError, read_exr

        try:
            read_exr(p)
        except ExrError as e:
            raise PipelineError(
                f"--use {stage}: {p} does not open as EXR ({e}); fix: pass an OpenEXR "
                f"file (e.g. oiiotool IN -o OUT.exr)"
            ) from None
    elif ext == ".ply":
        from plyfile import PlyData

        try:
            with open(p, "rb") as f:
                PlyData.read(f)
        except Exception as e:  # plyfile raises several types for a broken file
            raise PipelineError(
                f"--use {stage}: {p} does not open as PLY ({type(e).__name__}: {e}); fix: pass a valid PLY file"
            ) from None


# -- planning ------------------------------------------------------------------------------------
