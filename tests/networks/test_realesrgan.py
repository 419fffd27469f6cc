"""Real-ESRGAN engine: official key names, x2/x4 from the weights, wrap padding, exact output size."""

import numpy as np
import pytest
import torch

from holoflow.networks.realesrgan import rrdbnet_class, rrdbnet_from_state_dict, upscale, upscale_srgb
from holoflow.networks.weights import MissingWeights

from .engine_checks import seam_is_typical

pytestmark = pytest.mark.models
pytest.importorskip("safetensors")


def _save(tmp_path, scale, fmt):
    torch.manual_seed(scale)
    net = rrdbnet_class()(scale=scale, num_feat=8, num_block=1, num_grow_ch=4)
    for p in net.parameters():
        p.data.mul_(3.0)  # make the random net visibly non-trivial
    path = tmp_path / f"tiny_x{scale}.{fmt}"
    if fmt == "pth":
        torch.save({"params_ema": net.state_dict()}, path)  # the official checkpoints' layout
    else:
        from safetensors.torch import save_file

        save_file({k: v.contiguous() for k, v in net.state_dict().items()}, str(path))
    return path


def test_official_key_names():
    keys = set(rrdbnet_class()(scale=4, num_feat=8, num_block=2, num_grow_ch=4).state_dict())
    for k in (
        "conv_first.weight",
        "body.1.rdb3.conv5.bias",
        "conv_body.weight",
        "conv_up1.weight",
        "conv_up2.weight",
        "conv_hr.weight",
        "conv_last.bias",
    ):
        assert k in keys


@pytest.mark.parametrize("scale,fmt", [(2, "pth"), (4, "safetensors")])
def test_architecture_read_from_weights(tmp_path, scale, fmt):
    path = _save(tmp_path, scale, fmt)
    from holoflow.networks.weights import load_state_dict

    net = rrdbnet_from_state_dict(load_state_dict(path))
    assert net.scale == scale and len(net.body) == 1


@pytest.mark.parametrize("scale,fmt,size", [(2, "pth", (30, 60)), (4, "safetensors", (64, 128))])
def test_upscale_contract(tmp_path, base_image, scale, fmt, size):
    """One pass (x2: 32 -> 64 px wide, then resized to 60; x4: 32 -> 128), tiled."""
    path = _save(tmp_path, scale, fmt)
    small = base_image[::2, ::2]  # [16, 32, 3]
    tile = 24 if scale == 2 else 64  # x2: several tiles
    out = upscale(small, size[1], size[0], model=str(path), tile=tile)
    assert out.shape == (*size, 3) and out.dtype == np.float32
    assert np.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(out, upscale(small, size[1], size[0], model=str(path), tile=tile))
    assert seam_is_typical(out)  # one deterministic draw


def test_wrap_padding_makes_the_seam_an_ordinary_column(tmp_path, base_image):
    """Rolling the input in longitude rolls the network output: the seam is treated like any column."""
    from holoflow.networks.weights import load_state_dict

    net = rrdbnet_from_state_dict(load_state_dict(_save(tmp_path, 2, "pth")))
    img = torch.rand(1, 3, 16, 32, generator=torch.Generator().manual_seed(0))
    with torch.inference_mode():
        a = upscale_srgb(net, img, tile=64)
        b = upscale_srgb(net, torch.roll(img, 8, dims=-1), tile=64)
    assert torch.allclose(torch.roll(a, 16, dims=-1), b, atol=1e-5)


def test_passes_until_wide_enough(tmp_path, base_image):
    """x2 weights, 16 -> 48 px wide: two passes (16 -> 32 -> 64), then resized down to 48."""
    out = upscale(base_image[::4, ::4], 48, 24, model=str(_save(tmp_path, 2, "pth")), tile=64)
    assert out.shape == (24, 48, 3) and np.isfinite(out).all()


def test_missing_weights(tmp_path, base_image):
    with pytest.raises(MissingWeights, match="upscale.model"):
        upscale(base_image, 128, 64, model=str(tmp_path / "RealESRGAN_x4plus.pth"))
