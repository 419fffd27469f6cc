"""The report's HTML: one self-contained page (inline CSS, images as data: URIs, one small script).

The script runs on the window's load event and writes what loaded into ``<body>``:
``data-images-total``, ``data-images-loaded`` (complete and naturalWidth > 0) and
``data-images-broken`` (comma-separated titles); a broken image also gets a visible red label.
Tests read these attributes from headless Chromium's ``--dump-dom``.
"""

from __future__ import annotations

import html
import json
from typing import Any

from holoflow.report.figures import Figure
from holoflow.report.runinfo import RunInfo, StageInfo

CSS = """
body{font:14px/1.45 system-ui,-apple-system,'Segoe UI',sans-serif;margin:0 auto;max-width:1180px;padding:18px;
     color:#1d232a;background:#fbfbfa}
h1{font-size:22px;margin:0 0 4px}h2{font-size:17px;margin:28px 0 6px;border-bottom:1px solid #ddd;padding-bottom:3px}
table{border-collapse:collapse;margin:6px 0 10px}td,th{padding:2px 9px;border-bottom:1px solid #e4e4e4;text-align:left;
     vertical-align:top}th{background:#f0f0ee;font-weight:600}td.n{text-align:right;font-variant-numeric:tabular-nums}
.bar{display:inline-block;height:9px;background:#5b8def;margin-right:6px;vertical-align:middle}
.badge{display:inline-block;padding:0 7px;border-radius:9px;font-size:12px;color:#fff;background:#888}
.ran{background:#2d8a4e}.cached{background:#4a7bd0}.cut{background:#7a5bc7}.used{background:#b07b18}.notrun{background:#aaa}
figure{display:inline-block;margin:6px 10px 10px 0;vertical-align:top;max-width:calc(50% - 12px)}

figure img{max-width:100%;border:1px solid #ccc;display:block;image-rendering:auto}
figcaption{font-size:12px;color:#555;max-width:1024px}figcaption b{color:#1d232a}
.muted{color:#777}.note{color:#a33}.broken{outline:3px solid #d00}.brokenlabel{color:#d00;font-weight:600}
details{margin:4px 0}code{font-size:12px}
.kv{display:flex;flex-wrap:wrap;gap:4px 28px;align-items:flex-start}.kv table{font-size:12px;margin:2px 0}
.kv td.n{text-align:left}.cols{columns:3 320px;column-gap:24px;font-size:12px}.cols div{break-inside:avoid;
     border-bottom:1px solid #e8e8e8;padding:1px 0}.cols code{color:#555}
"""

SCRIPT = """
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images), ok = 0, broken = [];
  imgs.forEach(function (im) {
    if (im.complete && im.naturalWidth > 0) { ok += 1; return; }
    broken.push(im.alt); im.classList.add('broken');
    var s = document.createElement('div'); s.className = 'brokenlabel';
    s.textContent = 'image failed to load: ' + im.alt; im.parentNode.insertBefore(s, im);
  });
  document.body.setAttribute('data-images-total', imgs.length);
  document.body.setAttribute('data-images-loaded', ok);
  document.body.setAttribute('data-images-broken', broken.join(','));
});
"""

HOW_CLASS = {"ran": "ran", "cached": "cached", "cut off": "cut", "used": "used", None: "notrun"}


def esc(x: Any) -> str:
    return html.escape(str(x), quote=True)


