"""Parameters and engines of the panorama image stages: stylize, upscale, detail (stages/*.py).
Imports nothing heavy. Engine signatures: docs/extending.md."""

from __future__ import annotations

from dataclasses import dataclass

from holoflow.flow.params import Engines, StageParams, param


def max_width_param() -> int:
    """The ``max_width`` field that stylize, upscale and detail share: how wide an input may stay."""
    return param(
        2048,
        "an input wider than width keeps its own width up to this, and is resized to it beyond "
        "(a user's photo is never shrunk below it; holoflow/imageops/photo.py); 0 = no cap",
        "px",
        ge=0,
    )


@dataclass(frozen=True)
class StylizeParams(StageParams):
    """Lineart of the base panorama -> stylized panorama (docs/panorama.md)."""

    ENGINES = Engines(
        "engine(base: [H, W, 3] linear, prompt: str, cfg: StylizeParams, seed: int, device: str, progress) -> Stylized",
        weights={"controlnet_lineart": (("model", "sd15"), ("controlnet", "controlnet_lineart"))},
        classical="holoflow.imageops.engines:stylize_classical",
        controlnet_lineart="holoflow.networks.controlnet_lineart:stylize_engine",
    )

    width: int = param(1024, "output width (lineart and stylized panorama)", "px", ge=1)
    height: int = param(512, "output height", "px", ge=1)
    max_width: int = max_width_param()
    style: str = param(
        "auto",
        "auto = from the prompt's style words; none = passthrough; or a style name "
        "(holoflow/imageops/styles.py). A user's photo with no style asked for passes "
        "through with any engine",
    )
    model: str = param("", "controlnet_lineart: SD 1.5 base model (local dir or id in the user's cache)")
    controlnet: str = param("", "controlnet_lineart: ControlNet Lineart weights (local dir or id)")
    steps: int = param(20, "controlnet_lineart: denoising steps", ge=1)
    strength: float = param(1.0, "controlnet_lineart: img2img strength", ge=0, le=1)


@dataclass(frozen=True)
class UpscaleParams(StageParams):
    """Panorama -> panorama at width x height (super-resolution)."""

    ENGINES = Engines(
        "engine(pano: [H, W, 3] linear, prompt: str, cfg: UpscaleParams, seed: int, device: str, progress)"
        " -> ([h, w, 3] linear, meta: dict)",
        weights={"realesrgan": (("model", "realesrgan"),)},
        lanczos="holoflow.imageops.engines:upscale_lanczos",
        realesrgan="holoflow.networks.realesrgan:upscale_engine",
    )

    width: int = param(2048, "output width", "px", ge=1)
    height: int = param(1024, "output height", "px", ge=1)
    max_width: int = max_width_param()
    model: str = param("", "realesrgan: local weights")
    tile: int = param(256, "realesrgan: tile side", "px", ge=0)


@dataclass(frozen=True)
class DetailParams(StageParams):
    """Panorama -> detail-refined panorama at width x height."""

    ENGINES = Engines(
        "engine(pano: [H, W, 3] linear, prompt: str, cfg: DetailParams, seed: int, device: str, progress)"
        " -> ([h, w, 3] linear, meta: dict)",
        weights={"controlnet_tile": (("model", "tile_base"), ("controlnet", "controlnet_tile"))},
        classical="holoflow.imageops.engines:detail_classical",
        controlnet_tile="holoflow.networks.controlnet_tile:detail_engine",
    )

    width: int = param(2048, "output width", "px", ge=1)
    height: int = param(1024, "output height", "px", ge=1)
    max_width: int = max_width_param()
    strength: float = param(0.5, "classical: detail boost (0 = plain resize); controlnet_tile: img2img strength", ge=0)
    model: str = param("", "controlnet_tile: SD 1.5 base model")
    controlnet: str = param("", "controlnet_tile: ControlNet Tile weights")
    tile: int = param(512, "controlnet_tile: tile side", "px", ge=1)
    overlap: int = param(64, "controlnet_tile: tile overlap", "px", ge=0)
    steps: int = param(20, "controlnet_tile: denoising steps", ge=1)
    batch: int = param(1, "controlnet_tile: tiles per pipeline call (each keeps its seed; only rounding changes)", ge=1)
