"""`auto` depth: a relative-depth network when its weights are on the machine (a Hugging Face cache laid
out as huggingface_hub lays it out, `--models DIR`, a path), the layout engine otherwise; an imported
panorama's own Z kept as its depth; `holoflow models pull` / `list`. Tiny random Depth Anything models
written here; nothing is downloaded (the one network call, snapshot_download, is replaced where a
download is simulated, and made to fail for real with HF_HUB_OFFLINE=1)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.models
pytest.importorskip("transformers")

ROOT = Path(__file__).resolve().parents[2]
REPO = "depth-anything/Depth-Anything-V2-Small-hf"


@pytest.fixture(scope="module")
def tiny_da(tmp_path_factory):
    from holoflow.networks.random_models import save_depth_anything

    return save_depth_anything(tmp_path_factory.mktemp("da") / "depth_anything")


@pytest.fixture(scope="module")
def room_jpg(tmp_path_factory):
    """A 256 x 128 equirect 'photo': warm floor, pale walls, a darker band of furniture."""
    from PIL import Image

    v, u = np.mgrid[0:128, 0:256].astype(np.float64)
    img = np.stack([150 + 60 * np.sin(u / 13.0), 140 + 0.6 * v, 190 - 0.8 * v], -1)
    img[80:96] *= 0.5
    path = tmp_path_factory.mktemp("photo") / "room.jpg"
    Image.fromarray(img.clip(0, 255).astype(np.uint8)).save(path, quality=95)
    return path


def hf_cache_with(tiny_da, root: Path) -> Path:
    """An HF_HOME whose hub cache holds ``tiny_da`` as the default relative-depth model."""
    from holoflow.networks.manifest import place_in_hf_cache

    place_in_hf_cache(tiny_da, REPO, root / "hub")
    return root


def holoflow(*args, hf_home: Path, offline: bool = True) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HOME": str(hf_home), "PYTHONPATH": str(ROOT)}
    env.pop("HF_HUB_CACHE", None)
    if offline:
        env["HF_HUB_OFFLINE"] = "1"
    return subprocess.run(
        [sys.executable, "-m", "holoflow", *args], cwd=ROOT, capture_output=True, text=True, timeout=600, env=env
    )


def step_meta(store: Path, stage: str) -> dict:
    from holoflow.flow.store import Store

    st = Store(store)
    key = st.run_info(st.latest_run_id())["stages"][stage]["key"]
    return st.record(key)["provenance"]["meta"]


# -- the rule --------------------------------------------------------------------------------------


def test_resolve_engine_rule():
    from holoflow.depth.engines import resolve_engine

    assert resolve_engine("auto", True)[0] == "simulated"  # library callers (bench)
    assert resolve_engine("auto", True, source="procedural", network="/w")[0] == "simulated"
    assert resolve_engine("auto", True, source="given", network="/w")[0] == "given"
    assert resolve_engine("auto", True, source="given", metric=True)[0] == "given"
    engine, why = resolve_engine("auto", False, network="/hub/models--depth-anything--Depth-Anything-V2-Small-hf/s/r")
    assert engine == "depth_anything" and "Apache-2.0" in why and "V2 Small" in why
    engine, why = resolve_engine("auto", False)
    assert engine == "layout" and "holoflow models pull" in why
    engine, why = resolve_engine("auto", False, network="/w", metric=True)
    assert engine == "layout" and "camera-height" in why
    assert resolve_engine("prior", True, source="given") == ("prior", "engine 'prior' was chosen explicitly")


def test_truth_source_reads_the_header(tmp_path):
    from holoflow.depth.engines import truth_source
    from holoflow.io.exr import write_rgb

    rgb, z = np.full((8, 16, 3), 0.5, np.float32), np.full((8, 16), 2.0, np.float32)
    for name, attrs, extra, want in [
        ("proc", {"holoflow.stage": "base_pano", "holoflow.engine": "procedural"}, {"Z": z}, "procedural"),
        ("user", {}, {"Z": z}, "given"),
        ("diff", {"holoflow.stage": "base_pano", "holoflow.engine": "diffusion360"}, {"Z": z}, "given"),
        ("noz", {"holoflow.stage": "base_pano", "holoflow.engine": "procedural"}, {}, None),
    ]:
        (tmp_path / name).mkdir()
        write_rgb(tmp_path / name / "pano.exr", rgb, attrs, **extra)
        assert truth_source(tmp_path / name) == want, name
    assert truth_source(tmp_path / "absent") is None and truth_source(None) is None


# -- the network through the common rules ------------------------------------------------------------


def test_network_depth_goes_through_alignment_blending_and_metric_rules(tiny_da):
    """The tiny network's faces are the engine's raw output, aligned and blended like any engine's
    (every equirect pixel finite); metric_align's layout rule gives radial metres, sky +inf only."""
    from holoflow.depth import panorama as pd
    from holoflow.depth.config import MetricAlignParams, TangentDepthParams
    from holoflow.networks.depth_anything import relative_disparity

    v, u = np.mgrid[0:32, 0:64].astype(np.float32)
    pano = np.stack([0.2 + 0.1 * np.sin(u / 5), 0.3 + 0.4 * (v < 12), 0.9 * (v < 12) + 0.2], -1).astype(np.float32)
    cfg = TangentDepthParams(width=64, face_size=28, grid=(2, 2), model=str(tiny_da))
    res = pd.estimate_disparity(pano, None, "depth_anything", cfg)
    faces = pd.sample_faces(
        pano, pd._np(pd.icosahedron_faces(28, cfg.padding).K), pd._np(pd.icosahedron_faces(28, cfg.padding).viewmat), 28
    ).astype(np.float32)
    assert np.array_equal(res.raw, relative_disparity(faces, str(tiny_da), side=28))
    assert res.engine["engine"] == "depth_anything" and res.engine["net_side"] == 28
    assert res.disparity.shape == (32, 64) and np.isfinite(res.disparity).all()
    ok = res.alignment.face_ok
    assert np.isnan(res.aligned[~ok]).all() and np.isfinite(res.aligned[ok]).any()
    try:
        metric = pd.metric_from_disparity(
            res.disparity, pano, None, "layout", MetricAlignParams(faces=6, face_size=16, scene="outdoor")
        )
    except ValueError as e:  # a random network may anti-correlate with the layout: refused, in one line
        assert "non-positive scale" in str(e)
        return
    d = metric.depth
    assert not np.isnan(d).any() and ((d > 0) | np.isposinf(d)).all()


