"""Planar refinement of a network's metric panorama depth: the room's large planes straighten it.

A monocular network's depth is off by a smooth, low-frequency bias (a wall bends by several per cent)
on top of its pixel noise; seen from the centre that is invisible, but one step away every texture on
the bent wall swims by pixels. Indoors most pixels lie on a few large planes whose orientations follow
the room (Manhattan: a floor and ceiling, walls along two horizontal axes). This module finds those
planes in the depth itself, takes the ratio plane / depth on their pixels as a sample of the bias,
spreads it smoothly over the panorama (objects in front of a wall get the wall's correction, as the
bias is regional), and lays the plane pixels exactly on their planes. The planes that bound the room
(walls, floor, ceiling: nothing lies beyond them) take their offsets from where they meet, which the
bias does not move; a piece of furniture's front keeps its own fit, since its edges are no corners.

Arrays: radial depth [H, W] metres (+inf sky), equirect, world axes of docs/conventions (+y down).
Planes: ``axis`` a unit world vector [3] and ``offset`` s (metres) with p . a = s for the points p.
"""

from __future__ import annotations

import numpy as np

#: the planes' search: a plane gets pixels whose normal is within ``NORMAL_DEG`` of its axis and
#: whose depth is within ``tol`` (relative) of it; a plane needs ``MIN_SUPPORT`` of the panorama's
#: solid angle; offsets closer than ``MIN_OFFSET`` metres to the eye are not planes of the room; at
#: most ``MAX_PLANES``; two planes meet when they touch at ``MIN_CONTACTS`` pixel pairs or more
NORMAL_DEG = 25.0
MIN_SUPPORT = 0.01
MIN_OFFSET = 0.2
MAX_PLANES = 12
MIN_CONTACTS = 20
#: narrower panoramas are not refined: a step's blur, a ramp and a plane's curvature are a pixel or two
#: apart there, and no window tells them apart
MIN_WIDTH = 256
#: relative offset between a plane's leaning and facing pixels beyond which it is a curved surface
CURVED = 0.02
#: the planes must cover this share of the sphere for the scene to be a room (else nothing is changed)
MIN_ROOM = 0.3
#: a plane bounds the room when, of the directions towards it, under this share see something beyond it;
#: more is a piece of furniture (a shelf's front, a table top) with a wall or the floor behind it
BEYOND = 0.2
#: a snapped plane grows over the pixels connected to it that face its way, lie within ``GROW_TOL``
#: (relative) of it and cross no depth step over ``GROW_STEP`` (relative, 3 x 3 px): ``grow_planes``
GROW_TOL = 0.25
GROW_STEP = 0.05
#: a contact reads each plane's offset this many degrees from the crease, inside the plane: a skirting
#: board or a cornice (about 3 deg tall across a room) lies within the plane's tolerance a few cm before
#: it, and read on the moulding every wall would come out a per cent or so nearer than it is
CONTACT_INSET_DEG = 3.0
#: the planes and the bias are found on the depth at most this wide (``refine_with_planes``)
WORK_WIDTH = 1024
#: the bias correction: where no plane pixel is near, the planes' spread this many times wider
#: (``spread_log_ratio``), except within ``NEAR_SKY`` x width pixels of the sky (a window's frame)
WIDE_SPREAD = 4.0
NEAR_SKY = 12 / 1024
#: relative engines whose depth carries a network's blur and low-frequency bias (``refine: auto`` mends it)
BIASED_ENGINES = ("depth_anything", "simulated")


def wanted(mode: str, relative_engine: str) -> bool:
    """Whether metric_align refines the depth (sharp steps, then planes): ``mode`` on / off, or auto (a
    network's depth)."""
    return mode == "on" or (mode == "auto" and relative_engine in BIASED_ENGINES)


def room_axes(normals: np.ndarray, weight: np.ndarray, yaw: float | None = None) -> np.ndarray:
    """The room's three axes [3, 3] (rows: vertical (0, 1, 0), then the two horizontal wall axes) from
    unit normals [H, W, 3] weighted by [H, W]: the wall normals' dominant direction modulo 90 deg
    (circular mean of 4 x their heading, atan2(x, z)); or, given ``yaw`` (radians, the same heading),
    from that."""
    if yaw is None:
        n = normals.reshape(-1, 3)
        w = weight.reshape(-1) * (np.abs(n[:, 1]) < np.sin(np.radians(NORMAL_DEG)))  # wall-like normals
        heading = np.arctan2(n[:, 0], n[:, 2])
        z = np.sum(w * np.exp(4j * heading))
        yaw = float(np.angle(z) / 4.0) if abs(z) > 0 else 0.0
    a = np.array([np.sin(yaw), 0.0, np.cos(yaw)])
    b = np.array([np.cos(yaw), 0.0, -np.sin(yaw)])
    return np.stack([np.array([0.0, 1.0, 0.0]), a, b])


