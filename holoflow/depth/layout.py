"""Image-driven panorama depth without weights: a room layout indoors, ground / vertical / sky outdoors.

The ``layout`` depth engine (docs/depth-layout.md). From one equirect panorama (linear RGB [H, W, 3])
it estimates a radial depth [H, W] in metres, +inf for sky:

1. **Upright.** Line segments (OpenCV LSD) on perspective views become great circles on the sphere;
   the vertical vanishing direction is the direction most of them pass through (RANSAC, then a least
   squares refinement); the panorama is rotated so that it is world up (tilt corrected), and the
   Manhattan yaw is the dominant horizontal vanishing direction (``vanishing.py``).
2. **Indoor or outdoor** from the image (a blue / bright, textureless zenith cap with few segments is
   sky); ``LayoutConfig.scene`` overrides it.
3. **Lower boundary** per column: where the floor (ground) region that contains the nadir ends. A
   dynamic programme over columns picks one boundary row per column from a colour model of the floor
   (learnt from the rows around the nadir), image edges, Manhattan-horizontal line segments and a
   smoothness term (``boundary_dp``).
4. **Upper boundary** per column likewise: where the ceiling (indoors) or the sky (outdoors) that
   contains the zenith ends.
   Indoors (``manhattan``) the per-column state is instead a Manhattan wall: one of 4 orientations
   from the horizontal vanishing directions x an offset, scored by the same floor / ceiling costs plus
   the line segments along that wall's own direction, with a penalty per corner (``manhattan.py``);
   each column's floor / ceiling cost is capped (``region_cap``) so cluttered columns are bridged.
5. **Depth.** The floor is the plane ``camera_height`` below the eye: radial depth h / sin(-lat).
   A column's wall is vertical at horizontal distance d: radial d / cos(lat) between its floor
   boundary -atan(h / d) and its ceiling boundary atan(c / d). Indoors the ceiling height c above the
   eye is the one (of ``ceiling_steps`` candidates) whose wall fit costs least with a weak prior; the
   ceiling is the plane c above the eye. Outdoors the sky is +inf and the vertical structures rise
   from the ground boundary up to the sky boundary. Furniture is not modelled: it reads as floor or
   wall (docs/depth-layout.md, failure modes).

Metric scale comes from ``camera_height`` alone (1.6 m default, a standing adult's eye / a tripod).
Everything is computed on a ``work_width`` copy (fast: about a second at 512 x 256) and evaluated
analytically at the output size.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np


@dataclass
class LayoutConfig:
    """Parameters of the layout engine (units in each docstring)."""

    camera_height: float = 1.6
    """metres from the eye down to the floor / ground; sets the metric scale of everything."""
    scene: str = "auto"
    """auto | indoor | outdoor: room layout, or ground / vertical / sky; auto decides from the image."""
    work_width: int = 512
    """the panorama is analysed at this width (height width / 2), pixels."""
    upright: bool = True
    """estimate the camera's tilt from vertical line segments and correct it."""
    min_tilt_deg: float = 1.0
    """degrees: a smaller estimated tilt is left alone (resampling costs more than it corrects)."""
    max_tilt_deg: float = 30.0
    """a vertical vanishing direction further than this from the image's up is not trusted (degrees)."""
    min_depth: float = 0.4
    """metres: no vertical surface is placed nearer than this (horizontal distance)."""
    max_depth_indoor: float = 40.0
    """metres: the farthest horizontal distance of a wall indoors."""
    max_depth_outdoor: float = 300.0
    """metres: the farthest horizontal distance of a vertical structure outdoors."""
    smoothness: float = 6.0
    """DP cost per row of boundary change between neighbouring columns (data costs are per row too)."""
    jump: float = 30.0
    """rows: boundary changes beyond this cost no more (occlusion edges are allowed)."""
    edge_weight: float = 8.0
    """weight of the edge evidence at the boundary row against the region (colour) costs."""
    states: int = 96
    """number of wall distances (log-spaced, min_depth..max_depth) the per-column DP chooses from."""
    ceiling_weight: float = 0.5
    """weight of the ceiling evidence against the floor evidence in the joint DP."""
    distance_prior: float = 3.0
    """weight of the log-normal prior (sigma 0.7 in log metres) on the wall distance around typical_distance."""
    typical_distance: float = 3.0
    """metres: the most likely horizontal distance of a wall (indoors) or facade (outdoors)."""
    manhattan: bool = True
    """indoors: fit Manhattan walls (4 orientations from the horizontal vanishing directions x offsets)
    per column instead of a free wall distance per column (falls back to free when no yaw is found)."""
    wall_offsets: int = 64
    """number of wall offsets (log-spaced, min_depth..max_depth_indoor, metres) per wall orientation."""
    corner_penalty: float = 80.0
    """cost (row-cost units, like the data costs) of each change of wall between neighbouring columns."""
    corner_meet: float = 0.35
    """Manhattan fit: the share of ``corner_penalty`` a corner costs where its two walls meet (their
    distances in that column within ``corner_meet_tol``): a room's corners, a chimney breast's or a
    bay's sides, against a jump from a wall to another one behind it (1 = every corner the same)."""
    corner_meet_tol: float = 0.2
    """Manhattan fit: log-distance difference (about a fraction) over which a corner's cost rises from
    ``corner_meet`` to the whole ``corner_penalty``."""
    ceiling_steps: int = 29
    """number of ceiling heights (log-spaced, 0.3..2.5 x camera_height above the eye) tried by the
    Manhattan fit (each one a DP over the columns)."""
    free_ceiling_steps: int = 15
    """the same for the free-wall fit (indoors without a Manhattan yaw, or ``manhattan`` off)."""
    typical_ceiling: float = 1.2
    """metres: the most likely height of the ceiling above the eye (a 2.4-3 m room, eye at 1.6 m)."""
    ceiling_prior: float = 2.0
    """weight per column of the log-normal prior (sigma 0.5 in log metres) on the ceiling height
    around typical_ceiling (Manhattan fit only)."""
    region_cap: float = 10.0
    """Manhattan fit: a column's floor / ceiling row cost counts at most this much above its own best
    row (row-cost units, about rows of mislabelled pixels), so a column where furniture, a window or
    a same-coloured wall contradicts every wall hypothesis cannot outvote the rest (a truncated,
    robust data term). 0 = no cap."""
    segment_weight: float = 20.0
    """weight of the Manhattan-aligned line segments at a wall's floor / ceiling boundary (row-cost
    units per unit of evidence); only segments along that wall's own horizontal direction count."""
    trim_line_weight: float = 0.5
    """Manhattan fit: the share of its weight a segment keeps as a wall's foot (ceiling line) where the
    rows 2-4 below (above) it are not the floor's (ceiling's) colour: a skirting board's top edge and a
    cornice's lower edge run along the wall like its foot and its ceiling line, one trim's height inside
    them, and together they fit a wall 15-20 % too far (manhattan.region_beyond; 1 = every segment
    counts fully)."""
    ceiling_line_deg: float = 30.0
    """Manhattan fit: a wall seen over at least this many degrees whose ceiling line no segment shows
    (under 20 % of its columns) moves to the wall of its direction whose ceiling line segments show
    best (in at least 60 % of them): a sofa or a cupboard along a wall draws its top where the wall's
    foot would be, nothing stands in front of the ceiling's edge (manhattan.walls_to_ceiling_lines);
    0 = off."""
    ceiling_line_outward: float = 1.2
    """Manhattan fit: the farthest that rule moves a wall outwards, as a factor of its offset: a hearth,
    a step or a rug's edge before a wall draws its foot's line a hand's breadth to half a metre in front
    of it, while a farther line under a wall's ceiling is a cupboard's top (1 = only ever nearer)."""


