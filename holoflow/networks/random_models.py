"""Randomly initialised models of the engines' real architectures, saved the way real weights are.

``full=False``: tiny widths and depths, for tests (seconds on a CPU). ``full=True``: the published
sizes (SD 1.5 UNet/VAE/CLIP-L text encoder, ControlNet, RRDBNet x4plus, big-lama, Depth Anything
V2 Small or Large, ZoeDepth NK with BEiT-L/384), for timing the engines at paper resolution without the real
weights: compute cost does not depend on the weight values. Every engine loads these through its
own loading code (``from_pretrained`` from the folder, or its state-dict loader), as it would a
user's download. The outputs of random models are meaningless images; only shapes, ranges, seams,
determinism and timings are checked with them.
"""

from __future__ import annotations

from pathlib import Path


def _byte_chars() -> list[str]:
    """The 256 printable stand-ins byte-level BPE uses for bytes (GPT-2 / CLIP convention)."""
    keep = set(range(ord("!"), ord("~") + 1)) | set(range(ord("¡"), ord("¬") + 1)) | set(range(ord("®"), ord("ÿ") + 1))
    chars, n = [], 0
    for b in range(256):
        if b in keep:
            chars.append(chr(b))
        else:
            chars.append(chr(256 + n))
            n += 1
    return chars


def tokenizer_vocab() -> tuple[dict[str, int], list[tuple[str, str]]]:
    """A tiny CLIP BPE: bytes, word-final bytes, a few merges, the two special tokens."""
    chars = _byte_chars()
    vocab = {c: i for i, c in enumerate(chars)}
    vocab.update({c + "</w>": 256 + i for i, c in enumerate(chars)})
    merges = [("a", "n</w>"), ("t", "h"), ("th", "e</w>")]
    for a, b in merges:
        vocab.setdefault(a + b, len(vocab))
    vocab["<|startoftext|>"] = len(vocab)
    vocab["<|endoftext|>"] = len(vocab)
    return vocab, merges


def save_sd(folder: Path, full: bool = False, seed: int = 0) -> Path:
    """An SD 1.x pipeline folder (unet, vae, text_encoder, tokenizer, scheduler, model_index.json)."""
    import torch
    from diffusers import AutoencoderKL, PNDMScheduler, StableDiffusionPipeline, UNet2DConditionModel
    from transformers import CLIPTextConfig, CLIPTextModel, CLIPTokenizer

    torch.manual_seed(seed)
    vocab, merges = tokenizer_vocab()
    tokenizer = CLIPTokenizer(vocab=vocab, merges=merges, model_max_length=77)
    hidden = 768 if full else 16
    text = CLIPTextModel(
        CLIPTextConfig(
            vocab_size=len(vocab),
            hidden_size=hidden,
            intermediate_size=4 * hidden,
            projection_dim=hidden,
            num_attention_heads=12 if full else 2,
            num_hidden_layers=12 if full else 2,
            max_position_embeddings=77,
            bos_token_id=vocab["<|startoftext|>"],
            eos_token_id=vocab["<|endoftext|>"],
            pad_token_id=vocab["<|endoftext|>"],
        )
    )
    if full:
        unet = UNet2DConditionModel(
            sample_size=64,
            layers_per_block=2,
            block_out_channels=(320, 640, 1280, 1280),
            cross_attention_dim=768,
            attention_head_dim=8,
        )
        vae = AutoencoderKL(
            block_out_channels=(128, 256, 512, 512),
            layers_per_block=2,
            latent_channels=4,
            sample_size=512,
            down_block_types=("DownEncoderBlock2D",) * 4,
            up_block_types=("UpDecoderBlock2D",) * 4,
        )
    else:
        unet = UNet2DConditionModel(
            sample_size=16,
            layers_per_block=1,
            block_out_channels=(8, 16),
            norm_num_groups=4,
            cross_attention_dim=16,
            attention_head_dim=2,
            down_block_types=("CrossAttnDownBlock2D", "DownBlock2D"),
            up_block_types=("UpBlock2D", "CrossAttnUpBlock2D"),
        )
        vae = AutoencoderKL(
            block_out_channels=(8, 16),
            norm_num_groups=4,
            layers_per_block=1,
            latent_channels=4,
            sample_size=32,
            down_block_types=("DownEncoderBlock2D",) * 2,
            up_block_types=("UpDecoderBlock2D",) * 2,
        )
    sched = PNDMScheduler(
        beta_start=0.00085,
        beta_end=0.012,
        beta_schedule="scaled_linear",
        skip_prk_steps=True,
        set_alpha_to_one=False,
        steps_offset=1,
    )
    pipe = StableDiffusionPipeline(
        vae=vae,
        text_encoder=text,
        tokenizer=tokenizer,
        unet=unet,
        scheduler=sched,
        safety_checker=None,
        feature_extractor=None,
        requires_safety_checker=False,
    )
    pipe.save_pretrained(str(folder))
    return folder


