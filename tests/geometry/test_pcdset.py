"""The PCD set's method (holoflow/geometry/pcdset.py), without a process: edge split, sky-free
median depths, the supplementary rig and the ``seen`` pass."""

import math

import torch

from holoflow.geometry.camera import intrinsics_from_fov
from holoflow.geometry.config import PcdSetParams
from holoflow.geometry.pcdset import pcd_set, split_edge_points
from holoflow.geometry.pointcloud import equirect_to_points
from holoflow.geometry.rigs import base_rig


def _room(width=64, sky=True):
    """P_s of a cylinder wall (3 m) with a box (1.2 m) in front of the +z camera, floor 1.6 m below the
    eye; the upper half is sky on a 100 m shell when ``sky``. Returns (points [N, 3], colours [N, 3])."""
    h = width // 2
    v = (torch.arange(h, dtype=torch.float64) + 0.5) / h
    u = (torch.arange(width, dtype=torch.float64) + 0.5) / width
    lat = (math.pi / 2 - math.pi * v)[:, None].expand(h, width)
    lon = (2 * math.pi * u - math.pi)[None, :].expand(h, width)
    radial = 3.0 / torch.cos(lat).clamp_min(1e-3)  # the wall
    below = lat < 0
    radial = torch.where(below, torch.minimum(radial, 1.6 / torch.sin(-lat).clamp_min(1e-6)), radial)
    box = (lon.abs() < 0.4) & (lat.abs() < 0.3)
    radial = torch.where(box, torch.full_like(radial, 1.2), radial)
    if sky:
        radial = torch.where(lat > 0.2, torch.full_like(radial, 100.0), radial)
    colour = torch.stack([u[None, :].expand(h, width), v[:, None].expand(h, width), box.double()], -1)
    xyz, rgb = equirect_to_points(colour, radial)
    assert len(xyz) == width * h  # a full grid: the edge test needs one
    return xyz, rgb


def _cameras(count=6, size=24):
    return intrinsics_from_fov(60.0, size, size, dtype=torch.float64), base_rig(count, dtype=torch.float64)


def test_edge_split_leaves_out_depth_discontinuities_only():
    xyz, _ = _room(sky=False)
    keep = split_edge_points(xyz, 0.4)
    assert 0 < int((~keep).sum()) < 0.25 * len(xyz)  # the box's outline, and grazing floor
    assert bool(split_edge_points(xyz, 0.0).all())


def test_medians_follow_the_geometry_not_the_sky():
    xyz, rgb = _room(sky=True)
    K, V = _cameras()
    pcd = pcd_set(xyz, rgb, K, V, 24, 24, PcdSetParams())
    assert len(pcd.medians) == len(V) and max(pcd.medians) < 10.0  # never the 100 m shell
    assert pcd.viewmats.shape == (4 * len(V), 4, 4)


def test_views_hit_is_within_seen_and_edges_only_add_coverage():
    xyz, rgb = _room(sky=False)
    K, V = _cameras()
    with_edges = pcd_set(xyz, rgb, K, V, 24, 24, PcdSetParams(edge_threshold=0.4))
    without = pcd_set(xyz, rgb, K, V, 24, 24, PcdSetParams(edge_threshold=0.0))
    assert len(with_edges.edge_points) > 0 and len(without.edge_points) == 0
    more_seen = 0
    for j in range(len(with_edges.viewmats)):
        img, hit, seen = with_edges.view(j)
        assert img.shape == (24, 24, 3) and bool((hit <= seen).all())
        more_seen += int((seen > hit).sum())
        _, hit0, seen0 = without.view(j)
        assert torch.equal(hit0, seen0)
    assert more_seen > 0


def test_offset_scales_with_each_views_median_depth():
    xyz, rgb = _room(sky=False)
    K, V = _cameras()
    pcd = pcd_set(xyz, rgb, K, V, 24, 24, PcdSetParams(offset=0.1))
    centres = -torch.einsum("vji,vj->vi", pcd.viewmats[:, :3, :3], pcd.viewmats[:, :3, 3])  # [4 M, 3]
    dist = torch.linalg.vector_norm(centres, dim=-1).reshape(len(V), 4)
    expected = 0.1 * torch.tensor(pcd.medians, dtype=torch.float64)[:, None].expand(-1, 4)
    assert torch.allclose(dist, expected, rtol=1e-6)
