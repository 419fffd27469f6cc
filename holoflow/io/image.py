"""A user's own panorama file -> linear RGB equirect (what ``--use base_pano=FILE`` imports); and the
one PNG writer (``write_png``).

Reads JPG, PNG (8 / 16 bit), TIFF, HDR and EXR through OpenImageIO. Integer files (8 / 16 bit) are
sRGB-encoded and decoded to linear light; float files (HDR, EXR, float TIFF) are linear already and
kept as they are (values > 1 allowed), repaired by holoflow.io.validate's colour rule (NaN, inf,
negative, huge values; counted in the facts). A file the decoder reports as damaged (a JPEG cut short)
is refused. An equirect panorama is 2:1; anything else is refused with one
line giving the size. XMP GPano metadata (Google's photo-sphere tags) is honoured: a cropped panorama
(``GPano:CroppedAreaImageWidthPixels`` < ``GPano:FullPanoWidthPixels``) is placed at its
``CroppedAreaLeftPixels`` / ``CroppedAreaTopPixels`` into the full equirect canvas (black elsewhere).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from .validate import InputRefused, check_equirect_size, colour_rule, describe, repair_colour

#: extensions that import as images (EXR is read by holoflow.io.exr when it is a holoflow file)
IMAGE_EXTS = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".hdr", ".exr")
_GPANO = (
    "FullPanoWidthPixels",
    "FullPanoHeightPixels",
    "CroppedAreaImageWidthPixels",
    "CroppedAreaImageHeightPixels",
    "CroppedAreaLeftPixels",
    "CroppedAreaTopPixels",
)


class ImageImportError(InputRefused):
    """A file that cannot be used as an equirect panorama: one line, with the fix."""


def read_panorama_image(path: str | Path) -> tuple[np.ndarray, dict]:
    """Linear RGB [H, W, 3] float32 of an equirect panorama file, and its import facts (file name,
    sha256, size, pixel format, colour handling, GPano placement). Raises ImageImportError."""
    import OpenImageIO as oiio

    path = Path(path)
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        why = (oiio.geterror().strip() or "unknown format").splitlines()[0]
        raise ImageImportError(
            f"{path.name}: OpenImageIO cannot read it ({why}); fix: pass a JPG, PNG, TIFF, HDR or EXR panorama"
        )
    try:
        spec = inp.spec()
        fmt = str(spec.format)
        codes = fmt in ("uint8", "uint16")  # read as stored: linearised through a table below
        pixels = inp.read_image(0, 0, 0, min(spec.nchannels, 4), fmt if codes else "float")
        damage = inp.geterror().strip() if inp.has_error else ""
    finally:
        inp.close()
    if damage:  # a file cut short or corrupt: the decoder filled what it could not read
        raise ImageImportError(
            f"{path.name} is damaged (the decoder says: {damage.splitlines()[0]}); fix: copy or export the file again"
        )
    if pixels is None or spec.width < 1 or spec.height < 1:
        raise ImageImportError(f"{path.name}: no pixels could be read; fix: check the file")
    img = np.asarray(pixels).reshape(spec.height, spec.width, -1)
    rgb = img[..., :3] if img.shape[2] >= 3 else np.repeat(img[..., :1], 3, axis=2)
    integer = fmt.startswith("uint") or fmt.startswith("int")
    colour = "linear (float file, kept)"
    if integer:
        from holoflow.imageops.color import srgb_to_linear

        if codes:  # one table entry per code: the same curve, 1 / 30 of the time on a 6656 px photo
            top = np.iinfo(img.dtype).max
            # code x (1 / top) in float32: OpenImageIO's own conversion, so the values are its float read's
            rgb = srgb_to_linear(np.arange(top + 1, dtype=np.float32) * np.float32(1.0 / top))[rgb]
        else:
            rgb = srgb_to_linear(rgb)
        colour = f"sRGB {fmt} decoded to linear"
    try:
        rgb, counts = repair_colour(rgb)
    except ValueError as e:
        raise ImageImportError(f"{path.name}: {e}") from None
    facts = {
        "file": path.name,
        "sha256": _sha256(path),
        "size": [spec.width, spec.height],
        "format": fmt,
        "colour": colour,
    }
    if counts:
        facts["repaired"] = f"R,G,B: {describe(counts, rgb.size)} ({colour_rule()})"
    gpano = {k: spec.getattribute(f"GPano:{k}") for k in _GPANO}
    if all(gpano.get(k) is not None for k in _GPANO[:4]):
        rgb, placed = place_cropped(rgb, {k: int(v) for k, v in gpano.items() if v is not None})
        facts["gpano"] = placed
    try:
        check_equirect_size(path.name, rgb.shape[1], rgb.shape[0])
    except InputRefused as e:
        raise ImageImportError(str(e)) from None
    return rgb, facts


def place_cropped(rgb: np.ndarray, gpano: dict) -> tuple[np.ndarray, dict]:
    """Place a cropped panorama [h, w, 3] into its full canvas (GPano pixel fields) -> [H, W, 3], facts.

    The crop's own size may differ from the tagged one (a resized file): everything is scaled by the
    ratio of the actual width to ``CroppedAreaImageWidthPixels``. Columns wrap at the seam."""
    h, w = rgb.shape[:2]
    full_w, full_h = gpano["FullPanoWidthPixels"], gpano["FullPanoHeightPixels"]
    cw, ch = gpano["CroppedAreaImageWidthPixels"], gpano["CroppedAreaImageHeightPixels"]
    if (cw, ch) == (full_w, full_h):
        return rgb, {"cropped": False}
    s = w / max(cw, 1)
    FW, FH = int(round(full_w * s)), int(round(full_h * s))
    left, top = (
        int(round(gpano.get("CroppedAreaLeftPixels", 0) * s)),
        int(round(gpano.get("CroppedAreaTopPixels", 0) * s)),
    )
    out = np.zeros((FH, FW, 3), np.float32)
    rows = np.arange(h) + top
    keep = (rows >= 0) & (rows < FH)
    cols = (np.arange(w) + left) % FW
    out[np.ix_(rows[keep], cols)] = rgb[keep]
    return out, {
        "cropped": True,
        "full": [FW, FH],
        "left": left,
        "top": top,
        "crop": [w, h],
        "note": "placed into the full equirect canvas from XMP GPano; uncovered pixels are black",
    }


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_png(path: str | Path, rgb_u8: np.ndarray) -> None:
    """Write an 8-bit sRGB image [H, W, 3] as a PNG (Pillow, no optimisation pass: the same bytes for
    the same pixels); the one PNG writer (previews, pictures)."""
    from PIL import Image

    Image.fromarray(np.ascontiguousarray(rgb_u8), "RGB").save(str(path), optimize=False)