def find_planes(points: np.ndarray, normals: np.ndarray, weight: np.ndarray, axes: np.ndarray, tol: float) -> list:
    """Planes ``(axis [3], offset m, support)`` of points [N, 3] with unit normals [N, 3] and solid-angle
    weights [N] (summing to the panorama's share): along each axis, the heaviest offset (a histogram
    peak) whose pixels within ``tol`` (relative) carry ``MIN_SUPPORT``, its offset the weighted median of
    those pixels; taken greedily, the pixels of each plane removed before the next, at most
    ``MAX_PLANES``. A plane that is ``curved`` is dropped, except a floor (horizontal, below the eye):
    seen from the eye its far pixels are the grazing ones, whose normals a network's noise tilts the
    most, so under a smooth bias its leaning pixels sit a few per cent off its facing ones although it
    is flat."""
    cos_lim = np.cos(np.radians(NORMAL_DEG))
    free = np.ones(len(points), bool)
    planes = []
    while len(planes) < MAX_PLANES:
        best = None
        for axis in axes:
            facing = free & (np.abs(normals @ axis) > cos_lim)
            s = points[facing] @ axis  # [M] signed offsets
            if s.size == 0:
                continue
            far = np.abs(s) > MIN_OFFSET
            s, w = s[far], weight[facing][far]
            if s.size == 0:
                continue
            ls = np.sign(s) * np.log(np.abs(s))  # relative tolerance = a fixed width in log offset
            bins = np.arange(ls.min() - tol, ls.max() + 2 * tol, tol / 4)
            hist, _ = np.histogram(ls, bins, weights=w)
            run = np.convolve(hist, np.ones(8), mode="same")  # window of width 2 tol
            k = int(np.argmax(run))
            if best is None or run[k] > best[0]:
                best = (run[k], axis, 0.5 * (bins[k] + bins[k + 1]))
        if best is None or best[0] < MIN_SUPPORT:
            break
        _, axis, centre = best
        s = points @ axis
        ls = np.sign(s) * np.log(np.maximum(np.abs(s), 1e-12))
        near = free & (np.abs(normals @ axis) > cos_lim) & (np.abs(ls - centre) < tol)
        offset = _weighted_median(s[near], weight[near])
        on = free & (np.abs(normals @ axis) > cos_lim) & (np.abs(s / offset - 1.0) < tol)
        support = float(weight[on].sum())
        free &= ~on
        if support < MIN_SUPPORT or (
            not is_floor(axis, offset) and curved(s[on], np.abs(normals[on] @ axis), weight[on])
        ):
            continue
        planes.append((axis, float(offset), support))
    return planes


def is_floor(axis: np.ndarray, offset: float) -> bool:
    """Whether the plane p . axis = offset (metres) is a floor: horizontal (the vertical axis, +y down)
    and below the eye."""
    return bool(axis[1] > 0.9 and offset > 0)


def curved(offsets: np.ndarray, cos_to_axis: np.ndarray, weight: np.ndarray) -> bool:
    """Whether a plane's pixels (offsets [M] m, |cos| of their normal to the axis [M], weights [M]) are a
    patch of a curved surface: on a cylinder or a sphere the pixels whose normal leans off the axis lie
    nearer than those facing it (s = R cos), so the two groups' median offsets differ by more than
    ``CURVED``; on a plane, however noisy or bent its normals, they do not. Undecided (False) when
    either group holds under a tenth of the weight (exact planes have no leaning normals)."""
    lean = cos_to_axis < np.cos(np.radians(NORMAL_DEG / 2))
    total = weight.sum()
    if weight[lean].sum() < 0.1 * total or weight[~lean].sum() < 0.1 * total:
        return False
    facing, leaning = _weighted_median(offsets[~lean], weight[~lean]), _weighted_median(offsets[lean], weight[lean])
    return abs(np.log(leaning / facing)) > CURVED


