"""pre_opt -> inp_set -> transfer_opt run as processes (the step protocol) on a tiny synthetic scene
with exact truth; then the schedule's claim: G1 renders novel views at least as well as G0."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from holoflow.io.exr import read_exr
from holoflow.io.ply import read_points
from holoflow.quality import metrics
from holoflow.recon.optimize import panorama_extent, render_views

from . import synth

ROOT = Path(__file__).resolve().parents[2]
SIZE = 24
TRAIN = {"densify_every": 5, "densify_from": 5, "opacity_reset_every": 0, "max_gaussians": 6000, "init_opacity": 0.5}


def run_stage(tmp: Path, stage: str, engine: str, params: dict, inputs: dict) -> tuple[Path, str]:
    job = synth.job_spec(tmp, stage, engine, params, inputs)
    proc = subprocess.run(
        [sys.executable, str(ROOT / "stages" / f"{stage}.py"), str(job)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return Path(json.loads(job.read_text())["output_dir"]), proc.stdout


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("recon")
    inputs = synth.build(tmp / "in", SIZE)
    pre, pre_log = run_stage(
        tmp,
        "pre_opt",
        "cpu",
        {"pcd_iters": 40, "pano_iters": 40, **TRAIN},
        {"cloud": inputs["cloud"], "pcd": inputs["pcd"], "pano": inputs["pano"]},
    )
    inp, inp_log = run_stage(
        tmp,
        "inp_set",
        "opencv",
        {"alpha_threshold": 0.5, "method": "telea", "radius": 3, "model": "", "observed": "render"},
        {"gaussians": pre, "pcd": inputs["pcd"]},
    )
    # no colour fit (it reads the detail panorama, which this cube-face scene has none of; the tiny
    # pipeline runs it end to end, tests/recon/test_colour_fit.py checks it)
    tr, tr_log = run_stage(
        tmp,
        "transfer_opt",
        "cpu",
        {"iters": 80, "use_inp": True, "preview_size": 32, "fit_iters": 0, **TRAIN},
        {"cloud": inputs["cloud"], "pano": inputs["pano"], "inp": inp},
    )
    return dict(inputs=inputs, pre=pre, inp=inp, transfer=tr, logs=dict(pre=pre_log, inp=inp_log, transfer=tr_log))


def _meta(stdout: str) -> dict:
    out = {}
    for line in stdout.splitlines():
        if line.startswith("@meta "):
            out.update(json.loads(line[6:]))
    return out


def test_pre_opt_writes_g0_in_3dgs_layout(chain):
    from plyfile import PlyData

    names = PlyData.read(str(chain["pre"] / "gaussians.ply"))["vertex"].data.dtype.names
    for k in [
        "x",
        "y",
        "z",
        "f_dc_0",
        "f_dc_1",
        "f_dc_2",
        "opacity",
        "scale_0",
        "scale_1",
        "scale_2",
        "rot_0",
        "rot_1",
        "rot_2",
        "rot_3",
    ]:
        assert k in names
    log = json.loads((chain["pre"] / "train_log.json").read_text())
    assert [p["name"] for p in log["phases"]] == ["pcd", "pano"]
    meta = _meta(chain["logs"]["pre"])
    assert meta["gaussians"] > 0 and meta["psnr_pano"] > 15
    xyz, _ = read_points(chain["inputs"]["cloud"] / "pf.ply")
    for phase in log["phases"]:  # every phase trains at P_f's sky-free extent
        assert phase["train"]["extent"] == pytest.approx(panorama_extent(xyz), rel=1e-12)


def test_panorama_extent_ignores_the_sky_shell():
    """Half the cloud on a 300 m sky shell, half on surfaces 2-4 m away: the extent is the surfaces'
    median distance, where the median over all points (the trainer's default) is the shell."""
    g = np.random.default_rng(0)
    d = g.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.concatenate([g.uniform(2.0, 4.0, 900), np.full(1100, 300.0)])
    xyz = (d * r[:, None]).astype(np.float32)
    assert panorama_extent(xyz) == pytest.approx(float(np.median(r[:900])), rel=1e-3)
    assert float(np.median(np.linalg.norm(xyz, axis=1))) == pytest.approx(300.0, rel=1e-4)


def test_inp_set_fills_every_missing_pixel_and_skips_complete_views(chain):
    cams = json.loads((chain["inp"] / "cameras.json").read_text())
    pcd_cams = json.loads((chain["inputs"]["pcd"] / "cameras.json").read_text())
    assert [v["viewmat"] for v in cams["views"]] == [v["viewmat"] for v in pcd_cams["views"]]
    assert (chain["inp"] / "transforms.json").is_file()
    inpainted = complete = 0
    for v in cams["views"]:
        out, _ = read_exr(chain["inp"] / v["file"])
        ren, _ = read_exr(chain["inp"] / v["file"].replace("views/", "renders/"))
        pcd, _ = read_exr(chain["inputs"]["pcd"] / v["file"])
        missing = (ren["A"] < 0.5) | (pcd["A"] < 0.5)
        assert np.array_equal(out["A"] == 0, missing)  # A records the mask
        rgb = np.stack([out[c] for c in "RGB"], -1)
        raw = np.stack([ren[c] for c in "RGB"], -1)
        assert np.isfinite(rgb).all()
        assert np.array_equal(rgb[~missing], raw[~missing])  # observed pixels kept
        if missing.any():
            inpainted += 1
            # the synthetic room has no black: a filled pixel is never left at the empty background
            assert rgb[missing].max(-1).min() > 0.02
        else:
            complete += 1
            assert np.array_equal(rgb, raw)  # not inpainted
    assert inpainted > 0 and complete > 0
    meta = _meta(chain["logs"]["inp"])
    assert meta["inpainted_views"] == inpainted


@pytest.mark.parametrize("observed", ["render", "pcd"])
def test_inp_set_inpaints_only_what_no_point_reached(chain, tmp_path, observed):
    """A PCD set with a ``seen`` channel (pcd_set with edge_threshold > 0): pixels a P_s edge point
    reached (A = 0, seen = 1) keep G0's render. observed = render: missing = rendered alpha < threshold
    OR seen = 0 (the paper's render everywhere else); observed = pcd: pixels where a point landed
    (A = 1) carry the PCD set's colour and are never missing."""
    import shutil

    from holoflow.io.exr import write_exr

    pcd = tmp_path / "pcd"
    shutil.copytree(chain["inputs"]["pcd"], pcd)
    cams = json.loads((pcd / "cameras.json").read_text())
    for v in cams["views"]:
        ch, attrs = read_exr(pcd / v["file"])
        seen = ch["A"].copy()
        seen[:, : seen.shape[1] // 2] = 1.0  # left half: reached by edge points only
        write_exr(pcd / v["file"], {**ch, "seen": seen}, attrs)
    params = {"alpha_threshold": 0.5, "method": "telea", "radius": 3, "model": "", "observed": observed}
    inp, _ = run_stage(tmp_path, "inp_set", "opencv", params, {"gaussians": chain["pre"], "pcd": pcd})
    kept = 0
    for v in cams["views"]:
        out, _ = read_exr(inp / v["file"])
        ren, _ = read_exr(inp / v["file"].replace("views/", "renders/"))
        p, _ = read_exr(pcd / v["file"])
        landed = p["A"] >= 0.5
        missing = (ren["A"] < 0.5) | (p["seen"] < 0.5)
        rgb, src = (
            np.stack([out[c] for c in "RGB"], -1),
            np.stack([(p if observed == "pcd" else ren)[c] for c in "RGB"], -1),
        )
        if observed == "pcd":
            missing &= ~landed
            np.testing.assert_allclose(rgb[landed], src[landed], atol=2e-3)  # through sRGB and back
        else:
            assert np.array_equal(rgb[~missing], src[~missing])
        assert np.array_equal(out["A"] == 0, missing)
        kept += int((~landed & (out["A"] == 1)).sum())
    assert kept > 0  # holes of A that edge points reached were not inpainted


def test_transfer_opt_writes_scene_and_previews(chain):
    from PIL import Image

    from holoflow.splat import GaussianModel

    model = GaussianModel.load_ply(chain["transfer"] / "scene.ply")
    assert len(model) > 0 and torch.isfinite(model.means).all()
    strip = Image.open(chain["transfer"] / "previews" / "look_around.png")
    assert strip.size == (8 * 32, 3 * 32)
    gif = Image.open(chain["transfer"] / "previews" / "look_around.gif")
    assert gif.n_frames == 24
    log = json.loads((chain["transfer"] / "train_log.json").read_text())
    assert log["phases"][0]["views"] == 6 + 24  # PANO + INP sets


def test_transfer_beats_pre_opt_at_novel_views(chain):
    from holoflow.geometry.camera import intrinsics_from_fov
    from holoflow.splat import GaussianModel

    vm = synth.novel_cameras(12, seed=3)
    truth, _ = synth.render_truth(vm, SIZE)
    K = intrinsics_from_fov(90.0, SIZE, SIZE).float()
    views = [dict(image=t, viewmat=m, K=K) for t, m in zip(truth, vm)]
    scores = {}
    for tag, path in (("G0", chain["pre"] / "gaussians.ply"), ("G1", chain["transfer"] / "scene.ply")):
        rgb, alpha = render_views(GaussianModel.load_ply(path), views, "cpu")
        scores[tag] = (metrics.psnr(rgb, truth), metrics.empty_fraction(alpha))
    assert scores["G1"][0] >= scores["G0"][0], scores
    assert scores["G1"][1] <= scores["G0"][1] + 1e-3, scores


def test_bad_param_is_one_line_error(tmp_path):
    inputs = {"cloud": tmp_path, "pcd": tmp_path, "pano": tmp_path}
    job = synth.job_spec(tmp_path, "pre_opt", "cpu", {"pcd_iters": -1, "pano_iters": 1, **TRAIN}, inputs)
    proc = subprocess.run(
        [sys.executable, str(ROOT / "stages" / "pre_opt.py"), str(job)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert proc.returncode != 0
    assert proc.stderr.strip().count("\n") == 0 and "pcd_iters" in proc.stderr


def test_inp_set_lama_engine_through_the_stage(chain, tmp_path):
    """The lama engine's real loading path, with a tiny random big-lama-shaped generator."""
    pytest.importorskip("safetensors")
    from holoflow.networks.random_models import save_lama

    weights = save_lama(tmp_path / "big-lama-tiny.safetensors")
    out, log = run_stage(
        tmp_path,
        "inp_set",
        "lama",
        {"alpha_threshold": 0.5, "method": "telea", "radius": 3, "model": str(weights), "observed": "pcd"},
        {"gaussians": chain["pre"], "pcd": chain["inputs"]["pcd"]},
    )
    meta = _meta(log)
    assert meta["inpainted_views"] > 0 and meta["engine"] == "lama"
    for v in json.loads((out / "cameras.json").read_text())["views"]:
        ch, _ = read_exr(out / v["file"])
        assert all(np.isfinite(ch[c]).all() for c in "RGBA")


def test_inp_set_lama_without_weights_is_one_line_error(chain, tmp_path):
    job = synth.job_spec(
        tmp_path,
        "inp_set",
        "lama",
        {
            "alpha_threshold": 0.5,
            "method": "telea",
            "radius": 3,
            "model": str(tmp_path / "nothing-here"),
            "observed": "render",
        },
        {"gaussians": chain["pre"], "pcd": chain["inputs"]["pcd"]},
    )
    proc = subprocess.run(
        [sys.executable, str(ROOT / "stages" / "inp_set.py"), str(job)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert proc.returncode != 0 and proc.stderr.strip().count("\n") == 0, proc.stderr


@pytest.mark.parametrize(
    "iters, stop, steps",
    [(200, 0.5, [50, 100]), (200, 1.0, [50, 100, 150]), (100, 0.5, [50]), (60, 0.5, []), (2000, 0.0, [])],
)
def test_densification_stops_at_densify_stop(iters, stop, steps):
    """Densify at densify_from < step <= min(densify_stop x iters, iters - densify_every)."""
    from holoflow.recon.config import PreOptParams
    from holoflow.recon.optimize import train_config

    cfg = train_config(iters, PreOptParams(densify_every=50, densify_from=40, densify_stop=stop), "cpu")
    got = [
        it for it in range(1, iters + 1) if cfg.densify_from < it < cfg.densify_until and it % cfg.densify_every == 0
    ]
    assert got == steps
    with pytest.raises(ValueError, match="densify_stop"):
        PreOptParams(densify_stop=1.5)


def test_train_seed_gives_an_independent_optimisation_and_zero_keeps_the_old_draws():
    """train_seed 0 reproduces the phase seeds (seed + 1000 i); another value changes every phase's
    view order, so `holoflow eval --repeats` measures training noise on unchanged inputs."""
    from holoflow.geometry.camera import intrinsics_from_fov, look_at
    from holoflow.recon.config import PreOptParams
    from holoflow.recon.optimize import TRAIN_SEED_STRIDE, init_model, run_phases

    g = torch.Generator().manual_seed(0)
    xyz = (torch.rand(200, 3, generator=g) * 2 - 1).numpy() + np.array([0, 0, 4], np.float32)
    rgb = (torch.rand(200, 3, generator=g) * 255).to(torch.uint8).numpy()
    eyes = torch.tensor([[0.0, 0, 0], [0.3, 0, 0], [0, 0.3, 0], [-0.3, 0, 0]], dtype=torch.float64)
    vms = look_at(eyes, eyes + torch.tensor([0.0, 0, 1], dtype=torch.float64)).float()
    K = intrinsics_from_fov(60.0, 12, 12).float()
    views = [dict(image=torch.rand(12, 12, 3, generator=g), mask=None, viewmat=vm, K=K) for vm in vms]

    def fit(train_seed):
        model = init_model(xyz, rgb, 0.5)
        params = PreOptParams(densify_every=100, densify_from=500, train_seed=train_seed)
        log = run_phases(model, [("a", views, 3), ("b", views, 3)], params, "reference", seed=7)
        return model.means.detach().clone(), [ph["train"]["seed"] for ph in log["phases"]]

    m0, s0 = fit(0)
    m0b, _ = fit(0)
    m1, s1 = fit(1)
    assert s0 == [7, 1007] and s1 == [7 + TRAIN_SEED_STRIDE, 1007 + TRAIN_SEED_STRIDE]
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert torch.equal(m0, m0b) and not torch.equal(m0, m1)


@pytest.mark.parametrize("decay, offsets, spans", [("phase", [0, 0], [3, 5]), ("model", [0, 3], [8, 8])])
def test_lr_decay_runs_once_over_the_model_or_per_phase(decay, offsets, spans):
    """lr_decay model (3DGS, the paper profile): phase 2 continues phase 1's position-lr decay and SH
    band schedule; phase (the preview default): each phase decays afresh over its own steps."""
    from holoflow.geometry.camera import intrinsics_from_fov, look_at
    from holoflow.recon.config import PreOptParams
    from holoflow.recon.optimize import init_model, run_phases

    g = torch.Generator().manual_seed(0)
    xyz = (torch.rand(50, 3, generator=g) * 2 - 1).numpy() + np.array([0, 0, 4], np.float32)
    rgb = (torch.rand(50, 3, generator=g) * 255).to(torch.uint8).numpy()
    eye = torch.zeros(1, 3, dtype=torch.float64)
    vm = look_at(eye, eye + torch.tensor([0.0, 0, 1], dtype=torch.float64)).float()[0]
    views = [
        dict(image=torch.rand(8, 8, 3, generator=g), mask=None, viewmat=vm, K=intrinsics_from_fov(60.0, 8, 8).float())
    ]
    model = init_model(xyz, rgb, 0.5, sh_degree=1)
    cfg = PreOptParams(densify_every=100, densify_from=500, lr_decay=decay, sh_degree=1)
    log = run_phases(model, [("a", views, 3), ("b", views, 5)], cfg, "reference", seed=0)
    got = [
        (ph["train"]["config"]["step_offset"], ph["train"]["config"]["lr_means_steps"] or ph["iterations"])
        for ph in log["phases"]
    ]
    assert got == list(zip(offsets, spans))
    assert model.sh_rest.shape == (50, 3, 3)  # degree 1: three higher coefficients
    with pytest.raises(ValueError, match="lr_decay"):
        PreOptParams(lr_decay="never")
