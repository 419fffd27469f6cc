"""Engine helpers: the clipped colour transfer networks take, and the wrap-aware resize."""

import numpy as np
import pytest
import torch

from holoflow.imageops.color import linear_to_srgb, srgb_to_linear
from holoflow.networks.common import resize_wrap

pytestmark = pytest.mark.models


def test_srgb_round_trip_clipped_as_networks_take_it():
    x = np.linspace(0, 1, 101, dtype=np.float32)
    assert np.allclose(srgb_to_linear(linear_to_srgb(x, clip=True), clip=True), x, atol=1e-6)
    assert abs(float(linear_to_srgb(np.float32(0.18), clip=True)) - 0.4614) < 1e-3
    over = np.array([-0.5, 1.0, 4.0], dtype=np.float32)
    assert linear_to_srgb(over, clip=True).tolist() == [
        0.0,
        linear_to_srgb(np.float32(1.0)).item(),
        linear_to_srgb(np.float32(1.0)).item(),
    ]
    assert linear_to_srgb(over)[2] > 1.5  # unclipped: values above 1 pass the curve


@pytest.mark.parametrize("w_in,w_out,shift_in,shift_out", [(128, 100, 32, 25), (32, 128, 1, 4), (64, 48, 4, 3)])
def test_resize_wrap_is_shift_equivariant(w_in, w_out, shift_in, shift_out):
    """Longitude wraps: rolling the input rolls the output; the seam is an ordinary column."""
    img = torch.rand(3, 10, w_in, generator=torch.Generator().manual_seed(0))
    a = resize_wrap(img, 7, w_out)
    b = resize_wrap(torch.roll(img, shift_in, dims=-1), 7, w_out)
    assert a.shape == (3, 7, w_out)
    assert torch.allclose(torch.roll(a, shift_out, dims=-1), b, atol=1e-5)


def test_resize_wrap_keeps_constants_and_identity():
    img = torch.full((1, 3, 9, 20), 0.25)
    assert torch.allclose(resize_wrap(img, 5, 33), torch.full((1, 3, 5, 33), 0.25), atol=1e-6)
    x = torch.rand(1, 3, 9, 20)
    assert resize_wrap(x, 9, 20) is x
