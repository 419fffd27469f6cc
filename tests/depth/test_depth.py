"""Panorama depth: metrics, robust fits, face alignment, engines (incl. the simulation's calibration),
hard cases and the two stage programs. Small faces (16-48 px) keep the whole file well under a minute."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from holoflow.depth import panorama as pd
from holoflow.depth.accuracy import depth_metrics
from holoflow.depth.config import MetricAlignParams, TangentDepthParams
from holoflow.depth.engines import layout_radial_depth, simulated_relative
from holoflow.depth.face_alignment import align_faces
from holoflow.depth.faces import face_rays, find_overlaps
from holoflow.depth.metric_alignment import disparity_to_depth, robust_affine_fit, sky_mixed_edges

ROOT = Path(__file__).resolve().parents[2]


def _scene_radial(dirs):
    """A room with two spheres: radial depth [...] of unit directions [..., 3] (numpy, analytic)."""
    r = layout_radial_depth(dirs, {"floor": 1.5, "ceiling": 1.2, "wall": 3.5})
    for c, rad in (((1.0, 0.5, 2.0), 0.6), ((-1.5, 0.8, -1.0), 0.5)):
        c = np.array(c)
        b = dirs @ c
        disc = b**2 - (c @ c - rad**2)
        t = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)
        r = np.where((t > 0) & (t < r), t, r)
    return r


@pytest.fixture(scope="module")
def faces32():
    faces = pd.icosahedron_faces(32, 0.3)
    K, V = pd._np(faces.K), pd._np(faces.viewmat)
    dirs, cos = face_rays(K, V, 32, 32)
    return K, V, dirs, cos, find_overlaps(K, V, 32, 32)


@pytest.fixture(scope="module")
def room_pano():
    """A 64 x 32 panorama of the analytic room: linear RGB (shading by depth) and truth radial depth."""
    import torch

    from holoflow.geometry.sphere import equirect_directions

    dirs = equirect_directions(32, 64, dtype=torch.float64).numpy()
    r = _scene_radial(dirs)
    rgb = np.repeat((0.2 + 0.6 / r)[..., None], 3, -1).astype(np.float32)
    return rgb, r


# --- metrics and fits -------------------------------------------------------------------------------


def test_depth_metrics_values_sky_and_misses():
    t = np.array([1.0, 2.0, 4.0, np.inf])
    m = depth_metrics(np.array([1.1, 2.0, 4.0, 5.0]), t)
    assert m["n"] == 3 and m["sky_false"] == 1.0
    assert m["abs_rel"] == pytest.approx(0.1 / 3) and m["rmse"] == pytest.approx(np.sqrt(0.01 / 3))
    assert m["delta1"] == 1.0 and m["coverage"] == 1.0
    miss = depth_metrics(np.array([np.inf, 2.0, np.nan, np.inf]), t)
    assert miss["coverage"] == pytest.approx(1 / 3) and miss["delta1"] == pytest.approx(1 / 3)
    assert miss["abs_rel"] == 0.0 and miss["sky_false"] == 0.0
    assert np.isnan(depth_metrics(np.ones(2), np.full(2, np.inf))["abs_rel"])


def test_robust_fit_ignores_outliers_and_fails_clearly():
    rng = np.random.default_rng(0)
    x = rng.uniform(0.5, 3.0, 2000)
    y = 0.7 * x + 0.2
    y[:300] *= rng.uniform(2, 5, 300)  # 15% gross outliers
    fit = robust_affine_fit(x, y)
    assert fit["scale"] == pytest.approx(0.7, rel=1e-3) and fit["offset"] == pytest.approx(0.2, abs=2e-3)
    with pytest.raises(ValueError, match="constant"):
        robust_affine_fit(np.ones(10), np.linspace(1, 2, 10))
    with pytest.raises(ValueError, match="usable"):
        robust_affine_fit(np.ones(3), np.array([np.inf, np.nan, -1.0]))


def test_disparity_to_depth_sky_and_nonfinite():
    z = disparity_to_depth(np.array([1.0, 0.0, np.nan, -1.0, 0.5]), 2.0, 0.0, max_depth=100.0)
    assert z[0] == 0.5 and z[4] == 1.0 and np.isposinf(z[1:4]).all()


def test_sky_edge_mixtures_become_sky_and_nothing_else_moves():
    """A building at 20 m under the sky, its border blurred as face blending blurs it: the mixed pixels
    hold up to 3 km. Mostly-sky mixtures become sky, mostly-building ones stay (but for those within 2
    pixels of a pole over twice as near, documented); the rest, the far ground and the seam (columns
    wrap) stay bit for bit."""
    H, W = 32, 64
    disp = np.zeros((H, W))
    disp[10:] = 1 / 20.0  # building (rows 10..), sky above
    disp[20:] = 1 / np.linspace(200.0, 2.0, H - 20)[:, None]  # ground from far (row 20) to near
    disp[12:, 30:34] = 1 / 8.0  # a nearer pole below the building's top
    disp[10] *= 0.3  # a 2-pixel mixture: 30 % and 70 % building
    disp[11] *= 0.7
    depth = disparity_to_depth(disp, 1.0, 0.0, max_depth=3000.0)
    out = sky_mixed_edges(depth)
    assert np.isposinf(out[10]).all()  # mostly sky -> sky
    beside_pole = np.zeros(W, bool)
    beside_pole[28:36] = True
    assert np.isposinf(out[11, beside_pole]).all()
    # bit-equal on any CPU: the output is the input or +inf (a select), chosen by 1/x and min / max filters
    # (correctly rounded or exact in any order and SIMD width)
    assert np.array_equal(out[11, ~beside_pole], depth[11, ~beside_pole])  # mostly building: kept
    assert np.array_equal(out[12:], depth[12:])  # away from the sky: untouched
    assert np.array_equal(sky_mixed_edges(np.roll(depth, 32, axis=1)), np.roll(out, 32, axis=1))
    no_sky = np.where(np.isfinite(depth), depth, 500.0)
    assert np.array_equal(sky_mixed_edges(no_sky), no_sky)  # nothing to do without sky


# --- alignment --------------------------------------------------------------------------------------


def test_alignment_recovers_per_face_affine(faces32):
    """Exact disparities under an unknown affine map per face: affine and grid restore one consistent
    radial disparity (up to a global affine map); the naive median cannot undo the shifts."""
    K, V, dirs, cos, ov = faces32
    r = _scene_radial(dirs)
    rng = np.random.default_rng(1)
    raw = rng.uniform(0.3, 3, (20, 1, 1)) / (r * cos) + rng.uniform(0, 0.3, (20, 1, 1))
    truth = 1.0 / r
    errs = {}
    for method in ("median", "affine", "grid"):
        al = align_faces(raw, np.ones_like(raw, bool), cos, ov, TangentDepthParams(align=method, grid=(3, 3)))
        fit = robust_affine_fit(al.radial.ravel(), truth.ravel())
        pred = fit["scale"] * al.radial + fit["offset"]
        errs[method] = float(np.mean(np.abs(pred - truth) / truth))
        assert np.isfinite(al.radial).all() and al.face_ok.all()
    assert errs["affine"] < 1e-3 and errs["grid"] < 2e-3 and errs["median"] > 0.02
    al = align_faces(raw, np.ones_like(raw, bool), cos, ov, TangentDepthParams(align="grid", grid=(3, 3)))
    assert al.scale.shape == (20, 3, 3) and al.residuals["rel_mean_abs"] < 5e-3


def test_grid_beats_affine_beats_median_on_simulated_faces(faces32):
    K, V, dirs, cos, ov = faces32
    r = _scene_radial(dirs)
    raw = simulated_relative(r, cos, seed=3)
    truth = 1.0 / r
    errs = {}
    for method in ("median", "affine", "grid"):
        al = align_faces(raw, np.isfinite(raw), cos, ov, TangentDepthParams(align=method, grid=(4, 4)))
        fit = robust_affine_fit(al.radial.ravel(), truth.ravel())
        errs[method] = float(np.mean(np.abs(fit["scale"] * al.radial + fit["offset"] - truth) / truth))
    assert errs["grid"] < errs["affine"] < errs["median"], errs


# --- the simulated engine's calibration -------------------------------------------------------------


def _best_affine_abs_rel(raw, z):
    """AbsRel (in disparity) of each face's raw disparity after its best scale + shift vs 1 / z."""
    out = []
    for f in range(raw.shape[0]):
        ok = np.isfinite(z[f])
        A = np.stack([raw[f][ok], np.ones(ok.sum())], 1)
        coef, *_ = np.linalg.lstsq(A, 1.0 / z[f][ok], rcond=None)
        out.append(np.mean(np.abs(A @ coef - 1.0 / z[f][ok]) * z[f][ok]))
    return float(np.mean(out))


