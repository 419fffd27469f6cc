"""Rasterizer backends: fast CPU == dense reference (values and gradients), gradcheck, hard cases."""

import math

import pytest
import torch

from holoflow.splat import rasterize
from holoflow.splat.synthetic import intrinsics, look_at

NAMES = ("means", "quats", "scales", "opacities", "colors")


def random_scene(n, seed, dtype=torch.float64, sh=False):
    g = torch.Generator().manual_seed(seed)
    p = dict(
        means=torch.randn(n, 3, generator=g, dtype=dtype) * 0.6 + torch.tensor([0, 0, 3.0], dtype=dtype),
        quats=torch.randn(n, 4, generator=g, dtype=dtype),
        scales=torch.rand(n, 3, generator=g, dtype=dtype) * 0.25 + 0.02,
        opacities=torch.rand(n, generator=g, dtype=dtype) * 0.9 + 0.05,
        colors=(
            torch.randn(n, 4, 3, generator=g, dtype=dtype) * 0.5 if sh else torch.rand(n, 3, generator=g, dtype=dtype)
        ),
    )
    return {k: v.requires_grad_(True) for k, v in p.items()}


def assert_radii_match(got, want):
    """Radii (ceil of a float reach, px; 0 = not drawn) of two float paths (numba, torch): equal, or one
    apart where a reach within rounding of a whole pixel rounds up differently; at most 1 % of them.
    Bit-equal float paths are not guaranteed across CPUs (torch's SIMD width and MKL pick per CPU)."""
    d = (got.long() - want.long()).abs()
    assert int(d.max()) <= 1 and float((d > 0).float().mean()) <= 0.01, int((d > 0).sum())


def unpack(values, camera_ids, gaussian_ids, C, N):
    """A packed [P, ...] output of the fast path (one row per drawn pair) as [C, N, ...], 0 elsewhere."""
    out = values.new_zeros((C, N, *values.shape[1:]))
    out[camera_ids, gaussian_ids] = values
    return out


def dense_meta(out, C, N):
    """The fast path's packed meta as the dense backends give it: means2d [C, N, 2], radii [C, N]."""
    m = out["meta"]
    return {k: unpack(m[k].detach(), m["camera_ids"], m["gaussian_ids"], C, N) for k in ("means2d", "radii")}


def cameras(width, height, dtype=torch.float64, n=2):
    eyes = [[0, 0, 0], [0.3, -0.2, 0.1], [-0.4, 0.1, -0.2]][:n]
    vm = torch.stack([look_at(e, [0, 0, 3]) for e in eyes]).to(dtype)
    K = intrinsics(width, height, 70.0).to(dtype)[None].repeat(n, 1, 1)
    return vm, K


def render_and_grads(p, vm, K, W, H, backend, bg=None):
    out = rasterize(*[p[k] for k in NAMES], vm, K, W, H, backend=backend, background=bg)
    w = torch.linspace(0.2, 1.0, 3, dtype=out["rgb"].dtype, device=out["rgb"].device)
    loss = (out["rgb"] * w).sum() + 0.7 * out["alpha"].sum() + 0.05 * out["depth"].sum()
    grads = torch.autograd.grad(loss, [p[k] for k in NAMES])
    return out, dict(zip(NAMES, grads))


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("sh", [False, True])
def test_fast_matches_reference(seed, sh, dtype):
    W, H = 37, 29
    p = random_scene(60, seed, dtype, sh)
    vm, K = cameras(W, H, dtype)
    bg = torch.tensor([0.1, 0.2, 0.3], dtype=dtype)
    ref, gref = render_and_grads(p, vm, K, W, H, "reference", bg)
    fast, gfast = render_and_grads(p, vm, K, W, H, "cpu", bg)
    tol = dict(rtol=1e-9, atol=1e-10) if dtype == torch.float64 else dict(rtol=1e-4, atol=2e-5)
    for k in ("rgb", "alpha", "depth"):
        assert fast[k].shape == ref[k].shape
        torch.testing.assert_close(fast[k], ref[k], **tol)
    assert fast["meta"]["packed"] and not ref["meta"]["packed"]
    meta = dense_meta(fast, 2, 60)
    drawn = meta["radii"] > 0  # the fast path projects only those
    torch.testing.assert_close(meta["means2d"][drawn], ref["meta"]["means2d"][drawn].detach(), **tol)
    assert_radii_match(meta["radii"], ref["meta"]["radii"])
    gtol = dict(rtol=1e-8, atol=1e-8) if dtype == torch.float64 else dict(rtol=2e-3, atol=2e-3)
    for k in NAMES:
        scale = gref[k].abs().max().clamp_min(1.0)
        torch.testing.assert_close(gfast[k] / scale, gref[k] / scale, **gtol)
    assert ref["alpha"].max() > 0.5  # the scene is really in view


