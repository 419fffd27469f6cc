"""Hard inputs through `holoflow run --use base_pano=FILE` (tiny profile): odd values, sizes, channel layouts,
damaged and non-image files. Each either imports (repaired by the stated rule, said in the run's output and
the run record) with every artifact finite, +inf only in a depth channel (sky), or is refused in one line
with the store still usable (docs/hard-inputs.md)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from holoflow.io.exr import read_exr, write_exr

ROOT = Path(__file__).resolve().parents[2]
H, W = 64, 128


def _pano(h=H, w=W) -> np.ndarray:
    """A smooth linear RGB panorama [h, w, 3] in [0.05, 0.85]: a sky-to-floor gradient with stripes."""
    y = np.linspace(0, 1, h)[:, None, None]
    x = np.linspace(0, 2 * np.pi, w, endpoint=False)[None, :, None]
    return (0.45 + 0.4 * np.cos(x * 3 + np.arange(3)) * (1 - y) * y * 4 * 0.9).astype(np.float32)


def _write_image(path: Path, arr: np.ndarray, fmt: str) -> Path:
    import OpenImageIO as oiio

    arr = arr if arr.ndim == 3 else arr[..., None]
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(arr.shape[1], arr.shape[0], arr.shape[2], fmt))
    out.write_image(arr)
    out.close()
    return path


def _exr(path: Path, rgb: np.ndarray, **extra) -> Path:
    write_exr(path, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], **extra})
    return path


def _run(store: Path, src: Path, *extra: str) -> subprocess.CompletedProcess:
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        "run",
        "a room",
        "--pipeline",
        str(ROOT / "pipeline.yaml"),
        "--profile",
        "tiny",
        "--store",
        str(store),
        "--use",
        f"base_pano={src}",
        "--json",
        *extra,
    ]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)


def _non_finite(run_dir: Path) -> list[str]:
    """Every artifact of a run with a non-finite float, +inf in a Z channel excepted (sky)."""
    from plyfile import PlyData

    bad = []
    for f in sorted(p for p in run_dir.rglob("*") if p.is_file()):
        if f.suffix == ".exr":
            for name, a in read_exr(f)[0].items():
                ok = np.isfinite(a) | (np.isposinf(a) if name == "Z" else False)
                if not ok.all():
                    bad.append(f"{f.relative_to(run_dir)}:{name}")
        elif f.suffix == ".ply":
            for el in PlyData.read(str(f)).elements:
                bad += [
                    f"{f.relative_to(run_dir)}:{n}"
                    for n in el.data.dtype.names
                    if el.data[n].dtype.kind == "f" and not np.isfinite(el.data[n]).all()
                ]
    return bad


def _nan_inf_negative() -> np.ndarray:
    rgb = _pano()
    rng = np.random.default_rng(0)
    rgb[rng.random(rgb.shape[:2]) < 0.006] = np.nan  # 0.6 % NaN pixels (the file)
    rgb[3, 5:9] = np.inf
    rgb[4, 5:7] = -np.inf
    rgb[40:42] = -0.25  # negative rows
    return rgb


def test_nan_inf_negative_exr_is_repaired_and_every_artifact_is_finite(tmp_path):
    """The issue's file end to end: repaired at import by the stated rule, said on the step's line and in the
    run record, and all 13 stages' artifacts finite (the run used to end at export, step 13)."""
    src = _exr(tmp_path / "bad.exr", _nan_inf_negative())
    done = _run(tmp_path / "store", src)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "repaired R,G,B:" in done.stderr and "nan" in done.stderr and "-> 0" in done.stderr
    summary = json.loads(done.stdout)
    hows = {n: s["how"] for n, s in summary["stages"].items()}
    assert hows.pop("base_pano") == "used" and set(hows.values()) == {"ran"} and len(hows) == 12
    run_dir = tmp_path / "store" / "runs" / summary["run"]
    assert "nan" in json.loads((run_dir / "run.json").read_text())["stages"]["base_pano"]["import"]["repaired"]
    pano, attrs = read_exr(run_dir / "base_pano" / "pano.exr")
    rgb = np.stack([pano[c] for c in "RGB"], -1)
    assert np.isfinite(rgb).all() and rgb.min() >= 0.0
    assert "nan" in attrs["holoflow.import_notes"]["repaired"]
    assert _non_finite(run_dir) == []


