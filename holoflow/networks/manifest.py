"""The real-model engines' weights as a whole: which models a profile loads, whether they are here, and a
folder of models named by a manifest (`holoflow models`, `holoflow run --models DIR`).

A models folder holds ``manifest.json``: ``{"format": 1, "kind": "random" | "weights", "roles":
{ROLE: PATH}}`` with ROLE one of ``holoflow.networks.weights.DEFAULTS`` and PATH relative to the folder
(or absolute). ``holoflow run --models DIR`` points every real engine's model param that the profile
leaves empty at DIR's file for its role; the path becomes part of the step's params, so the cache
key tells results made from different folders apart. ``holoflow models random DIR`` writes such a
folder with randomly initialised models of every real architecture: real compute cost, noise images.

A chooser engine with a network it runs when the weights are here (``AUTO_NETWORK`` on the stage's
params class: tangent_depth's ``auto`` -> depth_anything) has its model param filled before the cache
key is made, from ``--models DIR`` or the user's Hugging Face cache: the key changes when weights
arrive, and ``auto`` runs the network. Such a model is optional: missing, ``auto`` runs another engine.

Only ``pull`` downloads (huggingface_hub's ``snapshot_download`` into the user's cache); nothing heavy
is imported until a model is written or looked up.
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
    "diffusion360": "sd",
    "sd15": "sd",
    "tile_base": "sd",
    "controlnet_lineart": "controlnet",
    "controlnet_tile": "controlnet",
    "realesrgan": "RealESRGAN_x2plus.pth",
    "depth_anything": "depth_anything",
    "zoedepth": "zoedepth",
    "lama": "big-lama.safetensors",
}


@dataclass
class ModelNeed:
    """One model a stage's engine will load: where from, and whether it is here."""

    stage: str
    engine: str
    param: str  # the stage param that names it (``stage.param``)
    role: str  # weights.DEFAULTS key
    model: str  # what the engine will be given: a path, an HF id, or "" (its default)
    present: bool
    detail: str  # the local path when present, else the one line saying how to get it
    optional: bool = False  # an ``auto`` engine's network: when missing, auto runs another engine
    about: str = ""  # name, parameters and licence of a known model (weights.KNOWN)


def engine_weights(r: "Resolved") -> tuple[tuple[str, str], ...]:
    """((param, role), ...) the resolved stage's engine loads, as its registry declares them
    (``Engines(weights=...)`` in the stage's config class); () for an engine without weights."""
    config = r.stage.config
    return config.ENGINES.weights.get(r.engine, ()) if config is not None else ()


def auto_network(r: "Resolved") -> tuple[str, str, str] | None:
    """(param, role, engine) of the network the resolved stage's chooser engine (``auto``) runs when its
    weights are here (``AUTO_NETWORK`` on the params class), else None."""
    config = r.stage.config
    if config is None or r.engine not in config.ENGINES.choosers:
        return None
    return getattr(config, "AUTO_NETWORK", None)


def _in_hf_cache(model: str) -> bool:
    """Whether the Hugging Face hub cache (HF_HUB_CACHE, else HF_HOME/hub, else
    XDG_CACHE_HOME/huggingface/hub, else ~/.cache/huggingface/hub) has a folder for the model id."""
    import os

    if model.count("/") != 1:
        return False
    hub = os.environ.get("HF_HUB_CACHE")
    if not hub:
        home = os.environ.get("HF_HOME") or os.path.join(
            os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "huggingface"
        )
        hub = os.path.join(home, "hub")
    return os.path.isdir(os.path.join(os.path.expanduser(hub), "models--" + model.replace("/", "--"), "snapshots"))


def needs(resolved: dict[str, "Resolved"], optional: bool = False) -> list[ModelNeed]:
    """Every model the resolved stages' engines load (with ``optional``, also the network of each ``auto``
    engine: ``ModelNeed.optional``), looked up locally (no download, no network)."""
    from .weights import DEFAULTS, MissingWeights, describe, resolve

    out = []
    for name, r in resolved.items():
        auto = auto_network(r)
        wanted = [(param, role, False) for param, role in engine_weights(r)]
        if auto is not None and (optional or r.params[auto[0]]):
            wanted.append((auto[0], auto[1], not r.params[auto[0]]))
        for param, role, maybe in wanted:
            model = str(r.params[param])
            try:
                path, present = str(resolve(model, role, f"{name}.{param}")), True
            except MissingWeights as e:
                path, present = str(e), False
            if maybe and not present:
                path = (
                    f"auto runs another engine without it; get it with `holoflow models pull {DEFAULTS[role]}` "
                    f"(or set {name}.{param}=/a/folder)"
                )
            engine = f"{r.engine} -> {auto[2]}" if auto is not None and param == auto[0] else r.engine
            out.append(
                ModelNeed(
                    name,
                    engine,
                    param,
                    role,
                    model or DEFAULTS.get(role, ""),
                    present,
                    path,
                    maybe,
                    describe(model or DEFAULTS.get(role, "")),
                )
            )
    return out


