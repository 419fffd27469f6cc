"""--use, inspect (EXR/PLY), gc and pin, dag, eval/report/bench dispatch."""

import json

import numpy as np
import pytest

from holoflow.io.exr import write_rgb


def _images(project, capsys, *args):
    rc, out, err = project.cli("run", *args, "--json", capsys=capsys)
    assert rc == 0, err
    return json.loads(out)


def test_use_exr_replaces_stage_output(project, capsys, monkeypatch):
    monkeypatch.chdir(project.root)
    mine = project.root / "mine.exr"
    write_rgb(mine, np.full((2, 3, 3), 0.5, np.float32), Z=np.ones((2, 3), np.float32))
    s = _images(project, capsys, "--pipeline", "images.yaml", "--use", f"img={mine}")
    assert project.how(s) == {"img": "used", "cloud": "ran"}
    pano = project.store / "latest" / "img" / "pano.exr"  # primary name, not mine.exr
    assert pano.read_bytes() == mine.read_bytes()
    rc, out, _ = project.cli("inspect", "cloud", "--pipeline", "images.yaml", "--json", capsys=capsys)
    ply = json.loads(out)["files"]["points.ply"]
    assert ply["elements"]["vertex"]["count"] == 6
    assert ply["elements"]["vertex"]["bbox_max"] == [2.0, 1.0, 1.0]


def test_use_rejects_non_exr_and_wrong_suffix(project, capsys):
    fake = project.root / "fake.exr"
    fake.write_text("not an exr")
    rc, out, err = project.cli("run", "--pipeline", "images.yaml", "--use", f"img={fake}", capsys=capsys)
    assert rc == 2 and "does not open as EXR" in err and len(err.strip().splitlines()) == 1
    png = project.root / "pano.png"
    png.write_bytes(b"\x89PNG")
    rc, out, err = project.cli("run", "--pipeline", "images.yaml", "--use", f"img={png}", capsys=capsys)
    # an image suffix is imported as a photo now (issue 20): a broken one is one clear line
    assert rc == 2 and "OpenImageIO cannot read it" in err and len(err.strip().splitlines()) == 1
    txt = project.root / "pano.txt"
    txt.write_text("x")
    rc, out, err = project.cli("run", "--pipeline", "images.yaml", "--use", f"img={txt}", capsys=capsys)
    assert rc == 2 and "main output is pano.exr" in err


def test_use_photo_decoded_once_per_store(project, capsys, monkeypatch):
    """A photo taken again (same bytes, same decoder code) reuses its imported EXR: no decode, the same
    digest and import facts in the run record; once the object is gone from the store it decodes again."""
    import OpenImageIO as oiio

    import holoflow.io.image as image

    monkeypatch.chdir(project.root)
    photo = project.root / "room.png"
    codes = np.random.default_rng(0).integers(0, 256, (8, 16, 3)).astype(np.uint8)
    out = oiio.ImageOutput.create(str(photo))
    assert out.open(str(photo), oiio.ImageSpec(16, 8, 3, "uint8"))
    out.write_image(codes)
    out.close()
    use = ("--pipeline", "images.yaml", "--use", f"img={photo}", "--until", "img")  # the toy cloud wants Z
    first = _images(project, capsys, *use)
    pano = (project.store / "latest" / "img" / "pano.exr").resolve()

    def refuse(path):
        raise AssertionError("decoded a second time")

    monkeypatch.setattr(image, "read_panorama_image", refuse)
    again = _images(project, capsys, *use)
    assert project.how(again) == {"img": "used"}
    assert (project.store / "latest" / "img" / "pano.exr").resolve() == pano
    runs = [json.loads((project.store / "runs" / s["run"] / "run.json").read_text()) for s in (first, again)]
    assert runs[1]["stages"]["img"]["import"] == runs[0]["stages"]["img"]["import"]
    assert runs[1]["stages"]["img"]["import"]["file"] == "room.png"
    pano.unlink()  # the object left the store
    with pytest.raises(AssertionError, match="decoded a second time"):
        project.cli("run", *use, capsys=capsys)


