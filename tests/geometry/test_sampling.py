"""equirect <-> pinhole resampling against an analytic panorama, through the poles and the seam."""

import math

import pytest
import torch

from holoflow.geometry.camera import intrinsics_from_fov, look_at, pinhole_rays
from holoflow.geometry.sampling import (
    equirect_to_pinhole,
    equirect_to_pinhole_batches,
    equirect_window,
    pad_equirect,
    pinhole_to_equirect,
    resize_equirect,
    ring_prefilter,
    sample_equirect,
)
from holoflow.geometry.sphere import direction_to_lonlat, equirect_directions, lonlat_to_equirect_pixel


def field(d):
    """Smooth test function of direction [..., 3] -> [..., 3] (values within [0, 1], gradient <= ~1/rad)."""
    x, y, z = d.unbind(-1)
    return torch.stack([0.5 + 0.4 * x, 0.5 + 0.3 * y * z + 0.1 * x, 0.5 + 0.2 * torch.sin(2 * z) + 0.2 * y], -1)


def analytic_pano(H, W, dtype, device):
    return field(equirect_directions(H, W, device=device, dtype=dtype)).permute(2, 0, 1)  # [3, H, W]


# views straight up, straight down, across the seam (looking at -z), along +x, oblique near the pole
TARGETS = [[0, -1, 0], [0, 1, 0], [0, 0, -1], [1, 0, 0], [0.1, -1, -0.05], [-0.3, 0.8, -1]]


def _cams(dtype, device, fov=90.0, size=32):
    K = intrinsics_from_fov(fov, size, size, device=device, dtype=dtype).expand(len(TARGETS), 3, 3)
    V = look_at(
        torch.zeros(len(TARGETS), 3, dtype=dtype, device=device), torch.tensor(TARGETS, dtype=dtype, device=device)
    )
    return K, V


@pytest.mark.parametrize("mode,tol", [("bilinear", 2e-3), ("antialias", 4e-3), ("nearest", 2e-2)])
def test_e2p_matches_analytic_function(dtype, device, mode, tol):
    """Stated bound: at 512x256 (0.7 deg pixels) the view equals the function within ``tol`` everywhere,
    poles and seam included (bilinear error ~ pixel^2 * curvature; nearest ~ pixel * gradient)."""
    pano = analytic_pano(256, 512, dtype, device)
    K, V = _cams(dtype, device)
    views = equirect_to_pinhole(pano, K, V, 32, 32, mode=mode)  # [6, 3, 32, 32]
    assert views.shape == (6, 3, 32, 32) and views.dtype == dtype
    _, dirs = pinhole_rays(K, V, 32, 32)
    truth = field(dirs).permute(0, 3, 1, 2)
    err = (views - truth).abs()
    assert float(err.max()) < tol, (mode, err.amax(dim=(1, 2, 3)))


def test_e2p_seam_is_continuous(dtype, device):
    """A view centred on the seam sees no jump: columns either side of the image centre differ smoothly."""
    pano = analytic_pano(64, 128, dtype, device)
    K = intrinsics_from_fov(60.0, 64, 64, device=device, dtype=dtype)[None]
    V = look_at(torch.zeros(3, dtype=dtype, device=device), torch.tensor([0.0, 0, -1], dtype=dtype, device=device))[
        None
    ]
    view = equirect_to_pinhole(pano, K, V, 64, 64)[0]
    steps = (view[:, :, 1:] - view[:, :, :-1]).abs()
    assert float(steps.max()) < 0.03


def test_pad_equirect_crosses_poles():
    pano = torch.arange(4 * 8, dtype=torch.float64).reshape(1, 4, 8)
    p = pad_equirect(pano, 1)
    assert p.shape == (1, 6, 10)
    # column wrap
    assert torch.equal(p[0, 1:-1, 0], pano[0, :, 7]) and torch.equal(p[0, 1:-1, -1], pano[0, :, 0])
    # row above the north pole at column c is row 0 at column c + W/2
    assert float(p[0, 0, 1]) == float(pano[0, 0, 4]) and float(p[0, -1, 1 + 5]) == float(pano[0, 3, 1])


def test_e2p_p2e_round_trip(dtype, device):
    """Views of a panorama blended back reproduce it (within bilinear error) wherever a view lands."""
    H, W = 32, 64
    pano = analytic_pano(H, W, dtype, device)
    K, V = _cams(dtype, device, fov=100.0, size=48)
    views = equirect_to_pinhole(pano, K, V, 48, 48)
    acc, wsum = pinhole_to_equirect(views, K, V, H, W)
    assert acc.shape == (3, H, W) and wsum.shape == (1, H, W)
    seen = wsum[0] > 0
    assert seen[0].all() and seen[-1].all()  # both polar rows are covered by the up/down views
    blend = acc[:, seen] / wsum[:, seen]
    assert float((blend - pano[:, seen]).abs().max()) < 0.02