def save_controlnet(sd_folder: Path, folder: Path, full: bool = False, seed: int = 1) -> Path:
    """A ControlNet made from the pipeline's UNet. Its zero-initialised output convs are perturbed
    so the control image really changes the result (as trained weights do)."""
    import torch
    from diffusers import ControlNetModel, UNet2DConditionModel

    torch.manual_seed(seed)
    unet = UNet2DConditionModel.from_pretrained(str(sd_folder), subfolder="unet")
    cnet = ControlNetModel.from_unet(unet, conditioning_embedding_out_channels=(16, 32, 96, 256) if full else (4, 8))
    with torch.no_grad():
        for p in cnet.parameters():
            p.add_(0.05 * torch.randn_like(p))
    cnet.save_pretrained(str(folder))
    return folder


def save_rrdbnet(path: Path, scale: int = 4, full: bool = False, seed: int = 0) -> Path:
    """An RRDBNet state dict in the official checkpoints' layout (``{"params_ema": ...}``)."""
    import torch

    from holoflow.networks.realesrgan import rrdbnet_class

    torch.manual_seed(seed)
    net = (
        rrdbnet_class()(scale=scale, num_feat=64, num_block=23, num_grow_ch=32)
        if full
        else rrdbnet_class()(scale=scale, num_feat=8, num_block=1, num_grow_ch=4)
    )
    torch.save({"params_ema": net.state_dict()}, str(path))
    return path


def save_lama(path: Path, full: bool = False, seed: int = 0) -> Path:
    """A LaMa generator state dict under ``generator.`` (as in the released Lightning checkpoint)."""
    import torch
    from safetensors.torch import save_file

    from holoflow.networks.lama import lama_class

    torch.manual_seed(seed)
    net = lama_class()() if full else lama_class()(ngf=8, n_down=2, n_blocks=2)
    save_file({"generator." + k: v.contiguous() for k, v in net.state_dict().items()}, str(path))
    return path


# Depth Anything sizes: (backbone width, layers, heads, layers whose features the DPT head takes, neck
# widths, fusion width, head width, input side px). large = ViT-L/14 (v1 / V2 Large), small = ViT-S/14
# (V2 Small), tiny = the same classes for tests.
DEPTH_ANYTHING_SIZES = {
    "large": (1024, 24, 16, (5, 12, 18, 24), [256, 512, 1024, 1024], 256, 32, 518),
    "small": (384, 12, 6, (3, 6, 9, 12), [48, 96, 192, 384], 64, 32, 518),
    "tiny": (16, 4, 2, (1, 2, 3, 4), [8, 8, 16, 16], 8, 8, 56),
}


