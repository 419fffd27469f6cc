"""Windows kept whole: the bars across an opening of the room, and the recess its wall hides.

A depth network blurs a window's bars into the sky behind them, and a depth map point-sampled to P_f's
grid drops bars thinner than its pixels: either way the bars' pixels come out as sky, so their colour
lands on the far shell and moves with the sky from any eye off the centre (the bars vanish, or smear
across the panes). The colour still shows them. For every *opening* (a connected sky region enclosed
by finite depth: not touching a pole row, at most ``max_fraction`` of the panorama) this module

1. fits a plane to the frame around it: the finite pixels ``ring_px`` beyond its border, back-projected
   to metres. Given the room's wall heading (``yaw``, from the panorama's lines), the plane is upright
   and faces the wall direction nearest the frame's own free plane; only its distance is fitted, a
   Tukey-reweighted location of the frame's points along that normal. A window sits in a wall: the
   free fit (no yaw) of all three of a plane's degrees of freedom to a thin ring is tilted by whatever
   else the ring holds, 20 degrees and 6-11 % of the distance on grey_white_room's bay windows, where
   the chimney breast's edge borders them. Without a yaw, and where the frame's own free fit turns
   more than ``WALL_TURN_DEG`` from every wall direction (a window in a canted wall) or that wall is
   seen edge-on: iteratively reweighted least squares (Tukey) over all three, so a bay's side reveals
   and the sill do not tilt it more than that;
2. fits the sky's own colour inside it: a quadratic in the pixel coordinates per channel, again
   reweighted, so bars and frame pixels are outliers, not part of the fit;
3. calls a pixel a *bar* when its colour is more than ``colour_tol`` (sRGB, and at least 4 robust
   sigmas of the sky's residual) off the sky's and it belongs to an outlier region that touches the
   opening's border and reaches 2 px into it (bars hold onto their frame and cross it; a cloud in the
   middle of a pane stays sky, and so does the rim of pixels a frame shares with the sky), together
   with the one-pixel rim of mixed colour around it (on the sky it would draw ghost bars);
4. gives every bar pixel the depth where its ray meets the frame's plane (within 1.5 x the ring's
   depth range) and takes it out of the sky;
5. puts onto that plane every finite pixel within 2 ``ring_px`` of the opening (and within its box,
   ``ring_px`` + 2 px beyond its extent) that lies behind it:
   nothing of the room is behind its window, but a network's blur pushes a frame's edge towards the
   sky (by half its distance, grey_white_room), where a step sideways sees it over the sky.

``opening_reveals`` then adds the points a recessed window hides from the centre: the side of its recess
behind the wall's edge and the frame behind that edge, so that a step sideways sees them, not the sky.

Pure functions on an equirect grid: colour [H, W, 3] sRGB in [0, 1], radial depth [H, W] in metres with
non-finite = sky, pixel centres at +0.5 (docs/conventions.md).
"""

from __future__ import annotations

import math

import numpy as np
import torch

TUKEY_C = 4.685  # Tukey's biweight constant (95 % efficiency for Gaussian residuals)
WALL_TURN_DEG = 35.0  # a free window plane turned further from every wall direction is its own wall's
# (grey_white_room's frames, a wall edge beside them, turned it up to 21 degrees)