@dataclass
class LayoutDepth:
    """``depth`` [H, W] radial metres (+inf sky) in the input panorama's frame; ``facts`` (JSON-able):
    scene, why, tilt, ceiling height, boundaries summary."""

    depth: np.ndarray
    facts: dict = field(default_factory=dict)


# -- small helpers -------------------------------------------------------------------------------
def _latitudes(H: int) -> np.ndarray:
    """Latitude (radians) of each row's centre [H] (docs/conventions.md)."""
    return np.pi / 2 - np.pi * (np.arange(H) + 0.5) / H


def _lab(srgb8: np.ndarray) -> np.ndarray:
    """8-bit sRGB [H, W, 3] -> float Lab [H, W, 3] (L 0..100)."""
    import cv2

    return cv2.cvtColor(srgb8.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab)


def _wrap_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of [H, W(, C)] wrapping across the seam (reflecting at the poles)."""
    import scipy.ndimage as ndi

    if sigma <= 0:
        return img
    s = (sigma, sigma) + (0,) * (img.ndim - 2)
    mode = ("reflect", "wrap") + ("nearest",) * (img.ndim - 2)
    return ndi.gaussian_filter(img, s, mode=mode)


# -- the boundary dynamic programme --------------------------------------------------------------
def boundary_dp(cost: np.ndarray, smoothness: float, jump: float) -> np.ndarray:
    """Minimum-cost path through a cost volume [K, W] (state k per column) -> states [W].

    Transition cost between neighbouring columns: ``smoothness`` * min(|k - k'|, ``jump``). Columns
    wrap (the seam is handled by solving over the panorama extended by a quarter turn on both sides
    and keeping the middle).
    """
    K, W = cost.shape
    pad = min(W, max(1, W // 4))
    ext = np.concatenate([cost[:, -pad:], cost, cost[:, :pad]], axis=1)  # [K, W + 2 pad]
    k = np.arange(K)
    trans = smoothness * np.minimum(np.abs(k[:, None] - k[None, :]), jump)  # [K, K] from k' to k
    n = ext.shape[1]
    acc = ext[:, 0].copy()
    back = np.zeros((n, K), dtype=np.int32)
    for c in range(1, n):
        tot = acc[None, :] + trans  # [k, k']
        back[c] = np.argmin(tot, axis=1)
        acc = tot[k, back[c]] + ext[:, c]
    path = np.empty(n, dtype=np.int64)
    path[-1] = int(np.argmin(acc))
    for c in range(n - 1, 0, -1):
        path[c - 1] = back[c, path[c]]
    return path[pad : pad + W]


def region_probability(lab: np.ndarray, seed: np.ndarray, other: np.ndarray, bins: int = 12) -> np.ndarray:
    """P(region | colour) [H, W] in [0, 1] from Lab histograms of ``seed`` and ``other`` pixel masks
    [H, W] (colour histograms with add-one smoothing, equal priors)."""
    lo = np.array([0.0, -60.0, -60.0])
    hi = np.array([100.0, 60.0, 60.0])
    q = np.clip(((lab - lo) / (hi - lo) * bins).astype(np.int64), 0, bins - 1)
    idx = (q[..., 0] * bins + q[..., 1]) * bins + q[..., 2]  # [H, W]
    hs = np.bincount(idx[seed], minlength=bins**3).astype(np.float64) + 0.5
    ho = np.bincount(idx[other], minlength=bins**3).astype(np.float64) + 0.5
    hs /= hs.sum()
    ho /= ho.sum()
    p = hs / (hs + ho)
    return p[idx]


def row_costs(prob: np.ndarray, edges: np.ndarray, edge_weight: float) -> np.ndarray:
    """Cost [H, W] of 'the region (rows >= b) starts at row b', for every row b and column.

    Sum over rows >= b (up to the bottom) of non-region-ness, plus the sum over rows < b of
    region-ness, minus ``edge_weight`` x the edge evidence between rows b-1 and b."""
    H, W = prob.shape
    below = np.cumsum((1.0 - prob)[::-1], axis=0)[::-1]
    above = np.concatenate([np.zeros((1, W)), np.cumsum(prob, axis=0)[:-1]], axis=0)
    return below + above - edge_weight * edges


def _edges(lab: np.ndarray) -> np.ndarray:
    """Vertical colour change between row r-1 and r, [H, W], normalised to ~[0, 1] (95th pct = 1)."""
    d = np.zeros(lab.shape[:2])
    diff = lab[1:] - lab[:-1]
    w = np.array([1.0, 1.5, 1.5])  # chroma counts a little more than lightness (shading)
    d[1:] = np.sqrt(((diff * w) ** 2).sum(-1))
    scale = np.percentile(d, 95) + 1e-6
    return np.minimum(d / scale, 1.5)


def lower_boundary(
    prob: np.ndarray,
    edges: np.ndarray,
    lat: np.ndarray,
    cfg: LayoutConfig,
    lat_range=(-np.radians(70), -np.radians(1.0)),
    extra: np.ndarray | None = None,
) -> np.ndarray:
    """Row index [W] (first floor row, top-down) of the floor region's upper edge per column.

    ``prob`` [H, W] floor probability, ``edges`` [H, W] boundary evidence between rows r-1 and r,
    ``lat`` [H] row latitudes. States are the rows with latitude in ``lat_range``.
    """
    H, W = prob.shape
    rows = np.nonzero((lat >= lat_range[0]) & (lat <= lat_range[1]))[0]
    top, bot = rows[0], rows[-1]
    r = np.arange(top, bot + 1)
    pf = prob[top : bot + 1]  # [K, W]
    nf = 1.0 - pf
    # cost(b) = sum_{rows >= b} (non-floor) + sum_{rows < b, in range} floor-ness - edge(b)
    below = np.cumsum(nf[::-1], axis=0)[::-1]  # [K, W]: rows b..bot
    above = np.concatenate([np.zeros((1, W)), np.cumsum(pf, axis=0)[:-1]], axis=0)  # rows top..b-1
    ev = edges[top : bot + 1] + (extra[top : bot + 1] if extra is not None else 0.0)
    cost = below + above - cfg.edge_weight * ev
    k = boundary_dp(cost, cfg.smoothness * 10, cfg.jump)
    return r[k]


def upper_boundary(
    prob: np.ndarray,
    edges: np.ndarray,
    lat: np.ndarray,
    cfg: LayoutConfig,
    lat_range=(np.radians(1.0), np.radians(70)),
    extra: np.ndarray | None = None,
) -> np.ndarray:
    """Row index [W] of the first non-ceiling (non-sky) row below the zenith region, per column."""
    H = prob.shape[0]
    flip = lambda a: a[::-1]  # noqa: E731 - mirror rows so the upper problem is the lower one
    fe2 = np.zeros_like(edges)
    fe2[1:] = flip(edges)[:-1]
    ex = None
    if extra is not None:
        ex = np.zeros_like(extra)
        ex[1:] = flip(extra)[:-1]
    b = lower_boundary(flip(prob), fe2, -flip(lat), cfg, (-lat_range[1], -lat_range[0]), ex)
    return H - b  # mirrored first-region row b -> first non-region row from the top is H - b


# -- depth of the layout -------------------------------------------------------------------------
def compose_depth(
    H: int, W: int, lat_floor: np.ndarray, lat_top: np.ndarray, h: float, ceiling: float | None, cfg: LayoutConfig
) -> np.ndarray:
    """Radial depth [H, W] (metres, +inf sky) from per-column boundary latitudes [W] (radians).

    ``lat_floor`` floor boundary (< 0), ``lat_top`` ceiling / sky boundary (> 0); ``h`` camera height;
    ``ceiling`` height of the ceiling above the eye (metres) or None outdoors (sky above ``lat_top``).
    """
    lat = _latitudes(H)[:, None]  # [H, 1]
    s, c = np.sin(lat), np.cos(lat)
    dmax = cfg.max_depth_indoor if ceiling is not None else cfg.max_depth_outdoor
    d_f = np.clip(h / np.tan(np.maximum(-lat_floor, 1e-4)), cfg.min_depth, dmax)[None, :]  # [1, W]
    floor = np.where(s < 0, h / np.maximum(-s, 1e-9), np.inf)
    if ceiling is None:
        vert = d_f / np.maximum(c, 1e-6)
        depth = np.where(lat < lat_floor[None, :], floor, vert)
        return np.where(lat >= lat_top[None, :], np.inf, depth)
    d_c = np.clip(ceiling / np.tan(np.maximum(lat_top, 1e-4)), cfg.min_depth, dmax)[None, :]
    d_c = np.maximum(d_c, d_f)  # the wall behind an object is not nearer than the object
    ceil = np.where(s > 0, ceiling / np.maximum(s, 1e-9), np.inf)
    vert = np.where(lat > 0, d_c, d_f) / np.maximum(c, 1e-6)
    depth = np.where(lat < lat_floor[None, :], floor, vert)
    return np.where(lat >= lat_top[None, :], ceil, depth)


def room_yaw(pano: np.ndarray) -> tuple[float | None, dict]:
    """The room's wall heading from the straight lines of a linear RGB panorama [H, W, 3], seen at this
    engine's working size (``work_srgb8``; holoflow.depth.manhattan.panorama_yaw): radians, modulo 90 deg,
    or None with fewer than 10 horizontal lines; and its facts."""
    from holoflow.depth.manhattan import panorama_yaw

    return panorama_yaw(work_srgb8(pano, LayoutConfig.work_width))


def work_srgb8(pano: np.ndarray, width: int) -> np.ndarray:
    """The copy of a linear RGB panorama [H, W, 3] that line and colour analysis runs on: at most
    ``width`` px wide (even, at least 16), exposure-normalised (median grey 0.18, so a dark or HDR
    panorama is analysed like a well-exposed one), 8-bit sRGB [width // 2, width, 3]."""
    from holoflow.geometry.sampling import resize_pano
    from holoflow.imageops.color import linear_to_uint8

    pano = np.nan_to_num(np.asarray(pano, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    Wk = max(16, min(int(width), pano.shape[1]))
    work = resize_pano(pano, Wk - Wk % 2)
    med = float(np.median(work.mean(-1)))
    work = work * (0.18 / med) if med > 1e-6 else work
    return linear_to_uint8(np.clip(work, 0.0, 1.0))


def estimate_layout_depth(
    pano: np.ndarray, cfg: LayoutConfig | None = None, out_shape: tuple[int, int] | None = None
) -> LayoutDepth:
    """Radial depth [H, W] (metres, +inf sky) of a linear RGB panorama [H, W, 3] (module docstring)."""
    cfg = cfg or LayoutConfig()
    if cfg.camera_height <= 0:
        raise ValueError(f"layout: camera_height must be > 0 metres, got {cfg.camera_height}")
    if cfg.scene not in ("auto", "indoor", "outdoor"):
        raise ValueError(f"layout: scene must be auto, indoor or outdoor, got {cfg.scene!r}")
    H0, W0 = out_shape or pano.shape[:2]
    srgb = work_srgb8(pano, cfg.work_width)
    Hk, Wk = srgb.shape[:2]
    facts: dict = {"config": asdict(cfg), "work_size": [Wk, Hk]}
    R = None
    if cfg.upright:
        from holoflow.depth.vanishing import rotate_equirect, rotation_to_upright, segment_normals, vertical_direction

        v, facts["upright"] = vertical_direction(*segment_normals(srgb), cfg.max_tilt_deg)
        if v is not None and facts["upright"]["tilt_deg"] > cfg.min_tilt_deg:
            R = rotation_to_upright(v)
            srgb = np.clip(rotate_equirect(srgb.astype(np.float64), R) + 0.5, 0, 255).astype(np.uint8)
    est = _estimate(srgb, cfg, facts, H0, W0)
    if R is not None:  # back to the input's frame: depth(d) = upright depth(R d), via disparity (sky 0)
        disp = np.where(np.isfinite(est.depth), 1.0 / np.maximum(est.depth, 1e-9), 0.0)
        disp = rotate_equirect(disp, R.T, mode="nearest")
        est.depth = np.where(disp > 0, 1.0 / np.where(disp > 0, disp, 1.0), np.inf).astype(np.float32)
    return est


@dataclass
class _Frame:
    """What the boundary fits found that turning wall distances into depth needs: the work size
    (Hk, Wk) and output size (H0, W0) in pixels, the eye height ``h`` (metres), the row latitudes
    ``lat`` [Hk], the zenith region's probability ``pc`` [Hk, Wk] and edges [Hk, Wk] (the outdoor sky
    boundary), the config and the facts being collected."""

    Hk: int
    Wk: int
    H0: int
    W0: int
    h: float
    lat: np.ndarray
    pc: np.ndarray
    edges: np.ndarray
    cfg: LayoutConfig
    facts: dict


def _estimate(srgb, cfg, facts, H0, W0):
    """Depth [H0, W0] of the upright work panorama ``srgb`` [Hk, Wk, 3] (uint8)."""
    Hk, Wk = srgb.shape[:2]
    lab = _wrap_blur(_lab(srgb), 1.0)
    lat = _latitudes(Hk)
    L = lat[:, None] * np.ones((1, Wk))
    edges = _edges(lab)
    scene, why = (cfg.scene, "set by the scene parameter") if cfg.scene != "auto" else classify_scene(lab, lat)
    facts.update(scene=scene, scene_why=why)
    seed_f = (L < -np.radians(50)) & (L > -np.radians(85))
    other_f = (L > -np.radians(8)) & (L < np.radians(35))
    seed_c = (L > np.radians(50)) & (L < np.radians(85))
    other_c = (L < np.radians(8)) & (L > -np.radians(35))
    pf = _wrap_blur(np.maximum(region_probability(lab, seed_f, other_f), 1e-6), 1.0)
    pc = _wrap_blur(np.maximum(region_probability(lab, seed_c, other_c), 1e-6), 1.0)
    h = float(cfg.camera_height)
    frame = _Frame(Hk, Wk, H0, W0, h, lat, pc, edges, cfg, facts)
    cost_f = row_costs(pf, edges, cfg.edge_weight)  # [Hk, Wk] floor starts at row b
    # ceiling: mirrored rows; cost_c[b] = 'the ceiling ends above row b' (rows < b are ceiling)
    ef = np.zeros_like(edges)
    ef[1:] = edges[::-1][:-1]
    cost_c = row_costs(pc[::-1], ef, cfg.edge_weight)  # [Hk, Wk] mirrored: ceiling ends at row H - b
    dist = np.exp(
        np.linspace(
            np.log(cfg.min_depth),
            np.log(cfg.max_depth_indoor if scene == "indoor" else cfg.max_depth_outdoor),
            cfg.states,
        )
    )
    row_f = np.clip(np.round((np.pi / 2 + np.arctan(h / dist)) / np.pi * Hk).astype(np.int64), 0, Hk - 1)
    # typical rooms: a weak log-normal prior on the wall distance (per column, in row-cost units)
    prior = cfg.distance_prior * (np.log(dist / cfg.typical_distance) / 0.7) ** 2
    data_f = cost_f[row_f] + prior[:, None]  # [K, Wk]
    if scene == "indoor" and cfg.manhattan:
        d = _manhattan_walls(srgb, cost_f, cost_c, pf, pc, h, cfg, facts)
        if d is not None:
            return _finish(d, facts["ceiling_above_eye_m"], frame)
    best = None
    heights = (
        [None] if scene != "indoor" else list(h * np.exp(np.linspace(np.log(0.3), np.log(2.5), cfg.free_ceiling_steps)))
    )
    for ceiling in heights:
        if ceiling is None:
            data = data_f
        else:
            # the ceiling's last row is above row b = first wall row; mirrored index H - b
            row_c = np.clip(np.round((np.pi / 2 - np.arctan(ceiling / dist)) / np.pi * Hk).astype(np.int64), 1, Hk - 1)
            data = data_f + cfg.ceiling_weight * cost_c[Hk - row_c]
        k = boundary_dp(data, cfg.smoothness, cfg.jump)
        total = float(data[k, np.arange(Wk)].sum())
        if best is None or total < best[0]:
            best = (total, ceiling, k)
    _, ceiling, k = best
    if ceiling is not None:
        facts["ceiling_above_eye_m"] = round(float(ceiling), 3)
    return _finish(dist[k], ceiling, frame)


def _manhattan_walls(srgb, cost_f, cost_c, pf, pc, h, cfg, facts):
    """Horizontal wall distance per column [Wk] (metres) from the Manhattan wall DP (manhattan.py), its
    walls moved to the ceiling's lines where furniture along them mimics their foot (``ceiling_line_deg``;
    pf / pc [Hk, Wk]: the floor's / ceiling's colour probability), or None when no Manhattan yaw is
    found; sets facts manhattan / ceiling_above_eye_m."""
    import scipy.ndimage as ndi

    from holoflow.depth.manhattan import (
        manhattan_dp,
        manhattan_yaw,
        region_beyond,
        segment_evidence,
        segment_rays,
        wall_distances,
        walls_to_ceiling_lines,
    )

    Hk, Wk = cost_f.shape
    if cfg.region_cap > 0:  # robust data term: each column's evidence is capped above its best row
        cost_f = np.minimum(cost_f - cost_f.min(0, keepdims=True), cfg.region_cap)
        cost_c = np.minimum(cost_c - cost_c.min(0, keepdims=True), cfg.region_cap)
    p1, p2, nrm, ln = segment_rays(srgb)
    yaw, facts["manhattan"] = manhattan_yaw(nrm, ln)
    if yaw is None:
        return None
    ev_f, ev_c = segment_evidence(p1, p2, nrm, yaw, Hk, Wk)  # [2, Hk, Wk] each
    ev_f = ndi.maximum_filter1d(ev_f, 3, axis=1)  # +-1 row: a line sits on either side of the boundary
    ev_c = ndi.maximum_filter1d(ev_c, 3, axis=1)
    if cfg.trim_line_weight < 1.0:  # a foot has the floor below it, a ceiling line the ceiling above it
        ev_f = region_beyond(ev_f, pf, 1, cfg.trim_line_weight)
        ev_c = region_beyond(ev_c, pc, -1, cfg.trim_line_weight)
    dmax = cfg.max_depth_indoor
    offsets = np.exp(np.linspace(np.log(cfg.min_depth), np.log(dmax), cfg.wall_offsets))  # [K] metres
    dW, valid = wall_distances(yaw, offsets, Wk, dmax)  # [S, Wk], S = 4 K
    fam = np.repeat(1 - np.arange(4) % 2, len(offsets))[:, None]  # [S, 1]: the wall's line family
    cols = np.arange(Wk)[None, :]
    rf = np.clip(np.round((np.pi / 2 + np.arctan(h / dW)) / np.pi * Hk).astype(np.int64), 0, Hk - 1)
    prior = cfg.distance_prior * (np.log(dW / cfg.typical_distance) / 0.7) ** 2
    base = cost_f[rf, cols] + prior - cfg.segment_weight * ev_f[fam, rf, cols]  # [S, Wk]
    best = None
    for ceiling in h * np.exp(np.linspace(np.log(0.3), np.log(2.5), cfg.ceiling_steps)):
        rc = np.clip(np.round((np.pi / 2 - np.arctan(ceiling / dW)) / np.pi * Hk).astype(np.int64), 1, Hk - 1)
        data = base + cfg.ceiling_weight * (cost_c[Hk - rc, cols] - cfg.segment_weight * ev_c[fam, rc, cols])
        data = np.where(valid, data, 1e6)
        path = manhattan_dp(data, cfg.corner_penalty)
        corners = int(np.count_nonzero(path != np.roll(path, 1)))
        total = float(data[path, cols[0]].sum()) + cfg.corner_penalty * corners
        total += Wk * cfg.ceiling_prior * (np.log(ceiling / cfg.typical_ceiling) / 0.5) ** 2
        if best is None or total < best[0]:
            best = (total, ceiling, path, corners, rc, data)
    _, ceiling, path, corners, rc, data = best
    if cfg.corner_meet < 1.0:  # again at the chosen height, with the corners where walls meet cheaper
        path = manhattan_dp(data, cfg.corner_penalty, np.log(dW), cfg.corner_meet, cfg.corner_meet_tol)
        corners = int(np.count_nonzero(path != np.roll(path, 1)))
    if cfg.ceiling_line_deg > 0:  # rc [S, Wk]: each wall's ceiling row at the chosen height
        # a wall's ceiling line: a segment there with the wall, not more ceiling, below it (a ceiling's
        # own tiles and lamps draw lines along the walls' directions too)
        below = 1.0 - sum(pc[np.minimum(rc + k, Hk - 1), cols] for k in (2, 3, 4)) / 3.0  # [S, Wk]
        support = np.where(valid, ev_c[fam, rc, cols] * below, 0.0)  # [S, Wk] each wall's ceiling line seen
        min_run = int(np.ceil(cfg.ceiling_line_deg / 360.0 * Wk))
        outward = int(np.log(cfg.ceiling_line_outward) / np.log(offsets[1] / offsets[0]) + 1e-9)  # offsets
        path, facts["manhattan"]["walls_to_ceiling_lines"] = walls_to_ceiling_lines(
            path, support, len(offsets), min_run, outward
        )
        corners = int(np.count_nonzero(path != np.roll(path, 1)))
    facts["ceiling_above_eye_m"] = round(float(ceiling), 3)
    facts["manhattan"]["walls"] = corners
    return dW[path, cols[0]]


def _finish(d, ceiling, f: _Frame):
    """Depth [H0, W0] from the horizontal wall distance per column ``d`` [Wk] (metres) and the ceiling
    height above the eye (metres; None outdoors: the sky boundary is fitted here)."""
    Hk, Wk, H0, W0, h, cfg, facts = f.Hk, f.Wk, f.H0, f.W0, f.h, f.cfg, f.facts
    lat_f = -np.arctan(h / d)
    if ceiling is not None:
        lat_c = np.arctan(ceiling / d)
    else:  # outdoors: the sky region around the zenith, its own boundary per column
        lat_c = np.pi / 2 - np.pi * upper_boundary(f.pc, f.edges, f.lat, cfg) / Hk
        lat_c = np.maximum(lat_c, lat_f + np.pi / Hk)  # the sky starts above the ground
    cols = (np.arange(W0) + 0.5) * Wk / W0 - 0.5
    lat_f0 = _interp_wrap(lat_f, cols)
    lat_c0 = _interp_wrap(lat_c, cols)
    depth = compose_depth(H0, W0, lat_f0, lat_c0, h, ceiling, cfg)
    facts["floor_distance_m"] = {
        "median": round(float(np.median(d)), 3),
        "p10": round(float(np.percentile(d, 10)), 3),
        "p90": round(float(np.percentile(d, 90)), 3),
    }
    return LayoutDepth(depth.astype(np.float32), facts)


def _interp_wrap(values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Linear interpolation of per-column values [W] at fractional columns x, wrapping at the seam."""
    W = values.shape[0]
    x0 = np.floor(x).astype(np.int64)
    t = x - x0
    return values[x0 % W] * (1 - t) + values[(x0 + 1) % W] * t


def classify_scene(lab: np.ndarray, lat: np.ndarray) -> tuple[str, str]:
    """indoor | outdoor from the zenith cap (lat > 45 deg) of a Lab panorama, and why (one line).

    Sky-like pixel: bluish and not darker than the image's median lightness, or clearly blue
    (b* < -20, L > 20) at any lightness. Bluish means b* < -5, relaxed up to b* < -2 when the ground
    (the median b* below the horizon) is warmer, so that the zenith is still 5 units bluer than the
    ground: a hazy or overcast sky is only slightly blue but bluer than the surfaces it lights, while
    a ceiling is lit like the floor. A cap where most pixels are sky-like is outdoors.
    """
    cap = lab[lat > np.radians(45)]
    Lc, bc = cap[..., 0], cap[..., 2]
    ground = lab[lat < 0]
    ground_b = float(np.median(ground[..., 2])) if ground.size else 0.0
    bluish = float(np.clip(ground_b - 5.0, -5.0, -2.0))  # b* threshold
    # a clear zenith is often darker than sunlit ground: a saturated blue counts at any lightness
    sky = ((Lc >= np.median(lab[..., 0])) & (bc < bluish)) | ((bc < -20) & (Lc > 20))
    frac = float(sky.mean()) if sky.size else 0.0
    if frac > 0.5:
        return "outdoor", f"{frac:.0%} of the zenith cap is bright bluish sky (> 50%; b* < {bluish:.1f})"
    return "indoor", f"{frac:.0%} of the zenith cap looks like sky (needs > 50%; b* < {bluish:.1f})"
