"""point_cloud's, pano_set's and pcd_set's parameters (one engine each: ``default``). Imports nothing
heavy."""

from __future__ import annotations

from dataclasses import dataclass

from holoflow.flow.params import Engines, StageParams, param


@dataclass(frozen=True)
class PointCloudParams(StageParams):
    """Equirect RGB-D -> P0, P_f, P_s (holoflow/geometry/clouds.py)."""

    ENGINES = Engines(
        "one engine, the method: equirect_to_points(rgb [H, W, 3], radial depth [H, W]) per cloud",
        default="holoflow.geometry.pointcloud:equirect_to_points",
    )

    p0_width: int = param(1024, "P0 at depth resolution", "px", ge=2)
    pf_width: int = param(
        0,
        "P_f: downsampled, then depth-gradient filtered; 0 = as fine as a view_size px "
        "view of view_fov_deg resolves (holoflow/geometry/area.py), capped at the "
        "panorama's own width and pf_max_width",
        "px",
        ge=0,
    )
    pf_max_width: int = param(
        1536, "pf_width 0: at most this wide (the Gaussian count grows as its square)", "px", ge=2
    )
    pf_detail_width: int = param(
        2048,
        "pf_width 0, pf_sampling area: when thinning the panorama to P_f's width loses detail "
        "(pf_detail_psnr), P_f is built this wide instead (at most the panorama's own width and "
        "what the view resolves) and sampled at this width only in the tiles holding the most detail "
        "(pf_detail_share of the sphere), at half of it elsewhere (holoflow/geometry/detail.py); "
        "not above P_f's width: off",
        "px",
        ge=0,
    )
    pf_detail_share: float = param(
        0.25,
        "pf_detail_width: the share of the sphere's area sampled at the full width (the tiles where "
        "halving the width takes the most away); 1 = all of it",
        gt=0,
        le=1,
    )
    pf_detail_psnr: float = param(
        38.0,
        "pf_detail_width: taken when the panorama thinned to P_f's width and back scores below this "
        "against itself (area-weighted; a smooth picture keeps P_f's width)",
        "dB",
        gt=0,
    )
    pf_sampling: str = param(
        "area",
        "P_f's points: area = rows thinned by cos(lat), so every point covers "
        "the same solid angle (no rings of thin Gaussians at the poles); grid = one "
        "per pixel (the paper)",
        choices=("area", "grid"),
    )
    pf_polar_density: float = param(
        2.0,
        "pf_sampling area: P_f's polar caps (beyond pf_polar_from_deg) are sampled "
        "from the panorama on a grid this many times finer than P_f's (rows at most "
        "pf_polar_upsample x the panorama's own), with this many times P_f's points along each ring: a "
        "photo's polar rows hold detail a view of the zenith or nadir resolves "
        "(holoflow/geometry/area.py); 1 = none",
        ge=1,
        le=4,
    )
    pf_polar_upsample: float = param(
        2.0,
        "pf_polar_density: the caps' grid at most this many times the panorama's "
        "own width; above 1 its rows are the panorama's upsampled bilinearly, which the "
        "discs render closer to the panorama's own views (holoflow/geometry/area.py)",
        ge=1,
        le=4,
    )
    pf_polar_from_deg: float = param(
        65.0, "pf_polar_density: the caps' edge, latitude north and south", "deg", ge=0, le=90
    )
    pf_polar_detail: float = param(
        1.0,
        "pf_polar_density: a cap is sampled finer only where thinning its rows to "
        "P_f's points would take away more than this many times what it takes at the "
        "sides (area-weighted mean square, holoflow/geometry/area.py called_for): a plain "
        "ceiling or sky keeps P_f's sampling; 0 = always",
        ge=0,
    )
    view_size: int = param(512, "pf_width 0: the view size P_f must stay sharp at (paper 512)", "px", ge=1)
    view_fov_deg: float = param(47.43, "pf_width 0: that view's field of view (paper 47.43)", "deg", gt=0, lt=180)
    ps_width: int = param(256, "P_s: for the PCD-set projection", "px", ge=2)
    depth_upsample: str = param(
        "guided",
        "a cloud wider than the depth: guided (each pixel takes the surface of the nearby depth "
        "pixels whose colour matches its own: edges land on the colour's, no depth between two "
        "surfaces; holoflow/geometry/upsample.py) or nearest (the nearest depth pixel)",
        choices=("guided", "nearest"),
    )
    grad_threshold: float = param(0.4, "P_f drops points whose relative depth gradient exceeds this (paper 0.4)", ge=0)
    grad_sides: str = param(
        "one_sided",
        "the gradient filter's differences: central (the paper's: both pixels "
        "beside a step are dropped, and a thin object two pixels wide with them) or one_sided "
        "(a pixel is dropped only when it differs from both neighbours along an axis: on a ramp, "
        "or alone; a line one pixel thick in front of what is behind it keeps its points; "
        "holoflow/geometry/pointcloud.py)",
        choices=("one_sided", "central"),
    )
    sky_radius: float = param(
        0.0, "far shell radius for unbounded pixels (0 = 2x the 99th percentile depth)", "m", ge=0
    )
    edge_radius: int = param(
        3,
        "P_f: occlusion edges drawn as ramps by the depth are made steps, each ramp "
        "pixel moved onto the near or far side within a window this many px around it "
        "(holoflow/geometry/edges.py), before the gradient filter and the layer; 0 = off",
        "px",
        ge=0,
    )
    edge_ratio: float = param(
        0.25,
        "edge_radius: far / near - 1 across a window that makes it an edge (a "
        "smooth surface spanning less is never touched; pixels within layer_tol of "
        "either end stay)",
        gt=0,
    )
    edge_rounds: int = param(2, "edge_radius: passes (a ramp wider than the window needs two)", ge=1)
    smooth_radius: int = param(
        3,
        "P_f: depth noise smoothed within each surface over a window this many px "
        "around each pixel, never across an edge (holoflow/geometry/surfaces.py); 0 = off",
        "px",
        ge=0,
    )
    smooth_range: float = param(
        0.05,
        "smooth_radius: relative depth difference at which a neighbour's weight "
        "falls to exp(-1/2) (steps of several times this are edges), at most "
        "smooth_noise x the depth's own per-pixel noise",
        gt=0,
    )
    smooth_noise: float = param(
        10.0,
        "smooth_radius: the range as a multiple of the depth's per-pixel noise (its header's "
        "holoflow.depth_noise: a network's before metric_align laid the planes, else "
        "holoflow/geometry/surfaces.py depth_noise on the depth's own grid; exact depth is then left "
        "nearly as it is); 0 = smooth_range always",
        ge=0,
    )
    opening_bars: bool = param(
        True,
        "window bars kept in their window: inside a sky region enclosed by the room, pixels whose "
        "colour is not the sky's and that hold onto the opening's border get the depth of the frame's "
        "plane instead of the far shell (holoflow/geometry/openings.py); a network blurs them into the "
        "sky, and P_f's grid drops bars thinner than its pixels",
    )
    opening_reveals: bool = param(
        True,
        "P_f: the side of a window's recess and the frame that the wall's edge hides from the centre get "
        "points (holoflow/geometry/openings.py); without them a step sideways shows the sky dome through "
        "the wall",
    )
    opening_colour_tol: float = param(
        0.06, "opening_bars: how far (sRGB distance) from the sky's fitted colour a pixel is a bar", gt=0
    )
    opening_plane: str = param(
        "walls",
        "opening_bars: the plane the bars go onto. walls = upright and facing the room's wall direction "
        "(the panorama's straight lines, holoflow/depth/manhattan.py), only its distance fitted to the "
        "frame; free = any plane through the frame, which a wall edge in front of the frame tilts (walls "
        "falls back to it without 10 horizontal lines, for a frame turned over 35 deg from every wall, "
        "and for a wall seen edge-on)",
        choices=("walls", "free"),
    )
    sky_dome: bool = param(
        True,
        "where the panorama shows sky, P_f gets a coarse sky dome behind everything, "
        "coloured by the sky around it (holoflow/geometry/clouds.py): a window seen from off "
        "the centre shows sky past its frame; the background layer then leaves the sky shell to it",
    )
    sky_dome_coarse: int = param(8, "sky_dome: its grid is P_f's width divided by this", ge=1)
    sky_dome_reach_deg: float = param(
        30.0,
        "sky_dome: only in directions within this angle of the sky (a window seen from 1 m off, 2 m away, "
        "shows sky up to 27 deg past its frame); elsewhere a crack between two surfaces would show sky",
        "deg",
        gt=0,
        le=180,
    )
    layer_baseline: float = param(
        1.0,
        "P_f gets a background layer: the far surface (and the sky shell) "
        "continued under each silhouette as far as an eye move of this much uncovers "
        "(holoflow/geometry/layers.py); 0 = none",
        "m",
        ge=0,
    )
    layer_tol: float = param(0.1, "background layer: relative depth step that counts as an occlusion edge", gt=0, lt=1)
    layer_max_deg: float = param(30.0, "background layer: widest band under a silhouette", "deg", gt=0)
    layer_slope: bool = param(
        False,
        "background layer: extrapolate the far surface's inverse-depth slope from "
        "the two pixels at the edge (off: the edge pixel's depth; an estimated depth's "
        "edge pixels are rarely the far surface's own)",
    )
    layer_stride: int = param(
        2,
        "background layer: on every this-many-th row and column of P_f's grid, its "
        "Gaussians as much wider (the layer is only seen from off the centre; 2: a "
        "quarter of the points, 0.5 m empties unchanged, holoflow/geometry/layers.py)",
        ge=1,
    )