def keep_opening_bars(
    srgb: torch.Tensor,
    depth: torch.Tensor,
    ring_px: int = 3,
    colour_tol: float = 0.06,
    max_fraction: float = 0.05,
    behind_tol: float = 0.03,
    yaw: float | None = None,
) -> tuple[torch.Tensor, dict]:
    """The module docstring's steps on srgb [H, W, 3] and radial depth [H, W] (metres, non-finite = sky),
    with the room's wall heading ``yaw`` (radians, atan2(x, z) modulo 90 deg; None = a free plane):
    (the depth with every bar pixel at its frame's plane [H, W], {"openings": how many sky regions were
    openings, "bar_pixels": how many pixels left the sky, "frame_pixels": how many finite pixels near
    an opening with bars (step 5) lay more than ``behind_tol`` (relative) behind its plane and
    went onto it})."""
    from holoflow.geometry.sphere import equirect_directions

    H, W = depth.shape
    d = depth.detach().cpu().double().numpy()
    col = srgb.detach().cpu().double().numpy()
    sky = ~(np.isfinite(d) & (d > 0))
    out = d.copy()
    found = {"openings": 0, "bar_pixels": 0, "frame_pixels": 0}
    dirs = None  # [H, W, 3] unit directions, made when the first bars are found
    for (y0, y1, x0, x1), comp in _openings(sky, max_fraction, ring_px + 2):
        found["openings"] += 1
        bars = _bar_pixels(comp, *_sky_fit(col[y0:y1, x0:x1], comp), colour_tol)
        if not bars.any():
            continue
        ring = _dilate(comp, ring_px) & ~_dilate(comp, 1) & ~sky[y0:y1, x0:x1]
        if ring.sum() < 12:
            continue
        if dirs is None:
            dirs = equirect_directions(H, W, dtype=torch.float64).numpy()
        u, ring_d = dirs[y0:y1, x0:x1], d[y0:y1, x0:x1][ring]
        points = u[ring] * ring_d[:, None]  # [R, 3] metres
        plane = _robust_plane(points)
        if yaw is not None:
            plane = _wall_plane(points, yaw, plane)
        if plane is None:
            continue
        normal, offset = plane  # offset > 0: a ray meets the plane at offset / cos, in front when cos > 0
        with np.errstate(divide="ignore"):
            t = offset / (u[bars] @ normal)  # [B] metres
        t = np.clip(np.where(t > 0, t, np.inf), ring_d.min() / 1.5, ring_d.max() * 1.5)  # edge-on: no bar lost
        out[y0:y1, x0:x1][bars] = t
        found["bar_pixels"] += int(bars.sum())
        # nothing of the room lies behind its window: a frame a network blurred past the plane goes onto it
        near = _dilate(comp, 2 * ring_px) & ~sky[y0:y1, x0:x1]  # within its box
        with np.errstate(divide="ignore"):
            t_near = offset / (u[near] @ normal)  # [F] metres
        box = out[y0:y1, x0:x1]  # a view of out
        behind = (t_near > 0) & (box[near] > t_near * (1 + behind_tol))
        box[near] = np.where(behind, t_near, box[near])
        found["frame_pixels"] += int(behind.sum())
    return torch.from_numpy(out).to(depth.dtype).to(depth.device), found