# -- a photo: network when the weights are here, layout and how to get it otherwise --------------------


def test_photo_run_picks_the_network_from_the_hf_cache_and_layout_without(tiny_da, room_jpg, tmp_path):
    hf = hf_cache_with(tiny_da, tmp_path / "hf")
    store = tmp_path / "store"
    args = (
        "run",
        "a room",
        "--use",
        f"base_pano={room_jpg}",
        "--profile",
        "tiny",
        "--until",
        "tangent_depth",
        "--store",
        str(store),
    )
    done = holoflow(*args, hf_home=hf)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (
        "tangent_depth: ran" in done.stdout
        and "engine depth_anything (auto: relative depth from the network" in done.stdout
        and "V2 Small" in done.stdout
    )
    meta = step_meta(store, "tangent_depth")
    assert meta["engine"]["engine"] == "depth_anything" and REPO.replace("/", "--") in meta["engine"]["model"]
    status = holoflow("status", *args[1:6], "--store", str(store), "--json", hf_home=hf)
    assert status.returncode == 0, status.stderr[-2000:]
    assert json.loads(status.stdout)["stages"]["tangent_depth"]["state"] == "fresh"  # the key run made

    empty = holoflow(*args, hf_home=tmp_path / "empty")
    assert empty.returncode == 0, empty.stderr[-2000:]
    assert (
        "engine layout (auto: no truth depth and no depth network" in empty.stdout
        and "holoflow models pull" in empty.stdout
    )
    assert step_meta(store, "tangent_depth")["engine"]["engine"] == "layout"  # a new key: not the cached network


def test_models_dir_and_explicit_path_feed_auto(tiny_da, tmp_path):
    from holoflow.flow import pipeline
    from holoflow.networks.manifest import apply_manifest, needs

    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "manifest.json").write_text(json.dumps({"format": 1, "roles": {"depth_anything": str(tiny_da)}}))
    pipe = pipeline.load(ROOT / "pipeline.yaml")
    r = pipeline.resolve(pipe, "preview")
    apply_manifest(r, tmp_path / "m")
    assert r["tangent_depth"].params["model"] == str(tiny_da) and r["metric_align"].params["model"] == ""
    assert not needs(pipeline.resolve(pipe, "preview"))  # an auto network is listed only when asked for
    need = [n for n in needs(r) if n.stage == "tangent_depth"]
    assert need[0].present and need[0].engine == "auto -> depth_anything" and need[0].about == ""  # a folder


def test_auto_with_a_missing_explicit_model_stops_before_running(room_jpg, tmp_path):
    done = holoflow(
        "run",
        "a room",
        "--use",
        f"base_pano={room_jpg}",
        "--profile",
        "tiny",
        "--until",
        "tangent_depth",
        "--set",
        "tangent_depth.model=/nowhere/da",
        "--store",
        str(tmp_path / "s"),
        hf_home=tmp_path / "hf",
    )
    assert done.returncode != 0 and "not found locally" in done.stderr and "tangent_depth.model" in done.stderr


# -- a panorama with its own depth --------------------------------------------------------------------


