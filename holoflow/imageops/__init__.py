"""Classical image operations on panoramas: the embedded default engines of stylize / upscale / detail.

Every operation that filters or resizes is wrap-aware: columns are padded circularly before and cropped
after, so the +-180 deg seam stays continuous (docs/conventions.md). Images are float32 [H, W, C]
numpy arrays; EXR data is linear light, 8-bit operations run in sRGB (``color``). See docs/panorama.md.
"""
