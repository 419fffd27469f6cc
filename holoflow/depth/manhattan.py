"""Manhattan-world room layout on the sphere: horizontal vanishing directions, boundary evidence from
line segments, and a Manhattan wall fit per column (a DP over walls, not over free distances).

Conventions (docs/conventions.md): world = OpenCV frame of the panorama centre, +y DOWN; a horizontal
direction at azimuth phi (radians) is (sin phi, 0, cos phi), the equirect longitude of that column.
The panorama is assumed upright (tilt already corrected, ``vanishing.py``).

- ``segment_rays``: LSD line segments on perspective views looking at the horizon and pitched up and
  down, as unit end rays [N, 3] on the sphere, great-circle normals and lengths.
- ``manhattan_yaw``: the Manhattan frame's yaw psi (radians, in [0, pi/2)): the horizontal 3D
  direction of every non-vertical segment, D = n x up, voted modulo 90 degrees.
- ``segment_evidence``: per wall family, the equirect rows crossed by segments that run along that
  family's horizontal direction, below the horizon (floor-wall candidates) and above it (ceiling-wall).
- ``wall_distances`` / ``manhattan_dp``: a wall with horizontal normal at azimuth alpha and offset a
  (metres) is seen at horizontal distance a / cos(phi - alpha) in column phi; the DP picks one wall
  (4 orientations x offsets) per column with a penalty per corner (less where the two walls meet than
  where one stands behind the other), so the layout is a Manhattan polygon (with occlusion jumps
  allowed) rather than a free per-column distance.
- ``walls_to_ceiling_lines``: a wall the fit put where its foot's line is, whose ceiling line no segment
  shows while another wall's of the same direction does, moves to that wall: a nearer one (furniture
  along a wall draws lines where its foot would be; nothing stands in front of the ceiling's edge) or
  one a few offsets farther (a hearth, a step or a rug's edge before it draws the foot's line).
"""

from __future__ import annotations

import numpy as np

UP = np.array([0.0, -1.0, 0.0])


def segment_rays(
    srgb8: np.ndarray,
    pitches_deg=(-40.0, 0.0, 40.0),
    views: int = 8,
    size: int = 256,
    fov_deg: float = 90.0,
    min_length: float = 10.0,
):
    """Line segments of an 8-bit sRGB panorama [H, W, 3] seen by ``views`` x len(``pitches_deg``)
    perspective views (degrees, + = looking up; ``segments.view_segments``). Returns (p1 [N, 3],
    p2 [N, 3]) unit end rays (world), normals [N, 3] (unit, p1 x p2) and lengths [N] (view pixels)."""
    from holoflow.depth.segments import great_circle_normals, view_segments

    yaws = np.tile(np.arange(views) * 2 * np.pi / views, len(pitches_deg))
    pitch = np.repeat(np.radians(np.asarray(pitches_deg, dtype=np.float64)), views)
    p1, p2, lengths = view_segments(srgb8, yaws, pitch, size, fov_deg, min_length)
    return p1, p2, great_circle_normals(p1, p2), lengths


def horizontal_directions(normals: np.ndarray, min_tilt_deg: float = 10.0):
    """Horizontal 3D direction azimuth (radians) [N] of each segment (D = n x up, a segment of a
    horizontal 3D line lies on a great circle whose normal is perpendicular to D), and a mask [N] of
    the segments that can be horizontal lines (great circle not vertical: |n . up| > sin(min_tilt))."""
    D = np.cross(normals, UP)  # [N, 3], horizontal
    az = np.arctan2(D[:, 0], D[:, 2])
    ok = np.abs(normals @ UP) > np.sin(np.radians(min_tilt_deg))
    return az, ok


