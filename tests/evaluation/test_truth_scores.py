"""holoflow.evaluation.truth_set / truth_scores and the novel rig's edge targets, on cases whose answer is known."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from holoflow.evaluation import truth_scores as ts
from holoflow.evaluation import viewing_size as viewing
from holoflow.evaluation.truth_set import eye_viewmat, read_truth_set, ring_eyes, write_truth_set

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "truth" / "grey_white_room"


def test_psnr_of_a_constant_error_is_known():
    a = torch.full((2, 4, 4, 3), 0.5, dtype=torch.float64)
    b = a + 0.1  # MSE 0.01 -> 20 dB
    assert ts.pooled_psnr(a, b) == pytest.approx(20.0, abs=1e-6)
    c = b.clone()
    c[1] = a[1] + 0.01  # second view 40 dB; pooled MSE 0.00505
    assert ts.per_view_psnr(a, c).tolist() == pytest.approx([20.0, 40.0], abs=1e-6)
    assert ts.pooled_psnr(a, c) == pytest.approx(-10 * math.log10(0.00505), abs=1e-6)
    assert ts.pooled_psnr(a, a) == math.inf


def test_depth_errors_use_finite_truth_where_the_render_is_not_empty():
    truth = torch.full((1, 2, 4), 2.0)
    truth[0, 1, 3] = math.inf  # sky: never scored
    depth = truth.clone()
    depth[0, 0, 0] = 2.2  # 10 % off: inside 1.25
    depth[0, 0, 1] = 5.0  # 150 % off: outside 1.25
    alpha = torch.ones(1, 2, 4)
    alpha[0, 1, 0] = 0.3  # empty: not scored, lowers coverage
    r = ts.depth_errors(depth, alpha, truth)
    assert r["pixels"] == 6 and r["coverage"] == pytest.approx(6 / 7)
    assert r["abs_rel"] == pytest.approx((0.1 + 1.5) / 6) and r["delta1"] == pytest.approx(5 / 6)
    none = ts.depth_errors(depth, torch.zeros(1, 2, 4), truth)
    assert math.isnan(none["abs_rel"]) and math.isnan(none["scale"]) and none["coverage"] == 0.0


def test_depth_scale_is_the_size_of_the_scene_not_its_outliers():
    truth = torch.linspace(1.0, 4.0, 40).reshape(1, 5, 8)
    depth = 1.03 * truth  # the whole room 3 % too large
    depth[0, 0, :3] = 0.1  # a few pixels wildly off: the median does not move
    r = ts.depth_errors(depth, torch.ones(1, 5, 8), truth)
    assert r["scale"] == pytest.approx(1.03)
    assert r["abs_rel"] > 0.03


def test_ring_scores_count_empty_and_cracked_pixels():
    rgb = torch.rand(2, 8, 8, 3, generator=torch.Generator().manual_seed(0))
    alpha = torch.ones(2, 8, 8)
    alpha[0, :2] = 0.2  # 16 px empty (and cracked)
    alpha[1, :1] = 0.7  # 8 px cracked, not empty
    z = torch.full((2, 8, 8), 3.0)
    r = ts.ring_scores(rgb, alpha, z, rgb, z)
    assert r["empty"] == pytest.approx(16 / 128) and r["cracked"] == pytest.approx(24 / 128)
    assert r["psnr"] == math.inf and r["ssim"] == pytest.approx(1.0) and r["abs_rel"] == 0.0 and r["delta1"] == 1.0
    assert r["per_view_cracked"] == [0.25, 0.125]


def test_ring_eyes_move_sideways_and_back_of_where_they_look():
    eyes = ring_eyes((0.0, 0.5), 8)
    assert len(eyes) == 16 and [e["ring"] for e in eyes] == [0.0] * 8 + [0.5] * 8
    for e in eyes[8:]:
        eye, look = np.array(e["eye"]), np.array(e["look"])
        assert np.linalg.norm(eye) == pytest.approx(0.5) and eye[1] == 0.0
        assert np.dot(eye, look) / 0.5 == pytest.approx(math.cos(2.0))  # 2 rad off the view direction
        vm = eye_viewmat(e["eye"], e["look"])
        assert torch.allclose(vm[2, :3], torch.tensor(look, dtype=torch.float64), atol=1e-9)
        assert torch.allclose(-vm[:3, :3].T @ vm[:3, 3], torch.tensor(eye, dtype=torch.float64), atol=1e-9)


@pytest.mark.skipif(not (SHARED / "cameras.json").is_file(), reason="the shared truth set is not on this machine")
def test_ring_eyes_are_the_shared_truth_sets_cameras():
    cams = json.loads((SHARED / "cameras.json").read_text())
    for v, e in zip(cams["views"], ring_eyes()):
        assert v["ring"] == e["ring"] and v["k"] == e["k"]
        assert np.allclose(v["viewmat"], eye_viewmat(e["eye"], e["look"]).numpy(), atol=1e-6)


def test_a_truth_set_written_from_a_scene_reads_back_with_exact_depth(tmp_path):
    from holoflow.scene import cast, scene_from_prompt

    scene = scene_from_prompt("a small wooden cabin", 0)
    write_truth_set(tmp_path / "t", scene, size=16, rings=(0.0, 0.5), per_ring=2, pano_width=64, samples=1)
    t = read_truth_set(tmp_path / "t")
    assert t.rgb.shape == (4, 16, 16, 3) and t.z.shape == (4, 16, 16) and t.rings == [0.0, 0.0, 0.5, 0.5]
    assert float(t.rgb.min()) >= 0 and float(t.rgb.max()) <= 1
    from holoflow.geometry.camera import pinhole_rays

    o, d = pinhole_rays(t.K.double(), t.viewmats[3].double(), 16, 16)  # [16, 16, 3] each
    dist = cast(scene, o.reshape(-1, 3).float(), d.reshape(-1, 3).float())[1].reshape(16, 16)
    z = dist * (d.reshape(16, 16, 3) @ t.viewmats[3, 2, :3].double()).float()
    assert torch.allclose(t.z[3], z, rtol=1e-4)
    assert json.loads((tmp_path / "t" / "cameras.json").read_text())["views"][3]["ring"] == 0.5


def _box_pano(h=64, w=128):
    """Radial depth [h, w]: a wall 3 m away everywhere, a box face 1 m away over longitudes 0..45 deg
    at the horizon, sky above 60 deg."""
    d = torch.full((h, w), 3.0)
    d[24:40, 64:80] = 1.0
    d[:5] = math.inf
    return d


def test_edge_targets_lie_on_the_near_side_of_depth_edges():
    pts, strength = viewing.edge_targets(_box_pano())
    assert len(pts) > 0 and (strength > 0.05).all()
    r = pts.norm(dim=1)
    assert torch.allclose(r, torch.ones_like(r), atol=1e-6)  # all on the box (the sky lies above 50 deg)
    assert len(viewing.edge_targets(torch.full((64, 128), 3.0))[0]) == 0


def test_novel_rig_looks_sideways_or_back_at_edge_targets():
    targets = viewing.edge_targets(_box_pano())
    vm, off = viewing.novel_rig((0.25, 0.5), 8, seed=1, targets=targets)
    again, _ = viewing.novel_rig((0.25, 0.5), 8, seed=1, targets=targets)
    assert torch.equal(vm, again)
    from holoflow.geometry.camera import camera_centers

    eyes = camera_centers(vm.double())
    fwd = vm[:, 2, :3].double()
    move = eyes / eyes.norm(dim=1, keepdim=True)
    pts = targets[0]
    hits = []
    for c in range(16):
        to = (pts - eyes[c]) / (pts - eyes[c]).norm(dim=1, keepdim=True)
        hits.append(int((to @ fwd[c]).argmax()) if (to @ fwd[c]).max() > 1 - 1e-5 else None)  # looks at a target
        if hits[-1] is not None:
            flat = pts[hits[-1]] * torch.tensor([1.0, 0, 1]).double()
            assert (flat / flat.norm()) @ move[c] <= 0.5 + 1e-9  # >= 60 deg off the move: sideways or back
    assert sum(h is not None for h in hits) >= 4  # the box spans a sixteenth of the turn
    assert hits[:8] == hits[8:]  # every distance looks at the same targets


def test_ring_strip_puts_truth_above_render():
    truth, render = torch.zeros(3, 8, 8, 3), torch.ones(3, 8, 8, 3)
    img = ts.ring_strip(truth, render, side=8, gap=2)
    assert img.shape == (18, 28, 3) and img[:8, :8].max() == 0 and img[10:, :8].min() == 255
    two = ts.ring_strip(truth, render, truth, side=8, gap=2)
    assert two.shape == (28, 28, 3) and two[20:, :8].max() == 0


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_surface_points_lie_where_the_views_depth_says(dtype):
    """surface_points: each pixel's world point is its camera z along its ray; sky stays NaN."""
    vm = eye_viewmat([0.3, 0.0, -0.2], [1.0, 0.0, 0.0])[None].to(dtype)
    K = torch.tensor([[8.0, 0, 8], [0, 8.0, 8], [0, 0, 1]], dtype=dtype)
    z = torch.full((1, 16, 16), 2.0, dtype=dtype)
    z[0, :2] = math.inf
    points, dirs = ts.surface_points(vm, K, z)
    cam = torch.einsum("ij,vhwj->vhwi", vm[0, :3, :3].double(), points) + vm[0, :3, 3].double()
    assert torch.allclose(cam[0, 2:, :, 2], torch.full((14, 16), 2.0, dtype=torch.float64), atol=1e-9)
    assert bool(torch.isnan(points[0, :2]).all()) and torch.allclose(dirs.norm(dim=-1), torch.ones(1, 16, 16).double())


