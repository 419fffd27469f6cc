"""The INP set: which pixels of G0's render at a supplementary camera are missing, and how they are filled.

Missing mask (1 = missing), per supplementary view:

    missing = (rendered alpha < alpha_threshold)  OR  (PCD mask says no point landed)

Why both. Rendered alpha alone misses disocclusions: the PCD phase of pre_opt leaves hole pixels
unsupervised and the PANO phase sees them only from the centre, so G0 is free to put stretched,
opaque Gaussians there (foreground edges smeared into the gap) and alpha is high over wrong content.
The PCD mask alone (the paper's M_ij, taken literally) misses what G0 failed to cover where points did
land, and says nothing about G0. Their union is the conservative choice: every pixel that nothing
observed, or that G0 does not cover, is filled by the inpainter. Its cost is that sampling pinholes
of the sparse P_s projection are filled too; those are a pixel or two wide, and filling them from
their neighbours changes almost nothing. Views whose mask is empty are passed through un-inpainted.

Engines: ``opencv`` (classical, no weights; ``method`` telea | ns via ``cv2.inpaint``,
fsr_fast | fsr_best via ``cv2.xphoto.inpaint``) and ``lama`` (``holoflow.engines.lama``). Images are
display-referred sRGB [N, H, W, 3] in [0, 1]: the inpainters are built for display images. Observed
pixels are returned bit-exact; only missing pixels change.
"""
from __future__ import annotations

import numpy as np

OPENCV_METHODS = ("telea", "ns", "fsr_fast", "fsr_best")


def missing_mask(alpha: np.ndarray, pcd_valid: np.ndarray | None, alpha_threshold: float = 0.5) -> np.ndarray:
    """Missing-pixel mask [N, H, W] bool (True = missing) from G0's rendered alpha [N, H, W] and the
    PCD set's validity [N, H, W] (1 = a point landed; None = no PCD mask)."""
    missing = np.asarray(alpha) < alpha_threshold
    if pcd_valid is not None:
        missing |= np.asarray(pcd_valid) < 0.5
    return missing


def inpaint_opencv(images: np.ndarray, masks: np.ndarray, method: str = "telea", radius: float = 5.0) -> np.ndarray:
    """Fill masked pixels with OpenCV's classical inpainting.

    images [N, H, W, 3] sRGB in [0, 1]; masks [N, H, W] (True/1 = missing); radius: neighbourhood in
    pixels (telea / ns). Returns [N, H, W, 3] float32; unmasked pixels are the input's, views with an
    empty mask are returned unchanged, fully masked views are set to mid grey (nothing to spread)."""
    import cv2

    if method not in OPENCV_METHODS:
        raise ValueError(f"inpaint: unknown opencv method {method!r}, expected one of {OPENCV_METHODS}")
    images = np.asarray(images, dtype=np.float32)
    masks = np.asarray(masks, dtype=bool)
    out = images.copy()
    for i in range(len(images)):
        m = masks[i]
        if not m.any():
            continue
        if m.all():
            out[i] = 0.5
            continue
        u8 = np.ascontiguousarray((np.clip(images[i], 0, 1) * 255.0 + 0.5).astype(np.uint8))
        m8 = m.astype(np.uint8)
        if method in ("telea", "ns"):
            flag = cv2.INPAINT_TELEA if method == "telea" else cv2.INPAINT_NS
            filled = cv2.inpaint(u8, m8, float(radius), flag)
        else:
            filled = np.zeros_like(u8)
            flag = cv2.xphoto.INPAINT_FSR_FAST if method == "fsr_fast" else cv2.xphoto.INPAINT_FSR_BEST
            cv2.xphoto.inpaint(u8, (1 - m8) * 255, filled, flag)      # xphoto: non-zero = valid
        out[i][m] = filled[m].astype(np.float32) / 255.0
    return out


def inpaint_views(images: np.ndarray, masks: np.ndarray, engine: str, params: dict, device: str = "cpu",
                  progress=None) -> np.ndarray:
    """Inpaint only the views that have missing pixels, with engine ``opencv`` or ``lama``.
    images [N, H, W, 3] sRGB [0, 1]; masks [N, H, W] bool. Returns [N, H, W, 3] float32 where observed
    pixels equal the input."""
    images = np.asarray(images, dtype=np.float32)
    masks = np.asarray(masks, dtype=bool)
    todo = np.flatnonzero(masks.reshape(len(masks), -1).any(1))
    out = images.copy()
    if len(todo) == 0:
        return out
    if engine == "opencv":
        filled = inpaint_opencv(images[todo], masks[todo], params.get("method", "telea"),
                                float(params.get("radius", 5)))
    elif engine == "lama":
        import torch

        from holoflow.engines import lama
        from holoflow.recon.views import linear_to_srgb, srgb_to_linear

        linear = srgb_to_linear(torch.from_numpy(images[todo])).numpy()   # the engine takes linear RGB
        filled = lama.inpaint(linear, masks[todo].astype(np.float32), params.get("model", ""), device, progress)
        filled = linear_to_srgb(torch.from_numpy(np.asarray(filled, np.float32))).numpy()
    else:
        raise ValueError(f"inpaint: unknown engine {engine!r}, expected opencv or lama")
    m = masks[todo][..., None]
    out[todo] = np.where(m, filled, images[todo])
    return out