@pytest.mark.parametrize("case", ["huge", "z_bad", "grey_png", "rgba_png", "png16", "tiff_with_nan"])
def test_odd_but_usable_files_import_finite(tmp_path, case):
    """Accepted files: the imported panorama and the colour and depth stages after it are finite."""
    rgb = _pano()
    if case == "huge":
        rgb[10:12] = 3e38  # near float32 max: squares overflow
        src = _exr(tmp_path / "huge.exr", rgb)
    elif case == "z_bad":
        z = np.full((H, W), 3.0, np.float32)
        z[:4] = np.inf  # sky: fine
        z[10, :8], z[20, :8], z[30, :8] = np.nan, -1.0, 0.0  # not: the Z channel is dropped
        src = _exr(tmp_path / "z.exr", rgb, Z=z)
    elif case == "grey_png":
        src = _write_image(tmp_path / "grey.png", (rgb[..., 0] * 255).astype(np.uint8), "uint8")
    elif case == "rgba_png":
        rgba = np.concatenate([rgb, np.full((H, W, 1), 0.5, np.float32)], -1)
        src = _write_image(tmp_path / "rgba.png", (rgba * 255).astype(np.uint8), "uint8")
    elif case == "png16":
        src = _write_image(tmp_path / "p16.png", (rgb * 65535).astype(np.uint16), "uint16")
    else:
        rgb[5, 5] = np.nan  # a float TIFF keeps NaN (RGBE .hdr cannot)
        src = _write_image(tmp_path / "p.tif", rgb, "float")
    done = _run(tmp_path / "store", src, "--until", "metric_align")
    assert done.returncode == 0, done.stderr[-2000:]
    run_dir = tmp_path / "store" / "runs" / json.loads(done.stdout)["run"]
    pano, attrs = read_exr(run_dir / "base_pano" / "pano.exr")
    assert all(np.isfinite(pano[c]).all() and pano[c].min() >= 0 and pano[c].max() <= 65504 for c in "RGB")
    if case in ("huge", "tiff_with_nan"):
        assert "repaired R,G,B:" in done.stderr
    if case == "z_bad":
        assert "Z" not in pano and "dropped Z:" in done.stderr and "1 nan" not in done.stderr
        assert "8 nan, 8 zero, 8 negative" in done.stderr
    assert _non_finite(run_dir) == []


