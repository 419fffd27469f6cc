"""Conventions of holoflow.geometry.sphere and .camera (docs/conventions.md), incl. poles and the seam."""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from holoflow.geometry.camera import (
    camera_centers,
    intrinsics,
    intrinsics_from_fov,
    invert_viewmat,
    look_at,
    pinhole_rays,
    project_points,
    quat_to_rotmat,
    rotmat_to_quat,
)
from holoflow.geometry.sphere import (
    direction_to_lonlat,
    equirect_directions,
    equirect_pixel_to_lonlat,
    lonlat_to_direction,
    lonlat_to_equirect_pixel,
)

TOL = {torch.float32: 2e-6, torch.float64: 1e-12}
PI = math.pi
# exact poles, the seam (+-pi), face-edge-like and ordinary values
lons = st.one_of(
    st.sampled_from([-PI, PI, 0.0, PI / 2, -PI / 2, math.atan(0.5), 3.0]), st.floats(-PI, PI, allow_nan=False)
)
lats = st.one_of(
    st.sampled_from([PI / 2, -PI / 2, 0.0, math.atan(0.5), 1.5707]), st.floats(-PI / 2, PI / 2, allow_nan=False)
)


def test_anchor_pixels(dtype, device):
    W, H = 16, 8
    u = torch.tensor([W / 2, 0.0, 3 * W / 4, W / 4], dtype=dtype, device=device)
    v = torch.tensor([H / 2, H / 2, H / 2, 0.0], dtype=dtype, device=device)
    d = lonlat_to_direction(*equirect_pixel_to_lonlat(u, v, W, H))
    expected = torch.tensor([[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0]], dtype=dtype, device=device)
    torch.testing.assert_close(d, expected, atol=1e-6, rtol=0)


@settings(max_examples=100, deadline=None)
@given(lon=lons, lat=lats)
@pytest.mark.parametrize("dt", [torch.float32, torch.float64])
def test_direction_pixel_round_trip(dt, lon, lat):
    W, H = 2048, 1024
    d = lonlat_to_direction(torch.tensor(lon, dtype=dt), torch.tensor(lat, dtype=dt))
    u, v = lonlat_to_equirect_pixel(*direction_to_lonlat(d), W, H)
    assert 0 <= float(u) < W and -1e-3 <= float(v) <= H + 1e-3
    d2 = lonlat_to_direction(*equirect_pixel_to_lonlat(u, v, W, H))
    # the pixel step amplifies rounding by W/(2 pi); float32 keeps ~1e-7 relative in u
    tol = 4e-6 if dt == torch.float32 else 1e-12
    assert torch.linalg.vector_norm(d - d2) < tol


@settings(max_examples=100, deadline=None)
@given(x=st.floats(-1, 1), y=st.floats(-1, 1), z=st.floats(-1, 1))
def test_direction_lonlat_float32_matches_float64(x, y, z):
    d64 = torch.tensor([x, y, z], dtype=torch.float64)
    if torch.linalg.vector_norm(d64) < 1e-3:
        return
    d64 = d64 / torch.linalg.vector_norm(d64)
    back32 = lonlat_to_direction(*direction_to_lonlat(d64.float()))
    back64 = lonlat_to_direction(*direction_to_lonlat(d64))
    assert torch.linalg.vector_norm(back32.double() - back64) < 1e-6
    assert torch.linalg.vector_norm(back64 - d64) < 1e-12


def test_equirect_directions(dtype, device):
    d = equirect_directions(6, 12, device=device, dtype=dtype)
    assert d.shape == (6, 12, 3) and d.dtype == dtype
    torch.testing.assert_close(torch.linalg.vector_norm(d, dim=-1), torch.ones(6, 12, dtype=dtype, device=device))
    # symmetric rows about the equator, top half looks up (-y)
    assert (d[:3, :, 1] < 0).all() and (d[3:, :, 1] > 0).all()
    torch.testing.assert_close(d[0, :, 1], d[5, :, 1].neg())


def _check_rotation(V, tol):
    R = V[..., :3, :3]
    eye = torch.eye(3, dtype=V.dtype, device=V.device).expand_as(R)
    assert torch.allclose(R @ R.transpose(-1, -2), eye, atol=tol)
    assert torch.allclose(torch.linalg.det(R), torch.ones_like(R[..., 0, 0]), atol=tol)


