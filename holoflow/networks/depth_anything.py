"""Relative disparity with Depth Anything (transformers ``AutoModelForDepthEstimation``).

The model folder (or cached model id, default ``depth-anything/Depth-Anything-V2-Small-hf``, the CPU
default; v1 and V2 Base / Large load the same way) holds the config, the weights and
``preprocessor_config.json``; its own preprocessing is used (the PIL image processor: no torchvision),
at the model's own input side (518 px) or at ``side`` px (a multiple of the 14 px patch). The network
predicts affine-invariant disparity (larger = nearer); it is
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


#: the ViT patch of every Depth Anything model: the network's input side is a multiple of it (px)
PATCH = 14


def network_side(size: int) -> int:
    """The input side (px) nearest to ``size`` that the network takes: a multiple of ``PATCH``, >= PATCH."""
    return max(PATCH, int(round(size / PATCH)) * PATCH)


def relative_disparity(
    images: np.ndarray,
    model: str = "",
    device: str = "cpu",
    progress: Progress = None,
    batch: int = 4,
    side: int | None = None,
) -> np.ndarray:
    """Affine-invariant disparity ``[N, H, W]`` float32 of linear RGB ``images [N, H, W, 3]``.

    ``side``: a square face is resized to ``side`` x ``side`` px for the network (a multiple of 14, the
    aspect kept otherwise; None = the processor's own size); the disparity is resized back to [H, W]
    bilinearly."""
    import torch
    from torch.nn import functional as F
    from transformers import AutoModelForDepthEstimation, DPTImageProcessorPil

    path = resolve(model, "depth_anything", "tangent_depth.model")
    dev = torch_device(device)
    processor = DPTImageProcessorPil.from_pretrained(str(path), local_files_only=True)
    net = AutoModelForDepthEstimation.from_pretrained(str(path), local_files_only=True).to(dev).eval()
    imgs = to_uint8_srgb(np.asarray(images))
    n, h, w = imgs.shape[:3]
    size = {} if side is None else {"size": {"height": int(side), "width": int(side)}}
    out = np.empty((n, h, w), np.float32)
    for i in range(0, n, batch):
        report(progress, i, n, "images")
        inputs = processor(images=list(imgs[i : i + batch]), return_tensors="pt", **size)
        with torch.inference_mode():
            disp = net(pixel_values=inputs["pixel_values"].to(dev)).predicted_depth  # [B, h', w']
            disp = F.interpolate(disp[:, None].float(), size=(h, w), mode="bilinear", align_corners=False)
        out[i : i + batch] = disp[:, 0].cpu().numpy()
    report(progress, n, n, "images")
    return out