@pytest.mark.parametrize("backend", ["reference", "cpu"])
def test_gradcheck(backend):
    W, H = 9, 7
    p = random_scene(4, 3, torch.float64)
    vm, K = cameras(W, H, torch.float64, n=1)
    K[:, 0, 0] = K[:, 1, 1] = 6.0  # wide view: all four Gaussians cover pixels

    def f(*args):
        out = rasterize(*args, vm, K, W, H, backend=backend)
        return out["rgb"], out["alpha"], out["depth"]

    assert torch.autograd.gradcheck(f, tuple(p[k] for k in NAMES), eps=1e-6, atol=1e-6, rtol=1e-4)


def test_deterministic():
    p = random_scene(80, 5, torch.float32)
    vm, K = cameras(31, 23, torch.float32)
    a, ga = render_and_grads(p, vm, K, 31, 23, "cpu")
    b, gb = render_and_grads(p, vm, K, 31, 23, "cpu")
    # the numba kernels' sums run in a fixed order whatever the thread count: exact on any CPU
    assert torch.equal(a["rgb"], b["rgb"]) and all(torch.equal(ga[k], gb[k]) for k in NAMES)


def test_packed_projection_parallel_equals_serial(monkeypatch):
    # several chunks of Gaussians, three cameras: the parallel passes place every pair where the serial
    # ones do, and the backward sums each Gaussian's cameras in the same order: exact on any CPU
    from holoflow.splat import project_cpu as cp

    n = 2 * cp.CHUNK + 300
    p = random_scene(n, 9, torch.float32)
    with torch.no_grad():
        p["means"][:, :2] *= 2  # some off-screen in each camera
    vm, K = cameras(40, 30, torch.float32, n=3)
    got = []
    for threshold in (0, 10**12):  # parallel kernels, serial twins
        monkeypatch.setattr(cp, "PARALLEL_MIN_WORK", threshold)
        out = cp.project_cpu(*[p[k] for k in ("means", "quats", "scales", "opacities")], vm, K, 40, 30, 0.01, 1e10)
        loss = (out["means2d"] * 0.3).sum() + out["conics"].sum() + 0.1 * out["depths"].sum()
        grads = torch.autograd.grad(loss, [p[k] for k in ("means", "quats", "scales")])
        got.append(([out[k].detach() for k in ("gaussian_ids", "camera_start", "means2d", "conics", "radii")], grads))
    (a, ga), (b, gb) = got
    assert 0 < len(a[0]) < 3 * n and all(torch.equal(x, y) for x, y in zip(a, b))
    assert all(torch.equal(x, y) for x, y in zip(ga, gb))


@pytest.mark.parametrize("chunks", [1, 3, 8, 64])
def test_tile_binning_is_the_same_for_any_chunk_count(chunks):
    """The parallel counting sort gives the serial one's lists: per tile ascending packed index."""
    import numpy as np

    from holoflow.splat import composite_cpu as cpu

    g = np.random.default_rng(chunks)
    N, W, H = 500, 70, 45
    m2 = g.uniform(-10, 80, (N, 2))
    ext = g.uniform(0.5, 30, (N, 2))
    box = np.empty((N, 4), np.int64)
    keep = cpu._boxes_serial(np.ones(N, np.bool_), m2, ext, g.uniform(0.01, 1, N), W, H, box)
    order = cpu.depth_order(g.uniform(1, 5, N).astype(np.float32), keep)
    args = (order, box, m2, g.normal(size=(N, 3)), g.uniform(0.01, 1, N), g.normal(size=(N, 4)), W, H)
    ref = cpu._bin_tiles_serial(*args, 1)
    got = cpu._bin_tiles(*args, chunks)
    for a, b in zip(ref, got):
        assert np.array_equal(a, b)  # integer tile lists: exact on any CPU
    rec, pbox, ft, offsets, ids, pstart, ent = ref
    assert all(np.all(np.diff(ids[offsets[t] : offsets[t + 1]]) > 0) for t in range(len(offsets) - 1))
    assert np.array_equal(np.sort(ent), np.arange(len(ids)))  # every entry owned exactly once