def plane_distance(dirs: np.ndarray, axis: np.ndarray, offset: float) -> np.ndarray:
    """Distance (m) [H, W] along each unit ray dirs [H, W, 3] to the plane p . axis = offset; -1 where
    the ray runs parallel to it (negative also where the plane lies behind)."""
    along = dirs @ axis  # [H, W]
    return np.where(np.abs(along) > 1e-6, offset / np.where(np.abs(along) > 1e-6, along, 1.0), -1.0)


def bounds_room(dirs: np.ndarray, depth: np.ndarray, weight: np.ndarray, planes: list, tol: float) -> list:
    """Per plane, whether it bounds the room (bool): of the directions [H, W, 3] whose rays reach the
    plane (weighted by [H, W], the finite depths' solid angle), under ``BEYOND`` see a depth [H, W] more
    than ``tol`` (relative) beyond it. Nothing lies behind a wall, the floor or the ceiling but openings;
    behind a cupboard's front or a table top the room goes on."""
    out = []
    for axis, offset, _ in planes:
        t = plane_distance(dirs, axis, offset)  # [H, W] m
        toward = (t > 0) & (weight > 0)
        beyond = toward & (depth > t * (1 + tol))
        reach = weight[toward].sum()
        out.append(bool(reach > 0 and weight[beyond].sum() < BEYOND * reach))
    return out


def plane_depth_ratio(
    dirs: np.ndarray, depth: np.ndarray, normals: np.ndarray, planes: list, tol: float, which: np.ndarray | None = None
):
    """Per pixel, the ratio (plane depth along the ray) / depth [H, W] for the plane it lies on (its normal
    within ``NORMAL_DEG`` of the plane's axis and its depth within ``tol``: the nearest such plane), and
    which plane [H, W] (-1: none)."""
    H, W = depth.shape
    best = np.full((H, W), np.inf)
    ratio = np.ones((H, W))
    given, which = which, np.full((H, W), -1)
    cos_lim = np.cos(np.radians(NORMAL_DEG))
    finite = np.isfinite(depth) & (depth > 0)
    for i, (axis, offset, _) in enumerate(planes):
        t = plane_distance(dirs, axis, offset)  # [H, W]
        r = np.where(finite & (t > 0), t / np.where(finite, depth, 1.0), np.inf)
        err = np.abs(np.log(np.where(np.isfinite(r) & (r > 0), r, np.inf)))
        if given is not None:
            hit = (given == i) & np.isfinite(err)
        else:
            hit = (err < np.log1p(tol)) & (err < best)
            if normals is not None:
                hit &= np.abs(normals @ axis) > cos_lim
        best = np.where(hit, err, best)
        ratio = np.where(hit, r, ratio)
        which = np.where(hit, i, which)
    return ratio, which


def spread_log_ratio(
    log_ratio: np.ndarray,
    known: np.ndarray,
    sigma: float,
    fade: float = 0.2,
    wide: float = WIDE_SPREAD,
    local: np.ndarray | None = None,
) -> np.ndarray:
    """log_ratio [H, W] known on ``known`` [H, W] spread over the panorama by normalized Gaussian
    convolution (``sigma`` pixels; columns wrap, rows clamp). Where the known pixels' local density is
    below ``fade`` it blends into the same spread ``wide`` times wider, which itself fades to 0 (no
    correction) where its density is below ``fade``; pixels of ``local`` [H, W] (bool) take no part of
    the wide spread and fade to 0 with the narrow one."""
    import scipy.ndimage as ndi

    mode = ("nearest", "wrap")
    w = known.astype(np.float64)
    samples = np.where(known, log_ratio, 0.0)

    def spread(s: float) -> tuple[np.ndarray, np.ndarray]:
        den = ndi.gaussian_filter(w, s, mode=mode)
        return ndi.gaussian_filter(samples, s, mode=mode) / np.maximum(den, 1e-12), np.clip(den / fade, 0.0, 1.0)

    near, a = spread(sigma)
    if wide <= 1:
        return near * a
    far, b = spread(wide * sigma)
    fallback = far * b if local is None else np.where(local, 0.0, far * b)
    return a * near + (1.0 - a) * fallback


