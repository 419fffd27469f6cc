import numpy as np
import pytest

from holoflow.io.exr import ExrError, read_exr, read_radial_depth, read_rgb, write_exr, write_rgb
from holoflow.io.ply import PlyError, gaussian_fields, read_gaussians, read_points, write_gaussians, write_points


def test_exr_round_trip_bit_exact_with_nan_inf_and_attrs(tmp_path):
    rng = np.random.default_rng(0)
    z = rng.random((5, 7), dtype=np.float32) * 10
    z[0, 0], z[1, 1], z[2, 2], z[3, 3] = np.nan, np.inf, -np.inf, -0.0
    attrs = {
        "holoflow.stage": "base_pano",
        "holoflow.depth_kind": "radial",
        "n": 3,
        "f": 0.25,
        "grid": [8, 7],
        "flag": True,
    }
    write_exr(tmp_path / "a.exr", {"Z": z, "mask": (z > 5).astype(np.float32)}, attrs)
    channels, back = read_exr(tmp_path / "a.exr")
    assert channels["Z"].tobytes() == z.tobytes()
    assert back["holoflow.depth_kind"] == "radial" and back["grid"] == [8, 7] and back["n"] == 3
    assert back["f"] == 0.25 and back["flag"] == 1


def test_exr_bytes_deterministic(tmp_path):
    rgb = np.random.default_rng(1).random((4, 8, 3), dtype=np.float32)
    write_rgb(tmp_path / "a.exr", rgb, {"k": "v"}, Z=rgb[..., 0])
    write_rgb(tmp_path / "b.exr", rgb, {"k": "v"}, Z=rgb[..., 0])
    assert (tmp_path / "a.exr").read_bytes() == (tmp_path / "b.exr").read_bytes()  # zlib on the same bytes
    assert np.array_equal(read_rgb(tmp_path / "a.exr"), rgb)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1)])
def test_exr_tiny_images(tmp_path, shape):
    a = np.arange(np.prod(shape), dtype=np.float32).reshape(shape)
    write_exr(tmp_path / "t.exr", {"Y": a})
    assert np.array_equal(read_exr(tmp_path / "t.exr")[0]["Y"], a)


def test_exr_errors(tmp_path):
    (tmp_path / "x.exr").write_bytes(b"not an exr")
    with pytest.raises(ExrError, match="not an EXR"):
        read_exr(tmp_path / "x.exr")
    with pytest.raises(ExrError, match="no such file"):
        read_exr(tmp_path / "missing.exr")
    with pytest.raises(ExrError, match="share one"):
        write_exr(tmp_path / "y.exr", {"R": np.zeros((2, 2)), "G": np.zeros((2, 3))})
    with pytest.raises(ExrError, match="no R"):
        write_exr(tmp_path / "z.exr", {"Y": np.zeros((2, 2))})
        read_rgb(tmp_path / "z.exr")


def test_points_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    xyz = rng.normal(size=(100, 3)).astype(np.float32)
    rgb = rng.integers(0, 256, (100, 3), dtype=np.uint8)
    write_points(tmp_path / "p.ply", xyz, rgb)
    x2, c2 = read_points(tmp_path / "p.ply")
    assert x2.tobytes() == xyz.tobytes() and c2.tobytes() == rgb.tobytes()
    write_points(tmp_path / "e.ply", np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    assert read_points(tmp_path / "e.ply")[0].shape == (0, 3)
    with pytest.raises(PlyError):
        write_points(tmp_path / "bad.ply", xyz, rgb.astype(np.float32))


def test_gaussians_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    names = [k for k in gaussian_fields(9) if k not in ("nx", "ny", "nz")]
    fields = {k: rng.normal(size=50).astype(np.float32) for k in names}
    fields["opacity"][0] = np.inf
    write_gaussians(tmp_path / "g.ply", fields)
    back = read_gaussians(tmp_path / "g.ply")
    assert list(back) == gaussian_fields(9)
    for k in names:
        assert back[k].tobytes() == fields[k].tobytes()
    assert not back["nx"].any()
    with pytest.raises(PlyError, match="missing"):
        write_gaussians(tmp_path / "h.ply", {"x": fields["x"]})


def test_radial_depth_is_read_and_other_depth_kinds_are_refused(tmp_path):
    z = np.array([[1.5, np.inf], [2.0, 3.0]], np.float32)
    write_exr(tmp_path / "radial.exr", {"Z": z}, {"holoflow.depth_kind": "radial"})
    write_exr(tmp_path / "unset.exr", {"Z": z})
    write_exr(tmp_path / "disp.exr", {"Z": z}, {"holoflow.depth_kind": "disparity"})
    write_exr(tmp_path / "noz.exr", {"Y": z})
    assert read_radial_depth(tmp_path / "radial.exr").tobytes() == z.tobytes()
    assert read_radial_depth(tmp_path / "unset.exr").tobytes() == z.tobytes()  # unset reads as radial
    for name in ("disp.exr", "noz.exr"):
        with pytest.raises(ExrError, match="no radial depth in channel Z"):
            read_radial_depth(tmp_path / name)
