"""export's parameters (one engine: ``default``). Imports nothing heavy."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from holoflow.flow.params import Engines, ParamError, StageParams, param

#: every format the export stage writes, in the order it writes them, with its file name
FORMATS = {
    "spz": "scene.spz",
    "splat": "scene.splat",
    "compressed_ply": "scene.compressed.ply",
    "glb": "scene.glb",
    "mesh": "mesh.glb",
}


@dataclass(frozen=True)
class ExportParams(StageParams):
    """The final scene (transfer_opt) in the formats web and game tools read, and the panorama's RGB-D
    (detail + metric_align) as a vertex-coloured mesh (holoflow/export/, docs/viewers.md)."""

    ENGINES = Engines(
        "one engine, the writers: export_formats(scene fields, out_dir, formats, workers) (holoflow/export/splats.py)",
        default="holoflow.export.formats:export_formats",
    )

    formats: str = param("all", "comma list of spz, splat, compressed_ply, glb, mesh; or all")
    mesh_width: int = param(
        0,
        "mesh.glb's equirect grid width; 0 = P_f's resolution, half the depth "
        "map's width (the paper's 2048 of 4096, and every profile here)",
        "px",
        ge=0,
    )
    mesh_edge_threshold: float = param(
        0.4,
        "mesh.glb: a triangle whose relative depth spread "
        "(max - min) / min exceeds this is cut (a depth discontinuity)",
        gt=0,
    )
    mesh_sky: str = param("dome", "mesh.glb: sky pixels as a far dome, or left out", choices=("dome", "omit"))
    sky_radius: float = param(
        0.0, "mesh.glb's sky dome radius (0 = 2x the 99th percentile depth, as point_cloud's far shell)", "m", ge=0
    )

    @classmethod
    def check(cls, name: str, value: Any) -> Any:
        out = super().check(name, value)
        if name == "formats":
            words = [w.strip() for w in out.split(",") if w.strip()]
            bad = [w for w in words if w not in FORMATS and w != "all"]
            if bad or not words:
                raise ParamError(
                    f"formats={value!r}: unknown format {', '.join(bad) or '(none)'}",
                    f"use a comma list of {', '.join(FORMATS)}, or all",
                )
            if "all" in words or set(words) == set(FORMATS):
                return "all"
            return ",".join(f for f in FORMATS if f in words)  # canonical: one order, no repeats
        return out

    @property
    def format_list(self) -> list[str]:
        """The formats to write, in FORMATS order."""
        return list(FORMATS) if self.formats == "all" else self.formats.split(",")
