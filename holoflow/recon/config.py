"""pre_opt's, inp_set's and transfer_opt's parameters and engines (docs/reconstruction.md). Imports
nothing heavy. The splatting stages' engine is the rasterizer backend (holoflow/splat/rasterize.py)."""

from __future__ import annotations

from dataclasses import dataclass

from holoflow.flow.params import Engines, StageParams, param

_RASTER = "holoflow.splat.rasterize:rasterize"  # one contract, the backend picked by name
_SPLAT_ENGINES = Engines(
    "rasterize(..., backend=ENGINE): the rasterizer every training step and render use",
    {"auto": "gsplat when the run's device is cuda, else cpu (resolved before the cache key)"},
    on_device={"auto": {"cuda": "gsplat", "cpu": "cpu"}},
    cpu=_RASTER,
    gsplat=_RASTER,
    reference=_RASTER,
)


@dataclass(frozen=True)
class OptimParams(StageParams):
    """What both optimisation schedules share (holoflow/recon/optimize.py)."""

    init_opacity: float = param(
        0.99,
        "opacity of the Gaussians made from P_f (3DGS: 0.1; footprint-sized "
        "Gaussians of a surface render the panorama as they start at 0.99)",
        gt=0,
        lt=1,
    )
    init_scale: str = param(
        "footprint",
        "initial size and turn of the Gaussians: footprint = the pixel each "
        "point of P_f stands for (pf.json's angular spacing x its distance; a disc facing "
        "the centre, holoflow/geometry/area.py), knn = isotropic, RMS distance to the 3 "
        "nearest points (3DGS; also used when the cloud has no pf.json)",
        choices=("footprint", "knn"),
    )
    footprint_width: float = param(
        0.68,
        "init_scale footprint: standard deviation along the surface as rendered "
        "at point_cloud's view_size (the rasterizer's 0.3 px^2 low-pass included, "
        "holoflow/geometry/area.py): wider is softer, narrower speckles "
        "(docs/reconstruction.md)",
        "fraction of the point's footprint",
        gt=0,
    )
    footprint_thickness: float = param(
        0.1, "init_scale footprint: standard deviation along the ray", "fraction of the point's footprint", gt=0
    )
    footprint_orient: str = param(
        "surface",
        "init_scale footprint: surface = each disc lies on its surface "
        "(pf.ply's normals; the footprint seen from the centre projected onto it), so "
        "neighbours overlap from eyes off the centre; centre = discs face the "
        "panorama centre",
        choices=("surface", "centre"),
    )
    footprint_max_stretch: float = param(
        6.0,
        "footprint_orient surface: a disc is at most this many times "
        "longer down a slanted surface than across (1 / cos(incidence))",
        ge=1,
    )
    densify_every: int = param(50, "split / clone every this many iterations (paper: 100)", "iters", ge=1)
    densify_from: int = param(
        40, "densify at densify_from < step <= densify_stop x iters (3DGS: from 500)", "iters", ge=0
    )
    densify_stop: float = param(
        0.5,
        "... and <= iters - densify_every (3DGS: until 15k of 30k; docs/reconstruction.md)",
        "fraction of iters",
        ge=0,
        le=1,
    )
    depth_weight: float = param(
        0.0,
        "weight of the depth loss on the PANO set's views: the rendered depth's mean relative error "
        "against metric_align's depth (holoflow/splat/train.py lambda_depth); 0 = colour only (paper)",
        ge=0,
    )
    background: str = param(
        "black",
        "colour behind the Gaussians while training: black (3DGS), or random = a new colour every step, so "
        "a see-through Gaussian costs loss (an enclosed scene is opaque everywhere; docs/bench-paper.md)",
        choices=("black", "random"),
    )
    opacity_reset_every: int = param(0, "0 = never (paper: no opacity reset)", "iters", ge=0)
    max_gaussians: int = param(200000, "densification stops growing past this count", ge=1)
    train_seed: int = param(
        0, "another value = an independent optimisation of the same inputs (holoflow eval --repeats)", ge=0
    )
    lr_decay: str = param(
        "phase",
        "position lr decay from 1.6e-4 to 1.6e-6 x extent: once over all of a "
        "model's phases (model, as 3DGS; the paper profile) or afresh in every phase (phase)",
        choices=("phase", "model"),
    )
    sh_degree: int = param(
        0,
        "spherical-harmonics degree of the Gaussians' colour; one more band every 1000 "
        "iterations (3DGS: 3; the paper profile)",
        ge=0,
        le=3,
    )


