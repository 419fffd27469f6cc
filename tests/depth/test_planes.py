"""Planar refinement (holoflow/depth/planes.py): a box room turned off the panorama's axes, its depth
bent by a smooth bias like a network's, is straightened back onto its walls; exact depth is left as it
is; an open scene without walls is untouched; ``auto`` is on only for a network's depth."""

import math

import numpy as np
import pytest
import torch

from holoflow.depth.planes import (
    curved,
    find_planes,
    grow_planes,
    plane_distance,
    refine_with_planes,
    room_axes,
    spread_log_ratio,
    wanted,
)
from holoflow.geometry.sphere import equirect_directions
from holoflow.geometry.surfaces import surface_normals

YAW = math.radians(20.0)
LO = np.array([-1.7, -1.2, -2.2])  # the room's walls along its own axes (m): x, y (ceiling, +y down), z
HI = np.array([2.3, 1.6, 3.1])  # floor at y = 1.6


def turned_room(H: int = 128, W: int = 256) -> np.ndarray:
    """Radial depth [H, W] of a box room (walls LO / HI in its frame) turned by YAW about the vertical."""
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()  # [H, W, 3]
    c, s = math.cos(YAW), math.sin(YAW)
    R = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])  # world -> room frame
    d = dirs @ R.T  # [H, W, 3]
    with np.errstate(divide="ignore"):
        t = np.where(d > 0, HI / d, np.where(d < 0, LO / d, np.inf))
    return t.min(-1)


def bias_field(H: int, W: int) -> np.ndarray:
    """A smooth multiplicative bias [H, W] (a few per cent, one to two cycles around), like a network's."""
    lon = (np.arange(W) + 0.5) / W * 2 * np.pi - np.pi
    lat = np.pi / 2 - (np.arange(H) + 0.5) / H * np.pi
    lon, lat = np.meshgrid(lon, lat)
    return np.exp(0.05 * np.sin(lon + 0.4) * np.cos(lat) + 0.03 * np.cos(2 * lon - 1.0) + 0.03 * np.sin(lat))


def abs_rel(d: np.ndarray, truth: np.ndarray) -> float:
    return float(np.mean(np.abs(d - truth) / truth))


def test_room_axes_find_the_turn_modulo_90_degrees():
    depth = torch.from_numpy(turned_room())
    n = surface_normals(depth).numpy()
    axes = room_axes(n, np.ones(depth.shape))
    yaw = math.atan2(axes[1][0], axes[1][2])
    assert math.isclose(math.remainder(yaw - YAW, math.pi / 2), 0.0, abs_tol=math.radians(1.0))
    assert np.allclose(axes[0], [0.0, 1.0, 0.0])


def test_a_bent_room_is_straightened_onto_its_walls():
    truth = turned_room()
    bent = truth * bias_field(*truth.shape) * np.exp(np.random.default_rng(0).normal(0, 0.01, truth.shape))
    before = abs_rel(bent, truth)
    out, facts = refine_with_planes(bent)
    after = abs_rel(out, truth)
    assert before > 0.03
    assert after < 0.55 * before, (before, after)
    # the floor's fit sets the scale (its own bias, 2 % here, is left); the other planes follow from where
    # they meet it, not from their own bent depth
    offsets = np.array(sorted(p["offset"] for p in facts["planes"]))
    want = np.sort(np.concatenate([LO, HI]))
    assert len(offsets) == 6 and np.allclose(offsets, want, rtol=0.025), offsets
    fitted = np.array(sorted(p["fitted"] for p in facts["planes"]))
    assert np.abs(offsets / want - 1).std() < 0.5 * np.abs(fitted / want - 1).std()
    assert facts["on_planes"] > 0.8


