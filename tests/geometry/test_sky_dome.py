"""The sky dome (holoflow/geometry/clouds.py): where a panorama shows sky, P_f gets coarse points behind
everything in the directions that are not sky, coloured by the sky; none without sky."""

import math

import torch

from holoflow.geometry.clouds import clean_sky, fill_from, point_clouds, sky_dome
from holoflow.geometry.config import PointCloudParams
from holoflow.geometry.sphere import equirect_directions


def test_fill_keeps_what_is_known_and_fills_the_rest_from_it():
    g = torch.Generator().manual_seed(0)
    values = torch.rand(30, 61, 3, generator=g)
    known = torch.rand(30, 61, generator=g) > 0.9
    out = fill_from(values, known)
    assert torch.equal(out[known], values[known]) and torch.isfinite(out).all()
    lo, hi = values[known].amin(0), values[known].amax(0)
    assert ((out >= lo - 1e-6) & (out <= hi + 1e-6)).all()  # averages of what is known
    one = torch.zeros(8, 16, dtype=torch.bool)
    one[3, 15] = True  # one known pixel: everything takes it
    assert torch.allclose(fill_from(values[:8, :16], one), values[3, 15].expand(8, 16, 3))


def _room_with_window(H=64, W=128):
    """A 2 m sphere room with a window (sky, inf depth) 20 deg wide ahead: rgb [H, W, 3], depth [H, W]."""
    dirs = equirect_directions(H, W, dtype=torch.float64)
    window = dirs[..., 2] > 0.95
    depth = torch.where(
        window, torch.full((H, W), float("inf"), dtype=torch.float64), torch.full((H, W), 2.0, dtype=torch.float64)
    )
    rgb = torch.where(window[..., None], torch.tensor([0.5, 0.7, 0.9]), torch.tensor([0.3, 0.2, 0.1]))
    return rgb.float(), depth, window


def test_the_dome_is_behind_the_shell_where_the_panorama_is_not_sky_coloured_as_the_sky():
    rgb, _, window = _room_with_window()
    xyz, colour = sky_dome(clean_sky(rgb, window), window, 10.0, 64)
    assert len(xyz) > 0.9 * 64 * 32 * (1 - window.double().mean())
    assert torch.allclose(torch.linalg.vector_norm(xyz, dim=-1), torch.full((len(xyz),), 10.0, dtype=xyz.dtype))
    assert torch.allclose(colour, torch.tensor([0.5, 0.7, 0.9]).expand_as(colour), atol=1e-5)
    assert float((xyz[:, 2] / 10.0).max()) < 0.99  # nothing straight ahead: the window is sky


def test_point_clouds_add_a_dome_only_where_there_is_sky():
    rgb, depth, _ = _room_with_window()
    cfg = PointCloudParams(pf_width=128, layer_baseline=0.0, pf_polar_density=1.0)
    with_sky = point_clouds(rgb, depth, cfg)
    assert with_sky.pf["dome"]["points"] == with_sky.meta["points"]["pf_dome"] > 0
    closed = point_clouds(rgb, torch.full_like(depth, 2.0), cfg)
    assert "dome" not in closed.pf and "pf_dome" not in closed.meta["points"]
    off = point_clouds(
        rgb, depth, PointCloudParams(pf_width=128, layer_baseline=0.0, pf_polar_density=1.0, sky_dome=False)
    )
    assert "dome" not in off.pf


def test_with_a_dome_the_background_layer_leaves_the_sky_shell_to_it():
    rgb, depth, _ = _room_with_window()
    cfg = dict(pf_width=128, pf_polar_density=1.0, layer_baseline=1.0)  # a 2 m room: the layer reaches 14 deg
    bare = point_clouds(rgb, depth, PointCloudParams(**cfg, sky_dome=False)).meta["points"]
    domed = point_clouds(rgb, depth, PointCloudParams(**cfg)).meta["points"]
    assert bare["pf_layer"] > 0  # the sky continued under the wall around the window
    assert domed.get("pf_layer", 0) == 0 and domed["pf_dome"] > 0  # the dome covers those directions


def test_the_sky_behind_the_room_takes_the_sky_inside_the_window_not_its_rim():
    """A frame's colour mixed into the window's outer pixels (antialiasing, a network's blur) is no part
    of the sky the dome and the layer continue behind the wall: they take the colour inside."""
    rgb, _, window = _room_with_window()
    inner = window.clone()
    for axis in (0, 1):
        for shift in (-1, 1):
            inner &= torch.roll(window, shift, axis)
    rim = window & ~inner  # the window's outermost pixels: half frame, half sky
    assert rim.any() and inner.any()
    mixed = torch.where(rim[..., None], torch.tensor([0.4, 0.45, 0.5]), rgb)
    clean = clean_sky(mixed, window, rim_px=1)
    assert torch.allclose(clean, torch.tensor([0.5, 0.7, 0.9]).expand_as(clean))
    _, colour = sky_dome(clean, window, 10.0, 64)
    assert torch.allclose(colour, torch.tensor([0.5, 0.7, 0.9]).expand_as(colour), atol=1e-5)
    _, raw = sky_dome(fill_from(mixed, window), window, 10.0, 64)  # the rim taken as sky
    assert (raw - torch.tensor([0.5, 0.7, 0.9])).abs().amax() > 0.05
    assert torch.equal(clean_sky(rgb, torch.zeros_like(window)), rgb)  # no sky: nothing to clean


def test_p_f_s_own_sky_takes_the_sky_inside_the_window_not_its_rim():
    """P_f's points on the sky's shell are coloured like the sky inside the window: a rim of frame colour
    there would move with the shell, a ghost of the frame in the panes seen from off the centre."""
    from holoflow.imageops.color import srgb_to_linear_torch

    rgb, depth, window = _room_with_window()
    inner = window & torch.roll(window, 1, 1) & torch.roll(window, -1, 1)
    inner &= torch.roll(window, 1, 0) & torch.roll(window, -1, 0)
    rim = window & ~inner
    mixed = torch.where(rim[..., None], torch.tensor([0.4, 0.45, 0.5]), rgb)  # sRGB
    cfg = PointCloudParams(pf_width=128, pf_sampling="grid", layer_baseline=0.0, sky_dome=False)  # a point a pixel
    pf = point_clouds(srgb_to_linear_torch(mixed), depth, cfg).clouds["pf"]
    r = torch.linalg.vector_norm(pf.xyz, dim=-1)
    on_shell = r > 3.0  # the room is 2 m, the shell twice its depth
    assert on_shell.sum() >= inner.sum()
    sky_u8 = torch.tensor([0.5, 0.7, 0.9]) * 255
    assert float((pf.rgb[on_shell].float() - sky_u8).abs().max()) <= 1.0


def test_the_dome_stays_within_its_reach_of_the_sky():
    """Behind a wall far from every window the dome would only show through cracks: none there."""
    rgb, _, window = _room_with_window()  # the window: within 18 deg of straight ahead
    xyz, _ = sky_dome(clean_sky(rgb, window), window, 10.0, 64, reach=math.radians(30))
    cos = xyz[:, 2] / 10.0  # the cosine to straight ahead
    assert len(xyz) > 0 and float(cos.min()) > math.cos(math.radians(18 + 30 + 6))  # + a dome cell
    assert float(cos.max()) < 0.99
    everywhere, _ = sky_dome(clean_sky(rgb, window), window, 10.0, 64)
    assert len(everywhere) > 4 * len(xyz)
