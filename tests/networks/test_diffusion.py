"""Diffusion engines (base_pano, stylize, detail) on a tiny random SD 1.x + ControlNet saved with
save_pretrained: the same from_pretrained path as real weights. Circular blending is checked on
its own (exact properties) and through each engine (seam no larger than neighbouring columns)."""

import numpy as np
import pytest
import torch

from holoflow.networks.circular import blend_overlap, decode_periodic, extend_periodic, overlap_columns

from .engine_checks import seam_is_typical

pytestmark = pytest.mark.models
pytest.importorskip("diffusers")


def test_overlap_columns():
    assert overlap_columns(128) == 8  # 1024 px / 8: 8 latent cols = 22.5 deg
    assert overlap_columns(192) == 16
    for w in (4, 8, 32, 100, 128, 192):
        k = overlap_columns(w)
        assert 2 <= k <= max(w, 2) and (w + k) % 8 == 0


def test_blend_overlap_makes_copies_equal_and_crossfades():
    x = torch.randn(1, 4, 3, 10 + 4, generator=torch.Generator().manual_seed(0))
    before = x.clone()
    blend_overlap(x, 4)
    assert torch.equal(x[..., :4], x[..., 10:])  # the two copies are one again (one value written twice)
    assert torch.equal(x[..., 4:10], before[..., 4:10])  # nothing else is touched
    t = (torch.arange(4) + 0.5) / 4
    assert torch.allclose(x[..., :4], (1 - t) * before[..., 10:] + t * before[..., :4])
    y = extend_periodic(torch.randn(1, 4, 3, 10), 4)  # already periodic: blending changes nothing
    assert torch.allclose(blend_overlap(y.clone(), 4), y, atol=1e-6)


def test_decode_periodic_sees_across_the_seam(tiny_sd):
    """Rolling the latent by r columns rolls the decoded image by r * vae_scale px, up to the VAE's
    global ops (GroupNorm statistics, mid-block attention see the padding): 10x closer than a plain
    decode, whose zero-padded borders make the seam a visible edge."""
    from diffusers import AutoencoderKL

    vae = AutoencoderKL.from_pretrained(str(tiny_sd[0]), subfolder="vae")
    lat = torch.randn(1, 4, 8, 16, generator=torch.Generator().manual_seed(1))
    a = decode_periodic(vae, lat, pad=8)
    b = decode_periodic(vae, torch.roll(lat, 3, dims=-1), pad=8)
    assert a.shape == (1, 3, 16, 32)
    with torch.no_grad():
        plain = [vae.decode(x / vae.config.scaling_factor).sample / 2 for x in (lat, torch.roll(lat, 3, dims=-1))]
    err = (torch.roll(a, 6, dims=-1) - b).abs().max()
    err_plain = (torch.roll(plain[0], 6, dims=-1) - plain[1]).abs().max()
    assert err < 0.1 * err_plain


def _check_pano(img, h=32, w=64):
    assert img.shape == (h, w, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and img.min() >= 0 and img.max() <= 1


def test_generate_pano(tiny_sd):
    from holoflow.networks.diffusion360 import generate_pano

    steps = []
    a = generate_pano(
        "a wooden cabin",
        64,
        32,
        steps=2,
        seed=0,
        model=str(tiny_sd[0]),
        progress=lambda d, t, what: steps.append((d, t)),
    )
    _check_pano(a)
    assert steps[-1] == (2, 2)
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(a, generate_pano("a wooden cabin", 64, 32, steps=2, seed=0, model=str(tiny_sd[0])))
    b = generate_pano("a wooden cabin", 64, 32, steps=2, seed=1, model=str(tiny_sd[0]))
    assert not np.array_equal(a, b)
    assert seam_is_typical(a, b)


def test_generate_pano_odd_size_is_resized(tiny_sd):
    from holoflow.networks.diffusion360 import generate_pano

    _check_pano(generate_pano("a beach", 60, 30, steps=1, seed=0, model=str(tiny_sd[0])), 30, 60)


def test_stylize(tiny_sd, base_image):
    from holoflow.networks.controlnet_lineart import stylize

    sd, cnet = tiny_sd
    line = np.zeros(base_image.shape[:2], np.float32)
    line[:, ::8] = 1
    line[10] = 1
    a = stylize(
        base_image, line, "watercolor", 64, 32, steps=2, strength=1.0, seed=0, model=str(sd), controlnet=str(cnet)
    )
    _check_pano(a)
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(
        a,
        stylize(
            base_image, line, "watercolor", 64, 32, steps=2, strength=1.0, seed=0, model=str(sd), controlnet=str(cnet)
        ),
    )
    other = stylize(
        base_image, 1 - line, "watercolor", 64, 32, steps=2, strength=1.0, seed=0, model=str(sd), controlnet=str(cnet)
    )
    assert not np.array_equal(a, other)  # the control image is really used
    assert seam_is_typical(a, other)


def test_refine(tiny_sd, base_image):
    from holoflow.networks.controlnet_tile import refine, tile_grid

    xs, ys, tw, th = tile_grid(64, 32, 32, 8)
    assert len(xs) >= 2 and xs[0] == 0 and xs[-1] + tw > 64  # a tile runs across the seam
    sd, cnet = tiny_sd
    a = refine(
        base_image,
        "detailed",
        64,
        32,
        strength=0.5,
        tile=32,
        overlap=8,
        steps=2,
        seed=0,
        model=str(sd),
        controlnet=str(cnet),
    )
    _check_pano(a)
    # same call, same inputs, same process: one code path, so bit-equal on any CPU
    assert np.array_equal(
        a,
        refine(
            base_image,
            "detailed",
            64,
            32,
            strength=0.5,
            tile=32,
            overlap=8,
            steps=2,
            seed=0,
            model=str(sd),
            controlnet=str(cnet),
        ),
    )
    others = [
        refine(
            base_image,
            "detailed",
            64,
            32,
            strength=0.5,
            tile=32,
            overlap=8,
            steps=2,
            seed=s,
            model=str(sd),
            controlnet=str(cnet),
        )
        for s in (1, 2)
    ]
    assert seam_is_typical(a, *others)
    batched = refine(
        base_image,
        "detailed",
        64,
        32,
        strength=0.5,
        tile=32,
        overlap=8,
        steps=2,
        seed=0,
        model=str(sd),
        controlnet=str(cnet),
        batch=3,
    )  # 3 tiles, then the rest
    assert np.abs(batched - a).max() < 1e-4  # each tile keeps its seed; rounding only
    assert np.abs(others[0] - a).max() > 1e-2
    same = refine(
        base_image,
        "detailed",
        64,
        32,
        strength=0.0,
        tile=32,
        overlap=8,
        steps=2,
        seed=0,
        model="/nonexistent",
        controlnet="/nonexistent",
    )
    assert np.allclose(same, base_image, atol=1e-5)  # strength 0: no model needed, input back


def test_missing_diffusion_weights(tmp_path, base_image):
    from holoflow.networks.controlnet_lineart import stylize
    from holoflow.networks.diffusion360 import generate_pano
    from holoflow.networks.weights import MissingWeights

    with pytest.raises(MissingWeights, match="base_pano.model"):
        generate_pano("x", 64, 32, model=str(tmp_path / "none"))
    with pytest.raises(MissingWeights, match="stylize.controlnet"):
        stylize(base_image, base_image[..., 0], "x", 64, 32, model=str(tmp_path), controlnet=str(tmp_path / "none"))
