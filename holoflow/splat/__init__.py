"""Differentiable 3D Gaussian splatting: projection, rasterizer backends, model, training.

``rasterize`` / ``render`` take activated or model parameters and return rgb, alpha and depth images;
backends: dense torch reference, fast CPU (numba), gsplat (CUDA). See docs/splatting.md.
"""

from holoflow.splat.model import GaussianModel
from holoflow.splat.rasterize import rasterize, render
from holoflow.splat.train import TrainConfig, train

__all__ = ["GaussianModel", "TrainConfig", "rasterize", "render", "train"]