def fmt(v: Any) -> str:
    """Numbers short (4 significant digits), the rest as text."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return esc(v if not isinstance(v, (list, dict)) else json.dumps(v))
    if isinstance(v, int):
        return str(v)
    return f"{v:.4g}"


def badge(how: str | None) -> str:
    return f'<span class="badge {HOW_CLASS.get(how, "ran")}">{esc(how or "not run")}</span>'


def figure_html(f: Figure) -> str:
    return (
        f'<figure><img src="{f.uri}" alt="{esc(f.title)}" loading="eager">'
        f"<figcaption><b>{esc(f.title)}</b> {esc(f.caption)}</figcaption></figure>"
    )


def kv_table(d: dict[str, Any]) -> str:
    rows = "".join(f"<tr><td><code>{esc(k)}</code></td><td class=n>{fmt(v)}</td></tr>" for k, v in d.items())
    return f"<table>{rows}</table>" if rows else '<p class="muted">none</p>'


def kv_columns(d: dict[str, Any]) -> str:
    """Many key: value pairs flowing in newspaper columns."""
    items = "".join(f"<div><code>{esc(k)}</code> {fmt(v)}</div>" for k, v in d.items())
    return f'<div class="cols">{items}</div>' if items else '<p class="muted">none</p>'


def summary_table(run: RunInfo) -> str:
    """One row per stage: state, engine, wall / CPU seconds (with a bar), peak RSS, provenance."""
    walls = [float(s.record.get("wall_s") or 0) for s in run.stages]
    longest = max(walls + [1e-9])
    head = (
        "<tr><th>stage</th><th>state</th><th>engine</th><th>wall s</th><th>CPU s</th><th>peak RSS MB</th>"
        "<th>computed in run</th><th>key</th><th>outputs</th></tr>"
    )
    rows = []
    for s, wall in zip(run.stages, walls):
        r = s.record
        if not s.ran:
            rows.append(
                f"<tr><td><a href='#{esc(s.name)}'>{esc(s.name)}</a></td><td>{badge(None)}</td>"
                + "<td></td>" * 7
                + "</tr>"
            )
            continue
        bar = f'<span class="bar" style="width:{max(1, round(120 * wall / longest))}px"></span>' if wall else ""
        size = sum(p.stat().st_size for p in s.files.values()) / 2**20
        origin = r.get("run", "")
        origin = "this run" if origin == run.run_id else origin
        rows.append(
            f"<tr><td><a href='#{esc(s.name)}'>{esc(s.name)}</a></td><td>{badge(s.how)}</td>"
            f"<td>{esc(engine_ran(r))}</td><td class=n>{bar}{fmt(r.get('wall_s', ''))}</td>"
            f"<td class=n>{fmt(r.get('cpu_s', ''))}</td><td class=n>{fmt(r.get('peak_rss_mb', ''))}</td>"
            f"<td>{esc(origin)}</td><td><code>{esc((s.key or '')[:12])}</code></td>"
            f"<td class=n>{len(s.files)} files, {size:.2f} MiB</td></tr>"
        )
    return f"<table>{head}{''.join(rows)}</table>"


def engine_ran(r: dict) -> str:
    """The engine a step's record names, and the one that actually ran when the stage resolved it
    itself (``auto`` -> ``layout``: the step's ``@meta`` engine facts)."""
    conf = str(r.get("engine", ""))
    meta = r.get("meta", {}).get("engine") if isinstance(r.get("meta"), dict) else None
    ran = meta.get("engine") if isinstance(meta, dict) else None
    return f"{conf} -> {ran}" if ran and ran != conf else conf


def stage_section(s: StageInfo, figs: list[Figure], notes: list[str], metrics: dict[str, Any]) -> str:
    """A stage's section: state, provenance, params, metrics, pictures."""
    out = [f'<h2 id="{esc(s.name)}">{esc(s.name)} {badge(s.how)}</h2>']
    if not s.ran:
        out.append(
            '<p class="muted">not run: this run did not include the stage (e.g. <code>--until</code> '
            "or a failed step before it), so there is nothing to show.</p>"
        )
        return "\n".join(out)
    r = s.record
    why = (r.get("meta", {}).get("engine") or {}) if isinstance(r.get("meta", {}).get("engine"), dict) else {}
    facts = [
        f"engine <b>{esc(engine_ran(r) or '?')}</b>" + (f" ({esc(why['why'])})" if why.get("why") else ""),
        f"program <code>{esc(r.get('program', '?'))}</code>",
        f"device {esc(r.get('device', '?'))}",
        f"seed {esc(r.get('seed', '?'))}",
        f"started {esc(r.get('started', '?'))}",
    ]
    if r.get("host"):
        facts.append(f"on {esc(r['host'])} ({esc(r.get('executor') or 'local')})")
    if s.how == "used":
        facts = ["outputs brought in with <code>--use</code> (no step ran)"]
    out.append("<p>" + " &middot; ".join(facts) + "</p>")
    blocks = [f"<details open><summary>params</summary>{kv_table(r.get('params', {}))}</details>"]
    if metrics:
        blocks.append(f'<details open style="flex:1"><summary>metrics</summary>{kv_columns(metrics)}</details>')
    out.extend(f'<p class="note">{esc(n)}</p>' for n in notes)
    if figs:
        out.append("<div>" + "".join(figure_html(f) for f in figs) + "</div>")
    elif not notes:
        out.append('<p class="muted">no pictures: the stage wrote no image, point cloud or training log.</p>')
    out.append(f'<div class="kv">{"".join(blocks)}</div>')
    return "\n".join(out)


def document(run: RunInfo, sections: list[str], run_metrics: dict[str, Any], footer: str) -> str:
    """The whole page."""
    m = run.meta
    title = f"holoflow run {run.run_id}"
    state = "ok" if m.get("ok") else "failed or interrupted"
    info = {
        "prompt": m.get("prompt"),
        "profile": m.get("profile"),
        "seed": m.get("seed"),
        "finished": m.get("finished"),
        "seconds (run wall time)": m.get("seconds"),
        "state": state,
        "pipeline": m.get("pipeline"),
        "run folder": str(run.run_dir),
    }
    return "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8">',
            f"<title>{esc(title)}</title><style>{CSS}</style></head><body>",
            f"<h1>{esc(title)}</h1>",
            f'<p class="muted">{esc(m.get("prompt", ""))}</p>',
            kv_table({k: v for k, v in info.items() if v is not None}),
            "<h2>stages</h2>",
            '<p class="muted">wall / CPU seconds and peak RSS are those of the step that computed the outputs '
            "(for a cached stage, in the run named).</p>",
            summary_table(run),
            "<h2>metrics</h2>",
            '<p class="muted">numbers each step reported (its key record\'s meta); more per stage below.</p>',
            kv_columns(run_metrics),
            *sections,
            f'<p class="muted" style="margin-top:30px">{esc(footer)}</p>',
            f"<script>{SCRIPT}</script>",
            "</body></html>",
            "",
        ]
    )