def test_simulated_relative_is_calibrated_like_a_network():
    """After the best single scale + shift per face, the simulation stays ~0.10 AbsRel off (paper: 0.116
    for Depth Anything through 360MonoDepth), with a smooth (low-frequency) part, not just white noise,
    and larger errors at depth edges (mixing)."""
    import scipy.ndimage as ndi

    faces = pd.icosahedron_faces(64, 0.3)
    K, V = pd._np(faces.K), pd._np(faces.viewmat)
    dirs, cos = face_rays(K, V, 64, 64)
    r = _scene_radial(dirs)
    raw = simulated_relative(r, cos, seed=0).astype(np.float64)
    z = r * cos
    assert 0.07 <= _best_affine_abs_rel(raw, z) <= 0.13
    rel = []
    for f in range(20):  # relative residual map after the best affine fit
        A = np.stack([raw[f].ravel(), np.ones(raw[f].size)], 1)
        coef, *_ = np.linalg.lstsq(A, 1.0 / z[f].ravel(), rcond=None)
        rel.append((A @ coef * z[f].ravel() - 1).reshape(64, 64))
    rel = np.array(rel)
    smooth = np.array([ndi.gaussian_filter(e, 4) for e in rel])
    assert smooth.std() > 0.6 * rel.std()  # mostly low-frequency
    logr = np.log(r)  # depth discontinuities: a 3 x 3 neighbour more than 20% nearer or farther
    edges = np.array([ndi.maximum_filter(lf, 3) - ndi.minimum_filter(lf, 3) for lf in logr]) > 0.2
    assert np.abs(rel - smooth)[edges].mean() > 1.5 * np.abs(rel - smooth)[~edges].mean()
    again = simulated_relative(r, cos, seed=0)
    # seeded; same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(again, raw.astype(np.float32))