def _hard_scene(case, dtype=torch.float64):
    p = {k: v.detach() for k, v in random_scene(12, 7, dtype).items()}
    vm, K = cameras(16, 12, dtype, n=1)
    W, H = 16, 12
    if case == "behind_camera":
        p["means"][:6, 2] = -p["means"][:6, 2]
    elif case == "near_plane":
        p["means"][:6, 2] = 0.01
        p["means"][6:, 2] = 0.0100001
    elif case == "huge_scales":
        p["scales"][:6] = 1e3
    elif case == "tiny_scales":
        p["scales"][:] = 1e-9
    elif case == "zero_quaternion":
        p["quats"][:6] = 0.0
    elif case == "opacity_0_and_1":
        p["opacities"][:6] = 0.0
        p["opacities"][6:] = 1.0
    elif case == "looking_up":
        vm = look_at([0, 0, 0], [0, -5, 0]).to(dtype)[None]  # world up is -y
        m = p["means"]
        p["means"] = torch.stack([m[:, 0], -m[:, 2], m[:, 1]], 1)  # the scene rotated overhead
    elif case == "empty":
        p = {k: v[:0] for k, v in p.items()}
    elif case == "one_pixel":
        W = H = 1
        K = intrinsics(1, 1, 70.0).to(dtype)[None]
    elif case == "non_square":
        W, H = 23, 5
        K = intrinsics(W, H, 70.0).to(dtype)[None]
    elif case == "far_off_axis":
        p["means"][:6, 0] = 1e4
    return {k: v.clone().requires_grad_(True) for k, v in p.items()}, vm, K, W, H


HARD = [
    "behind_camera",
    "near_plane",
    "huge_scales",
    "tiny_scales",
    "zero_quaternion",
    "opacity_0_and_1",
    "looking_up",
    "empty",
    "one_pixel",
    "non_square",
    "far_off_axis",
]


@pytest.mark.parametrize("case", HARD)
def test_hard_cases_finite_and_consistent(case):
    p, vm, K, W, H = _hard_scene(case)
    ref, gref = render_and_grads(p, vm, K, W, H, "reference")
    fast, gfast = render_and_grads(p, vm, K, W, H, "cpu")
    for out, grads in ((ref, gref), (fast, gfast)):
        assert out["rgb"].shape == (1, H, W, 3) and out["alpha"].shape == (1, H, W, 1)
        for k in ("rgb", "alpha", "depth"):
            assert torch.isfinite(out[k]).all(), (case, k)
        for k, g in grads.items():
            assert torch.isfinite(g).all(), (case, k)
    torch.testing.assert_close(fast["rgb"], ref["rgb"], rtol=1e-8, atol=1e-8)
    torch.testing.assert_close(fast["alpha"], ref["alpha"], rtol=1e-8, atol=1e-8)
    if case == "looking_up":
        assert ref["alpha"].max() > 0.1
    if case == "behind_camera":
        assert not (fast["meta"]["gaussian_ids"] < 6).any()


@pytest.mark.parametrize("backend", ["reference", "cpu"])
def test_no_camera_renders_nothing(backend):
    p = random_scene(10, 2, torch.float32)
    out = rasterize(*[p[k] for k in NAMES], torch.zeros(0, 4, 4), torch.zeros(0, 3, 3), 8, 6, backend=backend)
    assert out["rgb"].shape == (0, 6, 8, 3) and out["alpha"].shape == (0, 6, 8, 1)
    assert out["depth"].shape == (0, 6, 8, 1)


def test_gsplat_on_cpu_tensors_says_to_move_them():
    p = random_scene(3, 0, torch.float32)
    vm, K = cameras(8, 8, torch.float32, n=1)
    with pytest.raises(ValueError, match="CUDA tensors.*to\\('cuda'\\)"):
        rasterize(*[p[k] for k in NAMES], vm, K, 8, 8, backend="gsplat")


def test_bad_inputs_raise():
    p = random_scene(3, 0, torch.float32)
    vm, K = cameras(8, 8, torch.float32, n=1)
    with pytest.raises(ValueError, match="quats"):
        rasterize(p["means"], p["quats"][:, :3], p["scales"], p["opacities"], p["colors"], vm, K, 8, 8)
    with pytest.raises(ValueError, match="backend"):
        rasterize(*[p[k] for k in NAMES], vm, K, 8, 8, backend="nope")
    with pytest.raises(ValueError, match="1x1"):
        rasterize(*[p[k] for k in NAMES], vm, K, 0, 8)


