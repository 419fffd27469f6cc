"""Window bars kept in their window (holoflow/geometry/openings.py): bars the depth lost to the sky get
the frame's plane, also where the sky beside them mixes them in; the sky between them stays sky, a
cloud in a pane and an open sky stay untouched."""

import pytest
import torch

from holoflow.geometry.clouds import point_clouds
from holoflow.geometry.config import PointCloudParams
from holoflow.geometry.openings import keep_opening_bars
from holoflow.geometry.sphere import equirect_directions

H, W = 96, 192
WALL_Z = 2.0  # metres: a flat wall ahead, the plane z = 2


def _wall_with_window(bars: bool = True, cloud: bool = False):
    """A flat wall at z = 2 m ahead (elsewhere a 3 m sphere) with a window whose every pixel the depth
    calls sky (a network blurred the bars away); the colour still shows a cross of bars. Returns srgb
    [H, W, 3], depth [H, W], the bars' and the open panes' masks [H, W]."""
    dirs = equirect_directions(H, W, dtype=torch.float64)
    ahead = dirs[..., 2] > 0.3
    depth = torch.where(ahead, WALL_Z / dirs[..., 2].clamp_min(1e-6), torch.full((H, W), 3.0, dtype=torch.float64))
    v, u = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    window = (u >= 84) & (u < 108) & (v >= 34) & (v < 58)  # 3 % of the panorama
    depth[window] = float("inf")
    rgb = torch.full((H, W, 3), 0.3, dtype=torch.float64)
    sky = torch.stack([0.6 + 0.2 * v / H, 0.7 + 0.1 * v / H, 0.9 + 0 * v], -1).double()
    rgb[window] = sky[window]
    bar = window & ((u == 95) | (u == 96) | (v == 45) | (v == 46)) if bars else torch.zeros_like(window)
    rgb[bar] = 0.8
    if cloud:  # a white blob in the middle of a pane, touching no frame
        blob = ((u - 89) ** 2 + (v - 39) ** 2) <= 2
        rgb[blob] = torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64)
    panes = window & ~bar
    return rgb, depth, bar, panes


def _ring_of(mask: torch.Tensor) -> torch.Tensor:
    """mask grown by one pixel (4-neighbours), the rim a bar's mixed pixels live in."""
    grown = mask.clone()
    grown[1:] |= mask[:-1]
    grown[:-1] |= mask[1:]
    grown[:, 1:] |= mask[:, :-1]
    grown[:, :-1] |= mask[:, 1:]
    return grown


@pytest.mark.parametrize("mixed", [False, True])
def test_bars_lost_to_the_sky_get_the_frames_plane_and_the_panes_stay_sky(mixed):
    """mixed: the sky pixels beside a bar are half bar (an antialiased panorama), a third of the window."""
    rgb, depth, bar, panes = _wall_with_window()
    if mixed:
        rim = _ring_of(bar) & panes
        rgb[rim] = 0.5 * rgb[rim] + 0.5 * 0.8
    out, found = keep_opening_bars(rgb, depth)
    assert found["openings"] == 1 and found["bar_pixels"] >= int(bar.sum())
    dirs = equirect_directions(H, W, dtype=torch.float64)
    plane = WALL_Z / dirs[..., 2]
    assert torch.allclose(out[bar], plane[bar], rtol=1e-3)  # on the wall's plane, not on the shell
    far_from_bars = panes & ~_ring_of(_ring_of(bar))
    assert bool(torch.isinf(out[far_from_bars]).all())
    outside = torch.isfinite(depth)
    assert torch.equal(out[outside], depth[outside])  # nothing else moves


def test_a_frame_blurred_behind_its_window_goes_onto_the_plane_and_nothing_before_it_moves():
    rgb, depth, bar, panes = _wall_with_window()
    v, u = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    window = bar | panes
    edge = (u >= 83) & (u < 109) & (v >= 33) & (v < 59) & ~window  # the frame's pixels beside the sky
    blurred = edge & (u < 96)  # a network's blur pushed the left half halfway to the sky
    depth[blurred] *= 1.5
    before = edge & (u >= 96) & (v < 40)  # a part of the right half stands 0.3 m before the wall
    depth[before] -= 0.3
    out, found = keep_opening_bars(rgb, depth)
    dirs = equirect_directions(H, W, dtype=torch.float64)
    plane = WALL_Z / dirs[..., 2]
    assert found["frame_pixels"] == int(blurred.sum())
    assert torch.allclose(out[blurred], plane[blurred], rtol=0.02)  # back on the window's plane
    assert torch.equal(out[before], depth[before])  # in front of it: the room, left alone
    rest = torch.isfinite(depth) & ~blurred
    assert torch.equal(out[rest], depth[rest])


