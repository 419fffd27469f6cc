"""The real-model engines' weights as a whole: which models a profile loads, whether they are here, and a
folder of models named by a manifest (`holoflow models`, `holoflow run --models DIR`).

A models folder holds ``manifest.json``: ``{"format": 1, "kind": "random" | "weights", "roles":
{ROLE: PATH}}`` with ROLE one of ``holoflow.networks.weights.DEFAULTS`` and PATH relative to the folder
(or absolute). ``holoflow run --models DIR`` points every real engine's model param that the profile
leaves empty at DIR's file for its role; the path becomes part of the step's params, so the cache
key tells results made from different folders apart. ``holoflow models random DIR`` writes such a
folder with randomly initialised models of every real architecture: real compute cost, noise images.

Nothing here downloads, and nothing heavy is imported until a model is written or looked up.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from holoflow.flow.pipeline import Resolved

MANIFEST = "manifest.json"

# role -> the file or folder name ``models random`` writes for it (roles sharing an architecture share one).
RANDOM_LAYOUT: dict[str, str] = {
    "diffusion360": "sd", "sd15": "sd", "tile_base": "sd",
    "controlnet_lineart": "controlnet", "controlnet_tile": "controlnet",
    "realesrgan": "RealESRGAN_x2plus.pth", "depth_anything": "depth_anything", "zoedepth": "zoedepth",
    "lama": "big-lama.safetensors",
}


@dataclass
class ModelNeed:
    """One model a stage's engine will load: where from, and whether it is here."""

    stage: str
    engine: str
    param: str            # the stage param that names it (``stage.param``)
    role: str             # weights.DEFAULTS key
    model: str            # what the engine will be given: a path, an HF id, or "" (its default)
    present: bool
    detail: str           # the local path when present, else the one line saying how to get it


def engine_weights(r: "Resolved") -> tuple[tuple[str, str], ...]:
    """((param, role), ...) the resolved stage's engine loads, as its registry declares them
    (``Engines(weights=...)`` in the stage's config class); () for an engine without weights."""
    config = r.stage.config
    return config.ENGINES.weights.get(r.engine, ()) if config is not None else ()


def needs(resolved: dict[str, "Resolved"]) -> list[ModelNeed]:
    """Every model the resolved stages' engines load, looked up locally (no download, no network)."""
    from .weights import DEFAULTS, MissingWeights, resolve

    out = []
    for name, r in resolved.items():
        for param, role in engine_weights(r):
            model = str(r.params[param])
            try:
                path, present = str(resolve(model, role, f"{name}.{param}")), True
            except MissingWeights as e:
                path, present = str(e), False
            out.append(ModelNeed(name, r.engine, param, role, model or DEFAULTS.get(role, ""), present, path))
    return out