def fill_auto(resolved: dict[str, "Resolved"]) -> None:
    """Each ``auto`` engine's empty network param becomes the local path of its default weights when they
    are in the user's Hugging Face cache (in place; before the cache key is made). Downloads nothing, and
    imports huggingface_hub only when the cache holds the model's folder (``holoflow status`` stays light)."""
    from .weights import DEFAULTS, MissingWeights, resolve

    for name, r in resolved.items():
        auto = auto_network(r)
        if auto is None or r.params[auto[0]] or not _in_hf_cache(DEFAULTS.get(auto[1], "")):
            continue
        try:
            r.params[auto[0]] = str(resolve("", auto[1], f"{name}.{auto[0]}"))
        except MissingWeights:
            continue
        r.overrides[auto[0]] = "auto: found in the Hugging Face cache"


def check_present(resolved: dict[str, "Resolved"], profile: str | None) -> None:
    """Before any step starts: every model the ``resolved`` stages' engines load is here, or one
    PipelineError line names what is missing and the command that lists how to get it."""
    from holoflow.flow.pipeline import PipelineError

    missing = [m for m in needs(resolved) if not m.present and not m.optional]
    if missing:
        names = ", ".join(f"{m.stage}.{m.param} ({m.model or m.role})" for m in missing[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise PipelineError(
            f"{len(missing)} model(s) not found locally: {names}{more}; fix: "
            f"`holoflow models list --profile {profile}` says where each comes from "
            f"(or `holoflow models random DIR` + --models DIR for random weights)"
        )


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
        fill_auto(ctx.resolved)
        selected, needed, _ = select(ctx.pipe, item.opts, ctx.uses)
        wanted = {
            n: r
            for n, r in ctx.resolved.items()
            if n in needed
            and n in selected
            and n not in ctx.uses
            and r.stage.config is not None
            and (r.engine in r.stage.config.ENGINES.weights or auto_network(r) is not None)
        }
        if wanted:
            check_present(wanted, ctx.profile)


def read_manifest(folder: Path) -> dict[str, Path]:
    """{role: absolute path} of a models folder's manifest.json; ValueError (one line) when unusable."""
    file = Path(folder) / MANIFEST
    try:
        doc = json.loads(file.read_text())
    except FileNotFoundError:
        raise ValueError(
            f"--models {folder}: no {MANIFEST} there; fix: `holoflow models random {folder}`, "
            f'or write one: {{"format": 1, "roles": {{ROLE: PATH}}}}'
        ) from None
    except json.JSONDecodeError as e:
        raise ValueError(f"--models {folder}: {MANIFEST} is not JSON ({e.msg}, line {e.lineno})") from None
    roles = doc.get("roles") if isinstance(doc, dict) else None
    if not isinstance(roles, dict) or doc.get("format") != 1:
        raise ValueError(f'--models {folder}: {MANIFEST} needs {{"format": 1, "roles": {{ROLE: PATH}}}}')
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
        auto = auto_network(r)
        if auto is not None and not r.params[auto[0]] and auto[1] in roles:  # optional: only when DIR has it
            r.params[auto[0]] = str(roles[auto[1]])
            r.overrides[auto[0]] = "--models"
        for param, role in engine_weights(r):
            if r.params[param]:
                continue
            if role not in roles:
                raise PipelineError(
                    f"--models {folder}: {MANIFEST} has no '{role}' (needed by {name}.{param}, "
                    f"engine {r.engine}); fix: add it, or --set {name}.{param}=PATH"
                )
            r.params[param] = str(roles[role])
            r.overrides[param] = "--models"


def write_random(
    folder: Path, full: bool = False, seed: int = 0, progress=print, roles=None, depth_variant: str = "small"
) -> dict[str, str]:
    """Randomly initialised models of every real architecture (tiny, or ``full`` published sizes), or of
    ``roles`` only, and their manifest.json into ``folder``. ``depth_variant``: the Depth Anything
    architecture at full size ("small": V2 Small, the default model; "large"). Returns the manifest's roles."""
    from . import random_models as rm

    unknown = sorted(set(roles or ()) - set(RANDOM_LAYOUT))
    if unknown:
        raise ValueError(f"unknown role(s) {', '.join(unknown)}; roles: {', '.join(RANDOM_LAYOUT)}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    writers = {
        "sd": lambda p: rm.save_sd(p, full=full, seed=seed),
        "controlnet": lambda p: rm.save_controlnet(folder / "sd", p, full=full, seed=seed + 1),
        "RealESRGAN_x2plus.pth": lambda p: rm.save_rrdbnet(p, scale=2, full=full, seed=seed),
        "depth_anything": lambda p: rm.save_depth_anything(p, full=full, seed=seed, variant=depth_variant),
        "zoedepth": lambda p: rm.save_zoedepth(p, full=full, seed=seed),
        "big-lama.safetensors": lambda p: rm.save_lama(p, full=full, seed=seed),
    }
    chosen = {role: name for role, name in RANDOM_LAYOUT.items() if roles is None or role in roles}
    names = set(chosen.values()) | ({"sd"} if "controlnet" in chosen.values() else set())
    for name, write in writers.items():
        if name in names:
            progress(f"holoflow models: writing {name} ({'full size' if full else 'tiny'}, random weights)")
            write(folder / name)
    (folder / MANIFEST).write_text(
        json.dumps({"format": 1, "kind": "random", "full": full, "seed": seed, "roles": chosen}, indent=1) + "\n"
    )
    return chosen


def place_in_hf_cache(src: Path, repo_id: str, cache: Path | None = None, revision: str = "0" * 40) -> Path:
    """Copy a model folder ``src`` into a Hugging Face hub cache as huggingface_hub lays a download out
    (``models--ORG--NAME/blobs/``, ``snapshots/REVISION/`` with links to the blobs, ``refs/main``), so that
    the weights look downloaded (tests; random weights for timing). ``cache``: default the user's
    (``HF_HUB_CACHE``). Returns the snapshot folder."""
    import hashlib
    import os

    if cache is None:
        from huggingface_hub import constants

        cache = Path(constants.HF_HUB_CACHE)
    repo = Path(cache) / ("models--" + repo_id.replace("/", "--"))
    snap = repo / "snapshots" / revision
    for f in sorted(p for p in Path(src).rglob("*") if p.is_file()):
        data = f.read_bytes()
        blob = repo / "blobs" / hashlib.sha256(data).hexdigest()
        blob.parent.mkdir(parents=True, exist_ok=True)
        blob.write_bytes(data)
        link = snap / f.relative_to(src)
        link.parent.mkdir(parents=True, exist_ok=True)
        link.unlink(missing_ok=True)
        link.symlink_to(os.path.relpath(blob, link.parent))
    (repo / "refs").mkdir(parents=True, exist_ok=True)
    (repo / "refs" / "main").write_text(revision)
    return snap


class PullError(RuntimeError):
    """``holoflow models pull`` could not fetch a model; ``str(err)`` is one line for the user."""


def pull_targets(names: list[str], resolved: dict[str, "Resolved"] | None) -> tuple[list[str], list[str]]:
    """(HF ids ``owner/repo[/sub/path]`` to fetch, one line per model skipped): each of ``names`` (a role
    of weights.DEFAULTS or an HF id), or, with ``resolved``, every model its engines load and each
    ``auto`` engine's network. A name that is no HF id is a PullError; a profile's model that is a
    local path or has no HF repo (lama) is skipped with its line."""
    from .weights import DEFAULTS, _is_pathlike

    wanted = (
        [(n.role, n.model) for n in needs(resolved, optional=True)]
        if resolved is not None
        else [(name, DEFAULTS[name] if name in DEFAULTS else name) for name in names]
    )
    out, skipped = [], []
    for name, model in wanted:
        if not model or _is_pathlike(model) or Path(model).expanduser().exists() or model.count("/") < 1:
            what = f"{name} ({model})" if model else f"{name} (no Hugging Face repo; see docs/engines.md)"
            if resolved is None:
                raise PullError(
                    f"holoflow models pull: {what} is not a Hugging Face model id; roles: "
                    f"{', '.join(r for r in DEFAULTS if DEFAULTS[r])}, or owner/repo"
                )
            skipped.append(f"holoflow models: skipping {what}: a local file or folder, not fetched")
        elif model not in out:
            out.append(model)
    return out, skipped


def pull(models: list[str], progress=print) -> list[Path]:
    """Fetch each HF id (``owner/repo[/sub/path]``: only that part of the repo) into the user's Hugging
    Face cache with huggingface_hub's ``snapshot_download`` (its progress bars; an interrupted download
    resumes). Returns the local folders. No network or offline mode: PullError, one line."""
    from huggingface_hub import snapshot_download

    from .weights import _cache_dir, describe

    out = []
    for model in models:
        parts = model.split("/")
        repo, sub = "/".join(parts[:2]), "/".join(parts[2:])
        about = describe(repo)
        progress(
            f"holoflow models: fetching {repo}{'/' + sub if sub else ''}"
            + (f" ({about})" if about else "")
            + f" into {_cache_dir()}"
        )
        try:
            root = Path(snapshot_download(repo, allow_patterns=[sub, f"{sub}/*"] if sub else None))
        except _offline_errors() as e:
            raise PullError(
                f"holoflow models pull: cannot reach the Hugging Face Hub for {repo} (offline: "
                f"{type(e).__name__}); run it again with a network (a partial download resumes), or "
                f"copy the model folder here and set its stage's model=/that/folder"
            ) from None
        out.append(root / sub if sub else root)
    return out


def _offline_errors() -> tuple[type[BaseException], ...]:
    """What huggingface_hub raises without a network or in offline mode (its HTTP client's transport
    errors too, where that client is importable)."""
    from huggingface_hub.errors import LocalEntryNotFoundError, OfflineModeIsEnabled

    errors: tuple[type[BaseException], ...] = (
        LocalEntryNotFoundError,
        OfflineModeIsEnabled,
        ConnectionError,
        TimeoutError,
    )
    for client in ("httpx2", "httpx"):
        try:
            errors += (__import__(client).TransportError,)
        except (ImportError, AttributeError):
            continue
    return errors