@pytest.mark.parametrize("heading", [0.0, 0.3])
def test_with_the_rooms_heading_a_wall_edge_before_the_frame_does_not_tilt_the_bars(heading):
    """The wall turned by ``heading`` (radians) about the vertical; a pillar 0.6 m before it covers the
    frame's left side (a chimney breast beside a bay window): the bars go onto the wall's plane when the
    room's heading is known (any of its four wall directions), the free plane through the frame leans
    towards the pillar."""
    import math

    rgb, _, bar, panes = _wall_with_window()
    dirs = equirect_directions(H, W, dtype=torch.float64)
    normal = torch.tensor([math.sin(heading), 0.0, math.cos(heading)], dtype=torch.float64)
    plane = WALL_Z / (dirs @ normal).clamp_min(1e-6)  # [H, W] radial metres to the turned wall
    depth = torch.where((dirs @ normal) > 0.3, plane, torch.full((H, W), 3.0, dtype=torch.float64))
    depth[bar | panes] = float("inf")
    v, u = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    pillar = (u >= 78) & (u < 84) & (v >= 20) & (v < 72)  # the frame's left side and beyond
    depth[pillar] = plane[pillar] - 0.6
    rgb[pillar] = 0.5
    for yaw in (heading, heading + math.pi / 2):
        out, found = keep_opening_bars(rgb, depth, yaw=yaw)
        assert found["bar_pixels"] >= int(bar.sum())
        assert torch.allclose(out[bar], plane[bar], rtol=0.01)
    free, _ = keep_opening_bars(rgb, depth)
    assert float(((free[bar] - plane[bar]).abs() / plane[bar]).max()) > 0.03


def test_a_window_in_a_wall_that_is_not_the_rooms_keeps_its_own_plane():
    """The wall turned 45 degrees from the room's heading (a canted bay): its frame's free plane wins."""
    import math

    rgb, _, bar, panes = _wall_with_window()
    dirs = equirect_directions(H, W, dtype=torch.float64)
    normal = torch.tensor([math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4)], dtype=torch.float64)
    plane = WALL_Z / (dirs @ normal).clamp_min(1e-6)
    depth = torch.where((dirs @ normal) > 0.3, plane, torch.full((H, W), 3.0, dtype=torch.float64))
    depth[bar | panes] = float("inf")
    out, found = keep_opening_bars(rgb, depth, yaw=0.0)
    assert found["bar_pixels"] >= int(bar.sum())
    assert torch.allclose(out[bar], plane[bar], rtol=0.01)


def test_a_window_without_bars_a_cloud_in_a_pane_and_an_open_sky_stay_as_they_are():
    rgb, depth, _, _ = _wall_with_window(bars=False, cloud=True)
    out, found = keep_opening_bars(rgb, depth)
    assert found == {"openings": 1, "bar_pixels": 0, "frame_pixels": 0} and torch.equal(out, depth)
    rgb, depth, _, _ = _wall_with_window()
    depth[:40] = float("inf")  # the sky reaches the zenith: outdoors, not an opening
    out, found = keep_opening_bars(rgb, depth)
    assert found["openings"] == 0 and torch.equal(out, depth)


def test_point_clouds_put_the_bars_on_the_wall_only_when_asked():
    rgb, depth, bar, _ = _wall_with_window()
    from holoflow.imageops.color import srgb_to_linear_torch

    linear = srgb_to_linear_torch(rgb.float())
    cfg = dict(p0_width=W, pf_width=W, ps_width=W, layer_baseline=0.0, pf_polar_density=1.0, pf_sampling="grid")
    on = point_clouds(linear, depth, PointCloudParams(**cfg))
    off = point_clouds(linear, depth, PointCloudParams(**cfg, opening_bars=False))
    assert on.meta["points"]["pf_opening_bar_pixels"] >= int(bar.sum())
    assert "pf_opening_bar_pixels" not in off.meta["points"]

    def near_wall(cloud):
        xyz = cloud.xyz
        inside = (xyz[:, 2] - WALL_Z).abs() < 0.02
        return int(inside.sum())

    assert near_wall(on.clouds["p0"]) - near_wall(off.clouds["p0"]) >= int(bar.sum())


