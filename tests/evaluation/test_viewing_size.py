"""holoflow.evaluation.viewing_size: the viewing-size scorer on cases whose answer is known."""

import math

import numpy as np
import pytest
import torch

from holoflow.evaluation import viewing_size as viewing


def smooth_pano(h: int = 64, w: int = 128, seed: int = 0, cells: int = 6) -> torch.Tensor:
    """A smooth random linear panorama [3, h, w] in [0.05, 0.95] from cells x 2 cells random values."""
    g = torch.Generator().manual_seed(seed)
    lo = torch.rand(3, cells, 2 * cells, generator=g)
    x = torch.nn.functional.interpolate(lo[None], size=(h, w), mode="bicubic", align_corners=False)[0]
    return (0.05 + 0.9 * (x - x.min()) / (x.max() - x.min())).clamp(0, 1)


def pano_model(pano: torch.Tensor, radius: float = 3.0, drop=None):
    """Gaussians on a sphere of ``radius`` m, one per panorama pixel, coloured by the panorama (sRGB),
    opaque, sized to the pixel spacing; ``drop(dirs [N, 3]) -> [N] bool`` removes some."""
    from holoflow.geometry.sphere import equirect_directions
    from holoflow.imageops.color import linear_to_srgb_torch
    from holoflow.splat import GaussianModel

    H, W = pano.shape[1:]
    dirs = equirect_directions(H, W, dtype=torch.float64).reshape(-1, 3)
    rgb = linear_to_srgb_torch(pano.permute(1, 2, 0)).reshape(-1, 3).double()
    keep = torch.ones(len(dirs), dtype=torch.bool) if drop is None else ~drop(dirs)
    m = GaussianModel.from_points((dirs[keep] * radius).numpy(), rgb[keep].numpy(), opacity=0.99)
    with torch.no_grad():
        m.log_scales.fill_(math.log(radius * math.pi / H * 0.7))
    return m


def test_polar_split_picks_the_cameras_near_the_zenith_and_nadir():
    from holoflow.geometry.rigs import base_rig

    vm = base_rig(38)
    polar = viewing.polar_views(vm, 25.0)
    axis = vm[:, 2, :3].double()
    angle = torch.rad2deg(torch.acos(axis[:, 1].abs().clamp(max=1)))  # degrees to the nearer pole
    assert torch.equal(polar, angle <= 25.0)
    # the rig's layout (poles + spiral heights -1 + (2 i + 1) / 36): the two poles and the two spiral
    # cameras nearest each
    assert torch.nonzero(polar).flatten().tolist() == [0, 1, 2, 35, 36, 37]


def test_exact_reproduction_scores_infinite_and_blur_scores_lower():
    src = viewing.source_views(smooth_pano(), *_cams(), 48)
    polar = viewing.polar_views(_cams()[0], 25.0)
    same = viewing.base_scores(src, src, polar)
    assert same["psnr"] == math.inf and same["ssim"] == pytest.approx(1.0)
    blurred = torch.nn.functional.avg_pool2d(src.permute(0, 3, 1, 2), 5, 1, 2, count_include_pad=False)
    blur = viewing.base_scores(blurred.permute(0, 2, 3, 1), src, polar)
    assert 10 < blur["psnr"] < 60 and blur["ssim"] < 1.0
    assert blur["cameras"] + blur["polar_cameras"] == len(polar) and blur["polar_cameras"] == 6


def test_a_scene_of_the_source_beats_a_scene_of_its_blurred_copy():
    """Gaussians placed on a sphere with the panorama's colours, rendered by the CPU rasterizer at the
    base cameras, score high against the source's views; the same from a blurred panorama lower."""
    pano = smooth_pano(96, 192, cells=24)
    vm, K = _cams(32)
    src = viewing.source_views(pano, vm, K, 32)
    polar = viewing.polar_views(vm, 25.0)
    sharp = viewing.base_scores(viewing.render_at(pano_model(pano), vm, K, 32)[0], src, polar)
    soft = torch.nn.functional.avg_pool2d(pano[None], 9, 1, 4, count_include_pad=False)[0]
    blur = viewing.base_scores(viewing.render_at(pano_model(soft), vm, K, 32)[0], src, polar)
    assert sharp["psnr"] > 24 and sharp["psnr"] > blur["psnr"] + 3, (sharp["psnr"], blur["psnr"])