def test_pixel_centre_convention():
    """A tiny bright Gaussian on the optical axis lands on the pixel centre (W/2, H/2): with an even
    size, the four central pixels share it equally."""
    W = H = 8
    K = intrinsics(W, H, 60.0)[None]
    vm = torch.eye(4)[None]
    out = rasterize(
        torch.tensor([[0.0, 0.0, 2.0]]),
        torch.tensor([[1.0, 0, 0, 0]]),
        torch.full((1, 3), 1e-4),
        torch.tensor([0.9]),
        torch.ones(1, 3),
        vm,
        K,
        W,
        H,
        backend="cpu",
    )
    a = out["alpha"][0, ..., 0]
    centre = a[3:5, 3:5]
    assert torch.allclose(centre, centre[0, 0].expand(2, 2)) and centre[0, 0] > 0.1
    assert math.isclose(float(out["depth"][0, 3, 3, 0] / a[3, 3]), 2.0, rel_tol=1e-6)


@pytest.mark.cuda
def test_gsplat_cuda_matches_reference():
    if not torch.cuda.is_available():
        pytest.skip("needs a CUDA device")
    pytest.importorskip("gsplat")
    W, H = 64, 48
    p = {k: v.detach() for k, v in random_scene(200, 11, torch.float32).items()}
    vm, K = cameras(W, H, torch.float32)
    ref, gref = render_and_grads({k: v.clone().requires_grad_(True) for k, v in p.items()}, vm, K, W, H, "reference")
    pc = {k: v.cuda().requires_grad_(True) for k, v in p.items()}
    cu, gcu = render_and_grads(pc, vm.cuda(), K.cuda(), W, H, "gsplat")
    # Same projection and compositing rules: measured on an H100 (gsplat 1.5.3) max |diff| 2e-6
    # and gradient cosine 1.0000 against the reference.
    for k in ("rgb", "alpha", "depth"):
        assert (cu[k].cpu() - ref[k]).abs().max() < 1e-4, k
    for k in NAMES:
        cos = torch.nn.functional.cosine_similarity(gcu[k].cpu().flatten(), gref[k].flatten(), dim=0)
        assert cos > 0.999, (k, float(cos))


def test_fast_matches_reference_when_most_gaussians_are_out_of_view(dtype):
    # A panorama's cloud seen by one pinhole view: most Gaussians are behind the camera or off-screen,
    # which the fast path drops before colouring and compositing (and skips in the projection's
    # backward). Images, means2d, radii and gradients must still equal the dense reference's.
    g = torch.Generator().manual_seed(7)
    n = 400
    d = torch.randn(n, 3, generator=g, dtype=torch.float64)
    p = random_scene(n, 7, dtype, sh=True)
    with torch.no_grad():
        p["means"].copy_(
            (d / d.norm(dim=-1, keepdim=True) * (2 + torch.rand(n, 1, generator=g, dtype=torch.float64))).to(dtype)
        )
    W, H = 31, 23
    vm = look_at([0, 0, 0], [0, 0, 1]).to(dtype)[None]
    K = intrinsics(W, H, 60.0).to(dtype)[None]
    ref, gref = render_and_grads(p, vm, K, W, H, "reference")
    fast, gfast = render_and_grads(p, vm, K, W, H, "cpu")
    drawn = int((ref["meta"]["radii"] > 0).sum())
    assert 0 < drawn < n // 4  # the case this test is about
    tol = dict(rtol=1e-9, atol=1e-10) if dtype == torch.float64 else dict(rtol=1e-4, atol=2e-5)
    for k in ("rgb", "alpha", "depth"):
        torch.testing.assert_close(fast[k], ref[k], **tol)
    assert_radii_match(dense_meta(fast, 1, n)["radii"], ref["meta"]["radii"])
    gtol = dict(rtol=1e-8, atol=1e-8) if dtype == torch.float64 else dict(rtol=2e-3, atol=2e-3)
    for k in NAMES:
        scale = gref[k].abs().max().clamp_min(1.0)
        torch.testing.assert_close(gfast[k] / scale, gref[k] / scale, **gtol)