def save_depth_anything(folder: Path, full: bool = False, seed: int = 0, variant: str = "small") -> Path:
    """Depth Anything (DINOv2 backbone + DPT head) folder with its preprocessor config. ``full``: the
    published size of ``variant`` "small" (V2 Small: ViT-S/14, 24.8 M parameters, the default model) or
    "large" (v1 / V2 Large: ViT-L/14, 335 M); otherwise a tiny model of the same classes."""
    import torch
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config, DPTImageProcessorPil

    size = "tiny" if not full else variant
    if size not in DEPTH_ANYTHING_SIZES:
        raise ValueError(f"unknown Depth Anything variant {variant!r}; use small or large")
    hidden, layers, heads, taps, neck, fusion, head, side = DEPTH_ANYTHING_SIZES[size]
    torch.manual_seed(seed)
    backbone = Dinov2Config(
        hidden_size=hidden,
        num_hidden_layers=layers,
        num_attention_heads=heads,
        intermediate_size=4 * hidden if full else 2 * hidden,
        image_size=side,
        patch_size=14,
        reshape_hidden_states=False,
        out_features=[f"stage{k}" for k in taps],
    )
    cfg = DepthAnythingConfig(
        backbone_config=backbone,
        reassemble_hidden_size=hidden,
        fusion_hidden_size=fusion,
        neck_hidden_sizes=neck,
        head_hidden_size=head,
    )
    net = DepthAnythingForDepthEstimation(cfg)
    with torch.no_grad():
        net.head.conv3.bias.fill_(0.5)  # random init + the final ReLU would give all-zero disparity
    net.save_pretrained(str(folder))
    DPTImageProcessorPil(
        size={"height": side, "width": side},
        keep_aspect_ratio=True,
        ensure_multiple_of=14,
        image_mean=[0.485, 0.456, 0.406],
        image_std=[0.229, 0.224, 0.225],
    ).save_pretrained(str(folder))
    return folder


def save_zoedepth(folder: Path, full: bool = False, seed: int = 0) -> Path:
    """ZoeDepth with the NK metric head (two bin configurations: NYU indoor, KITTI outdoor)."""
    import torch
    from transformers import BeitConfig, ZoeDepthConfig, ZoeDepthForDepthEstimation, ZoeDepthImageProcessorPil

    torch.manual_seed(seed)
    bins = 64 if full else 8
    nk = [
        {"name": "nyu", "n_bins": bins, "min_depth": 1e-3, "max_depth": 10.0},
        {"name": "kitti", "n_bins": bins, "min_depth": 1e-3, "max_depth": 80.0},
    ]
    if full:  # BEiT-L/16 at 384, features from layers 6, 12, 18, 24
        backbone = BeitConfig(
            image_size=384,
            patch_size=16,
            hidden_size=1024,
            num_hidden_layers=24,
            num_attention_heads=16,
            intermediate_size=4096,
            out_indices=[6, 12, 18, 24],
            use_relative_position_bias=True,
            reshape_hidden_states=False,
            add_fpn=False,
        )
        cfg = ZoeDepthConfig(
            backbone_config=backbone,
            bin_configurations=nk,
            num_patch_transformer_layers=4,
            patch_transformer_hidden_size=128,
            patch_transformer_intermediate_size=1024,
            patch_transformer_num_attention_heads=4,
        )
        size = {"height": 384, "width": 512}
    else:  # the NK domain classifier needs a 128-wide patch transformer whatever the rest
        backbone = BeitConfig(
            image_size=64,
            patch_size=16,
            hidden_size=16,
            num_hidden_layers=4,
            num_attention_heads=2,
            intermediate_size=32,
            out_indices=[1, 2, 3, 4],
            use_relative_position_bias=True,
            reshape_hidden_states=False,
            add_fpn=False,
        )
        cfg = ZoeDepthConfig(
            backbone_config=backbone,
            neck_hidden_sizes=[8, 8, 16, 16],
            fusion_hidden_size=8,
            bottleneck_features=8,
            num_relative_features=4,
            bin_embedding_dim=8,
            num_attractors=[4, 2, 2, 1],
            num_patch_transformer_layers=4,
            patch_transformer_hidden_size=128,
            patch_transformer_intermediate_size=16,
            patch_transformer_num_attention_heads=2,
            bin_configurations=nk,
        )
        size = {"height": 64, "width": 64}
    ZoeDepthForDepthEstimation(cfg).save_pretrained(str(folder))
    ZoeDepthImageProcessorPil(size=size, keep_aspect_ratio=True, ensure_multiple_of=32).save_pretrained(str(folder))
    return folder
