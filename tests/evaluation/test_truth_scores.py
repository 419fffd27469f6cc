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
    assert math.isnan(none["abs_rel"]) and none["coverage"] == 0.0


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
