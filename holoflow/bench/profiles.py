"""`holoflow bench accuracy --profiles P1,P2,...`: the profiles on the accuracy-vs-time curve, scored
where people look.

Each named profile runs, through the real runner into one shared store, on procedural scenes (a
prompt each; the source is the detail panorama, and novel views have truth) and on the photos of a
folder (``holoflow run PHOTO_PROMPT --use base_pano=PHOTO``; the source is the photo itself) and on a
truth set (``--truth DIR``, docs/truth-sets.md) run three ways (``TRUTH_WAYS``: exact depth, the
simulated network's depth, RGB only), each also scored per ring against the truth set's views
(holoflow.evaluation.truth_scores); with ``--scene-truth`` the procedural scenes are scored the same
way against a truth set ray cast from each (``scene_truth_set``). Each finished run is scored by
``holoflow.evaluation.viewing_size.score_run`` at the viewing size (default 512 px at the paper's
47.43 deg) and timed by its stages' run records (wall and CPU seconds of computing each
stage, also when served from the cache: what a fresh run costs). A profile the pipeline does not
define, or one that needs a GPU or model weights absent here, is skipped with a line saying why:
nothing is faked.

Writes a markdown block (the table with each profile's goals and pictures' links) into ``--doc``
between ``BEGIN`` / ``END`` markers once every run is scored (the rest of the file is kept; written
atomically, so a stopped bench leaves the last table standing), pictures
``viewing-<case>-<profile>-{base,novel}.jpg`` (JPEG 90: photographs) and, for a truth set,
``truth-<case>-<profile>-ring-<r>.jpg`` (truth above render) into ``--pictures``, and with
``--json`` every number, run by run.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENES = ("a cozy wooden cabin at night", "a stone courtyard with a fountain")
PHOTOS = ROOT.parent / "shared" / "data" / "photos"  # the issue's ../shared/data/photos
PHOTO_PROMPT = "a room"
PHOTO_EXTS = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".hdr", ".exr")
# way -> (--use, --set) of a truth set run (DIR = the truth set's folder); engine names: holoflow/depth/config.py
TRUTH_WAYS = {
    "exact": (("base_pano=DIR/pano_z.exr", "metric_align=DIR/pano_z.exr"), ()),
    "simulated": (("base_pano=DIR/pano_z.exr",), ("tangent_depth.engine=simulated", "metric_align.engine=simulated")),
    "rgb": (("base_pano=DIR/pano.png",), ()),
}
BEGIN = "<!-- holoflow bench accuracy --profiles: begin (generated; edit outside these markers) -->"
END = "<!-- holoflow bench accuracy --profiles: end -->"


@dataclass(frozen=True)
class Case:
    """One input: ``name`` (file-name safe), the prompt, and ``uses`` (STAGE=PATH, as --use)."""

    name: str
    kind: str  # "scene" | "photo" | "truth"
    prompt: str
    uses: tuple[str, ...] = ()
    sets: tuple[str, ...] = ()
    truth: Path | None = None  # a truth set to score the run against per ring


def named(points: list, names: str, prog: str) -> list | None:
    """The sweep points (anything with a ``name``) named in the comma list ``names`` ("all": every one),
    in their own order; None, after saying on stderr which names ``prog`` does not know, when some are
    unknown."""
    if names == "all":
        return list(points)
    want = names.split(",")
    unknown = sorted(set(want) - {p.name for p in points})
    if unknown:
        print(f"{prog}: unknown point(s) {unknown}; choose from {[p.name for p in points]}", file=sys.stderr)
        return None
    return [p for p in points if p.name in want]


def stage_costs(store, summary: dict) -> dict[str, dict]:
    """Per stage of a run summary: how it was served and the cost of computing it, from its record:
    {stage: {how, wall_s, cpu_s, peak_rss_mb}} (seconds, MB)."""
    out = {}
    for name, entry in summary["stages"].items():
        prov = (store.record(entry["key"]) or {}).get("provenance", {}) if entry.get("key") else {}
        out[name] = {
            "how": entry["how"],
            "wall_s": float(prov.get("wall_s", math.nan)),
            "cpu_s": float(prov.get("cpu_s", math.nan)),
            "peak_rss_mb": float(prov.get("peak_rss_mb", math.nan)),
        }
    return out


def slug(text: str) -> str:
    return "-".join("".join(c if c.isalnum() else " " for c in text.lower()).split())[:48]


def cases(scenes: list[str], photos: Path | None, photo_prompt: str = PHOTO_PROMPT) -> tuple[list[Case], list[str]]:
    """The inputs: one Case per scene prompt and per image file of ``photos`` (sorted), and notes (a
    missing photo folder)."""
    out = [Case(slug(p), "scene", p) for p in scenes]
    notes = []
    if photos is not None:
        if photos.is_dir():
            out += [
                Case(slug(f.stem), "photo", photo_prompt, (f"base_pano={f}",))
                for f in sorted(photos.iterdir())
                if f.suffix.lower() in PHOTO_EXTS
            ]
        else:
            notes.append(f"no photo folder {photos}: photos not measured")
    return out, notes


def truth_cases(folder: Path | None, ways: list[str], prompt: str = PHOTO_PROMPT) -> tuple[list[Case], list[str]]:
    """One Case per way of ``TRUTH_WAYS`` for the truth set in ``folder`` (named <set>-<way>), and notes
    (no such truth set)."""
    unknown = sorted(set(ways) - set(TRUTH_WAYS))
    if unknown:
        raise SystemExit(f"holoflow bench accuracy: unknown truth way(s) {unknown}; choose from {list(TRUTH_WAYS)}")
    if folder is None:
        return [], []
    if not (folder / "cameras.json").is_file():
        return [], [f"no truth set {folder} (cameras.json missing): truth set not measured"]
    out = []
    for way in ways:
        uses, sets = TRUTH_WAYS[way]
        out.append(
            Case(
                f"{slug(folder.name)}-{way}",
                "truth",
                prompt,
                tuple(u.replace("DIR", str(folder)) for u in uses),
                sets,
                folder,
            )
        )
    return out, []


def unavailable(pipe, profile: str) -> str | None:
    """Why ``profile`` cannot run here (not defined, needs a GPU, needs weights), or None."""
    from holoflow.flow import pipeline
    from holoflow.networks.manifest import needs

    if profile not in pipe.profiles:
        return f"profile {profile!r} is not defined in {pipe.path.name} (defined: {', '.join(pipe.profiles)})"
    resolved = pipeline.resolve(pipe, profile)
    why = []
    gpu = [n for n, r in resolved.items() if r.resources.gpus > 0]
    if gpu:
        import torch

        if not torch.cuda.is_available():
            why.append(f"its stages {', '.join(gpu)} need a GPU and torch sees no CUDA device")
    missing = sorted({n.role for n in needs(resolved) if not n.present})
    if missing:
        why.append(f"model weights not here: {', '.join(missing)} (`holoflow models list`)")
    return "; ".join(why) or None


def measure(case: Case, profile: str, args) -> tuple[dict, dict, dict]:
    """Run (or serve from the store) one case in one profile and score it at the viewing size:
    (row of figures, scores, pictures)."""
    from holoflow.evaluation.runs import run_pipeline
    from holoflow.evaluation.viewing_size import ViewingSpec, score_run
    from holoflow.flow.store import Store

    t0 = time.monotonic()
    load = os.getloadavg()[0]
    run_dir, summary = run_pipeline(
        case.prompt, profile, list(args.sets) + list(case.sets), args.store, list(case.uses)
    )
    run_s = time.monotonic() - t0
    costs = stage_costs(Store(args.store), summary)
    info = Store(args.store).run_info(run_dir.name) or {}
    t0 = time.monotonic()
    spec = ViewingSpec(
        size=args.size, fov_deg=args.fov, nr_cameras=args.nr_cameras, seed=args.seed, backend=args.backend
    )
    scores, pictures = score_run(run_dir, info, spec)
    b, nr, nv = scores["base"], scores["nr"], scores["novel"]
    row = dict(
        case=case.name,
        kind=case.kind,
        profile=profile,
        run=run_dir.name,
        load1=round(load, 2),
        sweep_s=round(run_s, 1),
        score_s=round(time.monotonic() - t0, 1),
        wall_s=round(sum(c["wall_s"] for n, c in costs.items() if c["how"] != "used"), 1),
        cpu_s=round(sum(c["cpu_s"] for n, c in costs.items() if c["how"] != "used"), 1),
        gaussians=scores["gaussians"],
        psnr=b["psnr"],
        psnr_pooled=b["psnr_pooled"],
        ssim=b["ssim"],
        polar_psnr=b["polar_psnr"],
        polar_gap=b["polar_gap_db"],
        niqe=(nr.get("niqe") or {}).get("ratio", math.nan),
        brisque=(nr.get("brisque") or {}).get("ratio", math.nan),
        **{f"empty_{d}": r["empty"] for d, r in nv.items()},
        **{f"novel_psnr_{d}": r.get("psnr", math.nan) for d, r in nv.items()},
    )
    truth_dir = case.truth
    if truth_dir is None and case.kind == "scene" and getattr(args, "scene_truth", False):
        truth_dir = scene_truth_set(run_dir, Path(args.store) / "truth" / case.name)
    if truth_dir is not None:
        from holoflow.evaluation.truth_scores import score_truth

        truth, rings = score_truth(run_dir / "transfer_opt" / "scene.ply", truth_dir, args.backend)
        scores["truth"] = truth
        pictures["truth_rings"] = rings
        row["truth_score_s"] = round(truth["seconds"], 1)
        for key, r in truth["rings"].items():
            row.update({f"truth_{m}_{key}": r[m] for m in ("psnr", "ssim", "abs_rel", "empty", "cracked")})
    return row, scores, pictures


def scene_truth_set(run_dir: Path, folder: Path) -> Path:
    """The truth set of a procedural run's scene (base_pano/scene.json) in ``folder``, ray cast there
    (holoflow.evaluation.truth_set.write_truth_set) unless it already holds one."""
    if not (folder / "cameras.json").is_file():
        from holoflow.evaluation.truth_set import write_truth_set
        from holoflow.scene.model import Scene

        write_truth_set(folder, Scene.from_json((run_dir / "base_pano" / "scene.json").read_text()))
    return folder


def goal_marks(row: dict) -> str:
    """The goals of the row's profile (holoflow.evaluation.viewing_size.GOALS) that it misses, or 'all met'."""
    from holoflow.evaluation.viewing_size import goals_for

    _, g = goals_for(row["profile"])
    checks = {
        "psnr": (row["psnr"], False),
        "brisque": (row["brisque"], True),
        "niqe": (row["niqe"], True),
        "polar_gap": (row["polar_gap"], True),
        "empty_0.5": (row.get("empty_0.5", math.nan), True),
        "seconds": (row["wall_s"], True),
    }
    miss = [
        k
        for k, goal in g.items()
        if k in checks
        and not math.isnan(checks[k][0])
        and not (checks[k][0] <= goal if checks[k][1] else checks[k][0] >= goal)
    ]
    return "all met" if not miss else "missed: " + ", ".join(miss)