# --- hard cases -------------------------------------------------------------------------------------


def test_bad_engine_values_and_empty_face_stay_finite(faces32):
    K, V, dirs, cos, ov = faces32
    raw = simulated_relative(_scene_radial(dirs), cos, seed=4).astype(np.float64)
    raw[0, :5] = np.nan
    raw[1, :, :3] = np.inf
    raw[2, 10:12] = -5.0
    raw[3] = np.nan  # a face with no valid pixel
    al = align_faces(raw, np.isfinite(raw), cos, ov, TangentDepthParams(align="grid", grid=(3, 3)))
    assert not al.face_ok[3] and "3" in al.residuals["dropped_faces"]
    disp = pd.blend_faces(al.radial, np.ones_like(raw), K, V, 16, 32)
    assert np.isfinite(disp).all()


def test_negative_scale_face_is_dropped(faces32):
    K, V, dirs, cos, ov = faces32
    raw = 1.0 / (_scene_radial(dirs) * cos)
    raw[5] = -raw[5]  # an engine that inverted one face
    al = align_faces(raw, np.ones_like(raw, bool), cos, ov, TangentDepthParams(align="median"))
    assert not al.face_ok[5] and "median" in al.residuals["dropped_faces"]["5"]
    for method in ("affine", "grid"):
        al = align_faces(raw, np.ones_like(raw, bool), cos, ov, TangentDepthParams(align=method, grid=(2, 2)))
        assert np.isfinite(al.radial[al.face_ok]).all()
        assert (al.scale.reshape(20, -1).mean(1)[al.face_ok] > 0).all()