def manhattan_yaw(normals: np.ndarray, lengths: np.ndarray) -> tuple[float | None, dict]:
    """Yaw psi in [0, pi/2) (radians) of the horizontal Manhattan directions (psi and psi + 90 deg):
    the length-weighted mode of the segments' horizontal azimuths modulo 90 degrees (1-degree
    histogram smoothed over +-3 degrees, refined by the circular mean of 4 x azimuth within +-6
    degrees); None with fewer than 10 candidate segments. Also facts (support = weight share)."""
    if len(normals) == 0:
        return None, {"horizontal_segments": 0}
    az, ok = horizontal_directions(normals)
    if ok.sum() < 10:
        return None, {"horizontal_segments": int(ok.sum())}
    a = np.mod(az[ok], np.pi / 2)
    w = lengths[ok]
    hist = np.bincount(np.minimum((a / (np.pi / 2) * 90).astype(int), 89), weights=w, minlength=90)
    k = np.exp(-0.5 * (np.arange(-6, 7) / 3.0) ** 2)
    sm = sum(kk * np.roll(hist, s) for s, kk in zip(range(-6, 7), k))
    psi0 = (np.argmax(sm) + 0.5) * np.pi / 180
    diff = np.angle(np.exp(4j * (a - psi0))) / 4  # [-pi/4, pi/4)
    near = np.abs(diff) < np.radians(6)
    psi = psi0 + float(np.angle(np.sum(w[near] * np.exp(4j * diff[near])))) / 4 if near.any() else psi0
    return float(np.mod(psi, np.pi / 2)), {
        "horizontal_segments": int(ok.sum()),
        "yaw_deg": round(float(np.degrees(np.mod(psi, np.pi / 2))), 2),
        "yaw_support": round(float(w[near].sum() / max(w.sum(), 1e-9)), 3),
    }


def panorama_yaw(srgb8: np.ndarray) -> tuple[float | None, dict]:
    """``manhattan_yaw`` of the straight lines of an 8-bit sRGB panorama [H, W, 3] (``segment_rays``):
    the heading (radians, atan2(x, z), modulo 90 deg) of the room's walls, None with fewer than 10
    horizontal lines, and its facts."""
    _, _, normals, lengths = segment_rays(srgb8)
    return manhattan_yaw(normals, lengths)


def region_beyond(evidence: np.ndarray, prob: np.ndarray, side: int, keep: float) -> np.ndarray:
    """Boundary evidence [..., H, W] weighted by the region that lies beyond each row: ``keep`` + (1 -
    ``keep``) x the mean of prob [H, W] (a region's colour probability) over the rows 2-4 past it on
    ``side`` (+1: below, where a wall's foot has the floor; -1: above, where its ceiling line has the
    ceiling); the row next to a line shares its blur. Rows past the image's edge repeat its last row."""
    H = prob.shape[0]
    rows = np.arange(H)
    beyond = sum(prob[np.clip(rows + side * k, 0, H - 1)] for k in (2, 3, 4)) / 3.0  # [H, W]
    return evidence * (keep + (1.0 - keep) * beyond)


