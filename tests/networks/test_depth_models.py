"""Depth engines: tiny Depth Anything and ZoeDepth (real transformers architectures), saved with
save_pretrained and loaded through the engines' own from_pretrained path."""

import numpy as np
import pytest

pytestmark = pytest.mark.models
transformers = pytest.importorskip("transformers")


@pytest.fixture(scope="module")
def images():
    rng = np.random.default_rng(0)
    return rng.random((3, 24, 40, 3), dtype=np.float32)


@pytest.fixture(scope="module")
def tiny_depth_anything(tmp_path_factory):
    from holoflow.networks.random_models import save_depth_anything

    return save_depth_anything(tmp_path_factory.mktemp("depth_anything"))


@pytest.fixture(scope="module")
def tiny_zoedepth(tmp_path_factory):
    from holoflow.networks.random_models import save_zoedepth

    return save_zoedepth(tmp_path_factory.mktemp("zoedepth"))


def test_depth_anything_contract(tiny_depth_anything, images):
    from holoflow.networks.depth_anything import relative_disparity

    calls = []
    disp = relative_disparity(
        images, model=str(tiny_depth_anything), batch=2, progress=lambda d, t, w: calls.append((d, t))
    )
    assert disp.shape == (3, 24, 40) and disp.dtype == np.float32 and np.isfinite(disp).all()
    assert disp.std() > 0 and calls[-1] == (3, 3)
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(disp, relative_disparity(images, model=str(tiny_depth_anything)))


def test_zoedepth_contract(tiny_zoedepth, images):
    from holoflow.networks.zoedepth import metric_depth

    depth = metric_depth(images, model=str(tiny_zoedepth))
    assert depth.shape == (3, 24, 40) and depth.dtype == np.float32
    assert np.isfinite(depth).all() and depth.min() > 0
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(depth, metric_depth(images, model=str(tiny_zoedepth)))


def test_zoedepth_padding_removal():
    """The crop undoes ZoeDepth's reflect padding: a ramp over the padded canvas keeps its centre."""
    import torch

    from holoflow.networks.zoedepth import remove_padding

    h, w = 24, 40
    ph, pw = int(np.sqrt(h / 2) * 3), int(np.sqrt(w / 2) * 3)
    canvas = torch.arange(w + 2 * pw, dtype=torch.float32).repeat(h + 2 * ph, 1)[None] + 1  # [1, H', W']
    out = remove_padding(canvas, h, w, padded=True)
    assert out.shape == (1, h, w)
    assert torch.allclose(out[0, 0], torch.arange(pw, pw + w, dtype=torch.float32) + 1, atol=1e-3)


def test_missing_depth_weights(tmp_path, images):
    from holoflow.networks.depth_anything import relative_disparity
    from holoflow.networks.weights import MissingWeights
    from holoflow.networks.zoedepth import metric_depth

    with pytest.raises(MissingWeights, match="tangent_depth.model"):
        relative_disparity(images, model=str(tmp_path / "none"))
    with pytest.raises(MissingWeights, match="metric_align.model"):
        metric_depth(images, model=str(tmp_path / "none"))
