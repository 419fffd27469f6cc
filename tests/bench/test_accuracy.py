"""holoflow bench accuracy: the sweep's points resolve against pipeline.yaml, its fits and Pareto front
are right on known data, and a two-point tiny sweep reuses upstream stages through one store."""

import csv
import math

import pytest

from holoflow.bench import accuracy as acc


@pytest.mark.parametrize("point", acc.full_points() + acc.quick_points(), ids=lambda p: p.name)
def test_every_point_resolves_against_pipeline_yaml(point):
    params = acc.resolved_params(point.profile, list(point.sets))  # raises on an unknown param
    for item in point.sets:
        stage, rest = item.split(".", 1)
        assert rest.split("=", 1)[0] in params[stage]
    assert set(acc.stage_drivers(params)) == set(acc.STAGES)


def test_fit_costs_recovers_fixed_and_linear_costs_and_names_unvaried_drivers():
    drivers = [{"it": it, "it x n": it * n, "const": 7.0} for it in (50, 100, 200) for n in (1e3, 4e3)]
    seconds = [3.0 + 0.01 * d["it"] + 2e-5 * d["it x n"] for d in drivers]
    fit = acc.fit_costs(drivers, seconds)
    assert fit["fixed"] == pytest.approx(3.0, rel=1e-6) and fit["unvaried"] == ["const"]
    assert fit["coef"] == pytest.approx({"it": 0.01, "it x n": 2e-5}, rel=1e-6)
    assert acc.predict(fit, {"it": 1000, "it x n": 1000 * 1e6, "const": 7.0}) == pytest.approx(3 + 10 + 2e4)


def test_pareto_front_keeps_only_undominated_points():
    pts = [(10.0, 30.0), (20.0, 29.0), (30.0, 35.0), (5.0, 20.0), (40.0, 35.0)]
    assert acc.pareto(pts, higher_better=True) == [3, 0, 2]
    assert acc.pareto([(t, -s) for t, s in pts], higher_better=False) == [3, 0, 2]


def test_quick_sweep_reuses_upstream_and_resumes(tmp_path):
    store, out = tmp_path / "store", tmp_path / "out.csv"
    argv = [
        "--quick",
        "--points",
        "base,iters-x0.5",
        "--store",
        str(store),
        "--csv",
        str(out),
        "--plot",
        str(tmp_path / "p.png"),
    ]
    assert acc.main(argv) == 0
    rows = list(csv.DictReader(open(out)))
    assert [r["point"] for r in rows] == ["base", "iters-x0.5"]
    assert set(rows[1]["ran"].split()) == {"pre_opt", "inp_set", "transfer_opt", "export"}  # upstream from the store
    for name in ("base_pano", "tangent_depth", "pano_set"):  # same records, same costs
        assert rows[0][f"{name}_s"] == rows[1][f"{name}_s"] and float(rows[0][f"{name}_s"]) > 0
    for r in rows:
        assert 0 < float(r["abs_rel"]) < 1 and math.isfinite(float(r["g1_novel_psnr"]))
        assert float(r["total_cpu_s"]) > 0 and int(r["g1_gaussians"]) > 0
    assert (tmp_path / "p.png").stat().st_size > 10_000
    assert acc.main(argv) == 0  # resume: nothing reruns
    again = list(csv.DictReader(open(out)))
    assert [r["ran"] for r in again] == ["", ""]
    assert [r["g1_novel_psnr"] for r in again] == [r["g1_novel_psnr"] for r in rows]


def test_profiles_skip_what_the_pipeline_lacks_and_say_why():
    import torch

    from holoflow.bench import profiles
    from holoflow.flow import pipeline

    pipe = pipeline.load(profiles.ROOT / "pipeline.yaml")
    assert "not defined in pipeline.yaml" in profiles.unavailable(pipe, "no-such-profile")
    assert profiles.unavailable(pipe, "tiny") is None and profiles.unavailable(pipe, "preview") is None
    if not torch.cuda.is_available():
        assert "need a GPU" in profiles.unavailable(pipe, "paper")


def test_profiles_block_replaces_only_its_own_markers():
    from holoflow.bench import profiles

    doc = f"# title\n\nintro\n\n{profiles.BEGIN}\nold\n{profiles.END}\n\n## after\n"
    new = profiles.replace_block(doc, f"{profiles.BEGIN}\nnew\n{profiles.END}\n")
    assert new == f"# title\n\nintro\n\n{profiles.BEGIN}\nnew\n{profiles.END}\n\n## after\n"
    assert profiles.replace_block("# t\n", "B\n") == "# t\n\nB\n"


def test_a_block_written_on_a_full_disk_leaves_the_document_whole(tmp_path, monkeypatch):
    import os

    from holoflow.bench import profiles

    doc = tmp_path / "accuracy.md"
    old = f"# title\n\n{profiles.BEGIN}\nold\n{profiles.END}\n\n## after\n"
    doc.write_text(old)
    profiles.update_block(doc, f"{profiles.BEGIN}\nnew\n{profiles.END}\n")
    assert doc.read_text() == old.replace("old", "new")

    def full(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError):
        profiles.update_block(doc, f"{profiles.BEGIN}\nnewer, cut short\n{profiles.END}\n")
    assert doc.read_text() == old.replace("old", "new") and [p.name for p in tmp_path.iterdir()] == ["accuracy.md"]


def test_profiles_measure_a_photo_at_the_viewing_size(tmp_path):
    """`bench accuracy --profiles tiny,nosuch` on a folder with one small photo: the photo is run with
    --use base_pano, scored against itself at 192 px, timed from the run records; nosuch is skipped
    with a line; the doc keeps its text outside the markers and links the pictures."""
    import json

    import numpy as np
    import OpenImageIO as oiio

    from holoflow.bench import profiles

    photos = tmp_path / "photos"
    photos.mkdir()
    x = np.linspace(0, 1, 128)[None, :, None] * np.linspace(0.2, 1, 64)[:, None, None] * np.array([1.0, 0.6, 0.3])
    out = oiio.ImageOutput.create(str(photos / "room.png"))
    out.open(str(photos / "room.png"), oiio.ImageSpec(128, 64, 3, "uint8"))
    out.write_image((x * 255).astype(np.uint8))
    out.close()
    doc = tmp_path / "docs" / "acc.md"
    doc.parent.mkdir()
    doc.write_text("# kept\n")
    argv = [
        "--profiles",
        "tiny,nosuch",
        "--scenes",
        "",
        "--photos",
        str(photos),
        "--size",
        "192",
        "--nr-cameras",
        "2",
        "--store",
        str(tmp_path / "store"),
        "--doc",
        str(doc),
        "--json",
        str(tmp_path / "p.json"),
    ]
    assert acc.main(argv) == 0
    r = json.loads((tmp_path / "p.json").read_text())
    assert r["skipped"][0].startswith("nosuch: profile 'nosuch' is not defined")
    (run,) = r["runs"]
    row, scores = run["row"], run["scores"]
    assert (row["case"], row["kind"], row["profile"]) == ("room", "photo", "tiny")
    assert scores["source"] == "photo room.png (128x64)" and scores["spec"]["size"] == 192
    assert row["wall_s"] > 0 and row["cpu_s"] > 0 and math.isfinite(row["psnr"]) and 0 <= row["empty_0.5"] <= 1
    text = doc.read_text()
    assert text.startswith("# kept\n") and profiles.BEGIN in text and "| room | tiny |" in text
    assert "- skipped: nosuch" in text and "(images/viewing-room-tiny-base.jpg)" in text
    assert (doc.parent / "images" / "viewing-room-tiny-novel.jpg").stat().st_size > 1000