def test_fast_projection_draws_what_the_reference_tests_draw(dtype):
    # project_cpu skips the covariance of Gaussians that a cheap bound puts off the image; large ones
    # centred outside the view whose reach enters it must still be drawn, in every camera.
    from holoflow.splat.project import pixel_extent, project_gaussians
    from holoflow.splat.project_cpu import project_cpu

    p = {k: v.detach() for k, v in random_scene(600, 11, dtype).items()}
    g = torch.Generator().manual_seed(11)
    big = torch.rand(600, generator=g) < 0.3
    p["scales"][big] *= 8  # reach tens of px past their centres
    p["means"][:, :2] *= 3  # many centres off-screen
    W, H = 40, 30
    vm, K = cameras(W, H, dtype, n=3)
    packed = project_cpu(p["means"], p["quats"], p["scales"], p["opacities"], vm, K, W, H, 0.01, 1e10)
    start, gid = packed["camera_start"], packed["gaussian_ids"]
    for c in range(3):  # camera by camera, Gaussians ascending
        assert (torch.diff(gid[start[c] : start[c + 1]]) > 0).all()
    cam = torch.repeat_interleave(torch.arange(3), torch.diff(start))
    fast = {k: unpack(packed[k], cam, gid, 3, 600) for k in ("means2d", "conics", "depths", "ext", "radii")}
    fast["drawn"] = unpack(torch.ones(len(gid), dtype=torch.bool), cam, gid, 3, 600)
    assert (packed["radii"] >= 1).all()
    ref = project_gaussians(p["means"], p["quats"], p["scales"], vm, K, W, H, 0.01, 1e10)
    ops = p["opacities"][None].expand(3, -1)
    ext = pixel_extent(ref["cov2d"], ops)
    m2 = ref["means2d"]
    drawn = ref["valid"] & ((m2 + ext >= 0) & (m2 - ext <= m2.new_tensor([W, H]))).all(-1) & (ops >= 1 / 255)
    # the same tests on two float paths: equal except where a reach ends within rounding of the image edge
    margin = torch.minimum((m2 + ext).abs(), (m2 - ext - m2.new_tensor([W, H])).abs()).amin(-1)
    differ = fast["drawn"] != drawn
    assert bool((margin[differ] <= 1e-3).all()) and int(differ.sum()) <= 2, int(differ.sum())
    outside = drawn & ((m2 < 0) | (m2 > m2.new_tensor([W, H]))).any(-1)
    assert int(outside.sum()) > 10 and int((~drawn).sum()) > 100  # the cases this test is about
    radii = torch.where(drawn, ext.max(-1).values.ceil(), torch.zeros_like(ext[..., 0])).to(torch.int32)
    assert_radii_match(fast["radii"][~differ], radii[~differ])
    drawn = drawn & ~differ
    tol = dict(rtol=1e-9, atol=1e-9) if dtype == torch.float64 else dict(rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(fast["ext"][drawn], ext[drawn].double(), **tol)
    torch.testing.assert_close(fast["conics"][drawn], ref["conics"][drawn], **tol)
    torch.testing.assert_close(fast["means2d"][drawn], m2[drawn], **tol)
    torch.testing.assert_close(fast["depths"][drawn], ref["depths"][drawn], **tol)


@pytest.mark.parametrize("backend", ["reference", "cpu"])
def test_without_depth_same_colour_alpha_and_gradients(backend):
    p = random_scene(40, 3, torch.float64, sh=True)
    vm, K = cameras(20, 16)
    outs = []
    for depth in (True, False):
        out = rasterize(*[p[k] for k in NAMES], vm, K, 20, 16, backend=backend, depth=depth)
        loss = (out["rgb"] * torch.linspace(0.2, 1.0, 3, dtype=torch.float64)).sum() + 0.7 * out["alpha"].sum()
        outs.append((out, torch.autograd.grad(loss, [p[k] for k in NAMES])))
    (a, ga), (b, gb) = outs
    assert b["depth"] is None and a["depth"].shape == a["alpha"].shape
    # The cpu backend composites each channel in its own scalar loop, so dropping the depth channel
    # cannot change the others' bits on any CPU. The dense reference backend does it as one batched
    # matmul over 5 or 4 channels, and MKL may pick a different kernel (another summation order) for
    # each shape on another CPU (seen on AMD EPYC): equal to float64 rounding there, not bit-equal.
    exact = backend == "cpu"
    for k in ("rgb", "alpha"):
        if exact:
            assert torch.equal(a[k], b[k]), k
        else:
            torch.testing.assert_close(a[k], b[k], rtol=1e-12, atol=1e-12)
    for x, y in zip(ga, gb):
        if exact:
            assert torch.equal(x, y)
        else:
            torch.testing.assert_close(x, y, rtol=1e-12, atol=1e-12)