def test_an_empty_region_counts_as_empty():
    """A scene with the +z half of its sphere removed: a camera looking at +z sees nothing there."""
    pano = smooth_pano()
    model = pano_model(pano, drop=lambda d: d[:, 2] > 0.2)
    from holoflow.geometry.camera import look_at

    vm = torch.cat(
        [
            look_at(torch.zeros(1, 3), torch.tensor([[0.0, 0, 1]])),
            look_at(torch.zeros(1, 3), torch.tensor([[0.0, 0, -1]])),
        ]
    ).float()
    K = viewing.view_intrinsics(32, 60.0)
    _, alpha = viewing.render_at(model, vm, K, 32)
    r = viewing.novel_scores(alpha, torch.zeros(2), (1.0, 2.0), 0.5)
    assert r["1"]["empty"] == 1.0 and r["2"]["empty"] == 0.0
    a = torch.ones(4, 8, 8)
    a[1, :2] = 0.2  # a quarter of one image of the first distance
    r = viewing.novel_scores(a, torch.tensor([0.1, 0.2, 1.0, 1.0]), (0.25, 1.0), 0.5)
    assert r["0.25"]["empty"] == pytest.approx(1 / 8) and r["1"]["empty"] == 0.0
    assert r["0.25"]["offset_m"] == pytest.approx(0.15) and r["0.25"]["per_camera_empty"] == [0.0, 0.25]


def test_novel_rig_is_seeded_and_stays_short_of_walls():
    vm, off = viewing.novel_rig((0.25, 0.5, 1.0), 8, seed=3)
    again, _ = viewing.novel_rig((0.25, 0.5, 1.0), 8, seed=3)
    assert torch.equal(vm, again) and not torch.equal(vm, viewing.novel_rig((0.25, 0.5, 1.0), 8, seed=4)[0])
    from holoflow.geometry.camera import camera_centers

    eyes = camera_centers(vm.double())
    assert torch.allclose(
        eyes.norm(dim=1), torch.tensor([0.25] * 8 + [0.5] * 8 + [1.0] * 8, dtype=torch.float64), atol=1e-5
    )
    assert torch.allclose(eyes[:, 1], torch.zeros(24, dtype=torch.float64), atol=1e-6)  # horizontal moves
    # a wall 0.9 m away in every direction: eyes stop 0.3 m short of it
    vm, off = viewing.novel_rig((0.25, 0.5, 1.0), 8, seed=3, free=lambda d: torch.full((len(d),), 0.9))
    assert torch.allclose(off, torch.tensor([0.25] * 8 + [0.5] * 8 + [0.6] * 8, dtype=torch.float64))
    # camera k looks along its move for k mod 4 == 0, and back across the centre for k mod 4 == 2
    fwd = vm[:, 2, :3].double()
    move = eyes[:8] / eyes[:8].norm(dim=1, keepdim=True)
    assert (fwd[0] * move[0]).sum() > 0.8 and (fwd[2] * move[2]).sum() < -0.8


def test_ring_rig_is_the_truth_sets_eyes_for_every_run():
    """The rings rig: the truth sets' eyes (ring_eyes), whatever the depth: 8 a ring at 0.5 and 1 m, each
    looking horizontally sideways or back from where it moved, never along its move."""
    from holoflow.evaluation.truth_set import eye_viewmat, ring_eyes
    from holoflow.geometry.camera import camera_centers

    vm, off = viewing.ring_rig((0.5, 1.0), 8)
    eyes = ring_eyes((0.5, 1.0), 8)
    assert torch.equal(vm, torch.stack([eye_viewmat(e["eye"], e["look"]) for e in eyes]).float())
    assert off.tolist() == [0.5] * 8 + [1.0] * 8
    centres = camera_centers(vm.double())
    assert torch.allclose(centres.norm(dim=1), off, atol=1e-5)
    fwd = vm[:, 2, :3].double()  # the optical axis in world
    assert torch.allclose(fwd[:, 1], torch.zeros(16, dtype=torch.float64), atol=1e-6)
    along = (fwd * centres / centres.norm(dim=1, keepdim=True)).sum(1)
    assert float(along.max()) < 0.5  # sideways (cos 90 deg) or back, never toward the move