def test_constant_and_all_sky(room_pano):
    rgb, r = room_pano
    sky = np.full_like(r, np.inf)
    res = pd.estimate_disparity(rgb, sky, "simulated", TangentDepthParams(face_size=16, grid=(2, 2)))
    assert np.isfinite(res.disparity).all()
    with pytest.raises(ValueError):  # nothing metric to fit against, or a constant disparity
        pd.metric_from_disparity(res.disparity, rgb, sky, "simulated", MetricAlignParams(faces=3, face_size=16))
    with pytest.raises(ValueError, match="constant"):
        pd.metric_from_disparity(np.ones_like(r), rgb, r, "simulated", MetricAlignParams(faces=3, face_size=16))
    const = align_faces(
        np.ones((20, 8, 8)),
        np.ones((20, 8, 8), bool),
        np.ones((20, 8, 8)),
        find_overlaps(
            *[pd._np(x) for x in (pd.icosahedron_faces(8, 0.3).K, pd.icosahedron_faces(8, 0.3).viewmat)], 8, 8
        ),
        TangentDepthParams(),
    )
    assert np.isfinite(const.radial).all()


def test_negative_metric_scale_is_a_clear_error(room_pano):
    rgb, r = room_pano
    with pytest.raises(ValueError, match="non-positive scale"):
        pd.metric_from_disparity(-1.0 / r, rgb, r, "simulated", MetricAlignParams(faces=4, face_size=16))


def test_tiny_panorama_and_prior_engine():
    rgb = np.random.default_rng(0).random((4, 8, 3)).astype(np.float32)
    res = pd.estimate_disparity(rgb, None, "prior", TangentDepthParams(face_size=8, grid=(2, 2)))
    assert res.disparity.shape == (4, 8) and np.isfinite(res.disparity).all()
    md = pd.metric_from_disparity(res.disparity, rgb, None, "prior", MetricAlignParams(faces=3, face_size=8))
    assert np.isfinite(md.depth).all() and (md.depth > 0).all()
    with pytest.raises(ValueError, match="truth"):
        pd.estimate_disparity(rgb, None, "simulated", TangentDepthParams(face_size=8))


def test_pipeline_accuracy_on_analytic_room(room_pano):
    """End to end with the simulated engines: grid alignment + metric step lands near the goal."""
    rgb, r = room_pano
    res = pd.estimate_disparity(rgb, r, "simulated", TangentDepthParams(face_size=32, grid=(4, 4)))
    md = pd.metric_from_disparity(res.disparity, rgb, r, "simulated", MetricAlignParams(faces=6, face_size=32))
    m = pd.score(md.depth, r)
    assert m["abs_rel"] < 0.08 and m["delta1"] > 0.95 and m["coverage"] == 1.0
    again = pd.estimate_disparity(rgb, r, "simulated", TangentDepthParams(face_size=32, grid=(4, 4)))
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(again.disparity, res.disparity)


# --- the stage programs -----------------------------------------------------------------------------


