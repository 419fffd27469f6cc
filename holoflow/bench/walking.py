"""`holoflow bench accuracy --walk --truth DIR`: what accuracy off the centre costs in time.

The knobs that trade time for a scene that holds where people walk, one at a time around the preview
profile (``POINTS``: P_f's width, the colour fit's view size and passes, the training steps, the base
views' size, the background layer; and the quality profile), each run on a truth set
(docs/truth-sets.md) with its depth given one of the ``TRUTH_WAYS`` (default exact: the reconstruction's
own knobs, the depth held fixed) through the real runner into one shared store, so a point recomputes
only the stages its knob reaches and a stopped sweep resumes. Per point:

- time: the fresh-run cost, the sum over the stages of the wall (and CPU) seconds in their run
  records, also for stages served from the cache; the stages taken from the truth set (``--use``)
  cost nothing;
- accuracy: the scene at the truth views' cameras against their ray-cast truth
  (holoflow.evaluation.truth_scores), PSNR pooled per ring (0 m is the centre), and the cracked
  fraction (alpha < 0.9) at 0.5 m.

Writes a markdown block (the table, and each point's gain over the first against its extra seconds)
into ``--doc`` between ``BEGIN`` / ``END`` markers once the sweep is whole (atomically: a stopped or
failed sweep leaves the last table standing), and with ``--json`` every number, row by row.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from holoflow.bench.profiles import PHOTO_PROMPT, named, stage_costs, truth_cases, update_block

BEGIN = "<!-- holoflow bench accuracy --walk: begin (generated; edit outside these markers) -->"
END = "<!-- holoflow bench accuracy --walk: end -->"


@dataclass(frozen=True)
class Point:
    """One point: ``knob`` and its ``value`` as a reader sees them, the ``--set`` overrides and the
    profile they apply to (None: the sweep's base profile)."""

    name: str
    knob: str
    value: str
    sets: tuple[str, ...] = ()
    profile: str | None = None


POINTS = (
    Point("base", "profile", ""),  # the value: the base profile's name
    Point("pf-plain", "P_f by detail", "off (1536 px everywhere)", ("point_cloud.pf_detail_width=0",)),
    Point("detail-half", "P_f by detail", "2048 px in half the sphere", ("point_cloud.pf_detail_share=0.5",)),
    Point("detail-all", "P_f by detail", "2048 px everywhere", ("point_cloud.pf_detail_share=1",)),
    Point("fit-512", "colour fit view size", "512 px", ("transfer_opt.fit_size=512",)),
    Point("fit-3", "colour fit passes", "3", ("transfer_opt.fit_iters=3",)),
    Point(
        "steps-x4",
        "training steps",
        "x4 (40 + 40, 100)",
        ("pre_opt.pcd_iters=40", "pre_opt.pano_iters=40", "transfer_opt.iters=100"),
    ),
    Point("views-256", "base views' size", "256 px", ("pano_set.size=256",)),
    Point("no-layer", "background layer", "off", ("point_cloud.layer_baseline=0",)),
    Point("quality", "profile", "quality", (), "quality"),
)


def measure(point: Point, case, profile: str, args) -> dict:
    """Run (or serve from the store) one point on one truth-set case and score it per ring: a row."""
    from holoflow.evaluation.runs import run_pipeline
    from holoflow.evaluation.truth_scores import score_truth
    from holoflow.flow.store import Store

    load = os.getloadavg()[0]
    t0 = time.monotonic()
    run_dir, summary = run_pipeline(
        case.prompt,
        point.profile or profile,
        list(case.sets) + list(point.sets) + list(args.sets),
        args.store,
        list(case.uses),
    )
    sweep_s = time.monotonic() - t0
    costs = {n: c for n, c in stage_costs(Store(args.store), summary).items() if c["how"] != "used"}
    truth, _ = score_truth(run_dir / "transfer_opt" / "scene.ply", case.truth, args.backend)
    row = dict(
        point=point.name,
        knob=point.knob,
        value=point.value or point.profile or profile,
        way=case.name,
        profile=point.profile or profile,
        sets=" ".join(point.sets),
        run=run_dir.name,
        ran=" ".join(n for n, c in costs.items() if c["how"] == "ran"),
        load1=round(load, 2),
        sweep_s=round(sweep_s, 1),
        wall_s=round(sum(c["wall_s"] for c in costs.values()), 1),
        cpu_s=round(sum(c["cpu_s"] for c in costs.values()), 1),
        gaussians=truth["gaussians"],
    )
    for key, r in truth["rings"].items():
        row[f"psnr_{key}"] = r["psnr"]
        row[f"cracked_{key}"] = r["cracked"]
    return row


def _f(x: float, fmt: str = "{:.2f}") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def table(rows: list[dict], machine: str) -> str:
    """The markdown block: one line per point and way, its fresh-run seconds, the PSNR per ring, and
    what it buys over the way's first point at 0.5 and 1 m for the seconds it adds."""
    rings = sorted({k[len("psnr_") :] for r in rows for k in r if k.startswith("psnr_")}, key=float)
    first = {}
    for r in rows:
        first.setdefault(r["way"], r)
    lines = [
        BEGIN,
        f"Measured {time.strftime('%Y-%m-%d')} on {machine}. Fresh-run seconds: the sum of the stages' wall "
        "seconds from their run records (CPU seconds in brackets); PSNR in dB pooled over each ring's "
        "views against the truth set's ray-cast views; the gain is over the way's first point.",
        "",
        "| way | point | knob | value | fresh run s | Gaussians | "
        + " | ".join(f"{k} m dB" for k in rings)
        + " | alpha < 0.9 at 0.5 m % | gain 0.5 / 1 m dB | extra s |",
        "|" + "---|" * (len(rings) + 9),
    ]
    for r in rows:
        b = first[r["way"]]
        gain = " / ".join(  # rounded before the sign: no "-0.00"
            _f(round(r.get(f"psnr_{k}", math.nan) - b.get(f"psnr_{k}", math.nan), 2) + 0.0, "{:+.2f}")
            for k in ("0.5", "1")
        )
        extra = _f(round(r["wall_s"] - b["wall_s"], 0) + 0.0, "{:+.0f}")
        lines.append(
            f"| {r['way']} | {r['point']} | {r['knob']} | {r['value']} | {_f(r['wall_s'], '{:.0f}')} "
            f"({_f(r['cpu_s'], '{:.0f}')}) | {r['gaussians']} | "
            + " | ".join(_f(r.get(f"psnr_{k}", math.nan)) for k in rings)
            + f" | {_f(100 * r.get('cracked_0.5', math.nan))} | {gain} | {extra} |"
        )
    return "\n".join(lines + ["", END]) + "\n"


def run(args) -> int:
    """Run the walking sweep for the parsed ``holoflow bench accuracy --walk`` arguments (module
    docstring); returns the exit code."""
    from holoflow.evaluation.machine import machine

    ways = [w for w in args.truth_ways.split(",") if w]
    cases, notes = truth_cases(Path(args.truth) if args.truth else None, ways, PHOTO_PROMPT)
    if not cases:
        print(f"holoflow bench accuracy --walk: {'; '.join(notes) or 'needs --truth DIR'}", file=sys.stderr)
        return 2
    points = named(POINTS, args.points, "holoflow bench accuracy --walk")
    if points is None:
        return 2
    mach = machine()
    rows = []
    for case in cases:
        for p in points:
            row = measure(p, case, args.walk_profile, args)
            rows.append(row)
            print(
                f"walk: {case.name} {p.name:9s} fresh run {row['wall_s']:.0f} s ({row['cpu_s']:.0f} CPU-s), "
                + " / ".join(f"{row.get(f'psnr_{k}', math.nan):.2f}" for k in ("0", "0.25", "0.5", "1"))
                + f" dB at 0 / 0.25 / 0.5 / 1 m [ran {row['ran']}] (load {row['load1']})",
                file=sys.stderr,
                flush=True,
            )
            if args.json:  # a stopped sweep still leaves its rows here
                args.json.write_text(json.dumps(dict(machine=mach, rows=rows), indent=1, default=str))
    if args.doc:  # the document only takes a whole sweep: a stopped one leaves the last table standing
        update_block(args.doc, table(rows, mach), BEGIN, END)
    return 0
