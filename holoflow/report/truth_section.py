"""The report's walking section: a run's scores against truth sets, as ``holoflow eval run RUN --truth DIR``
left them in the run's ``eval/`` folder (``truth-<set>.json`` and one truth | render PNG per ring,
holoflow.evaluation.truth_scores), so the eye can check the ring table."""

from __future__ import annotations

import json
from pathlib import Path


def truth_sections(folder: Path) -> list[str]:
    """HTML sections, one per ``truth-<set>.json`` in ``folder`` (sorted; [] when there is none): the
    ring table and each ring's picture, truth above render."""
    import numpy as np
    from PIL import Image

    from holoflow.evaluation.truth_scores import ring_table
    from holoflow.report.figures import Figure
    from holoflow.report.page import esc, figure_html
    from holoflow.report.pictures import image_uri

    out = []
    for f in sorted(folder.glob("truth-*.json")) if folder.is_dir() else []:
        scores = json.loads(f.read_text())
        figs = []
        for key, name in scores.get("pictures", {}).items():
            if (folder / name).is_file():
                with Image.open(folder / name) as im:
                    img = np.asarray(im.convert("RGB"))
                r = scores["rings"][key]
                cap = f"{r['views']} views; PSNR {r['psnr']:.2f} dB, alpha < 0.9 {100 * r['cracked']:.2f} %"
                figs.append(Figure(f"ring {key} m: truth above render", image_uri(img), cap))
        head = f'<h2 id="{esc(f.stem)}">walking: against the truth set {esc(Path(scores["truth"]).name)}</h2>'
        out.append("\n".join([head, f"<pre>{esc(chr(10).join(ring_table(scores)))}</pre>", *map(figure_html, figs)]))
    return out
