"""Icosahedron tangent faces tile the sphere once; the base rig covers it; supplementary cameras move right."""

import math

import pytest
import torch

from holoflow.geometry.camera import camera_centers, fov_from_focal, intrinsics_from_fov, pinhole_rays, project_points
from holoflow.geometry.icosahedron import (
    equirect_face_index,
    face_of_direction,
    frustum_weight,
    icosahedron,
    tangent_faces,
    triangle_mask,
)
from holoflow.geometry.rigs import base_directions, base_rig, rig_coverage, supplementary_rig
from holoflow.geometry.sphere import equirect_directions


def _edge_planes(faces):
    """Inward normals [20, 3, 3] of each face's three great-circle edges."""
    v = faces.vertices
    n = torch.linalg.cross(v, torch.roll(v, -1, dims=1))  # [20, 3, 3]
    sign = torch.sign(torch.einsum("fkj,fj->fk", n, faces.centers))[..., None]
    return n * sign


def test_icosahedron_is_regular():
    verts, faces = icosahedron(dtype=torch.float64)
    edges = torch.linalg.vector_norm(verts[faces] - verts[faces].roll(1, dims=1), dim=-1)
    torch.testing.assert_close(edges, torch.full_like(edges, float(edges[0, 0])))
    assert faces.unique().numel() == 12


def test_triangles_tile_sphere_exactly_once(dtype, device):
    """Every direction lies in exactly one face's spherical triangle (by the edge-plane test, away from
    edges by more than eps), that face is the one face_of_direction picks, and it projects inside that
    face's padded image, inside its triangle mask's pixels."""
    faces = tangent_faces(size=64, device=device, dtype=dtype)
    dirs = equirect_directions(64, 128, device=device, dtype=dtype).reshape(-1, 3)
    # exact poles, the seam and points on face edges too
    v = faces.vertices
    mids = (v + v.roll(1, dims=1)).reshape(-1, 3)
    extra = torch.cat(
        [
            torch.tensor([[0, -1, 0], [0, 1, 0], [0, 0, -1], [-1e-9, 0, -1]], dtype=dtype, device=device),
            mids / torch.linalg.vector_norm(mids, dim=-1, keepdim=True),
        ]
    )
    dirs = torch.cat([dirs, extra])
    planes = _edge_planes(faces)
    s = torch.einsum("fkj,nj->nfk", planes, dirs).amin(-1)  # [N, 20] signed distance to the nearest edge
    inside = (s > -1e-6).sum(-1)
    strictly = (s > 1e-6).sum(-1)
    assert (inside >= 1).all() and (strictly <= 1).all()
    own = face_of_direction(dirs, faces.centers)
    assert (s[torch.arange(len(dirs)), own] > -1e-6).all()
    # the owner's padded image contains the direction, with margin
    rot = faces.viewmat.clone()
    rot[:, :3, 3] = 0
    for f in range(20):
        d = dirs[own == f]
        uv, z = project_points(d, faces.K[f], rot[f])
        assert (z > 0).all() and (uv > 2).all() and (uv < 62).all()


def test_triangle_masks_partition_pixels(dtype):
    faces = tangent_faces(size=48, dtype=dtype)
    mask = triangle_mask(faces)
    assert mask.shape == (20, 48, 48) and mask.dtype == torch.bool
    # same triangle shape in every face (upright, apex up or down): equal pixel counts
    counts = mask.sum((1, 2))
    assert (counts == counts[0]).all() and int(counts[0]) > 0
    # total solid angle of the masked pixels ~ 4 pi
    _, d = pinhole_rays(faces.K, faces.viewmat, 48, 48)
    fx, fy = faces.K[:, 0, 0], faces.K[:, 1, 1]
    cos3 = (d @ faces.centers[:, None, :, None]).squeeze(-1).clamp(
        min=0
    ) ** 3  # [20, s, s] solid angle ~ cos^3 / (fx fy)
    omega = (cos3 / (fx * fy)[:, None, None] * mask).sum()
    assert abs(float(omega) - 4 * math.pi) < 0.02 * 4 * math.pi