def test_look_at_straight_up_and_down(dtype, device):
    eye = torch.tensor([[0.0, 0, 0], [1.0, 2, 3]], dtype=dtype, device=device)
    for sign in (1.0, -1.0):
        target = eye + torch.tensor([0.0, sign, 0.0], dtype=dtype, device=device)
        V = look_at(eye, target)
        assert torch.isfinite(V).all()
        _check_rotation(V, TOL[dtype] * 10)
        f = V[:, 2, :3]  # forward row
        torch.testing.assert_close(f, (target - eye), atol=0, rtol=0)
        # image top (-y_cam) points to +z looking down, -z looking up
        top = -V[:, 1, :3]
        torch.testing.assert_close(top, torch.tensor([0.0, 0, sign], dtype=dtype, device=device).expand(2, 3))
        torch.testing.assert_close(camera_centers(V), eye)
    # continuity: nearly straight down matches the exact case
    near = look_at(eye[:1], eye[:1] + torch.tensor([0.0, 1.0, 1e-4], dtype=dtype, device=device))
    exact = look_at(eye[:1], eye[:1] + torch.tensor([0.0, 1.0, 0.0], dtype=dtype, device=device))
    assert torch.allclose(near, exact, atol=1e-3)


@settings(max_examples=100, deadline=None)
@given(f=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)))
def test_look_at_properties(f):
    fwd = torch.tensor(f, dtype=torch.float64)
    if torch.linalg.vector_norm(fwd) < 1e-3:
        return
    eye = torch.tensor([0.5, -0.2, 0.1], dtype=torch.float64)
    V = look_at(eye, eye + fwd)
    _check_rotation(V, 1e-12)
    torch.testing.assert_close(V[2, :3], fwd / torch.linalg.vector_norm(fwd))
    assert V[1, 1] >= -1e-6  # image down never points to world up (1e-6: look_at's fallback threshold)
    assert abs(float(V[0, 1])) < 1e-6  # image x stays horizontal (no roll)


def test_look_at_forward_is_identity(dtype, device):
    V = look_at(torch.zeros(3, dtype=dtype, device=device), torch.tensor([0.0, 0, 5], dtype=dtype, device=device))
    torch.testing.assert_close(V, torch.eye(4, dtype=dtype, device=device))


def test_pinhole_rays_and_projection_round_trip(dtype, device):
    K = intrinsics_from_fov(60.0, 8, 6, device=device, dtype=dtype)
    assert float(K[0, 2]) == 4.0 and float(K[1, 2]) == 3.0
    V = look_at(
        torch.tensor([1.0, 0, 0], dtype=dtype, device=device), torch.tensor([0.0, 1, 1], dtype=dtype, device=device)
    )
    o, d = pinhole_rays(K, V, 6, 8)
    assert o.shape == d.shape == (6, 8, 3)
    torch.testing.assert_close(torch.linalg.vector_norm(d, dim=-1), torch.ones(6, 8, dtype=dtype, device=device))
    pts = (o + 2.5 * d).reshape(-1, 3)
    uv, z = project_points(pts, K, V)
    ys, xs = torch.meshgrid(
        torch.arange(6, dtype=dtype, device=device) + 0.5,
        torch.arange(8, dtype=dtype, device=device) + 0.5,
        indexing="ij",
    )
    torch.testing.assert_close(uv, torch.stack([xs, ys], -1).reshape(-1, 2), atol=1e-4, rtol=0)
    assert (z > 0).all()
    # batched: two cameras
    Kb, Vb = torch.stack([K, K]), torch.stack([V, invert_viewmat(invert_viewmat(V))])
    _, db = pinhole_rays(Kb, Vb, 6, 8)
    torch.testing.assert_close(db[1], d)


def test_intrinsics_batched(dtype):
    K = intrinsics(torch.tensor([100.0, 200.0]), 50.0, 32.0, 16.0, dtype=dtype)
    assert K.shape == (2, 3, 3) and float(K[1, 0, 0]) == 200.0 and float(K[0, 2, 2]) == 1.0


@settings(max_examples=100, deadline=None)
@given(q=st.tuples(*[st.floats(-1, 1)] * 4))
def test_quaternion_round_trip(q):
    q = torch.tensor(q, dtype=torch.float64)
    if torch.linalg.vector_norm(q) < 1e-3:
        return
    R = quat_to_rotmat(q)
    q2 = rotmat_to_quat(R)
    torch.testing.assert_close(quat_to_rotmat(q2), R, atol=1e-10, rtol=0)
    q = q / torch.linalg.vector_norm(q)
    assert torch.allclose(q2, q, atol=1e-9) or torch.allclose(q2, -q, atol=1e-9)