def _p2e_dense(images, K, viewmat, height, width, weights):
    """Reference p2e: every equirect pixel projected into every view (no footprint)."""
    import torch.nn.functional as F

    from holoflow.geometry.camera import project_points

    B, C, h, w = images.shape
    dirs = equirect_directions(height, width, device=images.device, dtype=images.dtype).reshape(-1, 3)
    accum, wsum = images.new_zeros(C, height * width), images.new_zeros(1, height * width)
    for b in range(B):
        uv, z = project_points(dirs, K[b], viewmat[b])
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)
        grid = torch.stack([uv[:, 0] * (2.0 / w) - 1.0, uv[:, 1] * (2.0 / h) - 1.0], -1)[inside].reshape(1, 1, -1, 2)
        col = F.grid_sample(images[b : b + 1], grid, align_corners=False, padding_mode="border").reshape(C, -1)
        wt = F.grid_sample(weights[b : b + 1], grid, align_corners=False, padding_mode="border").reshape(1, -1)
        accum[:, inside] += col * wt
        wsum[:, inside] += wt
    return accum.reshape(C, height, width), wsum.reshape(1, height, width)


@pytest.mark.parametrize("views", ["targets", "icosahedron"])
def test_p2e_footprint_matches_dense_reference(dtype, device, views):
    """The windowed p2e reaches every pixel the dense projection reaches (poles, seam, padded faces)."""
    if views == "targets":
        K, V = _cams(dtype, device, fov=120.0, size=24)
    else:
        from holoflow.geometry.icosahedron import tangent_faces

        faces = tangent_faces(padding=0.3, size=24)
        K, V = faces.K.to(device, dtype), faces.viewmat.to(device, dtype)
    gen = torch.Generator().manual_seed(0)
    imgs = torch.rand(len(K), 2, 24, 24, generator=gen, dtype=dtype).to(device)
    wts = torch.rand(len(K), 1, 24, 24, generator=gen, dtype=dtype).to(device) + 0.1
    acc, wsum = pinhole_to_equirect(imgs, K, V, 48, 96, weights=wts)
    ref_acc, ref_wsum = _p2e_dense(imgs, K, V, 48, 96, wts)
    assert torch.equal(wsum > 0, ref_wsum > 0)  # weights >= 0.1: any coverage difference would fail wsum below too
    torch.testing.assert_close(acc, ref_acc)
    torch.testing.assert_close(wsum, ref_wsum)


def test_p2e_weights(dtype, device):
    K, V = _cams(dtype, device, size=8)
    imgs = torch.ones(6, 1, 8, 8, dtype=dtype, device=device)
    w = torch.full((6, 1, 8, 8), 0.25, dtype=dtype, device=device)
    acc, wsum = pinhole_to_equirect(imgs, K, V, 16, 32, weights=w)
    torch.testing.assert_close(acc, wsum)
    assert float(wsum.max()) <= 0.25 * 6 + 1e-6


def test_resize_equirect_wraps(dtype, device):
    pano = torch.rand(2, 16, 48, dtype=dtype, device=device, generator=None)
    small = resize_equirect(pano, 8, 24)
    rolled = resize_equirect(torch.roll(pano, 6, dims=-1), 8, 24)
    torch.testing.assert_close(rolled, torch.roll(small, 3, dims=-1))
    const = torch.full((1, 10, 30), 0.7, dtype=dtype, device=device)
    torch.testing.assert_close(resize_equirect(const, 7, 13), torch.full((1, 7, 13), 0.7, dtype=dtype, device=device))
    torch.testing.assert_close(resize_equirect(const, 20, 64), torch.full((1, 20, 64), 0.7, dtype=dtype, device=device))


def test_resize_equirect_antialiases(dtype, device):
    """A 1-pixel checkerboard shrunk 8x averages to grey instead of aliasing."""
    y, x = torch.meshgrid(torch.arange(64), torch.arange(128), indexing="ij")
    checker = ((x + y) % 2).to(dtype).to(device)[None]
    small = resize_equirect(checker, 8, 16)
    assert float((small - 0.5).abs().max()) < 0.05