def _f(x, fmt: str = "{:.2f}") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def markdown(
    rows: list[dict], skipped: list[str], notes: list[str], args, machine: str, pictures: dict[str, tuple[str, ...]]
) -> str:
    """The generated block: the table, the goals, the skipped profiles and links to the pictures."""
    from holoflow.evaluation.viewing_size import GOALS

    head = (
        "| input | profile | fresh run s (CPU s) | base PSNR dB (pooled) | SSIM | zenith/nadir gap dB | NIQE x | "
        "BRISQUE x | empty 0.25 / 0.5 / 1 m % | novel PSNR 0.5 m | Gaussians | goals |"
    )
    lines = [
        BEGIN,
        "",
        f"Measured with `holoflow bench accuracy --profiles {args.profiles}` on {machine}, "
        f"load {_f(max((r['load1'] for r in rows), default=math.nan), '{:.1f}')} (1-min average, worst "
        f"point). Viewing size {args.size} px, {args.fov} deg; base = the scene at the run's base cameras vs "
        "the source's views (the photo itself for a photo, else the detail panorama), means of the "
        "per-camera values over the cameras > 25 deg from the poles (pooled: PSNR of their pooled error); "
        "zenith/nadir gap = their PSNR below that mean; NIQE / BRISQUE = render / source; empty = alpha "
        "< 0.5 at 8 seeded novel cameras per distance; novel PSNR vs the procedural truth. Seconds: the "
        "sum of the stages' wall seconds from their run records (what a fresh run costs; the shared "
        "2-core machine's load included), CPU seconds in brackets.",
        "",
        head,
        "|" + "---|" * 12,
    ]
    for r in rows:
        e = " / ".join(_f(100 * r.get(f"empty_{d}", math.nan)) for d in ("0.25", "0.5", "1"))
        lines.append(
            f"| {r['case']} | {r['profile']} | {_f(r['wall_s'], '{:.0f}')} ({_f(r['cpu_s'], '{:.0f}')}) | "
            f"{_f(r['psnr'])} ({_f(r['psnr_pooled'])}) | {_f(r['ssim'], '{:.3f}')} | {_f(r['polar_gap'])} | "
            f"{_f(r['niqe'])} | {_f(r['brisque'])} | {e} | {_f(r.get('novel_psnr_0.5', math.nan))} | "
            f"{r['gaussians']} | {goal_marks(r)} |"
        )
    lines += [
        "",
        "Goals: "
        + "; ".join(
            f"{p}: " + ", ".join(f"{k} {'>=' if k == 'psnr' else '<='} {v}" for k, v in g.items())
            for p, g in GOALS.items()
        )
        + " (NIQE / BRISQUE as ratios, empty as a fraction).",
        "",
    ]
    lines += truth_table(rows)
    lines += [f"- skipped: {s}" for s in skipped] + [f"- note: {n}" for n in notes]
    if pictures:
        lines += [
            "",
            f"Pictures (left source, right render, centre 256 px of the {args.size} px views at 1:1; "
            "novel views 0.5 m off centre with empty pixels in magenta):",
            "",
        ]
        rel = Path(os.path.relpath(args.pictures, args.doc.parent)) if args.doc else Path(args.pictures)
        for key, names in pictures.items():
            if len(names) == 1:
                lines.append(f"- {key}: [truth above render]({(rel / names[0]).as_posix()})")
                continue
            base, novel = names
            lines.append(
                f"- {key}: [base cameras]({(rel / base).as_posix()}), [novel 0.5 m]({(rel / novel).as_posix()})"
            )
    return "\n".join(lines + ["", END]) + "\n"


