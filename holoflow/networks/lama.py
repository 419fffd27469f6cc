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

import re

import numpy as np

from holoflow.imageops.color import linear_to_srgb, srgb_to_linear
from holoflow.networks.common import report, torch_device
from holoflow.networks.weights import load_state_dict, resolve, weight_file
from holoflow.stage import Progress


def lama_class():
    """The FFCResNetGenerator nn.Module class (holoflow/networks/lama_arch.py, imported here so that
    importing this module skips torch)."""
    from holoflow.networks.lama_arch import FFCResNetGenerator

    return FFCResNetGenerator


def lama_from_state_dict(state: dict):
    """A generator shaped like ``state`` (release key names; ``generator.`` prefix optional)."""
    if "state_dict" in state and isinstance(state["state_dict"], dict):
        state = state["state_dict"]
    if any(k.startswith("generator.") for k in state):
        state = {k.removeprefix("generator."): v for k, v in state.items() if k.startswith("generator.")}
    idx = lambda pat: sorted({int(m.group(1)) for k in state if (m := re.match(pat, k))})  # noqa: E731
    blocks = idx(r"model\.(\d+)\.conv1\.")
    downs = [i for i in idx(r"model\.(\d+)\.ffc\.") if i >= 2]
    stem = state["model.1.ffc.convl2l.weight"]  # [ngf, in_ch, 7, 7]
    g = state[f"model.{blocks[0]}.conv1.ffc.convg2g.conv1.0.weight"].shape[1] if blocks else 0
    dim = state[f"model.{blocks[0]}.conv1.ffc.convl2l.weight"].shape[1] + g if blocks else 0
    ups = idx(r"model\.(\d+)\.weight")
    out_ch = state[f"model.{ups[-1]}.weight"].shape[0]
    net = lama_class()(
        in_ch=stem.shape[1],
        out_ch=out_ch,
        ngf=stem.shape[0],
        n_down=len(downs),
        n_blocks=len(blocks),
        ratio=(g + 0.5) / dim if dim else 0.0,
    )  # int(dim*r) == g
    net.load_state_dict(state, strict=True)
    return net.eval()


def inpaint(
    images: np.ndarray, masks: np.ndarray, model: str = "", device: str = "cpu", progress: Progress = None
) -> np.ndarray:
    """Fill ``masks == 1`` pixels of linear RGB ``images [N, H, W, 3]``; known pixels are kept.

    masks: ``[N, H, W]``, 1 = missing (> 0.5 counts). Views with nothing missing are returned as is.
    """
    import torch
    from torch.nn import functional as F

    file = weight_file(resolve(model, "lama", "inp_set.model"), "lama", "inp_set.model")
    dev = torch_device(device)
    net = lama_from_state_dict(load_state_dict(file)).to(dev)
    out = np.array(images, dtype=np.float32, copy=True)
    holes = np.asarray(masks) > 0.5  # [N, H, W]
    todo = [i for i in range(len(out)) if holes[i].any()]
    m = 2**net.n_down
    for n, i in enumerate(todo):
        report(progress, n, len(todo), "views")
        img = torch.from_numpy(linear_to_srgb(out[i], clip=True)).permute(2, 0, 1)[None].to(dev)  # [1, 3, H, W]
        hole = torch.from_numpy(holes[i].astype(np.float32))[None, None].to(dev)  # [1, 1, H, W]
        h, w = img.shape[-2:]
        ph, pw = (-h) % m, (-w) % m
        x = torch.cat([img * (1 - hole), hole], dim=1)
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        with torch.inference_mode():
            pred = net(x)[..., :h, :w]  # [1, 3, H, W] sRGB
        pred = (pred * hole + img * (1 - hole))[0].permute(1, 2, 0).cpu().numpy()
        out[i] = np.where(holes[i][..., None], srgb_to_linear(pred, clip=True), out[i])
    report(progress, len(todo), len(todo), "views")
    return out