def test_what_a_step_uncovers_behind_a_box_is_unseen_and_the_rest_is_seen():
    """A wall 3 m away, a box face 1 m away over longitudes 0..45 deg (``_box_pano``): from an eye moved
    0.5 m to the side, the wall just beside the box's silhouette was hidden from the centre; the box
    face, the wall far from it and the sky were seen."""
    pano = _box_pano().double()
    H, W = pano.shape
    from holoflow.geometry.sphere import equirect_directions

    dirs = equirect_directions(H, W, dtype=torch.float64)
    pts = dirs * pano[..., None]  # the panorama's own surface points
    seen = ts.seen_from_centre(pts[None], dirs[None], pano)
    assert bool(seen.all())  # from the centre everything is seen
    behind = dirs[32, 72] * 2.0  # halfway between the box (1 m) and the wall (3 m) along a box ray
    wall_behind = dirs[32, 72] * 3.0  # the wall straight behind the box face
    moved = torch.stack([behind, wall_behind, dirs[32, 20] * 3.0])[None, None]  # [1, 1, 3, 3]
    out = ts.seen_from_centre(moved, moved / moved.norm(dim=-1, keepdim=True), pano)
    assert out[0, 0].tolist() == [False, False, True]


def test_the_panorama_at_exact_surfaces_reproduces_views_of_a_flat_coloured_room():
    """panorama_at_surfaces on a room of one colour per wall direction: the colour of the direction of
    each surface point from the centre, whatever the eye."""
    from holoflow.geometry.sphere import equirect_directions

    H, W = 32, 64
    dirs = equirect_directions(H, W, dtype=torch.float64)
    pano = torch.stack([0.5 + 0.5 * dirs[..., 0], 0.5 + 0.5 * dirs[..., 1], 0.5 + 0.5 * dirs[..., 2]])  # [3, H, W]
    vm = eye_viewmat([0.4, 0.0, 0.1], [0.0, 0.0, 1.0])[None]
    K = torch.tensor([[16.0, 0, 16], [0, 16.0, 16], [0, 0, 1]])
    points, rays = ts.surface_points(vm, K, torch.full((1, 32, 32), 2.5))
    got = ts.panorama_at_surfaces(points, rays, pano)
    u = points / points.norm(dim=-1, keepdim=True)
    assert torch.allclose(got.double(), 0.5 + 0.5 * u, atol=0.03)  # bilinear on a 64 px panorama