def truth_table(rows: list[dict]) -> list[str]:
    """Markdown lines: the truth-set rows' per-ring PSNR (dB), AbsRel and cracked fraction at 0.5 m, and
    seconds ([] when no row has a truth score)."""
    rows = [r for r in rows if "truth_psnr_0" in r]
    if not rows:
        return []
    rings = sorted({k[len("truth_psnr_") :] for r in rows for k in r if k.startswith("truth_psnr_")}, key=float)
    lines = [
        "Truth set (`--truth`): the scene at the truth views' cameras (512 px, 47.43 deg) against their "
        "ray-cast truth, PSNR pooled over each ring's 8 views (sRGB); AbsRel of the rendered depth, empty "
        "(alpha < 0.5) and cracked (alpha < 0.9) at 0.5 m:",
        "",
        "| input | profile | fresh run s | "
        + " | ".join(f"{k} m dB" for k in rings)
        + " | AbsRel 0.5 m | empty 0.5 m % | alpha < 0.9 at 0.5 m % |",
        "|" + "---|" * (len(rings) + 6),
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['profile']} | {_f(r['wall_s'], '{:.0f}')} | "
            + " | ".join(_f(r.get(f"truth_psnr_{k}", math.nan)) for k in rings)
            + f" | {_f(r.get('truth_abs_rel_0.5', math.nan), '{:.4f}')} | "
            f"{_f(100 * r.get('truth_empty_0.5', math.nan))} | "
            f"{_f(100 * r.get('truth_cracked_0.5', math.nan))} |"
        )
    return lines + [""]