def test_a_given_yaw_turns_the_axes_whatever_the_normals_say():
    """The heading of the walls found elsewhere (the panorama's straight lines) sets the axes: a bias
    that tilts the normals does not tilt the planes, and the bent room is straightened as well."""
    truth = turned_room()
    n = surface_normals(torch.from_numpy(truth)).numpy()
    axes = room_axes(n, np.ones(truth.shape), yaw=YAW + math.radians(3.0))
    assert np.allclose(axes[1], [math.sin(YAW + math.radians(3.0)), 0.0, math.cos(YAW + math.radians(3.0))])
    assert np.allclose(axes[2] @ axes[1], 0.0) and np.allclose(axes[0], [0.0, 1.0, 0.0])
    bent = truth * bias_field(*truth.shape) * np.exp(np.random.default_rng(0).normal(0, 0.01, truth.shape))
    out, facts = refine_with_planes(bent, yaw=YAW)
    assert math.isclose(facts["yaw_deg"], math.degrees(YAW), abs_tol=1e-3)
    assert abs_rel(out, truth) < 0.55 * abs_rel(bent, truth)
    assert len(facts["planes"]) == 6


def with_cupboard(depth: np.ndarray, lo=(1.5, 0.1, -0.9), hi=(2.3, 1.6, 0.5)) -> np.ndarray:
    """``depth`` [H, W] with a cupboard in it: the box lo..hi (metres, the room's frame) against the wall
    x = HI[0], standing on the floor."""
    H, W = depth.shape
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()
    c, s = math.cos(YAW), math.sin(YAW)
    d = dirs @ np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]).T  # [H, W, 3] in the room's frame
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = np.array(lo) / d, np.array(hi) / d  # slabs
    near = np.nanmax(np.minimum(t0, t1), -1)
    far = np.nanmin(np.maximum(t0, t1), -1)
    return np.where((near <= far) & (near > 0), np.minimum(near, depth), depth)


def test_a_cupboards_front_does_not_bound_the_room():
    """Nothing lies beyond a wall, the floor or the ceiling; beyond a cupboard's front the room goes on,
    so its edges are not read as the room's corners."""
    out, facts = refine_with_planes(with_cupboard(turned_room()))
    bounds = {round(p["offset"], 2): p["bounds_room"] for p in facts["planes"]}
    assert bounds.pop(1.5) is False
    assert sorted(bounds) == sorted(np.round(np.concatenate([LO, HI]), 2)) and all(bounds.values())


def test_a_cupboard_keeps_its_own_fit_and_the_walls_their_seams():
    """Under a network's bias the walls take their offsets from the seams they share with the floor and
    each other; the cupboard's front, no side of the room, keeps the offset fitted to its own pixels."""
    truth = with_cupboard(turned_room())
    bent = truth * bias_field(*truth.shape)
    _, facts = refine_with_planes(bent)
    cupboard = [p for p in facts["planes"] if not p["bounds_room"]]
    walls = [p for p in facts["planes"] if p["bounds_room"] and p["axis"][1] == 0.0]
    assert len(cupboard) == 1 and cupboard[0]["contacts"] == 0 and cupboard[0]["offset"] == cupboard[0]["fitted"]
    assert len(walls) == 4 and all(p["contacts"] > 0 for p in walls)


def wall_and_patch(scale: float, soft: bool) -> tuple:
    """The turned room's wall x = HI[0] as plane 0 and its depth [H, W] scaled by ``scale`` about the
    wall's centre: smoothly (a Gaussian 0.3 rad wide: a network's regional bias) or, within 0.25 rad, as
    a step (a box's front before the wall). Returns (dirs, depth, normals, planes, which: the pixels
    within 5 % of the plane, patch [H, W] bool: where the depth is over 5 % off the plane)."""
    depth = turned_room()
    dirs = equirect_directions(*depth.shape, dtype=torch.float64).numpy()
    axis = np.array([math.cos(YAW), 0.0, -math.sin(YAW)])  # the room's x axis in the world
    angle = np.arccos(np.clip(dirs @ axis, -1.0, 1.0))  # [H, W] rad from the wall's centre
    depth = depth * (1 + (scale - 1) * np.exp(-((angle / 0.3) ** 2)) if soft else np.where(angle < 0.25, scale, 1.0))
    planes = [(axis, HI[0], 0.1)]
    t = plane_distance(dirs, axis, HI[0])
    which = np.where((t > 0) & (np.abs(t / depth - 1) < 0.05), 0, -1)
    patch = (t > 0) & (np.abs(t / depth - 1) > 0.05) & (angle < 0.5)
    return dirs, depth, surface_normals(torch.from_numpy(depth)).numpy(), planes, which, patch


