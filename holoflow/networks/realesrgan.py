"""Real-ESRGAN super-resolution (RRDBNet generator) with wrap-around padding at the +-180 deg seam.

The network is written here in torch with the key names of the official checkpoints
(``conv_first``, ``body.{i}.rdb{1,2,3}.conv{1..5}``, ``conv_body``, ``conv_up1``, ``conv_up2``,
``conv_hr``, ``conv_last``), so RealESRGAN_x4plus.pth / RealESRGAN_x2plus.pth (``params_ema``) and
their .safetensors conversions load with ``torch.load(weights_only=True)``. The architecture
(scale, width, depth, growth) is read from the state dict: x2 models see a 2x2 pixel-unshuffled
input (12 channels), x1 a 4x4 one (48), x4 the plain image (3).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from holoflow.imageops.color import linear_to_srgb, srgb_to_linear
from holoflow.networks.common import half_on_cuda, report, resize_wrap, to_chw, to_hwc, torch_device
from holoflow.networks.weights import load_state_dict, resolve, weight_file
from holoflow.stage import Progress


@functools.cache
def rrdbnet_class():
    """The RRDBNet nn.Module class (built lazily so importing this module does not import torch)."""
    import torch
    from torch import nn
    from torch.nn import functional as F

    class ResidualDenseBlock(nn.Module):
        """Five 3x3 convs, each seeing all previous features; residual scaled by 0.2."""

        def __init__(self, num_feat: int, num_grow_ch: int):
            super().__init__()
            for i in range(4):
                setattr(self, f"conv{i + 1}", nn.Conv2d(num_feat + i * num_grow_ch, num_grow_ch, 3, 1, 1))
            self.conv5 = nn.Conv2d(num_feat + 4 * num_grow_ch, num_feat, 3, 1, 1)

        def forward(self, x):
            feats = [x]
            for i in range(4):
                conv = getattr(self, f"conv{i + 1}")
                feats.append(F.leaky_relu(conv(torch.cat(feats, 1)), 0.2))
            return self.conv5(torch.cat(feats, 1)) * 0.2 + x

    class RRDB(nn.Module):
        """Residual-in-residual dense block: three dense blocks, residual scaled by 0.2."""

        def __init__(self, num_feat: int, num_grow_ch: int):
            super().__init__()
            self.rdb1 = ResidualDenseBlock(num_feat, num_grow_ch)
            self.rdb2 = ResidualDenseBlock(num_feat, num_grow_ch)
            self.rdb3 = ResidualDenseBlock(num_feat, num_grow_ch)

        def forward(self, x):
            return self.rdb3(self.rdb2(self.rdb1(x))) * 0.2 + x

    class RRDBNet(nn.Module):
        """ESRGAN generator; ``scale`` in {1, 2, 4}; input/output in [0, 1] sRGB, ``[B, C, H, W]``."""

        def __init__(self, num_in_ch=3, num_out_ch=3, scale=4, num_feat=64, num_block=23, num_grow_ch=32):
            super().__init__()
            self.scale = scale
            unshuffle = {4: 1, 2: 2, 1: 4}[scale]
            self.unshuffle = unshuffle
            self.conv_first = nn.Conv2d(num_in_ch * unshuffle**2, num_feat, 3, 1, 1)
            self.body = nn.Sequential(*[RRDB(num_feat, num_grow_ch) for _ in range(num_block)])
            self.conv_body = nn.Conv2d(num_feat, num_feat, 3, 1, 1)
            self.conv_up1 = nn.Conv2d(num_feat, num_feat, 3, 1, 1)
            self.conv_up2 = nn.Conv2d(num_feat, num_feat, 3, 1, 1)
            self.conv_hr = nn.Conv2d(num_feat, num_feat, 3, 1, 1)
            self.conv_last = nn.Conv2d(num_feat, num_out_ch, 3, 1, 1)

        def forward(self, x):  # [B, 3, H, W], H and W % unshuffle == 0
            if self.unshuffle > 1:
                x = F.pixel_unshuffle(x, self.unshuffle)
            feat = self.conv_first(x)
            feat = feat + self.conv_body(self.body(feat))
            feat = F.leaky_relu(self.conv_up1(F.interpolate(feat, scale_factor=2, mode="nearest")), 0.2)
            feat = F.leaky_relu(self.conv_up2(F.interpolate(feat, scale_factor=2, mode="nearest")), 0.2)
            return self.conv_last(F.leaky_relu(self.conv_hr(feat), 0.2))  # [B, 3, H*scale, W*scale]

    return RRDBNet


def rrdbnet_from_state_dict(state: dict):
    """An RRDBNet whose shape matches ``state`` (keys as the official checkpoints), weights loaded."""
    for key in ("params_ema", "params", "state_dict"):
        if key in state and isinstance(state[key], dict):
            state = state[key]
    state = {k.removeprefix("module."): v for k, v in state.items()}
    in_ch = state["conv_first.weight"].shape[1]
    unshuffle_sq = in_ch // state["conv_last.weight"].shape[0]
    scale = {1: 4, 4: 2, 16: 1}[unshuffle_sq]
    num_block = 1 + max(int(k.split(".")[1]) for k in state if k.startswith("body."))
    net = rrdbnet_class()(
        num_in_ch=in_ch // unshuffle_sq,
        num_out_ch=state["conv_last.weight"].shape[0],
        scale=scale,
        num_feat=state["conv_first.weight"].shape[0],
        num_block=num_block,
        num_grow_ch=state["body.0.rdb1.conv1.weight"].shape[0],
    )
    net.load_state_dict(state, strict=True)
    return net.eval()


def _tiled(net, x, tile: int, tile_pad: int):
    """Run ``net`` on ``x [1, 3, H, W]`` tile by tile (each tile sees ``tile_pad`` px of context)."""
    import torch
    from torch.nn import functional as F

    _, c, h, w = x.shape
    s, m = net.scale, net.unshuffle
    out = torch.zeros(1, c, h * s, w * s, dtype=x.dtype, device=x.device)
    tile = max(tile, 8)
    for y0 in range(0, h, tile):
        for x0 in range(0, w, tile):
            y1, x1 = min(y0 + tile, h), min(x0 + tile, w)
            py0, px0 = max(y0 - tile_pad, 0), max(x0 - tile_pad, 0)
            py1, px1 = min(y1 + tile_pad, h), min(x1 + tile_pad, w)
            patch = x[:, :, py0:py1, px0:px1]
            eh, ew = (-patch.shape[2]) % m, (-patch.shape[3]) % m  # pixel-unshuffle needs % m
            if eh or ew:
                patch = F.pad(patch, (0, ew, 0, eh), mode="replicate")
            res = net(patch)
            oy, ox = (y0 - py0) * s, (x0 - px0) * s
            out[:, :, y0 * s : y1 * s, x0 * s : x1 * s] = res[:, :, oy : oy + (y1 - y0) * s, ox : ox + (x1 - x0) * s]
    return out


def upscale_srgb(net, img, tile: int = 256, tile_pad: int = 32, wrap_pad: int = 32):
    """One network pass on sRGB ``img [1, 3, H, W]`` -> ``[1, 3, H*s, W*s]``, seamless in longitude.

    The image is padded with ``wrap_pad`` columns from its other side (and edge rows at the poles),
    so columns 0 and W-1 are upscaled with their true neighbours; the padding is cropped after.
    """
    import torch
    from torch.nn import functional as F

    h, w = img.shape[-2:]
    p = min(wrap_pad, w)
    x = torch.cat([img[..., w - p :], img, img[..., :p]], dim=-1)  # [1, 3, H, W + 2p]
    py = min(wrap_pad, h - 1)
    if py > 0:
        x = F.pad(x, (0, 0, py, py), mode="replicate")
    y = _tiled(net, x, tile, tile_pad)
    s = net.scale
    return y[..., py * s : (py + h) * s, p * s : (p + w) * s].clamp(0, 1)


def upscale(
    pano: np.ndarray,
    width: int,
    height: int,
    model: str = "",
    tile: int = 256,
    device: str = "cpu",
    progress: Progress = None,
) -> np.ndarray:
    """Real-ESRGAN to exactly ``width x height``: network passes until the image is at least that
    wide (x4plus: one pass from 1536 to 6144; x2plus: two), then a wrap-aware Lanczos resize.

    pano: linear RGB ``[H, W, 3]`` in [0, 1]. Returns linear RGB ``[height, width, 3]``.
    """
    import torch

    file = weight_file(resolve(model, "realesrgan", "upscale.model"), "realesrgan", "upscale.model")
    dev = torch_device(device)
    dtype = half_on_cuda(dev)
    net = rrdbnet_from_state_dict(load_state_dict(file)).to(dev, dtype)
    img = to_chw(linear_to_srgb(pano, clip=True), dev, dtype)  # [1, 3, H, W]
    passes = 0
    if net.scale > 1 and img.shape[-1] < width:
        passes = math.ceil(math.log(width / img.shape[-1], net.scale) - 1e-9)
    with torch.inference_mode():
        for i in range(passes):
            report(progress, i, passes + 1, "passes")
            img = upscale_srgb(net, img, tile=tile)
        img = resize_wrap(img.float(), height, width)
    report(progress, passes + 1, passes + 1, "passes")
    return srgb_to_linear(to_hwc(img.clamp(0, 1)), clip=True)


def upscale_engine(pano: np.ndarray, prompt: str, cfg, seed: int, device: str, progress: Progress):
    """upscale's ``realesrgan`` engine (holoflow.imageops.config.UpscaleParams): (pano, meta)."""
    return upscale(pano, cfg.width, cfg.height, cfg.model, cfg.tile, device, progress), {
        "model": cfg.model or "default"
    }
