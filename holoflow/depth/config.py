"""tangent_depth's and metric_align's parameters and engines (docs/depth.md). Imports nothing heavy.

A depth engine's own parameters are fields here whose doc names the engine (``model`` for
depth_anything / zoedepth); the engine reads them from the ``cfg`` it is given."""

from __future__ import annotations

from dataclasses import dataclass

from holoflow.flow.params import Engines, StageParams, param

_FACES = (
    "(images: [F, h, w, 3] linear, dirs: [F, h, w, 3], cos: [F, h, w], truth_radial: [F, h, w] m | None,"
    " seed, cfg: {cls}, device: str, progress, pano: [H, W, 3] linear)"
)
_AUTO = {
    "auto": "simulated on a procedural scene's truth, given on an imported Z, else depth_anything where its "
    "weights are on the machine (tangent_depth), else layout (holoflow.depth.engines.resolve_engine)"
}


def _camera_height():
    """The layout engine's eye height: one field of both depth stages (it gives relative and metric depth)."""
    return param(1.6, "layout: eye height above the floor / ground (the metric scale)", "m", gt=0)


def _scene():
    """The layout engine's scene kind: one field of both depth stages."""
    return param(
        "auto",
        "layout: room layout (indoor), ground / vertical / sky (outdoor), or decided from the image (auto)",
        choices=("auto", "indoor", "outdoor"),
    )


@dataclass(frozen=True)
class TangentDepthParams(StageParams):
    """Panorama -> 20 padded icosahedron tangent faces -> relative disparity -> alignment -> blending."""

    ENGINES = Engines(
        "engine" + _FACES.format(cls="TangentDepthParams") + " -> (perspective disparity [F, h, w], facts: dict)",
        _AUTO,
        weights={"depth_anything": (("model", "depth_anything"),)},
        simulated="holoflow.depth.engines:simulated_relative_engine",
        given="holoflow.depth.engines:given_relative_engine",
        prior="holoflow.depth.engines:prior_relative_engine",
        layout="holoflow.depth.engines:layout_relative_engine",
        depth_anything="holoflow.depth.engines:depth_anything_engine",
    )

    width: int = param(1024, "panorama downsampled to this width (paper 4096)", "px", ge=2)
    face_size: int = param(256, "tangent image side", "px", ge=2)
    padding: float = param(
        1.0, "gnomonic padding of each icosahedron triangle (wide overlaps)", "tangent-plane units", ge=0
    )
    align: str = param(
        "grid",
        "per-face alignment: median (naive), affine (1 scale+offset), grid",
        choices=("median", "affine", "grid"),
    )
    grid: tuple[int, int] = param((8, 7), "alignment grid (cols, rows) of scale/offset nodes per face", "nodes", ge=1)
    smoothness: float = param(1.0, "weight of the node-to-node smoothness term (docs/depth.md)", ge=0)
    scale_reg: float = param(0.001, "weight pulling nodes to the face's affine solution (no collapse to 0)", ge=0)
    blend_ramp: float = param(
        0.1, "faces blend with weights falling to 0 over this outer fraction of the half-size", gt=0, le=1
    )
    model: str = param("", "depth_anything: local dir or model id in the user's cache")
    net_size: int = param(
        0,
        "depth_anything: side of the square image the network sees (rounded to a multiple of 14); 0 = the face size",
        "px",
        ge=0,
    )
    net_batch: int = param(4, "depth_anything: faces per forward pass", "faces", ge=1)
    camera_height: float = _camera_height()
    scene: str = _scene()

    #: (param, role, engine) of the network ``auto`` runs when its weights are on the machine
    #: (holoflow.networks.manifest fills ``model`` before the cache key is made)
    AUTO_NETWORK = ("model", "depth_anything", "depth_anything")


@dataclass(frozen=True)
class MetricAlignParams(StageParams):
    """Metric depth on a seeded face subset -> one global scale + offset of the blended disparity."""

    ENGINES = Engines(
        "engine" + _FACES.format(cls="MetricAlignParams") + " -> (perspective depth z [F, h, w] m, facts: dict)",
        _AUTO,
        weights={"zoedepth": (("model", "zoedepth"),)},
        simulated="holoflow.depth.engines:simulated_metric_engine",
        given="holoflow.depth.engines:given_metric_engine",
        prior="holoflow.depth.engines:prior_metric_engine",
        layout="holoflow.depth.engines:layout_metric_engine",
        zoedepth="holoflow.depth.engines:zoedepth_engine",
    )

    faces: int = param(6, "number of tangent faces given metric depth (seeded random subset)", ge=1, le=20)
    face_size: int = param(256, "tangent face side for the metric engine", "px", ge=2)
    padding: float = param(0.3, "gnomonic padding of each face", "tangent-plane units", ge=0)
    max_depth: float = param(3000.0, "a metric disparity below 1 / max_depth is sky (+inf)", "m", gt=0)
    huber: float = param(0.05, "Huber threshold on the relative residual of the global fit", gt=0)
    model: str = param("", "zoedepth: local dir or model id in the user's cache")
    refine: str = param(
        "auto",
        "a network's depth: blurred steps made sharp (holoflow/depth/edges.py), then straightened by the "
        "room's planes (holoflow/depth/planes.py); auto: when a network (or its simulation) made the "
        "relative depth",
        choices=("auto", "on", "off"),
    )
    room_yaw: str = param(
        "lines",
        "refine: the heading of the room's walls for its planes: lines = the panorama's straight lines "
        "(holoflow/depth/manhattan.py; the depth's normals when fewer than 10 of them are horizontal), "
        "normals = the depth's surface normals, which a network's bias tilts",
        choices=("lines", "normals"),
    )
    camera_height: float = _camera_height()
    scene: str = _scene()