def test_imported_z_is_kept_as_the_depth_and_a_replaced_z_changes_it(tmp_path):
    from holoflow.depth.panorama import resize_radial
    from holoflow.io.exr import read_exr, write_rgb

    v, u = np.mgrid[0:64, 0:128].astype(np.float64)
    rgb = np.stack([0.3 + 0.2 * np.sin(u / 9), 0.4 + 0.002 * v, 0.5 - 0.003 * v], -1).astype(np.float32)
    depths = {"a": 2.0 + 1.5 * np.sin(u / 20) ** 2 + 0.01 * v, "b": 6.0 - 0.02 * v + 0.5 * np.cos(u / 7)}
    got = {}
    for name, z in depths.items():
        write_rgb(tmp_path / f"{name}.exr", rgb, {}, Z=z.astype(np.float32))
        store = tmp_path / f"store_{name}"
        done = holoflow(
            "run",
            "a room",
            "--use",
            f"base_pano={tmp_path / f'{name}.exr'}",
            "--profile",
            "tiny",
            "--until",
            "metric_align",
            "--store",
            str(store),
            hf_home=tmp_path / "hf",
        )
        assert done.returncode == 0, done.stderr[-2000:]
        assert "engine given (auto: the imported panorama has a Z channel" in done.stdout
        meta = step_meta(store, "metric_align")
        assert meta["engine"]["engine"] == "given"
        from holoflow.flow.store import Store

        st = Store(store)
        ch, attrs = read_exr(st.run_dir(st.latest_run_id()) / "metric_align" / "depth.exr")
        assert attrs["holoflow.engine"] == "given"
        got[name] = ch["Z"]
        np.testing.assert_allclose(got[name], resize_radial(z.astype(np.float32), *got[name].shape), rtol=1e-6)
    assert not np.allclose(got["a"], got["b"])


# -- pull and list ------------------------------------------------------------------------------------


def test_pull_help_and_offline_line(tmp_path):
    helped = holoflow("models", "pull", "--help", hf_home=tmp_path / "hf")
    assert helped.returncode == 0 and "--profile" in helped.stdout and "huggingface_hub" in helped.stdout
    done = holoflow("models", "pull", hf_home=tmp_path / "hf")  # HF_HUB_OFFLINE=1: the real call refuses
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert "cannot reach the Hugging Face Hub for depth-anything/Depth-Anything-V2-Small-hf" in lines[-1]
    assert not any("Traceback" in line for line in lines)


def test_pull_offline_error_is_one_line(monkeypatch, capsys):
    import huggingface_hub
    from huggingface_hub.errors import LocalEntryNotFoundError

    from holoflow.commands.models import main

    def offline(*a, **k):
        raise LocalEntryNotFoundError("Got: ConnectError: [Errno -3] Temporary failure in name resolution")

    monkeypatch.setattr(huggingface_hub, "snapshot_download", offline)
    assert main(["pull", "zoedepth"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        "cannot reach the Hugging Face Hub for Intel/zoedepth-nyu-kitti (offline: LocalEntryNotFoundError)" in err[-1]
    )


def test_pull_then_list_shows_it_present(tiny_da, tmp_path, monkeypatch, capsys):
    """pull's download replaced by a copy of a local folder into the cache's layout; list then finds it
    there through the same lookup the runs use."""
    import huggingface_hub
    from huggingface_hub import constants

    from holoflow.commands.models import main
    from holoflow.networks.manifest import place_in_hf_cache

    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(tmp_path / "hub"))
    calls, real = [], huggingface_hub.snapshot_download

    def download(repo_id, allow_patterns=None, local_files_only=False, **kw):
        if local_files_only:  # a lookup (list, runs): the real code, untouched
            return real(repo_id, allow_patterns=allow_patterns, local_files_only=True, **kw)
        calls.append((repo_id, allow_patterns))
        return str(place_in_hf_cache(tiny_da, repo_id, tmp_path / "hub", revision="a" * 40))

    monkeypatch.setattr(huggingface_hub, "snapshot_download", download)
    assert main(["list", "--profile", "preview"]) == 0
    assert " absent " in capsys.readouterr().out
    assert main(["pull", "--profile", "preview"]) == 0
    assert calls == [(REPO, None)]
    out = capsys.readouterr()
    assert "Apache-2.0" in out.err and "present at" in out.out
    assert main(["list", "--profile", "preview"]) == 0
    listed = capsys.readouterr().out
    assert " present " in listed and "snapshots/" + "a" * 40 in listed and "licence Apache-2.0" in listed
    assert main(["pull", "archerfmy0831/sd-t2i-360panoimage/sr-base"]) == 0
    assert calls[-1] == ("archerfmy0831/sd-t2i-360panoimage", ["sr-base", "sr-base/*"])
    assert main(["pull", "lama"]) == 1 and "not a Hugging Face model id" in capsys.readouterr().err
    calls.clear()
    assert main(["pull", "--profile", "paper"]) == 0  # every HF model the paper loads; lama skipped
    assert "skipping lama" in capsys.readouterr().err and ("Intel/zoedepth-nyu-kitti", None) in calls
    assert ("archerfmy0831/sd-t2i-360panoimage", ["sd-base", "sd-base/*"]) in calls


def test_models_random_writes_only_the_roles_asked(tmp_path):
    from holoflow.commands.models import main
    from holoflow.networks.manifest import read_manifest, write_random

    assert main(["random", str(tmp_path), "--only", "depth_anything"]) == 0
    assert set(read_manifest(tmp_path)) == {"depth_anything"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["depth_anything", "manifest.json"]
    with pytest.raises(ValueError, match="unknown role"):
        write_random(tmp_path, roles=["sdxl"], progress=lambda m: None)
