"""The run's device and profile lists: `--profile a,b` merge order, a profile's `device:`, the precedence
--device > $HOLOFLOW_DEVICE > profile > cpu, splat engine `auto`, and the `--models` manifest."""

import json
from pathlib import Path

import pytest

from holoflow.flow import context, pipeline
from holoflow.networks.manifest import apply_manifest, read_manifest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def real():
    return pipeline.load(ROOT / "pipeline.yaml")


def test_profile_list_applies_in_order(real):
    both = pipeline.resolve(real, "paper,tiny")
    assert both["base_pano"].engine == "diffusion360"  # from paper, tiny names no engine
    assert both["base_pano"].params["width"] == 128  # tiny's size wins over paper's
    assert both["pre_opt"].params["pcd_iters"] == 10 and both["pre_opt"].params["sh_degree"] == 3
    assert both["base_pano"].overrides["width"] == "profile tiny"
    assert both["base_pano"].resources.gpus == 1  # paper's key, tiny names none
    rev = pipeline.resolve(real, "tiny,paper")
    assert rev["base_pano"].params["width"] == 1024
    with pytest.raises(pipeline.PipelineError, match="unknown profile 'papr'.*did you mean 'paper'"):
        pipeline.resolve(real, "papr,tiny")


def test_profile_device(real):
    assert pipeline.profile_device(real, "paper") == "auto"
    assert pipeline.profile_device(real, "paper,tiny") == "auto"
    assert pipeline.profile_device(real, "tiny") is None
    assert pipeline.profile_device(real, None) is None


@pytest.mark.parametrize(
    "flag, env, profile, cuda, want",
    [
        (None, None, "tiny", False, "cpu"),
        (None, None, "paper", False, "cpu"),  # auto without a driver
        (None, None, "paper", True, "cuda"),  # auto with one
        ("cpu", None, "paper", True, "cpu"),  # --device wins over the profile
        (None, "cpu", "paper", True, "cpu"),  # so does $HOLOFLOW_DEVICE
        ("cuda", None, "tiny", False, "cuda"),  # explicit cuda is left to the steps
    ],
)
def test_run_device_precedence(real, monkeypatch, flag, env, profile, cuda, want):
    monkeypatch.setattr(context, "cuda_present", lambda: cuda)
    monkeypatch.delenv("HOLOFLOW_DEVICE", raising=False)
    if env:
        monkeypatch.setenv("HOLOFLOW_DEVICE", env)
    assert context.run_device(real, context.Options(profile=profile, device=flag)) == want


def test_profile_asking_for_cuda_without_it_is_one_line(real, monkeypatch):
    monkeypatch.setattr(context, "cuda_present", lambda: False)
    monkeypatch.delenv("HOLOFLOW_DEVICE", raising=False)
    monkeypatch.setitem(real.profile_devices, "paper", "cuda")
    with pytest.raises(pipeline.PipelineError, match="asks for device cuda.*--device cpu") as err:
        context.run_device(real, context.Options(profile="paper"))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("device, want", [("cuda", "gsplat"), ("cpu", "cpu")])
def test_splat_engine_auto(real, device, want):
    r = pipeline.resolve(real, "paper")
    context.resolve_device_engines(r, device)
    assert r["pre_opt"].engine == r["transfer_opt"].engine == want
    assert r["inp_set"].engine == "lama"  # not a splat engine: untouched


def test_bad_profile_device_is_refused(tmp_path):
    text = (ROOT / "pipeline.yaml").read_text().replace("    device: auto ", "    device: tpu ")
    (tmp_path / "pipeline.yaml").write_text(text)
    with pytest.raises(pipeline.PipelineError, match="asks for device 'tpu'"):
        pipeline.load(tmp_path / "pipeline.yaml")


def test_models_manifest_fills_empty_model_params(real, tmp_path):
    (tmp_path / "sd").mkdir()
    (tmp_path / "lama.safetensors").write_bytes(b"x")
    (tmp_path / "manifest.json").write_text(
        json.dumps({"format": 1, "roles": {"diffusion360": "sd", "lama": "lama.safetensors"}})
    )
    assert read_manifest(tmp_path)["lama"] == (tmp_path / "lama.safetensors").resolve()
    r = pipeline.resolve(real, "paper", ["inp_set.model=/mine/lama.safetensors"])
    only = {k: r[k] for k in ("base_pano", "inp_set")}
    apply_manifest(only, tmp_path)
    assert r["base_pano"].params["model"] == str((tmp_path / "sd").resolve())
    assert r["inp_set"].params["model"] == "/mine/lama.safetensors"  # a given param keeps its value
    with pytest.raises(pipeline.PipelineError, match="no 'sd15'.*stylize.model"):
        apply_manifest({"stylize": r["stylize"]}, tmp_path)


@pytest.mark.parametrize(
    "doc, match",
    [
        (None, "no manifest.json"),
        ("{", "not JSON"),
        ('{"format": 2, "roles": {}}', "needs"),
        ('{"format": 1, "roles": {"sdxl": "x"}}', "unknown role 'sdxl'"),
        ('{"format": 1, "roles": {"lama": "nope.pth"}}', "does not exist"),
    ],
)
def test_bad_manifest_is_one_line(tmp_path, doc, match):
    if doc is not None:
        (tmp_path / "manifest.json").write_text(doc)
    with pytest.raises(ValueError, match=match):
        read_manifest(tmp_path)