def check_present(resolved: dict[str, "Resolved"], profile: str | None) -> None:
    """Before any step starts: every model the ``resolved`` stages' engines load is here, or one
    PipelineError line names what is missing and the command that lists how to get it."""
    from holoflow.flow.pipeline import PipelineError

    missing = [m for m in needs(resolved) if not m.present]
    if missing:
        names = ", ".join(f"{m.stage}.{m.param} ({m.model or m.role})" for m in missing[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise PipelineError(f"{len(missing)} model(s) not found locally: {names}{more}; fix: "
                            f"`holoflow models list --profile {profile}` says where each comes from "
                            f"(or `holoflow models random DIR` + --models DIR for random weights)")


def prepare(items, models: str | None) -> None:
    """Before anything runs: ``--models DIR`` fills each item's empty model params from DIR's
    manifest, then every model the stages that will run load must be here (one PipelineError line
    otherwise). ``items``: holoflow.flow.context.BatchItem list. Imports no network code unless a
    stage's engine loads weights."""
    from holoflow.flow.context import select
    from holoflow.flow.pipeline import PipelineError

    for item in items:
        ctx = item.ctx
        if models:
            try:
                apply_manifest(ctx.resolved, Path(models))
            except PipelineError as e:
                raise PipelineError(f"scene {item.label}: {e}" if item.label else str(e)) from None
        selected, needed, _ = select(ctx.pipe, item.opts, ctx.uses)
        wanted = {n: r for n, r in ctx.resolved.items() if n in needed and n in selected and n not in ctx.uses
                  and r.stage.config is not None and r.engine in r.stage.config.ENGINES.weights}
        if wanted:
            check_present(wanted, ctx.profile)


def read_manifest(folder: Path) -> dict[str, Path]:
    """{role: absolute path} of a models folder's manifest.json; ValueError (one line) when unusable."""
    file = Path(folder) / MANIFEST
    try:
        doc = json.loads(file.read_text())
    except FileNotFoundError:
        raise ValueError(f"--models {folder}: no {MANIFEST} there; fix: `holoflow models random {folder}`, "
                         f"or write one: {{\"format\": 1, \"roles\": {{ROLE: PATH}}}}") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"--models {folder}: {MANIFEST} is not JSON ({e.msg}, line {e.lineno})") from None
    roles = doc.get("roles") if isinstance(doc, dict) else None
    if not isinstance(roles, dict) or doc.get("format") != 1:
        raise ValueError(f"--models {folder}: {MANIFEST} needs {{\"format\": 1, \"roles\": {{ROLE: PATH}}}}")
    from .weights import DEFAULTS

    out = {}
    for role, rel in roles.items():
        if role not in DEFAULTS:
            raise ValueError(f"--models {folder}: unknown role '{role}' in {MANIFEST}; roles: {', '.join(DEFAULTS)}")
        path = (Path(folder) / str(rel)).resolve()
        if not path.exists():
            raise ValueError(f"--models {folder}: {MANIFEST} names '{rel}' for {role}, which does not exist")
        out[role] = path
    return out


def apply_manifest(resolved: dict[str, "Resolved"], folder: Path) -> None:
    """Point each real engine's empty model param at ``folder``'s file for its role (in place).
    A param the profile or ``--set`` already gave keeps its value. Raises PipelineError."""
    from holoflow.flow.pipeline import PipelineError

    try:
        roles = read_manifest(folder)
    except ValueError as e:
        raise PipelineError(str(e)) from None
    for name, r in resolved.items():
        for param, role in engine_weights(r):
            if r.params[param]:
                continue
            if role not in roles:
                raise PipelineError(f"--models {folder}: {MANIFEST} has no '{role}' (needed by {name}.{param}, "
                                    f"engine {r.engine}); fix: add it, or --set {name}.{param}=PATH")
            r.params[param] = str(roles[role])
            r.overrides[param] = "--models"


def write_random(folder: Path, full: bool = False, seed: int = 0, progress=print) -> dict[str, str]:
    """Randomly initialised models of every real architecture (tiny, or ``full`` published sizes) and
    their manifest.json into ``folder``. Returns the manifest's roles."""
    from . import random_models as rm

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    writers = {
        "sd": lambda p: rm.save_sd(p, full=full, seed=seed),
        "controlnet": lambda p: rm.save_controlnet(folder / "sd", p, full=full, seed=seed + 1),
        "RealESRGAN_x2plus.pth": lambda p: rm.save_rrdbnet(p, scale=2, full=full, seed=seed),
        "depth_anything": lambda p: rm.save_depth_anything(p, full=full, seed=seed),
        "zoedepth": lambda p: rm.save_zoedepth(p, full=full, seed=seed),
        "big-lama.safetensors": lambda p: rm.save_lama(p, full=full, seed=seed),
    }
    for name, write in writers.items():
        progress(f"holoflow models: writing {name} ({'full size' if full else 'tiny'}, random weights)")
        write(folder / name)
    roles = dict(RANDOM_LAYOUT)
    (folder / MANIFEST).write_text(json.dumps({"format": 1, "kind": "random", "full": full, "seed": seed,
                                               "roles": roles}, indent=1) + "\n")
    return roles