def replace_block(text: str, block: str, begin: str = BEGIN, end: str = END) -> str:
    """``text`` with the ``begin`` ... ``end`` block replaced by ``block`` (appended when it has none)."""
    if begin in text and end in text:
        i, j = text.index(begin), text.index(end) + len(end)
        return text[:i] + block.rstrip("\n") + text[j:]
    return text.rstrip("\n") + "\n\n" + block


def update_block(path: Path, block: str, begin: str = BEGIN, end: str = END) -> None:
    """The ``begin`` ... ``end`` block of the document at ``path`` replaced by ``block`` (``replace_block``;
    a new document when there is none), written atomically: a full disk or a kill mid-write leaves the
    old document whole, never a truncated one."""
    from holoflow.flow.store import write_atomic

    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, replace_block(path.read_text() if path.is_file() else "", block, begin, end))


def write(args, block: str | None, runs: list[dict], skipped: list[str], notes: list[str]) -> None:
    """The block into ``--doc`` (``update_block``; None: the document is left as it is) and every number
    into ``--json``, when given."""
    from holoflow.evaluation.machine import machine

    if args.doc and block is not None:
        update_block(args.doc, block)
    if args.json:
        args.json.write_text(
            json.dumps(dict(machine=machine(), skipped=skipped, notes=notes, runs=runs), indent=1, default=str)
        )


