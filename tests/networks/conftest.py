"""Fixtures for the real-model engine tests: tiny random models of the real architectures,
saved to a temp dir once per session and loaded through each engine's own loading code."""

import os

import numpy as np
import pytest

os.environ["HF_HUB_OFFLINE"] = "1"


@pytest.fixture(autouse=True)
def _one_thread():
    """Tiny models: intra-op threads only add synchronisation (5x slower on a loaded 2-core box)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def tiny_sd(tmp_path_factory):
    pytest.importorskip("diffusers")
    pytest.importorskip("transformers")
    from holoflow.networks.random_models import save_controlnet, save_sd

    root = tmp_path_factory.mktemp("sd")
    sd = save_sd(root / "sd")
    return sd, save_controlnet(sd, root / "controlnet")


@pytest.fixture(scope="session")
def base_image():
    """A smooth periodic test panorama ``[32, 64, 3]`` (linear RGB)."""
    v, u = np.mgrid[0:32, 0:64].astype(np.float32)
    lon = 2 * np.pi * (u + 0.5) / 64
    img = np.stack([0.5 + 0.4 * np.sin(lon), 0.5 + 0.4 * np.cos(2 * lon) * (v / 32), 0.3 + 0.2 * (v / 32)], -1)
    return img.astype(np.float32)