def test_a_face_bent_past_the_snap_by_a_bias_grows_back_onto_its_plane():
    dirs, depth, normals, planes, which, patch = wall_and_patch(0.88, soft=True)
    assert patch.sum() > 100 and (which[patch] == -1).all()
    grown = grow_planes(dirs, depth, normals, planes, which)
    assert (grown[patch] == 0).all()
    assert (grown[which == 0] == 0).all()


def test_a_box_before_the_wall_is_not_grown_onto_it():
    """Its front faces the wall's way and lies within the growth's tolerance, but a depth step parts it."""
    dirs, depth, normals, planes, which, patch = wall_and_patch(0.85, soft=False)
    assert patch.sum() > 100
    grown = grow_planes(dirs, depth, normals, planes, which)
    assert (grown[patch] == -1).all()
    assert np.array_equal(grown >= 0, which >= 0)


def room_with_skirting(H: int, W: int, height: float = 0.12, thickness: float = 0.02) -> np.ndarray:
    """``turned_room`` with a skirting board along every wall: a slab ``height`` m tall standing
    ``thickness`` m before the wall on the floor (its front and its top face are ray cast)."""
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()
    c, s = math.cos(YAW), math.sin(YAW)
    d = dirs @ np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]).T  # [H, W, 3] in the room's frame
    t = turned_room(H, W)
    top = HI[1] - height

    def inside(p, i, other, lo, hi, y0, y1):  # p [H, W, 3] within the slab's extent
        return (
            (p[..., i] >= lo)
            & (p[..., i] <= hi)
            & (p[..., 1] >= y0)
            & (p[..., 1] <= y1)
            & (p[..., other] > LO[other])
            & (p[..., other] < HI[other])
        )

    with np.errstate(divide="ignore", invalid="ignore"):
        for i, other in ((0, 2), (2, 0)):
            for wall in (LO[i], HI[i]):
                front = wall - np.sign(wall) * thickness
                lo, hi = min(front, wall), max(front, wall)
                for hit in (front / d[..., i], top / d[..., 1]):  # the front face, the top face
                    ok = (hit > 0) & inside(hit[..., None] * d, i, other, lo, hi, top, HI[1]) & (hit < t)
                    t = np.where(ok, hit, t)
    return t


def walls_of(facts: dict) -> np.ndarray:
    """The offsets of the walls that bound the room, sorted."""
    return np.sort([p["offset"] for p in facts["planes"] if p["bounds_room"] and p["axis"][1] == 0.0])


def test_a_skirting_board_does_not_pull_the_walls_in(monkeypatch):
    """The board's face lies within a wall plane's tolerance, 2 cm before it, right where the wall meets
    the floor: read there, every wall comes out a per cent nearer. Read 3 deg into each plane, the walls
    are where they are, and under a network's bias where they would be without the board."""
    import holoflow.depth.planes as planes

    want = np.sort([LO[0], LO[2], HI[0], HI[2]])
    exact = room_with_skirting(256, 512)
    assert (exact < turned_room(256, 512) - 1e-3).mean() > 0.005  # the boards are seen
    assert np.allclose(walls_of(refine_with_planes(exact)[1]), want, rtol=1e-3)
    bias = bias_field(256, 512)
    plain = walls_of(refine_with_planes(turned_room(256, 512) * bias)[1])
    assert np.allclose(walls_of(refine_with_planes(exact * bias)[1]), plain, rtol=1e-3)
    monkeypatch.setattr(planes, "CONTACT_INSET_DEG", 0.0)  # read at the crease: the bias the inset removes
    assert (walls_of(refine_with_planes(exact)[1]) / want - 1 < -0.005).all()


