"""Where real-model weights come from: a local path, or a model id already in the user's HF cache.

Nothing here downloads (``holoflow models pull`` does: holoflow.networks.manifest). A model is given as

- a local directory or file (``/data/models/sd15``, ``~/big-lama.safetensors``), used as is;
- a Hugging Face model id, optionally with a sub-path inside the repo
  (``archerfmy0831/sd-t2i-360panoimage/sd-base``), looked up in the local HF cache only
  (``local_files_only=True``, the HF_HUB_OFFLINE semantics), whatever the network;
- ``""``: the engine's default id (``DEFAULTS``).

When the weights are not there, :class:`MissingWeights` carries ONE line saying what to download
and where to put it; stages print it and exit non-zero (docs/stage-protocol.md).
"""

from __future__ import annotations

from pathlib import Path

from holoflow.stage import UserError

# Default model ids per engine role (the paper's choices; docs/engines.md).
DEFAULTS: dict[str, str] = {
    "diffusion360": "archerfmy0831/sd-t2i-360panoimage/sd-base",
    "sd15": "stable-diffusion-v1-5/stable-diffusion-v1-5",
    "controlnet_lineart": "lllyasviel/control_v11p_sd15_lineart",
    "tile_base": "archerfmy0831/sd-t2i-360panoimage/sr-base",
    "controlnet_tile": "archerfmy0831/sd-t2i-360panoimage/sr-control",
    "realesrgan": "archerfmy0831/sd-t2i-360panoimage/RealESRGAN_x2plus.pth",
    "depth_anything": "depth-anything/Depth-Anything-V2-Small-hf",  # the CPU default; larger ones by name
    "zoedepth": "Intel/zoedepth-nyu-kitti",
    "lama": "",  # no official HF repo: a local file converted from big-lama (docs/engines.md)
}

WEIGHT_SUFFIXES = (".safetensors", ".pth", ".pt", ".bin")

# Models a user may name (``--set STAGE.model=ID``, ``holoflow models pull ID``): HF id -> (what it is,
# parameters, licence of the weights as the model card states it). Listed wherever a model is listed.
KNOWN: dict[str, tuple[str, str, str]] = {
    "depth-anything/Depth-Anything-V2-Small-hf": ("Depth Anything V2 Small (relative)", "24.8 M", "Apache-2.0"),
    "depth-anything/Depth-Anything-V2-Base-hf": ("Depth Anything V2 Base (relative)", "97.5 M", "CC-BY-NC-4.0"),
    "depth-anything/Depth-Anything-V2-Large-hf": ("Depth Anything V2 Large (relative)", "335.3 M", "CC-BY-NC-4.0"),
    "LiheYoung/depth-anything-large-hf": ("Depth Anything v1 Large (relative; the paper's)", "335.3 M", "Apache-2.0"),
    "Intel/zoedepth-nyu-kitti": ("ZoeDepth NK (metric)", "", "MIT"),
}


def describe(model: str) -> str:
    """'NAME, N parameters, licence L' for a KNOWN model id (the repo part of ``model``, or a snapshot
    folder of the HF cache: ``.../models--ORG--NAME/snapshots/REV``), else ''."""
    cached = [part for part in Path(model).parts if part.startswith("models--")]
    repo = cached[-1][len("models--") :].replace("--", "/", 1) if cached else "/".join(model.split("/")[:2])
    known = KNOWN.get(repo)
    if not known:
        return ""
    return f"{known[0]}, " + (f"{known[1]} parameters, " if known[1] else "") + f"licence {known[2]}"


class MissingWeights(UserError, RuntimeError):
    """Model weights are not available locally; ``str(err)`` is one line for the user."""


def _cache_dir() -> str:
    from huggingface_hub import constants

    return str(constants.HF_HUB_CACHE)


def _is_pathlike(model: str) -> bool:
    """A filesystem path rather than an HF id: absolute/relative/home paths, or a bare weight file
    name (an HF id names a file only after "owner/repo/")."""
    if model.startswith(("/", "./", "../", "~")) or "\\" in model:
        return True
    return Path(model).suffix in WEIGHT_SUFFIXES and model.count("/") < 2


def resolve(model: str, role: str, param: str) -> Path:
    """Local path of ``model`` (a path, an HF id[/sub/path] in the cache, or "" = DEFAULTS[role]).

    ``param`` names the setting a user changes to point at other weights (e.g. "base_pano.model"),
    so the error line says exactly what to do. Raises MissingWeights.
    """
    model = (model or DEFAULTS.get(role, "")).strip()
    if not model:
        raise MissingWeights(
            f"{role}: no model given and no default; set {param}=/path/to/weights (see docs/engines.md)"
        )
    local = Path(model).expanduser()
    if local.exists():
        return local.resolve()
    if _is_pathlike(model) or model.count("/") < 1:
        raise MissingWeights(
            f"{role}: weights not found at '{model}'; put them there or set {param}=/path/to/weights "
            f"(see docs/engines.md)"
        )
    parts = model.split("/")
    repo, sub = "/".join(parts[:2]), "/".join(parts[2:])
    from huggingface_hub import snapshot_download
    from huggingface_hub.errors import LocalEntryNotFoundError

    hint = (
        f"{role}: '{model}' is not in the local Hugging Face cache ({_cache_dir()}); download it with "
        f"`holoflow models pull {model}` or `hf download {repo}` (or save it to a folder and set "
        f"{param}=/that/folder)"
    )
    try:
        root = Path(snapshot_download(repo, local_files_only=True))
    except (LocalEntryNotFoundError, OSError, ValueError):
        raise MissingWeights(hint) from None
    path = root / sub if sub else root
    if not path.exists():
        raise MissingWeights(f"{hint}; the cached snapshot has no '{sub}'")
    return path


def weight_file(path: Path, role: str, param: str, prefer: str = "") -> Path:
    """The single weight file at ``path`` (a file, or a folder holding one .safetensors/.pth/...).

    With several candidates in a folder, the one whose name contains ``prefer`` wins; otherwise a
    safetensors file, and if that is still ambiguous the user is asked to name the file.
    """
    if path.is_file():
        return path
    found = sorted(p for p in path.iterdir() if p.suffix in WEIGHT_SUFFIXES and p.is_file())
    if prefer:
        found = [p for p in found if prefer.lower() in p.name.lower()] or found
    if len(found) > 1:
        found = [p for p in found if p.suffix == ".safetensors"] or found
    if len(found) != 1:
        what = "no weight file" if not found else f"several weight files ({', '.join(p.name for p in found)})"
        raise MissingWeights(f"{role}: {what} in '{path}'; set {param}=/path/to/the/file")
    return found[0]


def load_state_dict(file: Path) -> dict:
    """Tensors of a .safetensors or torch file, loaded safely (torch.load(weights_only=True))."""
    if file.suffix == ".safetensors":
        from safetensors.torch import load_file

        return load_file(str(file))
    import torch

    try:
        state = torch.load(str(file), map_location="cpu", weights_only=True)
    except Exception as err:  # pickles with arbitrary objects are refused by design
        raise MissingWeights(
            f"cannot load '{file}' as a plain state dict ({type(err).__name__}); convert it to "
            f".safetensors as described in docs/engines.md"
        ) from None
    if not isinstance(state, dict):
        raise MissingWeights(f"'{file}' holds a {type(state).__name__}, not a state dict; see docs/engines.md")
    return state
