"""The image-driven layout engine and image import: hard cases stay finite or fail with one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from holoflow.depth.layout import (
    LayoutConfig,
    boundary_dp,
    classify_scene,
    estimate_layout_depth,
    lower_boundary,
    upper_boundary,
)
from holoflow.depth.vanishing import rotate_equirect, rotation_to_upright, segment_normals, vertical_direction

REAL = Path(__file__).resolve().parents[3] / "shared" / "data"


def _room(H=128, W=256, wall=3.0, h=1.6, ceiling=1.2, lines=4):
    """A linear RGB box-room panorama: grey floor, beige walls with dark vertical corner lines, white
    ceiling, a dark skirting line; and its radial depth (a cylinder room)."""
    lat = np.pi / 2 - np.pi * (np.arange(H) + 0.5) / H
    L = lat[:, None] * np.ones((1, W))
    lat_f, lat_c = -np.arctan(h / wall), np.arctan(ceiling / wall)
    img = np.zeros((H, W, 3), np.float32)
    img[:] = (0.45, 0.35, 0.22)  # walls
    img[L < lat_f] = (0.08, 0.08, 0.09)  # floor
    img[L > lat_c] = (0.8, 0.8, 0.8)  # ceiling
    for c0 in np.linspace(0, W, lines + 1)[:-1].astype(int):  # vertical corner / door-frame edges
        band = (L >= lat_f) & (L <= lat_c)
        band[:, :c0] = False
        band[:, c0 + 3 :] = False
        img[band] = 0.05
    rng = np.random.default_rng(0)
    img *= np.exp(rng.normal(0, 0.03, img.shape)).astype(np.float32)
    return img


def test_boundary_dp_recovers_a_step_and_wraps():
    K, W = 20, 64
    truth = np.where(np.arange(W) < 32, 5, 12)
    cost = np.ones((K, W))
    cost[truth, np.arange(W)] = 0.0
    k = boundary_dp(cost, smoothness=0.1, jump=3)
    assert (k == truth).all()


def test_lower_and_upper_boundaries_on_a_synthetic_region_map():
    H, W = 64, 32
    lat = np.pi / 2 - np.pi * (np.arange(H) + 0.5) / H
    p = np.zeros((H, W))
    p[45:] = 1
    p[:12] = 1
    e = np.zeros((H, W))
    cfg = LayoutConfig()
    assert (lower_boundary(p, e, lat, cfg) == 45).all()
    assert (upper_boundary(p, e, lat, cfg) == 12).all()


def test_layout_recovers_a_synthetic_room():
    img = _room()
    est = estimate_layout_depth(img, LayoutConfig(scene="indoor"))
    d = est.depth
    assert d.shape == img.shape[:2] and np.isfinite(d).all() and (d > 0).all()
    H = d.shape[0]
    horizon = d[H // 2 - 2 : H // 2 + 2]  # walls at the horizon: 3 m
    assert abs(np.median(horizon) - 3.0) < 0.6
    floor_row = int(H * 0.9)  # the floor plane from the camera height
    lat = np.pi / 2 - np.pi * (floor_row + 0.5) / H
    assert np.median(d[floor_row]) == pytest.approx(1.6 / np.sin(-lat), rel=0.02)


def test_turning_the_camera_turns_the_depth():
    """Yaw is a nuisance: a quarter turn of the panorama (the line-segment views sit every 45 degrees,
    the Manhattan yaw is taken modulo 90 and the column DPs wrap) gives the turned depth (to float
    rounding), and
    any other turn moves the depth by a few percent on average (docs/depth-layout.md, round 5)."""
    img = _room()
    img = img * np.exp(np.random.default_rng(1).normal(0, 0.2, img.shape[:2] + (1,))).astype(np.float32)
    cfg = LayoutConfig(scene="indoor")
    d0 = estimate_layout_depth(img, cfg).depth
    W = img.shape[1]
    for shift in (W // 4, W // 2, 1, 19):
        d = np.roll(estimate_layout_depth(np.roll(img, shift, axis=1), cfg).depth, -shift, axis=1)
        if shift % (W // 4) == 0:
            # the turned depth up to float rounding: the views are the same pixels, but sums over them
            # (and BLAS blocks) run in another order after the turn, so bit-equality is not guaranteed
            np.testing.assert_allclose(d, d0, rtol=1e-5, err_msg=str(shift))
        else:
            assert np.mean(np.abs(d / d0 - 1)) < 0.05, shift


@pytest.mark.parametrize("kind", ["black", "constant", "hdr"])
def test_layout_is_finite_on_degenerate_images(kind):
    H, W = 64, 128
    img = {
        "black": np.zeros((H, W, 3), np.float32),
        "constant": np.full((H, W, 3), 0.5, np.float32),
        "hdr": _room(H, W) * 40.0,
    }[kind]
    est = estimate_layout_depth(img)
    assert est.depth.shape == (H, W)
    assert not np.isnan(est.depth).any()
    assert (est.depth[np.isfinite(est.depth)] > 0).all()
    if kind == "hdr":  # exposure-normalised: the same answer as the image at its own exposure
        ref = estimate_layout_depth(_room(H, W))
        assert np.allclose(np.median(est.depth), np.median(ref.depth), rtol=0.05)


def test_all_sky_panorama_is_sky_or_finite():
    H, W = 64, 128
    img = np.zeros((H, W, 3), np.float32)
    img[:] = (0.25, 0.45, 0.9)  # bright blue everywhere
    est = estimate_layout_depth(img)
    assert est.facts["scene"] == "outdoor"
    assert not np.isnan(est.depth).any()
    assert np.isinf(est.depth[0]).all()  # the zenith row is sky
    assert (est.depth[np.isfinite(est.depth)] > 0).all()


def test_deep_blue_sky_over_bright_ground_is_outdoors():
    """A clear zenith is often darker than sunlit grass (the procedural meadow): saturated blue counts
    as sky whatever its lightness; a white ceiling over a bright floor stays indoors."""
    H, W = 64, 128
    img = np.zeros((H, W, 3), np.float32)
    img[: H // 2] = (0.05, 0.12, 0.45)  # deep blue sky, darker than the ground
    img[H // 2 :] = (0.20, 0.45, 0.08)  # sunlit grass
    assert classify_scene(_lab_of(img), _lat(H))[0] == "outdoor"
    img[: H // 2] = (0.8, 0.8, 0.8)  # white ceiling
    img[H // 2 :] = (0.9, 0.9, 0.85)  # bright floor
    assert classify_scene(_lab_of(img), _lat(H))[0] == "indoor"


def test_hazy_sky_bluer_than_the_ground_is_outdoors():
    """An overcast / hazy zenith is only slightly blue (b* about -3) but bluer than the road it lights:
    outdoors; the same cool white over a floor of the same tint is a ceiling: indoors."""
    H, W = 64, 128
    img = np.zeros((H, W, 3), np.float32)
    img[: H // 2] = (0.52, 0.55, 0.59)  # hazy sky (b* -3.6), brighter than the ground
    img[H // 2 :] = (0.20, 0.19, 0.17)  # warm grey asphalt
    lab = _lab_of(img)
    assert -5 < np.median(lab[: H // 4, :, 2]) < -2  # only slightly bluish: the fixed b* < -5 test misses it
    assert classify_scene(lab, _lat(H))[0] == "outdoor"
    img[H // 2 :] = (0.22, 0.23, 0.245)  # a floor almost as cool as the ceiling (b* -2.5)
    assert classify_scene(_lab_of(img), _lat(H))[0] == "indoor"


def _lab_of(img):
    from holoflow.depth.layout import _lab
    from holoflow.imageops.color import linear_to_uint8

    return _lab(linear_to_uint8(np.clip(img, 0, 1)))


def _lat(H):
    return np.pi / 2 - np.pi * (np.arange(H) + 0.5) / H


def test_tilt_is_estimated_and_corrected():
    img = _room(256, 512, lines=24)
    a = np.radians(5.0)
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    tilted = rotate_equirect(img, R).astype(np.float32)
    from holoflow.imageops.color import linear_to_uint8

    v, facts = vertical_direction(*segment_normals(linear_to_uint8(np.clip(tilted, 0, 1))))
    assert v is not None and abs(facts["tilt_deg"] - 5.0) < 1.0
    Rup = rotation_to_upright(v)
    assert np.allclose(Rup @ v, [0, -1, 0], atol=1e-9)
    est = estimate_layout_depth(tilted, LayoutConfig(scene="indoor"))
    assert est.facts["upright"]["tilt_deg"] == pytest.approx(5.0, abs=1.0)
    assert np.isfinite(est.depth).all()


def test_layout_engine_plugs_into_the_depth_stages():
    from holoflow.depth import panorama as pd
    from holoflow.depth.config import MetricAlignParams, TangentDepthParams

    img = _room(64, 128)
    td = pd.estimate_disparity(img, None, "auto", TangentDepthParams(face_size=16, grid=(2, 2)))
    assert td.engine["engine"] == "layout" and "no truth" in td.engine["why"]
    md = pd.metric_from_disparity(td.disparity, img, None, "auto", MetricAlignParams(faces=6, face_size=16))
    assert md.engine["engine"] == "layout"
    assert np.isfinite(md.depth).all() and (md.depth > 0).all()
    assert 1.5 < np.median(md.depth[28:36]) < 5.0  # the horizon's walls (3 m) survive alignment


def test_camera_height_and_scene_are_checked():
    with pytest.raises(ValueError, match="camera_height"):
        estimate_layout_depth(_room(32, 64), LayoutConfig(camera_height=0.0))
    with pytest.raises(ValueError, match="scene"):
        estimate_layout_depth(_room(32, 64), LayoutConfig(scene="cave"))


# --- image import --------------------------------------------------------------------------------
def _write(path, arr, fmt):
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(arr.shape[1], arr.shape[0], arr.shape[2], fmt)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    out.write_image(arr)
    out.close()


def test_16bit_png_is_decoded_from_srgb(tmp_path):
    from holoflow.io.image import read_panorama_image

    arr = np.full((32, 64, 3), 32768, np.uint16)
    _write(tmp_path / "p.png", arr, "uint16")
    rgb, facts = read_panorama_image(tmp_path / "p.png")
    assert rgb.shape == (32, 64, 3) and "uint16" in facts["colour"]
    assert rgb.mean() == pytest.approx(((32768 / 65535 + 0.055) / 1.055) ** 2.4, rel=1e-3)  # sRGB -> linear


def test_hdr_values_above_one_are_kept(tmp_path):
    from holoflow.io.image import read_panorama_image

    arr = np.full((32, 64, 3), 7.5, np.float32)
    _write(tmp_path / "p.hdr", arr, "float")
    rgb, facts = read_panorama_image(tmp_path / "p.hdr")
    assert rgb.max() == pytest.approx(7.5, rel=0.02) and facts["colour"].startswith("linear")


def test_non_2to1_image_is_one_clear_line(tmp_path):
    from holoflow.io.image import ImageImportError, read_panorama_image

    _write(tmp_path / "sq.png", np.zeros((40, 50, 3), np.uint8), "uint8")
    with pytest.raises(ImageImportError) as e:
        read_panorama_image(tmp_path / "sq.png")
    assert "50x40" in str(e.value) and "2:1" in str(e.value) and "\n" not in str(e.value)


def test_gpano_crop_is_placed_into_the_full_canvas():
    from holoflow.io.image import place_cropped

    crop = np.ones((10, 40, 3), np.float32)
    full, facts = place_cropped(
        crop,
        {
            "FullPanoWidthPixels": 80,
            "FullPanoHeightPixels": 40,
            "CroppedAreaImageWidthPixels": 40,
            "CroppedAreaImageHeightPixels": 10,
            "CroppedAreaLeftPixels": 60,
            "CroppedAreaTopPixels": 15,
        },
    )
    assert full.shape == (40, 80, 3) and facts["cropped"]
    assert full[15:25, 60:80].all() and full[15:25, 0:20].all() and not full[:15].any()


def test_real_photo_imports_if_present():
    from holoflow.io.image import read_panorama_image

    photo = REAL / "photos" / "evl_room_B.jpg"
    if not photo.is_file():
        pytest.skip(f"{photo} absent (real data is optional)")
    rgb, facts = read_panorama_image(photo)
    assert rgb.shape == (1024, 2048, 3) and "uint8" in facts["colour"] and len(facts["sha256"]) == 64
