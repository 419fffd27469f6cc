"""LaMa inpainting: the big-lama generator (an FFC ResNet: fast Fourier convolutions) in torch.

Module and key names follow the released generator (``model.{i}.ffc.convl2l``, ``...convg2g.fu.
conv_layer``, ``model.{i}.conv1.bn_g``...), so a big-lama state dict loads as is; a
``generator.``-prefixed Lightning state dict (discriminator and loss keys ignored) too. The
shape (input channels, width, down-sampling steps, blocks, global ratio) is read from the weights;
big-lama is 4 -> 64 features, 3 down-samplings, 18 FFC blocks at 512 channels, 75 % of them global.

Input: image * (1 - mask) and the mask, sRGB in [0, 1]; output after a sigmoid, pasted into the
hole only. The official ``best.ckpt`` is a full Lightning pickle that ``weights_only`` refuses:
docs/engines.md shows the one-time conversion to .safetensors.
"""
from __future__ import annotations

import functools
import re

import numpy as np

from holoflow.imageops.color import linear_to_srgb, srgb_to_linear
from holoflow.networks.common import Progress, report, torch_device
from holoflow.networks.weights import load_state_dict, resolve, weight_file


@functools.cache
def _modules():
    import torch
    from torch import nn

    class FourierUnit(nn.Module):
        """1x1 conv + BN + ReLU on the real/imag parts of the 2D real FFT (channels interleaved)."""

        def __init__(self, in_ch: int, out_ch: int):
            super().__init__()
            self.conv_layer = nn.Conv2d(in_ch * 2, out_ch * 2, 1, bias=False)
            self.bn = nn.BatchNorm2d(out_ch * 2)
            self.relu = nn.ReLU(inplace=True)

        def forward(self, x):                                           # [B, C, H, W]
            b, _, h, w = x.shape
            f = torch.fft.rfftn(x.float(), dim=(-2, -1), norm="ortho")  # [B, C, H, W//2+1]
            f = torch.stack((f.real, f.imag), dim=2).reshape(b, -1, h, f.shape[-1]).to(x.dtype)
            f = self.relu(self.bn(self.conv_layer(f)))                  # [B, 2C', H, W//2+1]
            f = f.reshape(b, -1, 2, h, f.shape[-1]).float()
            return torch.fft.irfftn(torch.complex(f[:, :, 0], f[:, :, 1]), s=(h, w), dim=(-2, -1),
                                    norm="ortho").to(x.dtype)

    class SpectralTransform(nn.Module):
        """Global branch: 1x1 reduce, Fourier unit, residual, 1x1 expand."""

        def __init__(self, in_ch: int, out_ch: int):
            super().__init__()
            self.conv1 = nn.Sequential(nn.Conv2d(in_ch, out_ch // 2, 1, bias=False),
                                       nn.BatchNorm2d(out_ch // 2), nn.ReLU(inplace=True))
            self.fu = FourierUnit(out_ch // 2, out_ch // 2)
            self.conv2 = nn.Conv2d(out_ch // 2, out_ch, 1, bias=False)

        def forward(self, x):
            x = self.conv1(x)
            return self.conv2(x + self.fu(x))

    class FFC(nn.Module):
        """Fast Fourier convolution: local (l) and global (g) channel groups, four paths between them."""

        def __init__(self, in_ch, out_ch, kernel, ratio_gin, ratio_gout, stride=1, padding=0, dilation=1):
            super().__init__()
            in_g, out_g = int(in_ch * ratio_gin), int(out_ch * ratio_gout)
            in_l, out_l = in_ch - in_g, out_ch - out_g
            self.has_l, self.has_g = out_l > 0, out_g > 0

            def conv(i, o):
                if i == 0 or o == 0:
                    return nn.Identity()
                return nn.Conv2d(i, o, kernel, stride, padding, dilation, bias=False, padding_mode="reflect")

            self.convl2l, self.convl2g, self.convg2l = conv(in_l, out_l), conv(in_l, out_g), conv(in_g, out_l)
            self.convg2g = SpectralTransform(in_g, out_g) if in_g and out_g else nn.Identity()
            self.in_g = in_g

        def forward(self, x):
            x_l, x_g = x
            out_l = out_g = 0
            if self.has_l:
                out_l = self.convl2l(x_l) + (self.convg2l(x_g) if self.in_g else 0)
            if self.has_g:
                out_g = self.convl2g(x_l) + (self.convg2g(x_g) if self.in_g else 0)
            return out_l, out_g

    class FFC_BN_ACT(nn.Module):
        def __init__(self, in_ch, out_ch, kernel, ratio_gin, ratio_gout, stride=1, padding=0, dilation=1):
            super().__init__()
            self.ffc = FFC(in_ch, out_ch, kernel, ratio_gin, ratio_gout, stride, padding, dilation)
            out_g = int(out_ch * ratio_gout)
            self.bn_l = nn.BatchNorm2d(out_ch - out_g) if out_ch - out_g else nn.Identity()
            self.bn_g = nn.BatchNorm2d(out_g) if out_g else nn.Identity()
            self.act = nn.ReLU(inplace=True)

        def forward(self, x):
            x_l, x_g = self.ffc(x)
            if torch.is_tensor(x_l):
                x_l = self.act(self.bn_l(x_l))
            if torch.is_tensor(x_g):
                x_g = self.act(self.bn_g(x_g))
            return x_l, x_g

    class FFCResnetBlock(nn.Module):
        def __init__(self, dim, ratio):
            super().__init__()
            self.conv1 = FFC_BN_ACT(dim, dim, 3, ratio, ratio, padding=1)
            self.conv2 = FFC_BN_ACT(dim, dim, 3, ratio, ratio, padding=1)

        def forward(self, x):
            y = self.conv2(self.conv1(x))
            return x[0] + y[0], x[1] + y[1]

    class ToTuple(nn.Module):
        def forward(self, x):
            return (x, 0)

    class ConcatTuple(nn.Module):
        def forward(self, x):
            return torch.cat([t for t in x if torch.is_tensor(t)], dim=1)

    class FFCResNetGenerator(nn.Module):
        """LaMa generator. ``forward(x [B, in_ch, H, W])``, H and W multiples of 2**n_down; [0, 1] out.

        ``model`` indices match the release: 0 pad, 1 stem, 2.. down-sampling, then the FFC blocks,
        a concat, (ConvTranspose, BN, ReLU) per up-sampling, pad, 7x7 conv, sigmoid.
        """

        def __init__(self, in_ch=4, out_ch=3, ngf=64, n_down=3, n_blocks=18, ratio=0.75, max_feat=1024):
            super().__init__()
            layers: list = [nn.ReflectionPad2d(3), FFC_BN_ACT(in_ch, ngf, 7, 0, 0)]
            for i in range(n_down):
                c_in, c_out = min(max_feat, ngf * 2 ** i), min(max_feat, ngf * 2 ** (i + 1))
                layers.append(FFC_BN_ACT(c_in, c_out, 3, 0, ratio if i == n_down - 1 else 0, stride=2, padding=1))
            dim = min(max_feat, ngf * 2 ** n_down)
            layers += [FFCResnetBlock(dim, ratio) for _ in range(n_blocks)]
            layers.append(ConcatTuple())
            for i in range(n_down):
                c_in, c_out = min(max_feat, ngf * 2 ** (n_down - i)), min(max_feat, ngf * 2 ** (n_down - i - 1))
                layers += [nn.ConvTranspose2d(c_in, c_out, 3, stride=2, padding=1, output_padding=1),
                           nn.BatchNorm2d(c_out), nn.ReLU(True)]
            layers += [nn.ReflectionPad2d(3), nn.Conv2d(ngf, out_ch, 7), nn.Sigmoid()]
            self.model = nn.Sequential(*layers)
            self.n_down = n_down

        def forward(self, x):
            x = self.model[0](x)
            x = self.model[1]((x, 0))
            return self.model[2:](x)

    return FFCResNetGenerator


def lama_class():
    """The FFCResNetGenerator nn.Module class (built lazily: importing this module skips torch)."""
    return _modules()


def lama_from_state_dict(state: dict):
    """A generator shaped like ``state`` (release key names; ``generator.`` prefix optional)."""
    if "state_dict" in state and isinstance(state["state_dict"], dict):
        state = state["state_dict"]
    if any(k.startswith("generator.") for k in state):
        state = {k.removeprefix("generator."): v for k, v in state.items() if k.startswith("generator.")}
    idx = lambda pat: sorted({int(m.group(1)) for k in state if (m := re.match(pat, k))})  # noqa: E731
    blocks = idx(r"model\.(\d+)\.conv1\.")
    downs = [i for i in idx(r"model\.(\d+)\.ffc\.") if i >= 2]
    stem = state["model.1.ffc.convl2l.weight"]                             # [ngf, in_ch, 7, 7]
    g = state[f"model.{blocks[0]}.conv1.ffc.convg2g.conv1.0.weight"].shape[1] if blocks else 0
    dim = state[f"model.{blocks[0]}.conv1.ffc.convl2l.weight"].shape[1] + g if blocks else 0
    ups = idx(r"model\.(\d+)\.weight")
    out_ch = state[f"model.{ups[-1]}.weight"].shape[0]
    net = lama_class()(in_ch=stem.shape[1], out_ch=out_ch, ngf=stem.shape[0], n_down=len(downs),
                       n_blocks=len(blocks), ratio=(g + 0.5) / dim if dim else 0.0)  # int(dim*r) == g
    net.load_state_dict(state, strict=True)
    return net.eval()


def inpaint(images: np.ndarray, masks: np.ndarray, model: str = "", device: str = "cpu",
            progress: Progress = None) -> np.ndarray:
    """Fill ``masks == 1`` pixels of linear RGB ``images [N, H, W, 3]``; known pixels are kept.

    masks: ``[N, H, W]``, 1 = missing (> 0.5 counts). Views with nothing missing are returned as is.
    """
    import torch
    from torch.nn import functional as F

    file = weight_file(resolve(model, "lama", "inp_set.model"), "lama", "inp_set.model")
    dev = torch_device(device)
    net = lama_from_state_dict(load_state_dict(file)).to(dev)
    out = np.array(images, dtype=np.float32, copy=True)
    holes = np.asarray(masks) > 0.5                                        # [N, H, W]
    todo = [i for i in range(len(out)) if holes[i].any()]
    m = 2 ** net.n_down
    for n, i in enumerate(todo):
        report(progress, n, len(todo), "views")
        img = torch.from_numpy(linear_to_srgb(out[i], clip=True)).permute(2, 0, 1)[None].to(dev)  # [1, 3, H, W]
        hole = torch.from_numpy(holes[i].astype(np.float32))[None, None].to(dev)       # [1, 1, H, W]
        h, w = img.shape[-2:]
        ph, pw = (-h) % m, (-w) % m
        x = torch.cat([img * (1 - hole), hole], dim=1)
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        with torch.inference_mode():
            pred = net(x)[..., :h, :w]                                      # [1, 3, H, W] sRGB
        pred = (pred * hole + img * (1 - hole))[0].permute(1, 2, 0).cpu().numpy()
        out[i] = np.where(holes[i][..., None], srgb_to_linear(pred, clip=True), out[i])
    report(progress, len(todo), len(todo), "views")
    return out
