"""The paper's path end to end: every real engine in one run (`--profile paper,tiny`) with random tiny
models of the real architectures (`holoflow models random DIR`), on the CPU in CI and with gsplat on
CUDA where a GPU is present; and what a machine with no weights says."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PROMPT = "a cozy library"
REAL = {
    "base_pano": "diffusion360",
    "stylize": "controlnet_lineart",
    "upscale": "realesrgan",
    "detail": "controlnet_tile",
    "tangent_depth": "depth_anything",
    "metric_align": "zoedepth",
    "inp_set": "lama",
}

pytestmark = [pytest.mark.models, pytest.mark.slow]


def holoflow(*args: str, hf_home: Path | None = None) -> subprocess.CompletedProcess:
    """`holoflow ARGS` in the project root; ``hf_home``: an empty HF cache (no weights on this machine)."""
    env = {**os.environ, **({"HF_HOME": str(hf_home)} if hf_home is not None else {})}
    return subprocess.run(
        [sys.executable, "-m", "holoflow", *args], cwd=ROOT, capture_output=True, text=True, timeout=900, env=env
    )


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    pytest.importorskip("diffusers")
    folder = tmp_path_factory.mktemp("models")
    done = subprocess.run(
        [sys.executable, "-m", "holoflow", "models", "random", str(folder)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads((folder / "manifest.json").read_text())["kind"] == "random"
    return folder


def run_paper_tiny(models: Path, store: Path, device: str) -> dict:
    done = holoflow(
        "run",
        PROMPT,
        "--profile",
        "paper,tiny",
        "--models",
        str(models),
        "--device",
        device,
        "--json",
        "--store",
        str(store),
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def check_summary(summary: dict, device: str, splat_engine: str) -> None:
    stages = summary["stages"]
    assert len(stages) == 13 and {s["how"] for s in stages.values()} == {"ran"}
    assert {n: stages[n]["engine"] for n in REAL} == REAL
    assert stages["pre_opt"]["engine"] == stages["transfer_opt"]["engine"] == splat_engine
    assert {s["device"] for s in stages.values()} == {device}
    assert summary["profile"] == "paper,tiny" and summary["device"] == device


def test_paper_tiny_on_cpu_runs_every_real_engine(models, tmp_path):
    check_summary(run_paper_tiny(models, tmp_path / "store", "cpu"), "cpu", "cpu")


@pytest.mark.cuda
def test_paper_tiny_on_cuda_with_gsplat(models, tmp_path):
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("needs a CUDA device")
    pytest.importorskip("gsplat")
    summary = run_paper_tiny(models, tmp_path / "store", "cuda")
    check_summary(summary, "cuda", "gsplat")
    from holoflow.flow.store import Store

    meta = Store(tmp_path / "store").record(summary["stages"]["transfer_opt"]["key"])["provenance"]["meta"]
    assert meta["backend"] == "gsplat" and meta["gpu_peak_mb"] > 0 and meta["psnr_pano"] is not None


def test_without_weights_models_list_names_all_and_run_fails_in_one_line(tmp_path):
    listing = holoflow("models", "list", "--profile", "paper", hf_home=tmp_path / "hf")
    assert listing.returncode == 0, listing.stderr
    for stage, engine in REAL.items():
        assert f" {engine} " in listing.stdout and f"{stage}.model" in listing.stdout
    assert "MISSING" in listing.stdout and "hf download" in listing.stdout
    store = tmp_path / "store"
    done = holoflow(
        "run", PROMPT, "--profile", "paper", "--device", "cpu", "--store", str(store), hf_home=tmp_path / "hf"
    )
    assert done.returncode == 2
    err = done.stderr.strip().splitlines()
    assert len(err) == 1 and "not found locally" in err[0] and "holoflow models list" in err[0]
    assert not (store / "objects").exists() or not any((store / "objects").rglob("*"))


def test_profile_asking_for_cuda_fails_in_one_line_without_it(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    pipeline = tmp_path / "pipeline.yaml"
    text = (ROOT / "pipeline.yaml").read_text().replace("    device: auto ", "    device: cuda ")
    pipeline.write_text(text)
    (tmp_path / "stages").symlink_to(ROOT / "stages")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "holoflow",
            "run",
            PROMPT,
            "--profile",
            "paper,tiny",
            "--pipeline",
            str(pipeline),
            "--dry-run",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "HOLOFLOW_DEVICE": ""},
    )
    assert done.returncode == 2 and "--device cpu" in done.stderr and len(done.stderr.strip().splitlines()) == 1
