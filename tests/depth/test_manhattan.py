"""Manhattan layout pieces: the horizontal vanishing directions, the wall states, the wall DP, and a
synthetic rectangular room (rotated, off-centre) rendered from known geometry and recovered."""

from __future__ import annotations

import numpy as np
import pytest

from holoflow.depth.layout import LayoutConfig, estimate_layout_depth
from holoflow.depth.manhattan import (
    _dp_meeting_corners,
    manhattan_dp,
    manhattan_yaw,
    panorama_yaw,
    region_beyond,
    segment_evidence,
    wall_distances,
    walls_to_ceiling_lines,
)


def _box(H, W, yaw, walls, h=1.6, ceiling=1.1):
    """Radial depth [H, W] (metres) and surface id [H, W] (0 floor, 1 ceiling, 2 + o walls) of a box
    room: wall o has horizontal normal at azimuth yaw + o 90 deg, ``walls[o]`` metres from the eye."""
    lat = np.pi / 2 - np.pi * (np.arange(H) + 0.5) / H
    lon = 2 * np.pi * (np.arange(W) + 0.5) / W - np.pi
    La, Lo = np.meshgrid(lat, lon, indexing="ij")
    horiz = np.cos(La)
    t = np.full((H, W), np.inf)
    sid = np.zeros((H, W), int)
    for o, a in enumerate(walls):
        c = horiz * np.cos(Lo - (yaw + o * np.pi / 2))
        to = np.where(c > 1e-9, a / np.maximum(c, 1e-9), np.inf)
        sid = np.where(to < t, 2 + o, sid)
        t = np.minimum(t, to)
    s = np.sin(La)
    tf = np.where(s < 0, h / np.maximum(-s, 1e-9), np.inf)
    tc = np.where(s > 0, ceiling / np.maximum(s, 1e-9), np.inf)
    sid = np.where(tf < t, 0, np.where(tc < t, 1, sid))
    return np.minimum(t, np.minimum(tf, tc)), sid


def _segments_of_box(yaw, walls, h=1.6, ceiling=1.1):
    """End rays (p1, p2 [N, 3]) and normals of the floor and ceiling edges and the vertical corners of
    the box room (world: +y down), each edge cut into short pieces as a detector would see them."""
    dirs = [np.array([np.sin(yaw + o * np.pi / 2), 0.0, np.cos(yaw + o * np.pi / 2)]) for o in range(4)]
    P1, P2 = [], []
    for o in range(4):
        n, nxt = dirs[o], dirs[(o + 1) % 4]
        corner_a = walls[o] * n + walls[(o + 1) % 4] * nxt
        corner_b = walls[o] * n - walls[(o + 3) % 4] * nxt
        for y in (h, -ceiling):  # the floor edge (below) and the ceiling edge (above)
            for t0 in np.linspace(0, 1, 9)[:-1]:
                a = corner_b + (corner_a - corner_b) * t0 + np.array([0, y, 0])
                b = corner_b + (corner_a - corner_b) * (t0 + 1 / 8) + np.array([0, y, 0])
                P1.append(a), P2.append(b)
        P1.append(corner_a + np.array([0, h, 0])), P2.append(corner_a + np.array([0, -ceiling, 0]))
    p1, p2 = np.array(P1), np.array(P2)
    p1 /= np.linalg.norm(p1, axis=1, keepdims=True)
    p2 /= np.linalg.norm(p2, axis=1, keepdims=True)
    nrm = np.cross(p1, p2)
    return p1, p2, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def test_manhattan_yaw_from_synthetic_segments():
    for yaw in (0.0, np.radians(20.0), np.radians(63.0)):
        p1, p2, nrm = _segments_of_box(yaw, [2.0, 3.0, 2.5, 4.0])
        est, facts = manhattan_yaw(nrm, np.ones(len(nrm)))
        err = abs(np.angle(np.exp(4j * (est - yaw)))) / 4
        assert np.degrees(err) < 0.5, (np.degrees(yaw), facts)


