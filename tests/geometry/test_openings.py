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


def test_a_window_without_bars_a_cloud_in_a_pane_and_an_open_sky_stay_as_they_are():
    rgb, depth, _, _ = _wall_with_window(bars=False, cloud=True)
    out, found = keep_opening_bars(rgb, depth)
    assert found == {"openings": 1, "bar_pixels": 0} and torch.equal(out, depth)
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