@pytest.mark.cuda
def test_scoring_with_gsplat_matches_the_cpu_rasterizer(tmp_path):
    if not torch.cuda.is_available():
        pytest.skip("needs a CUDA device")
    pytest.importorskip("gsplat")
    from holoflow.scene import scene_from_prompt
    from holoflow.splat import GaussianModel

    write_truth_set(tmp_path / "t", scene_from_prompt("a small wooden cabin", 0), size=32, rings=(0.0, 0.5), per_ring=2)
    g = torch.Generator().manual_seed(3)
    d = torch.randn(3000, 3, generator=g)
    xyz = d / d.norm(dim=-1, keepdim=True) * 2.0  # a sphere of coloured points around the eyes
    GaussianModel.from_points(xyz.numpy(), torch.rand(3000, 3, generator=g).numpy(), opacity=0.9).save_ply(
        tmp_path / "scene.ply"
    )
    cpu, _ = ts.score_truth(tmp_path / "scene.ply", tmp_path / "t", "cpu")
    cuda, _ = ts.score_truth(tmp_path / "scene.ply", tmp_path / "t", "gsplat")  # the model is moved to the GPU
    for ring in ("0", "0.5"):
        assert abs(cuda["rings"][ring]["psnr"] - cpu["rings"][ring]["psnr"]) < 0.05, ring


