"""A user's photo stays their photo on its way to the detail panorama.

An image taken with ``--use base_pano=PHOTO`` carries ``holoflow.source`` in its EXR header
(holoflow/flow/uses.py). stylize, upscale and detail carry that provenance on and add
``holoflow.unaltered`` (1 while every stage so far passed the pixels through untouched, 0 once one
changed them). The rules, for every engine:

- stylize passes a photo through unless a style is asked for (a style word in the prompt, or
  ``stylize.style`` naming one);
- no stage shrinks its input: an input larger than the stage's width x height keeps its own size, up
  to the stage's ``max_width`` (recorded in the header and the step's record);
- detail leaves an unaltered photo alone (nothing was styled or upscaled, so there is nothing to
  restore).

Without a style the detail panorama is then the photo itself, value for value.
"""

from __future__ import annotations

from typing import Any

import numpy as np

SOURCE_KEYS = ("holoflow.source", "holoflow.source_sha256", "holoflow.source_colour")
UNALTERED = "holoflow.unaltered"
MAX_WIDTH = "holoflow.max_width"


def is_photo(attrs: dict[str, Any]) -> bool:
    """True when the panorama came from a user's image file (``--use``)."""
    return "holoflow.source" in attrs


def unaltered(attrs: dict[str, Any]) -> bool:
    """True when the panorama is a user's image with every pixel as imported."""
    return is_photo(attrs) and int(attrs.get(UNALTERED, 1)) == 1


def provenance(attrs: dict[str, Any], same: bool, max_width: int) -> dict[str, Any]:
    """Header attributes a stage writes after reading ``attrs``: the photo's source keys, whether the
    pixels are still the photo's (``same``: this stage changed nothing) and the size cap it used."""
    out: dict[str, Any] = {MAX_WIDTH: int(max_width)}
    if is_photo(attrs):
        out.update({k: attrs[k] for k in SOURCE_KEYS if k in attrs})
        out[UNALTERED] = int(unaltered(attrs) and same)
    return out


def keep_size(shape: tuple[int, ...], width: int, height: int, max_width: int) -> tuple[int, int]:
    """Output (height, width) of a stage sized ``width`` x ``height`` for an input of ``shape``
    [H, W, ...]: the stage's size, or the input's own when it is wider (up to ``max_width`` px,
    aspect kept; 0 = no cap), so no stage shrinks a photo below its resolution."""
    H, W = int(shape[0]), int(shape[1])
    if W <= width:
        return height, width
    w = W if max_width <= 0 else max(width, min(W, max_width))
    return (H, W) if w == W else (max(1, round(H * w / W)), w)


def same_pixels(a: np.ndarray, b: np.ndarray) -> bool:
    """True when two panoramas hold the same values (shape and every element)."""
    return a.shape == b.shape and bool(np.array_equal(a, b))


def unstyled_photo(
    photo: np.ndarray, width: int, height: int, max_width: int
) -> tuple[np.ndarray, np.ndarray, dict[str, Any], dict[str, Any]]:
    """stylize for a user's photo with no style asked for, as a stylize engine returns it: the photo
    [H, W, 3] linear at its own size (:func:`keep_size`; wider than ``max_width``: Lanczos-resized to it),
    its XDoG lineart [h, w] (1 = line), header attributes and record facts."""
    from holoflow.imageops.lineart import lineart
    from holoflow.imageops.resize import lanczos_resize

    h, w = keep_size(photo.shape, width, height, max_width)
    out = photo if w >= photo.shape[1] else lanczos_resize(photo, w, h)
    return out, lineart(out), {"holoflow.style": "none"}, {"style": "none (user's photo)"}
