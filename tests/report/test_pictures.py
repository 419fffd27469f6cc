"""Pictures of the run report: colour maps, mosaics, curves, JSON numbers (no store, no browser)."""

import math

import numpy as np

from holoflow.report import figures, pictures


def test_colour_map_ends_and_no_data():
    v = np.array([[0.0, 1.0, np.nan, np.inf]], np.float32)
    out = pictures.colour_map(v, 0.0, 1.0)
    assert out.shape == (1, 4, 3) and out.dtype == np.uint8
    assert out[0, 0, 2] > out[0, 0, 0] and out[0, 1, 0] > out[0, 1, 2]  # low blue, high red
    assert (out[0, 2] == pictures.NO_DATA).all() and (out[0, 3] == pictures.NO_DATA).all()


def test_depth_map_near_is_red_sky_is_grey():
    d = np.array([[1.0, 10.0, np.inf]], np.float32)
    out = pictures.depth_map(d)
    assert out[0, 0, 0] > out[0, 0, 2] and out[0, 1, 2] > out[0, 1, 0]
    assert (out[0, 2] == pictures.NO_DATA).all()


def test_mosaic_places_tiles_row_major():
    tiles = [np.full((4, 8, 3), i * 40, np.uint8) for i in range(5)]
    m = pictures.mosaic(tiles, cols=3, side=8, gap=2)
    assert m.shape == (2 * 10 - 2, 3 * 10 - 2, 3)
    # tile 4 sits in row 1, column 1, vertically centred (4 px tall in an 8 px cell)
    assert (m[10 + 2 : 10 + 6, 10:18] == 160).all() and (m[10:12, 10:18] == 255).all()


def test_encode_roundtrip_png():
    import cv2

    img = (np.arange(2 * 3 * 3).reshape(2, 3, 3) * 10).astype(np.uint8)
    back = cv2.imdecode(np.frombuffer(pictures.encode(img), np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
    assert (back == img).all()
    assert pictures.image_uri(img).startswith("data:image/png;base64,iVBOR")  # 6 colours: flat
    noise = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    assert pictures.image_uri(noise).startswith("data:image/jpeg;base64,/9j/")


def test_curves_png_is_a_png():
    data = pictures.curves_png(
        [{"label": "loss", "y": [1.0, 0.5, 0.25]}], "t", "loss", log_y=True, bounds=[(0, "pcd"), (2, "pano")]
    )
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000


def test_scalars_flatten_numbers_only():
    doc = {
        "a": 1,
        "b": {"c": 2.5, "d": [1, 2], "e": {"f": True}},
        "g": math.nan,
        "h": "x" * 100,
        "i": "ok",
        "per_face": {f"{i:02d}": 0.1 for i in range(figures.MAX_KEYS + 1)},
    }
    assert figures.scalars(doc) == {"a": 1, "b.c": 2.5, "b.e.f": True, "i": "ok"}


def test_train_log_curves_concatenate_phases(tmp_path):
    import json

    log = {
        "phases": [
            {"name": "pcd", "train": {"loss": [3, 2], "count": [10, 12]}},
            {"name": "pano", "train": {"loss": [1.5], "count": [12]}},
        ]
    }
    (tmp_path / "train_log.json").write_text(json.dumps(log))
    figs = figures.train_log_figures(tmp_path / "train_log.json", "train_log.json")
    assert [f.title for f in figs] == ["train_log.json: loss", "train_log.json: Gaussians"]
    assert "3 iterations over 2 phase(s): pcd (2), pano (1)" in figs[0].caption
    assert figs[1].caption.startswith("10 -> 12 Gaussians")


def test_moving_mean_matches_a_loop():
    y = [3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0]
    ref = [sum(y[i : i + 3]) / 3 for i in range(len(y) - 2)]
    assert np.allclose(figures.moving_mean(y, 3), ref)


def test_viewing_pictures_pick_the_worst_median_zenith_and_nadir():
    import torch

    from holoflow.report import viewing_section as viewing

    scores = {
        "base": {
            "per_camera_psnr": [20.0, 30.0, 25.0, 28.0, 22.0, 18.0],
            "polar": [True, False, False, False, False, True],
            "elevation_deg": [90.0, 40.0, 10.0, -10.0, -40.0, -90.0],
        },
        "spec": {"size": 32, "empty_alpha": 0.5},
        "source": "photo x.jpg",
        "novel": {"0.5": {"cameras": 2, "empty": 0.25, "offset_m": 0.5}},
    }
    assert viewing.pick_base(scores) == [(4, "lowest PSNR"), (3, "median PSNR"), (0, "zenith"), (5, "nadir")]
    g = torch.Generator().manual_seed(0)
    pics = {"source": torch.rand(6, 32, 32, 3, generator=g), "render": torch.rand(6, 32, 32, 3, generator=g)}
    img, cap = viewing.base_picture(scores, pics, side=16)
    assert img.shape == (4 * 16 + 3 * viewing.GAP, 2 * 16 + viewing.GAP, 3) and "camera 4 (lowest PSNR" in cap
    src = (pics["source"][3].numpy() * 255 + 0.5).astype(np.uint8)
    assert np.array_equal(
        img[16 + viewing.GAP : 32 + viewing.GAP, :16], src[8:24, 8:24]
    )  # row 2: camera 3, centre crop
    alpha = torch.ones(2, 32, 32)
    alpha[1, :8] = 0.0
    img, cap = viewing.novel_picture(scores, dict(novel=torch.full((2, 32, 32, 3), 0.5), novel_alpha=alpha), side=32)
    assert (img[:8, 32 + viewing.GAP : 64 + viewing.GAP] == viewing.EMPTY_RGB).all() and "25.00 %" in cap
    assert (img[8:, 32 + viewing.GAP : 64 + viewing.GAP] == 128).all()