def test_exact_depth_stays_as_it_is():
    truth = turned_room()
    out, facts = refine_with_planes(truth)
    assert len(facts["planes"]) == 6
    assert abs_rel(out, truth) < 1e-3


def test_an_open_scene_without_planes_is_untouched():
    H, W = 64, 128
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()
    sphere = 5.0 + 0.5 * np.sin(3 * np.arctan2(dirs[..., 0], dirs[..., 2]))  # hills, flat only in patches
    sphere = np.where(dirs[..., 1] < -0.2, np.inf, sphere)  # and sky above
    out, facts = refine_with_planes(sphere)
    assert facts["planes"] == []
    assert np.array_equal(out, sphere)


@pytest.mark.parametrize(
    "mode,engine,on",
    [
        ("auto", "depth_anything", True),
        ("auto", "simulated", True),
        ("auto", "layout", False),
        ("auto", "given", False),
        ("on", "layout", True),
        ("off", "depth_anything", False),
    ],
)
def test_auto_straightens_only_a_networks_depth(mode, engine, on):
    assert wanted(mode, engine) is on


def test_a_round_wall_is_not_flattened():
    H, W = 128, 256
    dirs = equirect_directions(H, W, dtype=torch.float64).numpy()
    radius = 3.5  # a round room: floor and ceiling are planes, the wall a cylinder about the eye
    horizontal = np.linalg.norm(dirs[..., [0, 2]], axis=-1)
    with np.errstate(divide="ignore"):
        t = np.minimum(radius / horizontal, np.where(dirs[..., 1] > 0, 1.5 / dirs[..., 1], -1.2 / dirs[..., 1]))
    out, facts = refine_with_planes(t)
    assert sorted(round(p["offset"], 3) for p in facts["planes"]) == [-1.2, 1.5]
    assert abs_rel(out, t) < 1e-3


def grazing_plane(height: float, n: int = 400) -> tuple:
    """Points [n, 3], unit normals [n, 3] and weights [n] of a horizontal plane ``height`` below the eye
    (+y down; negative: above) as a network leaves it: its far, grazing half tilted 18 deg by pixel noise
    and pushed 4 % farther by a smooth bias, its near half facing the eye where it truly is."""
    rng = np.random.default_rng(0)
    phi = rng.uniform(0, 2 * np.pi, n)
    far = np.arange(n) >= n // 2
    r = np.where(far, rng.uniform(3.0, 8.0, n), rng.uniform(0.5, 2.0, n))  # horizontal distance, metres
    bias = np.where(far, 1.04, 1.0)
    pts = np.stack([r * np.cos(phi), np.full(n, height), r * np.sin(phi)], -1) * bias[:, None]
    tilt = np.radians(np.where(far, 18.0, 0.0))
    normals = np.stack([np.sin(tilt) * np.cos(phi), np.cos(tilt) * np.sign(height), np.sin(tilt) * np.sin(phi)], -1)
    return pts, normals, np.full(n, 0.2 / n)


@pytest.mark.parametrize("height,kept", [(1.6, True), (-1.2, False)])
def test_a_floor_bent_by_a_bias_is_still_the_floor(height, kept):
    """A network's floor leans and lies farther where it is seen grazing, which the curvature test
    reads as a dome; a floor is flat, so it stays a plane, and the ceiling the same bias bends (a vault
    looks just so) is dropped."""
    pts, normals, w = grazing_plane(height)
    axes = room_axes(normals, w, yaw=0.0)
    assert curved(pts @ axes[0], np.abs(normals @ axes[0]), w)  # the curvature test alone drops either
    planes = find_planes(pts, normals, w, axes, tol=0.1)
    assert (len(planes) == 1) is kept
    if kept:
        assert planes[0][0][1] == 1.0 and abs(planes[0][1] / height - 1) < 0.05