# a window set back in its wall: the wall z = 2 m with a hole 0.3 < x < 1.0, -0.3 < y < 0.4 (+y down), the
# window's plane z = 2.4 m behind it, a cross of bars there; the recess's side x = 0.3 faces away from
# the centre (hidden by the wall's edge), the other three sides face it
RW, RH = 384, 192
HOLE = (0.3, 1.0, -0.3, 0.4)
WALL, PANE = 2.0, 2.4
WALL_GREY, REVEAL_GREY, BAR_GREY = 0.3, 0.55, 0.8


def _recessed_window(niche: tuple[float, float] | None = None, hole: tuple[float, ...] = HOLE):
    """Ray cast of the recessed window from the centre: srgb [RH, RW, 3], radial depth [RH, RW] (sky inf;
    elsewhere a 3 m sphere). niche (top, bottom y): the recess runs that far up and down, past the
    panes, with a panel in the window's plane above and below them; hole: the wall's hole (x0, x1, y0, y1)."""
    u = equirect_directions(RH, RW, dtype=torch.float64)  # [RH, RW, 3]
    x0, x1, y0, y1 = hole
    py0, py1 = y0, y1  # the panes
    if niche is not None:
        y0, y1 = niche
    depth = torch.full((RH, RW), 3.0, dtype=torch.float64)
    rgb = torch.full((RH, RW, 3), WALL_GREY, dtype=torch.float64)
    ahead = u[..., 2] > 0.2
    t_wall = WALL / u[..., 2].clamp_min(1e-6)
    p = u * t_wall[..., None]
    in_hole = ahead & (p[..., 0] > x0) & (p[..., 0] < x1) & (p[..., 1] > y0) & (p[..., 1] < y1)
    depth[ahead & ~in_hole] = t_wall[ahead & ~in_hole]
    t_pane = PANE / u[..., 2].clamp_min(1e-6)
    q = u * t_pane[..., None]
    back = in_hole & (q[..., 0] > x0) & (q[..., 0] < x1) & (q[..., 1] > y0) & (q[..., 1] < y1)
    through = back & (q[..., 1] > py0) & (q[..., 1] < py1)
    bar = through & (((q[..., 0] - 0.65).abs() < 0.02) | ((q[..., 1] - 0.05).abs() < 0.02))
    depth[through] = float("inf")
    depth[bar | (back & ~through)] = t_pane[bar | (back & ~through)]
    rgb[through] = torch.tensor([0.7, 0.8, 0.95], dtype=torch.float64)
    rgb[bar | (back & ~through)] = BAR_GREY
    side = in_hole & ~back  # the ray meets a side of the recess
    t_side = torch.full((RH, RW), float("inf"), dtype=torch.float64)
    for axis, value in ((0, x0), (0, x1), (1, y0), (1, y1)):
        t = value / torch.where(u[..., axis].abs() > 1e-9, u[..., axis], torch.full_like(t_side, 1e-9))
        z = u[..., 2] * t
        t_side = torch.where((t > 0) & (z >= WALL - 1e-9) & (z <= PANE + 1e-9), torch.minimum(t_side, t), t_side)
    depth[side] = t_side[side]
    rgb[side] = REVEAL_GREY
    return rgb, depth


def _assert_the_hidden_side_alone(xyz, depth, top: float, bottom: float, rows: int):
    """The reveal points xyz [R, 3] of ``_recessed_window``: only on its hidden side (x = HOLE's x0) and
    the window's plane behind that edge, between heights top and bottom, covering that side (``rows`` x 6
    samples of it each within two of P_f's steps of a point), and none in front of what the centre saw
    (depth [RH, RW])."""
    from holoflow.geometry.sampling import sample_equirect

    spacing = 2 * torch.pi / RW
    x0 = HOLE[0]
    tol = 2 * spacing * PANE  # two of P_f's steps at the window
    on_side = ((xyz[:, 0] - x0).abs() < tol) & (xyz[:, 2] > WALL - tol) & (xyz[:, 2] < PANE + tol)
    behind_edge = ((xyz[:, 2] - PANE).abs() < tol) & (xyz[:, 0] > x0 - tol) & (xyz[:, 0] < x0 + 0.25)
    assert bool((on_side | behind_edge).all())  # only on the hidden side and the window's plane behind it
    assert bool(((xyz[:, 1] > top - tol) & (xyz[:, 1] < bottom + tol)).all())
    # the hidden side is covered: every point of it has a reveal point within two steps
    ys, zs = torch.meshgrid(
        torch.linspace(top + 0.05, bottom - 0.05, rows), torch.linspace(WALL + 0.05, PANE - 0.05, 6), indexing="ij"
    )
    side = torch.stack([torch.full_like(ys, x0), ys, zs], -1).reshape(-1, 3).double()
    assert float(torch.cdist(side, xyz).min(1).values.max()) < tol
    # none of them is in front of what the centre saw
    r = torch.linalg.vector_norm(xyz, dim=-1)
    seen = sample_equirect(depth[None], xyz / r[:, None], "nearest")[:, 0]  # [R]
    assert bool((r >= seen * (1 - 1e-6)).all())