def opening_reveals(
    srgb: torch.Tensor,
    depth: torch.Tensor,
    spacing_rad: float,
    ring_px: int = 3,
    max_fraction: float = 0.05,
    max_depth: float = 0.6,
    bar_px: int = 3,
    frame_px: int = 16,
    recess_reach: float = 0.25,
) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """Points where a window's recess hides from the centre: the side the wall's edge hides, and the
    strip of the window behind that edge. A window sits back from its wall; from the centre one side of
    the recess faces the eye and the other lies behind the wall's edge, so one step sideways shows it,
    and without points there the sky dome shows through the wall. For every opening (a sky region
    enclosed by the room, at most ``max_fraction`` of the panorama; its panes closed over bars up to
    2 ``bar_px`` + 1 wide into one window) this

    1. takes the window's plane: a plane fitted to its bars when it has them, else the back-most plane
       of the finite pixels ``ring_px`` around it (``_window_plane``);
    2. measures how far each of those pixels stands in front of that plane; the recess's depth D is
       the 90th percentile of those between 2 cm (or 1 % of their distance) and ``max_depth`` metres
       (the wall around the window), and the pixels that touch the sky within a quarter of D are the
       wall's edge on the hidden side (the visible side's recess meets the window's frame, well under D);
       that edge is followed past the sky, within ``recess_reach`` x the window's size, along the pixels
       within a quarter of D that border one less than D / 2 in front of the plane: a recess taller than
       its panes hides its side over its whole height (``_along_the_recess``);
    3. sweeps each such edge pixel straight back to the window's plane along its normal (the hidden
       side; a pixel whose sweep the centre sees, a side facing it, is left out: ``_behind_what_was_seen``
       at the sweep's middle), then along the plane square off the edge (``_across_the_edge``: not
       towards where the ray past the edge meets the plane, which lies above or below the edge's foot
       off the eye's level), as far as the frame is wide where
       the centre sees it (``_frame_width``, within ``ring_px`` + 2 px of the panes' box, at most
       ``frame_px`` pixels): the frame the edge hides;
    4. spaces the points ``spacing_rad`` x the edge's distance apart (P_f's spacing) and colours them
       with the median colour of the recess's sides the centre sees (else of the wall's edge).

    srgb [H, W, 3] sRGB in [0, 1], depth [H, W] radial metres (non-finite = sky), after
    ``keep_opening_bars``. Returns (points [R, 3] metres, colours [R, 3] sRGB, {"reveals": windows
    that got points, "reveal_points": R}). Every point lies behind what the centre saw."""
    import cv2

    from holoflow.geometry.sphere import equirect_directions

    H, W = depth.shape
    d = depth.detach().cpu().double().numpy()
    col = srgb.detach().cpu().double().numpy()
    sky = ~(np.isfinite(d) & (d > 0))
    found = {"reveals": 0, "reveal_points": 0}
    points, colours = [np.zeros((0, 3))], [np.zeros((0, 3))]
    # a window's panes are one opening: close the sky over its bars (up to 2 bar_px + 1 wide)
    closed = cv2.morphologyEx(sky.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((2 * bar_px + 1,) * 2, np.uint8))
    dirs = None
    for (y0, y1, x0, x1), window in _openings(closed.astype(bool), max_fraction, ring_px + 2, grow=recess_reach):
        solid = ~sky[y0:y1, x0:x1]
        comp, bars = window & ~solid, window & solid  # the window's sky, and its bars
        ring = _dilate(window, ring_px) & solid  # its bars and frame
        if ring.sum() < 12:
            continue
        if dirs is None:
            dirs = equirect_directions(H, W, dtype=torch.float64).numpy()
        u, dd = dirs[y0:y1, x0:x1], np.where(solid, d[y0:y1, x0:x1], 0.0)
        xyz = u * dd[..., None]  # [h, w, 3]
        # the window's plane: its bars when it has them (its frame ring holds the bay's sides too)
        plane = _robust_plane(xyz[bars]) if bars.sum() >= 4 * ring_px * ring_px else _window_plane(xyz[ring])
        if plane is None:
            continue
        normal, offset = plane
        front = offset - xyz @ normal  # [h, w] metres in front of the window's plane
        edge = _dilate(comp, 1) & solid
        recessed = ring & (front > np.maximum(0.02, 0.01 * dd)) & (front < max_depth)  # the wall and the recess
        if recessed.sum() < 8:
            continue
        depth_w = float(np.quantile(front[recessed], 0.9))  # the recess's depth: where its wall stands
        at_wall = solid & (np.abs(front - depth_w) < 0.25 * depth_w)  # [h, w] the wall around the window
        jamb = edge & recessed & at_wall  # the wall's edge at the sky
        face = recessed & ~edge & (front < 0.75 * depth_w)  # the recess's sides seen beyond the sky's rim
        if face.sum() < 4:  # none seen: the wall's own edge
            face = recessed & ~edge
        if jamb.sum() < 8 or face.sum() < 4:
            continue
        jamb = _along_the_recess(jamb, at_wall & _dilate(~solid | (front < 0.5 * depth_w), 1))
        middle = xyz[jamb] + 0.5 * front[jamb][:, None] * normal  # [J, 3] halfway back to the window's plane
        jamb[jamb] = _behind_what_was_seen(middle, d)  # a side the centre sees is not hidden
        if not jamb.any():
            continue
        edge_xyz, ray = xyz[jamb], u[jamb]  # [J, 3]
        back = edge_xyz + front[jamb][:, None] * normal  # [J, 3] where the reveal meets the window's plane
        hit = ray * (offset / np.maximum(ray @ normal, 1e-6))[:, None]  # [J, 3] the plane behind the edge
        framed = solid & _box_around(window, ring_px + 2)  # the frame measured near the panes only
        across = _across_the_edge(hit - back, back, jamb, normal)  # the hidden strip runs square off the edge
        behind = back + _clip_length(across, _frame_width(window, framed, front, dd, spacing_rad, frame_px))
        step = spacing_rad * dd[jamb]  # [J] metres between points: P_f's own spacing at the edge
        colour = np.median(col[y0:y1, x0:x1][face], 0)  # [3]
        for a, b in ((edge_xyz, back), (back, behind)):  # the reveal, then the window's plane it hides
            new = _segments(a, b, step)
            points.append(new)
            colours.append(np.broadcast_to(colour, (len(new), 3)))
            found["reveal_points"] += len(new)
        found["reveals"] += 1
    xyz_all, rgb_all = np.concatenate(points), np.concatenate(colours)
    return torch.from_numpy(xyz_all), torch.from_numpy(rgb_all).to(srgb.dtype), found