def test_status_after_a_use_run_says_which_file_that_run_took(project, capsys, tmp_path):
    mine = tmp_path / "my text.txt"
    mine.write_text("my own text\n")
    project.run_json("--use", f"gen={mine}", capsys=capsys)
    rc, out, _ = project.cli("status", "--json", capsys=capsys)
    gen = json.loads(out)["stages"]["gen"]
    assert rc == 0 and gen["state"] == "missing"
    assert f"the latest run used {mine} (--use): holoflow status --use 'gen={mine}' shows that run" in gen["reasons"]
    rc, out, _ = project.cli("status", "--json", "--use", f"gen={mine}", capsys=capsys)
    st = json.loads(out)["stages"]
    assert {n: s["state"] for n, s in st.items()} == {"gen": "fresh", "upper": "fresh", "join": "fresh"}
    assert not any("latest run used" in r for s in st.values() for r in s["reasons"])


def test_use_text_file_and_folder_downstream_runs(project, capsys, tmp_path):
    project.run_json("p", capsys=capsys)
    mine = tmp_path / "whatever.txt"
    mine.write_text("my own text\n")
    s = project.run_json("--use", f"gen={mine}", capsys=capsys)
    assert project.how(s) == {"gen": "used", "upper": "ran", "join": "ran"}
    assert (project.store / "latest" / "upper" / "text.txt").read_text() == "MY OWN TEXT\n"
    folder = tmp_path / "outs"
    folder.mkdir()
    (folder / "text.txt").write_text("my own text\n")
    s = project.run_json("--use", f"gen={folder}", capsys=capsys)
    assert project.how(s) == {"gen": "used", "upper": "cut off", "join": "cut off"}
    other = tmp_path / "other.txt"
    other.write_text("other\n")
    s = project.run_json("--use", f"gen={other}", "--until", "gen", capsys=capsys)
    assert (project.store / "latest" / "gen" / "text.txt").read_text() == "other\n"


def test_inspect_exr_stats_and_header(project, capsys):
    _images(project, capsys, "--pipeline", "images.yaml")
    rc, out, _ = project.cli("inspect", "img", "--pipeline", "images.yaml", "--json", capsys=capsys)
    rep = json.loads(out)["files"]["pano.exr"]
    assert rep["width"] == 8 and rep["height"] == 4 and list(rep["channels"]) == ["R", "G", "B", "Z"]
    assert rep["channels"]["Z"]["posinf"] == 1 and rep["channels"]["Z"]["max"] == 2.0
    assert rep["attributes"]["holoflow.depth_kind"] == "radial"
    rc, out, _ = project.cli("inspect", str(project.store / "latest" / "img" / "pano.exr"), capsys=capsys)
    assert rc == 0 and "EXR 8 x 4" in out and "holoflow.stage: img" in out
    bad = project.root / "bad.ply"
    bad.write_text("nope")
    rc, out, err = project.cli("inspect", str(bad), capsys=capsys)
    assert rc == 2 and "not a readable PLY" in err


def test_gc_dry_run_then_yes_keeps_latest_and_pinned(project, capsys):
    first = project.run_json("p", capsys=capsys)["run"]
    second = project.run_json("--set", "upper.mode=title", capsys=capsys)["run"]
    project.run_json("--set", "upper.mode=lower", capsys=capsys)
    n_objects = sum(1 for _ in (project.store / "objects").rglob("*") if _.is_file())
    rc, out, _ = project.cli("gc", capsys=capsys)
    assert rc == 0 and "would delete 2 runs" in out and "--yes" in out
    assert sum(1 for _ in (project.store / "objects").rglob("*") if _.is_file()) == n_objects
    assert project.cli("pin", first) == 0
    rc, out, _ = project.cli("gc", "--yes", capsys=capsys)
    assert "deleted 1 runs" in out
    assert not (project.store / "runs" / second).exists() and (project.store / "runs" / first).exists()
    rc, out, _ = project.cli("verify", capsys=capsys)
    assert rc == 0
    s = project.run_json(capsys=capsys)  # the pinned default config is still cached
    assert set(project.how(s).values()) == {"cached"}
    s = project.run_json("--set", "upper.mode=title", capsys=capsys)
    assert project.how(s)["upper"] == "ran"


def test_dag_and_dispatch(project, capsys):
    rc, out, _ = project.cli("dag", "--mermaid", capsys=capsys)
    assert "gen -->|src| upper" in out and out.startswith("flowchart TD")
    from holoflow.commands import main

    assert main(["bench", "no_such_bench"]) == 2
    assert "holoflow.bench.no_such_bench is not installed" in capsys.readouterr().err
    assert main(["bench", "walking"]) == 2  # a part of bench accuracy, not a benchmark of its own
    assert "is `holoflow bench accuracy --walk --truth DIR`" in capsys.readouterr().err
