"""cameras.json, nerfstudio transforms.json and COLMAP text round-trip and use the right conventions."""

import json

import torch

from holoflow.geometry.camera import camera_centers, intrinsics_from_fov, look_at, rotmat_to_quat
from holoflow.geometry.camera_files import (
    cameras_json,
    cameras_tensors,
    read_cameras,
    read_colmap,
    read_transforms,
    write_cameras,
    write_colmap,
    write_transforms,
)
from holoflow.geometry.rigs import base_rig, supplementary_rig


def _cams():
    base = base_rig(5, dtype=torch.float64)
    sup = supplementary_rig(base, torch.full((5,), 2.0, dtype=torch.float64), 0.1, 10.0)
    V = torch.cat([base, sup])
    K = intrinsics_from_fov(47.4, 64, 48, dtype=torch.float64)
    names = [f"{i:03d}" for i in range(5)] + [f"{i // 4:03d}_{i % 4}" for i in range(20)]
    return (
        cameras_json(
            K,
            V,
            64,
            48,
            names,
            [f"views/{x}.exr" for x in names],
            kinds=["base"] * 5 + ["supplementary"] * 20,
            bases=list(range(5)) + [i // 4 for i in range(20)],
        ),
        K,
        V,
    )


def test_cameras_json_round_trip(tmp_path):
    cams, K, V = _cams()
    write_cameras(tmp_path / "cameras.json", cams)
    back = read_cameras(tmp_path / "cameras.json")
    K2, V2 = cameras_tensors(back)
    assert torch.equal(K2, K) and torch.equal(V2, V)  # JSON keeps a float's shortest repr: exact round trip
    assert back["views"][7]["kind"] == "supplementary" and back["views"][7]["base"] == 0
    assert back["K"] == K.tolist()
    write_cameras(tmp_path / "again.json", back)  # the added K is not written
    assert (tmp_path / "again.json").read_text() == (tmp_path / "cameras.json").read_text()


def test_nerfstudio_convention_and_round_trip(tmp_path):
    cams, K, V = _cams()
    write_transforms(tmp_path / "transforms.json", cams)
    t = json.loads((tmp_path / "transforms.json").read_text())
    assert t["fl_x"] == cams["fx"] and t["w"] == 64 and t["h"] == 48 and t["cx"] == 32.0
    c2w = torch.tensor([f["transform_matrix"] for f in t["frames"]], dtype=torch.float64)
    # OpenGL camera: -z column is the viewing direction, +y column is image up, position is the centre
    torch.testing.assert_close(-c2w[:, :3, 2], V[:, 2, :3])
    torch.testing.assert_close(c2w[:, :3, 1], -V[:, 1, :3])
    torch.testing.assert_close(c2w[:, :3, 3], camera_centers(V))
    back = read_transforms(tmp_path / "transforms.json")
    _, V2 = cameras_tensors(back)
    torch.testing.assert_close(V2, V, atol=1e-12, rtol=0)
    assert [v["name"] for v in back["views"]] == [v["name"] for v in cams["views"]]
    # identity world-to-camera is diag(1, -1, -1, 1) in nerfstudio
    ident = cameras_json(K, torch.eye(4, dtype=torch.float64)[None], 64, 48, ["a"], ["a.exr"])
    write_transforms(tmp_path / "i.json", ident)
    m = json.loads((tmp_path / "i.json").read_text())["frames"][0]["transform_matrix"]
    assert m == [[1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def test_colmap_round_trip(tmp_path):
    cams, K, V = _cams()
    write_colmap(tmp_path / "sparse", cams)
    lines = (tmp_path / "sparse" / "images.txt").read_text().splitlines()
    first = [ln for ln in lines if ln and not ln.startswith("#")][0].split()
    q = torch.tensor([float(x) for x in first[1:5]], dtype=torch.float64)
    torch.testing.assert_close(q, rotmat_to_quat(V[0, :3, :3]))  # qvec is world-to-camera, wxyz
    assert first[8] == "1" and first[9] == "views/000.exr"
    assert "PINHOLE 64 48" in (tmp_path / "sparse" / "cameras.txt").read_text()
    back = read_colmap(tmp_path / "sparse")
    K2, V2 = cameras_tensors(back)
    torch.testing.assert_close(K2, K)
    torch.testing.assert_close(V2, V, atol=1e-12, rtol=0)
    assert len(back["views"]) == 25


def test_look_at_camera_through_exports(tmp_path):
    """A camera at (1, 2, 3) looking at the origin keeps its pose through both formats."""
    V = look_at(torch.tensor([1.0, 2, 3], dtype=torch.float64), torch.zeros(3, dtype=torch.float64))[None]
    cams = cameras_json(intrinsics_from_fov(60, 8, 8, dtype=torch.float64), V, 8, 8, ["v"], ["v.exr"])
    write_transforms(tmp_path / "t.json", cams)
    write_colmap(tmp_path / "c", cams)
    for back in (read_transforms(tmp_path / "t.json"), read_colmap(tmp_path / "c")):
        torch.testing.assert_close(
            camera_centers(cameras_tensors(back)[1])[0], torch.tensor([1.0, 2, 3], dtype=torch.float64)
        )
