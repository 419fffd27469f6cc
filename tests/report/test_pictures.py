"""Pictures of the run report: colour maps, mosaics, curves, JSON numbers (no store, no browser)."""
import math

import numpy as np

from holoflow.report import figures, pictures


def test_colour_map_ends_and_no_data():
    v = np.array([[0.0, 1.0, np.nan, np.inf]], np.float32)
    out = pictures.colour_map(v, 0.0, 1.0)
    assert out.shape == (1, 4, 3) and out.dtype == np.uint8
    assert out[0, 0, 2] > out[0, 0, 0] and out[0, 1, 0] > out[0, 1, 2]     # low blue, high red
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
    assert (m[10 + 2:10 + 6, 10:18] == 160).all() and (m[10:12, 10:18] == 255).all()


def test_encode_roundtrip_png():
    import cv2

    img = (np.arange(2 * 3 * 3).reshape(2, 3, 3) * 10).astype(np.uint8)
    back = cv2.imdecode(np.frombuffer(pictures.encode(img), np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
    assert (back == img).all()
    assert pictures.image_uri(img).startswith("data:image/png;base64,iVBOR")          # 6 colours: flat
    noise = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    assert pictures.image_uri(noise).startswith("data:image/jpeg;base64,/9j/")


def test_curves_png_is_a_png():
    data = pictures.curves_png([{"label": "loss", "y": [1.0, 0.5, 0.25]}], "t", "loss", log_y=True,
                               bounds=[(0, "pcd"), (2, "pano")])
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000


def test_scalars_flatten_numbers_only():
    doc = {"a": 1, "b": {"c": 2.5, "d": [1, 2], "e": {"f": True}}, "g": math.nan, "h": "x" * 100, "i": "ok",
           "per_face": {f"{i:02d}": 0.1 for i in range(figures.MAX_KEYS + 1)}}
    assert figures.scalars(doc) == {"a": 1, "b.c": 2.5, "b.e.f": True, "i": "ok"}


def test_train_log_curves_concatenate_phases(tmp_path):
    import json

    log = {"phases": [{"name": "pcd", "train": {"loss": [3, 2], "count": [10, 12]}},
                      {"name": "pano", "train": {"loss": [1.5], "count": [12]}}]}
    (tmp_path / "train_log.json").write_text(json.dumps(log))
    figs = figures.train_log_figures(tmp_path / "train_log.json", "train_log.json")
    assert [f.title for f in figs] == ["train_log.json: loss", "train_log.json: Gaussians"]
    assert "3 iterations over 2 phase(s): pcd (2), pano (1)" in figs[0].caption
    assert figs[1].caption.startswith("10 -> 12 Gaussians")


def test_moving_mean_matches_a_loop():
    y = [3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0]
    ref = [sum(y[i:i + 3]) / 3 for i in range(len(y) - 2)]
    assert np.allclose(figures.moving_mean(y, 3), ref)