@dataclass(frozen=True)
class PanoSetParams(StageParams):
    """The panorama seen by the base cameras (holoflow/geometry/rigs.py)."""

    ENGINES = Engines(
        "one engine, the method: equirect_to_pinhole(pano [3, H, W], K, viewmats, size, size)",
        default="holoflow.geometry.sampling:equirect_to_pinhole",
    )

    rig: str = param(
        "fibonacci",
        "base camera layout: poles + golden-angle spiral (holoflow/geometry/rigs.py)",
        choices=("fibonacci",),
    )
    cameras: int = param(38, "number of base cameras (paper 38)", ge=1)
    size: int = param(128, "view side (paper 512)", "px", ge=1)
    fov_deg: float = param(
        47.43,
        "horizontal field of view; focal 582.69 px at 512 (LucidDreamer); 38 cameras need >= 47 deg to cover",
        "deg",
        gt=0,
        lt=180,
    )


@dataclass(frozen=True)
class PcdSetParams(StageParams):
    """P_s seen by the supplementary cameras through a z-buffer (holoflow/geometry/pcdset.py)."""

    ENGINES = Engines(
        "one engine, the method: pcd_set(points, linear, K, base viewmats, width, height, cfg)",
        default="holoflow.geometry.pcdset:pcd_set",
    )

    offset: float = param(0.1, "supplementary camera offset", "fraction of the base view's median depth", ge=0)
    angle_deg: float = param(10.0, "supplementary cameras turn back towards the base view's axis by this", "deg")
    splat_radius: int = param(0, "z-buffer splat radius; 0 = each point's own footprint (no sampling gaps)", "px", ge=0)
    edge_threshold: float = param(
        0.4,
        "P_s points on occlusion edges (relative depth gradient above this) "
        "leave the image and A, not `seen`; 0 = keep all",
        ge=0,
    )
