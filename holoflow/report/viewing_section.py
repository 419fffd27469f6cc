"""Pictures and the report section of the viewing-size scores (holoflow.evaluation.viewing_size), so the eye can
check the numbers: source | render crops at the viewing size, and the novel views with their holes.

Pure functions of ``score_run``'s (scores, pictures); images are uint8 [H, W, 3] sRGB.
"""

from __future__ import annotations

import numpy as np

EMPTY_RGB = (255, 0, 255)  # novel-view pixels with alpha below the threshold (nothing rendered there)
GAP = 4  # px of white between tiles


def pick_base(scores: dict) -> list[tuple[int, str]]:
    """Base cameras worth looking at: (index, why), in order: the non-polar camera with the lowest
    PSNR, the median one, then the zenith and nadir cameras (highest / lowest ``elevation_deg``)."""
    b = scores["base"]
    psnr, polar = b["per_camera_psnr"], b["polar"]
    side = sorted((p, i) for i, p in enumerate(psnr) if not polar[i])
    out = []
    if side:
        out += [(side[0][1], "lowest PSNR"), (side[len(side) // 2][1], "median PSNR")]
    elev = b["elevation_deg"]
    if any(polar):
        out += [
            (max(range(len(elev)), key=elev.__getitem__), "zenith"),
            (min(range(len(elev)), key=elev.__getitem__), "nadir"),
        ]
    return list(dict.fromkeys(out))


def crop(img: np.ndarray, side: int) -> np.ndarray:
    """The centre side x side px of uint8 [H, W, 3] at 1:1 (the whole image when smaller)."""
    h, w = img.shape[:2]
    y, x = max(0, (h - side) // 2), max(0, (w - side) // 2)
    return img[y : y + side, x : x + side]


def base_picture(scores: dict, pictures: dict, side: int = 256) -> tuple[np.ndarray, str]:
    """Rows source | render of the ``pick_base`` cameras, each the centre ``side`` px of the view at
    1:1 (the viewing size's own pixels), and a caption naming the rows."""
    from holoflow.evaluation.viewing_size import to_uint8

    src, ren = to_uint8(pictures["source"]), to_uint8(pictures["render"])
    rows, names = [], []
    for i, why in pick_base(scores):
        a, b = crop(src[i], side), crop(ren[i], side)
        gap = np.full((a.shape[0], GAP, 3), 255, np.uint8)
        rows.append(np.concatenate([a, gap, b], 1))
        names.append(f"camera {i} ({why}, {scores['base']['per_camera_psnr'][i]:.2f} dB)")
    sep = np.full((GAP, rows[0].shape[1], 3), 255, np.uint8)
    img = np.concatenate([x for r in rows for x in (r, sep)][:-1], 0)
    size = scores["spec"]["size"]
    return img, (
        f"left: the source's view ({scores['source']}), right: the scene's render; centre {side} px of "
        f"the {size} px views at 1:1; rows: " + "; ".join(names)
    )


def novel_picture(scores: dict, pictures: dict, distance: str = "0.5", side: int = 256) -> tuple[np.ndarray, str]:
    """The novel cameras of one distance (``novel_rig`` order), each fitted into ``side`` px, pixels
    with alpha below the threshold in magenta; a truth row above when the run has truth."""
    from holoflow.evaluation.viewing_size import to_uint8
    from holoflow.report.pictures import mosaic

    keys = list(scores["novel"])
    k = keys.index(distance)
    per = scores["novel"][distance]["cameras"]
    sl = slice(k * per, (k + 1) * per)
    ren = to_uint8(pictures["novel"][sl])
    empty = (pictures["novel_alpha"][sl] < scores["spec"]["empty_alpha"]).numpy()
    ren[empty] = EMPTY_RGB
    tiles = list(ren)
    truth = pictures.get("truth")
    if truth is not None:
        tiles = list(to_uint8(truth[sl])) + tiles
    cols = min(per, 4)
    r = scores["novel"][distance]
    cap = (
        f"{per} novel cameras {distance} m off centre (mean {r['offset_m']:.2f} m), looking toward the near "
        f"wall / right / back / left in turn; magenta = empty (alpha < {scores['spec']['empty_alpha']}), "
        f"{100 * r['empty']:.2f} % of the pixels"
        + (f"; first the {per} true views, then the {per} renders, in the same order" if truth is not None else "")
    )
    return mosaic(tiles, cols, side, gap=GAP), cap


def section_html(scores: dict, pictures: dict, profile: str | None) -> str:
    """The report's "what people see" section: the table with goals and both pictures."""
    from holoflow.evaluation.viewing_size import table
    from holoflow.report.figures import Figure
    from holoflow.report.page import esc, figure_html
    from holoflow.report.pictures import image_uri

    figs = []
    img, cap = base_picture(scores, pictures)
    figs.append(Figure(f"base cameras at {scores['spec']['size']} px", image_uri(img), cap))
    if "0.5" in scores["novel"]:
        img, cap = novel_picture(scores, pictures)
        figs.append(Figure("novel cameras 0.5 m off centre", image_uri(img), cap))
    return "\n".join(
        [
            f'<h2 id="viewing">what people see ({scores["spec"]["size"]} px)</h2>',
            f"<pre>{esc(chr(10).join(table(scores, profile)))}</pre>",
            *map(figure_html, figs),
        ]
    )
