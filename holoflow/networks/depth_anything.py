"""Relative disparity with Depth Anything (transformers ``AutoModelForDepthEstimation``).

The model folder (or cached model id, default ``LiheYoung/depth-anything-large-hf``) holds the
config, the weights and ``preprocessor_config.json``; its own preprocessing is used (the PIL image
processor: no torchvision). The network predicts affine-invariant disparity (larger = nearer); it is
resized back to each input's size, bilinearly. The scale and shift are unknown per image: the
tangent_depth alignment solves for them.
"""
from __future__ import annotations

import numpy as np

from holoflow.imageops.color import linear_to_srgb
from holoflow.networks.common import report, torch_device
from holoflow.networks.weights import resolve
from holoflow.stage import Progress


def to_uint8_srgb(images: np.ndarray) -> np.ndarray:
    """Linear ``[N, H, W, 3]`` in [0, 1] -> sRGB uint8 (what the image processors expect)."""
    return np.round(linear_to_srgb(images, clip=True) * 255.0).astype(np.uint8)


def relative_disparity(images: np.ndarray, model: str = "", device: str = "cpu",
                       progress: Progress = None, batch: int = 4) -> np.ndarray:
    """Affine-invariant disparity ``[N, H, W]`` float32 of linear RGB ``images [N, H, W, 3]``."""
    import torch
    from torch.nn import functional as F
    from transformers import AutoModelForDepthEstimation, DPTImageProcessorPil

    path = resolve(model, "depth_anything", "tangent_depth.model")
    dev = torch_device(device)
    processor = DPTImageProcessorPil.from_pretrained(str(path), local_files_only=True)
    net = AutoModelForDepthEstimation.from_pretrained(str(path), local_files_only=True).to(dev).eval()
    imgs = to_uint8_srgb(np.asarray(images))
    n, h, w = imgs.shape[:3]
    out = np.empty((n, h, w), np.float32)
    for i in range(0, n, batch):
        report(progress, i, n, "images")
        inputs = processor(images=list(imgs[i:i + batch]), return_tensors="pt")
        with torch.inference_mode():
            disp = net(pixel_values=inputs["pixel_values"].to(dev)).predicted_depth   # [B, h', w']
            disp = F.interpolate(disp[:, None].float(), size=(h, w), mode="bilinear", align_corners=False)
        out[i:i + batch] = disp[:, 0].cpu().numpy()
    report(progress, n, n, "images")
    return out