@dataclass(frozen=True)
class PreOptParams(OptimParams):
    """G0: Gaussians from P_f, trained on the PCD set (masked), then on the PANO set."""

    ENGINES = _SPLAT_ENGINES

    pcd_iters: int = param(10, "phase 1: PCD set, loss masked to pixels a point landed on (paper 2000)", "iters", ge=0)
    pano_iters: int = param(10, "phase 2: PANO set (paper 2000)", "iters", ge=0)


@dataclass(frozen=True)
class TransferOptParams(OptimParams):
    """G1: fresh Gaussians from P_f, trained on the PANO and INP sets together."""

    ENGINES = _SPLAT_ENGINES

    iters: int = param(
        25, "PANO + INP sets (paper 5000 = 1.25 x pre_opt's 2000 + 2000; every profile keeps 1.25x)", "iters", ge=0
    )
    use_inp: bool = param(True, "false = transfer on the PANO set only (the paper's ablation)")
    preview_size: int = param(96, "side of the look-around preview renders", "px", ge=1)
    fit_size: int = param(
        0,
        "colour fit after training: the base cameras at this view size, targets from "
        "the detail panorama (holoflow/recon/colour_fit.py); 0 = a quarter of P_f's width "
        "(pf.json; 384 without one): 384 px at the preview's 1536, 512 where P_f goes by detail "
        "(2048), about 1.8 view pixels per P_f point at 47.43 deg",
        "px",
        ge=0,
    )
    fit_iters: int = param(
        1,
        "colour fit passes over the base cameras at fit_size (0 = none, the paper); "
        "each is one render and one backward of every base view",
        "passes",
        ge=0,
    )
    fit_relax: float = param(1.0, "colour fit step: 1 = the full weight-normalised residual (SART)", gt=0, lt=2)
    fit_polar_weight: float = param(
        8.0,
        "colour fit: weight of the base views within 25 deg of the zenith or "
        "nadir, which see the polar caps head on, against 1 for the others",
        ge=0,
    )
    fit_max_colour: float = param(
        1.5,
        "colour fit: upper bound of a fitted colour (sRGB; the renderer "
        "clamps at 0 only, as 3DGS): above 1 a Gaussian can make up for coverage "
        "below 1 next to a white highlight; 8-bit formats (.splat) clip it",
        gt=0,
    )


@dataclass(frozen=True)
class InpSetParams(StageParams):
    """G0 rendered at the supplementary cameras; missing pixels inpainted (holoflow/recon/inpaint.py)."""

    ENGINES = Engines(
        "engine(images: [N, H, W, 3] sRGB, masks: [N, H, W] bool, depths: [N, H, W] m | None,"
        " cfg: InpSetParams, device: str, progress) -> [N, H, W, 3] sRGB",
        weights={"lama": (("model", "lama"),)},
        opencv="holoflow.recon.inpaint:opencv_engine",
        lama="holoflow.recon.inpaint:lama_engine",
    )

    alpha_threshold: float = param(
        0.5, "missing = rendered alpha < this OR no P_s point seen (docs/reconstruction.md)", ge=0, le=1
    )
    observed: str = param(
        "render",
        "observed pixels: render = G0's render (the paper's Eq. 3), pcd = the PCD set's colour where a point landed",
        choices=("render", "pcd"),
    )
    method: str = param(
        "background",
        "opencv: background (far-side fill, then telea), telea, ns, fsr_fast, fsr_best",
        choices=("background", "telea", "ns", "fsr_fast", "fsr_best"),
    )
    radius: int = param(5, "opencv telea / ns neighbourhood", "px", ge=1)
    max_dist: int = param(32, "opencv background: farthest observed pixel looked for along each direction", "px", ge=1)
    model: str = param("", "lama: local big-lama weights")