def segment_evidence(
    p1: np.ndarray,
    p2: np.ndarray,
    normals: np.ndarray,
    yaw: float,
    H: int,
    W: int,
    tol_deg: float = 4.0,
    horizon_deg: float = 2.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Boundary evidence maps from Manhattan-horizontal segments: (below [2, H, W], above [2, H, W]),
    index f = 0 for segments along azimuth ``yaw``, 1 along yaw + 90 degrees. A pixel counts the arc
    samples of such segments that fall in it (capped at 1 per segment and pixel, map clipped to
    [0, 1]); ``below`` holds segments whose midpoint is more than ``horizon_deg`` under the horizon,
    ``above`` those more than ``horizon_deg`` over it."""
    below = np.zeros((2, H, W))
    above = np.zeros((2, H, W))
    if len(normals) == 0:
        return below, above
    az, ok = horizontal_directions(normals)
    rel = np.mod(az - yaw, np.pi / 2)
    rel = np.minimum(rel, np.pi / 2 - rel)  # angle to the nearest Manhattan direction
    fam = (np.abs(np.angle(np.exp(2j * (az - yaw)))) > np.pi / 2).astype(int)  # 0: along yaw, 1: along yaw + 90
    keep = ok & (rel < np.radians(tol_deg))
    mid = p1 + p2
    mid /= np.maximum(np.linalg.norm(mid, axis=1, keepdims=True), 1e-12)
    mid_lat = np.arcsin(np.clip(-mid[:, 1], -1, 1))
    step = np.pi / H / 2  # half a pixel of arc
    for i in np.nonzero(keep & (np.abs(mid_lat) > np.radians(horizon_deg)))[0]:
        ang = float(np.arccos(np.clip(p1[i] @ p2[i], -1, 1)))
        m = max(2, int(ang / step) + 1)
        t = np.linspace(0.0, 1.0, m)[:, None]
        p = p1[i] * (1 - t) + p2[i] * t  # chord samples, normalised: on the great circle between the ends
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        lon = np.arctan2(p[:, 0], p[:, 2])
        lat = np.arcsin(np.clip(-p[:, 1], -1, 1))
        col = np.mod(((lon + np.pi) / (2 * np.pi) * W).astype(int), W)
        row = np.clip(((np.pi / 2 - lat) / np.pi * H).astype(int), 0, H - 1)
        target = below if mid_lat[i] < 0 else above
        idx = np.unique(row * W + col)
        target[fam[i]].reshape(-1)[idx] += 1.0  # the reshape of a C-contiguous slice is a view
    return np.minimum(below, 1.0), np.minimum(above, 1.0)


def wall_distances(yaw: float, offsets: np.ndarray, W: int, dmax: float) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal distance [4 K, W] (metres, clipped to ``dmax``) of each wall state in each column
    and its validity [4 K, W]. State s = o K + k: a wall with horizontal normal at azimuth
    yaw + o 90 degrees, ``offsets[k]`` metres from the eye (offsets [K] ascending). A wall is valid in
    the columns that face it (cos(phi - alpha) > 0.02) and where it is nearer than 1.5 dmax."""
    phi = (np.arange(W) + 0.5) / W * 2 * np.pi - np.pi  # [W] column azimuths (longitude)
    alpha = yaw + np.arange(4) * np.pi / 2  # [4]
    cosd = np.cos(phi[None, :] - alpha[:, None])  # [4, W]
    d = offsets[None, :, None] / np.maximum(cosd[:, None, :], 1e-6)  # [4, K, W]
    valid = (cosd[:, None, :] > 0.02) & (d < 1.5 * dmax)
    K = len(offsets)
    return np.minimum(d, dmax).reshape(4 * K, W), valid.reshape(4 * K, W)


def manhattan_dp(
    cost: np.ndarray, corner: float, log_dist: np.ndarray | None = None, meet: float = 1.0, meet_tol: float = 0.2
) -> np.ndarray:
    """One state per column [W] minimising sum of ``cost`` [S, W] + the corners' costs; columns wrap
    (solved over the panorama extended by a quarter turn on both sides, the middle kept).

    A change of state between neighbouring columns costs ``corner``. With ``log_dist`` [S, W] (each
    state's log horizontal distance) and ``meet`` < 1, a change between two walls that meet there
    costs less: ``corner`` x (meet + (1 - meet) min(1, |log d - log d'| / meet_tol)), so a room's
    real corners (depth continuous) come cheaper than jumps from one wall to another behind it."""
    if log_dist is None or meet >= 1.0:
        return _dp_constant_corner(cost, corner)
    return _dp_meeting_corners(cost, corner, log_dist, meet, meet_tol)


def _wrap_pad(W: int) -> int:
    """Columns the wrapping DPs add on each side: a quarter turn (at least 1, at most W)."""
    return min(W, max(1, W // 4))


def _wrap(a: np.ndarray, pad: int) -> np.ndarray:
    """[S, W] -> [S, W + 2 pad]: the panorama's last ``pad`` columns before it, its first after it."""
    return np.concatenate([a[:, -pad:], a, a[:, :pad]], axis=1)


def _dp_meeting_corners(
    cost: np.ndarray, corner: float, log_dist: np.ndarray, meet: float, meet_tol: float
) -> np.ndarray:
    """``manhattan_dp`` with each corner's cost from the two walls' distances: O(S^2) per column."""
    S, W = cost.shape
    pad = _wrap_pad(W)
    ext, lde = _wrap(cost, pad), _wrap(log_dist, pad)  # [S, W + 2 pad]
    n = ext.shape[1]
    acc = ext[:, 0].copy()
    came = np.zeros((n, S), dtype=np.int64)  # each state's best predecessor
    states = np.arange(S)
    for c in range(1, n):
        gap = np.minimum(np.abs(lde[:, c, None] - lde[None, :, c]) / meet_tol, 1.0)  # [S prev, S]
        step = corner * (meet + (1.0 - meet) * gap)
        step[states, states] = 0.0
        total = acc[:, None] + step
        came[c] = np.argmin(total, axis=0)
        acc = total[came[c], states] + ext[:, c]
    path = np.empty(n, dtype=np.int64)
    path[-1] = int(np.argmin(acc))
    for c in range(n - 1, 0, -1):
        path[c - 1] = came[c, path[c]]
    return path[pad : pad + W]


def _dp_constant_corner(cost: np.ndarray, corner: float) -> np.ndarray:
    """``manhattan_dp`` with every corner at ``corner``: O(S) per column (the best predecessor or stay)."""
    S, W = cost.shape
    pad = _wrap_pad(W)
    ext = _wrap(cost, pad)  # [S, W + 2 pad]
    n = ext.shape[1]
    acc = ext[:, 0].copy()
    stay = np.zeros((n, S), dtype=bool)  # True: came from the same state; else from the best one
    best = np.zeros(n, dtype=np.int64)
    for c in range(1, n):
        b = int(np.argmin(acc))
        best[c] = b
        sw = acc[b] + corner
        stay[c] = acc <= sw
        acc = np.where(stay[c], acc, sw) + ext[:, c]
    path = np.empty(n, dtype=np.int64)
    path[-1] = int(np.argmin(acc))
    for c in range(n - 1, 0, -1):
        path[c - 1] = path[c] if stay[c, path[c]] else best[c]
    return path[pad : pad + W]


def walls_to_ceiling_lines(
    path: np.ndarray,
    support: np.ndarray,
    offsets: int,
    min_run: int,
    outward: int = 0,
    seen: float = 0.6,
    missing: float = 0.2,
) -> tuple[np.ndarray, int]:
    """The wall states [W] of ``manhattan_dp``'s ``path`` with every run of one state over at least
    ``min_run`` neighbouring columns (wrapping) moved to another wall of the same direction when the
    ceiling line of its own wall is seen in under ``missing`` of its columns and that of the wall with
    the best seen line in at least ``seen`` of them. The other wall is any nearer one or one at most
    ``outward`` offsets farther. ``support`` [S, W]: the ceiling-line evidence (0..1) of each state in
    each column; states s = o ``offsets`` + k, offsets ascending (the layout of ``wall_distances``).
    Returns (the new path [W], how many runs moved)."""
    W = len(path)
    path = path.copy()
    starts = np.nonzero(path != np.roll(path, 1))[0]
    if len(starts) == 0:
        starts = np.array([0])
    moved = 0
    for i, c0 in enumerate(starts):
        c1 = starts[(i + 1) % len(starts)]
        run = np.arange(c0, c1 if c1 > c0 else c1 + W) % W  # [n] its columns
        if len(run) < min_run:
            continue
        o, k = divmod(int(path[run[0]]), offsets)
        score = support[o * offsets : (o + 1) * offsets][:, run].mean(1)  # [K] share of columns with a line
        reach = score[: min(k + outward + 1, offsets)].copy()  # the walls it may move to
        reach[k] = -1.0
        best = int(np.argmax(reach))
        if score[best] >= seen and score[k] < missing:
            path[run] = o * offsets + best
            moved += 1
    return path, moved