def contact_offsets(
    dirs: np.ndarray,
    depth: np.ndarray,
    which: np.ndarray,
    planes: list,
    ground: int,
    tol: float,
    gap: int = 6,
    bounds: list | None = None,
    inset: int = 0,
) -> tuple[list, list]:
    """Plane offsets [P] re-derived from where the planes that bound the room (``bounds`` [P] bool,
    ``bounds_room``; None: all) meet, the offset of plane ``ground`` (the floor) held; the others keep
    their fit and their pixels count as unassigned. Two planes touch where their pixels come within
    ``gap`` pixels of each other along a row or a column, with only unassigned pixels between and the
    depth continuous across (a real corner, not an occluding edge). Each side of a contact is read
    ``inset`` pixels further into its own plane along that row or column, past a moulding at the crease
    (``CONTACT_INSET_DEG``); the contact counts where that pixel lies on the plane too (its own or
    unassigned, and within ``tol`` of the plane's fit). A network's bias is smooth, so at a
    seam it is the same on both sides, and the measured depths there have the ratio of the true offsets:
    each pair of planes that touch at ``MIN_CONTACTS`` pixel pairs or more gives one equation (the
    median over its contacts) for the log of that ratio, and all offsets are solved at once by
    weighted least squares (``_solve_offsets``); a plane the solution moves by more than ``tol`` from
    its fit is dropped and the rest solved again. This is how a room layout is read: positions from where the
    edges are in the image, which a low-frequency bias does not move. Returns the offsets [P] and each
    plane's number of contacts in the solution ([P], 0: kept as fitted)."""
    offsets = [p[1] for p in planes]
    count = [0] * len(planes)
    if bounds is not None:  # furniture: neither a side of a contact nor in the solution
        which = np.where(np.isin(which, [i for i, b in enumerate(bounds) if not b]), -1, which)
    free = which < 0
    d = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan)
    axes = np.stack([p[0] for p in planes])  # [P, 3]
    fits = np.array([p[1] for p in planes], dtype=np.float64)  # [P]
    pairs = []  # (plane a, plane b, rays at a [M, 3], at b [M, 3], depth at a [M], at b [M])
    for axis in (0, 1):
        w, f, dd, dr = (which, free, d, dirs) if axis == 0 else (which.T, free.T, d.T, dirs.transpose(1, 0, 2))
        ld = np.log(dd)
        n = w.shape[0]

        def on_plane(at: slice, label: np.ndarray) -> np.ndarray:
            """Whether the pixels of rows ``at`` lie on plane ``label`` [...] (its own or unassigned, and
            within tol of its fit), where a contact's side is read."""
            cos = np.einsum("...k,...k->...", dr[at], axes[label])
            with np.errstate(divide="ignore", invalid="ignore"):
                t = fits[label] / cos
                near = np.abs(np.log(dd[at] / t)) < np.log1p(tol)
            return ((w[at] == label) | (w[at] < 0)) & (t > 0) & near

        between = np.ones((n - 1,) + w.shape[1:], bool)  # rows r + 1 .. r + k - 1 all unassigned
        for k in range(1, gap + 1):
            if k > 1:
                between = between[: n - k] & f[k - 1 : n - 1]
            a, b = w[: n - k], w[k:]
            cont = np.abs(ld[: n - k] - ld[k:]) < np.log1p(tol)
            hit = (a >= 0) & (b >= 0) & (a != b) & between & cont
            if n - k - 2 * inset <= 0:
                continue
            # a contact at rows r (a) and r + k (b) is read at r - inset and r + k + inset
            sub, ia, ib = slice(inset, n - k - inset), slice(0, n - k - 2 * inset), slice(k + 2 * inset, n)
            hit = hit[sub] & on_plane(ia, a[sub]) & on_plane(ib, b[sub])
            if hit.any():
                pairs.append((a[sub][hit], b[sub][hit], dr[ia][hit], dr[ib][hit], dd[ia][hit], dd[ib][hit]))
    if not pairs:
        return offsets, count
    pa, pb, ra, rb, da, db = (np.concatenate([p[c] for p in pairs]) for c in range(6))
    # each contact says log|s_a| - log|s_b| = log q: the depth ratio true / measured carries across the
    # corner (the bias is smooth), so s_a / s_b = (r_a . axis_a) d_a / ((r_b . axis_b) d_b)
    qa = np.einsum("mk,mk->m", ra, axes[pa]) * da
    qb = np.einsum("mk,mk->m", rb, axes[pb]) * db
    signs = np.sign(fits)
    ok = (np.sign(qa) == signs[pa]) & (np.sign(qb) == signs[pb])
    logq = np.log(np.abs(qa[ok]) / np.abs(qb[ok]))
    lo, hi = np.minimum(pa[ok], pb[ok]), np.maximum(pa[ok], pb[ok])
    logq = np.where(pa[ok] == lo, logq, -logq)  # as log|s_lo| - log|s_hi|
    edges = []  # (i, j, median log|s_i| - log|s_j|, contacts)
    for i, j in {(int(a), int(b)) for a, b in zip(lo, hi)}:
        m = (lo == i) & (hi == j)
        if m.sum() >= MIN_CONTACTS:
            edges.append((i, j, float(np.median(logq[m])), int(m.sum())))
    fitted = np.log(np.abs([p[1] for p in planes]))
    free_planes = {i for i in range(len(planes)) if bounds is None or bounds[i]} - {ground}
    for _ in range(len(planes)):  # solve; drop planes the contacts move by more than tol; solve again
        x, reached = _solve_offsets(edges, len(planes), ground, fitted[ground], free_planes)
        bad = {i for i in reached if i != ground and abs(x[i] - fitted[i]) > np.log1p(tol)}
        if not bad:
            break
        free_planes -= bad
        edges = [e for e in edges if e[0] not in bad and e[1] not in bad]
    for i in reached - {ground}:
        offsets[i] = float(signs[i] * np.exp(x[i]))
        count[i] = sum(e[3] for e in edges if i in e[:2])
    return offsets, count