def _openings(sky: np.ndarray, max_fraction: float, pad: int, grow: float = 0.0):
    """The openings of a sky mask [H, W]: its 8-connected regions of 16 px or more, at most
    ``max_fraction`` of the panorama, touching neither pole row. Yields ((y0, y1, x0, x1) the region's
    box grown by ``pad`` px plus ``grow`` x its longer side within the panorama, the region's mask
    [y1 - y0, x1 - x0] in that box)."""
    import cv2

    H, W = sky.shape
    n, labels, boxes, _ = cv2.connectedComponentsWithStats(sky.astype(np.uint8), connectivity=8)
    for i in range(1, n):
        x, y, w, h, area = (int(v) for v in boxes[i])
        if area < 16 or area > max_fraction * H * W or y == 0 or y + h == H:
            continue
        p = pad + round(grow * max(w, h))
        y0, y1, x0, x1 = max(0, y - p), min(H, y + h + p), max(0, x - p), min(W, x + w + p)
        yield (y0, y1, x0, x1), labels[y0:y1, x0:x1] == i


def _box_around(mask: np.ndarray, pad: int) -> np.ndarray:
    """The bounding box of mask [h, w] grown by pad px, as a mask [h, w]."""
    ys, xs = np.nonzero(mask)
    box = np.zeros_like(mask)
    box[max(0, ys.min() - pad) : ys.max() + pad + 1, max(0, xs.min() - pad) : xs.max() + pad + 1] = True
    return box


def _behind_what_was_seen(points: np.ndarray, depth: np.ndarray, tol: float = 0.01) -> np.ndarray:
    """Whether each of points [N, 3] (metres) lies more than ``tol`` (relative) behind what the centre
    sees in its direction (depth [H, W] radial metres, non-finite = sky: nothing is behind the sky)."""
    from holoflow.geometry.sampling import sample_equirect

    p = torch.from_numpy(points)
    seen = sample_equirect(torch.from_numpy(depth)[None], p, "nearest")[:, 0].numpy()  # [N]
    return np.linalg.norm(points, axis=-1) > seen * (1 + tol)


def _along_the_recess(jamb: np.ndarray, drop: np.ndarray) -> np.ndarray:
    """The wall's edge on the recess's hidden side, followed past the sky: the pixels of drop [h, w] (at
    the wall's depth, beside a pixel far behind it: the window's plane or the sky) 8-connected to the
    edge at the sky, jamb [h, w]. A recess taller than its panes (a niche, a panel above the window)
    hides its side over its whole height, not only beside the sky; a depth edge elsewhere in the box (a
    plant before the sill) is not connected to it and stays out."""
    import cv2

    n, labels = cv2.connectedComponents((drop | jamb).astype(np.uint8), connectivity=8)
    keep = np.zeros(n, bool)
    keep[np.unique(labels[jamb])] = True
    keep[0] = False
    return keep[labels]