def run(args) -> int:
    """Run the profile comparison for the parsed ``holoflow bench accuracy`` arguments (module
    docstring); returns the exit code."""
    from holoflow.evaluation.machine import machine
    from holoflow.evaluation.truth_scores import ring_strip
    from holoflow.flow import pipeline
    from holoflow.report.pictures import encode
    from holoflow.report.viewing_section import base_picture, novel_picture

    pipe = pipeline.load(ROOT / "pipeline.yaml")
    profiles = [p for p in args.profiles.split(",") if p]
    photos = Path(args.photos) if args.photos else None
    todo, notes = cases([s for s in args.scenes.split(";") if s], photos, args.photo_prompt)
    more, why = truth_cases(
        Path(args.truth) if args.truth else None, [w for w in args.truth_ways.split(",") if w], args.photo_prompt
    )
    todo, notes = todo + more, notes + why
    for n in why:
        print(f"accuracy: {n}", file=sys.stderr, flush=True)
    skipped, runnable = [], []
    for p in profiles:
        why = unavailable(pipe, p)
        if why:
            skipped.append(f"{p}: {why}")
            print(f"accuracy: skipping profile {p}: {why}", file=sys.stderr, flush=True)
        else:
            runnable.append(p)
    rows, pics, everything = [], {}, []
    for case in todo:
        for p in runnable:
            row, scores, pictures = measure(case, p, args)
            rows.append(row)
            everything.append(dict(row=row, scores=scores))
            print(
                f"accuracy: {case.name} {p}: {row['wall_s']:.0f} s fresh run, base {row['psnr']:.2f} dB, "
                f"BRISQUE x{row['brisque']:.2f}, zenith/nadir gap {row['polar_gap']:.2f} dB, 0.5 m empty "
                f"{100 * row.get('empty_0.5', math.nan):.2f} % ({goal_marks(row)})",
                file=sys.stderr,
                flush=True,
            )
            if args.pictures:
                args.pictures.mkdir(parents=True, exist_ok=True)
                names = (f"viewing-{case.name}-{p}-base.jpg", f"viewing-{case.name}-{p}-novel.jpg")
                (args.pictures / names[0]).write_bytes(encode(base_picture(scores, pictures)[0], "jpeg", 90))
                if "0.5" in scores["novel"]:
                    (args.pictures / names[1]).write_bytes(encode(novel_picture(scores, pictures)[0], "jpeg", 90))
                pics[f"{case.name} ({p})"] = names
                for key, (truth, render) in pictures.get("truth_rings", {}).items():
                    name = f"truth-{case.name}-{p}-ring-{key}.jpg"
                    (args.pictures / name).write_bytes(encode(ring_strip(truth, render, side=192), "jpeg", 90))
                    pics[f"{case.name} ({p}) truth | render {key} m"] = (name,)
            write(args, None, everything, skipped, notes)  # a stopped bench leaves its runs in --json
    block = markdown(rows, skipped, notes, args, machine(), pics)
    write(args, block, everything, skipped, notes)
    print(block)
    print(
        f"accuracy: {len(rows)} runs scored at {args.size} px; {len(skipped)} profile(s) skipped"
        + (f"; table in {args.doc}" if args.doc else ""),
        file=sys.stderr,
    )
    return 0
