"""base_pano's parameters and engines (stages/base_pano.py). Imports nothing heavy."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from holoflow.flow.params import Engines, StageParams, param


@dataclass(frozen=True)
class BasePanoParams(StageParams):
    """Text prompt -> equirectangular panorama (docs/panorama.md)."""

    ENGINES = Engines(
        "engine(prompt: str, cfg: BasePanoParams, seed: int, device: str, progress) -> Panorama",
        weights={"diffusion360": (("model", "diffusion360"),)},
        procedural="holoflow.scene.pano:procedural_pano",
        diffusion360="holoflow.networks.diffusion360:base_pano_engine",
    )

    width: int = param(
        0,
        "panorama width; 0 = the engine's own: procedural 2048 (upscale's width: a render has nothing left to "
        "upscale), others 1024 (diffusion360's training size)",
        "px",
        ge=0,
    )
    height: int = param(0, "panorama height; 0 = width / 2", "px", ge=0)
    samples: int = param(2, "procedural: antialiasing samples per pixel side", ge=1)
    model: str = param("", "diffusion360: local dir or model id in the user's cache")
    steps: int = param(30, "diffusion360: denoising steps", ge=1)
    guidance: float = param(7.5, "diffusion360: classifier-free guidance scale", ge=0)

    OWN_WIDTH = {"procedural": 2048}  # px; any other engine: 1024

    def sized_for(self, engine: str) -> "BasePanoParams":
        """These params with width and height 0 replaced by ``engine``'s own size (OWN_WIDTH, 2:1)."""
        width = self.width or self.OWN_WIDTH.get(engine, 1024)
        return replace(self, width=width, height=self.height or width // 2)


@dataclass
class Panorama:
    """What a base_pano engine returns: ``rgb`` [H, W, 3] linear; ``depth`` [H, W] radial metres (+inf
    sky) when the engine knows it, else None; ``attrs`` extra EXR header entries; ``files`` extra output
    files (name -> text); ``meta`` provenance for the step's record."""

    rgb: Any
    depth: Any = None
    attrs: dict = field(default_factory=dict)
    files: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
