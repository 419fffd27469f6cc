"""point_cloud, pano_set and pcd_set run as processes (the step protocol) on a small synthetic RGB-D pano."""

import contextlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from holoflow.geometry.camera_files import cameras_tensors, read_cameras, read_transforms
from holoflow.io.exr import read_exr, write_exr, write_rgb
from holoflow.io.ply import read_points

from .test_pointcloud import rgbd_pano  # the analytic room + ball scene

ROOT = Path(__file__).resolve().parents[2]


def run_stage(tmp: Path, stage: str, params: dict, inputs: dict) -> subprocess.CompletedProcess:
    out = tmp / f"{stage}_out"
    out.mkdir()
    job = {
        "stage": stage,
        "engine": "default",
        "params": params,
        "seed": 0,
        "prompt": "",
        "inputs": {k: str(v) for k, v in inputs.items()},
        "output_dir": str(out),
        "work_dir": str(tmp / f"{stage}_work"),
        "device": "cpu",
    }
    (tmp / f"{stage}.json").write_text(json.dumps(job))
    return subprocess.run(
        [sys.executable, str(ROOT / "stages" / f"{stage}.py"), str(tmp / f"{stage}.json")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )


@pytest.fixture(scope="module")
def rgbd_dir(tmp_path_factory):
    """pano.exr (linear RGB) and depth.exr (radial Z, the top 8 rows are sky = inf), 128 x 64."""
    d = tmp_path_factory.mktemp("rgbd")
    rgb, depth = rgbd_pano(64, 128, torch.float64, "cpu")
    depth[:8] = float("inf")
    write_rgb(d / "pano.exr", rgb.numpy().astype(np.float32), {"holoflow.stage": "detail"})
    write_exr(d / "depth.exr", {"Z": depth.numpy().astype(np.float32)}, {"holoflow.depth_kind": "radial"})
    return d


@pytest.fixture(scope="module")
def stage_outputs(rgbd_dir, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("stages")
    pc = run_stage(
        tmp,
        "point_cloud",
        {"p0_width": 128, "pf_width": 64, "ps_width": 64, "grad_threshold": 0.4, "sky_radius": 0.0},
        {"pano": rgbd_dir, "depth": rgbd_dir},
    )
    ps = run_stage(
        tmp, "pano_set", {"rig": "fibonacci", "cameras": 12, "size": 24, "fov_deg": 90.0}, {"pano": rgbd_dir}
    )
    pcd = None
    if pc.returncode == 0 and ps.returncode == 0:
        pcd = run_stage(
            tmp,
            "pcd_set",
            {"offset": 0.1, "angle_deg": 10.0, "splat_radius": 0},
            {"cloud": tmp / "point_cloud_out", "cameras": tmp / "pano_set_out"},
        )
    return tmp, pc, ps, pcd


def test_point_cloud_stage(stage_outputs):
    tmp, pc, _, _ = stage_outputs
    assert pc.returncode == 0, pc.stderr
    out = tmp / "point_cloud_out"
    xyz0, rgb0 = read_points(out / "p0.ply")
    assert xyz0.shape == (128 * 64, 3) and rgb0.dtype == np.uint8  # sky kept, on the shell
    r = np.linalg.norm(xyz0, axis=1).reshape(64, 128)
    shell = r[:8]
    assert np.allclose(shell, shell[0, 0], rtol=1e-5) and shell[0, 0] > r[8:].max()
    meta = [json.loads(ln[6:]) for ln in pc.stdout.splitlines() if ln.startswith("@meta ")][0]
    assert abs(meta["sky_fraction"] - 8 / 64) < 1e-6
    xyzf, _ = read_points(out / "pf.ply")
    layer = meta["points"]["pf_layer"]  # the background layer follows the filtered grid's points
    assert 0 < len(xyzf) - layer < 64 * 32 and layer > 0 and len(xyzf) == meta["points"]["pf"]
    xyzs, _ = read_points(out / "ps.ply")
    assert len(xyzs) == 64 * 32


def test_point_cloud_rejects_z_depth(rgbd_dir, tmp_path):
    ch, _ = read_exr(rgbd_dir / "depth.exr")
    write_exr(tmp_path / "depth.exr", ch, {"holoflow.depth_kind": "z"})
    res = run_stage(
        tmp_path,
        "point_cloud",
        {"p0_width": 32, "pf_width": 16, "ps_width": 16, "grad_threshold": 0.4, "sky_radius": 0.0},
        {"pano": rgbd_dir, "depth": tmp_path},
    )
    assert res.returncode != 0 and "radial" in res.stderr and "Traceback" not in res.stderr


def test_pano_set_stage(stage_outputs, rgbd_dir):
    tmp, _, ps, _ = stage_outputs
    assert ps.returncode == 0, ps.stderr
    out = tmp / "pano_set_out"
    cams = read_cameras(out / "cameras.json")
    assert len(cams["views"]) == 12 and cams["width"] == 24 and cams["cx"] == 12.0
    assert all((out / v["file"]).exists() for v in cams["views"])
    ch, attrs = read_exr(out / cams["views"][0]["file"])
    assert set(ch) == {"R", "G", "B"} and attrs["holoflow.colorspace"] == "linear"
    K, V = cameras_tensors(read_transforms(out / "transforms.json"))
    torch.testing.assert_close(V, cameras_tensors(cams)[1], atol=1e-6, rtol=0)
    meta = [json.loads(ln[6:]) for ln in ps.stdout.splitlines() if ln.startswith("@meta ")][0]
    assert meta["unseen_fraction"] == 0.0
    assert "warning" not in ps.stdout


def test_pcd_set_stage(stage_outputs):
    tmp, _, _, pcd = stage_outputs
    assert pcd is not None and pcd.returncode == 0, pcd and pcd.stderr
    out = tmp / "pcd_set_out"
    cams = read_cameras(out / "cameras.json")
    assert len(cams["views"]) == 48
    assert {v["kind"] for v in cams["views"]} == {"supplementary"}
    assert [v["base"] for v in cams["views"][:8]] == [0, 0, 0, 0, 1, 1, 1, 1]
    assert cams["views"][5]["name"] == "001_1"
    ch, _ = read_exr(out / cams["views"][0]["file"])
    assert set(ch) == {"R", "G", "B", "A", "seen"} and set(np.unique(ch["A"])) <= {0.0, 1.0}
    assert np.array_equal(ch["seen"], ch["A"])  # no edge filter: every landed point is in the image
    hits = np.mean([read_exr(out / v["file"])[0]["A"].mean() for v in cams["views"]])
    assert hits > 0.9  # automatic splat radii: only disocclusions stay empty
    meta = [json.loads(ln[6:]) for ln in pcd.stdout.splitlines() if ln.startswith("@meta ")][0]
    # supplementary cameras sit offset x median depth away from the centre
    _, V = cameras_tensors(cams)
    from holoflow.geometry.camera import camera_centers

    dist = torch.linalg.vector_norm(camera_centers(V), dim=-1).reshape(12, 4)
    med = torch.tensor(meta["median_depth"], dtype=torch.float64)
    torch.testing.assert_close(dist, 0.1 * med[:, None].expand(12, 4), atol=1e-3, rtol=1e-3)


def test_stage_reruns_are_byte_identical(stage_outputs, rgbd_dir, tmp_path):
    """point_cloud, pano_set and pcd_set run again on the same inputs write byte-identical files."""
    first, pc, ps, pcd = stage_outputs
    assert pc.returncode == ps.returncode == 0 and pcd is not None and pcd.returncode == 0
    runs = {
        "point_cloud": (
            {"p0_width": 128, "pf_width": 64, "ps_width": 64, "grad_threshold": 0.4, "sky_radius": 0.0},
            {"pano": rgbd_dir, "depth": rgbd_dir},
        ),
        "pano_set": ({"rig": "fibonacci", "cameras": 12, "size": 24, "fov_deg": 90.0}, {"pano": rgbd_dir}),
        "pcd_set": (
            {"offset": 0.1, "angle_deg": 10.0, "splat_radius": 0},
            {"cloud": first / "point_cloud_out", "cameras": first / "pano_set_out"},
        ),
    }
    for stage, (params, inputs) in runs.items():
        res = run_stage(tmp_path, stage, params, inputs)
        assert res.returncode == 0, res.stderr
        a, b = first / f"{stage}_out", tmp_path / f"{stage}_out"
        files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
        assert files and files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
        for f in files:
            # the same program on the same inputs, CPU and thread count: one code path
            assert (a / f).read_bytes() == (b / f).read_bytes(), f"{stage}: {f} differs on rerun"


def test_pcd_set_edge_points_leave_the_image_but_mark_pixels_seen(stage_outputs, tmp_path):
    """With edge_threshold > 0, P_s's edge points (the ball's silhouette, the horizon of the sky) leave
    the image and A, yet their pixels stay ``seen``: seen is exactly where the unfiltered P_s lands."""
    import math

    from holoflow.geometry.pointcloud import footprint_radius, project_points_zbuffer

    tmp, _, _, plain = stage_outputs
    assert plain is not None and plain.returncode == 0
    edged = run_stage(
        tmp_path,
        "pcd_set",
        {"offset": 0.1, "angle_deg": 10.0, "splat_radius": 0, "edge_threshold": 0.4},
        {"cloud": tmp / "point_cloud_out", "cameras": tmp / "pano_set_out"},
    )
    assert edged.returncode == 0, edged.stderr
    xyz = torch.from_numpy(read_points(tmp / "point_cloud_out" / "ps.ply")[0]).double()
    spacing = 2 * math.pi / math.sqrt(2 * len(xyz))
    cams = read_cameras(tmp_path / "pcd_set_out" / "cameras.json")
    K, V = cameras_tensors(cams)
    gained = 0
    for v, vm in zip(cams["views"], V):
        e, _ = read_exr(tmp_path / "pcd_set_out" / v["file"])
        with torch_threads(1):  # the step's thread count (cpus 1): the same code path as the step
            _, hit, _ = project_points_zbuffer(
                xyz, xyz[:, :1], K, vm, cams["height"], cams["width"], footprint_radius(xyz, vm, K, spacing)
            )
        assert np.array_equal(e["seen"], hit.float().numpy())
        assert (e["A"] <= e["seen"]).all()
        gained += int((e["seen"] > e["A"]).sum())
    assert gained > 0  # some pixels are seen only through edge points
    meta = [json.loads(ln[6:]) for ln in edged.stdout.splitlines() if ln.startswith("@meta ")][0]
    assert meta["edge_points_dropped"] > 0 and meta["unseen_fraction"] < meta["missing_fraction"]


def test_pcd_set_offsets_ignore_the_sky_shell(tmp_path):
    """Outdoors (upper hemisphere all sky, a few sky pixels left finite at 5 km), views looking up see
    mostly the far shell: their offset still follows the geometry's median depth, never the sky's."""
    rgb, depth = rgbd_pano(64, 128, torch.float64, "cpu")
    depth[:32] = float("inf")
    depth[30:32, :10] = 5000.0  # sky pixels a depth network left finite (0.5%), far beyond the shell
    src = tmp_path / "rgbd"
    src.mkdir()
    write_rgb(src / "pano.exr", rgb.numpy().astype(np.float32), {"holoflow.stage": "detail"})
    write_exr(src / "depth.exr", {"Z": depth.numpy().astype(np.float32)}, {"holoflow.depth_kind": "radial"})
    pc = run_stage(
        tmp_path,
        "point_cloud",
        {"p0_width": 64, "pf_width": 32, "ps_width": 64, "grad_threshold": 0.4, "sky_radius": 0.0},
        {"pano": src, "depth": src},
    )
    ps = run_stage(
        tmp_path, "pano_set", {"rig": "fibonacci", "cameras": 12, "size": 24, "fov_deg": 90.0}, {"pano": src}
    )
    assert pc.returncode == 0 and ps.returncode == 0, pc.stderr + ps.stderr
    pcd = run_stage(
        tmp_path,
        "pcd_set",
        {"offset": 0.1, "angle_deg": 10.0, "splat_radius": 0},
        {"cloud": tmp_path / "point_cloud_out", "cameras": tmp_path / "pano_set_out"},
    )
    assert pcd.returncode == 0, pcd.stderr
    shell = [json.loads(ln[6:]) for ln in pc.stdout.splitlines() if ln.startswith("@meta ")][0]["shell_radius"]
    med = [json.loads(ln[6:]) for ln in pcd.stdout.splitlines() if ln.startswith("@meta ")][0]["median_depth"]
    assert max(med) < 0.5 * shell and min(med) > 0


@contextlib.contextmanager
def torch_threads(n: int):
    """torch's intra-op thread count set to ``n`` for the block (a matmul's sums may split by thread)."""
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
