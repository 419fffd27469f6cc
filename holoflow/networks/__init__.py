"""Real-model engines: the paper's path (docs/engines.md).

One module per engine, each a plain function on numpy images (linear RGB float32 in [0, 1]):
``diffusion360.generate_pano``, ``controlnet_lineart.stylize``, ``realesrgan.upscale``,
``controlnet_tile.refine``, ``depth_anything.relative_disparity``, ``zoedepth.metric_depth``,
``lama.inpaint``. Weights come from a local path or the user's HF cache (``weights.resolve``);
missing weights raise ``weights.MissingWeights`` with one line saying what to download.
Nothing heavy is imported here: torch, diffusers and transformers load inside the functions.
"""
