"""The real-model engines' weights as a whole: which models a profile loads, whether they are here, and a
folder of models named by a manifest (`holoflow models`, `holoflow run --models DIR`).

A models folder holds ``manifest.json``: ``{"format": 1, "kind": "random" | "weights", "roles":
{ROLE: PATH}}`` with ROLE one of ``holoflow.engines.weights.DEFAULTS`` and PATH relative to the folder
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
    from .pipeline import Resolved

MANIFEST = "manifest.json"

# engine -> [(param of its stage, weight role)], in the order the engine loads them.
ENGINE_MODELS: dict[str, list[tuple[str, str]]] = {
    "diffusion360": [("model", "diffusion360")],
    "controlnet_lineart": [("model", "sd15"), ("controlnet", "controlnet_lineart")],
    "realesrgan": [("model", "realesrgan")],
    "controlnet_tile": [("model", "tile_base"), ("controlnet", "controlnet_tile")],
    "depth_anything": [("model", "depth_anything")],
    "zoedepth": [("model", "zoedepth")],
    "lama": [("model", "lama")],
}

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


def needs(resolved: dict[str, "Resolved"]) -> list[ModelNeed]:
    """Every model the resolved stages' engines load, looked up locally (no download, no network)."""
    from .engines.weights import DEFAULTS, MissingWeights, resolve

    out = []
    for name, r in resolved.items():
        for param, role in ENGINE_MODELS.get(r.engine, []):
            model = str(r.params[param])
            try:
                path, present = str(resolve(model, role, f"{name}.{param}")), True
            except MissingWeights as e:
                path, present = str(e), False
            out.append(ModelNeed(name, r.engine, param, role, model or DEFAULTS.get(role, ""), present, path))
    return out


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
    from .engines.weights import DEFAULTS

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
    from .pipeline import PipelineError

    try:
        roles = read_manifest(folder)
    except ValueError as e:
        raise PipelineError(str(e)) from None
    for name, r in resolved.items():
        for param, role in ENGINE_MODELS.get(r.engine, []):
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
    from .engines import random_models as rm

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


def main(argv: list[str]) -> int:
    """`holoflow models list [--profile P]` | `holoflow models random DIR [--full] [--seed N]`."""
    import argparse
    import sys

    p = argparse.ArgumentParser(prog="holoflow models", description="the real-model engines' weights")
    sub = p.add_subparsers(dest="verb", required=True)
    ls = sub.add_parser("list", help="one line per model the profile's real engines load: present or not, "
                        "and how to get it")
    ls.add_argument("--profile", default="paper", help="profile (comma list allowed; default paper)")
    ls.add_argument("--pipeline", default="pipeline.yaml")
    ls.add_argument("--models", metavar="DIR", help="look in DIR's manifest.json first (as run --models)")
    ls.add_argument("--json", action="store_true")
    rnd = sub.add_parser("random", help="write random models of every real architecture + manifest.json")
    rnd.add_argument("folder", metavar="DIR")
    rnd.add_argument("--full", action="store_true", help="published sizes (GBs; for timing), not tiny ones")
    rnd.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.verb == "random":
        write_random(Path(args.folder), full=args.full, seed=args.seed,
                     progress=lambda m: print(m, file=sys.stderr))
        print(f"holoflow models: random {'full-size' if args.full else 'tiny'} models in {args.folder} "
              f"(noise images at the real compute cost); use: holoflow run --models {args.folder}")
        return 0
    from .pipeline import find_pipeline, load, resolve

    pipe = load(find_pipeline(args.pipeline))
    resolved = resolve(pipe, args.profile)
    if args.models:
        apply_manifest(resolved, Path(args.models))
    found = needs(resolved)
    if args.json:
        print(json.dumps([n.__dict__ for n in found], indent=1))
        return 0
    if not found:
        print(f"holoflow models: profile '{args.profile}' uses no real-model engine")
        return 0
    for n in found:
        state = "present" if n.present else "MISSING"
        print(f"{n.stage + '.' + n.param:<24} {n.engine:<18} {state:<8} {n.model or '(none)'}")
        print(f"    {'at ' + n.detail if n.present else 'get: ' + n.detail}")
    missing = sum(not n.present for n in found)
    print(f"holoflow models: {len(found) - missing} of {len(found)} present"
          + (f"; without weights: `holoflow models random DIR` then `holoflow run --models DIR` gives the "
             f"real compute cost with noise images" if missing else ""))
    return 0