def test_e2p_antialias_mode_filters(dtype, device):
    y, x = torch.meshgrid(torch.arange(512), torch.arange(1024), indexing="ij")
    checker = ((x + y) % 2).to(dtype).to(device)[None]
    K, V = _cams(dtype, device, fov=90.0, size=16)
    aa = equirect_to_pinhole(checker, K, V, 16, 16, mode="antialias")
    bl = equirect_to_pinhole(checker, K, V, 16, 16, mode="bilinear")
    assert float((aa - 0.5).abs().mean()) < 0.5 * float((bl - 0.5).abs().mean())
    assert float((aa - 0.5).abs().mean()) < 0.1


def test_ring_prefilter_box_along_the_ring(dtype, device):
    """Rows whose box spans one column or less are untouched; a box wider than the ring is the row's
    mean; in between it is the exact box integral (checked against a brute-force sum on one row)."""
    g = torch.Generator().manual_seed(0)
    pano = torch.rand(3, 64, 128, generator=g, dtype=torch.float64).to(dtype).to(device)
    out = ring_prefilter(pano, 2 * math.pi / 128 * 0.5)  # 0.5 / sin(colat) columns: only rows near the poles
    colat = (torch.arange(64, dtype=torch.float64) + 0.5) * math.pi / 64
    plain = 0.5 / torch.sin(colat) <= 1
    assert torch.equal(out[:, plain], pano[:, plain])
    torch.testing.assert_close(ring_prefilter(pano, 10.0)[:, 0], pano[:, 0].mean(-1, keepdim=True).expand(3, 128))
    r, width = 2, float(0.5 / torch.sin(colat[2]))  # row 2: a box ~3.3 columns wide
    fine = pano[:, r].double().repeat_interleave(1000, -1)  # each pixel as 1000 constant sub-samples
    c = 1000 * 40 + 500  # the centre of pixel 40
    half = round(500 * width)
    want = fine[:, c - half : c + half].mean(-1)
    torch.testing.assert_close(out[:, r, 40].double(), want, atol=2e-3, rtol=0)


def test_e2p_antialias_zenith_matches_supersampling(dtype, device):
    """Seen straight up, columns alternating 0 / 1 are finer than the view near the pole: the
    antialiased view matches brute-force supersampling (16 x 16 bilinear samples a pixel), where
    the plain 2 x 2 supersampling of the panorama aliases them into moire."""
    stripes = (torch.arange(512) % 2).to(dtype).to(device).expand(1, 256, 512).contiguous()
    K, V = _cams(dtype, device, fov=47.43, size=32)
    K, V = K[:1], V[:1]  # straight up

    def supersampled(n):
        k = torch.diag(torch.tensor([float(n), float(n), 1.0], dtype=dtype, device=device)) @ K
        return torch.nn.functional.avg_pool2d(equirect_to_pinhole(stripes, k, V, 32 * n, 32 * n), n)

    aa = equirect_to_pinhole(stripes, K, V, 32, 32, mode="antialias")
    ref = supersampled(16)
    plain = supersampled(2)
    err, err_plain = float((aa - ref).abs().mean()), float((plain - ref).abs().mean())
    assert err < 0.3 * err_plain and err < 0.03, (err, err_plain)


