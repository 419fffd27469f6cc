"""The four panorama stage programs run as processes (docs/stage-protocol.md) at a tiny size with their
default engines: contracts, byte determinism, seams, passthrough, and one-line user errors."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from holoflow.io.exr import read_exr, read_rgb
from holoflow.scene.model import Scene

ROOT = Path(__file__).resolve().parents[2]
W, H = 96, 48


def run_stage(
    tmp: Path,
    stage: str,
    engine: str,
    params: dict,
    prompt: str = "",
    inputs: dict | None = None,
    seed: int = 0,
    name: str | None = None,
) -> subprocess.CompletedProcess:
    name = name or stage
    out, work = tmp / name / "out", tmp / name / "work"
    out.mkdir(parents=True)
    work.mkdir(parents=True)
    job = {
        "stage": stage,
        "engine": engine,
        "params": params,
        "seed": seed,
        "prompt": prompt,
        "inputs": {k: str(v) for k, v in (inputs or {}).items()},
        "output_dir": str(out),
        "work_dir": str(work),
        "device": "cpu",
    }
    (tmp / name / "job.json").write_text(json.dumps(job))
    return subprocess.run(
        [sys.executable, str(ROOT / "stages" / f"{stage}.py"), str(tmp / name / "job.json")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )


def seam_ok(img: np.ndarray) -> bool:
    img = np.clip(img, 0.0, 1.0)
    img = img if img.ndim == 3 else img[..., None]
    steps = np.abs(np.diff(img, axis=1)).mean(axis=(0, 2))
    return bool(np.abs(img[:, -1] - img[:, 0]).mean() <= np.percentile(steps, 95))


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    """base_pano -> stylize -> upscale -> detail on a tiny size, plus a second base_pano run."""
    tmp = tmp_path_factory.mktemp("stages")
    prompt = "a small kitchen with brick walls and a lamp, watercolor"
    runs = {}
    runs["base"] = run_stage(tmp, "base_pano", "procedural", {"width": W, "height": H, "samples": 2}, prompt)
    runs["base2"] = run_stage(
        tmp, "base_pano", "procedural", {"width": W, "height": H, "samples": 2}, prompt, name="base_pano_again"
    )
    base = tmp / "base_pano" / "out"
    runs["stylize"] = run_stage(
        tmp, "stylize", "classical", {"width": W, "height": H, "style": "auto"}, prompt, {"pano": base}
    )
    runs["upscale"] = run_stage(
        tmp, "upscale", "lanczos", {"width": 2 * W, "height": 2 * H}, inputs={"pano": tmp / "stylize" / "out"}
    )
    runs["detail"] = run_stage(
        tmp,
        "detail",
        "classical",
        {"width": 2 * W, "height": 2 * H, "strength": 0.5},
        prompt,
        {"pano": tmp / "upscale" / "out"},
    )
    for name, r in runs.items():
        assert r.returncode == 0, f"{name}: {r.stderr}"
    return tmp, runs


def test_base_pano_contract_and_truth(chain):
    tmp, runs = chain
    channels, attrs = read_exr(tmp / "base_pano" / "out" / "pano.exr")
    assert set(channels) == {"R", "G", "B", "Z"}
    assert all(c.shape == (H, W) for c in channels.values())
    assert attrs["holoflow.depth_kind"] == "radial" and attrs["holoflow.colorspace"] == "linear"
    assert np.isfinite(channels["Z"]).all() and (channels["Z"] > 0).all()  # a room encloses
    scene = Scene.from_json((tmp / "base_pano" / "out" / "scene.json").read_text())
    assert scene.kind == "indoor" and scene.effects.lights
    assert "@meta" in runs["base"].stdout


def test_base_pano_same_prompt_and_seed_same_bytes(chain):
    tmp, _ = chain
    for f in ("pano.exr", "scene.json"):  # the same program on the same inputs and CPU: one code path
        assert (tmp / "base_pano" / "out" / f).read_bytes() == (tmp / "base_pano_again" / "out" / f).read_bytes()


def test_stylize_upscale_detail_contracts_and_seams(chain):
    tmp, _ = chain
    sty = read_rgb(tmp / "stylize" / "out" / "pano.exr")
    lines, attrs = read_exr(tmp / "stylize" / "out" / "lineart.exr")
    assert sty.shape == (H, W, 3) and set(lines) == {"Y"} and lines["Y"].shape == (H, W)
    assert attrs["holoflow.style"] == "watercolor"
    up = read_rgb(tmp / "upscale" / "out" / "pano.exr")
    det = read_rgb(tmp / "detail" / "out" / "pano.exr")
    assert up.shape == det.shape == (2 * H, 2 * W, 3)
    for img in (read_rgb(tmp / "base_pano" / "out" / "pano.exr"), sty, lines["Y"], up, det):
        assert np.isfinite(img).all() and seam_ok(img)


def test_stylize_without_a_style_word_passes_through(chain, tmp_path):
    tmp, _ = chain
    base = tmp / "base_pano" / "out"
    r = run_stage(
        tmp_path, "stylize", "classical", {"width": W, "height": H, "style": "auto"}, "a small kitchen", {"pano": base}
    )
    assert r.returncode == 0, r.stderr
    # a copy
    np.testing.assert_array_equal(read_rgb(tmp_path / "stylize" / "out" / "pano.exr"), read_rgb(base / "pano.exr"))
    assert (tmp_path / "stylize" / "out" / "lineart.exr").exists()


def test_user_mistakes_end_in_one_line(chain, tmp_path):
    tmp, _ = chain
    r = run_stage(tmp_path, "upscale", "bicubic", {"width": W, "height": H}, inputs={"pano": tmp / "base_pano" / "out"})
    assert r.returncode != 0 and r.stderr.strip().count("\n") == 0 and "unknown engine" in r.stderr
    r = run_stage(
        tmp_path,
        "stylize",
        "classical",
        {"width": W, "height": H, "style": "cubism"},
        inputs={"pano": tmp / "base_pano" / "out"},
    )
    assert r.returncode != 0 and "unknown style" in r.stderr and r.stderr.strip().count("\n") == 0


def test_base_pano_size_zero_is_the_engines_own():
    from holoflow.scene.config import BasePanoParams

    own = BasePanoParams()  # width = height = 0
    assert own.sized_for("procedural").width == 2048 and own.sized_for("procedural").height == 1024
    assert (own.sized_for("diffusion360").width, own.sized_for("diffusion360").height) == (1024, 512)
    given = BasePanoParams(width=640, height=0).sized_for("procedural")
    assert (given.width, given.height) == (640, 320)
    assert BasePanoParams(width=640, height=300).sized_for("diffusion360").height == 300