def _solve_offsets(edges: list, n: int, ground: int, x_ground: float, free: set) -> tuple[np.ndarray, set]:
    """Log offsets [n] from the contact equations ``edges`` (i, j, log|s_i| - log|s_j|, weight) by
    weighted least squares, ``ground`` held at ``x_ground``; only the planes of ``free`` linked to the
    ground through the equations are solved (the set returned, ground included)."""
    reached, grow = {ground}, True
    while grow:
        grow = False
        for i, j, _, _ in edges:
            if (i in reached) != (j in reached) and ({i, j} - reached) <= free:
                reached |= {i, j}
                grow = True
    x = np.zeros(n)
    x[ground] = x_ground
    unknown = sorted(reached - {ground})
    if not unknown:
        return x, reached
    col = {k: c for c, k in enumerate(unknown)}
    rows, rhs, w = [], [], []
    for i, j, d, cnt in edges:
        if i not in reached or j not in reached:
            continue
        row = np.zeros(len(unknown))
        b = d
        for k, sgn in ((i, 1.0), (j, -1.0)):
            if k == ground:
                b -= sgn * x_ground
            else:
                row[col[k]] += sgn
        rows.append(row)
        rhs.append(b)
        w.append(np.sqrt(cnt))
    A, b, w = np.array(rows), np.array(rhs), np.array(w)
    sol, *_ = np.linalg.lstsq(A * w[:, None], b * w, rcond=None)
    x[unknown] = sol
    return x, reached