def test_the_recess_side_the_wall_hides_gets_points_and_nothing_else_does():
    from holoflow.geometry.openings import opening_reveals

    rgb, depth = _recessed_window()
    xyz, colour, found = opening_reveals(rgb, depth, 2 * torch.pi / RW)
    assert found["reveals"] == 1 and found["reveal_points"] == len(xyz) > 50
    _assert_the_hidden_side_alone(xyz, depth, HOLE[2], HOLE[3], rows=12)
    assert torch.allclose(colour, torch.full_like(colour, REVEAL_GREY), atol=0.02)  # the recess's own colour


def test_a_recess_taller_than_its_panes_has_its_hidden_side_whole():
    from holoflow.geometry.openings import opening_reveals

    top, bottom = -0.5, 0.6  # the recess runs 0.2 m past the panes either way, a panel above and below them
    rgb, depth = _recessed_window(niche=(top, bottom))
    xyz, _, found = opening_reveals(rgb, depth, 2 * torch.pi / RW)
    assert found["reveals"] == 1
    _assert_the_hidden_side_alone(xyz, depth, top, bottom, rows=16)  # the panel's stretches included


def test_the_hidden_frame_is_as_wide_at_the_top_of_a_tall_window_as_at_eye_level():
    """A window reaching 1.3 m above the eye: the ray past its hidden edge meets the window's plane well
    above the edge's foot there, but the strip of frame behind the edge runs square off the edge, so it
    reaches as far beside the edge at the window's top as at eye level (sideways along the plane from
    the hidden side x = x0; taking the ray's meeting point instead, the strip shrinks to nothing at the
    top)."""
    from holoflow.geometry.openings import opening_reveals

    hole = (0.3, 1.0, -1.3, 0.2)
    rgb, depth = _recessed_window(hole=hole)
    xyz, _, found = opening_reveals(rgb, depth, 2 * torch.pi / RW)
    assert found["reveals"] == 1
    step = 2 * torch.pi / RW * PANE  # P_f's spacing at the window
    plane = (xyz[:, 2] - PANE).abs() < 2 * step  # the window's plane behind the edge
    reach, y = xyz[plane, 0] - hole[0], xyz[plane, 1]

    def reach_at(height: float) -> float:
        return float(reach[(y - height).abs() < 0.1].max())

    eye = reach_at(0.0)
    assert eye > 0.5 * step
    for height in (-1.1, -0.8, -0.5):
        assert abs(reach_at(height) - eye) < 0.5 * step, (height, reach_at(height), eye)


def test_a_window_flush_with_its_wall_and_an_open_sky_get_no_reveals():
    from holoflow.geometry.openings import opening_reveals

    rgb, depth, _, _ = _wall_with_window()
    _, _, found = opening_reveals(rgb, depth, 2 * torch.pi / W)
    assert found == {"reveals": 0, "reveal_points": 0}
    rgb, depth = _recessed_window()
    depth[:95, 195:225] = float("inf")  # the window's sky reaches the zenith: outdoors, not an opening
    xyz, _, found = opening_reveals(rgb, depth, 2 * torch.pi / RW)
    assert found["reveals"] == 0 and len(xyz) == 0


def test_point_clouds_add_the_reveals_to_p_f_only_when_asked():
    from holoflow.imageops.color import srgb_to_linear_torch

    rgb, depth = _recessed_window()
    linear = srgb_to_linear_torch(rgb.float())
    cfg = dict(p0_width=RW, pf_width=RW, ps_width=RW // 2, pf_polar_density=1.0, pf_sampling="grid")
    on = point_clouds(linear, depth, PointCloudParams(**cfg))
    off = point_clouds(linear, depth, PointCloudParams(**cfg, opening_reveals=False))
    n = on.meta["points"]["pf_reveal"]
    assert n > 50 and on.pf["reveal"]["points"] == n and "reveal" not in off.pf
    assert len(on.clouds["pf"].xyz) == len(off.clouds["pf"].xyz) + n
    assert len(on.clouds["p0"].xyz) == len(off.clouds["p0"].xyz)  # P_f's alone
