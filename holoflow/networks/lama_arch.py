"""LaMa's generator (big-lama): fast Fourier convolutions (FFC) in a ResNet, as nn.Modules whose
parameter names match the release's state dict. Imports torch: holoflow/networks/lama.py loads this
module only when a model is built."""

from __future__ import annotations

import torch
from torch import nn


class FourierUnit(nn.Module):
    """1x1 conv + BN + ReLU on the real/imag parts of the 2D real FFT (channels interleaved)."""

    def __init__(self, in_ch: int, out_ch: int):
        super().__init__()
        self.conv_layer = nn.Conv2d(in_ch * 2, out_ch * 2, 1, bias=False)
        self.bn = nn.BatchNorm2d(out_ch * 2)
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x):  # [B, C, H, W]
        b, _, h, w = x.shape
        f = torch.fft.rfftn(x.float(), dim=(-2, -1), norm="ortho")  # [B, C, H, W//2+1]
        f = torch.stack((f.real, f.imag), dim=2).reshape(b, -1, h, f.shape[-1]).to(x.dtype)
        f = self.relu(self.bn(self.conv_layer(f)))  # [B, 2C', H, W//2+1]
        f = f.reshape(b, -1, 2, h, f.shape[-1]).float()
        return torch.fft.irfftn(torch.complex(f[:, :, 0], f[:, :, 1]), s=(h, w), dim=(-2, -1), norm="ortho").to(x.dtype)


class SpectralTransform(nn.Module):
    """Global branch: 1x1 reduce, Fourier unit, residual, 1x1 expand."""

    def __init__(self, in_ch: int, out_ch: int):
        super().__init__()
        self.conv1 = nn.Sequential(
            nn.Conv2d(in_ch, out_ch // 2, 1, bias=False), nn.BatchNorm2d(out_ch // 2), nn.ReLU(inplace=True)
        )
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
            c_in, c_out = min(max_feat, ngf * 2**i), min(max_feat, ngf * 2 ** (i + 1))
            layers.append(FFC_BN_ACT(c_in, c_out, 3, 0, ratio if i == n_down - 1 else 0, stride=2, padding=1))
        dim = min(max_feat, ngf * 2**n_down)
        layers += [FFCResnetBlock(dim, ratio) for _ in range(n_blocks)]
        layers.append(ConcatTuple())
        for i in range(n_down):
            c_in, c_out = min(max_feat, ngf * 2 ** (n_down - i)), min(max_feat, ngf * 2 ** (n_down - i - 1))
            layers += [
                nn.ConvTranspose2d(c_in, c_out, 3, stride=2, padding=1, output_padding=1),
                nn.BatchNorm2d(c_out),
                nn.ReLU(True),
            ]
        layers += [nn.ReflectionPad2d(3), nn.Conv2d(ngf, out_ch, 7), nn.Sigmoid()]
        self.model = nn.Sequential(*layers)
        self.n_down = n_down

    def forward(self, x):
        x = self.model[0](x)
        x = self.model[1]((x, 0))
        return self.model[2:](x)
