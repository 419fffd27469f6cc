"""`holoflow eval run RUN --truth DIR` end to end: a tiny run scored against a truth set ray cast from its own
procedural scene (holoflow.evaluation.truth_set), the ring table printed, the numbers and a truth | render
picture per ring written beside the run, and the run's report showing them."""

import json

import pytest


@pytest.fixture(scope="module")
def truth_dir(two_runs, tmp_path_factory):
    """A 4-ring truth set (2 views a ring, 64 px) of the tiny run's own procedural scene."""
    from holoflow.evaluation.truth_set import write_truth_set
    from holoflow.scene.model import Scene

    store, _, _ = two_runs
    scene = Scene.from_json(((store / "latest").resolve() / "base_pano" / "scene.json").read_text())
    return write_truth_set(
        tmp_path_factory.mktemp("truth") / "cabin", scene, size=64, per_ring=2, pano_width=128, samples=1
    )


def test_eval_run_with_truth_scores_every_ring(two_runs, truth_dir, tmp_path, capsys):
    from holoflow.commands import evaluate

    store, _, _ = two_runs
    argv = ["--run", "latest", "--store", str(store), "--truth", str(truth_dir), "--size", "64", "--nr-cameras", "0"]
    assert evaluate.main(argv) == 0
    printed = capsys.readouterr().out
    folder = (store / "latest").resolve() / "eval"
    r = json.loads((folder / "truth-cabin.json").read_text())
    assert list(r["rings"]) == ["0", "0.25", "0.5", "1"] and r["views"] == 8
    for key, ring in r["rings"].items():
        assert ring["views"] == 2 and 5 < ring["psnr"] < 60 and 0 <= ring["cracked"] <= 1
        assert ring["empty"] <= ring["cracked"] and 0 < ring["delta1"] <= 1 and ring["abs_rel"] < 0.5
        assert 0.8 < ring["scale"] < 1.25  # the cabin's own depth: its size within a few per cent
        assert (folder / f"truth-cabin-ring-{key}.png").stat().st_size > 1000
    assert r["rings"]["0"]["psnr"] > 15  # the centre's own views of its own scene
    assert (
        "0.5 m" in printed and "a<0.9 %" in printed and " scale " in printed and "novel 0.5 m alpha < 0.9 %" in printed
    )
    v = json.loads((folder / "viewing.json").read_text())
    assert 0 <= v["novel"]["0.5"]["cracked"] <= 1 and v["novel"]["0.5"]["empty"] <= v["novel"]["0.5"]["cracked"]

    # the new spelling, into another folder; a folder that is no truth set is a user mistake
    assert (
        evaluate.main(
            [
                "run",
                "latest",
                "--store",
                str(store),
                "--truth",
                str(truth_dir),
                "--size",
                "64",
                "--nr-cameras",
                "0",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 0
    )
    assert json.loads((tmp_path / "o" / "truth-cabin.json").read_text())["rings"] == r["rings"]
    assert evaluate.main(["run", "latest", "--store", str(store), "--truth", str(tmp_path)]) == 2

    from holoflow.flow.store import Store
    from holoflow.report import build
    from holoflow.report.runinfo import collect

    html = build(collect(Store(store), "latest"), render_clouds=False, view_size=0)
    assert "walking: against the truth set cabin" in html
    assert all(f"ring {k} m: truth above render" in html for k in r["rings"])
