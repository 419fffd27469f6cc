"""`holoflow report [RUN]`: one self-contained HTML page for a run in the store (docs/report.md).

Each stage's outputs as pictures (panoramas, line art, depth / disparity colour maps, tangent faces and
view sets as contact sheets with their masks, point clouds, training curves, final scene renders), its
state (ran / cached / cut off / used / not run), engine, params, wall time, CPU time, peak RSS and
metrics. Images are embedded as data: URIs, so the one file can be mailed or archived.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

from holoflow.report.runinfo import ReportError, RunInfo, collect


def build(run: RunInfo, render_clouds: bool = True, view_size: int = 512) -> str:
    """The report page of ``run`` as HTML text; with ``view_size`` > 0 and a final scene, a first
    section scores it at that viewing size (holoflow.report.viewing_section); each truth score that
    ``holoflow eval run RUN --truth DIR`` left in runs/<id>/eval/ comes first (holoflow.report.truth_section)."""
    from holoflow.report import clouds as cl
    from holoflow.report import figures as fg
    from holoflow.report import page

    cloud_figs, renderer = _cloud_figures(run, cl) if render_clouds else ({}, "not rendered (--no-clouds)")
    sections, run_metrics = [], {}
    for s in run.stages:
        figs, notes, metrics = [], [], {}
        if s.ran:
            figs, notes = fg.stage_figures(s.files, cloud_figs.get(s.name, {}))
            if s.missing:
                notes.insert(
                    0,
                    f"{len(s.missing)} output(s) no longer in the store (removed by gc?): "
                    + ", ".join(s.missing[:5])
                    + (" ..." if len(s.missing) > 5 else ""),
                )
            metrics = fg.stage_metrics(s.record, s.files)
            run_metrics.update(
                {
                    f"{s.name}: {k}": v
                    for k, v in fg.scalars(s.record.get("meta", {})).items()
                    if isinstance(v, (int, float)) and not isinstance(v, bool)
                }
            )
        sections.append(page.stage_section(s, figs, notes, metrics))
    scene = run.run_dir / "transfer_opt" / "scene.ply"
    if view_size > 0 and scene.is_file():
        from holoflow.evaluation.viewing_size import ViewingSpec, score_run
        from holoflow.flow.store import read_json
        from holoflow.report.viewing_section import section_html

        info = read_json(run.run_dir / "run.json") or {}
        scores, pictures = score_run(run.run_dir, info, ViewingSpec(size=view_size))
        sections.insert(0, section_html(scores, pictures, run.meta.get("profile")))
    from holoflow.report.truth_section import truth_sections

    sections[:0] = truth_sections(run.run_dir / "eval")
    footer = (
        f"made by holoflow report at {time.strftime('%Y-%m-%d %H:%M:%S %Z')}; point clouds: {renderer}, "
        f"cut away above the panorama centre, seen from above"
    )
    return page.document(run, sections, run_metrics, footer)


def _cloud_figures(run: RunInfo, cl) -> tuple[dict[str, dict[str, Any]], str]:
    """{stage: {ply name: Figure}} for every PLY of the run, rendered in one batch, and the renderer."""
    import tempfile

    from holoflow.report import pictures as pic
    from holoflow.report.figures import Figure

    plys = [(s.name, rel, path) for s in run.stages for rel, path in s.files.items() if rel.endswith(".ply")]
    with tempfile.TemporaryDirectory(prefix="holoflow-report-") as tmp:
        jobs = [(path, Path(tmp) / f"{i}.png") for i, (_, _, path) in enumerate(plys)]
        images, renderer = cl.render_files(jobs)
    out: dict[str, dict[str, Any]] = {}
    for (stage, rel, _), img in zip(plys, images):
        if img is not None:
            out.setdefault(stage, {})[rel] = Figure(
                rel, pic.image_uri(img), f"{img.shape[1]} x {img.shape[0]}; rendered with {renderer}"
            )
    return out, renderer


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="holoflow report", description=__doc__.split("\n\n")[0])
    p.add_argument("run", nargs="?", default="latest", help="run id (runs/<id>) or 'latest' (default)")
    p.add_argument(
        "--pipeline",
        default="pipeline.yaml",
        help="pipeline file (default ./pipeline.yaml): gives the stage order and lists stages the run did not include",
    )
    p.add_argument("--store", help="store folder (default $HOLOFLOW_STORE, else artifacts/ beside the pipeline)")
    p.add_argument("-o", "--output", type=Path, help="HTML file to write (default ./report-<run id>.html)")
    p.add_argument("--no-clouds", action="store_true", help="skip the point-cloud pictures (faster)")
    p.add_argument(
        "--view-size",
        type=int,
        default=512,
        help="score the final scene at this viewing size, px (holoflow eval --run's table, source | "
        "render crops and novel views; 0 = skip)",
    )
    p.add_argument(
        "--screenshot", type=Path, metavar="PNG", help="also screenshot the page with headless Chromium (1280 px wide)"
    )
    p.add_argument("--screenshot-height", type=int, default=2400, help="screenshot height, CSS pixels")
    args = p.parse_args(argv)

    from holoflow.flow.pipeline import find_pipeline
    from holoflow.flow.store import Store

    path = find_pipeline(args.pipeline)
    store = Store(args.store or os.environ.get("HOLOFLOW_STORE") or (path.parent / "artifacts"))
    try:
        order = _stage_order(path)
        run = collect(store, args.run, order)
        html = build(run, render_clouds=not args.no_clouds, view_size=args.view_size)
    except ReportError as e:
        print(f"holoflow report: error: {e}", file=sys.stderr)
        return 2
    out = args.output or Path(f"report-{run.run_id}.html")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(html, encoding="utf-8")
    print(f"holoflow report: {out} ({len(html.encode()) / 2**20:.1f} MiB)", file=sys.stderr)
    if args.screenshot:
        from holoflow.report import chromium

        chromium.screenshot(out, args.screenshot, height=args.screenshot_height)
        print(f"holoflow report: screenshot {args.screenshot}", file=sys.stderr)
    return 0


def _stage_order(pipeline_path: Path) -> list[str]:
    """Stage names in topological order, or [] when there is no readable pipeline file (the run's own
    stages are then shown in run.json order)."""
    from holoflow.flow import pipeline

    try:
        return list(pipeline.load(pipeline_path).stages)
    except (pipeline.PipelineError, OSError):
        return []
