"""Metric depth with ZoeDepth (transformers ``ZoeDepthForDepthEstimation``; paper: ZoeDepth-NK).

The model folder (or cached id, default ``Intel/zoedepth-nyu-kitti``) carries its own
preprocessing (``preprocessor_config.json``: resize keeping aspect, reflect padding); the PIL image
processor is used (no torchvision). Its post-processing is redone here in torch (transformers'
PIL post-processor calls torchvision): resize to the padded input size, crop the reflect padding
ZoeDepth adds (``int(sqrt(side / 2) * 3)`` px per side); depths are floored at 1 mm. As in ZoeDepth's own evaluation,
the prediction is averaged with that of the mirrored
image. Output: perspective z depth in metres (distance along the optical axis, not along the ray).
"""

from __future__ import annotations

import numpy as np

from holoflow.networks.common import report, torch_device
from holoflow.networks.depth_anything import to_uint8_srgb
from holoflow.networks.weights import resolve
from holoflow.stage import Progress


def remove_padding(depth, h: int, w: int, padded: bool):
    """ZoeDepth output ``[B, h', w']`` -> ``[B, h, w]``: bicubic resize, crop the input padding."""
    from torch.nn import functional as F

    ph, pw = (int(np.sqrt(h / 2) * 3), int(np.sqrt(w / 2) * 3)) if padded else (0, 0)
    d = F.interpolate(depth[:, None], size=(h + 2 * ph, w + 2 * pw), mode="bicubic", align_corners=False)
    return d[:, 0, ph : ph + h, pw : pw + w].clamp_min(1e-3)  # bicubic may overshoot


def metric_depth(
    images: np.ndarray,
    model: str = "",
    device: str = "cpu",
    progress: Progress = None,
    batch: int = 4,
    flip: bool = True,
) -> np.ndarray:
    """Metric z depth ``[N, H, W]`` float32 (metres) of linear RGB ``images [N, H, W, 3]``."""
    import torch
    from transformers import ZoeDepthForDepthEstimation, ZoeDepthImageProcessorPil

    path = resolve(model, "zoedepth", "metric_align.model")
    dev = torch_device(device)
    processor = ZoeDepthImageProcessorPil.from_pretrained(str(path), local_files_only=True)
    net = ZoeDepthForDepthEstimation.from_pretrained(str(path), local_files_only=True).to(dev).eval()
    imgs = to_uint8_srgb(np.asarray(images))
    n, h, w = imgs.shape[:3]
    out = np.empty((n, h, w), np.float32)
    for i in range(0, n, batch):
        report(progress, i, n, "images")
        chunk = list(imgs[i : i + batch])
        pixels = processor(images=chunk, return_tensors="pt")["pixel_values"].to(dev)  # [B, 3, h', w']
        with torch.inference_mode():
            pred = net(pixel_values=pixels)
            flipped = net(pixel_values=torch.flip(pixels, dims=[3])) if flip else None
        depth = pred.predicted_depth.float()  # [B, h'', w'']
        if flipped is not None:
            depth = 0.5 * (depth + torch.flip(flipped.predicted_depth.float(), dims=[-1]))
        out[i : i + batch] = remove_padding(depth, h, w, bool(processor.do_pad)).cpu().numpy()
    report(progress, n, n, "images")
    return out