def refine_with_planes(
    depth: np.ndarray,
    tol: float = 0.1,
    snap: float = 0.05,
    sigma_frac: float = 1 / 128,
    yaw: float | None = None,
    work_width: int = WORK_WIDTH,
) -> tuple:
    """Radial depth [H, W] (metres, +inf sky) straightened by the room's planes, and facts (dict: the
    planes, the share of the panorama on them and of it grown, the correction's range).

    1. normals of the depth; the room's axes (``room_axes``; turned by ``yaw`` when it is given: the
       heading of the walls found otherwise, e.g. from the panorama's straight lines); its planes
       (``find_planes``, tolerance ``tol``); the floor (the heaviest horizontal plane below the eye)
       keeps its fitted offset, every other plane that bounds the room (``bounds_room``) takes the
       offset its contacts imply (``contact_offsets``), furniture keeps its fit;
    2. on the plane pixels the ratio plane / depth samples the network's low-frequency bias: its log,
       spread over the panorama with a Gaussian of ``sigma_frac`` x width pixels (``WIDE_SPREAD`` times
       wider where no plane pixel is near, but not at the sky's edge: ``spread_log_ratio``), multiplies
       every pixel;
    3. pixels within ``snap`` of a plane are laid on it, whatever their normal says: a network's normals
       are off by ~20 deg (median) pixel to pixel, and a plane left a patchwork of laid and unlaid pixels
       has a step at every seam, a crack one step away; each plane then grows over the pixels connected
       to it that face its way and cross no depth step (``grow_planes``), which it takes too.
    Steps 1 and 2 run on the depth shrunk to at most ``work_width`` pixels across (``shrink_depth``):
    a normal is fitted over a few pixels, so on a finer grid a network's pixel noise tilts it further
    and the planes would find less of the room the wider the panorama; step 3 runs at full width.
    When the planes cover under ``MIN_ROOM`` of the sphere (an open landscape, curved surfaces) the
    depth is returned unchanged."""
    import torch

    from holoflow.geometry.sphere import equirect_directions
    from holoflow.geometry.surfaces import surface_normals

    depth = np.asarray(depth, np.float64)
    H, W = depth.shape
    work = depth if W <= work_width else shrink_depth(depth, work_width)
    found = _room_planes(work, tol, sigma_frac, yaw)
    if found is None:  # not a room: an open scene, or curved surfaces
        return depth, {"planes": [], "on_planes": 0.0, "note": f"planes cover under {MIN_ROOM:.0%}: not a room"}
    planes, facts, log_c, normals = found
    finite = np.isfinite(depth) & (depth > 0)
    if work is not depth:  # the correction is smooth: enlarged bilinearly; the normals at full width
        import cv2

        log_c = cv2.resize(log_c, (W, H), interpolation=cv2.INTER_LINEAR)
        normals = surface_normals(torch.from_numpy(depth)).numpy()
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()  # [H, W, 3]
    out = np.where(finite, depth * np.exp(log_c), depth)
    _, snapped = plane_depth_ratio(dirs, out, None, planes, snap)
    on = grow_planes(dirs, out, normals, planes, snapped, sigma=2.0 * W / work.shape[1])
    ratio, _ = plane_depth_ratio(dirs, out, None, planes, np.inf, on)
    out = np.where(on >= 0, out * ratio, out)
    weight = _solid_angle(H, W) * finite
    facts = {
        "planes": facts["planes"],
        "on_planes": float(weight[on >= 0].sum()),
        "grown": float(weight[(on >= 0) & (snapped < 0)].sum()),
        "yaw_deg": facts["yaw_deg"],
        "correction": [float(np.exp(log_c[finite].min())), float(np.exp(log_c[finite].max()))],
    }
    if work is not depth:
        facts["work_width"] = int(work.shape[1])
    return out, facts


def _room_planes(depth: np.ndarray, tol: float, sigma_frac: float, yaw: float | None):
    """Steps 1-2 of ``refine_with_planes`` on radial depth [H, W]: (the planes with their offsets, facts,
    the log of the bias correction [H, W], the normals [H, W, 3]), or None when the planes cover under
    ``MIN_ROOM`` of the sphere."""
    import torch

    from holoflow.geometry.sphere import equirect_directions
    from holoflow.geometry.surfaces import surface_normals

    H, W = depth.shape
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()  # [H, W, 3]
    finite = np.isfinite(depth) & (depth > 0)
    weight = _solid_angle(H, W) * finite  # a share of the sphere
    normals = surface_normals(torch.from_numpy(depth)).numpy()  # [H, W, 3]
    pts = dirs * np.where(finite, depth, 0.0)[..., None]
    keep = finite.reshape(-1)
    axes = room_axes(normals, weight, yaw)
    planes = find_planes(pts.reshape(-1, 3)[keep], normals.reshape(-1, 3)[keep], weight.reshape(-1)[keep], axes, tol)
    if sum(p[2] for p in planes) < MIN_ROOM:
        return None
    ratio, which = plane_depth_ratio(dirs, depth, normals, planes, tol)
    floors = [i for i, p in enumerate(planes) if is_floor(p[0], p[1])]
    fitted, contacts = [p[1] for p in planes], [0] * len(planes)
    bounds = bounds_room(dirs, depth, weight, planes, tol)
    if floors:
        inset = int(round(CONTACT_INSET_DEG / 360.0 * W))
        offsets, contacts = contact_offsets(dirs, depth, which, planes, floors[0], tol, bounds=bounds, inset=inset)
        planes = [(p[0], o, p[2]) for p, o in zip(planes, offsets)]
        ratio, _ = plane_depth_ratio(dirs, depth, normals, planes, np.inf, which)
    near_sky = None
    if not finite.all():  # openings: their frames keep the narrow correction only
        import scipy.ndimage as ndi

        near_sky = ndi.distance_transform_edt(finite) <= NEAR_SKY * W
    log_c = spread_log_ratio(np.log(ratio), which >= 0, sigma_frac * W, local=near_sky)
    facts = {
        "planes": [
            {
                "axis": [round(float(v), 4) for v in p[0]],
                "offset": p[1],
                "fitted": f,
                "contacts": c,
                "share": p[2],
                "bounds_room": b,
            }
            for p, f, c, b in zip(planes, fitted, contacts, bounds)
        ],
        "yaw_deg": round(float(np.degrees(np.arctan2(axes[1][0], axes[1][2]))), 3),
    }
    return planes, facts, log_c, normals