def test_a_wide_panorama_is_straightened_as_the_narrow_one():
    """A network's noise is as wide as the pixels it saw: on a panorama four times wider it spans 4 x 4
    px, which tilts normals fitted over a few pixels off the walls until the planes find no room. They
    are found on the depth shrunk to ``work_width``, so the wide panorama comes out as the narrow one."""
    H, W, k = 128, 256, 4
    noise = np.random.default_rng(0).normal(0.0, 0.04, (H, W))
    narrow_truth, truth = turned_room(H, W), turned_room(H * k, W * k)
    narrow = narrow_truth * bias_field(H, W) * np.exp(noise)
    wide = truth * bias_field(H * k, W * k) * np.exp(np.kron(noise, np.ones((k, k))))
    out_narrow, _ = refine_with_planes(narrow)
    out, facts = refine_with_planes(wide, work_width=W)
    assert facts["work_width"] == W and facts["on_planes"] > 0.8
    assert abs_rel(out, truth) < 0.5 * abs_rel(wide, truth)
    assert abs_rel(out, truth) < 1.25 * abs_rel(out_narrow, narrow_truth)
    _, full = refine_with_planes(wide, work_width=W * k)  # the planes sought at full width
    assert full["on_planes"] == 0.0 and "not a room" in full["note"]


def pillar_room(H: int = 128, W: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """``turned_room`` with a round pillar (0.55 m radius, floor to ceiling) 1.6 m ahead: radial depth
    [H, W] and the pillar's pixels [H, W]."""
    room = turned_room(H, W)
    d = equirect_directions(H, W, dtype=torch.float64).numpy()
    a = d[..., 0] ** 2 + d[..., 2] ** 2
    b, c = -2 * 1.6 * d[..., 2], 1.6**2 - 0.55**2
    disc = b**2 - 4 * a * c
    t = np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * np.maximum(a, 1e-12)), np.inf)
    t = np.where((t > 0) & (d[..., 1] * t > LO[1]) & (d[..., 1] * t < HI[1]), t, np.inf)
    return np.minimum(room, t), t < room


def test_an_object_with_no_plane_near_takes_the_planes_regional_correction():
    """A round pillar is no plane and spans more than the narrow spread reaches: without the wide spread
    its middle keeps the whole bias; with it, the planes' correction around it."""
    truth, pillar = pillar_room()
    bent = truth * bias_field(*truth.shape) * np.exp(np.random.default_rng(0).normal(0, 0.01, truth.shape))
    out, _ = refine_with_planes(bent)
    with pytest.MonkeyPatch.context() as mp:
        import holoflow.depth.planes as planes

        narrow = planes.spread_log_ratio
        mp.setattr(planes, "spread_log_ratio", lambda *a, **k: narrow(*a, **{**k, "wide": 1.0}))
        out_narrow, _ = refine_with_planes(bent)
    err = abs_rel(out[pillar], truth[pillar])
    assert err < 0.7 * abs_rel(out_narrow[pillar], truth[pillar]) and err < 0.6 * abs_rel(bent[pillar], truth[pillar])
    assert abs_rel(out, truth) <= abs_rel(out_narrow, truth)


def test_the_spread_falls_back_to_the_wide_one_except_where_local():
    """Known samples on the left: just past the narrow spread's reach the correction is the wide
    spread's, on ``local`` pixels none; near the samples both are the narrow spread's."""
    H, W = 64, 256
    known = np.zeros((H, W), bool)
    known[:, 20:60] = True
    log_ratio = np.full((H, W), 0.05)
    local = np.zeros((H, W), bool)
    local[:, 90:] = True
    out = spread_log_ratio(log_ratio, known, 4.0, local=local)
    narrow = spread_log_ratio(log_ratio, known, 4.0, wide=1.0)
    assert np.allclose(out[:, 30:50], 0.05) and np.allclose(narrow[:, 30:50], 0.05)
    assert np.all(out[:, 72] > 0.04) and np.all(narrow[:, 72] < 0.002)  # 13 px past the samples: 3 sigma
    assert np.all(out[:, 95] < 1e-6)  # local: the narrow spread's, faded to none