def _truncated_jpeg(path: Path) -> Path:
    full = _write_image(path.with_name("full.jpg"), (_pano() * 255).astype(np.uint8), "uint8")
    data = full.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def _file(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _depth_exr(path: Path, z: np.ndarray) -> Path:
    write_exr(path, {"Z": z})
    return path


REFUSED = {
    "1x1": (lambda p: _write_image(p / "one.png", np.zeros((1, 1, 3), np.uint8), "uint8"), "1x1, not a 2:1"),
    "3x1": (lambda p: _write_image(p / "three.png", np.zeros((1, 3, 3), np.uint8), "uint8"), "3x1, not a 2:1"),
    "2x1_tiny": (lambda p: _exr(p / "tiny.exr", np.full((2, 4, 3), 0.5, np.float32)), "too small"),
    "non_2to1_exr": (lambda p: _exr(p / "wide.exr", np.full((64, 200, 3), 0.5, np.float32)), "200x64, not a 2:1"),
    "truncated_jpeg": (lambda p: _truncated_jpeg(p / "cut.jpg"), "is damaged (the decoder says"),
    "zero_bytes": (lambda p: _file(p / "empty.jpg", b""), "cannot read it"),
    "text_as_jpg": (lambda p: _file(p / "text.jpg", b"not a picture\n"), "cannot read it"),
    "all_nan_exr": (lambda p: _exr(p / "nan.exr", np.full((H, W, 3), np.nan, np.float32)), "no colour value is finite"),
    "z_only_bad": (lambda p: _depth_exr(p / "z.exr", np.full((H, W), -1.0, np.float32)), "depth channel Z has"),
}


def test_refused_files_fail_in_one_line_and_leave_the_store_usable(tmp_path):
    """Each refused file: exit 2 or 1 before any step runs, one line on stderr naming the file and the
    fix; the same store then verifies and serves a good import."""
    store = tmp_path / "store"
    for case, (make, words) in REFUSED.items():
        src = make(tmp_path)
        done = _run(store, src)
        assert done.returncode != 0, case
        lines = [ln for ln in done.stderr.strip().splitlines() if ln.strip()]
        assert len(lines) == 1 and words in lines[0] and "fix:" in lines[0], (case, done.stderr)
    verify = subprocess.run(
        [sys.executable, "-m", "holoflow", "verify", "--store", str(store)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert verify.returncode == 0, verify.stdout + verify.stderr
    good = _run(store, _exr(tmp_path / "good.exr", _pano()), "--until", "stylize")
    assert good.returncode == 0, good.stderr[-2000:]


def test_a_stage_writing_nan_fails_at_that_stage_in_one_line(tmp_path):
    """The finite-output guard of holoflow.stage.run_main: a step whose EXR holds a NaN exits 1 with one
    line naming the stage, the file and the channel; sky (+inf Z) passes."""
    prog = tmp_path / "nan_stage.py"
    prog.write_text(
        "import numpy as np\n"
        "from holoflow.stage import Job, run_main\n"
        "from holoflow.io.exr import write_exr\n"
        "def main():\n"
        "    job = Job.from_argv()\n"
        "    z = np.full((2, 4), np.inf, np.float32)\n"
        "    write_exr(job.output('sky.exr'), {'Z': z}, {'holoflow.depth_kind': 'radial'})\n"
        "    y = np.ones((2, 4), np.float32)\n"
        "    y[1, 2] = np.nan if job.params.get('nan') else 0.0\n"
        "    write_exr(job.output('x.exr'), {'Y': y})\n"
        "    return 0\n"
        "run_main(main, 'nan_stage')\n"
    )
    for nan, code in ((False, 0), (True, 1)):
        job = tmp_path / f"job{nan}.json"
        out = tmp_path / f"out{nan}"
        job.write_text(
            json.dumps({"stage": "nan_stage", "engine": "x", "params": {"nan": nan}, "output_dir": str(out)})
        )
        out.mkdir()
        done = subprocess.run(
            [sys.executable, str(prog), str(job)],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=120,
            env={**__import__("os").environ, "PYTHONPATH": str(ROOT)},
        )
        assert done.returncode == code, done.stderr
        if nan:
            assert done.stderr.strip() == (
                "nan_stage: non-finite output, nothing committed: x.exr: channel Y has "
                "1 NaN, 0 +inf, 0 -inf of 8 values (docs/hard-inputs.md)"
            )


@pytest.mark.parametrize("fmt", ["uint8", "uint16"])
def test_integer_codes_decode_as_the_float_read(tmp_path, fmt):
    """8 / 16-bit files are linearised through a table of every code: what the curve gives on
    OpenImageIO's own float read of the file (grey and RGBA layouts too). Equal on this machine; the
    tolerance only allows numpy's float32 pow to differ by an ulp between its SIMD and scalar loops."""
    import OpenImageIO as oiio

    from holoflow.imageops.color import srgb_to_linear
    from holoflow.io.image import read_panorama_image

    top = np.iinfo(fmt).max
    codes = np.random.default_rng(5).integers(0, top + 1, (H, W, 4)).astype(fmt)
    for name, arr in (("rgb", codes[..., :3]), ("grey", codes[..., :1]), ("rgba", codes)):
        src = _write_image(tmp_path / f"{name}.png", arr, fmt)
        inp = oiio.ImageInput.open(str(src))
        floats = np.asarray(inp.read_image(0, 0, 0, min(arr.shape[2], 4), "float"), np.float32)
        inp.close()
        want = srgb_to_linear(floats.reshape(H, W, -1))
        want = want[..., :3] if want.shape[2] >= 3 else np.repeat(want[..., :1], 3, axis=2)
        rgb, facts = read_panorama_image(src)
        np.testing.assert_allclose(rgb, want, rtol=1e-6, atol=0)
        assert rgb.dtype == np.float32 and facts["colour"] == f"sRGB {fmt} decoded to linear"