def shrink_depth(depth: np.ndarray, width: int) -> np.ndarray:
    """Radial depth [H, W] (metres, +inf sky) shrunk to ``width`` px across (height in proportion): each
    pixel the geometric mean of the finite depths it covers (area weights), sky where over half of it is
    sky."""
    import cv2

    H, W = depth.shape
    height = max(1, round(H * width / W))
    finite = np.isfinite(depth) & (depth > 0)
    log_d = np.where(finite, np.log(np.where(finite, depth, 1.0)), 0.0)
    share = cv2.resize(finite.astype(np.float64), (width, height), interpolation=cv2.INTER_AREA)
    mean = cv2.resize(log_d, (width, height), interpolation=cv2.INTER_AREA) / np.maximum(share, 1e-12)
    return np.where(share > 0.5, np.exp(mean), np.inf)


def _solid_angle(H: int, W: int) -> np.ndarray:
    """Each equirect pixel's share of the sphere [H, W] (rows by the cosine of their latitude)."""
    lat = (0.5 - (np.arange(H) + 0.5) / H) * np.pi
    return np.broadcast_to(np.cos(lat)[:, None] / (np.cos(lat).sum() * W), (H, W))


def grow_planes(
    dirs: np.ndarray,
    depth: np.ndarray,
    normals: np.ndarray,
    planes: list,
    which: np.ndarray,
    tol: float = GROW_TOL,
    step: float = GROW_STEP,
    sigma: float = 2.0,
) -> np.ndarray:
    """Plane membership ``which`` [H, W] (-1: none) grown over the smooth surface around each plane: a
    pixel joins plane i when it is connected (8-neighbours) to i's pixels through pixels that face along
    i's axis (their normals [H, W, 3], smoothed over ``sigma`` px, within ``NORMAL_DEG``), lie within
    ``tol`` (relative) of the plane and cross no depth step (the lightly smoothed depth ranges under
    ``step``, relative, over their 3 x 3 px). A network's regional bias bends part of a face past the
    snap tolerance (a bookshelf's top 9 % near while its middle sits on its plane); connected to the
    rest and facing the same way, it is the same face. The connections do not wrap across the
    panorama's seam: each side grows from its own plane pixels. depth [H, W] radial metres (+inf sky)."""
    import scipy.ndimage as ndi

    mode = ("nearest", "wrap")
    finite = np.isfinite(depth) & (depth > 0)
    n = np.stack([ndi.gaussian_filter(np.nan_to_num(normals[..., k]), sigma, mode=mode) for k in range(3)], -1)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-9)
    log_d = ndi.gaussian_filter(np.log(np.where(finite, depth, 1.0)), 1.0, mode=mode)
    spread = ndi.maximum_filter(log_d, 3, mode=mode) - ndi.minimum_filter(log_d, 3, mode=mode)
    smooth = finite & (spread < np.log1p(step))
    out = which.copy()
    for i, (axis, offset, _) in enumerate(planes):
        t = plane_distance(dirs, axis, offset)  # [H, W] m
        off = np.abs(np.log(np.where(t > 0, t, 1.0) / np.where(finite, depth, 1.0)))
        facing = np.abs(n @ axis) > np.cos(np.radians(NORMAL_DEG))
        joins = (out < 0) & smooth & (t > 0) & (off < np.log1p(tol)) & facing
        labels, _ = ndi.label((out == i) | joins, structure=np.ones((3, 3)))
        mine = np.unique(labels[out == i])
        out[np.isin(labels, mine[mine > 0]) & (out < 0)] = i
    return out


def _weighted_median(x: np.ndarray, w: np.ndarray) -> float:
    """The value of x [M] below which half of the weight w [M] lies."""
    order = np.argsort(x)
    c = np.cumsum(w[order])
    return float(x[order][np.searchsorted(c, 0.5 * c[-1])])
