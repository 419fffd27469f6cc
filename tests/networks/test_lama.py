"""LaMa engine: the big-lama generator layout, loaded from a state dict; holes filled, rest kept."""

import numpy as np
import pytest

from holoflow.networks.lama import inpaint, lama_class, lama_from_state_dict
from holoflow.networks.weights import MissingWeights

pytestmark = pytest.mark.models
pytest.importorskip("safetensors")


@pytest.fixture(scope="module")
def tiny_lama(tmp_path_factory):
    """Saved as the released Lightning checkpoint's generator part ("generator." keys)."""
    from holoflow.networks.random_models import save_lama

    return save_lama(tmp_path_factory.mktemp("lama") / "big-lama-tiny.safetensors")


def test_release_key_layout():
    """Keys of big-lama's generator (n_down=3 -> FFC blocks start at model.5)."""
    keys = set(lama_class()(ngf=8, n_down=3, n_blocks=1).state_dict())
    for k in (
        "model.1.ffc.convl2l.weight",
        "model.1.bn_l.running_var",
        "model.4.ffc.convl2g.weight",
        "model.5.conv1.ffc.convg2g.conv1.0.weight",
        "model.5.conv1.ffc.convg2g.fu.conv_layer.weight",
        "model.5.conv2.bn_g.weight",
        "model.7.weight",
        "model.8.running_mean",
        "model.14.weight",
    ):
        assert k in keys, k


def test_shape_read_from_weights(tiny_lama):
    from holoflow.networks.weights import load_state_dict

    state = load_state_dict(tiny_lama)
    state["discriminator.model.0.weight"] = state["generator.model.1.ffc.convl2l.weight"]  # ignored
    net = lama_from_state_dict(state)
    assert net.n_down == 2 and sum(1 for m in net.model if type(m).__name__ == "FFCResnetBlock") == 2


def test_inpaint_contract(tiny_lama):
    rng = np.random.default_rng(0)
    images = rng.random((3, 30, 44, 3), dtype=np.float32)
    masks = np.zeros((3, 30, 44), np.float32)
    masks[0, 5:15, 10:30] = 1
    masks[2, :, :3] = 1
    out = inpaint(images, masks, model=str(tiny_lama))
    assert out.shape == images.shape and out.dtype == np.float32 and np.isfinite(out).all()
    keep = masks < 0.5
    assert np.array_equal(out[keep], images[keep])  # known pixels untouched
    assert np.array_equal(out[1], images[1])  # nothing missing: not inpainted
    assert np.abs(out[0][masks[0] > 0.5] - images[0][masks[0] > 0.5]).mean() > 1e-3
    assert out.min() >= 0 and out.max() <= 1
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(out, inpaint(images, masks, model=str(tiny_lama)))


def test_missing_weights(tmp_path):
    with pytest.raises(MissingWeights, match="inp_set.model"):
        inpaint(np.zeros((1, 8, 8, 3), np.float32), np.ones((1, 8, 8), np.float32), model="")