def test_segment_evidence_lies_on_the_wall_boundaries():
    H, W, yaw, walls = 128, 256, np.radians(20.0), [2.0, 3.0, 2.5, 4.0]
    p1, p2, nrm = _segments_of_box(yaw, walls)
    below, above = segment_evidence(p1, p2, nrm, yaw, H, W)
    depth, sid = _box(H, W, yaw, walls)
    floor_edge = np.zeros((H, W), bool)
    floor_edge[1:] = (sid[1:] == 0) & (sid[:-1] >= 2)
    hit = below.sum(0) > 0
    near = np.zeros_like(floor_edge)
    for dr in (-2, -1, 0, 1, 2):
        near |= np.roll(floor_edge, dr, axis=0)
    assert hit.sum() > W / 2 and (hit & near).sum() / hit.sum() > 0.95
    assert above.sum() > 0 and (below[:, : H // 2].sum() == 0) and (above[:, H // 2 :].sum() == 0)


def test_wall_distances_and_dp_recover_a_piecewise_room():
    W, yaw = 256, np.radians(10.0)
    offsets = np.exp(np.linspace(np.log(0.5), np.log(20.0), 32))
    d, valid = wall_distances(yaw, offsets, W, 20.0)
    assert d.shape == (4 * 32, W) and valid.shape == d.shape
    phi = (np.arange(W) + 0.5) / W * 2 * np.pi - np.pi
    s = 1 * 32 + 10  # orientation 1, offset 10
    ok = valid[s]
    np.testing.assert_allclose(d[s, ok], np.minimum(offsets[10] / np.cos(phi[ok] - yaw - np.pi / 2), 20.0))
    truth = np.where((np.arange(W) > 40) & (np.arange(W) < 200), 7, 90)
    cost = np.random.default_rng(1).uniform(0, 1, (4 * 32, W))
    cost[truth, np.arange(W)] -= 3.0
    cost[:, 100:104] = 0.0  # a gap of no evidence is bridged by the corner penalty
    np.testing.assert_array_equal(manhattan_dp(cost, 5.0), truth)  # an integer path: exact on any CPU


def _path_cost(cost, path, corner):
    return float(cost[path, np.arange(cost.shape[1])].sum()) + corner * int(np.count_nonzero(path != np.roll(path, 1)))


def test_meeting_corners_dp_with_every_corner_whole_matches_the_constant_corner_dp():
    """The O(S^2) DP (``_dp_meeting_corners``) at meet = 1 finds a path as cheap as the O(S) one."""
    rng = np.random.default_rng(3)
    cost = rng.uniform(0, 1, (12, 80))
    cost[rng.integers(0, 12, 80), np.arange(80)] -= 2.0
    log_dist = rng.uniform(0, 1, (12, 80))
    fast = manhattan_dp(cost, 1.5)
    slow = _dp_meeting_corners(cost, 1.5, log_dist, 1.0, 0.2)
    np.testing.assert_allclose(_path_cost(cost, slow, 1.5), _path_cost(cost, fast, 1.5), rtol=1e-12)


@pytest.mark.parametrize("jump, expected", [(0.0, 1), (1.0, 0)])
def test_a_corner_where_two_walls_meet_costs_less_than_a_jump_behind(jump, expected):
    """Wall 1 is cheaper than wall 0 over half the columns by 1 per column (50 in all); two corners at
    40 each are not worth it, at 0.35 x 40 where the walls meet (equal distances) they are."""
    W = 100
    cost = np.zeros((2, W))
    cost[0, 50:] = 1.0
    cost[1, :50] = 1.0
    log_dist = np.stack([np.zeros(W), np.full(W, jump)])
    path = manhattan_dp(cost, 40.0, log_dist, meet=0.35, meet_tol=0.2)
    assert (path[60:90] == expected).all() and (path[10:40] == 0).all()
    assert (manhattan_dp(cost, 40.0) == 0).all()  # constant corners: no switch


_COLOURS = np.array(
    [
        (0.10, 0.09, 0.08),
        (0.85, 0.85, 0.85),
        (0.50, 0.40, 0.28),
        (0.42, 0.33, 0.24),
        (0.50, 0.40, 0.28),
        (0.42, 0.33, 0.24),
    ],
    np.float32,
)  # floor, ceiling, 4 walls


def _rendered_room(H, W, yaw, walls, h, ceiling):
    """Linear RGB [H, W, 3] of the box room (flat colours, dark edges, slight noise) and its depth."""
    depth, sid = _box(H, W, yaw, walls, h, ceiling)
    img = _COLOURS[sid]
    edge = np.zeros((H, W), bool)
    edge[1:] |= sid[1:] != sid[:-1]
    edge[:, 1:] |= sid[:, 1:] != sid[:, :-1]
    img[edge] = 0.03  # dark skirting, cornice and corner lines
    img *= np.exp(np.random.default_rng(0).normal(0, 0.02, img.shape)).astype(np.float32)
    return img, depth


def test_layout_recovers_a_rendered_manhattan_room():
    H, W, yaw, walls, h, ceiling = 256, 512, np.radians(25.0), [2.0, 3.2, 2.6, 4.0], 1.6, 1.1
    img, depth = _rendered_room(H, W, yaw, walls, h, ceiling)
    est = estimate_layout_depth(img, LayoutConfig(scene="indoor"))
    assert "manhattan" in est.facts and est.facts["manhattan"].get("yaw_deg") is not None
    assert abs(est.facts["manhattan"]["yaw_deg"] - 25.0) < 1.5
    rel = np.abs(est.depth - depth) / depth
    assert np.isfinite(est.depth).all()
    assert np.median(rel) < 0.05 and rel.mean() < 0.12, (np.median(rel), rel.mean(), est.facts)
    assert abs(est.facts["ceiling_above_eye_m"] - ceiling) / ceiling < 0.15


def test_region_beyond_keeps_the_lines_with_the_region_past_them():
    """A line keeps its whole weight where the region fills the rows past it on its side, ``keep``
    where none of it does: the floor below a wall's foot, the ceiling above its ceiling line."""
    H, W = 20, 3
    floor = (np.arange(H) >= 12)[:, None] * np.ones((1, W))  # rows 12.. are floor
    ev = np.ones((2, H, W))
    below = region_beyond(ev, floor, 1, 0.3)
    assert np.allclose(below[:, 12], 1.0) and np.allclose(below[:, 5], 0.3)  # the foot, a line on the wall
    ceiling = (np.arange(H) < 6)[:, None] * np.ones((1, W))  # rows ..5 are ceiling
    above = region_beyond(ev, ceiling, -1, 0.3)
    assert np.allclose(above[:, 6], 1.0) and np.allclose(above[:, 14], 0.3)
    assert np.allclose(region_beyond(ev, floor, 1, 1.0), ev)  # keep 1: off


def test_a_skirting_boards_top_edge_is_not_taken_for_the_walls_foot():
    """A white skirting board 0.15 m high whose top edge is the only line near the walls' foot (no line
    where it meets the floor, as on a wooden floor): a line with the skirting, not the floor, below it
    counts for half, so the walls stand at their foot; counted whole, the board's top edge puts them
    8 % too far, with the ceiling as much too high."""
    H, W, yaw, walls, h, ceiling = 256, 512, np.radians(25.0), [2.0, 3.2, 2.6, 4.0], 1.6, 1.1
    depth, sid = _box(H, W, yaw, walls, h, ceiling)
    below_eye = -depth * np.sin(np.pi / 2 - np.pi * (np.arange(H) + 0.5) / H)[:, None]  # metres
    sid = np.where((sid >= 2) & (below_eye > h - 0.15), 6, sid)  # 6: the skirting
    colours = np.concatenate([_COLOURS, [(0.9, 0.9, 0.88)]]).astype(np.float32)
    colours[1] = 0.55  # a grey ceiling over white trim
    img = colours[sid]
    edge = np.zeros((H, W), bool)
    edge[1:] = (sid[1:] != sid[:-1]) & ~((sid[1:] == 0) & (sid[:-1] == 6))
    edge[:, 1:] |= sid[:, 1:] != sid[:, :-1]
    img[edge] = 0.03
    img *= np.exp(np.random.default_rng(0).normal(0, 0.02, img.shape)).astype(np.float32)
    est = estimate_layout_depth(img, LayoutConfig(scene="indoor"))
    whole = estimate_layout_depth(img, LayoutConfig(scene="indoor", trim_line_weight=1.0))
    assert np.median(np.abs(est.depth - depth) / depth) < 0.02
    assert np.median(whole.depth / depth) > 1.05


def test_panorama_yaw_reads_the_walls_heading_from_the_image_alone():
    """The heading of a rendered room's walls from its straight lines (what metric_align's planes use
    instead of a network's tilted normals), modulo 90 degrees."""
    from holoflow.depth.layout import work_srgb8

    for deg in (25.0, 70.0):
        img, _ = _rendered_room(256, 512, np.radians(deg), [2.0, 3.2, 2.6, 4.0], 1.6, 1.1)
        yaw, facts = panorama_yaw(work_srgb8(img, 512))
        assert yaw is not None and facts["horizontal_segments"] >= 10
        assert abs(np.degrees(np.angle(np.exp(4j * (yaw - np.radians(deg))))) / 4) < 1.0, (deg, facts)


def test_capped_region_cost_bridges_a_block_of_contradicting_columns():
    """A third of the columns painted floor-coloured from 3 to 35 deg below the horizon (a low,
    floor-coloured sofa or bed flooding the floor boundary): with the capped data term the Manhattan
    walls of the rest of the room continue through the block; uncapped, the block pulls its walls out
    (every corner at the whole penalty, so that the cap alone is measured)."""
    H, W, yaw, walls, h, ceiling = 256, 512, np.radians(25.0), [2.0, 3.2, 2.6, 4.0], 1.6, 1.1
    img, depth = _rendered_room(H, W, yaw, walls, h, ceiling)
    lat = np.pi / 2 - np.pi * (np.arange(H) + 0.5) / H
    rows = (lat < -np.radians(3)) & (lat > -np.radians(35))
    img[np.ix_(rows, np.arange(300, 300 + int(0.35 * W)))] = _COLOURS[0]
    capped = estimate_layout_depth(img, LayoutConfig(scene="indoor", corner_meet=1.0))
    uncapped = estimate_layout_depth(img, LayoutConfig(scene="indoor", region_cap=0.0, corner_meet=1.0))
    assert (np.abs(capped.depth - depth) / depth).mean() < 0.03
    assert (np.abs(uncapped.depth - depth) / depth).mean() > 0.05


def _two_walls(K=5, W=100):
    """A path over W columns: wall (o 0, k 1) in columns 0-59, (o 0, k 4) in 60-99; no line seen."""
    path = np.where(np.arange(W) < 60, 1, 4)
    return path, np.zeros((4 * K, W)), K


def test_a_wall_without_its_ceiling_line_moves_to_the_nearer_one_that_has_it():
    """A sofa's top taken for its wall's foot puts the wall too far, and no segment shows that far wall's
    ceiling line while the near wall's shows over the whole run: the run moves to the near wall."""
    path, support, K = _two_walls()
    support[2, 60:] = 1.0  # the ceiling line of wall (0, 2), nearer than (0, 4)
    out, moved = walls_to_ceiling_lines(path, support, K, min_run=30)
    assert moved == 1
    assert (out[60:] == 2).all() and (out[:60] == 1).all()


def test_a_wall_keeps_its_offset_when_its_own_line_shows_or_the_run_is_narrow_or_the_line_is_farther():
    path, support, K = _two_walls()
    support[2, 60:] = 1.0
    assert walls_to_ceiling_lines(path, support, K, min_run=41)[1] == 0  # a doorway's width: left alone
    own = support.copy()
    own[4, 60:70] = 1.0  # its own line in a quarter of its columns
    assert walls_to_ceiling_lines(path, own, K, min_run=30)[1] == 0
    farther = np.zeros_like(support)
    farther[3, :60] = 1.0  # the first run's best line lies farther than its wall: not moved outwards
    out, moved = walls_to_ceiling_lines(path, farther, K, min_run=30)
    assert moved == 0 and (out == path).all()
    out, moved = walls_to_ceiling_lines(path, farther, K, min_run=30, outward=1)  # two offsets out: too far
    assert moved == 0 and (out == path).all()


def test_a_wall_behind_a_hearth_moves_out_to_its_ceiling_line_within_reach():
    """A hearth before a chimney breast draws the breast's foot line in front of it, and the breast's
    ceiling line shows one offset farther: with ``outward`` >= 1 the run moves out to it."""
    path, support, K = _two_walls()
    support[2, :60] = 1.0  # the ceiling line of wall (0, 2), one offset beyond the first run's (0, 1)
    out, moved = walls_to_ceiling_lines(path, support, K, min_run=30, outward=1)
    assert moved == 1
    assert (out[:60] == 2).all() and (out[60:] == 4).all()


def test_one_wall_all_round_is_one_run():
    K, W = 5, 64
    path, support = np.full(W, 3), np.zeros((4 * K, W))
    support[1] = 1.0
    out, moved = walls_to_ceiling_lines(path, support, K, min_run=10)
    assert moved == 1 and (out == 1).all()