def _run_stage(tmp_path, stage, engine, params, inputs):
    out = tmp_path / f"{stage}_{engine}_out"
    out.mkdir()
    job = {
        "stage": stage,
        "engine": engine,
        "params": params,
        "seed": 0,
        "prompt": "",
        "inputs": {k: str(v) for k, v in inputs.items()},
        "output_dir": str(out),
        "work_dir": str(tmp_path / "work"),
        "device": "cpu",
    }
    (tmp_path / f"{stage}.json").write_text(json.dumps(job))
    proc = subprocess.run(
        [sys.executable, str(ROOT / "stages" / f"{stage}.py"), str(tmp_path / f"{stage}.json")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    return proc, out


def test_stages_write_contract_and_metrics(tmp_path, room_pano):
    from holoflow.io.exr import read_exr, write_rgb

    rgb, r = room_pano
    src = tmp_path / "base"
    src.mkdir()
    write_rgb(src / "pano.exr", rgb, {"holoflow.depth_kind": "radial"}, Z=r.astype(np.float32))
    proc, td = _run_stage(
        tmp_path,
        "tangent_depth",
        "simulated",
        {
            "width": 64,
            "face_size": 16,
            "padding": 0.3,
            "grid": [3, 3],
            "smoothness": 1.0,
            "scale_reg": 0.01,
            "blend_ramp": 0.5,
            "align": "grid",
            "model": "",
        },
        {"pano": src, "truth": src},
    )
    assert proc.returncode == 0, proc.stderr
    ch, attrs = read_exr(td / "disparity.exr")
    assert attrs["holoflow.depth_kind"] == "disparity" and attrs["holoflow.simulation"] == 1
    assert ch["Y"].shape == (32, 64) and np.isfinite(ch["Y"]).all()
    assert sorted(read_exr(td / "faces" / "face_07.exr")[0]) == ["aligned.Y", "raw.Y"]
    assert "rel_rms" in json.loads((td / "alignment.json").read_text())["residuals"]
    assert "truth_oracle_affine" in proc.stdout
    prog = [json.loads(line[10:]) for line in proc.stdout.splitlines() if line.startswith("@progress ")]
    assert prog and prog[-1] == {"done": 20, "total": 20, "what": "faces"}
    proc, ma = _run_stage(
        tmp_path,
        "metric_align",
        "simulated",
        {"faces": 4, "face_size": 16, "model": ""},
        {"disparity": td, "pano": src, "truth": src},
    )
    assert proc.returncode == 0, proc.stderr
    ch, attrs = read_exr(ma / "depth.exr")
    assert attrs["holoflow.depth_kind"] == "radial" and (ch["Z"] > 0).all()
    rep = json.loads((ma / "metric_align.json").read_text())
    assert rep["truth_metrics"]["abs_rel"] < 0.15 and len(rep["faces"]) == 4
    meta = [json.loads(line[6:]) for line in proc.stdout.splitlines() if line.startswith("@meta ")]
    assert meta and "truth_metrics" in meta[0]


def test_unknown_engines_fail_clearly(room_pano):
    rgb, r = room_pano
    with pytest.raises(ValueError, match="unknown relative depth engine"):
        pd.estimate_disparity(rgb, r, "nonesuch", TangentDepthParams(face_size=8))
    with pytest.raises(ValueError, match="unknown metric depth engine"):
        pd.metric_from_disparity(1.0 / r, rgb, r, "nonesuch", MetricAlignParams(faces=2, face_size=8))
    with pytest.raises(ValueError, match="align='nonesuch' is not one of median, affine, grid"):
        pd.estimate_disparity(rgb, r, "prior", TangentDepthParams(face_size=8, align="nonesuch"))


def test_real_engines_get_linear_faces_and_progress_takes_what(monkeypatch, room_pano):
    """The real engines encode sRGB themselves (docs/conventions.md: EXR colour is linear light), so the depth code
    must hand them the *linear* faces: an encode here too would be a double encode. Their progress
    callbacks are called (done, total, what), as holoflow.stage.Job.progress takes them."""
    from holoflow.imageops.color import linear_to_srgb
    from holoflow.networks import depth_anything, zoedepth

    rgb, r = room_pano
    faces = pd.icosahedron_faces(16, 0.3)
    K, V = pd._np(faces.K), pd._np(faces.viewmat)
    linear = pd.sample_faces(rgb, K, V, 16)  # [20, 16, 16, 3]
    dirs, cos = face_rays(K, V, 16, 16)
    z = _scene_radial(dirs) * cos  # what a perfect network would see, per face
    seen = {}

    def fake(kind, make):
        def engine(images, model="", device="cpu", progress=None, **kw):
            seen[kind] = np.array(images)
            progress(0, len(images), "images")  # a 2-argument callback raises TypeError here
            progress(len(images), len(images), "images")
            which = [int(np.argmin(np.abs(linear - im).sum((1, 2, 3)))) for im in np.asarray(images)]
            return make(z[which])

        return engine

    monkeypatch.setattr(depth_anything, "relative_disparity", fake("da", lambda zf: 2.0 / zf + 0.3))
    monkeypatch.setattr(zoedepth, "metric_depth", fake("zd", lambda zf: zf))
    calls = []
    progress = lambda done, total, what: calls.append((done, total, what))  # noqa: E731
    res = pd.estimate_disparity(
        rgb, None, "depth_anything", TangentDepthParams(face_size=16, padding=0.3, grid=(2, 2)), progress=progress
    )
    md = pd.metric_from_disparity(
        res.disparity, rgb, None, "zoedepth", MetricAlignParams(faces=3, face_size=16), progress=progress
    )
    assert np.allclose(seen["da"], linear, atol=1e-6)
    assert np.allclose(seen["zd"], linear[md.faces], atol=1e-6)
    assert not np.allclose(seen["da"], linear_to_srgb(linear, clip=True), atol=0.05)  # an encode would show
    assert calls == [(0, 20, "images"), (20, 20, "images"), (0, 3, "images"), (3, 3, "images")]
    # the engines' own encode: linear 0.18 is sRGB 0.4614 -> 118 (a second encode would give 179)
    assert depth_anything.to_uint8_srgb(np.full((1, 1, 1, 3), 0.18, np.float32)).ravel().tolist() == [118] * 3


@pytest.mark.slow
@pytest.mark.models
def test_real_engines_dispatch_with_tiny_random_models(tmp_path, room_pano):
    """depth_anything / zoedepth engines through the whole depth path (tiny random local models)."""
    pytest.importorskip("transformers")
    from holoflow.networks.random_models import save_depth_anything, save_zoedepth

    rgb, r = room_pano
    da = save_depth_anything(tmp_path / "da")
    zd = save_zoedepth(tmp_path / "zd")
    res = pd.estimate_disparity(
        rgb, None, "depth_anything", TangentDepthParams(face_size=16, grid=(2, 2), model=str(da))
    )
    assert res.engine["engine"] == "depth_anything" and np.isfinite(res.disparity).all()
    # the seeded random models (seed 0) give a disparity that grows with zoedepth's: a fit scale near 160
    md = pd.metric_from_disparity(
        res.disparity, rgb, None, "zoedepth", MetricAlignParams(faces=2, face_size=16, model=str(zd))
    )
    assert md.engine["engine"] == "zoedepth" and len(md.faces) == 2
    assert md.fit["scale"] > 0 and md.depth.shape == res.disparity.shape
    assert np.isfinite(md.depth).all() and (md.depth > 0).all()


@pytest.mark.parametrize("relative_engine,noted", [("simulated", True), ("layout", False)])
def test_a_refined_depth_says_the_noise_it_had_before_the_planes(relative_engine, noted):
    """metric_align's refinement lays most of a room exactly on its planes, which leaves no noise to
    measure; the fit records the network depth's noise from before them (point_cloud's smoothing reads
    it from depth.exr's header), and only when it refined."""
    import torch

    from holoflow.geometry.sphere import equirect_directions
    from holoflow.geometry.surfaces import depth_noise

    dirs = equirect_directions(128, 256, dtype=torch.float64).numpy()
    r = _scene_radial(dirs)
    rgb = np.repeat((0.2 + 0.6 / r)[..., None], 3, -1).astype(np.float32)
    noisy = r * np.exp(0.02 * np.random.default_rng(0).standard_normal(r.shape))
    out = pd.metric_from_disparity(
        1.0 / noisy, rgb, r, "simulated", MetricAlignParams(faces=4, face_size=32), relative_engine=relative_engine
    )
    assert ("depth_noise" in out.fit) is noted
    if noted:
        assert out.fit["depth_noise"] > 0.01  # the 2 % noise, not the planes' none
        assert depth_noise(torch.from_numpy(out.depth.astype(np.float64))) < 0.5 * out.fit["depth_noise"]