def test_free_distance_reads_the_depth_panorama():
    from holoflow.geometry.sphere import equirect_directions

    depth = torch.full((32, 64), 2.0)
    depth[:8] = math.inf  # sky above
    dirs = torch.tensor([[0.0, 0, 1], [0.0, -1, 0], [1.0, 0, 0]])
    d = viewing.free_distance(depth, dirs)
    assert d.tolist() == [2.0, math.inf, 2.0]
    assert torch.isfinite(viewing.free_distance(depth, equirect_directions(32, 64)[20:].reshape(-1, 3))).all()


def test_source_views_of_a_photo_are_read_from_the_recorded_file(tmp_path):
    """A --use'd photo is read from its file at full resolution; when the file changed since the run,
    the run's imported copy is used and the report says so."""
    import OpenImageIO as oiio

    from holoflow.io.exr import write_rgb
    from holoflow.io.image import read_panorama_image

    photo = tmp_path / "room.png"
    pixels = (np.random.default_rng(0).random((64, 128, 3)) * 255).astype(np.uint8)
    out = oiio.ImageOutput.create(str(photo))
    out.open(str(photo), oiio.ImageSpec(128, 64, 3, "uint8"))
    out.write_image(pixels)
    out.close()
    rgb, facts = read_panorama_image(photo)
    run = tmp_path / "run"
    (run / "base_pano").mkdir(parents=True)
    write_rgb(run / "base_pano" / "pano.exr", rgb * 0.5, {"holoflow.source_sha256": facts["sha256"]})
    info = {"stages": {"base_pano": {"how": "used", "source": str(photo)}}}
    src = viewing.run_source(run, info)
    assert src.kind.startswith("photo room.png (128x64)") and not src.notes
    assert torch.equal(src.pano, torch.from_numpy(rgb).permute(2, 0, 1))
    photo.write_bytes(photo.read_bytes() + b"x")  # the file changed since the run
    src = viewing.run_source(run, info)
    assert src.kind.startswith("imported") and "changed" in src.notes[0]
    assert torch.allclose(src.pano, torch.from_numpy(rgb * 0.5).permute(2, 0, 1))


def test_table_names_each_goal_and_whether_it_is_met():
    scores = {
        "spec": {"size": 512, "fov_deg": 47.43, "pole_deg": 25.0, "empty_alpha": 0.5, "wall_margin": 0.3, "seed": 0},
        "base": {
            "cameras": 32,
            "polar_cameras": 6,
            "psnr": 33.0,
            "ssim": 0.9,
            "polar_psnr": 30.0,
            "polar_ssim": 0.8,
            "polar_gap_db": 3.0,
        },
        "nr": {
            "cameras": 12,
            "niqe": {"render": 5.5, "source": 5.0, "ratio": 1.1},
            "brisque": None,
            "unavailable": {"brisque": "no package"},
        },
        "novel": {"0.5": {"cameras": 8, "empty": 0.001, "offset_m": 0.5}},
        "source": "photo x.jpg",
        "gaussians": 10,
    }
    text = "\n".join(viewing.table(scores, "preview"))
    assert "33.00" in text and ">= 32.00" in text and "no package" in text
    lines = {ln.split("  ")[1].strip(): ln for ln in text.splitlines() if ln.startswith("  ")}
    assert lines["base PSNR dB (32 cameras)"].endswith(" met")
    assert lines["zenith/nadir gap below the others dB"].endswith("NOT met")
    assert lines["novel 0.5 m empty % (8 cams, 0.50 m)"].endswith(" met")
    assert "1.10x" in text and ">= 37.00" in "\n".join(viewing.table(scores, "preview,quality"))


def _cams(size: int = 48):
    from holoflow.geometry.rigs import base_rig

    return base_rig(38).float(), viewing.view_intrinsics(size, viewing.PAPER_FOV_DEG)