def test_depth_edges_band_a_box_and_the_sky_not_a_slanted_wall():
    """depth_edges: a box 1 m away before a wall 3 m away and a strip of sky give bands 2 reach + 2 px wide
    along their borders (the pixels either side of a step, widened by ``reach``); a wall slanting away
    (z rising 2 % a pixel) has no edge."""
    z = torch.linspace(2.0, 2.0 * 1.02**31, 32).expand(1, 32, 32).clone()  # [1, 32, 32] slanting, columns
    z[0, 10:20, 10:20] = 1.0  # the box
    z[0, :3] = math.inf  # sky over the top rows
    edges = ts.depth_edges(z, reach=1)
    assert bool(edges[0, 9:21, 9:21].all()) is False  # the box's inside is no edge
    assert bool(edges[0, 9:12, 9:21].all()) and bool(edges[0, 18:21, 9:21].all())  # top and bottom borders
    assert bool(edges[0, 10:20, 9:12].all()) and bool(edges[0, 10:20, 18:21].all())  # left and right
    assert not bool(edges[0, 12:18, 12:18].any())
    assert bool(edges[0, 1:5].all())  # the sky's border (rows 2 | 3), widened by one px
    assert not bool(edges[0, 5:8].any()) and not bool(edges[0, 22:].any())  # the slanting wall


def test_ring_scores_split_the_error_between_edges_and_surfaces():
    """A render wrong only along the box's silhouette loses PSNR on the edges and none on the surfaces."""
    z = torch.full((1, 32, 32), 3.0)
    z[0, 10:20, 10:20] = 1.0
    truth = torch.rand(1, 32, 32, 3, generator=torch.Generator().manual_seed(0))
    render = truth.clone()
    render[0, 10:20, 10] = 1.0 - render[0, 10:20, 10]  # the box's left column, shifted colours
    out = ts.ring_scores(render, torch.ones(1, 32, 32), z, truth, z)
    assert out["psnr_surfaces"] == math.inf and math.isfinite(out["psnr_edges"])
    assert out["edges"] == pytest.approx(float(ts.depth_edges(z).double().mean()))
