"""The engines on CUDA (float16 where the engine uses it): same contracts as on the CPU."""

import numpy as np
import pytest
import torch

from .engine_checks import seam_is_typical

pytestmark = [
    pytest.mark.models,
    pytest.mark.cuda,
    pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device"),
]


def _ok(img, shape):
    assert img.shape == shape and img.dtype == np.float32 and np.isfinite(img).all()


def test_diffusion_engines_cuda(tiny_sd, base_image):
    from holoflow.networks.controlnet_lineart import stylize
    from holoflow.networks.controlnet_tile import refine
    from holoflow.networks.diffusion360 import generate_pano

    sd, cnet = tiny_sd
    panos = [generate_pano("a room", 64, 32, steps=2, seed=s, model=str(sd), device="cuda") for s in (0, 1)]
    for p in panos:
        _ok(p, (32, 64, 3))
    assert seam_is_typical(*panos)
    line = (base_image[..., 0] > 0.5).astype(np.float32)
    _ok(
        stylize(base_image, line, "ink", 64, 32, steps=2, seed=0, model=str(sd), controlnet=str(cnet), device="cuda"),
        (32, 64, 3),
    )
    _ok(
        refine(
            base_image,
            "detail",
            64,
            32,
            strength=0.5,
            tile=32,
            overlap=8,
            steps=2,
            seed=0,
            model=str(sd),
            controlnet=str(cnet),
            device="cuda",
        ),
        (32, 64, 3),
    )


def test_other_engines_cuda(tmp_path, base_image):
    from holoflow.networks import random_models as rm
    from holoflow.networks.depth_anything import relative_disparity
    from holoflow.networks.lama import inpaint
    from holoflow.networks.realesrgan import upscale
    from holoflow.networks.zoedepth import metric_depth

    _ok(upscale(base_image, 256, 128, model=str(rm.save_rrdbnet(tmp_path / "x4.pth")), device="cuda"), (128, 256, 3))
    faces = np.stack([base_image[:, :32], base_image[:, 32:]])  # [2, 32, 32, 3]
    masks = np.zeros(faces.shape[:3], np.float32)
    masks[:, 8:20, 8:20] = 1
    _ok(inpaint(faces, masks, model=str(rm.save_lama(tmp_path / "lama.safetensors")), device="cuda"), faces.shape)
    _ok(relative_disparity(faces, model=str(rm.save_depth_anything(tmp_path / "da")), device="cuda"), (2, 32, 32))
    depth = metric_depth(faces, model=str(rm.save_zoedepth(tmp_path / "zoe")), device="cuda")
    _ok(depth, (2, 32, 32))
    assert depth.min() > 0