def test_default_padding_field_of_view():
    faces = tangent_faces(padding=0.3, size=256, dtype=torch.float64)
    K = faces.K[0]
    across = fov_from_focal(float(K[0, 0]), 256)
    along = math.degrees(math.atan(float(K[1, 2] / K[1, 1])) + math.atan(float((256 - K[1, 2]) / K[1, 1])))
    assert abs(across - 99.5) < 0.5 and abs(along - 88.1) < 0.5
    w = frustum_weight(faces)
    assert float(w[:, 128, 128].min()) == 1.0 and float(w[:, 0, :].max()) < 0.05
    assert float(w[triangle_mask(faces)].min()) > 0.1  # every triangle pixel has weight for blending


def test_equirect_face_index():
    idx = equirect_face_index(16, 32)
    assert idx.shape == (16, 32) and set(idx.unique().tolist()) == set(range(20))
    assert (idx[0] < 5).all() and (idx[-1] >= 15).all()  # polar rows belong to the polar faces


def test_base_rig_covers_sphere(dtype):
    V = base_rig(38, dtype=dtype)
    assert V.shape == (38, 4, 4)
    torch.testing.assert_close(camera_centers(V), torch.zeros(38, 3, dtype=dtype), atol=1e-6, rtol=0)
    d = base_directions(38, dtype=dtype)
    assert float(d[0, 1]) == -1.0 and float(d[-1, 1]) == 1.0  # both poles
    K = intrinsics_from_fov(47.4, 64, 64, dtype=dtype)
    cover = rig_coverage(K, V, 64, 64, 256, 512)
    assert int(cover.min()) >= 1
    with pytest.raises(ValueError):
        base_rig(38, layout="nope")


def test_supplementary_rig(dtype):
    base = base_rig(6, dtype=dtype)
    depths = torch.arange(1, 7, dtype=dtype)
    sup = supplementary_rig(base, depths, offset=0.1, angle_deg=10.0)
    assert sup.shape == (24, 4, 4)
    R = sup[:, :3, :3]
    torch.testing.assert_close(R @ R.transpose(1, 2), torch.eye(3, dtype=dtype).expand(24, 3, 3), atol=1e-6, rtol=0)
    centres = camera_centers(sup).reshape(6, 4, 3)
    dist = torch.linalg.vector_norm(centres, dim=-1)
    torch.testing.assert_close(dist, 0.1 * depths[:, None].expand(6, 4), atol=1e-6, rtol=0)
    Rb = base[:, :3, :3]
    # above: moved to the base camera's -y; left: to its -x
    up = torch.einsum("mij,mj->mi", Rb, centres[:, 0]) / dist[:, :1]
    left = torch.einsum("mij,mj->mi", Rb, centres[:, 2]) / dist[:, :1]
    torch.testing.assert_close(up, torch.tensor([0.0, -1, 0], dtype=dtype).expand(6, 3), atol=1e-6, rtol=0)
    torch.testing.assert_close(left, torch.tensor([-1.0, 0, 0], dtype=dtype).expand(6, 3), atol=1e-6, rtol=0)
    # turned back towards the base axis by angle_deg: the camera above looks slightly down
    fwd = sup[:, 2, :3].reshape(6, 4, 3)
    fwd_in_base = torch.einsum("mij,mkj->mki", Rb, fwd)  # [6, 4, 3]
    a = math.radians(10.0)
    expected = torch.tensor(
        [
            [0, math.sin(a), math.cos(a)],
            [0, -math.sin(a), math.cos(a)],
            [math.sin(a), 0, math.cos(a)],
            [-math.sin(a), 0, math.cos(a)],
        ],
        dtype=dtype,
    )
    torch.testing.assert_close(fwd_in_base, expected.expand(6, 4, 3), atol=1e-6, rtol=0)