def _pad_reference(pano, pad):
    """Spherical padding by explicit index arithmetic (the definition)."""
    H, W = pano.shape[-2:]
    out = torch.empty(*pano.shape[:-2], H + 2 * pad, W + 2 * pad, dtype=pano.dtype)
    for r in range(-pad, H + pad):
        for c in range(-pad, W + pad):
            if r < 0 or r >= H:
                src_r = min(max(-r - 1 if r < 0 else 2 * H - 1 - r, 0), H - 1)
                out[..., r + pad, c + pad] = pano[..., src_r, (c + W // 2) % W]
            else:
                out[..., r + pad, c + pad] = pano[..., r, c % W]
    return out


@pytest.mark.parametrize("shape,pad", [((5, 8), 2), ((4, 6), 1), ((5, 7), 2), ((1, 2), 2), ((2, 1), 2), ((1, 1), 1)])
def test_pad_equirect_matches_definition(shape, pad):
    pano = torch.arange(2 * shape[0] * shape[1], dtype=torch.float64).reshape(2, *shape)
    assert torch.equal(pad_equirect(pano, pad), _pad_reference(pano, pad))  # copies: exact on any CPU


def test_one_pixel_and_non_square_panoramas(dtype, device):
    K, V = _cams(dtype, device, size=3)
    for H, W in [(1, 1), (1, 2), (2, 1), (3, 10)]:
        pano = torch.full((2, H, W), 0.25, dtype=dtype, device=device)
        for mode in ("bilinear", "nearest", "antialias"):
            out = equirect_to_pinhole(pano, K, V, 3, 5, mode=mode)
            assert out.shape == (6, 2, 3, 5)
            torch.testing.assert_close(out, torch.full_like(out, 0.25))
        torch.testing.assert_close(resize_equirect(pano, 1, 1), torch.full((2, 1, 1), 0.25, dtype=dtype, device=device))


def _odd_cameras(dtype, device):
    """Views through both poles, across the seam, oblique, with fx != fy and skew, non-square images."""
    targets = torch.tensor(
        [[0, -1, 0], [0, 1, 0], [0, 0, -1], [-0.02, 0.3, -1], [0.7, -0.5, 0.2], [0.1, -1, -0.05]],
        dtype=dtype,
        device=device,
    )
    V = look_at(torch.zeros_like(targets), targets)
    K = intrinsics_from_fov(100.0, 40, 24, device=device, dtype=dtype).repeat(len(targets), 1, 1)
    K[1, 1, 1] *= 1.3  # fx != fy
    K[3, 0, 1] = 4.0  # skew
    K[4, 0, 2] += 5.5  # off-centre principal point
    return K, V


def test_e2p_fast_path_matches_reference(dtype, device):
    """Stated bound: equirect_to_pinhole (window + separable angles) equals the simple reference
    sample_equirect(pano, pinhole_rays(...)) within 5e-5 (float32) / 1e-10 (float64) on a panorama of
    independent uniform [0, 1) pixels (so it is a bound on coordinate differences of ~1e-4 px); nearest
    picks the same pixel except at exact ties (rays on a pixel border, e.g. the diagonals of a view
    straight up land on multiples of 45 deg of longitude), where either neighbour is right."""
    g = torch.Generator().manual_seed(3)
    K, V = _odd_cameras(dtype, device)
    _, dirs = pinhole_rays(K, V, 24, 40)
    lon, lat = direction_to_lonlat(dirs.double())
    tol = 5e-5 if dtype == torch.float32 else 1e-10
    for H, W, shared in [(48, 96, True), (25, 51, False)]:  # odd W too; one panorama for all views or one each
        pano = torch.rand(len(K), 3, H, W, generator=g, dtype=torch.float64).to(dtype).to(device)
        src = pano[0] if shared else pano
        u, v = lonlat_to_equirect_pixel(lon, lat, W, H)
        tie = torch.minimum((u - u.round()).abs(), (v - v.round()).abs()) < 1e-4  # [6, 24, 40]
        fast = equirect_to_pinhole(src, K, V, 24, 40)  # [6, 3, 24, 40]
        ref = sample_equirect(src, dirs)
        assert fast.shape == ref.shape and fast.dtype == dtype
        assert float((fast - ref).abs().max()) < tol
        near = equirect_to_pinhole(src, K, V, 24, 40, mode="nearest")
        differ = (near != sample_equirect(src, dirs, "nearest")).any(1)  # [6, 24, 40]
        assert not (differ & ~tie).any() and float(tie.double().mean()) < 0.01


@pytest.mark.parametrize("H,W", [(5, 8), (4, 7), (1, 2), (2, 1), (1, 1)])
def test_equirect_window_matches_definition(H, W):
    """Any window (wrapping the seam several times, crossing a pole) equals the padded definition."""
    pano = torch.arange(2 * H * W, dtype=torch.float64).reshape(2, H, W)
    pad = 3
    ref = _pad_reference(pano, pad)  # rows -pad..H+pad-1, columns -pad..W+pad-1
    for r0, r1 in [(-pad, H + pad), (0, H), (-1, 1), (H - 1, H + 2)]:
        for c0, c1 in [(-pad, W + pad), (0, W), (W - 1, W + 2), (-2, 1)]:
            win = equirect_window(pano, r0, r1, c0, c1)
            assert win.is_contiguous()
            assert torch.equal(win, ref[:, r0 + pad : r1 + pad, c0 + pad : c1 + pad]), (r0, r1, c0, c1)


@pytest.mark.parametrize("shared_K", [True, False])
def test_e2p_in_batches_equals_one_call(shared_K):
    pano = analytic_pano(32, 64, torch.float32, "cpu")
    K, V = _cams(torch.float32, "cpu", size=16)  # 6 cameras
    K = K[0] if shared_K else K
    batches = list(equirect_to_pinhole_batches(pano, K, V, 16, 16, batch=4))
    assert [start for start, _ in batches] == [0, 4] and [len(v) for _, v in batches] == [4, 2]
    whole = equirect_to_pinhole(pano, K.expand(6, 3, 3), V, 16, 16, mode="antialias")
    assert torch.equal(torch.cat([v for _, v in batches]), whole)