def _frame_width(
    window: np.ndarray, solid: np.ndarray, front: np.ndarray, dd: np.ndarray, spacing_rad: float, most_px: int
) -> float:
    """How wide (metres) a window's frame is where the centre sees it: the pixels in the window's plane
    (within 2 cm or 1 %) up to ``most_px`` outside its closed mask window [h, w], per pixel of the
    window's border that lies in that plane (solid [h, w], front [h, w] metres before the plane, dd [h, w]
    radial metres)."""
    on_plane = solid & (np.abs(front) < np.maximum(0.02, 0.01 * dd))
    frame = on_plane & _dilate(window, most_px) & ~window
    border = on_plane & _dilate(window, 1) & ~window
    if border.sum() == 0 or frame.sum() == 0:
        return 0.0
    return float(frame.sum() / border.sum() * spacing_rad * np.median(dd[frame]))


def _across_the_edge(v: np.ndarray, points: np.ndarray, jamb: np.ndarray, normal: np.ndarray, r: int = 3):
    """v [J, 3] (in the window's plane) without its part along the wall's edge: the edge's direction at
    each of points [J, 3] (the edge's pixels jamb [h, w], in their row-major order, swept onto the plane
    of ``normal``) is the main axis of the edge's points within r px of it. The ray past a vertical
    edge high above the eye meets the plane above the edge's foot: the hidden strip of frame is the
    stretch square off the edge, as wide at the top of a window as at its sill."""
    from scipy.ndimage import uniform_filter

    h, w = jamb.shape
    m = jamb.astype(np.float64)
    p = np.zeros((h, w, 3))
    p[jamb] = points
    size = 2 * r + 1

    def box(x: np.ndarray) -> np.ndarray:  # [h, w] local mean over the window (zeros outside the edge)
        return uniform_filter(x, size, mode="constant")[jamb]

    n = box(m)  # [J] share of the window on the edge
    mean = np.stack([box(p[..., i]) for i in range(3)], -1) / n[:, None]  # [J, 3]
    cov = np.empty((len(points), 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = cov[:, j, i] = box(p[..., i] * p[..., j]) / n - mean[:, i] * mean[:, j]
    along = np.linalg.eigh(cov)[1][..., 2]  # [J, 3] the main axis
    along = along - np.outer(along @ normal, normal)
    along /= np.maximum(np.linalg.norm(along, axis=1, keepdims=True), 1e-12)
    lone = n * size * size < 3  # too few neighbours for a direction: v as it is
    return v - np.where(lone[:, None], 0.0, (v * along).sum(1, keepdims=True) * along)


def _clip_length(v: np.ndarray, most: float) -> np.ndarray:
    """Vectors v [N, 3] shortened to at most ``most`` long."""
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return v * np.minimum(1.0, most / np.maximum(n, 1e-12))


def _segments(a: np.ndarray, b: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Points [R, 3] along the segments from a [N, 3] to b [N, 3], ``step`` [N] metres apart (a itself
    left out, b in)."""
    steps = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(int))  # [N]
    k = np.concatenate([np.arange(1, s + 1) / s for s in steps])  # [R] fractions of the way
    j = np.repeat(np.arange(len(a)), steps)
    return a[j] + k[:, None] * (b[j] - a[j])


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """mask [h, w] bool grown by r px (square)."""
    import cv2

    return cv2.dilate(mask.astype(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8)).astype(bool)


def _sky_fit(col: np.ndarray, comp: np.ndarray) -> tuple[np.ndarray, float]:
    """The sky's colour over the opening comp [h, w] (step 2): a quadratic in the pixel coordinates per
    channel, Tukey-reweighted so bars and frame pixels do not pull it. Returns (each pixel's distance
    from it [P], P = comp's pixels in row-major order, and the robust sigma of the distances of the
    pixels the fit kept)."""
    yy, xx = np.nonzero(comp)
    sy, sx = max(1.0, (yy.max() - yy.min()) / 2), max(1.0, (xx.max() - xx.min()) / 2)
    a, b = (yy - yy.mean()) / sy, (xx - xx.mean()) / sx
    design = np.stack([np.ones_like(a), a, b, a * a, a * b, b * b], 1)  # [P, 6]
    c = col[comp]  # [P, 3]
    resid = np.linalg.norm(c - np.median(c, 0), axis=1)  # start from the median colour
    for _ in range(8):
        # the scale from the best 30 % (a Gaussian's |x| has 0.385 sigma there): bars and the pixels
        # that mix them in can be half of a small pane, which would inflate a median's scale
        scale = max(float(np.quantile(resid, 0.3)) / 0.385, 1e-3)
        weights = _tukey(resid, scale)
        sw = np.sqrt(weights)[:, None]
        coef, *_ = np.linalg.lstsq(design * sw, c * sw, rcond=None)
        resid = np.linalg.norm(c - design @ coef, axis=1)  # [P]
    scale = max(float(np.quantile(resid, 0.3)) / 0.385, 1e-3)
    weights = _tukey(resid, scale)
    inlier = resid[weights > 0]
    return resid, 1.4826 * float(np.median(inlier)) if len(inlier) else 0.0


def _tukey(resid: np.ndarray, scale: float) -> np.ndarray:
    """Tukey's biweight [N] of residuals resid [N] at a robust scale (the same units): 1 at 0, 0 beyond
    TUKEY_C scales."""
    return np.clip(1 - (resid / (TUKEY_C * scale)) ** 2, 0, None) ** 2


def _bar_pixels(comp: np.ndarray, resid: np.ndarray, sigma: float, colour_tol: float) -> np.ndarray:
    """The opening comp [h, w]'s pixels whose colour is off the sky's fit (resid [P] and sigma of
    ``_sky_fit``) by more than colour_tol and 4 sigmas, and whose outlier region touches the opening's border and
    reaches 2 px inside it (step 3), with their one-pixel rim."""
    import cv2

    odd = np.zeros_like(comp)
    odd[comp] = resid > max(colour_tol, 4 * sigma)
    if not odd.any():
        return odd
    inner = cv2.erode(comp.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    n, labels = cv2.connectedComponents(odd.astype(np.uint8), connectivity=8)
    touching = np.intersect1d(labels[odd & comp & ~inner], labels[odd & inner])
    bars = np.isin(labels, touching[touching > 0]) & odd
    return _dilate(bars, 1) & comp  # a bar's rim of mixed pixels goes with the bar, not onto the sky


def _window_plane(points: np.ndarray, tries: int = 256, seed: int = 0) -> tuple[np.ndarray, float] | None:
    """The plane of a window from the points [R, 3] around it (metres): the back-most plane that many of
    them lie on. The frame around an opening also holds the wall's edge and the recess's sides, all in
    front of the window; nothing of the room lies behind it. Among ``tries`` planes through three of
    the points (seeded), the one with the most points within 1 % of their distance (at least 1 cm) less
    twice those behind it by more than three times that wins, and ``_robust_plane`` refits its points;
    None unless a tenth of the points lie on it and at most one in twenty behind it."""
    r = np.linalg.norm(points, axis=1)
    points = points[r < 1.5 * np.median(r)]  # not the sky a network's blur pulled into the frame
    if len(points) < 3:
        return None
    rng = np.random.default_rng(seed)
    tol = np.maximum(0.01 * np.linalg.norm(points, axis=1), 0.01)  # [R]
    look = points.mean(0) / max(float(np.linalg.norm(points.mean(0))), 1e-12)  # towards the window
    median = float(np.median(np.linalg.norm(points, axis=1)))
    best, best_score = None, -np.inf
    for _ in range(tries):
        a, b, c = points[rng.choice(len(points), 3, replace=False)]
        normal = np.cross(b - a, c - a)
        if np.linalg.norm(normal) < 1e-12:
            continue
        normal /= np.linalg.norm(normal)
        offset = float(normal @ a)
        if offset < 0:
            normal, offset = -normal, -offset
        if normal @ look < 0.3 or offset / (normal @ look) < 0.9 * median:  # edge-on, or before its frame
            continue
        front = offset - points @ normal  # [R] metres before the plane (the centre's side)
        score = int((np.abs(front) < tol).sum()) - 2 * int((front < -3 * tol).sum())
        if score > best_score:
            best, best_score = (normal, offset), score
    if best is None:
        return None
    front = best[1] - points @ best[0]
    if (np.abs(front) < tol).mean() < 0.1 or (front < -3 * tol).mean() > 0.05:
        return None  # no plane that enough of them lie on with the rest in front: not a window's
    plane = _robust_plane(points[np.abs(front) < 3 * tol])
    return plane if plane is not None and plane[0] @ look >= 0.3 else None


def _wall_plane(
    points: np.ndarray, yaw: float, free: tuple[np.ndarray, float] | None
) -> tuple[np.ndarray, float] | None:
    """The upright plane n . p = offset through points [R, 3] (metres) around an opening whose normal n
    is one of the room's horizontal wall directions (yaw + k 90 deg, k = 0..3; +y is down): the one
    nearest the ``free`` plane's (``_robust_plane`` through them; without it, the one that looks most
    towards them), offset their Tukey-reweighted location along n (metres). The free plane comes back
    instead where it turns more than ``WALL_TURN_DEG`` from every wall direction (a window in a wall
    that is not the room's: a canted bay) or where n is seen edge-on (n . mean direction < 0.3)."""
    look = points.mean(0) / max(float(np.linalg.norm(points.mean(0))), 1e-12)
    walls = [np.array([math.sin(a), 0.0, math.cos(a)]) for a in yaw + np.arange(4) * math.pi / 2]
    if free is None:
        normal = max(walls, key=lambda n: float(n @ look))
    else:
        across = free[0] * np.array([1.0, 0.0, 1.0])  # its horizontal part
        across = across / max(float(np.linalg.norm(across)), 1e-12)
        normal = max(walls, key=lambda n: abs(float(n @ across)))
        normal = normal if float(normal @ look) > 0 else -normal
        if math.degrees(math.acos(min(1.0, abs(float(normal @ across))))) > WALL_TURN_DEG:
            return free
    if float(normal @ look) < 0.3:
        return free
    along = points @ normal  # [R] metres
    offset = float(np.median(along))
    floor = 0.005 * offset  # 5 mm at 1 m: no frame is flatter
    for _ in range(8):
        resid = along - offset
        scale = max(1.4826 * float(np.median(np.abs(resid))), floor)
        weights = _tukey(resid, scale)
        offset = float((weights * along).sum() / max(float(weights.sum()), 1e-12))
    return (normal, offset) if offset > 0 else free


def _robust_plane(points: np.ndarray) -> tuple[np.ndarray, float] | None:
    """A plane n . p = offset (|n| = 1, offset > 0: the centre on its inner side) through points [R, 3]
    metres by Tukey-reweighted total least squares; None when fewer than half of them fit it."""
    weights = np.ones(len(points))
    normal, offset = None, 0.0
    floor = 0.005 * float(np.median(np.linalg.norm(points, axis=1)))  # 5 mm at 1 m: no plane is flatter
    for _ in range(8):
        centre = (points * weights[:, None]).sum(0) / weights.sum()
        q = (points - centre) * np.sqrt(weights)[:, None]
        normal = np.linalg.svd(q, full_matrices=False)[2][-1]
        offset = float(normal @ centre)
        resid = np.abs(points @ normal - offset)
        scale = max(1.4826 * float(np.median(resid)), floor)
        weights = _tukey(resid, scale)
        if weights.sum() < 3:
            return None
    if (weights > 0).mean() < 0.5 or not math.isfinite(offset) or abs(offset) < 1e-9:
        return None
    if offset < 0:
        normal, offset = -normal, -offset
    return normal, offset
